"""The shapes of the 21 YCB-Video objects: meshes and collision pieces built from primitives.

How the shapes are made (sizes in :mod:`handsim.world.ycbv`'s ``_FACTS`` and next to each builder):

==============================  =========================================================
object                          shape
==============================  =========================================================
cans (002, 005, 007)            cylinder along ``y``, end chamfer sized to the diameter
boxes (003, 004, 008, 009,      box of the nominal (Calli) size, tilted 1-12 degrees in the
036, 061), meat can (010)       model frame; 010 has rounded edges (see ``_BOXES``)
bottles (006, 021)              lofted elliptic body + shoulder + neck + cap (021's cap is
                                off-centre, as on the real bottle)
banana (011)                    tapered tube along a circular arc (fitted radius, span and
                                tilt); collision = a chain of 6 tapered capsules
pitcher (019), mug (025)        revolved open shell with a tube handle stitched into its
                                wall; collision = 16 wall sectors per band around the
                                cavity, the floor disc and 4 handle pieces
bowl (024)                      revolved open shell on a flat foot; collision = 16 x 3 wall
                                sectors and the foot
power drill (035)               barrel + nose + chuck + grip + battery, filleted
scissors (037)                  two 2.5 mm blade plates, crossed shanks, two handle loops
marker (040)                    barrel r 9.5 mm with a conical tip and a cap clip
clamps (051, 052)               two mirrored levers (bowed jaw + handle) on a spring pivot
==============================  =========================================================

The YCB-Video scans are not aligned with the faces of their boxes: a box of the nominal size,
tilted by a few degrees, reproduces both the bounding box and the diameter of the scan to
< 0.01 mm (the boxes are fitted that way), while an axis-aligned box of the scan's extents
would be up to 14 % too long in diagonal (the gelatin box) and too thick.

"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from handsim.world.meshing import (
    _circle_2d,
    _disc_points,
    _grid_axes,
    _hull,
    _loft,
    _revolve,
    _revolve_rows,
    _ring_points,
    _rows_m,
    _sd_extrude,
    _sd_extrude_round,
    _sd_polygon,
    _sd_revolved,
    _sd_round_box,
    _sd_round_cylinder,
    _sd_segments,
    _sdf_object,
    _slab_points,
    _smooth_union,
    _spheres,
)
from handsim.world.objects import _MM, _Geometry
from handsim.world.symmetry import NO_SYMMETRY, Symmetry, _rot

if TYPE_CHECKING:
    import trimesh

__all__ = []


def _can(radius_mm: float, height_mm: float, diameter_mm: float) -> _Geometry:
    """Cylinder along y; the end chamfer is the smallest that brings the diameter to the facts."""
    r, h, d = radius_mm, height_mm, diameter_mm
    c1 = (h - math.sqrt(max(d * d - 4 * r * r, 0.0))) / 2
    c2 = (2 * r - math.sqrt(max(d * d - h * h, 0.0))) / 2
    c = min(max(c1, c2, 0.5), 0.25 * min(r, h))
    rows = [
        (0, 0, -h / 2),
        (r - c, r - c, -h / 2),
        (r, r, -h / 2 + c),
        (r, r, h / 2 - c),
        (r - c, r - c, h / 2),
        (0, 0, h / 2),
    ]
    mesh = _revolve(rows, n_around=96)
    return _Geometry(mesh, [_hull(mesh.vertices)], rest_up=np.array([0.0, 1.0, 0.0]))


# Boxes: nominal Calli sizes (mm, along the box's own axes) and the tilt (rotation vector,
# degrees) that reproduce the YCB-Video bounding box and diameter. Fitted by least squares to
# the facts extents + diameter with the nominal size as a weak prior; residuals < 0.01 mm.
# Rounding: edge radius (mm) of the potted meat can (a rounded tin).
_BOXES: dict[str, tuple[tuple[float, float, float], tuple[float, float, float], float]] = {
    "003_cracker_box": ((158.03, 210.02, 60.03), (1.981, 1.737, -1.138), 0.0),
    "004_sugar_box": ((88.42, 173.55, 37.77), (-2.345, 3.453, 1.419), 0.0),
    "008_pudding_box": ((109.03, 85.48, 33.79), (0.056, 2.671, 2.417), 0.0),
    "009_gelatin_box": ((84.85, 71.46, 27.97), (-0.448, 11.213, -4.562), 0.0),
    "010_potted_meat_can": ((97.98, 82.57, 50.46), (-0.229, 4.909, -0.863), 6.0),
    "036_wood_block": ((86.44, 203.38, 86.44), (-1.03, -0.613, -0.743), 0.0),
    "061_foam_brick": ((75.09, 49.75, 49.75), (-0.021, 2.489, -0.959), 0.0),
}


def _box_shape(name: str) -> str:
    dims, rotvec_deg, rounding = _BOXES[name]
    size = " x ".join(f"{d:.0f}" for d in dims)
    kind = f"rounded box (edge r {rounding:.0f} mm)" if rounding else "box"
    return f"{kind} {size} mm, tilted {np.linalg.norm(rotvec_deg):.1f} deg in the model frame"


def _box(name: str, four_fold_axis: int | None = None) -> _Geometry:
    """A (rounded) box of the nominal size, tilted as the YCB-Video scan is.

    Args:
        name: key of ``_BOXES``.
        four_fold_axis: box axis with a square cross-section; the symmetry is then the
            dihedral group of order 8 (4-fold about it, 2-fold about the other two axes).
    """
    dims, rotvec_deg, rounding = _BOXES[name]
    half = np.asarray(dims) * _MM / 2
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix()
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    if rounding > 0:
        r = rounding * _MM
        local = _spheres(signs * (half - r), r)
    else:
        local = signs * half
    mesh = _hull(local @ rot.T)
    up = rot[:, int(np.argmin(dims))]
    symmetry = NO_SYMMETRY
    # A plain box's shape turns onto itself by 180 degrees about each of its axes; the print
    # of a cereal box does not, so this holds in depth only.
    half_turns = [rot @ _rot(a, 180.0) @ rot.T for a in "xyz"]
    depth_symmetry = Symmetry.from_rotations(half_turns)
    if four_fold_axis is not None:
        others = [i for i in range(3) if i != four_fold_axis]
        gens = [_rot("xyz"[four_fold_axis], 90.0)] + [_rot("xyz"[i], 180.0) for i in others]
        symmetry = Symmetry.from_rotations([rot @ g @ rot.T for g in gens])
        depth_symmetry = None  # the texture's group already holds the shape's
    return _Geometry(
        mesh, [mesh.copy()], rest_up=up, symmetry=symmetry, depth_symmetry=depth_symmetry
    )


def _bottle(rows_mm: Sequence[Sequence[float]], piece_rows: Sequence[tuple[int, int]]) -> _Geometry:
    """Lofted bottle about y; collision pieces are hulls of the given (inclusive) row ranges."""
    rows = _rows_m(rows_mm)
    n = 64
    mesh = _loft(*_revolve_rows(rows, n), n)
    angles = 2.0 * np.pi * np.arange(n) / n
    pieces = [_hull(_ring_points(rows[i0 : i1 + 1], angles)) for i0, i1 in piece_rows]
    return _Geometry(mesh, pieces, rest_up=np.array([0.0, 1.0, 0.0]))


def _mustard_bottle() -> _Geometry:
    """French's mustard: elliptic body 97 x 59 mm, shoulders, neck and a flip-top cap."""
    rows = [
        (0, 0, -96),
        (44, 25, -96),
        (47.5, 28.5, -94.5),
        (48.5, 29.5, -90),
        (48.5, 29.5, 15),
        (46.5, 28.5, 32),
        (40, 25.5, 45),
        (30, 21, 54),
        (18, 16, 59.5),
        (14, 14, 62),
        (16.5, 16.5, 62),
        (16.5, 16.5, 80),
        (12, 12, 84),
        (6, 6, 86),
        (4.5, 4.5, 95),
        (3, 3, 96),
        (0, 0, 96),
    ]
    return _bottle(rows, [(0, 4), (4, 9), (9, 16)])


