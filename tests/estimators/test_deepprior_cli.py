"""`handsim train` (resume after a kill is exact) and `handsim evaluate` on a tiny dataset."""

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from handsim.cli import main
from handsim.errors import InvalidEstimatorParams
from handsim.estimators.deepprior.data import CropDataset, load_frames
from handsim.estimators.deepprior.train import InvalidTrainConfig, TrainConfig, train

TINY = dict(
    kind="deepprior++", epochs=2, batch_size=8, size=32, fc=16, width=0.125, prior_dim=4,
    max_frames=16, seed=3,
)  # fmt: skip


class _Killed(Exception):
    pass


def test_train_resume_after_a_kill_equals_an_uninterrupted_run(tiny_data, tmp_path):
    """A run killed after epoch 1 and rerun ends with the same weights as a straight run."""
    torch.set_num_threads(1)
    config = TrainConfig(**TINY)
    full = train([tiny_data], tmp_path / "full", config, progress=False, log=lambda s: None)
    assert full["epochs_done"] == 2

    def kill_after_first_epoch(line):
        if line.startswith('{"epoch": 1'):
            raise _Killed

    with pytest.raises(_Killed):
        train([tiny_data], tmp_path / "cut", config, progress=False, log=kill_after_first_epoch)
    lines = []
    resumed = train([tiny_data], tmp_path / "cut", config, progress=False, log=lines.append)
    assert any("resuming" in line and "after epoch 1" in line for line in lines)
    timings = ("elapsed_s", "data_wait_s")  # wall-clock measurements, not results
    strip = [{k: v for k, v in e.items() if k not in timings} for e in resumed["history"]]
    assert strip == [{k: v for k, v in e.items() if k not in timings} for e in full["history"]]
    a = torch.load(tmp_path / "full" / "last.pt", weights_only=True)["model"]
    b = torch.load(tmp_path / "cut" / "last.pt", weights_only=True)["model"]
    for key in a:
        torch.testing.assert_close(a[key], b[key], msg=key)
    metrics = json.loads((tmp_path / "cut" / "metrics.json").read_text())
    assert metrics["epochs_done"] == 2
    assert np.sum(metrics["pca_explained_variance"]) == pytest.approx(1.0)
    with pytest.raises(InvalidTrainConfig, match="other options .*epochs"):
        train([tiny_data], tmp_path / "cut", TrainConfig(**{**TINY, "epochs": 3}), progress=False)


def test_init_starts_from_a_checkpoint_of_the_same_network(tiny_data, tmp_path):
    """--init loads a run's weights (lr 0 keeps them); another network is refused by name."""
    torch.set_num_threads(1)
    quiet = {"progress": False, "log": lambda s: None}
    config = TrainConfig(**{**TINY, "epochs": 1})
    train([tiny_data], tmp_path / "a", config, **quiet)
    lines = []
    tuned = TrainConfig(**{**TINY, "epochs": 1, "lr": 0.0, "init": str(tmp_path / "a")})
    train([tiny_data], tmp_path / "b", tuned, progress=False, log=lines.append)
    assert any(line.startswith("starting from the weights of") for line in lines)
    a = torch.load(tmp_path / "a" / "last.pt", weights_only=True)["model"]
    b = torch.load(tmp_path / "b" / "last.pt", weights_only=True)["model"]
    for key in a:
        if "running_" not in key and "num_batches" not in key:  # batch norm still tracks
            torch.testing.assert_close(a[key], b[key], msg=key)
    other = TrainConfig(**{**TINY, "width": 0.25, "init": str(tmp_path / "a")})
    with pytest.raises(InvalidTrainConfig, match="holds another network .*width"):
        train([tiny_data], tmp_path / "c", other, **quiet)


def test_crop_dataset_is_deterministic_per_epoch(tiny_data):
    """A sample is the same when drawn twice in an epoch, and changes with the epoch."""
    frames = load_frames(tiny_data, "all")
    ds = CropDataset(frames, rotation=True, scale=True, translation=True, size=32)
    x0, y0 = ds.sample(0)
    x1, y1 = ds.sample(0)
    np.testing.assert_array_equal(x0, x1)
    ds.epoch = 1
    assert not np.array_equal(ds.sample(0)[1], y0)


