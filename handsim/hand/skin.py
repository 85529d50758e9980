"""The hand's skin: one smooth closed mesh per rigid segment, built from :class:`HandParams`.

What a depth camera sees of the hand (:attr:`HandParams.surface` ``"skin"``, the default).
Collision stays the primitives of :func:`~handsim.hand.skeleton.build_skeleton`; the skin is drawn
instead of the capsule look (``surface="capsules"``).

Why per-part rigid meshes and not MuJoCo's ``<skin>`` (linear-blend skinning): every body carries
its own mesh geom, so the depth pass is MuJoCo's ordinary mesh draw (no per-frame CPU skinning),
segmentation by hand part comes from the geom -> body -> part map unchanged (a skin is one
object: one segmentation id for the whole hand), and no joint can collapse (linear-blend
skinning loses volume at twisted or strongly flexed joints, the candy-wrapper effect). Joints
stay closed by construction instead of by blending:

- A finger segment is a *round cone* (the convex hull of two spheres at its joints) whose
  cross-sections are ellipses, wider than deep (``_WIDTH_RATIO``): in the segment frame the
  solid is ``{(x, y, z): (x / s(y), y, z) in round cone}``. At a flexion joint both neighbours
  end in the same spheroid ``(x / s)^2 + (y^2 + z^2) / r^2 <= 1``, which a rotation about the
  flexion axis (``x``) maps onto itself, so a flexed joint neither opens a gap nor grows a step.
  Where a joint also abducts (finger MCPs, thumb CMC and MCP) the proximal side holds a sphere
  that contains the distal segment's end for every direction (the palm's knuckle spheres, the
  thumb metacarpal's round distal end).
- The joint radii are the means of the neighbouring collision capsule radii (the MCP takes the
  proximal phalanx's), so the pads follow the collision capsules to within half a radius step
  (0.5 mm on a medium hand), and the fingertip ends exactly at the tip keypoint.
- The palm (with the forearm stub) is a smooth union of signed-distance primitives, meshed by
  surface nets on a 2.5 mm grid and projected onto the zero set: the collision box and
  metacarpal capsules with rounded edges and filled grooves, the thenar eminence (a round cone
  from the thumb's CMC toward the palm centre, and the sphere the thumb metacarpal turns in),
  the hypothenar eminence along the ulnar border, web spaces (ridges between neighbouring
  knuckles, palmar and distal of the MCP line) and a forearm stub of elliptic section that
  tapers to the wrist. From the wrist crease on it is clipped (smoothly) to 1.8 mm outside the
  palm's collision primitives, so that the skin lies within 2 mm of the collision surface
  where the hand touches things (:func:`~handsim.hand.skin_measure.collision_gap_m` measures
  it).

Anatomy (medium hand, 189 mm): palm breadth at the metacarpal heads 0.45 hand length = 85 mm,
the British adult men's median (Pheasant & Haslegrave, *Bodyspace*, 3rd ed., 2006; Nigerian
students' means 85.8 mm men, 76.9 mm women: Ibeachu, Abu & Didia 2011, Asian J Med Sci 3:146);
palm thickness 27 mm (the MANO mean hand, fitted to 3-D scans of 31 people: Romero, Tzionas &
Black 2017, "Embodied Hands", ACM TOG 36:245); finger sections 10 % wider than deep, fingertip
pads 12 % [estimate]; forearm 0.30 hand length broad and 0.18 deep at the wrist, 0.36 by 0.25 at
the stub's end 0.55 hand length up the forearm [estimate].

All geometry is in the body frames of :class:`~handsim.hand.skeleton.Skeleton` (metres; hand frame
``+x`` radial, ``+y`` distal, ``+z`` palmar for the right hand); a left hand is the mirror image
(``x -> -x``) of the right one.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import os
import pathlib
from collections.abc import Callable

import numpy as np

from handsim.errors import InvalidHandParams
from handsim.hand.blas import blas_kernels
from handsim.hand.lofting import loft_faces

__all__ = [
    "SURFACES",
    "SKIN_DETAILS",
    "SkinPart",
    "build_skin",
    "skin_deviation_m",
    "round_cone_profile",
    "FOREARM_LENGTH_RATIO",
    "ELBOW_RATIO",
    "UPPER_ARM_RATIOS",
    "forearm_extension",
]

SURFACES: tuple[str, ...] = ("skin", "capsules")
"""Valid values of :attr:`HandParams.surface <handsim.hand.skeleton.HandParams.surface>`."""

# Width / depth of the phalanx sections and of the fingertip pad [estimate].
_WIDTH_RATIO = 1.10
_TIP_WIDTH_RATIO = 1.12
# The palm's skin stays within this of its collision primitives (blended over _CLIP_BLEND_M).
_CLIP_M = 0.0018
_CLIP_BLEND_M = 0.0015


@dataclasses.dataclass(frozen=True)
class _Resolution:
    """How finely a level of detail samples the skin."""

    rings_per_cap: int  # rings on each spherical cap of a phalanx's round cone
    rings_on_cone: int  # rings on the cone between the caps
    around: int  # vertices around each ring
    palm_grid_m: float  # surface-nets grid step of a medium (189 mm) palm, metres


SKIN_DETAILS: tuple[str, ...] = ("full", "coarse")
"""Levels of detail of the skin: ``"full"`` (what cameras draw by default; about 32 000
triangles) and ``"coarse"`` (a quarter of them: the palm on a grid twice as coarse, half the
vertices around and along each phalanx), the depth sensor's skin for small projected hands."""

