"""Grasp execution: the expert that follows a plan and regulates its grip.

:class:`GraspExpert` follows a plan (its phases) and regulates the grip force from touch. Its
score (:class:`LiftTracker`, :mod:`.success`) and the ground-truth episode loop
(:func:`run_episode`, :mod:`.episode`) live apart and are importable from here too.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from handsim.envs.experts import PoseActions
from handsim.envs.grasping.perception import (
    _PoseFilter,
    _quat_angle,
    _quat_from_matrix,
    _quat_slerp,
    _rotvec_from_quat,
)
from handsim.envs.grasping.planning import (
    _CLOSE_S,
    _EXPERT_ANGULAR_SPEED_RAD_S,
    _LIFT_TARGET_M,
    _PREGRASP_DIST_M,
    _SETTLE_S,
    _SLOW_SPEED_M_S,
    _SQUEEZE_S,
    EXPERT_WRIST_SPEED_M_S,
    TOUCH_PARTS,
    GraspPlan,
    GraspPlanningError,
    GraspRecipe,
    GraspState,
    InvalidGraspState,
    _checker,
    grasp_recipe,
    plan_grasp,
)
from handsim.envs.grasping.success import (
    FailureReason,
    GraspOutcome,
    LiftTracker,
    evaluate_lift,
)
from handsim.envs.physics import skin_friction
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_LIMITS, JOINT_NAMES, HandPose
from handsim.world.objects import YCBObject

# ContactMetrics, contact_metrics and run_episode resolve through __getattr__ (at the end).
__all__ = [
    "GraspExpert",
    "FailureReason",
    "GraspOutcome",
    "LiftTracker",
    "evaluate_lift",
]

# The expert -----------------------------------------------------------------------------------

GRIP_SAFETY_FACTOR = 1.6
"""Grip force over the force that just prevents slip. People grip with 1.3 to 3 times the slip
force and scale it with the load (grip-load coupling; Johansson & Westling 1984, Exp. Brain
Res. 56:550-564); the expert aims at 1.6."""
GRIP_FRICTION: float | None = None
"""Hand-object friction the expert assumes when sizing its grip force; ``None``: skin on the
object's material (:func:`handsim.envs.base.skin_friction`), as a person judges a surface."""
GRIP_REFLEX_FACTOR = GRIP_SAFETY_FACTOR
"""Once the object has slipped or turned in the hold (:data:`HOLD_SLIP_M`,
:data:`HOLD_TURN_RAD`), the grip aims at this multiple of the force it moved under (its slip
force under the actual load, a torque about the pinch included), at most the lift's grip."""
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
_LIFTOFF_M = 0.03  # a rim pinch lifts its vessel this far clear of the table, m...
_LIFTOFF_PAUSE_S = 0.4  # ...and waits this long for the swing to die down, s
_PALM_PRESS_M = 0.02  # the side wrap's wrist goes this far past palm contact, m
_VIA_BACK_M = 0.06  # a reach from behind passes this far behind the pre-grasp, m
# ...and this far above the object's top, m: the hand, thumb up, hangs 5-8 cm below its wrist;
# at 5 cm it swept over the pitcher base's rim and knocked it over (handle away from the user).
_VIA_CLEARANCE_M = 0.10
_REPLAN_PERIOD_S = 0.1  # at most one re-plan per 0.1 s
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
of the estimates before the grasp), so noise is not read as slip. The grip then tightens to
:data:`GRIP_SAFETY_FACTOR` times the force it moved under (at most the lift's grip), as people
raise their grip when an object starts to slip or turn in their fingers: the force at which it
moved is its slip force under its actual load, a torque about the pinch included (Kinoshita,
Backstrom, Flanagan & Johansson 1997, J. Neurophysiol. 78:1619-1630)."""
HOLD_TURN_RAD = float(np.deg2rad(1.5))
"""Or once it has turned this far in the palm frame (the perceived orientation against that at
the hold's first step; a rim pinch's: at its last lift's): a pinch above or off the centre of
mass lets its object turn about the pinch before it slides, and once turning it speeds up (the
banana went from 1 deg to 12 deg within 0.2 s as the grip eased). At 3 deg the grip reacted
too late: the banana, medium left hand, seeds 0-19, 12/20 with the grip reflex
(:data:`GRIP_REFLEX_FACTOR`), 20/20 at 1.5 deg."""
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
    speed 0.45 m/s), ``"approach"`` (the final 8 cm, peak 0.15 m/s), ``"close"`` (0.4 s: the
    digits close to the planned contact posture while an open hand that hovered sinks to the
    grasp), ``"squeeze"`` (0.3 s: the finger targets go past contact, so the position
    actuators press), ``"settle"`` (0.2 s: the grip eases to the force the object needs),
    ``"lift"`` (0.15 m up, peak speed the recipe's ``lift_speed_m_s``, 0.25 m/s but for the
    cracker box; a rim pinch lifts its vessel 3 cm clear of the table, waits 0.4 s for the
    swing that leaving the table starts to die down, then lifts on) and ``"hold"`` (until the
    episode ends).
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
    :data:`HOLD_TURN_RAD` in the palm frame (a rim pinch: since its last lift began), and
    never again after that: it then tightens to :data:`GRIP_REFLEX_FACTOR` times the force
    the object moved under, at most the lift's grip (a reflex, as people raise their grip
    when an object starts to slip or turn in their fingers). The recipe's margins
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
        self._reflex_n = 0.0

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
        self._reflex_n = 0.0
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
        reach = [
            *_reach_from_behind(self.obj, self.recipe, plan, T, start, pre_pos, quat),
            _Segment("reach", 0.0, pre_pos, quat, plan.preshape),
        ]
        segments = [
            _Segment("approach", 0.0, plan.approach_end, quat, plan.preshape),
            _Segment("close", _CLOSE_S, grasp_pos, quat, plan.contact),
            _Segment("squeeze", _SQUEEZE_S, grasp_pos, quat, plan.closed),
            _Segment("settle", _SETTLE_S, grasp_pos, quat, plan.closed),
            _Segment("lift", 0.0, lift_pos, quat, plan.closed),
        ]
        if plan.strategy == "rim" and _LIFTOFF_PAUSE_S > 0:
            # A vessel pinched at its rim hangs off the pinch and swings as it leaves the
            # table: lift it clear, wait for the swing to die down, then lift on.
            liftoff_pos = grasp_pos + np.array([0.0, 0.0, _LIFTOFF_M])
            segments[-1:-1] = [
                _Segment("lift", 0.0, liftoff_pos, quat, plan.closed),
                _Segment("lift", _LIFTOFF_PAUSE_S, liftoff_pos, quat, plan.closed),
            ]
        if first != "approach":  # a re-plan during the approach goes on from where it is
            segments = reach + segments
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
            # A rim pinch is watched from its last lift on (the object steady after the
            # pause), the others from the hold's start.
            watched = self.phase == "hold" or (
                self.phase == "lift"
                and self.plan.strategy == "rim"
                and self._index == len(self._segments) - 1
            )
            if watched and not self._easing_stopped and self._slipping(state):
                self._easing_stopped = True
                # The force it began to move under is its slip force under the actual load
                # (a torque about the pinch included): aim at the safety factor over it, but
                # never above the lift's grip.
                self._reflex_n = min(
                    GRIP_REFLEX_FACTOR * force, self._grip_force_target(lifting=True)
                )
            wanted = max(wanted, self._reflex_n)
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


def __getattr__(name: str) -> object:
    # The episode loop lives in .episode (it imports the expert): importable from here too.
    if name in ("ContactMetrics", "contact_metrics", "run_episode"):
        from handsim.envs.grasping import episode

        return getattr(episode, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
