"""Compiled loops (numba) of dataset generation and writing."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(nogil=True, cache=True)
def depth_units_into(depth: np.ndarray, scale: float, out: np.ndarray) -> None:
    """``out = rint(depth * scale)`` as uint16, in float64; 0 where that is not in 0..65535.

    NaN, infinities, negative depths and depths past the uint16 range all give 0 (no depth):
    one pass over the image, where NumPy made six and a temporary of the nonzero pixels.

    Args:
        depth: (N,) float32 or float64 depth, metres (0 = none).
        scale: units per metre.
        out: (N,) uint16, written.
    """
    for i in range(depth.size):
        z = depth[i]
        if z != 0:
            units = np.rint(np.float64(z) * scale)
            out[i] = np.uint16(units) if 0.0 <= units <= 65535.0 else 0
        else:
            out[i] = 0


@numba.njit(nogil=True, cache=True)
def nearest_box_depth(
    aabb: np.ndarray,
    xmat: np.ndarray,
    xpos: np.ndarray,
    eye: np.ndarray,
    forward: np.ndarray,
) -> float:
    """Smallest depth along ``forward`` from ``eye`` of the corners of oriented boxes.

    Args:
        aabb: (n, 6) boxes in their geom frames: centre, then half sizes (MuJoCo's
            ``geom_aabb``), metres.
        xmat: (n, 9) geom orientations, row-major rotation matrices (world from geom).
        xpos: (n, 3) geom positions in the world, metres.
        eye: (3,) the camera's position, metres.
        forward: (3,) unit viewing direction.

    Returns:
        The smallest ``(corner - eye) . forward``, metres (``inf`` for no boxes).
    """
    nearest = np.inf
    for g in range(aabb.shape[0]):
        # The direction in the geom frame: depth is affine in the local corner.
        local_forward = np.zeros(3)
        for i in range(3):
            for j in range(3):
                local_forward[j] += xmat[g, 3 * i + j] * forward[i]
        depth = 0.0
        for i in range(3):
            depth += (xpos[g, i] - eye[i]) * forward[i]
        for j in range(3):
            depth += aabb[g, j] * local_forward[j] - aabb[g, 3 + j] * abs(local_forward[j])
        nearest = min(nearest, depth)
    return nearest
