"""Pinhole cameras with exact intrinsics, in the OpenCV convention, and their MuJoCo cameras.

Conventions: the camera frame is OpenCV's (``+x`` right, ``+y`` down, ``+z`` forward);
pixel ``(u, v)`` has its centre at integer coordinates, ``u`` to the right, ``v`` down. MuJoCo
cameras look along their ``-z`` with ``+y`` up; the rotation between the two frames,
:data:`R_MJCAM_FROM_CV`, is applied here and nowhere else (``docs/conventions.md``).

Exact intrinsics in MuJoCo: a camera with ``resolution = (W, H)``, ``focal_pixel = (fx, fy)``
and ``principal_pixel = (px, py)`` renders a point ``(X, Y, Z)`` (OpenCV camera frame) at pixel
index ``u = fx X / Z + (W - 1) / 2 - px`` and ``v = fy Y / Z + (H - 1) / 2 - py`` (measured by
rendering small spheres, and pinned by a projection test for every preset), so OpenCV's
``(cx, cy)`` needs ``principal_pixel = ((W - 1) / 2 - cx, (H - 1) / 2 - cy)``.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from handsim._validate import is_real, show
from handsim.errors import HandSimError, UnknownName

__all__ = [
    "CameraIntrinsics",
    "CAMERA_PRESETS",
    "R_MJCAM_FROM_CV",
    "camera_preset",
    "add_camera",
    "look_at_quat_wxyz",
    "T_cam_from_world",
]

R_MJCAM_FROM_CV: np.ndarray = np.diag([1.0, -1.0, -1.0])
"""Rotation from the OpenCV camera frame to MuJoCo's camera frame (its own inverse)."""
R_MJCAM_FROM_CV.setflags(write=False)

# MuJoCo needs a physical sensor size with focal_pixel; any value works (it only fixes units).
_SENSOR_PIXEL_PITCH_M = 6e-6


class InvalidCamera(HandSimError, ValueError):
    """Camera intrinsics or placement are invalid."""


MAX_IMAGE_SIDE = 8192
"""Largest image width or height, pixels (MuJoCo's offscreen buffer and memory stay sane)."""


