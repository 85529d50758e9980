"""MJCF out: Hand.to_xml / Scene.to_xml / save compile back to the same model."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from handsim.errors import HandSimError
from handsim.hand.model import Hand, HandParams
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import GESTURES, gesture
from handsim.world.mjcf import MjcfError, save_spec, spec_to_xml, write_obj
from handsim.world.registry import get_object
from handsim.world.scene import ObjectPlacement, Scene, SceneSpec

# MuJoCo's XML writer drops trailing zero sizes and its reader fills them with the default
# (sphere sites use size[0] only); a joint equality's unused data[5:] and objtype likewise.
_WRITER_QUIRKS = {"site_size", "eq_data", "eq_objtype", "mesh_pathadr", "names", "paths"}
# Mesh geom frames come from the mesh's inertia, summed in another order: ~1e-16 apart; a
# dof's length scale follows from its body's geom frames (the skin's meshes).
_MESH_FRAME_FIELDS = {"geom_pos", "geom_quat", "bvh_aabb", "dof_length"}


def _numeric_fields(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    fields = {}
    for name in dir(model):
        if name.startswith("_"):
            continue
        value = getattr(model, name)
        if isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
            fields[name] = value
    return fields


def assert_same_model(reference: mujoco.MjModel, loaded: mujoco.MjModel) -> None:
    """Every numeric array equal (mesh geom frames to 1e-12), sizes and masses included."""
    for size in ("nq", "nv", "nu", "nbody", "ngeom", "nsite", "njnt", "neq", "nmesh", "ncam"):
        assert getattr(loaded, size) == getattr(reference, size), size
    np.testing.assert_array_equal(loaded.body_mass, reference.body_mass)
    ref, new = _numeric_fields(reference), _numeric_fields(loaded)
    assert set(ref) == set(new)
    for name, value in ref.items():
        if name in _WRITER_QUIRKS:
            continue
        assert new[name].shape == value.shape, name
        if name in _MESH_FRAME_FIELDS:
            np.testing.assert_allclose(new[name], value, rtol=0, atol=1e-12, err_msg=name)
        else:
            np.testing.assert_array_equal(new[name], value, err_msg=name)
    np.testing.assert_array_equal(loaded.site_size[:, 0], reference.site_size[:, 0])
    for name in range(reference.neq):
        assert loaded.eq(name).name == reference.eq(name).name
    np.testing.assert_array_equal(loaded.eq_data[:, :5], reference.eq_data[:, :5])


def assert_same_kinematics(ref: mujoco.MjModel, new: mujoco.MjModel, qpos: np.ndarray) -> None:
    """Forward kinematics of ``qpos`` (one row per pose) agree within 1e-9."""
    data_ref, data_new = mujoco.MjData(ref), mujoco.MjData(new)
    for q in np.atleast_2d(qpos):
        data_ref.qpos[:] = q
        data_new.qpos[:] = q
        mujoco.mj_kinematics(ref, data_ref)
        mujoco.mj_kinematics(new, data_new)
        for field in ("xpos", "xquat", "geom_xpos", "geom_xmat", "site_xpos", "cam_xpos"):
            np.testing.assert_allclose(
                getattr(data_new, field), getattr(data_ref, field), rtol=0, atol=1e-9
            )


def _hand_poses(hand: Hand, model: mujoco.MjModel) -> np.ndarray:
    binding = hand.bind(model)
    data = mujoco.MjData(model)
    rows = []
    for k, name in enumerate(["open", "fist", "pinch", "ok", "rock"]):
        pose = gesture(name)
        rotvec = np.array([0.3 * k, -0.2, 1.0 - 0.4 * k])
        binding.set_pose(data, HandPose(np.array([0.1 * k, -0.05, 0.2]), rotvec, pose.angles))
        rows.append(data.qpos.copy())
    return np.array(rows)


@pytest.fixture(scope="module")
def objects_scene() -> Scene:
    """Hand, table and four objects (one repeated) at fixed places."""
    names = ("003_cracker_box", "005_tomato_soup_can", "025_mug", "005_tomato_soup_can")
    placements = tuple(
        ObjectPlacement(n, (0.2 * k - 0.3, 0.1, get_object(n).rest_height_m + 5e-4))
        for k, n in enumerate(names)
    )
    return Scene(SceneSpec(objects=placements))


@pytest.mark.parametrize("side", ["right", "left"])
def test_hand_to_xml_compiles_to_the_same_model(side: str) -> None:
    """The default hand of each side: same model, same forward kinematics."""
    hand = Hand(HandParams(side=side))
    reference = hand.compile()
    loaded = mujoco.MjModel.from_xml_string(hand.to_xml())
    assert_same_model(reference, loaded)
    assert_same_kinematics(reference, loaded, _hand_poses(hand, reference))


def test_hand_save_writes_a_file_that_compiles(tmp_path) -> None:
    """Hand.save writes the XML and one OBJ per skin mesh; it compiles to the same model."""
    hand = Hand(HandParams(side="left", hand_length=0.16))
    path = hand.save(tmp_path / "sub" / "left_hand.xml")
    assert path == tmp_path / "sub" / "left_hand.xml"
    model = hand.compile()
    meshes = {f"{model.mesh(i).name}.obj" for i in range(model.nmesh)}
    assert {p.name for p in (tmp_path / "sub" / "assets").iterdir()} == meshes
    assert 'file="assets/lh_' in path.read_text() and "vertex=" not in path.read_text()
    loaded = mujoco.MjModel.from_xml_path(str(path))
    assert_same_model(model, loaded)
    assert_same_model(model, mujoco.MjModel.from_xml_string(hand.to_xml()))


def test_hand_to_xml_documents_names_and_is_deterministic() -> None:
    """The naming comment heads the file; two builds give the same text."""
    hand = Hand()
    xml = hand.to_xml()
    assert xml == Hand().to_xml()
    head = xml.split("<compiler", 1)[0]
    for name in ("rh_index_mcp_flex", "rh_index_mcp_flex_act", "rh_kp_index_tip", "rh_mocap"):
        assert name in head
    model = mujoco.MjModel.from_xml_string(xml)
    for name in hand.joint_names:
        assert model.joint(name).id >= 0
    for name in hand.actuator_names:
        assert model.actuator(name).id >= 0


def test_coupled_dip_hand_keeps_its_couplings() -> None:
    """A non-default hand (coupled DIPs, no forearm) round-trips too."""
    hand = Hand(HandParams(hand_length=0.15, couple_dip=True, forearm=False))
    reference = hand.compile()
    loaded = mujoco.MjModel.from_xml_string(hand.to_xml())
    assert_same_model(reference, loaded)
    assert loaded.nu == 17
    assert_same_kinematics(reference, loaded, _hand_poses(hand, reference))


def test_hand_dynamics_match_after_steps() -> None:
    """Closing the hand into a fist: the two models step alike."""
    hand = Hand()
    reference = hand.compile()
    loaded = mujoco.MjModel.from_xml_string(hand.to_xml())
    datas = [mujoco.MjData(m) for m in (reference, loaded)]
    for model, data in zip((reference, loaded), datas, strict=True):
        hand.bind(model).set_target(data, gesture("fist"))
        for _ in range(100):
            mujoco.mj_step(model, data)
    np.testing.assert_allclose(datas[1].qpos, datas[0].qpos, rtol=0, atol=1e-9)


def test_scene_to_xml_compiles_to_the_same_model(objects_scene: Scene) -> None:
    """A scene with objects, inline meshes."""
    loaded = mujoco.MjModel.from_xml_string(objects_scene.to_xml())
    assert_same_model(objects_scene.model, loaded)
    assert_same_kinematics(objects_scene.model, loaded, objects_scene.data.qpos)


def test_scene_save_writes_xml_and_obj_assets(objects_scene: Scene, tmp_path) -> None:
    """Scene.save: XML plus one OBJ per mesh; same model and kinematics from the file."""
    path = objects_scene.save(tmp_path / "scene.xml")
    meshes = sorted(p.name for p in (tmp_path / "assets").iterdir())
    assert meshes == sorted(
        f"{objects_scene.model.mesh(i).name}.obj" for i in range(objects_scene.model.nmesh)
    )
    xml = path.read_text()
    assert 'file="assets/' in xml and str(tmp_path) not in xml
    assert "vertex=" not in xml
    loaded = mujoco.MjModel.from_xml_path(str(path))
    assert_same_model(objects_scene.model, loaded)
    # Several poses: the scene's reset state and objects moved and turned.
    rng = np.random.default_rng(0)
    qpos = np.tile(objects_scene.data.qpos, (4, 1))
    for body, _ in objects_scene.objects:
        adr = objects_scene.model.jnt_qposadr[objects_scene.model.body(body).jntadr[0]]
        qpos[1:, adr : adr + 3] += rng.uniform(-0.05, 0.05, (3, 3))
        quat = rng.normal(size=(3, 4))
        qpos[1:, adr + 3 : adr + 7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    assert_same_kinematics(objects_scene.model, loaded, qpos)
    # Meshes are the object's float32 vertices, exactly.
    mug = get_object("025_mug")
    mesh = loaded.mesh("obj_025_mug_visual")
    assert mesh.vertnum[0] == len(mug.visual_mesh.vertices)


def test_scene_save_steps_like_the_scene(objects_scene: Scene, tmp_path) -> None:
    """From the same full state, 50 steps with contacts agree."""
    path = objects_scene.save(tmp_path / "scene.xml")
    loaded = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(loaded)
    mujoco.mj_setState(
        loaded, data, _full_state(objects_scene), mujoco.mjtState.mjSTATE_FULLPHYSICS
    )
    reference = mujoco.MjData(objects_scene.model)
    mujoco.mj_setState(
        objects_scene.model,
        reference,
        _full_state(objects_scene),
        mujoco.mjtState.mjSTATE_FULLPHYSICS,
    )
    for _ in range(50):
        mujoco.mj_step(objects_scene.model, reference)
        mujoco.mj_step(loaded, data)
    np.testing.assert_allclose(data.qpos, reference.qpos, rtol=0, atol=1e-9)


def _full_state(scene: Scene) -> np.ndarray:
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty(mujoco.mj_stateSize(scene.model, spec))
    mujoco.mj_getState(scene.model, scene.data, state, spec)
    return state


def test_spec_to_xml_prints_full_precision() -> None:
    """Numbers are shortest round-trip decimals; MuJoCo default restored."""
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name="b", pos=[1 / 3, 0.1, 1e-17])
    body.add_geom(name="g", size=[np.pi / 10, 0, 0], rgba=[0.1, 0.2, 0.3, 1.0])
    xml = spec_to_xml(spec)
    assert 'pos="0.3333333333333333 0.1 1e-17"' in xml
    assert 'rgba="0.1 0.2 0.3 1"' in xml  # float32 attributes: shortest float32 decimals
    model = mujoco.MjModel.from_xml_string(xml)
    assert model.body_pos[1, 0] == 1 / 3
    assert model.geom_size[0, 0] == np.pi / 10
    # MuJoCo's own setting is restored afterwards.
    assert 'pos="0.333333 0.1 ' in spec.to_xml()


def test_write_obj_round_trips_float32_vertices(tmp_path) -> None:
    """OBJ lines are the float32 shortest decimals and 1-based faces."""
    rng = np.random.default_rng(1)
    vertices = rng.normal(scale=0.05, size=(4, 3))
    faces = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
    write_obj(tmp_path / "t.obj", vertices, faces)
    spec = mujoco.MjSpec()
    spec.meshdir = str(tmp_path)
    spec.add_mesh(name="t", file="t.obj")
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname="t")
    spec.compiler.degree = False
    model = spec.compile()
    assert model.mesh_vertnum[0] == 4
    lines = (tmp_path / "t.obj").read_text().splitlines()
    assert lines[0] == "v " + " ".join(str(v) for v in vertices[0].astype(np.float32))
    assert lines[4:] == ["f 1 2 3", "f 1 4 2", "f 1 3 4", "f 2 4 3"]


def test_save_spec_refuses_file_meshes_and_bad_assets_dir(tmp_path) -> None:
    """Clear errors for what save_spec cannot write."""
    spec = mujoco.MjSpec()
    spec.add_mesh(name="m", file="somewhere.stl")
    with pytest.raises(MjcfError, match="mesh 'm' is not built in memory"):
        save_spec(spec, tmp_path / "x.xml")
    with pytest.raises(MjcfError, match="assets_dir must be a non-empty relative folder name"):
        save_spec(mujoco.MjSpec(), tmp_path / "x.xml", assets_dir="/abs")
    assert issubclass(MjcfError, HandSimError) and issubclass(MjcfError, ValueError)


def test_gestures_used_here_exist() -> None:
    """The gestures the poses above use are registered."""
    assert {"open", "fist", "pinch", "ok", "rock"} <= set(GESTURES)
