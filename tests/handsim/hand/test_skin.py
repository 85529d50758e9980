"""The skin: closed meshes per body, joints without gaps, volume kept, close to the collision."""

import os
import subprocess
import sys

import mujoco
import numpy as np
import pytest
import trimesh

from handsim.errors import InvalidHandParams
from handsim.frame import FrameRenderer
from handsim.hand.model import FOREARM_GEOM, UPPER_ARM_GEOM, Hand, HandParams
from handsim.hand.pose import DIGITS, JOINT_LIMITS, JOINT_NAMES, HandPose
from handsim.hand.pose_sources import gesture
from handsim.hand.skin import build_skin, skin_deviation_m
from handsim.hand.skin_measure import collision_gap_m, digit_volume_m3, joint_crease_depth_m
from handsim.world.camera import camera_preset
from handsim.world.scene import SEGMENT_LABELS, CameraSpec, Scene, SceneSpec


def _posed(params: HandParams | None = None):
    hand = Hand(params)
    model = hand.compile()
    return hand.bind(model), mujoco.MjData(model)


@pytest.mark.parametrize(
    "params",
    [HandParams(), HandParams(side="left", hand_length=0.15, thickness_scale=0.7, forearm=False)],
)
def test_every_part_is_a_closed_outward_mesh_on_its_signed_distance(params):
    """One closed, outward-wound mesh per body whose vertices lie on its zero set."""
    parts = build_skin(params)
    assert [p.body for p in parts] == list(range(16))
    for part in parts:
        mesh = trimesh.Trimesh(part.vertices, part.faces, process=False)
        # Closed: every edge borders an even number of faces (surface nets may pinch two
        # sheets at an edge on the palm; the phalanges are exact 2-manifolds).
        edges = np.sort(mesh.edges, axis=1)
        _, uses = np.unique(edges, axis=0, return_counts=True)
        assert np.all(uses % 2 == 0)
        assert mesh.is_watertight or part.body == 0
        assert mesh.volume > 0
        assert np.abs(part.sdf(part.vertices)).max() < 1e-5


def test_left_skin_is_the_mirror_of_the_right():
    """Left vertices and distances are the right hand's mirrored through x = 0."""
    right, left = build_skin(HandParams()), build_skin(HandParams(side="left"))
    for r, lf in zip(right, left, strict=True):
        np.testing.assert_array_equal(lf.vertices, r.vertices * [-1.0, 1.0, 1.0])
        np.testing.assert_array_equal(lf.sdf(r.vertices * [-1.0, 1.0, 1.0]), r.sdf(r.vertices))


def test_surface_selects_the_visual_geoms_and_keeps_the_collision_geoms():
    """Skin: one mesh per body in group 2; capsules: the old copies. Collision is identical."""
    skin, caps = (Hand(HandParams(surface=s)).compile() for s in ("skin", "capsules"))

    def geoms(model, group):
        return {
            model.geom(i).name: (int(model.geom_type[i]), tuple(np.round(model.geom_size[i], 9)))
            for i in range(model.ngeom)
            if model.geom_group[i] == group
        }

    assert geoms(skin, 3) == geoms(caps, 3)
    # The arm beyond the palm's stub is drawn the same by both: a mesh and a capsule.
    arm = {"rh_" + FOREARM_GEOM, "rh_" + UPPER_ARM_GEOM}
    assert {n: v for n, v in geoms(skin, 2).items() if n in arm} == {
        n: v for n, v in geoms(caps, 2).items() if n in arm
    }
    visual = {n: v for n, v in geoms(skin, 2).items() if n not in arm}
    assert len(visual) == 16 and skin.nmesh == 17  # the skin's, and the forearm's
    assert all(t == mujoco.mjtGeom.mjGEOM_MESH for t, _ in visual.values())
    assert all(
        t != mujoco.mjtGeom.mjGEOM_MESH for n, (t, _) in geoms(caps, 2).items() if n not in arm
    )
    for i in np.nonzero(skin.geom_group == 2)[0]:
        assert skin.geom_contype[i] == 0 and skin.geom_conaffinity[i] == 0


