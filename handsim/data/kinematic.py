"""The kinematic frame source: a posed hand among objects, without physics.

Every episode draws a hand (size, side), objects on the table and a pose source, and every
frame of the episode a pose, a viewpoint, a wrist placement near an object and a camera around
the hand; a hand alone is turned toward the camera as the viewpoint draws it
(:mod:`handsim.data.views`). Frames where the hand enters an object or the table, or the
forearm (drawn only, without contact) the table, by more than
:data:`~handsim.data.config.MAX_PENETRATION_M` are redrawn. With a background
(:attr:`~handsim.data.config.GenerationConfig.background`) the backdrop is stood behind the
hand, forearm and objects of every frame. An episode whose objects do not fit on the table, or
whose hand and objects give no accepted frame, raises :class:`~handsim.data.config.CannotDraw`
(the shard redraws the episode).
"""

from __future__ import annotations

import collections
import contextlib
from collections.abc import Callable, Iterator

import mujoco
import numpy as np

from handsim.data import _kernels
from handsim.data.arrays import POSE_SOURCE_CODES, VIEWPOINT_CODES, frame_to_arrays
from handsim.data.config import (
    MAX_PENETRATION_M,
    MAX_TRIES_PER_FRAME,
    MIN_KEYPOINTS_IN_FRAME,
    MOTION_FRAME_PERIOD_S,
    CannotDraw,
    GenerationConfig,
)
from handsim.data.views import hand_rotation_in_camera
from handsim.frame import Frame, FrameRenderer
from handsim.hand.model import FOREARM_GEOM, hand_params
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import (
    GESTURES,
    gesture,
    random_motion,
    sample_grasp,
    sample_synergy,
    sample_uniform,
)
from handsim.world.camera import CameraIntrinsics, camera_preset, look_at_quat_wxyz
from handsim.world.render import shared_render_context
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    CameraSpec,
    InvalidScene,
    Scene,
    SceneSpec,
    sample_placements,
)
from handsim.world.sensors import sensor_model

__all__ = [
    "KinematicSource",
    "KEPT_SCENES",
    "SHOULDER_M",
    "MIN_EYE_HEIGHT_M",
    "camera_on_line",
    "through_object_direction",
    "near_range_m",
    "forearm_geom",
    "alone_shoulder_m",
    "near_geoms",
    "beyond_near",
    "accepted_arrays",
]

KEPT_SCENES = 2
"""Scenes a kinematic source keeps between episodes (a right and a left hand alone)."""
_PALM_OFFSET_M = 0.07
"""The palm centre lies about this far along the hand's +y (distal) from the wrist."""
MIN_EYE_HEIGHT_M = 0.03
_PALM_LABEL = SEGMENT_LABELS.index("palm")
SHOULDER_M = np.array([0.18, -0.55, 0.30])
"""The right shoulder of the person at the table's -y edge (the left one at -x), world,
metres: seated, 0.3 m above the table top, shoulders 0.36 m apart [estimate]. The upper arm
is drawn from the elbow to it."""
# A hand alone: the shoulder from the palm (third person, the person facing the camera: behind
# the hand, below it, on the image's left for a right hand) or from the eye (egocentric: below
# and beside a head-mounted camera pitched down about 40 deg), in the alone camera's axes
# (world: +x image right, +y the line of sight, +z up), metres [estimate].
_ALONE_SHOULDER_FROM_PALM_M = np.array([-0.18, 0.30, -0.25])
_ALONE_SHOULDER_FROM_EYE_M = np.array([0.18, 0.10, -0.20])
# The backdrop's gap behind the farthest hand or object point, metres: a wall anywhere from
# just behind to a room's depth away; the torso just behind the elbow [estimate].
_BACKDROP_GAP_M = {"wall": (0.1, 1.5), "torso": (0.05, 0.3), "clutter": (0.1, 0.8)}
"""Cameras stay this far above the table top (world z = 0), metres."""
_THIRD_PERSON_AZIMUTH_DEG = 60.0
"""Among objects, the third-person camera stands within +- this of the table's front, deg."""
_THIRD_PERSON_ELEVATION_DEG = (20.0, 45.0)
"""Among objects, the third-person camera's elevation above the palm, uniform, deg."""
_EGO_ELEVATION_DEG = (40.0, 70.0)
"""Among objects, the head-mounted camera's elevation above the palm, uniform, deg."""
_EGO_AZIMUTH_DEG = 30.0
"""Among objects, the head-mounted camera stands within +- this of behind the wrist, deg."""

