"""Grasp planning: the search for a collision-checked grasp of an object at its pose.

Plans come from the object's surface points and the hand's forward kinematics
(:mod:`.hand_geometry`), for the recipe of the object (:mod:`.recipes`). The expert's state,
start pose and timing (:mod:`.state`) and the recipes stay importable from here, where they
were first defined (they are documented in their own modules).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from handsim.envs.grasping.hand_geometry import (
    _CLOSURES,
    _FALLBACK_PAD_RAISES_M,
    _SPAN_DEPTHS_M,
    _SPAN_FINGER_FRACTION,
    _SPAN_FINGERS,
    _SPAN_SQUEEZE_RAD,
    _SPAN_WIDTH_M,
    _checker,
    _Closing,
    _closing,
    _closure_path,
    _CollisionChecker,
    _grip_scale,
    _hand_geometry,
    _nominal_stiffness,
    _side_preshape,
    _solid_run,
    _span_path,
    _squeeze,
    _wide_open,  # noqa: F401 (re-exported for benchmarks/span_path_search.py)
)
from handsim.envs.grasping.recipes import (  # noqa: F401 (re-exported)
    GRASP_RECIPES,
    OBJECT_RECIPES,
    OBJECT_SHAPE_CLASSES,
    GraspRecipe,
    ShapeClass,
    grasp_recipe,
    shape_class,
)

# Re-exported: execution, kinematic_grasps, the tests and benchmarks import these from here.
from handsim.envs.grasping.state import (  # noqa: F401
    _CLOSE_S,
    _EXPERT_ANGULAR_SPEED_RAD_S,
    _LIFT_TARGET_M,
    _PREGRASP_DIST_M,
    _SETTLE_S,
    _SLOW_SPEED_M_S,
    _SQUEEZE_S,
    CONTROL_DT_S,
    EXPERT_WRIST_SPEED_M_S,
    FRAME_SKIP,
    HOLD_DURATION_S,
    LIFT_HEIGHT_M,
    MAX_SLIP_M,
    MAX_TURN_RAD,
    MAX_WRIST_SPEED_M_S,
    TOUCH_PARTS,
    GraspPlanningError,
    GraspState,
    InvalidGraspState,
    _check_transform,
    _object_body_id,
    _world_points,
    start_pose,
    touch_forces,
)
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_LIMITS, HandPose
from handsim.hand.pose_sources import GRASP_TYPES
from handsim.world.objects import YCBObject

__all__ = ["GraspPlan", "plan_grasp"]


# Plans ----------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class GraspPlan:
    """A planned grasp, world frame.

    Attributes:
        grasp_type: key of :data:`handsim.hand.pose_sources.GRASP_TYPES`.
        strategy: ``"top"``, ``"side"`` or ``"rim"`` (see :class:`GraspRecipe`).
        wrist_pos: (3,) wrist position at the grasp, metres.
        rotation: ``world_from_hand`` at the grasp.
        approach_dir: (3,) unit direction of the final approach motion (toward the object).
        preshape: (21,) open hand angles for the approach, radians.
        contact: (21,) angles at which the digits reach the object, radians.
        closed: (21,) finger targets of the squeeze (beyond first contact), radians.
        hover_m: the approach ends this far above the grasp wrist; the wrist sinks to the
            grasp while the digits close (an open hand reaches lower than a closed one).
        width_m: object width between the opposing pads, metres.
        contact_closure: closure of ``grasp_type`` at which the pads meet the object.
        span: a wide box's span grasp (the thumb tip and the middle and ring pads on the side
            walls just under the top edges).
    """

    grasp_type: str
    strategy: str
    wrist_pos: np.ndarray
    rotation: Rotation
    approach_dir: np.ndarray
    preshape: np.ndarray
    contact: np.ndarray
    closed: np.ndarray
    hover_m: float
    width_m: float
    contact_closure: float
    span: bool = False

    @property
    def approach_end(self) -> np.ndarray:
        """(3,) wrist position where the approach ends (hovering above the grasp), metres."""
        return self.wrist_pos + np.array([0.0, 0.0, self.hover_m])

    def pose(self, angles: np.ndarray, offset_m: np.ndarray | None = None) -> HandPose:
        """The grasp wrist pose (optionally shifted by ``offset_m``, world) with ``angles``."""
        pos = self.wrist_pos if offset_m is None else self.wrist_pos + offset_m
        return HandPose(pos, self.rotation.as_rotvec(), angles)


_SIDE_OVERCLOSE = 0.5
_TABLE_CLEARANCE_M = 0.002
_OPENING_M = 0.03  # the preshaped pads clear the object by this much in total


def _raise_above_table(
    checker: _CollisionChecker,
    T: np.ndarray,
    wrist: np.ndarray,
    rotation: Rotation,
    postures: Sequence[np.ndarray],
    max_raise_m: float,
) -> np.ndarray | None:
    """Lift the wrist until every posture clears the table; None if it takes > max_raise_m."""
    raised = wrist.copy()
    for _ in range(4):
        worst = min(
            checker.clearance(HandPose(raised, rotation.as_rotvec(), a), T)[1] for a in postures
        )
        if worst >= _TABLE_CLEARANCE_M:
            return raised
        raised = raised + np.array([0.0, 0.0, _TABLE_CLEARANCE_M - worst + 5e-4])
        if raised[2] - wrist[2] > max_raise_m:
            return None
    return None


# A vessel's handle stays this far (horizontally) from the line of a pinch around its body:
# the pinch axis at least 40 deg off the mug's handle.
_HANDLE_CLEARANCE_M = 0.03


def _top_candidates(
    obj: YCBObject,
    T: np.ndarray,
    params: HandParams,
    recipe: GraspRecipe,
    preferred_dir: np.ndarray,
    fallback: bool = False,
) -> list[tuple[float, Callable[[bool], GraspPlan | None]]]:
    """Top and rim grasps across horizontal axes: (cost, plan builder) per axis.

    The pads go as deep as the recipe allows, or higher by its ``pad_raises_m`` (at most 8 mm
    under the top); ``fallback``: only at the half steps :data:`_FALLBACK_PAD_RAISES_M`, with
    no span grasp (for where the usual heights leave no plan).
    """
    checker = _checker(obj, params)
    weights = _nominal_stiffness(obj, params) if recipe.nominal_squeeze else None
    points = _world_points(obj, T)
    com = T[:3, :3] @ obj.com_m + T[:3, 3]
    top = float(points[:, 2].max())
    deepest = max(recipe.height_fraction * top, top - recipe.max_depth_m, 0.0)
    # Shallower pads if the hand cannot reach that deep (up to 2 cm higher, 8 mm below the top).
    raises_m = _FALLBACK_PAD_RAISES_M if fallback else recipe.pad_raises_m
    heights = [deepest + r for r in raises_m if deepest + r <= top - 0.008]
    if not heights and not fallback:
        heights = [deepest]
    closings = [
        (
            _closing(
                params,
                recipe,
                _closure_path(recipe),
                recipe.contact_fraction,
                recipe.squeeze_rad * _grip_scale(obj),
            ),
            heights,
            deepest,
        )
    ]
    span = None
    if recipe.wide:
        # Too wide for the pinch: the hand's widest span, tips on the walls under the top edges.
        span = _closing(
            params,
            dataclasses.replace(recipe, fingers=_SPAN_FINGERS),
            _span_path(),
            _SPAN_FINGER_FRACTION,
            _SPAN_SQUEEZE_RAD * _grip_scale(obj),
            thumb_fraction=1.0,
        )
        span_heights = [] if fallback else [top - d for d in _SPAN_DEPTHS_M]
        closings.append((span, span_heights, top - _SPAN_DEPTHS_M[0]))
    # Grasp through the COM if the object is there, else through the nearest surface point;
    # with ``max_offset_m``, also at points along the object's long axis (narrower there).
    centres = []
    axis_angles = np.deg2rad(np.arange(0.0, 360.0, 10.0))
    if recipe.strategy == "rim":
        # The rim point nearest the user; the pads pinch its wall radially.
        rim = points[points[:, 2] > top - 0.01]
        centres.append((rim[np.argmin((rim[:, :2] - com[:2]) @ preferred_dir[:2])], 0.0))
    else:
        xy = points[:, :2] - com[:2]
        long_axis = np.linalg.eigh(xy.T @ xy)[1][:, -1]
        if recipe.across_long_axis:
            across = math.atan2(long_axis[0], -long_axis[1])
            axis_angles = np.array([across, across + math.pi])
            s_long = xy @ long_axis
            long_end = long_axis if s_long.max() > -s_long.min() else -long_axis
        offsets = np.arange(-recipe.max_offset_m, recipe.max_offset_m + 1e-9, 0.01)
        for offset in offsets[np.argsort(np.abs(offsets), kind="stable")]:
            target = com[:2] + offset * long_axis
            if recipe.across_long_axis:
                target = target + recipe.across_shift_m * long_end
            xy_dist = np.linalg.norm(points[:, :2] - target, axis=1)
            if xy_dist.min() < 0.005:
                centres.append((np.array([*target, com[2]]), abs(offset)))
            elif offset == 0.0:
                centres.append((points[np.argmin(xy_dist)].copy(), 0.0))

    def builder(c: _Closing, k: int, u: np.ndarray, grasp_point: np.ndarray, width: float):
        def build(narrow: bool) -> GraspPlan | None:
            v_hat = c.contact_vec[k] / np.linalg.norm(c.contact_vec[k])
            palm_down, _ = Rotation.align_vectors(
                [u, [0.0, 0.0, -1.0]], [v_hat, [0.0, 0.0, 1.0]], weights=[1e4, 1.0]
            )
            mid = 0.5 * (c.spheres[k, 0] + c.spheres[k, 1:].mean(axis=0))
            contact = c.angles[min(k + 3, len(_CLOSURES) - 1)]
            # Roll about the grasp axis (it stays horizontal) to keep the other digits off the
            # table: the roll with the most table clearance, the smallest on ties.
            best = None
            for roll_deg in (0.0, 10.0, -10.0, 20.0, -20.0, 30.0, -30.0):
                rotation = Rotation.from_rotvec(np.deg2rad(roll_deg) * u) * palm_down
                pose = HandPose(grasp_point - rotation.apply(mid), rotation.as_rotvec(), contact)
                clearance = min(checker.clearance(pose, T)[1], _TABLE_CLEARANCE_M)
                if best is None or clearance > best[0] + 1e-4:
                    best = (clearance, rotation)
            rotation = best[1]
            closed = _squeeze(c.angles, k, c.squeeze_rad, weights)
            wrist = _raise_above_table(
                checker,
                T,
                grasp_point - rotation.apply(mid),
                rotation,
                [contact],
                max_raise_m=max(0.0, top - recipe.min_depth_m - grasp_point[2]),
            )
            if wrist is None:
                return None
            # Open by 3 cm more than the width, or by other amounts (into holes, or wider)
            # until the way down is clear. An open hand reaches lower than a closing one: it
            # hovers, and sinks to the grasp while closing.
            openings = []
            for extra in (_OPENING_M, 0.02, 0.008):
                wide_enough = np.nonzero(c.gap >= width + extra)[0]
                openings.append(int(wide_enough.max()) if wide_enough.size else 0)
            # 3 cm, then half way to fully open, fully open; on the second pass narrower (into
            # holes).
            openings = [openings[0], openings[0] // 2, 0] if not narrow else openings[1:]
            for k_pre in dict.fromkeys(openings):
                hovering = _raise_above_table(checker, T, wrist, rotation, [c.angles[k_pre]], 0.06)
                if hovering is None:
                    continue
                plan = GraspPlan(
                    grasp_type=recipe.grasp_type,
                    strategy=recipe.strategy,
                    wrist_pos=wrist,
                    rotation=rotation,
                    approach_dir=np.array([0.0, 0.0, -1.0]),
                    preshape=c.angles[k_pre],
                    contact=contact,
                    closed=closed,
                    hover_m=float(hovering[2] - wrist[2]),
                    width_m=width,
                    contact_closure=float(_CLOSURES[k]),
                    span=c is span,
                )
                if _approach_is_clear(plan, obj, T, params):
                    return plan
            return None

        return build

    candidates = []
    for index, (closing, variant_heights, deepest_h) in enumerate(closings):
        for (centre, offset), height in itertools.product(centres, variant_heights):
            near = np.abs(points[:, 2] - height) < 0.01
            rel = points[near] - centre
            handle = None
            if obj.cavity_point_m is not None and recipe.strategy == "top":
                # A vessel held around its body: the points farther from the cavity's axis
                # than its wall are the handle, which the pinch keeps away from.
                axis = T[:3, :3] @ obj.cavity_point_m + T[:3, 3]
                radial = np.linalg.norm(points[near, :2] - axis[:2], axis=1)
                handle = radial > 1.1 * float(np.median(radial))
            for angle in axis_angles:
                u = np.array([np.cos(angle), np.sin(angle), 0.0])
                if recipe.across_long_axis:
                    # Palm down, the object's long end on the thumb's side (left of u for a right
                    # hand), the fingers turned at most max_yaw_rad from pointing away from the
                    # user.
                    handed = 1.0 if params.side == "right" else -1.0
                    thumb_side = np.array([-u[1], u[0]]) * handed
                    if thumb_side @ long_end < 0.0:
                        continue
                    toward_thumb = handed * math.atan2(
                        preferred_dir[0] * u[1] - preferred_dir[1] * u[0], u @ preferred_dir
                    )
                    if not -recipe.max_yaw_rad[1] <= toward_thumb <= recipe.max_yaw_rad[0]:
                        continue
                if recipe.strategy == "rim":
                    inward = com[:2] - centre[:2]
                    if u[:2] @ inward < np.cos(np.deg2rad(25.0)) * np.linalg.norm(inward):
                        continue
                n = np.array([-u[1], u[0], 0.0])
                strip = np.abs(rel @ n) < recipe.band_m
                if recipe.strategy == "rim":
                    strip &= np.abs(rel @ u) < 0.03
                if strip.sum() < 3:
                    continue
                if handle is not None and (handle & (np.abs(rel @ n) < _HANDLE_CLEARANCE_M)).any():
                    continue
                s = rel[strip] @ u
                if recipe.finger_holes:
                    s = _solid_run(s, 2.0 * _hand_geometry(params).distal_radius["thumb"])
                    if s is None:
                        continue
                width = float(s.max() - s.min())
                # Wide recipes: the pinch up to _SPAN_WIDTH_M, the span beyond.
                if recipe.wide and (width > _SPAN_WIDTH_M) != (index == 1):
                    continue
                if width + 0.004 > closing.gap.max() - 0.005:
                    continue
                k = int(np.argmin(np.abs(closing.gap - (width + 0.004))))
                grasp_point = centre + u * 0.5 * (s.max() + s.min())
                grasp_point[2] = height
                # A narrow grip (pads square to the surface) near the COM, the fingers pointing
                # away from the user (the hand's y axis is about u), the pads deep.
                yaw_cost = 1.0 - float(u @ preferred_dir)
                cost = 3.0 * width + offset + 0.05 * yaw_cost + 2.0 * abs(height - deepest_h)
                candidates.append((cost, builder(closing, k, u, grasp_point, width)))
    return candidates


def _approach_dir(recipe: GraspRecipe, T: np.ndarray, default: np.ndarray) -> np.ndarray:
    """The horizontal direction a side wrap prefers: the recipe's, in the world, or ``default``."""
    if recipe.approach_obj is None:
        return default
    d = T[:3, :3] @ np.asarray(recipe.approach_obj, dtype=np.float64)
    d[2] = 0.0
    norm = float(np.linalg.norm(d))
    return default if norm < 1e-6 else d / norm


