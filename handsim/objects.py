"""The 21 YCB-Video objects as simulation objects, and import of user meshes.

Every object is a frozen :class:`YCBObject`: a watertight visual mesh, convex collision pieces,
mass and inertia, model points for ADD/ADI, the diameter, the 8 bounding-box corners, the
symmetries and a stable resting pose, all in SI units (metres, kilograms) in the object frame.
The registry :data:`OBJECTS` holds one :class:`ObjectSpec` (facts + recipe) per YCB-Video
object; :func:`get_object` builds (and caches) an object by name, :func:`load_object` imports
a user mesh (OBJ/PLY/STL/GLB, e.g. the real YCB models) into the same type, and
:func:`add_object` puts any object into a ``mujoco.MjSpec``.

Conventions:

- Object frame: the model axes of the YCB-Video ``textured_simple.obj`` models (facts table
  5.1: cans and bottles have their axis along ``y``), origin at the centre of the axis-aligned
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

How the shapes are made (sizes in ``_FACTS`` and next to each builder):

==============================  =========================================================
object                          shape
==============================  =========================================================
cans (002, 005, 007)            cylinder along ``y``, end chamfer sized to the diameter
boxes (003, 004, 008, 009, 036, box of the nominal (Calli) size, tilted 1-12 degrees in the
061), potted meat can (010)     model frame; 010 has rounded edges (see ``_BOXES``)
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

Meshing: single-piece shapes are lofts of elliptic rings (exact, 0.4-5k faces); the vessels
are a loft of the shell plus a tube whose end rings are slid onto the wall and stitched into
windows cut in it (one closed genus-1 surface, no boolean operations). The drill, scissors,
marker and clamps are signed-distance unions (rounded edges, filleted joints) meshed by
marching tetrahedra on a rectilinear grid (closed 2-manifold by construction), then
decimated by edge collapses that stay on the surface (0.15 mm) and keep it a manifold
(2-12k faces). Collision pieces are convex hulls of the same primitives, so hollow objects
stay hollow to the fingers. Building all 21 objects takes ~6 s; :func:`get_object` caches.

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
collision geoms / meshes ``obj_<name>_collision_<k>``         group 3, k = 0, 1, ...
=======================  ===================================  ================================

A second copy of an object in one scene takes another body name (``body_name=``); every
other name is derived from the body name.

Dependencies: trimesh, scipy, MuJoCo; CoACD (``pip install coacd``, optional, imported by
:func:`load_object` only) for the convex decomposition of imported meshes.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import itertools
import math
import os
import re
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import mujoco
import numpy as np
import scipy.sparse as sp
import trimesh
from scipy.spatial.distance import pdist
from scipy.spatial.transform import Rotation

from handsim.errors import HandSimError, UnknownName

__all__ = [
    "InvalidMesh",
    "InvalidObjectParams",
    "MeshImportWarning",
    "Symmetry",
    "NO_SYMMETRY",
    "YCBObject",
    "ObjectSpec",
    "ObjectRegistry",
    "OBJECTS",
    "OBJECT_NAMES",
    "Decomposition",
    "get_object",
    "load_object",
    "add_object",
    "MESH_FORMATS",
    "SIZE_RANGE_M",
    "N_MODEL_POINTS",
    "VISUAL_GROUP",
    "COLLISION_GROUP",
]


class InvalidMesh(HandSimError, ValueError):
    """A mesh is empty, non-finite, of an absurd size or in an unsupported format."""


class InvalidObjectParams(HandSimError, ValueError):
    """An object parameter (mass, scale, name, option) is invalid."""


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


# Symmetries ----------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class Symmetry:
    """The symmetries of an object's shape, in the object frame (BOP ``models_info`` style).

    Args:
        kind: ``"none"``, ``"continuous"`` (rotation by any angle about ``axis``) or
            ``"discrete"`` (the rigid transforms in ``discrete``).
        axis: unit axis of a continuous symmetry, object frame; ``None`` otherwise.
        offset_m: a point on the continuous axis, metres, object frame.
        discrete: (K, 4, 4) float64 rigid transforms (object frame to itself, metres), the
            group elements other than the identity; (0, 4, 4) unless ``kind == "discrete"``.
    """

    kind: Literal["none", "continuous", "discrete"] = "none"
    """``none``, ``continuous`` or ``discrete``."""
    axis: tuple[float, float, float] | None = None
    """Unit axis of a continuous symmetry (object frame), else ``None``."""
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """A point on the continuous axis, metres."""
    discrete: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 4, 4)))
    """(K, 4, 4) non-identity symmetry transforms, metres."""

    def __post_init__(self) -> None:
        kinds = ("none", "continuous", "discrete")
        if self.kind not in kinds:
            raise InvalidObjectParams(f"symmetry kind must be one of {kinds}, got {self.kind!r}")
        discrete = np.asarray(self.discrete, dtype=np.float64)
        if discrete.size % 16 or (discrete.ndim != 3 and discrete.size):
            raise InvalidObjectParams(
                f"discrete must be a (K, 4, 4) array of transforms, got shape {discrete.shape}"
            )
        discrete = discrete.reshape(-1, 4, 4).copy()
        offset = np.asarray(self.offset_m, dtype=np.float64)
        if offset.shape != (3,) or not np.all(np.isfinite(offset)):
            raise InvalidObjectParams(f"offset_m must be 3 finite numbers, got {self.offset_m!r}")
        if self.kind == "continuous":
            axis = np.asarray(self.axis if self.axis is not None else (), dtype=np.float64)
            if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0:
                raise InvalidObjectParams(
                    f"a continuous symmetry needs a finite non-zero 3-vector axis, got "
                    f"{self.axis!r}"
                )
            object.__setattr__(self, "axis", tuple(float(a) for a in axis / np.linalg.norm(axis)))
        elif self.axis is not None:
            raise InvalidObjectParams(f"axis is only for kind='continuous', got kind={self.kind!r}")
        if self.kind == "discrete" and len(discrete) == 0:
            raise InvalidObjectParams("a discrete symmetry needs at least one (4, 4) transform")
        if self.kind != "discrete" and len(discrete) > 0:
            raise InvalidObjectParams(f"discrete transforms given with kind={self.kind!r}")
        for t in discrete:
            r = t[:3, :3]
            if not (
                np.allclose(r @ r.T, np.eye(3), atol=1e-6)
                and np.isclose(np.linalg.det(r), 1.0, atol=1e-6)
                and np.allclose(t[3], (0, 0, 0, 1))
            ):
                raise InvalidObjectParams(f"a symmetry transform is not a rigid motion:\n{t}")
        discrete.setflags(write=False)
        object.__setattr__(self, "discrete", discrete)
        object.__setattr__(self, "offset_m", tuple(float(v) for v in offset))

    @classmethod
    def continuous(
        cls, axis: Sequence[float], offset_m: Sequence[float] = (0.0, 0.0, 0.0)
    ) -> Symmetry:
        """Rotation by any angle about ``axis`` through ``offset_m`` (object frame, metres)."""
        return cls(kind="continuous", axis=tuple(axis), offset_m=tuple(offset_m))

    @classmethod
    def from_rotations(
        cls, generators: Sequence[np.ndarray], center_m: Sequence[float] = (0.0, 0.0, 0.0)
    ) -> Symmetry:
        """The finite group generated by rotations about ``center_m``.

        Args:
            generators: 3x3 rotation matrices (object frame).
            center_m: (3,) fixed point of the rotations, metres.
        """
        group = _close_group([np.asarray(g, dtype=np.float64) for g in generators])
        center = np.asarray(center_m, dtype=np.float64)
        out = []
        for r in group:
            if np.allclose(r, np.eye(3), atol=1e-9):
                continue
            t = np.eye(4)
            t[:3, :3] = r
            t[:3, 3] = center - r @ center
            out.append(t)
        return cls(kind="discrete", discrete=np.array(out))

    def __repr__(self) -> str:
        if self.kind == "continuous":
            return f"Symmetry(continuous, axis={self.axis}, offset_m={self.offset_m})"
        if self.kind == "discrete":
            return f"Symmetry(discrete, {len(self.discrete)} non-identity transforms)"
        return "Symmetry(none)"

    def transforms(self, n_continuous: int = 36) -> np.ndarray:
        """All symmetry transforms, the identity first (BOP ``get_symmetry_transformations``).

        Args:
            n_continuous: number of rotation steps a continuous symmetry is discretized into.

        Returns:
            (M, 4, 4) float64 rigid transforms, metres; ``M = 1`` without symmetry,
            ``K + 1`` for a discrete one, ``n_continuous`` for a continuous one.
        """
        if self.kind == "continuous":
            if n_continuous < 1:
                raise InvalidObjectParams(f"n_continuous must be >= 1, got {n_continuous}")
            axis = np.asarray(self.axis)
            offset = np.asarray(self.offset_m)
            out = np.tile(np.eye(4), (n_continuous, 1, 1))
            for i in range(n_continuous):
                r = Rotation.from_rotvec(axis * (2.0 * np.pi * i / n_continuous)).as_matrix()
                out[i, :3, :3] = r
                out[i, :3, 3] = offset - r @ offset
            return out
        return np.concatenate([np.eye(4)[None], self.discrete])

    def moved(self, translation_m: np.ndarray) -> Symmetry:
        """The same symmetry after the object is translated by ``translation_m`` (3,), metres."""
        shift = np.eye(4)
        shift[:3, 3] = translation_m
        if self.kind == "continuous":
            return Symmetry.continuous(self.axis, np.asarray(self.offset_m) + translation_m)
        if self.kind == "discrete":
            inv = np.linalg.inv(shift)
            return Symmetry(
                kind="discrete", discrete=np.array([shift @ t @ inv for t in self.discrete])
            )
        return self

    def to_bop(self) -> dict[str, list]:
        """The BOP ``models_info`` entries (millimetres, flattened row-major 4x4 transforms)."""
        info: dict[str, list] = {}
        if self.kind == "continuous":
            info["symmetries_continuous"] = [
                {"axis": list(self.axis), "offset": [v / _MM for v in self.offset_m]}
            ]
        elif self.kind == "discrete":
            flat = []
            for t in self.discrete:
                t_mm = t.copy()
                t_mm[:3, 3] /= _MM
                flat.append([float(v) for v in t_mm.ravel()])
            info["symmetries_discrete"] = flat
        return info


NO_SYMMETRY = Symmetry()
"""An object without symmetries."""


def _close_group(generators: list[np.ndarray]) -> list[np.ndarray]:
    group = [np.eye(3)]
    frontier = [np.eye(3)]
    while frontier:
        new = []
        for a in frontier:
            for g in generators:
                c = g @ a
                if not any(np.allclose(c, b, atol=1e-9) for b in group):
                    group.append(c)
                    new.append(c)
        frontier = new
        if len(group) > 120:
            raise InvalidObjectParams("symmetry generators do not form a finite group")
    return group


def _rot(axis: str, deg: float) -> np.ndarray:
    return Rotation.from_euler(axis, deg, degrees=True).as_matrix()


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
    """A registered YCB-Video object: facts (facts table 5.1) and the recipe of its shape.

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
        )


