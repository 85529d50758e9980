"""Grasp execution: the expert that follows a plan, the success definition, episodes.

:class:`GraspExpert` follows a plan, :class:`LiftTracker` scores it and :func:`run_episode` is the
ground-truth episode loop.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Literal

import mujoco
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from handsim.envs.experts import PoseActions
from handsim.envs.grasping.planning import (
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
    TOUCH_PARTS,
    GraspPlan,
    GraspPlanningError,
    GraspRecipe,
    GraspState,
    InvalidGraspState,
    _check_transform,
    _checker,
    _object_body_id,
    grasp_recipe,
    plan_grasp,
    start_pose,
)
from handsim.envs.physics import HandDriver, skin_friction
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_LIMITS, JOINT_NAMES, HandPose
from handsim.world.objects import YCBObject
from handsim.world.scene import Scene

__all__ = [
    "GraspExpert",
    "ContactMetrics",
    "contact_metrics",
    "FailureReason",
    "GraspOutcome",
    "LiftTracker",
    "evaluate_lift",
    "run_episode",
]

# The expert -----------------------------------------------------------------------------------

GRIP_SAFETY_FACTOR = 1.6
"""Grip force over the force that just prevents slip. People grip with 1.3 to 3 times the slip
force and scale it with the load (grip-load coupling; Johansson & Westling 1984, Exp. Brain
Res. 56:550-564); the expert aims at 1.6."""
GRIP_FRICTION: float | None = None
"""Hand-object friction the expert assumes when sizing its grip force; ``None``: skin on the
object's material (:func:`handsim.envs.base.skin_friction`), as a person judges a surface."""
LIFT_ACCELERATION_M_S2 = 2.0
"""Upward acceleration the grip is sized for on top of gravity while lifting (the expert's
minimum-jerk lift peaks near 1.5 m/s^2), m/s^2; the static hold is sized for gravity alone."""
MIN_GRIP_SCALE = 0.02
"""The regulated grip never eases below this fraction of the squeeze's joint deflections
(the default of :attr:`GraspRecipe.min_grip_scale`)."""
MAX_GRIP_SCALE = 1.5
"""Nor presses beyond this multiple of them (a grip that touch reports too light tightens)."""
REPLAN_DISTANCE_M = 0.004
"""The expert re-plans when its estimate of the object's position moves this far, metres."""
REPLAN_ANGLE_RAD = float(np.deg2rad(4.0))
"""Or when its estimate of the object's orientation turns this far, radians."""
_PALM_PRESS_M = 0.02  # the side wrap's wrist goes this far past palm contact, m
_VIA_BACK_M = 0.06  # a reach from behind passes this far behind the pre-grasp, m
_VIA_CLEARANCE_M = 0.05  # ...and this far above the object's top, m
_REPLAN_PERIOD_S = 0.1  # at most one re-plan per 0.1 s
_FILTER_WINDOW = 100  # perceived poses averaged while the object is still (2 s)
_MOTION_MIN_M = 0.01  # the object moved: the recent estimates left the filtered pose by this
_SUPPORT_SNAP_M = 0.02  # estimates whose lowest point is this close to the table rest on it
_GRIP_RATE = 0.5  # exponent of the multiplicative force correction per control step
# The grip scale falls by at most 3 % per control step (a gradual relaxation, so that the slip
# check stops it before an eased grip lets go of a pinch; at 10 % the scissors, seed 0, were
# dropped at skin friction within 0.1 s of the hold)...
_GRIP_EASE = 0.97
_GRIP_TIGHTEN = 1.25  # ...and rises by up to 25 % (people tighten fast when a grip slips)
FALL_HEIGHT_M = -0.05
"""An object whose origin drops below this height (world z) has fallen off the table."""
HOLD_SLIP_M = 0.0015
"""The hold's easing stops for good once the object has moved this far in the palm frame
(metres; the median of the last five perceived positions against that of the hold's first
five): a grip eased until the object starts to slip is held there, not eased further (people
stop relaxing their grip at the first slip; Johansson & Westling 1984). With a noisy
estimator the threshold is at least four times the noise of that difference (from the spread
of the estimates before the grasp), so noise is not read as slip. (Going back three easing
steps as well was tried and not kept: see the commit history.)"""
HOLD_TURN_RAD = float(np.deg2rad(3.0))
"""Or once it has turned this far in the palm frame (the perceived orientation against that at
the hold's first step): a pinch eased too far lets its object turn about the pinch before it
slides (the large clamp at friction 0.5 turned 0.4 deg, then 3.4 deg within three control
steps, while its origin had moved less than :data:`HOLD_SLIP_M`). 2 deg gave the same
successes but stopped the easing of held objects early (the extra-large clamp held at 6.2 times
its weight instead of 4.8 at the default friction)."""
_SLIP_WINDOW = 5
MIN_GRIP_FORCE_N = 1.0
"""The least total grip force, newtons: for objects lighter than about 30 g people's
grip-to-load ratio rises (Hiramatsu, Kimura, Kadota, Ito & Kinoshita 2015, PLoS ONE), and
finger forces below this are within the position actuators' own error."""
_PRESSING_N = 0.2  # a finger pressing with less than this carries no share of the grip

# Flexion joints of each digit and the keypoint on each joint's axis (its lever to the tip).
_DIGIT_JOINTS = {
    "thumb": (
        ("thumb_cmc_flex", "thumb_cmc"),
        ("thumb_mcp_flex", "thumb_mcp"),
        ("thumb_ip_flex", "thumb_ip"),
    ),
    **{
        f: (
            (f"{f}_mcp_flex", f"{f}_mcp"),
            (f"{f}_pip_flex", f"{f}_pip"),
            (f"{f}_dip_flex", f"{f}_dip"),
        )
        for f in ("index", "middle", "ring", "little")
    },
}
_DIGIT_JOINT_INDICES = {
    d: np.array([JOINT_NAMES.index(j) for j, _ in joints]) for d, joints in _DIGIT_JOINTS.items()
}
_DIGIT_ALL_JOINTS = {
    d: np.array([i for i, name in enumerate(JOINT_NAMES) if name.startswith(f"{d}_")])
    for d in _DIGIT_JOINTS
}


# Rotations of the per-step path as (w, x, y, z) quaternions through MuJoCo's C functions
# (HandPose.quat_wxyz for a pose's): scipy's Rotation objects cost tens of microseconds each to
# make and combine.
def _rotvec_from_quat(quat: np.ndarray) -> np.ndarray:
    """(3,) rotation vector (angle in [0, pi]) of a unit wxyz quaternion."""
    rotvec = np.empty(3)
    mujoco.mju_quat2Vel(rotvec, quat, 1.0)
    return rotvec


def _quat_angle(quat_a: np.ndarray, quat_b: np.ndarray) -> float:
    """Angle of the rotation between two unit wxyz quaternions, radians in [0, pi]."""
    rotvec = np.empty(3)
    mujoco.mju_subQuat(rotvec, quat_a, quat_b)
    return math.sqrt(float(rotvec @ rotvec))


