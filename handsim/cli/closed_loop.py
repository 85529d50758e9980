"""``handsim closed-loop``: an env's expert with an estimator in every step, feedback off and on."""

from __future__ import annotations

import argparse
from typing import Any

from handsim.cli._args import (
    add_quiet,
    choice_help,
    non_negative_int,
    number,
    object_name,
    positive_int,
    probability,
    progress_bar,
    seed,
    strict_json,
)
from handsim.cli.estimators import BUILTIN_ESTIMATORS, EstimatorSpec, parse_estimator_spec
from handsim.errors import HandSimError
from handsim.estimators.oracle import MAX_NOISE_MM

__all__ = ["ESTIMATORS", "add_parser", "estimator_arg"]


ESTIMATORS = tuple(BUILTIN_ESTIMATORS)
"""Built-in estimators of ``handsim closed-loop``: the noisy oracle, the centre-of-mass
localizer and the shipped DeepPrior++ / DeepPrior; ``--estimator`` also takes a learned
estimator's checkpoint (``NAME.pt`` or a ``handsim train`` run folder) and
``module:Class[:kwargs-json]``."""


def _is_checkpoint(text: str) -> bool:
    """A learned estimator's checkpoint: ``NAME.pt`` or a training run folder."""
    from pathlib import Path

    path = Path(text)
    return (path.suffix == ".pt" and path.is_file()) or (path / "best.pt").is_file()


def estimator_arg(text: str) -> str | EstimatorSpec:
    """``--estimator``: a built-in name, a checkpoint, or a user estimator loaded now."""
    if text in BUILTIN_ESTIMATORS or _is_checkpoint(text):
        return text
    if ":" not in text:
        raise argparse.ArgumentTypeError(
            f"unknown estimator {text!r}; give one of {', '.join(BUILTIN_ESTIMATORS)}, a "
            "learned estimator's checkpoint (NAME.pt or a handsim train run folder) or "
            "module:Class[:kwargs-json]"
        )
    try:
        return parse_estimator_spec(text)
    except HandSimError as err:  # argparse names the option itself
        raise argparse.ArgumentTypeError(str(err).removeprefix("--estimator: ")) from None


def _factory(args: argparse.Namespace) -> tuple[Any, dict[str, Any]]:
    """A function that builds a fresh estimator, and how the report names it."""
    if isinstance(args.estimator, EstimatorSpec):
        spec = args.estimator
        return spec.make, {"name": spec.name, "spec": spec.text, "kwargs": spec.kwargs}
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

        return make_estimator, {"name": "oracle"}
    if args.estimator == "com":
        from handsim.estimators import CenterOfMassLocalizer

        return CenterOfMassLocalizer, {"name": "com"}
    from handsim.estimators import DeepPriorEstimator

    checkpoint = args.estimator
    DeepPriorEstimator(checkpoint)  # fail now, with the reason, not inside the loop
    return lambda: DeepPriorEstimator(checkpoint), {"name": "learned", "checkpoint": checkpoint}


