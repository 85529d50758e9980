"""Depth and segmentation rendering from a MuJoCo camera, in the OpenCV convention.

One :class:`DepthRenderer` per (model, camera) holds one offscreen OpenGL context and is reused
for every frame; depth and segmentation come from the same draw (MuJoCo's segmentation colours
in the colour buffer, metric depth from the depth buffer). Depth is float32 metres along the
optical axis (``0.0`` = no surface); the segmentation is the MuJoCo geom id seen at each pixel
(``-1`` = background). Cameras render the geom groups in :data:`RENDERED_GEOM_GROUPS`: the
visual geoms (group 2) and scene geometry (groups 0 and 1), never the hand's collision geoms
(group 3). Headless rendering needs ``MUJOCO_GL=egl`` (``import handsim`` sets it when there is
no display).
"""

from __future__ import annotations

import os

import mujoco
import numpy as np
from mujoco import gl_context

from handsim.errors import HandSimError, UnknownName
from handsim.world.camera import CameraIntrinsics

__all__ = ["DepthRenderer", "RENDERED_GEOM_GROUPS", "RenderError"]

RENDERED_GEOM_GROUPS: tuple[int, ...] = (0, 1, 2)
"""Geom groups a depth camera sees."""


class RenderError(HandSimError, RuntimeError):
    """The renderer cannot be created for this model and camera."""


def _make_gl_context(width: int, height: int) -> object | None:
    """An offscreen OpenGL context: MuJoCo's choice, or EGL when that needs a missing display.

    MuJoCo picks its backend (``MUJOCO_GL``) when it is first imported; a program that imports
    mujoco before handsim on a headless machine gets GLFW, which needs a display.
    """
    if gl_context.GLContext is None:
        return None
    glfw_without_display = (
        gl_context.GLContext.__module__.startswith("mujoco.glfw")
        and not os.environ.get("DISPLAY")
        and not os.environ.get("WAYLAND_DISPLAY")
    )
    if glfw_without_display:
        from mujoco.egl import GLContext as EGLContext

        return EGLContext(width, height)
    return gl_context.GLContext(width, height)


