"""Tests of handsim.world: the 21 YCB-Video objects, user-mesh import and MuJoCo bodies.

Invariants are checked over every registered object. Tolerances against the facts table
(``/work/shared/facts/hand_objects_sensors.md`` section 5):

- extents: 1.5 % or 1 mm, whichever is larger. Every builder is dimensioned (or fitted) to the
  facts extents, so what remains is meshing error (chords of curved surfaces, the decimation
  of the composite shapes: < 0.5 mm measured).
- diameter: 3 %. The diameter is a derived quantity: the boxes, cans and the banana are fitted
  to it, the other primitives only approximate the scanned silhouettes (largest measured
  deviation: 1.4 %, the large clamp).
- mass: exact (it is an input).
"""

from __future__ import annotations

import dataclasses
import itertools
import sys

import mujoco
import numpy as np
import pytest
import trimesh
from scipy.spatial.distance import pdist
from scipy.spatial.transform import Rotation

from handsim.errors import HandSimError, UnknownName
from handsim.hand.model import HAND_PHYSICS_OPTIONS
from handsim.world.mesh_import import load_object
from handsim.world.objects import (
    COLLISION_GROUP,
    N_MODEL_POINTS,
    NO_SYMMETRY,
    VISUAL_GROUP,
    InvalidMesh,
    InvalidObjectParams,
    MeshImportWarning,
    Symmetry,
    YCBObject,
    add_object,
)
from handsim.world.registry import OBJECT_NAMES, OBJECTS, get_object

EXTENT_REL_TOL = 0.015
EXTENT_ABS_TOL = 1e-3
DIAMETER_REL_TOL = 0.03
HOLLOW = ("019_pitcher_base", "024_bowl", "025_mug")
# Genus of each visual surface (handles and finger loops are holes through the solid).
GENUS = {
    "019_pitcher_base": 1,
    "025_mug": 1,
    "037_scissors": 2,
    "051_large_clamp": 1,
    "052_extra_large_clamp": 1,
}
SYMMETRIC = tuple(n for n in OBJECT_NAMES if OBJECTS[n].symmetry_kind != "none")

try:
    import coacd  # noqa: F401

    HAVE_COACD = True
except ImportError:
    HAVE_COACD = False


# Geometry helpers -------------------------------------------------------------------------------


