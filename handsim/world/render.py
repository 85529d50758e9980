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

import contextlib
import math
import os
import threading
from collections.abc import Iterator, Sequence

import mujoco
import numpy as np
from mujoco import gl_context

from handsim._validate import is_real
from handsim.errors import HandSimError, UnknownName
from handsim.world.camera import CameraIntrinsics

__all__ = ["DepthRenderer", "RENDERED_GEOM_GROUPS", "RenderError", "shared_render_context"]

RENDERED_GEOM_GROUPS: tuple[int, ...] = (0, 1, 2)
"""Geom groups a depth camera sees."""

_OBJ_GEOM = int(mujoco.mjtObj.mjOBJ_GEOM)


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


class _Spare(threading.local):
    """Per thread: open shared_render_context blocks, and a context kept for the next renderer.

    ``spare`` is a closed renderer's OpenGL context and MjrContext, with its model's key.
    """

    depth = 0
    spare: tuple | None = None  # (pid, gl context, MjrContext, key)


_SPARE = _Spare()


def _context_key(model: mujoco.MjModel) -> tuple:
    """What an MjrContext holds of a model besides its meshes' shapes (which are re-uploaded).

    Equal keys: a context made for one model draws the other once its meshes are re-uploaded
    (textures, height fields, skins and flexes would need more, so models with any of them
    never share; planes are drawn from lists sized by their geoms).
    """
    plane = model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE
    vis = model.vis
    return (
        vis.global_.offwidth,
        vis.global_.offheight,
        vis.quality.offsamples,
        vis.quality.numslices,
        vis.quality.numstacks,
        vis.quality.numquads,
        model.nmesh,
        model.ntex + model.nhfield + model.nskin + model.nflex,
        model.geom_size[plane].tobytes(),
    )


def _free_spare() -> None:
    spare, _SPARE.spare = _SPARE.spare, None
    if spare is not None and spare[0] == os.getpid():
        _, gl, context, _ = spare
        if gl is not None:
            gl.make_current()
        context.free()
        if gl is not None:
            gl.free()


