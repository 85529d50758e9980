"""A reactive operator: the task's expert closing its own loop on what the headset shows.

A replayed stream (:func:`~handsim.envs.teleop.streams.stream_from_expert`) cannot react: if
noise knocks the object aside, the recorded hand still closes on the empty place, and latency
changes nothing it does. :class:`ReactiveOperator` plans from the displayed simulation
instead, as a person in a headset does:

- **sees** the simulation late: the state it plans from is the one of ``display_latency_s +
  reaction_s`` ago (the display's delay plus a human visuomotor reaction delay, drawn per
  episode in ``reaction_s``, 150-250 ms by default); its clock is the present;
- **feels** nothing: no haptics in VR, so the expert's touch sense is off
  (``touch_forces_n=None``; the grasp expert then sizes its grip by its joint-torque model);
- **moves** with visual-motor noise: a slow random drift (Ornstein-Uhlenbeck, time constant
  ``motor_time_s``) of the wrist (``motor_noise_mm`` std per axis) and of every joint angle
  (``motor_noise_rad``) on top of the expert's command;
- **corrects** the wrist's drift as it sees it: the wrist's deviation from where it meant
  it, shown ``display_latency_s + reaction_s`` late, is integrated into a correction with
  time constant ``correction_s`` (closed-loop visual-motor control: a person watching the
  hand does not let a drift build up into a missed grasp; ``None``: no correction). The
  joints' drift is not corrected: 0.02 rad does not show on a virtual hand, and no haptics
  tell the fingers where the object is.
"""

from __future__ import annotations

import collections
import dataclasses
import math
from typing import Any

import numpy as np

from handsim.envs.teleop.loop import InvalidTeleopConfig
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.pose import HandPose

__all__ = ["ReactiveOperator", "OPERATORS"]

OPERATORS: tuple[str, ...] = ("reactive", "replay")
"""Sweep operators: ``reactive`` (:class:`ReactiveOperator`) or ``replay`` (the expert's
recorded stream, :func:`~handsim.envs.teleop.streams.stream_from_expert`)."""


def _check_range(name: str, value: Any, low: float, high: float) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or not low <= value <= high
    ):
        raise InvalidTeleopConfig(f"{name} must be a number in [{low:g}, {high:g}]; got {value!r}")