def _bleach_cleanser() -> _Geometry:
    """Soft Scrub bottle: elliptic body 103 x 68 mm; neck and cap 18 mm off the axis (+x)."""
    rows = [
        (0, 0, -125.5, 0),
        (47, 30.5, -125.5, 0),
        (50.5, 33, -123, 0),
        (51.5, 34, -118, 0),
        (51.5, 34, 45, 0),
        (49, 32.5, 62, 1),
        (41, 28, 76, 4),
        (30, 22, 85, 9),
        (18, 16, 91, 15),
        (15, 15, 93, 18),
        (19, 19, 93, 18),
        (19, 19, 113, 18),
        (14, 14, 118, 18),
        (6, 6, 120, 18),
        (4, 4, 125.5, 18),
        (0, 0, 125.5, 18),
    ]
    return _bottle(rows, [(0, 4), (4, 9), (9, 15)])


def _marker() -> _Geometry:
    """Expo marker: barrel r 9.5 mm along y, conical felt tip at -y, cap clip on +z.

    The clip (2 mm proud of the barrel) gives the facts' 19 x 21 mm cross-section and keeps
    the marker from rolling; the symmetry is continuous about the barrel axis up to the clip
    (as in BOP).
    """
    mm = _MM
    profile = (
        np.array(
            [
                (0.0, -60.5),
                (2.5, -60.5),
                (3.5, -58.0),
                (7.0, -50.0),
                (8.5, -47.0),
                (9.5, -45.0),
                (9.5, 57.0),
                (8.5, 59.5),
                (7.0, 60.5),
                (0.0, 60.5),
            ]
        )
        * mm
    )
    clip = (np.array([0.0, 37.0, 9.5]) * mm, np.array([3.0, 16.0, 2.0]) * mm, 1.0 * mm)

    def sdf(p: np.ndarray) -> np.ndarray:
        return _smooth_union([_sd_revolved(p, profile), _sd_round_box(p, *clip)], 1.5 * mm)

    axes = _grid_axes(np.array([-10, -61, -10]) * mm, np.array([10, 61, 12]) * mm, 1.0 * mm)
    mesh = _sdf_object(sdf, axes, 3.0 * mm)
    rows = np.column_stack([profile[:, 0], profile[:, 0], profile[:, 1], np.zeros(len(profile))])
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    pieces = [
        _hull(_ring_points(rows, 2 * np.pi * np.arange(48) / 48)),
        _hull(_spheres(signs * (clip[1] - clip[2]) + clip[0], clip[2])),
    ]
    return _Geometry(
        mesh,
        pieces,
        rest_up=np.array([1.0, 0.0, 0.0]),
        symmetry=Symmetry.continuous((0.0, 1.0, 0.0)),
    )


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


