"""Evaluation of a learned estimator on a dataset split (``handsim evaluate``).

:func:`evaluate` runs the whole inference pipeline (the detector's first centre, refined
localizer, crop, network) on every frame of the split and writes ``metrics.json`` with
``mean_error_mm`` (mean keypoint error over all joints of the frames with an estimate) at its
top level, the :func:`~handsim.metrics.evaluate_hand_poses` report (F(tau), PCK, AUCs, per
joint), errors per occlusion bucket and per sensor, the localization error of every stage
(centre of mass, plane-removed centre of mass, the pipeline's detector, refined, each against
the true middle-finger MCP), the pose
error when the crop is centred by each of them and by the truth, and the inference time; and
the plots ``f_tau.png``, ``pck.png``, ``error_by_occlusion.png``, ``error_by_joint.png``.

A checkpoint that works in the canonical right-hand frame gets the left hands' frames mirrored
(as its estimator does); errors are distances, the same in either frame. The report has the
errors per side too.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from handsim import metrics
from handsim.hand.keypoints import KEYPOINT_NAMES

from .data import FrameSet, load_frames, side_frame
from .preprocess import MIDDLE_MCP, PlaneRemovedLocalizer

__all__ = ["OCCLUSION_EDGES", "evaluate"]

OCCLUSION_EDGES = (0.0, 0.1, 0.3, 0.5, 0.7, 1.0)
"""Occlusion buckets of the report (hand occlusion ratio)."""


def _stats(errors_mm: np.ndarray) -> dict[str, Any]:
    e = errors_mm[np.isfinite(errors_mm)]
    return {
        "n": int(e.size),
        "n_missed": int(errors_mm.size - e.size),
        "mean_mm": float(e.mean()) if e.size else None,
        "median_mm": float(np.median(e)) if e.size else None,
    }


def evaluate(
    estimator: str | os.PathLike[str],
    data: Sequence[str | os.PathLike[str]] | FrameSet,
    out: str | os.PathLike[str],
    *,
    split: str = "test",
    localizer: str | None = "localizer",
    detector: str = "learned",
    max_frames: int = 0,
    progress: bool = True,
    threads: int = 0,
    with_centres: bool = True,
    device: str = "cpu",
    canonical_side: bool | None = None,
) -> dict[str, Any]:
    """Evaluate a pose checkpoint (or shipped name) on a split; write the report and plots.

    Args:
        estimator: ``"deepprior++"``, ``"deepprior"`` or a checkpoint path / run folder.
        data: dataset folders, or frames in memory (e.g. :func:`~.data.env_frames`).
        out: output folder.
        split: ``train``, ``val``, ``test`` or ``all``.
        localizer: localizer checkpoint, or ``None`` for the detector's centre alone.
        detector: the pipeline's first centre (``RefinedLocalizer``'s ``detector``).
        max_frames: evaluate at most this many frames (0: all).
        progress: show a progress bar.
        threads: torch CPU threads (0: torch's default).
        with_centres: also run the network on crops centred by the plain centre of mass, the
            plane-removed one and the true middle MCP (``mean_error_mm_by_crop_centre``).
        device: torch device of the networks.
        canonical_side: mirror left hands into the right-hand frame (``None``: the
            checkpoint's flag; ``False`` runs a canonical network on left hands as they are,
            for the side study).

    Returns:
        The report (also ``out/metrics.json``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from tqdm import tqdm

    from handsim.estimators import CenterOfMassLocalizer

    from .estimator import DeepPriorEstimator

    est = DeepPriorEstimator(
        estimator,
        localizer=localizer,
        detector=detector,
        threads=threads or None,
        device=device,
        canonical_side=canonical_side,
    )
    if isinstance(data, FrameSet):
        frames = data
        data_names = ["(frames in memory)"]
    else:
        frames = load_frames(data, split, max_frames=max_frames or None)
        data_names = [str(d) for d in data]
    # The pipeline below runs on the frames as stored: put them in the network's frame.
    frames = side_frame(frames, est.canonical_side)
    n = len(frames)
    pred = np.full((n, 21, 3), np.nan)
    loc_err = {
        "com": np.full(n, np.nan),
        "plane_removed_com": np.full(n, np.nan),
        "detector": np.full(n, np.nan),  # the pipeline's first centre
        "refined": np.full(n, np.nan),
    }
    # The pose error when the crop is centred by each localizer (and by the truth).
    centres = ("com", "plane_removed_com", "detector", "ground_truth")
    pose_at = {k: np.full(n, np.nan) for k in centres}
    com, plane, first = CenterOfMassLocalizer(), PlaneRemovedLocalizer(), est.localizer.base
    times = []
    for i in tqdm(range(n), desc="evaluate", disable=not progress):
        depth, K = frames.depth(i), frames.K[i]  # noqa: N806
        mcp = frames.keypoints_cam[i, MIDDLE_MCP]
        gt_i = frames.keypoints_cam[i]
        c0 = com.localize(depth, K.astype(np.float64))
        if c0 is not None:
            loc_err["com"][i] = np.linalg.norm(c0 - mcp) * 1000.0
            if with_centres:
                pose_at["com"][i] = _mean_mm(est.predict_at(depth, K, c0), gt_i)
        if with_centres:
            pose_at["ground_truth"][i] = _mean_mm(est.predict_at(depth, K, mcp), gt_i)
        cp = plane.localize(depth, K)
        if cp is not None:
            loc_err["plane_removed_com"][i] = np.linalg.norm(cp - mcp) * 1000.0
            if with_centres:
                pose_at["plane_removed_com"][i] = _mean_mm(est.predict_at(depth, K, cp), gt_i)
        t0 = time.perf_counter()
        c1 = first.localize(depth, K)
        if c1 is None:
            times.append(time.perf_counter() - t0)
            continue
        c2 = est.localizer.refine(depth, K, c1)
        pred[i] = est.predict_at(depth, K, c2)
        times.append(time.perf_counter() - t0)
        loc_err["detector"][i] = np.linalg.norm(c1 - mcp) * 1000.0
        if with_centres:
            pose_at["detector"][i] = _mean_mm(est.predict_at(depth, K, c1), gt_i)
        loc_err["refined"][i] = np.linalg.norm(c2 - mcp) * 1000.0
    found = np.all(np.isfinite(pred), axis=(1, 2))
    gt = frames.keypoints_cam
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    safe = np.where(found[:, None, None], pred, gt)  # misses are masked below
    visible = np.repeat(found[:, None], 21, axis=1)
    report = metrics.evaluate_hand_poses(safe, gt, visible=visible)
    frame_mean = np.where(found, metrics.frame_mean_error_mm(safe, gt), np.nan)
    occ = frames.occlusion
    known = np.isfinite(occ)
    by_occ = []
    if known.any():
        for b in metrics.errors_by_occlusion(frame_mean[known], occ[known], OCCLUSION_EDGES):
            by_occ.append(b.to_dict())
    by_sensor = {str(s): _stats(frame_mean[frames.sensor == s]) for s in np.unique(frames.sensor)}
    by_side = {
        side: _stats(frame_mean[frames.is_left == left])
        for side, left in (("right", False), ("left", True))
    }
    result: dict[str, Any] = {
        "estimator": repr(est),
        "data": data_names,
        "split": split,
        "n_frames": n,
        "n_missed": int((~found).sum()),
        "mean_error_mm": report.mean_mm,
        "median_error_mm": report.median_mm,
        "mean_max_error_mm": report.mean_max_mm,
        "auc_f_tau": report.auc_f_tau,
        "auc_pck": report.auc_pck,
        "per_joint_mean_mm": report.per_joint_mean_mm,
        "by_occlusion": by_occ,
        "occlusion_unknown_frames": int((~known).sum()),
        "by_sensor": by_sensor,
        "by_side": by_side,
        "canonical_side": est.canonical_side,
        "localization_mm": {k: _stats(v) for k, v in loc_err.items()},
        "mean_error_mm_by_crop_centre": (
            {
                **{k: _stats(v)["mean_mm"] for k, v in pose_at.items()},
                "refined": report.mean_mm,
            }
            if with_centres
            else None
        ),
        "inference_ms_mean": float(np.mean(times) * 1000.0) if times else None,
        "torch_threads": _threads(),
        "report": report.to_dict(),
    }
    (out / "metrics.json").write_text(json.dumps(metrics_json(result), indent=2) + "\n")
    name = Path(str(estimator)).name
    metrics.plot_f_tau({name: report}, out / "f_tau.png")
    metrics.plot_pck({name: report}, out / "pck.png")
    fig, ax = plt.subplots(figsize=(6, 3.5))
    labels = [f"{b['lower']:.1f}-{b['upper']:.1f}\n(n={b['n_frames']})" for b in by_occ]
    ax.bar(range(len(by_occ)), [b["mean"] or 0.0 for b in by_occ], color="tab:red")
    ax.set_xticks(range(len(by_occ)), labels, fontsize=8)
    ax.set(xlabel="hand occlusion ratio", ylabel="mean keypoint error / mm", title=name)
    fig.tight_layout()
    fig.savefig(out / "error_by_occlusion.png", dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(8, 3.5))
    per_joint = [report.per_joint_mean_mm[k] or 0.0 for k in KEYPOINT_NAMES]
    ax.bar(range(21), per_joint, color="tab:blue")
    ax.set_xticks(range(21), KEYPOINT_NAMES, rotation=90, fontsize=7)
    ax.set(ylabel="mean error / mm", title=name)
    fig.tight_layout()
    fig.savefig(out / "error_by_joint.png", dpi=100)
    plt.close(fig)
    return result


def _mean_mm(pred_m: np.ndarray, gt_m: np.ndarray) -> float:
    return float(np.linalg.norm(pred_m - gt_m, axis=-1).mean() * 1000.0)


def _threads() -> int:
    import torch

    return int(torch.get_num_threads())


def metrics_json(value: Any) -> Any:
    """``value`` with non-finite floats as ``None`` (strict JSON)."""
    if isinstance(value, dict):
        return {k: metrics_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [metrics_json(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value
