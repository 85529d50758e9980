"""Training and evaluation data of the learned estimators: handsim dataset folders in memory.

:func:`load_frames` reads the depth images (as stored, uint16) and the labels of a split of one
or more dataset folders (``handsim generate``) into a :class:`FrameSet`; :class:`CropDataset`
turns it into augmented crops for torch (:func:`~handsim.estimators.deepprior.preprocess.augment`).

With ``canonical_side=True`` the left hands' frames are stored mirrored into the right-hand
frame (depth columns flipped, ``cx' = W - 1 - cx``, ``x -> -x`` on the keypoints, their order
kept): training, the PCA prior and the crop centres then see right hands only. Errors are
distances, so they are the same in either frame.
"""

from __future__ import annotations

import dataclasses
import mmap
import multiprocessing
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from handsim.data.manifest import Manifest
from handsim.data.shards import ShardReader
from handsim.data.splits import folder_splits, split_mask
from handsim.errors import HandSimError

from .preprocess import (
    CROP_SIZE,
    CUBE_M,
    MIDDLE_MCP,
    AugmentParams,
    augment,
    mirror_depth,
    mirror_intrinsics,
    mirror_points,
    sample_augmentation,
)

__all__ = [
    "FrameSet",
    "load_frames",
    "env_frames",
    "side_frame",
    "CropDataset",
    "InvalidTrainingData",
]


class InvalidTrainingData(HandSimError, ValueError):
    """A dataset folder or split has no usable frames; the message says which."""


@dataclasses.dataclass
class FrameSet:
    """Frames of a split in memory.

    Attributes:
        depth_units: (N, H, W) uint16 depth in units of ``depth_scale_m`` (0 = none).
        depth_scale_m: metres per depth unit, (N,) (folders may differ).
        K: (N, 3, 3) intrinsics.
        keypoints_cam: (N, 21, 3) keypoints, metres, camera frame.
        occlusion: (N,) hand occlusion ratio (NaN where not computed).
        hand_length_m: (N,) hand length, metres.
        sensor: (N,) sensor model name of each frame's folder.
        is_left: (N,) bool, the frame shows a left hand.
        mirrored: (N,) bool, the frame is stored mirrored into the right-hand frame.
    """

    depth_units: np.ndarray
    depth_scale_m: np.ndarray
    K: np.ndarray
    keypoints_cam: np.ndarray
    occlusion: np.ndarray
    hand_length_m: np.ndarray
    sensor: np.ndarray
    is_left: np.ndarray
    mirrored: np.ndarray

    def __len__(self) -> int:
        return len(self.K)

    def depth(self, i: int) -> np.ndarray:
        """(H, W) float32 depth of frame ``i``, metres."""
        return self.depth_units[i].astype(np.float32) * np.float32(self.depth_scale_m[i])


def _shard_keep(reader: ShardReader, folder: str, splits: dict, split: str) -> np.ndarray:
    keep = split_mask(splits, reader.labels("episode"), split, f"--data {folder}")
    return keep & reader.labels("valid").astype(bool)


def _read_shard(
    folder: str,
    name: str,
    splits: dict,
    split: str,
    sensor: str,
    canonical_side: bool,
    depth_out: np.ndarray | None = None,
) -> dict[str, np.ndarray] | None:
    """The kept frames of one shard as :func:`load_frames`' parts, or ``None`` if none.

    With ``depth_out`` (as many frames as the shard keeps) the depth images are written there
    and left out of the parts.
    """
    import h5py

    reader = ShardReader(Path(folder) / name)
    try:
        keep = _shard_keep(reader, folder, splits, split)
        if not keep.any():
            return None
        with h5py.File(reader.path, "r") as f:
            depth = f["depth"][:]
        depth, K = depth[keep], reader.labels("K")[keep]  # noqa: N806
        kp = reader.labels("keypoints_cam")[keep]
        left = reader.labels("is_left")[keep].astype(bool)
        if canonical_side and left.any():
            depth[left] = mirror_depth(depth[left])
            K[left] = mirror_intrinsics(K[left], depth.shape[-1])
            kp[left] = mirror_points(kp[left])
        n = int(keep.sum())
        parts = {
            "depth": depth,
            "scale": np.full(n, reader.depth_scale_mm / 1000.0),
            "K": K,
            "kp": kp,
            "left": left,
            "occ": reader.labels("hand_occlusion_ratio")[keep],
            "length": reader.labels("hand_length_m")[keep],
            "sensor": np.array([sensor] * n),
        }
        if depth_out is not None:
            depth_out[...] = parts.pop("depth")
        return parts
    finally:
        reader.close()


