"""Import of user meshes (OBJ/PLY/STL/GLB via trimesh, e.g. the real YCB models).

An imported mesh becomes a :class:`~handsim.world.objects.YCBObject` with convex collision
pieces (CoACD when installed).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from handsim._validate import boolean, choice, integer, real_array, real_scalar, show
from handsim.errors import InvalidObjectParams
from handsim.world.meshing import _hull
from handsim.world.objects import (
    _NAME_RE,
    MESH_FORMATS,
    N_MODEL_POINTS,
    SIZE_RANGE_M,
    InvalidMesh,
    MeshImportWarning,
    YCBObject,
    _check_rgba,
    _check_sampling,
    _finalize,
)
from handsim.world.symmetry import NO_SYMMETRY, Symmetry

if TYPE_CHECKING:
    # trimesh loads when a mesh is read, not on `import handsim`.
    import trimesh

__all__ = [
    "COACD_MAX_FACES",
    "COACD_TIMEOUT_S",
    "Decomposition",
    "MAX_FACES",
    "load_object",
]

MAX_FACES = 100_000
"""Default face budget of an imported visual mesh; larger meshes are decimated to it
(quadric decimation, ``pip install fast-simplification``) or refused when that is missing."""

COACD_MAX_FACES = 10_000
"""CoACD gets a copy decimated to at most this many faces (when fast-simplification is there)."""

COACD_TIMEOUT_S = 10.0
"""Default time limit of the CoACD decomposition, seconds (then: the convex hull, a warning)."""

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
    max_faces: int = MAX_FACES,
    coacd_timeout_s: float = COACD_TIMEOUT_S,
) -> YCBObject:
    """Import a mesh file (OBJ/PLY/STL/GLB) as an object usable like a built-in one.

    The mesh keeps its own frame unless ``recenter`` (so the real YCB-Video models keep the
    frame their poses are given in). Collision pieces come from CoACD (``pip install coacd``)
    when available, else from the convex hull with a :class:`MeshImportWarning` (concave parts
    such as a mug's cavity are then filled). Mass properties assume uniform density; a mesh
    that is not watertight (even after filling holes) gets them from its convex hull, with a
    warning.

    Cost is bounded: a mesh with more than ``max_faces`` faces is decimated to that budget
    (with a warning; it needs ``pip install fast-simplification``, else the mesh is refused),
    CoACD runs in a child process on a copy of at most :data:`COACD_MAX_FACES` faces and is
    stopped after ``coacd_timeout_s`` seconds (then the convex hull is used, with a warning),
    and no step keeps more than O(faces) memory.

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
        max_faces: face budget of the visual mesh, 1000..10,000,000 (see above).
        coacd_timeout_s: time limit of CoACD in seconds, in (0, 3600].

    Raises:
        InvalidMesh: missing, empty or unreadable file, unsupported format, empty mesh,
            non-finite vertices, a largest extent outside :data:`SIZE_RANGE_M` after scaling,
            a flat mesh, or more than ``max_faces`` faces without fast-simplification.
        InvalidObjectParams: invalid name, mass, scale, decomposition or sampling options,
            or ``decomposition="coacd"`` without CoACD installed.
    """
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise InvalidObjectParams(
            f"name must be non-empty and use only letters, digits and underscores "
            f"(it becomes MJCF names obj_<name>...), got {show(name)}"
        )
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidObjectParams(f"path must be a str or os.PathLike, got {show(path)}")
    mass_kg = real_scalar("mass_kg", mass_kg, InvalidObjectParams, lo=0.0, lo_open=True, unit="kg")
    scale = real_scalar("scale", scale, InvalidObjectParams, lo=0.0, lo_open=True)
    choice("decomposition", decomposition, _DECOMPOSITIONS, InvalidObjectParams)
    coacd_threshold = real_scalar(
        "coacd_threshold", coacd_threshold, InvalidObjectParams, lo=0.0, hi=1.0, lo_open=True
    )
    recenter = boolean("recenter", recenter, InvalidObjectParams)
    up = real_array("rest_up", rest_up, InvalidObjectParams, shape=(3,))
    if np.linalg.norm(up) == 0:
        raise InvalidObjectParams(f"rest_up must be a finite non-zero 3-vector, got {rest_up!r}")
    if symmetry is not None and not isinstance(symmetry, Symmetry):
        raise InvalidObjectParams(f"symmetry must be a Symmetry, got {show(symmetry)}")
    max_faces = integer("max_faces", max_faces, InvalidObjectParams, lo=1000, hi=10_000_000)
    coacd_timeout_s = real_scalar(
        "coacd_timeout_s", coacd_timeout_s, InvalidObjectParams, lo=0.0, hi=3600.0, lo_open=True
    )
    _check_sampling(n_model_points, seed)
    mesh = _read_mesh(Path(path), max_faces)
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
        import trimesh

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

    pieces = _convex_pieces(
        mesh, decomposition, float(coacd_threshold), int(seed), path, coacd_timeout_s
    )
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


def _decimate(
    mesh: trimesh.Trimesh, max_faces: int, path: object, what: str, hint: bool
) -> trimesh.Trimesh:
    """``mesh`` reduced to at most ``max_faces`` faces by quadric decimation.

    Without fast-simplification (or when decimation fails) a ``hint`` call raises
    :class:`InvalidMesh`; otherwise the mesh is returned as it is.
    """
    if len(mesh.faces) <= max_faces:
        return mesh
    try:
        import fast_simplification  # noqa: F401, PLC0415 - optional, imported on use
    except ImportError:
        if not hint:
            return mesh
        raise InvalidMesh(
            f"{path}: the mesh has {len(mesh.faces):,} faces, more than {what}={max_faces:,}; "
            f"install fast-simplification (pip install 'handsim[mesh]') to decimate it "
            f"automatically, decimate it yourself, or pass a larger {what}"
        ) from None
    import trimesh

    n = len(mesh.faces)
    reduced = mesh.simplify_quadric_decimation(face_count=max_faces)
    reduced = trimesh.Trimesh(
        np.asarray(reduced.vertices, dtype=np.float64), np.asarray(reduced.faces), process=True
    )
    reduced.update_faces(reduced.nondegenerate_faces())
    reduced.remove_unreferenced_vertices()
    if len(reduced.faces) == 0 or len(reduced.faces) > max_faces:
        if not hint:
            return mesh
        raise InvalidMesh(
            f"{path}: the mesh has {n:,} faces, more than {what}={max_faces:,}, and decimation "
            f"failed; decimate it yourself or pass a larger {what}"
        )
    if hint:
        warnings.warn(
            f"{path}: the mesh has {n:,} faces, more than {what}={max_faces:,}; it was "
            f"decimated to {len(reduced.faces):,} faces (quadric decimation)",
            MeshImportWarning,
            stacklevel=4,
        )
    return reduced


def _read_mesh(path: Path, max_faces: int = MAX_FACES) -> trimesh.Trimesh:
    """Read a mesh file into one Trimesh (metres as stored), validating it.

    A mesh above ``max_faces`` is decimated right after its vertices are merged (before the
    per-face clean-up, which would cost seconds on millions of faces).
    """
    if path.suffix.lower() not in MESH_FORMATS:
        raise InvalidMesh(
            f"{path}: unsupported mesh format {path.suffix!r}; supported: {', '.join(MESH_FORMATS)}"
        )
    if not path.is_file():
        raise InvalidMesh(f"{path}: no such file")
    fmt = path.suffix.lower()[1:].upper()
    if path.stat().st_size == 0:
        raise InvalidMesh(f"{path}: the file is empty (it holds no triangles)")
    if fmt == "OBJ" or (fmt == "STL" and not _is_binary_stl(path)):
        # Text formats: trimesh guesses encodings of non-UTF-8 bytes (and may then ask for
        # an optional module); a mesh file that is not text is simply not a valid file.
        with path.open("rb") as f:
            head = f.read(1 << 16)
        if b"\0" in head or not _decodes(head):
            raise InvalidMesh(
                f"{path}: not a valid {fmt} file (the file is not text; is it corrupt or of "
                f"another format?)"
            )
    import trimesh

    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as err:  # noqa: BLE001 - trimesh raises many types on bad files
        raise InvalidMesh(
            f"{path}: not a valid {fmt} file (trimesh could not parse it: "
            f"{type(err).__name__}: {err})"
        ) from err
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
    del loaded, vertices
    if len(mesh.faces) > max_faces:
        mesh = _decimate(mesh, max_faces, path, "max_faces", hint=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) == 0:
        raise InvalidMesh(f"{path}: every triangle is degenerate (empty mesh)")
    return mesh


def _is_binary_stl(path: Path) -> bool:
    """Whether an STL file's size matches the binary layout (84 + 50 bytes per triangle)."""
    size = path.stat().st_size
    if size < 84:
        return False
    with path.open("rb") as f:
        header = f.read(84)
    n = int.from_bytes(header[80:84], "little")
    return size == 84 + 50 * n


def _decodes(data: bytes) -> bool:
    # A cut at the end of the sample may split a multi-byte character.
    for cut in range(4):
        try:
            data[: len(data) - cut].decode("utf-8")
            return True
        except UnicodeDecodeError:
            continue
    try:
        data.decode("ascii")
    except UnicodeDecodeError:
        return False
    return True


def _convex_pieces(
    mesh: trimesh.Trimesh,
    method: str,
    threshold: float,
    seed: int,
    path: object,
    timeout_s: float = COACD_TIMEOUT_S,
) -> list[trimesh.Trimesh]:
    """Convex collision pieces of an imported mesh (CoACD or the convex hull)."""
    if method in ("auto", "coacd"):
        try:
            import coacd  # noqa: F401, PLC0415 - optional; checked here, run in a child
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
        parts = _run_coacd(
            _decimate(mesh, COACD_MAX_FACES, path, "COACD_MAX_FACES", hint=False),
            threshold,
            seed,
            timeout_s,
            path,
        )
        if parts is None:
            return [_hull(np.asarray(mesh.vertices))]
        pieces = []
        for vertices, _faces in parts:
            try:
                pieces.append(_hull(np.asarray(vertices, dtype=np.float64)))
            except Exception:  # noqa: BLE001 - qhull rejects flat slivers; they carry no volume
                continue
        if pieces:
            return pieces
    return [_hull(np.asarray(mesh.vertices))]


# CoACD runs in a child process so that it can be stopped: it has no time limit of its own and
# takes minutes on some inputs (e.g. an open tube); the child imports only numpy and coacd.
_COACD_CHILD = """
import sys
import numpy as np
import coacd
data = np.load(sys.argv[1])
coacd.set_log_level("error")
parts = coacd.run_coacd(
    coacd.Mesh(data["vertices"], data["faces"]),
    threshold=float(data["threshold"]),
    seed=int(data["seed"]),
)
out = {}
for k, (v, f) in enumerate(parts):
    out[f"v{k}"] = np.asarray(v, dtype=np.float64)
    out[f"f{k}"] = np.asarray(f, dtype=np.int64)
np.savez(sys.argv[2], **out)
"""


def _run_coacd(
    mesh: trimesh.Trimesh, threshold: float, seed: int, timeout_s: float, path: object
) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """CoACD's convex parts of ``mesh``, or None (with a warning) on a timeout or a failure."""
    with tempfile.TemporaryDirectory(prefix="handsim_coacd_") as tmp:
        src, dst = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.npz")
        np.savez(
            src,
            vertices=np.asarray(mesh.vertices, dtype=np.float64),
            faces=np.asarray(mesh.faces, dtype=np.int64),
            threshold=threshold,
            seed=seed,
        )
        try:
            run = subprocess.run(
                [sys.executable, "-c", _COACD_CHILD, src, dst],
                capture_output=True,
                timeout=timeout_s,
                check=False,
            )
        except subprocess.TimeoutExpired:
            reason = f"CoACD did not finish within coacd_timeout_s={timeout_s:g} s"
        else:
            if run.returncode == 0 and os.path.exists(dst):
                with np.load(dst) as data:
                    n = len(data.files) // 2
                    return [(data[f"v{k}"], data[f"f{k}"]) for k in range(n)]
            tail = run.stderr.decode(errors="replace").strip().splitlines()[-1:]
            reason = f"CoACD failed ({'; '.join(tail) or f'exit status {run.returncode}'})"
    warnings.warn(
        f"{path}: {reason}; the collision geometry is the convex hull of the mesh "
        f"(concave parts such as a cavity are filled)",
        MeshImportWarning,
        stacklevel=4,
    )
    return None
