"""Where the pipeline's crop centre lands: the first centre and each refinement step, per set.

    python benchmarks/detector_check.py BENCH --detectors plane learned [--localizer CKPT] \
        [--sets hand_object occlusion] --out centres.json

For every handsim-bench set and detector it prints the distance of the detector's centre, of
each of the localizer's refinement steps, and of the guarded result (the pipeline's crop
centre) from the true middle-finger MCP: mean / median mm and the share over 50 mm (the crop
then holds little of the hand). Left hands are mirrored into the right-hand frame, as the
pipeline does.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from handsim.cli.benchmark_sets import valid_frames
from handsim.estimators.deepprior.estimator import RefinedLocalizer
from handsim.estimators.deepprior.preprocess import (
    MIDDLE_MCP,
    mirror_depth,
    mirror_intrinsics,
    mirror_points,
)


def _distances_mm(loc: RefinedLocalizer, frames: list[dict]) -> np.ndarray:
    """(N, iterations + 2) distances: first centre, each step, the guarded centre."""
    rows = []
    for arrays in frames:
        depth = np.asarray(arrays["depth"], np.float32)
        K = np.asarray(arrays["K"], np.float64)  # noqa: N806
        mcp = np.asarray(arrays["keypoints_cam"], np.float64)[MIDDLE_MCP]
        if bool(arrays["is_left"]):
            width = depth.shape[1]
            depth, K, mcp = mirror_depth(depth), mirror_intrinsics(K, width), mirror_points(mcp)  # noqa: N806
        first = loc.base.localize(depth, K)
        if first is None:
            continue
        centres, _, lost = loc.path(depth, K, first)
        final = centres[0] if (lost and loc.guard) else centres[-1]
        rows.append([*np.linalg.norm(centres - mcp, axis=1), np.linalg.norm(final - mcp)])
    return np.asarray(rows) * 1000.0


def main() -> None:
    """Print the table; ``--out`` writes it as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bench", type=Path)
    parser.add_argument("--detectors", nargs="+", default=["plane", "learned"])
    parser.add_argument("--localizer", default="localizer")
    parser.add_argument("--sets", nargs="+", default=None, help="default: every set")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()

    sets = args.sets or sorted(json.loads((args.bench / "benchmark.json").read_text())["sets"])
    result: dict = {"localizer": args.localizer, "detectors": {}}
    for detector in args.detectors:
        loc = RefinedLocalizer(args.localizer, detector=detector)
        stages = ["detector", *(f"step {i + 1}" for i in range(loc.iterations)), "guarded"]
        result["detectors"][detector] = {}
        for name in sets:
            d = _distances_mm(loc, list(valid_frames(args.bench / name)))
            table = {
                stage: {
                    "mean_mm": float(d[:, k].mean()),
                    "median_mm": float(np.median(d[:, k])),
                    "over_50mm": float((d[:, k] > 50).mean()),
                }
                for k, stage in enumerate(stages)
            }
            result["detectors"][detector][name] = {"frames": len(d), **table}
            cells = "  ".join(
                f"{stage} {t['mean_mm']:.1f}/{t['median_mm']:.1f}/{t['over_50mm']:.0%}"
                for stage, t in table.items()
            )
            print(f"{detector:8s} {name:18s} n={len(d):3d}  {cells}", flush=True)
    if args.out:
        args.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
