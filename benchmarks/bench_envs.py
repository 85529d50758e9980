"""Benchmark: env step rates, vector-env scaling, the closed loop, and memory over 10^4 steps.

Run: ``python benchmarks/bench_envs.py [--steps 300] [--memory-steps 10000] [--repeats 2]
[--only {all,vector,obs_modes,rgb_array}] [--out FILE.json]``.

Measured in one run (ICVL camera, 320x240 depth observation, default frame skip 10 = 50 Hz
control, no sensor noise unless stated):

- ``env_steps_per_s``: one env, for each id: HandPose-v0 driven by its gesture expert,
  Grasp-v0 by its grasp expert (tomato soup can), GraspClutter-v0 (4 objects) by random pose
  actions; plus Grasp-v0 with structured-light noise;
- ``async_2_vs_1``: steps/s of ``AsyncVectorEnv`` (spawned workers) with 2 HandPose-v0 envs
  against 1, and the ratio (this machine has 2 cores);
- ``make_vec_fork_2_vs_1``: the same through ``gym.make_vec(..., vectorization_mode="async")``
  with default arguments (forked workers) after this process has rendered; best of
  ``--repeats`` interleaved runs each;
- ``obs_modes``: Grasp-v0 steps/s with the same random pose actions in ``"state"`` (nothing
  rendered), ``"privileged_state"``, ``"depth"`` and ``"depth"`` with ``labels=False``, and
  the ratio state / depth (best of ``--repeats`` interleaved runs);
- ``rgb_array``: renders/s of ``render()`` alone at 320 x 240 (viewer camera, shadows on) and
  steps/s of step + render in ``rgb_array`` and ``depth_array`` modes, against the depth
  step rate;
- ``closed_loop``: Grasp-v0 steps/s inside ``EstimatorLoop`` with the oracle (10 mm noise),
  feedback off (estimate measured only) and on (estimate retargeted and handed to the expert);
- ``memory``: resident memory after a warm-up of 1000 steps and after ``--memory-steps``
  more steps of HandPose-v0 with resets every 150 steps (growth in MiB).
"""

from __future__ import annotations

import argparse
import json
import os
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


def _make_vec_rate(n: int, steps: int) -> float:
    """Steps/s of ``gym.make_vec`` with default arguments (fork on Linux)."""
    envs = gym.make_vec("handsim/HandPose-v0", num_envs=n, vectorization_mode="async")
    envs.reset(seed=list(range(n)))
    envs.action_space.seed(0)
    envs.step(envs.action_space.sample())
    start = time.perf_counter()
    for _ in range(steps):
        envs.step(envs.action_space.sample())
    elapsed = time.perf_counter() - start
    envs.close()
    return n * steps / elapsed


def _fixed_actions_rate(env: gym.Env, steps: int, render: bool = False) -> float:
    """Steps/s (with ``render()`` after each step when asked) on seeded random actions."""
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    env.step(actions[0])
    if render:
        env.render()
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if render:
            env.render()
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def _best_of(repeats: int, runs: dict) -> dict:
    """Best rate of each run over ``repeats`` interleaved rounds (less sensitive to load)."""
    best = {name: 0.0 for name in runs}
    for _ in range(repeats):
        for name, run in runs.items():
            best[name] = max(best[name], run())
    return best


def _obs_modes(steps: int, repeats: int) -> dict:
    grasp = {"objects": "005_tomato_soup_can"}
    envs = {
        "state": gym.make("handsim/Grasp-v0", obs_mode="state", **grasp),
        "privileged_state": gym.make("handsim/Grasp-v0", obs_mode="privileged_state", **grasp),
        "depth": gym.make("handsim/Grasp-v0", **grasp),
        "depth (labels=False)": gym.make("handsim/Grasp-v0", labels=False, **grasp),
    }
    rates = _best_of(
        repeats, {name: (lambda e=env: _fixed_actions_rate(e, steps)) for name, env in envs.items()}
    )
    for env in envs.values():
        env.close()
    rates["ratio_state_vs_depth"] = rates["state"] / rates["depth"]
    return rates


def _rgb_array(steps: int, repeats: int) -> dict:
    grasp = {"objects": "005_tomato_soup_can", "render_width": 320, "render_height": 240}
    rgb = gym.make("handsim/Grasp-v0", render_mode="rgb_array", **grasp)
    depth_view = gym.make("handsim/Grasp-v0", render_mode="depth_array", **grasp)
    depth = gym.make("handsim/Grasp-v0", **grasp)
    rgb.reset(seed=0)
    rgb.render()

    def renders() -> float:
        start = time.perf_counter()
        for _ in range(steps):
            rgb.render()
        return steps / (time.perf_counter() - start)

    rates = _best_of(
        repeats,
        {
            "render_only_per_s": renders,
            "rgb_array_steps_per_s": lambda: _fixed_actions_rate(rgb, steps, render=True),
            "depth_array_steps_per_s": lambda: _fixed_actions_rate(depth_view, steps, True),
            "depth_obs_steps_per_s": lambda: _fixed_actions_rate(depth, steps),
        },
    )
    for env in (rgb, depth_view, depth):
        env.close()
    rates["ratio_rgb_array_vs_depth"] = (
        rates["rgb_array_steps_per_s"] / rates["depth_obs_steps_per_s"]
    )
    return rates


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
    parser.add_argument(
        "--out", default=None, help="default: benchmarks/results/bench_envs[_ONLY].json"
    )
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument(
        "--only",
        choices=["all", "vector", "obs_modes", "rgb_array"],
        default="all",
        help="run one group of measurements",
    )
    args = parser.parse_args()
    if args.out is None:
        suffix = "" if args.only == "all" else f"_{args.only}"
        args.out = f"benchmarks/results/bench_envs{suffix}.json"
    results: dict = {"cpu_count": os.cpu_count(), "load_avg_1min_start": os.getloadavg()[0]}
    if args.only != "all":
        runs = {
            "vector": lambda: {"make_vec_fork_2_vs_1": _make_vec_2_vs_1(args)},
            "obs_modes": lambda: {"obs_modes": _obs_modes(args.steps, args.repeats)},
            "rgb_array": lambda: {"rgb_array": _rgb_array(args.steps, args.repeats)},
        }
        results.update(runs[args.only]())
        _write(results, args.out)
        return
    results["env_steps_per_s"] = {}
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
    results["make_vec_fork_2_vs_1"] = _make_vec_2_vs_1(args)
    results["obs_modes"] = _obs_modes(args.steps, args.repeats)
    results["rgb_array"] = _rgb_array(args.steps, args.repeats)
    results["memory"] = _memory(args.memory_steps)
    _write(results, args.out)


def _make_vec_2_vs_1(args: argparse.Namespace) -> dict:
    # Render in this process first: forked workers must not inherit a hanging GL state.
    parent = gym.make("handsim/HandPose-v0")
    parent.reset(seed=0)
    parent.step(parent.action_space.sample())
    best = _best_of(
        args.repeats,
        {
            "1_worker": lambda: _make_vec_rate(1, args.steps),
            "2_workers": lambda: _make_vec_rate(2, args.steps),
        },
    )
    parent.close()
    return {**best, "ratio": best["2_workers"] / best["1_worker"]}


def _write(results: dict, path: str) -> None:
    results["load_avg_1min_end"] = os.getloadavg()[0]
    print(json.dumps(results, indent=2))
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(f"written: {out}")


if __name__ == "__main__":
    main()