@dataclasses.dataclass
class _Geometry:
    visual: trimesh.Trimesh
    pieces: list[trimesh.Trimesh]
    rest_up: np.ndarray
    symmetry: Symmetry = NO_SYMMETRY
    cavity: np.ndarray | None = None


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
    else:
        shift = np.zeros(3)

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

    hull_vertices = _hull_vertices(np.asarray(visual.vertices))
    diameter = float(pdist(hull_vertices).max()) if len(hull_vertices) > 1 else 0.0

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
    for g in range(group.max() + 1):
        members = np.flatnonzero(group == g)
        n = normals[members[0]]
        p = com - (n @ com - offsets[members[0]]) * n
        tri = verts[faces[members]]
        inside = np.ones(len(members), dtype=bool)
        for i in range(3):
            u, v = tri[:, i], tri[:, (i + 1) % 3]
            inside &= np.einsum("ij,j->i", np.cross(v - u, p - u), n) >= -1e-12
        if not inside.any():
            continue
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
        m = float(np.linalg.norm(a + t[:, None] * (b - a) - p, axis=1).min())
        if m > best_margin:
            best_margin, fallback = m, -n
        score = float(-n @ hint)
        if m >= margin and score > best_score:
            best_up, best_score = -n, score
    return best_up if best_up is not None else fallback


