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
from scipy.spatial.transform import Rotation, Slerp

from handsim.envs.base import HandDriver
from handsim.envs.grasping.planning import (
    _CLOSE_S,
    _EXPERT_ANGULAR_SPEED_RAD_S,
    _LIFT_SPEED_M_S,
    _LIFT_TARGET_M,
    _PREGRASP_DIST_M,
    _SETTLE_S,
    _SLOW_SPEED_M_S,
    _SQUEEZE_S,
    CONTROL_DT_S,
    EXPERT_WRIST_SPEED_M_S,
    FRAME_SKIP,
    GRASP_RECIPES,
    HOLD_DURATION_S,
    LIFT_HEIGHT_M,
    MAX_SLIP_M,
    GraspPlan,
    GraspState,
    InvalidGraspState,
    _check_transform,
    _checker,
    _object_body_id,
    plan_grasp,
    shape_class,
    start_pose,
)
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_LIMITS, JOINT_NAMES, HandPose
from handsim.hand.pose_sources import minimum_jerk
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

GRIP_SAFETY_FACTOR = 2.0
"""Grip force over the force that just prevents slip. People grip with 1.3 to 3 times the slip
force and scale it with the load (grip-load coupling; Johansson & Westling 1984, Exp. Brain
Res. 56:550-564); the expert aims at 2."""
GRIP_FRICTION = 1.0
"""Hand-object friction coefficient the expert assumes when sizing its grip force."""
LIFT_ACCELERATION_M_S2 = 2.0
"""Upward acceleration the grip is sized for on top of gravity (the expert's minimum-jerk lift
peaks near 1.5 m/s^2), m/s^2."""
MIN_GRIP_SCALE = 0.2
"""The grip eases off to no less than this fraction of the squeeze's joint deflections: the
force model leaves out the palm and the proximal segments, and below it small boxes and the
extra-large clamp were dropped in the sweep (docs/grasping.md)."""
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
    rotation: Rotation
    angles: np.ndarray


def _duration(
    pos0: np.ndarray,
    pos1: np.ndarray,
    rot0: Rotation,
    rot1: Rotation,
    speed_m_s: float,
    minimum_s: float,
) -> float:
    distance = float(np.linalg.norm(pos1 - pos0))
    angle = float((rot1 * rot0.inv()).magnitude())
    # Minimum jerk peaks at 1.875 times the mean speed.
    return max(minimum_s, 1.875 * distance / speed_m_s, 1.875 * angle / _EXPERT_ANGULAR_SPEED_RAD_S)


