"""Benchmark of the hand: model build, forward kinematics, physics with contacts, retargeting.

Run: ``python benchmarks/bench_hand.py [--out benchmarks/results/bench_hand.json] [--only NAME]``.
Prints each figure and writes them all to JSON. Figures are measured in this run only. Times are
per call on one core (BLAS threads limited to one); ``*_median`` and ``*_best`` are the median
and the fastest call (the fastest shows the cost without other processes' interference).
"""

from __future__ import annotations

import os

# One core: numpy's BLAS must not spread the small solves over threads (set before importing
# numpy, hence the imports below the loop).
# ruff: noqa: E402
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import dataclasses
import json
import platform
import time
from pathlib import Path

import mujoco
import numpy as np

from handsim.errors import InvalidKeypoints
from handsim.hand.keypoints import from_format, to_format
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


def _random_pose(rng: np.random.Generator) -> HandPose:
    margin = np.deg2rad(2.0)
    return HandPose(
        rng.uniform(-0.2, 0.2, 3),
        rng.uniform(-np.pi, np.pi, 3),
        rng.uniform(JOINT_LIMITS[:, 0] + margin, JOINT_LIMITS[:, 1] - margin),
    )


def _stream(rng: np.random.Generator, frames: int) -> HandPose:
    """A 90 Hz stream: the hand moves from one random pose toward another (about 1 s apart)."""
    start, end = _random_pose(rng), _random_pose(rng)
    t = np.arange(frames)[:, None] / 90.0
    return HandPose(
        start.wrist_pos + t * (end.wrist_pos - start.wrist_pos),
        np.broadcast_to(start.wrist_rotvec, (frames, 3)),
        np.clip(
            start.angles + t * (end.angles - start.angles), JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
        ),
    )


def _ms(times: list[float]) -> tuple[float, float]:
    return 1000 * float(np.median(times)), 1000 * float(np.min(times))


def bench_retarget(rng: np.random.Generator) -> dict:
    """Retargeting of 5 mm-noise keypoint streams: warm and cold time, accuracy, side check."""
    params = HandParams()
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    track = {"check_side": False, "report_clamped": False}
    warm_t, cold_t, side_t = [], [], []
    warm_err, cold_err, warm_ang, cold_ang, clean_err, noisy_in = [], [], [], [], [], []
    for _ in range(20):
        poses = _stream(rng, 10)
        truth = fk.keypoints(poses)
        noisy = truth + rng.normal(scale=0.005, size=truth.shape)
        previous = None
        for k in range(len(noisy)):
            start = time.perf_counter()
            cold = retarget(noisy[k], **track)
            cold_t.append(time.perf_counter() - start)
            cold_err.append(np.linalg.norm(fk.keypoints(cold.pose) - truth[k], axis=-1).mean())
            cold_ang.append(np.rad2deg(np.abs(cold.pose.angles - poses.angles[k])).mean())
            noisy_in.append(np.linalg.norm(noisy[k] - truth[k], axis=-1).mean())
            if previous is not None:
                start = time.perf_counter()
                warm = retarget(noisy[k], previous.pose, initial_scale=previous.scale, **track)
                warm_t.append(time.perf_counter() - start)
                warm_err.append(np.linalg.norm(fk.keypoints(warm.pose) - truth[k], axis=-1).mean())
                warm_ang.append(np.rad2deg(np.abs(warm.pose.angles - poses.angles[k])).mean())
                previous = warm
            else:
                previous = cold
        start = time.perf_counter()
        retarget(noisy[0], report_clamped=False)
        side_t.append(time.perf_counter() - start)
        exact = retarget(truth[0])
        clean_err.append(np.linalg.norm(fk.keypoints(exact.pose) - truth[0], axis=-1).mean())
    figures = {
        "retarget_warm_ms_per_frame_median": _ms(warm_t)[0],
        "retarget_warm_ms_per_frame_best": _ms(warm_t)[1],
        "retarget_cold_ms_per_frame_median": _ms(cold_t)[0],
        "retarget_cold_ms_per_frame_best": _ms(cold_t)[1],
        "retarget_cold_with_side_check_ms_median": _ms(side_t)[0],
        "retarget_warm_target_ms": 2.0,
        "retarget_cold_target_ms": 10.0,
        "retarget_clean_mean_keypoint_error_mm": 1000 * float(np.mean(clean_err)),
        "retarget_noise5mm_input_keypoint_error_mm": 1000 * float(np.mean(noisy_in)),
        "retarget_noise5mm_warm_keypoint_error_mm": 1000 * float(np.mean(warm_err)),
        "retarget_noise5mm_cold_keypoint_error_mm": 1000 * float(np.mean(cold_err)),
        "retarget_noise5mm_warm_angle_error_deg": float(np.mean(warm_ang)),
        "retarget_noise5mm_cold_angle_error_deg": float(np.mean(cold_ang)),
    }
    # Formats with fewer points, through from_format (5 mm noise on the format's labels).
    for fmt in ("nyu14", "icvl16"):
        errors, times = [], []
        for _ in range(30):
            pose = _random_pose(rng)
            points = fk.points(pose)
            labels = to_format(points + rng.normal(scale=0.005, size=points.shape), fmt)
            start = time.perf_counter()
            result = retarget(from_format(labels, fmt), **track)
            times.append(time.perf_counter() - start)
            errors.append(np.linalg.norm(fk.keypoints(result.pose) - fk.keypoints(pose), axis=-1))
        figures[f"retarget_{fmt}_noise5mm_keypoint_error_mm"] = 1000 * float(np.mean(errors))
        figures[f"retarget_{fmt}_cold_ms_median"] = _ms(times)[0]
    # Side check: right hands onto a left hand must be refused, right onto right accepted.
    left = Retargeter(dataclasses.replace(params, side="left"))
    refused_wrong = refused_right = 0
    for n, (target, counter) in enumerate(((left, "wrong"), (retarget, "right"))):
        for _ in range(200 if n == 0 else 500):
            truth = fk.keypoints(_random_pose(rng))
            try:
                target(truth + rng.normal(scale=0.005, size=truth.shape), report_clamped=False)
            except InvalidKeypoints:
                if counter == "wrong":
                    refused_wrong += 1
                else:
                    refused_right += 1
    figures["side_check_right_onto_left_refused_of_200"] = refused_wrong
    figures["side_check_right_onto_right_refused_of_500"] = refused_right
    figures.update(_bench_mink(rng, fk, retarget))
    return figures