def _banana(
    arc_radius_mm: float = 156.92,
    half_angle_deg: float = 36.23,
    tilt_deg: float = 27.18,
    r_max_mm: float = 19.0,
    r_end_mm: float = 6.5,
) -> _Geometry:
    """A tapered tube along a circular arc in the x-z plane, hemispherical ends.

    The tube radius is ``r_end + (r_max - r_end) sin(pi u)^0.4`` along the arc (u in [0, 1]),
    flat over most of the length so the banana lies on its side. ``tilt_deg`` turns the arc
    about y (the YCB-Video banana is not aligned with its bounding box). The defaults are the
    unique least-squares fit of (arc radius, half angle, tilt) to the facts extents x = 179,
    z = 109 mm and diameter 198.4 mm (residuals < 1e-6 mm); the thickness 38 mm = 2 r_max.
    """
    big_r = arc_radius_mm * _MM
    phi = math.radians(half_angle_deg)
    r_max, r_end = r_max_mm * _MM, r_end_mm * _MM
    n_seg, n_around, n_cap = 48, 40, 6
    s = np.linspace(-phi, phi, n_seg + 1)
    u = (s + phi) / (2 * phi)
    radius = r_end + (r_max - r_end) * np.sin(np.pi * u) ** 0.4
    centers = np.stack([big_r * np.sin(s), np.zeros_like(s), big_r * np.cos(s)], axis=1)
    normal = np.stack([np.sin(s), np.zeros_like(s), np.cos(s)], axis=1)
    tangent = np.stack([np.cos(s), np.zeros_like(s), -np.sin(s)], axis=1)
    binormal = np.tile([0.0, 1.0, 0.0], (len(s), 1))

    psi = np.linspace(0.0, np.pi / 2, n_cap + 1)[1:-1]
    rows_c, rows_u, rows_v = [], [], []

    def cap(i: int, direction: float, order: np.ndarray) -> None:
        for a in order:
            rows_c.append(centers[i] + direction * tangent[i] * r_end * math.sin(a))
            rows_u.append(normal[i] * r_end * math.cos(a))
            rows_v.append(binormal[i] * r_end * math.cos(a))

    rows_c.append(centers[0] - tangent[0] * r_end)
    rows_u.append(np.zeros(3))
    rows_v.append(np.zeros(3))
    cap(0, -1.0, psi[::-1])
    for i in range(len(s)):
        rows_c.append(centers[i])
        rows_u.append(normal[i] * radius[i])
        rows_v.append(binormal[i] * radius[i])
    cap(-1, 1.0, psi)
    rows_c.append(centers[-1] + tangent[-1] * r_end)
    rows_u.append(np.zeros(3))
    rows_v.append(np.zeros(3))

    rot = _rot("y", tilt_deg)
    mesh = _loft(
        np.array(rows_c) @ rot.T, np.array(rows_u) @ rot.T, np.array(rows_v) @ rot.T, n_around
    )
    # Collision: a chain of 6 tapered capsules (hulls of two spheres) along the arc.
    knots = np.linspace(0, n_seg, 7).astype(int)
    pieces = []
    for i0, i1 in zip(knots[:-1], knots[1:], strict=True):
        idx = np.arange(i0, i1 + 1)
        pieces.append(_hull(_spheres(centers[idx] @ rot.T, radius[idx])))
    return _Geometry(mesh, pieces, rest_up=np.array([0.0, 1.0, 0.0]))


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


