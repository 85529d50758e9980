"""Grasp planning: the expert's state, start poses, shape classes, recipes and grasp plans.

Plans are collision-checked and come from an object's surface points and the hand's forward
kinematics.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from collections.abc import Callable, Sequence
from typing import Literal

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from handsim.errors import HandSimError
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import (
    ACTUATOR_GAINS,
    HAND_PHYSICS_OPTIONS,
    HAND_SIZES,
    Hand,
    HandParams,
    _joint_kind,
)
from handsim.hand.pose import JOINT_LIMITS, JOINT_NAMES, NUM_ANGLES, HandPose, joint_index
from handsim.hand.pose_sources import GRASP_TYPES
from handsim.world.objects import YCBObject, add_object
from handsim.world.scene import SEGMENT_LABELS, Scene

__all__ = [
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
]


FRAME_SKIP = 10
"""Physics steps per control step."""
CONTROL_DT_S = FRAME_SKIP * float(HAND_PHYSICS_OPTIONS["timestep"])
"""Control period, seconds (0.02 s: 50 Hz)."""
LIFT_HEIGHT_M = 0.10
"""Height the object origin must rise above its rest height, metres."""
HOLD_DURATION_S = 2.0
"""How long a lifted object must be held, seconds."""
MAX_SLIP_M = 0.01
"""Largest displacement of the object origin in the palm frame during the hold, metres."""
MAX_TURN_RAD = math.radians(10.0)
"""Largest rotation of the object in the palm frame during the hold, radians (10 deg)."""
MAX_WRIST_SPEED_M_S = 0.5
"""Largest wrist target speed the expert may command, m/s (the wrist follows a stiff weld)."""
EXPERT_WRIST_SPEED_M_S = 0.3
"""Peak wrist speed of the expert's minimum-jerk segments, m/s."""
_EXPERT_ANGULAR_SPEED_RAD_S = 2.5
_SLOW_SPEED_M_S = 0.15  # final approach
_LIFT_SPEED_M_S = 0.25
_LIFT_TARGET_M = 0.15  # the expert lifts 5 cm more than the success height
_PREGRASP_DIST_M = 0.08
_CLOSE_S = 0.4
_SQUEEZE_S = 0.3
_SETTLE_S = 0.2

TOUCH_PARTS: tuple[str, ...] = ("palm", "thumb", "index", "middle", "ring", "little")
"""Hand parts of :attr:`GraspState.touch_forces_n`, in order."""
_PALM_LABEL = SEGMENT_LABELS.index("palm")

ShapeClass = Literal[
    "can", "bottle", "box", "disk", "vessel", "bowl", "tool", "flat_tool", "clamp", "elongated"
]


class InvalidGraspState(HandSimError, ValueError):
    """A grasp state, scene instance or episode argument is malformed."""


class GraspPlanningError(HandSimError, RuntimeError):
    """The expert found no collision-free grasp for the object in this pose."""


# State ----------------------------------------------------------------------------------------


_EYE3 = np.eye(3)


def _check_transform(T: object, name: str) -> np.ndarray:
    array = np.array(T, dtype=np.float64)
    if array.shape != (4, 4) or not np.isfinite(array).all():
        raise InvalidGraspState(
            f"{name} must be a finite (4, 4) rigid transform; received shape "
            f"{np.shape(T)} {'with NaN/Inf' if array.shape == (4, 4) else ''}".rstrip()
        )
    rot = array[:3, :3]
    # np.allclose(rot.T @ rot, I, atol=1e-5) and a positive determinant, without their overhead.
    orthonormal = (np.abs(rot.T @ rot - _EYE3) <= 1e-5 + 1e-5 * _EYE3).all()
    # The determinant's sign: (r0 x r1) . r2, from the six products np.cross would make.
    (a, b, c), (d, e, f), (g, h, i) = rot.tolist()
    if not orthonormal or a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0:
        raise InvalidGraspState(f"{name}[:3, :3] must be a rotation matrix; received {rot}")
    return array


