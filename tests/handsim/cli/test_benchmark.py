"""`handsim benchmark make / run`: versioned, bit-identical sets; one table, strict JSON."""

import json
import os
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

import handsim.cli.benchmark_sets
from handsim.cli import benchmark as cli_benchmark
from handsim.cli.benchmark import (
    SETS,
    BenchmarkError,
    compare_runs,
    make_benchmark,
    run_benchmark,
)
from handsim.cli.benchmark_sets import BLAS_KERNEL, recorded_blas_environment
from handsim.data.manifest import Manifest
from handsim.data.shards import ShardReader

N = 2  # frames per set of the tiny benchmark

# The digests of the tiny benchmark: a fast alarm for a generator change (the real sets,
# handsim.cli.benchmark_sets.DIGESTS, are checked by a slow test in test_benchmark_sets.py).
TINY_DIGESTS = {
    "hand_third_person": "sha256:aac35532418393562b39b2cfa4a531dcadb840177e47e0b279a41b8530cb8dad",
    "hand_egocentric": "sha256:d842892221a79cf103148711d755e997c9733bb27ce5eb036a9df1bdaf6c5ed4",
    "hand_object": "sha256:a04b536f6074a10a4f7d18d75e9e105e2995b7a5fe5eba4ed174d8b193c59bd8",
    "occlusion": "sha256:7767c5bc1d48830051a2d08281bc778f8b484aace7e5f5202687721d896ef69c",
    "sensor_none": "sha256:c24229acc476f3ff8cd796abb51de2bc6b3ea0651627440ff5c2ed17f83c47cf",
    "sensor_tof": "sha256:2a45563d64eddb9627df7b019c4fd7a3f61a750a01e70aea8544cd229b552585",
}


def _cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "handsim.cli", *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
    )


