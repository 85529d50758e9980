"""Benchmark of the scripted grasp expert: pick up and lift each YCB-Video object.

For each object and seed: the object is placed by ``handsim.world.scene.sample_placements`` (yaw and
position from the seed), a scene with the table, a medium right hand and that object is built,
and :func:`handsim.envs.grasping.run_episode` runs the expert from a seeded start pose. Success
is the definition of :mod:`handsim.envs.grasping`: lifted 0.10 m, then held 2 s with less than
1 cm of slip and 10 deg of turn in the palm frame (both over the whole hold window, from its
first step).

With ``--env``, each episode is instead a full ``handsim/Grasp-v0`` episode (``reset(seed)``,
the env's own placement and start pose, depth rendered every step, the expert from
``make_expert``) and success is the env's ``info["is_success"]`` when it ends.

Run: ``python benchmarks/bench_grasp.py [--env] [--objects NAME ...] [--seeds N]
[--first-seed S] [--hand-size small|medium|large|LENGTH_M] [--side right|left] [--sizes all]
[--friction skin|mujoco|MU] [--object-noise-mm SIGMA [--noise-kind axis|3d]] [--no-replan]
[--workers N] [--out|--json benchmarks/results/bench_grasp.json]``. Prints one row per object
(grasp type, successes, mean lift, largest slip and turn, failure reasons) and writes every
episode to JSON (``slip_m`` and ``turn_rad`` per episode: of the successful window, or the
largest of any window on failure).

Contact quality (``run_episode`` mode), per object over its episodes:

- ``hold p95/max mm``: the deepest hand-object penetration (MuJoCo contact ``dist < 0``) of
  every control step of the hold phase: its 95th percentile and maximum;
- ``all mm``: the deepest hand-object penetration over whole episodes; ``table mm``: the
  deepest hand-table penetration;
- ``F/W``: the median over the hold of the total hand-object normal force over the object's
  weight (the median over episodes; ``F/W max`` the largest episode median);
- ``slip mm`` / ``turn deg``: the largest slip / turn in the palm frame of a successful hold.

``--workers N`` runs the episodes in N processes; every episode depends only on its object,
seed and options, so the records (and tables) are those of a serial run. The JSON's
``per_object`` maps each object to ``{"size side": [successes, episodes]}``.

``--sizes all`` runs the small, medium and large presets, right and left (one table each).
``--physics`` instead measures the physics rate of a held grasp: ``HandDriver.step`` (one
control step: mocap tracking, ``mj_step(nstep=10)``, divergence checks, ``mj_forward``) against
bare single ``mj_step`` calls from the same state, in physics steps/s and their ratio.
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import dataclasses
import json
import multiprocessing
import platform
import time
from pathlib import Path

import mujoco
import numpy as np

from handsim.envs.grasping import (
    CONTROL_DT_S,
    FRAME_SKIP,
    GraspExpert,
    GraspPlanningError,
    GraspState,
    contact_metrics,
    run_episode,
    shape_class,
)
from handsim.envs.physics import HandDriver, set_skin_friction
from handsim.hand.model import HAND_SIZES, hand_params
from handsim.world.registry import OBJECTS, get_object
from handsim.world.scene import Scene, SceneSpec, sample_placements

_MAX_STEPS = 400  # 8 s at 50 Hz


def _env_episode(
    name: str, seed: int, hand_size_m: float = 0.189, side: str = "right", friction: str = "skin"
) -> dict:
    """One handsim/Grasp-v0 episode with the grasp expert."""
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)

    env = gym.make(
        "handsim/Grasp-v0",
        objects=name,
        hand_size=hand_size_m,
        handedness=side,
        object_friction=friction if friction in ("skin", "mujoco") else float(friction),
    )
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
            "turn_rad": info.get("turn_rad"),
            "steps": env.unwrapped.elapsed_steps,
        }
    finally:
        env.close()


def _clutter_episode(seed: int) -> dict:
    """One GraspClutter-v0 episode (3-6 objects from all 21, a random target) with the expert.

    A fresh env per episode, so the record depends on the seed only (any process, any order).
    """
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)

    env = gym.make("handsim/GraspClutter-v0")
    try:
        _, info = env.reset(seed=seed)
        base = env.unwrapped
        target = base.scene.objects[base.target_instance][1].name
        try:
            expert = base.make_expert()
        except GraspPlanningError:
            return {"seed": seed, "target": target, "success": False, "failure": "no_plan"}
        while True:
            _, _, terminated, truncated, info = env.step(expert.act(base.expert_state()).vector)
            if terminated or truncated:
                break
        return {
            "seed": seed,
            "target": target,
            "n_objects": len(base.scene.objects),
            "success": bool(info.get("is_success", False)),
            "failure": None if info.get("is_success") else base.tracker.outcome().failure,
        }
    finally:
        env.close()


def run_clutter(episodes: int, first_seed: int = 0, pool=None) -> dict:
    """GraspClutter-v0 episodes ``first_seed ..`` with the expert (in ``pool`` if given)."""
    seeds = range(first_seed, first_seed + episodes)
    if pool is None:
        results = map(_clutter_episode, seeds)
    else:
        results = (f.result() for f in [pool.submit(_clutter_episode, s) for s in seeds])
    runs = []
    for run in results:
        runs.append(run)
        print(run, flush=True)
    ok = sum(r["success"] for r in runs)
    return {"episodes": len(runs), "successes": ok, "runs": runs}


def _contact_summary(obj, records: list[tuple[str, object]]) -> dict:
    """Penetration and force figures of one episode from its per-step contact metrics."""
    hold = [m for phase, m in records if phase == "hold"]
    weight = obj.mass_kg * 9.81
    summary = {
        "max_depth_mm": 1000 * max((m.object_depth_m for _, m in records), default=0.0),
        "max_table_depth_mm": 1000 * max((m.table_depth_m for _, m in records), default=0.0),
    }
    if hold:
        depth = np.array([m.object_depth_m for m in hold])
        force = np.array([m.normal_force_n for m in hold])
        summary.update(
            {
                "hold_depth_p95_mm": 1000 * float(np.percentile(depth, 95)),
                "hold_depth_max_mm": 1000 * float(depth.max()),
                "hold_force_over_weight": float(np.median(force) / weight),
                "deepest_geom": max(hold, key=lambda m: m.object_depth_m).deepest_geom,
            }
        )
    return summary


def _noisy_perception(sigma_mm: float, kind: str, seed: int):
    """A ``perceive`` hook: the object position perturbed independently at every step.

    ``kind="axis"``: ``N(0, sigma^2)`` per world axis (3-D error ~1.6 sigma on average);
    ``"3d"``: an error of exactly ``sigma`` in a uniformly random direction.
    """
    if sigma_mm <= 0:
        return None
    rng = np.random.default_rng(10_000 + seed)

    def perceive(state: GraspState) -> GraspState:
        if kind == "axis":
            offset = rng.normal(0.0, sigma_mm / 1000.0, 3)
        else:
            direction = rng.normal(size=3)
            offset = sigma_mm / 1000.0 * direction / np.linalg.norm(direction)
        T = state.T_world_from_obj.copy()
        T[:3, 3] += offset
        return dataclasses.replace(state, T_world_from_obj=T)

    return perceive


def _size_length(hand_size: str, seed: int = 0) -> float:
    if hand_size == "random":  # drawn per episode from (0.15, 0.22) m
        return float(np.random.default_rng(20_000 + seed).uniform(0.15, 0.22))
    return HAND_SIZES[hand_size] if hand_size in HAND_SIZES else float(hand_size)


def _set_friction(scene: Scene, friction: str) -> float | None:
    """Apply ``--friction`` to the scene; the friction the expert sizes its grip for.

    A number is what the hand feels, so the expert sizes its grip for it too; otherwise
    (``None``) for skin on the object's material.
    """
    if friction != "mujoco":
        set_skin_friction(scene, None if friction == "skin" else float(friction))
    return None if friction in ("mujoco", "skin") else float(friction)


def _episode(
    name: str,
    seed: int,
    use_env: bool = False,
    hand_size: str = "medium",
    side: str = "right",
    friction: str = "skin",
    object_noise_mm: float = 0.0,
    noise_kind: str = "axis",
    replan: bool = True,
) -> dict:
    """One episode of one object (arguments as :func:`run_object`); its JSON record.

    Depends only on its arguments (the seed fixes placement, start pose and noise), so episodes
    run in any order or process give the same records.
    """
    obj = get_object(name)
    start = time.perf_counter()
    params = hand_params(_size_length(hand_size, seed), side)
    if use_env:
        try:
            episode = _env_episode(name, seed, params.hand_length, side, friction)
        except GraspPlanningError as err:
            episode = {"seed": seed, "success": False, "failure": "no_plan", "error": str(err)}
        return {**episode, "hand_length_m": params.hand_length, "wall_s": _since(start)}
    rng = np.random.default_rng(seed)
    placements = sample_placements(rng, [name])
    scene = Scene(SceneSpec(hand=params, objects=placements))
    expert = GraspExpert(obj, params, replan=replan, friction=_set_friction(scene, friction))
    records: list = []

    def record(step: int, expert: GraspExpert) -> None:
        records.append((expert.phase, contact_metrics(scene, 0)))

    try:
        outcome = run_episode(
            scene,
            0,
            expert,
            rng,
            _MAX_STEPS,
            on_step=record,
            perceive=_noisy_perception(object_noise_mm, noise_kind, seed),
        )
    except GraspPlanningError as err:
        return {
            "seed": seed,
            "success": False,
            "failure": "no_plan",
            "error": str(err),
            "hand_length_m": params.hand_length,
            "wall_s": _since(start),
        }
    outcome = outcome.to_dict()
    if expert.plan is None:
        outcome["failure"] = "no_plan"
    return {
        "seed": seed,
        "grasp_type": expert.grasp_type,
        "replans": expert.replans,
        "hand_length_m": params.hand_length,
        **outcome,
        **_contact_summary(obj, records),
        "wall_s": _since(start),
    }


def _since(start: float) -> float:
    return time.perf_counter() - start


def _object_row(name: str, episodes: list[dict]) -> dict:
    """The row of one object from its episode records (in seed order)."""
    obj = get_object(name)
    grasp_types = collections.Counter(
        e["grasp_type"] for e in episodes if e.get("grasp_type") is not None
    )
    ok = [e for e in episodes if e["success"]]
    lifts = [e["max_lift_m"] for e in episodes if "max_lift_m" in e]
    slips = [e["slip_m"] for e in ok]
    turns = [e["turn_rad"] for e in ok if e.get("turn_rad") is not None]
    failures = collections.Counter(e["failure"] for e in episodes if not e["success"])

    def pooled(key: str, fn) -> float | None:
        values = [e[key] for e in episodes if key in e]
        return float(fn(values)) if values else None

    return {
        "object": name,
        "shape_class": shape_class(obj),
        "grasp_type": "/".join(grasp_types) or "-",
        "successes": len(ok),
        "episodes": len(episodes),
        "mean_lift_m": float(np.mean(lifts)) if lifts else 0.0,
        "mean_slip_m": float(np.mean(slips)) if slips else None,
        "failures": dict(failures),
        "hold_depth_p95_mm": pooled("hold_depth_p95_mm", np.max),
        "hold_depth_max_mm": pooled("hold_depth_max_mm", np.max),
        "max_depth_mm": pooled("max_depth_mm", np.max),
        "max_table_depth_mm": pooled("max_table_depth_mm", np.max),
        "force_over_weight": pooled("hold_force_over_weight", np.median),
        "max_slip_m": max(slips) if slips else None,
        "max_turn_rad": max(turns) if turns else None,
        "wall_s": float(sum(e.get("wall_s", 0.0) for e in episodes)),
        "runs": episodes,
    }


def run_object(
    name: str,
    seeds: int,
    first_seed: int = 0,
    use_env: bool = False,
    hand_size: str = "medium",
    side: str = "right",
    friction: str = "skin",
    object_noise_mm: float = 0.0,
    noise_kind: str = "axis",
    replan: bool = True,
) -> dict:
    """Run ``seeds`` episodes with one object; return its row and the episodes.

    ``friction``: ``"skin"`` (per material), ``"mujoco"`` (MuJoCo's 1.0) or a number (every
    object, and the expert sizes its grip for it; otherwise for skin on the material);
    ``object_noise_mm``/``noise_kind``: the expert perceives the object's position with that
    error at every step (see :func:`_noisy_perception`); ``replan=False``: the expert plans
    once, at the start (open loop).
    """
    episodes = [
        _episode(
            name, seed, use_env, hand_size, side, friction, object_noise_mm, noise_kind, replan
        )
        for seed in range(first_seed, first_seed + seeds)
    ]
    return _object_row(name, episodes)


def bench_physics(
    names: list[str], control_steps: int = 100, repeats: int = 7, friction: str = "skin"
) -> dict:
    """Physics steps/s of held grasps: ``HandDriver.step`` against bare ``mj_step`` calls.

    Timed in process CPU time (MuJoCo runs on one thread), best of ``repeats`` interleaved
    runs, so other processes on a shared machine distort the ratio less. ``friction`` as
    for :func:`run_object`.
    """
    params = hand_params("medium")
    rows = []
    for name in names:
        rng = np.random.default_rng(0)
        scene = Scene(SceneSpec(hand=params, objects=sample_placements(rng, [name])))
        expert = GraspExpert(get_object(name), params, friction=_set_friction(scene, friction))
        held = []

        def stop(step: int, expert: GraspExpert, held=held) -> None:
            held.append(expert.phase == "hold")

        run_episode(scene, 0, expert, rng, _MAX_STEPS, stop_on_success=False, on_step=stop)
        hold_target = expert.act(GraspState.from_sim(scene, 0, _MAX_STEPS * CONTROL_DT_S))
        model, data = scene.model, scene.data
        snapshot = mujoco.MjData(model)
        mujoco.mj_copyData(snapshot, model, data)
        driver_s, bare_s = [], []
        for _ in range(repeats):  # interleaved, best of: the machine is shared
            mujoco.mj_copyData(data, model, snapshot)
            driver = HandDriver(scene)
            driver.set_target(hold_target)
            start = time.process_time()
            for _ in range(control_steps):
                driver.step(FRAME_SKIP)
            driver_s.append(time.process_time() - start)
            mujoco.mj_copyData(data, model, snapshot)
            start = time.process_time()
            for _ in range(control_steps * FRAME_SKIP):
                mujoco.mj_step(model, data)
            bare_s.append(time.process_time() - start)
        n = control_steps * FRAME_SKIP
        row = {
            "object": name,
            "held": bool(held and held[-1]),
            "driver_steps_per_s": n / min(driver_s),
            "bare_steps_per_s": n / min(bare_s),
            "mean_contacts": int(data.ncon),
        }
        row["ratio"] = row["driver_steps_per_s"] / row["bare_steps_per_s"]
        rows.append(row)
        print(
            f"{name:<24} held={row['held']!s:<5} driver {row['driver_steps_per_s']:8.0f} "
            f"bare {row['bare_steps_per_s']:8.0f} steps/s  ratio {row['ratio']:.2f}",
            flush=True,
        )
    ratios = [r["ratio"] for r in rows]
    driver = [r["driver_steps_per_s"] for r in rows]
    print(
        f"median ratio {np.median(ratios):.2f} (min {min(ratios):.2f}); median held-grasp "
        f"physics {np.median(driver):.0f} steps/s"
    )
    return {
        "median_ratio": float(np.median(ratios)),
        "median_driver_steps_per_s": float(np.median(driver)),
        "objects": rows,
    }


def _fmt(value: float | None, scale: float = 1.0, digits: int = 1) -> str:
    return "-" if value is None else f"{scale * value:.{digits}f}"


def _episode_args(args: argparse.Namespace, hand_size: str, side: str) -> tuple:
    """The arguments of :func:`_episode` after name and seed."""
    return (
        args.env,
        hand_size,
        side,
        args.friction,
        args.object_noise_mm,
        args.noise_kind,
        not args.no_replan,
    )


def _submit(pool, names: list[str], args: argparse.Namespace, hand_size: str, side: str) -> dict:
    """Queue every episode of one table in ``pool``: object name -> futures in seed order."""
    extra = _episode_args(args, hand_size, side)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    return {name: [pool.submit(_episode, name, seed, *extra) for seed in seeds] for name in names}


def run_table(
    names: list[str],
    args: argparse.Namespace,
    hand_size: str,
    side: str,
    pending: dict | None = None,
) -> dict:
    """One success / contact table for a hand size and side.

    ``pending``: the table's episodes already queued in a process pool (see :func:`_submit`);
    otherwise they run here, one after the other.
    """
    header = (
        f"{'object':<24} {'class':<10} {'grasp type':<20} {'ok':>7} {'lift mm':>8} "
        f"{'slip mm':>8} {'turn deg':>8} {'hold p95':>8} {'hold max':>8} {'all mm':>7} "
        f"{'table':>6} {'F/W':>6}  failures"
    )
    print(f"hand {hand_size} {side}")
    print(header)
    print("-" * len(header))
    rows = []
    start = time.perf_counter()
    for name in names:
        if pending is not None:
            row = _object_row(name, [f.result() for f in pending[name]])
        else:
            row = run_object(
                name, args.seeds, args.first_seed, *_episode_args(args, hand_size, side)
            )
        rows.append(row)
        failures = ", ".join(f"{k} {v}" for k, v in row["failures"].items()) or "-"
        print(
            f"{name:<24} {row['shape_class']:<10} {row['grasp_type']:<20} "
            f"{row['successes']:>3}/{row['episodes']:<3} {1000 * row['mean_lift_m']:>8.0f} "
            f"{_fmt(row['max_slip_m'], 1000):>8} "
            f"{_fmt(row['max_turn_rad'], 180 / np.pi):>8} "
            f"{_fmt(row.get('hold_depth_p95_mm'), 1, 2):>8} "
            f"{_fmt(row.get('hold_depth_max_mm'), 1, 2):>8} "
            f"{_fmt(row.get('max_depth_mm'), 1, 2):>7} "
            f"{_fmt(row.get('max_table_depth_mm'), 1, 2):>6} "
            f"{_fmt(row.get('force_over_weight')):>6}  {failures}",
            flush=True,
        )
    total = sum(r["successes"] for r in rows)
    episodes = sum(r["episodes"] for r in rows)
    at_target = sum(r["successes"] >= 0.95 * r["episodes"] for r in rows)
    forces = [r["force_over_weight"] for r in rows if r.get("force_over_weight") is not None]
    wall = time.perf_counter() - start
    cpu = sum(r["wall_s"] for r in rows)
    print("-" * len(header))
    print(
        f"total {total}/{episodes} ({100 * total / max(episodes, 1):.1f} %); objects at >= 95 %: "
        f"{at_target}/{len(rows)}; median F/W {_fmt(np.median(forces) if forces else None)}; "
        f"wall {wall:.0f} s (episodes {cpu:.0f} s)"
    )
    return {
        "hand_size": hand_size,
        "side": side,
        "total_successes": total,
        "total_episodes": episodes,
        "median_force_over_weight": float(np.median(forces)) if forces else None,
        "wall_s": wall,
        "episodes_s": cpu,
        "per_object": {r["object"]: [r["successes"], r["episodes"]] for r in rows},
        "objects": rows,
    }


def main() -> None:
    """Run the benchmark, print the table and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--objects", nargs="*", default=list(OBJECTS), help="object names")
    parser.add_argument("--seeds", type=int, default=20, help="episodes per object")
    parser.add_argument("--first-seed", type=int, default=0, help="seeds are first .. first+N-1")
    parser.add_argument("--env", action="store_true", help="run full Grasp-v0 episodes")
    parser.add_argument(
        "--hand-size",
        default="medium",
        help="small, medium, large, a length in metres, or random (0.15-0.22 m per episode)",
    )
    parser.add_argument("--side", default="right", choices=("right", "left"))
    parser.add_argument(
        "--sizes", choices=("all",), help="every preset size, right and left (6 tables)"
    )
    parser.add_argument(
        "--friction",
        default="skin",
        help="hand-object friction: skin (per material, the envs' default), mujoco (1.0) or a "
        "number",
    )
    parser.add_argument(
        "--object-noise-mm",
        type=float,
        default=0.0,
        help="error of the perceived object position at every step, mm (see --noise-kind)",
    )
    parser.add_argument(
        "--noise-kind",
        choices=("axis", "3d"),
        default="axis",
        help="axis: Gaussian std per axis; 3d: that exact distance in a random direction",
    )
    parser.add_argument(
        "--no-replan", action="store_true", help="the expert plans once, at the start"
    )
    parser.add_argument(
        "--physics", action="store_true", help="measure held-grasp physics steps/s only"
    )
    parser.add_argument(
        "--clutter", type=int, default=0, help="run this many GraspClutter-v0 episodes instead"
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=1,
        help="episodes run in this many processes (results identical to 1; default 1)",
    )
    parser.add_argument(
        "--out", "--json", default="benchmarks/results/bench_grasp.json", help="JSON written"
    )
    args = parser.parse_args()
    if args.workers < 1:
        parser.error(f"--workers must be at least 1, got {args.workers}")
    if args.friction not in ("skin", "mujoco"):
        try:
            valid = float(args.friction) > 0
        except ValueError:
            valid = False
        if not valid:
            parser.error(f"--friction must be skin, mujoco or a number > 0, got {args.friction!r}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    pool = None
    if args.workers > 1 and not args.physics:
        # spawn: each worker imports MuJoCo (and EGL for --env) itself.
        context = multiprocessing.get_context("spawn")
        pool = concurrent.futures.ProcessPoolExecutor(args.workers, mp_context=context)
    try:
        _run(args, out, pool)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)


