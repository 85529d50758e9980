"""Scripted experts that are not grasps: smooth gesture motions for ``handsim/HandPose-v0``.

An expert turns a *state* into an absolute 27-DoF target (:class:`~handsim.hand.pose.HandPose`,
world frame) for the ``"pose"`` control mode; its ``action(state)`` gives that target as the
env's action, float32 inside the action space (what ``env.step`` and Minari's ``DataCollector``
check). The state may be the truth or an estimate
(closed-loop evaluation with feedback), so an expert never reads ``MjData``. The grasping expert
lives in :mod:`handsim.envs.grasping`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from handsim.envs.base import _POSE_HI, _POSE_LO
from handsim.errors import HandSimError
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import (
    MAX_JOINT_SPEED,
    MAX_WRIST_ANGULAR_SPEED,
    MAX_WRIST_SPEED,
    smooth_motion,
)

__all__ = ["HandState", "GestureExpert", "ExpertError", "PoseActions", "pose_action"]

# The "pose" control mode's Box bounds, in its float32.
_ACTION_LO = _POSE_LO.astype(np.float32)
_ACTION_HI = _POSE_HI.astype(np.float32)


class ExpertError(HandSimError, RuntimeError):
    """An expert was used out of order (e.g. ``act`` before ``reset``)."""


def pose_action(pose: HandPose) -> np.ndarray:
    """A 27-DoF target as an action of the ``"pose"`` control mode.

    Args:
        pose: absolute target, world frame.

    Returns:
        (27,) float32 ``[wrist_pos (m), wrist_rotvec (rad), 21 angles (rad)]``, rounded to
        float32 and then clipped to the action space's float32 bounds, so that
        ``env.action_space.contains`` holds (``HandPose.vector`` is float64).
    """
    return np.clip(pose.vector.astype(np.float32), _ACTION_LO, _ACTION_HI)


class PoseActions:
    """Adds ``action(state)`` to an expert whose ``act(state)`` returns a :class:`HandPose`."""

    def act(self, state: Any) -> HandPose:  # noqa: D102  (each expert documents its own)
        raise NotImplementedError

    def action(self, state: Any) -> np.ndarray:
        """The next target as the ``"pose"`` control mode's action: (27,) float32, in bounds."""
        return pose_action(self.act(state))


@dataclasses.dataclass(frozen=True)
class HandState:
    """What a hand-only expert sees.

    Attributes:
        time_s: episode time, seconds.
        hand_pose: the measured or estimated 27-DoF pose, world frame.
        keypoints_world: (21, 3) measured or estimated keypoints, world frame, metres.
    """

    time_s: float
    hand_pose: HandPose
    keypoints_world: np.ndarray


class GestureExpert(PoseActions):
    """Moves the hand to a goal pose along a minimum-jerk path, correcting with feedback.

    At :meth:`reset` it plans :func:`~handsim.hand.pose_sources.smooth_motion` from the perceived
    pose to the goal (and optionally through ``via`` poses), at a speed fraction drawn from
    ``speed_range`` of the natural speed limits. Each :meth:`act` returns the path's next sample
    ``r`` plus ``gain * (r - perceived)`` on the wrist position and the angles (the perceived
    pose lags the target under load; with an estimated state its errors enter the commands).

    Args:
        dt: control period, seconds (the env's ``control_dt``).
        gain: feedback gain (>= 0; 0 = open loop after planning).
        speed_range: (low, high) fraction of the natural speed limits, 0 < low <= high <= 1.
        hold_s: seconds to stay at the goal at the end of the path.
        rng: random generator for the speed (default: a fixed seed).

    Raises:
        ExpertError: for invalid arguments (the message gives the valid range).
    """

    def __init__(
        self,
        dt: float,
        *,
        gain: float = 0.5,
        speed_range: tuple[float, float] = (0.3, 0.7),
        hold_s: float = 0.2,
        rng: np.random.Generator | None = None,
    ) -> None:
        if not dt > 0:
            raise ExpertError(f"dt must be > 0 seconds; received {dt}")
        if not gain >= 0:
            raise ExpertError(f"gain must be >= 0; received {gain}")
        lo, hi = speed_range
        if not 0 < lo <= hi <= 1:
            raise ExpertError(
                f"speed_range must satisfy 0 < low <= high <= 1; received {speed_range}"
            )
        self.dt = float(dt)
        self.gain = float(gain)
        self.speed_range = (float(lo), float(hi))
        self.hold_s = float(hold_s)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._path: HandPose | None = None
        self._step = 0

    def reset(self, state: HandState, goal: HandPose, via: tuple[HandPose, ...] = ()) -> None:
        """Plan the path from the perceived pose through ``via`` to ``goal``."""
        speed = self.rng.uniform(*self.speed_range)
        keyframes = [state.hand_pose.clip(), *(v.clip() for v in via), goal.clip()]
        self._path = smooth_motion(
            keyframes,
            self.dt,
            max_joint_speed=speed * MAX_JOINT_SPEED,
            max_wrist_speed=speed * MAX_WRIST_SPEED,
            max_wrist_angular_speed=speed * MAX_WRIST_ANGULAR_SPEED,
            hold=[0.0] * (len(keyframes) - 1) + [self.hold_s],
        )
        self._step = 0

    @property
    def done(self) -> bool:
        """Whether the path has been played to its end."""
        return self._path is not None and self._step >= len(self._path)

    def act(self, state: HandState) -> HandPose:
        """The next absolute target (world frame).

        Raises:
            ExpertError: if called before :meth:`reset`.
        """
        if self._path is None:
            raise ExpertError("GestureExpert.act() called before reset(state, goal)")
        ref = self._path[min(self._step, len(self._path) - 1)]
        self._step += 1
        perceived = state.hand_pose
        wrist = ref.wrist_pos + self.gain * (ref.wrist_pos - perceived.wrist_pos)
        angles = ref.angles + self.gain * (ref.angles - perceived.angles)
        return HandPose(wrist, ref.wrist_rotvec, angles).clip()