def test_crop_dataset_alt_centers_are_drawn_with_their_probability(tiny_data):
    """alt_fraction 1 always crops at the alternative centres, 0 never."""
    frames = load_frames(tiny_data, "all")
    mcp = frames.keypoints_cam[:, 9]
    far = mcp + [0.05, 0.0, 0.0]
    at_mcp = CropDataset(frames, mcp, size=32)
    always = CropDataset(frames, far, size=32, alt_centers=mcp, alt_fraction=1.0)
    never = CropDataset(frames, far, size=32, alt_centers=mcp, alt_fraction=0.0)
    for i in range(3):
        np.testing.assert_array_equal(always.sample(i)[0], at_mcp.sample(i)[0])
        assert not np.array_equal(never.sample(i)[1], at_mcp.sample(i)[1])


def test_cli_train_and_evaluate_write_metrics(tiny_data, tmp_path, capsys):
    """`handsim train` then `handsim evaluate` on its run folder: metrics.json and plots."""
    run = tmp_path / "run"
    args = ["train", "deepprior++", "--data", str(tiny_data), "--out", str(run), "--epochs", "1",
            "--size", "32", "--fc", "16", "--width", "0.125", "--prior-dim", "4",
            "--batch-size", "8", "-q", "--threads", "1"]  # fmt: skip
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["epochs_done"] == 1
    out = tmp_path / "eval"
    args = ["evaluate", "--estimator", str(run), "--data", str(tiny_data), "--out", str(out),
            "--split", "all", "--localizer", "none", "-q"]  # fmt: skip
    assert main(args) == 0
    report = json.loads((out / "metrics.json").read_text())
    assert report["mean_error_mm"] > 0 and report["n_frames"] == 30
    assert set(report["localization_mm"]) == {"com", "plane_removed_com", "detector", "refined"}
    assert "detector='learned'" in report["estimator"]
    assert len(report["per_joint_mean_mm"]) == 21
    assert "structured_light" in report["by_sensor"]
    for name in ("f_tau.png", "pck.png", "error_by_occlusion.png", "error_by_joint.png"):
        assert (out / name).stat().st_size > 0


def test_cli_errors(tmp_path, capsys):
    """A missing checkpoint or dataset is one error line naming what is valid (exit 2)."""
    assert main(["evaluate", "--estimator", str(tmp_path / "none"), "--data", str(tmp_path),
                 "--out", str(tmp_path / "o")]) == 2  # fmt: skip
    assert "give a shipped name" in capsys.readouterr().err
    assert main(["train", "localizer", "--data", str(tmp_path), "--out", str(tmp_path / "r"),
                 "-q"]) == 2  # fmt: skip
    assert "error" in capsys.readouterr().err


def test_loader_workers_do_not_change_the_result(tiny_data, tmp_path):
    """Crops come from per-sample seeds: 2 DataLoader processes train the same weights as 0."""
    torch.set_num_threads(1)
    config = TrainConfig(**{**TINY, "epochs": 1})
    quiet = {"progress": False, "log": lambda s: None}
    train([tiny_data], tmp_path / "w0", config, loader_workers=0, **quiet)
    train([tiny_data], tmp_path / "w2", config, loader_workers=2, **quiet)
    a = torch.load(tmp_path / "w0" / "last.pt", weights_only=True)["model"]
    b = torch.load(tmp_path / "w2" / "last.pt", weights_only=True)["model"]
    for key in a:
        torch.testing.assert_close(a[key], b[key], msg=key)