class ReactiveOperator:
    """The task's expert as an operator who sees the simulation late and moves with noise.

    Args:
        env: the loop's task env (``loop.env``; its ``unwrapped`` needs ``make_expert`` and
            ``expert_state``, as Grasp-v0 and Press-v0 have).
        seed: the episode's seed (the expert's speed jitter, the reaction delay, the noise).
        reaction_s: ``(low, high)`` seconds: the reaction delay, drawn uniformly per episode.
        display_latency_s: the display's delay, seconds (a sweep uses its latency axis).
        motor_noise_mm: std of the wrist's drift per axis, mm.
        motor_noise_rad: std of every joint angle's drift, rad.
        motor_time_s: time constant of the drift, seconds.
        correction_s: time constant of the visual correction of the wrist's drift, seconds
            (``None``: not corrected).

    Raises:
        InvalidTeleopConfig: an env without an expert, or a setting out of range.
    """

    def __init__(
        self,
        env: Any,
        seed: int = 0,
        *,
        reaction_s: tuple[float, float] = (0.15, 0.25),
        display_latency_s: float = 0.0,
        motor_noise_mm: float = 2.0,
        motor_noise_rad: float = 0.02,
        motor_time_s: float = 0.5,
        correction_s: float | None = 0.5,
    ) -> None:
        base = getattr(env, "unwrapped", env)
        if not (hasattr(base, "make_expert") and hasattr(base, "expert_state")):
            raise InvalidTeleopConfig(
                f"{type(base).__name__} has no expert (make_expert, expert_state): the reactive "
                "operator needs a task such as handsim/Grasp-v0 or handsim/Press-v0"
            )
        if len(tuple(reaction_s)) != 2 or not reaction_s[0] <= reaction_s[1]:
            raise InvalidTeleopConfig(
                f"reaction_s must be (low, high) seconds with low <= high; got {reaction_s!r}"
            )
        for v in reaction_s:
            _check_range("reaction_s", v, 0.0, 2.0)
        _check_range("display_latency_s", display_latency_s, 0.0, 2.0)
        _check_range("motor_noise_mm", motor_noise_mm, 0.0, 100.0)
        _check_range("motor_noise_rad", motor_noise_rad, 0.0, 1.0)
        _check_range("motor_time_s", motor_time_s, 1e-3, 100.0)
        if correction_s is not None:
            _check_range("correction_s", correction_s, 1e-3, 100.0)
        self.env = env
        self._base = base
        self._rng = np.random.default_rng([seed, 28])
        self._expert_rng = np.random.default_rng(seed)  # as stream_from_expert's expert
        self.reaction_s = float(self._rng.uniform(*reaction_s))
        self.display_latency_s = float(display_latency_s)
        self.motor_noise_mm = float(motor_noise_mm)
        self.motor_noise_rad = float(motor_noise_rad)
        self.motor_time_s = float(motor_time_s)
        self.correction_s = None if correction_s is None else float(correction_s)
        self._fk: ForwardKinematics | None = None  # the scene exists after the env's reset
        self._expert: Any = None
        self._seen: collections.deque = collections.deque()
        self._drift = np.zeros(3 + 21)
        self._correction = np.zeros(3 + 21)
        self._seen_offsets: collections.deque = collections.deque()

    @property
    def delay_s(self) -> float:
        """What the operator plans from is this old: display latency + reaction delay."""
        return self.display_latency_s + self.reaction_s

    def __call__(self, step: int) -> np.ndarray:
        """The operator's keypoints (21, 3), world frame, metres, at control step ``step``."""
        base = self._base
        dt = float(base.control_dt)
        now = base.expert_state()
        if self._expert is None or step <= 1:
            self._expert = base.make_expert(self._expert_rng)
            self._fk = ForwardKinematics(base.scene.hand.params)
            self._seen.clear()
            self._drift[:] = 0.0
            self._correction[:] = 0.0
            self._seen_offsets.clear()
        lag = int(round(self.delay_s / dt))
        self._seen.append(now)
        while len(self._seen) > lag + 1:
            self._seen.popleft()
        seen = self._seen[0]  # the oldest kept: `lag` steps ago (or the start)
        changes: dict[str, Any] = {"time_s": now.time_s}
        if hasattr(seen, "touch_forces_n"):
            changes["touch_forces_n"] = None  # no haptics in a headset
        if hasattr(seen, "joint_angles_rad"):
            # The grip is sized from the contact posture, which the operator's own closing hand
            # stands in for (it passes through the virtual object): current, not delayed.
            changes["joint_angles_rad"] = now.joint_angles_rad
        pose = self._expert.act(dataclasses.replace(seen, **changes))
        # Ornstein-Uhlenbeck drift: stationary std as set, correlation time motor_time_s.
        a = math.exp(-dt / self.motor_time_s)
        std = np.r_[np.full(3, self.motor_noise_mm * 1e-3), np.full(21, self.motor_noise_rad)]
        self._drift = a * self._drift + math.sqrt(1 - a * a) * std * self._rng.standard_normal(24)
        # The hand's deviation the operator sees is its own, `lag` steps old; it integrates it
        # away (a delayed integral controller: stable while lag * dt / correction_s < pi / 2).
        offset = self._drift - self._correction
        self._seen_offsets.append(offset.copy())
        while len(self._seen_offsets) > lag + 1:
            self._seen_offsets.popleft()
        if self.correction_s is not None:
            # The wrist's offset shows against the scene; a joint's 0.02 rad does not (and no
            # haptics tell the fingers), so only the wrist is corrected.
            self._correction[:3] += dt / self.correction_s * self._seen_offsets[0][:3]
        low, high = self.env.action_space.low, self.env.action_space.high
        vec = np.clip(pose.vector, low, high)
        vec[:3] += offset[:3]
        vec[6:] = np.clip(vec[6:] + offset[3:], low[6:], high[6:])
        assert self._fk is not None
        return self._fk.keypoints(HandPose.from_vector(vec))
