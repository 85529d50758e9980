"""Benchmark of the hand: model build, forward kinematics, physics with contacts, retargeting.

Run: ``python benchmarks/bench_hand.py [--out benchmarks/results/bench_hand.json]``.
Prints each figure and writes them all to JSON. Figures are measured in this run only.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import mujoco
import numpy as np

from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import Hand, HandParams
from handsim.hand.pose import JOINT_LIMITS, HandPose
from handsim.hand.retarget import Retargeter


def _best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def bench_build() -> dict:
    """Hand construction (spec + actuator tuning compile) and compile into a scene."""
    build = _best_of(lambda: Hand(HandParams()), 10)
    hand = Hand(HandParams())
    compile_s = _best_of(hand.compile, 10)
    return {"hand_build_ms": 1000 * build, "hand_compile_ms": 1000 * compile_s}


def bench_fk(rng: np.random.Generator) -> dict:
    """Forward kinematics throughput, batched and one pose at a time."""
    fk = ForwardKinematics(HandParams())
    n = 10_000
    batch = HandPose(
        rng.normal(size=(n, 3)),
        rng.normal(size=(n, 3)),
        rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1], (n, 21)),
    )
    batched = _best_of(lambda: fk.keypoints(batch), 5)
    single = batch[0]
    one = _best_of(lambda: [fk.keypoints(single) for _ in range(1000)], 3) / 1000
    return {"fk_batched_poses_per_s": n / batched, "fk_single_poses_per_s": 1.0 / one}


def bench_physics(rng: np.random.Generator) -> dict:
    """Physics steps/s of a free hand that grips and releases a box resting on a floor."""
    hand = Hand(HandParams())
    spec = mujoco.MjSpec()
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1], name="floor")
    box = spec.worldbody.add_body(name="box", pos=[0, 0.1, 0.03])
    box.add_freejoint()
    box.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.03, 0.03, 0.03], mass=0.2, name="box")
    hand.attach_to(spec)
    model = spec.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    # Palm down above the box, forearm along -y.
    pose = HandPose.neutral(wrist_pos=(0.0, 0.0, 0.06), wrist_rotvec=(np.pi, 0.0, 0.0))
    binding.set_pose(data, pose)
    steps, contacts = 5000, 0
    start = time.perf_counter()
    for k in range(steps):
        if k % 250 == 0:
            angles = rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
            binding.set_target(data, pose.replace(angles=angles))
        mujoco.mj_step(model, data)
        contacts += data.ncon
    wall = time.perf_counter() - start
    return {
        "physics_steps_per_s": steps / wall,
        "physics_realtime_factor": steps * model.opt.timestep / wall,
        "physics_mean_contacts": contacts / steps,
    }


def bench_retarget(rng: np.random.Generator) -> dict:
    """Retargeting time and accuracy, clean and with 5 mm isotropic keypoint noise."""
    params = HandParams()
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    margin = np.deg2rad(2.0)
    clean_err, noisy_err, noisy_angle_err, times = [], [], [], []
    for _ in range(50):
        pose = HandPose(
            rng.uniform(-0.2, 0.2, 3),
            rng.uniform(-np.pi, np.pi, 3),
            rng.uniform(JOINT_LIMITS[:, 0] + margin, JOINT_LIMITS[:, 1] - margin),
        )
        truth = fk.keypoints(pose)
        start = time.perf_counter()
        result = retarget(truth)
        times.append(time.perf_counter() - start)
        clean_err.append(np.linalg.norm(fk.keypoints(result.pose) - truth, axis=-1).mean())
        noisy = truth + rng.normal(scale=0.005, size=truth.shape)
        result = retarget(noisy)
        noisy_err.append(np.linalg.norm(fk.keypoints(result.pose) - truth, axis=-1).mean())
        noisy_angle_err.append(np.rad2deg(np.abs(result.pose.angles - pose.angles)).mean())
    return {
        "retarget_ms_per_frame": 1000 * float(np.median(times)),
        "retarget_clean_mean_keypoint_error_mm": 1000 * float(np.mean(clean_err)),
        "retarget_noise5mm_mean_keypoint_error_mm": 1000 * float(np.mean(noisy_err)),
        "retarget_noise5mm_mean_angle_error_deg": float(np.mean(noisy_angle_err)),
    }


def main() -> None:
    """Run every benchmark, print the figures and write them to JSON."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="benchmarks/results/bench_hand.json")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    results = {
        "machine": {"python": platform.python_version(), "cpu": platform.processor() or "?"},
        "mujoco": mujoco.__version__,
    }
    for bench in (bench_build, bench_fk, bench_physics, bench_retarget):
        figures = bench(rng) if bench is not bench_build else bench()
        for key, value in figures.items():
            print(f"{key:<45} {value:12.3f}")
        results.update(figures)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(f"written: {out}")


if __name__ == "__main__":
    main()