def _quat_slerp(quat_0: np.ndarray, quat_1: np.ndarray, s: float) -> np.ndarray:
    """Spherical interpolation from ``quat_0`` (s = 0) to ``quat_1`` (s = 1), the short way."""
    rotvec = np.empty(3)
    mujoco.mju_subQuat(rotvec, quat_1, quat_0)  # quat_0 * exp(rotvec) = quat_1
    quat = quat_0.copy()
    mujoco.mju_quatIntegrate(quat, rotvec, s)
    return quat


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:  # noqa: N803
    """(4,) wxyz quaternion of a (3, 3) rotation matrix."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(R, dtype=np.float64).reshape(9))
    return quat


def _median_rows(values: np.ndarray) -> np.ndarray:
    """Per-column median of an (n, k) array: ``np.median(values, axis=0)`` without its overhead."""
    n = len(values)
    ordered = np.sort(values, axis=0)
    if n % 2:
        return ordered[n // 2]
    return (ordered[n // 2 - 1] + ordered[n // 2]) / 2.0


def _robust_sigma(values: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Per-column spread of an (n, k) array about ``centre``: 1.4826 x the MAD.

    The standard deviation for Gaussian values, not moved by outliers.
    """
    return 1.4826 * _median_rows(np.abs(values - centre))


@dataclasses.dataclass
class _Segment:
    name: str
    duration_s: float
    pos: np.ndarray
    quat: np.ndarray  # (4,) wxyz, world_from_hand
    angles: np.ndarray


def _duration(
    pos0: np.ndarray,
    pos1: np.ndarray,
    quat0: np.ndarray,
    quat1: np.ndarray,
    speed_m_s: float,
    minimum_s: float,
) -> float:
    distance = float(np.linalg.norm(pos1 - pos0))
    angle = _quat_angle(quat1, quat0)
    # Minimum jerk peaks at 1.875 times the mean speed.
    return max(minimum_s, 1.875 * distance / speed_m_s, 1.875 * angle / _EXPERT_ANGULAR_SPEED_RAD_S)


_HULLS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _hull_points(points: np.ndarray) -> np.ndarray:
    """The points on the convex hull of ``points`` (all of them if the hull is degenerate).

    The lowest point of a posed object is a hull vertex (a linear function's minimum over a
    point set lies on its hull), so the filter's per-estimate test reads a few dozen points
    rather than the model's thousands. Cached per points array.
    """
    cached = _HULLS.get(id(points))
    if cached is not None and cached[0] is points:
        return cached[1]
    try:
        hull = points[np.sort(ConvexHull(points).vertices)]
    except (QhullError, ValueError):
        hull = points
    _HULLS[id(points)] = (points, hull)
    return hull


class _PoseFilter:
    """The object's pose from a stream of perceived poses, assuming it stays still.

    Position: the per-axis median of the estimates since the object last moved (at most
    :data:`_FILTER_WINDOW`), orientation: their chordal mean, so one bad estimate shifts the
    result by little. It has moved when the median of the last five estimates leaves the
    filtered position by more than :data:`_MOTION_MIN_M` or four times the spread expected of
    such a median; the window then restarts from those five. Estimates that put the object's
    lowest point within :data:`_SUPPORT_SNAP_M` of the table are first lowered or raised onto
    it (an object waiting to be grasped rests on the table).
    """

    def __init__(self, obj: YCBObject) -> None:
        self.points = _hull_points(np.asarray(obj.model_points_m))
        # The estimates since the object last moved: rows [start, end) of reused buffers.
        self._pos = np.empty((2 * _FILTER_WINDOW, 3))
        self._quat = np.empty((2 * _FILTER_WINDOW, 4))  # wxyz
        self._start = self._end = 0

    def __len__(self) -> int:
        return self._end - self._start

    def add(self, T: np.ndarray) -> None:
        R = T[:3, :3]  # noqa: N806
        pos = T[:3, 3].copy()
        lowest = float((self.points @ R[2]).min() + pos[2])
        if abs(lowest) < _SUPPORT_SNAP_M:
            pos[2] -= lowest
        if self._end == len(self._pos):  # full: move the window to the front
            n = len(self)
            self._pos[:n] = self._pos[self._start : self._end]
            self._quat[:n] = self._quat[self._start : self._end]
            self._start, self._end = 0, n
        self._pos[self._end] = pos
        self._quat[self._end] = _quat_from_matrix(R)
        self._end += 1
        if len(self) > _FILTER_WINDOW:
            self._start += 1
        if len(self) >= 10:
            window = self._pos[self._start : self._end - 5]
            centre = _median_rows(window)
            # Robust per-axis spread of the estimates (MAD), and that of a median of five.
            sigma = _robust_sigma(window, centre)
            recent = _median_rows(self._pos[self._end - 5 : self._end])
            gate = max(_MOTION_MIN_M, 4.0 * float(np.linalg.norm(sigma)) * 1.25 / np.sqrt(5))
            if np.linalg.norm(recent - centre) > gate:
                self._start = self._end - 5

    def spread_m(self) -> float:
        """Robust spread of the position estimates (norm of the per-axis MAD sigmas), metres.

        0 until ten estimates have come since the object last moved.
        """
        if len(self) < 10:
            return 0.0
        window = self._pos[self._start : self._end]
        return float(np.linalg.norm(_robust_sigma(window, _median_rows(window))))

    def pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = _median_rows(self._pos[self._start : self._end])
        # The chordal mean of the orientations: the principal eigenvector of sum(q q^T)
        # (Markley et al. 2007; scipy's Rotation.mean), whatever the quaternions' signs.
        quat = self._quat[self._start : self._end]
        _, vectors = np.linalg.eigh(quat.T @ quat)
        mean = np.empty(9)
        mujoco.mju_quat2Mat(mean, np.ascontiguousarray(vectors[:, -1]))
        T[:3, :3] = mean.reshape(3, 3)
        return T


def _close(T: np.ndarray, reference: np.ndarray) -> bool:
    """Within :data:`REPLAN_DISTANCE_M` and :data:`REPLAN_ANGLE_RAD` of ``reference``."""
    moved = float(np.linalg.norm(T[:3, 3] - reference[:3, 3]))
    if moved >= REPLAN_DISTANCE_M:
        return False
    turned = _quat_angle(_quat_from_matrix(T[:3, :3]), _quat_from_matrix(reference[:3, :3]))
    return turned < REPLAN_ANGLE_RAD