def _run(args: argparse.Namespace) -> int:
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)
    from handsim.envs.closed_loop import evaluate_closed_loop, write_report

    if args.video:
        import importlib.util

        if not all(importlib.util.find_spec(m) for m in ("imageio", "imageio_ffmpeg")):
            raise HandSimError(
                "--video needs imageio and imageio-ffmpeg; install them with "
                "pip install 'handsim[video]'"
            )
    make_estimator, naming = _factory(args)
    env_kwargs = {"obs_mode": "depth", "sensor": args.sensor, "camera": args.camera}
    if args.objects:
        env_kwargs["objects"] = args.objects
    max_steps = gym.spec(args.env).max_episode_steps or 0
    total = 2 * args.episodes * max_steps
    with progress_bar(total, "closed loop", "step", enabled=not args.quiet) as bar:
        report = evaluate_closed_loop(
            args.env,
            make_estimator,
            episodes=args.episodes,
            seed=args.seed,
            env_kwargs=env_kwargs,
            progress=bar.update,
            media_dir=args.out,
            video=args.video,
        )
    report["estimator"] = {**naming, **report["estimator"]}
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
    print(strict_json(summary))
    written = [str(p) for p in paths.values()]
    for mode in report["modes"].values():
        if mode["media"]["worst_frame"] is not None:
            written.append(mode["media"]["worst_frame"]["path"])
        written += [v["path"] for v in mode["media"]["videos"]]
    print("written: " + ", ".join(written))
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``handsim closed-loop`` to the program's subcommands."""
    from handsim.envs import ENV_IDS
    from handsim.envs.config import SENSORS
    from handsim.world.camera import CAMERA_PRESETS
    from handsim.world.registry import OBJECT_NAMES

    loop = sub.add_parser(
        "closed-loop",
        help="run an expert with an estimator in the loop, feedback off and on; write a report",
        description="Run N episodes of an env with its scripted expert and a pose estimator in "
        "every step, once acting on the truth and once on the estimate; write closed_loop.json "
        "(strict JSON), plots (f_tau, success, error_over_time, error_by_occlusion, "
        "success_by_object), the worst frame of each mode and, with --video, MP4s of the depth "
        "with the estimated and the true skeleton.",
    )
    loop.add_argument(
        "--env",
        default="handsim/Grasp-v0",
        choices=ENV_IDS,
        metavar="ID",
        help=choice_help("env id", ENV_IDS, "%(default)s"),
    )
    loop.add_argument(
        "--estimator",
        type=estimator_arg,
        default="oracle",
        metavar="NAME|MODULE:CLASS[:KWARGS]",
        help=choice_help("estimator", ESTIMATORS, "%(default)s")
        + ", a learned estimator's checkpoint (NAME.pt or a handsim train run folder), or a "
        "user estimator module:Class[:kwargs-json] (a module path or a .py file; the kwargs a "
        "JSON object), checked against handsim.estimator.Estimator",
    )
    loop.add_argument(
        "--noise-mm",
        type=number(0, MAX_NOISE_MM),
        default=10.0,
        help="oracle noise per axis, mm (default: %(default)s)",
    )
    loop.add_argument(
        "--object-noise-mm",
        type=number(0, MAX_NOISE_MM),
        default=None,
        help="oracle object translation noise per axis, mm (default: --noise-mm)",
    )
    loop.add_argument(
        "--object-noise-deg",
        type=number(0, 180),
        default=0.0,
        help="oracle object rotation noise, deg (default: %(default)s)",
    )
    loop.add_argument(
        "--dropout",
        type=probability,
        default=0.0,
        help="oracle dropout probability in [0, 1] (default: %(default)s)",
    )
    loop.add_argument(
        "--latency-steps",
        type=non_negative_int,
        default=0,
        help="oracle latency, steps (default: %(default)s)",
    )
    loop.add_argument(
        "--episodes", type=positive_int, default=5, help="episodes per mode (default: %(default)s)"
    )
    loop.add_argument("--seed", type=seed, default=0, help="first seed (default: %(default)s)")
    loop.add_argument(
        "--objects",
        nargs="+",
        type=object_name,
        metavar="NAME",
        help=choice_help(
            "objects the episodes draw from (default: the env's); names also without their "
            "number, e.g. mustard_bottle",
            OBJECT_NAMES,
        ),
    )
    loop.add_argument(
        "--sensor",
        default="structured_light",
        choices=SENSORS,
        metavar="NAME",
        help=choice_help("depth sensor model", SENSORS, "%(default)s"),
    )
    loop.add_argument(
        "--camera",
        default="icvl",
        choices=tuple(CAMERA_PRESETS),
        metavar="PRESET",
        help=choice_help("camera preset", tuple(CAMERA_PRESETS), "%(default)s"),
    )
    loop.add_argument(
        "--video",
        action="store_true",
        help="also write one MP4 per mode and episode under OUT/video/ (needs handsim[video])",
    )
    loop.add_argument(
        "--out", default="handsim-closed-loop", help="output folder (default: %(default)s)"
    )
    add_quiet(loop)
    loop.set_defaults(func=_run)
