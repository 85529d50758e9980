"""Smooth hand motions: minimum-jerk trajectories through keyframes with human speed limits.

Motion
------

:func:`smooth_motion` joins keyframes with minimum-jerk segments (Flash & Hogan 1985):
``s(tau) = 10 tau**3 - 15 tau**4 + 6 tau**5``, whose peak speed is ``1.875 * delta / T``. Each
segment takes the shortest duration (rounded up to whole ``dt``) for which no joint, the wrist
position and the wrist rotation (slerp, same time scaling) exceed their speed limits:

- :data:`MAX_JOINT_SPEED` = 49.1 rad/s: closing the hand (90 deg of flexion) in 60 ms at
  natural fast speed (handsim design) with a minimum-jerk profile, ``1.875 * (pi / 2) / 0.06``.
- :data:`MAX_WRIST_SPEED` = 1.0 m/s, a natural reaching speed [E]; fast human hand movements
  reach 5 m/s (:data:`WRIST_SPEED_CAP`, the largest value accepted).
- :data:`MAX_WRIST_ANGULAR_SPEED` = 3.0 rad/s, a natural wrist/forearm rotation speed [E].

Sample ``k`` of a motion is at time ``k * dt`` seconds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from handsim._validate import show, to_real_array
from handsim.errors import InvalidPose, UnknownName
from handsim.hand._sampling import (
    MAX_SAMPLES,
    _add_noise,
    _check_nonnegative,
    _check_positive,
    _check_range,
    _check_rng,
)
from handsim.hand.pose import NUM_ANGLES, HandPose
from handsim.hand.pose_library import GESTURES, GRASP_TYPES
from handsim.hand.samplers import sample_synergy, sample_uniform

__all__ = [
    "MAX_JOINT_SPEED",
    "MAX_WRIST_SPEED",
    "WRIST_SPEED_CAP",
    "MAX_WRIST_ANGULAR_SPEED",
    "minimum_jerk",
    "segment_durations",
    "smooth_motion",
    "MOTION_SOURCES",
    "random_motion",
]


# 5. Smooth motions -------------------------------------------------------------------------

MAX_JOINT_SPEED = 1.875 * (np.pi / 2) / 0.060
"""Peak joint speed, rad/s (49.1): a 90 deg minimum-jerk closure in 60 ms."""
MAX_WRIST_SPEED = 1.0
"""Default peak wrist translation speed, m/s (natural reaching [E])."""
WRIST_SPEED_CAP = 5.0
"""Largest accepted ``max_wrist_speed``, m/s (fast human hand movements)."""
MAX_WRIST_ANGULAR_SPEED = 3.0
"""Default peak wrist rotation speed, rad/s [E]."""

_MIN_JERK_PEAK = 1.875


def minimum_jerk(tau: np.ndarray | float) -> np.ndarray:
    """Minimum-jerk position profile ``10 t^3 - 15 t^4 + 6 t^5``.

    Args:
        tau: normalized time, clipped to [0, 1].

    Returns:
        Progress in [0, 1], same shape; zero velocity and acceleration at both ends.
    """
    t = np.clip(np.asarray(tau, dtype=np.float64), 0.0, 1.0)
    return t**3 * (10.0 + t * (-15.0 + 6.0 * t))


def _check_keyframes(keyframes: object) -> list[HandPose]:
    if isinstance(keyframes, HandPose):
        raise InvalidPose(
            "keyframes must be a sequence of single HandPose objects, not one HandPose; "
            "wrap it in a list"
        )
    try:
        frames = list(keyframes)  # type: ignore[call-overload]
    except TypeError:
        raise InvalidPose(
            f"keyframes must be a sequence of HandPose; received {type(keyframes).__name__}"
        ) from None
    if not frames:
        raise InvalidPose("keyframes must hold at least 1 HandPose; received an empty sequence")
    for i, f in enumerate(frames):
        if not isinstance(f, HandPose) or f.batch_shape != ():
            what = f"batch shape {f.batch_shape}" if isinstance(f, HandPose) else type(f).__name__
            raise InvalidPose(f"keyframe {i} must be a single HandPose; received {what}")
        f.validate()
    return frames


def _speed_limits(
    max_joint_speed: float | np.ndarray, max_wrist_speed: float, max_wrist_angular_speed: float
) -> tuple[np.ndarray, float, float]:
    try:
        if isinstance(max_joint_speed, (bool, np.bool_)):
            raise TypeError("max_joint_speed")
        joint = np.broadcast_to(to_real_array(max_joint_speed), (NUM_ANGLES,))
    except (TypeError, ValueError):
        joint = np.full(NUM_ANGLES, np.nan)
    if not np.all(np.isfinite(joint) & (joint > 0.0)):
        raise InvalidPose(
            "max_joint_speed must be > 0 rad/s, a scalar or one per joint (21,); received "
            f"{max_joint_speed!r}"
        )
    wrist = _check_positive(max_wrist_speed, "max_wrist_speed", "m/s")
    if wrist > WRIST_SPEED_CAP:
        raise InvalidPose(
            f"max_wrist_speed must be at most {WRIST_SPEED_CAP} m/s (fast human hand "
            f"movements); received {max_wrist_speed!r}"
        )
    angular = _check_positive(max_wrist_angular_speed, "max_wrist_angular_speed", "rad/s")
    return joint, wrist, angular


def _segment_durations(
    frames: list[HandPose], joint: np.ndarray, wrist: float, angular: float
) -> np.ndarray:
    # scipy.spatial loads when a motion is made, not on `import handsim`.
    from scipy.spatial.transform import Rotation

    out = np.zeros(len(frames) - 1)
    for i, (a, b) in enumerate(zip(frames[:-1], frames[1:], strict=True)):
        rel = Rotation.from_rotvec(a.wrist_rotvec).inv() * Rotation.from_rotvec(b.wrist_rotvec)
        out[i] = _MIN_JERK_PEAK * max(
            float(np.max(np.abs(b.angles - a.angles) / joint)),
            float(np.linalg.norm(b.wrist_pos - a.wrist_pos)) / wrist,
            float(rel.magnitude()) / angular,
        )
    return out


def segment_durations(
    keyframes: Sequence[HandPose],
    *,
    max_joint_speed: float | np.ndarray = MAX_JOINT_SPEED,
    max_wrist_speed: float = MAX_WRIST_SPEED,
    max_wrist_angular_speed: float = MAX_WRIST_ANGULAR_SPEED,
) -> np.ndarray:
    """Shortest minimum-jerk duration of each segment between consecutive keyframes.

    Args:
        keyframes: K single poses within the joint limits.
        max_joint_speed: peak joint speed, rad/s, scalar or (21,).
        max_wrist_speed: peak wrist translation speed, m/s (at most :data:`WRIST_SPEED_CAP`).
        max_wrist_angular_speed: peak wrist rotation speed, rad/s.

    Returns:
        (K - 1,) seconds, ``1.875 * max(delta / limit)`` over joints, position and rotation.

    Raises:
        InvalidPose: for bad keyframes or limits.
    """
    frames = _check_keyframes(keyframes)
    limits = _speed_limits(max_joint_speed, max_wrist_speed, max_wrist_angular_speed)
    return _segment_durations(frames, *limits)


def _assemble(
    frames: list[HandPose], durations: np.ndarray, holds: np.ndarray, dt: float
) -> HandPose:
    """Sample the minimum-jerk path; each segment and hold is rounded up to whole ``dt``."""
    from scipy.spatial.transform import Rotation, Slerp

    pos, rot, ang = [], [], []

    def hold(frame: HandPose, seconds: float) -> None:
        steps = math.ceil(seconds / dt - 1e-9)
        pos.append(np.repeat(frame.wrist_pos[None], steps, axis=0))
        rot.append(np.repeat(frame.wrist_rotvec[None], steps, axis=0))
        ang.append(np.repeat(frame.angles[None], steps, axis=0))

    pos.append(frames[0].wrist_pos[None])
    rot.append(frames[0].wrist_rotvec[None])
    ang.append(frames[0].angles[None])
    hold(frames[0], holds[0])
    for i, (a, b) in enumerate(zip(frames[:-1], frames[1:], strict=True)):
        steps = math.ceil(durations[i] / dt - 1e-9)
        if steps > 0:
            s = minimum_jerk(np.arange(1, steps + 1) / steps)[:, None]
            pos.append((1.0 - s) * a.wrist_pos + s * b.wrist_pos)
            ang.append((1.0 - s) * a.angles + s * b.angles)
            key = Rotation.from_rotvec(np.stack([a.wrist_rotvec, b.wrist_rotvec]))
            rotvec = Slerp([0.0, 1.0], key)(s[:, 0]).as_rotvec()
            # Land exactly on the keyframe (no float round trip through quaternions).
            rotvec[-1] = b.wrist_rotvec
            pos[-1][-1] = b.wrist_pos
            ang[-1][-1] = b.angles
            rot.append(rotvec)
        hold(b, holds[i + 1])
    # Keyframes are within limits and s is monotone in [0, 1]: no clipping needed.
    return HandPose(np.concatenate(pos), np.concatenate(rot), np.concatenate(ang))


def _check_holds(hold: float | Sequence[float], count: int) -> np.ndarray:
    try:
        h = np.asarray(hold)
    except ValueError:
        h = np.full(count, math.nan)
    h = h.astype(np.float64) if h.dtype.kind in "iuf" else np.full(count, math.nan)
    if h.ndim == 0:
        h = np.full(count, float(h))
    if h.shape != (count,) or not np.all(np.isfinite(h) & (h >= 0.0)):
        raise InvalidPose(
            f"hold must be seconds >= 0, a scalar or one per keyframe ({count}); received {hold!r}"
        )
    return h


def smooth_motion(
    keyframes: Sequence[HandPose],
    dt: float,
    *,
    max_joint_speed: float | np.ndarray = MAX_JOINT_SPEED,
    max_wrist_speed: float = MAX_WRIST_SPEED,
    max_wrist_angular_speed: float = MAX_WRIST_ANGULAR_SPEED,
    hold: float | Sequence[float] = 0.0,
) -> HandPose:
    """A minimum-jerk motion through keyframes, as fast as the speed limits allow.

    Each segment lasts :func:`segment_durations` rounded up to a whole number of ``dt``, so
    every keyframe is a sample and no peak speed exceeds its limit. Angles and the wrist
    position follow ``a + s (b - a)``, the wrist rotation the slerp at ``s``, with ``s`` the
    :func:`minimum_jerk` profile.

    Args:
        keyframes: K >= 1 single poses within the joint limits.
        dt: sample period, seconds (> 0).
        max_joint_speed: peak joint speed, rad/s, scalar or (21,) per joint.
        max_wrist_speed: peak wrist speed, m/s, at most :data:`WRIST_SPEED_CAP`.
        max_wrist_angular_speed: peak wrist rotation speed, rad/s.
        hold: seconds to stay at each keyframe (the first and last included), scalar or (K,);
            rounded up to whole ``dt``.

    Returns:
        A batch over time (T,): sample k is at ``k * dt`` s; sample 0 is the first keyframe
        and sample T - 1 the last, exactly.

    Raises:
        InvalidPose: for no keyframe, a batched or out-of-limit keyframe, ``dt <= 0``, a
            non-positive speed limit, a wrist speed above the cap or a negative hold.
    """
    frames = _check_keyframes(keyframes)
    dt = _check_positive(dt, "dt", "seconds")
    limits = _speed_limits(max_joint_speed, max_wrist_speed, max_wrist_angular_speed)
    holds = _check_holds(hold, len(frames))
    durations = _segment_durations(frames, *limits)
    steps = 1 + sum(math.ceil(t / dt - 1e-9) for t in (*durations, *holds))
    if steps > MAX_SAMPLES:
        raise InvalidPose(
            f"the motion would have {steps} samples, more than {MAX_SAMPLES}; use a larger dt "
            f"(received {dt!r} s) or shorter holds"
        )
    return _assemble(frames, durations, holds, dt)


MOTION_SOURCES: tuple[str, ...] = ("gestures", "grasps", "synergy", "uniform")
"""Keyframe sources of :func:`random_motion`."""


def _random_keyframe(rng: np.random.Generator, source: str, noise_deg: float) -> np.ndarray:
    if source == "gestures":
        name = tuple(GESTURES)[rng.integers(len(GESTURES))]
        return _add_noise(GESTURES[name].angles.copy(), rng, noise_deg)
    if source == "grasps":
        name = tuple(GRASP_TYPES)[rng.integers(len(GRASP_TYPES))]
        return _add_noise(GRASP_TYPES[name].angles(rng.uniform(0.0, 1.0)), rng, noise_deg)
    if source == "synergy":
        return sample_synergy(rng, 1, num_synergies=5).angles[0]
    return sample_uniform(rng, 1).angles[0]


def random_motion(
    rng: np.random.Generator,
    duration: float,
    dt: float,
    *,
    sources: Sequence[str] = ("gestures", "grasps"),
    hold_range: tuple[float, float] = (0.1, 0.6),
    speed_range: tuple[float, float] = (0.3, 1.0),
    wrist_range_m: float = 0.0,
    wrist_rotation_rad: float = 0.0,
    noise_deg: float = 3.0,
) -> HandPose:
    """A random sequence of postures joined by minimum-jerk segments.

    Keyframes are drawn one after another: a source uniformly from ``sources``, then a
    gesture (uniform name), a grasp (uniform type and closure in [0, 1]), a synergy posture (5
    components) or a coupled uniform posture; gestures and grasps get ``noise_deg`` noise. The
    wrist is drawn uniformly in a cube of half-side ``wrist_range_m`` around the origin and
    rotated by a uniform angle up to ``wrist_rotation_rad`` about a uniform axis. Each segment
    runs at a uniform fraction ``speed_range`` of the default speed limits (never faster), and
    each keyframe is held for a uniform time in ``hold_range``.

    Args:
        rng: random generator.
        duration: seconds (> 0).
        dt: sample period, seconds (> 0).
        sources: a non-empty subset of :data:`MOTION_SOURCES`.
        hold_range: (low, high) hold seconds, 0 <= low <= high.
        speed_range: (low, high) fractions of the speed limits, 0 < low <= high <= 1.
        wrist_range_m: half-side of the wrist position cube, metres (>= 0).
        wrist_rotation_rad: largest wrist rotation from identity, radians, in [0, pi].
        noise_deg: per-angle noise of gesture and grasp keyframes, degrees (>= 0).

    Returns:
        A batch over time of ``floor(duration / dt) + 1`` samples at ``k * dt`` s.

    Raises:
        UnknownName: for an unknown source (the message lists them).
        InvalidPose: for other bad arguments.
    """
    rng = _check_rng(rng)
    duration = _check_positive(duration, "duration", "seconds")
    dt = _check_positive(dt, "dt", "seconds")
    if not isinstance(sources, (str, Sequence)):
        raise InvalidPose(
            f"sources must be a name or a sequence of names of {', '.join(MOTION_SOURCES)}; "
            f"received {show(sources)}"
        )
    srcs = [sources] if isinstance(sources, str) else list(sources)
    if not srcs:
        raise InvalidPose(
            f"sources must name at least one of {', '.join(MOTION_SOURCES)}; received {sources!r}"
        )
    for s in srcs:
        if s not in MOTION_SOURCES:
            raise UnknownName(
                f"unknown motion source {s!r}; valid names: {', '.join(MOTION_SOURCES)}"
            )
    h_lo, h_hi = _check_range(hold_range, "hold_range", 0.0, math.inf, "seconds")
    v_lo, v_hi = _check_range(speed_range, "speed_range", 0.0, 1.0, "(fraction of the limits)")
    if v_lo <= 0.0:
        raise InvalidPose(f"speed_range must have low > 0; received {speed_range!r}")
    wrist_range_m = _check_nonnegative(wrist_range_m, "wrist_range_m", "metres")
    wrist_rotation_rad = _check_nonnegative(wrist_rotation_rad, "wrist_rotation_rad", "radians")
    if wrist_rotation_rad > np.pi:
        raise InvalidPose(f"wrist_rotation_rad must be in [0, pi]; received {wrist_rotation_rad!r}")
    _check_nonnegative(noise_deg, "noise_deg", "(degrees)")

    if dt > 3600.0:
        # A larger step is a mistake (and segments shorter than 1e-9 dt would never end).
        raise InvalidPose(f"dt must be at most 3600 seconds; received {dt!r}")
    if duration / dt > MAX_SAMPLES:
        raise InvalidPose(
            f"duration / dt must be at most {MAX_SAMPLES} samples; received duration={duration!r}"
            f" s, dt={dt!r} s"
        )
    num_samples = math.floor(duration / dt + 1e-9) + 1
    frames: list[HandPose] = []
    durations: list[float] = []
    holds: list[float] = []
    elapsed = 0.0
    while elapsed < num_samples * dt:
        angles = _random_keyframe(rng, srcs[rng.integers(len(srcs))], noise_deg)
        pos = rng.uniform(-wrist_range_m, wrist_range_m, size=3)
        axis = rng.normal(size=3)
        axis /= max(np.linalg.norm(axis), 1e-12)
        rotvec = axis * rng.uniform(0.0, wrist_rotation_rad)
        frame = HandPose(pos, rotvec, angles)
        if frames:
            speed = rng.uniform(v_lo, v_hi)
            limits = (
                MAX_JOINT_SPEED * speed,
                MAX_WRIST_SPEED * speed,
                MAX_WRIST_ANGULAR_SPEED * speed,
            )
            seg = float(
                _segment_durations(
                    [frames[-1], frame], np.full(NUM_ANGLES, limits[0]), *limits[1:]
                )[0]
            )
            durations.append(seg)
            elapsed += math.ceil(seg / dt - 1e-9) * dt
        # A hold longer than the motion is cut anyway (and must not be allocated).
        holds.append(min(rng.uniform(h_lo, h_hi), (num_samples + 1) * dt))
        elapsed += math.ceil(holds[-1] / dt - 1e-9) * dt
        frames.append(frame)
    motion = _assemble(frames, np.asarray(durations), np.asarray(holds), dt)
    return motion[:num_samples]
