"""``handsim train`` and ``handsim evaluate``: the learned estimators (DeepPrior, DeepPrior++).

- ``handsim train deepprior|deepprior++|localizer --data DIR [DIR ...] --out RUN``: train (or
  resume: the same command again continues a killed run) and write ``RUN/metrics.json``.
- ``handsim train detector --data DIR [DIR ...] --out RUN``: the whole-image hand detector
  (:mod:`handsim.estimators.deepprior.detector`), with the same run rules.
- ``handsim train synthesizer|updater --data DIR [DIR ...] --out RUN``: the feedback loop's
  networks (:mod:`handsim.estimators.feedback.train`), with the same run rules.
- ``handsim evaluate --estimator CKPT|deepprior|deepprior++ --data DIR --out OUT``: the whole
  pipeline on a split; ``OUT/metrics.json`` (``mean_error_mm`` at its top level) and plots.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from handsim.cli._args import (
    add_quiet,
    choice_help,
    integer,
    non_negative_int,
    number,
    output_folder,
    positive_int,
    seed,
    strict_json,
)
from handsim.errors import HandSimError

__all__ = ["add_parser"]

# Crop side: the networks halve it five times; 512 is four times DeepPrior's 128.
_crop_side = integer(32, 512, "a multiple of 32; the networks halve the crop five times")


def _crop_size(value: str) -> int:
    size = _crop_side(value)
    if size % 32:
        raise argparse.ArgumentTypeError(
            f"expected an integer in [32, 512] that is a multiple of 32; received {value!r}"
        )
    return size


def _check_device(device: str) -> None:
    import torch

    if device == "cuda" and not torch.cuda.is_available():
        raise HandSimError("--device cuda: no CUDA device is available to torch; use cpu")


_FEEDBACK_KINDS = ("synthesizer", "updater")
# Options of the feedback networks only (None: not given), refused for the others.
_FEEDBACK_OPTIONS = {
    "--synthesizer": "synthesizer",
    "--synthesizer-checkpoint": "synthesizer_checkpoint",
    "--predictor": "predictor",
    "--lam": "lam",
    "--filters": "filters",
    "--perturb-sigma-mm": "perturb_sigma_mm",
    "--perturbations": "perturbations",
    "--iterations": "iterations",
    "--max-val-frames": "max_val_frames",
    "--no-truth-starts": "no_truth_starts",
}


def _train_feedback(args: argparse.Namespace) -> int:
    from handsim.estimators.feedback.train import (
        FeedbackTrainConfig,
        train_synthesizer,
        train_updater,
    )

    checks = [
        ("--init", args.init),
        ("--detector", args.detector),
        ("--refine-iterations", args.refine_iterations),
        ("--bone-loss", args.bone_loss),
    ]
    if args.kind == "synthesizer":
        checks.append(("--localizer", args.localizer))
    for option, value in checks:
        if value is not None:
            args.parser.error(f"argument {option}: not allowed with {args.kind} (DeepPrior only)")
    defaults = FeedbackTrainConfig()

    def given(name: str, default):  # noqa: ANN001, ANN202
        value = getattr(args, name)
        return default if value is None else value

    predictor = given("predictor", defaults.predictor)
    localizer = given("localizer", defaults.localizer)
    config = FeedbackTrainConfig(
        kind=args.kind,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        weight_decay=args.weight_decay,
        cube_m=args.cube_mm / 1000.0,
        size=args.size or 128,
        fc=args.fc or 1024,
        filters=given("filters", defaults.filters),
        lam=given("lam", defaults.lam),
        synthesizer=given("synthesizer", defaults.synthesizer),
        synthesizer_checkpoint=args.synthesizer_checkpoint,
        predictor=None if predictor == "none" else predictor,
        perturb_sigma_m=given("perturb_sigma_mm", 1000 * defaults.perturb_sigma_m) / 1000.0,
        perturbations=given("perturbations", defaults.perturbations),
        iterations=given("iterations", defaults.iterations),
        offset_sigma_m=given("offset_sigma_mm", 5.0) / 1000.0,
        localizer=None if localizer == "none" else localizer,
        max_frames=args.max_frames,
        max_val_frames=given("max_val_frames", defaults.max_val_frames),
        truth_starts=not args.no_truth_starts,
        seed=args.seed,
    )
    _check_device(args.device)
    log = lambda line: print(line, file=sys.stderr, flush=True)  # noqa: E731
    if args.kind == "synthesizer":
        metrics = train_synthesizer(args.data, args.out, config, progress=not args.quiet, log=log)
        keys = ("kind", "epochs_done", "best_val_mean_px_error_mm", "train_time_s")
    else:
        metrics = train_updater(
            args.data, args.out, config, device=args.device, progress=not args.quiet, log=log
        )
        keys = ("kind", "epochs_done", "best_val_mean_error_mm", "val_error_mm_per_iteration",
                "train_time_s")  # fmt: skip
    summary = {k: metrics[k] for k in (*keys, "train_frames", "val_frames")}
    print(strict_json({**summary, "out": str(args.out)}))
    return 0


# Options of the pose networks that the detector does not take (None or 0: not given).
_NOT_DETECTOR = {
    "--size": "size",
    "--fc": "fc",
    "--offset-sigma-mm": "offset_sigma_mm",
    "--localizer": "localizer",
    "--init": "init",
    "--detector": "detector",
    "--refine-iterations": "refine_iterations",
    "--bone-loss": "bone_loss",
}


def _train_detector(args: argparse.Namespace) -> int:
    from handsim.estimators.deepprior.detector import DetectorTrainConfig, train_detector

    for option, name in _NOT_DETECTOR.items():
        if getattr(args, name) or (name == "refine_iterations" and args.refine_iterations == 0):
            args.parser.error(f"argument {option}: not allowed with detector")
    config = DetectorTrainConfig(
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        weight_decay=args.weight_decay,
        max_frames=args.max_frames,
        seed=args.seed,
        canonical_side=not args.no_canonical_side,
    )
    _check_device(args.device)
    metrics = train_detector(
        args.data,
        args.out,
        config,
        device=args.device,
        progress=not args.quiet,
        log=lambda line: print(line, file=sys.stderr, flush=True),
    )
    keys = ("kind", "epochs_done", "best_val_mean_error_mm", "train_time_s")
    summary = {k: metrics[k] for k in (*keys, "train_frames", "val_frames")}
    print(strict_json({**summary, "out": str(args.out)}))
    return 0


def _train(args: argparse.Namespace) -> int:
    import torch

    from handsim.estimators.deepprior.train import TrainConfig, train

    if args.threads:
        torch.set_num_threads(args.threads)
    if args.kind in _FEEDBACK_KINDS:
        return _train_feedback(args)
    for option, name in _FEEDBACK_OPTIONS.items():
        if getattr(args, name) is not None:
            args.parser.error(
                f"argument {option}: not allowed with {args.kind} (synthesizer and updater only)"
            )
    if args.kind == "detector":
        return _train_detector(args)
    if args.refine_iterations is not None and (args.kind == "localizer" or not args.localizer):
        args.parser.error(
            "argument --refine-iterations: needs --localizer, with a pose network (without one "
            "the crops are at the true middle MCP)"
        )
    if args.bone_loss is not None and args.kind == "localizer":
        args.parser.error("argument --bone-loss: not allowed with localizer (pose networks only)")
    size = args.size if args.size else (64 if args.kind == "localizer" else 128)
    fc = args.fc if args.fc else (256 if args.kind == "localizer" else 1024)
    offset = (
        args.offset_sigma_mm
        if args.offset_sigma_mm is not None
        else (20.0 if args.kind == "localizer" else 5.0)
    )
    config = TrainConfig(
        kind=args.kind,
        arch=args.arch,
        prior_dim=args.prior_dim,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        weight_decay=args.weight_decay,
        bone_loss=args.bone_loss or 0.0,
        cube_m=args.cube_mm / 1000.0,
        size=size,
        fc=fc,
        width=args.width,
        rotation="rotation" in args.augment,
        scale="scale" in args.augment,
        translation="translation" in args.augment,
        offset_sigma_m=offset / 1000.0,
        localizer=args.localizer,
        detector=args.detector or "plane",
        refine_iterations=3 if args.refine_iterations is None else args.refine_iterations,
        init=args.init,
        max_frames=args.max_frames,
        seed=args.seed,
        canonical_side=not args.no_canonical_side,
    )
    _check_device(args.device)
    metrics = train(
        args.data,
        args.out,
        config,
        device=args.device,
        loader_workers=args.loader_workers,
        amp=args.amp,
        val_every=args.val_every,
        progress=not args.quiet,
        log=lambda line: print(line, file=sys.stderr, flush=True),
    )
    summary = {
        k: metrics[k]
        for k in (
            "kind",
            "epochs_done",
            "best_val_mean_error_mm",
            "train_time_s",
            "train_frames",
            "val_frames",
        )
    }
    print(strict_json({**summary, "out": str(args.out)}))
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from handsim.estimators.deepprior.evaluate import evaluate

    # An option of the other frame source would be silently ignored: refuse it.
    env_options = {"--env-episodes": args.env_episodes, "--every": args.every, "--seed": args.seed}
    if args.env is not None and args.split is not None:
        args.parser.error("argument --split: not allowed with argument --env (it splits --data)")
    if args.data is not None:
        for option, value in env_options.items():
            if value is not None:
                args.parser.error(
                    f"argument {option}: not allowed with argument --data (it applies to --env)"
                )
    _check_device(args.device)
    data = args.data
    if args.env is not None:
        from handsim.estimators.deepprior.data import env_frames

        data = env_frames(
            args.env,
            episodes=3 if args.env_episodes is None else args.env_episodes,
            every=5 if args.every is None else args.every,
            seed=0 if args.seed is None else args.seed,
        )
    report = evaluate(
        args.estimator,
        data,
        args.out,
        split="test" if args.split is None else args.split,
        localizer=None if args.localizer == "none" else args.localizer,
        detector=args.detector,
        max_frames=args.max_frames,
        progress=not args.quiet,
        threads=args.threads,
        device=args.device,
        canonical_side=False if args.no_canonical_side else None,
    )
    keys = ("estimator", "n_frames", "n_missed", "mean_error_mm", "auc_f_tau", "localization_mm")
    report = {
        **report,
        "localization_mm": {k: v["mean_mm"] for k, v in report["localization_mm"].items()},
    }
    print(strict_json({k: report[k] for k in keys if k in report}))
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``handsim train`` and ``handsim evaluate``."""
    from handsim.envs import ENV_IDS
    from handsim.estimators.deepprior.train import KINDS

    kinds = (*KINDS, "detector", *_FEEDBACK_KINDS)
    tr = sub.add_parser(
        "train",
        help="train DeepPrior, DeepPrior++, the hand localizer and detector or the feedback "
        "loop's networks",
        description="Train a learned estimator on the train split of dataset folders (handsim "
        "generate), validating on their val split. Checkpoints (last.pt, best.pt + JSON "
        "configs) go to --out; the same command again resumes a killed run.",
    )
    tr.add_argument("kind", choices=kinds, help=f"what to train: {', '.join(kinds)}")
    tr.add_argument(
        "--data", nargs="+", required=True, type=Path, metavar="DIR", help="dataset folders"
    )
    tr.add_argument("--out", required=True, type=output_folder, metavar="DIR", help="run folder")
    tr.add_argument("--epochs", type=integer(1, 100_000), default=20, help="epochs (default: 20)")
    tr.add_argument("--batch-size", type=integer(1, 4096), default=64, help="batch (default: 64)")
    tr.add_argument(
        "--lr", type=number(0, 1, lo_open=True), default=1e-3, help="Adam lr (default: 1e-3)"
    )
    tr.add_argument(
        "--weight-decay", type=number(0, 1), default=1e-4, help="Adam weight decay (default: 1e-4)"
    )
    tr.add_argument(
        "--arch",
        choices=("shallow", "deep", "multiscale"),
        default="deep",
        help="DeepPrior network (deepprior only; default: deep)",
    )
    tr.add_argument(
        "--prior-dim",
        type=integer(0, 63, "at most the 63 coordinates of 21 keypoints"),
        default=30,
        help="prior bottleneck dimension, 0 = direct regression (default: 30)",
    )
    tr.add_argument(
        "--cube-mm",
        type=number(0, 1000, lo_open=True),
        default=250.0,
        help="cube edge, mm (default: 250)",
    )
    tr.add_argument(
        "--size",
        type=_crop_size,
        default=0,
        help="crop side, px, a multiple of 32 in [32, 512] (default: 128; localizer 64)",
    )
    tr.add_argument(
        "--fc",
        type=integer(1, 8192),
        default=0,
        help="fully connected units (default: 1024; localizer 256)",
    )
    tr.add_argument(
        "--width",
        type=number(0, 8, lo_open=True),
        default=1.0,
        help="DeepPrior++ conv filter factor (default: 1 = 64/128/256/256)",
    )
    tr.add_argument(
        "--augment",
        nargs="*",
        default=["rotation", "scale", "translation"],
        choices=("rotation", "scale", "translation"),
        metavar="AUG",
        help="online augmentations: rotation scale translation (default: all; "
        "none: give --augment alone)",
    )
    tr.add_argument(
        "--offset-sigma-mm",
        type=number(0, 500),
        default=None,
        help="centre offset sigma, mm (default: 5; localizer 20)",
    )
    tr.add_argument(
        "--localizer",
        default=None,
        metavar="CKPT",
        help="crop pose training frames at this localizer's refined centres "
        "(default: at the true middle MCP; updater: the shipped localizer, none: at the true "
        "middle MCP plus --offset-sigma-mm)",
    )
    tr.add_argument(
        "--detector",
        default=None,
        metavar="NAME|CKPT",
        help="the first centre the --localizer refines (plane, com, learned or a detector "
        "checkpoint; default: plane), as at inference",
    )
    tr.add_argument(
        "--refine-iterations",
        type=integer(0, 10),
        default=None,
        metavar="N",
        help="refinement steps of the --localizer from the detector's centre (default: 3; 0: "
        "the detector's centre as it is); the estimator crops as the network was trained",
    )
    tr.add_argument(
        "--bone-loss",
        type=number(0, 100),
        default=None,
        metavar="W",
        help="weight of a bone-length term beside the joints' loss (pose networks; default: 0): "
        "predicted against true lengths of the 20 bones and the palm's transverse links",
    )
    tr.add_argument(
        "--init",
        default=None,
        metavar="CKPT",
        help="start from this checkpoint's weights (a run folder, a .pt file or a shipped "
        "name: deepprior++, localizer; the same network options), e.g. to fine-tune",
    )
    tr.add_argument(
        "--max-frames",
        type=non_negative_int,
        default=0,
        help="use at most this many training frames (default: all)",
    )
    tr.add_argument(
        "--val-every", type=positive_int, default=1, help="validate every N epochs (default: 1)"
    )
    tr.add_argument("--seed", type=seed, default=0, help="seed (default: 0)")
    tr.add_argument(
        "--no-canonical-side",
        action="store_true",
        help="train on left and right hands as they come (default: left hands are mirrored "
        "into the right-hand frame, in training and at inference)",
    )
    tr.add_argument(
        "--device", choices=("cpu", "cuda"), default="cpu", help="torch device (default: cpu)"
    )
    tr.add_argument(
        "--threads", type=integer(0, 1024), default=0, help="torch CPU threads (default: torch's)"
    )
    tr.add_argument(
        "--loader-workers",
        type=integer(0, 256),
        default=0,
        metavar="N",
        help="processes that crop and augment (default: 0, in the training process; e.g. the "
        "number of free cores when training on a GPU)",
    )
    tr.add_argument(
        "--amp",
        action="store_true",
        help="with --device cuda: bfloat16 mixed precision for the forward pass",
    )
    fb = tr.add_argument_group("feedback loop (synthesizer, updater)")
    fb.add_argument(
        "--synthesizer",
        choices=("renderer", "learned"),
        default=None,
        help="updater: the synthesizer of the starting poses (default: renderer)",
    )
    fb.add_argument(
        "--synthesizer-checkpoint",
        default=None,
        metavar="CKPT",
        help="updater with --synthesizer learned: a `handsim train synthesizer` run folder",
    )
    fb.add_argument(
        "--predictor",
        default=None,
        metavar="CKPT|none",
        help="updater: DeepPrior network whose outputs are starting poses (default: deepprior++; "
        "none: the truth and its perturbations only)",
    )
    fb.add_argument(
        "--lam", type=number(0, 1), default=None, help="updater: the loss's lambda (default: 0.6)"
    )
    fb.add_argument(
        "--filters", type=integer(1, 1024), default=None, help="conv filters (default: 32)"
    )
    fb.add_argument(
        "--perturb-sigma-mm",
        type=number(0, 500),
        default=None,
        help="updater: sigma of the starting poses' perturbations, mm per coordinate (default: 10)",
    )
    fb.add_argument(
        "--perturbations",
        type=integer(0, 100),
        default=None,
        help="updater: perturbed copies of the truth and of the prediction (default: 1)",
    )
    fb.add_argument(
        "--iterations",
        type=integer(1, 20),
        default=None,
        help="updater: updates in validation, the estimator's default (default: 2)",
    )
    fb.add_argument(
        "--no-truth-starts",
        action="store_const",
        const=True,
        default=None,
        help="updater: leave the truth out of the starting poses (its perturbations stay)",
    )
    fb.add_argument(
        "--max-val-frames",
        type=non_negative_int,
        default=None,
        help="updater: validate on at most this many frames (default: 0, all)",
    )
    add_quiet(tr)
    tr.set_defaults(func=_train, parser=tr)

    ev = sub.add_parser(
        "evaluate",
        help="evaluate a learned estimator on a dataset split: metrics.json and plots",
        description="Run a learned estimator (plane removal, refined localizer, crop, network) "
        "on every frame of a split and write metrics.json (mean_error_mm, F(tau), PCK, AUC, "
        "per joint, per occlusion bucket, per sensor, localization errors) and PNG plots.",
    )
    ev.add_argument(
        "--estimator",
        required=True,
        metavar="CKPT|deepprior|deepprior++",
        help="shipped weights by name, a checkpoint NAME.pt or a run folder",
    )
    # Frames come from datasets or from an env, never both: one of the two is required.
    source = ev.add_mutually_exclusive_group(required=True)
    source.add_argument("--data", nargs="+", type=Path, metavar="DIR", help="dataset folders")
    source.add_argument(
        "--env",
        default=None,
        choices=ENV_IDS,
        metavar="ID",
        help=choice_help(
            "instead of --data: frames of this env's scripted expert (e.g. handsim/Grasp-v0: "
            "hand-object frames with the table in view)",
            ENV_IDS,
        ),
    )
    ev.add_argument("--env-episodes", type=positive_int, help="with --env: episodes (default: 3)")
    ev.add_argument(
        "--every", type=positive_int, help="with --env: keep every N-th step (default: 5)"
    )
    ev.add_argument("--seed", type=seed, help="with --env: first seed (default: 0)")
    ev.add_argument("--out", required=True, type=output_folder, metavar="DIR", help="output folder")
    ev.add_argument(
        "--split",
        choices=("train", "val", "test", "all"),
        help="with --data: the split (default: test)",
    )
    ev.add_argument(
        "--localizer",
        default="localizer",
        metavar="CKPT|none",
        help="localizer checkpoint (default: the shipped one; none: the detector's centre alone)",
    )
    ev.add_argument(
        "--detector",
        default="learned",
        metavar="NAME|CKPT",
        help="the first centre: learned (default: the shipped whole-image hand detector), "
        "plane, com or a detector checkpoint",
    )
    ev.add_argument(
        "--max-frames",
        type=non_negative_int,
        default=0,
        help="evaluate at most this many frames (default: all)",
    )
    ev.add_argument(
        "--threads", type=integer(0, 1024), default=0, help="torch CPU threads (default: torch's)"
    )
    ev.add_argument(
        "--device", choices=("cpu", "cuda"), default="cpu", help="torch device (default: cpu)"
    )
    ev.add_argument(
        "--no-canonical-side",
        action="store_true",
        help="give a canonical (right-hand frame) network left hands unmirrored (default: the "
        "checkpoint's canonical_side flag decides)",
    )
    add_quiet(ev)
    ev.set_defaults(func=_evaluate, parser=ev)
