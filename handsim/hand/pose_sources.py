"""Pose sources: anatomical uniform sampling, postural synergies, grasps, gestures and motions.

Every source returns a :class:`~handsim.hand.pose.HandPose` (angles in radians, :data:`JOINT_NAMES`
order, wrist at the origin with identity rotation unless stated) whose angles lie within
:data:`~handsim.hand.pose.JOINT_LIMITS`. Every random draw takes a ``numpy.random.Generator``; the
same generator state gives bit-identical output.

Sources
-------

:func:`sample_uniform`
    Uniform within the joint limits, optionally with the anatomical couplings below.
:func:`sample_synergy`, :func:`synergy_pose`, :func:`synergy_basis`
    Postural synergies: a PCA basis of the grasp library (see "Synergy basis").
:data:`GRASP_TYPES`, :func:`grasp_pose`, :func:`sample_grasp`
    13 grasp types of the GRASP taxonomy (Feix et al. 2016), each a function of ``closure``.
:data:`GESTURES`, :func:`gesture`
    14 named hand gestures.
:func:`smooth_motion`, :func:`random_motion`
    Minimum-jerk motions through keyframes with human speed limits.

Anatomical couplings (:func:`sample_uniform` with ``coupled=True``)
------------------------------------------------------------------

1. **DIP = 2/3 PIP** (Rijpkema & Girard 1991, used by Lin et al. 2000): each
   finger's DIP is ``DIP_PIP_RATIO * PIP`` plus Gaussian noise of ``DIP_NOISE_DEG`` = 5 deg
   standard deviation clipped at 2 sigma (10 deg), then clipped to the DIP limits. The noise is an
   engineering choice [E]: the rule is a mean relation, not an identity.
2. **MCP abduction shrinks with MCP flexion**: the collateral ligaments of the finger MCP
   joints are slack in extension and taut in flexion (cam-shaped metacarpal heads), so spread is
   largest with the finger straight and nearly nil in a fist [anatomy, well known; numbers E].
   The abduction range is ``JOINT_LIMITS * f`` with ``f = 1 - (1 - ABD_RANGE_AT_FULL_FLEXION) *
   clip(mcp_flex / 90 deg, 0, 1)``: full range at 0 deg and below (hyperextension), 20 % of it
   at 90 deg; abduction is drawn uniformly within the shrunk range.
3. **Neighbouring fingers are not independent** (shared flexor bellies of the middle, ring and
   little fingers and the extensor juncturae; Häger-Ross & Schieber 2000 measured the ring
   finger as the least independent [M]). The rule bounds a finger's flexion against the *mean*
   of its two neighbours: the ring finger stays within ``INTERFINGER_MAX_DEVIATION_DEG["ring"]``
   = 55 deg of the mean of middle and little, and the middle finger within 65 deg of the mean
   of index and ring, for MCP flexion and for PIP flexion separately [E]. Pairwise bounds were
   rejected because they forbid easy gestures (victory, horns, "call me": a finger straight
   next to a curled one); the mean rule forbids what hands find hard, e.g. the ring finger
   straight while middle and little are in a fist. Flexions are drawn by rejection, so they
   are uniform over the constrained region. Index and little are otherwise free, the thumb is
   uniform within its limits.

With ``coupled=False`` every angle is independent and uniform within its limits.

Synergy basis
-------------

Santello, Flanders & Soechting (1998) recorded 15 joint angles while subjects shaped the hand
to many imagined objects; the first two principal components explained over 80 % of the variance
(J. Neurosci. 18:10105). No such recordings ship with handsim, so :func:`synergy_basis` follows
their protocol on a *synthetic* library: the postures of every grasp in :data:`GRASP_TYPES` at
11 closures from 0.5 to 1.0 (that is, holding objects from the largest to the smallest size of
each type; 143 postures). It is a PCA of handsim's own grasp table, not of human data: the
numbers below describe this library and are not a measurement.

- PC1 explains 56.0 % of the variance, PC1 + PC2 73.4 %, the first 3 83.4 % and the first 5
  94.8 % (asserted in the tests). Santello's >80 % for two components came from real hands
  grasping many objects; this library mixes 13 grasp types of distinct shapes, which spreads
  the variance over a third component.
- PC1 is PIP and DIP flexion of all four fingers together (loadings 0.22 to 0.43, MCP small):
  wrapping versus pad grasps. PC2 is MCP flexion of the middle, ring and little fingers with
  thumb flexion. Compared with GraspIt's human eigengrasps over the 12 finger flexions (GraspIt
  file ``human_eigen_cgdb_refined.xml``; :data:`GRASPIT_EG1_FINGER_FLEXION`): PC1 is
  GraspIt's EG2 ("PIP/DIP versus MCP", ``|cos| = 0.92``) rather than EG1 (``|cos| = 0.28``);
  EG1, finger MCP flexion together, is closest to PC2 (``|cos| = 0.83``). The two planes agree:
  span(PC1, PC2) holds 86 % of EG1's norm and 94 % of EG2's. The order differs because the
  library's largest contrast is between grasp types, not object sizes.

Grasp taxonomy
--------------

Each :class:`GraspType` carries its GRASP-taxonomy metadata (class power / intermediate /
precision, opposition palm / pad / side, thumb abducted / adducted; Feix et al. 2016) and
two anchor postures. ``closure`` in [0, 1] selects the posture:

- ``closure = 0``: open preshape. The digits that touch the object (:attr:`GraspType.digits`)
  have a quarter of the 0.5-anchor flexions (abductions and the thumb's palmar abduction are
  kept, so the hand is already shaped for the grasp); the other digits keep the 0.5 anchor
  (for instance the ring and little fingers stay tucked in a tripod grasp).
- ``closure = 0.5``: holding the largest object of the type (:attr:`GraspType.object_size_m`
  [0]); ``closure = 1``: holding the smallest ([1]).
- Angles are interpolated linearly between the three anchors.

The anchors were derived offline at the medium hand (189 mm) with a kinematic grasp planner and
rounded to whole degrees: fingers close from the flat hand with MCP : PIP : DIP rates 1 : 1 :
0.67 until each link touches the object (GraspIt's breakaway autograsp). The object is a
cylinder (power wraps; across the palm, its radial end 15 deg more distal, as a handle lies
from the hypothenar to the index base) or a sphere (power sphere) of the stated size resting
on the palm. For the precision grasps and the lateral pinch the finger posture is chosen from
typical postures [E] and the object (sphere, cylinder or disk) is placed against the distal pads.
The thumb's five angles are then optimized (SciPy L-BFGS-B, within limits) to reach the far
side of the object, or the radial side of the index (lateral pinch, adducted thumb), without
penetrating the object or the other digits' capsules. ``fixed_hook`` is set by hand.

Mean finger (index to little) MCP / PIP / DIP flexion at the anchors (closure 0.5 -> 1, deg)
against estimated typical ranges [E]:

======================  ===================  ==================  ======================
grasp                   handsim 0.5          handsim 1.0         estimate
======================  ===================  ==================  ======================
large_diameter          42 / 42 / 28         54 / 56 / 38        30-45 / 30-50 / 20-30
medium_wrap             59 / 66 / 44         68 / 80 / 54        45-60 / 60-80 / 40-50
small_diameter          62 / 92 / 62         57 / 108 / 76       60-80 / 80-100 / 50-70
power_sphere            37 / 37 / 24         47 / 48 / 33        30-50 / 40-60 / 20-40
prismatic_4_finger      55 / 15 / 10         60 / 35 / 23        20-40 / 20-40 / 10-25
======================  ===================  ==================  ======================

At closure 0.5 (largest objects) the power grasps are within the table's ranges (the power
sphere's PIP 3 deg below); the smallest objects need more flexion than the table estimates. The
precision grasps flex the MCPs more than the table (55-60 deg; tripod index and middle MCP
55-58 against 30-50) because handsim's thumb tip reaches at most about 124 mm distal of the
wrist at the medium hand (the index PIP is at 132 mm), so the fingertips have to come down to
meet it; the lateral pinch's index (MCP 35-45, PIP 50-65) is within its range.

Gestures
--------

Angles are constants (degrees in the source). Where digits touch, the constants come from
an optimization with :class:`~handsim.hand.kinematics.ForwardKinematics` at the medium hand:
``pinch`` and ``ok`` minimize ``(|thumb tip - index tip| - 15 mm)**2`` (15 mm = the thumb and
index distal skin radii, 8 + 7 mm, so that the pads touch) over the five thumb and four index
joints within limits, with a penalty on capsule overlap and a pull toward a natural posture;
``fist``, ``point``, ``victory``, ``three`` and ``rock`` place the thumb tip on the outside of
the curled fingers' middle phalanges; ``four`` folds it across the palm toward the ring and
little MCPs. Every preset hand size scales the hand uniformly, so the same angles make the
thumb and index touch at every size, and on the left hand (the mirror image).

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

import dataclasses
import functools
import math
import types
from collections.abc import Mapping, Sequence
from typing import Literal, TypeVar

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from handsim._validate import is_real, show, to_real_array
from handsim.errors import InvalidPose, UnknownName
from handsim.hand.pose import DIGITS, FINGERS, JOINT_LIMITS, JOINT_NAMES, NUM_ANGLES, HandPose

__all__ = [
    "DIP_PIP_RATIO",
    "DIP_NOISE_DEG",
    "ABD_RANGE_AT_FULL_FLEXION",
    "INTERFINGER_MAX_DEVIATION_DEG",
    "abduction_range_fraction",
    "sample_uniform",
    "SynergyBasis",
    "synergy_basis",
    "synergy_pose",
    "sample_synergy",
    "GRASPIT_EG1_FINGER_FLEXION",
    "GraspType",
    "GRASP_TYPES",
    "grasp_pose",
    "sample_grasp",
    "Gesture",
    "GESTURES",
    "gesture",
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

_J = {name: i for i, name in enumerate(JOINT_NAMES)}
_LO = JOINT_LIMITS[:, 0]
_HI = JOINT_LIMITS[:, 1]


def _idx(joint: str) -> list[int]:
    """Indices of ``<finger>_<joint>`` for the four fingers, radial to ulnar."""
    return [_J[f"{f}_{joint}"] for f in FINGERS]


_MCP_FLEX = _idx("mcp_flex")
_MCP_ABD = _idx("mcp_abd")
_PIP = _idx("pip_flex")
_DIP = _idx("dip_flex")
_THUMB = [_J[n] for n in JOINT_NAMES if n.startswith("thumb_")]


# Validation helpers ------------------------------------------------------------------------


def _check_rng(rng: object) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise InvalidPose(
            f"rng must be a numpy.random.Generator (e.g. numpy.random.default_rng(0)); "
            f"received {type(rng).__name__}"
        )
    return rng


MAX_SAMPLES = 1_000_000
"""Largest number of poses one call returns (a batch or a motion), so memory stays sane."""


def _check_count(n: object) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InvalidPose(f"n must be an integer >= 1 (number of poses); received {show(n)}")
    if n > MAX_SAMPLES:
        raise InvalidPose(f"n must be at most {MAX_SAMPLES} (number of poses); received {n}")
    return int(n)


def _check_positive(value: object, name: str, unit: str) -> float:
    v = float(value) if is_real(value) else math.nan  # type: ignore[arg-type]
    if not (math.isfinite(v) and v > 0.0):
        raise InvalidPose(f"{name} must be a finite number > 0 {unit}; received {value!r}")
    return v


def _check_nonnegative(value: object, name: str, unit: str) -> float:
    v = float(value) if is_real(value) else math.nan  # type: ignore[arg-type]
    if not (math.isfinite(v) and v >= 0.0):
        raise InvalidPose(f"{name} must be a finite number >= 0 {unit}; received {value!r}")
    return v


def _batch_pose(angles: np.ndarray) -> HandPose:
    """Wrist at the origin, identity rotation, for angles of shape (..., 21)."""
    batch = angles.shape[:-1]
    return HandPose(np.zeros(batch + (3,)), np.zeros(batch + (3,)), angles)


# 1. Uniform sampling with anatomical couplings ---------------------------------------------

DIP_PIP_RATIO = 2.0 / 3.0
"""Mean DIP flexion / PIP flexion (Rijpkema & Girard 1991)."""
DIP_NOISE_DEG = 5.0
"""Standard deviation (deg) of the DIP deviation from ``DIP_PIP_RATIO * PIP``, before clipping
at 2 sigma [E]."""
ABD_RANGE_AT_FULL_FLEXION = 0.2
"""Fraction of the MCP abduction range left at 90 deg of MCP flexion [E]."""
INTERFINGER_MAX_DEVIATION_DEG: Mapping[str, float] = types.MappingProxyType(
    {"middle": 65.0, "ring": 55.0}
)
"""Largest difference (deg) between a finger's MCP (and PIP) flexion and the mean of its two
neighbours' [E]."""


