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
the hand side. With two hands (a two-hand scene) one detector watches both: pinches and grabs
are each hand's own; a button press or release, and a slider move, name the hand touching that
control then (the nearest index fingertip when none touches it).
:class:`~handsim.envs.teleop.loop.TeleopEpisode` keeps them in ``events``, the metrics count
them by kind, and :func:`~handsim.envs.teleop.loop.write_rollout` stores them in the rollout's
``meta``.
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
        base: the unwrapped task env (after ``reset``); every hand of its scene is watched.
        dt_s: the control period, seconds.
    """

    def __init__(self, base: Any, dt_s: float) -> None:
        scene = base.scene
        model = scene.model
        hands = getattr(scene, "hands", None) or (scene.hand,)
        self.sides: tuple[str, ...] = tuple(h.params.side for h in hands)
        self.side = self.sides[0]
        self.dt_s = float(dt_s)
        # Hand geoms -> 0 (thumb), 1 (another finger), -1 (palm and the rest); -2 not a hand.
        self._geom_digit = np.full(model.ngeom, -2, dtype=np.int8)
        self._geom_hand = np.full(model.ngeom, -1, dtype=np.int8)  # index into sides
        self._index_tip_sites = []
        for h, hand in enumerate(hands):
            prefix = hand.prefix
            root = model.body(hand.root_body).id
            self._index_tip_sites.append(model.site(f"{prefix}kp_index_tip").id)
            for g in range(model.ngeom):
                b = int(model.geom_bodyid[g])
                if int(model.body_rootid[b]) != int(model.body_rootid[root]):
                    continue
                name = model.body(b).name
                self._geom_hand[g] = h
                if name.startswith(prefix + "thumb"):
                    self._geom_digit[g] = 0
                elif any(
                    name.startswith(prefix + d) for d in ("index", "middle", "ring", "little")
                ):
                    self._geom_digit[g] = 1
                else:
                    self._geom_digit[g] = -1
        # The panel's controls (Press-v0): geoms of each button and of the slider's knob.
        self._control_geoms: dict[str, np.ndarray] = {}
        for g in range(model.ngeom):
            body = model.body(int(model.geom_bodyid[g])).name
            if body.startswith("press_button_") or body == "press_slider":
                key = "slider" if body == "press_slider" else body[len("press_") :]
                self._control_geoms.setdefault(key, [])
                self._control_geoms[key].append(g)
        self._control_geoms = {k: np.array(v) for k, v in self._control_geoms.items()}
        self._geom_object: dict[int, str] = {}
        for body_name, _ in getattr(scene, "objects", ()):
            b = model.body(body_name).id
            for g in np.flatnonzero(model.geom_bodyid == b):
                self._geom_object[int(g)] = body_name
        self._is_object = np.zeros(model.ngeom, dtype=bool)
        self._is_object[list(self._geom_object)] = True
        self._pinching = [False] * len(self.sides)
        self._held: dict[tuple[int, str], int] = {}  # (hand, object) -> last step opposing
        self._pressed: np.ndarray | None = None
        self._slider_m: float | None = None
        self.events: list[InteractionEvent] = []

    def _emit(
        self,
        kind: str,
        step: int,
        target: str | None = None,
        value: float | None = None,
        hand: int = 0,
    ) -> None:
        self.events.append(
            InteractionEvent(
                kind, step, step * self.dt_s, time.time(), self.sides[hand], target, value
            )
        )

    def _hand_at(self, control: str, hand_g: np.ndarray, other_g: np.ndarray, data: Any) -> int:
        """The hand touching a panel control now, else the one whose index tip is nearest."""
        if len(self.sides) == 1:
            return 0
        geoms = self._control_geoms.get(control)
        if geoms is not None and hand_g.size:
            hands = self._geom_hand[hand_g[np.isin(other_g, geoms)]]
            hands = hands[hands >= 0]
            if hands.size:
                return int(np.bincount(hands).argmax())
        if geoms is None:
            return 0
        centre = data.geom_xpos[geoms].mean(axis=0)
        tips = data.site_xpos[self._index_tip_sites]
        return int(np.argmin(np.linalg.norm(tips - centre, axis=1)))

    def update(
        self,
        step: int,
        tracked: np.ndarray | dict[str, np.ndarray | None] | None,
        data: Any,
        info: dict,
    ) -> None:
        """Look for events after the physics of ``step``.

        Args:
            step: the control step.
            tracked: (21, 3) the tracked keypoints applied at this step (NaN rows untracked),
                or ``None`` (nothing tracked: the pinch state holds); with two hands, a dict
                of them by side (a side missing or ``None``: its pinch state holds).
            data: the task's ``MjData`` after the step.
            info: the step's ``info``.
        """
        if not isinstance(tracked, dict):
            tracked = {self.side: tracked}
        for h, side in enumerate(self.sides):
            kp = tracked.get(side)
            if kp is None:
                continue
            gap = float(np.linalg.norm(kp[_THUMB_TIP] - kp[_INDEX_TIP]))
            if math.isfinite(gap):
                if not self._pinching[h] and gap < PINCH_START_M:
                    self._pinching[h] = True
                    self._emit("pinch_start", step, value=gap, hand=h)
                elif self._pinching[h] and gap > PINCH_END_M:
                    self._pinching[h] = False
                    self._emit("pinch_end", step, value=gap, hand=h)
        touching: dict[tuple[int, str], set[int]] = {}
        hand_g = other_g = np.zeros(0, dtype=np.intp)
        if data.ncon:
            pairs = np.asarray(data.contact.geom[: data.ncon])
            # Both orders of each pair; keep (finger digit, object geom) ones.
            hand_g = np.concatenate([pairs[:, 0], pairs[:, 1]])
            other_g = np.concatenate([pairs[:, 1], pairs[:, 0]])
            digits = self._geom_digit[hand_g]
            keep = (digits >= 0) & self._is_object[other_g]
            hands = self._geom_hand[hand_g]
            for h, digit, other in zip(hands[keep], digits[keep], other_g[keep], strict=True):
                key = (int(h), self._geom_object[int(other)])
                touching.setdefault(key, set()).add(int(digit))
        release_steps = max(1, int(math.ceil(RELEASE_S / self.dt_s - 1e-9)))
        for key, digits in touching.items():
            if {0, 1} <= digits:
                if key not in self._held:
                    self._emit("grab", step, key[1], hand=key[0])
                self._held[key] = step
        for key, last in list(self._held.items()):
            if step - last >= release_steps:
                del self._held[key]
                self._emit("release", step, key[1], hand=key[0])
        pressed = info.get("pressed")
        if pressed is not None:
            pressed = np.asarray(pressed, dtype=bool)
            before = self._pressed if self._pressed is not None else np.zeros_like(pressed)
            for i in np.flatnonzero(pressed != before):
                kind = "button_press" if pressed[i] else "button_release"
                button = f"button_{int(i)}"
                hand = self._hand_at(button, hand_g, other_g, data)
                self._emit(kind, step, button, hand=hand)
            self._pressed = pressed.copy()
        slider = info.get("slider_m")
        if slider is not None and math.isfinite(float(slider)):
            slider = float(slider)
            if self._slider_m is None:
                self._slider_m = slider
            elif abs(slider - self._slider_m) >= SLIDER_STEP_M:
                self._slider_m = slider
                hand = self._hand_at("slider", hand_g, other_g, data)
                self._emit("slider", step, "slider", slider, hand=hand)

    def counts(self) -> dict[str, int]:
        """Events of each kind so far."""
        return {k: sum(e.kind == k for e in self.events) for k in EVENT_KINDS}