@dataclasses.dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of a depth camera (OpenCV convention, no distortion).

    Attributes:
        width: image width, pixels.
        height: image height, pixels.
        fx: focal length along u, pixels.
        fy: focal length along v, pixels.
        cx: principal point u, pixels (pixel centres at integers).
        cy: principal point v, pixels.
        name: preset name, for reports.
        range_m: ``(near, far)`` working range of the sensor along the optical axis, metres.
            Surfaces outside it give no depth (0), as on the real sensor: the render's far
            clip plane is ``far`` and :class:`~handsim.frame.renderer.FrameRenderer` drops surfaces
            nearer than ``near``. Presets carry their sensor's published range; the default
            is a generic 0.1-10 m.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    name: str = "custom"
    range_m: tuple[float, float] = (0.1, 10.0)

    def __post_init__(self) -> None:
        for field in ("width", "height"):
            value = getattr(self, field)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise InvalidCamera(
                    f"width and height must be integers; received {field}={show(value)} "
                    f"({type(value).__name__})"
                )
            if not 1 <= value <= MAX_IMAGE_SIDE:
                raise InvalidCamera(
                    f"width and height must be in [1, {MAX_IMAGE_SIDE}] pixels; received "
                    f"{self.width} x {self.height}"
                )
            object.__setattr__(self, field, int(value))
        for field in ("fx", "fy", "cx", "cy"):
            if not is_real(getattr(self, field)):
                value = getattr(self, field)
                raise InvalidCamera(
                    f"{field} must be a finite real number of pixels; received {show(value)} "
                    f"({type(value).__name__})"
                )
            object.__setattr__(self, field, float(getattr(self, field)))
        if not (np.isfinite(self.fx) and np.isfinite(self.fy) and self.fx > 0 and self.fy > 0):
            raise InvalidCamera(
                f"fx and fy must be positive pixels; received fx={self.fx!r}, fy={self.fy!r}"
            )
        # A focal length far outside the image (a < 1e-4 or > 1e4 pixel field of view ratio)
        # gives a degenerate projection in MuJoCo.
        side = max(self.width, self.height)
        for field in ("fx", "fy"):
            if not 1e-3 * side <= getattr(self, field) <= 1e4 * side:
                raise InvalidCamera(
                    f"{field} must be in [{1e-3 * side:g}, {1e4 * side:g}] pixels for a "
                    f"{self.width} x {self.height} image; received {getattr(self, field)!r}"
                )
        if not (np.isfinite(self.cx) and np.isfinite(self.cy)):
            raise InvalidCamera(f"cx and cy must be finite; received {self.cx!r}, {self.cy!r}")
        for field, size in (("cx", self.width), ("cy", self.height)):
            if not -10 * size <= getattr(self, field) <= 11 * size:
                raise InvalidCamera(
                    f"{field} must be within 10 image sizes of the image, [{-10 * size}, "
                    f"{11 * size}] pixels; received {getattr(self, field)!r}"
                )
        if not isinstance(self.name, str):
            raise InvalidCamera(f"name must be a str; received {show(self.name)}")
        pair = self.range_m
        ok = isinstance(pair, (tuple, list)) and len(pair) == 2 and all(is_real(v) for v in pair)
        near, far = (float(pair[0]), float(pair[1])) if ok else (np.nan, np.nan)
        if not (np.isfinite(far) and 0.0 < near < far):
            raise InvalidCamera(
                f"range_m must be (near, far) metres with 0 < near < far < inf; received "
                f"{show(self.range_m)}"
            )
        object.__setattr__(self, "range_m", (near, far))

    @property
    def K(self) -> np.ndarray:  # noqa: N802 (the standard name of the matrix)
        """(3, 3) intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def fovy_deg(self) -> float:
        """Vertical field of view, degrees (for information; the camera uses fx, fy)."""
        return float(np.rad2deg(2.0 * np.arctan(self.height / (2.0 * self.fy))))

    @property
    def mujoco_principal_pixel(self) -> tuple[float, float]:
        """MuJoCo ``principal_pixel`` that puts the principal point at ``(cx, cy)``."""
        return ((self.width - 1) / 2.0 - self.cx, (self.height - 1) / 2.0 - self.cy)

    def scaled(self, width: int, height: int) -> CameraIntrinsics:
        """The same camera (same field of view and optical axis) with a ``width x height`` image.

        Pixel centres are at integer coordinates, so the image's outer edges, at ``-0.5`` and
        ``W - 0.5``, stay where they are: ``fx' = fx s``, ``cx' = (cx + 0.5) s - 0.5`` with
        ``s = width / W`` (and the same along ``v`` with ``height / H``). A ray hits pixel
        coordinate ``u`` in this image and ``(u + 0.5) s - 0.5`` in the scaled one. Rendering
        with the result renders at that size (no resize); the working range is kept.

        Args:
            width: image width, pixels.
            height: image height, pixels.

        Returns:
            The scaled intrinsics, named ``"<name>@<W>x<H>"`` (``self`` at the same size).

        Raises:
            InvalidCamera: for a size that is not an integer in ``[1, MAX_IMAGE_SIDE]``.
        """
        for field, value in (("width", width), ("height", height)):
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise InvalidCamera(
                    f"scaled() needs integer width and height in pixels; received "
                    f"{field}={show(value)} ({type(value).__name__})"
                )
        if (width, height) == (self.width, self.height):
            return self
        sx, sy = width / self.width, height / self.height
        return dataclasses.replace(
            self,
            width=int(width),
            height=int(height),
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
            name=f"{self.name.split('@')[0]}@{int(width)}x{int(height)}",
        )

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Project points given in the camera frame to pixels.

        Args:
            points_cam: (..., 3) points in the OpenCV camera frame, metres (z > 0).

        Returns:
            (..., 2) pixel coordinates ``(u, v)``.
        """
        p = np.asarray(points_cam, dtype=np.float64)
        # fx * x / z + cx and fy * y / z + cy, both columns at once.
        f, c = np.array((self.fx, self.fy)), np.array((self.cx, self.cy))
        return p[..., :2] * f / p[..., 2:3] + c

    def backproject(self, depth_m: np.ndarray) -> np.ndarray:
        """Back-project a depth image to camera-frame points.

        Args:
            depth_m: (H, W) depth along the optical axis, metres (0 = no measurement).

        Returns:
            (H, W, 3) points in the OpenCV camera frame, metres (zeros where depth is 0).
        """
        depth = np.asarray(depth_m, dtype=np.float64)
        v, u = np.indices(depth.shape)
        x = (u - self.cx) / self.fx * depth
        y = (v - self.cy) / self.fy * depth
        return np.stack([x, y, depth], axis=-1)


# Working ranges. PrimeSense PS1080 structured-light sensors (Kinect v1, Carmine) return depth
# from about 0.35-0.4 m (Kinect for Windows "near mode" 0.4-3 m; Carmine 1.09 specified
# 0.35-1.4 m for full accuracy) out to about 4 m (Kinect for Windows SDK default range
# 0.8-4 m). The Creative Interactive Gesture Camera / Senz3D (DS325 time of flight) is
# specified for 0.15-1 m (Creative Senz3D product sheet). The Intel RealSense SR300 is specified
# for 0.2-1.5 m indoors (Intel RealSense SR300 datasheet; librealsense camera specs).
_PS1080_RANGE_M = (0.35, 4.0)
_DS325_RANGE_M = (0.15, 1.0)
_SR300_RANGE_M = (0.2, 1.5)