def _side_candidates(
    obj: YCBObject,
    T: np.ndarray,
    params: HandParams,
    recipe: GraspRecipe,
    preferred_dir: np.ndarray,
) -> list[tuple[float, Callable[[bool], GraspPlan | None]]]:
    """Side wraps (palm against an upright object, thumb up): (cost, builder) per direction."""
    checker = _checker(obj, params)
    grasp = GRASP_TYPES[recipe.grasp_type]
    preshape = _side_preshape(params.hand_length)
    # Targets past the fully closed posture, so that a hand large for the object still
    # presses on it (the grip force loop then scales the deflections).
    closed = np.clip(
        grasp.angles(1.0) + _SIDE_OVERCLOSE * (grasp.angles(1.0) - grasp.large),
        JOINT_LIMITS[:, 0],
        JOINT_LIMITS[:, 1],
    )
    points = _world_points(obj, T)
    top = float(points[:, 2].max())
    height = (
        recipe.height_fraction * top if recipe.handle else min(recipe.height_fraction * top, 0.14)
    )
    band = points[np.abs(points[:, 2] - height) < 0.01]
    if recipe.handle and obj.cavity_point_m is not None:
        # The handle: the band's points farther from the cavity's axis than the wall.
        axis = T[:3, :3] @ obj.cavity_point_m + T[:3, 3]
        radial = np.linalg.norm(band[:, :2] - axis[:2], axis=1)
        band = band[radial > 1.1 * float(np.median(radial))]
    if len(band) < 3:
        return []  # no upright object there (it fell over, or off the table)
    centre = 0.5 * (band.max(axis=0) + band.min(axis=0))

    def builder(d: np.ndarray, span: float):
        def build(narrow: bool) -> GraspPlan | None:
            if narrow:
                return None
            # Thumb up: the hand's x axis is radial for a right hand and ulnar for a left one.
            x_dir = np.array([0.0, 0.0, 1.0 if params.side == "right" else -1.0])
            y_dir = np.cross(d, x_dir)
            rotation = Rotation.from_matrix(np.stack([x_dir, y_dir, d], axis=1))
            # The object's axis sits over the bases of the proximal phalanges; the palm
            # advances along d until it is about to touch the object.
            depth = float(-((band - centre) @ d).min())
            far = np.array([centre[0], centre[1], height]) - rotation.apply(
                [0.0, 0.4 * params.hand_length, depth + 0.06]
            )
            advance = _advance_to_contact(checker, T, far, rotation, preshape, d, 0.08)
            if advance is None:
                return None
            wrist = _raise_above_table(checker, T, far + advance * d, rotation, [preshape], 0.03)
            if wrist is None:
                return None
            plan = GraspPlan(
                grasp_type=recipe.grasp_type,
                strategy="side",
                wrist_pos=wrist,
                rotation=rotation,
                approach_dir=d,
                preshape=preshape,
                contact=grasp.large,
                closed=closed,
                hover_m=0.0,
                width_m=span,
                contact_closure=0.5,
            )
            return plan if _approach_is_clear(plan, obj, T, params) else None

        return build

    candidates = []
    for angle in np.deg2rad(np.arange(0.0, 360.0, 10.0)):
        d = np.array([np.cos(angle), np.sin(angle), 0.0])
        if d @ preferred_dir < np.cos(np.deg2rad(recipe.approach_cone_deg)):
            continue
        if d[1] < np.cos(np.deg2rad(recipe.max_from_user_deg)):
            continue  # the user is at -y
        span = float(np.ptp((band - centre) @ np.cross(d, [0.0, 0.0, 1.0])))
        # The palm on the broad face: the digits wrap around the object's thin dimension.
        depth = float(np.ptp((band - centre) @ d))
        candidates.append((depth + 0.03 * (1.0 - float(d @ preferred_dir)), builder(d, span)))
    return candidates