def _interfinger_ok(flex: np.ndarray) -> np.ndarray:
    """(m, 4) finger flexions (rad, index..little) -> (m,) bool, the neighbour rule holds."""
    index, middle, ring, little = flex.T
    dev_middle = np.abs(middle - 0.5 * (index + ring))
    dev_ring = np.abs(ring - 0.5 * (middle + little))
    return (dev_middle <= np.deg2rad(INTERFINGER_MAX_DEVIATION_DEG["middle"])) & (
        dev_ring <= np.deg2rad(INTERFINGER_MAX_DEVIATION_DEG["ring"])
    )


def _sample_flexions(rng: np.random.Generator, n: int, cols: list[int]) -> np.ndarray:
    """(n, 4) flexions uniform within the limits of ``cols``, subject to the neighbour rule."""
    lo, hi = _LO[cols], _HI[cols]
    out = np.empty((0, 4))
    # Acceptance is about 0.8, so batches of 2n rarely need a second round.
    while len(out) < n:
        cand = rng.uniform(lo, hi, size=(2 * n + 16, 4))
        out = np.concatenate([out, cand[_interfinger_ok(cand)]])
    return out[:n]


def abduction_range_fraction(mcp_flex: np.ndarray) -> np.ndarray:
    """Fraction of the MCP abduction range available at a given MCP flexion (coupling rule 2).

    Args:
        mcp_flex: (...) MCP flexion, radians.

    Returns:
        (...) fraction in [:data:`ABD_RANGE_AT_FULL_FLEXION`, 1].
    """
    t = np.clip(np.asarray(mcp_flex, dtype=np.float64) / (np.pi / 2), 0.0, 1.0)
    return 1.0 - (1.0 - ABD_RANGE_AT_FULL_FLEXION) * t


