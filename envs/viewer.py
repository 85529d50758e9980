"""``render()`` for people: a viewer camera that frames the hand and the objects.

:class:`ViewerRendering` is the part of :class:`~handsim.envs.base.HandSimEnv` (a base class of
it) that draws the ``render_mode`` images: ``rgb_array``, ``depth_array``, ``depth_rgb_array``
and the ``human`` viewer window, from a free camera aimed at each reset at the hand, the objects
and the room above them. It is not the depth sensor, whose frames are the observation.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import cv2
import mujoco
import numpy as np

__all__ = ["ViewerRendering", "depth_colormap"]

_DEPTH_RENDER_MODES = ("depth_array", "depth_rgb_array")

_VIEWER_AZIMUTH_DEG = 150.0
_VIEWER_ELEVATION_DEG = -25.0
_VIEWER_LIFT_MARGIN_M = 0.12
"""Room framed above the objects (a lift is 0.10 m), metres."""
_SHADOW_LIGHT = "key"
"""The one light that casts shadows in ``render()`` (each shadow is one more pass)."""


def depth_colormap(depth_m: np.ndarray, near_m: float, far_m: float) -> np.ndarray:
    """Colour-map depth for people: near red, far blue (turbo), no surface black.

    Args:
        depth_m: (H, W) depth, metres (0 or beyond ``far_m``: no surface shown).
        near_m: depth shown red, metres.
        far_m: depth shown dark blue, metres.

    Returns:
        (H, W, 3) uint8 RGB image.
    """
    t = (far_m - depth_m) / max(far_m - near_m, 1e-6)
    index = np.clip(t * 255.0, 0, 255).astype(np.uint8)
    rgb = cv2.applyColorMap(index, cv2.COLORMAP_TURBO)[..., ::-1]
    rgb[(depth_m <= 0) | (depth_m > far_m)] = 0
    return np.ascontiguousarray(rgb)


class ViewerRendering:
    """The ``render()`` of :class:`~handsim.envs.base.HandSimEnv` (a base class of it).

    It uses the env's ``scene``, ``config``, ``render_mode`` and ``_own_process``, and keeps
    ``_rgb_renderer``, ``_viewer``, ``_viewer_camera`` and ``_viewer_range_m``, which
    :class:`~handsim.envs.base.HandSimEnv` sets up.
    """

    def _frame_viewer(self) -> None:
        """Aim the viewer camera at the hand and the objects (once per episode, at reset).

        The camera looks from the user's right, 25 deg down, at the centre of the hand's
        keypoints, the objects' boxes and the room above them for a lift, from a distance at
        which all of it fits the vertical field of view.
        """
        scene, data = self.scene, self.scene.data
        keypoints = scene.binding.keypoints(data)
        # The forearm stub behind the wrist (keypoint 0), away from the middle MCP (9).
        back = keypoints[0] - keypoints[9]
        forearm = keypoints[0] + 0.1 * back / max(float(np.linalg.norm(back)), 1e-9)
        points = [keypoints, forearm[None]]
        for body, obj in scene.objects:
            b = scene.model.body(body).id
            corners = obj.corners_m @ data.xmat[b].reshape(3, 3).T + data.xpos[b]
            points += [corners, corners + [0.0, 0.0, _VIEWER_LIFT_MARGIN_M]]
        points = np.concatenate(points)
        lo, hi = points.min(axis=0), points.max(axis=0)
        center = (lo + hi) / 2
        radius = max(float(np.linalg.norm(hi - lo)) / 2, 0.08)
        aspect = self.config.render_width / self.config.render_height
        half_fov = np.deg2rad(scene.model.vis.global_.fovy) / 2
        half_fov = min(half_fov, np.arctan(np.tan(half_fov) * aspect))
        distance = 1.1 * radius / np.sin(half_fov)
        camera = mujoco.MjvCamera()
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        camera.lookat[:] = center
        camera.distance = distance
        camera.azimuth = _VIEWER_AZIMUTH_DEG
        camera.elevation = _VIEWER_ELEVATION_DEG
        self._viewer_camera = camera
        self._viewer_range_m = (max(distance - 1.5 * radius, 0.01), distance + 1.5 * radius)

    @contextlib.contextmanager
    def viewer_clip_planes(self) -> Iterator[None]:
        """Within the block, OpenGL's clip planes span the viewer camera's range.

        The scene's clip planes follow the depth sensor's working range (a 320 x 240 ICVL
        sensor sees up to 1 m), which would cut what the viewer camera, further away, shows.
        """
        vis = self.scene.model.vis.map
        extent = self.scene.model.stat.extent
        saved = (vis.znear, vis.zfar)
        near_m, far_m = self._viewer_range_m
        vis.znear, vis.zfar = min(saved[0], near_m / extent), max(saved[1], far_m / extent)
        try:
            yield
        finally:
            vis.znear, vis.zfar = saved

    def render(self) -> np.ndarray | None:
        """Render by ``render_mode``, from a viewer camera that frames the hand and the objects.

        The viewer camera is aimed at each reset (:meth:`_frame_viewer`); it is not the
        depth sensor.

        Returns:
            ``rgb_array``: ``(render_height, render_width, 3)`` uint8 colour image (no
            reflections; no shadows with ``render_quality="fast"``, the default; with
            ``"high"`` one light casts shadows, with a shadow map about half the image size);
            ``depth_array``: ``(render_height, render_width)`` float32 depth of the viewer camera,
            metres along its optical axis, ``0.0`` where no surface was hit (Gymnasium's
            convention: a 2-D array); ``depth_rgb_array``: that depth colour-mapped for people
            and videos, ``(render_height, render_width, 3)`` uint8 (:func:`depth_colormap`: near
            red, far blue, no surface black); ``human``: ``None`` (updates the viewer window).
        """
        if self.render_mode is None or self.scene is None:
            return None
        self._own_process()
        if self.render_mode == "human":
            if self._viewer is None:
                from mujoco import viewer

                self._viewer = viewer.launch_passive(self.scene.model, self.scene.data)
            self._viewer.sync()
            return None
        if self._rgb_renderer is None:
            model = self.scene.model
            w, h = self.config.render_width, self.config.render_height
            model.vis.global_.offwidth = max(model.vis.global_.offwidth, w)
            model.vis.global_.offheight = max(model.vis.global_.offheight, h)
            shadows = self.render_mode == "rgb_array" and self.config.render_quality == "high"
            if shadows:
                # Cheap shadows (software GL pays per pixel and per pass): one shadow-casting
                # light, a shadow map about half the image size (MuJoCo's default is 4096).
                model.vis.quality.shadowsize = int(
                    np.clip(2 ** int(np.ceil(np.log2(max(w, h)))) // 2, 256, 2048)
                )
                for light in range(model.nlight):
                    model.light_castshadow[light] = model.light(light).name == _SHADOW_LIGHT
            self._rgb_renderer = mujoco.Renderer(model, h, w)
            # No reflection pass; the shadow pass only for high-quality colour (depth needs no
            # lighting). The depth sensor's renderer draws neither.
            flags = self._rgb_renderer.scene.flags
            flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
            flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
            if self.render_mode in _DEPTH_RENDER_MODES:
                self._rgb_renderer.enable_depth_rendering()
        with self.viewer_clip_planes():
            self._rgb_renderer.update_scene(self.scene.data, camera=self._viewer_camera)
            image = self._rgb_renderer.render()
            far_m = float(self.scene.model.vis.map.zfar * self.scene.model.stat.extent)
        if self.render_mode in _DEPTH_RENDER_MODES:
            # MuJoCo returns the far clip plane where nothing was hit; handsim's depth says 0.
            image[image >= far_m * (1.0 - 1e-5)] = 0.0
        if self.render_mode == "depth_rgb_array":
            return depth_colormap(image, *self._viewer_range_m)
        return image

    def _close_rgb(self) -> None:
        self._own_process()
        if self._rgb_renderer is not None:
            self._rgb_renderer.close()
            self._rgb_renderer = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