@dataclasses.dataclass(frozen=True, eq=False)
class GraspState:
    """What the grasp expert sees at one control step (ground truth or an estimate).

    Attributes:
        time_s: time since the episode start, seconds.
        hand_pose: the measured or estimated 27-DoF hand pose, world frame.
        keypoints_world: (21, 3) hand keypoints, world frame, metres.
        T_world_from_obj: (4, 4) pose of the target object (world: z up, table top at z = 0).
        obj: the target's geometry (extents, model points, symmetries, name).
        joint_angles_rad: (21,) proprioception: the physical hand's joint angles, as its own
            joint sensors read them (never a pose estimate); default: ``hand_pose.angles``.
        touch_forces_n: (6,) touch: the total normal force each hand part presses on the
            target with (:data:`TOUCH_PARTS` order: palm, thumb, index, middle, ring,
            little), newtons, as the skin's mechanoreceptors sense it (never an estimate);
            ``None``: not sensed.
        obstacles: the other objects on the table, as ``(object, (4, 4) T_world_from_obj)``
            pairs; the planner keeps the hand off them.
    """

    time_s: float
    hand_pose: HandPose
    keypoints_world: np.ndarray
    T_world_from_obj: np.ndarray
    obj: YCBObject
    joint_angles_rad: np.ndarray | None = None
    touch_forces_n: np.ndarray | None = None
    obstacles: tuple[tuple[YCBObject, np.ndarray], ...] = ()

    def __post_init__(self) -> None:
        if not (isinstance(self.time_s, (int, float, np.floating)) and math.isfinite(self.time_s)):
            raise InvalidGraspState(f"time_s must be a finite number; received {self.time_s!r}")
        if not isinstance(self.hand_pose, HandPose) or self.hand_pose.batch_shape != ():
            raise InvalidGraspState(
                f"hand_pose must be a single HandPose; received {type(self.hand_pose).__name__}"
            )
        keypoints = np.array(self.keypoints_world, dtype=np.float64)
        if keypoints.shape != (21, 3) or not np.isfinite(keypoints).all():
            raise InvalidGraspState(
                "keypoints_world must be a finite (21, 3) array in metres; received shape "
                f"{keypoints.shape}"
            )
        if not isinstance(self.obj, YCBObject):
            raise InvalidGraspState(
                f"obj must be a YCBObject (handsim.world.get_object); received "
                f"{type(self.obj).__name__}"
            )
        angles = self.hand_pose.angles if self.joint_angles_rad is None else self.joint_angles_rad
        angles = np.array(angles, dtype=np.float64)
        if angles.shape != (21,) or not np.isfinite(angles).all():
            raise InvalidGraspState(
                f"joint_angles_rad must be a finite (21,) array in radians; received shape "
                f"{angles.shape}"
            )
        object.__setattr__(self, "joint_angles_rad", angles)
        if self.touch_forces_n is not None:
            touch = np.array(self.touch_forces_n, dtype=np.float64)
            if touch.shape != (len(TOUCH_PARTS),) or not np.isfinite(touch).all():
                raise InvalidGraspState(
                    f"touch_forces_n must be a finite ({len(TOUCH_PARTS)},) array in newtons "
                    f"(palm, thumb, index, middle, ring, little); received shape {touch.shape}"
                )
            object.__setattr__(self, "touch_forces_n", touch)
        obstacles = []
        for item in self.obstacles:
            if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], YCBObject)):
                raise InvalidGraspState(
                    "obstacles must be (YCBObject, (4, 4) T_world_from_obj) pairs; received "
                    f"{type(item).__name__}"
                )
            obstacles.append((item[0], _check_transform(item[1], "an obstacle's T_world_from_obj")))
        object.__setattr__(self, "obstacles", tuple(obstacles))
        object.__setattr__(self, "time_s", float(self.time_s))
        object.__setattr__(self, "keypoints_world", keypoints)
        object.__setattr__(
            self, "T_world_from_obj", _check_transform(self.T_world_from_obj, "T_world_from_obj")
        )

    @classmethod
    def from_sim(cls, scene: Scene, instance: int, time_s: float) -> GraspState:
        """The ground-truth state of a scene.

        Args:
            scene: a scene with a hand.
            instance: index of the target object in ``scene.objects``.
            time_s: time since the episode start, seconds.

        Raises:
            InvalidGraspState: if the scene has no hand or ``instance`` is out of range.
        """
        body_id = _object_body_id(scene, instance)
        data = scene.data
        T = np.eye(4)
        T[:3, :3] = data.xmat[body_id].reshape(3, 3)
        T[:3, 3] = data.xpos[body_id]
        pose = scene.binding.pose(data)
        fields = {
            "time_s": time_s,
            "hand_pose": pose,
            "keypoints_world": scene.binding.keypoints(data),
            "T_world_from_obj": T,
            "obj": scene.objects[instance][1],
            "joint_angles_rad": pose.angles.copy(),
            "touch_forces_n": touch_forces(scene, instance),
            "obstacles": tuple(
                (other, _body_pose(scene, int(scene.model.body(body).id)))
                for k, (body, other) in enumerate(scene.objects)
                if k != instance
            ),
        }
        finite = (
            isinstance(time_s, (int, float, np.floating))
            and math.isfinite(time_s)
            and np.isfinite(T).all()
            and np.isfinite(fields["keypoints_world"]).all()
            and np.isfinite(fields["touch_forces_n"]).all()
            and all(np.isfinite(T_other).all() for _, T_other in fields["obstacles"])
        )
        if not finite:
            return cls(**fields)  # raises, naming what is not finite (a diverged state)
        # MuJoCo's arrays have the right shapes and its rotations are rotations: the checks of
        # __post_init__ (a third of the cost of a state) have nothing to find.
        state = object.__new__(cls)
        for name, value in fields.items():
            object.__setattr__(state, name, value)
        object.__setattr__(state, "time_s", float(time_s))
        return state


