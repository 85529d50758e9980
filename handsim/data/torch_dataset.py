"""A map-style torch dataset over handsim dataset folders (torch is imported per sample).

:class:`HandSimDataset` gives random access to every frame of one or more dataset folders
(``manifest.json`` + shards), filtered by split, occlusion, object and sensor, with an optional
transform. Shards are opened lazily in the process that reads, so the dataset is safe with
``DataLoader(num_workers > 0)`` (each worker opens its own files). It is a map-style dataset
(``__len__`` and ``__getitem__``), which is all ``DataLoader`` needs; torch is imported when a
sample is made, never by importing handsim.

A sample is a dict of tensors: ``depth`` (1, H, W) float32 metres (0 = no measurement),
``segmentation`` (H, W) int64, every label of :data:`~handsim.data.arrays.LABEL_SCHEMA` as a
tensor, ``episode`` and ``step``; the transform (if any) receives and returns that dict.
``keys=`` keeps only the named entries (less to read, convert and collate).

Throughput: ``DataLoader`` fetches a batch with one :meth:`HandSimDataset.__getitems__` call,
which reads each run of consecutive frames of a shard at once. Pass
``batch_sampler=dataset.batch_sampler(batch_size)`` (:class:`BlockBatchSampler`): batches made
of a few random blocks of consecutive frames, in a new random order every epoch, so that most
reads are whole blocks (a plain shuffled sampler reads frame by frame).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from handsim.data.manifest import Manifest
from handsim.data.shards import ShardReader
from handsim.data.splits import SPLITS, InvalidDatasetQuery, folder_splits, split_mask
from handsim.errors import HandSimError
from handsim.world.registry import OBJECTS

# SPLITS and InvalidDatasetQuery are importable from here too; they live in handsim.data.splits.
__all__ = [
    "HandSimDataset",
    "BlockBatchSampler",
]

_IMAGES = ("depth", "segmentation", "depth_clean")
_RUN_GAP = 4  # frames a run of reads may skip (filtered-out frames are read and dropped)


class HandSimDataset:
    """Frames of handsim dataset folders for PyTorch.

    Args:
        folders: one dataset folder or several.
        split: ``"train"``, ``"val"``, ``"test"`` (by episode, :mod:`handsim.data.splits`:
            10 % of a folder's episodes each for val and test, at least one each) or ``"all"``.
        occlusion_range: keep frames whose hand occlusion ratio lies in ``[low, high]``.
        objects: keep frames that show at least one of these objects (names).
        sensors: keep folders generated with one of these sensor models.
        transform: called on every sample dict.
        keys: keep only these entries of a sample (e.g. ``("depth", "keypoints_px",
            "visible")``); ``None`` keeps all.

    Raises:
        InvalidDatasetQuery: for a folder that is not a dataset, a bad split or filter, or a
            val / test split of a folder with too few episodes to have one.
    """

    def __init__(
        self,
        folders: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
        *,
        split: str = "all",
        occlusion_range: tuple[float, float] = (0.0, 1.0),
        objects: Sequence[str] | None = None,
        sensors: Sequence[str] | None = None,
        transform: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
        keys: Sequence[str] | None = None,
    ) -> None:
        if isinstance(folders, (str, os.PathLike)):
            folders = [folders]
        if split not in SPLITS:
            raise InvalidDatasetQuery(
                f"split must be one of {', '.join(SPLITS)}; received {split!r}"
            )
        lo, hi = self._range(occlusion_range)
        ycbv_ids = None
        if objects is not None:
            if isinstance(objects, str):
                raise InvalidDatasetQuery(
                    f"objects must be a list of object names; received {objects!r}"
                )
            ycbv_ids = []
            for name in objects:
                if name not in OBJECTS:
                    raise InvalidDatasetQuery(
                        f"unknown object {name!r}; valid: {', '.join(OBJECTS)}"
                    )
                ycbv_ids.append(OBJECTS[name].ycbv_id)
        if transform is not None and not callable(transform):
            raise InvalidDatasetQuery(f"transform must be callable; received {transform!r}")
        self.transform = transform
        if keys is not None:
            from handsim.data.arrays import DRAW_LABEL_SCHEMA, LABEL_SCHEMA

            valid = (
                *LABEL_SCHEMA,
                *DRAW_LABEL_SCHEMA,
                *("depth", "segmentation", "depth_clean", "episode", "step"),
            )
            if isinstance(keys, str) or not all(k in valid for k in keys):
                raise InvalidDatasetQuery(
                    f"keys must be a list drawn from {', '.join(valid)}; received {keys!r}"
                )
            keys = tuple(keys)
        self.keys = keys
        # Images to read: only those kept (decompressing an image is most of a read).
        self._images = None if keys is None else tuple(k for k in _IMAGES if k in keys)
        self._readers: list[ShardReader] = []
        index = []
        for folder in folders:
            try:
                manifest = Manifest.read(folder)
            except HandSimError as err:
                raise InvalidDatasetQuery(str(err)) from err
            if sensors is not None and manifest.config.get("sensor") not in sensors:
                continue
            splits = folder_splits(folder, manifest) if split != "all" else {}
            for record in sorted(manifest.shards.values(), key=lambda s: s.name):
                reader = ShardReader(Path(folder) / record.name)
                if len(reader) != record.frames:
                    raise InvalidDatasetQuery(
                        f"{Path(folder) / record.name} holds {len(reader)} frames but the "
                        f"manifest says {record.frames}: the folder was changed after it was "
                        "made; run `handsim dataset check` on it"
                    )
                keep = np.ones(len(reader), dtype=bool)
                if split != "all":
                    keep &= split_mask(splits, reader.labels("episode"), split, str(folder))
                ratio = np.nan_to_num(reader.labels("hand_occlusion_ratio"))
                keep &= (ratio >= lo) & (ratio <= hi)
                if ycbv_ids is not None:
                    shown = reader.labels("object_ycbv_id")
                    valid = reader.labels("object_valid")
                    keep &= (np.isin(shown, ycbv_ids) & valid).any(axis=1)
                reader.close()
                k = len(self._readers)
                self._readers.append(reader)
                index.extend((k, int(i)) for i in np.flatnonzero(keep))
        self._index = np.asarray(index, dtype=np.int64).reshape(-1, 2)

    @staticmethod
    def _range(value: object) -> tuple[float, float]:
        ok = (
            isinstance(value, (tuple, list))
            and len(value) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            and 0.0 <= value[0] <= value[1] <= 1.0
        )
        if not ok:
            raise InvalidDatasetQuery(
                f"occlusion_range must be (low, high) with 0 <= low <= high <= 1; received "
                f"{value!r}"
            )
        return float(value[0]), float(value[1])

    def __len__(self) -> int:
        return len(self._index)

    def _check_index(self, i: object) -> int:
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i < len(self):
            raise IndexError(f"sample {i!r} is out of range: the dataset has {len(self)}")
        return int(i)

    def _sample(self, arrays: dict[str, np.ndarray], row: int | None) -> dict[str, Any]:
        import torch

        sample = {}
        for key in self.keys if self.keys is not None else arrays:
            array = arrays[key] if row is None else arrays[key][row]
            if key in ("depth", "depth_clean"):
                array = array[None]
            elif key == "segmentation":
                array = array.astype(np.int64)
            sample[key] = torch.from_numpy(np.ascontiguousarray(array))
        return self.transform(sample) if self.transform is not None else sample

    def __getitem__(self, i: int) -> dict[str, Any]:
        shard, frame = self._index[self._check_index(i)]
        return self._sample(self._readers[shard][int(frame)], None)

    def _runs(
        self, indices: Sequence[int], stored: bool = False
    ) -> Iterator[tuple[dict[str, np.ndarray], np.ndarray, ShardReader]]:
        """Read ``indices`` in runs of nearby frames of one shard, in order.

        Yields ``(block, rows, reader)``: the block's arrays (images as stored with
        ``stored``), the rows of it that are the next samples, and the shard's reader. A run
        goes on while the next sample is a later frame of the same shard at most
        :data:`_RUN_GAP` frames on (filtered-out frames in between are read and dropped).
        """
        rows = self._index[[self._check_index(i) for i in indices]]
        k, n = 0, len(rows)
        while k < n:
            shard, first = rows[k]
            end = k + 1
            while (
                end < n
                and rows[end, 0] == shard
                and 0 < rows[end, 1] - rows[end - 1, 1] <= _RUN_GAP
            ):
                end += 1
            last = rows[end - 1, 1]
            reader = self._readers[shard]
            block = reader.read_block(int(first), int(last) + 1, self._images, stored=stored)
            yield block, rows[k:end, 1] - first, reader
            k = end

    def __getitems__(self, indices: Sequence[int]) -> list[dict[str, Any]]:
        """Samples ``indices``: what ``DataLoader`` asks for one batch.

        Runs of consecutive frames of a shard are read at once
        (:meth:`~handsim.data.shards.ShardReader.read_block`).
        """
        return [
            self._sample(block, int(row)) for block, rows, _ in self._runs(indices) for row in rows
        ]

    def batch(self, indices: Sequence[int]) -> dict[str, Any]:
        """Samples ``indices`` as one batch: a dict of stacked tensors, like ``default_collate``.

        The collate-free path of :meth:`loader`: the block reads are copied straight into the
        batch. Every tensor of the batch is a view of one buffer, allocated in shared memory
        inside a ``DataLoader`` worker, so a batch crosses to the main process as one shared
        segment instead of one per key (which cost more than reading it). The transform, if
        any, is applied to every sample (then they are collated as usual).

        Raises:
            InvalidDatasetQuery: if the batch mixes shards with and without a requested image
                (e.g. ``depth_clean``).
        """
        import torch

        if self.transform is not None:
            return torch.utils.data.default_collate(self.__getitems__(indices))
        runs = list(self._runs(indices, stored=True))
        n = sum(len(rows) for _, rows, _ in runs)
        first = runs[0][0] if runs else {}
        keys = [k for k in (self.keys if self.keys is not None else first) if k in first]
        layout, total = [], 0
        for key in keys:
            sample_shape = first[key].shape[1:]
            if key in ("depth", "depth_clean") or not sample_shape:
                sample_shape = (1, *sample_shape)  # a scalar label is (1,), as in __getitem__
            dtype = {"segmentation": np.dtype(np.int64), "depth": np.dtype(np.float32)}.get(
                key.replace("depth_clean", "depth"), first[key].dtype
            )
            layout.append((key, sample_shape, dtype, total))
            total += -(-n * int(np.prod(sample_shape)) * dtype.itemsize // 64) * 64  # aligned
        buffer = _new_buffer(total)
        out = {}
        for key, sample_shape, dtype, offset in layout:
            size = n * int(np.prod(sample_shape)) * dtype.itemsize
            tensor = buffer[offset : offset + size].view(_torch_dtype(dtype))
            out[key] = tensor.view(n, *sample_shape)
            target = tensor.numpy().reshape(n, *first[key].shape[1:])
            row = 0
            for block, rows, reader in runs:
                if key not in block:
                    raise InvalidDatasetQuery(
                        f"this batch mixes shards with and without {key!r}; leave it out of keys"
                    )
                whole = len(rows) == len(block["valid"])  # rows are then 0..n-1: no gather
                source = block[key] if whole else block[key][rows]
                rows_out = target[row : row + len(rows)]
                if key in ("depth", "depth_clean"):
                    # Stored units to metres, written straight into the batch (one pass).
                    scale = np.float32(reader.depth_scale_mm / 1000.0)
                    np.multiply(source, scale, out=rows_out, dtype=np.float32)
                else:
                    rows_out[...] = source  # uint8 -> int64 for the segmentation
                row += len(rows)
        return out

    def loader(
        self,
        batch_size: int,
        *,
        num_workers: int = 0,
        shuffle: bool = True,
        block_size: int = 8,
        seed: int = 0,
        **kwargs: Any,
    ):
        """A ``DataLoader`` of batches made by :meth:`batch` from a :class:`BlockBatchSampler`.

        The fastest way to read: batches of random blocks of consecutive frames, each batch
        read and turned into tensors in one call in a worker (no per-sample collation).
        ``kwargs`` go to ``torch.utils.data.DataLoader`` (e.g. ``persistent_workers=True``,
        ``pin_memory=True``).
        """
        import torch

        sampler = self.batch_sampler(batch_size, block_size=block_size, shuffle=shuffle, seed=seed)
        return torch.utils.data.DataLoader(
            _Batches(self),
            sampler=sampler,
            batch_size=None,
            num_workers=num_workers,
            **kwargs,
        )

    def batch_sampler(
        self, batch_size: int, *, block_size: int = 8, shuffle: bool = True, seed: int = 0
    ) -> BlockBatchSampler:
        """A :class:`BlockBatchSampler` over this dataset (``DataLoader(batch_sampler=...)``)."""
        return BlockBatchSampler(
            len(self), batch_size, block_size=block_size, shuffle=shuffle, seed=seed
        )


class _Batches:
    """A map-style view whose item ``[indices]`` is the batch :meth:`HandSimDataset.batch`."""

    def __init__(self, dataset: HandSimDataset) -> None:
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, indices: Sequence[int]) -> dict[str, Any]:
        return self.dataset.batch(indices)


class BlockBatchSampler:
    """Batches of random blocks of consecutive samples: fast reads, still shuffled.

    The samples ``0..n-1`` are cut into blocks of ``block_size`` consecutive indices (frames of
    one shard stay together); every epoch the blocks are shuffled and joined into batches of
    ``batch_size`` (a batch holds ``batch_size / block_size`` random blocks), so each shard is
    read a block at a time. Every sample appears once per epoch.

    Args:
        n: number of samples.
        batch_size: samples per batch (the last batch may be smaller).
        block_size: consecutive samples per block (1 = a plain shuffle).
        shuffle: shuffle the blocks every epoch (``False``: in order).
        seed: seed of the first epoch's order (epoch ``e`` uses ``(seed, e)``).

    Raises:
        InvalidDatasetQuery: for a non-positive size.
    """

    def __init__(
        self, n: int, batch_size: int, *, block_size: int = 8, shuffle: bool = True, seed: int = 0
    ) -> None:
        for name, value, low in (
            ("n", n, 0),
            ("batch_size", batch_size, 1),
            ("block_size", block_size, 1),
        ):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise InvalidDatasetQuery(f"{name} must be an integer >= {low}; received {value!r}")
        self.n, self.batch_size, self.block_size = int(n), int(batch_size), int(block_size)
        self.shuffle, self.seed, self.epoch = bool(shuffle), int(seed), 0

    def __len__(self) -> int:
        return -(-self.n // self.batch_size)

    def __iter__(self):
        starts = np.arange(0, self.n, self.block_size)
        if self.shuffle:
            np.random.default_rng([self.seed, self.epoch]).shuffle(starts)
        self.epoch += 1
        order = np.concatenate(
            [np.arange(s, min(s + self.block_size, self.n)) for s in starts] or [np.zeros(0, int)]
        )
        for b in range(0, self.n, self.batch_size):
            yield order[b : b + self.batch_size].tolist()


def _torch_dtype(dtype: np.dtype):
    import torch

    return torch.from_numpy(np.empty(0, dtype=dtype)).dtype


def _new_buffer(nbytes: int):
    """A (nbytes,) uint8 tensor, in shared memory inside a DataLoader worker.

    What ``default_collate`` does for its batches: the worker writes the batch once, and
    sending it to the main process copies nothing.
    """
    import torch

    if torch.utils.data.get_worker_info() is not None:
        storage = torch.empty(0, dtype=torch.uint8).untyped_storage()._new_shared(nbytes)
        return torch.empty(0, dtype=torch.uint8).set_(storage)
    return torch.empty(nbytes, dtype=torch.uint8)
