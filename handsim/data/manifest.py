"""The dataset manifest (``manifest.json``) and the dataset-level check.

The manifest makes a dataset reproducible and resumable: the generation config, the versions
of handsim, MuJoCo, NumPy and h5py, the git commit when the package runs from a checkout, the
seed of every shard, each complete shard's frame count, size, SHA-256 and episodes redrawn by
cause (summed as ``redraws``), the label schema with units, and the occlusion histogram. It is
rewritten atomically (temporary file, then rename) after every completed shard, so it never
lists a shard that does not exist.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import subprocess
from pathlib import Path
from typing import Any

import numpy as np

from handsim.data.arrays import DRAW_LABEL_SCHEMA, LABEL_SCHEMA
from handsim.data.shards import (
    DEPTH_SCALE_RANGE_MM,
    PARTIAL_SUFFIX,
    SHARD_SUFFIX,
    ShardInfo,
    check_shard,
    write_error,
)
from handsim.errors import HandSimError

__all__ = [
    "MANIFEST_NAME",
    "InvalidManifest",
    "Manifest",
    "environment_versions",
    "git_commit",
    "label_schema_json",
    "check_dataset",
]

MANIFEST_NAME = "manifest.json"
"""File name of the manifest inside a dataset folder."""


class InvalidManifest(HandSimError, ValueError):
    """A dataset folder has no readable manifest, or the manifest lacks a field."""


def environment_versions() -> dict[str, str]:
    """Versions of what shapes the data: handsim, MuJoCo, NumPy, h5py and Python."""
    import h5py
    import mujoco

    import handsim

    return {
        "handsim": handsim.__version__,
        "mujoco": mujoco.__version__,
        "numpy": np.__version__,
        "h5py": h5py.__version__,
        "python": platform.python_version(),
    }


def git_commit() -> str | None:
    """The git commit of the handsim checkout that runs, or ``None`` (installed, no git)."""
    root = Path(__file__).resolve().parents[2]
    try:
        out = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    commit = out.stdout.strip()
    return commit if out.returncode == 0 and len(commit) == 40 else None


def label_schema_json() -> dict[str, dict[str, Any]]:
    """The shards' labels as JSON: key -> shape, dtype, unit.

    :data:`~handsim.data.arrays.LABEL_SCHEMA`, then
    :data:`~handsim.data.arrays.DRAW_LABEL_SCHEMA`.
    """
    return {
        key: {"shape": list(shape), "dtype": dtype.name, "unit": unit}
        for key, (shape, dtype, unit) in {**LABEL_SCHEMA, **DRAW_LABEL_SCHEMA}.items()
    }


@dataclasses.dataclass
class Manifest:
    """What a dataset folder holds and how it was made.

    Attributes:
        config: the generation config (JSON-able).
        seeds: seed of each shard, by shard index.
        shards: the complete shards (index -> record).
        depth_scale_mm: stored depth unit, millimetres.
        image_shape: ``(H, W)`` of every frame.
        versions: :func:`environment_versions` at creation.
        git_commit: :func:`git_commit` at creation.
        occlusion_histogram: bucket edges and counts of the hand occlusion ratio, when known.
    """

    config: dict[str, Any]
    seeds: list[int]
    shards: dict[int, ShardInfo]
    depth_scale_mm: float
    image_shape: tuple[int, int]
    versions: dict[str, str] = dataclasses.field(default_factory=environment_versions)
    git_commit: str | None = dataclasses.field(default_factory=git_commit)
    occlusion_histogram: dict[str, list[float]] | None = None

    @property
    def frames(self) -> int:
        """Frames in the complete shards."""
        return sum(s.frames for s in self.shards.values())

    @property
    def redraws(self) -> dict[str, int]:
        """Episodes redrawn in the complete shards, by cause (summed over their records)."""
        total: dict[str, int] = {}
        for record in self.shards.values():
            for reason, n in record.redraws.items():
                total[reason] = total.get(reason, 0) + n
        return dict(sorted(total.items()))

    @staticmethod
    def shard_name(index: int) -> str:
        """File name of shard ``index``."""
        return f"shard-{index:05d}{SHARD_SUFFIX}"

    def to_json(self) -> dict[str, Any]:
        """The manifest as strict JSON (no NaN)."""
        return {
            "format": "handsim-dataset-1",
            "config": self.config,
            "versions": self.versions,
            "git_commit": self.git_commit,
            "depth_scale_mm": self.depth_scale_mm,
            "image_shape": list(self.image_shape),
            "frames": self.frames,
            "redraws": self.redraws,
            "seeds": list(self.seeds),
            "shards": [
                {"index": i, **dataclasses.asdict(s)} for i, s in sorted(self.shards.items())
            ],
            "label_schema": label_schema_json(),
            "occlusion_histogram": self.occlusion_histogram,
        }

    def write(self, folder: str | os.PathLike[str]) -> Path:
        """Write ``manifest.json`` atomically into ``folder``; returns its path."""
        path = Path(folder) / MANIFEST_NAME
        tmp = path.with_suffix(".json.tmp")
        text = json.dumps(self.to_json(), indent=2, allow_nan=False) + "\n"
        try:
            tmp.write_text(text)
            os.replace(tmp, path)
        except OSError as err:
            tmp.unlink(missing_ok=True)  # the manifest before stays whole
            raise write_error(err, path, MANIFEST_NAME) from err
        return path

    @classmethod
    def read(cls, folder: str | os.PathLike[str]) -> Manifest:
        """Read a dataset folder's manifest.

        Raises:
            InvalidManifest: if it is missing, not JSON or lacks a field (named).
        """
        path = Path(folder) / MANIFEST_NAME
        if not path.is_file():
            raise InvalidManifest(
                f"{folder} has no {MANIFEST_NAME}: it is not a handsim dataset (make one with "
                "`handsim generate`)"
            )
        try:
            doc = json.loads(path.read_text())
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            raise InvalidManifest(f"{path} is not valid JSON ({err})") from err
        fields = ("config", "seeds", "shards", "depth_scale_mm", "image_shape", "versions")
        missing = [k for k in fields if not isinstance(doc, dict) or k not in doc]
        if missing:
            raise InvalidManifest(f"{path} lacks {', '.join(missing)}")
        try:
            shards = {
                int(s["index"]): ShardInfo(
                    name=str(s["name"]),
                    frames=_count("frames", s["frames"], 1),
                    sha256=str(s["sha256"]),
                    bytes=_count("bytes", s["bytes"], 0),
                    redraws=_redraws(s.get("redraws", {})),
                )
                for s in doc["shards"]
            }
        except (KeyError, TypeError, ValueError) as err:
            raise InvalidManifest(f"{path}: a shard record is malformed ({err!r})") from err
        scale = doc["depth_scale_mm"]
        if (
            isinstance(scale, bool)
            or not isinstance(scale, (int, float))
            or not DEPTH_SCALE_RANGE_MM[0] <= scale <= DEPTH_SCALE_RANGE_MM[1]
        ):
            lo, hi = DEPTH_SCALE_RANGE_MM
            raise InvalidManifest(
                f"{path}: depth_scale_mm must be a number in [{lo:g}, {hi:g}] (millimetres "
                f"per stored depth unit); received {scale!r}"
            )
        shape = doc["image_shape"]
        if not (
            isinstance(shape, list)
            and len(shape) == 2
            and all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in shape)
        ):
            raise InvalidManifest(
                f"{path}: image_shape must be [height, width] in pixels (positive integers); "
                f"received {shape!r}"
            )
        if not isinstance(doc["config"], dict):
            raise InvalidManifest(f"{path}: config must be a mapping; received {doc['config']!r}")
        return cls(
            config=doc["config"],
            seeds=[int(s) for s in doc["seeds"]],
            shards=shards,
            depth_scale_mm=float(scale),
            image_shape=tuple(shape),
            versions=doc["versions"],
            git_commit=doc.get("git_commit"),
            occlusion_histogram=doc.get("occlusion_histogram"),
        )


def _count(name: str, value: Any, lo: int) -> int:
    """A shard record's integer field, checked (a string or a float is malformed)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ValueError(f"{name} must be an integer >= {lo}; received {value!r}")
    return value


