"""Does a divergence flag mean the physics left its valid range? Bang-bang stress episodes.

Runs random bang-bang actions (each action component at a bound, at random: the stress case of
tests/envs/test_divergence.py) on HandPose-v0 with the driver's speed check switched off, so
every episode runs to its end unless MuJoCo itself warns (mjWARN_BADQACC / BADQVEL / BADQPOS,
after which MuJoCo resets the state). Per control step it records the largest ratio of a DoF's
speed to its bound (``HandDriver.speed_bounds``), the deepest contact penetration and the
kinetic energy. A step whose ratio passes a threshold counts as *flagged*; a flag is *true* when
the episode then blows up (MuJoCo warns, the state turns non-finite or no hand pose, or a
speed passes 1000 times its bound) within the next
``--horizon`` steps, else *false* (the speed came back down and the episode went on).

    python benchmarks/divergence_check.py --seeds 40 --out /tmp/divergence.json

Prints, for each threshold factor (times the bound), the number of flagged episodes and how
many of them were true, and the largest ratio reached by an episode that never blew up.
"""

from __future__ import annotations

import argparse
import json
import sys

import gymnasium as gym
import mujoco
import numpy as np

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.errors import HandSimError

BLOW_UP = 1000.0  # speed / bound: orders of magnitude past any motion of a hand


def _episode(env_id: str, seed: int, hand_size: float, steps: int) -> dict:
    env = gym.make(env_id, hand_size=hand_size, obs_mode="state")
    env.reset(seed=seed)
    base = env.unwrapped
    driver = base.driver
    model, data = base.scene.model, base.scene.data
    driver._within_bounds = lambda: True  # only MuJoCo's warnings (and the blow-up) stop it
    lo, hi = env.action_space.low, env.action_space.high
    rng = np.random.default_rng(seed)
    ratios, depths, energies, where = [], [], [], []
    hand_root = model.body(base.scene.hand.root_body).id
    dof_is_hand = model.body_rootid[model.dof_bodyid] == hand_root
    blew_up = None
    for step in range(steps):
        try:
            *_, terminated, truncated, info = env.step(np.where(rng.random(27) < 0.5, lo, hi))
        except HandSimError:  # a state that is no hand pose (a joint turned 100 rad or more)
            blew_up = step
            ratios.append(float("inf"))
            depths.append(float("nan"))
            energies.append(float("inf"))
            break
        qvel = data.qvel
        finite = bool(np.all(np.isfinite(qvel)))
        bounds = driver.speed_bounds()
        ratios.append(float(np.max(np.abs(qvel) / bounds)) if finite else float("inf"))
        worst = int(np.argmax(np.abs(qvel) / bounds)) if finite else 0
        where.append("hand" if dof_is_hand[worst] else "object")
        dist = data.contact.dist[: data.ncon]
        depths.append(float(max(0.0, -dist.min())) if data.ncon else 0.0)
        energy = float("inf")
        if finite:
            mv = np.zeros(model.nv)
            mujoco.mj_mulM(model, data, mv, qvel)
            energy = 0.5 * float(qvel @ mv)
        energies.append(energy)
        if info["physics_diverged"] or ratios[-1] > BLOW_UP:
            blew_up = step
            break
        if terminated or truncated:
            break
    env.close()
    return {
        "seed": seed,
        "hand_size_m": hand_size,
        "ratios": ratios,
        "worst_dof": where,
        "penetration_m": depths,
        "kinetic_energy_j": energies,
        "blew_up_at": blew_up,
    }


def main(argv: list[str] | None = None) -> int:
    """Run the episodes and print the flag counts by threshold."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="handsim/HandPose-v0")
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--horizon", type=int, default=5)
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.15, 0.189, 0.235])
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    episodes = [
        _episode(args.env, seed, size, args.steps)
        for size in args.sizes
        for seed in range(args.seeds)
    ]
    print(f"{args.env}: {len(episodes)} episodes ({args.seeds} seeds x sizes {args.sizes}), "
          f"{args.steps} steps of bang-bang actions, speed check off")  # fmt: skip
    blown = sum(e["blew_up_at"] is not None for e in episodes)
    print(f"MuJoCo warned or the state went non-finite in {blown}")
    table = []
    for factor in (1, 2, 3, 5, 10, 20, 50):
        flagged = true = 0
        for e in episodes:
            first = next((i for i, r in enumerate(e["ratios"]) if r > factor), None)
            if first is None:
                continue
            flagged += 1
            end = e["blew_up_at"]
            is_true = end is not None and end - first <= args.horizon
            true += is_true
            if not is_true and factor == 1:
                print(f"    false flag: seed {e['seed']}, hand {e['hand_size_m']} m, step "
                      f"{first}: {e['worst_dof'][first]} DoF at {e['ratios'][first]:.2f} x its "
                      f"bound")  # fmt: skip
        table.append({"factor": factor, "flagged": flagged, "true": true})
        print(f"  bound x {factor:>3}: {flagged:3d} episodes flagged, {true:3d} of them blew up "
              f"within {args.horizon} steps, {flagged - true:3d} went on")  # fmt: skip
    calm = [max(e["ratios"]) for e in episodes if e["blew_up_at"] is None]
    if calm:
        print(f"largest speed / bound in an episode that never blew up: {max(calm):.2f}")
        i = int(np.argmax(calm))
        e = [e for e in episodes if e["blew_up_at"] is None][i]
        j = int(np.argmax(e["ratios"]))
        print(f"  (seed {e['seed']}, hand {e['hand_size_m']} m, step {j}: penetration "
              f"{e['penetration_m'][j] * 1000:.1f} mm, kinetic energy "
              f"{e['kinetic_energy_j'][j]:.3g} J)")  # fmt: skip
    before = [
        e["ratios"][e["blew_up_at"] - 1] if e["blew_up_at"] else None
        for e in episodes
        if e["blew_up_at"] is not None
    ]
    print(f"speed / bound the step before MuJoCo warned: {before}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"table": table, "episodes": episodes}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
