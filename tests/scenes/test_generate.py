"""The committed MJCF assets in scenes/: in sync with the generator, complete, and usable."""

from __future__ import annotations

import fnmatch
import importlib.resources
import pathlib
import re

import mujoco
import numpy as np
import pytest

from handsim.hand.pose import JOINT_NAMES
from handsim.hand.pose_sources import GESTURES, gesture
from handsim.scenes.generate import GRASP_OBJECT, PARTS, generate
from handsim.world.registry import OBJECT_NAMES

SCENES = pathlib.Path(str(importlib.resources.files("handsim.scenes")))
FAST_OBJECTS = ("003_cracker_box", "005_tomato_soup_can", "025_mug")
_REGENERATE_HINT = "scenes/ is out of date: run `python -m handsim.scenes` and commit the result"


def _committed_files() -> set[pathlib.Path]:
    return {
        p.relative_to(SCENES)
        for p in SCENES.rglob("*")
        if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts
    }


def _require_generating_mujoco() -> None:
    match = re.search(r"Generated with MuJoCo (\S+),", (SCENES / "README.md").read_text())
    assert match, "scenes/README.md must name the MuJoCo version the files were made with"
    if match.group(1) != mujoco.__version__:
        pytest.skip(
            f"scenes/ was generated with MuJoCo {match.group(1)}; installed: "
            f"{mujoco.__version__} (its XML writer may format differently)"
        )


def _assert_identical(files: list[pathlib.Path], root: pathlib.Path) -> None:
    for path in files:
        relative = path.relative_to(root)
        committed = SCENES / relative
        assert committed.is_file(), f"{relative} is not committed; {_REGENERATE_HINT}"
        assert committed.read_bytes() == path.read_bytes(), f"{relative}: {_REGENERATE_HINT}"


def _scene_files() -> list[pathlib.Path]:
    return sorted(SCENES.rglob("scene*.xml"))


def test_regenerating_hands_grasp_and_some_objects_gives_the_committed_bytes(tmp_path) -> None:
    """Fast sync check: both hands, the grasp scene and three objects."""
    _require_generating_mujoco()
    files = generate(tmp_path, objects=FAST_OBJECTS)
    assert len(files) == len(set(files))
    _assert_identical(files, tmp_path)


@pytest.mark.slow
def test_regenerating_everything_gives_exactly_the_committed_files(tmp_path) -> None:
    """Full sync check (~30 s: builds all 21 objects): same file set, same bytes."""
    _require_generating_mujoco()
    files = generate(tmp_path)
    assert {p.relative_to(tmp_path) for p in files} == _committed_files()
    _assert_identical(files, tmp_path)


def test_generation_is_deterministic(tmp_path) -> None:
    """Two runs write the same bytes (independent of the committed files)."""
    first = generate(tmp_path / "a", parts=("hand",))
    second = generate(tmp_path / "b", parts=("hand",))
    assert [p.relative_to(tmp_path / "a") for p in first] == [
        p.relative_to(tmp_path / "b") for p in second
    ]
    for a, b in zip(first, second, strict=True):
        assert a.read_bytes() == b.read_bytes()


def test_generate_rejects_unknown_parts(tmp_path) -> None:
    """The error lists the valid parts."""
    with pytest.raises(ValueError, match=r"unknown parts \['hands'\]; valid parts: hand, objects"):
        generate(tmp_path, parts=("hands",))
    assert PARTS == ("hand", "objects", "grasp")


def test_every_folder_has_its_required_files() -> None:
    """Menagerie layout: README per folder, model + scene per asset, the 21 objects."""
    files = _committed_files()
    for folder in ("", "hand", "objects", "grasp"):
        assert pathlib.Path(folder, "README.md") in files
    for side in ("right", "left"):
        for name in (f"{side}_hand.xml", f"scene_{side}.xml", f"keyframes_{side}.xml"):
            assert pathlib.Path("hand", name) in files
    assert pathlib.Path("grasp", "scene.xml") in files
    folders = sorted(p.name for p in (SCENES / "objects").iterdir() if p.is_dir())
    assert folders == sorted(OBJECT_NAMES)
    for name in OBJECT_NAMES:
        assert pathlib.Path("objects", name, f"{name}.xml") in files
        assert pathlib.Path("objects", name, "scene.xml") in files


def test_assets_folders_hold_exactly_the_meshes_the_xml_uses() -> None:
    """No missing and no stray mesh files; no mesh file written by two models."""
    for assets in sorted(SCENES.rglob("assets")):
        used: list[str] = []
        for xml in sorted(assets.parent.glob("*.xml")):
            files = re.findall(r'<mesh [^>]*file="([^"]+)"', xml.read_text())
            assert all(u.startswith("assets/") for u in files), xml
            used += files
        assert len(used) == len(set(used)), f"a mesh in {assets} is used by two models"
        assert set(used) == {f"assets/{p.name}" for p in assets.iterdir()}, assets