class GraspExpert(PoseActions):
    """A scripted pick-and-lift expert for one object.

    Phases (:attr:`phase`): ``"wait"`` (no grasp found yet for the perceived object pose: the
    hand stays where it is), ``"reach"`` (to 8 cm before the grasp, shaping the hand: peak
    speed 0.3 m/s), ``"approach"`` (the final 8 cm, peak 0.15 m/s), ``"close"`` (0.4 s: the
    digits close to the planned contact posture while an open hand that hovered sinks to the
    grasp), ``"squeeze"`` (0.3 s: the finger targets go past contact, so the position
    actuators press), ``"settle"`` (0.2 s: the grip eases to the force the object needs),
    ``"lift"`` (0.15 m up, peak speed the recipe's ``lift_speed_m_s``, 0.25 m/s but for the
    cracker box) and ``"hold"`` (until the episode ends).
    :attr:`grasp_type` is the grasp taxonomy type and ``plan.strategy`` how it is applied
    (:class:`GraspRecipe`).

    Closed loop: the plan is made at :meth:`reset` from the state's object pose and, with
    ``replan`` (the default), made again during the reach and the approach whenever the
    expert's estimate of the object's pose moves by :data:`REPLAN_DISTANCE_M` or
    :data:`REPLAN_ANGLE_RAD` (at most every 0.1 s). That estimate filters the perceived
    poses of every step (:class:`_PoseFilter`: a median while the object stays still, restarted
    when it moves), so an estimator's noise shrinks with time and one bad estimate is not
    fatal, while an object the hand pushes before it closes is followed. The motion toward a
    new plan starts from the pose the expert last commanded (the target never jumps); a small
    correction during the approach continues the approach, a larger one reaches again. Without
    a plan (no collision-free grasp for the perceived pose) the expert waits and tries again.

    :meth:`act` follows minimum-jerk segments in time, and waits (up to 1 s) at the end of the
    reach and of the approach until the state's wrist is within 2 cm of its target. It closes
    along a fixed schedule; contact needs no sensing because the position actuators stop at
    the object and press with their torque-limited stiffness.

    Grip force: from the end of the squeeze the expert regulates the grip to
    :data:`GRIP_SAFETY_FACTOR` times the slip force of the load (the weight, plus the lift's
    acceleration until the hold) at the hand-object friction ``friction``: the total normal
    force the state's touch sense reports (:attr:`GraspState.touch_forces_n`) is driven to it
    by scaling every digit's deflection from the measured contact posture (proprioception at
    the end of the squeeze) toward the squeeze targets, within :data:`MIN_GRIP_SCALE` and
    :data:`MAX_GRIP_SCALE`. A position actuator held off its target presses with ``kp *
    (target - angle)``, so the force follows the scale. The grip only tightens while lifting;
    in the hold it eases until the object has moved :data:`HOLD_SLIP_M` or turned
    :data:`HOLD_TURN_RAD` in the palm frame, and never again after that. The recipe's margins
    (:attr:`GraspRecipe.grip_margin`, :attr:`GraspRecipe.lift_grip_margin`) multiply the
    factor. Without touch (``touch_forces_n`` is ``None``) the scale comes once
    from a joint-torque force model (:meth:`grip_targets`).

    Args:
        obj: the object to grasp.
        hand_params: the hand that will grasp it.
        rng: optional generator; it jitters the segment speeds by up to 10 % (None: none).
        friction: the hand-object friction the grip is sized for (``None``:
            :data:`GRIP_FRICTION`, by default skin on the object's material).
        replan: re-plan from the filtered perceived object pose during the reach and the
            approach (``False``: the plan of :meth:`reset` only, which then raises
            :class:`GraspPlanningError` when it finds no grasp).
    """

    def __init__(
        self,
        obj: YCBObject,
        hand_params: HandParams,
        *,
        rng: np.random.Generator | None = None,
        friction: float | None = None,
        replan: bool = True,
    ) -> None:
        if not isinstance(obj, YCBObject):
            raise InvalidGraspState(
                f"obj must be a YCBObject (handsim.world.get_object); received {type(obj).__name__}"
            )
        if not isinstance(hand_params, HandParams):
            raise InvalidGraspState(
                f"hand_params must be a HandParams; received {type(hand_params).__name__}"
            )
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise InvalidGraspState(
                f"rng must be a numpy.random.Generator or None; received {type(rng).__name__}"
            )
        if friction is None:
            friction = GRIP_FRICTION if GRIP_FRICTION is not None else skin_friction(obj.name)
        if not (
            isinstance(friction, (int, float, np.floating))
            and not isinstance(friction, bool)
            and math.isfinite(friction)
            and friction > 0
        ):
            raise InvalidGraspState(f"friction must be a finite number > 0; received {friction!r}")
        self.obj = obj
        self.hand_params = hand_params
        self.rng = rng
        self.friction = float(friction)
        self.replan = bool(replan)
        # Position-actuator stiffness per joint (N m/rad; 0 where a joint has no actuator).
        checker = _checker(obj, hand_params)
        self._kp = np.zeros(len(JOINT_NAMES))
        self._kp[checker.binding.actuated] = checker.model.actuator_gainprm[
            checker.binding.actuator_ids, 0
        ]
        self._torque = np.full(len(JOINT_NAMES), np.inf)
        self._torque[checker.binding.actuated] = checker.model.actuator_forcerange[
            checker.binding.actuator_ids, 1
        ]
        self.recipe = grasp_recipe(obj)
        self.plan: GraspPlan | None = None
        self.planning_error: GraspPlanningError | None = None
        """The last planning failure (``None`` once a plan exists)."""
        self.replans = 0
        """Plans made after :meth:`reset` (closed loop)."""
        self.phase = "idle"
        self._segments: list[_Segment] = []
        self._index = 0
        self._segment_start_s = 0.0
        self._from: _Segment | None = None
        self._filter: _PoseFilter | None = None
        self._obstacles: tuple = ()
        self._planned_T: np.ndarray | None = None
        self._failed_T: np.ndarray | None = None
        self._last_plan_s = -math.inf
        self._commanded: _Segment | None = None
        self._scale = np.ones(3)  # speed jitter of reach, approach, lift
        self._grip: tuple[np.ndarray, np.ndarray] | None = None  # contact angles, squeeze
        self._grip_scale: list[float] = [1.0]
        self._groups: list[tuple[np.ndarray, np.ndarray, float]] = []
        self._grip_force_n: float | None = None
        self._hold_palm: list[np.ndarray] = []  # perceived object positions in the palm frame
        self._hold_ref: np.ndarray | None = None
        self._hold_slip_gate_m = HOLD_SLIP_M
        self._hold_turn_ref: np.ndarray | None = None  # object orientation in the palm frame
        self._eased: list[list[float]] = []  # grip scales of the last easing steps
        self._easing_stopped = False

    @property
    def grasp_type(self) -> str:
        """The grasp type (:data:`handsim.hand.pose_sources.GRASP_TYPES` key) of the recipe."""
        return self.plan.grasp_type if self.plan is not None else self.recipe.grasp_type

    def reset(self, state: GraspState) -> None:
        """Plan the grasp for the state's object pose and restart the phases.

        Raises:
            InvalidGraspState: if ``state`` is not a :class:`GraspState` of this object.
            GraspPlanningError: if no collision-free grasp exists and ``replan`` is off (with
                it, the expert waits in phase ``"wait"`` and plans again on later states).
        """
        self._check_state(state)
        scale = 1.0 if self.rng is None else float(self.rng.uniform(0.9, 1.1))
        self._scale = np.full(3, scale)
        hand = state.hand_pose
        self._commanded = _Segment(
            "start",
            0.0,
            hand.wrist_pos.copy(),
            hand.quat_wxyz,
            hand.angles.copy(),
        )
        self.plan = None
        self.planning_error = None
        self.replans = 0
        self._grip = None
        self._grip_force_n = None
        self._hold_palm = []
        self._hold_ref = None
        self._hold_turn_ref = None
        self._eased = []
        self._easing_stopped = False
        self._filter = _PoseFilter(self.obj)
        self._filter.add(state.T_world_from_obj)
        self._obstacles = state.obstacles
        self._planned_T = None
        self._failed_T = None
        self._segments = []
        self._index = 0
        self._from = self._commanded
        self._segment_start_s = state.time_s
        self.phase = "wait"
        T = state.T_world_from_obj if not self.replan else self._filter.pose()
        try:
            self._make_plan(T, state.time_s, "reach")
        except GraspPlanningError as err:
            if not self.replan:
                raise
            self.planning_error = err
            self._failed_T = T
        self.replans = 0

    def _plan(self, T: np.ndarray) -> GraspPlan:
        """A plan clear of the obstacles if one exists, else one that ignores them."""
        if self._obstacles:
            try:
                return plan_grasp(self.obj, T, self.hand_params, self._obstacles)
            except GraspPlanningError:
                pass
        return plan_grasp(self.obj, T, self.hand_params)

    def _make_plan(
        self, T: np.ndarray, time_s: float, first: str, plan: GraspPlan | None = None
    ) -> None:
        """Plan for object pose ``T`` (unless given) and lay out segments from the command."""
        self._last_plan_s = time_s
        plan = self._plan(T) if plan is None else plan
        self.plan = plan
        self.planning_error = None
        self._planned_T = T
        self.replans += 1
        start = self._commanded
        pre_pos = plan.approach_end - _PREGRASP_DIST_M * plan.approach_dir
        # A side wrap presses the palm onto the object while the digits close (a power grasp
        # holds the object against the palm).
        grasp_pos = plan.wrist_pos + (_PALM_PRESS_M if plan.strategy == "side" else 0.0) * (
            plan.approach_dir
        )
        lift_pos = grasp_pos + np.array([0.0, 0.0, _LIFT_TARGET_M])
        quat = plan.rotation.as_quat(scalar_first=True)
        segments = [
            *_reach_from_behind(self.obj, self.recipe, plan, T, start, pre_pos, quat),
            _Segment("reach", 0.0, pre_pos, quat, plan.preshape),
            _Segment("approach", 0.0, plan.approach_end, quat, plan.preshape),
            _Segment("close", _CLOSE_S, grasp_pos, quat, plan.contact),
            _Segment("squeeze", _SQUEEZE_S, grasp_pos, quat, plan.closed),
            _Segment("settle", _SETTLE_S, grasp_pos, quat, plan.closed),
            _Segment("lift", 0.0, lift_pos, quat, plan.closed),
        ]
        if first == "approach":
            segments = segments[-6:]
        previous = start
        for segment in segments:
            if segment.duration_s == 0.0:
                speed, jitter = {
                    "reach": (EXPERT_WRIST_SPEED_M_S, self._scale[0]),
                    "lift": (self.recipe.lift_speed_m_s, self._scale[2]),
                }.get(segment.name, (_SLOW_SPEED_M_S, self._scale[1]))
                segment.duration_s = jitter * _duration(
                    previous.pos, segment.pos, previous.quat, segment.quat, speed, 0.4
                )
            previous = segment
        self._segments = segments
        self._from = start
        self._index = 0
        self._segment_start_s = time_s
        self.phase = segments[0].name

    def _maybe_replan(self, state: GraspState) -> None:
        """Closed loop: plan again if the filtered object pose moved (reach, approach, wait)."""
        self._obstacles = state.obstacles
        if not self.replan or self.phase not in ("wait", "reach", "approach"):
            # The filtered pose serves re-planning only, which never comes back once the
            # digits close (or without replan): it stops taking estimates.
            return
        self._filter.add(state.T_world_from_obj)
        t = state.time_s
        if t - self._last_plan_s < _REPLAN_PERIOD_S - 1e-9:
            return
        T = self._filter.pose()
        for reference in (self._planned_T, self._failed_T):
            if reference is not None and _close(T, reference):
                return
        first = "reach"
        if self.phase == "approach" and self.plan is not None:
            old = self.plan
        try:
            plan = self._plan(T)
        except GraspPlanningError as err:
            self._last_plan_s = t
            self._failed_T = T
            if self.plan is None:
                self.planning_error = err
            return  # keep the current plan; try again when the estimate moves
        if self.phase == "approach" and self.plan is not None:
            # Continue the approach if the new approach line passes near the hand and the
            # orientation barely changes; else reach again (back out to the new pre-grasp).
            here = self._commanded.pos
            a = plan.approach_end - _PREGRASP_DIST_M * plan.approach_dir
            d = plan.approach_dir
            along = float(np.clip((here - a) @ d, 0.0, _PREGRASP_DIST_M))
            off_line = float(np.linalg.norm(here - (a + along * d)))
            turn = _quat_angle(
                plan.rotation.as_quat(scalar_first=True), old.rotation.as_quat(scalar_first=True)
            )
            if off_line < 0.01 and turn < np.deg2rad(10.0) and plan.strategy == old.strategy:
                first = "approach"
        self._make_plan(T, t, first, plan)

    def grip_targets(self, state: GraspState) -> np.ndarray:
        """Finger targets that press on the object with a grip force sized to its weight.

        The force model used when the state has no touch sense (:attr:`GraspState.
        touch_forces_n` is ``None``). Called when the squeeze has pressed the digits onto the
        object. A position actuator held off its target presses with ``kp * (target - angle)``
        (up to its torque limit), so the joint deflections give each digit's force (torque
        over the lever from the joint's keypoint to the tip; the median over its flexion
        joints). The grip force aimed at is :data:`GRIP_SAFETY_FACTOR` times what the weight
        and the lift acceleration need at the expert's friction: half on the thumb, half
        shared by the pressing fingers. Each digit's deflections are scaled down to that force
        (never up: the squeeze is the most the expert presses; never below 0.2 of them, as the
        model leaves out the palm and the proximal segments).

        Args:
            state: the state at the end of the squeeze.

        Returns:
            (21,) joint targets, radians.
        """
        # Proprioception, not the (possibly estimated) pose: the deflections set the force.
        measured = state.joint_angles_rad
        squeeze = self.plan.closed
        grip_n = self._grip_force_target(lifting=True)
        keypoints = state.keypoints_world
        forces = {}
        for digit, joints in _DIGIT_JOINTS.items():
            tip = keypoints[KEYPOINT_NAMES.index(f"{digit}_tip")]
            estimates = []
            for joint, keypoint in joints:
                j = JOINT_NAMES.index(joint)
                lever = float(np.linalg.norm(tip - keypoints[KEYPOINT_NAMES.index(keypoint)]))
                torque = min(self._kp[j] * abs(squeeze[j] - measured[j]), self._torque[j])
                estimates.append(torque / max(lever, 1e-3))
            forces[digit] = float(np.median(estimates))
        fingers = [d for d in _DIGIT_JOINTS if d != "thumb" and forces[d] > _PRESSING_N]
        targets = squeeze.copy()
        for digit, force_n in forces.items():
            wanted = 0.5 * grip_n / (1 if digit == "thumb" else max(len(fingers), 1))
            scale = float(np.clip(wanted / max(force_n, 1e-6), 0.2, 1.0))
            joints = _DIGIT_ALL_JOINTS[digit]
            targets[joints] = measured[joints] + scale * (squeeze[joints] - measured[joints])
        return np.clip(targets, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])

    def _grip_force_target(self, lifting: bool) -> float:
        """Total normal force aimed at, newtons: safety factor x load / friction.

        The factor is :data:`GRIP_SAFETY_FACTOR` times the recipe's ``grip_margin``, and times
        its ``lift_grip_margin`` while settling and lifting.
        """
        accel = 9.81 + (LIFT_ACCELERATION_M_S2 if lifting else 0.0)
        factor = GRIP_SAFETY_FACTOR * self.recipe.grip_margin
        if lifting:
            factor *= self.recipe.lift_grip_margin
        grip_n = factor * self.obj.mass_kg * accel / self.friction
        return max(grip_n, MIN_GRIP_FORCE_N)

    def _slipping(self, state: GraspState) -> bool:
        """Has the object slipped in the palm frame since the hold began?

        Slipped: moved :data:`HOLD_SLIP_M` or turned :data:`HOLD_TURN_RAD`.
        """
        hand = state.hand_pose
        quat = np.empty(4)
        mujoco.mju_negQuat(quat, hand.quat_wxyz)  # world -> palm
        in_palm = np.empty(3)
        mujoco.mju_rotVecQuat(in_palm, state.T_world_from_obj[:3, 3] - hand.wrist_pos, quat)
        palm = np.empty(9)
        mujoco.mju_quat2Mat(palm, hand.quat_wxyz)
        turn = palm.reshape(3, 3).T @ state.T_world_from_obj[:3, :3]
        if self._hold_turn_ref is None:
            self._hold_turn_ref = turn
        cos = (np.trace(self._hold_turn_ref.T @ turn) - 1.0) / 2.0
        if math.acos(min(max(cos, -1.0), 1.0)) > HOLD_TURN_RAD:
            return True
        self._hold_palm = [*self._hold_palm[1 - _SLIP_WINDOW :], in_palm]
        if len(self._hold_palm) < _SLIP_WINDOW:
            return False
        recent = np.median(np.stack(self._hold_palm), axis=0)
        if self._hold_ref is None:
            self._hold_ref = recent
            # Perception noise must not read as slip: the gate is four times the spread of
            # the difference of two medians of five estimates (1.25 sigma / sqrt(5) each),
            # sigma the estimates' spread while the object stood still before the grasp.
            median_sigma_m = 1.25 * self._filter.spread_m() / np.sqrt(_SLIP_WINDOW)
            self._hold_slip_gate_m = max(HOLD_SLIP_M, 4.0 * np.sqrt(2.0) * median_sigma_m)
            return False
        return bool(np.linalg.norm(recent - self._hold_ref) > self._hold_slip_gate_m)

    def _grip_groups(self) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """(joint indices, touch parts, share of the grip force) of each regulated group.

        A side wrap presses the object against the palm with every digit: one group, the
        whole hand's force. Other grasps oppose the thumb to the fingers: the thumb and the
        fingers each press with half of it, so the object is not pushed sideways.
        """
        if self.plan.strategy == "side":
            return [(np.arange(len(JOINT_NAMES)), np.arange(len(TOUCH_PARTS)), 1.0)]
        fingers = np.concatenate([_DIGIT_ALL_JOINTS[f] for f in TOUCH_PARTS[2:]])
        return [
            (_DIGIT_ALL_JOINTS["thumb"], np.array([1]), 0.5),
            (fingers, np.arange(2, len(TOUCH_PARTS)), 0.5),
        ]

    def _regulated_angles(self, state: GraspState) -> np.ndarray:
        """Finger targets of the grip-force loop (touch + proprioception), one control step."""
        contact, squeeze = self._grip
        touch = state.touch_forces_n
        # The settle eases to the first scales; the loop regulates from the lift on.
        if touch is not None and self.phase != "settle":
            # One correction for every group: once lifted, the thumb and the fingers press
            # on each other through the object, so only their common level is controllable.
            wanted = self._grip_force_target(lifting=self.phase != "hold")
            force = float(touch.sum())
            # While the load grows (the lift) the grip only tightens; it eases in the hold,
            # until the object starts to slip.
            if self.phase == "hold" and not self._easing_stopped and self._slipping(state):
                self._easing_stopped = True
            ease = 1.0 if self.phase == "lift" or self._easing_stopped else _GRIP_EASE
            ratio = float(np.clip((wanted / max(force, 1e-3)) ** _GRIP_RATE, ease, _GRIP_TIGHTEN))
            if ratio < 1.0:
                self._eased = [*self._eased[-2:], list(self._grip_scale)]
            self._grip_scale = [
                float(np.clip(k * ratio, self.recipe.min_grip_scale, MAX_GRIP_SCALE))
                for k in self._grip_scale
            ]
            self._grip_force_n = force
        scale = np.ones(len(JOINT_NAMES))
        for k, (joints, _, _) in enumerate(self._groups):
            scale[joints] = self._grip_scale[k]
        targets = contact + scale * (squeeze - contact)
        return np.clip(targets, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])

    def _start_grip(self, state: GraspState) -> None:
        """End of the squeeze: the measured contact posture, and the first grip scales."""
        contact = state.joint_angles_rad.copy()
        squeeze = self.plan.closed
        self._grip = (contact, squeeze)
        touch = state.touch_forces_n
        groups = self._groups = self._grip_groups()  # fixed from here: the plan no longer changes
        if touch is not None:
            wanted = self._grip_force_target(lifting=True)
            self._grip_scale = [
                float(
                    np.clip(
                        share * wanted / max(touch[parts].sum(), 1e-3),
                        self.recipe.min_grip_scale,
                        1.0,
                    )
                )
                if touch[parts].sum() > 1e-3
                else 1.0
                for _, parts, share in groups
            ]
        else:
            # No touch: one scale from the force model, kept.
            grip = self.grip_targets(state)
            deflection = squeeze - contact
            moving = np.abs(deflection) > 1e-6
            scale = (
                float(np.median((grip - contact)[moving] / deflection[moving]))
                if moving.any()
                else 1.0
            )
            self._grip_scale = [scale] * len(groups)

    def _check_state(self, state: GraspState) -> None:
        if not isinstance(state, GraspState):
            raise InvalidGraspState(f"state must be a GraspState; received {type(state).__name__}")
        if state.obj.name != self.obj.name:
            raise InvalidGraspState(
                f"the state's object is {state.obj.name!r} but this expert grasps "
                f"{self.obj.name!r}; make one GraspExpert per object"
            )

    def act(self, state: GraspState) -> HandPose:
        """The absolute target pose for this control step.

        Args:
            state: the current state (same object as at :meth:`reset`).

        Returns:
            The 27-DoF target (world frame), for ``HandBinding.set_target``.

        Raises:
            InvalidGraspState: if called before :meth:`reset` or with a bad state.
        """
        if self._filter is None:
            raise InvalidGraspState("call reset(state) before act(state)")
        self._check_state(state)
        self._maybe_replan(state)
        pose = self._follow(state)
        self._commanded = _Segment(
            "commanded", 0.0, pose.wrist_pos, self._commanded_quat, pose.angles
        )
        return pose

    def _follow(self, state: GraspState) -> HandPose:
        t = state.time_s
        if self.plan is None:
            self.phase = "wait"
            here = self._commanded
            self._commanded_quat = here.quat
            return HandPose(here.pos, _rotvec_from_quat(here.quat), here.angles)
        while self._index < len(self._segments):
            segment = self._segments[self._index]
            elapsed = t - self._segment_start_s
            if elapsed < segment.duration_s:
                break
            # Wait at the end of a motion until the wrist has (nearly) arrived.
            if segment.name in ("reach", "approach"):
                error = np.linalg.norm(state.hand_pose.wrist_pos - segment.pos)
                if error > 0.02 and elapsed < segment.duration_s + 1.0:
                    break
            self._from = segment
            self._index += 1
            self._segment_start_s = t
            if segment.name == "squeeze":
                # The digits press on the object: from now on, regulate the grip force.
                self._start_grip(state)
        if self._index >= len(self._segments):
            self.phase = "hold"
            last = self._segments[-1]
            self._commanded_quat = last.quat
            return HandPose(last.pos, _rotvec_from_quat(last.quat), self._regulated_angles(state))
        segment = self._segments[self._index]
        self.phase = segment.name
        tau = (t - self._segment_start_s) / max(segment.duration_s, 1e-9)
        # minimum_jerk on one number, in Python floats (the same operations, bit for bit).
        t = min(max(tau, 0.0), 1.0)
        s = min(max(t**3 * (10.0 + t * (-15.0 + 6.0 * t)), 0.0), 1.0)
        start = self._from
        pos = start.pos + s * (segment.pos - start.pos)
        quat = _quat_slerp(start.quat, segment.quat, s)
        self._commanded_quat = quat
        if self._grip is not None:
            angles = self._regulated_angles(state)
            if segment.name == "settle":
                # Ease from the squeeze to the regulated grip (the target never jumps).
                angles = start.angles + s * (angles - start.angles)
        else:
            angles = start.angles + s * (segment.angles - start.angles)
        return HandPose(pos, _rotvec_from_quat(quat), angles)


