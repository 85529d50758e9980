"""Closed-loop evaluation: an expert does a task while an estimator runs in every step.

:func:`evaluate_closed_loop` runs N episodes of an env with the env's scripted expert and an
estimator inside :class:`~handsim.envs.wrappers.EstimatorLoop`, once with feedback off (the
expert acts on the truth; the estimator is only measured) and once with feedback on (the
expert acts on the estimate), on the same seeds. It reports, per mode:

- per-frame estimation errors: mean keypoint error, F(tau) of the max keypoint error and its
  AUC over 0-80 mm (:mod:`handsim.metrics`), hand-centre error, and the mean keypoint error by
  occlusion bucket, where a frame's occlusion is the fraction of its 21 keypoints that are not
  visible (:attr:`handsim.frame.Frame.visible`), in buckets [0, 0.25), [0.25, 0.5),
  [0.5, 0.75), [0.75, 1];
- task success: the fraction of episodes with ``info["is_success"]`` at their end (an episode
  whose expert finds no plan for the perceived state, e.g. no collision-free grasp for a noisy
  object pose, is a failure with ``"no_plan"`` and no frames);
- the estimator's mean time per call.

:func:`write_report` saves it as JSON with an F(tau) plot and a success bar plot (PNG).
``handsim closed-loop`` is the command-line entry point.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from handsim import metrics
from handsim.envs.wrappers import EstimatorLoop
from handsim.errors import HandSimError
from handsim.estimator import Estimator

__all__ = ["evaluate_closed_loop", "write_report", "OCCLUSION_EDGES"]

OCCLUSION_EDGES: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)
"""Bucket edges of the per-frame keypoint occlusion fraction."""


def _run_mode(
    env_id: str,
    make_estimator: Callable[[], Estimator],
    feedback: bool,
    episodes: int,
    seed: int,
    env_kwargs: dict[str, Any],
) -> dict[str, Any]:
    env = EstimatorLoop(gym.make(env_id, **env_kwargs), make_estimator(), feedback=feedback)
    frame_max, frame_mean, center, occlusion, times = [], [], [], [], []
    outcomes = []
    try:
        for episode in range(episodes):
            _, info = env.reset(seed=seed + episode)
            try:
                expert = env.make_expert(np.random.default_rng(seed + episode))
            except HandSimError as err:
                # E.g. no collision-free grasp for the perceived object pose: a failed episode.
                outcomes.append(
                    {"seed": seed + episode, "success": False, "steps": 0, "no_plan": str(err)}
                )
                continue
            steps, done = 0, False
            while True:
                errors, frame = info.get("estimate_errors"), info["frame"]
                if errors is not None and frame is not None:
                    frame_max.append(errors["kp_max_mm"])
                    frame_mean.append(errors["kp_mean_mm"])
                    center.append(errors["center_mm"])
                    occlusion.append(1.0 - float(np.mean(frame.visible)))
                    times.append(info["estimator_time_s"])
                if done:
                    break
                action = expert.act(env.expert_state()).vector
                _, _, terminated, truncated, info = env.step(action)
                steps += 1
                done = terminated or truncated
            outcomes.append(
                {
                    "seed": seed + episode,
                    "success": bool(info.get("is_success", False)),
                    "steps": steps,
                    "physics_diverged": bool(info.get("physics_diverged", False)),
                }
            )
    finally:
        env.close()
    frame_max_mm = np.array(frame_max, dtype=np.float64)
    frame_mean_mm = np.array(frame_mean, dtype=np.float64)
    # A frame without a keypoint estimate (dropout, a localizer) fails every threshold.
    frame_max_mm[np.isnan(frame_max_mm)] = np.inf
    taus = metrics.threshold_grid_mm()
    f_tau = metrics.fraction_of_frames_within(frame_max_mm, taus)
    finite = np.isfinite(frame_mean_mm)
    buckets = metrics.errors_by_occlusion(
        np.where(finite, frame_mean_mm, np.nan), np.array(occlusion), OCCLUSION_EDGES
    )
    center_mm = np.array(center, dtype=np.float64)
    return {
        "feedback": feedback,
        "episodes": outcomes,
        "success_rate": float(np.mean([o["success"] for o in outcomes])),
        "n_frames": int(frame_max_mm.size),
        "n_frames_with_keypoints": int(finite.sum()),
        "kp_mean_mm": float(np.mean(frame_mean_mm[finite])) if finite.any() else math.nan,
        "kp_max_mean_mm": (float(np.mean(frame_max_mm[finite])) if finite.any() else math.nan),
        "center_mm": (float(np.nanmean(center_mm)) if np.isfinite(center_mm).any() else math.nan),
        "f_tau_thresholds_mm": [float(t) for t in taus],
        "f_tau": [float(v) for v in f_tau],
        "f_tau_auc": metrics.curve_auc(taus, f_tau),
        "by_occlusion": [
            {
                "occlusion": [b.lower, b.upper],
                "n_frames": b.n_frames,
                "kp_mean_mm": b.mean,
            }
            for b in buckets
        ],
        "estimator_time_mean_s": float(np.mean(times)) if times else math.nan,
    }


def evaluate_closed_loop(
    env_id: str,
    make_estimator: Callable[[], Estimator],
    *,
    episodes: int = 5,
    seed: int = 0,
    env_kwargs: dict[str, Any] | None = None,
    feedback_modes: tuple[bool, ...] = (False, True),
) -> dict[str, Any]:
    """Run the env's expert with an estimator in the loop, feedback off and on.

    Args:
        env_id: a registered handsim id (its env must have ``make_expert``).
        make_estimator: builds a fresh estimator (called once per feedback mode, so both modes
            start from the same estimator state).
        episodes: episodes per mode (seeds ``seed ... seed + episodes - 1``).
        seed: first seed.
        env_kwargs: keyword arguments of ``gym.make`` (need a depth ``obs_mode``).
        feedback_modes: which modes to run.

    Returns:
        ``{"env_id", "env_kwargs", "episodes", "seed", "modes": {"feedback_off": ...,
        "feedback_on": ...}}``, JSON-serializable (the module docstring lists each figure).

    Raises:
        ValueError: for ``episodes < 1``.
    """
    if not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be an int >= 1; received {episodes!r}")
    kwargs = dict(env_kwargs or {})
    modes = {
        ("feedback_on" if feedback else "feedback_off"): _run_mode(
            env_id, make_estimator, feedback, episodes, seed, kwargs
        )
        for feedback in feedback_modes
    }
    return {
        "env_id": env_id,
        "env_kwargs": kwargs,
        "episodes": episodes,
        "seed": seed,
        "modes": modes,
    }


def write_report(report: dict[str, Any], out_dir: str | Path) -> dict[str, Path]:
    """Write ``closed_loop.json``, ``f_tau.png`` and ``success.png`` into ``out_dir``.

    Returns:
        The written paths by kind (``"json"``, ``"f_tau"``, ``"success"``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "closed_loop.json"}
    paths["json"].write_text(json.dumps(report, indent=2, allow_nan=True))
    fig, ax = plt.subplots(figsize=(5, 4))
    for name, mode in report["modes"].items():
        ax.plot(
            mode["f_tau_thresholds_mm"],
            100 * np.array(mode["f_tau"]),
            label=f"{name.replace('_', ' ')} (AUC {mode['f_tau_auc']:.3f})",
        )
    ax.set_xlabel("Distance threshold tau / mm")
    ax.set_ylabel("Frames with max keypoint error <= tau / %")
    ax.set_ylim(0, 100)
    ax.grid(True, alpha=0.3)
    ax.legend()
    ax.set_title(report["env_id"])
    paths["f_tau"] = out / "f_tau.png"
    fig.tight_layout()
    fig.savefig(paths["f_tau"], dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(4, 3.5))
    names = list(report["modes"])
    rates = [100 * report["modes"][n]["success_rate"] for n in names]
    ax.bar([n.replace("_", " ") for n in names], rates, color=["#4c72b0", "#dd8452"][: len(names)])
    for i, rate in enumerate(rates):
        ax.text(i, rate + 1, f"{rate:.0f} %", ha="center")
    ax.set_ylim(0, 110)
    ax.set_ylabel(f"Task success / % of {report['episodes']} episodes")
    ax.set_title(report["env_id"])
    paths["success"] = out / "success.png"
    fig.tight_layout()
    fig.savefig(paths["success"], dpi=100)
    plt.close(fig)
    return paths
