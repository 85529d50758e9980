"""Wrappers of handsim envs: :class:`EstimatorLoop` runs a pose estimator inside every step."""

from __future__ import annotations

import math
import time
from typing import Any

import gymnasium as gym
import numpy as np

from handsim.envs.base import HandSimEnv, without_images
from handsim.envs.config import InvalidEnvConfig
from handsim.estimator import (
    Estimate,
    Estimator,
    PrivilegedEstimator,
    estimate_errors,
    hand_center,
)
from handsim.frame import Frame
from handsim.hand.retarget import Retargeter

__all__ = ["EstimatorLoop", "perceived_state_inputs"]


def _world_from_cam(frame: Frame) -> np.ndarray:
    return np.linalg.inv(frame.T_cam_from_world)


def perceived_state_inputs(
    estimate: Estimate,
    frame: Frame,
    retargeter: Retargeter,
    target_instance: int | None,
    previous_pose: Any = None,
) -> dict[str, Any]:
    """Turn an estimate into the world-frame values an expert state is built from.

    - keypoints: ``keypoints_cam`` mapped to the world; the 27-DoF hand pose is retargeted from
      them (:class:`~handsim.hand.retarget.Retargeter`, warm-started at ``previous_pose``);
    - a centre only (a hand localizer): the true pose and keypoints translated by the centre's
      error (position from the estimate, articulation from the truth);
    - the target object's pose, when the estimate has it.

    Args:
        estimate: a valid estimate.
        frame: the ground truth of the same step (camera extrinsics, and the truth where the
            estimate has nothing).
        retargeter: a retargeter of the episode's hand.
        target_instance: the object the expert handles (``None``: none).
        previous_pose: warm start of the retargeting.

    Returns:
        Keyword arguments for the env's ``expert_state``: ``hand_pose``, ``keypoints_world``,
        and ``T_world_from_obj`` when the target's pose is estimated.
    """
    T_world_cam = _world_from_cam(frame)  # noqa: N806
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]  # noqa: N806
    out: dict[str, Any] = {}
    if estimate.keypoints_cam is not None:
        keypoints = estimate.keypoints_cam @ R.T + t
        out["keypoints_world"] = keypoints
        # The estimate is of this hand (its side and its size): noise must not change either.
        fit = retargeter(
            keypoints,
            initial=previous_pose,
            fit_scale=False,
            initial_scale=1.0,
            check_side=False,
            report_clamped=False,
        )
        out["hand_pose"] = fit.pose
    elif estimate.center_cam is not None:
        true_keypoints = frame.keypoints_cam @ R.T + t
        true_center = hand_center(true_keypoints)
        shift = (estimate.center_cam @ R.T + t) - true_center
        out["keypoints_world"] = true_keypoints + shift
        out["hand_pose"] = frame.hand_pose.replace(wrist_pos=frame.hand_pose.wrist_pos + shift)
    if target_instance is not None and target_instance in estimate.object_poses:
        out["T_world_from_obj"] = T_world_cam @ estimate.object_poses[target_instance]
    return out


