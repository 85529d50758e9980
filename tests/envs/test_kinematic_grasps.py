"""The 'grasp' frame source: kinematic frames of planned grasps, in contact, without overlap."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from handsim.data.config import PRESETS, CannotDraw, GenerationConfig, InvalidGenerationConfig
from handsim.data.generation import generate, generate_shard
from handsim.data.manifest import Manifest
from handsim.data.shards import ShardReader
from handsim.envs import kinematic_grasps
from handsim.envs.grasping import GraspPlanningError
from handsim.envs.kinematic_grasps import (
    MAX_GRASP_PENETRATION_M,
    TOUCH_DEPTH_M,
    GraspSource,
    _depths,
)
from handsim.world.registry import OBJECTS

# One can, a few frames an episode, noise-free depth: planning and closing dominate.
TINY = {
    "source": "grasp",
    "frames": 6,
    "frames_per_shard": 6,
    "frames_per_episode": 3,
    "sensor": "none",
    "num_objects_range": (1, 1),
    "objects": ("005_tomato_soup_can",),
}


def _frames(source: GraspSource, seed: int, episodes: int, frames: int):
    """(arrays, deepest overlap in m) of the frames of a few episodes, measured as made.

    Episodes that cannot be drawn are redrawn from the same generator, as a shard does.
    """
    rng = np.random.default_rng(seed)
    out, done = [], 0
    for _ in range(10 * episodes):
        try:
            for arrays in source.episode(rng, lambda ratio, visible: True, frames):
                scene = next(reversed(source._scenes.values()))[0]  # the episode's scene
                out.append((arrays, _depths(scene, scene.binding.pose(scene.data))[1]))
        except CannotDraw:
            continue
        done += 1
        if done == episodes:
            break
    return out


def test_grasp_frames_touch_the_object_without_entering_it():
    """Every frame touches the grasped object; nothing enters an object or the table by > 3 mm.

    Two objects, so the other one is an obstacle of the plan (it may stay untouched).
    """
    config = GenerationConfig.from_mapping(
        TINY, num_objects_range=(2, 2), objects=("005_tomato_soup_can", "009_gelatin_box")
    )
    source = GraspSource(config)
    try:
        frames = _frames(source, seed=3, episodes=3, frames=2)
    finally:
        source.close()
    assert len(frames) == 6
    in_contact = [int(a["contact_count"]) > 0 for a, _ in frames]
    assert np.mean(in_contact) >= 0.8
    deepest = max(d for _, d in frames)
    assert deepest <= MAX_GRASP_PENETRATION_M
    # Digits stop just past their touch: a contact needs an overlap, but a small one.
    assert 0.0 < deepest
    for arrays, _ in frames:
        n = int(arrays["contact_count"])
        assert set(arrays["contact_instance"][:n].tolist()) <= {0, 1}


def test_the_upright_drill_is_grasped_without_entering_it():
    """The upright drill's grasp frames touch it and enter nothing by more than the limit.

    Upright on its battery it is wrapped by its grip, or pinched from the top facing the user.
    """
    config = GenerationConfig.from_mapping(TINY, objects=("035_power_drill",))
    source = GraspSource(config)
    try:
        frames = _frames(source, seed=0, episodes=4, frames=1)
    finally:
        source.close()
    assert len(frames) == 4
    assert all(int(a["contact_count"]) > 0 for a, _ in frames)
    assert max(d for _, d in frames) <= MAX_GRASP_PENETRATION_M


def test_close_onto_stops_each_digit_at_its_touch():
    """Closed digits overlap what they touch by about TOUCH_DEPTH_M.

    The planned contact closure itself (the digits not stopped at the surface) enters the can
    by more than the limit.
    """
    config = GenerationConfig.from_mapping(TINY)
    source = GraspSource(config)
    try:
        scene, _ = source._scene(np.random.default_rng(0))
        grasp = source._grasp(scene, 0)
        assert not isinstance(grasp, str), grasp
        plan, closed = grasp
        depth, deepest, touches = _depths(scene, closed)
        assert touches and deepest <= MAX_GRASP_PENETRATION_M
        touching = depth[3:] > 0  # thumb .. little
        assert touching.sum() >= 2  # the thumb and at least one finger hold the can
        assert np.all(depth[3:][touching] < TOUCH_DEPTH_M + 0.001)
        assert _depths(scene, plan.pose(plan.contact))[1] > MAX_GRASP_PENETRATION_M
    finally:
        source.close()


def test_grasp_shards_are_deterministic(tmp_path):
    """A shard depends on (seed, index) only: made twice, byte-identical; another seed differs."""
    config = GenerationConfig.from_mapping(TINY)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = generate_shard(config, 0, tmp_path / "a")
    b = generate_shard(config, 0, tmp_path / "b")
    assert a == b
    assert generate_shard(GenerationConfig.from_mapping(TINY, seed=1), 0, tmp_path / "a") != a


def test_a_kept_source_changes_no_shard(tmp_path):
    """A worker's source kept from shard to shard (scenes, planner caches, counts) changes nothing.

    Shard 1 made after shard 0 is shard 1 made alone, so a resumed run is the uninterrupted one.
    """
    from handsim.data import generation

    config = GenerationConfig.from_mapping(TINY, frames=8, frames_per_shard=4, frames_per_episode=2)
    generation.close_kept_source()
    for index in range(2):
        (tmp_path / f"kept{index}").mkdir()
        kept = generate_shard(config, index, tmp_path / f"kept{index}")
    (source,) = generation._KEPT_SOURCE.values()
    assert isinstance(source, GraspSource)
    generation.close_kept_source()
    (tmp_path / "fresh").mkdir()
    assert generate_shard(config, 1, tmp_path / "fresh") == kept
    generation.close_kept_source()


def test_an_object_without_a_grasp_is_redrawn_and_counted_in_the_manifest(tmp_path, monkeypatch):
    """No hovering hand: an episode whose object has no grasp is redrawn, and counted."""
    plan_grasp = kinematic_grasps.plan_grasp

    def no_marker_grasp(obj, *args, **kwargs):
        if obj.name == "040_large_marker":
            raise GraspPlanningError("no collision-free grasp (test)")
        return plan_grasp(obj, *args, **kwargs)

    monkeypatch.setattr(kinematic_grasps, "plan_grasp", no_marker_grasp)
    # One frame an episode: six episodes, some of which draw the marker.
    config = GenerationConfig.from_mapping(
        TINY,
        frames_per_episode=1,
        num_objects_range=(2, 2),
        objects=("005_tomato_soup_can", "040_large_marker"),
    )
    manifest = generate(config, tmp_path)
    assert set(manifest.redraws) == {"grasp"} and manifest.redraws["grasp"] >= 1
    # Written to manifest.json and read back.
    assert Manifest.read(tmp_path).redraws == manifest.redraws
    reader = ShardReader(tmp_path / "shard-00000.h5")
    assert len(reader) == 6 and (reader.labels("contact_count") > 0).all()
    # Every contact is with a can, never with the marker.
    can_id = OBJECTS["005_tomato_soup_can"].ycbv_id
    for i in range(len(reader)):
        a = reader[i]
        can = {k for k in range(2) if a["object_ycbv_id"][k] == can_id}
        n = int(a["contact_count"])
        touched = set(a["contact_instance"][:n].tolist())
        assert touched and touched <= can

    # The episode says which object and why.
    source = GraspSource(GenerationConfig.from_mapping(TINY, objects=("040_large_marker",)))
    try:
        with pytest.raises(CannotDraw, match="no grasp: 040_large_marker at its sampled pose"):
            next(source.episode(np.random.default_rng(0), lambda r, v: True, 2))
    finally:
        source.close()


def test_a_grasp_that_cannot_close_without_overlap_is_redrawn(monkeypatch):
    """A planned grasp whose closed hand would enter the can too deep is not shown."""
    monkeypatch.setattr(kinematic_grasps, "close_onto", lambda scene, plan: None)
    source = GraspSource(GenerationConfig.from_mapping(TINY))
    try:
        with pytest.raises(CannotDraw, match="closed grasp overlaps: 005_tomato_soup_can") as err:
            next(source.episode(np.random.default_rng(0), lambda r, v: True, 2))
        assert err.value.reason == "grasp"
    finally:
        source.close()


def test_approach_frames_are_open_and_clear():
    """approach_fraction 1: the open hand on its way in, no deeper than the limit."""
    config = GenerationConfig.from_mapping(TINY, approach_fraction=1.0)
    source = GraspSource(config)
    try:
        frames = _frames(source, seed=0, episodes=2, frames=3)
    finally:
        source.close()
    assert frames and max(d for _, d in frames) <= MAX_GRASP_PENETRATION_M
    poses = {a["hand_pose"].tobytes() for a, _ in frames}
    assert len(poses) == len(frames)  # every frame at its own point of the approach


@pytest.mark.parametrize(
    ("values", "match"),
    [
        (
            {"num_objects_range": (0, 1)},
            r"source 'grasp' grasps an object in every frame: num_objects_range must start",
        ),
        ({"approach_fraction": 1.5}, r"approach_fraction must be a number in \[0, 1\]"),
        (
            {"source": "kinematic", "approach_fraction": 0.2},
            r"approach_fraction is a field of the 'grasp' source",
        ),
        ({"frame_stride": 2}, r"env_id and frame_stride are fields of the 'rollout' source"),
    ],
)
def test_grasp_config_errors_name_the_field(values, match):
    """Fields the grasp source cannot honour are refused with what is valid."""
    with pytest.raises(InvalidGenerationConfig, match=match):
        GenerationConfig.from_mapping({**TINY, **values})


def test_the_hand_object_presets_use_grasps():
    """hand-object and occlusion-heavy frames come from grasps; hand-only stays kinematic."""
    assert GenerationConfig.from_mapping(PRESETS["hand-object"]).source == "grasp"
    assert GenerationConfig.from_mapping(PRESETS["occlusion-heavy"]).source == "grasp"
    assert GenerationConfig.from_mapping(PRESETS["hand-only"]).source == "kinematic"


def test_the_cli_generates_grasp_frames(tmp_path):
    """``handsim generate --preset hand-object``, as a subprocess: grasp frames, in contact."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    run = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "generate", "--preset", "hand-object"]
        + ["--frames", "2", "--seed", "3", "--out", str(tmp_path / "d")],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["frames"] == 2
    assert Manifest.read(tmp_path / "d").config["source"] == "grasp"
    counts = ShardReader(tmp_path / "d" / "shard-00000.h5").labels("contact_count")
    assert len(counts) == 2 and (counts > 0).all()


def test_through_object_views_see_a_grasp_from_above_through_an_object(tmp_path):
    """A box grasped from above is seen through an object from above the table.

    (Behind the grasped box as seen from the palm would be under the table.)
    """
    config = GenerationConfig.from_mapping(
        TINY,
        frames=4,
        frames_per_shard=4,
        frames_per_episode=2,
        num_objects_range=(2, 2),
        objects=("010_potted_meat_can",),
        viewpoints=("through_object",),
        occlusion_range=(0.1, 0.95),
    )
    generate(config, tmp_path)
    reader = ShardReader(tmp_path / "shard-00000.h5")
    assert len(reader) == 4
    for i in range(len(reader)):
        a = reader[i]
        eye = np.linalg.inv(a["T_cam_from_world"])[:3, 3]
        assert eye[2] > 0.0  # above the table top
        assert 0.1 <= a["hand_occlusion_ratio"] <= 0.95
        assert int(a["contact_count"]) > 0
