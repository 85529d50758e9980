"""Grip stabilisation: a digit on an object stops at its surface and opens only on intent.

Tracking noise moves every retargeted joint angle from frame to frame; a physical hand that
follows them opens and closes its fingers around an object at the noise's rate and lets it
go. VR physics hands keep a grip the way the object would stop a real finger: once a digit
touches an object while the tracked digit closes onto it, the surface is latched (the
digit's joint angles at that moment, the *contact posture*), and from then on

- the digit never opens beyond the contact posture: each flexion target is the larger of the
  tracked one and the contact posture's (a tracked digit that closes further, past the
  surface, presses harder, as a position actuator held off its target does); its spread
  (abduction) joints follow tracking (held at the contact posture they broke the grasp
  expert's replayed grasps, seeds 0-3 of 0-5, which move them while squeezing);
- it releases when the tracked digit clearly opens, its mean flexion (a running mean of the
  targets, so one frame's noise does not count) falling more than a band below the contact
  posture's (the user lets go), or after some time off every object (the object is gone).

This is the grasp *intent* of VR SDKs with hysteresis: closing past the surface grips,
opening within the band keeps the grip. Nothing is attached: the object is held by the
fingers' torque-limited position actuators pressing on it, as in a grasp without the
stabiliser, so a success with it is a physical grasp. The time a digit spends latched is
reported (``grip_hold_s``) so a sweep shows how much the grip leaned on it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from handsim.hand.pose import FINGERS, JOINT_NAMES

__all__ = [
    "GripStabiliser",
    "DigitContacts",
    "DIGITS",
    "GRIP_BAND_RAD",
    "GRIP_SMOOTH_S",
    "GRIP_RELEASE_S",
]

DIGITS: tuple[str, ...] = ("thumb", *FINGERS)
GRIP_BAND_RAD = 0.2
"""Hysteresis on a latched digit's mean flexion, rad (11.5 deg): a tracked digit that opens
less than this below the contact posture keeps its grip; beyond it, it releases."""
GRIP_SMOOTH_S = 0.15
"""Time constant of the running mean of the targets that latching and release are judged on,
seconds: one frame's noise neither latches a grip nor breaks it."""
GRIP_RELEASE_S = 0.3
"""A latched digit off every object this long releases (the object is gone)."""

_DIGIT_JOINTS = [
    np.array([i for i, n in enumerate(JOINT_NAMES) if n.startswith(d + "_")]) for d in DIGITS
]
_DIGIT_FLEX = [np.array([i for i in idx if "flex" in JOINT_NAMES[i]]) for idx in _DIGIT_JOINTS]
_DIGIT_SPREAD = [
    np.array([i for i in idx if "flex" not in JOINT_NAMES[i]], dtype=int) for idx in _DIGIT_JOINTS
]


class DigitContacts:
    """Which digits of a hand touch an object (not the table, a button or the other hand).

    Args:
        scene: the scene (``env.unwrapped.scene``, or one hand's view of a two-hand scene):
            its ``model``, ``hand`` (``root_body``) and ``objects`` ((body name, object) pairs).
    """

    def __init__(self, scene: Any) -> None:
        model = scene.model
        prefix = scene.hand.root_body.split("_", 1)[0] + "_"
        root = model.body(scene.hand.root_body).id
        # Hand geoms -> digit index (DIGITS order), -1 for the rest of the model.
        self._geom_digit = np.full(model.ngeom, -1, dtype=np.int8)
        for g in range(model.ngeom):
            b = int(model.geom_bodyid[g])
            if int(model.body_rootid[b]) != int(model.body_rootid[root]):
                continue
            name = model.body(b).name
            for d, digit in enumerate(DIGITS):
                if name.startswith(prefix + digit):
                    self._geom_digit[g] = d
        self._is_object = np.zeros(model.ngeom, dtype=bool)
        # Object geoms -> index into scene.objects (-1: not an object).
        self._geom_object = np.full(model.ngeom, -1, dtype=np.int16)
        for k, (body_name, _) in enumerate(getattr(scene, "objects", ())):
            on_body = model.geom_bodyid == model.body(body_name).id
            self._is_object[on_body] = True
            self._geom_object[on_body] = k

    def touching(self, data: Any) -> np.ndarray:
        """(5,) bool: each digit (DIGITS order) touches an object now."""
        out = np.zeros(len(DIGITS), dtype=bool)
        if data.ncon:
            pairs = np.asarray(data.contact.geom[: data.ncon])
            for a, b in ((0, 1), (1, 0)):
                digits = self._geom_digit[pairs[:, a]]
                keep = (digits >= 0) & self._is_object[pairs[:, b]]
                out[digits[keep]] = True
        return out

    def touched_object(self, data: Any) -> int:
        """The index (into ``scene.objects``) of the object most digits touch; -1 if none."""
        counts: dict[int, set[int]] = {}
        if data.ncon:
            pairs = np.asarray(data.contact.geom[: data.ncon])
            for a, b in ((0, 1), (1, 0)):
                digits = self._geom_digit[pairs[:, a]]
                objects = self._geom_object[pairs[:, b]]
                for d, k in zip(digits.tolist(), objects.tolist(), strict=True):
                    if d >= 0 and k >= 0:
                        counts.setdefault(k, set()).add(d)
        return max(counts, key=lambda k: len(counts[k])) if counts else -1


