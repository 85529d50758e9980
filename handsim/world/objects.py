"""The 21 YCB-Video objects as simulation objects, and import of user meshes.

Every object is a frozen :class:`YCBObject`: a watertight visual mesh, convex collision pieces,
mass and inertia, model points for ADD/ADI, the diameter, the 8 bounding-box corners, the
symmetries and a stable resting pose, all in SI units (metres, kilograms) in the object frame.
This module holds the object type (:class:`YCBObject`, :class:`ObjectSpec`) and
:func:`add_object`, which puts any object into a ``mujoco.MjSpec``; their symmetries are
:class:`~handsim.world.symmetry.Symmetry` (:mod:`handsim.world.symmetry`). The 21 shapes are
made in :mod:`handsim.world.ycbv_shapes` (from primitives meshed by
:mod:`handsim.world.meshing`), with their facts in :mod:`handsim.world.ycbv`,
registered in :mod:`handsim.world.registry` (:data:`OBJECTS`, :func:`get_object`), and user
meshes are imported by :mod:`handsim.world.mesh_import` (:func:`load_object`).

Conventions:

- Object frame: the model axes of the YCB-Video ``textured_simple.obj`` models (PoseCNN's
  extents: cans and bottles have their axis along ``y``), origin at the centre of the axis-aligned
  bounding box. Extents are the bounding-box sizes along ``x, y, z``.
- Box corners (:attr:`YCBObject.corners_m`, 8 x 3) are in ``itertools.product`` order of
  (min, max) per axis: corner ``k`` takes the max along ``x`` if bit 2 of ``k`` is set, along
  ``y`` if bit 1 is set and along ``z`` if bit 0 is set, i.e. ``(---), (--+), (-+-), (-++),
  (+--), (+-+), (++-), (+++)``.
- Diameter: the largest distance between two mesh vertices (BOP ``models_info``).
- Mass: Calli et al. 2015. Inertia: the visual mesh with uniform density, scaled to the mass.
- Symmetry (:class:`Symmetry`, BOP style): continuous about ``y`` for the master chef can,
  bowl and marker; discrete for the wood block (4-fold about its long axis, 2-fold about the
  others: 8 elements), foam brick (same, long axis ``x``) and the clamps (180 degrees about
  their long axis ``x``). The facts' per-axis angles come from configs of BOP-frame models;
  they are mapped here to the YCB-Video axes by the geometry (e.g. the bowl's axis is ``y``,
  the wood block's long axis is ``y``). The large clamp's facts diameter (183.1 =
  hypot(173, 60) mm) puts its jaw tip on the ``x`` axis, so its turn is about ``x``, not ``y``.

Resting pose (:attr:`YCBObject.rest_quat_wxyz`): the face of the convex hull nearest to the
shape's natural up axis on which the centre of mass projects at least 0.1 mm inside (cans and
bottles upright, boxes on their largest face, flat objects lying).

Names in MJCF (``<name>`` is the object name, e.g. ``005_tomato_soup_can``):

=======================  ===================================  ================================
element                  name                                 notes
=======================  ===================================  ================================
body                     ``obj_<name>``                       explicit mass, COM, inertia
free joint               ``obj_<name>_root``                  optional
visual geom / mesh       ``obj_<name>_visual``                group 2, contype=conaffinity=0
collision geoms/meshes   ``obj_<name>_collision_<k>``         group 3, k = 0, 1, ...
=======================  ===================================  ================================

A second copy of an object in one scene takes another body name (``body_name=``); every
other name is derived from the body name.

Dependencies: trimesh, scipy, MuJoCo; CoACD (``pip install coacd``, optional, imported by
:func:`load_object` only) for the convex decomposition of imported meshes.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Literal

import mujoco
import numpy as np

from handsim._validate import to_real_array
from handsim.errors import HandSimError, InvalidObjectParams
from handsim.world.symmetry import (
    NO_SYMMETRY,
    SYMMETRY_MODALITIES,
    Symmetry,
    SymmetryModality,
)

if TYPE_CHECKING:
    # trimesh and scipy.spatial load where objects are built, not on `import handsim`.
    import trimesh
    from scipy.spatial.transform import Rotation

__all__ = [
    "InvalidMesh",
    "InvalidObjectParams",
    "MeshImportWarning",
    "Symmetry",
    "SYMMETRY_MODALITIES",
    "SymmetryModality",
    "NO_SYMMETRY",
    "YCBObject",
    "ObjectSpec",
    "add_object",
    "MESH_FORMATS",
    "SIZE_RANGE_M",
    "N_MODEL_POINTS",
    "VISUAL_GROUP",
    "COLLISION_GROUP",
]


class InvalidMesh(HandSimError, ValueError):
    """A mesh is empty, non-finite, of an absurd size or in an unsupported format."""


class MeshImportWarning(UserWarning):
    """An imported mesh needed a fallback (no CoACD, not watertight)."""


MESH_FORMATS: tuple[str, ...] = (".obj", ".ply", ".stl", ".glb")
"""File suffixes :func:`load_object` accepts (read by trimesh)."""

SIZE_RANGE_M: tuple[float, float] = (0.005, 1.0)
"""Valid largest extent of an imported object after scaling, metres (a hand can grasp it)."""

N_MODEL_POINTS = 2000
"""Default number of model points (surface samples) for ADD/ADI."""

VISUAL_GROUP = 2
"""MuJoCo geom group of visual geoms (what cameras render)."""

COLLISION_GROUP = 3
"""MuJoCo geom group of collision geoms (hidden from cameras by default)."""

_MM = 1e-3
_NAME_RE = re.compile(r"^[A-Za-z0-9_]+$")
_FRICTION = (1.0, 0.005, 0.0001)


# The object ----------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class YCBObject:
    """A rigid object ready for simulation, rendering and pose metrics (object frame, SI).

    Built-in objects come from :func:`get_object`, user meshes from :func:`load_object`; both
    are used the same way (:func:`add_object`, metrics on :attr:`model_points_m`). Arrays are
    read-only; treat the meshes as read-only too (``mesh.copy()`` before editing).
    """

    name: str
    """Object name, e.g. ``005_tomato_soup_can``; MJCF names are ``obj_<name>...``."""
    visual_mesh: trimesh.Trimesh = dataclasses.field(repr=False)
    """What cameras see: a watertight triangle mesh (built-ins), metres, object frame."""
    collision_meshes: tuple[trimesh.Trimesh, ...] = dataclasses.field(repr=False)
    """Convex pieces whose union approximates the shape (hollow objects stay hollow)."""
    mass_kg: float
    """Mass, kg."""
    com_m: np.ndarray = dataclasses.field(repr=False)
    """(3,) centre of mass, metres, object frame."""
    inertia_kg_m2: np.ndarray = dataclasses.field(repr=False)
    """(3, 3) inertia tensor about the centre of mass, object axes, kg m^2."""
    model_points_m: np.ndarray = dataclasses.field(repr=False)
    """(N, 3) float64 seeded surface samples of the visual mesh, metres (ADD/ADI)."""
    diameter_m: float
    """Largest distance between two mesh vertices, metres."""
    extents_m: np.ndarray = dataclasses.field(repr=False)
    """(3,) bounding-box size along x, y, z, metres."""
    corners_m: np.ndarray = dataclasses.field(repr=False)
    """(8, 3) bounding-box corners, metres, in the order of the module docstring."""
    symmetry: Symmetry
    """Shape symmetries (BOP style)."""
    rest_quat_wxyz: np.ndarray = dataclasses.field(repr=False)
    """(4,) an orientation (object to world) in which the object rests stably on a plane z=0:
    the stable face of the convex hull nearest to the shape's natural up axis (cans upright,
    boxes on their largest face, flat objects lying; ``rest_up`` for imported meshes)."""
    rest_height_m: float = dataclasses.field(repr=False)
    """Height of the object origin above the plane in the rest orientation, metres."""
    rgba: tuple[float, float, float, float] = dataclasses.field(repr=False)
    """Colour of the visual geom."""
    shape: str
    """Short description of how the shape was made (or the source file)."""
    ycbv_id: int | None = None
    """1-based YCB-Video object id (BOP ``obj_id``), ``None`` for user meshes."""
    cavity_point_m: np.ndarray | None = dataclasses.field(default=None, repr=False)
    """(3,) a point inside the cavity that fingers can enter (bowl, mug, pitcher), metres,
    object frame; ``None`` for solid objects."""
    depth_symmetry: Symmetry | None = dataclasses.field(default=None, repr=False)
    """Symmetries of the shape alone, as a depth camera sees it (colour and print ignored),
    where they exceed :attr:`symmetry`: e.g. the soup and tuna cans, plain cylinders whose
    labels break the rotation in colour only. ``None``: the same as :attr:`symmetry`."""

    def symmetry_of(self, modality: SymmetryModality = "texture") -> Symmetry:
        """The symmetries that hold for a modality (:data:`SYMMETRY_MODALITIES`).

        Args:
            modality: ``"texture"``: poses that look the same in colour (BOP's ycbv
                symmetries, :attr:`symmetry`); ``"depth"``: poses that give the same depth
                image (:attr:`depth_symmetry`, else :attr:`symmetry`).

        Raises:
            InvalidObjectParams: for another modality.
        """
        if modality == "texture":
            return self.symmetry
        if modality == "depth":
            return self.symmetry if self.depth_symmetry is None else self.depth_symmetry
        raise InvalidObjectParams(
            f"symmetry modality must be one of {SYMMETRY_MODALITIES}; received {modality!r}"
        )

    @property
    def body_name(self) -> str:
        """Default MJCF body name, ``obj_<name>``."""
        return f"obj_{self.name}"

    @property
    def visual_geom_name(self) -> str:
        """Default MJCF name of the visual geom (and its mesh asset)."""
        return f"{self.body_name}_visual"

    @property
    def collision_geom_names(self) -> tuple[str, ...]:
        """Default MJCF names of the collision geoms (and their mesh assets)."""
        return tuple(f"{self.body_name}_collision_{k}" for k in range(len(self.collision_meshes)))

    @property
    def joint_name(self) -> str:
        """Default MJCF name of the free joint."""
        return f"{self.body_name}_root"

    def add_to(self, spec: mujoco.MjSpec, **kwargs: Any) -> mujoco.MjsBody:
        """Shorthand for :func:`add_object` ``(spec, self, **kwargs)``."""
        return add_object(spec, self, **kwargs)


@dataclasses.dataclass(frozen=True)
class ObjectSpec:
    """A registered YCB-Video object: facts (extents, diameter, mass) and the recipe of its shape.

    :meth:`build` (or :func:`get_object`) makes the :class:`YCBObject`.
    """

    name: str
    """Canonical name, e.g. ``005_tomato_soup_can``."""
    ycbv_id: int
    """1-based YCB-Video / BOP ``ycbv`` object id."""
    extents_m: tuple[float, float, float]
    """Bounding box of the YCB-Video model along x, y, z, metres (PoseCNN ``extents.txt``)."""
    diameter_m: float
    """Diameter of the YCB-Video model, metres (BOP ``models_eval``)."""
    mass_kg: float
    """Mass, kg (Calli et al. 2015)."""
    shape: str
    """Shape class and how it is approximated."""
    symmetry_kind: Literal["none", "continuous", "discrete"]
    """Kind of the shape's symmetry (the transforms are on the built object)."""
    rgba: tuple[float, float, float, float] = dataclasses.field(repr=False)
    """Colour of the visual geom."""
    _builder: Callable[[], _Geometry] = dataclasses.field(default=None, repr=False, compare=False)

    @property
    def alias(self) -> str:
        """Short name without the YCB number, e.g. ``tomato_soup_can``."""
        return self.name.split("_", 1)[1]

    def build(self, n_model_points: int = N_MODEL_POINTS, seed: int = 0) -> YCBObject:
        """Build the object (uncached; :func:`get_object` caches).

        Args:
            n_model_points: number of surface samples in ``model_points_m``.
            seed: seed of the surface sampling.

        Raises:
            InvalidObjectParams: if ``n_model_points`` or ``seed`` is invalid.
        """
        _check_sampling(n_model_points, seed)
        return self._finish(self._builder(), n_model_points, seed)

    def _finish(self, geom: _Geometry, n_model_points: int, seed: int) -> YCBObject:
        return _finalize(
            name=self.name,
            visual=geom.visual,
            pieces=geom.pieces,
            mass_kg=self.mass_kg,
            symmetry=geom.symmetry,
            rest_up=geom.rest_up,
            rgba=self.rgba,
            shape=self.shape,
            ycbv_id=self.ycbv_id,
            n_model_points=n_model_points,
            seed=seed,
            recenter=True,
            cavity=geom.cavity,
            depth_symmetry=geom.depth_symmetry,
        )


