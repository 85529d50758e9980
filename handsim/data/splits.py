"""Train / val / test splits of a dataset folder, by episode.

Frames of one episode share a hand, objects and a scene, so a split never cuts an episode. The
episodes of a folder are ranked by a stable hash of (folder seed, episode) and dealt out in
that order: ``val`` takes episodes until it holds at least 10 % of the folder's frames (at
least one episode), then ``test`` likewise, and ``train`` keeps the rest (at least one
episode). Drawing each episode's split independently (a 10 % chance each) left a 500-frame
occlusion-heavy folder (39 episodes, some cut short) with a 4-frame ``val`` split; dealing by
frames gives each held-out split about a tenth of the frames.

A folder with fewer than :data:`MIN_SPLIT_EPISODES` episodes is all ``train``; asking it for
``val`` or ``test`` raises :class:`InvalidDatasetQuery`, which says why.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from handsim.data.manifest import Manifest
from handsim.data.shards import ShardReader
from handsim.errors import HandSimError

__all__ = [
    "SPLITS",
    "SPLIT_FRACTIONS",
    "MIN_SPLIT_EPISODES",
    "InvalidDatasetQuery",
    "episode_splits",
    "folder_splits",
    "split_mask",
]

SPLITS = ("train", "val", "test", "all")
"""Split names; ``all`` is every frame."""
SPLIT_FRACTIONS = (0.8, 0.1, 0.1)
"""Fractions of a folder's episodes in train, val and test (val and test rounded)."""
MIN_SPLIT_EPISODES = 3
"""Episodes a folder needs for a val and a test split: one each, and one to train on."""


class InvalidDatasetQuery(HandSimError, ValueError):
    """A dataset folder, split or filter is invalid; the message says what is valid."""


def _rank(seed: int, episode: int) -> int:
    digest = hashlib.blake2b(f"{seed}:{episode}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little")


def episode_splits(seed: int, episodes: Iterable[int]) -> dict[int, str]:
    """The split of every episode of a folder.

    Args:
        seed: the folder's base seed (``manifest.config["seed"]``).
        episodes: the episode id of every frame of the folder (an id appears once per frame).

    Returns:
        ``{episode: "train" | "val" | "test"}``. With :data:`MIN_SPLIT_EPISODES` episodes or
        more, ``val`` and ``test`` each hold the fewest episodes, in hash order, whose frames
        reach 10 % of the folder's (at least one episode each; ``train`` keeps at least one);
        with fewer, every episode is ``train``. The result depends only on the seed and the
        episodes' frame counts.
    """
    counts: dict[int, int] = {}
    for e in episodes:
        counts[int(e)] = counts.get(int(e), 0) + 1
    ranked = sorted(counts, key=lambda e: (_rank(seed, e), e))
    splits = dict.fromkeys(ranked, "train")
    if len(ranked) < MIN_SPLIT_EPISODES:
        return splits
    target = SPLIT_FRACTIONS[1] * sum(counts.values())
    i = 0
    for split, keep_after in (("val", 2), ("test", 1)):
        frames = 0
        # Deal at least one episode; stop at the target or when the later splits need the rest.
        while i < len(ranked) - keep_after and (frames == 0 or frames < target):
            splits[ranked[i]] = split
            frames += counts[ranked[i]]
            i += 1
    return splits


def folder_splits(
    folder: str | os.PathLike[str], manifest: Manifest | None = None
) -> dict[int, str]:
    """:func:`episode_splits` of a dataset folder's episodes (read from its shards).

    Args:
        folder: a dataset folder.
        manifest: its manifest, if already read.

    Returns:
        ``{episode: split}`` over every episode of the folder.

    Raises:
        InvalidManifest: if ``folder`` is not a dataset folder.
    """
    manifest = manifest if manifest is not None else Manifest.read(folder)
    episodes: list[np.ndarray] = []
    for record in manifest.shards.values():
        reader = ShardReader(Path(folder) / record.name)
        episodes.append(reader.labels("episode"))
        reader.close()
    ids = np.concatenate(episodes) if episodes else np.zeros(0, np.int64)
    return episode_splits(int(manifest.config.get("seed", 0)), ids.tolist())


def split_mask(splits: dict[int, str], episodes: np.ndarray, split: str, where: str) -> np.ndarray:
    """Which frames (by their episode ids) are in ``split``.

    Args:
        splits: :func:`folder_splits` of the folder.
        episodes: (N,) episode id per frame.
        split: one of :data:`SPLITS`.
        where: the folder, for the error message.

    Returns:
        (N,) bool.

    Raises:
        InvalidDatasetQuery: for an unknown split, or ``val`` / ``test`` of a folder with fewer
            than :data:`MIN_SPLIT_EPISODES` episodes (the message says why and what to do).
    """
    if split not in SPLITS:
        raise InvalidDatasetQuery(f"split must be one of {', '.join(SPLITS)}; received {split!r}")
    if split == "all":
        return np.ones(len(episodes), dtype=bool)
    if split != "train" and len(splits) < MIN_SPLIT_EPISODES:
        raise InvalidDatasetQuery(
            f"{where} has {len(splits)} episode(s): a {split!r} split needs at least "
            f"{MIN_SPLIT_EPISODES} episodes (one for val, one for test, the rest for train); "
            "generate more frames (or fewer frames_per_episode), or use split='all'"
        )
    return np.array([splits.get(int(e)) == split for e in episodes], dtype=bool)
