"""Grasp intent: one decision per hand, from many keypoints, drives the fingers while it grasps.

Retargeted from keypoints with 10 mm of noise per axis, a finger joint's angle moves 0.2 to
0.6 rad (std) from frame to frame, with little bias (under 0.1 rad for most joints, the grasp
expert's poses, seed 0, 200 noisy fits each); a physical hand that follows 21 such angles
shakes whatever it holds. VR SDKs do not let the raw finger joints hold an object: their grab
detection (Meta Interaction SDK's grab rules, Ultraleap's grab strength) reduces the tracked
hand to a curl or aperture measure, compares it with thresholds with hysteresis, and while
the hand "grabs" the object follows the grab, not the joints. :class:`GraspIntent` does that
for a physical hand:

- **measure**: the hand's *closure*, the mean distance of the ten distal keypoints (each
  digit's tip and the joint below it) from the palm centre (the wrist and the four finger
  MCPs), over the palm's size (the wrist-to-MCP distance, averaged over a second): ten
  points at once, so the noise averages out, smoothed further in time (``smooth_s``). The
  same measure of the physical hand is its reference.
- **onset** (a Schmitt trigger's upper threshold): the physical thumb and at least one other
  digit touch an object (an opposition, as the ``grab`` event) while the tracked hand is at
  least as closed as the physical one, within ``onset_margin`` (the operator closes onto the
  object, which stops the physical hand).
- **grasp**: a digit on the object holds its *contact flexion* (its flexion joints' angles
  when it first touched, in this grasp) plus ``press_rad``: the position actuators press on
  the object with their stiffness times it, whatever the tracked angles do. The other digits
  and every spread joint follow the *intent posture*, the tracked joint angles averaged since
  the onset (a running mean with time constant ``hold_s``, started from the light running
  mean of ``smooth_s``), whose noise falls with the averaging (0.4 rad of noise is about
  0.06 rad after a 0.4 s average). The grip stabiliser
  (:class:`~handsim.envs.teleop.grip.GripStabiliser`) then acts on that target as without
  the intent.
- **release** (the lower threshold): the tracked closure opens more than ``band`` above its
  running mean during the grasp (time constant ``hold_s``: the user lets go), or no digit
  has touched an object for ``release_s`` (the object is gone). The tracked angles come back
  over ``blend_s`` (linearly, from the target last applied).

- **closure assist** (``close_s`` > 0; ``TeleopConfig(closure_assist=True)``): as VR SDKs'
  hand grab with finger auto-closure, each digit of the object's grasp type (the grasp
  expert's recipe for it: a tripod's thumb, index and middle, a wrap's five) that does not
  touch the object yet closes from its physical angles along the type's closing path (its
  preshape to its closed posture in ``close_s``, on to the joint limits) until it touches;
  from its contact it presses by ``press_rad`` (the position actuator's stiffness times it,
  within its force limit). The tracked flexion no longer drives those digits.

The wrist is not touched: the intent drives the fingers only. Nothing is attached: the
object is held by the fingers' position actuators pressing on it, so a success with the
intent is a physical grasp. The seconds in grasp intent and the number of onsets and releases
are in the loop's metrics (``intent_grasp_s``, ``intent_onsets``, ``intent_releases``), and
the seconds the closure assist drove a digit (``closure_assist_s``, per digit
``closure_assist_digit_s``), with ``success_assisted`` for a success while it did. A
scene without objects (Press-v0) never grasps: the intent passes the tracked angles unchanged.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from handsim.envs.teleop.filters import InvalidFilter, _positive
from handsim.envs.teleop.grip import _DIGIT_FLEX, DIGITS, DigitContacts
from handsim.hand.pose import JOINT_LIMITS

__all__ = [
    "GraspIntent",
    "INTENT_DEFAULTS",
    "CLOSE_S",
    "NOISE_GATE_RAD",
    "make_grasp_intent",
    "hand_closure",
    "palm_size",
]

NOISE_GATE_RAD = 0.05
"""``noise_gate_rad`` with the closure assist: the retargeted flexion's estimated noise was at
most 0.005 rad at 0 mm of keypoint noise, and 0.13 rad or more in 99 % of the steps at 5 mm
(the reactive operator on Grasp-v0, 60 ms latency, 5 % dropped frames, seeds 0-2)."""

CLOSE_S = 0.5
"""``close_s`` of the closure assist (``TeleopConfig(closure_assist=True)``): a digit closes
along its grasp type's path from preshape to closed in this many seconds (the grasp
expert's own closure takes 0.4 s to the contact posture)."""