def _point_triangle_distance(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Distance from points (N, 3) to triangles (N, 3, 3), pairwise."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    unit = n / np.maximum(norm, 1e-300)
    height = np.einsum("ij,ij->i", p - a, unit)
    q = p - height[:, None] * unit
    inside = norm[:, 0] > 1e-20
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, q - u), n) >= 0

    def segment(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        e = v - u
        t = np.clip(
            np.einsum("ij,ij->i", p - u, e) / np.maximum(np.einsum("ij,ij->i", e, e), 1e-300), 0, 1
        )
        return np.linalg.norm(p - u - t[:, None] * e, axis=1)

    edges = np.minimum(np.minimum(segment(a, b), segment(b, c)), segment(c, a))
    return np.where(inside, np.abs(height), edges)


def _distance_to_mesh(points: np.ndarray, mesh: trimesh.Trimesh, reach: float) -> np.ndarray:
    """Exact distance from (N, 3) points to the mesh surface where it is below ``reach`` (m).

    Candidate triangles are those whose bounding box, grown by ``reach``, contains the point;
    points farther than ``reach`` from every triangle get ``inf``.
    """
    tri = np.asarray(mesh.triangles)
    lo = tri.min(axis=1) - reach
    hi = tri.max(axis=1) + reach
    out = np.full(len(points), np.inf)
    for start in range(0, len(points), 100):
        chunk = points[start : start + 100]
        hit = np.all((chunk[:, None, :] >= lo[None]) & (chunk[:, None, :] <= hi[None]), axis=2)
        pi, ti = np.nonzero(hit)
        d = _point_triangle_distance(chunk[pi], tri[ti])
        best = np.full(len(chunk), np.inf)
        np.minimum.at(best, pi, d)
        out[start : start + 100] = best
    return out


def _winding_number(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """Generalized winding number of (N, 3) points: ~1 inside a closed mesh, ~0 outside."""
    tri = np.asarray(mesh.triangles)[None] - points[:, None, None, :]
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
    det = np.einsum("nfi,nfi->nf", a, np.cross(b, c))
    dots = (
        la * lb * lc
        + np.einsum("nfi,nfi->nf", a, b) * lc
        + np.einsum("nfi,nfi->nf", b, c) * la
        + np.einsum("nfi,nfi->nf", c, a) * lb
    )
    return (2.0 * np.arctan2(det, dots)).sum(axis=1) / (4.0 * np.pi)


def _plane_distance(points: np.ndarray, piece: trimesh.Trimesh) -> np.ndarray:
    """Max over the face planes of a convex piece: < 0 inside it, ~distance outside."""
    normals = np.asarray(piece.face_normals)
    offsets = np.einsum("ij,ij->i", normals, np.asarray(piece.triangles)[:, 0])
    return (points @ normals.T - offsets).max(axis=1)


def _subsample(points: np.ndarray, n: int = 300) -> np.ndarray:
    return points[np.random.default_rng(0).choice(len(points), n, replace=False)]


# MuJoCo helpers ---------------------------------------------------------------------------------


def _scene(obj: YCBObject, lift: float = 0.01) -> mujoco.MjSpec:
    spec = mujoco.MjSpec()
    for key, value in HAND_PHYSICS_OPTIONS.items():
        setattr(spec.option, key, value)
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=(1, 1, 0.1))
    add_object(spec, obj, pos=(0.0, 0.0, obj.rest_height_m + lift), quat_wxyz=obj.rest_quat_wxyz)
    return spec


def _drop(obj: YCBObject) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Drop ``obj`` in its rest pose from 1 cm onto a floor and simulate 1 s."""
    model = _scene(obj).compile()
    data = mujoco.MjData(model)
    for _ in range(round(1.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    return model, data


def _assert_rests(obj: YCBObject) -> None:
    model, data = _drop(obj)
    warnings = {mujoco.mjtWarning(i).name: w.number for i, w in enumerate(data.warning) if w.number}
    assert not warnings, f"MuJoCo warnings: {warnings}"
    body = model.body(obj.body_name).id
    speed = np.linalg.norm(data.qvel[:3])
    spin = np.linalg.norm(data.qvel[3:])
    assert speed < 5e-3, f"still moving at {speed:.2e} m/s"
    assert spin < 0.05, f"still turning at {spin:.2e} rad/s"
    rot = data.xmat[body].reshape(3, 3)
    vertices = np.concatenate([p.vertices for p in obj.collision_meshes])
    lowest = float((vertices @ rot.T + data.xpos[body])[:, 2].min())
    assert lowest > -1e-3, f"sank {-lowest * 1e3:.2f} mm into the floor"
    assert abs(data.xpos[body][2] - obj.rest_height_m) < 2e-3
    rest = np.empty(9)
    mujoco.mju_quat2Mat(rest, obj.rest_quat_wxyz)
    cos = (np.trace(rest.reshape(3, 3).T @ rot) - 1.0) / 2.0
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))) < 5.0, "left its rest orientation"


# Registry ---------------------------------------------------------------------------------------


def test_registry_holds_the_21_ycbv_objects_in_id_order():
    """OBJECTS has the 21 YCB-Video objects, ids 1..21, unique names and aliases."""
    assert len(OBJECTS) == 21
    assert tuple(OBJECTS) == OBJECT_NAMES
    assert [OBJECTS[n].ycbv_id for n in OBJECT_NAMES] == list(range(1, 22))
    assert OBJECT_NAMES[0] == "002_master_chef_can"
    assert OBJECT_NAMES[-1] == "061_foam_brick"
    assert len({OBJECTS[n].alias for n in OBJECT_NAMES}) == 21


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_aliases_resolve_to_the_same_object(name):
    """Canonical name, short alias and obj_ body name give the same (cached) object."""
    alias = OBJECTS[name].alias
    assert OBJECTS[alias] is OBJECTS[name]
    assert alias in OBJECTS and f"obj_{name}" in OBJECTS
    assert get_object(alias) is get_object(name) is get_object(f"obj_{name}")
    assert get_object(name).name == name


def test_unknown_name_lists_the_valid_names():
    """An unknown name raises UnknownName with suggestions and every valid name."""
    with pytest.raises(UnknownName, match=r"unknown object 'tomato_can'\. Did you mean") as err:
        get_object("tomato_can")
    message = str(err.value)
    assert all(n in message for n in OBJECT_NAMES)
    assert isinstance(err.value, KeyError) and isinstance(err.value, HandSimError)
    with pytest.raises(UnknownName, match="Valid names: 002_master_chef_can"):
        OBJECTS["nope"]
    assert "nope" not in OBJECTS and 5 not in OBJECTS
    assert OBJECTS.get("nope") is None


def test_get_object_validates_sampling_options():
    """Bad n_model_points or seed raise InvalidObjectParams naming the option."""
    with pytest.raises(InvalidObjectParams, match="n_model_points must be >= 1, got 0"):
        get_object("mug", n_model_points=0)
    with pytest.raises(InvalidObjectParams, match="seed must be a non-negative int"):
        get_object("mug", seed=-1)


# Geometry of every object -----------------------------------------------------------------------


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_visual_mesh_is_a_closed_surface_of_the_expected_genus(name):
    """The visual mesh is watertight, consistently wound outward, one body, expected genus."""
    mesh = get_object(name).visual_mesh
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0
    assert mesh.body_count == 1
    assert mesh.euler_number == 2 - 2 * GENUS.get(name, 0)


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_collision_pieces_are_convex_and_cover_the_visual_surface(name):
    """Every collision piece is a closed convex mesh; together they hug the visual surface."""
    obj = get_object(name)
    assert len(obj.collision_meshes) >= 1
    for piece in obj.collision_meshes:
        assert piece.is_watertight and piece.is_convex and piece.volume > 0
    points = _subsample(obj.model_points_m)
    gap = np.min([_plane_distance(points, p) for p in obj.collision_meshes], axis=0)
    assert gap.max() < 3e-3, f"visual surface {gap.max() * 1e3:.2f} mm outside the pieces"
    lo, hi = obj.visual_mesh.bounds
    for piece in obj.collision_meshes:
        assert np.all(piece.bounds[0] > lo - 2e-3) and np.all(piece.bounds[1] < hi + 2e-3)


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_extents_diameter_and_mass_match_the_facts(name):
    """Measured extents, diameter and mass agree with the facts table (module docstring)."""
    obj = get_object(name)
    spec = OBJECTS[name]
    facts = np.array(spec.extents_m)
    tol = np.maximum(EXTENT_REL_TOL * facts, EXTENT_ABS_TOL)
    measured = obj.extents_m
    assert np.all(np.abs(measured - facts) <= tol), (
        f"extents {np.round(measured * 1e3, 1)} mm vs facts {np.round(facts * 1e3, 1)} mm"
    )
    assert obj.diameter_m == pytest.approx(spec.diameter_m, rel=DIAMETER_REL_TOL), (
        f"diameter {obj.diameter_m * 1e3:.1f} mm vs facts {spec.diameter_m * 1e3:.1f} mm"
    )
    assert obj.mass_kg == spec.mass_kg
    hull = trimesh.convex.convex_hull(obj.visual_mesh.vertices)
    assert obj.diameter_m == pytest.approx(pdist(np.asarray(hull.vertices)).max())


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_model_points_lie_on_the_surface(name):
    """Model points are (N, 3) float64 samples on the visual surface."""
    obj = get_object(name)
    points = obj.model_points_m
    assert points.shape == (N_MODEL_POINTS, 3) and points.dtype == np.float64
    d = _distance_to_mesh(_subsample(points), obj.visual_mesh, reach=1e-4)
    assert d.max() < 1e-9


@pytest.mark.parametrize("name", ["005_tomato_soup_can", "051_large_clamp"])
def test_objects_are_deterministic_and_seeded(name):
    """Two builds are identical; the seed (only) changes the model points."""
    a = OBJECTS[name].build(n_model_points=50, seed=3)
    b = OBJECTS[name].build(n_model_points=50, seed=3)
    c = OBJECTS[name].build(n_model_points=50, seed=4)
    assert np.array_equal(a.visual_mesh.vertices, b.visual_mesh.vertices)
    assert np.array_equal(a.visual_mesh.faces, c.visual_mesh.faces)
    assert np.array_equal(a.model_points_m, b.model_points_m)
    assert not np.array_equal(a.model_points_m, c.model_points_m)
    assert a.model_points_m.shape == (50, 3)


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_corners_are_the_bounding_box_centred_on_the_origin(name):
    """The 8 corners are the bbox in itertools.product order; the bbox centre is the origin."""
    obj = get_object(name)
    lo, hi = obj.visual_mesh.bounds
    expected = np.array(
        [
            [(lo, hi)[bit][i] for i, bit in enumerate(bits)]
            for bits in itertools.product((0, 1), repeat=3)
        ]
    )
    assert np.array_equal(obj.corners_m, expected)
    np.testing.assert_allclose(obj.corners_m[7] - obj.corners_m[0], obj.extents_m)
    np.testing.assert_allclose(lo + hi, 0.0, atol=1e-12)


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_mass_properties_are_physical(name):
    """Inertia is symmetric, positive definite, obeys the triangle inequality; COM inside."""
    obj = get_object(name)
    inertia = obj.inertia_kg_m2
    np.testing.assert_allclose(inertia, inertia.T, atol=1e-15)
    principal = np.linalg.eigvalsh(inertia)
    assert principal.min() > 0
    assert principal[0] + principal[1] >= principal[2] * (1 - 1e-9)
    assert np.all(np.abs(obj.com_m) < obj.extents_m / 2)
    # Uniform density: the inertia per unit mass is the mesh's.
    mesh = obj.visual_mesh
    np.testing.assert_allclose(
        inertia, mesh.moment_inertia * obj.mass_kg / mesh.volume, rtol=1e-9, atol=1e-15
    )


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_spec_symmetry_kind_matches_the_object(name):
    """ObjectSpec.symmetry_kind is the kind of the built object's symmetry."""
    assert get_object(name).symmetry.kind == OBJECTS[name].symmetry_kind


@pytest.mark.parametrize("name", SYMMETRIC)
def test_symmetries_map_the_shape_onto_itself(name):
    """Each symmetry transform moves the model points onto the surface again.

    At least 90 % of the points land within 0.5 mm and none farther than 3 mm: the marker's
    clip (2 mm proud) breaks its continuous symmetry slightly, as in BOP.
    """
    obj = get_object(name)
    points = _subsample(obj.model_points_m, 200)
    transforms = obj.symmetry.transforms(n_continuous=6)[1:]
    assert len(transforms) >= 1
    for t in transforms:
        moved = points @ t[:3, :3].T + t[:3, 3]
        d = _distance_to_mesh(moved, obj.visual_mesh, reach=3e-3)
        assert np.mean(d < 5e-4) >= 0.9 and np.all(d <= 3e-3)


DEPTH_ONLY_SYMMETRIC = (
    "003_cracker_box", "004_sugar_box", "005_tomato_soup_can", "007_tuna_fish_can",
    "008_pudding_box", "009_gelatin_box", "010_potted_meat_can",
)  # fmt: skip


@pytest.mark.parametrize("name", DEPTH_ONLY_SYMMETRIC)
def test_depth_symmetries_map_the_shape_onto_itself(name):
    """Plain cans and boxes: symmetric in depth (the shape), not in texture (their print)."""
    obj = get_object(name)
    assert obj.symmetry_of("texture") is obj.symmetry and obj.symmetry.kind == "none"
    depth = obj.symmetry_of("depth")
    expected = "continuous" if name.endswith("_can") and "meat" not in name else "discrete"
    assert depth.kind == expected
    points = _subsample(obj.model_points_m, 200)
    transforms = depth.transforms(n_continuous=7)[1:]
    assert len(transforms) >= 3
    for t in transforms:
        moved = points @ t[:3, :3].T + t[:3, 3]
        assert np.all(_distance_to_mesh(moved, obj.visual_mesh, reach=3e-3) < 5e-4)
    # A turn that is no symmetry moves points off the surface (the check can fail).
    quarter = np.eye(4)
    quarter[:3, :3] = Rotation.from_rotvec([np.pi / 2, 0.0, 0.0]).as_matrix()
    moved = points @ quarter[:3, :3].T
    assert np.any(_distance_to_mesh(moved, obj.visual_mesh, reach=3e-3) > 2e-3)


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_depth_symmetry_contains_the_texture_symmetry(name):
    """Whatever looks the same in colour gives the same depth: depth symmetries are a superset."""
    obj = get_object(name)
    depth, texture = obj.symmetry_of("depth"), obj.symmetry_of("texture")
    if texture.kind == "continuous":
        assert depth.kind == "continuous" and depth.axis == texture.axis
    elif texture.kind == "discrete":
        for t in texture.discrete:
            assert any(np.allclose(t, d, atol=1e-9) for d in depth.transforms())
    if name not in DEPTH_ONLY_SYMMETRIC:
        assert depth is texture
    with pytest.raises(InvalidObjectParams, match="modality must be one of"):
        obj.symmetry_of("rgb")


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_hollow_objects_are_hollow_to_the_fingers(name):
    """Bowl, mug and pitcher have an empty cavity: no collision piece or visual volume."""
    obj = get_object(name)
    if name not in HOLLOW:
        assert obj.cavity_point_m is None
        return
    centre = obj.cavity_point_m
    # The cavity point and a ring of points 2 cm around it, in the horizontal (x-z) plane.
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = centre + 0.02 * np.column_stack([np.cos(angles), np.zeros(8), np.sin(angles)])
    probes = np.vstack([centre, ring])
    for piece in obj.collision_meshes:
        assert np.all(_plane_distance(probes, piece) > 0)
    np.testing.assert_allclose(_winding_number(probes, obj.visual_mesh), 0.0, atol=1e-6)
    # ... while the wall is solid: the COM side of a wall point is inside the visual mesh.
    wall = obj.visual_mesh.vertices[np.argmax(obj.visual_mesh.vertices[:, 2])]
    inner = wall - np.array([0.0, 0.0, 1e-3])
    assert _winding_number(inner[None], obj.visual_mesh)[0] == pytest.approx(1.0, abs=1e-6)


def test_objects_are_frozen_and_read_only():
    """YCBObject fields cannot be reassigned and its arrays cannot be written."""
    obj = get_object("mug")
    with pytest.raises(dataclasses.FrozenInstanceError):
        obj.mass_kg = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        obj.model_points_m[0, 0] = 1.0
    assert obj.body_name == "obj_025_mug"
    assert obj.collision_geom_names[0] == "obj_025_mug_collision_0"


# Symmetry ---------------------------------------------------------------------------------------


def test_symmetry_groups_transforms_and_bop_export():
    """Discrete groups are closed, transforms start with the identity, BOP export is in mm."""
    rx = np.diag([1.0, -1.0, -1.0])
    rz90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    d4 = Symmetry.from_rotations([rz90, rx], center_m=(0.0, 0.0, 0.01))
    assert d4.kind == "discrete" and len(d4.discrete) == 7
    t = d4.transforms()
    np.testing.assert_allclose(t[0], np.eye(4))
    centre = np.array([0.0, 0.0, 0.01, 1.0])
    for m in t:
        np.testing.assert_allclose(m @ centre, centre, atol=1e-12)
    bop = d4.to_bop()
    assert len(bop["symmetries_discrete"]) == 7 and len(bop["symmetries_discrete"][0]) == 16
    cont = Symmetry.continuous((0.0, 2.0, 0.0), offset_m=(0.001, 0.0, 0.0))
    assert cont.axis == (0.0, 1.0, 0.0)
    assert cont.to_bop() == {
        "symmetries_continuous": [{"axis": [0.0, 1.0, 0.0], "offset": [1.0, 0.0, 0.0]}]
    }
    assert cont.transforms(n_continuous=4).shape == (4, 4, 4)
    assert NO_SYMMETRY.transforms().shape == (1, 4, 4) and NO_SYMMETRY.to_bop() == {}
    moved = cont.moved(np.array([0.0, 0.0, 0.002]))
    assert moved.offset_m == pytest.approx((0.001, 0.0, 0.002))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"kind": "mirror"}, r"symmetry kind must be one of \('none', 'continuous', 'discrete'\)"),
        ({"kind": "continuous"}, "a continuous symmetry needs a finite non-zero 3-vector axis"),
        ({"kind": "none", "axis": (0, 1, 0)}, "axis is only for kind='continuous'"),
        ({"kind": "discrete"}, "a discrete symmetry needs at least one"),
        ({"kind": "discrete", "discrete": 2 * np.eye(4)[None]}, "not a rigid motion"),
    ],
)
def test_symmetry_validation(kwargs, match):
    """Invalid symmetries raise InvalidObjectParams saying what is valid."""
    with pytest.raises(InvalidObjectParams, match=match):
        Symmetry(**kwargs)


