"""Closed-loop evaluation: an expert does a task while an estimator runs in every step.

:func:`evaluate_closed_loop` runs N episodes of an env with the env's scripted expert and an
estimator inside :class:`~handsim.envs.wrappers.EstimatorLoop`, once with feedback off (the
expert acts on the truth; the estimator is only measured) and once with feedback on (the
expert acts on the estimate), on the same seeds. It reports, per mode:

- per-frame estimation errors: mean keypoint error, F(tau) of the max keypoint error and its
  AUC over 0-80 mm (:mod:`handsim.metrics`), hand-centre error, and the mean keypoint error by
  occlusion bucket, where a frame's occlusion is the fraction of its 21 keypoints that are not
  visible (:attr:`handsim.frame.record.Frame.visible`), in buckets [0, 0.25), [0.25, 0.5),
  [0.5, 0.75), [0.75, 1];
- task success: the fraction of episodes with ``info["is_success"]`` at their end (an episode
  whose expert finds no plan for the perceived state, e.g. no collision-free grasp for a noisy
  object pose, is a failure with ``"no_plan"`` and no frames);
- the estimator's mean time per call;
- per episode: the target object (``None`` for envs without one) and the mean keypoint error of
  every frame (``None`` where the estimate has no keypoints), so error over time and success
  per object can be plotted.

With a ``media_dir`` it also draws (:mod:`handsim.viz`) the frame of largest keypoint error of
each mode (``worst_frame_<mode>.png``) and, with ``video=True``, one MP4 per mode and episode
(``video/<mode>_ep<seed>.mp4``) of the depth with the estimated and the true skeleton
(:func:`handsim.viz.draw_estimate`; sensors up to 400 pixels wide at twice their resolution).

:func:`write_report` saves it as strict JSON (non-finite numbers as ``null``) with plots (PNG)
of F(tau), success per mode, error over time, error by occlusion bucket and success per object;
every plot title names the env and the estimator with its settings.
``handsim closed-loop`` is the command-line entry point.
"""

from __future__ import annotations

import json
import math
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import gymnasium as gym
import numpy as np

from handsim import metrics, viz
from handsim.envs.wrappers import EstimatorLoop
from handsim.errors import HandSimError
from handsim.estimator import Estimator, describe_estimator
from handsim.metrics._common import to_strict_json  # noqa: F401 (part of this module's API)

__all__ = [
    "evaluate_closed_loop",
    "write_report",
    "to_strict_json",
    "estimator_label",
    "OCCLUSION_EDGES",
]

OCCLUSION_EDGES: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)
"""Bucket edges of the per-frame keypoint occlusion fraction."""

_SMALL_WIDTH = 400  # sensors up to this wide (320x240) are drawn at twice their resolution


def estimator_label(report: dict[str, Any]) -> str:
    """The estimator and its settings as the report names it.

    Its own description (:func:`~handsim.estimator.describe_estimator`); for one that has
    none, the command line's ``module:Class:{kwargs}`` spec when the report has it, else the
    class name.
    """
    estimator = report.get("estimator")
    if isinstance(estimator, dict):
        if not estimator.get("describes_itself", True) and estimator.get("spec"):
            return str(estimator["spec"])
        return str(estimator.get("repr") or estimator.get("name") or "estimator")
    return str(estimator) if estimator else "estimator"


def _episode_object(env: gym.Env, info: dict[str, Any]) -> str | None:
    target = getattr(env.unwrapped, "target_instance", None)
    frame = info.get("frame")
    if target is None or frame is None or target >= len(frame.objects):
        return None
    return frame.objects[target].name


