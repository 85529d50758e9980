"""Controls for the learned estimators inside envs: the same frames, one thing changed at a time.

Records the frames of an env's expert rollouts with the expert on the truth (feedback off,
so every estimator sees the same frames), then runs fresh estimators on them offline:

- ``grasp``: ``handsim/Grasp-v0`` (structured light, ICVL camera): DeepPrior++ (its estimate
  made in the loop, one estimator over all episodes as ``handsim closed-loop`` runs it)
  against the feedback estimator after 0, 1 and 2 updates, at the localizer's centre and at
  the true middle-finger MCP, and with the hand's length given; per phase of the expert's
  episode.
- ``handpose``: ``handsim/HandPose-v0`` (no sensor noise, ICVL camera): the DeepPrior++
  pipeline (with the localizer's guard, the default, and without it), cropped at the true MCP,
  at the first centre without the refinement CNN, after one refinement step, and, unguarded,
  with the arm's pixels removed and with a flat wall 0.1 m behind the hand; ``--checkpoint``
  picks the pose network (a run's ``best.pt``), e.g. to compare two trainings on these frames,
  and ``--detector`` the first centre (``learned``, as shipped, or ``plane``; also for
  ``walk``).
- ``detectors``: ``handsim/Grasp-v0`` (as ``grasp``): for each detector of ``--detectors``
  (``plane``, ``learned`` or a detector checkpoint), its first centre's and its refined
  centre's distance from the true middle-finger MCP (mm) and the DeepPrior++ pipeline's error
  behind it, per phase of the expert's episode.
- ``walk``: where the localizer's refinement goes, unguarded, on every set of a benchmark
  (``--bench``) and on the HandPose-v0 frames: its displacement from the detector's centre
  after each step, the move the network still asks for at the refined centre (the guard's
  test: more than half the cube), how many frames the guard sends back to the detector's
  centre, and the centre's distance from the true middle-finger MCP at the detector's centre,
  refined and guarded (mm, median / 90th percentile / max, or mean).

Usage: ``python benchmarks/in_loop_controls.py grasp --seeds 0 1 2 3 4 --stride 3 --out
grasp.json``, ``python benchmarks/in_loop_controls.py handpose --seeds 0 --stride 5``, ``python
benchmarks/in_loop_controls.py detectors --seeds 0 1 2 3 --stride 6`` or
``python benchmarks/in_loop_controls.py walk --bench BENCH --seeds 0 1 2 --stride 5``.
Figures are mean keypoint errors over the 21 joints, mm, unless named otherwise.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import handsim.envs  # noqa: F401 (registers the envs)
from handsim.envs.wrappers import EstimatorLoop
from handsim.estimators import DeepPriorEstimator, FeedbackEstimator
from handsim.estimators.deepprior.preprocess import (
    MIDDLE_MCP,
    mirror_depth,
    mirror_intrinsics,
    mirror_points,
)


def _error_mm(keypoints: np.ndarray | None, truth: np.ndarray) -> float:
    if keypoints is None:
        return float("nan")
    return float(np.linalg.norm(keypoints - truth, axis=1).mean() * 1000.0)


def record(env_id: str, env_kwargs: dict, estimator, seeds: list[int], stride: int) -> list[dict]:
    """Frames of the expert on the truth, with the loop's own estimate of each."""
    env = EstimatorLoop(gym.make(env_id, **env_kwargs), estimator, feedback=False)
    frames = []
    try:
        for seed in seeds:
            obs, info = env.reset(seed=seed)
            expert = env.make_expert(np.random.default_rng(seed))
            step, done = 0, False
            while not done:
                if step % stride == 0:
                    base = env.unwrapped
                    frame = base.frame
                    estimate = info["estimate"]
                    frames.append(
                        {
                            "seed": seed,
                            "step": step,
                            "phase": getattr(expert, "phase", "-"),
                            "depth": obs["depth"].copy(),
                            "segmentation": obs.get("segmentation"),
                            "labels": base.scene.label_names,
                            "K": base.obs_intrinsics.K.copy(),
                            "truth": frame.keypoints_cam.copy(),
                            "is_left": base.scene.hand.params.side == "left",
                            "in_loop": estimate.keypoints_cam,
                        }
                    )
                action = expert.act(env.expert_state()).vector
                obs, _, terminated, truncated, info = env.step(action)
                step += 1
                done = terminated or truncated
    finally:
        env.close()
    return frames


def _table(frames: list[dict], columns: dict[str, Callable[[dict], float]]) -> dict:
    errors = {name: np.array([f(fr) for fr in frames]) for name, f in columns.items()}
    phases = list(dict.fromkeys(fr["phase"] for fr in frames))
    out = {"all": {k: float(np.nanmean(v)) for k, v in errors.items()}, "n": len(frames)}
    out["by_phase"] = {}
    for phase in phases:
        m = np.array([fr["phase"] == phase for fr in frames])
        out["by_phase"][phase] = {"n": int(m.sum())}
        out["by_phase"][phase].update({k: float(np.nanmean(v[m])) for k, v in errors.items()})
    return out