class GraspExpert:
    """A scripted pick-and-lift expert for one object.

    Phases (:attr:`phase`): ``"reach"`` (to 8 cm before the grasp, shaping the hand: peak
    speed 0.3 m/s), ``"approach"`` (the final 8 cm, peak 0.15 m/s), ``"close"`` (0.4 s: the
    digits close to the planned contact posture while an open hand that hovered sinks to the
    grasp), ``"squeeze"`` (0.3 s: the finger targets go past contact, so the position
    actuators press), ``"settle"`` (0.2 s: the fingers ease off to the grip force the object
    needs, :meth:`grip_targets`), ``"lift"`` (0.15 m up, peak 0.25 m/s) and
    ``"hold"`` (until the episode ends). :attr:`grasp_type` is the grasp taxonomy type and
    ``plan.strategy`` how it is applied (:class:`GraspRecipe`).

    The plan is made once, at :meth:`reset`, from the state's object pose. :meth:`act` follows
    minimum-jerk segments in time (the target never jumps: each segment starts where the last
    one ended), and waits (up to 1 s) at the end of the reach and of the approach until the
    state's wrist is within 2 cm of its target. It closes along a fixed schedule; contact needs
    no sensing because the position actuators stop at the object and press with their
    torque-limited stiffness. The grip force is then set from proprioception: the joint
    angles at the end of the squeeze say how far each actuator is held off its target, hence
    how hard each digit presses.

    Args:
        obj: the object to grasp.
        hand_params: the hand that will grasp it.
        rng: optional generator; it jitters the segment speeds by up to 10 % (None: none).
    """

    def __init__(
        self, obj: YCBObject, hand_params: HandParams, *, rng: np.random.Generator | None = None
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
        self.obj = obj
        self.hand_params = hand_params
        self.rng = rng
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
        self.recipe = GRASP_RECIPES[shape_class(obj)]
        self.plan: GraspPlan | None = None
        self.phase = "idle"
        self._segments: list[_Segment] = []
        self._index = 0
        self._segment_start_s = 0.0
        self._from: _Segment | None = None

    @property
    def grasp_type(self) -> str:
        """The grasp type (:data:`handsim.hand.pose_sources.GRASP_TYPES` key) of the recipe."""
        return self.plan.grasp_type if self.plan is not None else self.recipe.grasp_type

    def reset(self, state: GraspState) -> None:
        """Plan the grasp for the state's object pose and restart the phases.

        Raises:
            InvalidGraspState: if ``state`` is not a :class:`GraspState` of this object.
            GraspPlanningError: if no collision-free grasp exists.
        """
        self._check_state(state)
        plan = plan_grasp(self.obj, state.T_world_from_obj, self.hand_params)
        self.plan = plan
        scale = 1.0 if self.rng is None else float(self.rng.uniform(0.9, 1.1))
        hand = state.hand_pose
        start = _Segment(
            "start",
            0.0,
            hand.wrist_pos.copy(),
            Rotation.from_rotvec(hand.wrist_rotvec),
            hand.angles.copy(),
        )
        pre_pos = plan.approach_end - _PREGRASP_DIST_M * plan.approach_dir
        lift_pos = plan.wrist_pos + np.array([0.0, 0.0, _LIFT_TARGET_M])
        segments = [
            _Segment("reach", 0.0, pre_pos, plan.rotation, plan.preshape),
            _Segment("approach", 0.0, plan.approach_end, plan.rotation, plan.preshape),
            _Segment("close", _CLOSE_S, plan.wrist_pos, plan.rotation, plan.contact),
            _Segment("squeeze", _SQUEEZE_S, plan.wrist_pos, plan.rotation, plan.closed),
            _Segment("settle", _SETTLE_S, plan.wrist_pos, plan.rotation, plan.closed),
            _Segment("lift", 0.0, lift_pos, plan.rotation, plan.closed),
        ]
        previous = start
        for segment in segments:
            if segment.duration_s == 0.0:
                speed = {"reach": EXPERT_WRIST_SPEED_M_S, "lift": _LIFT_SPEED_M_S}.get(
                    segment.name, _SLOW_SPEED_M_S
                )
                segment.duration_s = scale * _duration(
                    previous.pos, segment.pos, previous.rotation, segment.rotation, speed, 0.4
                )
            previous = segment
        self._segments = segments
        self._from = start
        self._index = 0
        self._segment_start_s = state.time_s
        self.phase = segments[0].name

    def grip_targets(self, state: GraspState) -> np.ndarray:
        """Finger targets that press on the object with a grip force sized to its weight.

        Called when the squeeze has pressed the digits onto the object. A position actuator
        held off its target presses with ``kp * (target - angle)`` (up to its torque limit), so
        the joint deflections give each digit's force (torque over the lever from the joint's
        keypoint to the tip; the median over its flexion joints). The grip force aimed at is
        :data:`GRIP_SAFETY_FACTOR` times what the weight and the lift acceleration need at
        friction :data:`GRIP_FRICTION`: half on the thumb, half shared by the pressing fingers.
        Each digit's deflections are scaled down to that force (never up: the squeeze is the
        most the expert presses; never below :data:`MIN_GRIP_SCALE` of them).

        Args:
            state: the state at the end of the squeeze.

        Returns:
            (21,) joint targets, radians.
        """
        # Proprioception, not the (possibly estimated) pose: the deflections set the force.
        measured = state.joint_angles_rad
        squeeze = self.plan.closed
        load_n = self.obj.mass_kg * (9.81 + LIFT_ACCELERATION_M_S2)
        grip_n = GRIP_SAFETY_FACTOR * load_n / GRIP_FRICTION
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
            scale = float(np.clip(wanted / max(force_n, 1e-6), MIN_GRIP_SCALE, 1.0))
            joints = _DIGIT_ALL_JOINTS[digit]
            targets[joints] = measured[joints] + scale * (squeeze[joints] - measured[joints])
        return np.clip(targets, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])

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
        if self.plan is None:
            raise InvalidGraspState("call reset(state) before act(state)")
        self._check_state(state)
        t = state.time_s
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
            if segment.name == "squeeze" and not self.plan.hooked:
                # The digits press on the object: ease them to the grip force it needs.
                grip = self.grip_targets(state)
                for later in self._segments[self._index :]:
                    later.angles = grip
        if self._index >= len(self._segments):
            self.phase = "hold"
            last = self._segments[-1]
            return HandPose(last.pos, last.rotation.as_rotvec(), last.angles)
        segment = self._segments[self._index]
        self.phase = segment.name
        tau = (t - self._segment_start_s) / max(segment.duration_s, 1e-9)
        s = float(np.clip(minimum_jerk(np.clip(tau, 0.0, 1.0)), 0.0, 1.0))
        start = self._from
        pos = start.pos + s * (segment.pos - start.pos)
        slerp = Slerp([0.0, 1.0], Rotation.concatenate([start.rotation, segment.rotation]))
        rotation = slerp([s])[0]
        angles = start.angles + s * (segment.angles - start.angles)
        return HandPose(pos, rotation.as_rotvec(), angles)


