"""Rollouts seen through the held object: hand occlusion, contact and cost of a preset.

Generates ``--frames`` frames of a rollout preset (1 worker, in this process) and prints, from
the shards: the hand occlusion ratio (median, quartiles; of the frames with and without a
hand-object contact), the fraction of frames with a contact, the manifest's occlusion
histogram; and the cost: wall-clock frames/s, frames per CPU-second of this process (all its
threads, OpenGL's included: on a shared machine the wall-clock rate says how many free cores
there were), the views rendered (those the occlusion control refused included) and the kept
steps left without a frame (``through_object`` episodes).

Usage: ``python benchmarks/bench_rollout_occlusion.py [--preset grasp-rollouts-occluded]
[--frames 240] [--seed 0] [--set '{"objects": ["037_scissors"]}'] [--views-per-step 8]``;
``--set`` overrides config fields (JSON), ``--views-per-step`` the source's
``VIEWS_PER_STEP``. Writes ``benchmarks/results/bench_rollout_occlusion.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def main() -> None:
    """Run the benchmark (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="grasp-rollouts-occluded")
    parser.add_argument("--frames", type=int, default=240)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--set", default="{}", help="config fields to override, as JSON")
    parser.add_argument("--views-per-step", type=int, default=None)
    args = parser.parse_args()

    import handsim.envs.rollouts as rollouts
    from handsim.data.generation import PRESETS, GenerationConfig, generate
    from handsim.data.shards import ShardReader

    if args.views_per_step is not None:
        rollouts.VIEWS_PER_STEP = args.views_per_step
    counters = {"views_rendered": 0, "steps_without_view": 0}
    close = rollouts.RolloutSource.close

    def counting_close(source: rollouts.RolloutSource) -> None:
        counters["views_rendered"] += source.views_rendered
        counters["steps_without_view"] += source.steps_without_view
        close(source)

    rollouts.RolloutSource.close = counting_close
    config = GenerationConfig.from_mapping(
        {**PRESETS[args.preset], **json.loads(args.set)}, frames=args.frames, seed=args.seed
    )
    with tempfile.TemporaryDirectory() as tmp:
        wall, cpu = time.perf_counter(), time.process_time()
        manifest = generate(config, tmp, workers=1)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        ratio, contact = [], []
        for record in manifest.shards.values():
            reader = ShardReader(Path(tmp) / record.name)
            ratio.append(reader.labels("hand_occlusion_ratio"))
            contact.append(reader.labels("contact_count") > 0)
            reader.close()
    ratio, contact = np.concatenate(ratio), np.concatenate(contact)

    def median(values: np.ndarray) -> float | None:
        return round(float(np.median(values)), 3) if values.size else None

    result = {
        "preset": args.preset,
        "overrides": json.loads(args.set),
        "frames": int(ratio.size),
        "seed": args.seed,
        "views_per_step": rollouts.VIEWS_PER_STEP,
        "occlusion_median": median(ratio),
        "occlusion_quartiles": [round(float(q), 3) for q in np.percentile(ratio, [25, 75])],
        "occlusion_median_in_contact": median(ratio[contact]),
        "occlusion_median_without_contact": median(ratio[~contact]),
        "frames_without_contact": int((~contact).sum()),
        "contact_rate": round(float(contact.mean()), 3),
        "histogram": manifest.occlusion_histogram,
        "frames_per_s": round(ratio.size / wall, 2),
        "frames_per_cpu_s": round(ratio.size / cpu, 2),
        "load_average": os.getloadavg(),
        **counters,
    }
    print(json.dumps(result, indent=1))
    out = Path(__file__).parent / "results" / "bench_rollout_occlusion.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