CAMERA_PRESETS: dict[str, CameraIntrinsics] = {
    # NYU hand dataset, PrimeSense Carmine 1.09 (structured light).
    "nyu_carmine": CameraIntrinsics(
        640, 480, 588.036865, 587.075073, 320.0, 240.0, "nyu_carmine", _PS1080_RANGE_M
    ),
    # ICVL and MSRA15, Intel Creative Interactive Gesture Camera (time of flight).
    "icvl": CameraIntrinsics(320, 240, 241.42, 241.42, 160.0, 120.0, "icvl", _DS325_RANGE_M),
    "msra": CameraIntrinsics(320, 240, 241.42, 241.42, 160.0, 120.0, "msra", _DS325_RANGE_M),
    # BigHand2.2M / HANDS17 / FPHA, Intel RealSense SR300.
    "sr300": CameraIntrinsics(
        640, 480, 475.065948, 475.065857, 315.944855, 245.287079, "sr300", _SR300_RANGE_M
    ),
}
"""Depth-sensor intrinsics and working ranges of the hand-pose datasets' sensors."""


def camera_preset(name: str) -> CameraIntrinsics:
    """A camera preset by name.

    Raises:
        UnknownName: listing the valid presets.
    """
    if not isinstance(name, str) or name not in CAMERA_PRESETS:
        raise UnknownName(
            f"unknown camera preset {name!r}; valid presets: {', '.join(CAMERA_PRESETS)}"
        )
    return CAMERA_PRESETS[name]


def look_at_quat_wxyz(eye: np.ndarray, target: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Orientation of a MuJoCo camera at ``eye`` looking at ``target``.

    Args:
        eye: (3,) camera position, world frame, metres.
        target: (3,) point to look at, world frame, metres.
        up: (3,) world direction that appears up in the image.

    Returns:
        (4,) quaternion ``world_from_mjcam`` in (w, x, y, z) order.

    Raises:
        InvalidCamera: if eye and target coincide or the view is parallel to ``up``.
    """
    # Scalar arithmetic: a camera is placed per generated frame, and NumPy's per-call cost on
    # 3-vectors is most of the time.
    ex, ey, ez = (float(v) for v in np.asarray(eye, float).reshape(3))
    tx, ty, tz = (float(v) for v in np.asarray(target, float).reshape(3))
    ux, uy, uz = (float(v) for v in np.asarray(up, float).reshape(3))
    fx, fy, fz = tx - ex, ty - ey, tz - ez
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    if norm < 1e-9:
        raise InvalidCamera(f"camera eye and target coincide at {np.asarray(eye).tolist()}")
    fx, fy, fz = fx / norm, fy / norm, fz / norm
    rx, ry, rz = fy * uz - fz * uy, fz * ux - fx * uz, fx * uy - fy * ux  # forward x up
    norm = math.sqrt(rx * rx + ry * ry + rz * rz)
    if norm < 1e-6:
        raise InvalidCamera(
            f"the viewing direction {[fx, fy, fz]} is parallel to up {list(up)}; pass "
            "another up vector"
        )
    rx, ry, rz = rx / norm, ry / norm, rz / norm
    cx, cy, cz = ry * fz - rz * fy, rz * fx - rx * fz, rx * fy - ry * fx  # right x forward
    # MuJoCo camera axes in world (the matrix's columns): x right, y up, z backward.
    rot = np.array([rx, cx, -fx, ry, cy, -fy, rz, cz, -fz])
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, rot)
    return quat


def add_camera(
    parent: mujoco.MjsBody,
    name: str,
    intrinsics: CameraIntrinsics,
    pos: np.ndarray,
    quat_wxyz: np.ndarray,
) -> mujoco.MjsCamera:
    """Add a MuJoCo camera that renders exactly with ``intrinsics``.

    Args:
        parent: body (or world body) of an ``MjSpec`` to attach the camera to.
        name: camera name.
        intrinsics: pinhole intrinsics.
        pos: (3,) camera position in the parent frame, metres.
        quat_wxyz: (4,) orientation ``parent_from_mjcam`` (see :func:`look_at_quat_wxyz`).

    Returns:
        The camera spec. Render it with an image of ``intrinsics.width x intrinsics.height``.
    """
    cam = parent.add_camera(name=name, pos=pos, quat=quat_wxyz)
    cam.resolution = [intrinsics.width, intrinsics.height]
    cam.focal_pixel = [intrinsics.fx, intrinsics.fy]
    cam.principal_pixel = list(intrinsics.mujoco_principal_pixel)
    cam.sensor_size = [
        intrinsics.width * _SENSOR_PIXEL_PITCH_M,
        intrinsics.height * _SENSOR_PIXEL_PITCH_M,
    ]
    return cam


def T_cam_from_world(data: mujoco.MjData, camera_id: int) -> np.ndarray:  # noqa: N802
    """The OpenCV camera's pose: maps world points into the camera frame.

    Args:
        data: simulation data after ``mj_forward`` / ``mj_kinematics``.
        camera_id: MuJoCo camera id.

    Returns:
        (4, 4) homogeneous transform ``T_cam_from_world``.
    """
    R_world_from_mjcam = data.cam_xmat[camera_id].reshape(3, 3)  # noqa: N806
    R_cam_from_world = R_MJCAM_FROM_CV @ R_world_from_mjcam.T  # noqa: N806
    T = np.eye(4)  # noqa: N806
    T[:3, :3] = R_cam_from_world
    T[:3, 3] = -R_cam_from_world @ data.cam_xpos[camera_id]
    return T
