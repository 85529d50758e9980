"""The hand's anatomy: :class:`HandParams` and the kinematic :class:`Skeleton` built from them.

:func:`build_skeleton` turns the parameters (size, handedness, palm breadth, thickness, forearm
stub, DIP coupling) into bodies, joint axes, collision primitives and keypoint sites, from which
both the MuJoCo model (:class:`~handsim.hand.model.Hand`) and the NumPy forward kinematics
(:mod:`handsim.hand.kinematics`) are made, so the two cannot drift apart.

Geometry (right hand; hand frame ``+x`` radial, ``+y`` distal, ``+z`` palmar, origin at the wrist
crease centre; see :mod:`handsim.hand.pose`):

- Segment lengths are Buchholz, Armstrong & Goldstein (1992) ratios of ``hand_length``.
  The middle MCP sits at ``y = (1 - 0.277 - 0.170 - 0.108) * hand_length`` so that the straight
  middle fingertip lies exactly ``hand_length`` from the wrist.
- The MCP row is an arc: the other MCPs are set proximal to the middle one by the factors in
  ``_MCP_ARC`` (index 0.975, ring 0.945, little 0.875; chosen so that index and ring fingertips
  land near 0.94 and the little fingertip near 0.80 of hand length [estimate]) and palmar by
  the MANO mean hand's metacarpal arch (``_MCP_PALMAR``).
- MCP lateral spacing follows the MANO mean hand (24 : 23 : 17 mm), spread so the outer skin
  edges of the palm span ``palm_breadth``.
- The thumb CMC (trapeziometacarpal joint) is 0.196 palm breadths radial of the wrist
  (Buchholz et al. 1992, as laid out in the hand model of Sancho-Bru et al.), 10 mm distal and
  11 mm palmar at 189 mm: in the trapezium, a little proximal of the metacarpal bases (0.073
  hand lengths), where the joint's flexion-extension axis lies (Hollister et al. 1992).
- Flexion axes are tilted within the palm plane so that flexed fingers converge toward the
  thumb base (``_FLEX_TILT_DEG``; MyoHand's MCP axes fan out the same way).
- Phalanx radii are MyoHand's skin capsules, scaled with hand length and ``thickness_scale``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np

from handsim._validate import is_real, show
from handsim.errors import InvalidHandParams, UnknownName
from handsim.hand.keypoints import EXTRA_POINT_NAMES, EXTRA_POINT_RULES, KEYPOINT_NAMES
from handsim.hand.pose import FINGERS, JOINT_NAMES
from handsim.hand.skin import SURFACES

if TYPE_CHECKING:
    # scipy.spatial loads when a skeleton is built, not on `import handsim`.
    from scipy.spatial.transform import Rotation

__all__ = [
    "HandParams",
    "HAND_SIZES",
    "hand_params",
    "Skeleton",
    "SkeletonBody",
    "Capsule",
    "Box",
    "build_skeleton",
    "extra_point_positions",
]

Side = Literal["right", "left"]
Surface = Literal["skin", "capsules"]

HAND_LENGTH_RANGE_M = (0.140, 0.235)
PALM_BREADTH_RATIO_RANGE = (0.35, 0.55)
THICKNESS_SCALE_RANGE = (0.7, 1.4)

HAND_SIZES: dict[str, float] = {"small": 0.165, "medium": 0.189, "large": 0.210}
"""Preset hand lengths, metres: about the women's mean, the ANSUR II mixed mean, and a large
man's hand (surveyed means: men 185-198 mm, women 168-181 mm)."""