def test_symmetry_names_stay_importable_from_objects():
    """The names moved to handsim.world.symmetry (and handsim.errors) are the objects' own."""
    import handsim.errors
    import handsim.world.objects as objects
    import handsim.world.symmetry as symmetry

    for name in symmetry.__all__:
        assert name in objects.__all__
        assert getattr(objects, name) is getattr(symmetry, name), name
    assert objects.InvalidObjectParams is handsim.errors.InvalidObjectParams
    assert issubclass(handsim.errors.InvalidObjectParams, HandSimError)


# MuJoCo -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_object_rests_stably_on_a_plane(name):
    """Dropped from 1 cm in its rest pose, the object settles within 1 s: no warnings."""
    _assert_rests(get_object(name))


def test_power_drill_rests_upright_on_its_battery():
    """The drill stands on its battery (object -y down), its grip clear of the table for a wrap.

    Lying on its side its grip was 10 mm above the table; upright the grip's lowest point is
    above the battery (58 mm thick along the barrel's height) and the chuck points along +x.
    """
    obj = get_object("035_power_drill")
    rest = Rotation.from_quat(np.roll(np.array(obj.rest_quat_wxyz), -1))
    np.testing.assert_allclose(rest.apply(np.array([0.0, 1.0, 0.0])), [0.0, 0.0, 1.0], atol=1e-9)
    points = rest.apply(np.array(obj.model_points_m))
    bottom = points[:, 2].min()
    assert bottom == pytest.approx(-obj.rest_height_m, abs=1e-3)
    # Over 3 cm above the table, the rested drill's width across the barrel is the grip's (at
    # most 45 mm) between the battery and the barrel.
    band = points[np.abs(points[:, 2] - bottom - 0.085) < 0.005]
    assert np.ptp(band[:, 1]) < 0.045
    assert np.all(band[:, 0] < 0.0)  # behind the chuck's side: the barrel ends at +93 mm
    _assert_rests(obj)


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_mujoco_body_names_groups_and_inertia(name):
    """The body, joint and geoms have the documented names, groups, mass and inertia."""
    obj = get_object(name)
    model = _scene(obj).compile()
    body = model.body(f"obj_{name}")
    assert model.joint(f"obj_{name}_root").type[0] == mujoco.mjtJoint.mjJNT_FREE
    visual = model.geom(f"obj_{name}_visual")
    assert visual.group[0] == VISUAL_GROUP
    assert visual.contype[0] == 0 and visual.conaffinity[0] == 0
    assert model.mesh(f"obj_{name}_visual").id >= 0
    for k in range(len(obj.collision_meshes)):
        geom = model.geom(f"obj_{name}_collision_{k}")
        assert geom.group[0] == COLLISION_GROUP and geom.contype[0] == 1
        assert geom.bodyid[0] == body.id
    n_geoms = np.count_nonzero(model.geom_bodyid == body.id)
    assert n_geoms == len(obj.collision_meshes) + 1
    assert body.mass[0] == pytest.approx(obj.mass_kg)
    np.testing.assert_allclose(body.ipos, obj.com_m, atol=1e-9)
    np.testing.assert_allclose(
        np.sort(body.inertia), np.linalg.eigvalsh(obj.inertia_kg_m2), rtol=1e-6
    )