def sample_uniform(rng: np.random.Generator, n: int, *, coupled: bool = True) -> HandPose:
    """Random hand postures, uniform within the joint limits.

    Args:
        rng: random generator; the same state gives identical poses.
        n: number of poses (>= 1).
        coupled: apply the anatomical couplings of the module docstring (DIP = 2/3 PIP with
            noise, MCP abduction range shrinking with MCP flexion, neighbouring-finger
            flexion bounds). With False every angle is independent.

    Returns:
        A batch of ``n`` poses: angles (n, 21) radians within limits, wrist at the origin.

    Raises:
        InvalidPose: if ``rng`` is not a Generator or ``n < 1``.
    """
    rng = _check_rng(rng)
    n = _check_count(n)
    if not isinstance(coupled, (bool, np.bool_)):
        raise InvalidPose(f"coupled must be True or False; received {show(coupled)}")
    if not coupled:
        return _batch_pose(rng.uniform(_LO, _HI, size=(n, NUM_ANGLES)))
    angles = np.empty((n, NUM_ANGLES))
    angles[:, _THUMB] = rng.uniform(_LO[_THUMB], _HI[_THUMB], size=(n, len(_THUMB)))
    angles[:, _MCP_FLEX] = _sample_flexions(rng, n, _MCP_FLEX)
    angles[:, _PIP] = _sample_flexions(rng, n, _PIP)
    noise = np.clip(
        rng.normal(0.0, DIP_NOISE_DEG, size=(n, 4)), -2 * DIP_NOISE_DEG, 2 * DIP_NOISE_DEG
    )
    dip = DIP_PIP_RATIO * angles[:, _PIP] + np.deg2rad(noise)
    angles[:, _DIP] = np.clip(dip, _LO[_DIP], _HI[_DIP])
    frac = abduction_range_fraction(angles[:, _MCP_FLEX])
    u = rng.uniform(0.0, 1.0, size=(n, 4))
    angles[:, _MCP_ABD] = frac * (_LO[_MCP_ABD] + u * (_HI[_MCP_ABD] - _LO[_MCP_ABD]))
    return _batch_pose(angles)


# 3. Grasp taxonomy (defined before the synergies, which are built from it) ------------------