def _rotation_to_z(up: np.ndarray) -> Rotation:
    """The smallest rotation taking the unit vector ``up`` to +z."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s = np.linalg.norm(axis)
    c = float(np.dot(up, z))
    if s < 1e-12:
        return Rotation.identity() if c > 0 else Rotation.from_rotvec([np.pi, 0.0, 0.0])
    return Rotation.from_rotvec(axis / s * math.atan2(s, c))


def _hull_vertices(points: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of (N, 3) points (all points if the hull is degenerate)."""
    try:
        return np.asarray(trimesh.convex.convex_hull(points).vertices)
    except Exception:  # noqa: BLE001 - qhull fails on flat or tiny point sets
        return points


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
    j = np.arange(n_around)
    jn = (j + 1) % n_around
    faces = [np.stack([np.zeros(n_around, dtype=np.int64), 1 + jn, 1 + j], axis=1)]
    for r in range(n_rings - 1):
        a = 1 + r * n_around
        b = a + n_around
        faces.append(np.stack([a + j, a + jn, b + jn], axis=1))
        faces.append(np.stack([a + j, b + jn, b + j], axis=1))
    last = 1 + n_rings * n_around
    a = 1 + (n_rings - 1) * n_around
    faces.append(np.stack([np.full(n_around, last), a + j, a + jn], axis=1))
    mesh = trimesh.Trimesh(vertices, np.concatenate(faces), process=False)
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
    hull = trimesh.convex.convex_hull(np.asarray(points, dtype=np.float64))
    if hull.volume < 0:
        hull.invert()
    return hull