# Success --------------------------------------------------------------------------------------

FailureReason = Literal["not_lifted", "dropped", "slipped", "hold_incomplete", "diverged"]


@dataclasses.dataclass(frozen=True)
class GraspOutcome:
    """The result of a pick-and-lift episode.

    Attributes:
        success: lifted by :data:`LIFT_HEIGHT_M` and held :data:`HOLD_DURATION_S` with less
            than :data:`MAX_SLIP_M` slip.
        failure: why it failed (``None`` on success): ``"not_lifted"`` (never reached the lift
            height), ``"dropped"`` (lifted, but below the lift height at the end),
            ``"slipped"`` (still lifted at the end, but it slipped ``MAX_SLIP_M`` or more in
            the palm frame and the hold restarted), ``"hold_incomplete"`` (still lifted and not
            slipping, held for less than the hold duration), ``"diverged"`` (physics).
        max_lift_m: highest rise of the object origin above its rest height, metres.
        slip_m: on success the largest slip in the successful window; otherwise the largest
            slip seen in any window, metres.
        hold_s: duration of the last hold window, seconds.
        success_time_s: episode time at which the hold completed (``None`` on failure).
        steps: control steps run.
    """

    success: bool
    failure: FailureReason | None
    max_lift_m: float
    slip_m: float
    hold_s: float
    success_time_s: float | None
    steps: int

    def to_dict(self) -> dict[str, object]:
        """A JSON-serializable dict of the fields."""
        return dataclasses.asdict(self)


class LiftTracker:
    """Per-step evaluation of the lift success definition (module docstring).

    Feed every control step with :meth:`update`; :attr:`success` turns true once an object has
    been held lifted for :data:`HOLD_DURATION_S` with slip below :data:`MAX_SLIP_M`, and stays
    true. :meth:`outcome` summarizes the episode so far.

    Args:
        rest_height_m: height of the object origin at rest (episode start), metres.
        lift_height_m: the lift threshold (default :data:`LIFT_HEIGHT_M`).
        hold_s: the hold duration (default :data:`HOLD_DURATION_S`).
        max_slip_m: the slip threshold (default :data:`MAX_SLIP_M`).
    """

    def __init__(
        self,
        rest_height_m: float,
        *,
        lift_height_m: float = LIFT_HEIGHT_M,
        hold_s: float = HOLD_DURATION_S,
        max_slip_m: float = MAX_SLIP_M,
    ) -> None:
        for name, value in (
            ("rest_height_m", rest_height_m),
            ("lift_height_m", lift_height_m),
            ("hold_s", hold_s),
            ("max_slip_m", max_slip_m),
        ):
            if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value)):
                raise InvalidGraspState(f"{name} must be a finite number; received {value!r}")
        if lift_height_m <= 0 or hold_s <= 0 or max_slip_m <= 0:
            raise InvalidGraspState(
                "lift_height_m, hold_s and max_slip_m must be > 0; received "
                f"{lift_height_m}, {hold_s}, {max_slip_m}"
            )
        self.rest_height_m = float(rest_height_m)
        self.lift_height_m = float(lift_height_m)
        self.hold_s = float(hold_s)
        self.max_slip_m = float(max_slip_m)
        self.success = False
        self.success_time_s: float | None = None
        self.max_lift_m = -math.inf
        self.steps = 0
        self._window_start_s: float | None = None
        self._window_pos_palm: np.ndarray | None = None
        self._window_slip_m = 0.0
        self._last_time_s = -math.inf
        self._ever_lifted = False
        self._broken: FailureReason | None = None
        self._break_slip_m = 0.0
        self._window_duration_s = 0.0

    def update(
        self, time_s: float, obj_pos_world: np.ndarray, T_world_from_palm: np.ndarray
    ) -> bool:
        """Add one step.

        Args:
            time_s: episode time, seconds (increasing).
            obj_pos_world: (3,) object origin, world frame, metres.
            T_world_from_palm: (4, 4) pose of the palm (hand root) body, world frame.

        Returns:
            :attr:`success` after this step.

        Raises:
            InvalidGraspState: for non-increasing time or malformed arrays.
        """
        if not time_s > self._last_time_s:
            raise InvalidGraspState(
                f"time_s must increase from step to step; received {time_s} after "
                f"{self._last_time_s}"
            )
        pos = np.asarray(obj_pos_world, dtype=np.float64)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise InvalidGraspState(
                f"obj_pos_world must be 3 finite numbers (m); received {obj_pos_world!r}"
            )
        T = _check_transform(T_world_from_palm, "T_world_from_palm")
        self._last_time_s = float(time_s)
        self.steps += 1
        if self.success:
            return True
        lift = float(pos[2] - self.rest_height_m)
        self.max_lift_m = max(self.max_lift_m, lift)
        pos_palm = T[:3, :3].T @ (pos - T[:3, 3])
        if lift < self.lift_height_m:
            if self._window_start_s is not None:
                self._broken = "dropped"
            self._close_window()
            return False
        self._ever_lifted = True
        if self._window_start_s is None:
            self._open_window(time_s, pos_palm)
            return False
        slip = float(np.linalg.norm(pos_palm - self._window_pos_palm))
        if slip >= self.max_slip_m:
            self._broken = "slipped"
            self._break_slip_m = max(self._break_slip_m, slip)
            self._open_window(time_s, pos_palm)
            return False
        self._window_slip_m = max(self._window_slip_m, slip)
        self._window_duration_s = time_s - self._window_start_s
        # A small tolerance absorbs float round-off in time stamps (k * dt).
        if self._window_duration_s >= self.hold_s - 1e-9:
            self.success = True
            self.success_time_s = float(time_s)
        return self.success

    def _open_window(self, time_s: float, pos_palm: np.ndarray) -> None:
        self._window_start_s = float(time_s)
        self._window_pos_palm = pos_palm
        self._window_slip_m = 0.0
        self._window_duration_s = 0.0

    def _close_window(self) -> None:
        self._window_start_s = None
        self._window_pos_palm = None

    def update_from_sim(self, scene: Scene, instance: int, time_s: float) -> bool:
        """:meth:`update` with the ground truth of ``scene`` (object ``instance``)."""
        body_id = _object_body_id(scene, instance)
        palm_id = int(scene.model.body(scene.hand.root_body).id)
        data = scene.data
        T = np.eye(4)
        T[:3, :3] = data.xmat[palm_id].reshape(3, 3)
        T[:3, 3] = data.xpos[palm_id]
        return self.update(time_s, data.xpos[body_id], T)

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
        elif self._window_start_s is None:
            failure = "dropped"
        else:
            # Still lifted at the end: the last window restarted after a slip, or ran short.
            failure = "slipped" if self._broken == "slipped" else "hold_incomplete"
        return GraspOutcome(
            success=self.success,
            failure=failure,
            max_lift_m=float(self.max_lift_m) if self.steps else 0.0,
            slip_m=float(
                self._window_slip_m
                if self.success
                else max(self._window_slip_m, self._break_slip_m)
            ),
            hold_s=float(self._window_duration_s),
            success_time_s=self.success_time_s,
            steps=self.steps,
        )


