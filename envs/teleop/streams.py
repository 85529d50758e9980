"""Operator streams: where the tracked hand that drives the physical hand comes from.

An :class:`OperatorStream` is a sequence of the operator's hand in the world frame of the task
(metres, ``z`` up, table top at ``z = 0``): 21 keypoints in :data:`~handsim.hand.KEYPOINT_NAMES`
order per frame (absent points NaN), with timestamps, and, for streams of 27-DoF poses, the
poses themselves. Streams come from

- files (:func:`load_stream`, :func:`save_stream`): NPZ or JSON, schema below;
- generated motions (:func:`stream_from_poses`, :func:`stream_from_motion`) and the scripted
  experts of the envs (:func:`stream_from_expert`), so nothing needs a recording;
- live JSON packets over UDP or WebSocket (:mod:`handsim.envs.teleop.live`).

File schema (JSON object, or NPZ with the same keys as arrays)
------------------------------------------------------------

==================  =====================================================================
key                 meaning
==================  =====================================================================
``format``          one of :data:`STREAM_FORMATS`: a keypoint format of
                    :data:`handsim.hand.keypoints.FORMATS` (``handsim21`` = ``mediapipe21``
                    = the canonical 21; ``openxr26`` = ``XrHandJointEXT`` order), ``webxr25``
                    (WebXR Hand Input order: ``openxr26`` without the palm),
                    ``mediapipe_world`` (MediaPipe world landmarks: 21 points, metres, origin
                    near the hand centre, ``y`` down) or ``pose27`` (27-DoF
                    ``[wrist_pos 3, wrist_rotvec 3, angles 21]`` vectors of
                    :class:`~handsim.hand.pose.HandPose`). Default ``handsim21``.
``units``           ``"m"`` (default) or ``"mm"`` for positions and radii. Keypoints whose
                    hand is not 80-400 mm long (:data:`HAND_LENGTH_PLAUSIBLE_M`) are refused,
                    naming the likely unit.
``up_axis``         axes of the source frame: ``"z"`` (handsim world: ``x`` right, ``y``
                    away from the user, ``z`` up), ``"y"`` (OpenXR / WebXR: ``y`` up,
                    ``-z`` forward) or ``"-y"`` (camera-like: ``y`` down, ``z`` forward).
                    Default ``"y"`` for ``openxr26`` / ``webxr25``, ``"-y"`` for
                    ``mediapipe_world``, else ``"z"``. Poses (``pose27``) must be ``"z"``.
``hand``            ``"right"`` (default) or ``"left"``.
``hand_length_m``   the operator's hand length (``pose27`` only; default 0.189 m).
``fps``             frame rate, when frames carry no ``t`` (0.01 to 10 000).
``frames``          JSON: a list of ``{"t": seconds, "keypoints": [[x, y, z], ...],
                    "radii": [...]}`` (a ``null`` row, or three ``null``, for an
                    untracked joint, as in live packets; ``radii`` optional, one per
                    joint, OpenXR/WebXR) or
                    ``{"t": seconds, "pose": [27 numbers]}``.
``t``               NPZ: (T,) seconds, strictly increasing (or give ``fps``).
``keypoints``       NPZ: (T, N, 3) points of the format (NaN = not tracked).
``radii``           NPZ: (T, N) joint radii (optional).
``pose``            NPZ: (T, 27) pose vectors.
==================  =====================================================================

Timestamps need not be uniform: :meth:`OperatorStream.resample` interpolates to the sim rate
(linear for positions and angles, slerp for the wrist rotation). A malformed file raises
:class:`InvalidStream` naming the key, the frame and what is valid.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pathlib
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from handsim.errors import HandSimError
from handsim.hand.keypoints import FORMATS, from_format
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HAND_SIZES, hand_params
from handsim.hand.pose import HandPose

__all__ = [
    "STREAM_FORMATS",
    "UP_AXES",
    "InvalidStream",
    "OperatorStream",
    "load_stream",
    "save_stream",
    "stream_to_doc",
    "parse_stream",
    "frame_to_world",
    "stream_from_poses",
    "stream_from_motion",
    "stream_from_expert",
]

STREAM_FORMATS: tuple[str, ...] = (
    "handsim21",
    *sorted(FORMATS),
    "webxr25",
    "mediapipe_world",
    "pose27",
)
"""Accepted values of a stream's ``format`` (module docstring)."""
UP_AXES: tuple[str, ...] = ("z", "y", "-y")
"""Accepted source frames (module docstring)."""
MAX_STREAM_FRAMES = 1_000_000
"""Longest stream accepted, frames (about 3 hours at 90 Hz)."""
_MAX_ABS_M = 100.0  # positions farther than this from the origin are a unit mistake
STREAM_FPS_RANGE = (0.01, 10_000.0)
"""Frame rates a stream file may give with ``fps``, frames per second."""
HAND_LENGTH_PLAUSIBLE_M = (0.08, 0.40)
"""Hand lengths a keypoint stream may show, metres (wrist to middle fingertip along its bones):
adult hands measure 0.16-0.22 m; the range leaves room for children and tracker offsets, and
refuses a unit mistake (a factor of 1000)."""

