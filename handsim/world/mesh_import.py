"""Import of user meshes (OBJ/PLY/STL/GLB via trimesh, e.g. the real YCB models).

An imported mesh becomes a :class:`~handsim.world.objects.YCBObject` with convex collision
pieces (CoACD when installed).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from handsim.world.meshing import _hull
from handsim.world.objects import (
    _NAME_RE,
    MESH_FORMATS,
    N_MODEL_POINTS,
    NO_SYMMETRY,
    SIZE_RANGE_M,
    InvalidMesh,
    InvalidObjectParams,
    MeshImportWarning,
    Symmetry,
    YCBObject,
    _check_rgba,
    _check_sampling,
    _finalize,
)

__all__ = [
    "Decomposition",
    "load_object",
]

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
