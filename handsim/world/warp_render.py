"""Batched depth and geom segmentation with MuJoCo Warp's ray-cast renderer.

:class:`WarpDepthRenderer` renders one camera of a compiled model in N worlds per launch, on a
CUDA device or (slowly) on the CPU, and gives what :class:`~handsim.world.render.DepthRenderer`
gives for one: depth along the optical axis in metres (0 where no geom is seen) and the geom id
of each pixel (-1 for background), for the geom groups in
:data:`~handsim.world.render.RENDERED_GEOM_GROUPS`. The camera's intrinsics come from the model
(``add_camera`` writes the OpenCV ``K`` as focal and principal pixels), and MuJoCo Warp maps
them to rays as MuJoCo's OpenGL projection does, off-centre principal point included.

It needs the optional extra ``handsim[gpu]`` (``mujoco-warp``, ``warp-lang``); this module
imports them when a renderer is made, never on ``import handsim``. The first renderer in a
process compiles Warp's kernels (tens of seconds on the CPU; cached in ``WARP_CACHE_PATH``).

The device model is a copy of the model when the renderer is made: mesh vertices moved later
(a rescaled hand) are copied with :meth:`WarpDepthRenderer.refresh_meshes`, other model changes
need a new renderer; the camera's pose is read from each world's ``MjData`` at every render.
The geom ids become depth, ids or segmentation labels on the device (one kernel over every
world's pixels), so only the final images are read back.

:class:`WarpSceneRenderer` is :class:`~handsim.world.render.DepthRenderer`'s interface on one
Warp world: a :class:`~handsim.frame.renderer.FrameRenderer` renders through it with its own
label code (the hand occlusion ratio's and the silhouettes' renders included).
"""

from __future__ import annotations

import importlib.util
import math
import time
from collections.abc import Sequence

import mujoco
import numpy as np

from handsim._validate import is_real
from handsim.errors import HandSimError, UnknownName
from handsim.world.camera import CameraIntrinsics
from handsim.world.render import RENDERED_GEOM_GROUPS, DepthRenderer

__all__ = ["WarpRenderError", "WarpDepthRenderer", "WarpSceneRenderer", "warp_available"]

_MJ_OBJ_GEOM = int(mujoco.mjtObj.mjOBJ_GEOM)
_MJ_MESH = int(mujoco.mjtGeom.mjGEOM_MESH)
_MJ_PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)


class WarpRenderError(HandSimError, RuntimeError):
    """MuJoCo Warp is missing, or a batched render was asked for with bad input."""


def warp_available() -> bool:
    """Whether ``mujoco_warp`` and ``warp`` can be imported (the ``handsim[gpu]`` extra)."""
    return all(importlib.util.find_spec(name) is not None for name in ("warp", "mujoco_warp"))


def _import_warp() -> tuple[object, object]:
    try:
        import warp as wp

        # Warp prints its set-up and each kernel load on stdout, where the CLI writes JSON.
        wp.config.log_level = wp.LOG_WARNING
        import mujoco_warp as mjw
    except ImportError as err:
        raise WarpRenderError(
            "the warp backend needs MuJoCo Warp: pip install 'handsim[gpu]' "
            f"(mujoco-warp, warp-lang); import failed: {err}"
        ) from err
    return wp, mjw