# Buchholz et al. 1992 segment lengths / hand length (metacarpal, proximal, middle, distal).
_BUCHHOLZ = {
    "thumb": (0.251, 0.196, None, 0.158),
    "index": (0.374, 0.265, 0.143, 0.097),
    "middle": (0.373, 0.277, 0.170, 0.108),
    "ring": (0.336, 0.259, 0.165, 0.107),
    "little": (0.295, 0.206, 0.117, 0.093),
}
_REF_HAND_LENGTH = 0.189
_MCP_ARC = {"index": 0.975, "middle": 1.0, "ring": 0.945, "little": 0.875}
# MANO mean hand, palmar offsets of the MCPs relative to the middle MCP / 189 mm.
_MCP_PALMAR = {"index": 0.0196, "middle": 0.0, "ring": 0.0132, "little": 0.0444}
# MANO mean hand MCP spacing index-middle-ring-little: 24.1, 23.3, 16.5 mm.
_MCP_SPREAD_FRACTION = {"index": 0.0, "middle": 0.377, "ring": 0.742, "little": 1.0}
# Flexion-axis tilt in the palm plane (deg) at MCP and at PIP/DIP.
_FLEX_TILT_DEG = {
    "index": (0.0, 0.0),
    "middle": (3.0, 2.0),
    "ring": (7.0, 4.0),
    "little": (12.0, 6.0),
}
# Skin capsule radii at 189 mm (MyoHand; thumb from thumb breadth ~19-21 mm at the IP), metres.
_RADII = {
    "thumb": (0.0110, 0.0095, None, 0.0080),
    "index": (None, 0.0090, 0.0080, 0.0070),
    "middle": (None, 0.0090, 0.0080, 0.0070),
    "ring": (None, 0.0085, 0.0075, 0.0068),
    "little": (None, 0.0080, 0.0070, 0.0060),
}
_PALM_THICKNESS_RATIO = 0.143  # 27 mm at 189 mm (MANO palm box)
# Thumb CMC (trapeziometacarpal joint) in the hand frame: radial 0.196 palm breadth (Buchholz
# et al. 1992); distal 10 mm and palmar 11 mm at 189 mm (in the trapezium, proximal of the
# metacarpal bases at 0.073 hand length, where the joint's flexion axis lies).
_THUMB_CMC = (0.196, 0.010 / _REF_HAND_LENGTH, 0.011 / _REF_HAND_LENGTH)
# Thumb rest orientation: radial deviation from the hand axis, palmar tilt, pronation (deg).
_THUMB_REST_DEG = (30.0, 15.0, -70.0)


def _scaled(value: float, hand_length: float) -> float:
    return value * hand_length / _REF_HAND_LENGTH


@dataclasses.dataclass(frozen=True)
class HandParams:
    """Parameters of a hand model.

    Attributes:
        hand_length: wrist crease to the middle fingertip with the hand flat, metres
            (valid 0.140 to 0.235).
        side: ``"right"`` or ``"left"``; the left hand is the exact mirror of the right.
        palm_breadth: breadth at the metacarpal heads, metres; ``None`` gives 0.45 *
            hand_length. Valid ratio to hand_length: 0.35 to 0.55.
        thickness_scale: multiplies every radius and the palm thickness (valid 0.7 to 1.4).
        forearm: add the arm (part of what a depth camera sees): a forearm stub in the palm
            (collision capsules, and the palm's skin), and, drawn only (no contact, no mass),
            the forearm beyond it to the elbow (:data:`~handsim.hand.model.FOREARM_GEOM`) and
            the upper arm (:data:`~handsim.hand.model.UPPER_ARM_GEOM`,
            :meth:`~handsim.hand.model.HandBinding.point_upper_arm`).
        couple_dip: tie each DIP to 2/3 of its PIP with an equality constraint (the DIP
            actuators are then omitted).
        surface: what cameras see: ``"skin"`` (default), a smooth closed mesh per segment with
            palm eminences, web spaces and elliptic finger sections (:mod:`handsim.hand.skin`),
            or ``"capsules"``, copies of the collision primitives (the earlier look). Physics
            is the same for both.
    """

    hand_length: float = 0.189
    side: Side = "right"
    palm_breadth: float | None = None
    thickness_scale: float = 1.0
    forearm: bool = True
    couple_dip: bool = False
    surface: Surface = "skin"

    def __post_init__(self) -> None:
        for field in ("hand_length", "palm_breadth", "thickness_scale"):
            value = getattr(self, field)
            if value is None and field == "palm_breadth":
                continue
            if not is_real(value):
                raise InvalidHandParams(
                    f"{field} must be a real number (metres for lengths); received "
                    f"{show(value)} ({type(value).__name__})"
                )
            object.__setattr__(self, field, float(value))
        lo, hi = HAND_LENGTH_RANGE_M
        if not (np.isfinite(self.hand_length) and lo <= self.hand_length <= hi):
            raise InvalidHandParams(
                f"hand_length must be in [{lo}, {hi}] m (wrist crease to middle fingertip); "
                f"received {self.hand_length!r}"
            )
        if not isinstance(self.side, str) or self.side not in ("right", "left"):
            raise InvalidHandParams(f"side must be 'right' or 'left'; received {self.side!r}")
        if self.palm_breadth is not None:
            ratio = self.palm_breadth / self.hand_length
            rlo, rhi = PALM_BREADTH_RATIO_RANGE
            if not (np.isfinite(ratio) and rlo <= ratio <= rhi):
                raise InvalidHandParams(
                    f"palm_breadth must be between {rlo} and {rhi} times hand_length "
                    f"({rlo * self.hand_length:.4f} to {rhi * self.hand_length:.4f} m for this "
                    f"hand); received {self.palm_breadth!r}"
                )
        tlo, thi = THICKNESS_SCALE_RANGE
        if not (np.isfinite(self.thickness_scale) and tlo <= self.thickness_scale <= thi):
            raise InvalidHandParams(
                f"thickness_scale must be in [{tlo}, {thi}]; received {self.thickness_scale!r}"
            )
        if self.surface not in SURFACES:
            raise InvalidHandParams(
                f"surface must be one of {', '.join(map(repr, SURFACES))}; "
                f"received {self.surface!r}"
            )
        for flag in ("forearm", "couple_dip"):
            if not isinstance(getattr(self, flag), bool):
                raise InvalidHandParams(
                    f"{flag} must be True or False; received {getattr(self, flag)!r}"
                )

    @property
    def breadth(self) -> float:
        """Palm breadth in metres (the default applied)."""
        return 0.45 * self.hand_length if self.palm_breadth is None else self.palm_breadth

    @property
    def prefix(self) -> str:
        """Name prefix of every MJCF element of this hand: ``"rh_"`` or ``"lh_"``."""
        return "rh_" if self.side == "right" else "lh_"


