"""The rollout source of dataset generation: env episodes driven by their experts."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.data.generation import (
    PRESETS,
    SOURCES,
    CannotDraw,
    GenerationConfig,
    InvalidGenerationConfig,
    generate,
    generate_shard,
    make_source,
    register_source,
)
from handsim.data.kinematic import MIN_EYE_HEIGHT_M
from handsim.data.manifest import check_dataset
from handsim.data.shards import ShardReader, file_sha256
from handsim.envs.rollouts import (
    ROLLOUT_ENV_IDS,
    RolloutSource,
    _above_table,
    through_object_views,
)
from handsim.frame import FrameRenderer
from handsim.hand.pose_sources import gesture
from handsim.world.camera import camera_preset
from handsim.world.registry import OBJECTS
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    CameraSpec,
    ObjectPlacement,
    Scene,
    SceneSpec,
)

# Small: one object, noise-free, two frames 3 steps apart per episode.
TINY = {
    **PRESETS["grasp-rollouts"],
    "frames": 4,
    "frames_per_shard": 2,
    "frames_per_episode": 2,
    "frame_stride": 3,
    "sensor": "none",
    "objects": ("005_tomato_soup_can",),
}


def test_the_rollout_source_is_resolved_by_name_and_registered_sources_too():
    """source='rollout' resolves to RolloutSource; register_source adds a name."""
    config = GenerationConfig.from_mapping(TINY)
    source = make_source(config)
    assert isinstance(source, RolloutSource)
    source.close()
    assert set(ROLLOUT_ENV_IDS) == {
        "handsim/Grasp-v0",
        "handsim/GraspClutter-v0",
        "handsim/HandPose-v0",
    }
    register_source("rollout-copy", "handsim.envs.rollouts:RolloutSource")
    try:
        assert isinstance(
            make_source(GenerationConfig.from_mapping({**TINY, "source": "rollout-copy"})),
            RolloutSource,
        )
    finally:
        del SOURCES["rollout-copy"]
    with pytest.raises(InvalidGenerationConfig, match="'module:class' spec"):
        register_source("x", "no_colon")
    register_source("broken", "handsim.no_such_module:X")
    try:
        with pytest.raises(InvalidGenerationConfig, match="source 'broken'.*cannot be imported"):
            GenerationConfig.from_mapping({**TINY, "source": "broken"})
    finally:
        del SOURCES["broken"]


def test_rollout_shards_are_seeded_labelled_and_resumable(tmp_path):
    """Frames of expert rollouts: labelled, deterministic per shard, resumed identically."""
    config = GenerationConfig.from_mapping(TINY)
    manifest = generate(config, tmp_path / "a")
    assert manifest.frames == 4 and check_dataset(tmp_path / "a")["ok"]
    reader = ShardReader(tmp_path / "a" / "shard-00000.h5")
    frame = reader[1]
    assert frame["valid"] and frame["in_frame"].sum() >= 15
    assert (
        frame["object_valid"][0]
        and frame["object_ycbv_id"][0] == OBJECTS["005_tomato_soup_can"].ycbv_id
    )
    assert frame["depth"].shape == (240, 320) and np.any(frame["depth"] > 0)
    assert 0.150 <= frame["hand_length_m"] <= 0.220
    # Shard 1 made alone, elsewhere, is the same file.
    info = generate_shard(config, 1, tmp_path)
    assert info.sha256 == manifest.shards[1].sha256
    # Resume: a lost shard is made again identically.
    lost = tmp_path / "a" / "shard-00001.h5"
    lost.unlink()
    generate(config, tmp_path / "a")
    assert file_sha256(lost) == manifest.shards[1].sha256


def test_an_episode_without_a_grasp_is_redrawn_not_empty(monkeypatch):
    """An expert that finds no grasp raises CannotDraw('grasp'): the shard redraws the episode."""
    from handsim.envs.experts import ExpertError
    from handsim.envs.grasp import GraspEnv

    def no_grasp(self, rng=None, state=None):
        raise ExpertError("no collision-free grasp of 005_tomato_soup_can (test)")

    monkeypatch.setattr(GraspEnv, "make_expert", no_grasp)
    source = make_source(GenerationConfig.from_mapping(TINY))
    try:
        with pytest.raises(CannotDraw, match="no collision-free grasp") as err:
            next(source.episode(np.random.default_rng(0), lambda ratio, visible: True, 2))
        assert err.value.reason == "grasp"
    finally:
        source.close()


def test_hand_pose_rollouts_and_clutter_configs():
    """HandPose-v0 rollouts give hand-only frames; GraspClutter takes an object range."""
    config = GenerationConfig.from_mapping(
        {**TINY, "env_id": "handsim/HandPose-v0", "num_objects_range": (0, 0)}
    )
    source = make_source(config)
    frames = list(source.episode(np.random.default_rng(0), lambda ratio, visible: True, 2))
    source.close()
    assert len(frames) == 2
    assert not frames[0]["object_valid"].any() and frames[0]["hand_occlusion_ratio"] == 0.0
    GenerationConfig.from_mapping(
        {
            **TINY,
            "env_id": "handsim/GraspClutter-v0",
            "objects": PRESETS["grasp-rollouts"].get("objects", GenerationConfig.objects),
            "num_objects_range": (3, 4),
        }
    )


@pytest.mark.parametrize(
    ("values", "match"),
    [
        ({"env_id": "handsim/Nope-v0"}, "env_id must be one of handsim/Grasp-v0"),
        ({"env_id": None}, "env_id must be one of"),
        (
            {
                "env_id": "handsim/HandPose-v0",
                "num_objects_range": (0, 0),
                "viewpoints": ("through_object",),
            },
            "viewpoint 'through_object' needs objects; handsim/HandPose-v0 has none",
        ),
        ({"num_objects_range": (1, 2)}, r"num_objects_range must be \(1, 1\)"),
        (
            {"env_id": "handsim/HandPose-v0", "num_objects_range": (1, 1)},
            r"num_objects_range must be \(0, 0\)",
        ),
        (
            {"env_id": "handsim/GraspClutter-v0", "num_objects_range": (3, 6)},
            "num_objects_range must be 1 <= low <= high <= min",
        ),
        (
            {
                "env_id": "handsim/HandPose-v0",
                "num_objects_range": (0, 0),
                "occlusion_range": (0.2, 1.0),
            },
            "has no objects",
        ),
        ({"frame_stride": 0}, r"frame_stride must be an integer in \[1, 10000\]"),
        ({"source": "physics"}, "source must be one of kinematic, rollout"),
        ({"source": "kinematic"}, "env_id and frame_stride are fields of the 'rollout' source"),
        ({"env_id": 3}, "env_id must be an env id"),
    ],
)
def test_rollout_config_errors_name_the_field(values, match):
    """Every field the rollout source cannot honour is named with what is valid."""
    with pytest.raises(InvalidGenerationConfig, match=match):
        GenerationConfig.from_mapping({**TINY, **values})


def _hand_beside_lifted_can() -> tuple[Scene, np.ndarray]:
    """A right hand, palm toward a can held 25 cm above the table, fingers along +y."""
    can = OBJECTS["002_master_chef_can"]
    obj = np.array([0.1, 0.0, 0.25])
    camera = CameraSpec.look_at("camera", camera_preset("icvl"), (0.0, -0.6, 0.4), (0.0, 0.0, 0.1))
    scene = Scene(
        SceneSpec(objects=(ObjectPlacement(can.name, tuple(obj)),), cameras=(camera,), table=True)
    )
    # Hand z (palmar) -> world +x, y (distal) -> +y, x (radial) -> -z.
    R = np.column_stack([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # noqa: N806
    palm = obj - np.array([0.5 * can.extents_m[0] + 0.02, 0.0, 0.0])
    wrist = palm - 0.07 * R[:, 1]
    scene.reset(
        gesture("open").replace(wrist_pos=wrist, wrist_rotvec=Rotation.from_matrix(R).as_rotvec())
    )
    return scene, obj


def test_through_object_views_put_the_object_between_camera_and_hand():
    """The camera looks at a hand keypoint along a line through the held object.

    Geometry: the keypoint lies on the optical axis, the object's centre between the eye and
    the keypoint and within the can's radius of the axis, the eye above the table. Render: the
    keypoint is hidden by the object, and nothing is nearer than the near range.
    """
    scene, obj = _hand_beside_lifted_can()
    radius = 0.5 * OBJECTS["002_master_chef_can"].extents_m[0]
    place = through_object_views(scene, near_m=0.35, distance_range_m=(0.4, 0.7))
    cam = scene.model.camera("camera").id
    rng = np.random.default_rng(0)
    looked_at = set()
    with FrameRenderer(scene, "camera") as renderer:
        for _ in range(12):
            assert place(rng)
            eye = scene.data.cam_xpos[cam]
            forward = -scene.data.cam_xmat[cam].reshape(3, 3)[:, 2]  # MuJoCo looks along -z
            rel = scene.binding.keypoints(scene.data) - eye
            along = rel @ forward
            off_axis = np.linalg.norm(rel - along[:, None] * forward, axis=1)
            k = int(np.argmin(off_axis))
            looked_at.add(k)
            assert off_axis[k] < 1e-9
            obj_along = (obj - eye) @ forward
            assert 0.0 < obj_along < along[k]
            assert np.linalg.norm(obj - eye - obj_along * forward) < radius
            assert eye[2] >= MIN_EYE_HEIGHT_M
            frame = renderer.render(rng)
            assert not frame.visible[k] and frame.occluder[k] == 0  # object instance 0
            # The hand (the arm is drawn only, and may come nearer) and the object.
            seen = frame.segmentation >= SEGMENT_LABELS.index("palm")
            assert seen.any() and frame.depth[seen].min() >= 0.35
            assert (frame.segmentation == OBJECT_LABEL_OFFSET).any()
    assert len(looked_at) > 5  # drawn from the hand's keypoints


def test_above_table_raises_a_ray_into_the_table_just_enough():
    """A ray into the table is raised (heading kept) to the eye height; others only normalized."""
    down = np.array([3.0, 4.0, -5.0])
    raised = _above_table(down, 0.2, 0.8)
    assert np.isclose(np.linalg.norm(raised), 1.0)
    assert np.isclose(0.2 + 0.8 * raised[2], MIN_EYE_HEIGHT_M)
    np.testing.assert_allclose(raised[:2] / np.linalg.norm(raised[:2]), [0.6, 0.8])
    level = np.array([1.0, 0.0, -0.1])
    np.testing.assert_allclose(_above_table(level, 0.2, 0.8), level / np.linalg.norm(level))


def test_the_occluded_rollout_preset_honours_its_buckets_and_is_seeded(tmp_path):
    """``handsim generate`` with the ``grasp-rollouts-occluded`` preset fills its buckets.

    Four frames, one per bucket (with one large can, so that the run is short); the shard
    made again in this process from the same seed is the same file.
    """
    values = {**PRESETS["grasp-rollouts-occluded"], "objects": ["002_master_chef_can"]}
    (tmp_path / "occluded.json").write_text(json.dumps(values))
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    out = tmp_path / "occ"
    cmd = [sys.executable, "-m", "handsim.cli", "generate", "--config"]
    subprocess.run(
        [*cmd, str(tmp_path / "occluded.json"), "--frames", "4", "--seed", "0", "--out", str(out)],
        check=True,
        capture_output=True,
        env=env,
    )
    manifest = json.loads((out / "manifest.json").read_text())
    edges = PRESETS["grasp-rollouts-occluded"]["occlusion_buckets"][0]
    assert manifest["occlusion_histogram"] == {"edges": list(edges), "counts": [1, 1, 1, 1]}
    config = GenerationConfig.from_mapping(values, frames=4, seed=0)
    assert generate_shard(config, 0, tmp_path).sha256 == manifest["shards"][0]["sha256"]