class WarpDepthRenderer:
    """Renders depth and geom segmentation of one camera in ``nworld`` worlds per call.

    Args:
        model: compiled model containing the camera (added with
            :func:`~handsim.world.camera.add_camera` using ``intrinsics``).
        camera: camera name.
        intrinsics: the camera's intrinsics (they set the image size).
        nworld: worlds rendered per call, >= 1.
        device: Warp device, ``"cpu"`` or ``"cuda"`` (``"cuda:N"``); default: Warp's default
            device (a GPU when there is one).
        dynamic_intrinsics: compute each pixel's ray from the camera's intrinsics at every
            render (:meth:`set_intrinsics`) instead of once when the renderer is made.

    Raises:
        UnknownName: if the camera is not in the model (the message lists the cameras).
        WarpRenderError: if MuJoCo Warp is not installed, ``nworld`` is not a positive integer,
            the device is unknown, or the model's camera image size differs from
            ``intrinsics``.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        camera: str,
        intrinsics: CameraIntrinsics,
        nworld: int,
        device: str | None = None,
        *,
        dynamic_intrinsics: bool = False,
    ) -> None:
        names = [model.camera(i).name for i in range(model.ncam)]
        if camera not in names:
            raise UnknownName(
                f"camera {camera!r} is not in the model; cameras: {', '.join(names) or 'none'}"
            )
        if isinstance(nworld, bool) or not isinstance(nworld, (int, np.integer)) or nworld < 1:
            raise WarpRenderError(f"nworld must be an integer >= 1; received {nworld!r}")
        cam_id = int(model.camera(camera).id)
        res = tuple(int(v) for v in model.cam_resolution[cam_id])
        if res != (intrinsics.width, intrinsics.height):
            raise WarpRenderError(
                f"camera {camera!r} was added for a {res[0]} x {res[1]} image but the "
                f"intrinsics are {intrinsics.width} x {intrinsics.height}; add the camera with "
                "these intrinsics (handsim.world.camera.add_camera)"
            )
        wp, mjw = _import_warp()
        self._wp, self._mjw = wp, mjw
        if device is not None:
            try:
                device = wp.get_device(device)
            except (RuntimeError, ValueError) as err:
                cuda = ", ".join(str(d) for d in wp.get_cuda_devices()) or "none"
                raise WarpRenderError(
                    f"unknown Warp device {device!r}; valid: 'cpu', CUDA devices: {cuda}"
                ) from err
        self.device = wp.get_device(device)
        self.model = model
        self.camera = camera
        self.camera_id = cam_id
        self.intrinsics = intrinsics
        self.nworld = int(nworld)
        active = [i == cam_id for i in range(model.ncam)]
        with wp.ScopedDevice(self.device):
            self._m = mjw.put_model(model)
            self._d = mjw.put_data(model, mujoco.MjData(model), nworld=self.nworld)
            self._rc = mjw.create_render_context(
                model,
                nworld=self.nworld,
                cam_res=[(intrinsics.width, intrinsics.height)] * model.ncam,
                render_rgb=False,
                render_depth=[True] * model.ncam,
                render_seg=[True] * model.ncam,
                use_textures=False,
                enabled_geom_groups=list(RENDERED_GEOM_GROUPS),
                cam_active=active,
                use_precomputed_rays=not dynamic_intrinsics,
            )
        # Cameras render in model order among the active ones: ours is the only one.
        self._offset = 0
        self._out = None  # the post-processed images on the device, made at the first render
        self._host = None  # page-locked host buffers for them (CUDA), made at the first render
        self._values: tuple[bytes, object] | None = None

    def _upload(self, datas: Sequence[mujoco.MjData]) -> None:
        if len(datas) != self.nworld:
            raise WarpRenderError(
                f"render() needs one MjData per world, {self.nworld}; received {len(datas)}"
            )
        wp, d = self._wp, self._d
        fields = ("qpos", "mocap_pos", "mocap_quat")
        for field in fields:
            host = np.stack([getattr(data, field) for data in datas])
            if host.size:
                getattr(d, field).assign(wp.array(host, dtype=getattr(d, field).dtype))
        self._cam_xpos = np.stack([data.cam_xpos for data in datas])
        self._cam_xmat = np.stack([data.cam_xmat.reshape(-1, 3, 3) for data in datas])

    def set_intrinsics(self, cam_intrinsic: np.ndarray) -> None:
        """Give the device model the cameras' intrinsics (``MjModel.cam_intrinsic``).

        Args:
            cam_intrinsic: (ncam, 4) focal lengths and principal point offsets, sensor units,
                as in ``MjModel.cam_intrinsic``; they take effect only for a renderer made with
                ``dynamic_intrinsics=True``.
        """
        wp = self._wp
        host = np.asarray(cam_intrinsic, dtype=np.float32).reshape(1, self.model.ncam, 4)
        with wp.ScopedDevice(self.device):
            self._m.cam_intrinsic.assign(wp.array(host, dtype=self._m.cam_intrinsic.dtype))

    def refresh_meshes(self, mesh_ids: Sequence[int], mesh_vert: np.ndarray | None = None) -> None:
        """Copy the meshes' vertices from the model to the device and refit their BVHs.

        For vertices moved in place without changing the triangles, e.g. a hand rescaled with
        :meth:`Scene.set_hand_length <handsim.world.scene.Scene.set_hand_length>`: a refit
        costs a fraction of a new renderer (the BVH keeps its tree, so a uniform scale leaves
        it as good as a new one).

        Args:
            mesh_ids: mesh indices in the model.
            mesh_vert: (nmeshvert, 3) every mesh's vertices to read from, the model's
                layout; default: the model's ``mesh_vert``.
        """
        wp, rc, model = self._wp, self._rc, self.model
        mesh_vert = model.mesh_vert if mesh_vert is None else mesh_vert
        bvh_ids = rc.mesh_bvh_id.numpy()
        bounds = rc.mesh_bounds_size.numpy()
        with wp.ScopedDevice(self.device):
            for mesh in mesh_ids:
                start = int(model.mesh_vertadr[mesh])
                points = mesh_vert[start : start + int(model.mesh_vertnum[mesh])]
                warp_mesh = rc.mesh_registry[int(bvh_ids[mesh])]
                warp_mesh.points.assign(wp.array(points, dtype=wp.vec3))
                warp_mesh.refit()
                # The half extents the scene's BVH bounds the mesh's geoms with.
                bounds[mesh] = np.maximum(np.abs(points.min(axis=0)), np.abs(points.max(axis=0)))
            rc.mesh_bounds_size.assign(wp.array(bounds, dtype=wp.vec3))

    def render(
        self,
        datas: Sequence[mujoco.MjData],
        *,
        depth_range_m: tuple[float, float] | None = None,
        timings_s: dict[str, float] | None = None,
        host_geom_poses: bool = False,
        geom_size: np.ndarray | None = None,
        geom_poses: tuple[np.ndarray, np.ndarray] | None = None,
        geom_values: np.ndarray | None = None,
        fill: int = -1,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Render the worlds' current states (their ``qpos`` and mocap poses).

        Args:
            datas: ``nworld`` simulation data; only ``qpos``, ``mocap_pos``, ``mocap_quat``
                and the camera poses (``cam_xpos``, ``cam_xmat``: each world its own camera
                pose, e.g. after ``mj_camlight``) are read; kinematics run on the device.
            depth_range_m: ``(near, far)``: pixels whose depth is outside it are background
                (depth 0, geom id -1), as with :meth:`DepthRenderer.render
                <handsim.world.render.DepthRenderer.render>`.
            timings_s: a dict to add each stage's seconds to (``upload``, ``kinematics``,
                ``render``, ``postprocess`` (on the device), ``readback``), for benchmarks;
                the device is synchronized between stages then, which costs a little.
            host_geom_poses: take every geom's pose from the worlds' ``geom_xpos`` and
                ``geom_xmat`` (computed on the host) instead of running kinematics on the
                device: for geoms the host moves outside the kinematic tree (the hand's upper
                arm, :meth:`~handsim.hand.model.HandBinding.point_upper_arm`).
            geom_size: (N, ngeom, 3) each world's geom sizes (the upper arm's length differs
                per world); default: the model's when the renderer was made.
            geom_poses: ``(geom_xpos, geom_xmat)``, (N, ngeom, 3) and (N, ngeom, 9), world
                frame: every geom's pose, taken instead of the worlds' own (implies
                ``host_geom_poses``).
            geom_values: (ngeom,) integer values (e.g. segmentation labels) to give instead of
                geom ids, mapped on the device: the second image is ``geom_values[geom id]``,
                ``fill`` on background, in ``geom_values``' dtype.
            fill: the second image's value on background, with ``geom_values``.

        Returns:
            ``(depth_m, geom_id)``: (N, H, W) float32 metres along the optical axis, 0 where no
            geom is seen; (N, H, W) int32 geom ids, -1 for background (or the values).
        """
        wp, mjw = self._wp, self._mjw
        clock = _Stages(wp, timings_s)
        self._upload(datas)
        clock("upload")
        if geom_size is not None:
            geom_size = np.asarray(geom_size, dtype=np.float32)
            if geom_size.shape != (self.nworld, self.model.ngeom, 3):
                raise WarpRenderError(
                    f"geom_size must be ({self.nworld}, {self.model.ngeom}, 3), one row per "
                    f"world and geom; received shape {geom_size.shape}"
                )
        with wp.ScopedDevice(self.device):
            if geom_size is not None:
                self._m.geom_size = wp.array(geom_size, dtype=wp.vec3)
            if host_geom_poses or geom_poses is not None:
                if geom_poses is None:
                    geom_poses = tuple(
                        np.stack([getattr(data, field) for data in datas])
                        for field in ("geom_xpos", "geom_xmat")
                    )
                fields = (("geom_xpos", (3,)), ("geom_xmat", (3, 3)))
                for (field, shape), host in zip(fields, geom_poses, strict=True):
                    host = np.asarray(host, dtype=np.float32)
                    host = host.reshape(self.nworld, self.model.ngeom, *shape)
                    target = getattr(self._d, field)
                    target.assign(wp.array(host, dtype=target.dtype))
            else:
                mjw.kinematics(self._m, self._d)
            # Each world's camera pose is its MjData's (the model's camera pose is per world
            # in data generation: the host moves it and calls mj_camlight).
            self._d.cam_xpos.assign(wp.array(self._cam_xpos, dtype=self._d.cam_xpos.dtype))
            self._d.cam_xmat.assign(wp.array(self._cam_xmat, dtype=self._d.cam_xmat.dtype))
            clock("kinematics")
            mjw.refit_bvh(self._m, self._d, self._rc)
            mjw.render(self._m, self._d, self._rc)
            clock("render")
            # Geom ids, the working range and the values (e.g. segmentation labels) on the
            # device, in one pass over every world's pixels: only the images come back.
            h, w = self.intrinsics.height, self.intrinsics.width
            n = h * w
            if self._out is None:
                self._out = (
                    wp.empty((self.nworld, n), dtype=wp.float32),
                    wp.empty((self.nworld, n), dtype=wp.int32),
                    wp.empty(1, dtype=wp.int32),
                )
            values, fill_value = self._values_on_device(geom_values, fill)
            near, far = (0.0, np.inf) if depth_range_m is None else depth_range_m
            wp.launch(
                _postprocess_kernel(),
                dim=(self.nworld, n),
                inputs=[
                    self._rc.depth_data, self._rc.seg_data, _MJ_OBJ_GEOM, self._offset,
                    np.float32(near), np.float32(far), values, geom_values is not None,
                    int(fill_value),
                ],
                outputs=[self._out[0], self._out[1]],
            )  # fmt: skip
            clock("postprocess")
            depth_m, ids = (image.reshape(-1, h, w) for image in self._readback())
            clock("readback")
        if geom_values is not None:
            ids = ids.astype(np.asarray(geom_values).dtype, copy=False)
        return depth_m, ids

    def _readback(self) -> tuple[np.ndarray, np.ndarray]:
        """The post-processed images on the host, arrays of their own.

        Not the buffers the next render writes: on the CPU device ``numpy()`` is a view of
        them. From a CUDA device through page-locked buffers kept between renders: on an H200 a
        copy into pageable memory moved 1.2-7 GB/s, into page-locked memory 46-55 GB/s.
        """
        wp, images = self._wp, self._out[:2]
        if self.device.is_cuda:
            if self._host is None:
                self._host = tuple(
                    wp.empty(out.shape, dtype=out.dtype, device="cpu", pinned=True)
                    for out in images
                )
            for host, out in zip(self._host, images, strict=True):
                wp.copy(host, out)
            wp.synchronize_device(self.device)
            images = self._host
        depth_m, ids = (image.numpy().copy() for image in images)
        return depth_m, ids

    def _values_on_device(self, geom_values: np.ndarray | None, fill: int) -> tuple[object, int]:
        """The (ngeom,) values on the device (kept while they are the same) and the fill."""
        wp = self._wp
        if geom_values is None:
            return self._out[2], -1
        geom_values = np.asarray(geom_values)
        if geom_values.shape != (self.model.ngeom,) or geom_values.dtype.kind not in "iu":
            raise WarpRenderError(
                f"geom_values must be ({self.model.ngeom},) integers, one per geom; received "
                f"shape {geom_values.shape}, dtype {geom_values.dtype}"
            )
        key = geom_values.tobytes()
        if self._values is None or self._values[0] != key:
            with wp.ScopedDevice(self.device):
                self._values = (key, wp.array(geom_values.astype(np.int32), dtype=wp.int32))
        return self._values[1], fill

    def raw_images(self) -> tuple[np.ndarray, np.ndarray]:
        """The last render's images as the ray caster left them (for tests).

        Returns:
            ``(depth, seg)``: (N, H, W) float32 ray-cast depth (along the optical axis, any
            range) and (N, H, W, 2) int32 (object id, object type) per pixel.
        """
        h, w = self.intrinsics.height, self.intrinsics.width
        n = h * w
        depth = self._rc.depth_data.numpy()[:, self._offset : self._offset + n]
        seg = self._rc.seg_data.numpy()[:, self._offset : self._offset + n]
        return depth.reshape(-1, h, w).astype(np.float32), seg.reshape(-1, h, w, 2)