# Success --------------------------------------------------------------------------------------

FailureReason = Literal["not_lifted", "dropped", "slipped", "turned", "hold_incomplete", "diverged"]


@dataclasses.dataclass(frozen=True)
class GraspOutcome:
    """The result of a pick-and-lift episode.

    Attributes:
        success: lifted by :data:`LIFT_HEIGHT_M` and held :data:`HOLD_DURATION_S` with less
            than :data:`MAX_SLIP_M` slip and :data:`MAX_TURN_RAD` turn in the palm frame.
        failure: why it failed (``None`` on success): ``"not_lifted"`` (never reached the lift
            height), ``"dropped"`` (lifted, but below the lift height at the end),
            ``"slipped"`` / ``"turned"`` (still lifted at the end, but its hold window ended
            when the object had moved :data:`MAX_SLIP_M` or turned :data:`MAX_TURN_RAD` or
            more in the palm frame; slip is checked first), ``"hold_incomplete"`` (still lifted
            and within both limits, held for less than the hold duration), ``"diverged"``
            (physics).
        max_lift_m: highest rise of the object origin above its rest height, metres.
        slip_m: on success the largest slip of the successful window; otherwise the largest
            slip of any window, metres.
        turn_rad: the same for the turn (rotation angle of the object in the palm frame),
            radians.
        hold_s: duration of the last hold window, seconds.
        success_time_s: episode time at which the hold completed (``None`` on failure).
        steps: control steps run.
    """

    success: bool
    failure: FailureReason | None
    max_lift_m: float
    slip_m: float
    turn_rad: float
    hold_s: float
    success_time_s: float | None
    steps: int

    def to_dict(self) -> dict[str, object]:
        """A JSON-serializable dict of the fields."""
        return dataclasses.asdict(self)