def test_add_object_copies_fixed_bodies_and_validation():
    """Second copies need a new body name; fixed bodies have no joint; bad poses raise."""
    obj = get_object("tomato_soup_can")
    spec = mujoco.MjSpec()
    add_object(spec, obj)
    with pytest.raises(InvalidObjectParams, match="already has a body or mesh named"):
        add_object(spec, obj)
    table = spec.worldbody.add_body(name="table", pos=(0, 0, 0.7))
    body = add_object(spec, obj, body_name="can_2", parent=table, free_joint=False)
    assert body.name == "can_2"
    model = spec.compile()
    assert model.njnt == 1
    assert model.geom("can_2_collision_0").bodyid[0] == model.body("can_2").id
    with pytest.raises(InvalidObjectParams, match="pos must be 3 finite numbers"):
        add_object(mujoco.MjSpec(), obj, pos=(0, 0, np.nan))
    with pytest.raises(InvalidObjectParams, match="quat_wxyz must be 4 finite numbers"):
        add_object(mujoco.MjSpec(), obj, quat_wxyz=(0, 0, 0, 0))
    with pytest.raises(InvalidObjectParams, match="body_name must use only letters"):
        add_object(mujoco.MjSpec(), obj, body_name="my can")


# Import of user meshes --------------------------------------------------------------------------