@dataclasses.dataclass
class _Geometry:
    visual: trimesh.Trimesh
    pieces: list[trimesh.Trimesh]
    rest_up: np.ndarray
    symmetry: Symmetry = NO_SYMMETRY
    cavity: np.ndarray | None = None
    depth_symmetry: Symmetry | None = None


def _finalize(
    *,
    name: str,
    visual: trimesh.Trimesh,
    pieces: Sequence[trimesh.Trimesh],
    mass_kg: float,
    symmetry: Symmetry,
    rest_up: np.ndarray,
    rgba: Sequence[float],
    shape: str,
    ycbv_id: int | None,
    n_model_points: int,
    seed: int,
    recenter: bool,
    mass_mesh: trimesh.Trimesh | None = None,
    cavity: np.ndarray | None = None,
    depth_symmetry: Symmetry | None = None,
) -> YCBObject:
    """Centre (optionally), then derive mass properties, samples, diameter, corners, rest pose."""
    visual = visual.copy()
    pieces = [p.copy() for p in pieces]
    if recenter:
        shift = -visual.bounds.mean(axis=0)
        visual.apply_translation(shift)
        for p in pieces:
            p.apply_translation(shift)
        symmetry = symmetry.moved(shift)
        if depth_symmetry is not None:
            depth_symmetry = depth_symmetry.moved(shift)
    else:
        shift = np.zeros(3)

    import trimesh

    # Uniform density scaled to the mass: trimesh's unit-density inertia times mass / volume.
    solid = visual if mass_mesh is None else mass_mesh.copy()
    if mass_mesh is not None:
        solid.apply_translation(shift)
    volume = float(solid.volume)
    com = np.asarray(solid.center_mass, dtype=np.float64)
    inertia = np.asarray(solid.moment_inertia, dtype=np.float64) * (mass_kg / volume)
    inertia = 0.5 * (inertia + inertia.T)

    points, _ = trimesh.sample.sample_surface(visual, n_model_points, seed=seed)
    points = np.asarray(points, dtype=np.float64)

    diameter = point_set_diameter(_hull_vertices(np.asarray(visual.vertices)))

    lo, hi = visual.bounds
    corners = np.array([[(lo, hi)[b][i] for i, b in enumerate(bits)] for bits in _CORNER_BITS])

    rest = _rotation_to_z(_stable_up(np.asarray(visual.vertices), com, np.asarray(rest_up)))
    rest_height = float(-(np.asarray(visual.vertices) @ rest.as_matrix().T)[:, 2].min())
    quat_xyzw = rest.as_quat()
    rest_quat = np.roll(quat_xyzw, 1)

    cavity_point = None if cavity is None else np.asarray(cavity, dtype=np.float64) + shift
    if cavity_point is not None:
        cavity_point.setflags(write=False)
    arrays = dict(
        com_m=com,
        inertia_kg_m2=inertia,
        model_points_m=points,
        extents_m=np.asarray(hi - lo, dtype=np.float64),
        corners_m=corners,
        rest_quat_wxyz=rest_quat,
    )
    for a in arrays.values():
        a.setflags(write=False)
    return YCBObject(
        name=name,
        visual_mesh=visual,
        collision_meshes=tuple(pieces),
        mass_kg=float(mass_kg),
        diameter_m=diameter,
        symmetry=symmetry,
        rest_height_m=rest_height,
        rgba=tuple(float(c) for c in rgba),
        shape=shape,
        ycbv_id=ycbv_id,
        cavity_point_m=cavity_point,
        depth_symmetry=depth_symmetry,
        **arrays,
    )