def _rotation_angle_rad(R: np.ndarray) -> float:  # noqa: N803
    """The angle of a rotation matrix, radians in [0, pi].

    ``atan2(sin, cos)`` from the skew part and the trace: accurate at small angles, where
    ``arccos((trace - 1) / 2)`` loses half the digits.

    Args:
        R: (3, 3) rotation matrix.
    """
    sin = 0.5 * math.sqrt(
        (R[2, 1] - R[1, 2]) ** 2 + (R[0, 2] - R[2, 0]) ** 2 + (R[1, 0] - R[0, 1]) ** 2
    )
    cos = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    return math.atan2(sin, cos)


class LiftTracker:
    """Per-step evaluation of the lift success definition (module docstring).

    Feed every control step with :meth:`update`; :attr:`success` turns true once an object has
    been held lifted for :data:`HOLD_DURATION_S` with slip below :data:`MAX_SLIP_M` and turn
    below :data:`MAX_TURN_RAD`, and stays true. :meth:`outcome` summarizes the episode so far.

    The hold window opens at the first step at which the object is lifted; the object's pose
    in the palm frame at that step is the reference of the whole window. A window that reaches
    either limit ends the hold: no new window opens until the object has been below the lift
    height again (a reference taken while the object still slides would hide the slip).

    Args:
        rest_height_m: height of the object origin at rest (episode start), metres.
        lift_height_m: the lift threshold (default :data:`LIFT_HEIGHT_M`).
        hold_s: the hold duration (default :data:`HOLD_DURATION_S`).
        max_slip_m: the slip threshold (default :data:`MAX_SLIP_M`).
        max_turn_rad: the turn threshold (default :data:`MAX_TURN_RAD`).
    """

    def __init__(
        self,
        rest_height_m: float,
        *,
        lift_height_m: float = LIFT_HEIGHT_M,
        hold_s: float = HOLD_DURATION_S,
        max_slip_m: float = MAX_SLIP_M,
        max_turn_rad: float = MAX_TURN_RAD,
    ) -> None:
        for name, value in (
            ("rest_height_m", rest_height_m),
            ("lift_height_m", lift_height_m),
            ("hold_s", hold_s),
            ("max_slip_m", max_slip_m),
            ("max_turn_rad", max_turn_rad),
        ):
            if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value)):
                raise InvalidGraspState(f"{name} must be a finite number; received {value!r}")
        if lift_height_m <= 0 or hold_s <= 0 or max_slip_m <= 0 or max_turn_rad <= 0:
            raise InvalidGraspState(
                "lift_height_m, hold_s, max_slip_m and max_turn_rad must be > 0; received "
                f"{lift_height_m}, {hold_s}, {max_slip_m}, {max_turn_rad}"
            )
        self.rest_height_m = float(rest_height_m)
        self.lift_height_m = float(lift_height_m)
        self.hold_s = float(hold_s)
        self.max_slip_m = float(max_slip_m)
        self.max_turn_rad = float(max_turn_rad)
        self.success = False
        self.success_time_s: float | None = None
        self.max_lift_m = -math.inf
        self.steps = 0
        self._window_start_s: float | None = None
        self._window_pos_palm: np.ndarray | None = None
        self._window_R_palm: np.ndarray | None = None
        self._window_slip_m = 0.0
        self._window_turn_rad = 0.0
        self._last_time_s = -math.inf
        self._ever_lifted = False
        self._broken: FailureReason | None = None
        # Set when a window reached a limit; cleared once the object is below the lift height.
        self._hold_ended = False
        self._break_slip_m = 0.0
        self._break_turn_rad = 0.0
        self._window_duration_s = 0.0

    def update(
        self, time_s: float, T_world_from_obj: np.ndarray, T_world_from_palm: np.ndarray
    ) -> bool:
        """Add one step.

        Args:
            time_s: episode time, seconds (increasing).
            T_world_from_obj: (4, 4) pose of the object body (its origin), world frame.
            T_world_from_palm: (4, 4) pose of the palm (hand root) body, world frame.

        Returns:
            :attr:`success` after this step.

        Raises:
            InvalidGraspState: for non-increasing time or malformed arrays.
        """
        self._check_time(time_s)
        obj = _check_transform(T_world_from_obj, "T_world_from_obj")
        palm = _check_transform(T_world_from_palm, "T_world_from_palm")
        return self._update(time_s, obj[:3, :3], obj[:3, 3], palm[:3, :3], palm[:3, 3])

    def _check_time(self, time_s: float) -> None:
        if not time_s > self._last_time_s:
            raise InvalidGraspState(
                f"time_s must increase from step to step; received {time_s} after "
                f"{self._last_time_s}"
            )

    def _update(
        self,
        time_s: float,
        R_world_from_obj: np.ndarray,  # noqa: N803
        pos: np.ndarray,
        R_world_from_palm: np.ndarray,  # noqa: N803
        palm_pos: np.ndarray,
    ) -> bool:
        """:meth:`update` on checked arrays."""
        self._last_time_s = float(time_s)
        self.steps += 1
        if self.success:
            return True
        lift = float(pos[2] - self.rest_height_m)
        self.max_lift_m = max(self.max_lift_m, lift)
        if lift < self.lift_height_m:
            if self._window_start_s is not None:
                self._broken = "dropped"
            self._close_window()
            self._hold_ended = False
            return False
        self._ever_lifted = True
        if self._hold_ended:
            return False
        pos_palm = R_world_from_palm.T @ (pos - palm_pos)
        R_palm_from_obj = R_world_from_palm.T @ R_world_from_obj  # noqa: N806
        if self._window_start_s is None:
            self._open_window(time_s, pos_palm, R_palm_from_obj)
            return False
        slip = float(np.linalg.norm(pos_palm - self._window_pos_palm))
        turn = _rotation_angle_rad(self._window_R_palm.T @ R_palm_from_obj)
        self._window_slip_m = max(self._window_slip_m, slip)
        self._window_turn_rad = max(self._window_turn_rad, turn)
        if slip >= self.max_slip_m or turn >= self.max_turn_rad:
            self._broken = "slipped" if slip >= self.max_slip_m else "turned"
            self._break_slip_m = max(self._break_slip_m, self._window_slip_m)
            self._break_turn_rad = max(self._break_turn_rad, self._window_turn_rad)
            self._window_duration_s = time_s - self._window_start_s
            self._close_window()
            self._hold_ended = True
            return False
        self._window_duration_s = time_s - self._window_start_s
        # A small tolerance absorbs float round-off in time stamps (k * dt).
        if self._window_duration_s >= self.hold_s - 1e-9:
            self.success = True
            self.success_time_s = float(time_s)
        return self.success

    def _open_window(self, time_s: float, pos_palm: np.ndarray, R_palm: np.ndarray) -> None:  # noqa: N803
        self._window_start_s = float(time_s)
        self._window_pos_palm = pos_palm
        self._window_R_palm = R_palm
        self._window_slip_m = 0.0
        self._window_turn_rad = 0.0
        self._window_duration_s = 0.0

    def _close_window(self) -> None:
        self._window_start_s = None
        self._window_pos_palm = None
        self._window_R_palm = None

    def update_from_sim(self, scene: Scene, instance: int, time_s: float) -> bool:
        """:meth:`update` with the ground truth of ``scene`` (object ``instance``)."""
        body_id = _object_body_id(scene, instance)
        palm_id = int(scene.model.body(scene.hand.root_body).id)
        data = scene.data
        self._check_time(time_s)
        pos, palm_pos = data.xpos[body_id], data.xpos[palm_id]
        R_obj = data.xmat[body_id].reshape(3, 3)  # noqa: N806
        R = data.xmat[palm_id].reshape(3, 3)  # noqa: N806
        # MuJoCo's xmat is a rotation; only a diverged state could be non-finite.
        finite = np.isfinite(pos).all() and np.isfinite(palm_pos).all()
        if not (finite and np.isfinite(R).all() and np.isfinite(R_obj).all()):
            raise InvalidGraspState(
                f"the scene's object or palm pose is not finite (object at {pos}); the physics "
                "diverged"
            )
        return self._update(time_s, R_obj.copy(), pos.copy(), R.copy(), palm_pos.copy())

    def outcome(self, diverged: bool = False) -> GraspOutcome:
        """The outcome of the episode so far (call at its end).

        Args:
            diverged: the physics diverged (the episode was cut short).
        """
        failure: FailureReason | None
        if self.success:
            failure = None
        elif diverged:
            failure = "diverged"
        elif not self._ever_lifted:
            failure = "not_lifted"
        elif self._hold_ended:
            failure = self._broken  # still lifted after the window reached a limit
        elif self._window_start_s is None:
            failure = "dropped"
        else:
            failure = "hold_incomplete"
        return GraspOutcome(
            success=self.success,
            failure=failure,
            max_lift_m=float(self.max_lift_m) if self.steps else 0.0,
            slip_m=float(
                self._window_slip_m
                if self.success
                else max(self._window_slip_m, self._break_slip_m)
            ),
            turn_rad=float(
                self._window_turn_rad
                if self.success
                else max(self._window_turn_rad, self._break_turn_rad)
            ),
            hold_s=float(self._window_duration_s),
            success_time_s=self.success_time_s,
            steps=self.steps,
        )