def hand_params(size: str | float = "medium", side: Side = "right", **kwargs: object) -> HandParams:
    """Hand parameters from a preset size name or a hand length in metres.

    Args:
        size: one of :data:`HAND_SIZES` or a hand length in metres.
        side: ``"right"`` or ``"left"``.
        **kwargs: other :class:`HandParams` fields.

    Raises:
        UnknownName: for an unknown preset name.
        InvalidHandParams: for invalid values.
    """
    if not isinstance(size, str) and not is_real(size):
        raise InvalidHandParams(
            f"size must be one of {', '.join(HAND_SIZES)} or a hand length in metres; "
            f"received {show(size)} ({type(size).__name__})"
        )
    if isinstance(size, str):
        if size not in HAND_SIZES:
            raise UnknownName(
                f"unknown hand size {size!r}; valid presets: {', '.join(HAND_SIZES)} "
                "(or a hand length in metres)"
            )
        size = HAND_SIZES[size]
    return HandParams(hand_length=float(size), side=side, **kwargs)


# Skeleton ------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Capsule:
    """A capsule from ``start`` to ``end`` (body frame, metres) with ``radius``."""

    start: np.ndarray
    end: np.ndarray
    radius: float


@dataclasses.dataclass(frozen=True)
class Box:
    """A box centred at ``pos`` (body frame, metres) with half sizes ``half_size``."""

    pos: np.ndarray
    half_size: np.ndarray


@dataclasses.dataclass(frozen=True)
class SkeletonBody:
    """One rigid segment of the hand.

    Attributes:
        name: body name without side prefix, e.g. ``"index_proximal"``.
        part: hand part it belongs to (``"palm"`` or a digit name), for segmentation.
        parent: index of the parent body in :attr:`Skeleton.bodies` (-1 for the palm).
        pos: (3,) origin in the parent frame, metres.
        quat_wxyz: (4,) orientation in the parent frame.
        joints: (angle index, (3,) unit axis in this body's frame) per hinge, outermost first;
            every hinge is at the body origin.
        geoms: collision primitives in this body's frame.
    """

    name: str
    part: str
    parent: int
    pos: np.ndarray
    quat_wxyz: np.ndarray
    joints: tuple[tuple[int, np.ndarray], ...]
    geoms: tuple[Capsule | Box, ...]


@dataclasses.dataclass(frozen=True)
class Skeleton:
    """Kinematic skeleton of one hand (see :func:`build_skeleton`).

    Attributes:
        params: the parameters it was built from.
        bodies: bodies in topological order; ``bodies[0]`` is the palm (the free root).
        keypoints: 21 entries ``(body index, (3,) position in that body's frame)`` in
            :data:`KEYPOINT_NAMES` order.
    """

    params: HandParams
    bodies: tuple[SkeletonBody, ...]
    keypoints: tuple[tuple[int, np.ndarray], ...]


