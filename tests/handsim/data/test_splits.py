"""Train / val / test by episode: a tenth of the frames each, one episode at least, or a refusal."""

import math

import numpy as np
import pytest

from handsim.data.splits import (
    MIN_SPLIT_EPISODES,
    InvalidDatasetQuery,
    episode_splits,
    split_mask,
)


def _counts(splits):
    values = list(splits.values())
    return [values.count(s) for s in ("train", "val", "test")]


def test_a_500_frame_dataset_of_25_frame_episodes_has_two_val_and_two_test_episodes():
    """20 episodes (ids as generate writes them: shard * 10**6 + episode) split 16 / 2 / 2."""
    ids = [shard * 1_000_000 + e for shard in range(2) for e in range(10)]
    frames = np.repeat(ids, 25)
    for seed in range(50):  # never fewer: the shares are dealt, not drawn
        assert _counts(episode_splits(seed, frames)) == [16, 2, 2]


@pytest.mark.parametrize("n", [3, 4, 9, 14, 15, 25, 100, 1000])
def test_one_frame_episodes_give_val_and_test_a_tenth_each_and_at_least_one(n):
    """With equal episodes val and test hold ceil(n / 10) each; train the rest; each once."""
    splits = episode_splits(7, range(n))
    held = math.ceil(0.1 * n)
    assert _counts(splits) == [n - 2 * held, held, held]
    assert sorted(splits) == list(range(n))


def test_uneven_episodes_are_dealt_by_frames():
    """Short and long episodes: each held-out split reaches 10 % of the frames, by one episode."""
    # Like an occlusion-heavy folder whose episodes end early: 39 episodes of 1 to 25 frames.
    rng = np.random.default_rng(0)
    lengths = rng.integers(1, 26, size=39)
    frames = np.repeat(np.arange(39), lengths)
    for seed in range(20):
        splits = episode_splits(seed, frames)
        for split in ("val", "test"):
            held = [e for e, s in splits.items() if s == split]
            total = lengths[held].sum()
            assert total >= 0.1 * len(frames)
            assert total < 0.1 * len(frames) + lengths[held].max()  # passed by one episode


def test_splits_are_deterministic_and_follow_the_seed():
    """Same seed and episodes: the same splits; another seed deals other episodes."""
    episodes = np.arange(40)
    a = episode_splits(0, episodes)
    assert a == episode_splits(0, episodes[::-1].tolist())  # the order of frames is irrelevant
    b = episode_splits(1, episodes)
    assert a != b and _counts(a) == _counts(b)


def test_too_few_episodes_are_all_train_and_val_is_refused_with_the_reason():
    """Below MIN_SPLIT_EPISODES every episode trains; asking for val or test says why."""
    assert MIN_SPLIT_EPISODES == 3
    splits = episode_splits(0, [0, 1])
    assert _counts(splits) == [2, 0, 0]
    episodes = np.array([0, 0, 1])
    assert split_mask(splits, episodes, "train", "data/x").all()
    assert split_mask(splits, episodes, "all", "data/x").all()
    for split in ("val", "test"):
        with pytest.raises(
            InvalidDatasetQuery,
            match=rf"data/x has 2 episode\(s\): a '{split}' split needs at least 3 episodes",
        ):
            split_mask(splits, episodes, split, "data/x")
    with pytest.raises(InvalidDatasetQuery, match="split must be one of train, val, test, all"):
        split_mask(splits, episodes, "dev", "data/x")