INTENT_DEFAULTS: dict[str, float] = {
    "smooth_s": 0.1,
    "hold_s": 0.4,
    "band": 0.1,
    "onset_margin": 0.05,
    "release_s": 0.3,
    "blend_s": 0.2,
    "press_rad": 0.2,
    "close_s": 0.0,
    "noise_gate_rad": 0.0,
}
"""``smooth_s``: time constant of the closure's and the angles' light running mean, s;
``hold_s``: time constant of the intent posture's running mean during a grasp, s; ``band``:
the hysteresis on the closure (palm sizes; 0.1 is about 9 mm of the distal points' mean
distance on the default hand): a grasp releases when the closure opens this far above its
running mean during the grasp; ``onset_margin``: a grasp starts when the tracked closure is
at most this much above the physical hand's (palm sizes: the noise biases the tracked
closure up by about 0.03 at 10 mm per axis); ``release_s``: seconds off every object that
release a grasp; ``blend_s``: seconds over which the tracked angles come back after a
release (from the target last applied); ``press_rad``: how far past its contact flexion a digit
on the object is held during a grasp, rad (0: the intent posture instead); ``close_s``:
closure assist (0: off): while it grasps, each digit of the object's grasp type that does
not touch yet closes along the type's closing path (its preshape to its closed posture in
``close_s`` seconds) until it touches, instead of following the tracked flexion;
``noise_gate_rad``: a grasp starts only while the tracked flexion's estimated noise
(:attr:`GraspIntent.noise_rad`) is at least this, rad (0: always): with clean tracking the
operator's own fingers grasp better than the intent does."""

_ALL_FLEX = np.concatenate(_DIGIT_FLEX)
_PALM = np.array([0, 5, 9, 13, 17])
_MCPS = np.array([5, 9, 13, 17])
# Each digit's tip and the joint below it (thumb IP and tip, fingers DIP and tip).
_DISTAL = np.array([3, 4, 7, 8, 11, 12, 15, 16, 19, 20])