def _strict(text):
    def refuse(constant):
        raise AssertionError(f"non-strict JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """A tiny benchmark, made by the CLI."""
    out = tmp_path_factory.mktemp("bench") / "b"
    result = _cli("benchmark", "make", "--out", str(out), "--frames-per-set", str(N), "-q")
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    summary = _strict(result.stdout)
    assert summary["version"] == f"handsim-bench-v1-n{N}"
    assert summary["sets"] == {s.name: N for s in SETS}
    record = json.loads((out / "benchmark.json").read_text())
    assert summary["digests"] == {k: v["digest"] for k, v in record["sets"].items()}
    return out


def test_the_tiny_sets_are_the_recorded_ones(bench):
    """The generator still makes the sets it made: a change needs a new benchmark version."""
    record = json.loads((bench / "benchmark.json").read_text())
    found = {k: v["digest"] for k, v in record["sets"].items()}
    assert found == TINY_DIGESTS, (
        "the generator's frames changed: handsim-bench-v1's sets change with them, so give "
        "them a new version (handsim.cli.benchmark_sets: VERSION, DIGESTS; docs/benchmark.md) "
        f"and record the tiny sets' digests here: {found}"
    )


def test_cli_module_reexports_the_benchmark_sets():
    """The sets and make moved to benchmark_sets; the old import path gives the same objects."""
    for name in ("VERSION", "SETS", "BenchmarkError", "make_benchmark"):
        assert getattr(cli_benchmark, name) is getattr(handsim.cli.benchmark_sets, name)
    assert cli_benchmark._read_benchmark is handsim.cli.benchmark_sets.read_benchmark


def test_make_refuses_a_set_whose_digest_is_not_the_recorded_one(bench, tmp_path, monkeypatch):
    """A version's recorded digest that the made set does not have: refused, both named."""
    copy = tmp_path / "b"
    shutil.copytree(bench, copy)
    wrong = "sha256:" + "0" * 64
    monkeypatch.setitem(
        handsim.cli.benchmark_sets.DIGESTS, f"handsim-bench-v1-n{N}", {"hand_object": wrong}
    )
    found = handsim.cli.benchmark_sets.set_digest(copy / "hand_object")
    with pytest.raises(
        BenchmarkError,
        match=rf"set 'hand_object' of handsim-bench-v1-n{N} is not the set this version names: "
        rf"expected digest {wrong} \(recorded for handsim-bench-v1-n{N} in "
        r"handsim.cli.benchmark_sets\), "
        rf"found {found}\. A versioned set never changes: if the generator changed .* give "
        r"the new sets a new version",
    ):
        make_benchmark(copy, frames_per_set=N)


def test_make_cli_refuses_sets_other_than_its_folder_recorded(bench, tmp_path):
    """A resumed make checks the sets against the digests its folder recorded (exit 2).

    A tampered shard is remade by ``generate`` (its file hash is in the manifest), so the
    folder's record is what differs here: as when a make killed under one generator is resumed
    under another.
    """
    copy = tmp_path / "b"
    shutil.copytree(bench, copy)
    record = json.loads((copy / "benchmark.json").read_text())
    found = record["sets"]["sensor_tof"]["digest"]
    record["sets"]["sensor_tof"]["digest"] = "sha256:" + "2" * 64
    (copy / "benchmark.json").write_text(json.dumps(record))
    result = _cli("benchmark", "make", "--out", str(copy), "--frames-per-set", str(N), "-q")
    assert result.returncode == 2, result.stderr
    assert (
        f"set 'sensor_tof' of handsim-bench-v1-n{N} is not the set this version names: "
        f"expected digest sha256:{'2' * 64} (recorded in {copy / 'benchmark.json'} when it was "
        f"made), found {found}"
    ) in result.stderr
    assert "Traceback" not in result.stderr


def test_make_generates_with_the_recorded_blas_kernels(bench):
    """`make` runs OpenBLAS's recorded kernels where the CPU can, or the ones the user set."""
    record = json.loads((bench / "benchmark.json").read_text())
    if "OPENBLAS_CORETYPE" in os.environ:
        assert record["openblas_coretype"] == os.environ["OPENBLAS_CORETYPE"]
    elif recorded_blas_environment() is not None:
        assert record["openblas_coretype"] == BLAS_KERNEL == "Haswell"
        assert "openblas:Haswell" in record["blas_kernels"].split(",")
    else:
        assert record["openblas_coretype"] == "unset"


def test_make_is_bit_identical_on_repeat(bench, tmp_path):
    """The same command elsewhere gives the same shards, byte for byte."""
    result = _cli("benchmark", "make", "--out", str(tmp_path / "again"), "--frames-per-set",
                  str(N), "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    for s in SETS:
        a, b = Manifest.read(bench / s.name), Manifest.read(tmp_path / "again" / s.name)
        assert {k: v.sha256 for k, v in a.shards.items()} == {
            k: v.sha256 for k, v in b.shards.items()
        }
        for record in a.shards.values():
            with h5py.File(bench / s.name / record.name) as fa:
                with h5py.File(tmp_path / "again" / s.name / record.name) as fb:
                    np.testing.assert_array_equal(fa["depth"][:], fb["depth"][:])
    # Both sides are in the benchmark (even this tiny one, by its fixed seeds).
    sides = np.concatenate(
        [
            ShardReader(bench / s.name / record.name).labels("is_left")
            for s in SETS
            for record in Manifest.read(bench / s.name).shards.values()
        ]
    )
    assert sides.any() and not sides.all()


def test_make_refuses_another_version_and_foreign_folders(bench, tmp_path):
    """A folder of another version (or not a benchmark) is never overwritten."""
    result = _cli("benchmark", "make", "--out", str(bench), "--frames-per-set", "3", "-q")
    assert result.returncode == 2
    assert "holds 'handsim-bench-v1-n2', not 'handsim-bench-v1-n3'" in result.stderr
    assert "a versioned set is never changed" in result.stderr
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    with pytest.raises(BenchmarkError, match="not empty and holds no benchmark.json"):
        make_benchmark(tmp_path / "other", frames_per_set=N)
    with pytest.raises(BenchmarkError, match="holds 'handsim-bench-v1-n2', not 'handsim-bench-v1'"):
        make_benchmark(bench)


def test_run_exact_oracle_cli_table_json_plots_and_closed_loop(bench, tmp_path):
    """A noise-free oracle: 0 mm everywhere, AUC 1; the closed-loop part is in the JSON."""
    out = tmp_path / "oracle"
    result = _cli(
        "benchmark", "run", "--estimator", "oracle", "--noise-mm", "0", "--bench", str(bench),
        "--out", str(out), "--episodes", "1", "-q",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "| **all** | 12 | 0.0 | 0.0 | 1.000 | 0.0 | 0 |" in result.stdout
    assert "Sets: the content digests handsim-bench-v1-n2 records." in result.stdout
    report = _strict((out / "benchmark.json").read_text())
    assert report["benchmark"] == "handsim-bench-v1-n2"
    made = json.loads((bench / "benchmark.json").read_text())["sets"]
    assert report["set_digests"] == {k: v["digest"] for k, v in made.items()}
    assert report["set_digests_match"] is True
    assert set(report["offline"]["sets"]) == {s.name for s in SETS}
    for s in report["offline"]["sets"].values():
        assert s["n_frames"] == N and s["mean_mm"] == 0.0 and s["auc_f_tau"] == 1.0
    sides = report["offline"]["by_side"]
    assert sides["left"]["n_frames"] + sides["right"]["n_frames"] == 6 * N
    loop = report["closed_loop"]
    assert loop["episodes"] == 1 and 0.0 <= loop["success_rate_feedback_on"] <= 1.0
    assert (out / "closed_loop" / "closed_loop.json").is_file()
    for name in ("f_tau.png", "error_by_set.png", "table.md"):
        assert (out / name).stat().st_size > 0


def test_run_localizer_writes_null_keypoint_figures(bench, tmp_path):
    """No keypoints: mean, median and AUC are null (not 0); the centre error exists."""
    from handsim.estimators import CenterOfMassLocalizer

    result = run_benchmark(bench, CenterOfMassLocalizer, {"name": "com"}, tmp_path, episodes=0)
    text = (tmp_path / "benchmark.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    every = result["offline"]["all"]
    assert every["mean_mm"] is None and every["auc_f_tau"] is None and every["f_tau"] is None
    assert every["center_mm"] > 0 and result["closed_loop"] is None
    assert result["estimator"]["describe"].startswith("CenterOfMassLocalizer(")


def test_run_a_user_file_and_refuse_a_non_benchmark(bench, tmp_path):
    """file.py:Class runs like a built-in; a folder that is not a benchmark is refused."""
    (tmp_path / "my_est.py").write_text(
        "import numpy as np\n"
        "from handsim.estimator import Estimate, EstimatorBase\n\n\n"
        "class Still(EstimatorBase):\n"
        "    def predict(self, depth, K):\n"
        "        return Estimate(keypoints_cam=np.tile([0.0, 0.0, 0.5], (21, 1)))\n"
    )
    out = tmp_path / "user"
    result = _cli(
        "benchmark", "run", "--estimator", "my_est.py:Still", "--bench", str(bench),
        "--out", str(out), "--episodes", "0", "-q", cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    report = _strict((out / "benchmark.json").read_text())
    assert report["estimator"]["spec"] == "my_est.py:Still"
    assert report["offline"]["all"]["mean_mm"] > 50
    result = _cli("benchmark", "run", "--estimator", "com", "--bench", str(tmp_path), "-q")
    assert result.returncode == 2
    assert "is not a benchmark folder (no readable benchmark.json)" in result.stderr


def test_compare_puts_runs_in_one_table(bench, tmp_path):
    """compare: one row per run (a localizer's centre error in brackets); versions must match."""
    from handsim.estimators import CenterOfMassLocalizer, OracleEstimator

    run_benchmark(
        bench, lambda: OracleEstimator(noise_mm=0.0, rng=0), {"name": "oracle", "noise_mm": 0.0},
        tmp_path / "a", episodes=0,
    )  # fmt: skip
    run_benchmark(bench, CenterOfMassLocalizer, {"name": "com"}, tmp_path / "b", episodes=0)
    result = _cli("benchmark", "compare", str(tmp_path / "a"), str(tmp_path / "b"),
                  "--out", str(tmp_path / "c"))  # fmt: skip
    assert result.returncode == 0, result.stderr
    rows = [line for line in result.stdout.splitlines() if line.startswith("| oracle")]
    assert rows == ["| oracle 0 mm | " + "0.0 | " * 7 + "1.000 | 0.0 | n/a |"]
    assert "| com | (" in result.stdout
    assert (tmp_path / "c" / "success_vs_error.png").stat().st_size > 0
    other = json.loads((tmp_path / "b" / "benchmark.json").read_text())
    other["benchmark"] = "handsim-bench-v2"
    (tmp_path / "b" / "benchmark.json").write_text(json.dumps(other))
    with pytest.raises(BenchmarkError, match="results of one benchmark version compare"):
        compare_runs([tmp_path / "a", tmp_path / "b"], tmp_path / "d")
    # Results of one version measured on different sets do not compare either.
    other["benchmark"] = f"handsim-bench-v1-n{N}"
    other["set_digests"] = {**other["set_digests"], "occlusion": "sha256:" + "1" * 64}
    (tmp_path / "b" / "benchmark.json").write_text(json.dumps(other))
    with pytest.raises(
        BenchmarkError,
        match=r"were measured on different sets \(content digests differ for occlusion\)",
    ):
        compare_runs([tmp_path / "a", tmp_path / "b"], tmp_path / "d")
