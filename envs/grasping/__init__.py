"""Scripted grasping: a :class:`GraspExpert` that picks up and lifts YCB objects, and its score.

The pieces an environment needs to run a pick-and-lift episode:

- :class:`GraspState`: what the expert sees (the hand pose, keypoints, the target object's
  pose and geometry, proprioception, touch and the other objects). It may come from ground
  truth (:meth:`GraspState.from_sim`) or from a pose estimate; the expert never reads
  ``MjData``.
- :func:`start_pose`: the seeded initial hand pose of an episode (open hand, palm down, on the
  user's side of the object).
- :class:`GraspExpert`: plans a grasp at :meth:`~GraspExpert.reset` (and re-plans while it
  reaches) and returns an absolute 27-DoF target pose at every control step
  (:meth:`~GraspExpert.act`).
- :class:`LiftTracker` / :func:`evaluate_lift`: the success definition (below).
- :func:`run_episode`: the ground-truth loop used by the tests and ``benchmarks/bench_grasp.py``.

Control: the env applies the expert's pose with :class:`handsim.envs.physics.HandDriver` (the
wrist follows a mocap target through a soft weld, the fingers have position actuators) and steps
the physics :data:`FRAME_SKIP` times (0.002 s each, so the expert runs at 50 Hz);
:func:`run_episode` does the same.

Grasps are physical: contact and friction only. No equality constraint, adhesion or change of
the object's mass, gravity or friction is used.

Success (:class:`LiftTracker`): the object origin rises at least :data:`LIFT_HEIGHT_M` = 0.10 m
above its rest height, and then stays lifted for :data:`HOLD_DURATION_S` = 2 s while, in the
palm frame, it moves less than :data:`MAX_SLIP_M` = 0.01 m (slip: displacement of the object
origin expressed in the frame of the palm body) and turns less than :data:`MAX_TURN_RAD` = 10 deg
(turn: angle of the rotation of the object's frame expressed in the palm's frame). Both are
measured over the whole hold window against the object's pose in the palm frame at the
window's first step, the first control step at which the object is lifted. A window that
reaches either limit ends the hold ("slipped" or "turned"); a new window opens only after the
object has been below the lift height again. If the object drops below the lift height the
window ends too, and a later lift opens a new one.

How the expert grasps (:data:`OBJECT_SHAPE_CLASSES`, :data:`GRASP_RECIPES`): the object's shape
class selects a strategy and a grasp type of the GRASP taxonomy
(:data:`handsim.hand.pose_sources.GRASP_TYPES`):

==========  ==================================  ============================================
class       objects                             grasp (type; how)
==========  ==================================  ============================================
can         002 master chef can, 005 tomato     large diameter; side wrap, palm against the
            soup can                            can, thumb up
bottle      006 mustard, 021 bleach cleanser    large diameter; side wrap, palm on the broad
                                                face
box         003, 004, 008, 009, 010, 036, 061   prismatic 4 finger; the whole hand from the
                                                top, thumb and finger pads across the
                                                narrowest side, no finger straight out; boxes
                                                wider than 0.13 m (003) with the widest span:
                                                the thumb tip and the middle and ring pads on
                                                the side walls just under the top edges, the
                                                index and little curled over the top; the
                                                sugar box (004) with the middle and ring
                                                fingers hooked over its far wall, the index
                                                and little curled over the top
disk        007 tuna fish can                   prismatic 4 finger; from the top
tool        035 power drill                     small diameter; upright, the grip wrapped
                                                from behind, the index under the barrel,
                                                whichever way it faces (:data:`OBJECT_RECIPES`)
vessel      019 pitcher base                    small diameter; by its handle, the fingers
                                                through the opening between it and the wall
                                                (:data:`OBJECT_RECIPES`)
vessel      025 mug                             prismatic 4 finger; around its body from
                                                above, as the boxes, the pinch away from the
                                                handle (:data:`OBJECT_RECIPES`)
bowl        024 bowl                            palmar pinch; thumb outside and index inside
                                                the rim nearest the user
flat_tool   037 scissors                        tripod; fingertips into the loops, pinching
                                                the material between them
clamp       051, 052 clamps                     tripod; fingertips at the table, across the
                                                arms at the pivot, the thumb opposite the
                                                index and the middle finger (052: the ring
                                                and little fingers straight above it)
elongated   011 banana, 040 large marker        tripod; fingertips at the table, across the
                                                body (the banana's below its equator:
                                                :data:`OBJECT_RECIPES`)
==========  ==================================  ============================================

Planning (at :meth:`GraspExpert.reset`, and again during the reach and the approach when the
expert's filtered estimate of the object pose moves; from the state's object pose and the
object's model points): the grasp axis and centre come from the object's surface points (the
narrowest cross-section through the centre of mass that the hand can span), the wrist pose from
the hand's forward kinematics (the thumb and finger contact spheres meet the object at the
closure where their gap equals the object's width), and every candidate is checked for
collisions with the table, the object and the state's ``obstacles`` (other objects) in a
private kinematic copy (the env's ``MjData`` is never read). The digits squeeze past contact,
then the grip force is regulated from touch (:attr:`GraspState.touch_forces_n`) to
:data:`GRIP_SAFETY_FACTOR` times the slip force of the load at skin friction on the object's
material (people scale their grip with the load; :class:`GraspExpert`), with the recipe's
margins (:class:`GraspRecipe`: pad pinches of boxes and tripods grip harder while lifting, and
tripods in the hold as well). Motions are
minimum-jerk segments with a peak wrist speed of :data:`EXPERT_WRIST_SPEED_M_S` (below
:data:`MAX_WRIST_SPEED_M_S`).

Results: ``benchmarks/bench_grasp.py`` (20 seeds per object, medium right hand).
"""

