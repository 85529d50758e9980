"""Interaction events, as VR SDKs report them, detected every control step of the teleop loop.

==================  =========================================================================
kind                when (``target``, ``value``)
==================  =========================================================================
``pinch_start``     the *tracked* thumb and index tips come closer than
                    :data:`PINCH_START_M` (what a headset's pinch gesture reads; ``value``:
                    their distance, metres)
``pinch_end``       they part beyond :data:`PINCH_END_M` (hysteresis: no chatter near the
                    threshold)
``grab``            the *physical* thumb and another finger both touch an object (opposition;
                    ``target``: the object's body name)
``release``         that opposition is lost for :data:`RELEASE_S` (``target``: the object)
``button_press``    a push button passes its press depth (``Press-v0``; ``target``:
                    ``"button_<i>"``)
``button_release``  it comes back above its release depth
``slider``          the slider's knob moved :data:`SLIDER_STEP_M` or more since the last
                    event (``target``: ``"slider"``; ``value``: its position, metres)
==================  =========================================================================

Each :class:`InteractionEvent` has the step, the episode time (``t_s``: step times the control
period), the wall-clock Unix time (``unix_s``, to line up with a live sender's timestamps) and
the hand side. :class:`~handsim.envs.teleop.loop.TeleopEpisode` keeps them in ``events``, the
metrics count them by kind, and :func:`~handsim.envs.teleop.loop.write_rollout` stores them in
the rollout's ``meta``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np

__all__ = [
    "EVENT_KINDS",
    "PINCH_START_M",
    "PINCH_END_M",
    "RELEASE_S",
    "SLIDER_STEP_M",
    "InteractionEvent",
    "EventDetector",
]

EVENT_KINDS: tuple[str, ...] = (
    "pinch_start",
    "pinch_end",
    "grab",
    "release",
    "button_press",
    "button_release",
    "slider",
)
PINCH_START_M = 0.02
"""Thumb-index tip distance under which a pinch starts, metres."""
PINCH_END_M = 0.03
"""Distance over which it ends, metres."""
RELEASE_S = 0.05
"""Opposition lost this long is a release, seconds (contacts flicker for a step or two)."""
SLIDER_STEP_M = 0.002
"""Slider motion reported as an event, metres."""
_THUMB_TIP, _INDEX_TIP = 4, 8


@dataclasses.dataclass(frozen=True)
class InteractionEvent:
    """One interaction event (module docstring).

    Attributes:
        kind: one of :data:`EVENT_KINDS`.
        step: the control step (1 = the first step after the reset).
        t_s: episode time, seconds.
        unix_s: wall-clock time when detected, seconds since the epoch.
        hand: ``"right"`` or ``"left"``.
        target: the object body, ``"button_<i>"``, ``"slider"``, or ``None`` (pinch).
        value: pinch distance or slider position, metres, else ``None``.
    """

    kind: str
    step: int
    t_s: float
    unix_s: float
    hand: str
    target: str | None = None
    value: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The event as a JSON-ready dict."""
        return dataclasses.asdict(self)