def _rotation_quat_wxyz(rotation: Rotation) -> np.ndarray:
    return np.roll(rotation.as_quat(), 1)


def _unit(v: Sequence[float]) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _right_skeleton(params: HandParams) -> Skeleton:
    hl = params.hand_length
    thick = params.thickness_scale
    breadth = params.breadth
    palm_t = _PALM_THICKNESS_RATIO * hl * thick
    bodies: list[SkeletonBody] = []
    keypoints: dict[str, tuple[int, np.ndarray]] = {}
    zero = np.zeros(3)
    identity = np.array([1.0, 0.0, 0.0, 0.0])

    # MCP positions on the arc.
    y_mcp_middle = (1.0 - sum(_BUCHHOLZ["middle"][1:])) * hl
    span = breadth - palm_t
    mcp = {
        f: np.array(
            [
                span / 2 - _MCP_SPREAD_FRACTION[f] * span,
                _MCP_ARC[f] * y_mcp_middle,
                _scaled(_MCP_PALMAR[f], hl) * _REF_HAND_LENGTH,
            ]
        )
        for f in FINGERS
    }

    # Palm: a box over the carpus and proximal palm plus one capsule per metacarpal; the
    # capsules give the knuckle arc and the rounded palm edges.
    palm_geoms: list[Capsule | Box] = []
    box_top = 0.8 * mcp["little"][1]
    palm_geoms.append(
        Box(
            pos=np.array([0.0, box_top / 2, 0.0]),
            half_size=np.array([span / 2, box_top / 2, palm_t / 2]),
        )
    )
    for f in FINGERS:
        base = np.array([mcp[f][0] * 0.8, 0.25 * mcp[f][1], 0.0])
        palm_geoms.append(Capsule(start=base, end=mcp[f].copy(), radius=palm_t / 2))
    if params.forearm:
        wrist_r = 0.1 * hl * thick
        for dx in (-0.05 * hl, 0.05 * hl):
            palm_geoms.append(
                Capsule(
                    start=np.array([dx, -0.55 * hl, 0.0]),
                    end=np.array([dx, -0.4 * wrist_r, 0.0]),
                    radius=wrist_r,
                )
            )
    bodies.append(SkeletonBody("palm", "palm", -1, zero, identity, (), tuple(palm_geoms)))
    keypoints["wrist"] = (0, zero.copy())

    def add_chain(digit: str, base_pos, base_quat, joint_specs, lengths, radii, kp_names):
        """Append a serial chain; joint_specs[k] = list of (joint name, axis) for segment k."""
        parent = 0
        pos, quat = base_pos, base_quat
        segments = ("metacarpal", "proximal", "middle", "distal")
        seg_names = (
            segments[4 - len(lengths) :]
            if digit != "thumb"
            else (
                "metacarpal",
                "proximal",
                "distal",
            )
        )
        for k, (length, radius) in enumerate(zip(lengths, radii, strict=True)):
            joints = tuple((JOINT_NAMES.index(f"{digit}_{j}"), _unit(a)) for j, a in joint_specs[k])
            end = np.array([0.0, length, 0.0])
            last = k == len(lengths) - 1
            # The distal capsule stops one radius short so its skin ends at the tip keypoint.
            cap_end = end - np.array([0.0, radius, 0.0]) if last else end
            geom = Capsule(start=zero.copy(), end=cap_end, radius=radius)
            bodies.append(
                SkeletonBody(f"{digit}_{seg_names[k]}", digit, parent, pos, quat, joints, (geom,))
            )
            index = len(bodies) - 1
            keypoints[f"{digit}_{kp_names[k]}"] = (index, zero.copy())
            if last:
                keypoints[f"{digit}_tip"] = (index, end)
            parent, pos, quat = index, end, identity

    # Thumb.
    rad_dev, palmar_tilt, pronation = _THUMB_REST_DEG
    from scipy.spatial.transform import Rotation

    thumb_rest = Rotation.from_euler("ZXY", [-rad_dev, palmar_tilt, pronation], degrees=True)
    cmc = np.array([_THUMB_CMC[0] * breadth, _THUMB_CMC[1] * hl, _THUMB_CMC[2] * hl * thick])
    mc, pp, _, dp = _BUCHHOLZ["thumb"]
    r_mc, r_pp, _, r_dp = _RADII["thumb"]
    x_axis, palm_away = (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)
    add_chain(
        "thumb",
        cmc,
        _rotation_quat_wxyz(thumb_rest),
        [
            [("cmc_flex", x_axis), ("cmc_abd", palm_away)],
            [("mcp_abd", palm_away), ("mcp_flex", x_axis)],
            [("ip_flex", x_axis)],
        ],
        [mc * hl, pp * hl, dp * hl],
        [_scaled(r, hl) * thick for r in (r_mc, r_pp, r_dp)],
        ("cmc", "mcp", "ip"),
    )

    # Fingers: parallel at zero abduction; abduction (toward the thumb) outermost.
    for f in FINGERS:
        _, pp, mp, dp = _BUCHHOLZ[f]
        _, r_pp, r_mp, r_dp = _RADII[f]
        tilt_mcp, tilt_ip = np.deg2rad(_FLEX_TILT_DEG[f])
        flex_mcp = (np.cos(tilt_mcp), np.sin(tilt_mcp), 0.0)
        flex_ip = (np.cos(tilt_ip), np.sin(tilt_ip), 0.0)
        add_chain(
            f,
            mcp[f],
            identity,
            [
                [("mcp_abd", (0.0, 0.0, -1.0)), ("mcp_flex", flex_mcp)],
                [("pip_flex", flex_ip)],
                [("dip_flex", flex_ip)],
            ],
            [pp * hl, mp * hl, dp * hl],
            [_scaled(r, hl) * thick for r in (r_pp, r_mp, r_dp)],
            ("mcp", "pip", "dip"),
        )

    return Skeleton(params, tuple(bodies), tuple(keypoints[n] for n in KEYPOINT_NAMES))