from handsim.envs.grasping.episode import ContactMetrics, contact_metrics, run_episode
from handsim.envs.grasping.execution import (
    FALL_HEIGHT_M,
    GRIP_FRICTION,
    GRIP_SAFETY_FACTOR,
    MAX_GRIP_SCALE,
    MIN_GRIP_FORCE_N,
    MIN_GRIP_SCALE,
    REPLAN_ANGLE_RAD,
    REPLAN_DISTANCE_M,
    GraspExpert,
)
from handsim.envs.grasping.planning import (
    CONTROL_DT_S,
    EXPERT_WRIST_SPEED_M_S,
    FRAME_SKIP,
    GRASP_RECIPES,
    HOLD_DURATION_S,
    LIFT_HEIGHT_M,
    MAX_SLIP_M,
    MAX_TURN_RAD,
    MAX_WRIST_SPEED_M_S,
    OBJECT_RECIPES,
    OBJECT_SHAPE_CLASSES,
    TOUCH_PARTS,
    GraspPlan,
    GraspPlanningError,
    GraspRecipe,
    GraspState,
    InvalidGraspState,
    ShapeClass,
    grasp_recipe,
    plan_grasp,
    shape_class,
    start_pose,
    touch_forces,
)
from handsim.envs.grasping.success import (
    FailureReason,
    GraspOutcome,
    LiftTracker,
    evaluate_lift,
)

__all__ = [
    "FALL_HEIGHT_M",
    "FRAME_SKIP",
    "CONTROL_DT_S",
    "LIFT_HEIGHT_M",
    "HOLD_DURATION_S",
    "MAX_SLIP_M",
    "MAX_TURN_RAD",
    "MAX_WRIST_SPEED_M_S",
    "EXPERT_WRIST_SPEED_M_S",
    "InvalidGraspState",
    "GraspPlanningError",
    "GraspState",
    "TOUCH_PARTS",
    "touch_forces",
    "start_pose",
    "ShapeClass",
    "OBJECT_SHAPE_CLASSES",
    "GraspRecipe",
    "GRASP_RECIPES",
    "OBJECT_RECIPES",
    "grasp_recipe",
    "shape_class",
    "GraspPlan",
    "plan_grasp",
    "GraspExpert",
    "GRIP_SAFETY_FACTOR",
    "GRIP_FRICTION",
    "MIN_GRIP_SCALE",
    "MAX_GRIP_SCALE",
    "MIN_GRIP_FORCE_N",
    "REPLAN_DISTANCE_M",
    "REPLAN_ANGLE_RAD",
    "ContactMetrics",
    "contact_metrics",
    "FailureReason",
    "GraspOutcome",
    "LiftTracker",
    "evaluate_lift",
    "run_episode",
]
