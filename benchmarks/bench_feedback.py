"""The feedback estimator on one CPU core: frames/s per frame and batched, both synthesizers.

Measured in one run, on this machine, with ``torch.set_num_threads(1)`` and
``cv2.setNumThreads(1)``, on the frames of one handsim-bench set (default
``hand_third_person``, the first ``--frames``), the whole pipeline (plane removal, refined
localizer, crop, DeepPrior++, k updates) with the shipped updater:

- per frame: ``FeedbackEstimator.predict`` on each frame in turn;
- batched: ``FeedbackEstimator.predict_batch`` on batches of ``--batch`` frames of one side
  (the frames grouped by side, as the estimator's side is set per batch);

for ``renderer`` (each update retargets and renders crop by crop: on a CPU it does not batch)
and ``learned`` (a network: one call per batch and update), with 0 to ``--iterations``
updates. Speed does not depend on the weights: the learned synthesizer has random weights of
the documented config (filters 16, FC 1024) unless ``--synthesizer-checkpoint`` is given. Each
variant runs once untimed on a few frames first (the renderer builds its scene on first use).
The parts apart: each synthesizer's time per crop and the updater's per frame, at batch 1 and
``--batch``. Every figure is the best of ``--repeats`` runs, the variants interleaved (on a
shared machine the best run is the least disturbed; all runs are in the JSON); the ratios
(batched / per frame) come from this one run; the load average is recorded before and after.

Usage: ``python benchmarks/bench_feedback.py --bench BENCH [--frames 128] [--batch 32]
[--iterations 3] [--repeats 3]``. Writes ``benchmarks/results/bench_feedback.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")


def _random_synthesizer(folder: Path, fc: int, filters: int) -> str:
    """A learned synthesizer of random weights (128 px, 0.25 m) saved under ``folder``."""
    import torch

    from handsim.estimators.deepprior.checkpoint import save_checkpoint
    from handsim.estimators.feedback.models import build_feedback_model

    torch.manual_seed(0)
    model_config = {"arch": "synthesizer", "size": 128, "fc": fc, "filters": filters}
    model = build_feedback_model(model_config)
    path = folder / "synthesizer.pt"
    config = {"model": model_config, "cube_m": 0.25, "kind": "synthesizer"}
    save_checkpoint(path, {"model": model.state_dict()}, config)
    return str(path)


def _per_frame(est, depths, Ks, left) -> float:  # noqa: N803
    """Seconds for ``predict`` on every frame."""
    t0 = time.perf_counter()
    for d, k, s in zip(depths, Ks, left, strict=True):
        est.set_side(bool(s))
        est.predict(d, k)
    return time.perf_counter() - t0


def _batched(est, depths, Ks, left, batch: int) -> float:  # noqa: N803
    """Seconds for ``predict_batch`` on batches of ``batch`` frames of one side."""
    import numpy as np

    t0 = time.perf_counter()
    for side in (False, True):
        idx = np.flatnonzero(left == side)
        est.set_side(side)
        for s in range(0, len(idx), batch):
            i = idx[s : s + batch]
            est.predict_batch(depths[i], Ks[i])
    return time.perf_counter() - t0


def _components(est_r, est_l, depths, Ks, batch: int) -> dict:  # noqa: N803
    """Milliseconds per crop of each synthesizer and per frame of the updater, batch 1 and B.

    On DeepPrior++'s first poses of the frames (right-hand frame, the localizer's centres;
    the renderer's retargeting starts cold, as at the first update).
    """
    import numpy as np
    import torch

    from handsim.estimators.deepprior.preprocess import crop_depth, crop_matrix

    first = est_r.first
    found = [(i, first.localizer.localize(d, Ks[i])) for i, d in enumerate(depths)]
    idx = np.array([i for i, c in found if c is not None])
    centers = np.stack([c for _, c in found if c is not None])
    Ks = Ks[idx]  # noqa: N806
    cube, size = first.cube_m, first.size
    x = np.stack(
        [
            crop_depth(depths[i], crop_matrix(c, k, cube, size), c[2], cube, size)
            for i, c, k in zip(idx, centers, Ks, strict=True)
        ]
    )
    d = torch.from_numpy(x[:, None])
    with torch.inference_mode():
        poses = first.model(d.contiguous(memory_format=torch.channels_last)).float().numpy()
    n = len(idx)
    out = {}
    for b in (1, batch):
        chunks = [slice(s, min(s + b, n)) for s in range(0, n, b)]
        for name, est in (("renderer", est_r), ("learned", est_l)):
            t0 = time.perf_counter()
            for c in chunks:
                est.synth(poses[c], centers[c], Ks[c], np.nan, np.zeros(c.stop - c.start, bool))
            seconds = time.perf_counter() - t0
            out[f"{name} synthesizer ms per crop, batch {b}"] = 1000 * seconds / n
        y = torch.from_numpy(est_l.synth(poses, centers, Ks, np.nan)[0][:, None])
        t0 = time.perf_counter()
        with torch.inference_mode():
            for c in chunks:
                est_r.updater(d[c], y[c])
        out[f"updater ms per frame, batch {b}"] = 1000 * (time.perf_counter() - t0) / n
    return out


def main() -> None:
    """Measure and write ``benchmarks/results/bench_feedback.json``."""
    import cv2
    import numpy as np
    import torch

    from handsim.cli.benchmark import _read_benchmark
    from handsim.estimators import FeedbackEstimator
    from handsim.estimators.deepprior.data import load_frames

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bench", required=True, help="a `handsim benchmark make` folder")
    parser.add_argument("--set", default="hand_third_person", help="the bench set's frames")
    parser.add_argument("--frames", type=int, default=128, help="frames timed")
    parser.add_argument("--batch", type=int, default=32, help="frames per predict_batch call")
    parser.add_argument("--iterations", type=int, default=3, help="most updates timed")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each; the best is kept")
    parser.add_argument("--synthesizer-checkpoint", default=None, help="a trained one")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results/bench_feedback.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    bench = Path(args.bench)
    folder = bench / str(_read_benchmark(bench)["sets"][args.set]["folder"])
    frames = load_frames(folder, max_frames=args.frames)
    depths = np.stack([frames.depth(i) for i in range(len(frames))])
    Ks, left = frames.K, frames.is_left.astype(bool)  # noqa: N806
    results: dict = {
        "bench_set": args.set,
        "frames": len(frames),
        "left_frames": int(left.sum()),
        "batch": args.batch,
        "repeats": args.repeats,
        "torch_threads": torch.get_num_threads(),
        "opencv_threads": cv2.getNumThreads(),
        "cpu_count": os.cpu_count(),
        "load_average_1min_before": os.getloadavg()[0],
        "fps": {},
    }
    fps = results["fps"]
    with tempfile.TemporaryDirectory() as tmp:
        ckpt = args.synthesizer_checkpoint or _random_synthesizer(Path(tmp), 1024, 16)
        results["synthesizer_checkpoint"] = args.synthesizer_checkpoint or "random weights"
        ests = {
            "renderer": FeedbackEstimator(synthesizer="renderer"),
            "learned": FeedbackEstimator(synthesizer="learned", synthesizer_checkpoint=ckpt),
        }
        _components(ests["renderer"], ests["learned"], depths[:4], Ks[:4], 2)  # warm-up
        runs = [
            _components(ests["renderer"], ests["learned"], depths, Ks, args.batch)
            for _ in range(args.repeats)
        ]
        results["components"] = {key: min(r[key] for r in runs) for key in runs[0]}
        results["components_all"] = runs
        for name, value in results["components"].items():
            print(f"{name}: {value:.2f}", flush=True)
        for est in ests.values():  # untimed warm-up of every path
            est.iterations = 1
            _per_frame(est, depths[:4], Ks[:4], left[:4])
            _batched(est, depths[:4], Ks[:4], left[:4], args.batch)
        rates: dict = {}
        for _ in range(args.repeats):  # the variants interleaved, so that load hits all alike
            for synth, est in ests.items():
                for k in range(args.iterations + 1):
                    est.iterations = k
                    r = rates.setdefault(f"{synth} {k} updates", {"per_frame": [], "batched": []})
                    r["per_frame"].append(len(frames) / _per_frame(est, depths, Ks, left))
                    r["batched"].append(len(frames) / _batched(est, depths, Ks, left, args.batch))
        for name, r in rates.items():
            per_frame, batched = max(r["per_frame"]), max(r["batched"])
            fps[name] = {
                "per_frame": per_frame,
                "batched": batched,
                "batched_over_per_frame": batched / per_frame,
                "all_repeats": r,
            }
            print(
                f"{name:18s}: {per_frame:7.1f} frames/s per frame, {batched:7.1f} batched "
                f"({batched / per_frame:.2f}x)",
                flush=True,
            )
        for est in ests.values():
            est.close()
    # An update's cost: the time per frame it adds, from the largest update count.
    k = args.iterations
    results["ms_per_update"] = {
        f"{synth} {mode}": 1000.0
        * (1 / fps[f"{synth} {k} updates"][mode] - 1 / fps[f"{synth} 0 updates"][mode])
        / max(k, 1)
        for synth in ("renderer", "learned")
        for mode in ("per_frame", "batched")
    }
    results["load_average_1min_after"] = os.getloadavg()[0]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results["ms_per_update"], indent=2))
    print(
        f"load average {results['load_average_1min_before']:.2f} before, "
        f"{results['load_average_1min_after']:.2f} after; written: {out}"
    )


if __name__ == "__main__":
    main()
