"""handsim-bench's test sets: what they are, how they are made, and their content digests.

:data:`SETS` are the versioned test sets of :data:`VERSION`, each a dataset folder made by
:func:`~handsim.data.generation.generate` from a fixed seed. A versioned set never changes: a
change of the generator that changes a set needs a new version, with a new name. That promise
is checked, not trusted: :func:`set_digest` hashes what defines a set's frames, and
:data:`DIGESTS` records the digest of every set of every version, so
:func:`make_benchmark` refuses sets that differ from the ones the version names. The command
line (``handsim benchmark make / run / compare``) is :mod:`handsim.cli.benchmark`.

The digest (:data:`DIGEST_SCHEME`) is a SHA-256 over every shard of the set, in shard order,
frame by frame as stored: the images exactly (depth as its stored ``uint16`` units of
``depth_scale_mm``, segmentation, paired clean depth if kept), every label of the shard
(:data:`~handsim.data.arrays.LABEL_SCHEMA`, how each frame was drawn, episode and step) with
integers and booleans exact and floats rounded to :data:`DIGEST_FLOAT_STEP` of their unit
(1 um, 1 urad, 1e-6 px; a NaN pixel of a keypoint behind the camera as one fixed value), and
each array's name, dtype and shape. The stored images are already quantized (0.1 mm depth), so
they are compared exactly: what an estimator sees may not move at all. Floats are rounded so
that a last-bit difference of float arithmetic (another NumPy SIMD path or BLAS) does not
change the digest, while any change of a label by a micrometre does. The digest reads the
decoded arrays, not the files, so the HDF5 and compression libraries do not enter it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from handsim.errors import HandSimError
from handsim.hand.blas import blas_kernels

__all__ = [
    "VERSION",
    "BenchSet",
    "SETS",
    "DIGESTS",
    "DIGEST_SCHEME",
    "DIGEST_FLOAT_STEP",
    "BenchmarkError",
    "version_name",
    "set_digest",
    "make_benchmark",
    "BLAS_KERNEL",
    "recorded_blas_environment",
    "read_benchmark",
    "valid_frames",
]

VERSION = "handsim-bench-v1"
"""The version ``make`` builds. Never change a set under it: a new set is a new version."""

DIGEST_SCHEME = "handsim-bench-digest-1"
"""Name of the digest's definition (the module docstring); hashed first, so a change of the
definition changes every digest."""

DIGEST_FLOAT_STEP = 1e-6
"""Float labels are hashed rounded to this step of their unit (m, rad, px, N)."""

BLAS_KERNEL = "Haswell"
"""OpenBLAS's kernels (``OPENBLAS_CORETYPE``) that the digests were recorded with. The sets of
grasps in contact are simulated, and a simulation carries a last-bit difference of its inputs
into a different grasp: with the kernels OpenBLAS picks on an AVX-512 CPU (NumPy's matrix
products round differently) ``hand_object`` differs. ``handsim benchmark make`` generates with
these kernels where the CPU runs them (x86-64 with AVX2 and FMA)."""


def recorded_blas_environment() -> dict[str, str] | None:
    """The environment for a process that generates with :data:`BLAS_KERNEL`, or ``None``.

    ``None`` when this process already chose (``OPENBLAS_CORETYPE`` is set: the kernel is picked
    when NumPy loads OpenBLAS, so only a new process can change it) or when the CPU cannot run
    the kernels (not x86-64 Linux with AVX2 and FMA: such a machine makes what it makes, and
    ``make`` refuses sets that differ).
    """
    import os
    import platform

    if "OPENBLAS_CORETYPE" in os.environ or platform.machine() != "x86_64":
        return None
    try:
        cpuinfo = Path("/proc/cpuinfo").read_text()
    except OSError:
        return None
    flags = next((line for line in cpuinfo.splitlines() if line.startswith("flags")), "")
    if not {"avx2", "fma"} <= set(flags.split()):
        return None
    return {**os.environ, "OPENBLAS_CORETYPE": BLAS_KERNEL}


_HAND_ONLY = {"num_objects_range": (0, 0), "frames_per_episode": 5}


@dataclasses.dataclass(frozen=True)
class BenchSet:
    """One test set of the benchmark.

    Attributes:
        name: folder name.
        what: one line for the report.
        frames: frames of the set.
        config: :class:`~handsim.data.config.GenerationConfig` fields besides ``frames``.
    """

    name: str
    what: str
    frames: int
    config: dict[str, Any]


SETS: tuple[BenchSet, ...] = (
    BenchSet(
        "hand_third_person",
        "hand alone, third person, structured light",
        300,
        {**_HAND_ONLY, "viewpoints": ("third_person",), "seed": 2601},
    ),
    BenchSet(
        "hand_egocentric",
        "hand alone, egocentric, structured light",
        300,
        {**_HAND_ONLY, "viewpoints": ("egocentric",), "seed": 2602},
    ),
    BenchSet(
        "hand_object",
        "hand grasping 1-3 objects (in contact), structured light",
        300,
        {"source": "grasp", "num_objects_range": (1, 3), "frames_per_episode": 5, "seed": 2603},
    ),
    BenchSet(
        "occlusion",
        "hand behind objects, 4 occlusion buckets 0.1-0.95 in equal parts",
        100,
        {
            "source": "grasp",
            "num_objects_range": (2, 4),
            "viewpoints": ("through_object",),
            "distance_range_m": (0.4, 0.7),
            "occlusion_buckets": ((0.1, 0.3, 0.5, 0.7, 0.95), (0.25, 0.25, 0.25, 0.25)),
            "max_fraction_below_min_visible": 0.05,
            "frames_per_episode": 5,
            "seed": 2604,
        },
    ),
    BenchSet(
        "sensor_none",
        "hand alone, third person, noise-free depth",
        150,
        {**_HAND_ONLY, "viewpoints": ("third_person",), "sensor": "none", "seed": 2605},
    ),
    BenchSet(
        "sensor_tof",
        "hand alone, third person, time of flight",
        150,
        {**_HAND_ONLY, "viewpoints": ("third_person",), "sensor": "tof", "seed": 2606},
    ),
)
"""The sets of :data:`VERSION`. Every set has both sides (``left_fraction`` 0.5), the ICVL
camera (320 x 240) and one shard per 100 frames; the three sensor models are the
``structured_light`` of ``hand_third_person`` and the two ``sensor_*`` sets."""

DIGESTS: dict[str, dict[str, str]] = {
    VERSION: {
        "hand_third_person": (
            "sha256:c51961c08949a8aad511652d79bb49309ad591597fe9cf303d72043af6442957"
        ),
        "hand_egocentric": (
            "sha256:82aa4661f32758c4fa6dada6e6c2353a091eccab552012ffc234db6e21ffc4ed"
        ),
        "hand_object": "sha256:bcd061fa56136bd32cc9650f2986ad1da2645e15f2e85b3c06fbaa5a7f7a4ce1",
        "occlusion": "sha256:e8c6e7df535c05bb50eb33d5b95cd66eb7fb3efd08dd76609e7cf9cfd7ba7256",
        "sensor_none": "sha256:7b85b952235f4df0f017c844770e59314f7f6c9174e3f9094817d54eb405b006",
        "sensor_tof": "sha256:da10ecdec3a250175b108210083f5113cc605313adf53f8fcf53e16c92fde3c0",
    },
}
"""Version name -> set name -> :func:`set_digest` of the set that version names. A version
that is not here (a resized test benchmark, ``-nN``) is checked against the digests its own
folder recorded when it was first made."""


class BenchmarkError(HandSimError, ValueError):
    """A benchmark folder is not one, holds another version, or cannot be made."""


def version_name(frames_per_set: int | None) -> str:
    """The version name of a benchmark of ``frames_per_set`` frames per set (``None``: its own).

    A resized benchmark is not the benchmark: it carries its size in its name
    (``handsim-bench-v1-nN``).
    """
    return VERSION if frames_per_set is None else f"{VERSION}-n{frames_per_set}"


def _configs(frames_per_set: int | None) -> dict[str, Any]:
    from handsim.data.config import GenerationConfig

    out = {}
    for s in SETS:
        frames = s.frames if frames_per_set is None else frames_per_set
        out[s.name] = GenerationConfig(frames=frames, frames_per_shard=min(frames, 100), **s.config)
    return out


def _canonical(values: np.ndarray) -> np.ndarray:
    """An array as the digest hashes it: floats on the rounding grid, all little-endian."""
    if values.dtype.kind == "f":
        finite = np.isfinite(values)
        steps = np.round(np.where(finite, values, 0.0) / DIGEST_FLOAT_STEP)
        # int64 holds the grid up to 9.2e12 units; -0.0 and 0.0 become the same 0.
        out = steps.astype("<i8")
        out[~finite] = np.iinfo(np.int64).min
        return out
    if values.dtype.kind == "b":
        return values.astype(np.uint8)
    return values.astype(values.dtype.newbyteorder("<"), copy=False)


def set_digest(folder: str | Path) -> str:
    """The content digest of one dataset folder (a benchmark set): ``"sha256:<hex>"``.

    What it covers is in the module docstring. Two folders have the same digest exactly when
    their shards hold the same frames in the same order (floats up to
    :data:`DIGEST_FLOAT_STEP`).

    Args:
        folder: a dataset folder with ``manifest.json`` (complete shards only).

    Returns:
        ``"sha256:"`` and 64 hex digits.

    Raises:
        InvalidManifest: if the folder is not a dataset.
        InvalidShard: if a shard cannot be read (the message names it).
    """
    from handsim.data.manifest import Manifest
    from handsim.data.shards import ShardReader

    folder = Path(folder)
    manifest = Manifest.read(folder)
    sha = hashlib.sha256(DIGEST_SCHEME.encode())
    for record in sorted(manifest.shards.values(), key=lambda s: s.name):
        reader = ShardReader(folder / record.name)
        try:
            block = reader.read_block(0, len(reader), stored=True) if len(reader) else {}
            sha.update(f"{record.name} {len(reader)} {reader.depth_scale_mm!r}\n".encode())
        finally:
            reader.close()
        for key in sorted(block):
            values = _canonical(np.asarray(block[key]))
            sha.update(f"{key} {values.dtype.str} {values.shape}\n".encode())
            sha.update(np.ascontiguousarray(values).tobytes())
    return f"sha256:{sha.hexdigest()}"


def _refuse(name: str, set_name: str, expected: str, found: str, where: str) -> BenchmarkError:
    return BenchmarkError(
        f"set {set_name!r} of {name} is not the set this version names: expected digest "
        f"{expected} ({where}), found {found}. A versioned set never changes: if the generator "
        f"changed (poses, objects, views, rendering, sensor noise), give the new sets a new "
        f"version name (handsim.cli.benchmark_sets.VERSION) and record their digests in "
        f"handsim.cli.benchmark_sets.DIGESTS; to compare with results of {name}, make it with the "
        f"handsim release that recorded them, through `handsim benchmark make` (it generates "
        f"with OpenBLAS's {BLAS_KERNEL} kernels, as the digests were recorded; this process: "
        f"OPENBLAS_CORETYPE={_coretype()}, kernels {blas_kernels()})"
    )


def _coretype() -> str:
    import os

    return os.environ.get("OPENBLAS_CORETYPE", "unset")


def _increments(progress: Callable[[int], None] | None) -> Callable[[int, int], None] | None:
    """``generate``'s (done, total) calls as the increments a progress bar takes."""
    if progress is None:
        return None
    last = [0]

    def step(done: int, _total: int) -> None:
        progress(done - last[0])
        last[0] = done

    return step