BOX_SIZE = (0.05, 0.08, 0.03)


def _write(tmp_path, mesh: trimesh.Trimesh, filename: str):
    path = tmp_path / filename
    mesh.export(path)
    return path


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply", ".glb"])
def test_load_object_round_trip_of_a_box(tmp_path, suffix):
    """A box written by trimesh comes back with its size, mass, inertia and compiles."""
    box = trimesh.creation.box(BOX_SIZE)
    box.apply_translation((0.01, 0.0, 0.0))
    path = _write(tmp_path, box, f"box{suffix}")
    obj = load_object(path, name="box", mass_kg=0.2, decomposition="convex_hull", seed=1)
    assert isinstance(obj, YCBObject) and obj.ycbv_id is None
    np.testing.assert_allclose(obj.extents_m, BOX_SIZE, atol=1e-9)
    np.testing.assert_allclose(obj.com_m, (0.01, 0.0, 0.0), atol=1e-9)
    a, b, c = BOX_SIZE
    expected = 0.2 / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    np.testing.assert_allclose(obj.inertia_kg_m2, expected, atol=1e-12)
    assert obj.diameter_m == pytest.approx(np.linalg.norm(BOX_SIZE))
    assert len(obj.collision_meshes) == 1 and obj.collision_meshes[0].is_convex
    assert np.max(_distance_to_mesh(_subsample(obj.model_points_m), obj.visual_mesh, 1e-4)) < 1e-9
    assert obj.corners_m[0] == pytest.approx((-0.015, -0.04, -0.015))
    _assert_rests(obj)


