"""handsim.cli.benchmark_sets: the sets' content digests (images exact, labels to 1e-6), v1."""

import json
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

from handsim.cli import benchmark_sets as benchmark
from handsim.cli.benchmark_sets import (
    DIGEST_FLOAT_STEP,
    DIGESTS,
    SETS,
    VERSION,
    set_digest,
    valid_frames,
)
from handsim.data.generation import GenerationConfig, generate
from handsim.data.manifest import Manifest
from handsim.data.shards import ShardReader, file_sha256


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Three frames of a hand alone in two shards, with sensor noise (a set in miniature)."""
    out = tmp_path_factory.mktemp("digest") / "d"
    config = GenerationConfig(
        frames=3, frames_per_shard=2, frames_per_episode=3, num_objects_range=(0, 0), seed=7
    )
    generate(config, out)
    return out


def _copy(dataset, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(dataset, out)
    return out


def _shard(folder):
    return folder / Manifest.read(folder).shards[0].name


def test_digest_is_a_sha256_and_the_same_for_a_copy(dataset, tmp_path):
    """A digest names its hash; a copy of the folder (the same frames) has the same one."""
    digest = set_digest(dataset)
    assert digest.startswith("sha256:") and len(digest) == len("sha256:") + 64
    assert set_digest(_copy(dataset, tmp_path)) == digest


def test_digest_reads_the_frames_not_the_file_bytes(dataset, tmp_path):
    """The same arrays written with other compression: other file bytes, the same digest."""
    copy = _copy(dataset, tmp_path)
    shard = _shard(copy)
    before = file_sha256(shard)
    rewritten = shard.with_suffix(".tmp")
    with h5py.File(shard, "r") as src, h5py.File(rewritten, "w") as dst:
        dst.attrs.update(dict(src.attrs))

        def rewrite(name, obj):
            if isinstance(obj, h5py.Dataset):
                dst.create_dataset(name, data=obj[()], compression="gzip", compression_opts=9)

        src.visititems(rewrite)
    rewritten.replace(shard)
    assert file_sha256(shard) != before
    assert set_digest(copy) == set_digest(dataset)


@pytest.mark.parametrize(
    ("dataset_name", "index", "change", "same"),
    [
        # Labels: a float's last bits do not count, a micrometre does.
        ("labels/keypoints_cam", (0, 3, 2), 1e-9, True),
        ("labels/keypoints_cam", (0, 3, 2), 3 * DIGEST_FLOAT_STEP, False),
        ("labels/hand_pose", (1, 10), 3e-6, False),
        ("labels/is_left", (0,), None, False),
        ("labels/occluder", (1, 5), 1, False),
        # Images: one depth unit (0.1 mm) of one pixel, one segmentation label.
        ("depth", (0, 120, 160), 1, False),
        ("segmentation", (1, 0, 0), 1, False),
    ],
)
def test_digest_is_strict_on_images_and_labels_to_their_rounding(
    dataset, tmp_path, dataset_name, index, change, same
):
    """A change of one value of one frame changes the digest, unless it is below the rounding."""
    copy = _copy(dataset, tmp_path)
    with h5py.File(_shard(copy), "r+") as f:
        ds = f[dataset_name]
        value = ds[index]
        ds[index] = (not value) if change is None else value + change
    assert (set_digest(copy) == set_digest(dataset)) is same


def test_digest_covers_the_order_of_the_frames(dataset, tmp_path):
    """Two frames swapped are another set."""
    copy = _copy(dataset, tmp_path)
    with h5py.File(_shard(copy), "r+") as f:
        for name in ("depth", "segmentation", "labels/keypoints_cam"):
            values = f[name][()]
            f[name][...] = values[::-1]
    assert set_digest(copy) != set_digest(dataset)


def test_valid_frames_gives_every_valid_frame_in_shard_order(dataset):
    """The shared frame reader (benchmark run, benchmarks/deepprior_bench_check.py)."""
    frames = list(valid_frames(dataset))
    names = [s.name for _, s in sorted(Manifest.read(dataset).shards.items())]
    expected = [
        ShardReader(dataset / n)[i] for n in names for i in range(len(ShardReader(dataset / n)))
    ]
    assert len(frames) == len(expected) == 3
    for got, want in zip(frames, expected, strict=True):
        np.testing.assert_array_equal(got["depth"], want["depth"])
        np.testing.assert_array_equal(got["keypoints_cam"], want["keypoints_cam"])
    assert frames[0]["depth"].dtype == np.float32


def test_every_set_of_the_version_has_a_recorded_digest():
    """DIGESTS names every set of VERSION, each a sha256."""
    assert set(DIGESTS[VERSION]) == {s.name for s in SETS}
    for digest in DIGESTS[VERSION].values():
        assert digest.startswith("sha256:") and len(digest) == 71


@pytest.mark.slow
def test_make_builds_the_recorded_v1_sets(tmp_path):
    """The real handsim-bench-v1 (1 300 frames, about 80-240 s): every digest as recorded.

    Made by the command, which generates with the recorded BLAS kernels (see BLAS_KERNEL).
    """
    done = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "benchmark", "make", "--out", str(tmp_path / "v1"),
         "-q"],
        capture_output=True, text=True, timeout=1800,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "v1" / "benchmark.json").read_text())
    assert record["version"] == VERSION
    assert {k: v["digest"] for k, v in record["sets"].items()} == DIGESTS[VERSION]
    assert benchmark.read_benchmark(tmp_path / "v1")["sets"] == record["sets"]