def _deg(
    thumb: tuple[float, float, float, float, float],
    index: tuple[float, float, float, float],
    middle: tuple[float, float, float, float],
    ring: tuple[float, float, float, float],
    little: tuple[float, float, float, float],
) -> np.ndarray:
    """(21,) read-only radians from degrees, in :data:`JOINT_NAMES` order.

    The thumb tuple is (cmc_flex, cmc_abd, mcp_flex, mcp_abd, ip_flex); each finger tuple is
    (mcp_flex, mcp_abd, pip_flex, dip_flex).
    """
    out = np.deg2rad(np.array([*thumb, *index, *middle, *ring, *little], dtype=np.float64))
    out.setflags(write=False)
    return out


GraspClass = Literal["power", "intermediate", "precision"]
Opposition = Literal["palm", "pad", "side"]
ThumbPosition = Literal["abducted", "adducted"]

_PRESHAPE_FLEXION_FACTOR = 0.25
_FLEXION_COLS = np.array([not n.endswith("_abd") for n in JOINT_NAMES])


@dataclasses.dataclass(frozen=True, eq=False)
class GraspType:
    """One grasp type of the GRASP taxonomy (Feix et al. 2016) and its posture.

    Attributes:
        name: registry key, e.g. ``"medium_wrap"``.
        grasp_class: ``"power"``, ``"intermediate"`` or ``"precision"``.
        opposition: ``"palm"``, ``"pad"`` or ``"side"`` opposition.
        thumb: ``"abducted"`` or ``"adducted"`` thumb.
        digits: the digits that touch the object (:data:`~handsim.hand.pose.DIGITS` names).
        object_size_m: (largest, smallest) object size in metres that the anchors at closure
            0.5 and 1.0 were built for (diameter; the gap for the pinches).
        objects: typical objects (YCB object-set ids where one fits).
        description: one line on the posture.
        large: (21,) radians, the posture at closure 0.5 (largest object).
        small: (21,) radians, the posture at closure 1.0 (smallest object).
    """

    name: str
    grasp_class: GraspClass
    opposition: Opposition
    thumb: ThumbPosition
    digits: tuple[str, ...]
    object_size_m: tuple[float, float]
    objects: str
    description: str
    large: np.ndarray
    small: np.ndarray

    @property
    def preshape(self) -> np.ndarray:
        """(21,) radians, the open preshape at closure 0 (see the module docstring)."""
        out = self.large.copy()
        for digit in self.digits:
            cols = np.array([n.startswith(digit + "_") for n in JOINT_NAMES]) & _FLEXION_COLS
            out[cols] *= _PRESHAPE_FLEXION_FACTOR
        return out

    def angles(self, closure: float | np.ndarray) -> np.ndarray:
        """Joint angles at a closure, without noise.

        Args:
            closure: scalar or (n,) closure in [0, 1] (0 open preshape, 0.5 largest object,
                1 smallest object).

        Returns:
            (21,) or (n, 21) radians, within the joint limits.

        Raises:
            InvalidPose: if a closure is outside [0, 1] or not finite.
        """
        c = _check_closure(closure)
        lower = np.clip(c, 0.0, 0.5)[..., None] * 2.0
        upper = (np.clip(c, 0.5, 1.0)[..., None] - 0.5) * 2.0
        pre = self.preshape
        out = pre + lower * (self.large - pre) + upper * (self.small - self.large)
        return np.clip(out, _LO, _HI)


def _check_closure(closure: object) -> np.ndarray:
    try:
        if isinstance(closure, (bool, np.bool_)):
            raise TypeError("closure")
        c = to_real_array(closure)
    except (TypeError, ValueError):
        raise InvalidPose(
            f"closure must be a number or array in [0, 1]; received {closure!r}"
        ) from None
    if c.ndim > 1 or not np.all(np.isfinite(c)) or np.any((c < 0.0) | (c > 1.0)):
        raise InvalidPose(
            "closure must be a scalar or a 1-D array of values in [0, 1] (0 open preshape, "
            f"1 closed on the smallest object); received {closure!r}"
        )
    return c


_ALL = DIGITS

