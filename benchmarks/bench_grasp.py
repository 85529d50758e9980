"""Benchmark of the scripted grasp expert: pick up and lift each YCB-Video object.

For each object and seed: the object is placed by ``handsim.world.scene.sample_placements`` (yaw and
position from the seed), a scene with the table, a medium right hand and that object is built,
and :func:`handsim.envs.grasping.run_episode` runs the expert from a seeded start pose. Success
is the definition of :mod:`handsim.envs.grasping`: lifted 0.10 m, then held 2 s with less than
1 cm of slip in the palm frame.

With ``--env``, each episode is instead a full ``handsim/Grasp-v0`` episode (``reset(seed)``,
the env's own placement and start pose, depth rendered every step, the expert from
``make_expert``) and success is the env's ``info["is_success"]`` when it ends.

Run: ``python benchmarks/bench_grasp.py [--env] [--objects NAME ...] [--seeds N]
[--first-seed S] [--out benchmarks/results/bench_grasp.json]``. Prints one row per object
(grasp type, successes, mean lift and slip, failure reasons) and writes every episode to JSON.
"""

from __future__ import annotations

import argparse
import collections
import json
import platform
import time
from pathlib import Path

import mujoco
import numpy as np

from handsim.envs.grasping import (
    GraspExpert,
    GraspPlanningError,
    run_episode,
    shape_class,
)
from handsim.hand.model import hand_params
from handsim.world.registry import OBJECTS, get_object
from handsim.world.scene import Scene, SceneSpec, sample_placements

_MAX_STEPS = 400  # 8 s at 50 Hz


def _env_episode(name: str, seed: int) -> dict:
    """One handsim/Grasp-v0 episode with the grasp expert."""
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)

    env = gym.make("handsim/Grasp-v0", objects=name)
    try:
        _, info = env.reset(seed=seed)
        expert = env.unwrapped.make_expert()
        max_lift = 0.0
        while True:
            action = expert.act(env.unwrapped.expert_state()).vector
            _, _, terminated, truncated, info = env.step(action)
            max_lift = max(max_lift, info.get("lift_m", 0.0))
            if terminated or truncated:
                break
        success = bool(info.get("is_success", False))
        failure = None
        if not success:
            failure = (
                "diverged" if info["physics_diverged"] else env.unwrapped.tracker.outcome().failure
            )
        return {
            "seed": seed,
            "grasp_type": expert.grasp_type,
            "success": success,
            "failure": failure,
            "max_lift_m": max_lift,
            "slip_m": info.get("slip_m"),
            "steps": env.unwrapped.elapsed_steps,
        }
    finally:
        env.close()


def run_clutter(episodes: int, first_seed: int = 0) -> dict:
    """GraspClutter-v0 episodes (3-6 objects from all 21, a random target) with the expert."""
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)

    env = gym.make("handsim/GraspClutter-v0")
    runs = []
    for seed in range(first_seed, first_seed + episodes):
        _, info = env.reset(seed=seed)
        base = env.unwrapped
        target = base.scene.objects[base.target_instance][1].name
        try:
            expert = base.make_expert()
        except GraspPlanningError:
            runs.append({"seed": seed, "target": target, "success": False, "failure": "no_plan"})
            continue
        while True:
            _, _, terminated, truncated, info = env.step(expert.act(base.expert_state()).vector)
            if terminated or truncated:
                break
        runs.append(
            {
                "seed": seed,
                "target": target,
                "n_objects": len(base.scene.objects),
                "success": bool(info.get("is_success", False)),
                "failure": None if info.get("is_success") else base.tracker.outcome().failure,
            }
        )
        print(runs[-1], flush=True)
    env.close()
    ok = sum(r["success"] for r in runs)
    return {"episodes": len(runs), "successes": ok, "runs": runs}