def test_compiled_meshes_sit_where_the_skin_says():
    """MuJoCo recentres meshes; the drawn vertices still match the skin in the body frames."""
    binding, data = _posed()
    model = binding.model
    binding.set_pose(data, gesture("fist"))
    for part in build_skin(binding.hand.params):
        name = binding.hand.prefix + binding.hand.skeleton.bodies[part.body].name
        geom = model.geom(f"{name}_visual_0")
        mesh = model.mesh(f"{name}_visual_0")
        vert = model.mesh_vert[mesh.vertadr[0] : mesh.vertadr[0] + mesh.vertnum[0]]
        drawn = vert @ data.geom_xmat[geom.id].reshape(3, 3).T + data.geom_xpos[geom.id]
        body = model.body(name).id
        want = part.vertices @ data.xmat[body].reshape(3, 3).T + data.xpos[body]
        assert drawn.shape == want.shape
        np.testing.assert_allclose(np.sort(drawn, axis=0), np.sort(want, axis=0), atol=1e-7)


def test_invalid_surface_is_rejected():
    """An unknown surface names the valid ones."""
    with pytest.raises(InvalidHandParams, match="surface must be one of 'skin', 'capsules'"):
        HandParams(surface="mesh")


def _random_poses(n: int, seed: int = 0) -> list[HandPose]:
    rng = np.random.default_rng(seed)
    lo, hi = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
    poses = [HandPose.neutral().replace(angles=rng.uniform(lo, hi)) for _ in range(n)]
    return poses + [HandPose.neutral().replace(angles=a) for a in (lo, hi)]


@pytest.mark.parametrize("side", ["right", "left"])
def test_no_gap_or_step_deeper_than_3_mm_at_any_in_limit_pose(side):
    """Every segment's base stays inside its parent's skin (random poses and both limit sets)."""
    binding, data = _posed(HandParams(side=side))
    worst = 0.0
    for pose in _random_poses(30):
        binding.set_pose(data, pose)
        worst = max(worst, joint_crease_depth_m(binding, data).max())
    assert worst < 3e-3
    # Measured: under 0.2 mm (the tessellation of the envelopes).
    assert worst < 5e-4


@pytest.mark.parametrize("digit", DIGITS)
def test_finger_volume_is_kept_over_the_flexion_range(digit):
    """The union of a digit's segments keeps its volume within 10 % from extension to flexion."""
    binding, data = _posed()
    flex = [
        i
        for i, n in enumerate(JOINT_NAMES)
        if n.startswith(digit) and n.endswith(("flex", "ip_flex"))
    ]
    volumes = []
    for t in np.linspace(0.0, 1.0, 5):
        angles = np.zeros(len(JOINT_NAMES))
        angles[flex] = JOINT_LIMITS[flex, 0] + t * (JOINT_LIMITS[flex, 1] - JOINT_LIMITS[flex, 0])
        binding.set_pose(data, HandPose.neutral().replace(angles=angles))
        volumes.append(digit_volume_m3(binding, data, digit))
    change = np.array(volumes) / volumes[0] - 1.0
    assert np.abs(change).max() < 0.10, change


@pytest.mark.parametrize("name", ["open", "fist", "pinch"])
def test_skin_follows_the_collision_surface_on_pads_and_palm(name):
    """Palmar skin of the phalanges and of the palm lies within 2 mm of the collision surface."""
    binding, data = _posed()
    binding.set_pose(data, gesture(name))
    gap = collision_gap_m(binding, data)
    assert len(gap["pads"]) > 500 and len(gap["palm"]) > 500
    assert gap["pads"].max() < 2e-3
    assert gap["palm"].max() < 2e-3


# The far corner of the parameter range: the longest, broadest and thickest hand.
_LARGEST = HandParams(hand_length=0.235, palm_breadth=0.55 * 0.235, thickness_scale=1.4)


@pytest.mark.parametrize(
    "params",
    [
        HandParams(hand_length=0.14, palm_breadth=0.35 * 0.14, thickness_scale=0.7),
        HandParams(hand_length=0.235, palm_breadth=0.55 * 0.235, thickness_scale=1.2),
        HandParams(hand_length=0.235, thickness_scale=1.4),
        _LARGEST,
        HandParams(side="left", forearm=False),
    ],
)
def test_skin_follows_the_collision_surface_for_extreme_hands(params):
    """The 2 mm bound holds for small and large hands too (flat hand), the thumb included."""
    binding, data = _posed(params)
    binding.set_pose(data, HandPose.neutral())
    gap = collision_gap_m(binding, data)
    assert gap["pads"].max() < 2e-3 and gap["palm"].max() < 2e-3
    thumb = collision_gap_m(binding, data, parts=("thumb",))
    assert len(thumb["pads"]) > 100 and thumb["pads"].max() < 2e-3