def test_package_data_covers_every_committed_file() -> None:
    """pyproject.toml's package-data globs for handsim.scenes match every file in scenes/."""
    tomllib = pytest.importorskip("tomllib")
    pyproject = SCENES.parent / "pyproject.toml"
    if not pyproject.is_file():
        pytest.skip("not a source checkout")
    config = tomllib.loads(pyproject.read_text())
    globs = config["tool"]["setuptools"]["package-data"]["handsim.scenes"]
    for path in _committed_files():
        assert any(
            fnmatch.fnmatch(path.as_posix(), g) or fnmatch.fnmatch(path.name, g.split("/")[-1])
            for g in globs
        ), path


@pytest.mark.parametrize("path", _scene_files(), ids=lambda p: p.relative_to(SCENES).as_posix())
def test_every_scene_compiles_and_steps_one_second_without_warnings(path) -> None:
    """Each scene loads from its file, steps 1 s under noisy control, and warns about nothing."""
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    steps = round(1.0 / model.opt.timestep)
    lo, hi = model.actuator_ctrlrange.T
    for k in range(steps):
        if model.nu and k % 50 == 0:
            data.ctrl[:] = lo + rng.uniform(0.2, 0.8, model.nu) * (hi - lo)
        mujoco.mj_step(model, data)
    assert all(w.number == 0 for w in data.warning), [w.number for w in data.warning]
    assert np.all(np.isfinite(data.qpos))


@pytest.mark.parametrize("path", _scene_files(), ids=lambda p: p.relative_to(SCENES).as_posix())
def test_no_element_is_unnamed(path) -> None:
    """Bodies, joints, geoms, sites, actuators, meshes, cameras and lights all have names."""
    model = mujoco.MjModel.from_xml_path(str(path))
    for kind, count in (
        ("body", model.nbody),
        ("joint", model.njnt),
        ("geom", model.ngeom),
        ("site", model.nsite),
        ("actuator", model.nu),
        ("mesh", model.nmesh),
        ("camera", model.ncam),
        ("light", model.nlight),
    ):
        for i in range(1 if kind == "body" else 0, count):
            assert getattr(model, kind)(i).name, f"{path.name}: unnamed {kind} {i}"


@pytest.mark.parametrize("name", OBJECT_NAMES)
def test_objects_rest_on_the_floor(name) -> None:
    """Each object stays where it starts (< 1 mm, < 1 deg in 1 s): it rests on the floor.

    Neither falling nor being pushed out of the floor means its rest pose touches ``z = 0``.
    """
    model = mujoco.MjModel.from_xml_path(str(SCENES / "objects" / name / "scene.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    body = model.body(f"obj_{name}").id
    pos0, quat0 = data.xpos[body].copy(), data.xquat[body].copy()
    for _ in range(round(1.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    assert np.linalg.norm(data.xpos[body] - pos0) < 1e-3
    angle = 2 * np.arccos(min(1.0, abs(float(np.dot(data.xquat[body], quat0)))))
    assert np.rad2deg(angle) < 1.0


@pytest.mark.parametrize("side", ["right", "left"])
def test_hand_keyframes_are_the_gestures(side) -> None:
    """Loading keyframe ``<gesture>`` puts the gesture's angles in qpos and ctrl."""
    model = mujoco.MjModel.from_xml_path(str(SCENES / "hand" / f"scene_{side}.xml"))
    data = mujoco.MjData(model)
    prefix = "rh_" if side == "right" else "lh_"
    assert model.nkey == len(GESTURES)
    for name in GESTURES:
        mujoco.mj_resetDataKeyframe(model, data, model.key(name).id)
        angles = [data.qpos[model.joint(prefix + j).qposadr[0]] for j in JOINT_NAMES]
        np.testing.assert_allclose(angles, gesture(name).angles, rtol=0, atol=1e-12)
        ctrl = [data.ctrl[model.actuator(f"{prefix}{j}_act").id] for j in JOINT_NAMES]
        np.testing.assert_allclose(ctrl, gesture(name).angles, rtol=0, atol=1e-12)


def test_grasp_scene_starts_with_the_hand_above_the_table() -> None:
    """The hand's root and mocap start at Scene.reset()'s pose; the object rests on the table."""
    model = mujoco.MjModel.from_xml_path(str(SCENES / "grasp" / "scene.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    palm = model.body("rh_palm").id
    np.testing.assert_allclose(data.xpos[palm], [0.0, -0.1, 0.12], atol=1e-12)
    np.testing.assert_allclose(data.mocap_pos[0], [0.0, -0.1, 0.12], atol=1e-12)
    obj = model.body(f"obj_{GRASP_OBJECT}").id
    for _ in range(250):
        mujoco.mj_step(model, data)
    assert data.xpos[obj][2] > 0.05  # still on the table top, not fallen through
    assert model.camera("third_person").id >= 0