class GripStabiliser:
    """Stops each digit at the surface it touches and keeps it there until the user opens.

    Args:
        base: the task env (``env.unwrapped``) after its reset: its scene's hand and objects.
        dt_s: the control period, seconds.
        band_rad: the hysteresis on the digit's mean flexion, rad.
        smooth_s: time constant of the running mean of the targets, seconds.
        release_s: seconds off every object after which a latched digit releases.
    """

    def __init__(
        self,
        base: Any,
        dt_s: float,
        band_rad: float = GRIP_BAND_RAD,
        smooth_s: float = GRIP_SMOOTH_S,
        release_s: float = GRIP_RELEASE_S,
        steady: bool | str = False,
    ) -> None:
        scene = base.scene
        self.steady = steady if steady == "hand" else bool(steady)
        self._binding = scene.binding
        self._contacts = DigitContacts(scene)
        self.band_rad = float(band_rad)
        self._alpha = 1.0 - float(np.exp(-dt_s / smooth_s))
        self._mean: np.ndarray | None = None
        self._release_steps = max(1, round(release_s / dt_s))
        self._contact: list[np.ndarray | None] = [None] * len(DIGITS)
        self._press: list[np.ndarray | None] = [None] * len(DIGITS)  # held flexion targets
        self._off = np.zeros(len(DIGITS), dtype=int)
        self.held_steps = 0
        """Steps with at least one digit latched."""

    def touching(self, data: Any) -> np.ndarray:
        """(5,) bool: each digit (DIGITS order) touches an object now."""
        return self._contacts.touching(data)

    def latched(self) -> np.ndarray:
        """(5,) bool: each digit (DIGITS order) is held at a contact posture."""
        return np.array([c is not None for c in self._contact])

    def __call__(self, target: np.ndarray, data: Any) -> np.ndarray:
        """The stabilised 27-DoF target for the tracked ``target`` and the contacts in ``data``."""
        out = np.array(target, dtype=np.float64)
        angles = out[6:]
        touching = self.touching(data)
        if self._mean is None:
            self._mean = angles.copy()
        else:
            self._mean += self._alpha * (angles - self._mean)
        mean = self._mean
        physical: np.ndarray | None = None
        for d in range(len(DIGITS)):
            flex = _DIGIT_FLEX[d]
            contact = self._contact[d]
            if contact is None:
                if not touching[d]:
                    continue
                if physical is None:
                    physical = self._binding.pose(data).angles
                # Latch when the tracked digit is at or inside the surface it touches.
                if float(np.mean(mean[flex] - physical[flex])) < 0.0:
                    continue
                contact = self._contact[d] = physical.copy()
                self._off[d] = 0
                self._press[d] = np.maximum(mean[flex], contact[flex])
            else:
                self._off[d] = 0 if touching[d] else self._off[d] + 1
                opened = float(np.mean(mean[flex] - contact[flex])) < -self.band_rad
                if opened or self._off[d] >= self._release_steps:
                    self._contact[d] = self._press[d] = None  # let go, or the object is gone
                    continue
            press = self._press[d]
            assert press is not None
            # The grip tightens as the tracked digit closes and eases only when it opens by
            # more than the band: noise and drift within it leave the press as it was.
            change = float(np.mean(mean[flex] - press))
            if change > 0.0 or change < -self.band_rad:
                press = self._press[d] = np.maximum(mean[flex], contact[flex])
            if self.steady:
                # A held digit takes the running mean, not one frame's noise: the press (which
                # rises as the mean closes) and its spread joints' mean.
                angles[flex] = press
                spread = _DIGIT_SPREAD[d]
                angles[spread] = mean[spread]
                continue
            # Past the surface the tracked digit presses; it never opens below the contact.
            angles[flex] = np.maximum(angles[flex], press)
        if any(c is not None for c in self._contact):
            self.held_steps += 1
            if self.steady == "hand":
                # While the hand holds, its free digits take the running mean too.
                for d in range(len(DIGITS)):
                    if self._contact[d] is None:
                        angles[_DIGIT_JOINTS[d]] = mean[_DIGIT_JOINTS[d]]
        return out