class _Media:
    """Pictures of one mode: the worst frame (PNG) and, optionally, MP4s per episode."""

    def __init__(self, media_dir: Path | None, mode: str, video: bool, fps: float) -> None:
        self.dir, self.mode, self.video, self.fps = media_dir, mode, video, fps
        self.worst_mm = -math.inf
        self.worst: dict[str, Any] | None = None
        self.writer: viz.VideoWriter | None = None
        self.videos: list[dict[str, Any]] = []
        self.range_m: tuple[float, float] | None = None

    def start_episode(self, seed: int) -> None:
        self.range_m: tuple[float, float] | None = None
        if self.dir is not None and self.video:
            path = self.dir / "video" / f"{self.mode}_ep{seed:03d}.mp4"
            self.writer = viz.VideoWriter(path, fps=self.fps)
            self.videos.append({"seed": seed, "path": str(path), "n_frames": 0})

    def add(self, obs: dict[str, Any], info: dict[str, Any], seed: int, step: int) -> None:
        if self.dir is None or "depth" not in obs:
            return
        errors, frame = info.get("estimate_errors"), info.get("frame")
        if frame is None:
            return
        error = errors["kp_max_mm"] if errors is not None else math.nan
        image = None
        if self.writer is not None:
            image = self._draw(obs, info, frame)
            self.writer.append(image)
            self.videos[-1]["n_frames"] += 1
        if math.isfinite(error) and error > self.worst_mm:
            if image is None:
                image = self._draw(obs, info, frame)
            self.worst_mm = error
            path = self.dir / f"worst_frame_{self.mode}.png"
            cv2.imwrite(str(path), image)
            self.worst = {"seed": seed, "step": step, "kp_max_mm": error, "path": str(path)}

    def _draw(self, obs: dict[str, Any], info: dict[str, Any], frame: Any) -> np.ndarray:
        depth = obs["depth"]
        if self.range_m is None:  # one colour range per episode: steady colours in a video
            self.range_m = viz.depth_range_m(depth)
        upscale = 2 if depth.shape[-1] <= _SMALL_WIDTH else 1
        near, far = self.range_m
        estimate = info.get("estimate")
        return viz.draw_estimate(depth, frame, estimate, near_m=near, far_m=far, upscale=upscale)

    def end_episode(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None

    def summary(self) -> dict[str, Any]:
        return {"worst_frame": self.worst, "videos": self.videos}


def _run_mode(
    env_id: str,
    make_estimator: Callable[[], Estimator],
    feedback: bool,
    episodes: int,
    seed: int,
    env_kwargs: dict[str, Any],
    progress: Callable[[int], None] | None,
    media: _Media,
) -> dict[str, Any]:
    estimator = make_estimator()
    env = EstimatorLoop(gym.make(env_id, **env_kwargs), estimator, feedback=feedback)
    max_steps = env.spec.max_episode_steps if env.spec is not None else None
    frame_max, frame_mean, center, occlusion, times = [], [], [], [], []
    outcomes = []
    try:
        for episode in range(episodes):
            episode_seed = seed + episode
            obs, info = env.reset(seed=episode_seed)
            target = _episode_object(env, info)
            try:
                expert = env.make_expert(np.random.default_rng(episode_seed))
            except HandSimError as err:
                # E.g. no collision-free grasp for the perceived object pose: a failed episode.
                outcomes.append(
                    {
                        "seed": episode_seed,
                        "object": target,
                        "success": False,
                        "steps": 0,
                        "no_plan": str(err),
                        "kp_mean_mm": [],
                    }
                )
                if progress is not None and max_steps:
                    progress(max_steps)
                continue
            media.start_episode(episode_seed)
            steps, done, series = 0, False, []
            try:
                while True:
                    errors, frame = info.get("estimate_errors"), info["frame"]
                    if errors is not None and frame is not None:
                        frame_max.append(errors["kp_max_mm"])
                        frame_mean.append(errors["kp_mean_mm"])
                        center.append(errors["center_mm"])
                        occlusion.append(1.0 - float(np.mean(frame.visible)))
                        times.append(info["estimator_time_s"])
                        series.append(errors["kp_mean_mm"])
                    media.add(obs, info, episode_seed, steps)
                    if done:
                        break
                    action = expert.act(env.expert_state()).vector
                    obs, _, terminated, truncated, info = env.step(action)
                    steps += 1
                    if progress is not None:
                        progress(1)
                    done = terminated or truncated
            finally:
                media.end_episode()
            if progress is not None and max_steps and steps < max_steps:
                progress(max_steps - steps)  # an episode that ended early
            outcomes.append(
                {
                    "seed": episode_seed,
                    "object": target,
                    "success": bool(info.get("is_success", False)),
                    "steps": steps,
                    "physics_diverged": bool(info.get("physics_diverged", False)),
                    "kp_mean_mm": [float(e) for e in series],
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
    if not finite.any():  # no keypoints at all: no curve exists (null in the JSON, not 0)
        f_tau = np.full(len(taus), math.nan)
    buckets = metrics.errors_by_occlusion(
        np.where(finite, frame_mean_mm, np.nan), np.array(occlusion), OCCLUSION_EDGES
    )
    center_mm = np.array(center, dtype=np.float64)
    by_object: dict[str, list[bool]] = {}
    for o in outcomes:
        by_object.setdefault(o["object"] or "(none)", []).append(o["success"])
    return {
        "feedback": feedback,
        "estimator": describe_estimator(estimator),
        "control_dt_s": getattr(env.unwrapped, "control_dt", None),
        "episodes": outcomes,
        "success_rate": float(np.mean([o["success"] for o in outcomes])),
        "success_by_object": {
            name: {"episodes": len(s), "success_rate": float(np.mean(s))}
            for name, s in by_object.items()
        },
        "n_frames": int(frame_max_mm.size),
        "n_frames_with_keypoints": int(finite.sum()),
        "kp_mean_mm": float(np.mean(frame_mean_mm[finite])) if finite.any() else math.nan,
        "kp_max_mean_mm": (float(np.mean(frame_max_mm[finite])) if finite.any() else math.nan),
        "center_mm": (float(np.nanmean(center_mm)) if np.isfinite(center_mm).any() else math.nan),
        "f_tau_thresholds_mm": [float(t) for t in taus],
        "f_tau": [float(v) for v in f_tau],
        "f_tau_auc": metrics.curve_auc(taus, f_tau) if finite.any() else math.nan,
        "by_occlusion": [
            {
                "occlusion": [b.lower, b.upper],
                "n_frames": b.n_frames,
                "kp_mean_mm": b.mean,
            }
            for b in buckets
        ],
        "estimator_time_mean_s": float(np.mean(times)) if times else math.nan,
        "media": media.summary(),
    }


def evaluate_closed_loop(
    env_id: str,
    make_estimator: Callable[[], Estimator],
    *,
    episodes: int = 5,
    seed: int = 0,
    env_kwargs: dict[str, Any] | None = None,
    feedback_modes: tuple[bool, ...] = (False, True),
    progress: Callable[[int], None] | None = None,
    media_dir: str | Path | None = None,
    video: bool = False,
    video_fps: float = 25.0,
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
        progress: called with the number of env steps just done; an episode that ends early
            (or has no plan) reports its remaining steps, so the calls of a run add up to
            ``len(feedback_modes) * episodes * max_episode_steps`` (e.g. for a progress bar).
        media_dir: folder for pictures (``worst_frame_<mode>.png``; with ``video``, MP4s
            under ``video/``); ``None`` draws nothing.
        video: write one MP4 per mode and episode into ``media_dir`` (needs the ``video``
            extra).
        video_fps: frames per second of the MP4s.

    Returns:
        ``{"env_id", "env_kwargs", "episodes", "seed", "estimator": {"repr"}, "modes":
        {"feedback_off": ..., "feedback_on": ...}}``, JSON-serializable (the module docstring
        lists each figure; non-finite figures are NaN, see :func:`to_strict_json`).

    Raises:
        ValueError: for ``episodes < 1``, or ``video`` without ``media_dir``.
        HandSimError: for an estimator instance where a factory is expected, or feedback modes
            that are not booleans.
    """
    instance = not isinstance(make_estimator, type) and hasattr(make_estimator, "predict")
    if instance or not callable(make_estimator):
        received = "an estimator instance" if instance else type(make_estimator).__name__
        raise HandSimError(
            "make_estimator must build a fresh estimator per feedback mode (a class or a "
            f"function, e.g. lambda: OracleEstimator(noise_mm=10)); received {received}"
        )
    if (
        not isinstance(feedback_modes, (tuple, list))
        or not feedback_modes
        or not all(isinstance(m, (bool, np.bool_)) for m in feedback_modes)
    ):
        raise HandSimError(
            "feedback_modes must be a non-empty tuple of booleans, e.g. (False, True); "
            f"received {feedback_modes!r}"
        )
    if not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be an int >= 1; received {episodes!r}")
    if video and media_dir is None:
        raise ValueError("video=True needs a media_dir to write the MP4s into; received None")
    media_path = None if media_dir is None else Path(media_dir)
    if media_path is not None:
        media_path.mkdir(parents=True, exist_ok=True)
    kwargs = dict(env_kwargs or {})
    modes = {}
    for feedback in feedback_modes:
        name = "feedback_on" if feedback else "feedback_off"
        media = _Media(media_path, name, video, video_fps)
        modes[name] = _run_mode(
            env_id, make_estimator, feedback, episodes, seed, kwargs, progress, media
        )
    first = next(iter(modes.values()), {})
    return {
        "env_id": env_id,
        "env_kwargs": kwargs,
        "episodes": episodes,
        "seed": seed,
        "estimator": {
            "repr": first.get("estimator", ("", False))[0],
            "describes_itself": first.get("estimator", ("", False))[1],
        },
        "modes": modes,
    }


def _title(ax: Any, report: dict[str, Any], what: str) -> None:
    label = "\n".join(textwrap.wrap(estimator_label(report), 70))
    ax.set_title(f"{what}, {report['env_id']}\n{label}", fontsize=8)


def _mode_label(name: str) -> str:
    return name.replace("_", " ")


def write_report(report: dict[str, Any], out_dir: str | Path) -> dict[str, Path]:
    """Write ``closed_loop.json`` (strict JSON) and the report's plots into ``out_dir``.

    Plots (PNG): ``f_tau.png`` (F(tau) per mode), ``success.png`` (success per mode),
    ``error_over_time.png`` (mean keypoint error per step, one line per episode and mode),
    ``error_by_occlusion.png`` (mean keypoint error per occlusion bucket and mode) and
    ``success_by_object.png`` (success per target object and mode). Titles name the env and
    the estimator with its settings (:func:`estimator_label`).

    Returns:
        The written paths by kind (``"json"``, ``"f_tau"``, ``"success"``,
        ``"error_over_time"``, ``"error_by_occlusion"``, ``"success_by_object"``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "closed_loop.json"}
    paths["json"].write_text(json.dumps(to_strict_json(report), indent=2, allow_nan=False))
    names = list(report["modes"])
    colours = dict(zip(names, ["#4c72b0", "#dd8452"], strict=False))

    def save(fig: Any, kind: str) -> None:
        paths[kind] = out / f"{kind}.png"
        fig.tight_layout()
        fig.savefig(paths[kind], dpi=100)
        plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for name, mode in report["modes"].items():
        ax.plot(
            mode["f_tau_thresholds_mm"],
            100 * np.array(mode["f_tau"]),
            color=colours.get(name),
            label=(
                f"{_mode_label(name)} (AUC {mode['f_tau_auc']:.3f})"
                if math.isfinite(mode["f_tau_auc"])
                else f"{_mode_label(name)} (no keypoints: no curve)"
            ),
        )
    ax.set_xlabel("Distance threshold tau / mm")
    ax.set_ylabel("Frames with max keypoint error <= tau / %")
    ax.set_ylim(0, 100)
    ax.grid(True, alpha=0.3)
    ax.legend()
    _title(ax, report, "F(tau)")
    save(fig, "f_tau")

    fig, ax = plt.subplots(figsize=(5, 4))
    rates = [100 * report["modes"][n]["success_rate"] for n in names]
    ax.bar([_mode_label(n) for n in names], rates, color=[colours[n] for n in names])
    for i, rate in enumerate(rates):
        ax.text(i, rate + 1, f"{rate:.0f} %", ha="center")
    ax.set_ylim(0, 110)
    ax.set_ylabel(f"Task success / % of {report['episodes']} episodes")
    _title(ax, report, "Task success")
    save(fig, "success")

    fig, ax = plt.subplots(figsize=(7, 4))
    dt = _control_period_s(report)
    for name, mode in report["modes"].items():
        for i, episode in enumerate(mode["episodes"]):
            series = np.array(
                [math.nan if e is None else e for e in episode.get("kp_mean_mm", [])], float
            )
            if series.size == 0:
                continue
            t = np.arange(series.size) * (dt or 1.0)
            label = _mode_label(name) if i == 0 else None
            ax.plot(t, series, color=colours.get(name), alpha=0.7, lw=1, label=label)
    ax.set_xlabel("Episode time / s" if dt else "Step")
    ax.set_ylabel("Mean keypoint error / mm")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend()
    _title(ax, report, "Keypoint error over time (one line per episode)")
    save(fig, "error_over_time")

    fig, ax = plt.subplots(figsize=(6, 4))
    width = 0.8 / max(len(names), 1)
    for j, name in enumerate(names):
        buckets = report["modes"][name]["by_occlusion"]
        x = np.arange(len(buckets)) + (j - (len(names) - 1) / 2) * width
        means = [math.nan if b["kp_mean_mm"] is None else b["kp_mean_mm"] for b in buckets]
        ax.bar(x, means, width, color=colours.get(name), label=_mode_label(name))
        for xi, b, m in zip(x, buckets, means, strict=True):
            ax.text(xi, 0 if math.isnan(m) else m, f"n={b['n_frames']}", ha="center",
                    va="bottom", fontsize=7)  # fmt: skip
    buckets = report["modes"][names[0]]["by_occlusion"] if names else []
    ax.set_xticks(np.arange(len(buckets)))
    ax.set_xticklabels([f"{100 * lo:.0f}-{100 * hi:.0f} %" for lo, hi in
                        (b["occlusion"] for b in buckets)])  # fmt: skip
    ax.set_xlabel("Hidden keypoints in the frame")
    ax.set_ylabel("Mean keypoint error / mm")
    ax.grid(True, axis="y", alpha=0.3)
    ax.set_ylim(0, 1.3 * max(ax.get_ylim()[1], 1.0))
    ax.legend(loc="upper center", ncol=max(len(names), 1))
    _title(ax, report, "Keypoint error by occlusion")
    save(fig, "error_by_occlusion")

    fig, ax = plt.subplots(figsize=(7, 4))
    objects = sorted({o for n in names for o in report["modes"][n].get("success_by_object", {})})
    for j, name in enumerate(names):
        by_object = report["modes"][name].get("success_by_object", {})
        x = np.arange(len(objects)) + (j - (len(names) - 1) / 2) * width
        rates = [100 * by_object[o]["success_rate"] if o in by_object else 0.0 for o in objects]
        ax.bar(x, rates, width, color=colours.get(name), label=_mode_label(name))
        for xi, o in zip(x, objects, strict=True):
            if o in by_object:
                n = by_object[o]["episodes"]
                ax.text(xi, 100 * by_object[o]["success_rate"], f"n={n}", ha="center",
                        va="bottom", fontsize=7)  # fmt: skip
    ax.set_xticks(np.arange(len(objects)))
    ax.set_xticklabels(objects, rotation=20, ha="right", fontsize=8)
    ax.set_ylim(0, 130)
    ax.set_yticks(range(0, 101, 20))
    ax.set_ylabel("Task success / %")
    ax.legend(loc="upper center", ncol=max(len(names), 1))
    _title(ax, report, "Task success per object")
    save(fig, "success_by_object")
    return paths


def _control_period_s(report: dict[str, Any]) -> float | None:
    periods = [m.get("control_dt_s") for m in report["modes"].values()]
    return next((float(p) for p in periods if p), None)