_DEPTH_OUT: np.ndarray | None = None  # load_frames' shared depth buffer, inherited by its workers


def _shard_shape_task(task: tuple) -> tuple[int, tuple[int, ...]]:
    """(kept frames, (H, W)) of one shard, without decompressing its images."""
    import h5py

    folder, name, splits, split = task[:4]
    reader = ShardReader(Path(folder) / name)
    try:
        n = int(_shard_keep(reader, folder, splits, split).sum())
        with h5py.File(reader.path, "r") as f:
            return n, tuple(f["depth"].shape[1:])
    finally:
        reader.close()


def _read_shard_into_task(item: tuple) -> dict[str, np.ndarray] | None:
    task, start, stop = item
    assert _DEPTH_OUT is not None
    return _read_shard(*task, depth_out=_DEPTH_OUT[start:stop])


def _read_parallel(
    tasks: list[tuple], workers: int
) -> tuple[list[dict[str, np.ndarray]], np.ndarray | None]:
    """``(parts, depth)`` of every shard, read by ``workers`` forked processes.

    The depth images (most of the bytes) go straight into an anonymous shared mapping made
    before the readers fork, so they are neither pickled back nor concatenated again: memory
    peaks at the data's size, not twice it. ``depth`` is that array (the parts hold no depth),
    or ``None`` when the shards' images differ in size (the parts then hold their own).
    """
    global _DEPTH_OUT
    fork = multiprocessing.get_context("fork")
    with fork.Pool(min(workers, len(tasks))) as pool:
        shapes = pool.map(_shard_shape_task, tasks, chunksize=4)
    sizes = {shape for n, shape in shapes if n}
    if len(sizes) != 1:  # no frames, or images of several sizes: nothing to share
        with fork.Pool(min(workers, len(tasks))) as pool:
            return [s for s in pool.map(_read_shard_task, tasks, chunksize=1) if s], None
    (h, w), total = sizes.pop(), sum(n for n, _ in shapes)
    buffer = mmap.mmap(-1, total * h * w * 2)
    depth = np.frombuffer(buffer, dtype=np.uint16).reshape(total, h, w)
    ends = np.cumsum([n for n, _ in shapes])
    items = [(t, e - n, e) for t, (n, _), e in zip(tasks, shapes, ends, strict=True) if n]
    _DEPTH_OUT = depth
    try:
        with fork.Pool(min(workers, len(items))) as pool:
            parts = pool.map(_read_shard_into_task, items, chunksize=1)
    finally:
        _DEPTH_OUT = None
    return [p for p in parts if p], depth


def _read_shard_task(task: tuple) -> dict[str, np.ndarray] | None:
    return _read_shard(*task)


def load_frames(
    folders: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    split: str = "all",
    *,
    max_frames: int | None = None,
    canonical_side: bool = False,
    workers: int = 0,
) -> FrameSet:
    """Read every frame of a split (``train``/``val``/``test``/``all``, by episode).

    Splits are those of :class:`~handsim.data.torch_dataset.HandSimDataset`
    (:mod:`handsim.data.splits`: 10 % of a folder's episodes each for val and test).
    ``canonical_side=True`` stores the left hands' frames mirrored into the right-hand frame
    (``mirrored`` says which). ``workers > 1`` reads (decompresses) the shards in that many
    forked processes, straight into one shared array; the frames and their order are the same.
    With ``max_frames`` the shards are read one after another, up to the shard that completes
    the count.

    Raises:
        InvalidTrainingData: if a folder is not a dataset or the split is empty.
        InvalidDatasetQuery: for a val / test split of a folder with too few episodes.
    """
    if isinstance(folders, (str, os.PathLike)):
        folders = [folders]
    tasks = []
    for folder in folders:
        try:
            manifest = Manifest.read(folder)
        except HandSimError as err:
            raise InvalidTrainingData(f"--data {folder}: {err}") from None
        splits = folder_splits(folder, manifest) if split != "all" else {}
        sensor = str(manifest.config.get("sensor", "unknown"))
        for record in sorted(manifest.shards.values(), key=lambda s: s.name):
            tasks.append((str(folder), record.name, splits, split, sensor, canonical_side))
    parallel = workers > 1 and max_frames is None and len(tasks) > 1
    depth = None
    if parallel and "fork" in multiprocessing.get_all_start_methods():
        shards, depth = _read_parallel(tasks, workers)
    else:
        shards, total = [], 0
        for task in tasks:
            if max_frames is not None and total >= max_frames:
                break  # enough frames: do not decompress the rest
            part = _read_shard(*task)
            if part is not None:
                shards.append(part)
                total += len(part["K"])
    if not shards:
        raise InvalidTrainingData(
            f"no {split!r} frames in {', '.join(str(f) for f in folders)} (generate more "
            "frames: val and test are 10 % of the episodes each)"
        )
    cat = {k: np.concatenate([s[k] for s in shards]) for k in shards[0]}
    if depth is not None:
        cat["depth"] = depth
    n = len(cat["K"]) if max_frames is None else min(max_frames, len(cat["K"]))
    return FrameSet(
        depth_units=cat["depth"][:n],
        depth_scale_m=cat["scale"][:n],
        K=cat["K"][:n],
        keypoints_cam=cat["kp"][:n],
        occlusion=cat["occ"][:n],
        hand_length_m=cat["length"][:n],
        sensor=cat["sensor"][:n],
        is_left=cat["left"][:n],
        mirrored=cat["left"][:n] & bool(canonical_side),
    )


