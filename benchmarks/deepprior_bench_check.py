"""A DeepPrior++ checkpoint on handsim-bench sets: error, palm width, and its two controls.

    python benchmarks/deepprior_bench_check.py BENCH --checkpoint RUN/dpp/best.pt \
        --localizer RUN/localizer/best.pt [--detector plane|learned|CKPT] \
        [--refine-iterations 3] \
        [--sets hand_third_person hand_object] --out check.json

For every set and every mode it prints the mean and median 3D keypoint error (mm, over the
frames where a hand was found) and the palm width (index MCP to little MCP, mm), predicted
against true, per side (and, over both sides, its ratio per quartile of the frames' error, in
the JSON); for ``pipeline`` also the crop centre's distance from the true middle
MCP (mean, median, share over 50 mm: the localization's failures). Modes (one network, one
change each):

- ``pipeline``: the estimator as shipped (localizer, canonical side from the checkpoint);
- ``unmirrored``: the same with ``canonical_side=False`` (left hands given as they come);
- ``true_centre``: the crop at the true middle MCP instead of the localizer's centre.

Checkpoints default to the shipped weights (``deepprior++``, ``localizer``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from handsim.cli.benchmark_sets import valid_frames
from handsim.estimators.deepprior.estimator import DeepPriorEstimator
from handsim.estimators.deepprior.preprocess import (
    mirror_depth,
    mirror_intrinsics,
    mirror_points,
)

INDEX_MCP, MIDDLE_MCP, LITTLE_MCP = 5, 9, 17
MODES = ("pipeline", "unmirrored", "true_centre")


def _palm_width_mm(keypoints_m: np.ndarray) -> float:
    return float(np.linalg.norm(keypoints_m[INDEX_MCP] - keypoints_m[LITTLE_MCP]) * 1000.0)


def _predict(est: DeepPriorEstimator, mode: str, arrays: dict) -> np.ndarray | None:
    depth = np.asarray(arrays["depth"], np.float32)
    K = np.asarray(arrays["K"], np.float64)  # noqa: N806
    left = bool(arrays["is_left"])
    est.reset()
    est.set_side(left)
    if mode != "true_centre":
        estimate = est.predict(depth, K)
        return estimate.keypoints_cam if estimate.valid else None
    gt = np.asarray(arrays["keypoints_cam"], np.float64)
    centre = gt[MIDDLE_MCP]
    if est.canonical_side and left:  # crop the mirrored frame at the mirrored centre
        width = depth.shape[1]
        kp = est.predict_at(mirror_depth(depth), mirror_intrinsics(K, width), mirror_points(centre))
        return mirror_points(kp)
    return est.predict_at(depth, K, centre)


def _centre_error_mm(est: DeepPriorEstimator, arrays: dict) -> float:
    """Distance of the pipeline's last crop centre from the true middle MCP, mm."""
    centre = est._tracked
    if est.canonical_side and bool(arrays["is_left"]):
        centre = mirror_points(centre)
    gt = np.asarray(arrays["keypoints_cam"], np.float64)[MIDDLE_MCP]
    return float(np.linalg.norm(centre - gt) * 1000.0)


def _summary(err: list[float], pw_pred: list[float], pw_true: list[float], n: int) -> dict:
    err_a = np.asarray(err)
    pred, true = np.asarray(pw_pred), np.asarray(pw_true)
    return {
        "frames": n,
        "found": len(err_a),
        "mean_error_mm": float(err_a.mean()) if len(err_a) else None,
        "median_error_mm": float(np.median(err_a)) if len(err_a) else None,
        "palm_width_pred_mm": float(pred.mean()) if len(pred) else None,
        "palm_width_true_mm": float(true.mean()) if len(true) else None,
        # Per frame, then averaged: a folded palm shows here even when the means agree.
        "palm_width_abs_rel_error": float(np.mean(np.abs(pred - true) / true))
        if len(pred)
        else None,
        "palm_width_ratio_by_error_quartile": _by_quartile(err_a, pred / true)
        if len(pred) >= 4
        else None,
    }