def _body_pose(scene: Scene, body_id: int) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = scene.data.xmat[body_id].reshape(3, 3)
    T[:3, 3] = scene.data.xpos[body_id]
    return T


def touch_forces(scene: Scene, instance: int) -> np.ndarray:
    """(6,) total normal force of each hand part on object ``instance``, newtons.

    Parts in :data:`TOUCH_PARTS` order; read from the scene's current contacts (after
    ``mj_forward``).

    Raises:
        InvalidGraspState: for a scene without a hand or a bad instance.
    """
    body_id = _object_body_id(scene, instance)
    model, data = scene.model, scene.data
    forces = np.zeros(len(TOUCH_PARTS))
    n = data.ncon
    if n == 0:
        return forces
    geoms = data.contact.geom[:n]
    labels = scene.geom_labels[geoms].astype(int) - _PALM_LABEL
    on_target = model.geom_bodyid[geoms] == body_id
    # A hand part on one side, the target on the other; visited in (contact, side) order.
    hits = on_target[:, ::-1] & (labels >= 0) & (labels < len(TOUCH_PARTS))
    wrench = np.zeros(6)
    for i, side in zip(*np.nonzero(hits), strict=True):
        mujoco.mj_contactForce(model, data, int(i), wrench)
        forces[labels[i, side]] += wrench[0]
    return forces


def _object_body_id(scene: Scene, instance: int) -> int:
    if scene.binding is None:
        raise InvalidGraspState("the scene has no hand; build it with SceneSpec(hand=...)")
    n = len(scene.objects)
    if isinstance(instance, bool) or not isinstance(instance, (int, np.integer)):
        raise InvalidGraspState(f"instance must be an int in [0, {n}); received {instance!r}")
    if not 0 <= instance < n:
        raise InvalidGraspState(
            f"instance must index scene.objects, [0, {n}); received {instance} "
            f"(objects: {', '.join(body for body, _ in scene.objects) or 'none'})"
        )
    return int(scene.model.body(scene.objects[instance][0]).id)


# Start pose -----------------------------------------------------------------------------------

_START_DISTANCE_M = 0.22  # palm centre to object origin, horizontal, toward -y
_START_HEIGHT_M = 0.18  # wrist above the table
_START_JITTER_M = 0.02
_START_JITTER_RAD = np.deg2rad(5.0)
_START_CLEAR_M = 0.12  # objects this close to the start palm (horizontally) raise the hand
_PALM_DOWN = Rotation.from_matrix(np.diag([-1.0, 1.0, -1.0]))  # fingers +y, palm toward -z