def side_frame(frames: FrameSet, canonical_side: bool) -> FrameSet:
    """``frames`` with its left hands mirrored (``canonical_side``) or as seen (not).

    Frames already in the asked frame are shared, not copied; the others are mirrored copies.

    Args:
        frames: the frames (any mix of mirrored and unmirrored).
        canonical_side: ``True``: left hands in the right-hand frame; ``False``: as rendered.

    Returns:
        A :class:`FrameSet` (``frames`` itself when nothing changes).
    """
    flip = frames.mirrored != (frames.is_left & bool(canonical_side))
    if not flip.any():
        return frames
    depth, K, kp = frames.depth_units.copy(), frames.K.copy(), frames.keypoints_cam.copy()  # noqa: N806
    depth[flip] = mirror_depth(depth[flip])
    K[flip] = mirror_intrinsics(K[flip], depth.shape[-1])
    kp[flip] = mirror_points(kp[flip])
    return dataclasses.replace(
        frames, depth_units=depth, K=K, keypoints_cam=kp, mirrored=frames.mirrored ^ flip
    )


class CropDataset:
    """Crops of a :class:`FrameSet` for torch: pose labels or the localizer's offset.

    Sample ``i`` of epoch ``e`` draws its augmentation from ``default_rng([seed, e, i])``, so
    an epoch is the same however it is batched or resumed.

    Args:
        frames: the frames.
        centers: (N, 3) crop centres before augmentation, metres (e.g. the refined localizer's
            output; default: the true middle-finger MCP).
        target: ``"pose"`` (normalized (63,) keypoints) or ``"localizer"`` (the (3,) offset of
            the middle MCP from the crop centre, in half cubes).
        cube_m: cube edge, metres.
        size: crop side, pixels.
        rotation, scale, translation: the augmentations to draw (all off for evaluation).
        offset_sigma_m: standard deviation of the centre offset, metres.
        seed: augmentation seed.
        alt_centers: (N, 3) other crop centres, drawn instead of ``centers`` with probability
            ``alt_fraction`` per sample and epoch (the localizer learns from both its start,
            the centre of mass, and from near its goal, so that it can be iterated).
        alt_fraction: probability of ``alt_centers``.
    """

    def __init__(
        self,
        frames: FrameSet,
        centers: np.ndarray | None = None,
        *,
        target: str = "pose",
        cube_m: float = CUBE_M,
        size: int = CROP_SIZE,
        rotation: bool = False,
        scale: bool = False,
        translation: bool = False,
        offset_sigma_m: float = 0.005,
        seed: int = 0,
        alt_centers: np.ndarray | None = None,
        alt_fraction: float = 0.5,
    ) -> None:
        self.frames = frames
        self.alt_centers = None if alt_centers is None else np.asarray(alt_centers)
        self.alt_fraction = float(alt_fraction)
        self.centers = (
            frames.keypoints_cam[:, MIDDLE_MCP] if centers is None else np.asarray(centers)
        )
        self.target = target
        self.cube_m, self.size = cube_m, size
        self.flags = {"rotation": rotation, "scale": scale, "translation": translation}
        self.offset_sigma_m = offset_sigma_m
        self.seed, self.epoch = seed, 0

    def __len__(self) -> int:
        return len(self.frames)

    def params(self, i: int) -> AugmentParams:
        """The augmentation of sample ``i`` in the current epoch."""
        if not any(self.flags.values()):
            return AugmentParams()
        rng = np.random.default_rng([self.seed, self.epoch, i])
        return sample_augmentation(rng, offset_sigma_m=self.offset_sigma_m, **self.flags)

    def sample(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """``(crop (1, S, S) float32, target float32)`` of frame ``i``."""
        f = self.frames
        center = self.centers[i]
        if self.alt_centers is not None:
            if np.random.default_rng([self.seed, self.epoch, i, 1]).random() < self.alt_fraction:
                center = self.alt_centers[i]
        crop, labels, _, _ = augment(
            f.depth(i),
            f.K[i],
            f.keypoints_cam[i],
            center,
            self.params(i),
            cube_m=self.cube_m,
            size=self.size,
        )
        if self.target == "localizer":
            y = labels[MIDDLE_MCP]
        else:
            y = labels.reshape(-1)
        return crop[None].astype(np.float32), y.astype(np.float32)

    def __getitem__(self, i: int) -> tuple[Any, Any]:
        import torch

        x, y = self.sample(int(i))
        return torch.from_numpy(x), torch.from_numpy(y)


def env_frames(
    env_id: str = "handsim/Grasp-v0",
    *,
    episodes: int = 3,
    every: int = 5,
    seed: int = 0,
    sensor: str = "structured_light",
    canonical_side: bool = False,
) -> FrameSet:
    """Frames of an env's scripted expert (acting on the truth), every ``every``-th step.

    The frames an estimator sees inside the closed loop (e.g. hand-object frames of
    ``handsim/Grasp-v0`` from its third-person camera, the table in view), for offline
    evaluation.

    Args:
        env_id: a registered handsim env id with ``make_expert``.
        episodes: episodes (seeds ``seed ... seed + episodes - 1``).
        every: keep every this many steps.
        seed: first seed.
        sensor: depth sensor model.
        canonical_side: store left hands' frames mirrored into the right-hand frame.

    Returns:
        The frames (depth stored in 0.1 mm units). ``occlusion`` is the frame's hand occlusion
        ratio where it was computed, else the fraction of keypoints that are not visible.

    Raises:
        InvalidTrainingData: for an env id that is not a registered handsim env.
    """
    import gymnasium as gym

    import handsim.envs  # registers the ids

    if env_id not in handsim.envs.ENV_IDS:
        raise InvalidTrainingData(
            f"env_id must be a registered handsim env, one of "
            f"{', '.join(handsim.envs.ENV_IDS)}; received {env_id!r}"
        )

    scale_m = 1e-4
    parts: dict[str, list[Any]] = {k: [] for k in ("depth", "K", "kp", "occ", "length", "left")}
    env = gym.make(env_id, obs_mode="depth", sensor=sensor)
    try:
        for episode in range(episodes):
            obs, info = env.reset(seed=seed + episode)
            expert = env.unwrapped.make_expert(np.random.default_rng(seed + episode))
            step, done = 0, False
            while not done:
                frame = env.unwrapped.frame
                if frame is not None and step % every == 0:
                    depth = np.rint(np.asarray(obs["depth"], np.float64) / scale_m)
                    depth = np.clip(depth, 0, 65535).astype(np.uint16)
                    K = np.asarray(frame.K, np.float64)  # noqa: N806
                    kp = np.asarray(frame.keypoints_cam, np.float64)
                    left = frame.handedness == "left"
                    if canonical_side and left:
                        depth = mirror_depth(depth)
                        K, kp = mirror_intrinsics(K, depth.shape[1]), mirror_points(kp)  # noqa: N806
                    parts["depth"].append(depth)
                    parts["K"].append(K)
                    parts["kp"].append(kp)
                    parts["left"].append(left)
                    ratio = frame.hand_occlusion_ratio
                    if ratio is None or not np.isfinite(ratio):  # not computed: keypoints
                        ratio = 1.0 - float(np.mean(frame.visible))
                    parts["occ"].append(float(ratio))
                    parts["length"].append(float(frame.hand_length_m))
                action = expert.act(env.unwrapped.expert_state()).vector
                obs, _, terminated, truncated, info = env.step(action)
                step += 1
                done = terminated or truncated
    finally:
        env.close()
    n = len(parts["K"])
    return FrameSet(
        depth_units=np.stack(parts["depth"]),
        depth_scale_m=np.full(n, scale_m),
        K=np.stack(parts["K"]),
        keypoints_cam=np.stack(parts["kp"]),
        occlusion=np.asarray(parts["occ"]),
        hand_length_m=np.asarray(parts["length"]),
        sensor=np.array([sensor] * n),
        is_left=np.asarray(parts["left"], dtype=bool),
        mirrored=np.asarray(parts["left"], dtype=bool) & bool(canonical_side),
    )
