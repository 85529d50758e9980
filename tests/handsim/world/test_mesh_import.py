"""Mesh import at scale: exact O(n)-memory diameter, face budget, CoACD time limit, bad files."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import trimesh
from scipy.spatial.distance import pdist

from handsim.errors import HandSimError
from handsim.world.mesh_import import load_object
from handsim.world.objects import (
    InvalidMesh,
    MeshImportWarning,
    _hull_vertices,
    point_set_diameter,
)
from handsim.world.registry import OBJECT_NAMES, get_object


@pytest.mark.parametrize("seed", range(6))
def test_point_set_diameter_equals_pdist(seed):
    """The branch-and-bound diameter equals the brute-force maximum pairwise distance."""
    rng = np.random.default_rng(seed)
    n = [2, 7, 300, 1500, 3000, 5000][seed]
    points = rng.normal(size=(n, 3)) * rng.uniform(0.01, 1.0, size=3)
    if seed % 2:
        points /= np.linalg.norm(points, axis=1, keepdims=True)  # all on a sphere: worst case
    expected = pdist(points).max()
    assert point_set_diameter(points) == pytest.approx(expected, rel=1e-12)


def test_point_set_diameter_of_degenerate_sets():
    """One point has diameter 0; repeated points do not change the maximum."""
    assert point_set_diameter(np.zeros((1, 3))) == 0.0
    pts = np.repeat(np.array([[0.0, 0.0, 0.0], [0.3, 0.4, 0.0]]), 500, axis=0)
    assert point_set_diameter(pts) == pytest.approx(0.5, rel=1e-15)


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_builtin_diameters_match_pdist_over_hull_vertices(name):
    """Every built-in object's diameter is the old pdist maximum to 1e-9 relative."""
    obj = get_object(name)
    hull = _hull_vertices(np.asarray(obj.visual_mesh.vertices))
    assert obj.diameter_m == pytest.approx(pdist(hull).max(), rel=1e-9)


def _sphere_file(tmp_path, subdivisions=4):
    path = tmp_path / "sphere.ply"
    trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.04).export(path)
    return path


def test_a_mesh_over_the_face_budget_is_decimated_with_a_warning(tmp_path):
    """5120 faces with max_faces=1000: decimated to <= 1000 faces, size kept."""
    pytest.importorskip("fast_simplification")
    path = _sphere_file(tmp_path)
    with pytest.warns(MeshImportWarning, match=r"5,120 faces, more than max_faces=1,000; it was"):
        obj = load_object(
            path, name="ball", mass_kg=0.1, max_faces=1000, decomposition="convex_hull"
        )
    assert len(obj.visual_mesh.faces) <= 1000
    np.testing.assert_allclose(obj.extents_m, 0.08, rtol=0.02)
    assert obj.diameter_m == pytest.approx(0.08, rel=0.02)


def test_a_mesh_over_the_face_budget_is_refused_without_decimation(tmp_path, monkeypatch):
    """Without fast-simplification the message says how to proceed."""
    monkeypatch.setitem(sys.modules, "fast_simplification", None)
    path = _sphere_file(tmp_path)
    with pytest.raises(
        InvalidMesh, match=r"more than max_faces=1,000; install fast-simplification"
    ):
        load_object(path, name="ball", mass_kg=0.1, max_faces=1000, decomposition="convex_hull")


def test_coacd_is_stopped_at_its_time_limit(tmp_path):
    """CoACD on an open tube (minutes on main) stops at coacd_timeout_s; the hull is used."""
    pytest.importorskip("coacd")
    tube = trimesh.creation.cylinder(radius=0.02, height=0.05, sections=32)
    tube.update_faces(np.abs(tube.face_normals[:, 2]) < 0.5)
    tube.remove_unreferenced_vertices()
    path = tmp_path / "tube.ply"
    tube.export(path)
    with pytest.warns(MeshImportWarning) as record:
        obj = load_object(path, name="tube", mass_kg=0.1, decomposition="coacd", coacd_timeout_s=1)
    messages = " | ".join(str(w.message) for w in record)
    assert "CoACD did not finish within coacd_timeout_s=1 s" in messages
    assert len(obj.collision_meshes) == 1 and obj.collision_meshes[0].is_convex


@pytest.mark.parametrize(
    ("filename", "content", "match"),
    [
        ("noise.obj", None, r"not a valid OBJ file \(the file is not text"),
        ("noise.stl", None, r"not a valid STL file"),
        ("noise.ply", None, r"not a valid PLY file \(trimesh could not parse it"),
        ("noise.glb", None, r"not a valid GLB file"),
        ("empty.ply", b"", r"the file is empty"),
        ("empty.stl", b"", r"the file is empty"),
        ("words.obj", b"hello world\nfoo bar\n", r"holds no triangles"),
    ],
)
def test_unreadable_files_give_a_clear_error(tmp_path, filename, content, match):
    """Random bytes, empty files and text without triangles: InvalidMesh naming the file."""
    path = tmp_path / filename
    path.write_bytes(np.random.default_rng(0).bytes(5000) if content is None else content)
    with pytest.raises(InvalidMesh, match=match) as err:
        load_object(path, name="thing", mass_kg=0.1, decomposition="convex_hull")
    assert isinstance(err.value, HandSimError)
    assert "charset_normalizer" not in str(err.value)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"max_faces": 10}, r"max_faces must be an int in \[1000, 10000000\]"),
        ({"max_faces": 1e5}, r"max_faces must be an int"),
        ({"coacd_timeout_s": 0}, r"coacd_timeout_s must be in \(0, 3600\]"),
        ({"coacd_timeout_s": float("nan")}, r"coacd_timeout_s must be in"),
        ({"scale": "1"}, r"scale must be a finite number > 0, got '1' \(str\)"),
        ({"symmetry": "none"}, r"symmetry must be a Symmetry"),
        ({"rest_up": (0, 0, 1j)}, r"rest_up must be finite numbers of shape \(3,\)"),
    ],
)
def test_load_object_rejects_bad_options(tmp_path, kwargs, match):
    """New and existing options are checked before the file is read."""
    path = _sphere_file(tmp_path, subdivisions=1)
    with pytest.raises(HandSimError, match=match):
        load_object(path, **{"name": "ball", "mass_kg": 0.1, **kwargs})