def _run(args: argparse.Namespace, out: Path, pool) -> None:
    start = time.perf_counter()
    if args.clutter:
        result = run_clutter(args.clutter, args.first_seed, pool)
        print(f"GraspClutter-v0: {result['successes']}/{result['episodes']} successes")
        out.write_text(json.dumps({**result, "workers": args.workers}, indent=2))
        print(f"written: {out}")
        return
    names = [OBJECTS.canonical(n) for n in args.objects]
    meta = {
        "machine": {"python": platform.python_version(), "cpu": platform.processor()},
        "mujoco": mujoco.__version__,
    }
    if args.physics:
        result = bench_physics(names, friction=args.friction)
        out.write_text(json.dumps({**meta, "friction": args.friction, **result}, indent=2))
        print(f"written: {out}")
        return
    hands = (
        [(size, side) for size in ("small", "medium", "large") for side in ("right", "left")]
        if args.sizes == "all"
        else [(args.hand_size, args.side)]
    )
    # With a pool, every table's episodes are queued at once so no worker idles between tables.
    pending = [None if pool is None else _submit(pool, names, args, *hand) for hand in hands]
    tables = [
        run_table(names, args, *hand, queued) for hand, queued in zip(hands, pending, strict=True)
    ]
    total = sum(t["total_successes"] for t in tables)
    episodes = sum(t["total_episodes"] for t in tables)
    wall = time.perf_counter() - start
    print(f"all tables: {total}/{episodes}; wall {wall:.0f} s with {args.workers} worker(s)")
    out.write_text(
        json.dumps(
            {
                **meta,
                "mode": "handsim/Grasp-v0 episodes" if args.env else "run_episode",
                "seeds": args.seeds,
                "first_seed": args.first_seed,
                "friction": args.friction,
                "object_noise_mm": args.object_noise_mm,
                "noise_kind": args.noise_kind,
                "replan": not args.no_replan,
                "max_steps": _MAX_STEPS,
                "workers": args.workers,
                "wall_s": wall,
                "total_successes": total,
                "total_episodes": episodes,
                # object -> "size side" -> [successes, episodes]
                "per_object": {
                    name: {f"{t['hand_size']} {t['side']}": t["per_object"][name] for t in tables}
                    for name in names
                },
                "tables": tables,
            },
            indent=2,
        )
    )
    print(f"written: {out}")


if __name__ == "__main__":
    main()