def test_localizer_centers_in_worker_processes_and_batches_equal_one_by_one(tiny_data, tmp_path):
    """Forked plane fits and the batched refinement give each frame's one-by-one centre."""
    from handsim.estimators.deepprior.estimator import RefinedLocalizer
    from handsim.estimators.deepprior.preprocess import PlaneRemovedLocalizer
    from handsim.estimators.deepprior.train import localizer_centers

    torch.set_num_threads(1)
    frames = load_frames(tiny_data, "all")
    loc_config = TrainConfig(kind="localizer", epochs=1, batch_size=8, size=32, fc=16, seed=1)
    train([tiny_data], tmp_path / "loc", loc_config, progress=False, log=lambda s: None)
    ckpt = str(tmp_path / "loc" / "last.pt")
    serial, found = localizer_centers(frames, ckpt)
    forked, found2 = localizer_centers(frames, ckpt, workers=2)
    np.testing.assert_array_equal(found, found2)
    np.testing.assert_allclose(forked, serial, atol=1e-9)
    # The plane fit misses a pointing hand whose arm is seen lengthwise: 1 of these 30 frames
    # (199 of 200 hand-only frames of seed 11; none before the arm was drawn).
    assert found.sum() >= len(found) - 1
    refined = RefinedLocalizer(ckpt)
    base = PlaneRemovedLocalizer()
    for i in range(0, len(frames), 7):
        start = base.localize(frames.depth(i), frames.K[i])
        one = refined.refine(frames.depth(i), frames.K[i], start)
        np.testing.assert_allclose(serial[i], one, atol=1e-6)
        assert not np.allclose(one, start)  # the network moved it


def test_env_frames_keep_every_nth_step_of_the_expert():
    """Frames of Grasp-v0's expert: depth, intrinsics and keypoints of every 20th step."""
    from handsim.estimators.deepprior.data import env_frames

    frames = env_frames("handsim/Grasp-v0", episodes=1, every=20, seed=0)
    assert 5 <= len(frames) <= 40
    assert frames.depth_units.dtype == np.uint16 and frames.depth_units.ndim == 3
    assert frames.keypoints_cam.shape == (len(frames), 21, 3)
    assert np.all(frames.keypoints_cam[..., 2] > 0.1)  # in front of the camera
    assert np.all((frames.occlusion >= 0) & (frames.occlusion <= 1))


def test_deepprior_with_the_com_detector_and_no_refinement(tiny_data, tmp_path):
    """detector='com' without a localizer is DeepPrior's own pipeline; a bad name is refused."""
    from handsim.estimators.deepprior.checkpoint import InvalidCheckpoint
    from handsim.estimators.deepprior.estimator import DeepPriorEstimator
    from handsim.estimators.deepprior.preprocess import MIDDLE_MCP

    torch.set_num_threads(1)
    train([tiny_data], tmp_path / "dp", TrainConfig(**TINY), progress=False, log=lambda s: None)
    est = DeepPriorEstimator(tmp_path / "dp", localizer=None, detector="com")
    assert "detector='com'" in repr(est) and est.info()["detector"] == "com"
    frames = load_frames(tiny_data, "all")
    estimate = est.predict(frames.depth(0), frames.K[0])
    assert estimate.valid and estimate.keypoints_cam.shape == (21, 3)
    # The hand is the nearest thing: the centre of mass lands within a cube of the MCP.
    center = est.localizer.localize(frames.depth(0), frames.K[0])
    assert np.linalg.norm(center - frames.keypoints_cam[0, MIDDLE_MCP]) < 0.125
    with pytest.raises(InvalidCheckpoint, match="detector must be one of plane, com"):
        DeepPriorEstimator(tmp_path / "dp", localizer=None, detector="table")


