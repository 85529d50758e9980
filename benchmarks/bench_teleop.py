"""Benchmark: the teleop loop's steps per second on one core, per mode, with the time per stage.

Run: ``python benchmarks/bench_teleop.py [--steps 300] [--repeats 2] [--out FILE.json]``.

The process is pinned to one CPU core (``os.sched_setaffinity``; Mesa's software rasterizer
runs without worker threads, ``LP_NUM_THREADS=0``). For each task (Grasp-v0 and Press-v0,
their scripted experts' streams of seed 0, replayed with the operator holding still after the
stream ends) it measures, best of ``--repeats`` interleaved runs of ``--steps`` steps:

- ``physics_only``: ``env.step`` with the stream's poses as actions (no tracking): the limit;
- ``direct``: the loop in direct mode with 5 mm noise and the One Euro filter (faults, filter,
  retargeting, physics);
- ``camera_oracle``: camera mode, 320 x 240 ICVL capture of the operator hand, no sensor noise,
  the oracle estimator;
- ``camera_oracle_structured_light``: the same with the structured-light sensor model.

Each entry has ``steps_per_s``, ``ratio_to_physics`` and ``stage_ms`` (mean per step: capture,
estimator, faults, filter, retarget, physics). The goal is >= 90 steps/s (a headset's rate)
with the oracle and in direct mode. Results go to ``benchmarks/results/bench_teleop.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.teleop import FaultConfig, TeleopConfig, TeleopLoop, stream_from_expert
from handsim.estimators import OracleEstimator

TASKS = {"handsim/Grasp-v0": {}, "handsim/Press-v0": {"task": "button"}}
MODES = {
    "direct": (TeleopConfig(faults=FaultConfig(noise_mm=5.0), filter="one_euro"), False),
    "camera_oracle": (TeleopConfig(mode="camera"), True),
    "camera_oracle_structured_light": (
        TeleopConfig(mode="camera", sensor="structured_light"),
        True,
    ),
}


def _physics_rate(env_id: str, kwargs: dict, actions: np.ndarray, steps: int) -> float:
    env = gym.make(env_id, obs_mode="state", **kwargs)
    env.reset(seed=0)
    start = time.perf_counter()
    for i in range(steps):
        _, _, terminated, truncated, _ = env.step(actions[min(i + 1, len(actions) - 1)])
        if truncated:
            env.reset(seed=0)
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def main() -> None:
    """Run the benchmark and write its JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", default="benchmarks/results/bench_teleop.json")
    args = parser.parse_args()
    core = sorted(os.sched_getaffinity(0))[0]
    os.sched_setaffinity(0, {core})
    results: dict = {
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "pinned_core": core,
            "load_average": os.getloadavg(),
        },
        "steps": args.steps,
        "tasks": {},
    }
    for env_id, kwargs in TASKS.items():
        stream = stream_from_expert(env_id, 0, env_kwargs=kwargs)
        entry: dict = {"stream_frames": len(stream)}
        best: dict = {}
        for _ in range(args.repeats):
            rate = _physics_rate(env_id, kwargs, stream.poses, args.steps)
            best["physics_only"] = max(
                best.get("physics_only", {"steps_per_s": 0}),
                {"steps_per_s": rate},
                key=lambda d: d["steps_per_s"],
            )
            for name, (config, camera) in MODES.items():
                estimator = OracleEstimator(rng=0) if camera else None
                with TeleopLoop(env_id, config, estimator=estimator, env_kwargs=kwargs) as loop:
                    loop.run(stream, 0, max_steps=5)  # warm-up: scene, renderer, GL context
                    m = loop.run(stream, 0, max_steps=args.steps, stop_at_success=False).metrics
                run = {
                    "steps_per_s": m["steps_per_s"],
                    "stage_ms": m["stage_ms"],
                    "success": m["success"],
                }
                if run["steps_per_s"] > best.get(name, {"steps_per_s": 0})["steps_per_s"]:
                    best[name] = run
        physics = best["physics_only"]["steps_per_s"]
        for run in best.values():
            run["ratio_to_physics"] = run["steps_per_s"] / physics
        entry.update(best)
        results["tasks"][env_id] = entry
        print(f"{env_id} ({args.steps} steps, one core {core}, best of {args.repeats}):")
        for name, run in best.items():
            stages = ", ".join(f"{k} {v:.2f}" for k, v in run.get("stage_ms", {}).items())
            goal = (
                ""
                if name == "physics_only"
                else ("  >= 90 Hz" if run["steps_per_s"] >= 90 else "  < 90 Hz goal")
            )
            print(
                f"  {name:32s} {run['steps_per_s']:7.1f} steps/s  "
                f"x{run['ratio_to_physics']:.2f} of physics{goal}"
            )
            if stages:
                print(f"  {'':32s} ms/step: {stages}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(f"results: {out}")


if __name__ == "__main__":
    main()