def evaluate_lift(
    times_s: np.ndarray,
    T_world_from_obj: np.ndarray,
    T_world_from_palm: np.ndarray,
    rest_height_m: float,
) -> GraspOutcome:
    """Evaluate a recorded trajectory against the success definition.

    Args:
        times_s: (T,) increasing episode times, seconds.
        T_world_from_obj: (T, 4, 4) object poses (the body origin), world frame.
        T_world_from_palm: (T, 4, 4) palm poses, world frame.
        rest_height_m: height of the object origin at rest, metres.

    Returns:
        The outcome, as :class:`LiftTracker` would give after the last step.

    Raises:
        InvalidGraspState: for mismatched shapes or non-increasing times.
    """
    times = np.asarray(times_s, dtype=np.float64)
    obj = np.asarray(T_world_from_obj, dtype=np.float64)
    palm = np.asarray(T_world_from_palm, dtype=np.float64)
    if times.ndim != 1 or obj.shape != (len(times), 4, 4) or palm.shape != (len(times), 4, 4):
        raise InvalidGraspState(
            "expected times_s (T,), T_world_from_obj (T, 4, 4) and T_world_from_palm "
            f"(T, 4, 4); received {times.shape}, {obj.shape}, {palm.shape}"
        )
    tracker = LiftTracker(rest_height_m)
    for t, T_obj, T_palm in zip(times, obj, palm, strict=True):
        tracker.update(float(t), T_obj, T_palm)
    return tracker.outcome()


