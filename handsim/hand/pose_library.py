"""The pose library: the grasp taxonomy and named gestures, each a function of few parameters.

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
"""

from __future__ import annotations

import dataclasses
import types
from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np

from handsim._validate import show, to_real_array
from handsim.errors import InvalidPose
from handsim.hand._sampling import (
    _HI,
    _LO,
    _add_noise,
    _batch_pose,
    _check_count,
    _check_range,
    _check_rng,
    _lookup,
)
from handsim.hand.pose import DIGITS, FINGERS, JOINT_NAMES, HandPose

__all__ = [
    "GraspType",
    "GRASP_TYPES",
    "grasp_pose",
    "sample_grasp",
    "Gesture",
    "GESTURES",
    "gesture",
]


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