def start_pose(
    rng: np.random.Generator,
    T_world_from_obj: np.ndarray,
    hand_params: HandParams,
    *,
    obj: YCBObject | None = None,
    obstacles: Sequence[tuple[YCBObject, np.ndarray]] = (),
) -> HandPose:
    """The seeded initial hand pose of a grasping episode.

    An open hand, palm down, fingers toward ``+y``, its palm centre 0.22 m from the object
    origin toward the user (``-y``) and the wrist 0.18 m above the table (higher when ``obj``
    is given and taller than 0.13 m: 0.05 m above its top), jittered by up to 2 cm per axis and
    5 deg per rotation axis.

    Args:
        rng: random generator (the only source of randomness).
        T_world_from_obj: (4, 4) pose of the target object, world frame.
        hand_params: the hand (its length places the palm centre).
        obj: the target object; its height raises the hand above tall objects.
        obstacles: other objects, ``(object, (4, 4) T_world_from_obj)``: the hand also starts
            0.05 m above the top of any of them that comes within 0.12 m (horizontally) of
            the palm centre, so that it never starts inside one.

    Returns:
        The start pose (world frame), all angles zero.

    Raises:
        InvalidGraspState: for a malformed transform or generator.
    """
    if not isinstance(rng, np.random.Generator):
        raise InvalidGraspState(
            f"rng must be a numpy.random.Generator; received {type(rng).__name__}"
        )
    T = _check_transform(T_world_from_obj, "T_world_from_obj")
    height = _START_HEIGHT_M
    if obj is not None:
        top = float((_world_points(obj, T)[:, 2]).max())
        height = max(height, top + 0.05)
    jitter = rng.uniform(-_START_JITTER_M, _START_JITTER_M, 3)
    rot_jitter = Rotation.from_rotvec(rng.uniform(-_START_JITTER_RAD, _START_JITTER_RAD, 3))
    rotation = rot_jitter * _PALM_DOWN
    palm_centre_in_hand = np.array([0.0, 0.25 * hand_params.hand_length, 0.0])
    centre_xy = np.array([T[0, 3], T[1, 3] - _START_DISTANCE_M]) + jitter[:2]
    for other, T_other in obstacles:
        points = _world_points(other, _check_transform(T_other, "an obstacle's T_world_from_obj"))
        if np.linalg.norm(points[:, :2] - centre_xy, axis=1).min() < _START_CLEAR_M:
            height = max(height, float(points[:, 2].max()) + 0.05)
    palm_centre = np.array([*centre_xy, height + jitter[2]])
    wrist = palm_centre - rotation.apply(palm_centre_in_hand)
    return HandPose(wrist, rotation.as_rotvec(), np.zeros(NUM_ANGLES))


# Object geometry ------------------------------------------------------------------------------


def _world_points(obj: YCBObject, T: np.ndarray) -> np.ndarray:
    return np.asarray(obj.model_points_m) @ T[:3, :3].T + T[:3, 3]


# Shape classes and recipes --------------------------------------------------------------------

OBJECT_SHAPE_CLASSES: dict[str, ShapeClass] = {
    "002_master_chef_can": "can",
    "003_cracker_box": "box",
    "004_sugar_box": "box",
    "005_tomato_soup_can": "can",
    "006_mustard_bottle": "bottle",
    "007_tuna_fish_can": "disk",
    "008_pudding_box": "box",
    "009_gelatin_box": "box",
    "010_potted_meat_can": "box",
    "011_banana": "elongated",
    "019_pitcher_base": "vessel",
    "021_bleach_cleanser": "bottle",
    "024_bowl": "bowl",
    "025_mug": "vessel",
    "035_power_drill": "tool",
    "036_wood_block": "box",
    "037_scissors": "flat_tool",
    "040_large_marker": "elongated",
    "051_large_clamp": "clamp",
    "052_extra_large_clamp": "clamp",
    "061_foam_brick": "box",
}
"""Shape class of each YCB-Video object (after the rpng/suo_slam labels)."""