def make_benchmark(
    out: str | Path,
    *,
    frames_per_set: int | None = None,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Build (or resume) the benchmark's test sets in ``out`` and check their digests.

    Every set's :func:`set_digest` is compared with the one its version records
    (:data:`DIGESTS`; a resized version: the one its folder recorded when first made) and
    written into ``benchmark.json`` once it agrees. The recorded sets of grasps come out only
    with OpenBLAS's :data:`BLAS_KERNEL` kernels, chosen when NumPy loads: the command line
    (``handsim benchmark make``) runs this in a process started with them; from Python, set
    ``OPENBLAS_CORETYPE`` before NumPy is imported (:func:`recorded_blas_environment`).

    Args:
        out: benchmark folder (created).
        frames_per_set: every set this many frames instead of its own (tests); the version
            name then says so (``handsim-bench-v1-nN``).
        progress: called with the frames made since the last call (e.g. a bar's ``update``).

    Returns:
        The ``benchmark.json`` record: ``version``, and per set ``what``, ``frames``,
        ``folder`` and ``digest``.

    Raises:
        BenchmarkError: if ``out`` holds another version or other files, or a set's digest
            differs from the recorded one (the message names the set and both digests).
    """
    from handsim.data.generation import generate

    out = Path(out)
    name = version_name(frames_per_set)
    record_path = out / "benchmark.json"
    held: dict[str, Any] = {}
    if record_path.is_file():
        try:
            held = json.loads(record_path.read_text())
            held_version = held.get("version")
        except (json.JSONDecodeError, AttributeError):
            held, held_version = {}, None
        if held_version != name:
            raise BenchmarkError(
                f"{out} holds {held_version!r}, not {name!r}: a versioned set is never changed; "
                "make this version in a new --out folder"
            )
    elif out.is_dir() and any(out.iterdir()):
        raise BenchmarkError(
            f"{out} is not empty and holds no benchmark.json; give a new or empty --out folder"
        )
    out.mkdir(parents=True, exist_ok=True)
    configs = _configs(frames_per_set)
    recorded = DIGESTS.get(name)
    held_sets = held.get("sets") if isinstance(held.get("sets"), dict) else {}
    if held.get("digest_scheme") != DIGEST_SCHEME:
        held_sets = {}  # digests of another definition (or none) are not compared
    record: dict[str, Any] = {
        "version": name,
        "digest_scheme": DIGEST_SCHEME,
        "openblas_coretype": _coretype(),
        "blas_kernels": blas_kernels(),
        "sets": {},
    }
    for s in SETS:
        entry = {"what": s.what, "frames": configs[s.name].frames, "folder": s.name}
        old = held_sets.get(s.name)
        if isinstance(old, dict) and "digest" in old:
            entry["digest"] = old["digest"]  # kept: a resumed make checks against it
        record["sets"][s.name] = entry
    # Written first: a killed make is resumed (and a different version refused) by name.
    record_path.write_text(json.dumps(record, indent=2) + "\n")
    for s in SETS:
        generate(configs[s.name], out / s.name, progress=_increments(progress))
        found = set_digest(out / s.name)
        entry = record["sets"][s.name]
        if recorded is not None and s.name in recorded:
            expected, where = recorded[s.name], f"recorded for {name} in handsim.cli.benchmark_sets"
        elif "digest" in entry:
            expected, where = entry["digest"], f"recorded in {record_path} when it was made"
        else:
            expected, where = found, ""
        if found != expected:
            raise _refuse(name, s.name, expected, found, where)
        entry["digest"] = found
        record_path.write_text(json.dumps(record, indent=2) + "\n")
    return record


def read_benchmark(folder: str | Path) -> dict[str, Any]:
    """The ``benchmark.json`` record of a benchmark folder (``version``, ``sets``).

    Raises:
        BenchmarkError: for a folder that is not a benchmark, or one of another benchmark.
    """
    folder = Path(folder)
    path = folder / "benchmark.json"
    try:
        record = json.loads(path.read_text())
        sets = record["sets"]
        version = record["version"]
    except (OSError, json.JSONDecodeError, KeyError, TypeError):
        raise BenchmarkError(
            f"--bench {folder} is not a benchmark folder (no readable benchmark.json); make one "
            "with `handsim benchmark make --out DIR`"
        ) from None
    if not str(version).startswith(VERSION):
        raise BenchmarkError(
            f"--bench {folder} holds {version!r}; this handsim runs {VERSION}: make it with "
            "`handsim benchmark make --out DIR`"
        )
    return {"version": version, "sets": sets}


def valid_frames(folder: str | Path) -> Iterator[dict[str, np.ndarray]]:
    """Every valid frame of a dataset folder, in shard order, as :class:`ShardReader` gives it.

    Args:
        folder: a dataset folder (``manifest.json`` and its shards).

    Yields:
        The arrays of one frame (:meth:`~handsim.data.shards.ShardReader.__getitem__`:
        labels, ``depth`` float32 metres, ``segmentation``, ``episode``, ``step``).
    """
    from handsim.data.manifest import Manifest
    from handsim.data.shards import ShardReader

    folder = Path(folder)
    manifest = Manifest.read(folder)
    for record in sorted(manifest.shards.values(), key=lambda s: s.name):
        reader = ShardReader(folder / record.name)
        try:
            for i in range(len(reader)):
                arrays = reader[i]
                if bool(arrays["valid"]):
                    yield arrays
        finally:
            reader.close()
