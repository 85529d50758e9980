"""The kinematic frame source: a posed hand among objects, without physics.

Every episode draws a hand (size, side), objects on the table and a pose source, and every
frame of the episode a pose, a wrist placement near an object and a camera viewpoint around the
hand. Frames where the hand enters an object or the table by more than
:data:`~handsim.data.config.MAX_PENETRATION_M` are redrawn.
"""

from __future__ import annotations

import collections
import contextlib
from collections.abc import Callable, Iterator

import mujoco
import numpy as np

from handsim.data import _kernels
from handsim.data.arrays import frame_to_arrays
from handsim.data.config import (
    MAX_PENETRATION_M,
    MAX_TRIES_PER_FRAME,
    MIN_KEYPOINTS_IN_FRAME,
    GenerationConfig,
)
from handsim.frame import FrameRenderer
from handsim.hand.model import hand_params
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import (
    GESTURES,
    gesture,
    sample_grasp,
    sample_synergy,
    sample_uniform,
)
from handsim.world.camera import camera_preset, look_at_quat_wxyz
from handsim.world.render import shared_render_context
from handsim.world.scene import CameraSpec, Scene, SceneSpec, sample_placements
from handsim.world.sensors import sensor_model

__all__ = ["KinematicSource", "KEPT_SCENES"]

KEPT_SCENES = 2
"""Scenes a kinematic source keeps between episodes (a right and a left hand alone)."""
_PALM_OFFSET_M = 0.07
"""The palm centre lies about this far along the hand's +y (distal) from the wrist."""
_MIN_EYE_HEIGHT_M = 0.03
"""Cameras stay this far above the table top (world z = 0), metres."""


