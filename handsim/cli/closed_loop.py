"""``handsim closed-loop``: an env's expert with an estimator in every step, feedback off and on."""

from __future__ import annotations

import argparse

__all__ = ["ESTIMATORS", "add_parser"]


ESTIMATORS = ("oracle", "com")
"""Estimators of ``handsim closed-loop``: the noisy oracle and the centre-of-mass localizer."""


def _run(args: argparse.Namespace) -> int:
    import json

    import handsim.envs  # noqa: F401 (registers the ids)
    from handsim.envs.closed_loop import evaluate_closed_loop, write_report

    if args.estimator == "oracle":
        from handsim.estimators import OracleEstimator

        def make_estimator():
            return OracleEstimator(
                noise_mm=args.noise_mm,
                dropout=args.dropout,
                latency_steps=args.latency_steps,
                object_noise_mm=(
                    args.noise_mm if args.object_noise_mm is None else args.object_noise_mm
                ),
                object_noise_deg=args.object_noise_deg,
                rng=args.seed,
            )
    else:
        from handsim.estimators import CenterOfMassLocalizer

        def make_estimator():
            return CenterOfMassLocalizer()

    env_kwargs = {"obs_mode": "depth", "sensor": args.sensor, "camera": args.camera}
    if args.objects:
        env_kwargs["objects"] = args.objects
    report = evaluate_closed_loop(
        args.env, make_estimator, episodes=args.episodes, seed=args.seed, env_kwargs=env_kwargs
    )
    report["estimator"] = {"name": args.estimator, "repr": repr(make_estimator())}
    paths = write_report(report, args.out)
    summary = {
        name: {
            "success_rate": mode["success_rate"],
            "kp_mean_mm": round(mode["kp_mean_mm"], 2),
            "center_mm": round(mode["center_mm"], 2),
            "f_tau_auc": round(mode["f_tau_auc"], 3),
        }
        for name, mode in report["modes"].items()
    }
    print(json.dumps(summary, indent=2))
    print("written: " + ", ".join(str(p) for p in paths.values()))
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``handsim closed-loop`` to the program's subcommands."""
    loop = sub.add_parser(
        "closed-loop",
        help="run an expert with an estimator in the loop, feedback off and on; write a report",
        description="Run N episodes of an env with its scripted expert and a pose estimator in "
        "every step, once acting on the truth and once on the estimate; write closed_loop.json, "
        "f_tau.png and success.png.",
    )
    loop.add_argument("--env", default="handsim/Grasp-v0", help="env id (default: %(default)s)")
    loop.add_argument("--estimator", choices=ESTIMATORS, default="oracle")
    loop.add_argument("--noise-mm", type=float, default=10.0, help="oracle noise per axis, mm")
    loop.add_argument(
        "--object-noise-mm",
        type=float,
        default=None,
        help="oracle object translation noise per axis, mm (default: --noise-mm)",
    )
    loop.add_argument(
        "--object-noise-deg", type=float, default=0.0, help="oracle object rotation noise, deg"
    )
    loop.add_argument("--dropout", type=float, default=0.0, help="oracle dropout probability")
    loop.add_argument("--latency-steps", type=int, default=0, help="oracle latency, steps")
    loop.add_argument("--episodes", type=int, default=5, help="episodes per mode")
    loop.add_argument("--seed", type=int, default=0)
    loop.add_argument("--objects", nargs="*", help="object names (default: the env's)")
    loop.add_argument("--sensor", default="structured_light", help="depth sensor model")
    loop.add_argument("--camera", default="icvl", help="camera preset")
    loop.add_argument("--out", default="handsim-closed-loop", help="output folder")
    loop.set_defaults(func=_run)