GRASP_TYPES: Mapping[str, GraspType] = types.MappingProxyType(
    {
        g.name: g
        for g in (
            GraspType(
                name="large_diameter",
                grasp_class="power",
                opposition="palm",
                thumb="abducted",
                digits=_ALL,
                object_size_m=(0.09, 0.06),
                objects="002 master chef can, 019 pitcher",
                description="fingers and thumb wrap a large cylinder",
                large=_deg(
                    (-17, 60, 23, 1, 45),
                    (40, 0, 40, 27),
                    (45, 0, 45, 30),
                    (44, 0, 44, 30),
                    (38, 0, 38, 26),
                ),
                small=_deg(
                    (-7, 45, 27, -1, 50),
                    (50, 0, 58, 39),
                    (58, 0, 58, 39),
                    (56, 0, 56, 38),
                    (50, 0, 50, 34),
                ),
            ),
            GraspType(
                name="medium_wrap",
                grasp_class="power",
                opposition="palm",
                thumb="abducted",
                digits=_ALL,
                object_size_m=(0.045, 0.032),
                objects="006 mustard bottle, 021 bleach cleanser",
                description="whole hand wraps a medium cylinder",
                large=_deg(
                    (-14, 35, 49, -10, 38),
                    (48, 0, 74, 49),
                    (66, 0, 68, 46),
                    (66, 0, 66, 44),
                    (57, 0, 57, 38),
                ),
                small=_deg(
                    (-17, 27, 55, 10, 52),
                    (54, 0, 87, 58),
                    (74, 0, 82, 55),
                    (76, 0, 81, 54),
                    (69, 0, 70, 47),
                ),
            ),
            GraspType(
                name="small_diameter",
                grasp_class="power",
                opposition="palm",
                thumb="abducted",
                digits=_ALL,
                object_size_m=(0.025, 0.015),
                objects="040 large marker, handles",
                description="fist-like wrap of a thin cylinder",
                large=_deg(
                    (-16, 19, 55, 10, 50),
                    (47, 0, 98, 66),
                    (70, 0, 94, 63),
                    (71, 0, 93, 62),
                    (62, 0, 84, 56),
                ),
                small=_deg(
                    (-16, 8, 55, 10, 54),
                    (40, 0, 110, 90),
                    (66, 0, 110, 73),
                    (68, 0, 109, 73),
                    (54, 0, 102, 68),
                ),
            ),
            GraspType(
                name="adducted_thumb",
                grasp_class="power",
                opposition="palm",
                thumb="adducted",
                digits=_ALL,
                object_size_m=(0.045, 0.032),
                objects="035 power drill handle, 048 hammer (light tool)",
                description="medium wrap with the thumb adducted along the index",
                large=_deg(
                    (-10, -2, 27, -2, 27),
                    (48, 0, 74, 49),
                    (66, 0, 68, 46),
                    (66, 0, 66, 44),
                    (57, 0, 57, 38),
                ),
                small=_deg(
                    (-15, 1, 34, -1, 34),
                    (54, 0, 87, 58),
                    (74, 0, 82, 55),
                    (76, 0, 81, 54),
                    (69, 0, 70, 47),
                ),
            ),
            GraspType(
                name="index_finger_extension",
                grasp_class="power",
                opposition="palm",
                thumb="abducted",
                digits=_ALL,
                object_size_m=(0.035, 0.025),
                objects="knife, 050 medium clamp",
                description="wrap with the index extended along the tool",
                large=_deg(
                    (-3, 35, 51, 10, 55),
                    (15, 0, 10, 5),
                    (72, 0, 79, 53),
                    (74, 0, 77, 52),
                    (66, 0, 66, 44),
                ),
                small=_deg(
                    (-8, 32, 55, 10, 75),
                    (20, 0, 15, 10),
                    (70, 0, 94, 63),
                    (71, 0, 93, 62),
                    (62, 0, 84, 56),
                ),
            ),
            GraspType(
                name="power_sphere",
                grasp_class="power",
                opposition="palm",
                thumb="abducted",
                digits=_ALL,
                object_size_m=(0.10, 0.07),
                objects="017 orange, 056 tennis ball",
                description="spread fingers and palm around a ball",
                large=_deg(
                    (-1, 53, 22, 1, 27),
                    (39, 10, 39, 26),
                    (38, 0, 38, 25),
                    (36, -8, 36, 24),
                    (34, -15, 34, 23),
                ),
                small=_deg(
                    (14, 42, 18, -10, 47),
                    (52, 10, 52, 34),
                    (46, 0, 51, 34),
                    (46, -8, 46, 35),
                    (45, -15, 45, 30),
                ),
            ),
            GraspType(
                name="fixed_hook",
                grasp_class="power",
                opposition="palm",
                thumb="adducted",
                digits=FINGERS,
                object_size_m=(0.04, 0.015),
                objects="bag handle, 019 pitcher handle",
                description="fingers hooked at PIP and DIP, thumb idle",
                large=_deg(
                    (0, 10, 10, 0, 10),
                    (10, 0, 60, 40),
                    (10, 0, 60, 40),
                    (10, 0, 60, 40),
                    (10, 0, 60, 40),
                ),
                small=_deg(
                    (0, 10, 10, 0, 10),
                    (15, 0, 95, 63),
                    (15, 0, 95, 63),
                    (15, 0, 95, 63),
                    (15, 0, 95, 63),
                ),
            ),
            GraspType(
                name="lateral_pinch",
                grasp_class="intermediate",
                opposition="side",
                thumb="adducted",
                digits=("thumb", "index"),
                object_size_m=(0.02, 0.0),
                objects="037 scissors, a key or a card",
                description="thumb pad on the radial side of the curled index",
                large=_deg(
                    (7, -2, 0, 0, 0),
                    (35, 0, 50, 25),
                    (60, 0, 80, 50),
                    (70, -2, 85, 55),
                    (75, -6, 90, 60),
                ),
                small=_deg(
                    (10, 0, 8, 2, 6),
                    (45, 0, 65, 30),
                    (60, 0, 80, 50),
                    (70, -2, 85, 55),
                    (75, -6, 90, 60),
                ),
            ),
            GraspType(
                name="prismatic_4_finger",
                grasp_class="precision",
                opposition="pad",
                thumb="abducted",
                digits=_ALL,
                object_size_m=(0.05, 0.015),
                objects="003 cracker box, 009 gelatin box from the top",
                description="four finger pads in a row against the thumb pad",
                large=_deg(
                    (-14, 45, 52, -10, 16),
                    (55, 0, 15, 10),
                    (55, 0, 15, 10),
                    (55, -2, 15, 10),
                    (55, -5, 15, 10),
                ),
                small=_deg(
                    (-9, 33, 52, -10, 21),
                    (60, 0, 35, 23),
                    (60, 0, 35, 23),
                    (60, -2, 35, 23),
                    (60, -5, 35, 23),
                ),
            ),
            GraspType(
                name="palmar_pinch",
                grasp_class="precision",
                opposition="pad",
                thumb="abducted",
                digits=("thumb", "index"),
                object_size_m=(0.03, 0.001),
                objects="coin, sheet of paper, 026 sponge edge",
                description="thumb pad against index pad",
                large=_deg(
                    (-16, 24, 35, -10, 52),
                    (50, 0, 35, 23),
                    (15, 0, 20, 13),
                    (20, -4, 25, 17),
                    (25, -10, 30, 20),
                ),
                small=_deg(
                    (-9, 19, 37, -10, 44),
                    (51, 0, 61, 42),
                    (20, 0, 25, 17),
                    (25, -4, 30, 20),
                    (30, -10, 35, 23),
                ),
            ),
            GraspType(
                name="tripod",
                grasp_class="precision",
                opposition="pad",
                thumb="abducted",
                digits=("thumb", "index", "middle"),
                object_size_m=(0.04, 0.015),
                objects="005 tomato soup can lid, 014 lemon, a pen cap",
                description="thumb, index and middle pads; ring and little tucked",
                large=_deg(
                    (18, 38, 16, 0, 16),
                    (55, 2, 35, 23),
                    (58, -2, 35, 23),
                    (60, -2, 80, 53),
                    (65, -8, 85, 57),
                ),
                small=_deg(
                    (-15, 22, 45, -6, 56),
                    (55, 0, 55, 37),
                    (58, -3, 55, 37),
                    (60, -2, 80, 53),
                    (65, -8, 85, 57),
                ),
            ),
            GraspType(
                name="precision_sphere",
                grasp_class="precision",
                opposition="pad",
                thumb="abducted",
                digits=_ALL,
                object_size_m=(0.06, 0.035),
                objects="014 lemon, 017 orange with the fingertips",
                description="five pads around a sphere",
                large=_deg(
                    (-13, 34, 32, 1, 48),
                    (50, 8, 25, 17),
                    (52, 0, 25, 17),
                    (54, -6, 25, 17),
                    (56, -12, 25, 17),
                ),
                small=_deg(
                    (-5, 29, 34, 0, 51),
                    (55, 3, 40, 27),
                    (57, -1, 40, 27),
                    (59, -5, 40, 27),
                    (61, -9, 40, 27),
                ),
            ),
            GraspType(
                name="precision_disk",
                grasp_class="precision",
                opposition="pad",
                thumb="abducted",
                digits=_ALL,
                object_size_m=(0.11, 0.06),
                objects="jar lid, 029 plate rim",
                description="spread pads around the rim of a disk",
                large=_deg(
                    (-19, 52, -4, -10, 80),
                    (45, 15, 20, 13),
                    (45, 3, 20, 13),
                    (45, -12, 20, 13),
                    (45, -25, 20, 13),
                ),
                small=_deg(
                    (-6, 49, 7, -10, 80),
                    (55, 8, 35, 23),
                    (57, 0, 35, 23),
                    (59, -7, 35, 23),
                    (61, -14, 35, 23),
                ),
            ),
        )
    }
)
"""The grasp types by name (read-only). Class / opposition / thumb from Feix et al. 2016."""