# A hand alone: the palm at a fixed point, the camera in front of it looking along world +y
# with +z up in the image (no table: the world's orientation is arbitrary).
_ALONE_PALM = np.array([0.0, 0.0, 0.3])
_ALONE_VIEW_AXIS = np.array([0.0, 1.0, 0.0])
_ALONE_CAM_QUAT_WXYZ = look_at_quat_wxyz(-_ALONE_VIEW_AXIS, np.zeros(3))


def _world_from_opencv_camera(quat_wxyz: np.ndarray) -> np.ndarray:
    """(3, 3) rotation world <- OpenCV camera of a MuJoCo camera's ``world_from_mjcam``."""
    R = np.empty(9)  # noqa: N806
    mujoco.mju_quat2Mat(R, quat_wxyz)
    # MuJoCo cameras look along -z with y up; OpenCV's along +z with y down.
    return R.reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])


_R_WORLD_FROM_ALONE_CAM = _world_from_opencv_camera(_ALONE_CAM_QUAT_WXYZ)


def _distal_axis(rotvec: np.ndarray) -> np.ndarray:
    """The hand's +y (toward the fingers) in the world, for a wrist rotation vector."""
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-12:
        return np.array([0.0, 1.0, 0.0])
    quat, distal = np.empty(4), np.empty(3)
    mujoco.mju_axisAngle2Quat(quat, rotvec / angle, angle)
    mujoco.mju_rotVecQuat(distal, np.array([0.0, 1.0, 0.0]), quat)
    return distal


def through_object_direction(
    rng: np.random.Generator, target: np.ndarray, obj: np.ndarray
) -> np.ndarray:
    """Direction (not normalized) from ``target`` to a camera beyond the object ``obj``.

    The line from the target (the hand) through the object, turned a little (a Gaussian of
    0.08 on x and y, up to 0.12 upward) so that the object hides anything from a sliver to
    all of the hand; the upward turn keeps most cameras above the table.

    Args:
        rng: draws the turn.
        target: (3,) the point looked at (the palm), world frame, metres.
        obj: (3,) the occluding object's position, world frame, metres.
    """
    direction = (obj - target) / np.linalg.norm(obj - target)
    direction[:2] += rng.normal(scale=0.08, size=2)
    direction[2] += rng.uniform(0.0, 0.12)
    return direction


def camera_on_line(
    target: np.ndarray,
    direction: np.ndarray,
    distance_m: float,
    up: tuple[float, float, float] = (0.0, 0.0, 1.0),
) -> tuple[np.ndarray, np.ndarray]:
    """Eye ``distance_m`` from ``target`` along ``direction``, looking at the target.

    The eye is raised to :data:`MIN_EYE_HEIGHT_M` when it would be below the table top.

    Returns:
        ``(eye, quat_wxyz)``: (3,) position and (4,) MuJoCo camera orientation, world frame.
    """
    direction = direction / np.linalg.norm(direction)
    eye = target + distance_m * direction
    eye[2] = max(eye[2], MIN_EYE_HEIGHT_M)
    # What CameraSpec.look_at computes, without building (and validating) a spec per frame.
    return eye, look_at_quat_wxyz(eye, target, up)


def near_range_m(intrinsics: CameraIntrinsics, sensor: object) -> float:
    """The nearest distance that gets depth: the camera's and the sensor's working range."""
    return max(intrinsics.range_m[0], float(getattr(sensor, "min_range_m", 0.0)))