@dataclasses.dataclass(frozen=True)
class GraspRecipe:
    """How the expert grasps one shape class.

    Attributes:
        strategy: ``"top"`` (palm down, thumb and fingers pinch across a horizontal axis),
            ``"side"`` (palm against the side of an upright object, the digits wrap around it)
            or ``"rim"`` (from the top, thumb outside and fingers inside a vessel's wall).
        grasp_type: key of :data:`handsim.hand.pose_sources.GRASP_TYPES`.
        fingers: the fingers whose pads oppose the thumb (``"index"`` ... ``"little"``).
        height_fraction: pad height as a fraction of the object's height (top, rim: from the
            table; side: height of the palm centre line).
        max_depth_m: top grasps: the pads go at most this far below the object's top, metres.
        min_depth_m: top grasps: and at least this far (the wrist rises to clear the table
            until the pads are there), metres.
        squeeze_rad: how far past first contact the fingers are driven (the joint that
            closes most; the others in proportion), radians.
        band_m: half width of the strip of object surface the pads close on, metres.
        contact_fraction: where the digits touch, along the distal capsule (0.5 the pad,
            1.0 the tip: for objects low on the table).
        wide: open from the hand's widest span instead of the grasp type's preshape.
        max_offset_m: also try grasp centres up to this far from the COM along the object's
            long axis (a narrower section there costs its offset), metres.
        finger_holes: the digits may enter holes wider than a fingertip (scissors loops)
            and pinch the material between them.
        min_grip_scale: the regulated grip never eases below this fraction of the squeeze's
            joint deflections (:class:`~handsim.envs.grasping.GraspExpert`).
        grip_margin: the grip force aimed at is this multiple of the expert's
            (:data:`~handsim.envs.grasping.execution.GRIP_SAFETY_FACTOR` times the load over the
            friction), in every phase.
        lift_grip_margin: and this multiple of it (on top of ``grip_margin``) while the grip
            settles and the object is lifted; the hold eases back.
        across_long_axis: top grasps: the pinch axis only square to the object's long axis
            (horizontal), the fingers away from the user (within ``max_yaw_rad``) and the
            object's longer end on the thumb's side of the hand; no other direction.
        max_yaw_rad: with ``across_long_axis``: how far the pinch axis (about the fingers'
            direction) may turn from pointing away from the user, (toward the thumb, away from
            it), radians.
        across_shift_m: with ``across_long_axis``: the pinch centre this far from the centre
            of mass toward the object's longer end, metres.
        hook: wide top grasps: the middle and ring fingers close as hooks (their PIPs and DIPs
            bent, the MCPs closing), so their distal pads come down the far wall about
            vertically.
        straight_fingers: fingers outside the pinch that stay straight above the object
            (slightly hyperextended at the MCP) instead of closing with the others.
        pad_raises_m: top grasps: the pad heights tried above the deepest, metres.
        nominal_squeeze: top grasps: each joint's squeeze deflection times its nominal
            stiffness over its actuator's (at most 1), so that actuators stiffened for their
            bandwidth press with the nominal torque past contact.
        lift_speed_m_s: peak wrist speed of the lift, m/s.
    """

    strategy: Literal["top", "side", "rim"]
    grasp_type: str
    fingers: tuple[str, ...] = ("index", "middle")
    height_fraction: float = 0.5
    max_depth_m: float = 0.035
    min_depth_m: float = 0.004
    squeeze_rad: float = np.deg2rad(45.0)
    band_m: float = 0.012
    contact_fraction: float = 0.5
    wide: bool = False
    max_offset_m: float = 0.0
    finger_holes: bool = False
    min_grip_scale: float = 0.02
    grip_margin: float = 1.0
    lift_grip_margin: float = 1.0
    across_long_axis: bool = False
    max_yaw_rad: tuple[float, float] = (math.pi / 2.0, math.pi / 2.0)
    across_shift_m: float = 0.0
    hook: bool = False
    straight_fingers: tuple[str, ...] = ()
    pad_raises_m: tuple[float, ...] = (0.0, 0.01, 0.02)
    nominal_squeeze: bool = False
    lift_speed_m_s: float = _LIFT_SPEED_M_S