_T = TypeVar("_T")


def _lookup(registry: Mapping[str, _T], name: object, what: str) -> _T:
    if not isinstance(name, str) or name not in registry:
        raise UnknownName(f"unknown {what} {name!r}; valid names: {', '.join(registry)}")
    return registry[name]


def _add_noise(angles: np.ndarray, rng: np.random.Generator | None, noise_deg: float) -> np.ndarray:
    noise_deg = _check_nonnegative(noise_deg, "noise_deg", "(degrees)")
    if noise_deg == 0.0:
        return angles
    if rng is None:
        raise InvalidPose(
            f"noise_deg = {noise_deg} needs rng, a numpy.random.Generator; received rng=None"
        )
    rng = _check_rng(rng)
    noisy = angles + np.deg2rad(rng.normal(0.0, noise_deg, size=angles.shape))
    return np.clip(noisy, _LO, _HI)


def grasp_pose(
    name: str,
    closure: float | np.ndarray = 1.0,
    *,
    rng: np.random.Generator | None = None,
    noise_deg: float = 0.0,
) -> HandPose:
    """The posture of a grasp type at a closure.

    Args:
        name: a key of :data:`GRASP_TYPES`.
        closure: scalar or (n,) in [0, 1]: 0 open preshape, 0.5 holding the type's largest
            object, 1 its smallest.
        rng: random generator, required when ``noise_deg > 0``.
        noise_deg: standard deviation of Gaussian noise added to every angle, degrees; the
            result is clipped to the joint limits.

    Returns:
        A single pose (scalar closure) or a batch of n, wrist at the origin.

    Raises:
        UnknownName: for a name not in :data:`GRASP_TYPES` (the message lists them).
        InvalidPose: for a closure outside [0, 1], a negative noise or noise without rng.
    """
    grasp = _lookup(GRASP_TYPES, name, "grasp type")
    return _batch_pose(_add_noise(grasp.angles(closure), rng, noise_deg))


def sample_grasp(
    rng: np.random.Generator,
    n: int,
    *,
    names: Sequence[str] | None = None,
    closure_range: tuple[float, float] = (0.5, 1.0),
    noise_deg: float = 3.0,
) -> tuple[HandPose, tuple[str, ...]]:
    """Random grasp postures: a uniform grasp type, a uniform closure and Gaussian noise.

    Args:
        rng: random generator.
        n: number of poses (>= 1).
        names: grasp types to draw from (default: all of :data:`GRASP_TYPES`).
        closure_range: (low, high) within [0, 1]; the default covers holding an object.
        noise_deg: per-angle noise standard deviation, degrees (clipped to limits).

    Returns:
        ``(poses, labels)``: a batch of n poses and the grasp type name of each.

    Raises:
        UnknownName: for an unknown grasp type.
        InvalidPose: for bad ``n``, ``closure_range`` or ``noise_deg``.
    """
    rng = _check_rng(rng)
    n = _check_count(n)
    if names is not None and (isinstance(names, str) or not isinstance(names, Sequence)):
        raise InvalidPose(f"names must be a sequence of grasp type names; received {show(names)}")
    pool = tuple(GRASP_TYPES) if names is None else tuple(names)
    if not pool:
        raise InvalidPose(f"names must hold at least one grasp type; received {names!r}")
    grasps = [_lookup(GRASP_TYPES, g, "grasp type") for g in pool]
    lo, hi = _check_range(closure_range, "closure_range", 0.0, 1.0, "(closure)")
    choice = rng.integers(0, len(pool), size=n)
    closure = rng.uniform(lo, hi, size=n)
    angles = np.stack([grasps[k].angles(c) for k, c in zip(choice, closure, strict=True)])
    return _batch_pose(_add_noise(angles, rng, noise_deg)), tuple(pool[k] for k in choice)