def _by_quartile(err: np.ndarray, ratio: np.ndarray) -> list[float]:
    """Mean predicted / true palm width of the frames in each quartile of the error, best first.

    Where a loss on the joints is met by averaging the poses the network doubts between, the
    palm narrows most on the frames it gets worst.
    """
    edges = np.quantile(err, [0.25, 0.5, 0.75])
    bins = np.digitize(err, edges)
    return [float(ratio[bins == b].mean()) for b in range(4)]


def main() -> None:
    """Print the table; ``--out`` writes it as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bench", type=Path)
    parser.add_argument("--checkpoint", default="deepprior++")
    parser.add_argument("--localizer", default="localizer")
    parser.add_argument(
        "--detector", default="learned", help="learned (as shipped), plane, com or a CKPT"
    )
    parser.add_argument(
        "--refine-iterations", type=int, default=None, help="default: as the checkpoint trained"
    )
    parser.add_argument("--sets", nargs="+", default=None, help="default: every set")
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    parser.add_argument("--max-frames", type=int, default=0, help="per set (0: all)")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()

    sets = args.sets or sorted(json.loads((args.bench / "benchmark.json").read_text())["sets"])
    common = {
        "localizer": args.localizer,
        "detector": args.detector,
        "refine_iterations": args.refine_iterations,
        "threads": 1,
    }
    ests = {
        "pipeline": DeepPriorEstimator(args.checkpoint, **common),
        "unmirrored": DeepPriorEstimator(args.checkpoint, canonical_side=False, **common),
    }
    ests["true_centre"] = ests["pipeline"]
    result: dict = {
        "checkpoint": args.checkpoint,
        "localizer": args.localizer,
        "detector": args.detector,
        "refine_iterations": ests["pipeline"].localizer.iterations,
        "sets": {},
    }
    print(
        f"{'set':20s} {'mode':12s} {'side':5s} {'n':>4s} {'mean':>6s} {'median':>6s} "
        f"{'palm pred/true mm':>18s} {'|rel|':>6s}"
    )
    for name in sets:
        frames = list(valid_frames(args.bench / name))
        if args.max_frames:
            frames = frames[: args.max_frames]
        result["sets"][name] = {}
        for mode in args.modes:
            rows: dict[str, list] = {s: [[], [], [], [0]] for s in ("all", "left", "right")}
            centre_mm = []
            for arrays in frames:
                gt = np.asarray(arrays["keypoints_cam"], np.float64)
                side = "left" if bool(arrays["is_left"]) else "right"
                kp = _predict(ests[mode], mode, arrays)
                if mode == "pipeline" and kp is not None:
                    centre_mm.append(_centre_error_mm(ests[mode], arrays))
                for key in ("all", side):
                    rows[key][3][0] += 1
                    if kp is None:
                        continue
                    rows[key][0].append(float(np.mean(np.linalg.norm(kp - gt, axis=1)) * 1000.0))
                    rows[key][1].append(_palm_width_mm(kp))
                    rows[key][2].append(_palm_width_mm(gt))
            out = {s: _summary(r[0], r[1], r[2], r[3][0]) for s, r in rows.items()}
            result["sets"][name][mode] = out
            if centre_mm:
                c = np.asarray(centre_mm)
                out["all"]["centre_error_mm"] = {
                    "mean": float(c.mean()),
                    "median": float(np.median(c)),
                    "over_50mm": float((c > 50).mean()),
                }
                print(
                    f"{name:20s} centre: mean {c.mean():.1f} median {np.median(c):.1f} mm, "
                    f"{(c > 50).mean():.1%} over 50 mm"
                )
            for s, o in out.items():
                if o["mean_error_mm"] is None:
                    continue
                print(
                    f"{name:20s} {mode:12s} {s:5s} {o['found']:4d} {o['mean_error_mm']:6.1f} "
                    f"{o['median_error_mm']:6.1f} {o['palm_width_pred_mm']:8.1f} / "
                    f"{o['palm_width_true_mm']:7.1f} {o['palm_width_abs_rel_error']:6.2f}",
                    flush=True,
                )
    if args.out:
        args.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