def grasp(seeds: list[int], stride: int) -> dict:
    """Grasp-v0: DeepPrior++ (in the loop) against the feedback estimator on the same frames."""
    kwargs = {"obs_mode": "depth", "sensor": "structured_light", "camera": "icvl"}
    frames = record("handsim/Grasp-v0", kwargs, DeepPriorEstimator("deepprior++"), seeds, stride)
    fb = FeedbackEstimator()
    fb_length = FeedbackEstimator(hand_length_m=0.189)  # the envs' default hand
    cache: dict[tuple, list] = {}

    def updates(fr: dict, how: str) -> list:
        key = (id(fr), how)
        if key not in cache:
            est = fb_length if how == "length" else fb
            est.set_side(fr["is_left"])
            centre = fr["truth"][MIDDLE_MCP] if how == "true_centre" else None
            cache[key] = est.predict_iterations(fr["depth"], fr["K"], center=centre, iterations=2)
        return cache[key]

    columns: dict[str, Callable[[dict], float]] = {
        "deepprior++_in_loop": lambda fr: _error_mm(fr["in_loop"], fr["truth"])
    }
    for how in ("localizer", "true_centre", "length"):
        for k in range(3):
            columns[f"feedback_{how}_{k}"] = lambda fr, how=how, k=k: _error_mm(
                (updates(fr, how) or [None] * 3)[k], fr["truth"]
            )
    return _table(frames, columns)


def detectors(seeds: list[int], stride: int, names: list[str]) -> dict:
    """Grasp-v0: each detector's centres and the pipeline behind it, on the same frames."""
    kwargs = {"obs_mode": "depth", "sensor": "structured_light", "camera": "icvl"}
    ests = {name: DeepPriorEstimator("deepprior++", detector=name) for name in names}
    frames = record("handsim/Grasp-v0", kwargs, ests[names[0]], seeds, stride)

    def centre_mm(est: DeepPriorEstimator, fr: dict, refined: bool) -> float:
        depth, K, mcp = fr["depth"], fr["K"], fr["truth"][MIDDLE_MCP]  # noqa: N806
        if est.canonical_side and fr["is_left"]:
            depth, K = mirror_depth(depth), mirror_intrinsics(K, depth.shape[1])  # noqa: N806
            mcp = mirror_points(mcp)
        c = est.localizer.base.localize(depth, K)
        if c is None:
            return float("nan")
        if refined:
            c = est.localizer.refine(depth, K, c)
        return float(np.linalg.norm(c - mcp) * 1000.0)

    def pipeline(est: DeepPriorEstimator, fr: dict) -> float:
        est.reset()
        est.set_side(fr["is_left"])
        return _error_mm(est.predict(fr["depth"], fr["K"]).keypoints_cam, fr["truth"])

    columns: dict[str, Callable[[dict], float]] = {}
    for name, est in ests.items():
        columns[f"{name}: centre"] = lambda fr, est=est: centre_mm(est, fr, False)
        columns[f"{name}: refined centre"] = lambda fr, est=est: centre_mm(est, fr, True)
        columns[f"{name}: pipeline"] = lambda fr, est=est: pipeline(est, fr)
    return _table(frames, columns)


def _handpose_frames(seeds: list[int], stride: int, estimator) -> list[dict]:
    kwargs = {"obs_mode": "depth+segmentation", "sensor": "none", "camera": "icvl"}
    return record("handsim/HandPose-v0", kwargs, estimator, seeds, stride)


def handpose(
    seeds: list[int], stride: int, checkpoint: str = "deepprior++", detector: str = "learned"
) -> dict:
    """HandPose-v0: where DeepPrior++'s crop centre goes, one change at a time.

    The frames are recorded with the expert on the truth, so they are the same for every
    ``checkpoint`` (a pose network behind the shipped localizer).
    """
    est = DeepPriorEstimator(checkpoint, detector=detector)
    raw = DeepPriorEstimator(checkpoint, refine_guard=False, detector=detector)
    frames = _handpose_frames(seeds, stride, est)
    loc = raw.localizer

    def pipeline(depth: np.ndarray, fr: dict, which=raw) -> float:
        which.reset()
        return _error_mm(which.predict(depth, fr["K"]).keypoints_cam, fr["truth"])

    def refined(fr: dict, steps: int) -> float:
        c = loc.base.localize(fr["depth"], fr["K"])
        for _ in range(steps):
            c = loc.refine(fr["depth"], fr["K"], c)
        return _error_mm(raw.predict_at(fr["depth"], fr["K"], c), fr["truth"])

    def without_arm(fr: dict) -> float:
        depth = fr["depth"].copy()
        depth[fr["segmentation"] == fr["labels"].index("arm")] = 0.0
        return pipeline(depth, fr)

    def wall(fr: dict) -> float:
        depth = fr["depth"].copy()
        z_wall = fr["truth"][:, 2].max() + 0.1
        depth[(depth == 0) | (depth > z_wall)] = z_wall
        return pipeline(depth, fr)

    loc.iterations = 1  # refined() steps one at a time
    columns = {
        "first_centre": lambda fr: refined(fr, 0),
        "one_refinement": lambda fr: refined(fr, 1),
    }
    result_one = _table(frames, columns)
    loc.iterations = 3  # the shipped pipeline's
    columns = {
        "pipeline": lambda fr: pipeline(fr["depth"], fr, est),
        "pipeline_unguarded": lambda fr: pipeline(fr["depth"], fr),
        "true_centre": lambda fr: _error_mm(
            raw.predict_at(fr["depth"], fr["K"], fr["truth"][MIDDLE_MCP]), fr["truth"]
        ),
        "without_arm_unguarded": without_arm,
        "wall_0.1m_behind_unguarded": wall,
    }
    result = _table(frames, columns)
    result["all"].update(result_one["all"])
    for phase, row in result_one["by_phase"].items():
        result["by_phase"][phase].update(row)
    return result