class WarpSceneRenderer:
    """:class:`~handsim.world.render.DepthRenderer`'s interface on MuJoCo Warp, one world.

    A stand-in for the OpenGL renderer of a :class:`~handsim.frame.renderer.FrameRenderer` (its
    ``renderer``), so that every label is made by the same code as on the OpenGL path: the
    hand occlusion ratio's render with the objects hidden, the objects' silhouettes on BOP's
    canvas. It follows the model as the OpenGL renderer does:

    - geoms whose group is not in :data:`~handsim.world.render.RENDERED_GEOM_GROUPS` at
      render time are not seen (the labels hide geoms by moving them to group 5): the ray
      caster's geom set is fixed when it is made, so they are moved behind the camera;
    - the camera's intrinsics are read at every render (the canvas shifts the principal
      point, :meth:`render_segmentation_canvas`), with rays computed per render;
    - every geom's pose comes from the ``MjData`` (``geom_xpos``, ``geom_xmat``: the host's
      kinematics, with the upper arm turned outside the kinematic tree) and its size from the
      model (the arm's length);
    - :meth:`scale_geoms` scales the mesh vertices on the device (and refits their BVHs).

    Args:
        model: compiled model containing the camera.
        camera: camera name.
        intrinsics: the camera's intrinsics (they set the image size).
        device: Warp device (``"cpu"``, ``"cuda"``, ``"cuda:N"``; default: Warp's).

    Raises:
        UnknownName, WarpRenderError: as :class:`WarpDepthRenderer`.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        camera: str,
        intrinsics: CameraIntrinsics,
        device: str | None = None,
    ) -> None:
        self.model = model
        self.camera = camera
        self.intrinsics = intrinsics
        self._warp: WarpDepthRenderer | None = WarpDepthRenderer(
            model, camera, intrinsics, 1, device=device, dynamic_intrinsics=True
        )
        self.camera_id = self._warp.camera_id
        self.device = self._warp.device
        self._intrinsic = model.cam_intrinsic.copy()
        # The vertices on the device are these times the scale_geoms factor.
        self._uploaded_vert = model.mesh_vert.copy()
        self._mesh_scale = np.ones(model.nmesh)
        self._rendered = np.isin(model.geom_group, RENDERED_GEOM_GROUPS)

    timings_s: dict[str, float] | None = None
    """Set to a dict (on the class, for benchmarks) to add each render's stages to it
    (:meth:`WarpDepthRenderer.render`'s ``timings_s``); the device is synchronized then."""

    def __enter__(self) -> WarpSceneRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Free the device model."""
        self._warp = None

    def _check_open(self) -> WarpDepthRenderer:
        if self._warp is None:
            raise WarpRenderError("render() called after close()")
        return self._warp

    def upload_meshes(self, mesh_ids: Sequence[int]) -> None:
        """Copy meshes' vertices from the model again (a :meth:`scale_geoms` factor is dropped).

        Args:
            mesh_ids: mesh indices in the model.
        """
        warp = self._check_open()
        ids = [int(m) for m in mesh_ids]
        for mesh in ids:
            rows = self._mesh_rows(mesh)
            self._uploaded_vert[rows] = self.model.mesh_vert[rows]
            self._mesh_scale[mesh] = 1.0
        warp.refresh_meshes(ids)

    def _mesh_rows(self, mesh: int) -> slice:
        start = int(self.model.mesh_vertadr[mesh])
        return slice(start, start + int(self.model.mesh_vertnum[mesh]))

    def scale_geoms(self, geom_ids: Sequence[int], factor: float) -> None:
        """Draw mesh geoms scaled by ``factor`` about their own frames (see DepthRenderer).

        The meshes of ``geom_ids`` get the vertices uploaded times ``factor`` on the device
        (the others the vertices uploaded): a rescaled hand's skin is then what the model
        holds, as with the OpenGL renderer's
        :meth:`~handsim.world.render.DepthRenderer.scale_geoms`.

        Raises:
            WarpRenderError: for a factor that is not a positive finite number or a geom index
                outside the model.
        """
        warp = self._check_open()
        if not is_real(factor) or not 0.0 < float(factor) < math.inf:
            raise WarpRenderError(
                f"scale_geoms: factor must be a positive number; received {factor!r}"
            )
        ids = np.asarray(geom_ids, dtype=int).reshape(-1)
        if ids.size and (ids.min() < 0 or ids.max() >= self.model.ngeom):
            raise WarpRenderError(
                f"scale_geoms: geom ids must be in [0, {self.model.ngeom}); received "
                f"{ids.min()}..{ids.max()}"
            )
        model = self.model
        scale = np.ones(model.nmesh)
        meshes = model.geom_dataid[ids[model.geom_type[ids] == _MJ_MESH]]
        scale[meshes[meshes >= 0]] = float(factor)
        changed = np.flatnonzero(scale != self._mesh_scale)
        if not len(changed):
            return
        vertices = model.mesh_vert.copy()
        for mesh in changed:
            rows = self._mesh_rows(mesh)
            vertices[rows] = self._uploaded_vert[rows] * np.float32(scale[mesh])
        warp.refresh_meshes(changed, vertices)
        self._mesh_scale = scale

    def _render(
        self,
        data: mujoco.MjData,
        depth_range_m: tuple[float, float] | None,
        geom_values: np.ndarray | None = None,
        fill: int = -1,
    ) -> tuple[np.ndarray, np.ndarray]:
        warp, model = self._check_open(), self.model
        if not np.array_equal(model.cam_intrinsic, self._intrinsic):
            warp.set_intrinsics(model.cam_intrinsic)
            self._intrinsic = model.cam_intrinsic.copy()
        xpos, xmat = data.geom_xpos, data.geom_xmat
        hidden = self._rendered & ~np.isin(model.geom_group, RENDERED_GEOM_GROUPS)
        if hidden.any():
            planes = np.flatnonzero(hidden & (model.geom_type == _MJ_PLANE))
            if len(planes):
                names = ", ".join(model.geom(int(g)).name or str(g) for g in planes)
                raise WarpRenderError(
                    f"a plane cannot be hidden on MuJoCo Warp (moved behind the camera it still "
                    f"reaches into view): {names}; make the renderer with it in a group no "
                    "camera renders, or use the OpenGL DepthRenderer"
                )
            # Behind the camera (its +z; it looks along -z) by more than the geom's bounding
            # radius: no ray reaches it, and the scene's BVH stays valid.
            xpos = xpos.copy()
            back = data.cam_xmat[self.camera_id].reshape(3, 3)[:, 2]
            xpos[hidden] = data.cam_xpos[self.camera_id] + np.outer(
                1.0 + model.geom_rbound[hidden], back
            )
        depth_m, ids = warp.render(
            [data],
            depth_range_m=depth_range_m,
            geom_poses=(xpos[None], xmat[None]),
            geom_size=model.geom_size[None],
            timings_s=self.timings_s,
            geom_values=geom_values,
            fill=fill,
        )
        if self.timings_s is not None:
            self.timings_s["renders"] = self.timings_s.get("renders", 0) + 1
        return depth_m[0], ids[0]

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

        The arguments and results of :meth:`DepthRenderer.render
        <handsim.world.render.DepthRenderer.render>`.
        """
        depth_m, ids = self._render(data, depth_range_m, geom_values, fill)
        if out is None:
            return depth_m, ids
        out[0][...] = depth_m
        out[1][...] = ids
        return out

    def render_segmentation(
        self, data: mujoco.MjData, region: tuple[int, int, int, int] | None = None
    ) -> np.ndarray:
        """The geom-id image of ``region`` (clipped to the image), -1 for background."""
        w, h = self.intrinsics.width, self.intrinsics.height
        u0, v0, u1, v1 = (0, 0, w, h) if region is None else region
        u0, u1 = max(0, u0), min(w, u1)
        v0, v1 = max(0, v0), min(h, v1)
        if u1 <= u0 or v1 <= v0:
            return np.full((max(v1 - v0, 0), max(u1 - u0, 0)), -1, dtype=np.int32)
        return self._render(data, None)[1][v0:v1, u0:u1].copy()

    def render_segmentation_canvas(
        self, data: mujoco.MjData, region: tuple[int, int, int, int]
    ) -> np.ndarray:
        """The geom-id image of a pixel box that may reach beyond the image.

        The OpenGL renderer's own tiling (:meth:`DepthRenderer.render_segmentation_canvas
        <handsim.world.render.DepthRenderer.render_segmentation_canvas>`): windows of the
        image's size, each rendered with the principal point shifted by whole pixels.
        """
        return DepthRenderer.render_segmentation_canvas(self, data, region)


_KERNEL = None


def _postprocess_kernel() -> object:
    """The Warp kernel that turns the ray caster's images into depth and ids (or values).

    Per world and pixel: the geom id where the pixel sees a geom (-1 elsewhere: nothing, or
    another object type), background where the depth is outside ``[near, far]`` (float32
    compares, as :class:`~handsim.world.render.DepthRenderer`), depth 0 on background; the id
    mapped through ``values`` when asked (``fill`` on background). Made at the first render
    (``import handsim`` never imports Warp).
    """
    global _KERNEL
    if _KERNEL is None:
        import warp as wp

        @wp.kernel(enable_backward=False)
        def postprocess(
            depth_in: wp.array2d(dtype=wp.float32),
            seg_in: wp.array2d(dtype=wp.vec2i),
            obj_geom: int,
            offset: int,
            near: wp.float32,
            far: wp.float32,
            values: wp.array(dtype=wp.int32),
            use_values: bool,
            fill: int,
            depth_out: wp.array2d(dtype=wp.float32),
            ids_out: wp.array2d(dtype=wp.int32),
        ):
            world, pixel = wp.tid()
            seg = seg_in[world, offset + pixel]
            depth = depth_in[world, offset + pixel]
            geom = wp.where(seg[1] == obj_geom, seg[0], -1)
            if geom < 0 or depth < near or depth > far:
                depth_out[world, pixel] = wp.float32(0.0)
                ids_out[world, pixel] = fill
            else:
                depth_out[world, pixel] = depth
                if use_values:
                    ids_out[world, pixel] = values[geom]
                else:
                    ids_out[world, pixel] = geom

        _KERNEL = postprocess
    return _KERNEL


class _Stages:
    """Adds the seconds since the last call to ``timings_s[stage]`` (nothing when it is None)."""

    def __init__(self, wp: object, timings_s: dict[str, float] | None) -> None:
        self._wp, self._timings = wp, timings_s
        self._last = time.perf_counter()

    def __call__(self, stage: str) -> None:
        if self._timings is None:
            return
        self._wp.synchronize()
        now = time.perf_counter()
        self._timings[stage] = self._timings.get(stage, 0.0) + now - self._last
        self._last = now
