"""The canonical right-hand frame of the learned estimators: mirroring, data, inference."""

import json

import numpy as np
import pytest
import torch

from handsim.data.generation import GenerationConfig, generate
from handsim.errors import InvalidEstimatorParams
from handsim.estimators.deepprior import checkpoint as C
from handsim.estimators.deepprior.data import load_frames, side_frame
from handsim.estimators.deepprior.estimator import DeepPriorEstimator
from handsim.estimators.deepprior.models import build_model
from handsim.estimators.deepprior.preprocess import (
    mirror_depth,
    mirror_intrinsics,
    mirror_points,
)
from handsim.estimators.deepprior.train import TrainConfig, train

W, H = 64, 48
# cx, cy in binary fractions: W - 1 - (W - 1 - cx) == cx exactly (e.g. 159.5 of a preset).
K_CV = np.array([[60.0, 0.0, 30.25], [0.0, 61.0, 22.75], [0.0, 0.0, 1.0]])


def _project(points, K):  # noqa: N803
    uvw = points @ K.T
    return uvw[:, :2] / uvw[:, 2:]


def _blob_depth():
    """A hand-sized bump, off-centre and asymmetric (so a mirror is not the same image)."""
    v, u = np.mgrid[0:H, 0:W]
    depth = np.zeros((H, W), np.float32)
    blob = ((u - 22) / 9.0) ** 2 + ((v - 20) / 12.0) ** 2 < 1
    depth[blob] = 0.45 + 0.002 * (u[blob] - 22) + 0.001 * v[blob]
    depth[30:40, 35:50] = 0.47  # a "thumb"
    return depth


def test_mirroring_is_exact_and_involutive():
    """Twice is the identity; x -> -x projects to u' = W - 1 - u under the mirrored K."""
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.3, 0.8, size=(H, W)).astype(np.float32)
    np.testing.assert_array_equal(mirror_depth(mirror_depth(depth)), depth)
    assert mirror_depth(depth)[5, 0] == depth[5, W - 1]
    K_skew = K_CV.copy()  # noqa: N806
    K_skew[0, 1] = 0.7
    np.testing.assert_array_equal(mirror_intrinsics(mirror_intrinsics(K_skew, W), W), K_skew)
    points = np.column_stack([rng.uniform(-0.1, 0.1, (21, 2)), rng.uniform(0.3, 0.8, 21)])
    np.testing.assert_array_equal(mirror_points(mirror_points(points)), points)
    uv = _project(points, K_skew)
    uv_m = _project(mirror_points(points), mirror_intrinsics(K_skew, W))
    np.testing.assert_allclose(uv_m[:, 0], W - 1 - uv[:, 0], atol=1e-9)
    np.testing.assert_allclose(uv_m[:, 1], uv[:, 1], atol=1e-9)
    # A pixel's back-projected point, mirrored, is the mirrored pixel's back-projection.
    u, v, z = 17, 9, float(depth[9, 17])
    p = np.array([(u - K_CV[0, 2]) * z / K_CV[0, 0], (v - K_CV[1, 2]) * z / K_CV[1, 1], z])
    K_m = mirror_intrinsics(K_CV, W)  # noqa: N806
    um = W - 1 - u
    assert mirror_depth(depth)[v, um] == z
    q = np.array([(um - K_m[0, 2]) * z / K_m[0, 0], (v - K_m[1, 2]) * z / K_m[1, 1], z])
    np.testing.assert_allclose(q, mirror_points(p), atol=1e-12)


def _checkpoint(tmp_path, flag):
    config = {
        "model": {"arch": "resnet", "size": 32, "fc": 16, "width": 0.125, "prior_dim": 4},
        "cube_m": 0.25,
        "kind": "deepprior++",
    }
    if flag is not None:
        config["canonical_side"] = flag
    torch.manual_seed(0)
    net = build_model(config["model"]).eval()
    path = tmp_path / f"net_{flag}.pt"
    C.save_checkpoint(path, {"model": net.state_dict()}, config)
    return path


def test_a_left_frame_and_its_mirrored_right_frame_give_mirrored_predictions(tmp_path):
    """Random weights: predict(left, D, K) is the mirror of predict(right, mirror(D), K')."""
    torch.set_num_threads(1)
    depth = _blob_depth()
    est = DeepPriorEstimator(_checkpoint(tmp_path, True), localizer=None, detector="com")
    assert est.canonical_side
    est.set_side(True)
    left = est.predict(depth, K_CV)
    est.set_side(False)
    right = est.predict(mirror_depth(depth), mirror_intrinsics(K_CV, W))
    assert left.valid and right.valid
    np.testing.assert_allclose(left.keypoints_cam, mirror_points(right.keypoints_cam), atol=1e-9)
    # Without canonicalization the network sees the left frame as it is: another answer.
    off = DeepPriorEstimator(
        _checkpoint(tmp_path, True), localizer=None, detector="com", canonical_side=False
    )
    off.set_side(True)
    unmirrored = off.predict(depth, K_CV).keypoints_cam
    assert np.abs(unmirrored - left.keypoints_cam).max() > 1e-4
    # A right hand is never mirrored.
    est.set_side(False)
    np.testing.assert_array_equal(
        est.predict(depth, K_CV).keypoints_cam, off.predict(depth, K_CV).keypoints_cam
    )


def test_checkpoints_without_the_flag_keep_their_behaviour(tmp_path):
    """An old checkpoint (no canonical_side) is run unmirrored on either side."""
    depth = _blob_depth()
    old = DeepPriorEstimator(_checkpoint(tmp_path, None), localizer=None, detector="com")
    assert not old.canonical_side
    a = old.predict(depth, K_CV).keypoints_cam
    old.set_side(True)
    np.testing.assert_array_equal(old.predict(depth, K_CV).keypoints_cam, a)
    assert "canonical_side=False" in repr(old)


