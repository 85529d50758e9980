"""Depth and segmentation rendering from a MuJoCo camera, in the OpenCV convention.

One :class:`DepthRenderer` per (model, camera) holds one offscreen OpenGL context and is reused
for every frame. Depth is float32 metres along the optical axis (``0.0`` = no surface); the
segmentation is the MuJoCo geom id seen at each pixel (``-1`` = background). Cameras render the
geom groups in :data:`RENDERED_GEOM_GROUPS`: the visual geoms (group 2) and scene geometry (groups
0 and 1), never the hand's collision geoms (group 3). Headless rendering needs
``MUJOCO_GL=egl`` (``import handsim`` sets it when there is no display).
"""

from __future__ import annotations

import mujoco
import numpy as np

from handsim.camera import CameraIntrinsics
from handsim.errors import HandSimError, UnknownName

__all__ = ["DepthRenderer", "RENDERED_GEOM_GROUPS", "RenderError"]

RENDERED_GEOM_GROUPS: tuple[int, ...] = (0, 1, 2)
"""Geom groups a depth camera sees."""


class RenderError(HandSimError, RuntimeError):
    """The renderer cannot be created for this model and camera."""


class DepthRenderer:
    """Renders depth and geom segmentation of one camera.

    Args:
        model: compiled model containing the camera.
        camera: camera name.
        intrinsics: the camera's intrinsics (they set the image size); the camera must have
            been added with :func:`handsim.camera.add_camera` using the same intrinsics.

    Raises:
        UnknownName: if the camera is not in the model (the message lists the cameras).
        RenderError: if the model's offscreen buffer is smaller than the image.
    """

    def __init__(self, model: mujoco.MjModel, camera: str, intrinsics: CameraIntrinsics) -> None:
        names = [model.camera(i).name for i in range(model.ncam)]
        if camera not in names:
            raise UnknownName(
                f"camera {camera!r} is not in the model; cameras: {', '.join(names) or 'none'}"
            )
        w, h = intrinsics.width, intrinsics.height
        if model.vis.global_.offwidth < w or model.vis.global_.offheight < h:
            raise RenderError(
                f"the model's offscreen buffer is {model.vis.global_.offwidth} x "
                f"{model.vis.global_.offheight} pixels but the camera needs {w} x {h}; set "
                f"spec.visual.global_.offwidth = {w} and offheight = {h} before compiling"
            )
        self.model = model
        self.camera = camera
        self.camera_id = int(model.camera(camera).id)
        self.intrinsics = intrinsics
        self._renderer = mujoco.Renderer(model, h, w)
        self._option = mujoco.MjvOption()
        self._option.geomgroup[:] = 0
        self._option.geomgroup[list(RENDERED_GEOM_GROUPS)] = 1
        self._option.sitegroup[:] = 0

    def render(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Render the current state.

        Args:
            data: simulation data (positions up to date, e.g. after ``mj_forward``).

        Returns:
            ``(depth_m, geom_id)``: (H, W) float32 depth along the optical axis, metres, 0 where
            no geom is seen; (H, W) int32 geom id, -1 for background.
        """
        r = self._renderer
        r.update_scene(data, camera=self.camera_id, scene_option=self._option)
        r.enable_segmentation_rendering()
        seg = r.render()
        r.disable_segmentation_rendering()
        r.enable_depth_rendering()
        depth = r.render()
        r.disable_depth_rendering()
        is_geom = seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM
        geom_id = np.where(is_geom, seg[..., 0], -1).astype(np.int32)
        depth_m = np.where(is_geom, depth, 0.0).astype(np.float32)
        return depth_m, geom_id

    def close(self) -> None:
        """Free the OpenGL context."""
        self._renderer.close()

    def __enter__(self) -> DepthRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
