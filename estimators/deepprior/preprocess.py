"""Preprocessing of the learned estimators: localization, the 3D cube crop, augmentation, PCA.

NumPy, OpenCV and compiled loops (numba, :mod:`._kernels`; no torch), shared by training,
evaluation and inference.

**Localization on a table.** DeepPrior's centre of mass of the nearest depth slab assumes that
the hand is the nearest thing in view. :func:`remove_plane` first fits the dominant plane of
the depth image (the table, a wall) with RANSAC and drops its pixels; :func:`nearest_blob_com`
then takes the largest connected blob of the nearest remaining depth slab and returns its
centre of mass. A learned refinement (:class:`~handsim.estimators.deepprior.models.Localizer`)
moves that centre towards the middle-finger MCP.

The RANSAC is our own, one compiled loop: it scores 64 three-point hypotheses on a random
subsample of the measured points (every second pixel of every second row) and refits the
winner by least squares on all its inliers. scikit-learn's ``RANSACRegressor`` fits
``z = f(x, y)`` (a plane seen edge-on is not a function of x, y) and refits a regressor per
trial (about 100x slower), which does not fit the inference budget. Both steps work on the
bounding box of the measured pixels (a hand alone covers a tenth of a 320 x 240 image), with
the same arithmetic per pixel as on the whole image.

**Crop.** A cube of edge ``cube_m`` centred on ``center_cam`` is projected at the centre's
depth to an axis-aligned pixel box, which is resampled with nearest-neighbour sampling to
``size x size`` (one affine map, :func:`crop_matrix`). Depth is normalized to [-1, 1] by
``(d - z_c) / (cube / 2)``; missing pixels and pixels beyond the cube's back face are +1,
pixels before its front face -1. Keypoint labels are normalized the same way in 3D,
``(p - c) / (cube / 2)``; :func:`denormalize_keypoints` is the exact inverse.

**Augmentation** (:func:`augment`): an in-plane rotation of the image about the centre's pixel,
a cube scale and a 3D offset of the centre. Labels follow exactly: the keypoints' pixels rotate
with the image about the same pixel, their depth is kept, and they are back-projected; the
offset and the scale change the centre and the cube the labels are normalized with.

**Side.** The networks work in a canonical right-hand frame: a left hand's frame is mirrored
(:func:`mirror_depth`, :func:`mirror_intrinsics`, :func:`mirror_points`) into the right hand it
is the exact mirror of, and the prediction mirrored back. Mirroring the image columns
(``u' = W - 1 - u``) with ``cx' = W - 1 - cx`` is exactly ``x -> -x`` in the camera frame; the
keypoint order is kept (joint ``j`` of the left hand becomes joint ``j`` of the right).

**Prior.** :func:`fit_pca` is a PCA (not whitened) of normalized poses; the learned models
initialize their prior bottleneck from it.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from typing import Any

import cv2
import numpy as np

from handsim.estimator import Estimate, EstimatorBase, validate_depth_input

__all__ = [
    "CUBE_M",
    "CROP_SIZE",
    "MIDDLE_MCP",
    "AugmentParams",
    "PlaneFit",
    "fit_plane_ransac",
    "remove_plane",
    "nearest_blob_com",
    "PlaneRemovedLocalizer",
    "crop_matrix",
    "crop_depth",
    "normalize_keypoints",
    "denormalize_keypoints",
    "rotate_keypoints",
    "crop_pixels",
    "sample_augmentation",
    "augment",
    "fit_pca",
    "mirror_depth",
    "mirror_intrinsics",
    "mirror_points",
]

CUBE_M = 0.250
"""Default cube edge, metres (DeepPrior on NYU / ICVL / MSRA)."""
CROP_SIZE = 128
"""Default crop side, pixels."""
MIDDLE_MCP = 9
"""Keypoint index of the middle-finger MCP: the point the refined localizer predicts."""


@dataclasses.dataclass(frozen=True)
class AugmentParams:
    """One draw of the online augmentation.

    Attributes:
        angle_rad: in-plane rotation of the image about the centre's pixel, radians.
        scale: factor of the cube edge.
        offset_m: (3,) offset added to the crop centre, metres, camera frame.
    """

    angle_rad: float = 0.0
    scale: float = 1.0
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


# Localization ----------------------------------------------------------------------------------

# Defaults of the plane removal and the blob (PlaneRemovedLocalizer uses them too).
_MAX_DEPTH_M = 1.5
_MIN_SPREAD_M = 0.06
_MIN_PIXELS = 100


@dataclasses.dataclass(frozen=True)
class PlaneFit:
    """A plane ``n . p + d = 0`` (unit ``n``, camera frame, metres) and its inlier count."""

    normal: np.ndarray
    offset_m: float
    inliers: int


def fit_plane_ransac(
    points_m: np.ndarray,
    *,
    threshold_m: float = 0.008,
    hypotheses: int = 64,
    subsample: int = 1024,
    rng: np.random.Generator | int | None = 0,
) -> PlaneFit | None:
    """The dominant plane of a point cloud by RANSAC, vectorised over hypotheses.

    Args:
        points_m: (N, 3) points, metres.
        threshold_m: inlier distance, metres.
        hypotheses: random 3-point hypotheses.
        subsample: points the hypotheses are scored on.
        rng: random generator or seed (fixed by default: the same image gives the same plane).

    Returns:
        The :class:`PlaneFit` refitted by least squares on all its inliers, or ``None`` for
        fewer than 3 points.
    """
    fit = _fit_plane(
        np.asarray(points_m, dtype=np.float64), threshold_m, hypotheses, subsample, rng
    )
    if fit is None:
        return None
    n, d, inl = fit
    return PlaneFit(normal=n, offset_m=d, inliers=int(np.count_nonzero(inl)))


_THREAD = threading.local()


def _generator(seed: np.random.Generator | int | None) -> np.random.Generator:
    """``np.random.default_rng(seed)``, for an int seed without seeding again.

    Seeding (SeedSequence's hashing) costs more than the fit's draws; this thread's bit
    generator of the last int seed is reset to its seeded state instead (the same draws).
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        return np.random.default_rng(seed)
    cached = getattr(_THREAD, "generator", None)
    if cached is None or cached[0] != seed:
        bit_generator = np.random.PCG64(int(seed))
        cached = _THREAD.generator = (int(seed), bit_generator, bit_generator.state)
    cached[1].state = cached[2]
    return np.random.Generator(cached[1])


def _fit_plane(
    pts: np.ndarray,
    threshold_m: float,
    hypotheses: int,
    subsample: int,
    rng: np.random.Generator | int | None,
) -> tuple[np.ndarray, float, np.ndarray] | None:
    """:func:`fit_plane_ransac` on (N, 3) float64 points: ``(normal, offset, inlier mask)``."""
    from ._kernels import fit_plane

    if len(pts) < 3:
        return None
    rng = _generator(rng)
    sub = rng.integers(0, len(pts), size=min(subsample, len(pts)))
    tri = rng.integers(0, len(pts), size=(hypotheses, 3))
    n, d, inl, kept = fit_plane(np.ascontiguousarray(pts), sub, tri, float(threshold_m))
    return None if kept == 0 else (n, float(d), inl)


def _box(mask: np.ndarray) -> tuple[slice, slice] | None:
    """The bounding box of a (H, W) bool mask's True pixels as slices, or ``None`` if empty."""
    x, y, w, h = cv2.boundingRect(mask.view(np.uint8))
    return None if w == 0 else (slice(y, y + h), slice(x, x + w))


def remove_plane(
    depth_m: np.ndarray,
    K: np.ndarray,  # noqa: N803
    *,
    threshold_m: float = 0.008,
    min_fraction: float = 0.2,
    min_spread_m: float = _MIN_SPREAD_M,
    max_depth_m: float = _MAX_DEPTH_M,
    rng: np.random.Generator | int | None = 0,
) -> np.ndarray:
    """Depth with the dominant plane's pixels set to 0 (when the plane is large enough).

    Args:
        depth_m: (H, W) depth, metres, 0 = no measurement.
        K: (3, 3) intrinsics.
        threshold_m: plane inlier distance, metres.
        min_fraction: the plane is removed only if it holds at least this fraction of the
            measured pixels,
        min_spread_m: and if its inliers spread at least this much (the standard deviation
            along their second principal axis, metres): a flat palm alone in view is a plane
            too, but a narrow one.
        max_depth_m: depths beyond this are ignored (and set to 0).
        rng: RANSAC random generator or seed.

    Returns:
        (H, W) float32 depth copy, metres.
    """
    out, box = _clip(depth_m, max_depth_m)
    return _remove_plane(out, box, K, threshold_m, min_fraction, min_spread_m, rng)[0]


def _clip(depth_m: np.ndarray, max_depth_m: float) -> tuple[np.ndarray, tuple[slice, slice] | None]:
    """Depth in ``(0, max_depth_m]`` (0 elsewhere and for NaN) and the box of those pixels.

    Returns:
        ``(out, box)``: (H, W) float32 copy, metres, and the box as (rows, columns) slices, or
        ``None`` when no pixel is kept.
    """
    from ._kernels import clip_depth

    depth_m = np.asarray(depth_m)
    if depth_m.dtype != np.float32 or depth_m.ndim != 2:
        out = np.where((depth_m > 0) & (depth_m <= max_depth_m), depth_m, 0).astype(np.float32)
        return out, _box(out > 0)
    # One pass: the copy and the rows and columns that hold depth.
    out = np.empty(depth_m.shape, np.float32)
    rows, cols = np.empty(out.shape[0], np.uint8), np.zeros(out.shape[1], np.uint8)
    clip_depth(depth_m, np.float32(max_depth_m), out, rows, cols)
    r, c = np.flatnonzero(rows), np.flatnonzero(cols)
    if len(r) == 0:
        return out, None
    return out, (slice(int(r[0]), int(r[-1]) + 1), slice(int(c[0]), int(c[-1]) + 1))


def _remove_plane(
    out: np.ndarray,
    box: tuple[slice, slice] | None,
    K: np.ndarray,  # noqa: N803
    threshold_m: float,
    min_fraction: float,
    min_spread_m: float,
    rng: np.random.Generator | int | None,
) -> tuple[np.ndarray, tuple[slice, slice] | None]:
    """:func:`remove_plane` on clipped depth and its box, in place: ``(out, box)``.

    The work is done on the measured pixels' bounding box (a hand alone covers a tenth of the
    image), with the same arithmetic per pixel as on the whole image.
    """
    from ._kernels import drop_plane, half_points, spread_m

    K = np.asarray(K, dtype=np.float64)  # noqa: N806
    if box is None:
        return out, box
    rows, cols = box
    # The fit runs on every second pixel of every second row of the image (even coordinates);
    # the test on every pixel.
    pts = half_points(
        out, rows.start - rows.start % 2, rows.stop, cols.start - cols.start % 2, cols.stop, K
    )
    if len(pts) < 3:
        return out, box
    fit = _fit_plane(pts, threshold_m, 64, 1024, rng)
    if fit is None or np.count_nonzero(fit[2]) < min_fraction * len(pts):
        return out, box
    n, d, inl_mask = fit
    # The spread of (at most ~4000) inliers, every k-th.
    if spread_m(pts, inl_mask, max(1, int(np.count_nonzero(inl_mask)) // 2000)) < min_spread_m:
        return out, box
    if d < 0:  # the camera (origin) on the + side
        n, d = -n, -d
    # n . ray(u, v) * depth + d: the signed distance of every pixel's point. Drop the plane
    # and everything behind it (seen past the table's edge: the floor), in place.
    drop_plane(
        out[box],
        n[1] * (np.arange(rows.start, rows.stop) - K[1, 2]) / K[1, 1],
        n[0] * (np.arange(cols.start, cols.stop) - K[0, 2]) / K[0, 0],
        float(n[2]),
        float(d),
        float(threshold_m),
    )
    return out, box


def nearest_blob_com(
    depth_m: np.ndarray,
    K: np.ndarray,  # noqa: N803
    *,
    cube_m: float = CUBE_M,
    min_pixels: int = _MIN_PIXELS,
) -> np.ndarray | None:
    """Centre of mass of the largest connected blob of the nearest depth slab.

    The slab ``[z_min, z_min + cube]`` is split into 8-connected components and the largest
    one (of at least ``min_pixels`` pixels) is the hand: an object nearer than the hand on a
    table is usually smaller than the hand and its arm, and noise specks are tiny. Its mean
    pixel and median depth are back-projected.

    Args:
        depth_m: (H, W) depth, metres, 0 = no measurement (e.g. after :func:`remove_plane`).
        K: (3, 3) intrinsics.
        cube_m: slab depth, metres.
        min_pixels: smallest blob, pixels.

    Returns:
        (3,) centre in the camera frame, metres, or ``None`` if no blob is large enough.
    """
    depth_m = np.asarray(depth_m)
    if depth_m.dtype.kind != "f":  # as NumPy compares integers with a float: in float64
        depth_m = depth_m.astype(np.float64)
    return _nearest_blob_com(depth_m, K, _box(depth_m > 0), cube_m, min_pixels)


def _nearest_blob_com(
    depth_m: np.ndarray,
    K: np.ndarray,  # noqa: N803
    box: tuple[slice, slice] | None,
    cube_m: float,
    min_pixels: int,
) -> np.ndarray | None:
    """:func:`nearest_blob_com` in a box that holds every measured pixel.

    On the box, the blobs are the same and labelled in the same (raster) order.
    """
    from ._kernels import blob_sums, label_sizes, nearest_slab

    if box is None:
        return None
    depth = depth_m[box]
    count, _, slab = nearest_slab(depth, float(cube_m))
    if count < min_pixels:
        return None
    n, labels = cv2.connectedComponents(slab, connectivity=8)
    if n <= 1:
        return None
    sizes = label_sizes(labels, n)
    sizes[0] = -1  # the background
    sizes[sizes < min_pixels] = -1
    best = int(np.argmax(sizes))
    if sizes[best] < 0:
        return None
    su, sv, depths = blob_sums(labels, best, int(sizes[best]), depth)
    z = float(_median(depths))
    # The mean of the image's pixel coordinates: exact integer sums, one rounding.
    count = len(depths)
    u = (su + count * box[1].start) / count
    v = (sv + count * box[0].start) / count
    return np.array([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z])


def _median(values: np.ndarray) -> Any:
    """``np.median`` of a 1-D float array (no NaN) without its checks: the same value."""
    k = len(values) // 2
    if len(values) % 2:
        return np.partition(values, k)[k]
    part = np.partition(values, (k - 1, k))
    # np.median's mean of the two middle values, in the array's dtype.
    return (part[k - 1] + part[k]) / values.dtype.type(2)


class PlaneRemovedLocalizer(EstimatorBase):
    """Hand centre: RANSAC plane removal, then the nearest blob's centre of mass.

    Args:
        cube_mm: slab depth of the blob, mm.
        threshold_mm: plane inlier distance, mm.
        min_fraction: smallest plane, as a fraction of the measured pixels.
    """

    def __init__(
        self, *, cube_mm: float = 250.0, threshold_mm: float = 8.0, min_fraction: float = 0.2
    ) -> None:
        self.cube_m = float(cube_mm) / 1000.0
        self.threshold_m = float(threshold_mm) / 1000.0
        self.min_fraction = float(min_fraction)

    def localize(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray | None:  # noqa: N803
        """(3,) centre, metres, camera frame, or ``None`` (unchecked input)."""
        # remove_plane and nearest_blob_com, the blob searched in the box of the measured
        # pixels that the plane removal found.
        cleaned, box = _remove_plane(
            *_clip(depth_m, _MAX_DEPTH_M), K, self.threshold_m, self.min_fraction, _MIN_SPREAD_M, 0
        )
        return _nearest_blob_com(cleaned, K, box, self.cube_m, _MIN_PIXELS)

    def predict(self, depth: np.ndarray, K: np.ndarray) -> Estimate:  # noqa: N803
        """``Estimate(center_cam=...)`` or ``Estimate(valid=False)`` (no blob)."""
        depth_m, K_cv = validate_depth_input(depth, K)  # noqa: N806
        center = self.localize(depth_m, K_cv)
        return Estimate(valid=False) if center is None else Estimate(center_cam=center)


# Crop ------------------------------------------------------------------------------------------


def crop_matrix(
    center_cam: np.ndarray,
    K: np.ndarray,  # noqa: N803
    cube_m: float = CUBE_M,
    size: int = CROP_SIZE,
    angle_rad: float = 0.0,
) -> np.ndarray:
    """The (2, 3) affine map from image pixels ``(u, v)`` to crop pixels.

    The cube's face at the centre's depth spans ``size`` pixels; the image is first rotated by
    ``angle_rad`` about the centre's pixel (positive: counter-clockwise as seen on screen).

    Args:
        center_cam: (3,) crop centre, metres, camera frame (z > 0).
        K: (3, 3) intrinsics.
        cube_m: cube edge, metres.
        size: crop side, pixels.
        angle_rad: in-plane rotation, radians.

    Returns:
        (2, 3) float64 matrix ``M``: ``crop = M @ (u, v, 1)``.
    """
    cx, cy, cz = (float(c) for c in center_cam)
    fx, fy = float(K[0, 0]), float(K[1, 1])
    uc = fx * cx / cz + float(K[0, 2])
    vc = fy * cy / cz + float(K[1, 2])
    sx = size * cz / (fx * cube_m)
    sy = size * cz / (fy * cube_m)
    cos, sin = math.cos(angle_rad), math.sin(angle_rad)
    # diag(sx, sy) @ R, R = [[cos, sin], [-sin, cos]] (v points down: CCW on screen); in
    # Python floats, as this runs several times per frame at inference.
    a00, a01, a10, a11 = sx * cos, sx * sin, -sy * sin, sy * cos
    mid = (size - 1) / 2.0
    return np.array(
        [[a00, a01, mid - (a00 * uc + a01 * vc)], [a10, a11, mid - (a10 * uc + a11 * vc)]]
    )


def crop_depth(
    depth_m: np.ndarray,
    M: np.ndarray,  # noqa: N803
    center_z_m: float,
    cube_m: float = CUBE_M,
    size: int = CROP_SIZE,
) -> np.ndarray:
    """Crop and normalize depth: ``(d - z_c) / (cube / 2)`` in [-1, 1], missing and far = +1.

    Args:
        depth_m: (H, W) float32 depth, metres, 0 = no measurement.
        M: (2, 3) map of :func:`crop_matrix`.
        center_z_m: crop centre depth ``z_c``, metres.
        cube_m: cube edge, metres.
        size: crop side, pixels.

    Returns:
        (size, size) float32 normalized depth.
    """
    from ._kernels import normalize_crop

    norm = cv2.warpAffine(
        np.ascontiguousarray(depth_m, dtype=np.float32),
        M,
        (size, size),
        flags=cv2.INTER_NEAREST,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0.0,
    )
    normalize_crop(norm, np.float32(center_z_m), np.float32(cube_m / 2.0))
    return norm


def normalize_keypoints(keypoints_cam: np.ndarray, center_cam: np.ndarray, cube_m: float) -> Any:
    """``(p - c) / (cube / 2)``: (..., J, 3) metres -> normalized (the labels)."""
    return (np.asarray(keypoints_cam) - np.asarray(center_cam)[..., None, :]) / (cube_m / 2.0)


def denormalize_keypoints(normalized: np.ndarray, center_cam: np.ndarray, cube_m: Any) -> Any:
    """Exact inverse of :func:`normalize_keypoints`: (..., J, 3) -> metres, camera frame."""
    cube = np.asarray(cube_m, dtype=np.float64)[..., None, None]
    return np.asarray(normalized) * (cube / 2.0) + np.asarray(center_cam)[..., None, :]


def rotate_keypoints(
    keypoints_cam: np.ndarray,
    K: np.ndarray,  # noqa: N803
    center_cam: np.ndarray,
    angle_rad: float,
) -> np.ndarray:
    """Keypoints moved as the image rotates by ``angle_rad`` about the centre's pixel.

    Each keypoint's pixel is rotated like the image (:func:`crop_matrix`), its depth is kept,
    and it is back-projected.

    Args:
        keypoints_cam: (J, 3) keypoints, metres, camera frame (z > 0).
        K: (3, 3) intrinsics.
        center_cam: (3,) rotation centre, metres.
        angle_rad: rotation, radians.

    Returns:
        (J, 3) rotated keypoints, metres.
    """
    kp = np.asarray(keypoints_cam, dtype=np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    c = np.asarray(center_cam, dtype=np.float64)
    uc, vc = fx * c[0] / c[2] + cx, fy * c[1] / c[2] + cy
    u = fx * kp[:, 0] / kp[:, 2] + cx - uc
    v = fy * kp[:, 1] / kp[:, 2] + cy - vc
    cos, sin = math.cos(angle_rad), math.sin(angle_rad)
    ur, vr = cos * u + sin * v + uc, -sin * u + cos * v + vc
    z = kp[:, 2]
    return np.stack([(ur - cx) * z / fx, (vr - cy) * z / fy, z], axis=1)


def crop_pixels(keypoints_cam: np.ndarray, K: np.ndarray, M: np.ndarray) -> np.ndarray:  # noqa: N803
    """(J, 2) crop pixels of (J, 3) camera-frame keypoints under the map ``M``."""
    kp = np.asarray(keypoints_cam, dtype=np.float64)
    uv = np.stack(
        [K[0, 0] * kp[:, 0] / kp[:, 2] + K[0, 2], K[1, 1] * kp[:, 1] / kp[:, 2] + K[1, 2]], axis=1
    )
    return uv @ M[:, :2].T + M[:, 2]


def sample_augmentation(
    rng: np.random.Generator,
    *,
    rotation: bool = True,
    scale: bool = True,
    translation: bool = True,
    max_angle_deg: float = 180.0,
    scale_sigma: float = 0.02,
    offset_sigma_m: float = 0.005,
) -> AugmentParams:
    """Draw rotation U(-180, 180) deg, scale N(1, 0.02) and offset N(0, 5 mm) (each optional)."""
    angle = math.radians(rng.uniform(-max_angle_deg, max_angle_deg)) if rotation else 0.0
    s = float(rng.normal(1.0, scale_sigma)) if scale else 1.0
    offset = rng.normal(0.0, offset_sigma_m, size=3) if translation else np.zeros(3)
    return AugmentParams(
        angle_rad=angle, scale=max(s, 0.5), offset_m=tuple(float(o) for o in offset)
    )


def augment(
    depth_m: np.ndarray,
    K: np.ndarray,  # noqa: N803
    keypoints_cam: np.ndarray,
    center_cam: np.ndarray,
    params: AugmentParams = AugmentParams(),  # noqa: B008 (frozen)
    *,
    cube_m: float = CUBE_M,
    size: int = CROP_SIZE,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """One training sample: the augmented crop and its exactly transformed labels.

    Args:
        depth_m: (H, W) depth, metres.
        K: (3, 3) intrinsics.
        keypoints_cam: (J, 3) keypoints, metres, camera frame.
        center_cam: (3,) crop centre before the offset, metres.
        params: the augmentation.
        cube_m: cube edge before the scale, metres.
        size: crop side, pixels.

    Returns:
        ``(crop, labels, center, cube)``: (size, size) float32 normalized depth, (J, 3)
        normalized labels of the rotated keypoints, the (3,) centre and the cube edge used.
    """
    center = np.asarray(center_cam, dtype=np.float64) + np.asarray(params.offset_m)
    cube = cube_m * params.scale
    M = crop_matrix(center, K, cube, size, params.angle_rad)  # noqa: N806
    crop = crop_depth(depth_m, M, center[2], cube, size)
    rotated = rotate_keypoints(keypoints_cam, K, center, params.angle_rad)
    return crop, normalize_keypoints(rotated, center, cube), center, cube


# Side ------------------------------------------------------------------------------------------


def mirror_depth(depth: np.ndarray) -> np.ndarray:
    """Image columns flipped (a contiguous copy): (..., H, W) -> (..., H, W), same dtype."""
    return np.ascontiguousarray(np.asarray(depth)[..., ::-1])


def mirror_intrinsics(K: np.ndarray, width: int) -> np.ndarray:  # noqa: N803
    """Intrinsics of the column-flipped image: ``cx' = W - 1 - cx`` and the skew negated.

    Args:
        K: (..., 3, 3) intrinsics of an image ``width`` pixels wide.
        width: image width ``W``, pixels.

    Returns:
        (..., 3, 3) float64 intrinsics under which ``x -> -x`` projects to ``u' = W - 1 - u``.
    """
    out = np.array(K, dtype=np.float64)
    out[..., 0, 2] = (width - 1) - out[..., 0, 2]
    out[..., 0, 1] = -out[..., 0, 1]
    return out


def mirror_points(points_cam: np.ndarray) -> np.ndarray:
    """``x -> -x`` of (..., 3) camera-frame points (keypoints keep their order)."""
    out = np.array(points_cam, dtype=np.float64)
    out[..., 0] = -out[..., 0]
    return out


# Prior -----------------------------------------------------------------------------------------


def fit_pca(poses: np.ndarray, n_components: int) -> dict[str, np.ndarray]:
    """PCA of flattened normalized poses (not whitened).

    Args:
        poses: (N, D) poses (e.g. normalized (N, 21, 3) keypoints reshaped to (N, 63)).
        n_components: components kept (<= min(N, D)).

    Returns:
        ``mean`` (D,), ``components`` (n_components, D) orthonormal rows, ``explained`` (D',)
        explained-variance ratio of every component (all of them, for the curve).
    """
    X = np.asarray(poses, dtype=np.float64)  # noqa: N806
    mean = X.mean(axis=0)
    _, s, vt = np.linalg.svd(X - mean, full_matrices=False)
    var = s**2
    return {
        "mean": mean,
        "components": vt[:n_components],
        "explained": var / var.sum(),
    }