def test_side_options_are_checked(tmp_path):
    """set_side and canonical_side take bools, and say so."""
    path = _checkpoint(tmp_path, True)
    est = DeepPriorEstimator(path, localizer=None)
    with pytest.raises(InvalidEstimatorParams, match="is_left must be a bool .*received 'left'"):
        est.set_side("left")
    with pytest.raises(C.InvalidCheckpoint, match="canonical_side must be True, False or None"):
        DeepPriorEstimator(path, localizer=None, canonical_side="yes")


@pytest.fixture(scope="module")
def sided_data(tmp_path_factory):
    """12 hand-only frames, both sides (one frame per episode)."""
    out = tmp_path_factory.mktemp("sided")
    config = GenerationConfig(
        frames=12, frames_per_shard=12, frames_per_episode=1, seed=11,
        num_objects_range=(0, 0), viewpoints=("third_person",), left_fraction=0.5,
        hand_length_range_m=(0.18, 0.18),
    )  # fmt: skip
    generate(config, out)
    return out


def test_load_frames_mirrors_left_hands_into_the_right_hand_frame(sided_data):
    """Left frames: depth columns flipped, keypoints still on their pixels; right untouched."""
    raw = load_frames(sided_data)
    canon = load_frames(sided_data, canonical_side=True)
    left = raw.is_left
    assert left.any() and (~left).any()
    np.testing.assert_array_equal(canon.mirrored, left)
    np.testing.assert_array_equal(canon.depth_units[~left], raw.depth_units[~left])
    np.testing.assert_array_equal(canon.depth_units[left], raw.depth_units[left][..., ::-1])
    width = raw.depth_units.shape[-1]
    for i in np.flatnonzero(left):
        uv = _project(raw.keypoints_cam[i], raw.K[i])
        uv_m = _project(canon.keypoints_cam[i], canon.K[i])
        np.testing.assert_allclose(uv_m[:, 0], width - 1 - uv[:, 0], atol=1e-9)
        np.testing.assert_allclose(uv_m[:, 1], uv[:, 1], atol=1e-9)
    # The same frames either way round: side_frame converts exactly.
    back = side_frame(canon, False)
    for name in ("depth_units", "K", "keypoints_cam"):
        np.testing.assert_array_equal(getattr(back, name), getattr(raw, name))
    assert side_frame(raw, False) is raw
    np.testing.assert_array_equal(side_frame(raw, True).depth_units, canon.depth_units)


def test_training_records_the_side_convention(sided_data, tmp_path):
    """best.json says canonical_side; --no-canonical-side records False."""
    torch.set_num_threads(1)
    tiny = dict(
        kind="deepprior++", epochs=1, batch_size=4, size=32, fc=16, width=0.125, prior_dim=4,
        seed=1,
    )  # fmt: skip
    quiet = {"progress": False, "log": lambda s: None}
    for flag in (True, False):
        out = tmp_path / str(flag)
        train([sided_data], out, TrainConfig(**tiny, canonical_side=flag), **quiet)
        assert json.loads((out / "best.json").read_text())["canonical_side"] is flag
        assert DeepPriorEstimator(out, localizer=None).canonical_side is flag


def test_train_and_evaluate_cli_no_canonical_side_subprocess(sided_data, tmp_path):
    """--no-canonical-side: the run records False; evaluate reports the side and per side."""
    import subprocess
    import sys

    run = tmp_path / "run"
    train_args = [
        "train", "deepprior++", "--data", str(sided_data), "--out", str(run), "--epochs", "1",
        "--batch-size", "4", "--size", "32", "--fc", "16", "--width", "0.125",
        "--prior-dim", "4", "--threads", "1", "--no-canonical-side", "-q",
    ]  # fmt: skip
    result = subprocess.run(
        [sys.executable, "-m", "handsim.cli", *train_args], capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr
    assert json.loads((run / "best.json").read_text())["canonical_side"] is False
    out = tmp_path / "eval"
    eval_args = [
        "evaluate", "--estimator", str(run), "--data", str(sided_data), "--split", "all",
        "--localizer", "none", "--out", str(out), "--threads", "1", "-q",
    ]  # fmt: skip
    result = subprocess.run(
        [sys.executable, "-m", "handsim.cli", *eval_args], capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr
    report = json.loads((out / "metrics.json").read_text())
    assert report["canonical_side"] is False
    assert report["by_side"]["left"]["n"] + report["by_side"]["right"]["n"] == 12


def test_worker_processes_read_the_same_frames_and_centres(tmp_path):
    """load_frames and localizer_centers with workers give what one process gives, bit for bit."""
    from handsim.estimators.deepprior.train import localizer_centers

    config = GenerationConfig(
        frames=12, frames_per_shard=4, frames_per_episode=1, seed=12,
        num_objects_range=(0, 0), viewpoints=("third_person",), left_fraction=0.5,
    )  # fmt: skip
    generate(config, tmp_path / "data")
    serial = load_frames(tmp_path / "data", canonical_side=True)
    forked = load_frames(tmp_path / "data", canonical_side=True, workers=3)
    assert len(serial) == 12
    for name in serial.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(forked, name), getattr(serial, name))
    centers, found = localizer_centers(serial, "localizer")
    centers_forked, found_forked = localizer_centers(serial, "localizer", workers=2)
    assert found.any()
    np.testing.assert_array_equal(found_forked, found)
    np.testing.assert_array_equal(centers_forked, centers)