def _advance_to_contact(
    checker: _CollisionChecker,
    T: np.ndarray,
    wrist: np.ndarray,
    rotation: Rotation,
    angles: np.ndarray,
    direction: np.ndarray,
    max_m: float,
    gap_m: float = 0.002,
) -> float | None:
    """How far the hand moves along ``direction`` until it is ``gap_m`` from the object."""
    rotvec = rotation.as_rotvec()

    def gap(s: float) -> float:
        return checker.clearance(HandPose(wrist + s * direction, rotvec, angles), T)[0]

    if gap(0.0) < gap_m:
        return None
    lo, hi = 0.0, max_m
    if gap(hi) >= gap_m:
        return None
    # Clearance saturates at the checker's margin, so bisect on "closer than gap_m".
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        if gap(mid) >= gap_m:
            lo = mid
        else:
            hi = mid
    return lo


def _approach_is_clear(plan: GraspPlan, obj: YCBObject, T: np.ndarray, params: HandParams) -> bool:
    """The preshaped hand does not touch the object on the way in, nor the table at all."""
    checker = _checker(obj, params)
    hover = plan.approach_end - plan.wrist_pos
    for s in np.linspace(0.0, 1.0, 6):
        offset = hover - (1.0 - s) * _PREGRASP_DIST_M * plan.approach_dir
        to_obj, to_table = checker.clearance(plan.pose(plan.preshape, offset), T)
        if to_table < 0.0 or to_obj < (0.0 if s < 1.0 else -0.003):
            return False
    return True


