"""One hand's path through the teleop loop, shared by the one- and the two-hand loop.

From the hand's measured keypoints (the stream's, or camera mode's estimate) to its action:
the tracking faults (:class:`~handsim.envs.teleop.faults.FaultInjector`), the keypoint filter
(:mod:`~handsim.envs.teleop.filters`), the warm-started retargeting onto the physical hand
(:class:`~handsim.hand.retarget.Retargeter`) and the joint-space pose filter
(:class:`~handsim.envs.teleop.pose_filter.PoseFilter`); then, every control step, the grasp
intent (:class:`~handsim.envs.teleop.intent.GraspIntent`) and the grip stabiliser
(:class:`~handsim.envs.teleop.grip.GripStabiliser`) turn the last target into the action.
"""

from __future__ import annotations

import time
import types
from typing import Any

import numpy as np

from handsim.envs.teleop.faults import FaultConfig, FaultInjector
from handsim.envs.teleop.filters import make_filter
from handsim.envs.teleop.grip import DIGITS, GripStabiliser
from handsim.envs.teleop.intent import CLOSE_S, NOISE_GATE_RAD, GraspIntent, make_grasp_intent
from handsim.envs.teleop.pose_filter import ADAPTIVE_REFERENCE_M, make_pose_filter
from handsim.errors import InvalidKeypoints
from handsim.hand.pose import HandPose
from handsim.hand.pose_prior import KeypointNoiseEstimator, default_pose_prior
from handsim.hand.retarget import Retargeter, RetargetResult

__all__ = ["HandChannel"]


SIGMA_UPDATE_FRAMES = 25
"""With ``keypoint_sigma_mm="auto"``: frames between looks at the noise estimate."""
_SIGMA_CHANGE = (0.25, 0.5e-3)  # refit the prior's weight past 25 % + 0.5 mm of change


def _sigma_m(config: Any, faults: FaultConfig | None) -> float:
    """The prior's keypoint noise, metres (``auto`` starts at 0: the plain fit)."""
    sigma_mm = config.keypoint_sigma_mm
    if sigma_mm == "auto":
        return 0.0
    if sigma_mm is None:
        sigma_mm = (faults if faults is not None else config.faults).noise_mm
    return 1e-3 * float(sigma_mm)


def _retargeter(hand: Any, pose_prior: bool, sigma_m: float) -> Retargeter:
    """The loop's retargeter: least squares, or with ``pose_prior`` a MAP fit."""
    if not pose_prior:
        return Retargeter(hand)
    return Retargeter(hand, pose_prior=default_pose_prior(), keypoint_sigma_m=sigma_m)