def _power_drill() -> _Geometry:
    """Cordless drill: barrel (x), chuck at +x, grip and battery below (-y).

    It rests upright on its battery (``rest_up`` +y), as it stands on a bench: its centre of
    mass lies 22-37 mm inside the edges of the 80 x 58 mm battery footprint, and only upright
    is its grip clear of the table for a hand to wrap (lying on its side, 10 mm above it).
    """
    mm = _MM
    barrel = (np.array([-62.0, 65.0, 0.0]) * mm, np.array([25.0, 65.0, 0.0]) * mm, 29.0 * mm)
    nose = (np.array([25.0, 65.0, 0.0]) * mm, np.array([55.0, 65.0, 0.0]) * mm, 24.0 * mm)
    chuck = (np.array([55.0, 65.0, 0.0]) * mm, np.array([93.0, 65.0, 0.0]) * mm, 17.0 * mm)
    grip_rot = _rot("z", -12.0)
    grip = (np.array([-28.0, -10.0, 0.0]) * mm, np.array([17.0, 53.0, 19.0]) * mm, 8.0 * mm)
    battery = (np.array([-18.0, -76.0, 0.0]) * mm, np.array([40.0, 18.0, 29.0]) * mm, 6.0 * mm)

    def sdf(p: np.ndarray) -> np.ndarray:
        return _smooth_union(
            [
                _sd_segments(p, np.array(barrel[:2]), barrel[2]),
                _sd_round_cylinder(p, *nose, 3.0 * mm),
                _sd_round_cylinder(p, *chuck, 2.0 * mm),
                _sd_round_box(p, grip[0], grip[1], grip[2], grip_rot),
                _sd_round_box(p, battery[0], battery[1], battery[2]),
            ],
            6.0 * mm,
        )

    mesh = _sdf_object(
        sdf,
        _grid_axes(np.array([-92, -95, -30]) * mm, np.array([94, 95, 30]) * mm, 3.0 * mm),
        5.0 * mm,
    )
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))

    def round_box_points(center, half, radius, rot=None):
        rot = np.eye(3) if rot is None else rot
        return _spheres((signs * (half - radius)) @ rot.T + center, radius)

    pieces = [
        _hull(_spheres(np.array(barrel[:2]), barrel[2])),
        _hull(np.vstack([_disc_points(c, 0, nose[2], 48) for c in nose[:2]])),
        _hull(np.vstack([_disc_points(c, 0, chuck[2], 48) for c in chuck[:2]])),
        _hull(round_box_points(*grip, grip_rot)),
        _hull(round_box_points(*battery)),
    ]
    return _Geometry(mesh, pieces, rest_up=np.array([0.0, 1.0, 0.0]))


