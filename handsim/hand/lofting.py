"""Triangles of a lofted solid: a pole, rings of vertices, a pole.

Shared by the hand's skin (:mod:`handsim.hand.skin`) and the objects' revolved and lofted
meshes (:mod:`handsim.world.meshing`); it lives with the hand because the world imports the
hand, not the other way round.
"""

from __future__ import annotations

import numpy as np

__all__ = ["loft_faces"]


def loft_faces(n_rings: int, n_around: int) -> np.ndarray:
    """Triangles of a closed loft: vertex 0 a pole, ``n_rings`` rings of ``n_around``, a pole.

    Vertex ``1 + r * n_around + j`` is point ``j`` of ring ``r``; the last vertex is the second
    pole. The winding is counter-clockwise seen from outside when ring points run as
    ``c + cos(t) u + sin(t) v`` with ``t`` increasing and the rings advance along ``v x u``
    (for example ``u = +x``, ``v = +z``, rings advancing along ``+y``); for the opposite
    orientation reverse every triangle.

    Args:
        n_rings: number of rings (>= 1).
        n_around: vertices per ring (>= 3).

    Returns:
        (2 * n_rings * n_around, 3) int32 vertex indices.
    """
    j = np.arange(n_around)
    jn = (j + 1) % n_around
    faces = [np.stack([1 + j, 1 + jn, np.zeros(n_around, dtype=np.int64)], axis=1)]
    for r in range(n_rings - 1):
        a = 1 + r * n_around
        b = a + n_around
        faces.append(np.stack([b + jn, a + jn, a + j], axis=1))
        faces.append(np.stack([b + j, b + jn, a + j], axis=1))
    last = 1 + n_rings * n_around
    a = 1 + (n_rings - 1) * n_around
    faces.append(np.stack([a + jn, a + j, np.full(n_around, last)], axis=1))
    return np.concatenate(faces).astype(np.int32)
