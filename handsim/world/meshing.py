"""Meshing machinery for the built-in objects.

Lofts, revolutions, convex hulls, signed distance functions meshed by marching tetrahedra, and
surface-keeping decimation.

Meshing: single-piece shapes are lofts of elliptic rings (exact, 0.4-5k faces); the vessels
are a loft of the shell plus a tube whose end rings are slid onto the wall and stitched into
windows cut in it (one closed genus-1 surface, no boolean operations). The drill, scissors,
marker and clamps are signed-distance unions (rounded edges, filleted joints) meshed by
marching tetrahedra on a rectilinear grid (closed 2-manifold by construction), then
decimated by edge collapses that stay on the surface (0.15 mm) and keep it a manifold
(2-12k faces). Collision pieces are convex hulls of the same primitives, so hollow objects
stay hollow to the fingers. Building all 21 objects takes ~6 s; :func:`get_object` caches.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from handsim.hand.lofting import loft_faces
from handsim.world.objects import _MM

if TYPE_CHECKING:
    # trimesh and scipy.sparse load when a mesh is built, not on `import handsim`.
    import trimesh

__all__ = []

# Mesh construction ---------------------------------------------------------------------------


def _loft(centers: np.ndarray, u: np.ndarray, v: np.ndarray, n_around: int) -> trimesh.Trimesh:
    """A closed mesh through elliptic rings ``c + cos(t) u + sin(t) v`` (first/last: poles).

    Args:
        centers: (K, 3) ring centres; the first and last are single vertices (poles).
        u: (K, 3) first semi-axis vector of each ring (ignored for the poles).
        v: (K, 3) second semi-axis vector of each ring (ignored for the poles).
        n_around: vertices per ring.
    """
    centers = np.asarray(centers, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    t = 2.0 * np.pi * np.arange(n_around) / n_around
    rings = (
        centers[1:-1, None, :]
        + np.cos(t)[None, :, None] * u[1:-1, None, :]
        + np.sin(t)[None, :, None] * v[1:-1, None, :]
    )
    n_rings = len(centers) - 2
    vertices = np.concatenate([centers[:1], rings.reshape(-1, 3), centers[-1:]])
    import trimesh

    mesh = trimesh.Trimesh(vertices, loft_faces(n_rings, n_around), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _revolve_rows(rows: np.ndarray, n_around: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Loft inputs for rings about the y axis; ``rows`` (K, 4): semi-axis x, semi-axis z, y, x0."""
    rows = np.asarray(rows, dtype=np.float64)
    k = len(rows)
    centers = np.stack([rows[:, 3], rows[:, 2], np.zeros(k)], axis=1)
    u = np.zeros((k, 3))
    u[:, 0] = rows[:, 0]
    v = np.zeros((k, 3))
    v[:, 2] = rows[:, 1]
    return centers, u, v


def _revolve(rows_mm: Sequence[Sequence[float]], n_around: int = 64) -> trimesh.Trimesh:
    """Lofted solid about the y axis from (a, b, y[, x0]) rows in mm (first/last: poles)."""
    rows = _rows_m(rows_mm)
    return _loft(*_revolve_rows(rows, n_around), n_around)


def _rows_m(rows_mm: Sequence[Sequence[float]]) -> np.ndarray:
    rows = np.array([tuple(r) + (0.0,) * (4 - len(r)) for r in rows_mm], dtype=np.float64)
    return rows * _MM