class EventDetector:
    """Detects the events of one episode of a task env (module docstring).

    Args:
        base: the unwrapped task env (after ``reset``).
        dt_s: the control period, seconds.
    """

    def __init__(self, base: Any, dt_s: float) -> None:
        scene = base.scene
        model = scene.model
        self.side = scene.hand.params.side
        self.dt_s = float(dt_s)
        prefix = scene.hand.root_body.split("_", 1)[0] + "_"
        root = model.body(scene.hand.root_body).id
        # Hand geoms -> 0 (thumb), 1 (another finger), -1 (palm and the rest).
        self._geom_digit = np.full(model.ngeom, -2, dtype=np.int8)
        for g in range(model.ngeom):
            b = int(model.geom_bodyid[g])
            name = model.body(b).name
            if b == root or int(model.body_rootid[b]) == int(model.body_rootid[root]):
                if name.startswith(prefix + "thumb"):
                    self._geom_digit[g] = 0
                elif any(
                    name.startswith(prefix + d) for d in ("index", "middle", "ring", "little")
                ):
                    self._geom_digit[g] = 1
                else:
                    self._geom_digit[g] = -1
        self._geom_object: dict[int, str] = {}
        for body_name, _ in getattr(scene, "objects", ()):
            b = model.body(body_name).id
            for g in np.flatnonzero(model.geom_bodyid == b):
                self._geom_object[int(g)] = body_name
        self._is_object = np.zeros(model.ngeom, dtype=bool)
        self._is_object[list(self._geom_object)] = True
        self._pinching = False
        self._held: dict[str, int] = {}  # object -> last step with opposition
        self._pressed: np.ndarray | None = None
        self._slider_m: float | None = None
        self.events: list[InteractionEvent] = []

    def _emit(self, kind: str, step: int, target: str | None = None, value: float | None = None):
        self.events.append(
            InteractionEvent(kind, step, step * self.dt_s, time.time(), self.side, target, value)
        )

    def update(self, step: int, tracked: np.ndarray | None, data: Any, info: dict) -> None:
        """Look for events after the physics of ``step``.

        Args:
            step: the control step.
            tracked: (21, 3) the tracked keypoints applied at this step (NaN rows untracked),
                or ``None`` (nothing tracked: the pinch state holds).
            data: the task's ``MjData`` after the step.
            info: the step's ``info``.
        """
        if tracked is not None:
            gap = float(np.linalg.norm(tracked[_THUMB_TIP] - tracked[_INDEX_TIP]))
            if math.isfinite(gap):
                if not self._pinching and gap < PINCH_START_M:
                    self._pinching = True
                    self._emit("pinch_start", step, value=gap)
                elif self._pinching and gap > PINCH_END_M:
                    self._pinching = False
                    self._emit("pinch_end", step, value=gap)
        touching: dict[str, set[int]] = {}
        if data.ncon:
            pairs = np.asarray(data.contact.geom[: data.ncon])
            # Both orders of each pair; keep (finger digit, object geom) ones.
            hand_g = np.concatenate([pairs[:, 0], pairs[:, 1]])
            other_g = np.concatenate([pairs[:, 1], pairs[:, 0]])
            digits = self._geom_digit[hand_g]
            keep = (digits >= 0) & self._is_object[other_g]
            for digit, other in zip(digits[keep], other_g[keep], strict=True):
                touching.setdefault(self._geom_object[int(other)], set()).add(int(digit))
        release_steps = max(1, int(math.ceil(RELEASE_S / self.dt_s - 1e-9)))
        for obj, digits in touching.items():
            if {0, 1} <= digits:
                if obj not in self._held:
                    self._emit("grab", step, obj)
                self._held[obj] = step
        for obj, last in list(self._held.items()):
            if step - last >= release_steps:
                del self._held[obj]
                self._emit("release", step, obj)
        pressed = info.get("pressed")
        if pressed is not None:
            pressed = np.asarray(pressed, dtype=bool)
            before = self._pressed if self._pressed is not None else np.zeros_like(pressed)
            for i in np.flatnonzero(pressed != before):
                kind = "button_press" if pressed[i] else "button_release"
                self._emit(kind, step, f"button_{int(i)}")
            self._pressed = pressed.copy()
        slider = info.get("slider_m")
        if slider is not None and math.isfinite(float(slider)):
            slider = float(slider)
            if self._slider_m is None:
                self._slider_m = slider
            elif abs(slider - self._slider_m) >= SLIDER_STEP_M:
                self._slider_m = slider
                self._emit("slider", step, "slider", slider)

    def counts(self) -> dict[str, int]:
        """Events of each kind so far."""
        return {k: sum(e.kind == k for e in self.events) for k in EVENT_KINDS}