# Pad pinches of boxes and of thin objects at the table are sized for twice the hold's margin
# while the load comes off the table (the lift): with skin friction, the gelatin box is lifted
# with it and not without; the tripods need it too.
_LIFT_MARGIN = 2.0
# Tripods press fingertips near the top edge of thin objects, above and off their centre of
# mass: the weight also turns the object about the pinch, which point contacts hold by friction
# alone. Their grip has a larger margin in the hold as well.
_TRIPOD_MARGIN = 1.25
# Clamps: the thumb opposes the index and the middle finger together, so the planned pinch
# passes between them. With the index alone the middle finger,
# which closes beside it and pressed hardest, put the pinch 2-3 cm off the centre of mass (the
# extra-large clamp turned out of it in the lift).
_TRIPOD_FINGERS = ("index", "middle")
_LARGE_CLAMP_HOLD_MARGIN = 1.5

GRASP_RECIPES: dict[ShapeClass, GraspRecipe] = {
    "can": GraspRecipe("side", "large_diameter", height_fraction=0.45),
    # Bottles lower than cans (0.38 of the height, not 0.45): the thumb points up, and higher
    # its proximal segment reached the mustard bottle's sloping shoulder and pressed down on
    # it (normal 27 deg below the horizontal; skin friction, seeds 2, 3, 18 dropped, slipped
    # or not lifted; 20/20 at 0.38).
    "bottle": GraspRecipe("side", "large_diameter", height_fraction=0.38),
    "box": GraspRecipe(
        "top",
        "prismatic_4_finger",
        fingers=("middle",),
        contact_fraction=0.75,
        wide=True,
        lift_grip_margin=_LIFT_MARGIN,
    ),
    "disk": GraspRecipe("top", "prismatic_4_finger", lift_grip_margin=_LIFT_MARGIN),
    "vessel": GraspRecipe(
        "rim",
        "palmar_pinch",
        fingers=("index",),
        max_depth_m=0.02,
        squeeze_rad=float(np.deg2rad(25.0)),
    ),
    "bowl": GraspRecipe(
        "rim",
        "palmar_pinch",
        fingers=("index",),
        max_depth_m=0.02,
        squeeze_rad=float(np.deg2rad(25.0)),
    ),
    # The pads at 0.3 of the height, not 0.5: with skin friction the drill turned out of a
    # pinch higher on its body (seeds 0-1 not lifted or dropped; held with 0.3, seeds 0-9).
    # Squeezed with the nominal stiffnesses: the large hands' thumb CMC (4.9 N m/rad, not 3)
    # pressed 33 N against the index's 13 N, rolled the drill 15 deg in the squeeze and it
    # turned out of the pinch in the lift (large right hand, 17/20 at skin friction; 20/20).
    "tool": GraspRecipe("top", "prismatic_4_finger", height_fraction=0.3, nominal_squeeze=True),
    # The scissors keep the index alone: one finger enters a loop (with the index and the
    # middle finger together, 51 instead of 60 of 120 episodes over the six preset hands at
    # skin friction, 113 instead of about 107 at 1.0).
    "flat_tool": GraspRecipe(
        "top",
        "tripod",
        fingers=("index",),
        contact_fraction=1.0,
        finger_holes=True,
        max_offset_m=0.03,
        # Digits in the loops pinch 2.5 mm blades: eased further, they let the scissors turn
        # out of the pinch (seeds 0-1 dropped at 0.02, held at 0.15).
        min_grip_scale=0.15,
        squeeze_rad=float(np.deg2rad(30.0)),
        grip_margin=_TRIPOD_MARGIN,
        lift_grip_margin=_LIFT_MARGIN,
    ),
    # Pads 5 mm above the deepest before 1 cm: where the arms of the extra-large clamp's X
    # keep the open hand from the deepest pinch, the large hands' thumbs pressed 1 cm higher
    # on the top edge (normal 18-37 deg above the horizontal) and the clamp turned out of the
    # pinch in the lift (large right and left hands, 13/20 each at skin friction; 20/20 each).
    "clamp": GraspRecipe(
        "top",
        "tripod",
        fingers=_TRIPOD_FINGERS,
        contact_fraction=1.0,
        grip_margin=_TRIPOD_MARGIN,
        lift_grip_margin=_LIFT_MARGIN,
        pad_raises_m=(0.0, 0.005, 0.01, 0.02),
    ),
    "elongated": GraspRecipe(
        "top",
        "tripod",
        fingers=("index",),
        contact_fraction=1.0,
        band_m=0.008,
        grip_margin=_TRIPOD_MARGIN,
        lift_grip_margin=_LIFT_MARGIN,
    ),
}
"""The grasp of each shape class."""

