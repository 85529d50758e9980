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

The device model is a copy of the model when the renderer is made: a model changed later
(e.g. a rescaled hand's mesh vertices) needs a new renderer; the camera's pose is read from
each world's ``MjData`` at every render.
"""

from __future__ import annotations

import importlib.util
import time
from collections.abc import Sequence

import mujoco
import numpy as np

from handsim.errors import HandSimError, UnknownName
from handsim.world.camera import CameraIntrinsics
from handsim.world.render import RENDERED_GEOM_GROUPS

__all__ = ["WarpRenderError", "WarpDepthRenderer", "warp_available"]

_MJ_OBJ_GEOM = int(mujoco.mjtObj.mjOBJ_GEOM)


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
            )
        # Cameras render in model order among the active ones: ours is the only one.
        self._offset = 0

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

    def render(
        self,
        datas: Sequence[mujoco.MjData],
        *,
        depth_range_m: tuple[float, float] | None = None,
        timings_s: dict[str, float] | None = None,
        host_geom_poses: bool = False,
        geom_size: np.ndarray | None = None,
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
                ``render``, ``readback``, ``postprocess``), for benchmarks; the device is
                synchronized between stages then, which costs a little.
            host_geom_poses: take every geom's pose from the worlds' ``geom_xpos`` and
                ``geom_xmat`` (computed on the host) instead of running kinematics on the
                device: for geoms the host moves outside the kinematic tree (the hand's upper
                arm, :meth:`~handsim.hand.model.HandBinding.point_upper_arm`).
            geom_size: (N, ngeom, 3) each world's geom sizes (the upper arm's length differs
                per world); default: the model's when the renderer was made.

        Returns:
            ``(depth_m, geom_id)``: (N, H, W) float32 metres along the optical axis, 0 where no
            geom is seen; (N, H, W) int32 geom ids, -1 for background.
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
            if host_geom_poses:
                for field in ("geom_xpos", "geom_xmat"):
                    host = np.stack([getattr(data, field) for data in datas])
                    host = host.reshape(self.nworld, self.model.ngeom, -1)
                    if field == "geom_xmat":
                        host = host.reshape(self.nworld, self.model.ngeom, 3, 3)
                    target = getattr(self._d, field)
                    target.assign(wp.array(host.astype(np.float32), dtype=target.dtype))
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
            depth = self._rc.depth_data.numpy()
            seg = self._rc.seg_data.numpy()
            clock("readback")
        h, w = self.intrinsics.height, self.intrinsics.width
        n = h * w
        depth_m = depth[:, self._offset : self._offset + n].reshape(-1, h, w).astype(np.float32)
        seg = seg[:, self._offset : self._offset + n].reshape(-1, h, w, 2)
        ids = np.where(seg[..., 1] == _MJ_OBJ_GEOM, seg[..., 0], -1).astype(np.int32)
        background = ids < 0
        if depth_range_m is not None:
            near, far = np.float32(depth_range_m[0]), np.float32(depth_range_m[1])
            background |= (depth_m < near) | (depth_m > far)
            ids[background] = -1
        depth_m[background] = 0.0
        clock("postprocess")
        return depth_m, ids


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