class HandChannel:
    """One hand's faults, filter, retargeting, pose filter, grasp intent and grip.

    Args:
        config: the loop's :class:`~handsim.envs.teleop.loop.TeleopConfig`.
        scene: the scene as one hand sees it (``env.unwrapped.scene``, or one hand's view of a
            two-hand scene): its ``model``, ``data``, ``hand``, ``binding`` and ``objects``.
        dt_s: the control period, seconds.
        rng: the generator of this hand's faults.
        faults: the faults (default: ``config.faults``; camera mode moves the viewpoint).
    """

    def __init__(
        self,
        config: Any,
        scene: Any,
        dt_s: float,
        rng: np.random.Generator,
        faults: FaultConfig | None = None,
    ) -> None:
        rate_hz = 1.0 / dt_s
        self.injector = FaultInjector(faults if faults is not None else config.faults, rng)
        self.smoother = make_filter(config.filter, rate_hz, **config.filter_params)
        self.pose_smoother = (
            make_pose_filter(
                rate_hz,
                **config.pose_filter_params,
                wrist_only=config.pose_filter == "wrist",
                adaptive=config.pose_filter == "auto",
            )
            if config.pose_filter
            else None
        )
        self._hand_params = scene.hand.params
        self._prior = bool(getattr(config, "pose_prior", False))
        # The noise-adaptive pose filter's cut-offs follow the keypoint noise.
        self._adaptive = config.pose_filter == "auto"
        self.sigma_m = _sigma_m(config, faults)
        """The tracked keypoints' noise now, metres per axis (the prior's weight and the
        adaptive pose filter's cut-offs)."""
        self.retargeter = _retargeter(self._hand_params, self._prior, self.sigma_m)
        # "auto": the noise estimated from the tracked stream's own jitter.
        self.noise: KeypointNoiseEstimator | None = (
            KeypointNoiseEstimator()
            if getattr(config, "keypoint_sigma_mm", None) == "auto"
            else None
        )
        self._frames = 0
        self._sigma_known = self.noise is None
        self._set_filter_noise()
        intent_params = dict(config.intent_params)
        if getattr(config, "closure_assist", False):
            intent_params.setdefault("close_s", CLOSE_S)
            intent_params.setdefault("noise_gate_rad", NOISE_GATE_RAD)
        self.intent: GraspIntent | None = (
            make_grasp_intent(scene, dt_s, **intent_params) if config.grasp_intent else None
        )
        self.grip: GripStabiliser | None = (
            GripStabiliser(
                types.SimpleNamespace(scene=scene),
                dt_s,
                steady=getattr(config, "grip_steady", False),
            )
            if config.grip_hold
            else None
        )
        self.previous: HandPose | None = None
        self.scale: float | None = None
        self.target: np.ndarray = scene.binding.pose(scene.data).vector
        """(27,) the last retargeted (and pose-filtered) target: held while nothing fits."""

    def track(
        self, measured: np.ndarray, times: dict[str, float], tick: float
    ) -> tuple[np.ndarray, bool, RetargetResult | None]:
        """Faults, filter and retargeting of one measured frame.

        Args:
            measured: (21, 3) keypoints, world frame, metres (NaN rows: untracked).
            times: seconds per stage, added to (``faults``, ``filter``, ``retarget``).
            tick: ``time.perf_counter()`` when this hand's stage began.

        Returns:
            ``(tracked, dropped, fit)``: the tracked keypoints (21, 3), whether the frame was
            lost, and the retargeting's result (``None`` when fewer than 4 keypoints are
            tracked or the fit failed: the target holds).
        """
        tracked, dropped = self.injector(measured)
        t_fault = time.perf_counter()
        times["faults"] += t_fault - tick
        tracked = self.smoother(tracked)
        t_filter = time.perf_counter()
        times["filter"] += t_filter - t_fault
        if self.noise is not None:
            self._update_sigma(tracked, dropped)
        result = self._retarget(tracked)
        times["retarget"] += time.perf_counter() - t_filter
        return tracked, dropped, result

    def _update_sigma(self, tracked: np.ndarray, dropped: bool) -> None:
        assert self.noise is not None
        self.noise.update(tracked, dropped)
        self._frames += 1
        if self._frames % SIGMA_UPDATE_FRAMES:
            return
        sigma = self.noise.sigma_m
        relative, absolute = _SIGMA_CHANGE
        if sigma is None:
            return
        if not self._sigma_known or abs(sigma - self.sigma_m) > relative * self.sigma_m + absolute:
            self.sigma_m, self._sigma_known = sigma, True
            if self._prior:
                self.retargeter = _retargeter(self._hand_params, True, sigma)
            self._set_filter_noise()

    def _set_filter_noise(self) -> None:
        setter = getattr(self.pose_smoother, "set_keypoint_noise", None)
        if self._adaptive and setter is not None:
            # Until the stream's noise is known the filter smooths as tuned (the most).
            setter(self.sigma_m if self._sigma_known else ADAPTIVE_REFERENCE_M)

    def _retarget(self, tracked: np.ndarray) -> RetargetResult | None:
        if np.all(np.isfinite(tracked), axis=1).sum() < 4:
            return None
        try:
            result = self.retargeter(
                tracked,
                initial=self.previous,
                initial_scale=self.scale,
                check_side=False,
                report_clamped=False,
            )
        except InvalidKeypoints:
            return None
        self.previous, self.scale = result.pose, result.scale
        self.target = result.pose.vector
        if self.pose_smoother is not None:
            self.target = self.pose_smoother(self.target)
        return result

    def action(self, tracked: np.ndarray | None, data: Any) -> np.ndarray:
        """(27,) this step's action: the target after the grasp intent and the grip stabiliser.

        Args:
            tracked: this step's tracked keypoints (21, 3), or ``None`` (nothing received).
            data: the task's ``MjData`` after the last physics step.
        """
        action = self.intent(self.target, tracked, data) if self.intent is not None else self.target
        return self.grip(action, data) if self.grip is not None else action

    def assisted(self) -> bool:
        """The grasp intent's closure assist drives a digit of this hand now."""
        return self.intent is not None and self.intent.assisted()

    def metrics(self, dt_s: float) -> dict[str, Any]:
        """The hand's assist metrics: ``grip_hold_s``, ``intent_*`` and ``closure_assist_*``."""
        intent = self.intent
        digit_steps = intent.assist_steps if intent is not None else np.zeros(len(DIGITS))
        return {
            "keypoint_sigma_mm": 1e3 * self.sigma_m,
            "grip_hold_s": self.grip.held_steps * dt_s if self.grip is not None else 0.0,
            "intent_grasp_s": intent.grasp_steps * dt_s if intent is not None else 0.0,
            "intent_onsets": intent.onsets if intent is not None else 0,
            "intent_releases": intent.releases if intent is not None else 0,
            "closure_assist_s": intent.any_assist_steps * dt_s if intent is not None else 0.0,
            "closure_assist_digit_s": {
                d: float(n * dt_s) for d, n in zip(DIGITS, digit_steps, strict=True)
            },
        }