@pytest.mark.parametrize("name", ["fist", "pinch", "ok"])
def test_thumb_skin_follows_the_collision_surface_on_the_largest_hand(name):
    """On the largest, thickest hand the thumb's pads stay within 2 mm in contact gestures.

    Measured: the thumb's pads at most 1.94 mm (the fingertip pad, 12 % wider than deep),
    the palm at most 1.8 mm.
    """
    binding, data = _posed(_LARGEST)
    binding.set_pose(data, gesture(name))
    gap = collision_gap_m(binding, data)
    assert gap["pads"].max() < 2e-3 and gap["palm"].max() < 2e-3
    assert collision_gap_m(binding, data, parts=("thumb",))["pads"].max() < 2e-3


def test_largest_hand_has_no_gap_and_keeps_the_thumb_volume():
    """The joint and volume checks hold on the largest, thickest hand too (thumb included)."""
    binding, data = _posed(_LARGEST)
    worst = 0.0
    for pose in _random_poses(8, seed=1):
        binding.set_pose(data, pose)
        worst = max(worst, joint_crease_depth_m(binding, data).max())
    assert worst < 5e-4
    flex = [i for i, n in enumerate(JOINT_NAMES) if n.startswith("thumb") and "flex" in n]
    volumes = []
    for t in (0.0, 1.0):
        angles = np.zeros(len(JOINT_NAMES))
        angles[flex] = JOINT_LIMITS[flex, 0] + t * (JOINT_LIMITS[flex, 1] - JOINT_LIMITS[flex, 0])
        binding.set_pose(data, HandPose.neutral().replace(angles=angles))
        volumes.append(digit_volume_m3(binding, data, "thumb", samples=100_000))
    assert abs(volumes[1] / volumes[0] - 1.0) < 0.10


def test_segmentation_shows_every_hand_part_on_the_skin():
    """A flat hand seen from the palm side: palm and five digits in the labels, all visible."""
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_matrix(np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T)
    pose = gesture("open").replace(
        wrist_pos=np.array([0.0, 0.5, 0.1]), wrist_rotvec=rot.as_rotvec()
    )
    cam = CameraSpec.look_at("front", camera_preset("icvl"), (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    assert scene.hand.params.surface == "skin"
    scene.reset(pose)
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0))
    labels = set(np.unique(frame.segmentation).tolist())
    for part in ("palm", *DIGITS):
        assert SEGMENT_LABELS.index(part) in labels, part
    assert frame.visible.all()


@pytest.mark.parametrize(
    "params", [HandParams(), HandParams(side="left", hand_length=0.15, forearm=False)]
)
def test_coarse_skin_samples_the_same_surface_with_a_quarter_of_the_triangles(params):
    """The coarse level: the same bodies, closed meshes on the same zero sets, 1/4 the triangles."""
    full, coarse = build_skin(params), build_skin(params, "coarse")
    assert [p.body for p in coarse] == [p.body for p in full]
    for part, fine in zip(coarse, full, strict=True):
        edges = np.sort(trimesh.Trimesh(part.vertices, part.faces, process=False).edges, axis=1)
        assert np.all(np.unique(edges, axis=0, return_counts=True)[1] % 2 == 0)
        # Its vertices lie on the full part's surface (the same signed distance).
        assert np.abs(fine.sdf(part.vertices)).max() < 1e-5
    ratio = sum(len(p.faces) for p in coarse) / sum(len(p.faces) for p in full)
    assert 0.2 < ratio < 0.3


def test_skin_deviation_is_about_a_millimetre_and_zero_at_full_detail():
    """The coarse level strays by at most about a millimetre (where the palm's grid falls)."""
    for length_m in (0.15, 0.189, 0.22):
        assert 0.0003 < skin_deviation_m(HandParams(hand_length=length_m)) < 0.002
    assert skin_deviation_m(HandParams(), "full") == 0.0
    with pytest.raises(InvalidHandParams, match=r"one of 'full', 'coarse'; received 'fine'"):
        build_skin(HandParams(), "fine")