def _redraws(value: Any) -> dict[str, int]:
    """A shard record's redraw counts, checked (datasets made before them have none)."""
    if not isinstance(value, dict) or not all(
        isinstance(k, str) and isinstance(n, int) and not isinstance(n, bool) and n >= 0
        for k, n in value.items()
    ):
        raise ValueError(f"redraws must map a cause to a count >= 0; received {value!r}")
    return dict(value)


def check_dataset(folder: str | os.PathLike[str]) -> dict[str, Any]:
    """Check every shard of a dataset against its manifest; never raises for a bad shard.

    Returns:
        ``{"ok": bool, "shards": n, "frames": n, "problems": [...], "partial": [...],
        "unlisted": [...]}``: problems name the shard; partial files are shards in progress
        (a resumed run rewrites them); unlisted ``*.h5`` files are not in the manifest.

    Raises:
        InvalidManifest: if the folder has no readable manifest.
    """
    folder = Path(folder)
    manifest = Manifest.read(folder)
    problems = []
    for record in manifest.shards.values():
        problems += check_shard(folder / record.name, record)
    listed = {s.name for s in manifest.shards.values()}
    partial = sorted(p.name for p in folder.glob(f"*{PARTIAL_SUFFIX}"))
    unlisted = sorted(p.name for p in folder.glob(f"*{SHARD_SUFFIX}") if p.name not in listed)
    return {
        "ok": not problems,
        "shards": len(manifest.shards),
        "frames": manifest.frames,
        "problems": problems,
        "partial": partial,
        "unlisted": unlisted,
    }