_SPHERE_DIRS = np.asarray(trimesh.creation.icosphere(subdivisions=2).vertices)


def _spheres(centers: np.ndarray, radii: np.ndarray | float) -> np.ndarray:
    centers = np.atleast_2d(np.asarray(centers, dtype=np.float64))
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(centers),))
    return (centers[:, None, :] + radii[:, None, None] * _SPHERE_DIRS[None]).reshape(-1, 3)


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


# Shapes ---------------------------------------------------------------------------------------


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
    if four_fold_axis is not None:
        others = [i for i in range(3) if i != four_fold_axis]
        gens = [_rot("xyz"[four_fold_axis], 90.0)] + [_rot("xyz"[i], 180.0) for i in others]
        symmetry = Symmetry.from_rotations([rot @ g @ rot.T for g in gens])
    return _Geometry(mesh, [mesh.copy()], rest_up=up, symmetry=symmetry)


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
    """Cordless drill lying on its side: barrel (x), chuck at +x, grip and battery below."""
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
    return _Geometry(mesh, pieces, rest_up=np.array([0.0, 0.0, 1.0]))


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


# Registry -------------------------------------------------------------------------------------

# (YCB-V id, name, extents x, y, z in mm, diameter mm, mass g): facts table 5.1.
_FACTS: tuple[tuple[int, str, tuple[float, float, float], float, float], ...] = (
    (1, "002_master_chef_can", (103, 140, 103), 172.2, 414),
    (2, "003_cracker_box", (164, 215, 72), 269.6, 411),
    (3, "004_sugar_box", (95, 177, 50), 198.4, 514),
    (4, "005_tomato_soup_can", (68, 102, 68), 120.7, 349),
    (5, "006_mustard_bottle", (97, 192, 59), 199.8, 603),
    (6, "007_tuna_fish_can", (86, 34, 86), 90.2, 171),
    (7, "008_pudding_box", (114, 90, 39), 142.6, 187),
    (8, "009_gelatin_box", (94, 78, 45), 114.4, 97),
    (9, "010_potted_meat_can", (102, 84, 58), 129.7, 370),
    (10, "011_banana", (179, 38, 109), 198.4, 66),
    (11, "019_pitcher_base", (189, 249, 133), 263.6, 178),
    (12, "021_bleach_cleanser", (103, 251, 68), 260.8, 1131),
    (13, "024_bowl", (161, 55, 161), 162.3, 147),
    (14, "025_mug", (120, 81, 94), 126.9, 118),
    (15, "035_power_drill", (184, 188, 58), 230.4, 895),
    (16, "036_wood_block", (90, 206, 91), 237.3, 729),
    (17, "037_scissors", (202, 98, 16), 204.1, 82),
    (18, "040_large_marker", (19, 121, 21), 121.5, 15.8),
    (19, "051_large_clamp", (173, 120, 39), 183.1, 125),
    (20, "052_extra_large_clamp", (210, 164, 52), 231.4, 202),
    (21, "061_foam_brick", (78, 51, 53), 102.9, 28),
)


def _with_symmetry(build: Callable[[], _Geometry], symmetry: Symmetry) -> Callable[[], _Geometry]:
    def wrapped() -> _Geometry:
        geom = build()
        geom.symmetry = symmetry
        return geom

    return wrapped


_Y_AXIS = Symmetry.continuous((0.0, 1.0, 0.0))