def test_a_palm_kept_on_disk_is_the_one_meshed_and_a_damaged_file_is_remade(tmp_path, monkeypatch):
    """The palm's mesh read back from the disk cache is bitwise the mesh made; junk is ignored."""
    import handsim.hand.skin as skin

    monkeypatch.setattr(skin, "_CACHE_DIR", tmp_path)
    shape = HandParams(hand_length=0.17, surface="capsules")
    made = skin._right_parts.__wrapped__(shape, "coarse")[0]
    (kept_file,) = tmp_path.glob("palm-*.npz")
    kept = skin._right_parts.__wrapped__(shape, "coarse")[0]
    np.testing.assert_array_equal(kept.vertices, made.vertices)
    np.testing.assert_array_equal(kept.faces, made.faces)
    assert kept.faces.dtype == made.faces.dtype
    kept_file.write_bytes(b"not a mesh")
    remade = skin._right_parts.__wrapped__(shape, "coarse")[0]
    np.testing.assert_array_equal(remade.vertices, made.vertices)
    # Another hand is another file.
    skin._right_parts.__wrapped__(HandParams(hand_length=0.18, surface="capsules"), "coarse")
    assert len(list(tmp_path.glob("palm-*.npz"))) == 2
    # Beyond _CACHE_FILES the least recently made go.
    monkeypatch.setattr(skin, "_CACHE_FILES", 1)
    newest = skin._right_parts.__wrapped__(
        HandParams(hand_length=0.19, surface="capsules"), "coarse"
    )
    (left,) = tmp_path.glob("palm-*.npz")
    with np.load(left) as kept:
        np.testing.assert_array_equal(kept["vertices"], newest[0].vertices)


def test_a_palm_is_kept_per_blas_kernel(tmp_path, monkeypatch):
    """Other BLAS kernels round differently: a palm made with them is another file."""
    import handsim.hand.skin as skin
    from handsim.hand.blas import blas_kernels

    assert blas_kernels().split(",")[0].count(":") == 1  # e.g. openblas:Haswell
    monkeypatch.setattr(skin, "_CACHE_DIR", tmp_path)
    shape = HandParams(hand_length=0.17, surface="capsules")
    for kernels in ("openblas:Haswell", "openblas:SkylakeX", "openblas:Haswell"):
        monkeypatch.setattr(skin, "blas_kernels", lambda kernels=kernels: kernels)
        skin._right_parts.__wrapped__(shape, "coarse")
    assert len(list(tmp_path.glob("palm-*.npz"))) == 2


def test_a_palm_made_with_haswell_kernels_differs_from_the_default_ones():
    """Why the kernels are in the key: on an AVX-512 CPU the two palms differ in the last bit."""
    code = (
        "import hashlib, pathlib, tempfile; import handsim.hand.skin as skin; "
        "from handsim.hand import HandParams; "
        "skin._CACHE_DIR = pathlib.Path(tempfile.mkdtemp()); "
        "p = skin._right_parts.__wrapped__(HandParams(hand_length=0.17, surface='capsules'), "
        "'coarse')[0]; from handsim.hand.blas import blas_kernels; "
        "print(blas_kernels(), hashlib.sha256(p.vertices.tobytes()).hexdigest())"
    )
    out = {}
    for coretype in ("Haswell", None):
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if coretype:
            env["OPENBLAS_CORETYPE"] = coretype
        run = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
        )
        out[coretype] = run.stdout.split()
    if out["Haswell"][0] == out[None][0]:
        pytest.skip(f"this CPU's default kernels are Haswell's ({out[None][0]})")
    assert out["Haswell"][1] != out[None][1]


def test_the_measures_stay_importable_from_skin():
    """The measuring functions moved to skin_measure; the old import path gives the same ones."""
    import handsim.hand.skin as skin
    import handsim.hand.skin_measure as skin_measure
    from handsim.hand.skin import collision_gap_m as old_path

    assert old_path is skin_measure.collision_gap_m
    for name in skin_measure.__all__:
        assert getattr(skin, name) is getattr(skin_measure, name), name
    with pytest.raises(AttributeError, match="has no attribute 'no_such_measure'"):
        _ = skin.no_such_measure