# 2. Postural synergies ---------------------------------------------------------------------

GRASPIT_EG1_FINGER_FLEXION: np.ndarray = np.array(
    [
        [-0.413, -0.042, -0.008],
        [-0.515, -0.025, -0.013],
        [-0.530, 0.016, -0.066],
        [-0.451, -0.170, -0.075],
    ]
)
"""(4, 3) GraspIt human-hand eigengrasp EG1 restricted to finger flexion: rows index, middle,
ring, little; columns MCP, PIP, DIP (GraspIt's ``human_eigen_cgdb_refined.xml``)."""
GRASPIT_EG1_FINGER_FLEXION.setflags(write=False)

_SYNERGY_CLOSURES = np.linspace(0.5, 1.0, 11)


@dataclasses.dataclass(frozen=True, eq=False)
class SynergyBasis:
    """A PCA basis of hand postures.

    Attributes:
        mean: (21,) mean posture, radians.
        components: (21, 21) unit principal directions as rows, by decreasing variance. The
            sign is chosen so that the summed finger flexion loading (MCP, PIP, DIP) is
            positive: a positive coefficient closes the fingers.
        std: (21,) standard deviation along each component, radians.
        explained_variance_ratio: (21,) fraction of the total variance per component.
        source: where the postures came from.
    """

    mean: np.ndarray
    components: np.ndarray
    std: np.ndarray
    explained_variance_ratio: np.ndarray
    source: str

    def project(self, pose: HandPose, num_synergies: int) -> np.ndarray:
        """Coefficients of poses on the first components, in units of ``std``.

        Args:
            pose: a pose or a batch.
            num_synergies: number of components, 1 to 21.

        Returns:
            (..., num_synergies) coefficients.
        """
        k = _check_num_synergies(num_synergies)
        return ((pose.angles - self.mean) @ self.components[:k].T) / self.std[:k]


def _check_num_synergies(k: object) -> int:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= NUM_ANGLES:
        raise InvalidPose(f"num_synergies must be an integer in [1, {NUM_ANGLES}]; received {k!r}")
    return int(k)


