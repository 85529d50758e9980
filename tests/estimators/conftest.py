"""Shared fixtures of the estimator tests."""

import pytest

from handsim.data.generation import GenerationConfig, generate


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    """30 hand-only frames, one per episode (so every split has frames)."""
    out = tmp_path_factory.mktemp("tiny")
    config = GenerationConfig(
        frames=30, frames_per_shard=15, frames_per_episode=1, seed=5,
        num_objects_range=(0, 0), viewpoints=("third_person",), sensor="structured_light",
        hand_length_range_m=(0.18, 0.18),  # one skin build for every episode
    )  # fmt: skip
    generate(config, out)
    return out