@pytest.mark.parametrize("command", ["train", "evaluate"])
def test_cli_device_cuda_without_a_gpu_is_one_error_line(command, tmp_path, capsys, monkeypatch):
    """--device cuda on a machine without CUDA says so (exit 2) before any work."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    args = {
        "train": ["train", "localizer", "--data", str(tmp_path), "--out", str(tmp_path / "r")],
        "evaluate": ["evaluate", "--estimator", "deepprior++", "--data", str(tmp_path),
                     "--out", str(tmp_path / "o")],
    }[command]  # fmt: skip
    assert main([*args, "--device", "cuda", "-q"]) == 2
    assert "no CUDA device is available to torch; use cpu" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            {"size": 100_000},
            r"size must be a multiple of 32 in \[32, 512\] pixels; received 100000",
        ),
        ({"size": 48}, "size must be a multiple of 32"),
        ({"weight_decay": -1.0}, r"weight_decay must be in \[0, 1\]; received -1.0"),
        ({"offset_sigma_m": float("nan")}, r"offset_sigma_m must be in \[0, 0.5\] metres"),
        ({"lr": float("inf")}, r"lr must be in \[0, 1\]"),
        ({"cube_m": 0.0}, r"cube_m must be in \(0, 1\] metres; received 0.0"),
        ({"width": -0.5}, r"width must be in \(0, 8\]"),
        (
            {"refine_iterations": -1},
            r"refine_iterations must be an integer in \[0, 10\]; received -1",
        ),
    ],
)
def test_train_config_out_of_range_is_refused_before_any_work(change, message, tmp_path):
    """The Python surface checks what the CLI checks: NaN, negatives, absurd crop sizes."""
    with pytest.raises(InvalidTrainConfig, match=message):
        train([tmp_path], tmp_path / "r", TrainConfig(**{**TINY, **change}), progress=False)
    assert not (tmp_path / "r").exists()


def test_env_frames_refuse_an_unknown_env_id():
    """An unregistered id is a handsim error that lists the envs, not Gymnasium's NameNotFound."""
    from handsim.estimators.deepprior.data import InvalidTrainingData, env_frames

    with pytest.raises(InvalidTrainingData, match=r"one of handsim/HandPose-v0, .*'handsim/Nope"):
        env_frames("handsim/Nope-v0")


