"""Tests of `handsim generate`, `handsim dataset check|info` and `handsim export`."""

import json
import os
import re
import subprocess
import sys

import pytest

from handsim.cli import main

CONFIG = {
    "frames": 2,
    "frames_per_shard": 1,
    "frames_per_episode": 1,
    "sensor": "none",
    "num_objects_range": [1, 1],
    "objects": ["005_tomato_soup_can"],
}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """A two-shard dataset made from a JSON config through the CLI."""
    root = tmp_path_factory.mktemp("cli")
    (root / "config.json").write_text(json.dumps(CONFIG))
    assert main(["generate", "--config", str(root / "config.json"), "--out", str(root / "d")]) == 0
    return root / "d"


def test_generate_prints_strict_json_and_resumes(dataset, capsys, tmp_path):
    """The same command again finds everything done; --frames overrides the config."""
    (tmp_path / "config.json").write_text(json.dumps(CONFIG))
    args = ["generate", "--config", str(tmp_path / "config.json"), "--out", str(dataset)]
    assert main(args) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 2 and report["shards"] == 2


def test_check_exit_status_names_a_corrupt_shard(dataset, capsys, tmp_path):
    """Exit 0 for a sound dataset, 1 with the shard named for a damaged one."""
    assert main(["dataset", "check", str(dataset)]) == 0
    assert json.loads(capsys.readouterr().out)["ok"] is True
    broken = tmp_path / "broken"
    broken.mkdir()
    for path in dataset.iterdir():
        (broken / path.name).write_bytes(path.read_bytes())
    shard = broken / "shard-00001.h5"
    shard.write_bytes(shard.read_bytes()[:1000])
    assert main(["dataset", "check", str(broken)]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["problems"][0].startswith("shard-00001.h5: ")


def test_info_plot_writes_pictures(dataset, capsys):
    """`dataset info --plot` summarizes and writes the contact sheet and the histograms."""
    assert main(["dataset", "info", str(dataset), "--plot"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"] == 2 and info["image_shape"] == [240, 320]
    assert sorted(p.split("/")[-1] for p in info["plots"]) == [
        "contact_sheet.png",
        "histograms.png",
    ]
    assert (dataset / "contact_sheet.png").stat().st_size > 1000


@pytest.mark.parametrize("fmt", ["hand-labels", "bop"])
def test_export_writes_the_format(dataset, capsys, tmp_path, fmt):
    """Both exports run from the CLI into a new folder."""
    assert main(["export", fmt, str(dataset), str(tmp_path / fmt)]) == 0
    assert json.loads(capsys.readouterr().out)["format"] == fmt
    assert any((tmp_path / fmt).iterdir())


def test_export_hand_labels_subprocess_writes_its_schema(dataset, tmp_path):
    """`handsim export hand-labels` as a program: schema.json, labels, depth and hand masks."""
    import os
    import subprocess
    import sys

    out = tmp_path / "labels"
    result = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "export", "hand-labels", str(dataset), str(out)],
        capture_output=True,
        text=True,
        env={**os.environ, "MUJOCO_GL": "egl"},
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["format"] == "hand-labels"
    schema = json.loads((out / "schema.json").read_text())
    assert schema["format"] == "handsim-hand-labels-2"
    assert {"-1", "-2", "-3", "k >= 0"} == set(schema["occluder_codes"])
    splits = [k for k in report if k not in ("format", "out")]
    assert sum(report[k] for k in splits) == 2
    for split in splits:
        lines = (out / split / "labels.jsonl").read_text().splitlines()
        assert len(lines) == report[split]
        for text in lines:
            line = json.loads(text)
            assert set(line) == set(schema["fields"])
            assert all(isinstance(code, int) for code in line["occluder"])
            assert (out / split / line["depth"]).is_file()
            assert (out / split / line["hand_mask"]).is_file()


def test_export_bop_symmetry_subprocess(dataset, tmp_path):
    """`handsim export bop --symmetry depth`: the soup can's models_info is continuous."""
    import os
    import subprocess
    import sys

    from handsim.cli.data import _SYMMETRIES
    from handsim.world.registry import OBJECTS
    from handsim.world.symmetry import SYMMETRY_MODALITIES

    assert _SYMMETRIES == SYMMETRY_MODALITIES
    out = tmp_path / "bop"
    command = [sys.executable, "-m", "handsim.cli", "export", "bop", str(dataset), str(out)]
    env = {**os.environ, "MUJOCO_GL": "egl"}
    result = subprocess.run(
        [*command, "--symmetry", "depth"], capture_output=True, text=True, env=env, timeout=300
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["symmetry"] == "depth"
    info = json.loads((out / "models" / "models_info.json").read_text())
    soup = str(OBJECTS["005_tomato_soup_can"].ycbv_id)
    assert info[soup]["symmetries_continuous"][0]["axis"] == [0.0, 1.0, 0.0]
    bad = subprocess.run(
        [*command[:-1], str(tmp_path / "x"), "--symmetry", "rgb"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert bad.returncode == 2 and "choose from 'texture', 'depth'" in bad.stderr


def test_errors_are_one_line(capsys, tmp_path):
    """A folder that is no dataset, a bad preset and a bad config field: one line, exit 2."""
    assert main(["dataset", "info", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip().startswith("handsim: error: ")
    with pytest.raises(SystemExit) as exit_info:
        main(["generate", "--preset", "nope", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    choices = "choose from 'hand-only', 'hand-only-egocentric', 'hand-object', 'occlusion-heavy'"
    assert choices in capsys.readouterr().err
    (tmp_path / "bad.json").write_text(json.dumps({"frame": 3}))
    assert main(["generate", "--config", str(tmp_path / "bad.json"), "--out", str(tmp_path)]) == 2
    assert "unknown config field(s) frame" in capsys.readouterr().err


def test_generate_and_info_report_redraws_subprocess(tmp_path):
    """Through the real program: crowded tables are redrawn, and `dataset info` counts them.

    Three or four cracker boxes often do not fit on the table (the placement fails for about a
    third of the episodes): the run completes and reports the redraws by cause.
    """
    crowded = dict(
        CONFIG,
        frames=6,
        frames_per_shard=6,
        objects=["003_cracker_box"],
        num_objects_range=[3, 4],
    )
    (tmp_path / "crowded.json").write_text(json.dumps(crowded))
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    out = tmp_path / "d"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "handsim.cli",
            "generate",
            "--config",
            str(tmp_path / "crowded.json"),
        ]
        + ["--workers", "1", "--out", str(out)],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    made = json.loads(run.stdout)
    assert made["frames"] == 6 and made["redraws"]["placement"] >= 1
    info = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "dataset", "info", str(out)],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    assert json.loads(info.stdout)["redraws"] == made["redraws"]


def test_info_reports_the_hands_and_views_subprocess(tmp_path):
    """`handsim generate` and `handsim dataset info` as programs: the distribution is printed.

    Hand-alone third-person frames keep the palm cone; the mixes name the pose sources and
    views drawn; the constant-mean-pose error lies below the joints' mean distance.
    """
    config = {
        "frames": 8,
        "frames_per_shard": 4,
        "frames_per_episode": 2,
        "sensor": "none",
        "num_objects_range": [0, 0],
        "viewpoints": ["third_person"],
        "pose_sources": ["gesture", "motion"],
    }
    (tmp_path / "config.json").write_text(json.dumps(config))
    env = {**os.environ, "MUJOCO_GL": "egl"}
    run = [sys.executable, "-m", "handsim.cli"]
    out = tmp_path / "d"
    made = subprocess.run(
        [*run, "generate", "--config", str(tmp_path / "config.json"), "--out", str(out)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert made.returncode == 0, made.stderr
    result = subprocess.run(
        [*run, "dataset", "info", str(out)], capture_output=True, text=True, env=env, timeout=120
    )
    assert result.returncode == 0, result.stderr
    dist = json.loads(result.stdout)["distribution"]
    assert dist["frames"] == 8
    assert dist["viewpoints"] == {"third_person": 1.0}
    assert set(dist["pose_sources"]) <= {"gesture", "motion"}
    assert sum(dist["palm_angle"]["counts"]) == 8
    assert 0.0 <= dist["palm_angle"]["facing_angle_max_deg"] <= 90.0
    assert dist["contact_rate"] == 0.0 and dist["occlusion"]["counts"][0] == 8
    assert 0.0 < dist["constant_pose_error_mm"] < dist["mean_joint_distance_mm"]
    # One view: its own mean pose is the dataset's.
    assert dist["constant_pose_error_mm_by_viewpoint"] == {
        "third_person": dist["constant_pose_error_mm"]
    }


def test_check_and_info_refuse_a_tampered_manifest_subprocess(dataset, tmp_path):
    """`dataset check` and `dataset info` as programs: a bad depth scale is a one-line error."""
    import shutil

    folder = tmp_path / "tampered"
    shutil.copytree(dataset, folder)
    doc = json.loads((folder / "manifest.json").read_text())
    doc["depth_scale_mm"] = "abc"
    (folder / "manifest.json").write_text(json.dumps(doc))
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    for command in (["dataset", "check"], ["dataset", "info"]):
        run = subprocess.run(
            [sys.executable, "-m", "handsim.cli", *command, str(folder)],
            capture_output=True,
            text=True,
            env=env,
            check=False,
        )
        assert run.returncode == 2 and "Traceback" not in run.stderr
        assert "depth_scale_mm must be a number in [0.001, 10]" in run.stderr
        assert "received 'abc'" in run.stderr


@pytest.mark.parametrize(
    "command",
    [
        ["generate", "--preset", "hand-only", "--frames", "1", "--out"],
        ["export", "bop", "DATASET"],
        ["export", "hand-labels", "DATASET"],
        ["train", "localizer", "--data", "DATASET", "--out"],
    ],
)
def test_an_output_folder_that_is_a_file_is_refused_subprocess(dataset, tmp_path, command):
    """--out (or the export's folder) that is a file, or inside one: a usage error, exit 2."""
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    argv = [str(dataset) if a == "DATASET" else a for a in command]
    for out, message in (
        (blocker, "is a file, not a folder; give a folder"),
        (blocker / "inside", "cannot be made: .*a_file' is a file, not a folder"),
    ):
        run = subprocess.run(
            [sys.executable, "-m", "handsim.cli", *argv, str(out)],
            capture_output=True,
            text=True,
            env=env,
            check=False,
        )
        assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
        assert re.search(message, run.stderr), run.stderr
    assert blocker.read_text() == "not a folder"


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into any folder")
def test_an_output_folder_that_cannot_be_written_is_refused(tmp_path, capsys):
    """A read-only parent: refused before any work, with the folder named."""
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(SystemExit) as exit_info:
            main(["generate", "--preset", "hand-only", "--out", str(locked / "d")])
        assert exit_info.value.code == 2
        assert "is not writable by this user" in capsys.readouterr().err
    finally:
        locked.chmod(0o700)


def test_generate_with_workers_shows_progress_per_frame_subprocess(tmp_path):
    """`handsim generate --workers 2`: the bar moves with frames, not only at whole shards."""
    values = dict(CONFIG, frames=40, frames_per_shard=20, frames_per_episode=10)
    (tmp_path / "c.json").write_text(json.dumps(values))
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    run = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "generate", "--config", str(tmp_path / "c.json")]
        + ["--workers", "2", "--out", str(tmp_path / "d")],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["frames"] == 40
    counts = {int(n) for n in re.findall(r"(\d+)/40 ", run.stderr)}
    assert 40 in counts and counts - {0, 20, 40}, run.stderr


def test_generate_skin_detail_is_recorded_subprocess(tmp_path):
    """`handsim generate --skin-detail full` records the level in the manifest; bad ones fail."""
    values = dict(CONFIG, frames=2, frames_per_shard=2, frames_per_episode=2)
    (tmp_path / "c.json").write_text(json.dumps(values))
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    command = [sys.executable, "-m", "handsim.cli", "generate", "--config"]
    command.append(str(tmp_path / "c.json"))
    run = subprocess.run(
        command + ["--skin-detail", "full", "--out", str(tmp_path / "d"), "--quiet"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    manifest = json.loads((tmp_path / "d" / "manifest.json").read_text())
    assert manifest["config"]["skin_detail"] == "full"
    bad = subprocess.run(
        command + ["--skin-detail", "coarse", "--out", str(tmp_path / "e")],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert bad.returncode == 2
    assert re.search(r"--skin-detail: invalid choice: 'coarse' \(choose from '?auto", bad.stderr)
