"""The capture scene of camera mode: a render-only operator hand seen by the capture camera.

The operator hand lives in a scene of its own (nothing in it collides with the task); the task's
objects are mirrored into it every step, so they occlude it. It is posed from the stream
(27-DoF poses directly; keypoint streams are first retargeted onto it) and rendered with the
sensor model; :class:`CaptureFrame` is what the estimator (and an oracle) receives.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import mujoco
import numpy as np

from handsim.errors import InvalidKeypoints
from handsim.hand.model import hand_params
from handsim.hand.pose import HandPose
from handsim.hand.retarget import Retargeter

__all__ = ["CaptureFrame", "Capture", "world_from_cam"]


def world_from_cam(T_cam_from_world: np.ndarray, points_cam: np.ndarray) -> np.ndarray:  # noqa: N803
    """(N, 3) points, camera frame -> world frame (``T_cam_from_world`` (4, 4))."""
    R, t = T_cam_from_world[:3, :3], T_cam_from_world[:3, 3]  # noqa: N806
    return (points_cam - t) @ R


@dataclasses.dataclass(frozen=True)
class CaptureFrame:
    """One capture of the operator hand: what an estimator (and an oracle) receives.

    Attributes:
        depth: (H, W) float32 depth with the sensor model, metres, 0 = no measurement.
        K: (3, 3) intrinsics.
        T_cam_from_world: (4, 4) the capture camera's extrinsics.
        keypoints_cam: (21, 3) the operator hand's true keypoints, camera frame, metres.
        objects: empty (the oracle's object truths; the teleop loop estimates the hand only).
    """

    depth: np.ndarray
    K: np.ndarray  # noqa: N815
    T_cam_from_world: np.ndarray  # noqa: N815
    keypoints_cam: np.ndarray
    objects: tuple = ()


class Capture:
    """The capture scene: a render-only operator hand (and the task's objects) and a camera."""

    def __init__(self, env: Any, operator_length_m: float, side: str, config: Any):
        from handsim.world.camera import T_cam_from_world, camera_preset
        from handsim.world.render import DepthRenderer
        from handsim.world.scene import Scene, SceneSpec, third_person_camera
        from handsim.world.sensors import sensor_model

        base = env.unwrapped
        placements = tuple(getattr(base.scene.spec, "objects", ()))
        camera = third_person_camera(camera_preset(config.camera), name="camera")
        self.scene = Scene(
            SceneSpec(
                hand=hand_params(operator_length_m, side),
                objects=placements,
                cameras=(camera,),
                table=True,
            )
        )
        self.intrinsics = camera.intrinsics
        self.renderer = DepthRenderer(self.scene.model, "camera", self.intrinsics)
        self.sensor = sensor_model(config.sensor)
        self.K = self.intrinsics.K.copy()
        mujoco.mj_forward(self.scene.model, self.scene.data)
        self.T_cam_from_world = T_cam_from_world(self.scene.data, self.renderer.camera_id)
        self._range = tuple(np.float32(r) for r in self.intrinsics.range_m)
        self.retargeter = Retargeter(self.scene.hand.params)
        self.camera_pos_m = np.asarray(camera.pos_m, dtype=np.float64)
        # Mirrored objects: (qpos address in the task, qpos address here).
        self._objects = []
        for (body, _), (body2, _) in zip(base.scene.objects, self.scene.objects, strict=True):
            m1, m2 = base.scene.model, self.scene.model
            self._objects.append(
                (
                    int(m1.jnt_qposadr[m1.body(body).jntadr[0]]),
                    int(m2.jnt_qposadr[m2.body(body2).jntadr[0]]),
                )
            )
        self._previous: HandPose | None = None
        self._scale: float | None = None

    def pose_operator(self, pose: np.ndarray | None, keypoints: np.ndarray, task_data: Any) -> None:
        """Pose the operator hand (a 27-vector, or retargeted keypoints) among the objects."""
        scene = self.scene
        for a, b in self._objects:
            scene.data.qpos[b : b + 7] = task_data.qpos[a : a + 7]
        if pose is None:
            try:
                result = self.retargeter(
                    keypoints,
                    initial=self._previous,
                    check_side=False,
                    initial_scale=self._scale,
                    report_clamped=False,
                )
            except InvalidKeypoints:  # too few tracked joints: the operator hand holds still
                if self._previous is None:
                    return
                hand_pose = self._previous
            else:
                self._previous, self._scale = result.pose, result.scale
                hand_pose = result.pose
        else:
            hand_pose = HandPose.from_vector(pose)
        scene.binding.set_pose(scene.data, hand_pose)

    def reset(self) -> None:
        """Start an episode: the operator hand's retargeting starts cold."""
        self._previous, self._scale = None, None

    def render(self, rng: np.random.Generator) -> CaptureFrame:
        """Depth of the posed operator hand with the sensor model, and its truth."""
        depth, _ = self.renderer.render(self.scene.data)
        near, far = self._range
        depth[(depth < near) | (depth > far)] = 0.0
        depth = self.sensor.apply(depth, self.intrinsics, rng)
        T = self.T_cam_from_world  # noqa: N806
        kp = self.scene.binding.keypoints(self.scene.data) @ T[:3, :3].T + T[:3, 3]
        return CaptureFrame(depth, self.K, T, kp)

    def close(self) -> None:
        """Free the renderer."""
        self.renderer.close()