def _thick_polyline_pieces(points_2d: np.ndarray, width: float, z0: float, z1: float):
    """Convex pieces of an extruded thick polyline: one per segment (2D capsule x [z0, z1])."""
    return [
        _hull(_slab_points(np.vstack([_circle_2d(a, width), _circle_2d(b, width)]), z0, z1))
        for a, b in zip(points_2d[:-1], points_2d[1:], strict=True)
    ]


def _scissors() -> _Geometry:
    """Scissors lying flat: two 2.5 mm blade plates, crossed shanks and two handle loops.

    Length 202 mm (tip at +x), handle loops 98 mm wide together and 16 mm thick.
    """
    mm = _MM
    blade_a = np.array([(-8.0, -3.0), (70.0, -5.0), (101.0, 0.0), (-8.0, 9.0)]) * mm
    blade_b = blade_a[::-1] * np.array([1.0, -1.0])
    t_blade = 2.5 * mm
    loop_w, loop_z = 4.0 * mm, 8.0 * mm
    loops = []
    for sign in (1.0, -1.0):
        ang = np.linspace(0.0, 2 * np.pi, 13)
        loops.append(
            np.column_stack([-66.0 + 31.0 * np.cos(ang), sign * (26.0 + 19.0 * np.sin(ang))]) * mm
        )
    shank_w, shank_z = 4.5 * mm, 5.0 * mm
    shanks = [
        np.array([(-40.0, -16.0), (-6.0, 4.0)]) * mm,
        np.array([(-40.0, 16.0), (-6.0, -4.0)]) * mm,
    ]
    pivot = (np.array([0.0, 0.0, -4.0]) * mm, np.array([0.0, 0.0, 4.0]) * mm, 5.5 * mm)

    def sdf(p: np.ndarray) -> np.ndarray:
        q, z = p[:, :2], p[:, 2]
        blades = np.minimum(
            _sd_extrude(_sd_polygon(q, blade_a), z, 0.0, t_blade),
            _sd_extrude(_sd_polygon(q, blade_b), z, -t_blade, 0.0),
        )
        parts = [blades, _sd_round_cylinder(p, *pivot, 1.5 * mm)]
        parts += [
            _sd_extrude_round(_sd_segments(q, lp, loop_w), z, -loop_z, loop_z, 2.0 * mm)
            for lp in loops
        ]
        parts += [
            _sd_extrude_round(_sd_segments(q, s, shank_w), z, -shank_z, shank_z, 2.0 * mm)
            for s in shanks
        ]
        return _smooth_union(parts, 2.0 * mm)

    # x-y spacing 2.5 mm; z layers every 1.25 mm, off the plate faces (0, 2.5, 4, 5, 8 mm), so
    # that every plate holds a grid layer and each face lies between two layers.
    z_axis = (np.arange(-9, 9) + 0.5) * 1.25 * mm
    xy = _grid_axes(np.array([-102, -50, 0]) * mm, np.array([102, 50, 0]) * mm, 2.5 * mm)[:2]
    mesh = _sdf_object(sdf, [xy[0], xy[1], z_axis], 2.5 * mm)
    pieces = [
        _hull(_slab_points(blade_a, 0.0, t_blade)),
        _hull(_slab_points(blade_b, -t_blade, 0.0)),
        _hull(np.vstack([_disc_points(c, 2, pivot[2], 32) for c in pivot[:2]])),
    ]
    for lp in loops:
        pieces += _thick_polyline_pieces(lp, loop_w, -loop_z, loop_z)
    for s in shanks:
        pieces += _thick_polyline_pieces(s, shank_w, -shank_z, shank_z)
    return _Geometry(mesh, pieces, rest_up=np.array([0.0, 0.0, 1.0]))