class EstimatorLoop(gym.Wrapper):
    """Run an estimator on every observation; report its estimate, errors and time in ``info``.

    At every ``reset`` and ``step`` the wrapped env's depth observation (as (H, W) float32
    metres, whatever its ``depth_format`` and ``channel_axis``) and its ``K``
    (:attr:`~handsim.envs.base.HandSimEnv.obs_intrinsics`, scaled with ``width``/``height``) go
    to ``estimator.predict``. It wraps a bare env or one made by ``gym.make`` (it reaches the
    handsim env through ``env.unwrapped``). An estimator that implements
    :class:`~handsim.estimator.PrivilegedEstimator` (an oracle) first gets the step's
    ground-truth frame through ``observe_truth``. An estimator with a ``set_side(is_left)``
    method (optional, beside the protocol: learned estimators that mirror left hands into a
    right-hand frame) is told the side of the episode's hand at every reset, as a real system
    knows which hand it tracks. ``info`` then holds:

    - ``"frame"``: the :class:`~handsim.frame.record.Frame` the estimate is scored against,
      without its images (``None`` on a diverged step);
    - ``"estimate"``: the :class:`~handsim.estimator.Estimate`;
    - ``"estimate_errors"``: :func:`~handsim.estimator.estimate_errors` of it (mm; NaN when not
      computable, e.g. an invalid estimate);
    - ``"estimator_time_s"``: wall time of the ``predict`` call, seconds;
    - ``"estimator_stats"``: running statistics of the episode: ``n_frames``, ``n_valid``,
      ``kp_mean_mm`` and ``center_mm`` (means over valid frames), ``time_mean_s``.

    Feedback: :meth:`expert_state` returns what an expert should act on. With
    ``feedback=False`` it is the truth; with ``feedback=True`` it is built from the latest
    valid estimate (:func:`perceived_state_inputs`), so estimation errors change the rollout.
    After an invalid estimate (dropout) the last valid one is kept, as a tracker would; before
    the first valid estimate of an episode the truth is used.

    Args:
        env: a handsim env with a depth observation (``obs_mode`` with ``depth``) and labels.
        estimator: any object with the :class:`~handsim.estimator.Estimator` protocol.
        feedback: experts act on the estimate instead of the truth.

    Raises:
        InvalidEnvConfig: for an env without depth observations or labels, an estimator class
            instead of an instance, or an estimator without the protocol.
    """

    def __init__(self, env: gym.Env, estimator: Estimator, *, feedback: bool = False) -> None:
        super().__init__(env)
        base = env.unwrapped
        if not isinstance(base, HandSimEnv):
            raise InvalidEnvConfig(
                f"EstimatorLoop wraps handsim envs; received {type(base).__name__}"
            )
        if "depth" not in base.config.obs_mode:
            raise InvalidEnvConfig(
                f"EstimatorLoop needs depth observations; the env has obs_mode="
                f"{base.config.obs_mode!r}; use 'depth', 'depth+segmentation' or 'depth+state'"
            )
        if not base.config.labels:
            raise InvalidEnvConfig(
                "EstimatorLoop scores estimates against the frame labels; the env has "
                "labels=False; make it with labels=True"
            )
        if isinstance(estimator, type):
            raise InvalidEnvConfig(
                f"estimator must be an instance; received the class {estimator.__name__}; "
                f"pass {estimator.__name__}(...)"
            )
        if not isinstance(estimator, Estimator):
            raise InvalidEnvConfig(
                f"{type(estimator).__name__} is not an Estimator: it needs predict(depth, K), "
                "predict_batch(depths, Ks) and reset() (handsim.estimator.Estimator)"
            )
        self.estimator = estimator
        self.feedback = bool(feedback)
        self._privileged = isinstance(estimator, PrivilegedEstimator)
        self._retargeter: Retargeter | None = None
        self._perceived: dict[str, Any] | None = None

    def _estimate(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> None:
        frame: Frame | None = self.unwrapped.frame
        info["frame"] = None if frame is None else without_images(frame)
        if frame is None:  # diverged step: nothing was rendered
            return
        if self._privileged:
            self.estimator.observe_truth(frame)
        start = time.perf_counter()
        base = self.unwrapped
        depth = obs["depth"]
        if base.config.channel_axis:
            depth = depth[0]
        if depth.dtype == np.uint16:  # depth_format="uint16_mm"
            depth = depth.astype(np.float32) / np.float32(1000.0)
        estimate = self.estimator.predict(depth, base.obs_intrinsics.K)
        elapsed = time.perf_counter() - start
        errors = estimate_errors(
            estimate, frame, objects=[o for _, o in self.unwrapped.scene.objects]
        )
        stats = self._stats
        stats["n_frames"] += 1
        stats["time_sum_s"] += elapsed
        if estimate.valid:
            stats["n_valid"] += 1
            for key in ("kp_mean_mm", "center_mm"):
                if not math.isnan(errors[key]):
                    stats[f"{key}_sum"] += errors[key]
                    stats[f"{key}_n"] += 1
            if self.feedback:
                base = self.unwrapped
                target = getattr(base, "target_instance", None)
                previous = self._perceived.get("hand_pose") if self._perceived else None
                self._perceived = perceived_state_inputs(
                    estimate, frame, self._retargeter, target, previous
                )
        info["estimate"] = estimate
        info["estimate_errors"] = errors
        info["estimator_time_s"] = elapsed
        info["estimator_stats"] = {
            "n_frames": stats["n_frames"],
            "n_valid": stats["n_valid"],
            "kp_mean_mm": _mean(stats, "kp_mean_mm"),
            "center_mm": _mean(stats, "center_mm"),
            "time_mean_s": stats["time_sum_s"] / stats["n_frames"],
        }

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset the env and the estimator, then estimate the first observation."""
        obs, info = self.env.reset(**kwargs)
        self.estimator.reset()
        set_side = getattr(self.estimator, "set_side", None)
        if callable(set_side):
            set_side(self.unwrapped.scene.hand.params.side == "left")
        # Only feedback turns estimates into poses (the hand may differ per episode).
        if self.feedback:
            self._retargeter = Retargeter(self.unwrapped.scene.hand.params)
        self._perceived = None
        self._stats = {
            "n_frames": 0,
            "n_valid": 0,
            "time_sum_s": 0.0,
            "kp_mean_mm_sum": 0.0,
            "kp_mean_mm_n": 0,
            "center_mm_sum": 0.0,
            "center_mm_n": 0,
        }
        self._estimate(obs, info)
        return obs, info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict]:
        """Step the env, then estimate the new observation."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._estimate(obs, info)
        return obs, reward, terminated, truncated, info

    def expert_state(self) -> Any:
        """The state an expert acts on: the truth, or (``feedback=True``) the estimate."""
        base = self.unwrapped
        if not self.feedback or self._perceived is None:
            return base.expert_state()
        return base.expert_state(**self._perceived)

    def make_expert(self, rng: np.random.Generator | None = None) -> Any:
        """The env's expert, planned from :meth:`expert_state` (the estimate with feedback)."""
        return self.unwrapped.make_expert(rng, state=self.expert_state())


def _mean(stats: dict[str, Any], key: str) -> float:
    n = stats[f"{key}_n"]
    return stats[f"{key}_sum"] / n if n else math.nan
