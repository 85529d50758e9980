"""The feedback estimator's error after each iteration on a dataset split.

:func:`iteration_errors` runs :class:`~.estimator.FeedbackEstimator` (the whole pipeline: plane
removal, refined localizer, DeepPrior++, k updates) on every frame of a split, with each
frame's side, and reports the mean and median joint error after 0 (DeepPrior++ alone), 1, ...,
k updates, and the time per frame.
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from ..deepprior.data import load_frames
from .train import frame_sides

__all__ = ["iteration_errors"]


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
        predictor); ``frames``, ``missed`` (no hand blob), ``seconds_per_frame``.
    """
    frames = load_frames(data, split, max_frames=max_frames)
    sides = frame_sides(data, split, max_frames=max_frames)
    per_frame, missed, elapsed = [], 0, 0.0
    for i in range(len(frames)):
        depth, K = frames.depth(i), frames.K[i]  # noqa: N806
        estimator.set_side(bool(sides[i]))
        t0 = time.perf_counter()
        center = estimator.first.localizer.localize(depth, K)
        if center is None:
            missed += 1
            continue
        poses = estimator.predict_iterations(depth, K, center, iterations)
        elapsed += time.perf_counter() - t0
        truth = frames.keypoints_cam[i]
        per_frame.append([float(np.linalg.norm(p - truth, axis=1).mean()) * 1000 for p in poses])
    e = np.asarray(per_frame)
    return {
        "frames": len(frames),
        "missed": missed,
        "mean_error_mm": e.mean(axis=0).tolist() if len(e) else [],
        "median_error_mm": np.median(e, axis=0).tolist() if len(e) else [],
        "seconds_per_frame": elapsed / max(len(e), 1),
    }