OBJECT_RECIPES: dict[str, GraspRecipe] = {
    # The banana is thick and round (38 mm high): pads below its equator (0.35 of its height)
    # press up under its flanks. At its equator the thumb met the upper flank (normal 12-18 deg
    # downward) and the pinch let go as the hold eased (seeds 9, 15, 19 at skin friction). The
    # 19 mm marker keeps its pads at its axis (lower: 17/20, higher: 11/20). Squeezed 30 deg
    # past contact, not 45: the fingertips under the far flank and the thumb's proximal segment
    # on the near one rolled the banana 25-27 deg and raised it 6 mm off the table in the
    # squeeze, and it turned out of the pinch in the lift or the hold (the medium left hand,
    # 15/20 at skin friction and at 0.5; 17 deg, 3 mm and 20/20 at 30 deg).
    "011_banana": dataclasses.replace(
        GRASP_RECIPES["elongated"], height_fraction=0.35, squeeze_rad=float(np.deg2rad(30.0))
    ),
    # The scissors: the thumb and the index and middle pads across the loops' outer walls,
    # square to the long axis through the centre of mass (97 mm: the hand opens wide), when
    # the blades lie on the thumb's side of the hand. With the blades on the little finger's
    # side the middle finger meets the wall where it turns 31 deg toward the pivot and the
    # thumb presses down on the top edge, and at skin friction none of those were lifted;
    # there the shape class's pinch inside the loops. Pads planned at 0.4 of the height (the
    # table clearance raises the tips to about 11 mm); the large hands' longer fingers need
    # them 12-14 mm up, up to 2 mm under the top (at 4 mm they found no plan across). To keep
    # the blades on the thumb's side the wrist turns the fingers up to 135 deg from pointing
    # away from the user toward the thumb (the forearm across the body) and 120 deg the other
    # way, not 90: most pinches in the loops that failed lay there. The planned centre 3 mm
    # toward the pivot: the contacts land 3-4 mm toward the ends of the loops from it, and
    # planned at the centre of mass the pinch line passed behind it (the small hands dropped
    # them at friction 0.5, a 0.160 m hand at skin friction).
    "037_scissors": dataclasses.replace(
        GRASP_RECIPES["flat_tool"],
        fingers=("index", "middle"),
        height_fraction=0.4,
        wide=True,
        max_offset_m=0.0,
        finger_holes=False,
        across_long_axis=True,
        max_yaw_rad=(float(np.deg2rad(135.0)), float(np.deg2rad(120.0))),
        across_shift_m=0.003,
        min_depth_m=0.002,
    ),
    # The sugar box (38 mm high, pinched across 89 mm): the middle and ring fingers hooked
    # over the far wall, their pads on it with the thumb's on the near wall, 0.7 of the
    # height up (above the centre of mass, so the box hangs from the pinch). The box's
    # pinch closed the fingers along the prismatic grasp's curl: for the small hands their
    # middle segments met the far top edge first (normals 10-45 deg above the horizontal,
    # pushing the box down) and the index met the top face; at skin friction every episode
    # dropped it. The pads square on the walls need no lift margin (with the margin of 2 the
    # hold stopped easing at 7.9 times the weight, as the pinch turned in the compliant hand).
    "004_sugar_box": dataclasses.replace(
        GRASP_RECIPES["box"],
        fingers=("middle", "ring"),
        height_fraction=0.7,
        lift_grip_margin=1.0,
        hook=True,
        straight_fingers=("index", "little"),
    ),
    # The cracker box's span grasp: the small hands' thumb tips reach only the rounded top edge
    # of the near wall (normal 13-16 deg below the horizontal once pressed), so at skin
    # friction the grip has less to spare than the pads' friction promises. Eased to the
    # boxes' aim in the hold (3.8 times the weight) the thumb slid at its friction limit and
    # the box fell; lifted at 0.25 m/s the box crept down in the palm and turned out of the
    # pinch about its long axis. Held 1.25 times harder (4.8 times the weight), lifted at
    # 0.12 m/s with the lift margin that keeps the lift's aim under 8 times the weight (7.5).
    "003_cracker_box": dataclasses.replace(
        GRASP_RECIPES["box"],
        grip_margin=1.25,
        lift_grip_margin=1.3,
        lift_speed_m_s=0.12,
    ),
    # The extra-large clamp (an X of 52 mm high walls): the ring and little fingers, outside
    # the tripod, stay straight above it. Closing with the others, the ring finger's proximal
    # segment of the small hands pressed on the X's top edge (34 N in the squeeze) while the
    # thumb met it with its proximal segment, and at skin friction the clamp fell as the hold
    # eased; the large hands did not lift it in 7 of 20 episodes.
    "052_extra_large_clamp": dataclasses.replace(
        GRASP_RECIPES["clamp"], straight_fingers=("ring", "little")
    ),
    # The large clamp (125 g): the hold's margin 1.5, not the tripods' 1.25 (the lift's aim
    # unchanged, 4 times the slip force). With the medium left hand the thumb's proximal segment
    # presses on the top edge, 20 mm above the centre of mass, and its pad at about 0.6 N:
    # the clamp hangs from three contacts above it and, with no torsional friction at skin
    # friction, turned out of the pinch as the hold eased from 12 N toward its 4.6 N aim
    # (seeds 15, 19 dropped at 5-6 N).
    "051_large_clamp": dataclasses.replace(
        GRASP_RECIPES["clamp"],
        grip_margin=_LARGE_CLAMP_HOLD_MARGIN,
        lift_grip_margin=_LIFT_MARGIN * _TRIPOD_MARGIN / _LARGE_CLAMP_HOLD_MARGIN,
    ),
}
"""Objects whose grasp differs from that of their shape class."""


