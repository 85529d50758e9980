"""Generation with one Ray task per shard (a local Ray instance): same shards, kills retried."""

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from handsim.data.generation import GenerationConfig, generate
from handsim.data.manifest import check_dataset
from handsim.data.shards import PARTIAL_SUFFIX, file_sha256

ray = pytest.importorskip("ray")

TINY = {
    "frames": 4,
    "frames_per_shard": 2,
    "frames_per_episode": 2,
    "sensor": "none",
    "num_objects_range": (1, 1),
    "objects": ("005_tomato_soup_can",),
}


@pytest.fixture(scope="module")
def local_ray():
    """A local Ray instance with two CPUs (generate(ray='local') joins it)."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def _writer_pids(partial: Path) -> list[int]:
    """Processes that hold ``partial`` open (from /proc)."""
    pids = []
    for fd_dir in Path("/proc").glob("[0-9]*/fd"):
        try:
            if any(os.readlink(fd) == str(partial) for fd in fd_dir.iterdir()):
                pids.append(int(fd_dir.parent.name))
        except OSError:
            continue
    return pids


def test_ray_tasks_make_the_same_shards_as_local_workers(tmp_path, local_ray):
    """One Ray task per shard gives the shards a plain run gives, bit for bit."""
    config = GenerationConfig.from_mapping(TINY)
    by_ray = generate(config, tmp_path / "ray", ray="local")
    plain = generate(config, tmp_path / "plain")
    assert by_ray.shards == plain.shards
    assert check_dataset(tmp_path / "ray")["ok"]


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="needs /proc to find the writer")
def test_a_ray_task_killed_mid_shard_is_rerun_and_its_shard_is_identical(tmp_path, local_ray):
    """SIGKILL a Ray worker while it writes a shard: the task reruns; no half-written shard."""
    config = GenerationConfig.from_mapping(TINY, frames=6, frames_per_shard=6, frames_per_episode=6)
    reference = generate(config, tmp_path / "plain")
    out = tmp_path / "ray"
    result: dict = {}
    thread = threading.Thread(
        target=lambda: result.setdefault("manifest", generate(config, out, ray="local"))
    )
    thread.start()
    partial = out / f"shard-00000{PARTIAL_SUFFIX}"
    killed = []
    deadline = time.monotonic() + 120
    while not killed and time.monotonic() < deadline and thread.is_alive():
        if partial.exists():
            for pid in _writer_pids(partial):
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
        time.sleep(0.01)
    thread.join(timeout=300)
    assert killed, "no Ray worker was caught writing the shard"
    manifest = result["manifest"]
    assert manifest.shards == reference.shards
    assert file_sha256(out / "shard-00000.h5") == reference.shards[0].sha256
    assert not list(out.glob(f"*{PARTIAL_SUFFIX}")) and check_dataset(out)["ok"]


def test_the_cli_runs_on_ray(tmp_path, local_ray, capsys):
    """`handsim generate --ray local` makes the same dataset (joining the running instance)."""
    import json

    from handsim.cli import main

    (tmp_path / "c.json").write_text(json.dumps({**TINY, "frames": 2}))
    args = ["generate", "--config", str(tmp_path / "c.json"), "--out", str(tmp_path / "d")]
    assert main([*args, "--ray", "local"]) == 0
    assert json.loads(capsys.readouterr().out)["frames"] == 2
    assert check_dataset(tmp_path / "d")["ok"]
