"""Benchmark: env step rates, vector-env scaling, the closed loop, and memory over 10^4 steps.

Run: ``python benchmarks/bench_envs.py [--steps 300] [--memory-steps 10000] [--out FILE.json]``.

Measured in one run (ICVL camera, 320x240 depth observation, default frame skip 10 = 50 Hz
control, no sensor noise unless stated):

- ``env_steps_per_s``: one env, for each id: HandPose-v0 driven by its gesture expert,
  Grasp-v0 by its grasp expert (tomato soup can), GraspClutter-v0 (4 objects) by random pose
  actions; plus Grasp-v0 with structured-light noise;
- ``async_2_vs_1``: steps/s of ``AsyncVectorEnv`` (spawned workers) with 2 HandPose-v0 envs
  against 1, and the ratio (this machine has 2 cores);
- ``closed_loop``: Grasp-v0 steps/s inside ``EstimatorLoop`` with the oracle (10 mm noise),
  feedback off (estimate measured only) and on (estimate retargeted and handed to the expert);
- ``memory``: resident memory after a warm-up of 1000 steps and after ``--memory-steps``
  more steps of HandPose-v0 with resets every 150 steps (growth in MiB).
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.wrappers import EstimatorLoop
from handsim.estimators import OracleEstimator


def _expert_rate(env: gym.Env, steps: int, seed: int = 0) -> float:
    """Steps per second with the env's expert, resetting at episode ends."""
    # EstimatorLoop builds the expert's state (truth or estimate); a plain env gives the truth.
    source = env if isinstance(env, EstimatorLoop) else env.unwrapped
    env.reset(seed=seed)
    expert = source.make_expert(np.random.default_rng(seed))
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(expert.act(source.expert_state()).vector)
        if terminated or truncated:
            seed += 1
            env.reset(seed=seed)
            expert = source.make_expert(np.random.default_rng(seed))
    return steps / (time.perf_counter() - start)


def _random_rate(env: gym.Env, steps: int) -> float:
    env.reset(seed=0)
    env.action_space.seed(0)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def _vector_rate(n: int, steps: int) -> float:
    fns = [lambda: gym.make("handsim.envs:handsim/HandPose-v0") for _ in range(n)]
    envs = gym.vector.AsyncVectorEnv(fns, context="spawn")
    envs.reset(seed=list(range(n)))
    envs.action_space.seed(0)
    envs.step(envs.action_space.sample())  # warm-up (first render)
    start = time.perf_counter()
    for _ in range(steps):
        envs.step(envs.action_space.sample())
    elapsed = time.perf_counter() - start
    envs.close()
    return n * steps / elapsed


def _rss_mib() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _memory(steps: int) -> dict:
    env = gym.make("handsim/HandPose-v0")
    env.reset(seed=0)
    env.action_space.seed(0)

    def run(n: int) -> None:
        for _ in range(n):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()

    run(1000)
    before = _rss_mib()
    run(steps)
    after = _rss_mib()
    env.close()
    return {"steps": steps, "rss_after_warmup_mib": before, "rss_after_mib": after,
            "growth_mib": after - before}  # fmt: skip


def main() -> None:
    """Run every measurement, print it, write JSON."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--memory-steps", type=int, default=10_000)
    parser.add_argument("--out", default="benchmarks/results/bench_envs.json")
    args = parser.parse_args()
    results: dict = {"env_steps_per_s": {}}
    rates = results["env_steps_per_s"]
    rates["HandPose-v0 (gesture expert)"] = _expert_rate(
        gym.make("handsim/HandPose-v0"), args.steps
    )
    grasp = {"objects": "005_tomato_soup_can"}
    rates["Grasp-v0 (grasp expert)"] = _expert_rate(
        gym.make("handsim/Grasp-v0", **grasp), args.steps
    )
    rates["Grasp-v0 (grasp expert, structured light)"] = _expert_rate(
        gym.make("handsim/Grasp-v0", sensor="structured_light", **grasp), args.steps
    )
    rates["GraspClutter-v0 (4 objects, random actions)"] = _random_rate(
        gym.make("handsim/GraspClutter-v0", num_objects=4), args.steps
    )
    one, two = _vector_rate(1, args.steps), _vector_rate(2, args.steps)
    results["async_2_vs_1"] = {"1_worker": one, "2_workers": two, "ratio": two / one}
    results["closed_loop"] = {}
    for feedback in (False, True):
        env = EstimatorLoop(
            gym.make("handsim/Grasp-v0", **grasp),
            OracleEstimator(noise_mm=10.0, object_noise_mm=10.0, rng=0),
            feedback=feedback,
        )
        key = "feedback_on" if feedback else "feedback_off"
        results["closed_loop"][key] = _expert_rate(env, args.steps)
    results["memory"] = _memory(args.memory_steps)
    print(json.dumps(results, indent=2))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(f"written: {out}")


if __name__ == "__main__":
    main()
