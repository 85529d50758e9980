"""The rollout source of dataset generation: env episodes driven by their experts."""

import numpy as np
import pytest

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
from handsim.data.manifest import check_dataset
from handsim.data.shards import ShardReader, file_sha256
from handsim.envs.rollouts import ROLLOUT_ENV_IDS, RolloutSource
from handsim.world.registry import OBJECTS

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
        ({"viewpoints": ("through_object",)}, r"viewpoints \['through_object'\] are not env"),
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