def hand_closure(keypoints: np.ndarray, palm_size_m: float | None = None) -> float:
    """The hand's closure measure: distal keypoints' mean distance from the palm, in palm sizes.

    Args:
        keypoints: (21, 3) keypoints, metres, any frame; NaN rows for untracked points.
        palm_size_m: the palm's size to divide by, metres (default: this frame's
            :func:`palm_size_m`; a tracked hand's own is noisy, so the loop passes a running
            mean of it).

    Returns:
        The mean distance of the present distal points (tips and the joints below them)
        from the palm centre (mean of the wrist and the four finger MCPs), over the mean
        wrist-to-MCP distance; smaller is more closed (about 0.9 to 1.3 for an open hand,
        0.5 to 0.7 for a fist). NaN without the wrist, an MCP or at least 5 distal points.
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    palm = kp[_PALM]
    if not np.all(np.isfinite(palm)):
        return math.nan
    centre = palm.mean(axis=0)
    size = palm_size(kp) if palm_size_m is None else float(palm_size_m)
    distal = kp[_DISTAL]
    present = np.all(np.isfinite(distal), axis=1)
    if present.sum() < 5 or size <= 0:
        return math.nan
    return float(np.mean(np.linalg.norm(distal[present] - centre, axis=1)) / size)


def palm_size(keypoints: np.ndarray) -> float:
    """The mean distance from the wrist to the four finger MCPs, metres (NaN if one is absent)."""
    kp = np.asarray(keypoints, dtype=np.float64)
    return float(np.mean(np.linalg.norm(kp[_MCPS] - kp[0], axis=1)))


class GraspIntent:
    """Per-hand grasp intent with hysteresis; while it grasps, the fingers follow the intent.

    Args:
        scene: the task's scene (``env.unwrapped.scene``, or one hand's view of a two-hand
            scene): its ``model``, ``data``, ``hand``, ``binding`` and ``objects``.
        dt_s: the control period, seconds.
        smooth_s, hold_s, band, onset_margin, release_s, blend_s: see
            :data:`INTENT_DEFAULTS`.

    Raises:
        InvalidFilter: a non-positive time or a negative band.
    """

    def __init__(
        self,
        scene: Any,
        dt_s: float,
        *,
        smooth_s: float = INTENT_DEFAULTS["smooth_s"],
        hold_s: float = INTENT_DEFAULTS["hold_s"],
        band: float = INTENT_DEFAULTS["band"],
        onset_margin: float = INTENT_DEFAULTS["onset_margin"],
        release_s: float = INTENT_DEFAULTS["release_s"],
        blend_s: float = INTENT_DEFAULTS["blend_s"],
        press_rad: float = INTENT_DEFAULTS["press_rad"],
        close_s: float = INTENT_DEFAULTS["close_s"],
        noise_gate_rad: float = INTENT_DEFAULTS["noise_gate_rad"],
    ) -> None:
        self._binding = scene.binding
        self._contacts = DigitContacts(scene)
        dt = _positive("dt_s", dt_s)
        self._alpha_fast = 1.0 - math.exp(-dt / _positive("smooth_s", smooth_s))
        self._alpha_hold = 1.0 - math.exp(-dt / _positive("hold_s", hold_s))
        self.band = _positive("band", band, zero_ok=True)
        self.onset_margin = _positive("onset_margin", onset_margin, zero_ok=True)
        # The tracked palm's size over about a second (one frame's is noisy).
        self._alpha_size = 1.0 - math.exp(-dt / 1.0)
        self._size = math.nan
        self._release_steps = max(1, round(_positive("release_s", release_s) / dt))
        self._blend_steps = max(1, round(_positive("blend_s", blend_s, zero_ok=True) / dt))
        self.press_rad = _positive("press_rad", press_rad, zero_ok=True)
        self.close_s = _positive("close_s", close_s, zero_ok=True)
        self._dt = dt
        self.noise_gate_rad = _positive("noise_gate_rad", noise_gate_rad, zero_ok=True)
        self._alpha_noise = 1.0 - math.exp(-dt / 0.5)
        self._history: list[np.ndarray] = []  # the last two targets' flexion angles
        self._noise_ms = math.nan
        self.noise_rad = math.nan
        """The tracked flexion's estimated noise, rad: the RMS second difference of the
        targets' flexion angles over about 0.5 s, over sqrt(6) (white noise's ratio)."""
        self._objects = [obj for _, obj in getattr(scene, "objects", ())]
        self._closing: list[np.ndarray | None] = [None] * len(DIGITS)  # assisted flexion
        self._closed: list[np.ndarray | None] = [None] * len(DIGITS)  # where closing stops
        self._rate: list[np.ndarray | None] = [None] * len(DIGITS)  # rad per control step
        self._last: np.ndarray | None = None  # the angles applied at the last grasping step
        self.assist_steps = np.zeros(len(DIGITS), dtype=int)
        """Control steps in which the closure assist drove each digit's flexion (DIGITS
        order): closing it toward the object or pressing it from its contact."""
        self.any_assist_steps = 0
        """Control steps in which the closure assist drove at least one digit."""
        self._contact: list[np.ndarray | None] = [None] * len(DIGITS)
        self.grasping = False
        """The hand is in grasp intent now."""
        self.grasp_steps = 0
        """Control steps spent in grasp intent."""
        self.onsets = 0
        """Grasp onsets."""
        self.releases = 0
        """Releases (each follows an onset)."""
        self.closure = math.nan
        """The tracked hand's smoothed closure (:func:`hand_closure`)."""
        self._mean: np.ndarray | None = None  # light running mean of the tracked angles
        self._posture: np.ndarray | None = None  # the intent posture (running mean in grasp)
        self._reference = math.nan  # the closure's running mean during the grasp
        self._off = 0
        self._blend = 0  # steps of the release blend left

    def __call__(self, target: np.ndarray, tracked: np.ndarray | None, data: Any) -> np.ndarray:
        """The 27-DoF target with the fingers from the intent while it grasps.

        Args:
            target: (27,) the retargeted (and pose-filtered) target of this step.
            tracked: (21, 3) the tracked keypoints of this step, world frame, metres (NaN
                rows untracked), or ``None`` (nothing received: the state holds).
            data: the task's ``MjData`` after the last physics step.

        Returns:
            (27,) the target to apply; the wrist is ``target``'s.
        """
        out = np.array(target, dtype=np.float64)
        angles = out[6:]
        if self._mean is None:
            self._mean = angles.copy()
        else:
            self._mean += self._alpha_fast * (angles - self._mean)
        closure = math.nan
        if tracked is not None:
            size = palm_size(tracked)
            if math.isfinite(size):
                if math.isnan(self._size):
                    self._size = size
                self._size += self._alpha_size * (size - self._size)
            if math.isfinite(self._size):
                closure = hand_closure(tracked, self._size)
        if math.isfinite(closure):
            if math.isnan(self.closure):
                self.closure = closure
            else:
                self.closure += self._alpha_fast * (closure - self.closure)
        touching = self._contacts.touching(data)
        self._update_noise(angles)
        if not self.grasping:
            physical = hand_closure(self._binding.keypoints(data))
            quiet = self.noise_gate_rad > 0 and not self.noise_rad >= self.noise_gate_rad
            if (
                touching[0]
                and touching[1:].any()
                and self.closure <= physical + self.onset_margin
                and not quiet
            ):
                self.grasping = True
                self.onsets += 1
                self._posture = self._mean.copy()
                self._reference = self.closure
                self._contact = [None] * len(DIGITS)
                self._off = 0
                self._blend = 0
                if self.close_s > 0:
                    self._start_closure(data, self._contacts.touched_object(data))
        else:
            self._off = 0 if touching.any() else self._off + 1
            if math.isfinite(self.closure):
                self._reference += self._alpha_hold * (self.closure - self._reference)
            opened = self.closure > self._reference + self.band
            if opened or self._off >= self._release_steps:
                self.grasping = False
                self.releases += 1
                self._blend = self._blend_steps
        if self.grasping:
            assert self._posture is not None
            self._posture += self._alpha_hold * (angles - self._posture)
            out[6:] = self._posture
            if self.press_rad > 0 or self.close_s > 0:
                # A digit on the object presses past its contact posture by press_rad: its
                # flexion comes from the contact, not from the noisy tracked angles.
                physical = None
                for d, flex in enumerate(_DIGIT_FLEX):
                    if self._contact[d] is None and touching[d]:
                        if physical is None:
                            physical = self._binding.pose(data).angles
                        self._contact[d] = physical[flex] + self.press_rad
                    if self._contact[d] is not None:
                        out[6:][flex] = self._contact[d]
                        if self.close_s > 0:
                            self.assist_steps[d] += 1
                    elif self._closing[d] is not None:
                        # Not touching yet: close along the grasp type's path, at its pace.
                        closing = self._closing[d]
                        closing[:] = np.minimum(closing + self._rate[d], self._closed[d])
                        out[6:][flex] = closing
                        self.assist_steps[d] += 1
            if self.assisted():
                self.any_assist_steps += 1
            self._last = out[6:].copy()
            self.grasp_steps += 1
        elif self._blend > 0 and self._last is not None:
            # After a release the tracked angles return linearly from the angles last applied
            # (a pressing digit's too, not the averaged posture it was not following).
            w = self._blend / (self._blend_steps + 1)
            out[6:] = w * self._last + (1.0 - w) * angles
            self._blend -= 1
        return out

    def _update_noise(self, angles: np.ndarray) -> None:
        """Update :attr:`noise_rad` from this step's target angles.

        A smooth motion's second difference is small (a 1 rad closure in 0.4 s: about 0.015 rad
        at 50 Hz); white noise of std ``s`` gives ``sqrt(6) s``.
        """
        flex = angles[_ALL_FLEX]
        self._history.append(flex.copy())
        if len(self._history) < 3:
            return
        a, b, c = self._history[-3:]
        del self._history[0]
        ms = float(np.mean((c - 2 * b + a) ** 2)) / 6.0
        if math.isnan(self.noise_rad):
            self._noise_ms = ms
        else:
            self._noise_ms += self._alpha_noise * (ms - self._noise_ms)
        self.noise_rad = math.sqrt(self._noise_ms)

    def _start_closure(self, data: Any, k: int) -> None:
        """At an onset: the digits of object ``k``'s grasp type close from where they are."""
        self._closing = [None] * len(DIGITS)
        grasp = _grasp_type(self._objects[k]) if k >= 0 else None
        if grasp is None:
            return
        physical = self._binding.pose(data).angles
        steps = max(1.0, self.close_s / self._dt)
        for d, digit in enumerate(DIGITS):
            if digit not in grasp.digits:
                continue  # not a digit of this grasp: it follows the intent posture
            flex = _DIGIT_FLEX[d]
            start = physical[flex].copy()
            path = grasp.small[flex] - grasp.preshape[flex]
            self._rate[d] = np.maximum(path, 0.0) / steps
            # Past the type's closed posture it goes on to the joints' limits: it stops where
            # it touches, wherever the object's surface is.
            self._closed[d] = np.maximum(JOINT_LIMITS[flex, 1], start)
            self._closing[d] = start

    def assisted(self) -> bool:
        """The closure assist drives at least one digit now."""
        return (
            self.grasping
            and self.close_s > 0
            and (
                any(c is not None for c in self._contact)
                or any(c is not None for c in self._closing)
            )
        )


def _grasp_type(obj: Any) -> Any:
    """The grasp type (:class:`~handsim.hand.pose_library.GraspType`) the expert uses on ``obj``.

    ``None`` for an object the grasp recipes do not know (not a YCB-like object).
    """
    from handsim.envs.grasping.recipes import grasp_recipe
    from handsim.hand.pose_library import GRASP_TYPES
    from handsim.world.objects import YCBObject

    if not isinstance(obj, YCBObject):
        return None
    return GRASP_TYPES[grasp_recipe(obj).grasp_type]


def make_grasp_intent(scene: Any, dt_s: float, **params: float) -> GraspIntent:
    """A :class:`GraspIntent` with ``params`` (keys of :data:`INTENT_DEFAULTS`).

    Raises:
        InvalidFilter: an unknown parameter or a value out of range.
    """
    unknown = sorted(set(params) - set(INTENT_DEFAULTS))
    if unknown:
        raise InvalidFilter(
            f"grasp intent parameters {unknown} are not valid; choose from "
            f"{', '.join(INTENT_DEFAULTS)}"
        )
    return GraspIntent(scene, dt_s, **params)