_RESOLUTIONS = {
    "full": _Resolution(rings_per_cap=8, rings_on_cone=6, around=24, palm_grid_m=0.0025),
    "coarse": _Resolution(rings_per_cap=4, rings_on_cone=3, around=12, palm_grid_m=0.005),
}
_FULL = _RESOLUTIONS["full"]

Sdf = Callable[[np.ndarray], np.ndarray]


@dataclasses.dataclass(frozen=True)
class SkinPart:
    """The skin of one rigid body.

    Attributes:
        body: index of the body in :attr:`Skeleton.bodies <handsim.hand.skeleton.Skeleton.bodies>`.
        vertices: (V, 3) float64 vertex positions in the body frame, metres.
        faces: (F, 3) int32 triangles, counter-clockwise seen from outside.
        sdf: signed distance of (N, 3) body-frame points to this part's surface, metres,
            negative inside. The sign is exact; the magnitude is approximate where the palm's
            pieces blend, and within the width ratio (10 %) of the truth for the phalanges.
    """

    body: int
    vertices: np.ndarray
    faces: np.ndarray
    sdf: Sdf


# Round cones ---------------------------------------------------------------------------------


def round_cone_profile(
    r0: float,
    r1: float,
    length: float,
    rings_per_cap: int = _FULL.rings_per_cap,
    rings_on_cone: int = _FULL.rings_on_cone,
) -> tuple[np.ndarray, np.ndarray]:
    """Meridian of a round cone along ``+y`` (hull of spheres ``r0`` at 0 and ``r1`` at ``length``).

    Args:
        r0: radius of the sphere at ``y = 0``, metres.
        r1: radius of the sphere at ``y = length``, metres.
        length: distance between the sphere centres, metres (> ``|r0 - r1|``).
        rings_per_cap: rings on each spherical cap (the full skin's by default).
        rings_on_cone: rings on the cone between them.

    Returns:
        ``(y, rho)``: (K,) axial positions and radii, from the proximal pole (``rho = 0``) to
        the distal pole, sampled on both spherical caps and the cone between them.
    """
    alpha_t = np.arcsin((r0 - r1) / length)
    a0 = np.linspace(-np.pi / 2, alpha_t, rings_per_cap + 1)
    a1 = np.linspace(alpha_t, np.pi / 2, rings_per_cap + 1)
    y0, rho0 = r0 * np.sin(a0), r0 * np.cos(a0)
    y1, rho1 = length + r1 * np.sin(a1), r1 * np.cos(a1)
    t = np.linspace(0.0, 1.0, rings_on_cone + 2)[1:-1]
    yc = y0[-1] + t * (y1[0] - y0[-1])
    rc = rho0[-1] + t * (rho1[0] - rho0[-1])
    return np.concatenate([y0, yc, y1]), np.concatenate([rho0, rc, rho1])


def _sd_round_cone(p: np.ndarray, r0: float, r1: float, length: float) -> np.ndarray:
    """Exact signed distance to the round cone of :func:`round_cone_profile` (Quilez)."""
    q = np.hypot(p[:, 0], p[:, 2])
    y = p[:, 1]
    b = (r0 - r1) / length
    a = np.sqrt(max(1.0 - b * b, 0.0))
    k = -q * b + y * a  # position along the tangent line
    d_cone = q * a + y * b - r0
    d0 = np.hypot(q, y) - r0
    d1 = np.hypot(q, y - length) - r1
    return np.where(k < 0.0, d0, np.where(k > a * length, d1, d_cone))