def test_load_object_scale_and_recenter(tmp_path):
    """Scale converts file units to metres; recenter moves the bbox centre to the origin."""
    box = trimesh.creation.box([1000 * s for s in BOX_SIZE])
    box.apply_translation((20.0, 0.0, 0.0))
    path = _write(tmp_path, box, "box_mm.stl")
    kept = load_object(path, name="box", mass_kg=0.1, scale=0.001, decomposition="convex_hull")
    np.testing.assert_allclose(kept.extents_m, BOX_SIZE, atol=1e-9)
    np.testing.assert_allclose(kept.visual_mesh.bounds.mean(axis=0), (0.02, 0, 0), atol=1e-9)
    moved = load_object(
        path, name="box", mass_kg=0.1, scale=0.001, recenter=True, decomposition="convex_hull"
    )
    np.testing.assert_allclose(moved.visual_mesh.bounds.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(moved.collision_meshes[0].bounds.mean(axis=0), 0.0, atol=1e-12)


def test_load_object_falls_back_to_the_convex_hull_without_coacd(tmp_path, monkeypatch):
    """Without CoACD, "auto" warns and uses the hull; "coacd" raises with an install hint."""
    monkeypatch.setitem(sys.modules, "coacd", None)
    ring = trimesh.creation.annulus(r_min=0.02, r_max=0.04, height=0.02, sections=24)
    path = _write(tmp_path, ring, "ring.stl")
    with pytest.warns(MeshImportWarning, match="coacd is not installed.*convex hull"):
        obj = load_object(path, name="ring", mass_kg=0.1)
    assert len(obj.collision_meshes) == 1
    with pytest.raises(InvalidObjectParams, match=r"needs the coacd package \(pip install coacd\)"):
        load_object(path, name="ring", mass_kg=0.1, decomposition="coacd")


@pytest.mark.skipif(not HAVE_COACD, reason="coacd is not installed")
def test_load_object_decomposes_a_ring_with_coacd(tmp_path):
    """CoACD splits a ring into convex pieces and keeps its hole free."""
    ring = trimesh.creation.annulus(r_min=0.02, r_max=0.04, height=0.02, sections=24)
    path = _write(tmp_path, ring, "ring.stl")
    obj = load_object(path, name="ring", mass_kg=0.1, decomposition="coacd")
    assert len(obj.collision_meshes) > 1
    assert all(p.is_convex for p in obj.collision_meshes)
    for piece in obj.collision_meshes:
        assert _plane_distance(np.zeros((1, 3)), piece)[0] > 0


def test_load_object_uses_the_hull_for_the_mass_of_an_open_mesh(tmp_path):
    """An open mesh (a tube without caps) warns and takes its mass properties from its hull."""
    tube = trimesh.creation.cylinder(radius=0.02, height=0.05, sections=32)
    keep = np.abs(tube.face_normals[:, 2]) < 0.5
    tube.update_faces(keep)
    tube.remove_unreferenced_vertices()
    path = _write(tmp_path, tube, "tube.ply")
    with pytest.warns(MeshImportWarning, match="not watertight"):
        obj = load_object(path, name="tube", mass_kg=0.1, decomposition="convex_hull")
    # PLY stores float32 vertices: compare at that precision.
    hull = trimesh.convex.convex_hull(tube.vertices)
    np.testing.assert_allclose(
        obj.inertia_kg_m2, hull.moment_inertia * 0.1 / hull.volume, rtol=1e-6, atol=1e-15
    )


def _bad_files(tmp_path):
    (tmp_path / "empty.obj").write_text("")
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n")
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n")
    (tmp_path / "box.fbx").write_text("")
    _write(tmp_path, trimesh.creation.box((2.0, 0.1, 0.1)), "huge.stl")
    _write(tmp_path, trimesh.creation.box((0.002, 0.001, 0.001)), "tiny.stl")
    _write(tmp_path, trimesh.creation.box((50.0, 80.0, 30.0)), "millimetres.stl")
    _write(tmp_path, trimesh.creation.box(BOX_SIZE), "box.stl")


@pytest.mark.parametrize(
    ("filename", "kwargs", "error", "match"),
    [
        ("empty.obj", {}, InvalidMesh, "no triangles"),
        ("nan.obj", {}, InvalidMesh, "1 of 4 vertices are not finite"),
        ("flat.obj", {}, InvalidMesh, "the mesh is flat"),
        ("box.fbx", {}, InvalidMesh, r"unsupported mesh format '\.fbx'; supported: \.obj, \.ply"),
        ("missing.stl", {}, InvalidMesh, "no such file"),
        ("huge.stl", {}, InvalidMesh, r"largest extent after scale=1 is 2 m, expected 0.005..1 m"),
        ("tiny.stl", {}, InvalidMesh, "largest extent after scale=1 is 0.002 m"),
        ("millimetres.stl", {}, InvalidMesh, "in millimetres, pass scale=0.001"),
        ("box.stl", {"mass_kg": 0.0}, InvalidObjectParams, "mass_kg must be a finite number > 0"),
        ("box.stl", {"mass_kg": np.nan}, InvalidObjectParams, "mass_kg must be"),
        ("box.stl", {"mass_kg": "1 kg"}, InvalidObjectParams, "mass_kg must be"),
        ("box.stl", {"scale": -1.0}, InvalidObjectParams, "scale must be a finite number > 0"),
        ("box.stl", {"name": "my box"}, InvalidObjectParams, "name must be non-empty and use"),
        (
            "box.stl",
            {"decomposition": "vhacd"},
            InvalidObjectParams,
            r"decomposition must be one of \('auto', 'coacd', 'convex_hull'\), got 'vhacd'",
        ),
        ("box.stl", {"coacd_threshold": 0.0}, InvalidObjectParams, r"coacd_threshold must be in"),
        ("box.stl", {"rest_up": (0, 0, 0)}, InvalidObjectParams, "rest_up must be a finite"),
        (
            "box.stl",
            {"rgba": (1, 0, 0)},
            InvalidObjectParams,
            r"rgba must be 4 numbers in \[0, 1\]",
        ),
        ("box.stl", {"n_model_points": 0}, InvalidObjectParams, "n_model_points must be >= 1"),
    ],
)
def test_load_object_rejects_bad_input(tmp_path, filename, kwargs, error, match):
    """Every invalid file or option raises a HandSimError (and ValueError) that explains it."""
    _bad_files(tmp_path)
    args = {"name": "thing", "mass_kg": 0.1, "decomposition": "convex_hull", **kwargs}
    with pytest.raises(error, match=match) as err:
        load_object(tmp_path / filename, **args)
    assert isinstance(err.value, HandSimError) and isinstance(err.value, ValueError)
