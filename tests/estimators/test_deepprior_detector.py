"""The whole-image hand detector: its coordinates, input, training run and place in the pipeline."""

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from handsim.data.generation import GenerationConfig, generate
from handsim.estimators.deepprior.checkpoint import InvalidCheckpoint
from handsim.estimators.deepprior.detector import (
    DEPTH_MAX_M,
    GRID_H,
    GRID_W,
    INPUT_H,
    INPUT_W,
    DetectorTrainConfig,
    InvalidDetectorConfig,
    LearnedDetector,
    _shift,
    decode,
    detector_input,
    detector_targets,
    train_detector,
)
from handsim.estimators.deepprior.estimator import DeepPriorEstimator, RefinedLocalizer

TINY = dict(epochs=2, batch_size=8, channels=8, max_frames=16, seed=1)


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    """30 hand-only frames, one per episode (so every split has frames)."""
    out = tmp_path_factory.mktemp("tiny_det")
    config = GenerationConfig(
        frames=30, frames_per_shard=15, frames_per_episode=1, seed=7,
        num_objects_range=(0, 0), viewpoints=("third_person",), sensor="structured_light",
        hand_length_range_m=(0.18, 0.18),
    )  # fmt: skip
    generate(config, out)
    return out


@pytest.fixture(scope="module")
def tiny_run(tiny_data, tmp_path_factory):
    """A 2-epoch detector run on the tiny data."""
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("det_run")
    train_detector([tiny_data], out, DetectorTrainConfig(**TINY), progress=False, log=lambda s: 0)
    return out


def _keypoints(n, rng):
    kp = np.zeros((n, 21, 3))
    kp[:, 9] = rng.uniform([-0.2, -0.15, 0.3], [0.2, 0.15, 1.2], (n, 3))
    return kp


@pytest.mark.parametrize("size", [(320, 240), (640, 480), (160, 120)])
def test_targets_decoded_at_their_cell_give_the_mcp_back(size):
    """detector_targets and decode invert each other for any 4:3 image size (to 1e-12 m)."""
    rng = np.random.default_rng(0)
    w, h = size
    K = np.tile([[0.75 * w, 0, w / 2 - 0.3], [0, 0.75 * w, h / 2 + 0.2], [0, 0, 1.0]], (50, 1, 1))  # noqa: N806
    kp = _keypoints(50, rng)
    u = K[:, 0, 0] * kp[:, 9, 0] / kp[:, 9, 2] + K[:, 0, 2]
    v = K[:, 1, 1] * kp[:, 9, 1] / kp[:, 9, 2] + K[:, 1, 2]
    inside = (u > -0.5) & (u < w - 0.5) & (v > -0.5) & (v < h - 0.5)
    cell, position, depth_dm = detector_targets(kp, K, size)
    assert ((position[inside] >= 0) & (position[inside] < 1)).all()
    out = np.zeros((50, 4, GRID_H, GRID_W))
    gy, gx = np.divmod(cell, GRID_W)
    out[np.arange(50), 0, gy, gx] = 1.0
    out[np.arange(50), 1:3, gy, gx] = position
    out[np.arange(50), 3, gy, gx] = depth_dm
    np.testing.assert_allclose(decode(out, K, size), kp[:, 9], atol=1e-12)


def test_a_pixel_maps_to_its_cell():
    """The image's top-left pixel is in cell 0, the bottom-right one in the last cell."""
    K = np.array([[[300.0, 0, 160], [0, 300, 120], [0, 0, 1]]] * 2)  # noqa: N806
    corners = np.array([[0.0, 0.0], [319.0, 239.0]])
    kp = np.zeros((2, 21, 3))
    kp[:, 9, 2] = 0.5
    kp[:, 9, :2] = (corners - [160, 120]) * 0.5 / 300.0
    cell, position, _ = detector_targets(kp, K, (320, 240))
    assert cell.tolist() == [0, GRID_W * GRID_H - 1]
    # Pixel 0's centre is at 0.5 of INPUT_W / 320 input pixels, in cells of 4.
    np.testing.assert_allclose(position[0], [0.5 * INPUT_W / 320 / 4] * 2)


