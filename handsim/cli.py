"""The ``handsim`` command-line program."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["main"]


DEMO_GRASP_OBJECTS = ("005_tomato_soup_can", "006_mustard_bottle", "025_mug")
"""Objects of the demo's closed-loop evaluation on ``handsim/Grasp-v0``."""


def _demo_closed_loop(out: Path, episodes: int) -> dict:
    """The oracle (10 mm noise on keypoints and object position) in the loop of Grasp-v0."""
    import handsim.envs  # noqa: F401 (registers the ids)
    from handsim.envs.closed_loop import evaluate_closed_loop, write_report
    from handsim.estimators import OracleEstimator

    report = evaluate_closed_loop(
        "handsim/Grasp-v0",
        lambda: OracleEstimator(noise_mm=10.0, object_noise_mm=10.0, rng=0),
        episodes=episodes,
        env_kwargs={"objects": list(DEMO_GRASP_OBJECTS), "sensor": "structured_light"},
    )
    report["estimator"] = "OracleEstimator(noise_mm=10, object_noise_mm=10)"
    paths = write_report(report, out / "closed_loop")
    return {"report": report, "paths": {k: str(v) for k, v in paths.items()}}


def _demo(args: argparse.Namespace) -> int:
    import json

    from handsim.demo import run_demo

    # The core demo (hands, frames) cannot import the envs (layers); the CLI adds the loop.
    summary = run_demo(args.out, width=args.size, height=args.size)
    out = Path(args.out)
    lines = [(out / "summary.txt").read_text().rstrip("\n"), ""]
    if args.closed_loop_episodes > 0:
        loop = _demo_closed_loop(out, args.closed_loop_episodes)
        summary["closed_loop"] = {
            name: {
                "success_rate": mode["success_rate"],
                "kp_mean_mm": mode["kp_mean_mm"],
                "f_tau_auc": mode["f_tau_auc"],
            }
            for name, mode in loop["report"]["modes"].items()
        }
        summary["closed_loop"]["paths"] = loop["paths"]
        lines.append(
            f"closed loop, handsim/Grasp-v0, oracle with 10 mm noise, "
            f"{args.closed_loop_episodes} episode(s) per mode on {', '.join(DEMO_GRASP_OBJECTS)}:"
        )
        for name, mode in loop["report"]["modes"].items():
            lines.append(
                f"  {name.replace('_', ' '):<13} success {100 * mode['success_rate']:5.1f} %, "
                f"mean keypoint error {mode['kp_mean_mm']:.1f} mm, F(tau) AUC "
                f"{mode['f_tau_auc']:.3f}"
            )
        lines.append(f"closed-loop plots: {loop['paths']['f_tau']}, {loop['paths']['success']}")
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        (out / "summary.txt").write_text("\n".join(lines) + "\n")
    print((out / "summary.txt").read_text(), end="")
    return 0 if summary["hands"] else 1


def _info(args: argparse.Namespace) -> int:
    import mujoco

    import handsim
    from handsim.hand import HAND_SIZES, Hand
    from handsim.pose import JOINT_LIMITS_DEG, JOINT_NAMES

    model = Hand().compile()
    print(f"handsim {handsim.__version__}, MuJoCo {mujoco.__version__}")
    print(f"hand: nq={model.nq} nv={model.nv} nu={model.nu} bodies={model.nbody - 1}")
    print("size presets: " + ", ".join(f"{k}={v * 1000:.0f} mm" for k, v in HAND_SIZES.items()))
    print("joints (deg):")
    for name, (lo, hi) in zip(JOINT_NAMES, JOINT_LIMITS_DEG, strict=True):
        print(f"  {name:<16} {lo:7.1f} .. {hi:6.1f}")
    return 0


ESTIMATORS = ("oracle", "com")
"""Estimators of ``handsim closed-loop``: the noisy oracle and the centre-of-mass localizer."""


def _closed_loop(args: argparse.Namespace) -> int:
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


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="handsim",
        description="Simulated 27-DoF human hand with depth sensing for hand pose estimation.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    demo = sub.add_parser(
        "demo",
        help="play gestures with hands of three sizes and both sides; write a contact sheet",
        description="Build hands of three sizes and both sides, play a gesture sequence under "
        "physics, render labelled noisy depth frames of a hand among objects, run the oracle "
        "estimator in the loop of handsim/Grasp-v0 with feedback off and on, and write the "
        "contact sheets, plots and a summary to the output folder.",
    )
    demo.add_argument("--out", default="handsim-demo", help="output folder (default: %(default)s)")
    demo.add_argument("--size", type=int, default=200, help="tile size in pixels (default: 200)")
    demo.add_argument(
        "--closed-loop-episodes",
        type=int,
        default=3,
        help="episodes per feedback mode of the Grasp-v0 closed loop; 0 skips it (default: 3)",
    )
    demo.set_defaults(func=_demo)
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
    loop.set_defaults(func=_closed_loop)
    info = sub.add_parser("info", help="print versions, hand presets and joint limits")
    info.set_defaults(func=_info)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``handsim`` program.

    Args:
        argv: arguments (default: ``sys.argv[1:]``).

    Returns:
        The process exit status.
    """
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