def evaluate_lift(
    times_s: np.ndarray,
    obj_pos_world: np.ndarray,
    T_world_from_palm: np.ndarray,
    rest_height_m: float,
) -> GraspOutcome:
    """Evaluate a recorded trajectory against the success definition.

    Args:
        times_s: (T,) increasing episode times, seconds.
        obj_pos_world: (T, 3) object origin, world frame, metres.
        T_world_from_palm: (T, 4, 4) palm poses, world frame.
        rest_height_m: height of the object origin at rest, metres.

    Returns:
        The outcome, as :class:`LiftTracker` would give after the last step.

    Raises:
        InvalidGraspState: for mismatched shapes or non-increasing times.
    """
    times = np.asarray(times_s, dtype=np.float64)
    pos = np.asarray(obj_pos_world, dtype=np.float64)
    palm = np.asarray(T_world_from_palm, dtype=np.float64)
    if times.ndim != 1 or pos.shape != (len(times), 3) or palm.shape != (len(times), 4, 4):
        raise InvalidGraspState(
            "expected times_s (T,), obj_pos_world (T, 3) and T_world_from_palm (T, 4, 4); "
            f"received {times.shape}, {pos.shape}, {palm.shape}"
        )
    tracker = LiftTracker(rest_height_m)
    for t, p, T in zip(times, pos, palm, strict=True):
        tracker.update(float(t), p, T)
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


def run_episode(
    scene: Scene,
    instance: int,
    expert: GraspExpert,
    rng: np.random.Generator,
    max_steps: int = 400,
    *,
    stop_on_success: bool = True,
    on_step: Callable[[int, GraspExpert], None] | None = None,
) -> GraspOutcome:
    """Run one ground-truth pick-and-lift episode.

    Resets ``scene`` (objects at their placements, the hand at :func:`start_pose`), then per
    control step: state -> ``expert.act`` -> ``set_target`` -> :data:`FRAME_SKIP` physics steps
    -> success tracking.

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

    Returns:
        The outcome.

    Raises:
        InvalidGraspState: for a bad instance, expert or ``max_steps``.
        GraspPlanningError: if the expert finds no grasp.
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
    state = GraspState.from_sim(scene, instance, 0.0)
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
        state = GraspState.from_sim(scene, instance, time_s)
    return tracker.outcome(diverged=diverged)
