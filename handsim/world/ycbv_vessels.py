"""The open vessels of the YCB-Video objects: bowl (024), mug (025) and pitcher base (019).

Revolved open shells whose collision pieces leave the cavity empty (so a hand or a spoon can
enter it): convex sectors of the wall per band, the floor or foot disc and, for the mug and the
pitcher, a tube handle stitched into the wall with its own pieces. The other shapes, and the
table of how each object is made, are in :mod:`handsim.world.ycbv_shapes`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from handsim.world.meshing import (
    _hull,
    _loft,
    _revolve_rows,
    _ring_points,
    _rows_m,
)
from handsim.world.objects import _MM, _Geometry
from handsim.world.symmetry import Symmetry

if TYPE_CHECKING:
    import trimesh

__all__ = []


def _bowl() -> _Geometry:
    """Bowl: rim r 80.5 mm, height 55 mm, flat foot r 35 mm, 4 mm wall (elliptic profile)."""
    foot, rim, h, wall = 35.0, 80.5, 55.0, 4.0
    y0 = -h / 2
    phi = np.linspace(0.0, np.pi / 2, 13)
    outer = [(foot + (rim - foot) * math.sin(a), y0 + h - h * math.cos(a)) for a in phi]
    ra, rb = rim - foot - wall, h - wall
    inner = [(foot + ra * math.sin(a), y0 + h - rb * math.cos(a)) for a in phi[::-1]]
    profile = [(0.0, y0)] + outer + inner + [(0.0, y0 + wall)]
    rows_mm = [(r, r, y) for r, y in profile]
    rows = _rows_m(rows_mm)
    n = 96
    mesh = _loft(*_revolve_rows(rows, n), n)
    # Collision: the foot disc, then 16 sectors x 3 bands of the wall (hulls of the outer and
    # inner profile points of the band); the cavity stays empty.
    bottom = _hull(
        _ring_points(
            _rows_m([(0, 0, y0), (foot, foot, y0), (foot, foot, y0 + wall)]),
            2 * np.pi * np.arange(48) / 48,
        )
    )
    pieces = [bottom]
    out_rows = np.array([(r, r, y, 0.0) for r, y in outer]) * _MM
    in_rows = np.array([(r, r, y, 0.0) for r, y in inner[::-1]]) * _MM
    bands = [(0, 4), (4, 8), (8, 12)]
    for k in range(16):
        angles = 2 * np.pi * (k + np.array([0.0, 0.25, 0.5, 0.75, 1.0])) / 16
        for i0, i1 in bands:
            pts = np.concatenate(
                [
                    _ring_points(out_rows[i0 : i1 + 1], angles),
                    _ring_points(in_rows[i0 : i1 + 1], angles),
                ]
            )
            pieces.append(_hull(pts))
    return _Geometry(
        mesh,
        pieces,
        rest_up=np.array([0.0, 1.0, 0.0]),
        symmetry=Symmetry.continuous((0.0, 1.0, 0.0)),
        cavity=np.array([0.0, 0.0, 0.0]),
    )


def _wall_sectors(
    outer: np.ndarray, inner: np.ndarray, y_edges: Sequence[float], n_sectors: int = 16
) -> list[trimesh.Trimesh]:
    """Convex pieces of a revolved wall (about y): hulls of ``n_sectors`` x bands of the wall.

    Args:
        outer: (K, 2) outer wall profile (r, y), metres, y increasing.
        inner: (L, 2) inner wall profile (r, y), metres, y increasing.
        y_edges: band limits in y, metres.
        n_sectors: sectors around the axis; a hull's chord enters the cavity by at most
            ``r (1 - cos(pi / n_sectors))`` (0.8 mm for r = 43 mm and 16 sectors).
    """
    pieces = []
    for k in range(n_sectors):
        angles = 2 * np.pi * (k + np.linspace(0.0, 1.0, 5)) / n_sectors
        for ya, yb in zip(y_edges[:-1], y_edges[1:], strict=True):
            ys = np.linspace(ya, yb, 6)
            ro = np.interp(ys, outer[:, 1], outer[:, 0])
            ri = np.interp(ys, inner[:, 1], inner[:, 0])
            zeros = np.zeros(6)
            rows = np.concatenate(
                [np.column_stack([ro, ro, ys, zeros]), np.column_stack([ri, ri, ys, zeros])]
            )
            pieces.append(_hull(_ring_points(rows, angles)))
    return pieces


def _zip_loops(
    loop_a: np.ndarray, loop_b: np.ndarray, uv_a: np.ndarray, uv_b: np.ndarray
) -> np.ndarray:
    """Triangles bridging two nested closed loops (vertex ids), by polar angle in a 2D chart.

    Args:
        loop_a: (m,) vertex ids of the outer loop.
        loop_b: (n,) vertex ids of the inner loop.
        uv_a: (m, 2) chart coordinates of ``loop_a``.
        uv_b: (n, 2) chart coordinates of ``loop_b``; both loops must be star-shaped around
            the centroid of ``uv_b``.

    Returns:
        (m + n, 3) triangles (orientation not yet fixed).
    """
    centre = uv_b.mean(axis=0)
    loops = []
    for ids, uv in ((loop_a, uv_a), (loop_b, uv_b)):
        d = uv - centre
        area = np.sum(d[:, 0] * np.roll(d[:, 1], -1) - np.roll(d[:, 0], -1) * d[:, 1])
        if area < 0:
            ids, d = ids[::-1], d[::-1]
        ang = np.arctan2(d[:, 1], d[:, 0])
        start = int(np.argmin(ang))
        ids = np.roll(ids, -start)
        ang = np.unwrap(np.roll(ang, -start))
        loops.append((np.append(ids, ids[0]), np.append(ang, ang[0] + 2 * np.pi)))
    (a, aa), (b, ab) = loops
    i = j = 0
    m, n = len(a) - 1, len(b) - 1
    faces = []
    while i < m or j < n:
        if j == n or (i < m and aa[i + 1] <= ab[j + 1]):
            faces.append((a[i], a[i + 1], b[j]))
            i += 1
        else:
            faces.append((a[i], b[j + 1], b[j]))
            j += 1
    return np.array(faces, dtype=np.int64)


def _orient(faces: np.ndarray, vertices: np.ndarray, outward: np.ndarray) -> np.ndarray:
    """Flip the triangles whose normal points against ``outward`` (F, 3)."""
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", normal, outward) < 0
    faces = faces.copy()
    faces[flip] = faces[flip][:, ::-1]
    return faces


def _vessel(
    outer_mm: Sequence[tuple[float, float]],
    wall_mm: float,
    bottom_mm: float,
    handle_mm: Sequence[tuple[float, float]],
    handle_radius_mm: float,
    handle_groups: Sequence[tuple[int, int]],
    y_edges_mm: Sequence[float],
    n_around: int = 96,
) -> _Geometry:
    """An open-top revolved shell about y with a tube handle stitched into its outer wall.

    The shell is a loft of the closed profile (outer wall bottom to rim, then the inner wall,
    ``wall_mm`` inside, down to the ``bottom_mm`` thick floor). The handle is a tube of radius
    ``handle_radius_mm`` along ``handle_mm`` (x, y points in the z = 0 plane, ends heading into
    the wall); its end rings are slid along the tube onto the wall surface, a window of wall
    quads around each is removed, and the gap is bridged by a band of triangles. The result is
    one closed surface of genus 1, exact to the loft's polygon (no boolean operations).

    Collision: the floor disc, 16 wall sectors per band of ``y_edges_mm``, and hulls of groups
    of handle rings (``handle_groups``: inclusive index ranges into ``handle_mm``).
    """
    import trimesh

    outer = np.asarray(outer_mm, dtype=np.float64) * _MM
    wall, bottom, r_h = wall_mm * _MM, bottom_mm * _MM, handle_radius_mm * _MM
    y_lo = outer[0, 1]
    y_floor = y_lo + bottom

    # Handle tube: rings around the path, binormal +z (the path lies in z = 0).
    path = np.column_stack(
        [np.asarray(handle_mm, dtype=np.float64) * _MM, np.zeros(len(handle_mm))]
    )
    tangent = np.gradient(path, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    binormal = np.array([0.0, 0.0, 1.0])
    normal = np.cross(tangent, binormal)
    n_tube = 16
    phi = 2 * np.pi * np.arange(n_tube) / n_tube
    rings = path[:, None, :] + r_h * (
        np.cos(phi)[None, :, None] * normal[:, None, :] + np.sin(phi)[None, :, None] * binormal
    )

    def onto_wall(points: np.ndarray, direction: np.ndarray) -> np.ndarray:
        # Bisection for the point along ``direction`` where hypot(x, z) = R_outer(y).
        def gap(t: np.ndarray) -> np.ndarray:
            q = points + t[:, None] * direction
            return np.hypot(q[:, 0], q[:, 2]) - np.interp(q[:, 1], outer[:, 1], outer[:, 0])

        lo = np.full(len(points), -4 * r_h)
        hi = np.full(len(points), 4 * r_h)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            outside = gap(mid) > 0
            lo = np.where(outside, mid, lo)
            hi = np.where(outside, hi, mid)
        return points + (0.5 * (lo + hi))[:, None] * direction

    rings[0] = onto_wall(rings[0], -tangent[0])
    rings[-1] = onto_wall(rings[-1], tangent[-1])

    # Shell profile, with extra outer rows just below and above each handle footprint.
    margin = 1.5 * _MM
    ends = (rings[0], rings[-1])
    cuts = sorted(y for e in ends for y in (e[:, 1].min() - margin, e[:, 1].max() + margin))
    outer_y = np.unique(np.concatenate([outer[:, 1], cuts]))
    outer_rows = np.column_stack([np.interp(outer_y, outer[:, 1], outer[:, 0]), outer_y])
    inner = outer_rows[outer_rows[:, 1] > y_floor] - np.array([wall, 0.0])
    r_floor = np.interp(y_floor, outer[:, 1], outer[:, 0]) - wall
    inner = np.vstack([[r_floor, y_floor], inner])
    profile = np.vstack([[0.0, y_lo], outer_rows, inner[::-1], [0.0, y_floor]])
    rows = np.column_stack([profile[:, 0], profile[:, 0], profile[:, 1], np.zeros(len(profile))])
    shell = _loft(*_revolve_rows(rows, n_around), n_around)
    vertices = np.asarray(shell.vertices)
    faces = np.asarray(shell.faces)

    def vid(row: int, col: int) -> int:
        return 1 + (row - 1) * n_around + col % n_around

    d_theta = 2 * np.pi / n_around
    tube_ids = []
    new_vertices = [vertices]
    offset = len(vertices)
    for r in rings:
        tube_ids.append(offset + np.arange(n_tube))
        new_vertices.append(r)
        offset += n_tube
    all_vertices = np.concatenate(new_vertices)

    keep = np.ones(len(faces), dtype=bool)
    bridge = []
    row_of = {float(y): 1 + i for i, y in enumerate(outer_y)}
    vert_row = np.zeros(len(vertices), dtype=np.int64)
    vert_col = np.zeros(len(vertices), dtype=np.int64)
    vert_row[1:-1] = 1 + np.arange(len(vertices) - 2) // n_around
    vert_col[1:-1] = np.arange(len(vertices) - 2) % n_around
    for end, ids in ((ends[0], tube_ids[0]), (ends[-1], tube_ids[-1])):
        k0 = row_of[float(end[:, 1].min() - margin)]
        k1 = row_of[float(end[:, 1].max() + margin)]
        theta = np.mod(np.arctan2(end[:, 2], end[:, 0]), 2 * np.pi)
        j0 = int(np.floor(theta.min() / d_theta)) - 1
        j1 = int(np.ceil(theta.max() / d_theta)) + 1
        inside = (
            (vert_row[faces] >= k0).all(axis=1)
            & (vert_row[faces] <= k1).all(axis=1)
            & (vert_col[faces] >= j0).all(axis=1)
            & (vert_col[faces] <= j1).all(axis=1)
        )
        keep &= ~inside
        loop = (
            [vid(k0, j) for j in range(j0, j1 + 1)]
            + [vid(k, j1) for k in range(k0 + 1, k1 + 1)]
            + [vid(k1, j) for j in range(j1 - 1, j0 - 1, -1)]
            + [vid(k, j0) for k in range(k1 - 1, k0, -1)]
        )
        loop = np.array(loop)
        r_mid = float(np.hypot(end[:, 0], end[:, 2]).mean())

        def chart(p: np.ndarray, r_mid: float = r_mid) -> np.ndarray:
            return np.column_stack(
                [r_mid * np.mod(np.arctan2(p[:, 2], p[:, 0]), 2 * np.pi), p[:, 1]]
            )

        bridge.append(_zip_loops(loop, ids, chart(all_vertices[loop]), chart(end)))
    bridge = np.concatenate(bridge)
    centroid = all_vertices[bridge].mean(axis=1)
    radial = centroid * np.array([1.0, 0.0, 1.0])
    bridge = _orient(bridge, all_vertices, radial)

    tube_faces = []
    j = np.arange(n_tube)
    jn = (j + 1) % n_tube
    for a_ids, b_ids in zip(tube_ids[:-1], tube_ids[1:], strict=True):
        tube_faces.append(np.stack([a_ids[j], a_ids[jn], b_ids[jn]], axis=1))
        tube_faces.append(np.stack([a_ids[j], b_ids[jn], b_ids[j]], axis=1))
    tube_faces = np.concatenate(tube_faces)
    tube_centre = np.repeat(path[:-1], 2 * n_tube, axis=0)
    tube_faces = _orient(
        tube_faces, all_vertices, all_vertices[tube_faces].mean(axis=1) - tube_centre
    )

    mesh = trimesh.Trimesh(
        all_vertices, np.concatenate([faces[keep], tube_faces, bridge]), process=False
    )
    mesh.remove_unreferenced_vertices()

    angles = 2 * np.pi * np.arange(48) / 48
    floor_rows = [(0.0, 0.0, y_lo, 0.0)] + [(r, r, y, 0.0) for r, y in outer if y < y_floor]
    r_out_floor = np.interp(y_floor, outer[:, 1], outer[:, 0])
    floor_rows += [(r_out_floor, r_out_floor, y_floor, 0.0), (0.0, 0.0, y_floor, 0.0)]
    pieces = [_hull(_ring_points(np.array(floor_rows), angles))]
    pieces += _wall_sectors(outer_rows, inner, np.asarray(y_edges_mm) * _MM)
    pieces += [_hull(rings[i0 : i1 + 1].reshape(-1, 3)) for i0, i1 in handle_groups]
    return _Geometry(mesh, pieces, rest_up=np.array([0.0, 1.0, 0.0]))


def _arc_2d(center: Sequence[float], radius: float, deg0: float, deg1: float, n: int) -> np.ndarray:
    a = np.radians(np.linspace(deg0, deg1, n))
    return np.asarray(center, dtype=np.float64) + radius * np.column_stack([np.cos(a), np.sin(a)])


def _mug() -> _Geometry:
    """Mug: cylinder r 47 mm, height 81 mm, 4 mm wall, 5 mm floor; C handle on -x.

    The handle is a tube of radius 5.5 mm along a half circle (radius 20.5 mm) centred on the
    outer wall, so it sticks out 26 mm (extent x 120 = 94 + 26).
    """
    path = _arc_2d((-47.0, 0.0), 20.5, 90.0, 270.0, 17)
    outer = [(44.0, -40.5), (47.0, -37.5), (47.0, 40.5)]
    groups = [(0, 4), (4, 8), (8, 12), (12, 16)]
    geom = _vessel(outer, 4.0, 5.0, path, 5.5, groups, [-35.5, 40.5])
    geom.cavity = np.array([0.0, 0.0, 0.0])
    return geom


def _pitcher() -> _Geometry:
    """Pitcher base: belly r 66.5 mm, foot r 52, mouth r 48, height 249 mm, 2.5 mm wall.

    The handle (tube radius 9 mm) hangs on -x between heights -40 and +90 mm and reaches 56 mm
    beyond the belly (extent x 189 = 133 + 56).
    """
    outer = [
        (47.0, -124.5),
        (52.0, -120.0),
        (60.0, -100.0),
        (66.5, -60.0),
        (65.0, -20.0),
        (60.0, 30.0),
        (53.0, 80.0),
        (49.0, 115.0),
        (48.0, 124.5),
    ]
    path = [
        (-50.0, 86.0),
        (-65.0, 90.0),
        (-88.0, 80.0),
        (-106.0, 60.0),
        (-113.5, 32.0),
        (-111.0, 5.0),
        (-100.0, -18.0),
        (-84.0, -32.0),
        (-66.0, -40.0),
    ]
    groups = [(0, 2), (2, 4), (4, 6), (6, 8)]
    geom = _vessel(outer, 2.5, 3.0, path, 9.0, groups, [-121.5, -60.0, 30.0, 124.5], 128)
    geom.cavity = np.array([0.0, 0.0, 0.0])
    return geom
