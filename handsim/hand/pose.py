"""The 27-DoF hand pose: joint order, anatomical limits and the :class:`HandPose` type.

The pose vector is ``[wrist_pos (3), wrist_rotvec (3), angles (21)]``:

- ``wrist_pos``: position of the wrist keypoint (the origin of the hand frame) in the world
  frame, metres.
- ``wrist_rotvec``: rotation ``world_from_hand`` as a rotation vector (axis * angle), radians.
- ``angles``: the 21 articulations in :data:`JOINT_NAMES` order, radians.

Hand frame (right hand): origin at the wrist crease centre, ``+x`` radial (toward the thumb),
``+y`` distal (toward the fingertips), ``+z`` palmar. The left hand is the exact mirror image:
its frame has ``+x`` ulnar, so that the same angles give the mirrored posture.

Sign conventions: flexion is positive (toward the palm); finger MCP abduction is positive toward
the thumb (radial) for every finger; thumb CMC/MCP abduction is positive away from the palm
(palmar abduction).

Joint limits, in degrees, with their sources (``docs/hand.md`` has the table with what changed
and why):

=====================  ===========  =========================================================
joint                  range (deg)  source
=====================  ===========  =========================================================
thumb_cmc_flex         -40 .. 55    MyoHand CMC flex (-44.7 .. 40.1) adapted to handsim's
                                    thumb frame; at -40 the thumb and index metacarpals are
                                    62 deg apart in the palm plane: the clinical radial
                                    abduction of 60 deg (Eaton)
thumb_cmc_abd          -15 .. 60    clinical palmar abduction 45 / radial abduction 60 (Eaton)
thumb_mcp_flex         -10 .. 55    Eaton: MCP hyperextension 10 / flexion 55
thumb_mcp_abd          -10 .. 10    manotorch thumb MCP spread +-10
thumb_ip_flex          -15 .. 80    Eaton: IP hyperextension 15 / flexion 80
<finger>_mcp_flex      -20 .. 90    Lin et al. 2000 0 .. 90; hyperextension 20 (within the
                                    clinical 0 .. 45, Eaton)
index_mcp_abd          -15 .. 20    GraspIt HumanHand20DOF index +-20; ulnar side Lin +-15
middle_mcp_abd         -20 .. 20    Shadow hand knuckle +-20; goniometry norm 20 deg
ring_mcp_abd           -20 .. 20    GraspIt HumanHand20DOF ring +-20; holds the widest
                                    middle-ring spread (14.3 +- 2.3 deg, Chatzioglou et al.
                                    2024) with the middle finger straight
little_mcp_abd         -45 .. 15    ulnar: the mean widest ring-little spread (32.1 deg,
                                    Chatzioglou et al. 2024) beyond the ring's own ulnar
                                    deviation; MANO (D-Grasp) +-45.8; radial side limited by
                                    the ring finger
<finger>_pip_flex        0 .. 110   Lin et al. 2000
<finger>_dip_flex        0 .. 90    Lin et al. 2000
=====================  ===========  =========================================================
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from handsim.errors import InvalidPose

__all__ = [
    "FINGERS",
    "DIGITS",
    "JOINT_NAMES",
    "JOINT_LIMITS_DEG",
    "JOINT_LIMITS",
    "NUM_ANGLES",
    "NUM_DOF",
    "HandPose",
    "LimitViolation",
    "joint_index",
]

FINGERS: tuple[str, ...] = ("index", "middle", "ring", "little")
"""The four fingers, radial to ulnar."""
DIGITS: tuple[str, ...] = ("thumb",) + FINGERS
"""The five digits in keypoint order."""

_THUMB_JOINTS = ("cmc_flex", "cmc_abd", "mcp_flex", "mcp_abd", "ip_flex")
_FINGER_JOINTS = ("mcp_flex", "mcp_abd", "pip_flex", "dip_flex")

JOINT_NAMES: tuple[str, ...] = tuple(f"thumb_{j}" for j in _THUMB_JOINTS) + tuple(
    f"{f}_{j}" for f in FINGERS for j in _FINGER_JOINTS
)
"""The 21 articulations in pose-vector order (without the side prefix ``rh_``/``lh_``)."""

NUM_ANGLES = 21
NUM_DOF = 27

_FINGER_ABD_DEG = {"index": (-15, 20), "middle": (-20, 20), "ring": (-20, 20), "little": (-45, 15)}
_LIMITS_DEG: dict[str, tuple[float, float]] = {
    "thumb_cmc_flex": (-40.0, 55.0),
    "thumb_cmc_abd": (-15.0, 60.0),
    "thumb_mcp_flex": (-10.0, 55.0),
    "thumb_mcp_abd": (-10.0, 10.0),
    "thumb_ip_flex": (-15.0, 80.0),
}
for _f in FINGERS:
    _LIMITS_DEG[f"{_f}_mcp_flex"] = (-20.0, 90.0)
    _LIMITS_DEG[f"{_f}_mcp_abd"] = tuple(float(v) for v in _FINGER_ABD_DEG[_f])
    _LIMITS_DEG[f"{_f}_pip_flex"] = (0.0, 110.0)
    _LIMITS_DEG[f"{_f}_dip_flex"] = (0.0, 90.0)

JOINT_LIMITS_DEG: np.ndarray = np.array([_LIMITS_DEG[n] for n in JOINT_NAMES], dtype=np.float64)
"""(21, 2) lower and upper limit of each articulation, degrees."""
JOINT_LIMITS: np.ndarray = np.deg2rad(JOINT_LIMITS_DEG)
"""(21, 2) lower and upper limit of each articulation, radians."""
JOINT_LIMITS_DEG.setflags(write=False)
JOINT_LIMITS.setflags(write=False)

# Tolerance for "within limits": angles produced by float round trips may sit 1e-9 outside.
_LIMIT_TOL_RAD = 1e-9


def joint_index(name: str) -> int:
    """Index of an articulation in the 21-angle vector.

    Args:
        name: joint name without side prefix, e.g. ``"index_pip_flex"``.

    Returns:
        Position of the joint in :data:`JOINT_NAMES`.

    Raises:
        InvalidPose: if the name is not one of :data:`JOINT_NAMES`.
    """
    try:
        return JOINT_NAMES.index(name)
    except ValueError:
        raise InvalidPose(
            f"unknown joint {name!r}; valid joints: {', '.join(JOINT_NAMES)}"
        ) from None


class LimitViolation(NamedTuple):
    """One articulation outside its range."""

    joint: str
    value_rad: float
    lower_rad: float
    upper_rad: float

    def __str__(self) -> str:
        return (
            f"{self.joint} = {np.rad2deg(self.value_rad):.2f} deg is outside "
            f"[{np.rad2deg(self.lower_rad):.1f}, {np.rad2deg(self.upper_rad):.1f}] deg"
        )


MAX_ABS_POSE = {"wrist_pos": 1000.0, "wrist_rotvec": 100.0, "angles": 100.0}
"""Largest magnitude accepted per pose field (metres, radians): beyond it a value is a mistake
(and a rotation vector of 1e300 rad has no usable quaternion)."""


def _half_angle_sinc(angle: float) -> float:
    """``sin(angle / 2) / angle``, by its series for small angles (as scipy's from_rotvec)."""
    if angle <= 1e-3:
        return 0.5 - angle**2 / 48 + angle**4 / 3840
    return math.sin(angle / 2) / angle


def _as_float_array(value: object, name: str, last_dim: int) -> np.ndarray:
    # A copy: poses do not alias (or get mutated through) the caller's arrays.
    if (
        type(value) is np.ndarray
        and value.dtype == np.float64
        and value.ndim
        and value.shape[-1] == last_dim
    ):
        # The common case in a step loop, in one reduction (NaN fails the comparison and takes
        # the checks below, which name the problem).
        array = value.copy()
        if array.size == 0 or float(np.abs(array).max()) <= MAX_ABS_POSE[name]:
            return array
    try:
        raw = np.array(value)
    except ValueError:
        raise InvalidPose(
            f"{name} must be a real array of shape (..., {last_dim}); received a ragged or "
            f"invalid {type(value).__name__}"
        ) from None
    if raw.dtype == object:
        try:
            raw = np.array(raw.tolist(), dtype=np.float64)
        except (TypeError, ValueError):
            pass
    if raw.dtype.kind not in "iuf":
        raise InvalidPose(
            f"{name} must be real numbers of shape (..., {last_dim}); received dtype "
            f"{raw.dtype} ({type(value).__name__})"
        )
    array = raw.astype(np.float64)
    if array.ndim == 0 or array.shape[-1] != last_dim:
        raise InvalidPose(f"{name} must have shape (..., {last_dim}); received shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InvalidPose(f"{name} contains NaN or Inf: {array}")
    bound = MAX_ABS_POSE[name]
    if array.size and float(np.max(np.abs(array))) > bound:
        raise InvalidPose(
            f"{name} must have entries with |x| <= {bound:g}; received a largest magnitude of "
            f"{float(np.max(np.abs(array))):.4g}"
        )
    return array


@dataclasses.dataclass(frozen=True, eq=False)
class HandPose:
    """A 27-DoF hand pose, or a batch of them (leading dimensions shared by all fields).

    Attributes:
        wrist_pos: (..., 3) float64, wrist keypoint position in the world frame, metres.
        wrist_rotvec: (..., 3) float64, rotation ``world_from_hand`` as a rotation vector, rad.
        angles: (..., 21) float64, articulations in :data:`JOINT_NAMES` order, radians.
    """

    wrist_pos: np.ndarray
    wrist_rotvec: np.ndarray
    angles: np.ndarray

    def __post_init__(self) -> None:
        pos = _as_float_array(self.wrist_pos, "wrist_pos", 3)
        rotvec = _as_float_array(self.wrist_rotvec, "wrist_rotvec", 3)
        angles = _as_float_array(self.angles, "angles", NUM_ANGLES)
        shapes = {pos.shape[:-1], rotvec.shape[:-1], angles.shape[:-1]}
        if len(shapes) != 1:
            raise InvalidPose(
                "wrist_pos, wrist_rotvec and angles must share their batch shape; received "
                f"{pos.shape}, {rotvec.shape}, {angles.shape}"
            )
        object.__setattr__(self, "wrist_pos", pos)
        object.__setattr__(self, "wrist_rotvec", rotvec)
        object.__setattr__(self, "angles", angles)

    def __eq__(self, other: object) -> bool:
        """Exact (bitwise) equality of all fields; poses are compared, not identities."""
        if not isinstance(other, HandPose):
            return NotImplemented
        return all(
            np.array_equal(a, b)
            for a, b in (
                (self.wrist_pos, other.wrist_pos),
                (self.wrist_rotvec, other.wrist_rotvec),
                (self.angles, other.angles),
            )
        )

    __hash__ = None  # type: ignore[assignment]  (mutable arrays)

    # Construction ---------------------------------------------------------------------------

    @classmethod
    def from_vector(cls, vector: object) -> HandPose:
        """Build a pose from ``[wrist_pos(3), wrist_rotvec(3), angles(21)]``.

        Args:
            vector: (..., 27) array-like, SI units.

        Raises:
            InvalidPose: on a wrong shape or non-finite values.
        """
        try:
            v = np.asarray(vector)
            if v.dtype == object:
                v = np.array(v.tolist(), dtype=np.float64)
        except (TypeError, ValueError):
            v = np.asarray(None)
        if v.dtype.kind not in "iuf":
            raise InvalidPose(
                f"a hand pose vector must be real numbers of shape (..., {NUM_DOF}) "
                f"[wrist_pos(3), wrist_rotvec(3), angles(21)]; received {type(vector).__name__} "
                f"of dtype {v.dtype}"
            )
        v = v.astype(np.float64)
        if v.ndim == 0 or v.shape[-1] != NUM_DOF:
            raise InvalidPose(
                f"a hand pose vector must have shape (..., {NUM_DOF}) "
                f"[wrist_pos(3), wrist_rotvec(3), angles(21)]; received shape {v.shape}"
            )
        return cls(v[..., 0:3], v[..., 3:6], v[..., 6:])

    @classmethod
    def neutral(cls, wrist_pos: object = (0.0, 0.0, 0.0), wrist_rotvec: object = (0, 0, 0)):
        """The flat hand (all angles zero) at a given wrist placement."""
        return cls(np.asarray(wrist_pos), np.asarray(wrist_rotvec), np.zeros(NUM_ANGLES))

    @classmethod
    def from_angles(
        cls,
        angles_rad: Mapping[str, float],
        wrist_pos: object = (0.0, 0.0, 0.0),
        wrist_rotvec: object = (0.0, 0.0, 0.0),
    ) -> HandPose:
        """Build a pose from named angles (radians); joints not named are zero.

        Raises:
            InvalidPose: if a name is not one of :data:`JOINT_NAMES`.
        """
        angles = np.zeros(NUM_ANGLES)
        for name, value in angles_rad.items():
            angles[joint_index(name)] = value
        return cls(np.asarray(wrist_pos), np.asarray(wrist_rotvec), angles)

    # Views ----------------------------------------------------------------------------------

    @property
    def vector(self) -> np.ndarray:
        """(..., 27) the pose vector ``[wrist_pos, wrist_rotvec, angles]``."""
        return np.concatenate([self.wrist_pos, self.wrist_rotvec, self.angles], axis=-1)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading dimensions (``()`` for a single pose)."""
        return self.angles.shape[:-1]

    @property
    def quat_wxyz(self) -> np.ndarray:
        """(..., 4) rotation ``world_from_hand`` as a quaternion, MuJoCo's (w, x, y, z) order."""
        rotvec = self.wrist_rotvec
        if rotvec.shape == (3,):
            # One pose (the step loop's case): scalar arithmetic, no array temporaries.
            x, y, z = rotvec.tolist()
            angle = math.sqrt(x * x + y * y + z * z)
            scale = _half_angle_sinc(angle)
            return np.array([math.cos(angle / 2), scale * x, scale * y, scale * z])
        # scipy's Rotation.from_rotvec (and its series for small angles), without its overhead.
        angle = np.sqrt(np.sum(rotvec * rotvec, axis=-1))
        small = angle <= 1e-3
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.where(
                small, 0.5 - angle**2 / 48 + angle**4 / 3840, np.sin(angle / 2) / angle
            )
        return np.concatenate([np.cos(angle / 2)[..., None], scale[..., None] * rotvec], axis=-1)

    def __getitem__(self, index: object) -> HandPose:
        """Index into the batch dimensions."""
        return HandPose(self.wrist_pos[index], self.wrist_rotvec[index], self.angles[index])

    def __len__(self) -> int:
        if not self.batch_shape:
            raise TypeError("a single HandPose has no len(); it is not a batch")
        return self.batch_shape[0]

    def angle(self, name: str) -> np.ndarray:
        """One articulation by name, radians, shape ``batch_shape``."""
        return self.angles[..., joint_index(name)]

    def replace(self, **changes: object) -> HandPose:
        """Copy with fields replaced (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    # Limits ---------------------------------------------------------------------------------

    def violations(self) -> list[LimitViolation]:
        """Articulations outside :data:`JOINT_LIMITS` (every batch element is checked)."""
        flat = self.angles.reshape(-1, NUM_ANGLES)
        lower, upper = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
        bad = (flat < lower - _LIMIT_TOL_RAD) | (flat > upper + _LIMIT_TOL_RAD)
        return [
            LimitViolation(JOINT_NAMES[j], float(flat[i, j]), float(lower[j]), float(upper[j]))
            for i, j in zip(*np.nonzero(bad), strict=True)
        ]

    def within_limits(self) -> bool:
        """True when every articulation is inside its range."""
        return not self.violations()

    def validate(self) -> HandPose:
        """Raise if an articulation is outside its range; return self otherwise.

        Raises:
            InvalidPose: naming each offending joint, its value and its range in degrees.
        """
        bad = self.violations()
        if bad:
            listed = "; ".join(str(v) for v in bad[:5])
            more = f" (and {len(bad) - 5} more)" if len(bad) > 5 else ""
            raise InvalidPose(
                f"hand pose outside joint limits: {listed}{more}. Use HandPose.clip() to clamp it."
            )
        return self

    def clip(self) -> HandPose:
        """Copy with every articulation clamped to :data:`JOINT_LIMITS`."""
        # Fields of a valid pose, angles clamped into the limits: valid, no checks to repeat.
        clipped = object.__new__(type(self))
        object.__setattr__(clipped, "wrist_pos", self.wrist_pos.copy())
        object.__setattr__(clipped, "wrist_rotvec", self.wrist_rotvec.copy())
        object.__setattr__(
            clipped, "angles", np.clip(self.angles, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
        )
        return clipped

    def mirrored(self) -> HandPose:
        """The pose mirrored through the world ``x = 0`` plane (right <-> left hand).

        A left hand in the mirrored pose is the mirror image of a right hand in this pose.
        """
        flip = np.array([-1.0, 1.0, 1.0])
        return self.replace(wrist_pos=self.wrist_pos * flip, wrist_rotvec=self.wrist_rotvec * -flip)