_CORNER_BITS = tuple(itertools.product((0, 1), repeat=3))


def _stable_up(
    points: np.ndarray, com: np.ndarray, hint: np.ndarray, margin: float = 1e-4
) -> np.ndarray:
    """The up direction (object frame) of the stable resting pose nearest to ``hint``.

    An object rests on a face of its convex hull (coplanar hull triangles merged) when its
    centre of mass projects inside that face; faces where it projects less than ``margin``
    metres from an edge (the thin facets of a round barrel) are only neutrally stable and are
    skipped. Among the others, take the face whose inward normal is closest to ``hint`` (if
    none qualifies, the face with the largest margin).
    """
    import trimesh

    hint = hint / np.linalg.norm(hint)
    hull = trimesh.convex.convex_hull(points)
    normals = np.asarray(hull.face_normals)
    faces = np.asarray(hull.faces)
    verts = np.asarray(hull.vertices)
    offsets = np.einsum("ij,ij->i", normals, verts[faces[:, 0]])
    keys = np.column_stack([np.round(normals * 1e4), np.round(offsets * 1e5)])
    _, group = np.unique(keys, axis=0, return_inverse=True)
    group = group.ravel()
    best_up, best_score, best_margin, fallback = None, -np.inf, -np.inf, hint
    # Which faces contain the projection of the centre of mass on their group's plane, for
    # all faces at once (a hull can have 10^4 faces); only those groups are looked at below.
    _, first = np.unique(group, return_index=True)
    n_face = normals[first][group]
    p_face = com - (np.einsum("ij,j->i", n_face, com) - offsets[first][group])[:, None] * n_face
    tri_all = verts[faces]
    inside_all = np.ones(len(faces), dtype=bool)
    for i in range(3):
        u, v = tri_all[:, i], tri_all[:, (i + 1) % 3]
        inside_all &= np.einsum("ij,ij->i", np.cross(v - u, p_face - u), n_face) >= -1e-12
    candidates = np.unique(group[inside_all])
    sizes = np.bincount(group)[candidates]
    margins = np.empty(len(candidates))
    # One-triangle faces (all of them on a finely tessellated round hull) at once.
    single = sizes == 1
    if single.any():
        tri_faces = faces[first[candidates[single]]]
        p = p_face[first[candidates[single]]]
        m = np.full(len(tri_faces), np.inf)
        for i in range(3):
            e = np.sort(np.stack([tri_faces[:, i], tri_faces[:, (i + 1) % 3]], axis=1), axis=1)
            a, b = verts[e[:, 0]], verts[e[:, 1]]
            t = np.clip(
                np.einsum("ij,ij->i", p - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1
            )
            m = np.minimum(m, np.linalg.norm(a + t[:, None] * (b - a) - p, axis=1))
        margins[single] = m
    for k in np.flatnonzero(~single):
        members = np.flatnonzero(group == candidates[k])
        n = normals[members[0]]
        p = com - (n @ com - offsets[members[0]]) * n
        # Distance from p to the boundary edges of the face (edges used by one triangle).
        edges = np.sort(
            np.concatenate(
                [faces[members][:, [0, 1]], faces[members][:, [1, 2]], faces[members][:, [2, 0]]]
            ),
            axis=1,
        )
        uniq, count = np.unique(edges, axis=0, return_counts=True)
        a, b = verts[uniq[count == 1, 0]], verts[uniq[count == 1, 1]]
        t = np.clip(np.einsum("ij,ij->i", p - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
        margins[k] = float(np.linalg.norm(a + t[:, None] * (b - a) - p, axis=1).min())
    up_normals = -normals[first[candidates]]
    scores = up_normals @ hint
    for k in range(len(candidates)):
        m = float(margins[k])
        if m > best_margin:
            best_margin, fallback = m, up_normals[k]
        score = float(scores[k])
        if m >= margin and score > best_score:
            best_up, best_score = up_normals[k], score
    return best_up if best_up is not None else fallback


def _rotation_to_z(up: np.ndarray) -> Rotation:
    """The smallest rotation taking the unit vector ``up`` to +z."""
    from scipy.spatial.transform import Rotation

    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s = np.linalg.norm(axis)
    c = float(np.dot(up, z))
    if s < 1e-12:
        return Rotation.identity() if c > 0 else Rotation.from_rotvec([np.pi, 0.0, 0.0])
    return Rotation.from_rotvec(axis / s * math.atan2(s, c))


def point_set_diameter(points: np.ndarray, leaf_size: int = 32) -> float:
    """Exact largest distance between two of the (N, 3) ``points``, in O(N) memory.

    Branch and bound: the points are split into boxes of at most ``leaf_size`` points (a k-d
    split on the longest axis); a pair of boxes is compared point by point only when the
    largest distance between the boxes can beat the best distance found so far (started from
    the extreme points along 13 axes). The result is a distance between two input points, so
    it is exact, not an estimate; memory stays O(N) (no N x N distance matrix).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(pts)
    if n < 2:
        return 0.0
    if n <= 8 * leaf_size:
        return _max_cross_distance(pts, pts)
    dirs = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if any(d)], float)
    proj = pts @ dirs.T
    extreme = pts[np.unique(np.argmax(proj, axis=0))]
    best = _max_cross_distance(extreme, extreme)
    # A point farther than `best` from some point lies beyond best - R of the centre.
    center = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    radius = np.linalg.norm(pts - center, axis=1)
    pts = pts[radius + radius.max() >= best]
    n = len(pts)
    if n <= 8 * leaf_size:
        return max(best, _max_cross_distance(pts, pts))

    leaves: list[np.ndarray] = []
    stack = [np.arange(n)]
    while stack:
        idx = stack.pop()
        if len(idx) <= leaf_size:
            leaves.append(idx)
            continue
        sub = pts[idx]
        axis = int(np.argmax(np.ptp(sub, axis=0)))
        half = len(idx) // 2
        order = np.argpartition(sub[:, axis], half)
        stack += [idx[order[:half]], idx[order[half:]]]
    m = len(leaves)
    # Leaves padded to leaf_size by repeating a point (a repeat does not change a maximum).
    padded = np.empty((m, leaf_size, 3))
    for k, idx in enumerate(leaves):
        padded[k] = pts[np.resize(idx, leaf_size)]
    lo, hi = padded.min(axis=1), padded.max(axis=1)
    chunk = max(1, 2_000_000 // m)
    pairs_a, pairs_b, bounds = [], [], []
    for start in range(0, m, chunk):
        a = np.arange(start, min(m, start + chunk))
        # Largest distance between two axis-aligned boxes (an upper bound for their points).
        gap = np.maximum(np.abs(hi[a, None] - lo[None]), np.abs(hi[None] - lo[a, None]))
        ub = np.sqrt(np.einsum("ijk,ijk->ij", gap, gap))
        ia, ib = np.nonzero((ub > best) & (a[:, None] <= np.arange(m)[None]))
        pairs_a.append(a[ia])
        pairs_b.append(ib)
        bounds.append(ub[ia, ib])
    pa, pb, ub = (np.concatenate(x) for x in (pairs_a, pairs_b, bounds))
    order = np.argsort(-ub)
    pa, pb, ub = pa[order], pb[order], ub[order]
    batch = max(1, 1_000_000 // (leaf_size * leaf_size))
    start = 0
    while start < len(ub) and ub[start] > best:
        stop = start + batch
        sel = slice(start, stop)
        keep = ub[sel] > best
        d = padded[pa[sel][keep]][:, :, None, :] - padded[pb[sel][keep]][:, None, :, :]
        best = max(best, math.sqrt(float(np.einsum("ijkl,ijkl->ijk", d, d).max())))
        start = stop
    return float(best)


def _max_cross_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance between a point of ``a`` (N, 3) and one of ``b`` (M, 3), chunked."""
    best = 0.0
    step = max(1, 1_000_000 // max(len(b), 1))
    for start in range(0, len(a), step):
        d = a[start : start + step, None, :] - b[None, :, :]
        best = max(best, float(np.einsum("ijk,ijk->ij", d, d).max()))
    return math.sqrt(best)


def _hull_vertices(points: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of (N, 3) points (all points if the hull is degenerate)."""
    from scipy.spatial import ConvexHull

    try:
        return points[ConvexHull(points).vertices]
    except Exception:  # noqa: BLE001 - qhull fails on flat or tiny point sets
        return points


# Validation helpers ---------------------------------------------------------------------------


def _check_rgba(rgba: Sequence[float]) -> tuple[float, float, float, float]:
    try:
        arr = to_real_array(rgba)
    except ValueError:
        arr = np.full(4, np.nan)
    if arr.shape != (4,) or not np.all((arr >= 0) & (arr <= 1)):
        raise InvalidObjectParams(f"rgba must be 4 numbers in [0, 1], got {rgba!r}")
    return tuple(float(c) for c in arr)


def _reals(value: object) -> np.ndarray:
    """``value`` as float64, or an array of NaN (refused by the caller) for non-real input."""
    try:
        return to_real_array(value)
    except ValueError:
        return np.full(1, np.nan)


def _check_sampling(n_model_points: int, seed: int) -> None:
    if isinstance(n_model_points, bool) or not isinstance(n_model_points, (int, np.integer)):
        raise InvalidObjectParams(f"n_model_points must be an int >= 1, got {n_model_points!r}")
    if n_model_points < 1:
        raise InvalidObjectParams(f"n_model_points must be >= 1, got {n_model_points}")
    if n_model_points > 1_000_000:
        raise InvalidObjectParams(f"n_model_points must be <= 1000000, got {n_model_points}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**63:
        raise InvalidObjectParams(f"seed must be a non-negative int, got {seed!r}")


# MuJoCo -----------------------------------------------------------------------------------------


def add_object(
    spec: mujoco.MjSpec,
    obj: YCBObject,
    *,
    pos: Sequence[float] = (0.0, 0.0, 0.0),
    quat_wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    body_name: str | None = None,
    parent: mujoco.MjsBody | None = None,
    free_joint: bool = True,
    rgba: Sequence[float] | None = None,
    friction: Sequence[float] = _FRICTION,
) -> mujoco.MjsBody:
    """Add ``obj`` as a body to ``spec`` (names in the module docstring); return the body.

    The body frame is the object frame, placed at ``pos`` / ``quat_wxyz`` in ``parent``
    (``T_parent_from_obj``; use ``obj.rest_quat_wxyz`` and ``obj.rest_height_m`` to set it on
    a table). Mass, centre of mass and full inertia are set explicitly; the visual mesh is a
    geom in group 2 that does not collide; each convex piece is a mesh geom in group 3.

    Args:
        spec: the model to add to.
        obj: a built-in (:func:`get_object`) or imported (:func:`load_object`) object.
        pos: (3,) position in the parent frame, metres.
        quat_wxyz: (4,) orientation in the parent frame (normalized here).
        body_name: body name (default ``obj_<name>``); other names derive from it.
        parent: parent body (default the world body).
        free_joint: add a free joint ``<body_name>_root`` (else the object is fixed).
        rgba: visual colour (default ``obj.rgba``).
        friction: (3,) sliding, torsional, rolling friction of the collision geoms.

    Raises:
        InvalidObjectParams: a name already in ``spec``, a bad body name, a non-finite pose.
    """
    if not isinstance(spec, mujoco.MjSpec) or not isinstance(obj, YCBObject):
        raise InvalidObjectParams(
            f"add_object needs a mujoco.MjSpec and a YCBObject; received "
            f"{type(spec).__name__}, {type(obj).__name__}"
        )
    name = obj.body_name if body_name is None else body_name
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise InvalidObjectParams(
            f"body_name must use only letters, digits and underscores, got {name!r}"
        )
    position = _reals(pos)
    quat = _reals(quat_wxyz)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise InvalidObjectParams(f"pos must be 3 finite numbers (m), got {pos!r}")
    if quat.shape != (4,) or not np.all(np.isfinite(quat)) or np.linalg.norm(quat) < 1e-9:
        raise InvalidObjectParams(
            f"quat_wxyz must be 4 finite numbers, not all 0, got {quat_wxyz!r}"
        )
    fric = _reals(friction)
    if fric.shape != (3,) or not np.all(np.isfinite(fric)) or np.any(fric < 0):
        raise InvalidObjectParams(f"friction must be 3 non-negative numbers, got {friction!r}")
    color = obj.rgba if rgba is None else _check_rgba(rgba)
    visual_name = f"{name}_visual"
    collision_names = [f"{name}_collision_{k}" for k in range(len(obj.collision_meshes))]
    if spec.body(name) is not None or any(
        spec.mesh(n) is not None for n in [visual_name, *collision_names]
    ):
        raise InvalidObjectParams(
            f"the spec already has a body or mesh named {name!r}; pass another body_name "
            f"(e.g. {name + '_1'!r}) to add a second copy"
        )

    body = (spec.worldbody if parent is None else parent).add_body(
        name=name, pos=position, quat=quat / np.linalg.norm(quat)
    )
    if free_joint:
        body.add_freejoint(name=f"{name}_root")
    i = obj.inertia_kg_m2
    body.mass = obj.mass_kg
    body.ipos = obj.com_m
    body.fullinertia = [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]
    body.explicitinertial = True

    # The convex-hull inertia mode never fails (a user's visual mesh may be open); the body's
    # inertial is explicit, so geom masses only matter with inertiafromgeom="true".
    spec.add_mesh(
        name=visual_name,
        uservert=np.asarray(obj.visual_mesh.vertices, dtype=np.float64).ravel(),
        userface=np.asarray(obj.visual_mesh.faces, dtype=np.int32).ravel(),
        inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX,
    )
    body.add_geom(
        name=visual_name,
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=visual_name,
        group=VISUAL_GROUP,
        contype=0,
        conaffinity=0,
        density=0.0,
        rgba=color,
    )
    volume = sum(float(p.volume) for p in obj.collision_meshes)
    density = obj.mass_kg / volume
    for piece, piece_name in zip(obj.collision_meshes, collision_names, strict=True):
        spec.add_mesh(
            name=piece_name,
            uservert=np.asarray(piece.vertices, dtype=np.float64).ravel(),
            userface=np.asarray(piece.faces, dtype=np.int32).ravel(),
        )
        body.add_geom(
            name=piece_name,
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=piece_name,
            group=COLLISION_GROUP,
            density=density,
            friction=fric,
            rgba=(0.5, 0.5, 0.5, 0.4),
        )
    return body