def test_resuming_from_a_damaged_last_pt_names_the_file_and_the_fix(tiny_data, tmp_path):
    """Garbage, a truncated file, missing keys: InvalidCheckpoint naming the file, not torch's."""
    from handsim.estimators.deepprior.checkpoint import InvalidCheckpoint

    config = TrainConfig(**{**TINY, "epochs": 1})
    run = tmp_path / "run"
    train([tiny_data], run, config, progress=False, log=lambda s: None)
    last = run / "last.pt"
    whole = last.read_bytes()
    state = torch.load(last, weights_only=True)
    damaged = {
        "garbage": (b"not a checkpoint", r"it is not a readable checkpoint"),
        "truncated": (whole[: len(whole) // 2], r"it is not a readable checkpoint"),
    }
    for data, match in damaged.values():
        last.write_bytes(data)
        with pytest.raises(
            InvalidCheckpoint,
            match=rf"cannot resume from {last}: {match}.*delete {last} to train this run from "
            "its start",
        ):
            train([tiny_data], run, config, progress=False, log=lambda s: None)
    torch.save({k: v for k, v in state.items() if k != "optimizer"}, last)
    with pytest.raises(InvalidCheckpoint, match=r"it lacks optimizer \(a training state holds"):
        train([tiny_data], run, config, progress=False, log=lambda s: None)
    torch.save({**state, "model": {"w": torch.zeros(2)}}, last)
    with pytest.raises(InvalidCheckpoint, match=r"does not fit this run's network and optimizer"):
        train([tiny_data], run, config, progress=False, log=lambda s: None)
    nan = {k: v.clone() for k, v in state["model"].items()}
    next(v for v in nan.values() if v.is_floating_point()).fill_(float("nan"))
    torch.save({**state, "model": nan}, last)
    with pytest.raises(InvalidCheckpoint, match=r"its weights are not finite"):
        train([tiny_data], run, config, progress=False, log=lambda s: None)

    # The CLI, on a run it made: one error line, exit 2.
    run = tmp_path / "cli"
    last = run / "last.pt"
    args = ["train", "deepprior++", "--data", str(tiny_data), "--out", str(run), "--epochs", "1",
            "--size", "32", "--fc", "16", "--width", "0.125", "--prior-dim", "4",
            "--batch-size", "8", "--max-frames", "16", "-q", "--threads", "1"]  # fmt: skip
    assert main(args) == 0
    last.write_bytes(b"not a checkpoint")
    done = subprocess.run(
        [sys.executable, "-m", "handsim.cli", *args], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 2, done.stderr
    error = f"handsim: error: cannot resume from {last}: it is not a readable checkpoint (not"
    assert error in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


def test_closed_loop_cli_takes_the_refinement_guard(tmp_path):
    """`handsim closed-loop --estimator ...DeepPriorEstimator:{"refine_guard": ...}`.

    A value that is not a bool is one error line (exit 2) naming what is valid; ``false``
    runs the loop unguarded (the repr in the report says so) on HandPose-v0, where the
    refinement then walks up the arm (docs/deepprior.md: over 200 mm).
    """
    spec = "handsim.estimators:DeepPriorEstimator:"
    cmd = [sys.executable, "-m", "handsim.cli", "closed-loop", "--env", "handsim/HandPose-v0",
           "--episodes", "1", "--sensor", "none", "-q", "--out", str(tmp_path)]  # fmt: skip
    bad = subprocess.run(
        [*cmd, "--estimator", spec + '{"refine_guard": "no"}'],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert bad.returncode == 2, bad.stderr
    assert "refine_guard must be True" in bad.stderr and "received 'no'" in bad.stderr
    assert "Traceback" not in bad.stderr
    ok = subprocess.run(
        [
            *cmd,
            "--estimator",
            spec + '{"refine_guard": false, "refine_iterations": 3, "threads": 1}',
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert ok.returncode == 0, ok.stderr
    report = json.loads((tmp_path / "closed_loop.json").read_text())
    assert "refine_guard=False" in report["estimator"]["repr"]
    assert report["modes"]["feedback_off"]["kp_mean_mm"] > 150.0


def test_the_estimator_crops_as_its_network_was_trained(tiny_data, tmp_path, capsys):
    """A network trained at the detector's centres unrefined runs without the refinement."""
    from handsim.estimators.deepprior.estimator import DeepPriorEstimator
    from handsim.estimators.deepprior.preprocess import PlaneRemovedLocalizer

    run = tmp_path / "run"
    args = ["train", "deepprior++", "--data", str(tiny_data), "--out", str(run), "--epochs", "1",
            "--size", "32", "--fc", "16", "--width", "0.125", "--prior-dim", "4",
            "--batch-size", "8", "-q", "--threads", "1", "--localizer", "localizer",
            "--detector", "plane", "--refine-iterations", "0"]  # fmt: skip
    assert main(args) == 0
    capsys.readouterr()
    crop = json.loads((run / "best.json").read_text())["crop"]
    assert crop == {"detector": "plane", "localizer": "localizer", "refine_iterations": 0}
    frames = load_frames(tiny_data, "train", canonical_side=True)  # as training sees them
    centers = np.load(run / "centers_train.npy")
    plane = PlaneRemovedLocalizer()
    for i in range(0, len(frames), 5):  # the plane detector's centres, not refined
        np.testing.assert_allclose(centers[i], plane.localize(frames.depth(i), frames.K[i]))
    est = DeepPriorEstimator(run)
    assert est.localizer.iterations == 0 and est.info()["refine_iterations"] == 0
    assert DeepPriorEstimator(run, refine_iterations=2).localizer.iterations == 2
    with pytest.raises(InvalidEstimatorParams, match="track=True refines the previous frame"):
        DeepPriorEstimator(run, track=True)  # nothing would move the tracked centre
    # A checkpoint from before the record: the three steps it was trained with.
    from handsim.estimators.deepprior.checkpoint import load_checkpoint, save_checkpoint

    state, config = load_checkpoint(run)
    del config["crop"]
    save_checkpoint(tmp_path / "old.pt", {"model": state["model"]}, config)
    assert DeepPriorEstimator(tmp_path / "old.pt").localizer.iterations == 3
    # Without a localizer the crops are at the true MCP: no refinement to set.
    bad = args[: args.index("--localizer")] + ["--refine-iterations", "1"]
    with pytest.raises(SystemExit, match="2"):
        main(bad)
    assert "argument --refine-iterations: needs --localizer" in capsys.readouterr().err
