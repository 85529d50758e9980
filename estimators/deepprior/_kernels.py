"""Compiled loops (numba) of the plane-removal detector (:mod:`.preprocess`).

NumPy's version of the RANSAC plane fit made some forty calls on arrays of a thousand points
(each a few microseconds of call and temporary array), and the plane test and the blob's
statistics a pass over the image per operation. Each function here is one loop. The plane
test and the blob's sums do NumPy's arithmetic in NumPy's order (the same bits); the fit's dot
products and its least-squares refit (the smallest eigenvector of the inliers' 3 x 3 scatter
matrix instead of an SVD of all of them) differ from NumPy's by rounding only.

The first call in a process compiles them (a few seconds), or loads them from numba's cache
(``__pycache__`` beside this file, or ``NUMBA_CACHE_DIR``).
"""

from __future__ import annotations

import numba
import numpy as np

_JIT = {"nogil": True, "cache": True}


@numba.njit(**_JIT)
def clip_depth(
    depth_m: np.ndarray,
    max_depth_m: np.float32,
    out: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
) -> None:
    """Depth in ``(0, max_depth_m]``, +0 elsewhere, and the rows and columns that hold some.

    NaN, inf and -0 become +0 (as OpenCV's two thresholds and patchNaNs did).

    Args:
        depth_m: (H, W) float32 depth, metres.
        max_depth_m: farthest depth kept, metres.
        out: (H, W) float32, written.
        rows: (H,) uint8, written: 1 where the row holds a kept depth.
        cols: (W,) uint8, set to 1 (not cleared) where the column holds a kept depth.
    """
    zero = np.float32(0.0)
    for r in range(depth_m.shape[0]):
        seen = np.uint8(0)
        for c in range(depth_m.shape[1]):
            z = depth_m[r, c]
            keep = np.uint8((z > zero) & (z <= max_depth_m))  # uint8: the loop vectorises
            out[r, c] = z if keep else zero
            seen |= keep
            cols[c] |= keep
        rows[r] = seen