@functools.cache
def synergy_basis() -> SynergyBasis:
    """The postural-synergy basis (PCA of the grasp library; see the module docstring).

    Returns:
        The basis, computed once and cached; its arrays are read-only.
    """
    library = np.concatenate([g.angles(_SYNERGY_CLOSURES) for g in GRASP_TYPES.values()])
    mean = library.mean(axis=0)
    _, sing, vt = np.linalg.svd(library - mean, full_matrices=False)
    flexion = _MCP_FLEX + _PIP + _DIP
    vt = vt * np.where(vt[:, flexion].sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
    var = sing**2 / (len(library) - 1)
    arrays = (mean, vt, np.sqrt(var), var / var.sum())
    for a in arrays:
        a.setflags(write=False)
    return SynergyBasis(
        *arrays,
        source=(
            f"PCA of {len(library)} grasp postures: {len(GRASP_TYPES)} GRASP-taxonomy types x "
            f"{len(_SYNERGY_CLOSURES)} closures in [0.5, 1] (handsim.hand.pose_sources.GRASP_TYPES)"
        ),
    )


def synergy_pose(coefficients: Sequence[float] | np.ndarray) -> HandPose:
    """Posture from synergy coefficients.

    Args:
        coefficients: (..., k) coefficients of the first k components, in units of each
            component's standard deviation (1 <= k <= 21).

    Returns:
        Poses with angles ``mean + sum_i c_i std_i component_i``, clipped to the limits.

    Raises:
        InvalidPose: for a wrong shape or non-finite coefficients.
    """
    c = np.asarray(coefficients, dtype=np.float64)
    if c.ndim == 0 or not 1 <= c.shape[-1] <= NUM_ANGLES or not np.all(np.isfinite(c)):
        raise InvalidPose(
            f"coefficients must be finite with shape (..., k), 1 <= k <= {NUM_ANGLES}; "
            f"received shape {c.shape}"
        )
    basis = synergy_basis()
    k = c.shape[-1]
    angles = basis.mean + (c * basis.std[:k]) @ basis.components[:k]
    return _batch_pose(np.clip(angles, _LO, _HI))


def sample_synergy(
    rng: np.random.Generator, n: int, *, num_synergies: int = 2, scale: float = 1.0
) -> HandPose:
    """Random postures in the span of the first synergies.

    Coefficients are independent normal with standard deviation ``scale`` (in units of each
    component's own standard deviation), so ``scale = 1`` reproduces the library's spread
    along those components; the angles are clipped to the limits.

    Args:
        rng: random generator.
        n: number of poses (>= 1).
        num_synergies: number of leading components used, 1 to 21.
        scale: standard deviation of the coefficients (> 0).

    Returns:
        A batch of n poses, wrist at the origin.

    Raises:
        InvalidPose: for a bad ``rng``, ``n``, ``num_synergies`` or ``scale``.
    """
    rng = _check_rng(rng)
    n = _check_count(n)
    k = _check_num_synergies(num_synergies)
    scale = _check_positive(scale, "scale", "(coefficient standard deviation)")
    return synergy_pose(rng.normal(0.0, scale, size=(n, k)))


# 4. Gestures -------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class Gesture:
    """A named static hand gesture.

    Attributes:
        name: registry key.
        description: what the hand does.
        angles: (21,) radians, read-only.
    """

    name: str
    description: str
    angles: np.ndarray


_FIST = (88, 0, 100, 65)
_STRAIGHT = (0, 0, 0, 0)

GESTURES: Mapping[str, Gesture] = types.MappingProxyType(
    {
        g.name: g
        for g in (
            Gesture(
                "open", "flat hand, all joints at zero", _deg((0, 0, 0, 0, 0), *[_STRAIGHT] * 4)
            ),
            Gesture(
                "relaxed",
                "resting posture: mild flexion increasing toward the little finger",
                _deg(
                    (5, 15, 10, 0, 10),
                    (20, 0, 30, 20),
                    (25, 0, 35, 23),
                    (30, -2, 40, 27),
                    (35, -5, 45, 30),
                ),
            ),
            Gesture(
                "spread",
                "fingers straight and spread, thumb radially abducted",
                _deg(
                    (-20, 0, 0, 0, -10), (0, 18, 0, 0), (0, 0, 0, 0), (0, -13, 0, 0), (0, -25, 0, 0)
                ),
            ),
            Gesture(
                "fist",
                "all fingers curled, thumb across the index and middle middle phalanges",
                _deg((-12, 27, 44, 10, 70), _FIST, _FIST, _FIST, _FIST),
            ),
            Gesture(
                "point",
                "index straight, other fingers curled, thumb over the middle finger",
                _deg((-9, 27, 52, 0, 63), _STRAIGHT, _FIST, _FIST, _FIST),
            ),
            Gesture(
                "pinch",
                "thumb tip touching the index tip, other fingers loosely curled",
                _deg(
                    (18.5, 27.9, 9.4, -9.4, 11.7),
                    (50.5, -1.5, 62.6, 41.3),
                    (35, 0, 50, 33),
                    (45, 0, 60, 40),
                    (55, 0, 65, 43),
                ),
            ),
            Gesture(
                "ok",
                "thumb and index tips touching in a circle, other fingers extended",
                _deg(
                    (16.8, 23.1, 10.7, -9.7, 18.9),
                    (41.4, -3.1, 70.5, 48.0),
                    (5, -3, 10, 7),
                    (8, -8, 12, 8),
                    (10, -18, 15, 10),
                ),
            ),
            Gesture(
                "thumbs_up",
                "fist with the thumb extended radially",
                _deg((-20, 10, -5, 0, -10), _FIST, _FIST, _FIST, _FIST),
            ),
            Gesture(
                "victory",
                "index and middle straight and spread, ring and little curled under the thumb",
                _deg((2, 25, 55, 0, 61), (0, 10, 0, 0), (0, -8, 0, 0), _FIST, _FIST),
            ),
            Gesture(
                "three",
                "index, middle and ring straight, thumb holding the curled little finger",
                _deg((12, 18, 55, -1, 58), (0, 8, 0, 0), _STRAIGHT, (0, -8, 0, 0), _FIST),
            ),
            Gesture(
                "four",
                "four fingers straight and spread, thumb folded across the palm",
                _deg((25, -5, 55, -10, 80), (0, 8, 0, 0), _STRAIGHT, (0, -6, 0, 0), (0, -14, 0, 0)),
            ),
            Gesture(
                "call_me",
                "shaka: thumb and little finger extended, the others curled",
                _deg((-20, 5, 0, 0, -10), _FIST, _FIST, _FIST, (0, -25, 0, 0)),
            ),
            Gesture(
                "rock",
                "horns: index and little straight, thumb over the curled middle and ring",
                _deg((-3, 25, 52, 10, 64), (0, 5, 0, 0), _FIST, _FIST, (0, -20, 0, 0)),
            ),
            Gesture(
                "gun",
                "finger gun: index straight, thumb extended radially, others curled",
                _deg((-20, 5, 0, 0, 0), _STRAIGHT, _FIST, _FIST, _FIST),
            ),
        )
    }
)
"""The gestures by name (read-only)."""


def gesture(
    name: str,
    *,
    rng: np.random.Generator | None = None,
    noise_deg: float = 0.0,
) -> HandPose:
    """A named gesture.

    Args:
        name: a key of :data:`GESTURES`.
        rng: random generator, required when ``noise_deg > 0``.
        noise_deg: standard deviation of Gaussian noise added to every angle, degrees
            (clipped to the limits).

    Returns:
        A single pose, wrist at the origin.

    Raises:
        UnknownName: for a name not in :data:`GESTURES` (the message lists them).
        InvalidPose: for a negative noise or noise without rng.
    """
    g = _lookup(GESTURES, name, "gesture")
    return _batch_pose(_add_noise(g.angles.copy(), rng, noise_deg))


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


def _check_range(value: object, name: str, lo: float, hi: float, unit: str) -> tuple[float, float]:
    try:
        a, b = (float(v) if is_real(v) else math.nan for v in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        a = b = math.nan
    if not (math.isfinite(a) and math.isfinite(b) and lo <= a <= b <= hi):
        raise InvalidPose(
            f"{name} must be (low, high) with {lo} <= low <= high <= {hi} {unit}; "
            f"received {value!r}"
        )
    return a, b
