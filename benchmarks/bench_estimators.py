"""Learned estimators on one CPU core at batch 1, preprocessing included: frames/s.

Measured in one run, on this machine, with ``torch.set_num_threads(1)`` (and OpenCV's
``cv2.setNumThreads(1)``), on hand-only structured-light frames (320 x 240):

- preprocessing alone: the learned whole-image hand detector (the default first centre);
  RANSAC plane removal + nearest-blob centre of mass (``detector="plane"``); the refined
  localizer (3 iterations of the 64 x 64 CNN); the 128 x 128 crop;
- the centre of mass of the nearest depth slab (``detector="com"``) alone;
- the whole pipeline (``DeepPriorEstimator.predict``: checks, localization, refinement, crop,
  network, inverse normalization) for DeepPrior (the paper's deep network, FC 1024, with the
  prior; and the shipped one, ``weights/deepprior.json``, when its config differs) and for
  DeepPrior++ at the paper's width and at the shipped width (``weights/deepprior_pp.json``),
  each with the learned detector (the default) and with ``detector="plane"``;
- DeepPrior as its paper ran it (``detector="com"``, no refinement CNN: the centre of mass of
  the nearest depth slab, which fits hand-only frames, not a table scene), for both DeepPrior
  networks;
- each against its target (DeepPrior >= 500 frames/s, DeepPrior++ >= 60 frames/s) as a ratio;
- the closed loop: ``handsim/Grasp-v0`` steps per second with the shipped DeepPrior++ in
  :class:`~handsim.envs.wrappers.EstimatorLoop` (expert on the truth, the same seeds), the
  detector in every frame against ``track=True`` (the previous frame's centre refined), with
  the mean keypoint error of each (tracking must not cost accuracy), against 50 steps/s.

Speed does not depend on the weights: every pose network is timed with random weights of its
config (the shipped localizer refines), cropped as the shipped network of its family was
trained (its checkpoint's ``crop``: the refinement steps the pipeline runs; 3 without one).
The machine's load average is recorded (a shared machine is slower).

``--profile`` adds the time of each stage of one frame through the shipped DeepPrior and
DeepPrior++ pipelines and DeepPrior's with the paper's FC 1024 network
(``DeepPriorEstimator``'s own steps, in its order: the input checks, the detector (learned, as
shipped), each refinement step's crop and network, the pose crop, the pose network, the
keypoints),
median and mean ms over the frames and repeats, beside the whole ``predict`` on the same
frames.

``--baseline REV`` times the whole pipeline (shipped DeepPrior, the paper's FC 1024 network)
with the preprocessing module (detector and crop) of git revision ``REV`` and with the current
one, alternating in rounds in this process: a before/after ratio that the machine's load
weighs on equally.

Usage: ``python benchmarks/bench_estimators.py [--data DIR] [--frames 100] [--profile]
[--baseline REV]``; without ``--data`` it generates 60 hand-only frames in a temporary folder.
Writes ``benchmarks/results/bench_estimators.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

TARGET_FPS = {"deepprior": 500.0, "deepprior++": 60.0}
TARGET_LOOP_STEPS_S = 50.0


def _frames(data: str | None, n: int):
    from handsim.estimators.deepprior.data import load_frames

    if data is None:
        from handsim.data.generation import GenerationConfig, generate

        tmp = tempfile.mkdtemp(prefix="bench_estimators_")
        config = GenerationConfig(
            frames=60,
            frames_per_shard=60,
            frames_per_episode=10,
            num_objects_range=(0, 0),
            viewpoints=("third_person",),
            sensor="structured_light",
        )
        generate(config, tmp)
        data = tmp
    frames = load_frames(data, "all", max_frames=n)
    return [frames.depth(i) for i in range(len(frames))], list(frames.K)


def _rate(fn, items, repeat: int = 2) -> float:
    fn(*items[0])  # warm-up
    start = time.perf_counter()
    for _ in range(repeat):
        for item in items:
            fn(*item)
    return repeat * len(items) / (time.perf_counter() - start)


def _shipped_crop(name: str) -> dict | None:
    """How the shipped network ``name`` (deepprior, deepprior_pp) was cropped in training."""
    from handsim.estimators.deepprior.checkpoint import WEIGHTS_DIR

    path = WEIGHTS_DIR / f"{name}.json"
    return json.loads(path.read_text()).get("crop") if path.is_file() else None


def _estimator(config: dict, folder: Path, **kwargs):
    """A DeepPriorEstimator of a model config (random weights of that config).

    Its refinement steps are those of the shipped network of its family (the checkpoint's
    ``crop``): the pipeline as shipped, with this network in it.
    """
    import torch

    from handsim.estimators.deepprior.checkpoint import save_checkpoint
    from handsim.estimators.deepprior.estimator import DeepPriorEstimator
    from handsim.estimators.deepprior.models import build_model

    torch.manual_seed(0)
    path = folder / f"{config['arch']}_{config.get('width', 1)}_{config.get('fc', 1024)}.pt"
    meta = {"model": config, "cube_m": 0.25}
    crop = _shipped_crop("deepprior_pp" if config["arch"] == "resnet" else "deepprior")
    if crop:
        meta["crop"] = crop
    save_checkpoint(path, {"model": build_model(config).state_dict()}, meta)
    return DeepPriorEstimator(path, **kwargs)


def _profile(estimator, items: list, repeat: int = 5) -> dict:
    """Ms of each stage of the shipped pipeline on one frame, and of the whole predict.

    The stages call what ``DeepPriorEstimator.predict`` calls, in its order.
    """
    import numpy as np
    import torch

    from handsim.estimator import validate_depth_input
    from handsim.estimators.deepprior import preprocess as P
    from handsim.estimators.deepprior.estimator import DeepPriorEstimator, _as_input

    est = DeepPriorEstimator(estimator) if isinstance(estimator, str) else estimator
    loc = est.localizer
    clock = time.perf_counter

    def stages(depth, K):  # noqa: N803
        t = [clock()]
        depth_m, K_cv = validate_depth_input(depth, K)  # noqa: N806
        t.append(clock())
        c = loc.base.localize(depth_m, K_cv)
        t.append(clock())
        if c is None:
            return None
        with torch.inference_mode():
            for _ in range(loc.iterations):
                x = P.crop_depth(
                    depth_m,
                    P.crop_matrix(c, K_cv, loc.cube_m, loc.size),
                    c[2],
                    loc.cube_m,
                    loc.size,
                )
                t.append(clock())
                off = loc._forward(_as_input(x[None, None], loc.device))
                c = c + off[0].double().cpu().numpy() * (loc.cube_m / 2.0)
                t.append(clock())
            x = P.crop_depth(
                depth_m, P.crop_matrix(c, K_cv, est.cube_m, est.size), c[2], est.cube_m, est.size
            )
            t.append(clock())
            y = est._forward(_as_input(x[None, None], est.device))[0].double().cpu().numpy()
            t.append(clock())
        P.denormalize_keypoints(y.reshape(21, 3), c, est.cube_m)
        t.append(clock())
        return np.diff(t)

    names = ["checks", "detector"]
    for i in range(loc.iterations):
        names += [f"refine {i + 1} crop", f"refine {i + 1} network"]
    names += ["pose crop", "pose network", "keypoints"]
    for item in items[:3]:  # warm-up
        stages(*item)
        est.predict(*item)
    rows, whole = [], []
    for _ in range(repeat):
        for depth, K in items:  # noqa: N806
            row = stages(depth, K)
            if row is not None:
                rows.append(row)
            start = clock()
            est.predict(depth, K)
            whole.append(clock() - start)
    # Medians (a shared machine's preemptions land in the means) and means.
    median, mean = 1000.0 * np.median(rows, axis=0), 1000.0 * np.mean(rows, axis=0)
    return {
        "stages_ms_median": dict(zip(names, median.round(4).tolist(), strict=True)),
        "stages_ms_mean": dict(zip(names, mean.round(4).tolist(), strict=True)),
        "sum_of_stage_medians_ms": float(median.sum()),
        "predict_ms_median": 1000.0 * float(np.median(whole)),
        "predict_ms_mean": 1000.0 * float(np.mean(whole)),
        "frames_timed": len(rows),
    }


def _baseline(rev: str, estimators: dict, items: list, rounds: int = 8) -> dict:
    """Whole-pipeline ms with ``rev``'s preprocess module and the current one, alternating."""
    import importlib.util
    import subprocess
    import sys

    import numpy as np

    from handsim.estimators.deepprior import estimator as E  # noqa: N812
    from handsim.estimators.deepprior import preprocess as current

    root = Path(__file__).resolve().parent.parent
    source = subprocess.run(
        ["git", "show", f"{rev}:estimators/deepprior/preprocess.py"],
        cwd=root,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "preprocess_baseline.py"
        path.write_text(source)
        spec = importlib.util.spec_from_file_location("_preprocess_baseline", path)
        old = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = old  # dataclasses look their module up
        spec.loader.exec_module(old)
    out = {}
    for name, est in estimators.items():
        times: dict[str, list[float]] = {"baseline": [], "current": []}
        for _ in range(rounds):
            for tag, module in (("baseline", old), ("current", current)):
                est.localizer.base = module.PlaneRemovedLocalizer()
                E.crop_depth, E.crop_matrix = module.crop_depth, module.crop_matrix
                for item in items[:3]:  # warm-up
                    est.predict(*item)
                start = time.perf_counter()
                for item in items:
                    est.predict(*item)
                times[tag].append((time.perf_counter() - start) / len(items))
        E.crop_depth, E.crop_matrix = current.crop_depth, current.crop_matrix
        est.localizer.base = current.PlaneRemovedLocalizer()
        base_s, cur_s = float(np.median(times["baseline"])), float(np.median(times["current"]))
        out[name] = {
            "baseline_fps": 1.0 / base_s,
            "current_fps": 1.0 / cur_s,
            "speedup": base_s / cur_s,
            "rounds": rounds,
        }
    return {"revision": rev, "pipelines": out}


def _loop(episodes: int) -> dict:
    """Grasp-v0 steps/s and mean keypoint error with DeepPrior++ in the loop, track off / on."""
    import gymnasium as gym
    import numpy as np

    import handsim.envs  # noqa: F401 (registers the ids)
    from handsim.envs.wrappers import EstimatorLoop
    from handsim.estimators.deepprior.estimator import DeepPriorEstimator

    out = {}
    for name, track in (("deepprior++ detector every frame", False), ("deepprior++ track", True)):
        env = EstimatorLoop(
            gym.make("handsim/Grasp-v0", obs_mode="depth"),
            # Tracking follows the hand through the refinement: three steps, as before.
            DeepPriorEstimator(track=True, refine_iterations=3) if track else DeepPriorEstimator(),
        )
        steps, errors, elapsed, est_s = 0, [], 0.0, 0.0
        for seed in range(episodes):
            _, info = env.reset(seed=seed)
            expert = env.make_expert(np.random.default_rng(seed))
            done = False
            start = time.perf_counter()
            while not done:
                action = expert.act(env.expert_state()).vector
                _, _, terminated, truncated, info = env.step(action)
                steps += 1
                est_s += info.get("estimator_time_s", 0.0)
                errors.append(info["estimate_errors"]["kp_mean_mm"])
                done = terminated or truncated
            elapsed += time.perf_counter() - start
        env.close()
        out[name] = {
            "steps": steps,
            "steps_per_s": steps / elapsed,
            "estimator_ms_mean": 1000.0 * est_s / steps,
            "kp_mean_mm": float(np.nanmean(errors)),
        }
    return out


def main() -> None:
    """Run the benchmark and write the JSON."""
    import cv2
    import torch

    from handsim.estimators.com import CenterOfMassLocalizer
    from handsim.estimators.deepprior import preprocess as P
    from handsim.estimators.deepprior.checkpoint import WEIGHTS_DIR
    from handsim.estimators.deepprior.detector import LearnedDetector
    from handsim.estimators.deepprior.estimator import RefinedLocalizer

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", default=None, help="a hand-only dataset folder")
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument(
        "--loop-episodes", type=int, default=2, help="Grasp-v0 episodes per loop variant (0: none)"
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="also time each stage of the shipped DeepPrior and DeepPrior++ pipelines",
    )
    parser.add_argument(
        "--baseline",
        metavar="REV",
        default=None,
        help="also time the pipeline with git revision REV's preprocessing, alternating",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    depths, Ks = _frames(args.data, args.frames)  # noqa: N806
    items = list(zip(depths, Ks, strict=True))
    base = P.PlaneRemovedLocalizer()
    loc = RefinedLocalizer("localizer")
    centers = [base.localize(d, k) for d, k in items]
    found = [(d, k, c) for (d, k), c in zip(items, centers, strict=True) if c is not None]
    results: dict = {
        "frames": len(items),
        "frames_with_blob": len(found),
        "torch_threads": torch.get_num_threads(),
        "opencv_threads": cv2.getNumThreads(),
        "load_average_1min": os.getloadavg()[0],
        "cpu_count": os.cpu_count(),
        "fps": {},
    }
    fps = results["fps"]
    fps["learned_detector"] = _rate(LearnedDetector().localize, items)
    fps["plane_removed_com"] = _rate(base.localize, items)
    fps["com_detector"] = _rate(CenterOfMassLocalizer().localize, items)
    fps["refine_3_iterations"] = _rate(loc.refine, found)
    fps["crop_128"] = _rate(
        lambda d, k, c: P.crop_depth(d, P.crop_matrix(c, k), c[2]), found, repeat=5
    )
    shipped_pp = WEIGHTS_DIR / "deepprior_pp.json"
    pp_width = 0.25
    if shipped_pp.is_file():
        pp_width = json.loads(shipped_pp.read_text())["model"].get("width", 1.0)
    pp = {"arch": "resnet", "size": 128, "fc": 1024, "prior_dim": 30}
    deep = {"arch": "deep", "size": 128, "fc": 1024, "prior_dim": 30}
    configs = {"deepprior": deep, "deepprior++ (width 1)": pp}
    shipped_deep = WEIGHTS_DIR / "deepprior.json"
    if shipped_deep.is_file():
        model = json.loads(shipped_deep.read_text())["model"]
        if any(model.get(k) != v for k, v in deep.items()):
            configs[f"deepprior (FC {model['fc']}, as shipped)"] = model
    if pp_width != 1.0:
        configs[f"deepprior++ (width {pp_width}, as shipped)"] = {**pp, "width": pp_width}
    ratios = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, config in configs.items():
            target = TARGET_FPS["deepprior++" if name.startswith("deepprior++") else "deepprior"]
            for detector, label in (("learned", name), ("plane", f"{name}, plane detector")):
                est = _estimator(config, Path(tmp), detector=detector)
                fps[f"pipeline {label}"] = _rate(est.predict, items)
                ratios[label] = fps[f"pipeline {label}"] / target
        # DeepPrior as its paper ran it: the centre of mass of the nearest slab, no refinement
        # CNN (the refinement came with DeepPrior++; the plane fit is for table scenes).
        for net in [n for n in configs if n.startswith("deepprior ") or n == "deepprior"]:
            name = f"{net} (paper's pipeline: CoM detector, no refinement)"
            est = _estimator(configs[net], Path(tmp), localizer=None, detector="com")
            fps[f"pipeline {name}"] = _rate(est.predict, items)
            ratios[name] = fps[f"pipeline {name}"] / TARGET_FPS["deepprior"]
    if args.baseline:
        from handsim.estimators.deepprior.estimator import DeepPriorEstimator

        with tempfile.TemporaryDirectory() as tmp:
            pipelines = {
                "deepprior (FC 512, as shipped)": DeepPriorEstimator("deepprior"),
                "deepprior": _estimator(deep, Path(tmp)),
            }
            results["baseline"] = _baseline(args.baseline, pipelines, items)
    if args.profile:
        results["profile"] = {name: _profile(name, items) for name in ("deepprior", "deepprior++")}
        with tempfile.TemporaryDirectory() as tmp:
            results["profile"]["deepprior (paper's FC 1024)"] = _profile(
                _estimator(deep, Path(tmp)), items
            )
    if args.loop_episodes:
        results["loop"] = _loop(args.loop_episodes)
        for name, value in results["loop"].items():
            ratios[f"loop {name}"] = value["steps_per_s"] / TARGET_LOOP_STEPS_S
    results["ratio_to_target"] = ratios
    results["targets_fps"] = TARGET_FPS
    out = Path(__file__).parent / "results" / "bench_estimators.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