# Episodes -------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class ContactMetrics:
    """How the hand touches the target object and the table at one instant.

    Attributes:
        object_depth_m: deepest hand-object penetration (MuJoCo contact ``dist < 0``), metres;
            0 without penetration.
        table_depth_m: deepest hand-table penetration, metres.
        normal_force_n: total normal force of the hand-object contacts, newtons.
        deepest_geom: name of the hand geom of the deepest hand-object contact ("" if none).
    """

    object_depth_m: float
    table_depth_m: float
    normal_force_n: float
    deepest_geom: str


def contact_metrics(scene: Scene, instance: int) -> ContactMetrics:
    """Penetration and grip force of the hand on object ``instance`` (after ``mj_forward``).

    Raises:
        InvalidGraspState: for a scene without a hand or a bad instance.
    """
    body_id = _object_body_id(scene, instance)
    model, data = scene.model, scene.data
    n = data.ncon
    if n == 0:
        return ContactMetrics(0.0, 0.0, 0.0, "")
    root = model.body(scene.hand.root_body).id
    hand = model.body_rootid == root
    contact = data.contact
    g1, g2 = contact.geom1[:n], contact.geom2[:n]
    b1, b2 = model.geom_bodyid[g1], model.geom_bodyid[g2]
    h1, h2 = hand[b1], hand[b2]
    on_object = (h1 & (b2 == body_id)) | (h2 & (b1 == body_id))
    table = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "table")  # -1 without a table
    on_table = (h1 & (g2 == table)) | (h2 & (g1 == table))
    dist = contact.dist[:n]
    object_depth = float(max(0.0, -dist[on_object].min())) if on_object.any() else 0.0
    table_depth = float(max(0.0, -dist[on_table].min())) if on_table.any() else 0.0
    force, wrench = 0.0, np.zeros(6)
    for i in np.nonzero(on_object)[0]:
        mujoco.mj_contactForce(model, data, int(i), wrench)
        force += float(wrench[0])
    deepest = ""
    if on_object.any():
        i = np.nonzero(on_object)[0][np.argmin(dist[on_object])]
        deepest = model.geom(int(g1[i] if h1[i] else g2[i])).name
    return ContactMetrics(object_depth, table_depth, force, deepest)