# name: (builder, shape description, rgba)
_RECIPES: dict[str, tuple[Callable[[], _Geometry], str, tuple[float, float, float, float]]] = {
    "002_master_chef_can": (
        _with_symmetry(functools.partial(_can, 51.5, 140.0, 172.2), _Y_AXIS),
        "cylinder r 51.5 mm along y, chamfered ends",
        (0.15, 0.3, 0.65, 1.0),
    ),
    "003_cracker_box": (
        functools.partial(_box, "003_cracker_box"),
        _box_shape("003_cracker_box"),
        (0.8, 0.15, 0.1, 1.0),
    ),
    "004_sugar_box": (
        functools.partial(_box, "004_sugar_box"),
        _box_shape("004_sugar_box"),
        (0.95, 0.9, 0.6, 1.0),
    ),
    "005_tomato_soup_can": (
        functools.partial(_can, 34.0, 102.0, 120.7),
        "cylinder r 34 mm along y, chamfered ends",
        (0.75, 0.1, 0.1, 1.0),
    ),
    "006_mustard_bottle": (
        _mustard_bottle,
        "lofted bottle: elliptic body, neck, cap",
        (0.95, 0.8, 0.1, 1.0),
    ),
    "007_tuna_fish_can": (
        functools.partial(_can, 43.0, 34.0, 90.2),
        "cylinder r 43 mm along y, chamfered ends",
        (0.55, 0.6, 0.7, 1.0),
    ),
    "008_pudding_box": (
        functools.partial(_box, "008_pudding_box"),
        _box_shape("008_pudding_box"),
        (0.5, 0.3, 0.15, 1.0),
    ),
    "009_gelatin_box": (
        functools.partial(_box, "009_gelatin_box"),
        _box_shape("009_gelatin_box"),
        (0.85, 0.2, 0.3, 1.0),
    ),
    "010_potted_meat_can": (
        functools.partial(_box, "010_potted_meat_can"),
        "rounded box 98 x 83 x 50 mm (r 6), tilted 5 deg",
        (0.2, 0.3, 0.7, 1.0),
    ),
    "011_banana": (
        functools.partial(_banana),
        "tapered tube along an arc; capsule chain",
        (0.95, 0.85, 0.3, 1.0),
    ),
    "019_pitcher_base": (_pitcher, "revolved open shell + handle", (0.2, 0.45, 0.8, 1.0)),
    "021_bleach_cleanser": (
        _bleach_cleanser,
        "lofted bottle: elliptic body, off-axis cap",
        (0.92, 0.92, 0.9, 1.0),
    ),
    "024_bowl": (_bowl, "revolved open shell on a flat foot", (0.8, 0.15, 0.15, 1.0)),
    "025_mug": (_mug, "revolved open shell + C handle", (0.75, 0.15, 0.12, 1.0)),
    "035_power_drill": (_power_drill, "barrel + chuck + grip + battery", (0.9, 0.75, 0.1, 1.0)),
    "036_wood_block": (
        functools.partial(_box, "036_wood_block", four_fold_axis=1),
        _box_shape("036_wood_block"),
        (0.75, 0.6, 0.4, 1.0),
    ),
    "037_scissors": (_scissors, "blade plates + handle loops", (0.2, 0.4, 0.8, 1.0)),
    "040_large_marker": (
        _marker,
        "cylinder r 9.5 mm along y + conical tip + cap clip",
        (0.1, 0.1, 0.1, 1.0),
    ),
    "051_large_clamp": (
        functools.partial(_clamp, 173.0, 120.0, 39.0),
        "two mirrored levers + spring pivot",
        (0.95, 0.5, 0.1, 1.0),
    ),
    "052_extra_large_clamp": (
        functools.partial(_clamp, 210.0, 164.0, 52.0),
        "two mirrored levers + spring pivot",
        (0.95, 0.45, 0.05, 1.0),
    ),
    "061_foam_brick": (
        functools.partial(_box, "061_foam_brick", four_fold_axis=0),
        _box_shape("061_foam_brick"),
        (0.8, 0.2, 0.15, 1.0),
    ),
}


_SYMMETRY_KINDS = {
    "002_master_chef_can": "continuous",
    "024_bowl": "continuous",
    "036_wood_block": "discrete",
    "040_large_marker": "continuous",
    "051_large_clamp": "discrete",
    "052_extra_large_clamp": "discrete",
    "061_foam_brick": "discrete",
}


