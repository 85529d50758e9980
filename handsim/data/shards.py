"""Dataset shards: HDF5 files of labelled frames, written crash-safe, read with random access.

A shard is written under a temporary name (``<name>.h5.partial``) and renamed to
``<name>.h5`` only when it is complete (:meth:`ShardWriter.close`), so a run killed at any
moment leaves complete shards and at most one partial file per worker, which a resumed run
deletes and writes again. HDF5 via h5py, chunked and gzip-compressed (one chunk per image):

=================  ==================  ========  ============================================
dataset            shape               dtype     content
=================  ==================  ========  ============================================
``depth``          (N, H, W)           uint16    depth in units of ``depth_scale_mm`` (0 = none)
``depth_clean``    (N, H, W)           uint16    noise-free depth, when paired depth is kept
``segmentation``   (N, H, W)           uint8     segmentation labels (background 0, hand 4-9,
                                                 objects 10+)
``episode``        (N,)                int64     episode index of the frame
``step``           (N,)                int64     step index within the episode
``labels/<key>``   (N, ...)            schema    each label of the array form (``LABEL_SCHEMA``)
                                                 and how the frame was drawn
                                                 (``DRAW_LABEL_SCHEMA``; -1 if not given)
=================  ==================  ========  ============================================

Depth is stored as ``round(depth_m * 1000 / depth_scale_mm)`` (BOP's convention; the default
0.1 mm gives a 6.5535 m range at 0.05 mm worst-case rounding error); depth beyond the range is
stored as 0 (no measurement). File attributes: ``format`` (:data:`SHARD_FORMAT`),
``depth_scale_mm``, ``image_shape`` and ``frames``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import functools
import hashlib
import io
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from isal import isal_zlib

from handsim.data import _kernels
from handsim.data.arrays import (
    ADDED_LABELS,
    DRAW_LABEL_SCHEMA,
    LABEL_SCHEMA,
    check_label_arrays,
    fill_added_labels,
)
from handsim.errors import HandSimError

__all__ = [
    "SHARD_FORMAT",
    "SHARD_SUFFIX",
    "PARTIAL_SUFFIX",
    "DEFAULT_DEPTH_SCALE_MM",
    "InvalidShard",
    "DatasetWriteError",
    "ShardInfo",
    "ShardWriter",
    "ShardReader",
    "check_shard",
    "file_sha256",
    "depth_units",
]

SHARD_FORMAT = "handsim-shard-1"
"""Format tag written into every shard (bumped when the layout changes)."""
SHARD_SUFFIX = ".h5"
"""Suffix of a complete shard."""
PARTIAL_SUFFIX = ".h5.partial"
"""Suffix of a shard being written (never read; deleted on resume)."""
DEFAULT_DEPTH_SCALE_MM = 0.1
"""Stored depth unit, millimetres (BOP ``depth_scale``)."""
DEPTH_SCALE_RANGE_MM = (0.001, 10.0)
"""Stored depth units a dataset may use, millimetres (a config's and a manifest's)."""

# gzip (every HDF5 reader has it) at level 1: a depth image is mostly zeros, and level 1
# writes it ~2x and decodes it ~3x faster than level 4, for ~20 % more bytes. Byte shuffle
# helps the float labels but not the images. Shards written with other filters read the same.
_IMAGE_COMPRESSION = {"compression": "gzip", "compression_opts": 1}
# Images are deflated here with ISA-L (python-isal) and written as raw chunks: the same zlib
# streams HDF5's gzip filter decodes, made 4-6x faster than zlib's level 1 and a little
# smaller, without HDF5's chunk cache.
_IMAGE_DEFLATE_LEVEL = 1
_LABEL_COMPRESSION = {"compression": "gzip", "compression_opts": 1, "shuffle": True}
_LABEL_CHUNK = 64  # frames per label chunk
# Every label a shard stores: the array form, then how the frame was drawn.
_SHARD_LABELS = {**LABEL_SCHEMA, **DRAW_LABEL_SCHEMA}


def depth_units(
    depth_m: np.ndarray, depth_scale_mm: float, out: np.ndarray | None = None
) -> np.ndarray:
    """Depth in metres as uint16 units of ``depth_scale_mm``; out of range or invalid -> 0.

    ``out``: a uint16 array of the depth's shape to write into (default: a new one).
    """
    depth = np.asarray(depth_m)
    if depth.dtype not in (np.float32, np.float64):
        depth = depth.astype(np.float64)
    if out is None:
        out = np.empty(depth.shape, dtype=np.uint16)
    target = out if out.flags.c_contiguous else np.empty(out.shape, dtype=out.dtype)
    _kernels.depth_units_into(
        np.ascontiguousarray(depth).reshape(-1), 1000.0 / depth_scale_mm, target.reshape(-1)
    )
    if target is not out:
        np.copyto(out, target)
    return out


class InvalidShard(HandSimError, ValueError):
    """A shard is missing, truncated, corrupt or not a handsim shard; the message names it."""


class DatasetWriteError(HandSimError, OSError):
    """A dataset file could not be written (a full disk, a quota); the message names the folder."""


def write_error(err: OSError, path: Path, what: str) -> DatasetWriteError:
    """The :class:`DatasetWriteError` of a failed write of ``what`` at ``path``."""
    if err.errno in (errno.ENOSPC, errno.EDQUOT):
        cause = "the disk is full (no space left on device)"
        if err.errno == errno.EDQUOT:
            cause = "the disk quota is exceeded"
    else:
        cause = f"{err.strerror or err}"
    return DatasetWriteError(
        f"{what} could not be written in {path.parent}: {cause}. Nothing half-written is kept "
        "and the complete shards stay: free space (or choose another --out) and rerun the "
        "same command to resume"
    )


class _GuardedFile(io.FileIO):
    """The file HDF5 writes a shard through: its first failed write is kept, not retried.

    After a failed write (a full disk) HDF5's close flushes its metadata again, fails again and
    leaves the file open in the library, which then crashes at exit (a segfault, measured on a
    full tmpfs). Once ``discard`` is set, writes are dropped so the close completes; the partial
    file is deleted after.
    """

    error: OSError | None = None
    discard = False

    def readinto(self, buffer: Any) -> int:
        # HDF5 reads blocks it has allocated but not yet written; h5py's file-object driver
        # leaves the part past the end of the file as it was (uninitialized memory, which
        # HDF5 could write back into the shard). Zeros, as HDF5's own driver gives.
        view = memoryview(buffer).cast("B")
        n = super().readinto(view) or 0
        if n < len(view):
            view[n:] = bytes(len(view) - n)
        return len(view)

    def write(self, data: Any) -> int:
        view = memoryview(data).cast("B")
        if self.discard:
            return len(view)
        # h5py's file-object driver ignores a short write's count: finish it here, as HDF5's
        # own driver does (the rest of a short write on a nearly full disk raises ENOSPC).
        done = 0
        try:
            while done < len(view):
                wrote = super().write(view[done:])
                if not wrote:
                    raise OSError(errno.EIO, f"no byte of a write reached {self.name}")
                done += wrote
        except OSError as err:
            self.error = self.error or err
            raise
        return done

    def truncate(self, size: int | None = None) -> int:
        if self.discard:
            return self.tell() if size is None else size
        try:
            return super().truncate(size)
        except OSError as err:
            self.error = self.error or err
            raise


@dataclasses.dataclass(frozen=True)
class ShardInfo:
    """A complete shard as the manifest records it.

    Attributes:
        name: file name, e.g. ``"shard-00003.h5"``.
        frames: number of frames.
        sha256: hex SHA-256 of the file.
        bytes: file size, bytes.
        redraws: episodes redrawn while making the shard, by cause (see
            :class:`~handsim.data.config.CannotDraw`); empty when none were (or for a
            dataset made before they were counted).
    """

    name: str
    frames: int
    sha256: str
    bytes: int
    redraws: dict[str, int] = dataclasses.field(default_factory=dict)


def file_sha256(path: str | os.PathLike[str]) -> str:
    """Hex SHA-256 of a file, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _check_depth_scale(depth_scale_mm: object) -> float:
    if (
        isinstance(depth_scale_mm, bool)
        or not isinstance(depth_scale_mm, (int, float, np.floating, np.integer))
        or not np.isfinite(depth_scale_mm)
        or not 0.001 <= depth_scale_mm <= 10.0
    ):
        raise InvalidShard(
            f"depth_scale_mm must be a number in [0.001, 10] mm; received {depth_scale_mm!r}"
        )
    return float(depth_scale_mm)