def run_object(name: str, seeds: int, first_seed: int = 0, use_env: bool = False) -> dict:
    """Run ``seeds`` episodes with one object; return its row and the episodes."""
    params = hand_params("medium")
    obj = get_object(name)
    episodes = []
    start = time.perf_counter()
    grasp_types = collections.Counter()
    for seed in range(first_seed, first_seed + seeds):
        if use_env:
            try:
                episode = _env_episode(name, seed)
            except GraspPlanningError as err:
                episode = {"seed": seed, "success": False, "failure": "no_plan", "error": str(err)}
            grasp_types[episode.get("grasp_type", "-")] += 1
            episodes.append(episode)
            continue
        rng = np.random.default_rng(seed)
        placements = sample_placements(rng, [name])
        scene = Scene(SceneSpec(hand=params, objects=placements))
        expert = GraspExpert(obj, params)
        try:
            outcome = run_episode(scene, 0, expert, rng, _MAX_STEPS)
        except GraspPlanningError as err:
            episodes.append(
                {"seed": seed, "success": False, "failure": "no_plan", "error": str(err)}
            )
            continue
        grasp_types[expert.grasp_type] += 1
        episodes.append({"seed": seed, "grasp_type": expert.grasp_type, **outcome.to_dict()})
    wall = time.perf_counter() - start
    ok = [e for e in episodes if e["success"]]
    lifts = [e["max_lift_m"] for e in episodes if "max_lift_m" in e]
    slips = [e["slip_m"] for e in ok]
    failures = collections.Counter(e["failure"] for e in episodes if not e["success"])
    return {
        "object": name,
        "shape_class": shape_class(obj),
        "grasp_type": "/".join(grasp_types) or "-",
        "successes": len(ok),
        "episodes": len(episodes),
        "mean_lift_m": float(np.mean(lifts)) if lifts else 0.0,
        "mean_slip_m": float(np.mean(slips)) if slips else None,
        "failures": dict(failures),
        "wall_s": wall,
        "runs": episodes,
    }


def main() -> None:
    """Run the benchmark, print the table and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--objects", nargs="*", default=list(OBJECTS), help="object names")
    parser.add_argument("--seeds", type=int, default=20, help="episodes per object")
    parser.add_argument("--first-seed", type=int, default=0, help="seeds are first .. first+N-1")
    parser.add_argument("--env", action="store_true", help="run full Grasp-v0 episodes")
    parser.add_argument(
        "--clutter", type=int, default=0, help="run this many GraspClutter-v0 episodes instead"
    )
    parser.add_argument("--out", default="benchmarks/results/bench_grasp.json")
    args = parser.parse_args()
    if args.clutter:
        result = run_clutter(args.clutter, args.first_seed)
        print(f"GraspClutter-v0: {result['successes']}/{result['episodes']} successes")
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result, indent=2))
        print(f"written: {out}")
        return
    names = [OBJECTS.canonical(n) for n in args.objects]
    header = (
        f"{'object':<24} {'class':<10} {'grasp type':<20} {'ok':>7} {'lift mm':>8} "
        f"{'slip mm':>8}  failures"
    )
    print(header)
    print("-" * len(header))
    rows = []
    start = time.perf_counter()
    for name in names:
        row = run_object(name, args.seeds, args.first_seed, use_env=args.env)
        rows.append(row)
        slip = "-" if row["mean_slip_m"] is None else f"{1000 * row['mean_slip_m']:.1f}"
        failures = ", ".join(f"{k} {v}" for k, v in row["failures"].items()) or "-"
        print(
            f"{name:<24} {row['shape_class']:<10} {row['grasp_type']:<20} "
            f"{row['successes']:>3}/{row['episodes']:<3} {1000 * row['mean_lift_m']:>8.0f} "
            f"{slip:>8}  {failures}",
            flush=True,
        )
    total = sum(r["successes"] for r in rows)
    episodes = sum(r["episodes"] for r in rows)
    at_target = sum(r["successes"] >= 0.9 * r["episodes"] for r in rows)
    wall = time.perf_counter() - start
    print("-" * len(header))
    print(
        f"total {total}/{episodes} ({100 * total / max(episodes, 1):.1f} %); objects at >= 90 %: "
        f"{at_target}/{len(rows)}; wall {wall:.0f} s"
    )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "machine": {"python": platform.python_version(), "cpu": platform.processor()},
                "mujoco": mujoco.__version__,
                "mode": "handsim/Grasp-v0 episodes" if args.env else "run_episode",
                "seeds": args.seeds,
                "first_seed": args.first_seed,
                "max_steps": _MAX_STEPS,
                "total_successes": total,
                "total_episodes": episodes,
                "wall_s": wall,
                "objects": rows,
            },
            indent=2,
        )
    )
    print(f"written: {out}")


if __name__ == "__main__":
    main()