class ObjectRegistry(Mapping[str, ObjectSpec]):
    """The registered objects by canonical name (``005_tomato_soup_can``), in YCB-V id order.

    Look-ups also accept the short alias (``tomato_soup_can``) and the MJCF body name
    (``obj_005_tomato_soup_can``); iteration yields each canonical name once. An unknown name
    raises :class:`~handsim.errors.UnknownName` listing the valid names.
    """

    def __init__(self, specs: Sequence[ObjectSpec]) -> None:
        self._specs = {s.name: s for s in specs}
        self._aliases = {s.alias: s.name for s in specs}

    def canonical(self, name: str) -> str:
        """The canonical name of ``name`` (canonical, alias or ``obj_`` body name).

        Raises:
            UnknownName: if no object has that name.
        """
        if isinstance(name, str):
            key = name[4:] if name.startswith("obj_") else name
            if key in self._specs:
                return key
            if key in self._aliases:
                return self._aliases[key]
        known = list(self._specs) + list(self._aliases)
        close = difflib.get_close_matches(str(name), known, n=3)
        hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise UnknownName(
            f"unknown object {name!r}.{hint} Valid names: {', '.join(self._specs)} "
            f"(each also without its number, e.g. 'tomato_soup_can')."
        )

    def __getitem__(self, name: str) -> ObjectSpec:
        return self._specs[self.canonical(name)]

    def __contains__(self, name: object) -> bool:
        try:
            self.canonical(name)  # type: ignore[arg-type]
        except UnknownName:
            return False
        return True

    def __iter__(self) -> Iterator[str]:
        return iter(self._specs)

    def __len__(self) -> int:
        return len(self._specs)

    def __repr__(self) -> str:
        return f"ObjectRegistry({list(self._specs)})"


OBJECTS = ObjectRegistry(
    [
        ObjectSpec(
            name=name,
            ycbv_id=ycbv_id,
            extents_m=tuple(e / 1000 for e in extents_mm),
            diameter_m=diameter_mm / 1000,
            mass_kg=mass_g / 1000,
            shape=_RECIPES[name][1],
            symmetry_kind=_SYMMETRY_KINDS.get(name, "none"),
            rgba=_RECIPES[name][2],
            _builder=_RECIPES[name][0],
        )
        for ycbv_id, name, extents_mm, diameter_mm, mass_g in _FACTS
    ]
)
"""The 21 YCB-Video objects (:class:`ObjectRegistry` of :class:`ObjectSpec`)."""

OBJECT_NAMES: tuple[str, ...] = tuple(OBJECTS)
"""Canonical names of the registered objects, in YCB-Video id order."""