class ShardWriter:
    """Writes labelled frames to one shard, under a temporary name until :meth:`close`.

    Use it as a context manager: leaving the block normally completes the shard; an exception
    deletes the partial file (nothing half-written is ever named ``*.h5``).

    Args:
        path: the complete shard's path (must end in ``.h5``).
        image_shape: ``(H, W)`` of every frame.
        depth_scale_mm: stored depth unit, millimetres.
        paired_clean: also store the noise-free depth (``depth_clean`` in each frame's arrays).

    Raises:
        InvalidShard: for a bad path, shape or scale.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        image_shape: tuple[int, int],
        depth_scale_mm: float = DEFAULT_DEPTH_SCALE_MM,
        paired_clean: bool = False,
    ) -> None:
        import h5py

        self.path = Path(path)
        if self.path.suffix != SHARD_SUFFIX:
            raise InvalidShard(f"a shard path must end in {SHARD_SUFFIX!r}; received {self.path}")
        shape = tuple(image_shape) if isinstance(image_shape, (tuple, list)) else ()
        if len(shape) != 2 or not all(
            isinstance(s, (int, np.integer)) and not isinstance(s, bool) and 1 <= s <= 8192
            for s in shape
        ):
            raise InvalidShard(
                f"image_shape must be (H, W) with 1 <= H, W <= 8192; received {image_shape!r}"
            )
        self.image_shape = (int(shape[0]), int(shape[1]))
        self.depth_scale_mm = _check_depth_scale(depth_scale_mm)
        self.paired_clean = bool(paired_clean)
        self.partial_path = self.path.with_name(self.path.stem + PARTIAL_SUFFIX)
        self.frames = 0
        self._written = 0  # frames already in the file; the others wait in _pending
        # Frames not yet written: one preallocated block of _LABEL_CHUNK rows per label
        # dataset, and each image's compressed chunk.
        self._pending: dict[str, np.ndarray] = {}
        self._pending_chunks: dict[str, list[bytes]] = {}
        self._datasets: dict[str, h5py.Dataset] = {}
        self._file = None
        try:
            self._io = _GuardedFile(self.partial_path, "w+")
        except OSError as err:
            raise write_error(err, self.path, self.path.name) from err
        try:
            self._file = h5py.File(self._io, "w")
            self._create()
        except Exception as err:
            raise self._failed(err) from err

    def _create(self) -> None:
        f, (h, w) = self._file, self.image_shape
        f.attrs.update(
            format=SHARD_FORMAT, depth_scale_mm=self.depth_scale_mm, image_shape=(h, w), frames=0
        )
        images = ["depth", "segmentation"] + (["depth_clean"] if self.paired_clean else [])
        # Each image of a frame is converted into its buffer, then compressed to a chunk.
        self._image_buffers = {
            key: np.empty((h, w), np.uint8 if key == "segmentation" else np.uint16)
            for key in images
        }
        self._pending_chunks = {key: [] for key in images}
        for key, buffer in self._image_buffers.items():
            self._datasets[key] = f.create_dataset(
                key,
                (0, h, w),
                buffer.dtype,
                maxshape=(None, h, w),
                chunks=(1, h, w),
                **_IMAGE_COMPRESSION,
            )
        for key in ("episode", "step"):
            self._datasets[key] = f.create_dataset(
                key, (0,), np.int64, maxshape=(None,), chunks=(_LABEL_CHUNK,)
            )
        labels = f.create_group("labels")
        for key, (shape_k, dtype, unit) in _SHARD_LABELS.items():
            ds = labels.create_dataset(
                key,
                (0, *shape_k),
                dtype,
                maxshape=(None, *shape_k),
                chunks=(_LABEL_CHUNK, *shape_k),
                **_LABEL_COMPRESSION,
            )
            ds.attrs["unit"] = unit
            self._datasets["labels/" + key] = ds
        self._pending = {
            key: np.empty((_LABEL_CHUNK, *ds.shape[1:]), ds.dtype)
            for key, ds in self._datasets.items()
            if key not in self._pending_chunks
        }

    def _depth_units(self, depth_m: np.ndarray, key: str, out: np.ndarray) -> None:
        depth = np.asarray(depth_m)
        if depth.shape != self.image_shape or depth.dtype.kind != "f":
            raise InvalidShard(
                f"{key} must be a float array of shape {self.image_shape}; received "
                f"{depth.dtype} of shape {depth.shape}"
            )
        depth_units(depth, self.depth_scale_mm, out=out)

    def append(self, arrays: Mapping[str, np.ndarray], *, episode: int, step: int) -> None:
        """Add one frame.

        Args:
            arrays: :meth:`Frame.to_arrays(images=True) <handsim.frame.record.Frame.to_arrays>`
                of the frame (every label, ``depth`` and ``segmentation``; ``depth_clean`` when the
                writer keeps paired depth).
            episode: the frame's episode index.
            step: the frame's step index in its episode.

        Raises:
            InvalidShard: if an image is missing or of the wrong shape.
            InvalidLabelArrays: if a label does not follow the schema.
        """
        if self._file is None:
            raise InvalidShard(f"shard {self.path.name} is closed; open a new ShardWriter")
        check_label_arrays(arrays)
        needed = ["depth", "segmentation"] + (["depth_clean"] if self.paired_clean else [])
        missing = [k for k in needed if k not in arrays]
        if missing:
            raise InvalidShard(
                f"frame arrays lack {', '.join(missing)}: use frame.to_arrays(images=True)"
                + (" with a renderer that keeps clean depth" if "depth_clean" in missing else "")
            )
        seg = np.asarray(arrays["segmentation"])
        if seg.shape != self.image_shape or seg.min(initial=0) < 0 or seg.max(initial=0) > 255:
            raise InvalidShard(
                f"segmentation must be labels 0..255 of shape {self.image_shape}; received "
                f"shape {seg.shape}"
            )
        row, pending, images = self.frames - self._written, self._pending, self._image_buffers
        self._depth_units(arrays["depth"], "depth", images["depth"])
        if self.paired_clean:
            self._depth_units(arrays["depth_clean"], "depth_clean", images["depth_clean"])
        np.copyto(images["segmentation"], seg, casting="unsafe")  # 0..255, checked above
        for key, image in images.items():
            self._pending_chunks[key].append(isal_zlib.compress(image, _IMAGE_DEFLATE_LEVEL))
        pending["episode"][row] = episode
        pending["step"][row] = step
        for key in LABEL_SCHEMA:  # dtypes checked above
            pending["labels/" + key][row] = arrays[key]
        for key in DRAW_LABEL_SCHEMA:
            pending["labels/" + key][row] = arrays.get(key, -1)
        self.frames += 1
        if self.frames - self._written == _LABEL_CHUNK:
            self._flush()

    def _failed(self, err: Exception) -> Exception:
        """Drop the partial shard after ``err``; the error to raise (a failed write named)."""
        written = self._io.error
        self.abort()
        if written is not None:
            return write_error(written, self.path, self.path.name)
        return err

    def _flush(self) -> None:
        try:
            self._write_pending()
        except Exception as err:
            raise self._failed(err) from err

    def _write_pending(self) -> None:
        # One resize and one write per dataset per block of frames: h5py's per-call overhead
        # (tens of calls per frame) was most of the writing time.
        n = self.frames - self._written
        if n == 0:
            return
        for key, block in self._pending.items():
            dataset = self._datasets[key]
            dataset.resize(self.frames, axis=0)
            dataset[self._written : self.frames] = block[:n]
        for key, chunks in self._pending_chunks.items():
            dataset = self._datasets[key]
            dataset.resize(self.frames, axis=0)
            for i, chunk in enumerate(chunks, start=self._written):
                dataset.id.write_direct_chunk((i, 0, 0), chunk)
            chunks.clear()
        self._written = self.frames

    def close(self) -> ShardInfo:
        """Complete the shard: flush, rename to its final name and return its record."""
        if self._file is None:
            raise InvalidShard(f"shard {self.path.name} is already closed")
        self._flush()
        try:
            self._file.attrs["frames"] = self.frames
            self._file.close()
            self._file = None
            self._io.close()
            os.replace(self.partial_path, self.path)
        except Exception as err:
            raise self._failed(err) from err
        return ShardInfo(
            name=self.path.name,
            frames=self.frames,
            sha256=file_sha256(self.path),
            bytes=self.path.stat().st_size,
        )

    def abort(self) -> None:
        """Drop the shard: close and delete the partial file (the final name is never made)."""
        # Nothing more reaches the disk: HDF5's close after a failed write would fail again.
        self._io.discard = True
        self._datasets.clear()
        if self._file is not None:
            file, self._file = self._file, None
            with contextlib.suppress(Exception):
                file.close()
        with contextlib.suppress(OSError):
            self._io.close()
        self.partial_path.unlink(missing_ok=True)

    def __enter__(self) -> ShardWriter:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if exc_type is None:
            self.info = self.close()
        else:
            self.abort()


def _named_on_corruption(method: Callable) -> Callable:
    """Make a damaged shard's read error name the file.

    A read of damaged bytes (h5py's OSError, e.g. a failed filter) raises :class:`InvalidShard`
    naming the file and the check to run, not a bare HDF5 error.
    """

    @functools.wraps(method)
    def read(self: ShardReader, *args: Any, **kwargs: Any) -> Any:
        try:
            return method(self, *args, **kwargs)
        except OSError as err:
            raise InvalidShard(
                f"{self.path} cannot be read ({err}): the shard is damaged; run `handsim "
                "dataset check` on its folder (a rerun of `handsim generate` makes it again)"
            ) from err

    return read


class ShardReader:
    """Random access to the frames of one complete shard.

    The file is opened on first access in the process that reads (and re-opened after a
    fork), so one reader can be handed to ``DataLoader`` workers.

    Args:
        path: a complete shard (``*.h5``).

    Raises:
        InvalidShard: if the file is not a readable handsim shard.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._file = None
        self._pid = None
        self._labels: dict[str, np.ndarray] | None = None
        self._labels_pid: int | None = None
        f = self._open()
        self.frames = int(f.attrs["frames"])
        self.depth_scale_mm = float(f.attrs["depth_scale_mm"])
        self.image_shape = tuple(int(s) for s in f.attrs["image_shape"])
        self.has_clean = "depth_clean" in f

    def _open(self):
        import h5py

        if self._file is None or self._pid != os.getpid():
            try:
                self._file = h5py.File(self.path, "r")
            except (OSError, ValueError) as err:
                raise InvalidShard(f"{self.path} is not a readable HDF5 file ({err})") from err
            self._pid = os.getpid()
            if self._file.attrs.get("format") != SHARD_FORMAT:
                raise InvalidShard(
                    f"{self.path} is not a handsim shard (format "
                    f"{self._file.attrs.get('format')!r}, expected {SHARD_FORMAT!r})"
                )
        return self._file

    def __len__(self) -> int:
        return self.frames

    @_named_on_corruption
    def __getitem__(self, index: int) -> dict[str, np.ndarray]:
        """Frame ``index``: every label, ``depth`` (float32 metres), ``segmentation``, indices."""
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise InvalidShard(f"a frame index must be an int; received {type(index).__name__}")
        if not -self.frames <= index < self.frames:
            raise InvalidShard(
                f"frame {index} is out of range: {self.path.name} has {self.frames} frames"
            )
        index = int(index) % self.frames
        f = self._open()
        scale = np.float32(self.depth_scale_mm / 1000.0)
        labels = self._all_labels()
        out = {key: values[index].copy() for key, values in labels.items()}
        out["depth"] = f["depth"][index].astype(np.float32) * scale
        out["segmentation"] = f["segmentation"][index].astype(np.int16)
        if self.has_clean:
            out["depth_clean"] = f["depth_clean"][index].astype(np.float32) * scale
        out["episode"] = labels["episode"][index]
        out["step"] = labels["step"][index]
        return out

    @_named_on_corruption
    def read_block(
        self,
        start: int,
        stop: int,
        images: tuple[str, ...] | None = None,
        *,
        stored: bool = False,
    ) -> dict[str, np.ndarray]:
        """Frames ``start`` to ``stop - 1`` at once, ``(n, ...)`` arrays as :meth:`__getitem__`.

        One read per image dataset for the whole block (faster than frame by frame).
        ``images`` limits the images read (``depth``, ``segmentation``, ``depth_clean``);
        ``None`` reads them all. ``stored``: images as stored (depth uint16 in units of
        :attr:`depth_scale_mm`, segmentation uint8), for a caller that converts them into
        its own arrays.

        Raises:
            InvalidShard: for a range outside ``[0, frames]`` or an empty one.
        """
        if not (
            isinstance(start, (int, np.integer))
            and isinstance(stop, (int, np.integer))
            and 0 <= start < stop <= self.frames
        ):
            raise InvalidShard(
                f"a block must satisfy 0 <= start < stop <= {self.frames} ({self.path.name}); "
                f"received {start!r}, {stop!r}"
            )
        f = self._open()
        scale = np.float32(self.depth_scale_mm / 1000.0)
        out = {key: values[start:stop].copy() for key, values in self._all_labels().items()}
        wanted = ("depth", "segmentation", "depth_clean") if images is None else images
        for key in ("depth", "depth_clean"):
            if key in wanted and key in f:
                units = f[key][start:stop]
                out[key] = units if stored else np.multiply(units, scale, dtype=np.float32)
        if "segmentation" in wanted:
            segmentation = f["segmentation"][start:stop]
            out["segmentation"] = segmentation if stored else segmentation.astype(np.int16)
        return out

    @_named_on_corruption
    def _all_labels(self) -> dict[str, np.ndarray]:
        # Labels are a few kB per frame: read each shard's once (per process) instead of
        # decompressing a 64-frame chunk of every label for every sample.
        if self._labels is None or self._labels_pid != os.getpid():
            f = self._open()
            # Shards written before a label was added get it filled (arrays.ADDED_LABELS).
            self._labels = fill_added_labels({key: ds[:] for key, ds in f["labels"].items()})
            for key, (shape, dtype, _) in DRAW_LABEL_SCHEMA.items():
                if key not in self._labels:  # a shard written before these labels
                    self._labels[key] = np.full((self.frames, *shape), -1, dtype)
            self._labels["episode"] = f["episode"][:]
            self._labels["step"] = f["step"][:]
            self._labels_pid = os.getpid()
        return self._labels

    def labels(self, key: str) -> np.ndarray:
        """One label over every frame, ``(N, *shape)`` (e.g. for filtering)."""
        if key not in _SHARD_LABELS and key not in ("episode", "step"):
            raise InvalidShard(
                f"unknown label {key!r}; valid: episode, step, {', '.join(_SHARD_LABELS)}"
            )
        return self._all_labels()[key].copy()

    def close(self) -> None:
        """Close the file (it re-opens on the next access)."""
        if self._file is not None:
            self._file.close()
            self._file = None
        self._labels = None


def check_shard(path: str | os.PathLike[str], expected: ShardInfo | None = None) -> list[str]:
    """What is wrong with a shard, as sentences naming it; empty when it is sound.

    Reads every chunk, so truncation and corruption are found; never raises for a bad file.

    Args:
        path: the shard's path.
        expected: the manifest's record (frames and checksum are compared when given).
    """
    path = Path(path)
    if not path.is_file():
        return [f"{path.name}: missing"]
    problems = []
    if expected is not None:
        size = path.stat().st_size
        if size != expected.bytes:
            problems.append(f"{path.name}: {size} bytes, the manifest says {expected.bytes}")
        elif file_sha256(path) != expected.sha256:
            problems.append(f"{path.name}: checksum differs from the manifest (corrupt)")
    try:
        reader = ShardReader(path)
        f = reader._open()
        n = reader.frames
        for key in ("depth", "segmentation", "episode", "step"):
            if key not in f or f[key].shape[0] != n:
                problems.append(f"{path.name}: dataset {key!r} missing or not {n} frames long")
        for key in LABEL_SCHEMA:
            if key in ADDED_LABELS and key not in f["labels"]:
                continue  # an older shard: the reader fills it
            if key not in f["labels"] or f["labels"][key].shape[0] != n:
                problems.append(f"{path.name}: label {key!r} missing or not {n} frames long")
        if not problems:
            for key in ("depth", "segmentation", "depth_clean"):
                if key in f:
                    for i in range(n):  # one chunk per frame
                        f[key][i]
            for ds in f["labels"].values():
                ds[:]
        if expected is not None and n != expected.frames:
            problems.append(f"{path.name}: {n} frames, the manifest says {expected.frames}")
        reader.close()
    except InvalidShard as err:
        problems.append(f"{path.name}: {err}")
    except Exception as err:  # noqa: BLE001 - any decoding failure means a corrupt shard
        problems.append(f"{path.name}: unreadable ({type(err).__name__}: {err})")
    return problems