def _bench_mink(rng: np.random.Generator, fk: ForwardKinematics, retarget: Retargeter) -> dict:
    """The same warm-started fits with mink (differential IK, QP with daqp), when installed.

    Both fit the 21 keypoint sites with the hand's own size (scale fixed at 1) from the
    previous frame's fit; mink iterates its velocity QP to convergence.
    """
    try:
        import mink
    except ImportError:
        print("mink is not installed: skipping the comparison (pip install mink)")
        return {}
    hand = Hand(fk.skeleton.params)
    model = hand.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    configuration = mink.Configuration(model)
    tasks = [
        mink.FrameTask(name, "site", position_cost=1.0, orientation_cost=0.0)
        for name in hand.keypoint_site_names
    ]
    limits = [mink.ConfigurationLimit(model)]
    mink_t, mink_err, own_t, own_err = [], [], [], []
    for _ in range(20):
        truth = fk.keypoints(_random_pose(rng))
        first = truth + rng.normal(scale=0.005, size=truth.shape)
        second = truth + rng.normal(scale=0.005, size=truth.shape)
        previous = retarget(first, fit_scale=False, initial_scale=1.0, check_side=False)
        binding.set_pose(data, previous.pose)
        start = time.perf_counter()
        configuration.update(data.qpos)
        for task, point in zip(tasks, second, strict=True):
            task.set_target(mink.SE3.from_translation(point))
        for _ in range(100):
            velocity = mink.solve_ik(configuration, tasks, 1.0, "daqp", 1e-6, limits=limits)
            configuration.integrate_inplace(velocity, 1.0)
            if np.linalg.norm(velocity) < 1e-6:
                break
        mink_t.append(time.perf_counter() - start)
        data.qpos[:] = configuration.q
        mujoco.mj_kinematics(model, data)
        mink_err.append(np.linalg.norm(binding.keypoints(data) - truth, axis=-1).mean())
        start = time.perf_counter()
        result = retarget(
            second,
            previous.pose,
            fit_scale=False,
            initial_scale=1.0,
            check_side=False,
            report_clamped=False,
        )
        own_t.append(time.perf_counter() - start)
        own_err.append(np.linalg.norm(fk.keypoints(result.pose) - truth, axis=-1).mean())
    return {
        "mink_over_own_warm_time_ratio_median": float(np.median(mink_t) / np.median(own_t)),
        "mink_warm_ms_per_frame_median": _ms(mink_t)[0],
        "mink_noise5mm_keypoint_error_mm": 1000 * float(np.mean(mink_err)),
        "own_fixed_scale_warm_ms_per_frame_median": _ms(own_t)[0],
        "own_fixed_scale_noise5mm_keypoint_error_mm": 1000 * float(np.mean(own_err)),
    }


def main() -> None:
    """Run every benchmark, print the figures and write them to JSON."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="benchmarks/results/bench_hand.json")
    parser.add_argument("--only", help="run one benchmark: build, fk, physics or retarget")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    results = {
        "machine": {"python": platform.python_version(), "cpu": platform.processor() or "?"},
        "mujoco": mujoco.__version__,
        "load_average_1min_at_start": os.getloadavg()[0],
    }
    benches = (bench_build, bench_fk, bench_physics, bench_retarget)
    if args.only:
        benches = tuple(b for b in benches if b.__name__ == f"bench_{args.only}")
    for bench in benches:
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
