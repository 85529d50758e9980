"""The planner's hand: forward kinematics of the digits, a private collision model, postures.

Machinery of :mod:`.planning`: contact spheres on the distal capsules, a kinematic copy of
table, hand and object that reports clearances (never the env's model), and the closing paths
(preshapes, the wide opening, the span path, squeezes past contact).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import mujoco
import numpy as np

from handsim.envs.grasping.recipes import GraspRecipe
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import (
    ACTUATOR_GAINS,
    HAND_SIZES,
    Hand,
    HandParams,
    _joint_kind,
)
from handsim.hand.pose import JOINT_LIMITS, JOINT_NAMES, NUM_ANGLES, HandPose, joint_index
from handsim.hand.pose_sources import GRASP_TYPES
from handsim.world.objects import YCBObject, add_object

# Hand model helpers ---------------------------------------------------------------------------

_DIGIT_DISTAL_BODY = {
    "thumb": "thumb_distal",
    "index": "index_distal",
    "middle": "middle_distal",
    "ring": "ring_distal",
    "little": "little_distal",
}
_CLOSURES = np.linspace(0.0, 1.0, 101)


@dataclasses.dataclass(frozen=True)
class _HandGeometry:
    """Forward kinematics of one hand size and the distal capsules of its digits."""

    fk: ForwardKinematics
    distal_body: dict[str, int]
    distal_start: dict[str, np.ndarray]
    distal_end: dict[str, np.ndarray]
    distal_radius: dict[str, float]

    def contacts(self, angles: np.ndarray, digits: Sequence[str], fraction: float) -> np.ndarray:
        """Contact sphere centres on the distal capsules' axes, hand frame.

        Args:
            angles: (..., 21) radians.
            digits: digit names.
            fraction: where along each distal capsule (0 its base, 1 the centre of its tip).

        Returns:
            (..., len(digits), 3) metres; each sphere has the capsule's radius.
        """
        batch = angles.shape[:-1]
        pose = HandPose(np.zeros(batch + (3,)), np.zeros(batch + (3,)), angles)
        rots, poss = self.fk.body_frames(pose)
        out = []
        for d in digits:
            body = self.distal_body[d]
            local = (1.0 - fraction) * self.distal_start[d] + fraction * self.distal_end[d]
            out.append(
                poss[..., body, :] + np.einsum("...ij,j->...i", rots[..., body, :, :], local)
            )
        return np.stack(out, axis=-2)


@functools.lru_cache(maxsize=8)
def _hand_geometry(params: HandParams) -> _HandGeometry:
    fk = ForwardKinematics(params)
    names = [b.name for b in fk.skeleton.bodies]
    body, start, end, radius = {}, {}, {}, {}
    for digit, body_name in _DIGIT_DISTAL_BODY.items():
        index = names.index(body_name)
        capsule = fk.skeleton.bodies[index].geoms[0]
        body[digit] = index
        start[digit], end[digit], radius[digit] = capsule.start, capsule.end, capsule.radius
    return _HandGeometry(fk, body, start, end, radius)


class _CollisionChecker:
    """A private kinematic model of the table top, the hand and the object for planning.

    Reports how far the hand's collision geoms come within ``margin_m`` of the table top (the
    plane z = 0, as in :mod:`handsim.world.scene`) or the object; it never touches the env's
    model or data.
    """

    def __init__(self, obj: YCBObject, params: HandParams, margin_m: float = 0.003) -> None:
        spec = mujoco.MjSpec()
        spec.worldbody.add_geom(
            name="table",
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=(0.0, 0.0, 1.0),
            margin=margin_m,
        )
        hand = Hand(params)
        hand.attach_to(spec)
        body = add_object(spec, obj, free_joint=False)
        for geom in body.geoms:
            geom.margin = margin_m
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.binding = hand.bind(self.model)
        self.obj_body = int(self.model.body(obj.body_name).id)
        self.table_geom = int(self.model.geom("table").id)
        hand_bodies = {int(self.model.body(hand.prefix + b.name).id) for b in hand.skeleton.bodies}
        self.hand_geom = np.array(
            [int(self.model.geom_bodyid[g]) in hand_bodies for g in range(self.model.ngeom)]
        )
        self.margin_m = margin_m

    def clearance(self, pose: HandPose, T_world_from_obj: np.ndarray) -> tuple[float, float]:
        """Smallest signed distance (m) of the hand to the object and to the table.

        Distances above ``margin_m`` read as ``margin_m``; negative values are penetrations.
        """
        self.model.body_pos[self.obj_body] = T_world_from_obj[:3, 3]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, np.ascontiguousarray(T_world_from_obj[:3, :3]).ravel())
        self.model.body_quat[self.obj_body] = quat
        b = self.binding
        pose = pose.clip()
        q = b.root_qpos
        self.data.qpos[q : q + 3] = pose.wrist_pos
        self.data.qpos[q + 3 : q + 7] = pose.quat_wxyz
        self.data.qpos[b.joint_qpos] = pose.angles
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_collision(self.model, self.data)
        to_obj, to_table = self.margin_m, self.margin_m
        for k in range(self.data.ncon):
            contact = self.data.contact[k]
            g1, g2 = int(contact.geom1), int(contact.geom2)
            if self.hand_geom[g1] == self.hand_geom[g2]:
                continue
            other = g2 if self.hand_geom[g1] else g1
            if other == self.table_geom:
                to_table = min(to_table, float(contact.dist))
            elif int(self.model.geom_bodyid[other]) == self.obj_body:
                to_obj = min(to_obj, float(contact.dist))
        return to_obj, to_table


@functools.lru_cache(maxsize=32)
def _checker(obj: YCBObject, params: HandParams) -> _CollisionChecker:
    return _CollisionChecker(obj, params)


def _side_preshape(hand_length_m: float) -> np.ndarray:
    # Fingers straight (slightly hyperextended at the MCPs) and the thumb in full palmar
    # abduction and extension, so the open "C" of the hand passes around a thick object.
    # Hands shorter than the medium one open the thumb's CMC to its extension limit (-40 deg,
    # not -20): at -20 the thumb tip of a 0.152-0.165 m hand met the 102 mm master chef can
    # first and kept the palm 36-40 mm off it (the digits then closed on its near half only
    # and squeezed it out of the hand). Longer hands keep -20: at -40 the large left hand let
    # the mustard bottle slip (seed 14, skin friction).
    angles = np.zeros(NUM_ANGLES)
    cmc_flex_deg = -40.0 if hand_length_m < HAND_SIZES["medium"] else -20.0
    angles[joint_index("thumb_cmc_flex")] = np.deg2rad(cmc_flex_deg)
    angles[joint_index("thumb_cmc_abd")] = np.deg2rad(60.0)
    for finger in ("index", "middle", "ring", "little"):
        angles[joint_index(f"{finger}_mcp_flex")] = np.deg2rad(-10.0)
    return angles


def _wide_open() -> np.ndarray:
    # A wide opening for boxes: the thumb in full palmar abduction and extension, the fingers
    # spread, straight at the MCPs and hooked at the PIPs and DIPs (0.19 m between the thumb
    # and middle tips at 189 mm). A grid search over the finger flexions chose it as the
    # widest posture that can still descend over a 0.16 m wide box without touching it.
    angles = np.zeros(NUM_ANGLES)
    for name, deg in (
        ("thumb_cmc_flex", -20.0),
        ("thumb_cmc_abd", 60.0),
        ("thumb_mcp_flex", -10.0),
        ("thumb_mcp_abd", 10.0),
        ("thumb_ip_flex", -15.0),
        ("index_mcp_abd", 8.0),
        ("ring_mcp_abd", -6.0),
        ("little_mcp_abd", -12.0),
    ):
        angles[joint_index(name)] = np.deg2rad(deg)
    for finger in ("index", "middle", "ring", "little"):
        angles[joint_index(f"{finger}_pip_flex")] = np.deg2rad(20.0)
        angles[joint_index(f"{finger}_dip_flex")] = np.deg2rad(30.0)
    return angles


def _closure_path(recipe: GraspRecipe) -> np.ndarray:
    """(len(_CLOSURES), 21) postures from open to closed for a recipe."""
    grasp = GRASP_TYPES[recipe.grasp_type]
    if not recipe.wide:
        path = grasp.angles(_CLOSURES)
    else:
        # Open wider than the type's preshape: wide span -> largest object -> smallest object.
        anchors = np.stack([_wide_open(), grasp.large, grasp.small])
        c = np.clip(_CLOSURES * 2.0, 0.0, 2.0)
        lower = np.floor(np.minimum(c, 1.999)).astype(int)
        frac = (c - lower)[:, None]
        path = anchors[lower] + frac * (anchors[lower + 1] - anchors[lower])
    if not recipe.hook and not recipe.straight_fingers:
        return path
    fingers = {f: recipe.straight_fingers_deg for f in recipe.straight_fingers}
    if recipe.hook:
        mcp_open, mcp_closed = _HOOK_MCP_DEG
        hooked = (mcp_open + _CLOSURES * (mcp_closed - mcp_open), *_HOOK_PIP_DIP_DEG)
        fingers |= {"middle": hooked, "ring": hooked}
    path = path.copy()
    for finger, degrees in fingers.items():
        for joint, deg in zip(("mcp", "pip", "dip"), degrees, strict=True):
            path[:, joint_index(f"{finger}_{joint}_flex")] = np.deg2rad(deg)
    return np.clip(path, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])


# The hooked fingers: PIP and DIP fixed, the MCP closing from its hyperextension limit. Chosen
# from a grid of PIP 40-100 and DIP 0-40 deg (the planner's contact posture for the sugar box,
# small right hand, seeds 0-1): at 40 / 40 every proximal and middle segment stays off the box
# and the pads meet the walls; straighter DIPs or more bent PIPs put the middle segments
# 1-11 mm into the far top edge.
_HOOK_MCP_DEG = (-20.0, 90.0)
_HOOK_PIP_DIP_DEG = (40.0, 40.0)


def _nominal_stiffness(obj: YCBObject, params: HandParams) -> np.ndarray:
    """(21,) each joint's nominal stiffness over its actuator's (at most 1).

    Where a hand's links are heavy its position actuators are stiffer than the nominal ones
    (:data:`~handsim.hand.model.ACTUATOR_GAINS`), to keep their bandwidth: the fingers' MCP
    abduction of every preset hand (1.1-5.9 times nominal), and the thumb CMC of the large
    hands (4.9 N m/rad instead of 3), so a squeeze by the same angle pressed harder.
    Scaling the squeeze's deflection by this ratio presses with the nominal torques.
    """
    checker = _checker(obj, params)
    nominal = np.array([ACTUATOR_GAINS[_joint_kind(name)][0] for name in JOINT_NAMES])
    kp = nominal.copy()
    kp[checker.binding.actuated] = checker.model.actuator_gainprm[checker.binding.actuator_ids, 0]
    return np.minimum(nominal / kp, 1.0)


def _squeeze(
    path: np.ndarray, k: int, squeeze_rad: float, weights: np.ndarray | None = None
) -> np.ndarray:
    """Finger targets past first contact: along the closing direction of ``path`` at ``k``.

    Position actuators press with ``kp * (target - angle)``: the joint that moves most on the
    closing path is driven ``squeeze_rad`` beyond its contact angle, the others in proportion
    (clipped to the joint limits).
    """
    end = len(path) - 1
    lo = min(k, end - 10)
    direction = path[lo + 10] - path[lo]
    if np.abs(direction).max() < 1e-6:
        direction = path[end] - path[0]
    step = direction * (squeeze_rad / np.abs(direction).max())
    if weights is not None:
        step = step * weights
    return np.clip(path[k] + step, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])


def _solid_run(s: np.ndarray, hole_m: float) -> np.ndarray | None:
    """The surface samples of the solid run through ``s = 0``: ``s`` split at gaps > hole_m.

    A gap wider than a fingertip (a scissors loop) lets the digits in, so the pads close on
    the material around the centre only. None if the centre itself lies in such a gap.
    """
    order = np.sort(s)
    breaks = np.nonzero(np.diff(order) > hole_m)[0]
    bounds = np.concatenate([[0], breaks + 1, [len(order)]])
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        run = order[lo:hi]
        if run[0] - 0.5 * hole_m <= 0.0 <= run[-1] + 0.5 * hole_m:
            return run
    return None


def _grip_scale(obj: YCBObject) -> float:
    """Squeeze factor for the object's weight: 0.4 for the lightest, 1 from 180 g up.

    People grip with a safety margin over the force that just holds a load (grip force grows
    with it); a light object squeezed hard is pushed out of a pinch.
    """
    return float(np.clip(0.4 + obj.mass_kg / 0.3, 0.4, 1.0))


@dataclasses.dataclass(frozen=True)
class _Closing:
    """How the digits close in a top grasp: postures and contact spheres along the closure."""

    angles: np.ndarray  # (C, 21) postures, open to closed
    spheres: np.ndarray  # (C, 1 + F, 3) thumb and finger contact spheres, hand frame
    contact_vec: np.ndarray  # (C, 3) thumb sphere -> mean finger sphere
    gap: np.ndarray  # (C,) surface gap between them, metres
    squeeze_rad: float


def _closing(
    params: HandParams,
    recipe: GraspRecipe,
    angles: np.ndarray,
    fraction: float,
    squeeze: float,
    thumb_fraction: float | None = None,
) -> _Closing:
    geometry = _hand_geometry(params)
    digits = ("thumb", *recipe.fingers)
    spheres = geometry.contacts(angles, digits, fraction)
    if thumb_fraction is not None:
        spheres[:, 0] = geometry.contacts(angles, ("thumb",), thumb_fraction)[:, 0]
    radii = np.array([geometry.distal_radius[d] for d in digits])
    contact_vec = spheres[:, 1:].mean(axis=1) - spheres[:, 0]
    gap = np.linalg.norm(contact_vec, axis=-1) - radii[0] - radii[1:].mean()
    return _Closing(angles, spheres, contact_vec, gap, squeeze)


# The index and little fingers of the span grasp (MCP, PIP, DIP, degrees): curled over the
# box's top face. Straight (-20, 0, 20) they stuck out over the box; closing with the middle and
# ring fingers they pressed on the top face and the box stayed down (medium right, seeds 0-3);
# curled further (PIP 35-40) the small left hand's box stayed down in seeds 9 and 11 where it
# is held with them straight.
_SPAN_CURL_DEG = (-20.0, 30.0, 20.0)


def _span_path() -> np.ndarray:
    # Boxes wider than _SPAN_WIDTH_M: the thumb at its widest (full palmar abduction and
    # extension at the CMC), its tip on the near wall; the middle and ring fingers hyperextended
    # at the MCPs and curled at the PIPs and DIPs, so their distal pads meet the far wall about
    # vertically below the top edge; the shorter index and little fingers stay straighter, clear
    # of the top face. Closing curls the middle and ring fingers and flexes the thumb's IP. The
    # angles came from a search over the path (the pads' and segments' distances to a 0.164 m
    # wide box at the closure where the pads span it) for which hands from 0.18 to 0.22 m meet
    # both walls 1 cm below the top with no other segment within 3 mm of the box; at 0.165 m
    # the thumb's distal segment and the middle finger still cross the top edges by 3 mm.
    open_angles = _wide_open()
    delta = np.zeros(NUM_ANGLES)
    for name, deg in (
        ("thumb_cmc_flex", -40.0),
        ("thumb_cmc_abd", 60.0),
        ("thumb_mcp_flex", -10.0),
        ("thumb_mcp_abd", 10.0),
        ("thumb_ip_flex", 30.0),
    ):
        open_angles[joint_index(name)] = np.deg2rad(deg)
    delta[joint_index("thumb_ip_flex")] = np.deg2rad(50.0)
    for finger in ("index", "middle", "ring", "little"):
        # (MCP, PIP, DIP) at closure 0, degrees; the index and little fingers curled over the
        # top face, clear of it (not straight out), and not closing.
        mcp, pip, dip = (-17.0, 20.0, 39.0) if finger in ("middle", "ring") else _SPAN_CURL_DEG
        open_angles[joint_index(f"{finger}_mcp_flex")] = np.deg2rad(mcp)
        open_angles[joint_index(f"{finger}_pip_flex")] = np.deg2rad(pip)
        open_angles[joint_index(f"{finger}_dip_flex")] = np.deg2rad(dip)
        if finger in ("middle", "ring"):
            delta[joint_index(f"{finger}_mcp_flex")] = np.deg2rad(40.0)
            delta[joint_index(f"{finger}_pip_flex")] = np.deg2rad(71.0)
            delta[joint_index(f"{finger}_dip_flex")] = np.deg2rad(40.0)
    path = open_angles + _CLOSURES[:, None] * delta
    return np.clip(path, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])


_SPAN_WIDTH_M = 0.13
"""Boxes wider than this are held with the thumb and finger tips on the walls just under the
top edges (the hand's widest span)."""
_SPAN_DEPTHS_M = (0.010, 0.008, 0.012)
_SPAN_FINGERS = ("middle", "ring")
_SPAN_FINGER_FRACTION = 0.75  # the finger pads; the thumb touches with its tip
# Less than the pinch's 45 deg: squeezed 40 deg past contact, the large hand's pads dragged one
# wall up as they rolled on it and tilted the box 5 deg (not lifted at skin friction).
_SPAN_SQUEEZE_RAD = np.deg2rad(30.0)


# Half steps only where the recipe's steps (`GraspRecipe.pad_raises_m`) leave no plan: the tuna
# can (34 mm high) leaves no room for pads 1 cm higher than half its height (the limit 8 mm
# under the top), and at half its height the index's middle segment of hands under about
# 0.156 m crossed its top edge. (Among the others, the half steps changed 66 of the other top
# grasps' 2380 plans of seeds 0-19 and seven hands, 53 of them the clamps', which now try 5 mm
# among their own steps.)
_FALLBACK_PAD_RAISES_M = (0.005, 0.015)