def grasp_recipe(obj: YCBObject) -> GraspRecipe:
    """The recipe the expert grasps ``obj`` with: its own, else its shape class's."""
    return OBJECT_RECIPES.get(obj.name) or GRASP_RECIPES[shape_class(obj)]


def shape_class(obj: YCBObject) -> ShapeClass:
    """The shape class of an object: from the table for YCB objects, else from its size.

    Imported meshes are classed by their rested bounding box: taller than 0.12 m and narrower
    than 0.11 m is a bottle, an open cavity a bowl or vessel, otherwise a box.
    """
    if obj.name in OBJECT_SHAPE_CLASSES:
        return OBJECT_SHAPE_CLASSES[obj.name]
    rest = Rotation.from_quat(np.roll(obj.rest_quat_wxyz, -1))
    points = rest.apply(np.asarray(obj.model_points_m))
    size = points.max(axis=0) - points.min(axis=0)
    if obj.cavity_point_m is not None:
        return "bowl" if size[2] < 0.6 * min(size[0], size[1]) else "vessel"
    if size[2] > 0.12 and min(size[0], size[1]) < 0.11:
        return "bottle"
    return "box"


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
    fingers = {f: _STRAIGHT_FINGER_DEG for f in recipe.straight_fingers}
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
_STRAIGHT_FINGER_DEG = (-20.0, 0.0, 20.0)  # MCP, PIP, DIP: the span path's index and little


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
        # (MCP, PIP, DIP) at closure 0, degrees; the index and little fingers straighter.
        mcp, pip, dip = (-20.0, 0.0, 20.0) if finger in ("index", "little") else (-17.0, 20.0, 39.0)
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
    height = min(recipe.height_fraction * top, 0.14)
    band = points[np.abs(points[:, 2] - height) < 0.01]
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
        if d @ preferred_dir < np.cos(np.deg2rad(75.0)):
            continue
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
        functools.partial(_side_candidates, obj, T, params, r, preferred)
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