def _check_sampling(n_model_points: int, seed: int) -> None:
    if isinstance(n_model_points, bool) or not isinstance(n_model_points, (int, np.integer)):
        raise InvalidObjectParams(f"n_model_points must be an int >= 1, got {n_model_points!r}")
    if n_model_points < 1:
        raise InvalidObjectParams(f"n_model_points must be >= 1, got {n_model_points}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InvalidObjectParams(f"seed must be a non-negative int, got {seed!r}")


def get_object(name: str, *, n_model_points: int = N_MODEL_POINTS, seed: int = 0) -> YCBObject:
    """A built-in object by name (canonical, short alias or ``obj_`` body name); cached.

    Args:
        name: e.g. ``"005_tomato_soup_can"`` or ``"tomato_soup_can"``.
        n_model_points: number of surface samples in ``model_points_m``.
        seed: seed of the surface sampling.

    Raises:
        UnknownName: if ``name`` is not registered (the message lists the valid names).
        InvalidObjectParams: if ``n_model_points`` or ``seed`` is invalid.
    """
    canonical = OBJECTS.canonical(name)
    _check_sampling(n_model_points, seed)
    return _build_cached(canonical, int(n_model_points), int(seed))


@functools.lru_cache(maxsize=64)
def _build_cached(name: str, n_model_points: int, seed: int) -> YCBObject:
    return OBJECTS[name]._finish(_geometry_cached(name), n_model_points, seed)


@functools.cache
def _geometry_cached(name: str) -> _Geometry:
    # The meshes are copied by _finalize, so one geometry serves every sampling.
    return OBJECTS[name]._builder()


# Import of user meshes -------------------------------------------------------------------------

Decomposition = Literal["auto", "coacd", "convex_hull"]
_DECOMPOSITIONS = ("auto", "coacd", "convex_hull")


def load_object(
    path: str | os.PathLike[str],
    *,
    name: str,
    mass_kg: float,
    scale: float = 1.0,
    symmetry: Symmetry = NO_SYMMETRY,
    decomposition: Decomposition = "auto",
    coacd_threshold: float = 0.05,
    recenter: bool = False,
    rest_up: Sequence[float] = (0.0, 0.0, 1.0),
    rgba: Sequence[float] = (0.7, 0.7, 0.7, 1.0),
    n_model_points: int = N_MODEL_POINTS,
    seed: int = 0,
) -> YCBObject:
    """Import a mesh file (OBJ/PLY/STL/GLB) as an object usable like a built-in one.

    The mesh keeps its own frame unless ``recenter`` (so the real YCB-Video models keep the
    frame their poses are given in). Collision pieces come from CoACD (``pip install coacd``)
    when available, else from the convex hull with a :class:`MeshImportWarning` (concave parts
    such as a mug's cavity are then filled). Mass properties assume uniform density; a mesh
    that is not watertight (even after filling holes) gets them from its convex hull, with a
    warning.

    Args:
        path: mesh file; a GLB scene is flattened with its node transforms.
        name: object name, letters, digits and underscores (MJCF names are ``obj_<name>...``).
        mass_kg: mass, kg (> 0).
        scale: factor from file units to metres (``0.001`` for a file in millimetres).
        symmetry: symmetries of the shape, in the frame after scaling (and recentring).
        decomposition: ``"auto"`` (CoACD if installed, else convex hull with a warning),
            ``"coacd"`` (required) or ``"convex_hull"`` (one piece, no warning).
        coacd_threshold: CoACD concavity threshold in (0, 1]; smaller gives more pieces.
        recenter: move the origin to the bounding-box centre (as the built-in objects).
        rest_up: object-frame axis that points up when the object rests on a plane.
        rgba: colour of the visual geom.
        n_model_points: number of surface samples in ``model_points_m``.
        seed: seed of the surface sampling and of CoACD.

    Raises:
        InvalidMesh: missing or unreadable file, unsupported format, empty mesh, non-finite
            vertices, a largest extent outside :data:`SIZE_RANGE_M` after scaling, or a flat
            mesh.
        InvalidObjectParams: invalid name, mass, scale, decomposition or sampling options,
            or ``decomposition="coacd"`` without CoACD installed.
    """
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise InvalidObjectParams(
            f"name must be non-empty and use only letters, digits and underscores "
            f"(it becomes MJCF names obj_<name>...), got {name!r}"
        )
    if not _is_real(mass_kg) or not mass_kg > 0 or not math.isfinite(mass_kg):
        raise InvalidObjectParams(f"mass_kg must be a finite number > 0 (kg), got {mass_kg!r}")
    if not _is_real(scale) or not scale > 0 or not math.isfinite(scale):
        raise InvalidObjectParams(f"scale must be a finite number > 0, got {scale!r}")
    if decomposition not in _DECOMPOSITIONS:
        raise InvalidObjectParams(
            f"decomposition must be one of {_DECOMPOSITIONS}, got {decomposition!r}"
        )
    if not _is_real(coacd_threshold) or not 0 < coacd_threshold <= 1:
        raise InvalidObjectParams(f"coacd_threshold must be in (0, 1], got {coacd_threshold!r}")
    up = np.asarray(rest_up, dtype=np.float64)
    if up.shape != (3,) or not np.all(np.isfinite(up)) or np.linalg.norm(up) == 0:
        raise InvalidObjectParams(f"rest_up must be a finite non-zero 3-vector, got {rest_up!r}")
    _check_sampling(n_model_points, seed)
    mesh = _read_mesh(Path(path))
    mesh.apply_scale(float(scale))
    extent = float(np.max(mesh.extents))
    lo, hi = SIZE_RANGE_M
    if not lo <= extent <= hi:
        hint = ""
        for factor, unit in ((1e-3, "millimetres"), (1e-2, "centimetres"), (1e3, "kilometres")):
            if lo <= extent * factor <= hi:
                hint = f" If the file is in {unit}, pass scale={scale * factor:g}."
                break
        raise InvalidMesh(
            f"{path}: largest extent after scale={scale:g} is {extent:.4g} m, expected "
            f"{lo:g}..{hi:g} m (an object a hand can grasp).{hint}"
        )
    if float(np.min(mesh.extents)) < 1e-4:
        raise InvalidMesh(
            f"{path}: the mesh is flat (extents {np.round(mesh.extents, 6).tolist()} m); "
            f"an object needs a volume"
        )

    solid = mesh
    if not (mesh.is_watertight and mesh.is_winding_consistent):
        repaired = mesh.copy()
        trimesh.repair.fill_holes(repaired)
        trimesh.repair.fix_winding(repaired)
        if repaired.is_watertight and repaired.is_winding_consistent:
            mesh = solid = repaired
        else:
            warnings.warn(
                f"{path}: the mesh is not watertight; its mass properties come from its "
                f"convex hull (uniform density)",
                MeshImportWarning,
                stacklevel=2,
            )
            solid = _hull(np.asarray(mesh.vertices))
    if solid.volume < 0:
        solid.invert()

    pieces = _convex_pieces(mesh, decomposition, float(coacd_threshold), int(seed), path)
    symmetry = symmetry if symmetry is not None else NO_SYMMETRY
    return _finalize(
        name=name,
        visual=mesh,
        pieces=pieces,
        mass_kg=float(mass_kg),
        symmetry=symmetry,
        rest_up=up,
        rgba=_check_rgba(rgba),
        shape=f"imported from {Path(path).name}",
        ycbv_id=None,
        n_model_points=int(n_model_points),
        seed=int(seed),
        recenter=recenter,
        mass_mesh=None if solid is mesh else solid,
    )


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def _check_rgba(rgba: Sequence[float]) -> tuple[float, float, float, float]:
    arr = np.asarray(rgba, dtype=np.float64)
    if arr.shape != (4,) or not np.all((arr >= 0) & (arr <= 1)):
        raise InvalidObjectParams(f"rgba must be 4 numbers in [0, 1], got {rgba!r}")
    return tuple(float(c) for c in arr)


def _read_mesh(path: Path) -> trimesh.Trimesh:
    """Read a mesh file into one Trimesh (metres as stored), validating it."""
    if path.suffix.lower() not in MESH_FORMATS:
        raise InvalidMesh(
            f"{path}: unsupported mesh format {path.suffix!r}; supported: {', '.join(MESH_FORMATS)}"
        )
    if not path.is_file():
        raise InvalidMesh(f"{path}: no such file")
    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as err:  # noqa: BLE001 - trimesh raises many types on bad files
        raise InvalidMesh(f"{path}: trimesh could not read the file: {err}") from err
    if isinstance(loaded, trimesh.Scene):
        geoms = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        loaded = trimesh.util.concatenate(geoms) if geoms else trimesh.Trimesh()
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise InvalidMesh(f"{path}: the file holds no triangles (empty mesh)")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    if not np.all(np.isfinite(vertices)):
        bad = int(np.count_nonzero(~np.isfinite(vertices).all(axis=1)))
        raise InvalidMesh(f"{path}: {bad} of {len(vertices)} vertices are not finite (NaN/inf)")
    mesh = trimesh.Trimesh(vertices, np.asarray(loaded.faces), process=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) == 0:
        raise InvalidMesh(f"{path}: every triangle is degenerate (empty mesh)")
    return mesh


def _convex_pieces(
    mesh: trimesh.Trimesh, method: str, threshold: float, seed: int, path: object
) -> list[trimesh.Trimesh]:
    """Convex collision pieces of an imported mesh (CoACD or the convex hull)."""
    if method in ("auto", "coacd"):
        try:
            import coacd  # noqa: PLC0415 - optional dependency, imported on use
        except ImportError:
            if method == "coacd":
                raise InvalidObjectParams(
                    "decomposition='coacd' needs the coacd package (pip install coacd); "
                    "or pass decomposition='convex_hull'"
                ) from None
            warnings.warn(
                f"{path}: coacd is not installed, so the collision geometry is the convex hull "
                f"of the mesh (concave parts such as a cavity are filled). Install it with "
                f"'pip install coacd' for a convex decomposition.",
                MeshImportWarning,
                stacklevel=3,
            )
            return [_hull(np.asarray(mesh.vertices))]
        coacd.set_log_level("error")
        parts = coacd.run_coacd(
            coacd.Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)),
            threshold=threshold,
            seed=seed,
        )
        pieces = []
        for vertices, _faces in parts:
            try:
                pieces.append(_hull(np.asarray(vertices, dtype=np.float64)))
            except Exception:  # noqa: BLE001 - qhull rejects flat slivers; they carry no volume
                continue
        if pieces:
            return pieces
    return [_hull(np.asarray(mesh.vertices))]


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
    name = obj.body_name if body_name is None else body_name
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise InvalidObjectParams(
            f"body_name must use only letters, digits and underscores, got {name!r}"
        )
    position = np.asarray(pos, dtype=np.float64)
    quat = np.asarray(quat_wxyz, dtype=np.float64)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise InvalidObjectParams(f"pos must be 3 finite numbers (m), got {pos!r}")
    if quat.shape != (4,) or not np.all(np.isfinite(quat)) or np.linalg.norm(quat) < 1e-9:
        raise InvalidObjectParams(
            f"quat_wxyz must be 4 finite numbers, not all 0, got {quat_wxyz!r}"
        )
    fric = np.asarray(friction, dtype=np.float64)
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