def _reach_from_behind(
    obj: YCBObject,
    recipe: GraspRecipe,
    plan: GraspPlan,
    T: np.ndarray,
    start: _Segment,
    pre_pos: np.ndarray,
    quat: np.ndarray,
) -> list[_Segment]:
    """A reach waypoint for wraps approached along the object's own axis (the drill's grip).

    Their pre-grasp can lie beyond the object as the user sees it; a straight reach from the
    start pose swept the hand through it. The hand first goes 5 cm above the object's top and
    6 cm behind the pre-grasp, then comes down and forward to it, turning the wrist in
    proportion to the distance on both legs. (Only where the straight reach crossed the
    object's footprint: the medium right hand dropped from 19 to 16 of 20, seeds 0-19.)
    """
    if recipe.approach_obj is None or plan.strategy != "side":
        return []
    top = float(np.max(np.asarray(obj.model_points_m) @ T[2, :3] + T[2, 3]))
    via = pre_pos - _VIA_BACK_M * plan.approach_dir
    via[2] = top + _VIA_CLEARANCE_M
    first = float(np.linalg.norm(via - start.pos))
    fraction = first / max(first + float(np.linalg.norm(pre_pos - via)), 1e-9)
    return [_Segment("reach", 0.0, via, _quat_slerp(start.quat, quat, fraction), plan.preshape)]


def run_episode(
    scene: Scene,
    instance: int,
    expert: GraspExpert,
    rng: np.random.Generator,
    max_steps: int = 400,
    *,
    stop_on_success: bool = True,
    on_step: Callable[[int, GraspExpert], None] | None = None,
    perceive: Callable[[GraspState], GraspState] | None = None,
) -> GraspOutcome:
    """Run one ground-truth pick-and-lift episode.

    Resets ``scene`` (objects at their placements, the hand at :func:`start_pose`), then per
    control step: state -> ``expert.act`` -> ``set_target`` -> :data:`FRAME_SKIP` physics steps
    -> success tracking. As in ``handsim/Grasp-v0``, the episode ends when the object has
    fallen off the table (its origin below :data:`FALL_HEIGHT_M`).

    Args:
        scene: a scene with a hand and the target object.
        instance: index of the target in ``scene.objects``.
        expert: a :class:`GraspExpert` for that object.
        rng: random generator of the start pose.
        max_steps: control steps at most (400 = 8 s).
        stop_on_success: end the episode as soon as the hold succeeds.
        on_step: called after every control step with its index and the expert (whose
            ``phase`` says where the episode is); for measurements such as
            :func:`contact_metrics`.
        perceive: turns each ground-truth state into the one the expert acts on (e.g. a
            noisy object pose, as an estimator would give); ``None``: the truth.

    Returns:
        The outcome.

    Raises:
        InvalidGraspState: for a bad instance, expert or ``max_steps``.
        GraspPlanningError: if the expert finds no grasp at the start and does not re-plan.
    """
    body_id = _object_body_id(scene, instance)
    if not isinstance(expert, GraspExpert):
        raise InvalidGraspState(f"expert must be a GraspExpert; received {type(expert).__name__}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise InvalidGraspState(f"max_steps must be an int >= 1; received {max_steps!r}")
    obj = scene.objects[instance][1]
    if expert.obj.name != obj.name:
        raise InvalidGraspState(
            f"the expert grasps {expert.obj.name!r} but scene object {instance} is {obj.name!r}"
        )
    data = scene.data
    scene.reset()
    T0 = GraspState.from_sim(scene, instance, 0.0).T_world_from_obj
    scene.reset(start_pose(rng, T0, scene.hand.params, obj=obj))
    tracker = LiftTracker(float(data.xpos[body_id][2]))
    perceived = perceive if perceive is not None else (lambda state: state)
    state = perceived(GraspState.from_sim(scene, instance, 0.0))
    expert.reset(state)
    diverged = False
    # The env's driver: same mocap tracking and stepping as handsim/Grasp-v0.
    driver = HandDriver(scene)
    for step in range(int(max_steps)):
        driver.set_target(expert.act(state))
        if driver.step(FRAME_SKIP):
            diverged = True
            break
        time_s = (step + 1) * CONTROL_DT_S
        success = tracker.update_from_sim(scene, instance, time_s)
        if on_step is not None:
            on_step(step, expert)
        if success and stop_on_success:
            break
        if data.xpos[body_id][2] < FALL_HEIGHT_M:
            break  # fallen off the table (falling on, it would pass the divergence speed)
        state = perceived(GraspState.from_sim(scene, instance, time_s))
    return tracker.outcome(diverged=diverged)