@contextlib.contextmanager
def shared_render_context() -> Iterator[None]:
    """Within the block, renderers made one after another in a thread share an OpenGL context.

    A :class:`DepthRenderer` closed in the block keeps its OpenGL context, and its MuJoCo
    render context, for the next one made in the same thread: for a model of the same kind
    (:func:`_context_key`: e.g. another hand size, or other objects with as many meshes) only
    the meshes are uploaded again; otherwise the render context is made anew in the same
    OpenGL context. Images are the same as with separate renderers. For code that makes a
    renderer per scene, e.g. one per dataset episode; what is kept is freed when the block
    ends.
    """
    _SPARE.depth += 1
    try:
        yield
    finally:
        _SPARE.depth -= 1
        if _SPARE.depth == 0:
            _free_spare()


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
        self._key = _context_key(model)
        spare, _SPARE.spare = _SPARE.spare, None
        if spare is not None and spare[0] != os.getpid():
            spare = None  # made before a fork: not this process's to use
        self._geom_scale: tuple[np.ndarray, np.float32] | None = None
        self._gl = _make_gl_context(w, h) if spare is None else spare[1]
        if self._gl is not None:
            self._gl.make_current()
        if spare is not None and spare[3] == self._key:
            self._context = spare[2]
            self.upload_meshes(range(model.nmesh))
        else:
            if spare is not None:
                spare[2].free()
            # No shadow map: depth and segmentation draw no shadows, and allocating MuJoCo's
            # default 4096 x 4096 one is most of a context's cost (~35 ms of ~45 ms).
            shadow_size = model.vis.quality.shadowsize
            model.vis.quality.shadowsize = 0
            try:
                self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
            finally:
                model.vis.quality.shadowsize = shadow_size
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        # Reversed Z (0 = far) keeps depth precise far from the camera.
        self._context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        # Room for every geom and site several times over (decor is off); a 10 000-geom scene
        # costs ~10 ms to allocate, a lot for a renderer made per episode.
        self._scene = mujoco.MjvScene(model, maxgeom=max(1000, 4 * (model.ngeom + model.nsite)))
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
        self._lut = np.empty(256, dtype=np.int32)  # segmentation colour index -> geom id
        self._lut_key: tuple | None = None
        self._red: np.ndarray | None = None
        self._index_table_key: tuple | None = None
        self._index_table_cache = np.empty(0)
        extent = model.stat.extent
        near = np.float32(model.vis.map.znear * extent)
        far = np.float32(model.vis.map.zfar * extent)
        # OpenGL perspective depth, remapped for reversed Z: metric = d / (buffer + c).
        self._c = np.float32(-0.5) * (-(far + near) / (far - near)) - np.float32(0.5)
        self._d = np.float32(-0.5) * (-(np.float32(2) * far * near) / (far - near))

    def upload_meshes(self, mesh_ids: Sequence[int]) -> None:
        """Upload meshes again after their vertices changed in the model (e.g. a rescaled hand).

        Args:
            mesh_ids: mesh indices in the model.

        The meshes are then drawn as uploaded: a :meth:`scale_geoms` factor is dropped.
        """
        if self._context is None:
            raise RenderError("upload_meshes() called after close()")
        if self._gl is not None:
            self._gl.make_current()
        for mesh in mesh_ids:
            mujoco.mjr_uploadMesh(self.model, self._context, int(mesh))
        self._geom_scale = None

    def scale_geoms(self, geom_ids: Sequence[int], factor: float) -> None:
        """Draw mesh geoms scaled by ``factor`` about their own frames, from now on.

        Meshes whose vertices were scaled in the model by ``factor`` since their upload (a
        rescaled hand, :meth:`Scene.set_hand_length
        <handsim.world.scene.Scene.set_hand_length>`) then draw as uploaded again would, without
        the upload (tens of milliseconds for a hand's skin): the factor goes into each geom's
        drawn rotation matrix. Depth and segmentation use no normals, so this is exact up to
        float32 rounding. ``factor = 1`` draws them as uploaded.

        Args:
            geom_ids: mesh geom indices in the model (the others keep their scale).
            factor: positive scale factor relative to the uploaded vertices.

        Raises:
            RenderError: for a factor that is not a positive finite number or a geom index
                outside the model.
        """
        if not is_real(factor) or not 0.0 < float(factor) < math.inf:
            raise RenderError(f"scale_geoms: factor must be a positive number; received {factor!r}")
        ids = np.asarray(geom_ids, dtype=int).reshape(-1)
        if ids.size and (ids.min() < 0 or ids.max() >= self.model.ngeom):
            raise RenderError(
                f"scale_geoms: geom ids must be in [0, {self.model.ngeom}); received "
                f"{ids.min()}..{ids.max()}"
            )
        mask = np.zeros(self.model.ngeom, dtype=bool)
        mask[ids] = True
        self._geom_scale = (mask, np.float32(factor)) if factor != 1.0 and mask.any() else None

    def _draw(self, data: mujoco.MjData) -> None:
        if self._context is None:
            raise RenderError("render() called after close()")
        if self._gl is not None:
            self._gl.make_current()
        mujoco.mjv_updateScene(
            self.model, data, self._option, None, self._camera,
            mujoco.mjtCatBit.mjCAT_ALL, self._scene,
        )  # fmt: skip
        if self._geom_scale is not None:
            mask, factor = self._geom_scale
            for g in self._scene.geoms[: self._scene.ngeom]:
                if g.objtype == _OBJ_GEOM and mask[g.objid]:
                    g.mat *= factor
        mujoco.mjr_render(self._rect, self._scene, self._context)

    def _segment_lut(self) -> np.ndarray:
        """Geom id of each segmentation colour index (``segid + 1``; 0 = background -> -1).

        ``mjv_updateScene`` adds the visible geoms in model order, so the table changes only
        with what decides visibility (geom groups, transparency, materials) or the number of
        scene geoms: it is rebuilt then (reading the scene's geoms costs about 40 us a frame),
        and also when the scene's first or last geom is not the one the table says.
        """
        model, scene = self.model, self._scene
        ngeom = scene.ngeom
        key = (
            ngeom,
            model.geom_group.tobytes(),
            model.geom_rgba[:, 3].tobytes(),
            model.geom_matid.tobytes(),
            model.mat_rgba[:, 3].tobytes(),
        )
        lut = self._lut
        if key == self._lut_key and ngeom:
            geoms = scene.geoms
            ends = (geoms[0], geoms[ngeom - 1])
            if all(lut[g.segid + 1] == (g.objid if g.objtype == _OBJ_GEOM else -1) for g in ends):
                return lut
        if len(lut) < ngeom + 1:
            lut = self._lut = np.empty(ngeom + 1, dtype=np.int32)
        lut.fill(-1)
        for g in scene.geoms[:ngeom]:
            if g.segid >= 0 and g.objtype == _OBJ_GEOM:
                lut[g.segid + 1] = g.objid
        self._lut_key = key
        return lut

    def _colour_index(self, rgb_bottom_up: np.ndarray) -> np.ndarray:
        """Top-down (H, W) segmentation colour index: uint8 below 255 scene geoms, else int32."""
        # The offscreen buffer is bottom-up.
        rgb = rgb_bottom_up[::-1]
        if self._scene.ngeom < 255:
            # Segmentation colour = segid + 1 in the red byte.
            if self._red is None or self._red.shape != rgb.shape[:2]:
                self._red = np.empty(rgb.shape[:2], dtype=np.uint8)
            np.copyto(self._red, rgb[..., 0])
            return self._red
        return (
            rgb[..., 0].astype(np.int32)
            | (rgb[..., 1].astype(np.int32) << 8)
            | (rgb[..., 2].astype(np.int32) << 16)
        )

    def _geom_ids(
        self,
        rgb_bottom_up: np.ndarray,
        out: np.ndarray | None = None,
        geom_values: np.ndarray | None = None,
        fill: int = -1,
    ) -> np.ndarray:
        lut = self._segment_lut()
        if geom_values is not None:
            values = np.append(geom_values, fill).astype(geom_values.dtype)
            lut = values[lut]  # geom id -1 -> the appended fill value
        index = self._colour_index(rgb_bottom_up)
        if index.dtype == np.uint8:
            import cv2

            # A 256-entry table in OpenCV: a third of the cost of numpy's take.
            table = np.full(256, fill, dtype=lut.dtype)
            table[: len(lut)] = lut
            if out is None:
                return cv2.LUT(index, table)
            cv2.LUT(index, table, dst=out)
            return out
        return np.take(lut, np.minimum(index, len(lut) - 1), out=out)

    def render(
        self,
        data: mujoco.MjData,
        out: tuple[np.ndarray, np.ndarray] | None = None,
        *,
        geom_values: np.ndarray | None = None,
        fill: int = -1,
        depth_range_m: tuple[float, float] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Render the current state.

        Args:
            data: simulation data (positions up to date, e.g. after ``mj_forward``).
            out: ``(depth_m, geom_id)`` arrays to write into ((H, W) float32 and (H, W) int32,
                or ``geom_values``' dtype; C-contiguous), e.g. buffers reused every frame;
                default: new arrays.
            geom_values: (ngeom,) integer values (e.g. segmentation labels) to give instead of
                geom ids: the second image is ``geom_values[geom id]``, ``fill`` on background.
            fill: the second image's value on background (no geom), with ``geom_values``.
            depth_range_m: ``(near, far)``: pixels whose depth is outside ``[near, far]``
                (float32 compares) are given depth 0 and the background's value, as if no
                geom were seen there (e.g. a sensor's working range). Default: every depth.

        Returns:
            ``(depth_m, geom_id)``: (H, W) float32 depth along the optical axis, metres, 0 where
            no geom is seen; (H, W) int32 geom id, -1 for background, or the ``geom_values``
            image (``out`` when given).
        """
        self._draw(data)
        mujoco.mjr_readPixels(self._rgb, self._zbuffer, self._rect, self._context)
        if out is None:
            dtype = np.int32 if geom_values is None else geom_values.dtype
            out = (np.empty_like(self._zbuffer), np.empty(self._zbuffer.shape, dtype=dtype))
        depth_m, ids = out
        near_m, far_m = (0.0, np.inf) if depth_range_m is None else depth_range_m
        if self._scene.ngeom < 255:
            # Colour index = segid + 1 in the red byte: one compiled pass does it all.
            table = self._index_table(geom_values, fill, ids.dtype)
            # numba loads on the first render, not on `import handsim`.
            from handsim.world import _kernels

            _kernels.depth_and_labels(
                self._rgb, self._zbuffer, self._c, self._d, table,
                np.float32(near_m), np.float32(far_m), depth_m, ids,
            )  # fmt: skip
            return depth_m, ids
        self._geom_ids(self._rgb, out=ids, geom_values=geom_values, fill=fill)
        import cv2

        # float32 is enough: the relative rounding error is ~1e-7 (0.2 um at 1.5 m). Flipping
        # first keeps every pass on contiguous rows.
        cv2.flip(self._zbuffer, 0, dst=depth_m)
        np.add(depth_m, self._c, out=depth_m)
        np.divide(self._d, depth_m, out=depth_m)
        background = ~np.greater_equal(self._geom_ids(self._rgb), 0)
        if depth_range_m is not None:
            background |= depth_m < np.float32(near_m)
            background |= depth_m > np.float32(far_m)
            ids[background] = fill if geom_values is not None else -1
        depth_m[background] = 0.0
        return depth_m, ids

    def _index_table(
        self, geom_values: np.ndarray | None, fill: int, dtype: np.dtype
    ) -> np.ndarray:
        """(256,) value of each segmentation colour index (fewer than 255 scene geoms).

        Kept while the colour-to-geom table, the values and the fill are the same.
        """
        lut = self._segment_lut()
        values = None if geom_values is None else geom_values.tobytes()
        key = (lut.tobytes(), values, fill, np.dtype(dtype))
        if key != self._index_table_key:
            if geom_values is not None:
                lut = np.append(geom_values, fill).astype(geom_values.dtype)[lut]
            table = np.full(256, fill if geom_values is not None else -1, dtype=dtype)
            table[: len(lut)] = lut
            self._index_table_key, self._index_table_cache = key, table
        return self._index_table_cache

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

    def render_segmentation_canvas(
        self, data: mujoco.MjData, region: tuple[int, int, int, int]
    ) -> np.ndarray:
        """The geom-id image of a pixel box that may reach beyond the image.

        The image's pixel grid continues beyond its borders, as on a larger sensor with the
        same intrinsics (BOP renders an object on a canvas three times the image's size with
        the principal point shifted to see its whole silhouette). A box inside the image is
        one ordinary render; otherwise the box is cut into windows of at most the image's size
        (one for a box no larger than the image), each rendered with the camera's principal
        point shifted by a whole number of pixels so that the window falls on the image: pixel
        ``(u, v)`` of the canvas is then what a sensor that large would see there.

        Args:
            data: simulation data.
            region: ``(u0, v0, u1, v1)`` pixel box, end exclusive, in image pixel coordinates
                (negative or past the image size outside it).

        Returns:
            (v1 - v0, u1 - u0) int32 geom ids, -1 for background.
        """
        w, h = self.intrinsics.width, self.intrinsics.height
        u0, v0, u1, v1 = (int(x) for x in region)
        if u1 <= u0 or v1 <= v0:
            return np.full((max(v1 - v0, 0), max(u1 - u0, 0)), -1, dtype=np.int32)
        if u0 >= 0 and v0 >= 0 and u1 <= w and v1 <= h:
            return self.render_segmentation(data, region)
        out = np.empty((v1 - v0, u1 - u0), dtype=np.int32)
        intrinsic = self.model.cam_intrinsic[self.camera_id]
        saved = intrinsic.copy()
        # The principal point in the model is in sensor units (metres): pixel pitch per axis.
        pitch = self.model.cam_sensorsize[self.camera_id] / (w, h)
        try:
            for ov in range(v0, v1, h):
                for ou in range(u0, u1, w):
                    # Principal pixel + o shows canvas pixel u' + o at image pixel u'.
                    intrinsic[2] = saved[2] + ou * pitch[0]
                    intrinsic[3] = saved[3] + ov * pitch[1]
                    cw, ch = min(w, u1 - ou), min(h, v1 - ov)
                    tile = self.render_segmentation(data, (0, 0, cw, ch))
                    out[ov - v0 : ov - v0 + ch, ou - u0 : ou - u0 + cw] = tile
        finally:
            intrinsic[:] = saved
        return out

    def close(self) -> None:
        """Free the OpenGL context (idempotent); in :func:`shared_render_context`, keep it."""
        if self._context is not None and _SPARE.depth > 0:
            _free_spare()
            _SPARE.spare = (os.getpid(), self._gl, self._context, self._key)
            self._context = self._gl = None
            return
        if self._context is not None:
            # MjrContext.free deletes GL objects by name in the *current* context: make ours
            # current, or another renderer's framebuffer and meshes (same names) are deleted.
            if self._gl is not None:
                self._gl.make_current()
            self._context.free()
            self._context = None
        if self._gl is not None:
            self._gl.free()
            self._gl = None

    def __enter__(self) -> DepthRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
