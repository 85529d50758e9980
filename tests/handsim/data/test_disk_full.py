"""A full disk during generation: one clear error, no partial file, complete shards kept."""

import errno
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from handsim.data import shards
from handsim.data.generation import GenerationConfig, generate
from handsim.data.manifest import Manifest
from handsim.data.shards import PARTIAL_SUFFIX, DatasetWriteError, file_sha256

# 3 shards of 2 frames, noise-free, one object: seconds to make.
TINY = {
    "frames": 6,
    "frames_per_shard": 2,
    "frames_per_episode": 2,
    "sensor": "none",
    "num_objects_range": (1, 1),
    "objects": ("005_tomato_soup_can",),
}


def _fill_the_disk_at(monkeypatch, name):
    """Every write of the shard file ``name`` fails with ENOSPC, as on a full disk."""
    write = shards._GuardedFile.write

    def full(self, data):
        if Path(self.name).name.startswith(name) and not self.discard:
            self.error = self.error or OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            raise self.error
        return write(self, data)

    monkeypatch.setattr(shards._GuardedFile, "write", full)


def test_a_full_disk_is_one_clear_error_and_the_run_resumes(tmp_path, monkeypatch):
    """Shard 1 hits ENOSPC: DatasetWriteError naming the folder, shard 0 kept, resume exact."""
    config = GenerationConfig.from_mapping(TINY)
    run = tmp_path / "run"
    _fill_the_disk_at(monkeypatch, "shard-00001")
    with pytest.raises(
        DatasetWriteError,
        match=rf"shard-00001\.h5 could not be written in {run}: the disk is full \(no space "
        r"left on device\).*free space .* rerun the same command to resume",
    ):
        generate(config, run)
    assert not list(run.glob(f"*{PARTIAL_SUFFIX}"))
    kept = Manifest.read(run)
    assert sorted(kept.shards) == [0]
    assert file_sha256(run / "shard-00000.h5") == kept.shards[0].sha256

    monkeypatch.undo()
    resumed = generate(config, run)
    clean = generate(config, tmp_path / "clean")
    assert resumed.shards == clean.shards


def test_a_shard_writer_that_cannot_even_start_names_the_disk(tmp_path, monkeypatch):
    """ENOSPC while HDF5 writes the new file's header: the same error, no partial file."""
    _fill_the_disk_at(monkeypatch, "shard-00007")
    with pytest.raises(DatasetWriteError, match=r"shard-00007\.h5 could not be written"):
        with shards.ShardWriter(tmp_path / "shard-00007.h5", image_shape=(4, 4)) as writer:
            writer.close()
    assert list(tmp_path.iterdir()) == []


def test_a_manifest_on_a_full_disk_keeps_the_one_before(tmp_path, monkeypatch):
    """A manifest that cannot be written: DatasetWriteError; the last whole one stays."""
    config = GenerationConfig.from_mapping(TINY, frames=2)
    manifest = generate(config, tmp_path)
    before = (tmp_path / "manifest.json").read_text()

    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(DatasetWriteError, match=r"manifest\.json could not be written.*full"):
        manifest.write(tmp_path)
    monkeypatch.undo()
    assert (tmp_path / "manifest.json").read_text() == before
    assert not (tmp_path / "manifest.json.tmp").exists()


def _can_mount_a_tmpfs() -> bool:
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(
        ["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt || exit 1"],
        capture_output=True,
    )
    return probe.returncode == 0


_SCRIPT = """
set -u
mount -t tmpfs -o size=384k tmpfs "$MNT"
"$PY" -m handsim.cli generate --config "$CFG" --out "$MNT/ds" -q --workers "$W" \
    2>"$OUT/err1"
echo $? >"$OUT/rc1"
ls -a "$MNT/ds" >"$OUT/ls1"
mkdir "$OUT/first" && cp "$MNT/ds/manifest.json" "$MNT"/ds/shard-*.h5 "$OUT/first/"
mount -o remount,size=8m tmpfs "$MNT"
"$PY" -m handsim.cli generate --config "$CFG" --out "$MNT/ds" -q --workers "$W" \
    2>"$OUT/err2"
echo $? >"$OUT/rc2"
cp -r "$MNT/ds" "$OUT/final"
"""


@pytest.mark.parametrize("workers", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_generate_on_a_full_tmpfs(tmp_path, workers):
    """`handsim generate` on a 384 KiB tmpfs: exit 2 with the disk-full error, then resume.

    Shards of 20 noisy hand-only frames (~260 kB) fill the disk in the second shard. Was a
    segfault (h5py closed the file after the failed write) with one worker, a traceback that
    never said disk full with two.
    """
    if not _can_mount_a_tmpfs():
        pytest.skip("this machine does not allow a tmpfs in a user namespace (unshare -rm)")
    cfg = tmp_path / "config.json"
    values = {"frames": 60, "frames_per_shard": 20, "frames_per_episode": 10}
    cfg.write_text(json.dumps({**values, "num_objects_range": [0, 0]}))
    (tmp_path / "mnt").mkdir()
    out = tmp_path / "out"
    out.mkdir()
    env = dict(
        os.environ,
        MNT=str(tmp_path / "mnt"),
        PY=sys.executable,
        CFG=str(cfg),
        W=str(workers),
        OUT=str(out),
    )
    subprocess.run(["unshare", "-rm", "sh", "-c", _SCRIPT], env=env, check=True, timeout=600)
    err = (out / "err1").read_text()
    assert (out / "rc1").read_text().strip() == "2", err
    # Two workers write two shards at once: either may be the one that finds the disk full.
    assert re.match(r"handsim: error: shard-0000[0-2]\.h5 could not be written in ", err), err
    assert "the disk is full (no space left on device)" in err
    assert "Traceback" not in err and "Exception ignored" not in err
    assert not any(n.endswith(PARTIAL_SUFFIX) for n in (out / "ls1").read_text().split())
    first = Manifest.read(out / "first")
    assert len(first.shards) == 1 if workers == 1 else len(first.shards) <= 1
    for record in first.shards.values():
        assert file_sha256(out / "first" / record.name) == record.sha256

    assert (out / "rc2").read_text().strip() == "0", (out / "err2").read_text()
    final = Manifest.read(out / "final")
    assert sorted(final.shards) == [0, 1, 2]
    assert all(final.shards[i] == record for i, record in first.shards.items())
    for record in final.shards.values():
        assert file_sha256(out / "final" / record.name) == record.sha256
