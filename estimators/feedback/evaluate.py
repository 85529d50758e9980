"""The feedback estimator's error after each iteration: on a dataset split, or on handsim-bench.

:func:`iteration_errors` runs :class:`~.estimator.FeedbackEstimator` (the whole pipeline: plane
removal, refined localizer, DeepPrior++, k updates) on every frame of a split, with each
frame's side, and reports the mean and median joint error after 0 (DeepPrior++ alone), 1, ...,
k updates, and the time per frame. :func:`bench_iteration_errors` does the same on the sets of
a handsim-bench folder, per set and per occlusion bucket (the buckets of ``handsim benchmark
run``'s report); iteration 0 is DeepPrior++ alone on the same frames.

As a command (the figures of docs/feedback.md)::

    python -m handsim.estimators.feedback.evaluate --updater RUN/best.pt --bench BENCH --out J
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from handsim.errors import HandSimError

from ..deepprior.data import load_frames
from ..deepprior.preprocess import MIDDLE_MCP

__all__ = ["bench_iteration_errors", "iteration_errors", "main"]


def _errors(
    estimator: Any, frames: Any, iterations: int | None, true_center: bool = False
) -> tuple[np.ndarray, np.ndarray, float]:
    """Per-frame mean joint errors (mm) after each iteration (NaN rows: no hand blob).

    ``true_center``: crop at the true middle MCP instead of the localizer's centre (a control
    that takes the localizer's error out).
    """
    k = estimator.iterations if iterations is None else int(iterations)
    rows = np.full((len(frames), k + 1), np.nan)
    elapsed = 0.0
    for i in range(len(frames)):
        depth, K = frames.depth(i), frames.K[i]  # noqa: N806
        estimator.set_side(bool(frames.is_left[i]))
        t0 = time.perf_counter()
        center = frames.keypoints_cam[i, MIDDLE_MCP] if true_center else None
        poses = estimator.predict_iterations(depth, K, center, iterations=k)
        elapsed += time.perf_counter() - t0
        if poses is None:
            continue
        truth = frames.keypoints_cam[i]
        rows[i] = [float(np.linalg.norm(p - truth, axis=1).mean()) * 1000 for p in poses]
    found = np.isfinite(rows[:, 0])
    return rows, found, elapsed


def _summary(rows: np.ndarray) -> dict[str, Any]:
    found = np.isfinite(rows[:, 0]) if len(rows) else np.zeros(0, bool)
    e = rows[found]
    return {
        "frames": int(len(rows)),
        "missed": int((~found).sum()),
        "mean_error_mm": e.mean(axis=0).tolist() if len(e) else [],
        "median_error_mm": np.median(e, axis=0).tolist() if len(e) else [],
    }


def iteration_errors(
    estimator: Any,
    data: str | os.PathLike[str] | list[str | os.PathLike[str]],
    *,
    split: str = "test",
    max_frames: int | None = None,
    iterations: int | None = None,
) -> dict[str, Any]:
    """Joint errors (mm) after each iteration of ``estimator`` on a split of ``data``.

    Args:
        estimator: a :class:`~.estimator.FeedbackEstimator`.
        data: dataset folders.
        split: ``train``, ``val``, ``test`` or ``all``.
        max_frames: at most this many frames.
        iterations: updates (default: the estimator's).

    Returns:
        ``mean_error_mm`` and ``median_error_mm``: lists indexed by iteration (0 = the
        predictor), over the frames with a hand blob; ``frames``, ``missed`` (no hand blob),
        ``seconds_per_frame`` (the whole pipeline).
    """
    frames = load_frames(data, split, max_frames=max_frames)
    rows, _, elapsed = _errors(estimator, frames, iterations)
    return {**_summary(rows), "seconds_per_frame": elapsed / max(len(frames), 1)}


def bench_iteration_errors(
    estimator: Any,
    bench: str | os.PathLike[str],
    *,
    sets: list[str] | None = None,
    iterations: int | None = None,
    max_frames: int | None = None,
    true_center: bool = False,
) -> dict[str, Any]:
    """:func:`iteration_errors` on the sets of a handsim-bench folder, per set and occlusion.

    Args:
        estimator: a :class:`~.estimator.FeedbackEstimator`.
        bench: a ``handsim benchmark make`` folder.
        sets: the sets (default: all of the folder's).
        iterations: updates (default: the estimator's).
        max_frames: at most this many frames per set.
        true_center: crop at the true middle MCP, not at the localizer's centre (a control).

    Returns:
        ``sets`` (name -> summary), ``by_occlusion`` (the summaries of the occlusion buckets of
        all frames), ``all``, ``iterations`` and ``seconds_per_frame``.

    Raises:
        HandSimError: for a folder that is not a benchmark or an unknown set.
    """
    from handsim.cli.benchmark import OCCLUSION_EDGES, _read_benchmark

    bench = Path(bench)
    listed = _read_benchmark(bench)["sets"]
    names = list(listed) if sets is None else sets
    unknown = [n for n in names if n not in listed]
    if unknown:
        raise HandSimError(
            f"--bench {bench} has no set {', '.join(unknown)}; its sets: {', '.join(listed)}"
        )
    per_set, all_rows, all_occ, elapsed = {}, [], [], 0.0
    for name in names:
        frames = load_frames(bench / str(listed[name]["folder"]), max_frames=max_frames)
        rows, _, seconds = _errors(estimator, frames, iterations, true_center)
        per_set[name] = _summary(rows)
        all_rows.append(rows)
        all_occ.append(frames.occlusion)
        elapsed += seconds
    rows, occ = np.concatenate(all_rows), np.concatenate(all_occ)
    by_occ = []
    for lo, hi in zip(OCCLUSION_EDGES[:-1], OCCLUSION_EDGES[1:], strict=True):
        last = hi == OCCLUSION_EDGES[-1]
        m = (occ >= lo) & ((occ <= hi) if last else (occ < hi))
        by_occ.append({"occlusion": [lo, hi], **_summary(rows[m])})
    return {
        "iterations": int(rows.shape[1] - 1),
        "sets": per_set,
        "by_occlusion": by_occ,
        "all": _summary(rows),
        "seconds_per_frame": elapsed / max(len(rows), 1),
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m handsim.estimators.feedback.evaluate``: :func:`bench_iteration_errors`."""
    parser = argparse.ArgumentParser(
        prog="python -m handsim.estimators.feedback.evaluate",
        description="The feedback estimator's error after each update on handsim-bench, per "
        "set and occlusion bucket (update 0: DeepPrior++ alone on the same frames).",
    )
    parser.add_argument("--updater", default="feedback", help="updater checkpoint or run folder")
    parser.add_argument(
        "--predictor", default="deepprior++", help="the pose network (default: deepprior++)"
    )
    parser.add_argument("--bench", required=True, help="a `handsim benchmark make` folder")
    parser.add_argument("--out", required=True, help="JSON file to write")
    parser.add_argument("--iterations", type=int, default=None, help="updates (default: 3)")
    parser.add_argument("--sets", nargs="+", default=None, help="sets (default: all)")
    parser.add_argument("--max-frames", type=int, default=None, help="frames per set (all)")
    parser.add_argument("--synthesizer", choices=("renderer", "learned"), default="renderer")
    parser.add_argument("--synthesizer-checkpoint", default=None)
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default: 1)")
    parser.add_argument(
        "--detector",
        default="learned",
        help="the first centre: learned (default), plane, com or a detector checkpoint",
    )
    parser.add_argument(
        "--true-center",
        action="store_true",
        help="crop at the true middle MCP instead of the localizer's centre (a control)",
    )
    args = parser.parse_args(argv)
    import torch

    from .estimator import FeedbackEstimator

    torch.set_num_threads(args.threads)
    try:
        est = FeedbackEstimator(
            args.updater,
            predictor=args.predictor,
            synthesizer=args.synthesizer,
            synthesizer_checkpoint=args.synthesizer_checkpoint,
            detector=args.detector,
        )
        iterations = 3 if args.iterations is None else args.iterations
        report = bench_iteration_errors(
            est, args.bench, sets=args.sets, iterations=iterations, max_frames=args.max_frames,
            true_center=args.true_center,
        )  # fmt: skip
    except HandSimError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    report["estimator"] = {**est.info(), "true_center": args.true_center}
    est.close()
    Path(args.out).write_text(json.dumps(report, indent=2) + "\n")
    for name, s in {**report["sets"], "all": report["all"]}.items():
        errs = " -> ".join(f"{e:.1f}" for e in s["mean_error_mm"])
        print(f"{name:18s} {s['frames'] - s['missed']:5d} frames  mean mm by update: {errs}")
    print(f"{1.0 / max(report['seconds_per_frame'], 1e-9):.1f} frames/s; written: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