def _walk_rows(items, est: DeepPriorEstimator) -> dict:
    """The refinement's path on ``items`` ((depth, K, truth, is_left) each), unguarded."""
    loc = est.localizer
    steps, residual, err = [], [], []
    for depth, K, truth, is_left in items:  # noqa: N806
        if est.canonical_side and is_left:  # as the pipeline sees a left hand
            depth, K = mirror_depth(depth), mirror_intrinsics(K, depth.shape[1])  # noqa: N806
            truth = mirror_points(truth)
        c = loc.base.localize(depth, K)
        if c is None:
            continue
        path, move, lost = loc.path(depth, K, c)
        steps.append([np.linalg.norm(p - path[0]) for p in path[1:]])
        residual.append(np.linalg.norm(move))
        kept = path[0] if lost else path[-1]
        err.append([np.linalg.norm(p - truth[MIDDLE_MCP]) for p in (path[0], path[-1], kept)])
    steps_mm, residual_mm = 1000 * np.array(steps), 1000 * np.array(residual)
    err_mm = 1000 * np.array(err)

    def spread(x: np.ndarray) -> list[float]:
        return [round(float(v), 1) for v in np.percentile(x, [50, 90, 100])]

    return {
        "n": len(err),
        "displacement_mm_after_step": {
            str(k + 1): spread(steps_mm[:, k]) for k in range(steps_mm.shape[1])
        },
        "residual_mm": spread(residual_mm),
        "guard_fires": int(np.count_nonzero(residual_mm > 1000 * loc.cube_m / 2)),  # as path()
        "mcp_error_mm_mean": {
            "detector": round(float(err_mm[:, 0].mean()), 1),
            "refined": round(float(err_mm[:, 1].mean()), 1),
            "guarded": round(float(err_mm[:, 2].mean()), 1),
        },
    }


def walk(seeds: list[int], stride: int, bench: str | None, detector: str = "learned") -> dict:
    """The refinement's path on a benchmark's sets and on HandPose-v0's frames."""
    from pathlib import Path

    from handsim.cli.benchmark_sets import read_benchmark, valid_frames

    est = DeepPriorEstimator("deepprior++", refine_guard=False, detector=detector)
    out = {}
    if bench:
        for name, info in read_benchmark(bench)["sets"].items():
            folder = Path(bench) / info["folder"]
            items = (
                (
                    np.asarray(a["depth"]),
                    np.asarray(a["K"], np.float64),
                    np.asarray(a["keypoints_cam"], np.float64),
                    bool(a["is_left"]),
                )
                for a in valid_frames(folder)
            )
            out[name] = _walk_rows(items, est)
    frames = _handpose_frames(seeds, stride, est)
    items = [(fr["depth"], fr["K"], fr["truth"], fr["is_left"]) for fr in frames]
    out["HandPose-v0"] = _walk_rows(items, est)
    return out


def main() -> None:
    """Print the tables as JSON; ``--out`` writes them too."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("env", choices=("grasp", "handpose", "walk", "detectors"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--stride", type=int, default=3, help="keep every N-th step")
    parser.add_argument("--bench", default=None, help="walk: a handsim-bench folder")
    parser.add_argument(
        "--checkpoint", default="deepprior++", help="handpose: the pose network (default: shipped)"
    )
    parser.add_argument(
        "--detector", default="learned", help="handpose, walk: the first centre (or plane)"
    )
    parser.add_argument(
        "--detectors", nargs="+", default=["plane", "learned"], help="detectors: which"
    )
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    if args.env == "walk":
        result = walk(args.seeds, args.stride, args.bench, args.detector)
    elif args.env == "grasp":
        result = grasp(args.seeds, args.stride)
    elif args.env == "detectors":
        result = detectors(args.seeds, args.stride, args.detectors)
    else:
        result = handpose(args.seeds, args.stride, args.checkpoint, args.detector)
    result.update({"env": args.env, "seeds": args.seeds, "stride": args.stride})
    if args.env == "handpose":
        result["checkpoint"] = args.checkpoint
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