_MIRROR = np.array([-1.0, 1.0, 1.0])


def _mirror_point(p: np.ndarray) -> np.ndarray:
    return p * _MIRROR


def _mirror_axis(a: np.ndarray) -> np.ndarray:
    # Reflection M: M R(a, t) M = R(-M a, t); axes are pseudovectors.
    return -a * _MIRROR


def _mirror_quat(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], *_mirror_axis(q[1:])])


def _mirror_geom(g: Capsule | Box) -> Capsule | Box:
    if isinstance(g, Capsule):
        return Capsule(_mirror_point(g.start), _mirror_point(g.end), g.radius)
    return Box(_mirror_point(g.pos), g.half_size.copy())


def build_skeleton(params: HandParams) -> Skeleton:
    """Build the kinematic skeleton of a hand.

    Args:
        params: hand parameters.

    Returns:
        The skeleton; for a left hand every position, axis and orientation is mirrored through
        the hand frame's ``x = 0`` plane, so equal angles give mirror-image postures.
    """
    if not isinstance(params, HandParams):
        raise InvalidHandParams(
            f"params must be a HandParams; received {show(params)} ({type(params).__name__})"
        )
    right = _right_skeleton(dataclasses.replace(params, side="right"))
    if params.side == "right":
        return right
    bodies = tuple(
        dataclasses.replace(
            b,
            pos=_mirror_point(b.pos),
            quat_wxyz=_mirror_quat(b.quat_wxyz),
            joints=tuple((i, _mirror_axis(a)) for i, a in b.joints),
            geoms=tuple(_mirror_geom(g) for g in b.geoms),
        )
        for b in right.bodies
    )
    keypoints = tuple((i, _mirror_point(p)) for i, p in right.keypoints)
    return Skeleton(params, bodies, keypoints)


def extra_point_positions(skeleton: Skeleton) -> dict[str, np.ndarray]:
    """Where the extra points of other keypoint formats sit in the palm frame.

    Each is the affine combination :data:`~handsim.hand.keypoints.EXTRA_POINT_RULES` of the
    wrist and the MCPs, which are fixed in the palm, so the points are too.

    Args:
        skeleton: the hand's skeleton.

    Returns:
        :data:`~handsim.hand.keypoints.EXTRA_POINT_NAMES` -> (3,) position in the palm body's
        frame, metres.
    """
    in_palm = {}
    for name, (body_index, local) in zip(KEYPOINT_NAMES, skeleton.keypoints, strict=True):
        body = skeleton.bodies[body_index]
        if body_index == 0:
            in_palm[name] = local
        elif body.parent == 0 and not np.any(local):
            in_palm[name] = body.pos  # a digit's base joint: its body's origin
    return {
        name: sum(w * in_palm[source] for source, w in EXTRA_POINT_RULES[name].items())
        for name in EXTRA_POINT_NAMES
    }
