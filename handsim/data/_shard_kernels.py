"""Compiled per-pixel loop of the dataset writer (numba): see :func:`depth_units_into`."""

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