class DepthRenderer:
    """Renders depth and geom segmentation of one camera in a single OpenGL pass.

    Args:
        model: compiled model containing the camera.
        camera: camera name.
        intrinsics: the camera's intrinsics (they set the image size); the camera must have
            been added with :func:`handsim.world.camera.add_camera` using the same intrinsics.

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
        self._gl = _make_gl_context(w, h)
        if self._gl is not None:
            self._gl.make_current()
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        # Reversed Z (0 = far) keeps depth precise far from the camera.
        self._context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=10_000)
        # One pass gives both: geoms are drawn in their segmentation id colours.
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
        self._scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = self.camera_id
        self._option = mujoco.MjvOption()
        self._option.geomgroup[:] = 0
        self._option.geomgroup[list(RENDERED_GEOM_GROUPS)] = 1
        self._option.sitegroup[:] = 0
        self._rect = mujoco.MjrRect(0, 0, w, h)
        self._rgb = np.empty((h, w, 3), dtype=np.uint8)
        self._zbuffer = np.empty((h, w), dtype=np.float32)
        self._background = np.empty((h, w), dtype=bool)
        self._lut = np.empty(256, dtype=np.int32)  # segmentation colour -> geom id
        extent = model.stat.extent
        near = np.float32(model.vis.map.znear * extent)
        far = np.float32(model.vis.map.zfar * extent)
        # OpenGL perspective depth, remapped for reversed Z: metric = d / (buffer + c).
        self._c = np.float32(-0.5) * (-(far + near) / (far - near)) - np.float32(0.5)
        self._d = np.float32(-0.5) * (-(np.float32(2) * far * near) / (far - near))

    def _draw(self, data: mujoco.MjData) -> None:
        if self._context is None:
            raise RenderError("render() called after close()")
        if self._gl is not None:
            self._gl.make_current()
        mujoco.mjv_updateScene(
            self.model, data, self._option, None, self._camera,
            mujoco.mjtCatBit.mjCAT_ALL, self._scene,
        )  # fmt: skip
        mujoco.mjr_render(self._rect, self._scene, self._context)

    def _geom_ids(self, rgb_bottom_up: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        # The offscreen buffer is bottom-up.
        rgb = rgb_bottom_up[::-1]
        ngeom = self._scene.ngeom
        lut = self._lut
        if len(lut) < ngeom + 1:
            lut = self._lut = np.empty(ngeom + 1, dtype=np.int32)
        lut.fill(-1)
        for g in self._scene.geoms[:ngeom]:
            if g.segid >= 0 and g.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                lut[g.segid + 1] = g.objid
        if ngeom < 255:
            # Segmentation colour = segid + 1 in the red byte; one uint8 gather suffices.
            return np.take(lut, rgb[..., 0], out=out)
        segid = (
            rgb[..., 0].astype(np.int32)
            | (rgb[..., 1].astype(np.int32) << 8)
            | (rgb[..., 2].astype(np.int32) << 16)
        )  # 0 = background
        return np.take(lut, np.minimum(segid, len(lut) - 1), out=out)

    def render(
        self, data: mujoco.MjData, out: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Render the current state.

        Args:
            data: simulation data (positions up to date, e.g. after ``mj_forward``).
            out: ``(depth_m, geom_id)`` arrays to write into ((H, W) float32 and (H, W) int32,
                C-contiguous), e.g. buffers reused every frame; default: new arrays.

        Returns:
            ``(depth_m, geom_id)``: (H, W) float32 depth along the optical axis, metres, 0 where
            no geom is seen; (H, W) int32 geom id, -1 for background (``out`` when given).
        """
        self._draw(data)
        mujoco.mjr_readPixels(self._rgb, self._zbuffer, self._rect, self._context)
        if out is None:
            out = (np.empty_like(self._zbuffer), np.empty(self._zbuffer.shape, dtype=np.int32))
        depth_m, geom_id = out
        self._geom_ids(self._rgb, out=geom_id)
        # float32 is enough: the relative rounding error is ~1e-7 (0.2 um at 1.5 m).
        np.add(self._zbuffer[::-1], self._c, out=depth_m)
        np.divide(self._d, depth_m, out=depth_m)
        np.less(geom_id, 0, out=self._background)
        np.copyto(depth_m, np.float32(0.0), where=self._background)
        return depth_m, geom_id

    def render_segmentation(
        self, data: mujoco.MjData, region: tuple[int, int, int, int] | None = None
    ) -> np.ndarray:
        """Only the geom-id image (cheaper: the depth buffer is not read).

        Args:
            data: simulation data.
            region: ``(u0, v0, u1, v1)`` pixel box to read (end exclusive, clipped to the
                image); default: the whole image. Reading less is faster.

        Returns:
            (v1 - v0, u1 - u0) int32 geom ids of the region, -1 for background.
        """
        w, h = self.intrinsics.width, self.intrinsics.height
        u0, v0, u1, v1 = (0, 0, w, h) if region is None else region
        u0, u1 = max(0, u0), min(w, u1)
        v0, v1 = max(0, v0), min(h, v1)
        if u1 <= u0 or v1 <= v0:
            return np.full((max(v1 - v0, 0), max(u1 - u0, 0)), -1, dtype=np.int32)
        self._draw(data)
        rgb = np.empty((v1 - v0, u1 - u0, 3), dtype=np.uint8)
        # MjrRect counts rows from the bottom of the image.
        rect = mujoco.MjrRect(u0, h - v1, u1 - u0, v1 - v0)
        mujoco.mjr_readPixels(rgb, None, rect, self._context)
        return self._geom_ids(rgb)

    def close(self) -> None:
        """Free the OpenGL context (idempotent)."""
        if self._context is not None:
            self._context.free()
            self._context = None
        if self._gl is not None:
            self._gl.free()
            self._gl = None

    def __enter__(self) -> DepthRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