def test_input_subsamples_pixel_centres_and_masks_what_was_not_measured():
    """Depth beyond DEPTH_MAX_M and missing depth are 0 with a 0 mask; batches equal singles."""
    depth = np.zeros((240, 320), np.float32)
    depth[:, 160:] = 0.5
    depth[:120, 200:] = DEPTH_MAX_M + 0.1  # beyond the detector's range
    x = detector_input(depth)
    assert x.shape == (2, INPUT_H, INPUT_W) and x.dtype == np.float32
    assert (x[0, :, : INPUT_W // 2] == 0).all() and (x[1, :, : INPUT_W // 2] == 0).all()
    assert x[0, -1, -1] == pytest.approx(0.5 / DEPTH_MAX_M) and x[1, -1, -1] == 1
    assert x[0, 0, -1] == 0 and x[1, 0, -1] == 0
    batch = detector_input(np.stack([depth, depth]))
    np.testing.assert_array_equal(batch[1], x)


@pytest.mark.parametrize("dx, dy", [(0, 0), (3, -2), (-5, 4)])
def test_shift_moves_the_image_and_leaves_the_border_unmeasured(dx, dy):
    """Every pixel moves by (dx, dy); what comes in from outside is 0 (nothing measured)."""
    image = np.arange(1, 13 * 17 + 1, dtype=np.float32).reshape(13, 17)
    moved = _shift(image, dx, dy)
    for y in range(13):
        for x in range(17):
            sy, sx = y - dy, x - dx
            inside = 0 <= sy < 13 and 0 <= sx < 17
            assert moved[y, x] == (image[sy, sx] if inside else 0)


def test_train_resumes_to_the_same_weights_and_is_loaded_by_the_pipeline(
    tiny_data, tiny_run, tmp_path
):
    """A run killed after epoch 1 and rerun equals a straight run; the pipeline takes it."""

    class Killed(Exception):
        pass

    def kill(line):
        if line.startswith('{"epoch": 1'):
            raise Killed

    config = DetectorTrainConfig(**TINY)
    with pytest.raises(Killed):
        train_detector([tiny_data], tmp_path / "cut", config, progress=False, log=kill)
    lines = []
    resumed = train_detector(
        [tiny_data], tmp_path / "cut", config, progress=False, log=lines.append
    )
    assert any("after epoch 1" in line for line in lines) and resumed["epochs_done"] == 2
    a = torch.load(tiny_run / "last.pt", weights_only=True)["model"]
    b = torch.load(tmp_path / "cut" / "last.pt", weights_only=True)["model"]
    for key in a:
        torch.testing.assert_close(a[key], b[key], msg=key)
    history = json.loads((tiny_run / "metrics.json").read_text())["history"]
    assert all(e["val_mean_error_mm"] > 0 and 0 <= e["val_over_50mm"] <= 1 for e in history)
    with pytest.raises(InvalidDetectorConfig, match="other options .*epochs"):
        train_detector([tiny_data], tmp_path / "cut", DetectorTrainConfig(**{**TINY, "epochs": 3}))

    # The pipeline with the run as its first centre: a batch equals frames one by one.
    det = LearnedDetector(tiny_run)
    depth = np.full((240, 320), 0.6, np.float32)
    depth[100:140, 150:190] = 0.45
    K = np.array([[241.42, 0, 160], [0, 241.42, 120], [0, 0, 1.0]])  # noqa: N806
    one = det.localize(depth, K)
    both = det.localize_batch([depth, depth[:, ::-1].copy()], np.stack([K, K]))
    np.testing.assert_allclose(both[0], one, rtol=1e-6)
    assert det.localize(np.zeros_like(depth), K) is None
    est = DeepPriorEstimator("deepprior++", detector=str(tiny_run), threads=1)
    assert est.predict(depth, K).valid and "detector=" in repr(est)


def test_unknown_detectors_and_checkpoints_of_other_networks_are_refused(tmp_path):
    """Each is one error naming what is valid."""
    with pytest.raises(InvalidCheckpoint, match="detector must be one of plane, com, learned"):
        RefinedLocalizer(detector="nearest")
    with pytest.raises(InvalidCheckpoint, match="'localizer' network, not a hand detector"):
        LearnedDetector("localizer")
    with pytest.raises(InvalidCheckpoint, match="not found"):
        RefinedLocalizer(detector=str(tmp_path / "missing.pt"))


@pytest.mark.parametrize(
    "change, message",
    [
        ({"epochs": 0}, r"epochs must be an integer in \[1, 10000\]; received 0"),
        ({"channels": 2}, r"channels must be an integer in \[4, 512\]"),
        ({"shift_px": 100}, r"shift_px must be an integer in \[0, 64\]"),
        ({"lr": float("nan")}, r"lr must be in \[0, 1.0\]; received nan"),
        ({"depth_shift_m": 1.0}, r"depth_shift_m must be in \[0, 0.5\]"),
    ],
)
def test_bad_training_options_are_refused_before_any_work(change, message, tmp_path):
    """Out-of-range options raise before the run folder is made."""
    with pytest.raises(InvalidDetectorConfig, match=message):
        train_detector([tmp_path], tmp_path / "r", DetectorTrainConfig(**{**TINY, **change}))
    assert not (tmp_path / "r").exists()


def test_cli_train_detector_and_its_refused_options(tiny_data, tmp_path):
    """`handsim train detector` as a user runs it; a pose network's option is one error line."""
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "handsim.cli", "train", "detector", "--data", str(tiny_data),
           "--out", str(run), "--epochs", "1", "--batch-size", "8", "--max-frames", "16",
           "--threads", "1", "-q"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["kind"] == "detector" and summary["epochs_done"] == 1
    assert LearnedDetector(run).checkpoint == str(run)
    bad = subprocess.run([*cmd, "--localizer", "localizer"], capture_output=True, text=True)
    assert bad.returncode == 2
    assert "argument --localizer: not allowed with detector" in bad.stderr
    assert "Traceback" not in bad.stderr


def test_training_centres_from_the_detector_equal_its_frame_by_frame_centres(tiny_data, tiny_run):
    """localizer_centers(detector=RUN) runs the detector in batches: each frame's own centre."""
    from handsim.estimators.deepprior.data import load_frames
    from handsim.estimators.deepprior.train import localizer_centers

    frames = load_frames([tiny_data], "all", canonical_side=True)
    centres, found = localizer_centers(frames, None, detector=str(tiny_run))
    det = LearnedDetector(tiny_run)
    assert found.all()
    one = np.stack([det.localize(frames.depth(i), frames.K[i]) for i in range(len(frames))])
    np.testing.assert_allclose(centres, one, rtol=1e-6, atol=1e-9)