@numba.njit(**_JIT)
def _scatter(pts: np.ndarray, mask: np.ndarray, step: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Mean, 3 x 3 scatter matrix (centred) and count of every ``step``-th masked point.

    The points taken are the first masked one, the ``step + 1``-th, and so on.
    """
    mean = np.zeros(3)
    count = 0
    seen = 0
    for i in range(pts.shape[0]):
        if mask[i]:
            if seen % step == 0:
                mean[0] += pts[i, 0]
                mean[1] += pts[i, 1]
                mean[2] += pts[i, 2]
                count += 1
            seen += 1
    mean /= max(count, 1)
    scatter = np.zeros((3, 3))
    seen = 0
    for i in range(pts.shape[0]):
        if mask[i]:
            if seen % step == 0:
                x = pts[i, 0] - mean[0]
                y = pts[i, 1] - mean[1]
                z = pts[i, 2] - mean[2]
                scatter[0, 0] += x * x
                scatter[0, 1] += x * y
                scatter[0, 2] += x * z
                scatter[1, 1] += y * y
                scatter[1, 2] += y * z
                scatter[2, 2] += z * z
            seen += 1
    scatter[1, 0] = scatter[0, 1]
    scatter[2, 0] = scatter[0, 2]
    scatter[2, 1] = scatter[1, 2]
    return mean, scatter, count


@numba.njit(**_JIT)
def _inliers(pts: np.ndarray, n: np.ndarray, d: float, threshold_m: float, mask: np.ndarray) -> int:
    """``mask = |pts . n + d| < threshold``; returns the inlier count."""
    count = 0
    for i in range(pts.shape[0]):
        inside = abs(pts[i, 0] * n[0] + pts[i, 1] * n[1] + pts[i, 2] * n[2] + d) < threshold_m
        mask[i] = inside
        count += inside
    return count


@numba.njit(**_JIT)
def fit_plane(
    pts: np.ndarray, sub: np.ndarray, tri: np.ndarray, threshold_m: float
) -> tuple[np.ndarray, float, np.ndarray, int]:
    """RANSAC over given hypotheses, then a least-squares refit on the winner's inliers.

    Args:
        pts: (N, 3) float64 points, metres.
        sub: (S,) indices of the points the hypotheses are scored on.
        tri: (H, 3) indices of each hypothesis' three points.
        threshold_m: inlier distance, metres.

    Returns:
        ``(normal (3,), offset, inlier mask (N,), hypotheses kept)``; no hypothesis is kept
        when every triple is degenerate (the other values are then meaningless).
    """
    best_count, kept = -1, 0
    n = np.zeros(3)
    d = 0.0
    # The scored points in three contiguous arrays: the count below vectorises.
    sx, sy, sz = pts[sub, 0].copy(), pts[sub, 1].copy(), pts[sub, 2].copy()
    for h in range(tri.shape[0]):
        a, b, c = tri[h, 0], tri[h, 1], tri[h, 2]
        e0 = pts[b, 0] - pts[a, 0]
        e1 = pts[b, 1] - pts[a, 1]
        e2 = pts[b, 2] - pts[a, 2]
        f0 = pts[c, 0] - pts[a, 0]
        f1 = pts[c, 1] - pts[a, 1]
        f2 = pts[c, 2] - pts[a, 2]
        n0, n1, n2 = e1 * f2 - e2 * f1, e2 * f0 - e0 * f2, e0 * f1 - e1 * f0
        norm = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if not norm > 1e-12:
            continue
        kept += 1
        n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
        off = -(n0 * pts[a, 0] + n1 * pts[a, 1] + n2 * pts[a, 2])
        count = 0
        for i in range(len(sx)):
            count += abs(sx[i] * n0 + sy[i] * n1 + sz[i] * n2 + off) < threshold_m
        if count > best_count:  # the first of equal counts, as argmax
            best_count = count
            n[0], n[1], n[2], d = n0, n1, n2, off
    mask = np.zeros(pts.shape[0], np.bool_)
    if kept == 0:
        return n, d, mask, kept
    if _inliers(pts, n, d, threshold_m, mask) >= 3:
        mean, scatter, _ = _scatter(pts, mask, 1)
        n = np.linalg.eigh(scatter)[1][:, 0].copy()  # the smallest eigenvalue's: the normal
        d = -(n[0] * mean[0] + n[1] * mean[1] + n[2] * mean[2])
        _inliers(pts, n, d, threshold_m, mask)
    return n, d, mask, kept


@numba.njit(**_JIT)
def spread_m(pts: np.ndarray, mask: np.ndarray, step: int) -> float:
    """The standard deviation along the second principal axis of every ``step``-th inlier."""
    _, scatter, count = _scatter(pts, mask, step)
    return np.sqrt(max(np.linalg.eigvalsh(scatter)[1], 0.0) / max(count, 1))


@numba.njit(**_JIT)
def drop_plane(
    depth_m: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    n2: float,
    d: float,
    threshold_m: float,
) -> None:
    """Zero the pixels whose point lies within ``threshold_m`` of the plane or behind it.

    ``dist = (rows[r] + cols[c] + n2) * depth + d``, NumPy's order (``rows`` and ``cols`` are
    ``n_y (v - cy) / fy`` and ``n_x (u - cx) / fx`` of the box's pixels).

    Args:
        depth_m: (h, w) float32 depth of the box, metres, changed in place.
        rows: (h,) float64 row terms.
        cols: (w,) float64 column terms.
        n2: the normal's z.
        d: the plane's offset, metres (camera on the + side).
        threshold_m: inlier distance, metres.
    """
    zero = np.float32(0.0)
    for r in range(depth_m.shape[0]):
        row = rows[r]
        for c in range(depth_m.shape[1]):
            z = depth_m[r, c]
            # Without branches (the loop vectorises); a missing pixel stays 0.
            near = (row + cols[c] + n2) * np.float64(z) + d < threshold_m
            depth_m[r, c] = zero if near else z


@numba.njit(**_JIT)
def half_points(
    depth_m: np.ndarray,
    r0: int,
    r1: int,
    c0: int,
    c1: int,
    K: np.ndarray,  # noqa: N803
) -> np.ndarray:
    """The back-projected points of the measured pixels of a grid of every second pixel.

    The grid is rows ``r0, r0 + 2, ... < r1`` and columns ``c0, c0 + 2, ... < c1``, read
    row-major; a point is ``((u - cx) z / fx, (v - cy) z / fy, z)``, NumPy's arithmetic.

    Args:
        depth_m: (H, W) depth, metres, 0 = no measurement.
        r0: first row.
        r1: end row.
        c0: first column.
        c1: end column.
        K: (3, 3) float64 intrinsics.

    Returns:
        (N, 3) float64 points, metres, camera frame.
    """
    count = 0
    for r in range(r0, r1, 2):
        for c in range(c0, c1, 2):
            count += depth_m[r, c] > 0
    pts = np.empty((count, 3))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    k = 0
    for r in range(r0, r1, 2):
        for c in range(c0, c1, 2):
            if depth_m[r, c] > 0:
                z = np.float64(depth_m[r, c])
                pts[k, 0] = (c - cx) * z / fx
                pts[k, 1] = (r - cy) * z / fy
                pts[k, 2] = z
                k += 1
    return pts


@numba.njit(**_JIT)
def nearest_slab(depth_m: np.ndarray, cube_m: float) -> tuple[int, float, np.ndarray]:
    """The measured pixels (> 0) and those of them within ``cube_m`` of the nearest.

    The slab is ``0 < depth <= z_min + cube_m``, the bound rounded to the depth's dtype (as
    NumPy compares a float32 array with a Python float).

    Args:
        depth_m: (H, W) float depth, metres, 0 = no measurement.
        cube_m: slab depth, metres.

    Returns:
        ``(count, z_min, slab)``: the number of measured pixels, the nearest depth (``inf``
        if none) and the (H, W) uint8 slab mask (1 inside).
    """
    count = 0
    low = np.inf
    for r in range(depth_m.shape[0]):
        for c in range(depth_m.shape[1]):
            z = depth_m[r, c]
            count += z > 0
            low = min(low, z if z > 0 else np.inf)
    bound = np.empty(1, depth_m.dtype)
    bound[0] = np.float64(low) + cube_m
    far = bound[0]
    slab = np.empty(depth_m.shape, np.uint8)
    for r in range(depth_m.shape[0]):
        for c in range(depth_m.shape[1]):
            z = depth_m[r, c]
            slab[r, c] = (z > 0) & (z <= far)
    return count, low, slab


@numba.njit(**_JIT)
def label_sizes(labels: np.ndarray, n: int) -> np.ndarray:
    """(n,) int64 pixel count of each label ``0 .. n - 1`` of a (H, W) label image."""
    # Four partial counts (by column): neighbouring pixels of one blob do not wait on each
    # other's increment.
    partial = np.zeros((4, n), np.int64)
    for r in range(labels.shape[0]):
        for c in range(labels.shape[1]):
            partial[c & 3, labels[r, c]] += 1
    sizes = np.zeros(n, np.int64)
    for k in range(4):
        sizes += partial[k]
    return sizes


@numba.njit(**_JIT)
def blob_sums(
    labels: np.ndarray, label: int, count: int, depth_m: np.ndarray
) -> tuple[int, int, np.ndarray]:
    """Pixel-coordinate sums of the ``count`` pixels of one label and their depths.

    Returns:
        ``(sum of columns, sum of rows, (count,) depths in raster order)``.
    """
    depths = np.empty(count, depth_m.dtype)
    su, sv, k = 0, 0, 0
    for r in range(labels.shape[0]):
        for c in range(labels.shape[1]):
            if labels[r, c] == label:
                su += c
                sv += r
                depths[k] = depth_m[r, c]
                k += 1
    return su, sv, depths


@numba.njit(**_JIT)
def normalize_crop(crop: np.ndarray, center_z_m: np.float32, half_cube_m: np.float32) -> None:
    """``(d - z_c) / (cube / 2)`` clipped to [-1, 1], missing and far = +1, in place.

    In float32, NumPy's operations in NumPy's order (the same bits as the passes it replaces).

    Args:
        crop: (S, S) float32 depth, metres, 0 = no measurement; normalized in place.
        center_z_m: crop centre depth, metres.
        half_cube_m: half the cube edge, metres.
    """
    one = np.float32(1.0)
    for r in range(crop.shape[0]):
        for c in range(crop.shape[1]):
            z = crop[r, c]
            v = (z - center_z_m) / half_cube_m
            if z <= 0 or v > one:
                crop[r, c] = one
            elif v < -one:
                crop[r, c] = -one
            else:
                crop[r, c] = v