# Source axes -> handsim world (x right, y away from the user, z up); all proper rotations.
_TO_WORLD: dict[str, np.ndarray] = {
    "z": np.eye(3),
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "-y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}


class InvalidStream(HandSimError, ValueError):
    """An operator stream (file, packet or array) is malformed; the message names the field."""


MAX_RESAMPLED_FRAMES = 2_000_000
"""Most frames a resampled stream may have (about 4.6 h at 120 Hz, 1 GB of keypoints): a longer
span is a clock or unit mistake, refused before it is allocated."""


def _points_format(fmt: str) -> tuple[str, int]:
    """(format of :func:`from_format`, number of points) of a keypoint stream format."""
    if fmt in ("handsim21", "mediapipe_world"):
        return "mediapipe21", 21
    if fmt == "webxr25":
        return "openxr26", 25
    return fmt, len(FORMATS[fmt])


def _check_choice(name: str, value: object, valid: Sequence[str], where: str) -> str:
    if not isinstance(value, str) or value not in valid:
        raise InvalidStream(
            f"{where}{name}={value!r} is not valid; choose one of {', '.join(valid)}"
        )
    return value


def default_up_axis(fmt: str) -> str:
    """The source frame of a format when the file does not say (module docstring)."""
    if fmt in ("openxr26", "webxr25"):
        return "y"
    if fmt == "mediapipe_world":
        return "-y"
    return "z"


def frame_to_world(points: np.ndarray, fmt: str, up_axis: str, scale: float = 1.0) -> np.ndarray:
    """Points of one or more frames of a format -> canonical 21 keypoints, world frame, metres.

    Args:
        points: (..., N, 3) points in the order of ``fmt`` (NaN rows = not tracked).
        fmt: a keypoint format of :data:`STREAM_FORMATS` (not ``pose27``).
        up_axis: one of :data:`UP_AXES`.
        scale: metres per source unit (1 for metres, 1e-3 for millimetres).

    Returns:
        (..., 21, 3) float64 keypoints, world frame, metres; NaN rows for absent points.
    """
    base, n = _points_format(fmt)
    pts = np.asarray(points, dtype=np.float64) * scale
    if fmt == "webxr25":
        pad = np.full((*pts.shape[:-2], 1, 3), np.nan)
        pts = np.concatenate([pad, pts], axis=-2)
    kp = from_format(pts, base)
    return kp @ _TO_WORLD[up_axis].T


@dataclasses.dataclass(frozen=True, eq=False)
class OperatorStream:
    """The operator's tracked hand over time, in the task's world frame.

    Attributes:
        times_s: (T,) float64 timestamps, seconds, strictly increasing.
        keypoints_world: (T, 21, 3) float64 keypoints, world frame, metres; NaN rows where a
            point is not tracked.
        poses: (T, 27) float64 pose vectors (``pose27`` streams and generated ones), world
            frame, else ``None``.
        side: ``"right"`` or ``"left"``.
        hand_length_m: the operator's hand length, metres, when known (pose streams).
        radii_m: (T, 21) joint radii, metres, of OpenXR / WebXR streams (NaN where absent),
            else ``None``.
        source: where the stream came from (a path, ``"expert:handsim/Grasp-v0 seed 0"``, ...).
    """

    times_s: np.ndarray
    keypoints_world: np.ndarray
    poses: np.ndarray | None = None
    side: str = "right"
    hand_length_m: float | None = None
    radii_m: np.ndarray | None = None
    source: str = ""

    def __post_init__(self) -> None:
        t = np.asarray(self.times_s, dtype=np.float64)
        kp = np.asarray(self.keypoints_world, dtype=np.float64)
        if t.ndim != 1 or t.size < 1:
            raise InvalidStream(f"times_s must be a (T,) array with T >= 1; received {t.shape}")
        if kp.shape != (t.size, 21, 3):
            raise InvalidStream(
                f"keypoints_world must have shape (T, 21, 3) = ({t.size}, 21, 3); received "
                f"{kp.shape}"
            )
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            bad = int(np.argmax(~np.isfinite(t) | np.r_[False, np.diff(t) <= 0]))
            raise InvalidStream(
                f"times_s must be finite and strictly increasing; frame {bad} has t = {t[bad]}"
            )
        _check_choice("side", self.side, ("right", "left"), "")
        object.__setattr__(self, "times_s", t)
        object.__setattr__(self, "keypoints_world", kp)
        if self.poses is not None:
            poses = np.asarray(self.poses, dtype=np.float64)
            if poses.shape != (t.size, 27):
                raise InvalidStream(f"poses must have shape ({t.size}, 27); received {poses.shape}")
            object.__setattr__(self, "poses", poses)

    def __len__(self) -> int:
        return int(self.times_s.size)

    @property
    def duration_s(self) -> float:
        """Time from the first to the last frame, seconds."""
        return float(self.times_s[-1] - self.times_s[0])

    def rate_hz(self) -> float:
        """The stream's rate, Hz: one over its median frame period (50 for a single frame)."""
        if len(self) < 2:
            return 50.0
        return float(1.0 / np.median(np.diff(self.times_s)))

    def resample(self, rate_hz: float) -> OperatorStream:
        """The stream at ``rate_hz`` from its first timestamp to its last (interpolated).

        Keypoints are interpolated linearly per coordinate (a point absent at either
        neighbour stays absent); poses linearly in position and angles and by slerp in the
        wrist rotation, and their keypoints come from forward kinematics.

        Args:
            rate_hz: the sim's control rate, Hz (> 0).

        Returns:
            A stream whose frame ``k`` is at ``times_s[0] + k / rate_hz``.
        """
        if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
            raise InvalidStream(f"rate_hz must be a finite number > 0; received {rate_hz!r}")
        t0 = self.times_s[0]
        frames = self.duration_s * rate_hz
        if not frames < MAX_RESAMPLED_FRAMES:  # also NaN and inf
            raise InvalidStream(
                f"the stream spans {self.duration_s:.4g} s (t from {t0:.6g} to "
                f"{self.times_s[-1]:.6g}); at {rate_hz:g} Hz that is {frames:.3g} frames, more "
                f"than {MAX_RESAMPLED_FRAMES}: check that its timestamps are seconds from one "
                "clock (or its fps)"
            )
        n = int(math.floor(frames + 1e-9)) + 1
        t = t0 + np.arange(n) / rate_hz
        src = self.times_s
        idx = np.clip(np.searchsorted(src, t, side="right") - 1, 0, len(src) - 1)
        nxt = np.minimum(idx + 1, len(src) - 1)
        span = src[nxt] - src[idx]
        w = np.where(span > 0, (t - src[idx]) / np.where(span > 0, span, 1.0), 0.0)
        kp = self.keypoints_world
        new_kp = (1 - w)[:, None, None] * kp[idx] + w[:, None, None] * kp[nxt]
        exact = w == 0.0  # keep frames exactly (0 * NaN would be NaN anyway)
        new_kp[exact] = kp[idx[exact]]
        poses = radii = None
        if self.poses is not None:
            p = self.poses
            poses = (1 - w)[:, None] * p[idx] + w[:, None] * p[nxt]
            if len(src) > 1:
                slerp = Slerp(src, Rotation.from_rotvec(p[:, 3:6]))
                poses[:, 3:6] = slerp(np.clip(t, src[0], src[-1])).as_rotvec()
            new_kp = _pose_keypoints(poses, self.side, self.hand_length_m)
        if self.radii_m is not None:
            r = self.radii_m
            radii = (1 - w)[:, None] * r[idx] + w[:, None] * r[nxt]
        return dataclasses.replace(
            self, times_s=t, keypoints_world=new_kp, poses=poses, radii_m=radii
        )

    def translated(self, offset_m: Sequence[float]) -> OperatorStream:
        """The stream moved by ``offset_m`` (3,), metres, world frame."""
        offset = np.asarray(offset_m, dtype=np.float64).reshape(3)
        poses = None
        if self.poses is not None:
            poses = self.poses.copy()
            poses[:, :3] += offset
        return dataclasses.replace(self, keypoints_world=self.keypoints_world + offset, poses=poses)

    def first_wrist_m(self) -> np.ndarray:
        """(3,) the first tracked wrist position (keypoint 0), metres, world frame."""
        wrist = self.keypoints_world[:, 0]
        ok = np.all(np.isfinite(wrist), axis=1)
        if not ok.any():
            raise InvalidStream(f"the stream {self.source!r} never tracks the wrist (keypoint 0)")
        return wrist[int(np.argmax(ok))].copy()


def _pose_keypoints(poses: np.ndarray, side: str, hand_length_m: float | None) -> np.ndarray:
    fk = ForwardKinematics(hand_params(hand_length_m or HAND_SIZES["medium"], side))
    return fk.keypoints(HandPose.from_vector(poses))


# Files ------------------------------------------------------------------------------------


def _where(source: str) -> str:
    return f"stream {source}: "


def _array(where: str, field: str, value: Any, frame: int | None = None) -> np.ndarray:
    at = f"{field}" if frame is None else f"frames[{frame}].{field}"
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidStream(
            f"{where}{at} must be numbers (null for an untracked value); received "
            f"{str(value)[:60]!r}"
        ) from None
    return arr


def parse_stream(doc: dict[str, Any], source: str = "<dict>") -> OperatorStream:
    """Build a stream from a parsed JSON document or NPZ arrays (module docstring's schema).

    Args:
        doc: the file's keys (JSON object, or NPZ arrays by name).
        source: a name for messages (the path).

    Returns:
        The stream in the world frame, metres, at the file's own timestamps.

    Raises:
        InvalidStream: naming the field, the frame and what is valid.
    """
    where = _where(source)
    if not isinstance(doc, dict):
        raise InvalidStream(
            f"{where}the top level must be an object with 'frames'; received {type(doc).__name__}"
        )
    fmt = _check_choice("format", _str(doc.get("format", "handsim21")), STREAM_FORMATS, where)
    units = _check_choice("units", _str(doc.get("units", "m")), ("m", "mm"), where)
    scale = 1e-3 if units == "mm" else 1.0
    up = _check_choice("up_axis", _str(doc.get("up_axis", default_up_axis(fmt))), UP_AXES, where)
    side = _check_choice("hand", _str(doc.get("hand", "right")), ("right", "left"), where)
    length = doc.get("hand_length_m")
    if length is not None:
        length = float(_array(where, "hand_length_m", length))
        try:
            hand_params(length, side)
        except HandSimError as err:
            raise InvalidStream(f"{where}hand_length_m: {err}") from None
    if fmt == "pose27" and up != "z":
        raise InvalidStream(f"{where}up_axis must be 'z' for format 'pose27'; received {up!r}")
    key = "pose" if fmt == "pose27" else "keypoints"
    n_points = 27 if fmt == "pose27" else _points_format(fmt)[1]
    want = "(27,)" if fmt == "pose27" else f"({n_points}, 3)"
    if "frames" in doc:  # JSON
        frames = doc["frames"]
        if not isinstance(frames, list) or not frames:
            raise InvalidStream(
                f"{where}frames must be a non-empty list; received {str(frames)[:60]!r}"
            )
        if len(frames) > MAX_STREAM_FRAMES:
            raise InvalidStream(
                f"{where}frames has {len(frames)} frames; at most {MAX_STREAM_FRAMES}"
            )
        values, times, radii = [], [], []
        for i, frame in enumerate(frames):
            if not isinstance(frame, dict) or key not in frame:
                raise InvalidStream(
                    f"{where}frames[{i}] must be an object with {key!r} {want}; received "
                    f"{str(frame)[:60]!r}"
                )
            values.append(_array(where, key, _nulls(_null_rows(frame[key], fmt)), i))
            if values[-1].shape != (27,) if fmt == "pose27" else values[-1].shape != (n_points, 3):
                raise InvalidStream(
                    f"{where}frames[{i}].{key} has shape {values[-1].shape}; format {fmt!r} "
                    f"needs {want}"
                )
            times.append(frame.get("t"))
            if "radii" in frame:
                radii.append(_array(where, "radii", _nulls(frame["radii"]), i))
                if radii[-1].shape != (n_points,):
                    raise InvalidStream(
                        f"{where}frames[{i}].radii has shape {radii[-1].shape};"
                        f" format {fmt!r} needs ({n_points},)"
                    )
        values_arr = np.stack(values)
        if all(t is None for t in times):
            times_arr = None
        else:
            for i, t in enumerate(times):
                if t is None or isinstance(t, bool) or not isinstance(t, (int, float)):
                    raise InvalidStream(
                        f"{where}frames[{i}].t must be a number of seconds (give every frame "
                        f"a 't', or none and an 'fps'); received {t!r}"
                    )
            times_arr = np.array(times, dtype=np.float64)
        radii_arr = np.stack(radii) if radii and len(radii) == len(values) else None
    else:  # NPZ
        if key not in doc:
            raise InvalidStream(
                f"{where}missing the array {key!r} of shape (T, *{want}) for "
                f"format {fmt!r}; keys: {sorted(doc)}"
            )
        values_arr = _array(where, key, doc[key])
        full = (27,) if fmt == "pose27" else (n_points, 3)
        if values_arr.ndim != 1 + len(full) or values_arr.shape[1:] != full or not len(values_arr):
            raise InvalidStream(
                f"{where}{key} has shape {values_arr.shape}; format {fmt!r} "
                f"needs (T, {', '.join(map(str, full))}) with T >= 1"
            )
        times_arr = _array(where, "t", doc["t"]) if "t" in doc else None
        radii_arr = _array(where, "radii", doc["radii"]) if "radii" in doc else None
        if radii_arr is not None and radii_arr.shape != (len(values_arr), n_points):
            raise InvalidStream(
                f"{where}radii has shape {radii_arr.shape}; needs ({len(values_arr)}, {n_points})"
            )
    n = len(values_arr)
    if times_arr is None:
        fps = doc.get("fps")
        if fps is None:
            raise InvalidStream(
                f"{where}no timestamps: give frames a 't' (seconds) or the file an 'fps'"
            )
        fps = float(_array(where, "fps", fps))
        if not (math.isfinite(fps) and fps > 0):
            raise InvalidStream(f"{where}fps must be a number > 0; received {fps}")
        low, high = STREAM_FPS_RANGE
        if not low <= fps <= high:
            # fps 1e-300 spread two frames 1e300 s apart without a word.
            raise InvalidStream(
                f"{where}fps must be in [{low:g}, {high:g}] frames per second (a tracker's "
                f"rate); received {fps:g}"
            )
        times_arr = np.arange(n) / fps
    if times_arr.shape != (n,):
        raise InvalidStream(f"{where}t has shape {times_arr.shape}; needs ({n},), one per frame")
    for i in range(n):
        if not math.isfinite(times_arr[i]) or (i and times_arr[i] <= times_arr[i - 1]):
            raise InvalidStream(
                f"{where}frame {i}: t = {times_arr[i]} must be finite and greater than the "
                f"previous frame's ({times_arr[i - 1] if i else '-'}); timestamps are seconds, "
                "strictly increasing"
            )
    if fmt == "pose27":
        bad = ~np.isfinite(values_arr)
        if bad.any():
            i, j = (int(v) for v in np.argwhere(bad)[0])
            raise InvalidStream(
                f"{where}frame {i}: pose[{j}] is not finite; poses need 27 finite numbers"
            )
        _check_magnitude(where, values_arr[:, :3], "pose (wrist position)")
        kp = _pose_keypoints(values_arr, side, length)
        return OperatorStream(
            times_arr, kp, values_arr, side, length or HAND_SIZES["medium"], None, source
        )
    # A point is tracked when all three coordinates are numbers.
    partial = np.isfinite(values_arr).any(-1) & ~np.isfinite(values_arr).all(-1)
    if partial.any():
        i, j = (int(v) for v in np.argwhere(partial)[0])
        raise InvalidStream(
            f"{where}frame {i}: keypoints[{j}] = {values_arr[i, j].tolist()} "
            "has some but not all coordinates; give 3 numbers or 3 nulls"
        )
    _check_magnitude(where, values_arr * scale, "keypoints")
    kp = frame_to_world(values_arr, fmt, up, scale)
    radii_world = None
    if radii_arr is not None:
        neg = radii_arr < 0
        if neg.any():
            i, j = (int(v) for v in np.argwhere(neg)[0])
            raise InvalidStream(f"{where}frame {i}: radii[{j}] = {radii_arr[i, j]} must be >= 0")
        r = radii_arr * scale
        base, _ = _points_format(fmt)
        if fmt == "webxr25":
            r = np.concatenate([np.full((n, 1), np.nan), r], axis=1)
        radii_world = from_format(r[..., None], base)[..., 0]
    _check_hand_size(where, kp, units)
    return OperatorStream(times_arr, kp, None, side, length, radii_world, source)


def _check_magnitude(where: str, values: np.ndarray, field: str) -> None:
    big = np.abs(np.nan_to_num(values)) > _MAX_ABS_M
    if big.any():
        idx = tuple(int(v) for v in np.argwhere(big)[0])
        raise InvalidStream(
            f"{where}frame {idx[0]}: {field} value {values[idx]} is beyond {_MAX_ABS_M} m; "
            "are the units right ('units': 'm' or 'mm')?"
        )


# Wrist, middle MCP, PIP, DIP and tip: their bone lengths add up to the hand length whatever
# the pose.
_MIDDLE_CHAIN = [0, 9, 10, 11, 12]


def _check_hand_size(where: str, kp_m: np.ndarray, units: str) -> None:
    """Refuse keypoints whose hand is not of a human size (a metre/millimetre mistake)."""
    chain = kp_m[:, _MIDDLE_CHAIN]
    tracked = np.isfinite(chain).all(axis=(1, 2))
    if not tracked.any():
        return  # no frame shows the whole middle finger: nothing to measure
    bones = np.linalg.norm(np.diff(chain[tracked], axis=1), axis=-1).sum(axis=1)
    length_m = float(np.median(bones))
    low, high = HAND_LENGTH_PLAUSIBLE_M
    if low <= length_m <= high:
        return
    hint = "check the keypoint format and the units"
    if low <= length_m * 1000 <= high and units == "mm":
        hint = "the values look like metres: set 'units': 'm'"
    elif low <= length_m / 1000 <= high and units == "m":
        hint = "the values look like millimetres: set 'units': 'mm'"
    raise InvalidStream(
        f"{where}the keypoints show a hand {length_m * 1000:.4g} mm long (wrist to middle "
        f"fingertip, median of {int(tracked.sum())} frames, read with 'units': {units!r}); a "
        f"human hand is {low * 1000:.0f}-{high * 1000:.0f} mm: {hint}"
    )


def _str(value: Any) -> Any:
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return str(value)
    return value


def _null_rows(rows: Any, fmt: str) -> Any:
    """A ``null`` joint row (untracked, as in live packets) -> three nulls."""
    if fmt == "pose27" or not isinstance(rows, list):
        return rows
    return [[None, None, None] if row is None else row for row in rows]


def _nulls(value: Any) -> Any:
    """JSON null -> NaN (an untracked joint)."""
    if isinstance(value, list):
        return [_nulls(v) for v in value]
    return math.nan if value is None else value


def load_stream(path: str | os.PathLike[str], rate_hz: float | None = None) -> OperatorStream:
    """Read a stream file (``.json`` or ``.npz``; schema in the module docstring).

    Args:
        path: the file.
        rate_hz: resample to this rate (the sim's control rate), Hz; ``None`` keeps the file's
            timestamps.

    Returns:
        The stream, world frame, metres.

    Raises:
        InvalidStream: for a missing or unreadable file, an unknown suffix, or malformed
            content (naming the field and the frame).
    """
    p = pathlib.Path(path)
    if not p.is_file():
        raise InvalidStream(f"stream file {str(p)!r} does not exist")
    suffix = p.suffix.lower()
    if suffix == ".json":
        try:
            doc = json.loads(p.read_text())
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            raise InvalidStream(f"stream {p}: not valid JSON ({err})") from None
        except RecursionError:
            raise InvalidStream(
                f"stream {p}: JSON nested too deeply to be a stream (the schema is two levels)"
            ) from None
    elif suffix == ".npz":
        try:
            with np.load(p, allow_pickle=False) as npz:
                doc = {k: npz[k] for k in npz.files}
        except (OSError, ValueError) as err:
            raise InvalidStream(f"stream {p}: not a readable NPZ file ({err})") from None
        for k in ("format", "units", "up_axis", "hand"):
            if k in doc:
                doc[k] = str(doc[k])
        for k in ("fps", "hand_length_m"):
            if k in doc:
                doc[k] = float(doc[k])
    else:
        raise InvalidStream(
            f"stream file {str(p)!r} must end in .json or .npz; received {suffix or 'no suffix'!r}"
        )
    stream = parse_stream(doc, str(p))
    return stream.resample(rate_hz) if rate_hz is not None else stream


def save_stream(stream: OperatorStream, path: str | os.PathLike[str]) -> pathlib.Path:
    """Write a stream as ``.json`` or ``.npz``.

    The format is ``pose27`` if the stream has poses, else ``handsim21``; world frame, metres,
    ``up_axis`` ``"z"``.

    Returns:
        The written path.
    """
    p = pathlib.Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fmt = "pose27" if stream.poses is not None else "handsim21"
    head: dict[str, Any] = {"format": fmt, "units": "m", "up_axis": "z", "hand": stream.side}
    if stream.hand_length_m is not None:
        head["hand_length_m"] = float(stream.hand_length_m)
    values = stream.poses if stream.poses is not None else stream.keypoints_world
    key = "pose" if fmt == "pose27" else "keypoints"
    if p.suffix.lower() == ".npz":
        np.savez_compressed(
            p, t=stream.times_s, **{key: values}, **{k: np.array(v) for k, v in head.items()}
        )
    elif p.suffix.lower() == ".json":
        p.write_text(json.dumps(stream_to_doc(stream)))
    else:
        raise InvalidStream(f"stream file {str(p)!r} must end in .json or .npz")
    return p


def stream_to_doc(stream: OperatorStream) -> dict[str, Any]:
    """The stream as the JSON object of a stream file (what :func:`save_stream` writes)."""
    fmt = "pose27" if stream.poses is not None else "handsim21"
    head: dict[str, Any] = {"format": fmt, "units": "m", "up_axis": "z", "hand": stream.side}
    if stream.hand_length_m is not None:
        head["hand_length_m"] = float(stream.hand_length_m)
    values = stream.poses if stream.poses is not None else stream.keypoints_world
    key = "pose" if fmt == "pose27" else "keypoints"
    frames = [
        {
            "t": float(t),
            key: [[None if not math.isfinite(x) else float(x) for x in row] for row in v]
            if v.ndim == 2
            else [float(x) for x in v],
        }
        for t, v in zip(stream.times_s, values, strict=True)
    ]
    return {**head, "frames": frames}


# Generated streams ----------------------------------------------------------------------------


def stream_from_poses(
    poses: HandPose | np.ndarray,
    dt_s: float,
    *,
    side: str = "right",
    hand_length_m: float | None = None,
    source: str = "poses",
) -> OperatorStream:
    """A stream of 27-DoF poses sampled every ``dt_s`` seconds (keypoints by kinematics).

    Args:
        poses: a batch of T poses (or a (T, 27) array), world frame.
        dt_s: sample period, seconds.
        side: the operator's hand side.
        hand_length_m: the operator's hand length (default: medium, 0.189 m).
        source: a label.
    """
    vec = poses.vector if isinstance(poses, HandPose) else np.asarray(poses, dtype=np.float64)
    vec = np.atleast_2d(vec)
    length = hand_length_m or HAND_SIZES["medium"]
    kp = _pose_keypoints(vec, side, length)
    return OperatorStream(np.arange(len(vec)) * float(dt_s), kp, vec, side, length, None, source)


def stream_from_motion(
    rng: np.random.Generator,
    duration_s: float,
    dt_s: float,
    *,
    wrist_pos_m: Sequence[float] = (0.0, -0.1, 0.15),
    wrist_rotvec: Sequence[float] = (0.0, math.pi, 0.0),
    wrist_range_m: float = 0.05,
    side: str = "right",
    hand_length_m: float | None = None,
) -> OperatorStream:
    """A random smooth motion of :func:`~handsim.hand.pose_sources.random_motion` above the table.

    The motion's wrist (drawn around the origin) is moved to ``wrist_pos_m`` and turned by
    ``wrist_rotvec`` (default: palm down, fingers away from the user).

    Args:
        rng: random generator.
        duration_s: seconds.
        dt_s: sample period, seconds.
        wrist_pos_m: (3,) centre of the wrist's motion, world frame, metres.
        wrist_rotvec: (3,) base wrist rotation, world frame.
        wrist_range_m: half-side of the wrist's motion cube, metres.
        side: hand side.
        hand_length_m: the operator's hand length (default: medium).
    """
    from handsim.hand.pose_sources import random_motion

    motion = random_motion(
        rng, duration_s, dt_s, wrist_range_m=wrist_range_m, wrist_rotation_rad=0.3
    )
    vec = motion.vector.copy()
    base = Rotation.from_rotvec(wrist_rotvec)
    vec[:, :3] = base.apply(vec[:, :3]) + np.asarray(wrist_pos_m)
    vec[:, 3:6] = (base * Rotation.from_rotvec(vec[:, 3:6])).as_rotvec()
    return stream_from_poses(
        vec, dt_s, side=side, hand_length_m=hand_length_m, source=f"motion {duration_s} s"
    )


def stream_from_expert(
    env_id: str = "handsim/Grasp-v0",
    seed: int = 0,
    *,
    env_kwargs: dict[str, Any] | None = None,
    max_steps: int | None = None,
) -> OperatorStream:
    """The scripted expert's commands of one episode, as an operator stream.

    Runs the env's expert on the ground truth (``obs_mode="state"``: nothing is rendered) and
    records its 27-DoF command every control step: what an operator doing the task would
    have done. Replayed through :class:`~handsim.envs.teleop.TeleopLoop` on the same seed
    without faults, the physical hand repeats the expert's episode.

    Args:
        env_id: a registered handsim id whose env has ``make_expert`` and ``expert_state``.
        seed: the episode's seed (replay on the same seed: the same scene).
        env_kwargs: more keyword arguments of ``gym.make``.
        max_steps: stop after this many steps (default: the episode's end or the env's limit).

    Returns:
        A ``pose27`` stream at the env's control rate, starting at t = 0 (the reset).
    """
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)

    kwargs = {"obs_mode": "state", **(env_kwargs or {})}
    env = gym.make(env_id, **kwargs)
    try:
        base = env.unwrapped
        _, info = env.reset(seed=seed)
        expert = base.make_expert(np.random.default_rng(seed))
        limit = max_steps or (env.spec.max_episode_steps if env.spec else None) or 400
        poses = [base.scene.binding.pose(base.scene.data).vector]
        for _ in range(limit):
            action = expert.act(base.expert_state()).vector
            poses.append(np.clip(action, env.action_space.low, env.action_space.high))
            _, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        params = base.scene.hand.params
        return stream_from_poses(
            np.stack(poses),
            base.control_dt,
            side=params.side,
            hand_length_m=params.hand_length,
            source=f"expert:{env_id} seed {seed}",
        )
    finally:
        env.close()
