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

The open vessels (bowl, mug, pitcher) are built in :mod:`handsim.world.ycbv_vessels`.

The YCB-Video scans are not aligned with the faces of their boxes: a box of the nominal size,
tilted by a few degrees, reproduces both the bounding box and the diameter of the scan to
< 0.01 mm (the boxes are fitted that way), while an axis-aligned box of the scan's extents
would be up to 14 % too long in diagonal (the gelatin box) and too thick.

"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

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

# The open vessels (bowl, mug, pitcher) are built in ycbv_vessels; importable from here too.
from handsim.world.ycbv_vessels import (  # noqa: F401
    _arc_2d,
    _bowl,
    _mug,
    _orient,
    _pitcher,
    _vessel,
    _wall_sectors,
    _zip_loops,
)

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