def _clamp(length_mm: float, spread_mm: float, thickness_mm: float) -> _Geometry:
    """Spring (A-)clamp lying flat: two levers mirrored across the long axis (x).

    Each lever is a thick polyline: jaw tip at +x near the axis, a bowed jaw, the pivot, and a
    straight handle to the far corner at -x (handle ends span ``spread_mm`` in y). A spring
    cylinder (axis z) sits on the pivot. Levers are as thick (z) as the clamp, so the shape is
    symmetric under a 180 degree turn about x.
    """
    mm = _MM
    half_l, half_w, half_t = length_mm / 2, spread_mm / 2, thickness_mm / 2
    w = 0.04 * length_mm
    x_pivot = 0.12 * length_mm
    x_tip = half_l - w
    lever = (
        np.array(
            [
                (x_tip, 3.0),
                (x_pivot + 0.55 * (x_tip - x_pivot), 0.09 * length_mm),
                (x_pivot, 0.0),
                (-half_l + w, -(half_w - w)),
            ]
        )
        * mm
    )
    levers = [lever, lever * np.array([1.0, -1.0])]
    spring_r = 0.07 * length_mm * mm
    z0, z1 = -half_t * mm, half_t * mm
    pivot = (np.array([x_pivot * mm, 0.0, z0]), np.array([x_pivot * mm, 0.0, z1]), spring_r)

    def sdf(p: np.ndarray) -> np.ndarray:
        q, z = p[:, :2], p[:, 2]
        # All parts share the thickness: fillet them in 2D, then extrude with rounded edges.
        parts = [_sd_segments(q, lv, w * mm) for lv in levers]
        parts.append(np.linalg.norm(q - pivot[0][:2], axis=1) - spring_r)
        return _sd_extrude_round(_smooth_union(parts, 4.0 * mm), z, z0, z1, 3.0 * mm)

    axes = _grid_axes(
        np.array([-half_l, -half_w, -half_t]) * mm,
        np.array([half_l, half_w, half_t]) * mm,
        2.5 * mm,
    )
    mesh = _sdf_object(sdf, axes, 4.0 * mm)
    pieces = [_hull(np.vstack([_disc_points(c, 2, spring_r, 32) for c in pivot[:2]]))]
    for lv in levers:
        pieces += _thick_polyline_pieces(lv, w * mm, z0, z1)
    symmetry = Symmetry.from_rotations([_rot("x", 180.0)])
    return _Geometry(mesh, pieces, rest_up=np.array([0.0, 0.0, 1.0]), symmetry=symmetry)