def alone_shoulder_m(view: str, is_left: bool, eye_m: np.ndarray) -> np.ndarray:
    """The shoulder a hand alone's upper arm is drawn to (world, m), for the view.

    Args:
        view: the frame's viewpoint.
        is_left: a left hand (the shoulder mirrored).
        eye_m: (3,) the camera's eye, world, metres (it looks at the palm, at the alone
            frames' fixed palm centre).
    """
    mirror = np.array([-1.0, 1.0, 1.0]) if is_left else np.ones(3)
    if view == "egocentric":
        return np.asarray(eye_m, dtype=np.float64) + mirror * _ALONE_SHOULDER_FROM_EYE_M
    return _ALONE_PALM + mirror * _ALONE_SHOULDER_FROM_PALM_M


def forearm_geom(scene: Scene) -> int | None:
    """The hand's forearm geom (drawn only; None for a hand without one)."""
    if not scene.hand.params.forearm:
        return None
    return scene.model.geom(scene.hand.prefix + FOREARM_GEOM).id


def near_geoms(scene: Scene) -> np.ndarray:
    """The geoms kept beyond the near range: the hand's skin and every object geom.

    The forearm is not among them: it reaches toward the camera in many views, where a real
    sensor gets no depth either. (An object's half diameter around its body origin does not
    bound every object: the extra-large clamp reached 1.4 mm nearer than that.)
    """
    bodies = [scene.model.body(name).id for name, _ in scene.objects]
    objects = np.flatnonzero(np.isin(scene.model.geom_bodyid, bodies))
    skin = scene.hand_skin_geom_ids[scene.hand_skin_geom_ids != forearm_geom(scene)]
    return np.concatenate([skin, objects]).astype(np.intp)


def beyond_near(
    scene: Scene, geoms: np.ndarray, eye: np.ndarray, target: np.ndarray, near_m: float
) -> np.ndarray | None:
    """The eye moved back along its line of sight until ``geoms`` are beyond ``near_m``.

    Nothing nearer than the camera's or the sensor's working range gets depth (a
    structured-light sensor measures from 0.35 m): a hand or an occluder there would be a
    hole in the depth image. The bounding boxes of ``geoms`` (e.g. :func:`near_geoms`) are
    kept beyond that range.

    Args:
        scene: the scene, its geoms placed (after a forward pass).
        geoms: (n,) geom ids to keep beyond the range.
        eye: (3,) camera position, world frame, metres.
        target: (3,) the point the camera looks at, world frame, metres.
        near_m: the near range (:func:`near_range_m`), metres.

    Returns:
        (3,) the moved eye, or None when it would be below the table top.
    """
    forward = target - eye
    forward /= np.linalg.norm(forward)
    model, data = scene.model, scene.data
    # The nearest corner of the geoms' bounding boxes (in their geom frames).
    nearest = _kernels.nearest_box_depth(
        model.geom_aabb[geoms], data.geom_xmat[geoms], data.geom_xpos[geoms], eye, forward
    )
    if nearest >= near_m:
        return eye
    eye = eye - forward * (near_m - nearest)
    return eye if eye[2] >= MIN_EYE_HEIGHT_M else None


def accepted_arrays(
    frame: Frame, accept: Callable[[float, int], bool], source: str, view: str
) -> dict[str, np.ndarray] | None:
    """A labelled frame's arrays, or None when it is refused.

    ``pose_source`` and ``viewpoint`` are labelled; a frame is refused when fewer than
    :data:`MIN_KEYPOINTS_IN_FRAME` keypoints are in the image or ``accept`` (called with the
    hand occlusion ratio and the visible keypoints) refuses it.
    """
    ratio = frame.hand_occlusion_ratio or 0.0
    visible = int(frame.visible.sum())
    if frame.in_frame.sum() < MIN_KEYPOINTS_IN_FRAME or not accept(ratio, visible):
        return None
    arrays = frame_to_arrays(frame)
    arrays["hand_occlusion_ratio"][()] = ratio
    arrays["pose_source"] = np.int8(POSE_SOURCE_CODES.index(source))
    arrays["viewpoint"] = np.int8(VIEWPOINT_CODES.index(view))
    # The frame's own images, not copies: the writer only reads them, and before the
    # next frame is rendered.
    arrays["depth"], arrays["segmentation"] = frame.depth, frame.segmentation
    if frame.depth_clean is not None:
        arrays["depth_clean"] = frame.depth_clean
    return arrays


