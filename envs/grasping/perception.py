"""The grasp expert's perception: the object's pose filtered from a stream of estimates.

:class:`_PoseFilter` (the expert's estimate of a still object's pose) and the rotation helpers
of the expert's per-step path (wxyz quaternions through MuJoCo's C functions).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from handsim.world.objects import YCBObject

_FILTER_WINDOW = 100  # perceived poses averaged while the object is still (2 s)
_MOTION_MIN_M = 0.01  # the object moved: the recent estimates left the filtered pose by this
_SUPPORT_SNAP_M = 0.02  # estimates whose lowest point is this close to the table rest on it


# Rotations of the per-step path as (w, x, y, z) quaternions through MuJoCo's C functions
# (HandPose.quat_wxyz for a pose's): scipy's Rotation objects cost tens of microseconds each to
# make and combine.
def _rotvec_from_quat(quat: np.ndarray) -> np.ndarray:
    """(3,) rotation vector (angle in [0, pi]) of a unit wxyz quaternion."""
    rotvec = np.empty(3)
    mujoco.mju_quat2Vel(rotvec, quat, 1.0)
    return rotvec


def _quat_angle(quat_a: np.ndarray, quat_b: np.ndarray) -> float:
    """Angle of the rotation between two unit wxyz quaternions, radians in [0, pi]."""
    rotvec = np.empty(3)
    mujoco.mju_subQuat(rotvec, quat_a, quat_b)
    return math.sqrt(float(rotvec @ rotvec))


def _quat_slerp(quat_0: np.ndarray, quat_1: np.ndarray, s: float) -> np.ndarray:
    """Spherical interpolation from ``quat_0`` (s = 0) to ``quat_1`` (s = 1), the short way."""
    rotvec = np.empty(3)
    mujoco.mju_subQuat(rotvec, quat_1, quat_0)  # quat_0 * exp(rotvec) = quat_1
    quat = quat_0.copy()
    mujoco.mju_quatIntegrate(quat, rotvec, s)
    return quat


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:  # noqa: N803
    """(4,) wxyz quaternion of a (3, 3) rotation matrix."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(R, dtype=np.float64).reshape(9))
    return quat


def _median_rows(values: np.ndarray) -> np.ndarray:
    """Per-column median of an (n, k) array: ``np.median(values, axis=0)`` without its overhead."""
    n = len(values)
    ordered = np.sort(values, axis=0)
    if n % 2:
        return ordered[n // 2]
    return (ordered[n // 2 - 1] + ordered[n // 2]) / 2.0


def _robust_sigma(values: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Per-column spread of an (n, k) array about ``centre``: 1.4826 x the MAD.

    The standard deviation for Gaussian values, not moved by outliers.
    """
    return 1.4826 * _median_rows(np.abs(values - centre))


_HULLS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _hull_points(points: np.ndarray) -> np.ndarray:
    """The points on the convex hull of ``points`` (all of them if the hull is degenerate).

    The lowest point of a posed object is a hull vertex (a linear function's minimum over a
    point set lies on its hull), so the filter's per-estimate test reads a few dozen points
    rather than the model's thousands. Cached per points array.
    """
    cached = _HULLS.get(id(points))
    if cached is not None and cached[0] is points:
        return cached[1]
    try:
        hull = points[np.sort(ConvexHull(points).vertices)]
    except (QhullError, ValueError):
        hull = points
    _HULLS[id(points)] = (points, hull)
    return hull


class _PoseFilter:
    """The object's pose from a stream of perceived poses, assuming it stays still.

    Position: the per-axis median of the estimates since the object last moved (at most
    :data:`_FILTER_WINDOW`), orientation: their chordal mean, so one bad estimate shifts the
    result by little. It has moved when the median of the last five estimates leaves the
    filtered position by more than :data:`_MOTION_MIN_M` or four times the spread expected of
    such a median; the window then restarts from those five. Estimates that put the object's
    lowest point within :data:`_SUPPORT_SNAP_M` of the table are first lowered or raised onto
    it (an object waiting to be grasped rests on the table).
    """

    def __init__(self, obj: YCBObject) -> None:
        self.points = _hull_points(np.asarray(obj.model_points_m))
        # The estimates since the object last moved: rows [start, end) of reused buffers.
        self._pos = np.empty((2 * _FILTER_WINDOW, 3))
        self._quat = np.empty((2 * _FILTER_WINDOW, 4))  # wxyz
        self._start = self._end = 0

    def __len__(self) -> int:
        return self._end - self._start

    def add(self, T: np.ndarray) -> None:
        R = T[:3, :3]  # noqa: N806
        pos = T[:3, 3].copy()
        lowest = float((self.points @ R[2]).min() + pos[2])
        if abs(lowest) < _SUPPORT_SNAP_M:
            pos[2] -= lowest
        if self._end == len(self._pos):  # full: move the window to the front
            n = len(self)
            self._pos[:n] = self._pos[self._start : self._end]
            self._quat[:n] = self._quat[self._start : self._end]
            self._start, self._end = 0, n
        self._pos[self._end] = pos
        self._quat[self._end] = _quat_from_matrix(R)
        self._end += 1
        if len(self) > _FILTER_WINDOW:
            self._start += 1
        if len(self) >= 10:
            window = self._pos[self._start : self._end - 5]
            centre = _median_rows(window)
            # Robust per-axis spread of the estimates (MAD), and that of a median of five.
            sigma = _robust_sigma(window, centre)
            recent = _median_rows(self._pos[self._end - 5 : self._end])
            gate = max(_MOTION_MIN_M, 4.0 * float(np.linalg.norm(sigma)) * 1.25 / np.sqrt(5))
            if np.linalg.norm(recent - centre) > gate:
                self._start = self._end - 5

    def spread_m(self) -> float:
        """Robust spread of the position estimates (norm of the per-axis MAD sigmas), metres.

        0 until ten estimates have come since the object last moved.
        """
        if len(self) < 10:
            return 0.0
        window = self._pos[self._start : self._end]
        return float(np.linalg.norm(_robust_sigma(window, _median_rows(window))))

    def pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = _median_rows(self._pos[self._start : self._end])
        # The chordal mean of the orientations: the principal eigenvector of sum(q q^T)
        # (Markley et al. 2007; scipy's Rotation.mean), whatever the quaternions' signs.
        quat = self._quat[self._start : self._end]
        _, vectors = np.linalg.eigh(quat.T @ quat)
        mean = np.empty(9)
        mujoco.mju_quat2Mat(mean, np.ascontiguousarray(vectors[:, -1]))
        T[:3, :3] = mean.reshape(3, 3)
        return T
