"""Grip stabilisation: contact-aware finger targets with hysteresis on closure.

Tracking noise moves every retargeted joint angle from frame to frame; a physical hand that
follows them opens and closes its fingers around an object at the noise's rate and lets it
go. VR physics hands keep a grip the way a person does: once a digit touches an object, its
target is held at the running mean of its recent targets and stops following tracking
changes smaller than the noise (a dead band on the digit's mean flexion, measured on that
running mean), and changes only when the tracked digit clearly opens (release) or clearly
closes further (a tighter grip, re-latched there).

Nothing is attached: the object is held by the fingers' position actuators pressing on it, as
in a grasp without the stabiliser, so a success with it is a physical grasp. The time a digit
spends latched is reported (``grip_hold_s``) so a sweep shows how much the grip leaned on it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from handsim.hand.pose import FINGERS, JOINT_NAMES

__all__ = ["GripStabiliser", "DIGITS", "GRIP_BAND_RAD", "GRIP_SMOOTH_S", "GRIP_RELEASE_S"]

DIGITS: tuple[str, ...] = ("thumb", *FINGERS)
GRIP_BAND_RAD = 0.2
"""Dead band on a latched digit's mean flexion target, rad (11.5 deg): tracking changes within
it are noise; beyond it the digit releases (opening) or re-latches (closing)."""
GRIP_SMOOTH_S = 0.15
"""Time constant of the running mean of the targets the band is measured on, seconds: one
frame's noise neither latches a grip nor breaks it."""
GRIP_RELEASE_S = 0.3
"""A latched digit off every object this long releases (the object is gone)."""

_DIGIT_JOINTS = [
    np.array([i for i, n in enumerate(JOINT_NAMES) if n.startswith(d + "_")]) for d in DIGITS
]
_DIGIT_FLEX = [np.array([i for i in idx if "flex" in JOINT_NAMES[i]]) for idx in _DIGIT_JOINTS]


class GripStabiliser:
    """Holds each digit's target while it touches an object and tracking changes within noise.

    Args:
        base: the task env (``env.unwrapped``) after its reset: its scene's hand and objects.
        dt_s: the control period, seconds.
        band_rad: the dead band on the digit's mean flexion, rad.
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
    ) -> None:
        scene = base.scene
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
        for body_name, _ in getattr(scene, "objects", ()):
            self._is_object[model.geom_bodyid == model.body(body_name).id] = True
        self.band_rad = float(band_rad)
        self._alpha = 1.0 - float(np.exp(-dt_s / smooth_s))
        self._mean: np.ndarray | None = None
        self._release_steps = max(1, round(release_s / dt_s))
        self._held: list[np.ndarray | None] = [None] * len(DIGITS)
        self._off = np.zeros(len(DIGITS), dtype=int)
        self.held_steps = 0
        """Steps with at least one digit latched."""

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
        for d in range(len(DIGITS)):
            held = self._held[d]
            flex = _DIGIT_FLEX[d]
            if held is None:
                if touching[d]:
                    self._held[d] = mean[_DIGIT_JOINTS[d]].copy()
                    angles[_DIGIT_JOINTS[d]] = self._held[d]
                    self._off[d] = 0
                continue
            self._off[d] = 0 if touching[d] else self._off[d] + 1
            change = float(np.mean(mean[flex] - held[np.searchsorted(_DIGIT_JOINTS[d], flex)]))
            if change < -self.band_rad or self._off[d] >= self._release_steps:
                self._held[d] = None  # opened on purpose, or the object is gone
            elif change > self.band_rad:
                self._held[d] = mean[_DIGIT_JOINTS[d]].copy()  # squeezed on purpose
                angles[_DIGIT_JOINTS[d]] = self._held[d]
            else:
                angles[_DIGIT_JOINTS[d]] = held
        if any(h is not None for h in self._held):
            self.held_steps += 1
        return out