def _elliptic_round_cone(
    r0: float, r1: float, length: float, s0: float, s1: float, res: _Resolution = _FULL
) -> tuple[np.ndarray, np.ndarray, Sdf]:
    """Mesh and signed distance of a round cone whose sections are ``s(y)`` wider than deep."""
    y, rho = round_cone_profile(r0, r1, length, res.rings_per_cap, res.rings_on_cone)

    def width(yy: np.ndarray) -> np.ndarray:
        return s0 + (s1 - s0) * np.clip(yy / length, 0.0, 1.0)

    s = width(y)
    t = 2.0 * np.pi * np.arange(res.around) / res.around
    rings = np.stack(
        [
            np.cos(t)[None, :] * (s * rho)[1:-1, None],
            np.broadcast_to(y[1:-1, None], (len(y) - 2, res.around)),
            np.sin(t)[None, :] * rho[1:-1, None],
        ],
        axis=-1,
    ).reshape(-1, 3)
    vertices = np.concatenate([[[0.0, y[0], 0.0]], rings, [[0.0, y[-1], 0.0]]])
    faces = loft_faces(len(y) - 2, res.around)

    def sdf(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        scaled = p.copy()
        sp = width(p[:, 1])
        scaled[:, 0] = p[:, 0] / sp
        # The distance in the frame where the sections are round: its sign is exact and its
        # magnitude at most the true distance (the map to that frame is a contraction).
        return _sd_round_cone(scaled, r0, r1, length)

    return vertices, faces, sdf


# Signed-distance pieces of the palm -----------------------------------------------------------


def _sd_capsule(p: np.ndarray, a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    e = b - a
    w = p - a
    t = np.clip(w @ (e / (e @ e)), 0.0, 1.0)
    w -= t[:, None] * e
    return np.sqrt(np.einsum("ij,ij->i", w, w)) - r


def _sd_cone_between(p: np.ndarray, a: np.ndarray, b: np.ndarray, ra: float, rb: float):
    """Round cone from ``a`` (radius ``ra``) to ``b`` (radius ``rb``) in any direction."""
    axis = b - a
    length = float(np.linalg.norm(axis))
    y_axis = axis / length
    helper = np.array([0.0, 0.0, 1.0]) if abs(y_axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x_axis = np.cross(y_axis, helper)
    x_axis /= np.linalg.norm(x_axis)
    z_axis = np.cross(x_axis, y_axis)
    local = (p - a) @ np.stack([x_axis, y_axis, z_axis], axis=1)
    return _sd_round_cone(local, ra, rb, length)


def _sd_forearm(p: np.ndarray, y: np.ndarray, half_width: np.ndarray, half_depth: np.ndarray):
    """Elliptic sections with half axes interpolated between knots ``y``; flat end at ``y[0]``.

    The distal end (``y[-1]``) lies inside the palm, so only the proximal end is rounded.
    """
    a = np.interp(p[:, 1], y, half_width)
    c = np.interp(p[:, 1], y, half_depth)
    radial = (np.hypot(p[:, 0] / a, p[:, 2] / c) - 1.0) * np.minimum(a, c)
    # Round the rim of the cut end (radius `rim`) so that it meshes cleanly.
    rim = 0.3 * float(half_depth[0])
    w = np.stack([radial + rim, y[0] + rim - p[:, 1]], axis=1)
    rounded = np.linalg.norm(np.maximum(w, 0.0), axis=1) + np.minimum(w.max(axis=1), 0) - rim
    return np.maximum(rounded, p[:, 1] - y[-1])  # the flat distal end lies inside the palm


def _smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    h = np.maximum(k - np.abs(a - b), 0.0) / k
    return np.minimum(a, b) - 0.25 * k * h * h


def _palm_sdf(skeleton) -> tuple[Sdf, np.ndarray, np.ndarray]:
    """Signed distance of the palm (and forearm stub) in the palm frame, and its bounds."""
    params = skeleton.params
    hl = params.hand_length
    thick = params.thickness_scale
    bodies = skeleton.bodies
    palm = bodies[0]
    box = palm.geoms[0]
    half_t = float(box.half_size[2])
    metacarpals = [g for g in palm.geoms[1:] if g.start[1] >= 0.0]  # not the forearm
    index = {b.name: i for i, b in enumerate(bodies)}
    mcp = {f: bodies[index[f"{f}_proximal"]].pos for f in ("index", "middle", "ring", "little")}
    cmc = bodies[index["thumb_metacarpal"]].pos
    r_cmc = bodies[index["thumb_metacarpal"]].geoms[0].radius
    r_pp = {f: bodies[index[f"{f}_proximal"]].geoms[0].radius for f in mcp}
    breadth = params.breadth
    # At most 5 mm: at the wrist end, where no metacarpal capsule covers the box's edges, a
    # rounder edge would lie more than 2 mm inside the collision box.
    rounding = min(0.3 * half_t, 0.005)
    scale = hl / 0.189

    def collision(p: np.ndarray) -> np.ndarray:
        """The palm's collision primitives (exact union; the forearm's capsules left out)."""
        q = np.abs(p - box.pos) - box.half_size
        d = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
        for g in metacarpals:
            d = np.minimum(d, _sd_capsule(p, g.start, g.end, g.radius))
        return d

    def core(p: np.ndarray) -> np.ndarray:
        # The collision palm with its edges rounded and the grooves between the metacarpal
        # capsules filled (a smooth union among the capsules only: they are tangent to the
        # box, where a smooth union would inflate the palm everywhere).
        q = np.abs(p - box.pos) - (box.half_size - rounding)
        d = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0) - rounding
        caps = _sd_capsule(p, metacarpals[0].start, metacarpals[0].end, metacarpals[0].radius)
        for g in metacarpals[1:]:
            caps = _smin(caps, _sd_capsule(p, g.start, g.end, g.radius), 0.008 * scale)
        return np.minimum(d, caps)

    # Thenar eminence: from the sphere the thumb metacarpal turns in toward the palm centre.
    thenar_end = np.array([0.17 * breadth, 0.32 * mcp["middle"][1], half_t - 0.6 * r_cmc])
    # Hypothenar eminence along the ulnar border, proximal two thirds of the palm.
    hyp_r = 0.75 * half_t
    hyp_z = half_t + 0.0008 * thick - hyp_r
    hyp_a = np.array([-0.24 * breadth, 0.28 * mcp["little"][1], hyp_z])
    hyp_b = np.array([-0.31 * breadth, 0.62 * mcp["little"][1], hyp_z])
    # Web spaces: ridges between neighbouring knuckles, palmar and distal of the MCP line.
    webs = []
    fingers = ("index", "middle", "ring", "little")
    for f, g in zip(fingers[:-1], fingers[1:], strict=True):
        r = 0.5 * (r_pp[f] + r_pp[g])
        shift = np.array([0.0, 0.45 * r, 0.3 * r])
        webs.append((mcp[f] + shift, mcp[g] + shift, 0.5 * r))
    forearm = None
    if params.forearm:
        # Broadest and deepest at the stub's end, tapering to the wrist, where it is as deep
        # as the palm (no step), and running on inside the palm.
        forearm = (
            np.array([-0.55, -0.25, 0.0, 0.12]) * hl,
            np.array([0.18, 0.165, 0.145, 0.12]) * hl,
            np.array([0.125 * hl * thick, 0.105 * hl * thick, half_t - 0.0015, 0.6 * half_t]),
        )
    k = 0.012 * hl / 0.189

    def sdf(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        cmc_sphere = np.linalg.norm(p - cmc, axis=1) - r_cmc
        d = core(p)
        d = _smin(d, cmc_sphere, 0.4 * k)
        d = _smin(d, _sd_cone_between(p, cmc, thenar_end, r_cmc, 0.55 * r_cmc), 0.4 * k)
        d = _smin(d, _sd_capsule(p, hyp_a, hyp_b, hyp_r), 0.4 * k)
        for a, b, r in webs:
            d = _smin(d, _sd_capsule(p, a, b, r), 0.6 * k)
        if forearm is not None:
            d = _smin(d, _sd_forearm(p, *forearm), k)
        # Nothing of the hand (y >= 0) stands more than _CLIP_M outside the collision palm, so a
        # contact in physics is a contact in depth; the forearm is free. The sphere the thumb
        # metacarpal turns in is kept whole (the thumb's own collision capsule starts in it).
        offset = _CLIP_M + 3.0 * np.maximum(-p[:, 1], 0.0)
        d = -_smin(-d, offset - collision(p), _CLIP_BLEND_M)
        return np.minimum(d, cmc_sphere)

    # Bounds: the radial edge (index knuckle, thenar), the ulnar edge, the knuckle row, the
    # forearm's end and the palmar/dorsal reach of the largest pieces.
    x_hi = max(mcp["index"][0] + half_t, cmc[0] + r_cmc, 0.18 * hl)
    x_lo = min(mcp["little"][0] - half_t, hyp_b[0] - hyp_r, -0.18 * hl)
    y_lo = -0.55 * hl if params.forearm else -half_t
    y_hi = mcp["middle"][1] + half_t
    z_reach = max(half_t + 0.004, cmc[2] + r_cmc, 0.125 * hl * thick if params.forearm else 0)
    lo = np.array([x_lo, y_lo, -z_reach]) - 0.003
    hi = np.array([x_hi, y_hi, z_reach]) + 0.003
    return sdf, lo, hi


# Meshing the palm ------------------------------------------------------------------------------

# Corner offsets of a grid cell and its 12 edges (pairs of corner indices).
_CORNERS = np.array([(i & 1, i >> 1 & 1, i >> 2 & 1) for i in range(8)])
_EDGES = np.array(
    [
        (a, b)
        for a in range(8)
        for b in range(a + 1, 8)
        if np.abs(_CORNERS[a] - _CORNERS[b]).sum() == 1
    ]
)


def _surface_nets(sdf: Sdf, lo: np.ndarray, hi: np.ndarray, step: float):
    """Naive surface nets: one vertex per grid cell the surface crosses, one quad per crossed edge.

    Args:
        sdf: signed distance of (N, 3) points, negative inside.
        lo: (3,) lower corner of a box that holds the solid, metres.
        hi: (3,) upper corner.
        step: grid step, metres.

    Returns:
        ``(vertices, faces)``: (V, 3) float64 (each the mean of its cell's edge crossings) and
        (F, 3) int32 triangles wound counter-clockwise from outside. The surface is closed
        (the grid's border, one step outside the box, is outside the solid).
    """
    axes = [np.arange(a - step, b + 2 * step, step) for a, b in zip(lo, hi, strict=True)]
    shape = tuple(len(a) for a in axes)
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    f = sdf(grid.reshape(-1, 3)).reshape(shape)
    f = np.where(f == 0.0, 1e-12, f)
    inside = f < 0.0
    nx, ny, nz = (n - 1 for n in shape)

    def corner(c: np.ndarray, a: np.ndarray) -> np.ndarray:
        return a[c[0] : c[0] + nx, c[1] : c[1] + ny, c[2] : c[2] + nz]

    total = np.zeros((nx, ny, nz, 3))
    count = np.zeros((nx, ny, nz))
    for a, b in _EDGES:
        fa, fb = corner(_CORNERS[a], f), corner(_CORNERS[b], f)
        crossed = (fa < 0) != (fb < 0)
        t = np.where(crossed, fa / np.where(crossed, fa - fb, 1.0), 0.0)
        pa, pb = corner(_CORNERS[a], grid), corner(_CORNERS[b], grid)
        total += crossed[..., None] * (pa + t[..., None] * (pb - pa))
        count += crossed
    active = count > 0
    index = np.full((nx, ny, nz), -1, dtype=np.int64)
    index[active] = np.arange(int(active.sum()))
    vertices = total[active] / count[active][:, None]

    quads = []
    for axis in range(3):
        b, c = (axis + 1) % 3, (axis + 2) % 3
        lo_side = [slice(None)] * 3
        hi_side = [slice(None)] * 3
        lo_side[axis] = slice(0, -1)
        hi_side[axis] = slice(1, None)
        ins, outs = inside[tuple(lo_side)], inside[tuple(hi_side)]
        # Grid edges along `axis` that change sign, away from the border in b and c.
        change = ins != outs
        sel = [slice(None)] * 3
        sel[b] = slice(1, -1)
        sel[c] = slice(1, -1)
        e = np.argwhere(change[tuple(sel)])
        e[:, b] += 1
        e[:, c] += 1
        ring = []
        for db, dc in ((-1, -1), (0, -1), (0, 0), (-1, 0)):
            cell = e.copy()
            cell[:, b] += db
            cell[:, c] += dc
            ring.append(index[cell[:, 0], cell[:, 1], cell[:, 2]])
        q = np.stack(ring, axis=1)
        # Counter-clockwise about +axis; reversed where the outside is on the -axis side.
        outward_neg = ~ins[e[:, 0], e[:, 1], e[:, 2]]
        q[outward_neg] = q[outward_neg][:, ::-1]
        quads.append(q)
    quads = np.concatenate(quads)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int32)
    return vertices, faces


def _project(sdf: Sdf, p: np.ndarray, steps: int = 6, tol: float = 1e-7) -> np.ndarray:
    """Newton steps of (N, 3) points onto the zero set of ``sdf`` (finite differences).

    Points already within ``tol`` (metres) of the zero set are left alone.
    """
    eps = 1e-6
    p = np.array(p, dtype=np.float64)
    for _ in range(steps):
        f = sdf(p)
        active = np.abs(f) > tol
        if not active.any():
            break
        q, fq = p[active], f[active]
        g = np.stack([(sdf(q + eps * e) - fq) / eps for e in np.eye(3)], axis=1)
        p[active] = q - (fq / np.maximum(np.einsum("ij,ij->i", g, g), 1e-12))[:, None] * g
    return p


# Building --------------------------------------------------------------------------------------


_CACHE_DIR = pathlib.Path(__file__).parent / "__pycache__"
"""Where meshed palms are kept between processes (beside this module, as numba keeps its
compiled loops); nothing is kept where it is not writable."""
_CACHE_FILES = 96  # hand lengths on a 2 mm grid: 36, at two levels of detail


def _palm_mesh(skeleton, sdf: Sdf, lo: np.ndarray, hi: np.ndarray, step: float):
    """The palm's surface-nets mesh projected onto its zero set, from the disk cache if there.

    Meshing costs ~0.3 s, paid by every process that builds a hand (each dataset worker):
    the result is kept in a file named by a hash of everything it depends on (this module's
    and the lofting module's source, the hand's parameters and skeleton, the grid step,
    NumPy's version and its BLAS kernels, which round differently),
    so a kept mesh is bitwise the one this process would make.
    """
    key = hashlib.sha256()
    for module in (__file__, loft_faces.__code__.co_filename):
        key.update(pathlib.Path(module).read_bytes())
    key.update(np.__version__.encode())
    key.update(blas_kernels().encode())
    key.update(repr(skeleton.params).encode())
    key.update(np.float64(step).tobytes() + lo.tobytes() + hi.tobytes())
    for body in skeleton.bodies:
        key.update(repr((body.name, body.part, body.parent)).encode())
        key.update(np.asarray(body.pos, dtype=np.float64).tobytes())
        for g in body.geoms:
            for name in ("start", "end", "radius", "pos", "half_size"):
                if hasattr(g, name):
                    key.update(np.asarray(getattr(g, name), dtype=np.float64).tobytes())
    path = _CACHE_DIR / f"palm-{key.hexdigest()[:32]}.npz"
    with contextlib.suppress(OSError, ValueError, KeyError):
        with np.load(path) as kept:
            return kept["vertices"], kept["faces"]
    vertices, faces = _surface_nets(sdf, lo, hi, step)
    vertices = _project(sdf, vertices)
    # Written under a name of this process's, then renamed: a reader never sees half a file.
    with contextlib.suppress(OSError):
        _CACHE_DIR.mkdir(exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.npz")
        np.savez(partial, vertices=vertices, faces=faces)
        os.replace(partial, path)
        # At most _CACHE_FILES palms (about 0.4 MB each): the least recently made go.
        kept = sorted(_CACHE_DIR.glob("palm-*.npz"), key=lambda f: f.stat().st_mtime)
        for old in kept[:-_CACHE_FILES]:
            old.unlink(missing_ok=True)
    return vertices, faces


def _segment_kind(name: str) -> str:
    return name.split("_", 1)[1]


@functools.lru_cache(maxsize=64)  # a 2 mm grid of lengths over 0.15-0.22 m is 36
def _right_parts(params, detail: str = "full") -> tuple[SkinPart, ...]:
    from handsim.hand.skeleton import build_skeleton  # noqa: PLC0415 (it imports this module)

    skeleton = build_skeleton(dataclasses.replace(params, side="right", surface="capsules"))
    bodies = skeleton.bodies
    children = {b.parent: i for i, b in enumerate(bodies) if b.parent > 0}
    parts = []

    sdf, lo, hi = _palm_sdf(skeleton)
    # The grid scales with the hand: the same mesh density (and cost) for every size.
    res = _RESOLUTIONS[detail]
    step = res.palm_grid_m * params.hand_length / 0.189
    vertices, faces = _palm_mesh(skeleton, sdf, lo, hi, step)
    parts.append(SkinPart(0, vertices, faces, sdf))

    for i, body in enumerate(bodies[1:], start=1):
        capsule = body.geoms[0]
        r = capsule.radius
        kind = _segment_kind(body.name)
        parent = bodies[body.parent] if body.parent > 0 else None
        if parent is None or kind == "proximal" and body.part != "thumb":
            r0 = r  # the MCP (or CMC) takes the segment's own radius
        else:
            r0 = 0.5 * (r + parent.geoms[0].radius)
        child = children.get(i)
        if child is None:
            r1 = r
            length = float(capsule.end[1])  # the tip sphere's centre: its surface is the tip
        else:
            r1 = 0.5 * (r + bodies[child].geoms[0].radius)
            length = float(bodies[child].pos[1])
        if kind == "metacarpal":
            # Round, and so is the thumb proximal phalanx's base: the thumb MCP abducts and
            # flexes, and a sphere shared by both sides is closed under any rotation.
            s0 = s1 = 1.0
        elif body.part == "thumb" and kind == "proximal":
            s0, s1 = 1.0, _WIDTH_RATIO
        else:
            s0 = _WIDTH_RATIO
            s1 = _TIP_WIDTH_RATIO if child is None else _WIDTH_RATIO
        vertices, faces, sdf = _elliptic_round_cone(r0, r1, length, s0, s1, res)
        parts.append(SkinPart(i, vertices, faces, sdf))
    return tuple(parts)


def _mirror(part: SkinPart) -> SkinPart:
    flip = np.array([-1.0, 1.0, 1.0])
    right_sdf = part.sdf
    return SkinPart(
        part.body,
        part.vertices * flip,
        part.faces[:, ::-1].copy(),
        lambda p: right_sdf(np.asarray(p, dtype=np.float64) * flip),
    )


@functools.lru_cache(maxsize=64)  # a 2 mm grid of lengths over 0.15-0.22 m is 36
def build_skin(params, detail: str = "full") -> tuple[SkinPart, ...]:
    """The skin of a hand, one part per body (cached per parameters).

    Args:
        params: hand parameters (:class:`~handsim.hand.skeleton.HandParams`); ``surface`` is
            ignored.
        detail: level of detail (:data:`SKIN_DETAILS`): the same surface sampled more or less
            finely; every level's parts share the bodies, so they pose alike.

    Returns:
        One :class:`SkinPart` per body of :func:`~handsim.hand.skeleton.build_skeleton`, in body
        order (the palm, with the forearm stub, first). Arrays are read-only.

    Raises:
        InvalidHandParams: for an unknown ``detail``.
    """
    if not isinstance(detail, str) or detail not in _RESOLUTIONS:
        raise InvalidHandParams(
            f"detail must be one of {', '.join(map(repr, SKIN_DETAILS))}; received {detail!r}"
        )
    # The skin depends on the sizes and the forearm only: left and right share one build.
    shape = dataclasses.replace(params, side="right", surface="skin", couple_dip=False)
    parts = _right_parts(shape, detail)
    if params.side == "left":
        parts = tuple(_mirror(p) for p in parts)
    for p in parts:
        p.vertices.setflags(write=False)
        p.faces.setflags(write=False)
    return parts


@functools.lru_cache(maxsize=64)
def skin_deviation_m(params, detail: str = "coarse") -> float:
    """How far a level of detail's surface strays from the full skin's, metres (largest).

    Measured at the level's triangle centres and edge midpoints (its vertices lie on the
    surface, its flat triangles cut inside convex parts) with each part's signed distance:
    where the palm's pieces blend the distance is approximate, elsewhere exact for round
    sections and within the width ratio for elliptic ones. About proportional to hand length
    (the palm's grid scales with it), up to where the grid falls on the palm's edges; a hand
    rescaled in place (:meth:`Scene.set_hand_length
    <handsim.world.scene.Scene.set_hand_length>`) has its built mesh's, scaled.

    Args:
        params: hand parameters.
        detail: level of detail (:data:`SKIN_DETAILS`).

    Returns:
        The largest absolute distance, metres (0 for ``"full"``).
    """
    if detail == "full":
        build_skin(params, detail)  # validates the params' type as the other levels do
        return 0.0
    worst = 0.0
    for part in build_skin(params, detail):
        tri = part.vertices[part.faces]
        points = np.concatenate(
            [tri.mean(axis=1), 0.5 * (tri[:, 0] + tri[:, 1]), 0.5 * (tri[:, 1] + tri[:, 2])]
        )
        worst = max(worst, float(np.abs(part.sdf(points)).max()))
    return worst


# Measuring the skin against the skeleton: handsim.hand.skin_measure, which imports this
# module, so its functions load on first use from here.
_MEASURES = ("collision_gap_m", "joint_crease_depth_m", "digit_volume_m3")


def __getattr__(name: str):
    """The measuring functions, still importable from here (PEP 562)."""
    if name in _MEASURES:
        from handsim.hand import skin_measure  # noqa: PLC0415 (it imports this module)

        return getattr(skin_measure, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# The forearm ----------------------------------------------------------------------------------

FOREARM_LENGTH_RATIO = 1.40
"""Wrist crease to the tip of the elbow over hand length: the forearm (wrist to elbow joint) is
about 1.35 hand lengths (segment lengths 0.146 and 0.108 of body height, Drillis & Contini's
table in Winter, *Biomechanics and Motor Control of Human Movement*), plus the olecranon's
rounded end [estimate]."""

ELBOW_RATIO = 1.35
"""Wrist crease to the elbow joint's centre over hand length (the segment lengths above)."""
UPPER_ARM_RATIOS = (1.72, 0.24)
"""The upper arm, elbow to shoulder, over hand length: its length (0.186 of body height in the
same table) and its radius (45 mm at 189 mm, a mid-arm circumference of 0.28 m) [estimate]."""

# The forearm beyond the stub of the palm's skin: elliptic sections (y, half width, half depth)
# in hand lengths (depths also times thickness_scale), from inside the stub to the elbow, where a
# half-ellipsoid cap closes it. Broadest a third of the way up (the flexor and extensor bellies,
# 87 x 66 mm at 189 mm, a circumference of about 0.24 m) [estimate]. From y = -0.51 on it lies
# 0.5 mm outside the stub, whose rounded end it hides.
_FOREARM_PROFILE = np.array(
    [
        (-0.45, 0.170, 0.110),
        (-0.51, 0.182, 0.127),
        (-0.55, 0.183, 0.128),
        (-0.80, 0.225, 0.165),
        (-1.05, 0.230, 0.175),
        (-1.30, 0.205, 0.160),
    ]
)
_FOREARM_AROUND = 16
_FOREARM_CAP_DEG = (30.0, 60.0)  # cap rings, degrees from the elbow's pole


def _forearm_extension(hl: float, thick: float) -> tuple[np.ndarray, np.ndarray]:
    """The lofted forearm from inside the stub to the elbow: (V, 3) vertices, (F, 3) faces."""
    y, a, c = _FOREARM_PROFILE.T * hl
    c = c * thick
    cap_len = y[-1] + FOREARM_LENGTH_RATIO * hl  # from the last ring to the elbow's tip
    # Rings advance along +y (elbow first): loft_faces' winding with u = +x, v = +z.
    rings = [
        (y[-1] - cap_len * np.cos(np.deg2rad(phi)), s * a[-1], s * c[-1])
        for phi, s in ((p, np.sin(np.deg2rad(p))) for p in _FOREARM_CAP_DEG)
    ]
    rings += list(zip(y[::-1], a[::-1], c[::-1], strict=True))
    t = 2.0 * np.pi * np.arange(_FOREARM_AROUND) / _FOREARM_AROUND
    ring_points = [
        np.stack([ai * np.cos(t), np.full_like(t, yi), ci * np.sin(t)], axis=1)
        for yi, ai, ci in rings
    ]
    vertices = np.concatenate(
        [[[0.0, -FOREARM_LENGTH_RATIO * hl, 0.0]], *ring_points, [[0.0, y[0], 0.0]]]
    )
    return vertices, loft_faces(len(rings), _FOREARM_AROUND)


def forearm_extension(params) -> tuple[np.ndarray, np.ndarray]:
    """The forearm beyond the palm's stub, to the elbow: a lofted elliptic tube.

    It starts inside the stub of the palm's skin (whose rounded end it hides) and ends
    :data:`FOREARM_LENGTH_RATIO` hand lengths from the wrist crease, in line with the hand, in
    a few hundred triangles (the palm's skin has about 16 000).

    Args:
        params: hand parameters (:class:`~handsim.hand.skeleton.HandParams`).

    Returns:
        (V, 3) float64 vertices in the palm frame, metres, and (F, 3) int32 faces,
        counter-clockwise seen from outside.
    """
    vertices, faces = _forearm_extension(params.hand_length, params.thickness_scale)
    if params.side == "left":
        return vertices * np.array([-1.0, 1.0, 1.0]), faces[:, ::-1].copy()
    return vertices, faces