def _clear_of_obstacles(
    plan: GraspPlan,
    params: HandParams,
    obstacles: Sequence[tuple[YCBObject, np.ndarray]],
) -> bool:
    """The hand stays off every obstacle on the way in, while closing and while lifting."""
    if not obstacles:
        return True
    hover = plan.approach_end - plan.wrist_pos
    poses = [
        plan.pose(plan.preshape, hover - (1.0 - s) * _PREGRASP_DIST_M * plan.approach_dir)
        for s in np.linspace(0.0, 1.0, 5)
    ]
    poses += [plan.pose(angles) for angles in (plan.preshape, plan.contact, plan.closed)]
    poses += [plan.pose(plan.closed, np.array([0.0, 0.0, z])) for z in (0.05, 0.1, 0.15)]
    for other, T_other in obstacles:
        checker = _checker(other, params)
        if any(checker.clearance(pose, T_other)[0] < _OBSTACLE_CLEARANCE_M for pose in poses):
            return False
    return True


_OBSTACLE_CLEARANCE_M = 0.002


def plan_grasp(
    obj: YCBObject,
    T_world_from_obj: np.ndarray,
    params: HandParams,
    obstacles: Sequence[tuple[YCBObject, np.ndarray]] = (),
) -> GraspPlan:
    """Plan a grasp of ``obj`` at ``T_world_from_obj`` for a hand of ``params``.

    Args:
        obj: the object.
        T_world_from_obj: (4, 4) its pose, world frame.
        params: the hand.
        obstacles: other objects, ``(object, (4, 4) T_world_from_obj)`` pairs: candidates
            whose hand comes within 2 mm of one (approach, grasp, closing or lift) are
            skipped.

    Returns:
        The best-scoring candidate whose approach is free of collisions.

    Raises:
        GraspPlanningError: if no candidate grasp is free of collisions.
    """
    T = _check_transform(T_world_from_obj, "T_world_from_obj")
    recipe = grasp_recipe(obj)
    preferred = np.array([0.0, 1.0, 0.0])
    # An object's own recipe first; its shape class's where that finds no grasp; then, for top
    # grasps, the same with the pads at the half steps.
    recipes = dict.fromkeys([recipe, GRASP_RECIPES.get(OBJECT_SHAPE_CLASSES.get(obj.name), recipe)])
    candidate_sets = [
        functools.partial(_side_candidates, obj, T, params, r, _approach_dir(r, T, preferred))
        if r.strategy == "side"
        else functools.partial(_top_candidates, obj, T, params, r, preferred, fallback)
        for fallback in (False, True)
        for r in recipes
        if r.strategy != "side" or not fallback
    ]
    scored = []
    for candidates in candidate_sets:
        scored = sorted(candidates(), key=lambda c: c[0])
        # First with the hand opened wide, then (a second pass) opened just enough.
        for narrow, (_, build) in itertools.product((False, True), scored):
            plan = build(narrow)
            if plan is not None and _clear_of_obstacles(plan, params, obstacles):
                return plan
    raise GraspPlanningError(
        f"no collision-free {recipe.strategy} grasp ({recipe.grasp_type}) found for "
        f"{obj.name} at {np.round(T[:3, 3], 3).tolist()} m ({len(scored)} candidates"
        f"{f', {len(obstacles)} obstacles' if obstacles else ''})"
    )