class KinematicSource:
    """Frames of a kinematically posed hand among objects (no physics).

    Args:
        config: the generation config.
    """

    def __init__(self, config: GenerationConfig) -> None:
        self.config = config
        self.intrinsics = camera_preset(config.camera)
        self.sensor = sensor_model(config.sensor)
        self._near_m = near_range_m(self.intrinsics, self.sensor)
        # A new scene's renderer takes over the OpenGL context of the one it replaces (its
        # meshes uploaded again): ~10 ms less than a new context.
        self._render_context = contextlib.ExitStack()
        self._render_context.enter_context(shared_render_context())
        # Scenes kept between episodes with their renderers, least recently used first: an
        # episode with the same side, objects and placements rescales the hand of a kept one
        # (about 1 ms) instead of building a scene (~50 ms, plus ~0.15 s for each new hand
        # length's skin).
        self._scenes: collections.OrderedDict[tuple, tuple[Scene, FrameRenderer]] = (
            collections.OrderedDict()
        )

    warp_device: str | None = None
    """The Warp device of ``backend="warp"`` (``"cpu"``, ``"cuda"``; None: Warp's default)."""

    @classmethod
    def check_config(cls, config: GenerationConfig) -> None:
        """Every field is checked by :class:`GenerationConfig` itself."""

    def _frame_renderer(self, scene: Scene) -> FrameRenderer:
        """A scene's frame renderer: OpenGL, or MuJoCo Warp for ``backend="warp"``.

        On Warp the frame renderer keeps its label code and renders through a
        :class:`~handsim.world.warp_render.WarpSceneRenderer` (one world per render).
        """
        if self.config.backend != "warp":
            return FrameRenderer(scene, "camera", self.sensor, skin_detail=self.config.skin_detail)
        from handsim.world.warp_render import WarpSceneRenderer

        warp = WarpSceneRenderer(scene.model, "camera", self.intrinsics, device=self.warp_device)
        return FrameRenderer(scene, "camera", self.sensor, skin_detail="full", renderer=warp)

    def close(self) -> None:
        """Free the scenes, renderers and OpenGL context kept between episodes."""
        while self._scenes:
            self._scenes.popitem()[1][1].close()
        self._render_context.close()

    def _scene(self, rng: np.random.Generator) -> tuple[Scene, FrameRenderer]:
        """The episode's scene and renderer: a kept one when it has the same side and objects."""
        c = self.config
        length = float(rng.uniform(*c.hand_length_range_m))
        side = "left" if rng.random() < c.left_fraction else "right"
        n = int(rng.integers(c.num_objects_range[0], c.num_objects_range[1] + 1))
        names = [c.objects[i] for i in rng.choice(len(c.objects), size=n)] if n else []
        try:
            placements = sample_placements(rng, names) if names else ()
        except InvalidScene as err:  # the names are valid (the config): they do not fit
            raise CannotDraw("placement", str(err)) from err
        key = (side, placements)
        kept = self._scenes.pop(key, None)
        if kept is None:
            while len(self._scenes) >= KEPT_SCENES:
                self._scenes.popitem(last=False)[1][1].close()
            camera = CameraSpec.look_at(
                "camera", self.intrinsics, (0.0, -0.6, 0.4), (0.0, 0.0, 0.1)
            )
            spec = SceneSpec(
                # Every hand is the medium one rescaled: its skin is built once per process.
                hand=hand_params("medium", side),
                objects=placements,
                cameras=(camera,),
                table=n > 0,
                background=self.config.background,
                # A coarse skin only if drawn (the warp backend ray-casts every mesh: full).
                skin_lod=self.config.skin_detail != "full" and self.config.backend != "warp",
            )
            scene = Scene(spec)
            kept = (scene, self._frame_renderer(scene))
        self._scenes[key] = kept
        kept[0].set_hand_length(length)
        return kept

    def _postures(self, rng: np.random.Generator, source: str, n: int) -> np.ndarray:
        """(n, 21) finger angles from the pose source ``source``, radians."""
        if source == "gesture":
            names = list(GESTURES)
            return np.stack(
                [gesture(str(rng.choice(names)), rng=rng, noise_deg=5.0).angles for _ in range(n)]
            )
        if source == "grasp":
            return sample_grasp(rng, n)[0].angles
        if source == "synergy":
            return sample_synergy(rng, n, num_synergies=3).angles
        if source == "motion":
            # Gestures, grasps and synergy postures joined by human-speed minimum-jerk
            # motions, sampled every MOTION_FRAME_PERIOD_S.
            motion = random_motion(
                rng,
                (n - 1) * MOTION_FRAME_PERIOD_S,
                MOTION_FRAME_PERIOD_S,
                sources=("gestures", "grasps", "synergy"),
            )
            return motion.angles[:n]
        return sample_uniform(rng, n).angles

    def _hand_alone(
        self, rng: np.random.Generator, view: str, is_left: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A hand alone turned toward the camera as the view draws it (:mod:`.views`).

        The camera looks along world +y from in front of the palm, the world's +z up in the
        image (there is no table); the hand is turned in the camera's frame.

        Returns:
            Wrist position, rotation vector and palm centre (world, m), then the camera's eye
            (world, m) and orientation ``quat_wxyz`` (world from MuJoCo camera).
        """
        distance = rng.uniform(*self.config.distance_range_m)
        R_cam_from_hand = hand_rotation_in_camera(rng, view, is_left)  # noqa: N806
        R = _R_WORLD_FROM_ALONE_CAM @ R_cam_from_hand  # noqa: N806
        palm = _ALONE_PALM.copy()
        wrist = palm - R[:, 1] * _PALM_OFFSET_M
        quat, rotvec = np.empty(4), np.empty(3)
        mujoco.mju_mat2Quat(quat, R.reshape(-1))
        mujoco.mju_quat2Vel(rotvec, quat, 1.0)
        eye = palm - distance * _ALONE_VIEW_AXIS
        return wrist, rotvec, palm, eye, _ALONE_CAM_QUAT_WXYZ

    def _wrist(
        self, rng: np.random.Generator, scene: Scene, beside: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Wrist position, rotation vector, palm centre and the object it is near (world, m)."""
        k = int(rng.integers(len(scene.objects)))
        body_name, obj = scene.objects[k]
        body = scene.model.body(body_name).id
        obj_pos = scene.data.xpos[body].copy()
        # The palm faces the object from a random side above the table.
        direction = rng.normal(size=3)
        # Beside the object (for a camera behind it) or from a random side above it.
        direction[2] = rng.uniform(0.0, 0.15) if beside else abs(direction[2]) + 0.3
        direction /= np.linalg.norm(direction)
        palm = obj_pos + direction * (0.5 * obj.diameter_m + rng.uniform(0.02, 0.07))
        palm[2] = max(palm[2], 0.05)
        # Hand +z (palmar) toward the object, random roll about it.
        z = obj_pos - palm
        z /= np.linalg.norm(z)
        x, y = np.empty(3), np.empty(3)
        mujoco.mju_cross(x, rng.normal(size=3), z)
        x /= np.linalg.norm(x)
        mujoco.mju_cross(y, z, x)
        R = np.column_stack([x, y, z])  # noqa: N806
        wrist = palm - R[:, 1] * _PALM_OFFSET_M
        rotvec = np.empty(3)
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, R.reshape(-1))
        mujoco.mju_quat2Vel(rotvec, quat, 1.0)
        return wrist, rotvec, palm, obj_pos

    def _camera(
        self,
        rng: np.random.Generator,
        view: str,
        target: np.ndarray,
        obj: np.ndarray | None,
        rotvec: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The camera's eye and ``quat_wxyz`` among objects (world), looking at ``target``."""
        c = self.config
        distance = rng.uniform(*c.distance_range_m)
        up = (0.0, 0.0, 1.0)
        if view == "third_person":
            # Across the table, in front of the person: the table's front is world +y.
            azimuth = np.radians(rng.uniform(-_THIRD_PERSON_AZIMUTH_DEG, _THIRD_PERSON_AZIMUTH_DEG))
            elevation = np.radians(rng.uniform(*_THIRD_PERSON_ELEVATION_DEG))
            direction = np.array([np.sin(azimuth), np.cos(azimuth), np.tan(elevation)])
        elif view == "egocentric":
            # From behind the wrist (back along the forearm) and above, as from the eyes.
            back = -_distal_axis(rotvec)
            back[2] = 0.0
            norm = np.linalg.norm(back)
            back = back / norm if norm > 1e-6 else np.array([0.0, -1.0, 0.0])
            azimuth = np.radians(rng.uniform(-_EGO_AZIMUTH_DEG, _EGO_AZIMUTH_DEG))
            cos_a, sin_a = np.cos(azimuth), np.sin(azimuth)
            elevation = np.radians(rng.uniform(*_EGO_ELEVATION_DEG))
            direction = np.array(
                [
                    cos_a * back[0] - sin_a * back[1],
                    sin_a * back[0] + cos_a * back[1],
                    np.tan(elevation),
                ]
            )
        elif view == "through_object" and obj is not None:
            direction = through_object_direction(rng, target, obj)
        else:
            direction = rng.normal(size=3)
            direction[2] = abs(direction[2]) + 0.2
        return camera_on_line(target, direction, distance, up)

    @staticmethod
    def _place_backdrop(
        rng: np.random.Generator,
        scene: Scene,
        geoms: np.ndarray,
        eye: np.ndarray,
        target: np.ndarray,
    ) -> None:
        """Stand the backdrop a random gap behind the hand (forearm included) and objects.

        Its front plane lies beyond the farthest corner of ``geoms``' bounding boxes along the
        horizontal line of sight, so it never hides them (:meth:`Scene.place_backdrop`).
        """
        ahead = target - eye
        ahead[2] = 0.0
        ahead /= max(float(np.linalg.norm(ahead)), 1e-9)
        model, data = scene.model, scene.data
        farthest = -_kernels.nearest_box_depth(
            model.geom_aabb[geoms], data.geom_xmat[geoms], data.geom_xpos[geoms], eye, -ahead
        )
        gap = rng.uniform(*_BACKDROP_GAP_M[scene.spec.background])
        scene.place_backdrop(eye, target, farthest + gap)

    @staticmethod
    def _forearm_below_table_m(scene: Scene, forearm: int | None) -> float:
        """How far the forearm's skin reaches below the table top (world z = 0), metres."""
        if forearm is None or not scene.spec.table:
            return 0.0
        model, data = scene.model, scene.data
        mesh = model.geom_dataid[forearm]
        start = model.mesh_vertadr[mesh]
        vertices = model.mesh_vert[start : start + model.mesh_vertnum[mesh]]
        # World z of the vertices: the third row of the geom's rotation, then its height.
        z = vertices @ data.geom_xmat[forearm, 6:9] + data.geom_xpos[forearm, 2]
        return max(-float(z.min()), 0.0)

    @staticmethod
    def _penetration_m(scene: Scene) -> float:
        """Deepest overlap of a hand geom with an object or the table, metres."""
        data, labels = scene.data, scene.geom_labels
        deepest = 0.0
        for i in range(data.ncon):
            con = data.contact[i]
            hand = [_PALM_LABEL <= labels[g] < OBJECT_LABEL_OFFSET for g in (con.geom1, con.geom2)]
            if hand[0] != hand[1]:
                deepest = max(deepest, -float(con.dist))
        return deepest

    def _view(
        self,
        rng: np.random.Generator,
        scene: Scene,
        renderer: FrameRenderer,
        camera: tuple[np.ndarray, np.ndarray],
        palm: np.ndarray,
        geoms: np.ndarray,
        behind: np.ndarray,
        accept: Callable[[float, int], bool],
        source: str,
        view: str,
    ) -> dict[str, np.ndarray] | None:
        """The arrays of the posed hand seen from ``camera``, or None if refused.

        The camera (``(eye, quat_wxyz)``, world, looking at the palm centre ``palm``) moves
        back until ``geoms`` are beyond the near range, the backdrop (if any) stands behind
        ``behind``, and the frame is rendered; None when the camera would be below the table,
        fewer than :data:`MIN_KEYPOINTS_IN_FRAME` keypoints are in the image or ``accept``
        refuses it. ``source`` and ``view`` are labelled (``pose_source``, ``viewpoint``).
        A hand alone's upper arm is turned here, to the shoulder placed for the view from the
        eye in range (:func:`alone_shoulder_m`); at the table the caller has turned it.
        """
        eye, quat = camera
        eye = beyond_near(scene, geoms, eye, palm, self._near_m)
        if eye is None:
            return None
        if not scene.objects and not scene.spec.table:  # the arm is not among ``geoms``
            left = scene.spec.hand.side == "left"
            scene.binding.point_upper_arm(scene.data, alone_shoulder_m(view, left, eye))
        if self.config.background != "none":
            self._place_backdrop(rng, scene, behind, eye, palm)
        cam = scene.model.camera("camera").id
        scene.model.cam_pos[cam], scene.model.cam_quat[cam] = eye, quat
        mujoco.mj_camlight(scene.model, scene.data)
        frame = renderer.render(
            rng, keep_clean=self.config.paired_clean, hand_occlusion=bool(scene.objects)
        )
        return accepted_arrays(frame, accept, source, view)

    def episode(
        self, rng: np.random.Generator, accept: Callable[[float, int], bool], frames: int
    ) -> Iterator[dict[str, np.ndarray]]:
        """Yield the arrays (images included) of ``frames`` accepted frames of one episode.

        Args:
            rng: the episode's generator.
            accept: called with the hand occlusion ratio and the number of visible keypoints;
                False redraws the frame.
            frames: frames to yield.

        Raises:
            CannotDraw: ``"placement"`` when the episode's objects do not fit on the table;
                ``"frame"`` when :data:`MAX_TRIES_PER_FRAME` draws give no accepted frame (the
                episode's hand and objects may not reach the occlusion asked for).
        """
        scene, renderer = self._scene(rng)
        source = str(rng.choice(self.config.pose_sources))
        viewpoints = list(self.config.viewpoints)
        alone = not scene.objects and not scene.spec.table
        is_left = scene.spec.hand.side == "left"
        geoms, forearm = near_geoms(scene), forearm_geom(scene)
        # Everything the backdrop stands behind: what is kept in range, and the arm.
        arm = () if forearm is None else (forearm, scene.binding.upper_arm_id)
        behind = np.append(geoms, arm).astype(np.intp)
        shoulder = SHOULDER_M * ((-1.0, 1.0, 1.0) if scene.hand.params.side == "left" else 1.0)
        # Postures are drawn a batch at a time (a sampler's cost is mostly per call), a few
        # more than the frames for the draws that are refused.
        batch = frames + 8
        postures, used = self._postures(rng, source, batch), 0
        for _ in range(frames):
            for _ in range(MAX_TRIES_PER_FRAME):
                if used == batch:
                    postures, used = self._postures(rng, source, batch), 0
                view = viewpoints[int(rng.integers(len(viewpoints)))]
                if alone:
                    wrist, rotvec, palm, eye, quat = self._hand_alone(rng, view, is_left)
                    obj = None
                else:
                    wrist, rotvec, palm, obj = self._wrist(rng, scene, view == "through_object")
                pose = HandPose(wrist, rotvec, postures[used])
                used += 1
                if alone:  # nothing to touch: no contacts to find or label
                    scene.binding.set_pose(scene.data, pose, kinematics_only=True)
                else:  # forwards: the hand placed, its contacts found
                    scene.binding.set_pose(scene.data, pose)
                    if self._penetration_m(scene) > MAX_PENETRATION_M:
                        continue
                    # The forearm is drawn only (no contact): a real one cannot enter the table.
                    if self._forearm_below_table_m(scene, forearm) > MAX_PENETRATION_M:
                        continue
                    eye, quat = self._camera(rng, view, palm, obj, rotvec)
                    scene.binding.point_upper_arm(scene.data, shoulder)
                arrays = self._view(
                    rng, scene, renderer, (eye, quat), palm, geoms, behind, accept, source, view
                )
                if arrays is not None:
                    yield arrays
                    break
            else:
                # This scene cannot give an accepted frame: a new episode may.
                raise CannotDraw(
                    "frame",
                    f"{MAX_TRIES_PER_FRAME} draws of pose, wrist and view gave no accepted frame",
                )
