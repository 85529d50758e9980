"""The skin's coarse level of detail: the depth error it adds and the draw time it saves.

Frames as the ``hand-only`` preset draws them (kinematic source: poses, views, hand sizes and
sides, camera distances 0.35 to 0.7 m), with the ICVL camera's field of view at each image size
(``--sizes``, its ``K`` scaled). Every frame's state is rendered twice, with the full skin and
with the coarse one (``FrameRenderer.skin_detail``), and compared on the clean depth:

- hand pixels: pixels that either render labels as the hand (palm to little finger); the
  fraction of them whose depths agree within 1 mm (a pixel that only one render sees as hand
  disagrees), and the mean and 95th percentile of the depth difference over the pixels both
  see as hand, millimetres;
- labels: keypoint pixels (from the kinematics: must be identical), per-keypoint visibility and
  occluder (decided on the render: the fraction of keypoints whose flags agree);
- what ``skin_detail="auto"`` chooses (fraction of frames drawn coarse);
- the draw and read-back (``DepthRenderer.render``) of each level, process CPU time, the two
  levels interleaved frame by frame: their ratio.

Usage: ``python benchmarks/bench_skin_lod.py [--frames 200] [--sizes 160x120,320x240,640x480]``;
writes ``benchmarks/results/bench_skin_lod.json``. The load average is printed with the
figures: on a shared machine compare the ratios, each measured in one run.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def _measure(width: int, height: int, frames: int) -> dict:
    from handsim.data.config import PRESETS, GenerationConfig
    from handsim.data.generation import _Acceptor
    from handsim.data.kinematic import KinematicSource, near_range_m
    from handsim.frame import FrameRenderer
    from handsim.world.camera import camera_preset
    from handsim.world.scene import OBJECT_LABEL_OFFSET, SEGMENT_LABELS

    config = GenerationConfig.from_mapping(
        PRESETS["hand-only"],
        frames=frames,
        frames_per_shard=frames,
        sensor="none",
        skin_detail="auto",  # the scenes carry the coarse skin
    )
    source = KinematicSource(config)
    # The same views at another image size: the ICVL camera's K scaled.
    source.intrinsics = camera_preset(config.camera).scaled(width, height)
    source._near_m = near_range_m(source.intrinsics, source.sensor)
    palm = SEGMENT_LABELS.index("palm")
    rows: dict[str, list] = {k: [] for k in ("agree", "both_err_mm", "vis", "occ", "kp")}
    cpu = {"full": 0.0, "coarse": 0.0}
    auto_coarse = 0
    render = FrameRenderer.render

    def measured(self: FrameRenderer, rng: np.random.Generator, **kw: object):
        nonlocal auto_coarse
        self.skin_detail = "auto"
        T = self._camera_pose(self.scene.data)  # noqa: N806
        auto_coarse += self._coarse_wanted(self.scene.data, T[:3, :3], T[:3, 3])
        out = {}
        for detail in ("full", "coarse"):
            self.skin_detail = detail
            out[detail] = render(self, np.random.default_rng(0), keep_clean=True)
        # The draw alone, each level, interleaved (the state is the same).
        data, depth_out = self.scene.data, np.empty_like(self._depth_buffer)
        labels_out = np.empty(depth_out.shape, dtype=np.int16)
        for detail in ("full", "coarse", "full", "coarse"):
            coarse = detail == "coarse"
            if coarse:
                self._swap_skin(True)
            start = time.process_time()
            self.renderer.render(
                data, out=(depth_out, labels_out), geom_values=self._geom_labels, fill=0
            )
            cpu[detail] += time.process_time() - start
            if coarse:
                self._swap_skin(False)
        full, lod = out["full"], out["coarse"]
        hand_f = (full.segmentation >= palm) & (full.segmentation < OBJECT_LABEL_OFFSET)
        hand_c = (lod.segmentation >= palm) & (lod.segmentation < OBJECT_LABEL_OFFSET)
        either, both = hand_f | hand_c, hand_f & hand_c
        diff_mm = np.abs(full.depth_clean - lod.depth_clean) * 1000.0
        rows["agree"].append((int(np.count_nonzero(both & (diff_mm <= 1.0))), int(either.sum())))
        rows["both_err_mm"].append(diff_mm[both])
        rows["vis"].append(np.mean(full.visible == lod.visible))
        rows["occ"].append(np.mean(full.occluder == lod.occluder))
        rows["kp"].append(np.array_equal(full.keypoints_px, lod.keypoints_px, equal_nan=True))
        self.skin_detail = "full"
        return render(self, rng, **kw)

    FrameRenderer.render = measured  # type: ignore[method-assign]
    try:
        rng = np.random.default_rng([0, width])
        accept = _Acceptor(config, frames)
        made = 0
        while made < frames:
            try:
                for _ in source.episode(rng, accept, min(config.frames_per_episode, frames - made)):
                    made += 1
            except Exception as err:  # noqa: BLE001 (a redrawn episode, as generation does)
                if type(err).__name__ != "CannotDraw":
                    raise
    finally:
        FrameRenderer.render = render  # type: ignore[method-assign]
        source.close()
    agree = np.array(rows["agree"])
    err = np.concatenate(rows["both_err_mm"])
    n = len(rows["vis"])
    return {
        "size": f"{width}x{height}",
        "renders": n,
        "hand_px_within_1mm": float(agree[:, 0].sum() / max(agree[:, 1].sum(), 1)),
        "hand_px_per_frame": float(agree[:, 1].mean()),
        "depth_diff_mm_mean": float(err.mean()),
        "depth_diff_mm_p95": float(np.percentile(err, 95)),
        "depth_diff_mm_max": float(err.max()),
        "keypoint_px_identical": bool(all(rows["kp"])),
        "visible_agree": float(np.mean(rows["vis"])),
        "occluder_agree": float(np.mean(rows["occ"])),
        "auto_coarse_fraction": auto_coarse / max(n, 1),
        "draw_cpu_ms_full": 1000.0 * cpu["full"] / (2 * n),
        "draw_cpu_ms_coarse": 1000.0 * cpu["coarse"] / (2 * n),
        "draw_full_over_coarse": cpu["full"] / max(cpu["coarse"], 1e-12),
    }


def main() -> None:
    """Measure every image size and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200, help="frames per image size")
    parser.add_argument("--sizes", default="160x120,320x240,640x480", help="WxH,WxH,...")
    parser.add_argument("--out", default="benchmarks/results/bench_skin_lod.json")
    args = parser.parse_args()
    results = {"load_start": os.getloadavg()[0], "frames": args.frames, "sizes": []}
    for size in args.sizes.split(","):
        width, height = (int(x) for x in size.split("x"))
        row = _measure(width, height, args.frames)
        row["load"] = os.getloadavg()[0]
        results["sizes"].append(row)
        print(
            f"{row['size']:>8}: hand pixels within 1 mm {row['hand_px_within_1mm']:.4f} "
            f"({row['hand_px_per_frame']:.0f} a frame), depth difference mean "
            f"{row['depth_diff_mm_mean']:.3f} / p95 {row['depth_diff_mm_p95']:.3f} mm; keypoint "
            f"pixels identical {row['keypoint_px_identical']}, visibility agrees "
            f"{row['visible_agree']:.4f}, occluder {row['occluder_agree']:.4f}; auto coarse "
            f"{row['auto_coarse_fraction']:.2f}; draw full / coarse "
            f"{row['draw_full_over_coarse']:.2f} ({row['draw_cpu_ms_full']:.2f} / "
            f"{row['draw_cpu_ms_coarse']:.2f} ms CPU); load {row['load']:.1f}"
        )
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