class KinematicSource:
    """Frames of a kinematically posed hand among objects (no physics).

    Args:
        config: the generation config.
    """

    def __init__(self, config: GenerationConfig) -> None:
        self.config = config
        self.intrinsics = camera_preset(config.camera)
        self.sensor = sensor_model(config.sensor)
        # The nearest distance that gets depth: the camera's and the sensor's working range.
        self._near_m = max(
            self.intrinsics.range_m[0], float(getattr(self.sensor, "min_range_m", 0.0))
        )
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

    @classmethod
    def check_config(cls, config: GenerationConfig) -> None:
        """Every field is checked by :class:`GenerationConfig` itself."""

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
        placements = sample_placements(rng, names) if names else ()
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
            )
            scene = Scene(spec)
            kept = (scene, FrameRenderer(scene, "camera", self.sensor))
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
        return sample_uniform(rng, n).angles

    def _wrist(
        self, rng: np.random.Generator, scene: Scene, beside: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Wrist position, rotation vector, palm centre and the object it is near (world, m)."""
        if not scene.objects:
            # A uniform rotation: a normalized 4-D Gaussian quaternion.
            quat = rng.normal(size=4)
            quat /= np.linalg.norm(quat)
            R = np.empty(9)  # noqa: N806
            mujoco.mju_quat2Mat(R, quat)
            rotvec = np.empty(3)
            mujoco.mju_quat2Vel(rotvec, quat, 1.0)
            wrist = np.array([0.0, 0.0, 0.3])
            return wrist, rotvec, wrist + R.reshape(3, 3)[:, 1] * _PALM_OFFSET_M, None
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
        self, rng: np.random.Generator, view: str, target: np.ndarray, obj: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        c = self.config
        distance = rng.uniform(*c.distance_range_m)
        up = (0.0, 0.0, 1.0)
        if view == "third_person":
            direction = np.array([0.0, 1.0, 0.6])
        elif view == "egocentric":
            direction = np.array([0.0, -0.35, 0.45])
            up = (0.0, 1.0, 0.0)
        elif view == "through_object" and obj is not None:
            # Beyond the object as seen from the hand, turned a little so that the object hides
            # anything from a sliver to all of the hand; never below the table top.
            direction = (obj - target) / np.linalg.norm(obj - target)
            direction[:2] += rng.normal(scale=0.08, size=2)
            direction[2] += rng.uniform(0.0, 0.12)
        else:
            direction = rng.normal(size=3)
            direction[2] = abs(direction[2]) + 0.2
        direction /= np.linalg.norm(direction)
        eye = target + distance * direction
        eye[2] = max(eye[2], _MIN_EYE_HEIGHT_M)
        # What CameraSpec.look_at computes, without building (and validating) a spec per frame.
        return eye, look_at_quat_wxyz(eye, target, up)

    def _beyond_near(
        self, scene: Scene, geoms: np.ndarray, eye: np.ndarray, target: np.ndarray
    ) -> np.ndarray | None:
        """The eye moved back along its line of sight until the hand and objects are in range.

        Nothing nearer than the camera's or the sensor's working range gets depth (a
        structured-light sensor measures from 0.35 m): a hand or an occluder there would be a
        hole in the depth image. The bounding boxes of ``geoms`` (the hand's skin meshes and
        every geom of the objects) are kept beyond that range. None when the moved eye would
        be below the table top.
        """
        forward = target - eye
        forward /= np.linalg.norm(forward)
        model, data = scene.model, scene.data
        # The nearest corner of the geoms' bounding boxes (in their geom frames).
        nearest = _kernels.nearest_box_depth(
            model.geom_aabb[geoms], data.geom_xmat[geoms], data.geom_xpos[geoms], eye, forward
        )
        if nearest >= self._near_m:
            return eye
        eye = eye - forward * (self._near_m - nearest)
        return eye if eye[2] >= _MIN_EYE_HEIGHT_M else None

    @staticmethod
    def _near_geoms(scene: Scene) -> np.ndarray:
        """The geoms kept beyond the near range: the hand's skin and every object geom.

        (An object's half diameter around its body origin does not bound every object: the
        extra-large clamp reached 1.4 mm nearer than that.)
        """
        bodies = [scene.model.body(name).id for name, _ in scene.objects]
        objects = np.flatnonzero(np.isin(scene.model.geom_bodyid, bodies))
        return np.concatenate([scene.hand_skin_geom_ids, objects]).astype(np.intp)

    @staticmethod
    def _penetration_m(scene: Scene) -> float:
        """Deepest overlap of a hand geom with an object or the table, metres."""
        data, labels = scene.data, scene.geom_labels
        deepest = 0.0
        for i in range(data.ncon):
            con = data.contact[i]
            hand = [2 <= labels[g] < 8 for g in (con.geom1, con.geom2)]
            if hand[0] != hand[1]:
                deepest = max(deepest, -float(con.dist))
        return deepest

    def episode(
        self, rng: np.random.Generator, accept: Callable[[float], bool], frames: int
    ) -> Iterator[dict[str, np.ndarray]]:
        """Yield the arrays (images included) of ``frames`` accepted frames of one episode.

        Args:
            rng: the episode's generator.
            accept: called with the hand occlusion ratio; False redraws the frame.
            frames: frames to yield.

        Stops early when :data:`MAX_TRIES_PER_FRAME` draws give no accepted frame (the
        episode's hand and objects may not reach the occlusion asked for).
        """
        scene, renderer = self._scene(rng)
        source = str(rng.choice(self.config.pose_sources))
        viewpoints = list(self.config.viewpoints)
        alone = not scene.objects and not scene.spec.table
        near_geoms = self._near_geoms(scene)
        # Postures are drawn a batch at a time (a sampler's cost is mostly per call), a few
        # more than the frames for the draws that are refused.
        batch = frames + 8
        postures, used = self._postures(rng, source, batch), 0
        for _ in range(frames):
            for _ in range(MAX_TRIES_PER_FRAME):
                if used == batch:
                    postures, used = self._postures(rng, source, batch), 0
                view = viewpoints[int(rng.integers(len(viewpoints)))]
                wrist, rotvec, palm, obj = self._wrist(rng, scene, view == "through_object")
                pose = HandPose(wrist, rotvec, postures[used])
                used += 1
                if alone:  # nothing to touch: no contacts to find or label
                    scene.binding.set_pose(scene.data, pose, kinematics_only=True)
                else:  # forwards: the hand placed, its contacts found
                    scene.binding.set_pose(scene.data, pose)
                    if self._penetration_m(scene) > MAX_PENETRATION_M:
                        continue
                arrays = self._view(rng, scene, renderer, view, palm, obj, near_geoms, accept)
                if arrays is not None:
                    yield arrays
                    break
            else:
                return  # this scene cannot give an accepted frame: a new episode may

    def _view(
        self,
        rng: np.random.Generator,
        scene: Scene,
        renderer: FrameRenderer,
        view: str,
        palm: np.ndarray,
        obj: np.ndarray | None,
        near_geoms: np.ndarray,
        accept: Callable[[float], bool],
    ) -> dict[str, np.ndarray] | None:
        """The arrays of the posed hand seen from a drawn camera, or None if refused.

        The camera is drawn for ``view`` around the palm centre ``palm`` (and the object at
        ``obj``, world, m), kept beyond the near range, and the frame rendered; None when the
        camera would be below the table, fewer than :data:`MIN_KEYPOINTS_IN_FRAME` keypoints
        are in the image or ``accept`` refuses the hand occlusion ratio.
        """
        eye, quat = self._camera(rng, view, palm, obj)
        eye = self._beyond_near(scene, near_geoms, eye, palm)
        if eye is None:
            return None
        cam = scene.model.camera("camera").id
        scene.model.cam_pos[cam], scene.model.cam_quat[cam] = eye, quat
        mujoco.mj_camlight(scene.model, scene.data)
        frame = renderer.render(
            rng, keep_clean=self.config.paired_clean, hand_occlusion=bool(scene.objects)
        )
        ratio = frame.hand_occlusion_ratio or 0.0
        if frame.in_frame.sum() < MIN_KEYPOINTS_IN_FRAME or not accept(ratio):
            return None
        arrays = frame_to_arrays(frame)
        arrays["hand_occlusion_ratio"][()] = ratio
        # The frame's own images, not copies: the writer only reads them, and before the
        # next frame is rendered.
        arrays["depth"], arrays["segmentation"] = frame.depth, frame.segmentation
        if frame.depth_clean is not None:
            arrays["depth_clean"] = frame.depth_clean
        return arrays