def _ring_points(rows: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Points of (a, b, y, x0) rows (metres) at the given angles, (len(rows) * len(angles), 3)."""
    rows = np.asarray(rows, dtype=np.float64)
    x = rows[:, None, 3] + rows[:, None, 0] * np.cos(angles)[None, :]
    z = rows[:, None, 1] * np.sin(angles)[None, :]
    y = np.broadcast_to(rows[:, None, 2], x.shape)
    return np.stack([x, y, z], axis=-1).reshape(-1, 3)


def _hull(points: np.ndarray) -> trimesh.Trimesh:
    import trimesh

    hull = trimesh.convex.convex_hull(np.asarray(points, dtype=np.float64))
    if hull.volume < 0:
        hull.invert()
    return hull


@functools.cache
def _sphere_dirs() -> np.ndarray:
    import trimesh

    return np.asarray(trimesh.creation.icosphere(subdivisions=2).vertices)


def _spheres(centers: np.ndarray, radii: np.ndarray | float) -> np.ndarray:
    centers = np.atleast_2d(np.asarray(centers, dtype=np.float64))
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(centers),))
    return (centers[:, None, :] + radii[:, None, None] * _sphere_dirs()[None]).reshape(-1, 3)


def _disc_points(center: np.ndarray, normal_axis: int, radius: float, n: int = 32) -> np.ndarray:
    t = 2.0 * np.pi * np.arange(n) / n
    pts = np.zeros((n, 3))
    a, b = [i for i in range(3) if i != normal_axis]
    pts[:, a] = radius * np.cos(t)
    pts[:, b] = radius * np.sin(t)
    return pts + np.asarray(center, dtype=np.float64)


def _slab_points(points_2d: np.ndarray, z0: float, z1: float) -> np.ndarray:
    p = np.asarray(points_2d, dtype=np.float64)
    return np.concatenate(
        [np.column_stack([p, np.full(len(p), z0)]), np.column_stack([p, np.full(len(p), z1)])]
    )


def _circle_2d(center: Sequence[float], radius: float, n: int = 24) -> np.ndarray:
    t = 2.0 * np.pi * np.arange(n) / n
    return np.asarray(center, dtype=np.float64) + radius * np.column_stack([np.cos(t), np.sin(t)])


# Signed distance functions (negative inside) and marching tetrahedra.


def _sd_polygon(q: np.ndarray, poly: np.ndarray, skip_axis: bool = False) -> np.ndarray:
    """Signed distance of 2D points ``q`` (N, 2) to a closed polygon (E, 2).

    With ``skip_axis``, edges on ``q_x = 0`` (the axis of a revolved profile, for points with
    ``q_x >= 0``) are ignored: they are not boundary, and the inside test casts its ray
    towards +x, so they only matter (wrongly) for points on the axis.
    """
    d2 = np.full(len(q), np.inf)
    inside = np.zeros(len(q), dtype=bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        if skip_axis and abs(a[0]) < 1e-12 and abs(b[0]) < 1e-12:
            continue
        e = b - a
        w = q - a
        t = np.clip(w @ (e / (e @ e)), 0.0, 1.0)
        r = w - t[:, None] * e
        np.minimum(d2, np.einsum("ij,ij->i", r, r), out=d2)
        c1 = q[:, 1] >= a[1]
        c2 = q[:, 1] < b[1]
        c3 = e[0] * w[:, 1] > e[1] * w[:, 0]
        inside ^= (c1 & c2 & c3) | (~c1 & ~c2 & ~c3)
    return np.where(inside, -1.0, 1.0) * np.sqrt(d2)


def _sd_revolved(p: np.ndarray, profile: np.ndarray) -> np.ndarray:
    """Solid of revolution about the y axis of a closed (r, y) polygon touching r = 0."""
    q = np.column_stack([np.hypot(p[:, 0], p[:, 2]), p[:, 1]])
    return _sd_polygon(q, profile, skip_axis=True)


def _sd_segments(p: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    """Distance to a polyline (K, D) minus ``radius`` (capsule chain in 2D or 3D)."""
    d2 = np.full(len(p), np.inf)
    for a, b in zip(points[:-1], points[1:], strict=True):
        e = b - a
        w = p - a
        t = np.clip(w @ (e / (e @ e)), 0.0, 1.0)
        w -= t[:, None] * e
        np.minimum(d2, np.einsum("ij,ij->i", w, w), out=d2)
    return np.sqrt(d2) - radius


def _sd_round_box(
    p: np.ndarray,
    center: Sequence[float],
    half: Sequence[float],
    radius: float = 0.0,
    rot: np.ndarray | None = None,
) -> np.ndarray:
    local = p - np.asarray(center)
    if rot is not None:
        local = local @ rot
    q = np.abs(local) - (np.asarray(half) - radius)
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    return outside + np.minimum(q.max(axis=1), 0.0) - radius


def _sd_cylinder(p: np.ndarray, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """Capped cylinder from ``a`` to ``b`` (exact)."""
    a = np.asarray(a, dtype=np.float64)
    ba = np.asarray(b, dtype=np.float64) - a
    pa = p - a
    baba = ba @ ba
    paba = pa @ ba
    x = np.linalg.norm(pa * baba - paba[:, None] * ba, axis=1) - radius * baba
    y = np.abs(paba - 0.5 * baba) - 0.5 * baba
    x2 = x * x
    y2 = y * y * baba
    inside = np.maximum(x, y) < 0
    d = np.where(inside, -np.minimum(x2, y2), np.where(x > 0, x2, 0) + np.where(y > 0, y2, 0))
    return np.sign(d) * np.sqrt(np.abs(d)) / baba


def _sd_extrude(d2: np.ndarray, z: np.ndarray, z0: float, z1: float) -> np.ndarray:
    """Extrude a 2D signed distance between heights ``z0 < z1`` (exact)."""
    wz = np.abs(z - 0.5 * (z0 + z1)) - 0.5 * (z1 - z0)
    w = np.stack([d2, wz], axis=1)
    return np.minimum(w.max(axis=1), 0.0) + np.linalg.norm(np.maximum(w, 0.0), axis=1)


def _sd_extrude_round(
    d2: np.ndarray, z: np.ndarray, z0: float, z1: float, rounding: float
) -> np.ndarray:
    """Extrusion whose edges are rounded with radius ``rounding`` (same outer bounds)."""
    return _sd_extrude(d2 + rounding, z, z0 + rounding, z1 - rounding) - rounding


def _sd_round_cylinder(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, radius: float, rounding: float
) -> np.ndarray:
    """Capped cylinder from ``a`` to ``b`` with its rim edges rounded (same outer bounds)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    axis = (b - a) / np.linalg.norm(b - a)
    return _sd_cylinder(p, a + rounding * axis, b - rounding * axis, radius - rounding) - rounding


def _smooth_union(values: Sequence[np.ndarray], k: float) -> np.ndarray:
    """Union with fillets of size ~``k`` where parts meet (polynomial smooth minimum)."""
    out = values[0]
    for v in values[1:]:
        h = np.maximum(k - np.abs(out - v), 0.0) / k
        out = np.minimum(out, v) - 0.25 * k * h * h
    return out


# Kuhn triangulation of a cube (corner index = dx + 2 dy + 4 dz): 6 tetrahedra sharing the
# 0-7 diagonal; neighbouring cubes split their shared faces the same way.
_TETS = np.array(
    [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]
)


def _tet_cases() -> dict[int, list[list[tuple[int, int]]]]:
    cases: dict[int, list[list[tuple[int, int]]]] = {}
    for code in range(1, 15):
        ins = [i for i in range(4) if code >> i & 1]
        out = [i for i in range(4) if not code >> i & 1]
        if len(ins) == 1:
            cases[code] = [[(ins[0], o) for o in out]]
        elif len(ins) == 3:
            cases[code] = [[(i, out[0]) for i in ins]]
        else:
            (a, b), (c, d) = ins, out
            cases[code] = [[(a, c), (a, d), (b, d)], [(a, c), (b, d), (b, c)]]
    return cases


_TET_CASES = _tet_cases()


def _grid_axes(lo: Sequence[float], hi: Sequence[float], step: float) -> list[np.ndarray]:
    """Grid coordinates on multiples of ``step`` covering [lo, hi] with two cells of margin."""
    return [
        step * np.arange(math.floor(a / step) - 2, math.ceil(b / step) + 3)
        for a, b in zip(lo, hi, strict=True)
    ]


def _mesh_sdf(
    sdf: Callable[[np.ndarray], np.ndarray], axes: Sequence[np.ndarray]
) -> trimesh.Trimesh:
    """Mesh the zero set of ``sdf`` on a rectilinear grid by marching tetrahedra.

    Args:
        sdf: signed distance (negative inside) of (N, 3) points, metres.
        axes: increasing grid coordinates along x, y and z (the outer layers must be outside).

    The result is a closed 2-manifold (every edge in exactly two triangles) with outward
    normals, because the tetrahedra tile space consistently and the grid border is outside.
    """
    shape = np.array([len(a) for a in axes])
    step = min(float(np.diff(a).min()) for a in axes)
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    f = sdf(grid)
    # Keep grid values off zero so that no triangle collapses onto a grid point.
    f = np.where(np.abs(f) < 1e-3 * step, 1e-3 * step, f)
    inside = (f < 0).reshape(shape)

    ny, nz = shape[1], shape[2]
    offsets = np.array([(c & 1, c >> 1 & 1, c >> 2 & 1) for c in range(8)])
    cube_in = np.stack(
        [
            inside[dx : shape[0] - 1 + dx, dy : ny - 1 + dy, dz : nz - 1 + dz]
            for dx, dy, dz in offsets
        ],
        axis=-1,
    )
    count = cube_in.sum(axis=-1)
    cubes = np.argwhere((count > 0) & (count < 8))
    corner_ijk = cubes[:, None, :] + offsets[None, :, :]
    corner_ids = (corner_ijk[..., 0] * ny + corner_ijk[..., 1]) * nz + corner_ijk[..., 2]
    tets = corner_ids[:, _TETS].reshape(-1, 4)
    inside_flat = inside.reshape(-1)
    codes = (inside_flat[tets] * np.array([1, 2, 4, 8])).sum(axis=1)

    tri_a, tri_b, ref_in, ref_out = [], [], [], []
    for code, triangles in _TET_CASES.items():
        sel = tets[codes == code]
        if len(sel) == 0:
            continue
        ins = [i for i in range(4) if code >> i & 1]
        outs = [i for i in range(4) if not code >> i & 1]
        centre_in = grid[sel[:, ins]].mean(axis=1)
        centre_out = grid[sel[:, outs]].mean(axis=1)
        for tri in triangles:
            tri_a.append(np.stack([sel[:, i] for i, _ in tri], axis=1))
            tri_b.append(np.stack([sel[:, o] for _, o in tri], axis=1))
            ref_in.append(centre_in)
            ref_out.append(centre_out)
    ends_in = np.concatenate(tri_a)
    ends_out = np.concatenate(tri_b)
    n_grid = len(grid)
    keys = ends_in.astype(np.int64) * n_grid + ends_out
    unique, inverse = np.unique(keys.ravel(), return_inverse=True)
    faces = inverse.reshape(-1, 3)
    a = unique // n_grid
    b = unique % n_grid
    t = f[a] / (f[a] - f[b])
    vertices = grid[a] + t[:, None] * (grid[b] - grid[a])

    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = np.concatenate(ref_out) - np.concatenate(ref_in)
    flip = np.einsum("ij,ij->i", normal, outward) < 0
    faces[flip] = faces[flip][:, ::-1]
    import trimesh

    return trimesh.Trimesh(vertices, faces, process=False)


def _project(sdf: Callable[[np.ndarray], np.ndarray], p: np.ndarray, steps: int = 1) -> np.ndarray:
    """Newton steps of (N, 3) points onto the zero set of ``sdf`` (finite-difference gradient)."""
    eps = 1e-5
    for _ in range(steps):
        f = sdf(p)
        g = np.stack([(sdf(p + eps * e) - f) / eps for e in np.eye(3)], axis=1)
        p = p - (f / np.maximum(np.einsum("ij,ij->i", g, g), 1e-12))[:, None] * g
    return p


def _decimate(
    mesh: trimesh.Trimesh,
    target: float,
    sdf: Callable[[np.ndarray], np.ndarray],
    tolerance: float = 1.5e-4,
    max_passes: int = 80,
    seed: int = 0,
) -> trimesh.Trimesh:
    """Collapse edges shorter than ``target`` (metres) of a closed manifold mesh.

    Each pass collapses an independent set of short edges (endpoints of different collapses
    are not neighbours; several Luby rounds with seeded random priorities that favour short
    edges) to their midpoints projected onto the zero set of ``sdf``. A collapse is skipped if
    it breaks the link condition (the mesh would stop being a manifold), leaves a vertex with
    fewer than three neighbours, turns a neighbouring face by more than ~72 degrees, or moves
    the centroid of a neighbouring face more than ``tolerance`` (metres) off the surface (so
    curved regions keep small triangles and flat ones get large ones).
    """
    import scipy.sparse as sp
    import trimesh

    rng = np.random.default_rng(seed)
    # Marching-tetrahedra vertices interpolate the distance linearly; start from the surface.
    vertices = _project(sdf, np.asarray(mesh.vertices, dtype=np.float64), steps=2)
    faces = np.asarray(mesh.faces, dtype=np.int64).copy()
    for _ in range(max_passes):
        n_v = len(vertices)
        half = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        opposite = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
        forward = half[:, 0] < half[:, 1]
        edges = half[forward]
        opp_1 = opposite[forward]
        keys = half[:, 0] * n_v + half[:, 1]
        order = np.argsort(keys)
        twin = edges[:, 1] * n_v + edges[:, 0]
        opp_2 = opposite[order[np.searchsorted(keys[order], twin)]]
        valence = np.bincount(edges.ravel(), minlength=n_v)
        length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
        cand = (length < target) & (valence[opp_1] >= 4) & (valence[opp_2] >= 4)
        if not cand.any():
            break
        prio = np.where(cand, length / target + rng.random(len(edges)), np.inf)
        blocked = np.zeros(n_v, dtype=bool)
        sel = np.zeros(len(edges), dtype=bool)
        for _round in range(4):
            live = cand & ~sel & ~blocked[edges[:, 0]] & ~blocked[edges[:, 1]]
            if not live.any():
                break
            p = np.where(live, prio, np.inf)
            v_min = np.full(n_v, np.inf)
            np.minimum.at(v_min, edges[:, 0], p)
            np.minimum.at(v_min, edges[:, 1], p)
            ring_min = v_min.copy()
            np.minimum.at(ring_min, edges[:, 0], v_min[edges[:, 1]])
            np.minimum.at(ring_min, edges[:, 1], v_min[edges[:, 0]])
            new = live & (p == ring_min[edges[:, 0]]) & (p == ring_min[edges[:, 1]])
            sel |= new
            ends = np.zeros(n_v, dtype=bool)
            ends[edges[new].ravel()] = True
            blocked |= ends
            blocked[edges[ends[edges[:, 0]], 1]] = True
            blocked[edges[ends[edges[:, 1]], 0]] = True
        s = np.flatnonzero(sel)
        a, b = edges[s, 0], edges[s, 1]
        adjacency = sp.csr_matrix(
            (np.ones(2 * len(edges)), (edges.T.ravel(), edges[:, ::-1].T.ravel())), shape=(n_v, n_v)
        )
        common = np.asarray(adjacency[a].multiply(adjacency[b]).sum(axis=1)).ravel()
        ok = common == 2
        goal = _project(sdf, 0.5 * (vertices[a] + vertices[b]))
        owner = np.full(n_v, -1)
        owner[a] = np.arange(len(s))
        owner[b] = np.arange(len(s))
        face_owner = owner[faces].max(axis=1)
        touched = np.flatnonzero(face_owner >= 0)
        k = face_owner[touched]
        tri = faces[touched]
        is_end = (tri == a[k][:, None]) | (tri == b[k][:, None])
        dropped = is_end.sum(axis=1) == 2
        old = vertices[tri]
        new_pos = np.where(is_end[..., None], goal[k][:, None, :], old)
        n_old = np.cross(old[:, 1] - old[:, 0], old[:, 2] - old[:, 0])
        n_new = np.cross(new_pos[:, 1] - new_pos[:, 0], new_pos[:, 2] - new_pos[:, 0])
        a_old = np.linalg.norm(n_old, axis=1)
        a_new = np.linalg.norm(n_new, axis=1)
        cos = np.einsum("ij,ij->i", n_old, n_new) / np.maximum(a_old * a_new, 1e-30)
        off_surface = np.abs(sdf(new_pos.mean(axis=1))) > tolerance
        bad = ~dropped & (
            ((a_old > 1e-3 * target**2) & (cos < 0.3)) | (a_new < 1e-6 * target**2) | off_surface
        )
        bad_collapse = np.zeros(len(s), dtype=bool)
        np.logical_or.at(bad_collapse, k, bad)
        ok &= ~bad_collapse
        # Stop when a pass achieves little (the remaining short edges are mostly blocked).
        if ok.sum() < 0.002 * len(faces):
            break
        vertices[a[ok]] = goal[ok]
        remap = np.arange(n_v)
        remap[b[ok]] = a[ok]
        faces = remap[faces]
        faces = faces[
            (faces[:, 0] != faces[:, 1])
            & (faces[:, 1] != faces[:, 2])
            & (faces[:, 2] != faces[:, 0])
        ]
    used, faces = np.unique(faces, return_inverse=True)
    return trimesh.Trimesh(vertices[used], faces.reshape(-1, 3), process=False)


def _sdf_object(
    sdf: Callable[[np.ndarray], np.ndarray], axes: Sequence[np.ndarray], edge: float
) -> trimesh.Trimesh:
    """Marching tetrahedra on ``axes``, then decimation to edges of about ``edge`` metres."""
    return _decimate(_mesh_sdf(sdf, axes), edge, sdf)
