"""The grasp expert's state and timing: what it sees, touch, start poses, the success limits.

The constants here are shared by planning (:mod:`.planning`) and execution (:mod:`.execution`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from handsim.errors import HandSimError
from handsim.hand.model import HAND_PHYSICS_OPTIONS, HandParams
from handsim.hand.pose import NUM_ANGLES, HandPose
from handsim.world.objects import YCBObject
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
EXPERT_WRIST_SPEED_M_S = 0.45
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
