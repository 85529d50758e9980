"""The feedback loop: synthesizers, updater, loss, training (CLI, resume) and the estimator."""

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from handsim.data.generation import GenerationConfig, generate
from handsim.errors import InvalidEstimatorInput
from handsim.estimators.deepprior.checkpoint import InvalidCheckpoint
from handsim.estimators.deepprior.data import load_frames
from handsim.estimators.deepprior.preprocess import crop_depth, crop_matrix, normalize_keypoints
from handsim.estimators.feedback.models import (
    InvalidFeedbackModel,
    LearnedSynthesizer,
    Updater,
    build_feedback_model,
)
from handsim.estimators.feedback.synth import (
    InvalidSynthesizerInput,
    RendererSynthesizer,
    make_synthesizer,
)
from handsim.estimators.feedback.train import (
    FeedbackTrainConfig,
    InvalidFeedbackConfig,
    feedback_loss,
    frame_sides,
    train_updater,
)

CUBE = 0.25


@pytest.fixture(scope="module")
def clean_data(tmp_path_factory):
    """24 hand-only frames without sensor noise, one per episode, both sides."""
    out = tmp_path_factory.mktemp("clean")
    config = GenerationConfig(
        frames=24, frames_per_shard=12, frames_per_episode=1, seed=5,
        num_objects_range=(0, 0), viewpoints=("third_person",), sensor="none",
        hand_length_range_m=(0.18, 0.18),
    )  # fmt: skip
    generate(config, out)
    return out


@pytest.fixture(scope="module")
def synth():
    """One renderer synthesizer for the module's tests."""
    with RendererSynthesizer() as s:
        yield s


def _inputs(frames, i):
    c = frames.keypoints_cam[i, 9]
    pose = normalize_keypoints(frames.keypoints_cam[i], c, CUBE).reshape(1, 63)
    return pose, c[None], frames.K[i]


def test_renderer_reproduces_the_datas_crop_at_the_true_pose(clean_data, synth):
    """Rendered at the true pose, the hand's pixels lie within a few mm of the data's crop."""
    frames = load_frames(clean_data)
    left = frame_sides(clean_data)
    assert left.any() and not left.all()  # both sides are checked
    for i in range(8):
        pose, c, K = _inputs(frames, i)  # noqa: N806
        crops, poses = synth(pose, c, K, frames.hand_length_m[i], left[i : i + 1])
        data = crop_depth(frames.depth(i), crop_matrix(c[0], K), c[0, 2])
        hand = crops[0] < 1.0
        diff_mm = np.abs(crops[0] - data)[hand] * CUBE / 2 * 1000
        assert hand.sum() > 500
        assert np.median(diff_mm) < 2.0, i
        assert np.mean(diff_mm < 5.0) > 0.9, i
        assert poses[0] is not None


def test_renderer_is_deterministic_and_batched(clean_data, synth):
    """The same batch twice gives the same crops; a batch equals its frames one by one."""
    frames = load_frames(clean_data, max_frames=3)
    c = frames.keypoints_cam[:, 9]
    poses = normalize_keypoints(frames.keypoints_cam, c, CUBE).reshape(3, 63)
    a, _ = synth(poses, c, frames.K, frames.hand_length_m)
    b, _ = synth(poses, c, frames.K, frames.hand_length_m)
    assert a.shape == (3, 128, 128) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    one, _ = synth(poses[1:2], c[1:2], frames.K[1], frames.hand_length_m[1])
    np.testing.assert_array_equal(one[0], a[1])
    assert a.min() >= -1.0 and a.max() <= 1.0
    # The hand's size fitted to the pose (NaN length): nearly the true size's crop.
    fitted, _ = synth(poses[:1], c[:1], frames.K[0], np.nan)
    assert np.mean(np.abs(fitted[0] - a[0]) * CUBE / 2 * 1000 < 5.0) > 0.9


def test_renderer_refuses_bad_input(synth):
    """Shapes that do not agree and non-finite poses are refused with what is expected."""
    with pytest.raises(InvalidSynthesizerInput, match=r"expected poses \(B, 63\), centres"):
        synth(np.zeros((2, 63)), np.ones((3, 3)), np.eye(3), 0.18)
    with pytest.raises(InvalidSynthesizerInput, match="poses must be finite"):
        synth(np.full((1, 63), np.nan), np.ones((1, 3)), np.eye(3), 0.18)
    with pytest.raises(InvalidSynthesizerInput, match="renderer or learned; received 'x'"):
        make_synthesizer("x")
    with pytest.raises(InvalidSynthesizerInput, match="needs a checkpoint"):
        make_synthesizer("learned")


def test_network_shapes_and_the_updaters_zero_start():
    """Synthesizer: (B, 63) -> (B, 1, 128, 128) in [-1, 1]; a new updater predicts no update."""
    torch.manual_seed(0)
    s = LearnedSynthesizer(128, fc=32, filters=4)
    y = s(torch.randn(2, 63))
    assert y.shape == (2, 1, 128, 128) and y.abs().max() <= 1.0
    u = Updater(64, filters=4, fc=16)
    out = u(torch.randn(3, 1, 64, 64), torch.randn(3, 1, 64, 64))
    assert out.shape == (3, 63) and torch.all(out == 0)
    with pytest.raises(InvalidFeedbackModel, match=r"size must be 8 \* 2\*\*k"):
        LearnedSynthesizer(96)
    with pytest.raises(InvalidFeedbackModel, match="arch must be one of synthesizer, updater"):
        build_feedback_model({"arch": "resnet"})


def test_loss_is_zero_at_the_truth_and_a_hinge():
    """max(0, |P''-P| - lam |P'-P|): 0 at P'' = P' = P; 0 when the update gains enough."""
    p = torch.randn(4, 63)
    assert torch.all(feedback_loss(p, p, p) == 0)
    start = p + 1.0
    assert torch.all(feedback_loss(p + 0.5, start, p, 0.6) == 0)  # 0.5 < 0.6 of the way
    off = feedback_loss(p + 0.7, start, p, 0.6)
    torch.testing.assert_close(off, torch.full((4,), 0.1 * 63**0.5))
    assert torch.all(feedback_loss(p + 0.1, p, p) > 0)  # any update of the truth costs


TINY = dict(kind="updater", epochs=3, batch_size=8, size=32, fc=8, filters=2,
            predictor=None, max_frames=8, seed=1)  # fmt: skip


class _Killed(Exception):
    pass


def test_updater_resume_after_a_kill_equals_an_uninterrupted_run(clean_data, tmp_path):
    """Killed after epoch 2 (its pool grown by its own outputs) and rerun: the same weights."""
    torch.set_num_threads(1)
    config = FeedbackTrainConfig(**TINY)
    quiet = {"progress": False, "log": lambda s: None}
    full = train_updater([clean_data], tmp_path / "full", config, **quiet)
    assert full["epochs_done"] == 3 and len(full["val_error_mm_per_iteration"]) == 3
    assert full["history"][1]["pool"] > full["train_frames"] * 2

    def kill_after_second_epoch(line):
        if line.startswith('{"epoch": 2'):
            raise _Killed

    with pytest.raises(_Killed):
        train_updater([clean_data], tmp_path / "cut", config, progress=False,
                      log=kill_after_second_epoch)  # fmt: skip
    lines = []
    resumed = train_updater([clean_data], tmp_path / "cut", config, progress=False,
                            log=lines.append)  # fmt: skip
    assert any("after epoch 2" in line for line in lines)
    a = torch.load(tmp_path / "full" / "last.pt", weights_only=True)
    b = torch.load(tmp_path / "cut" / "last.pt", weights_only=True)
    for key in a["model"]:
        torch.testing.assert_close(a["model"][key], b["model"][key], msg=key)
    torch.testing.assert_close(a["pool_start"], b["pool_start"])
    strip = [{k: v for k, v in e.items() if k != "elapsed_s"} for e in resumed["history"]]
    assert strip == [{k: v for k, v in e.items() if k != "elapsed_s"} for e in full["history"]]
    with pytest.raises(InvalidFeedbackConfig, match="other options .*epochs"):
        train_updater([clean_data], tmp_path / "cut", FeedbackTrainConfig(**{**TINY, "epochs": 4}))
    with pytest.raises(InvalidFeedbackConfig, match="synthesizer must be one of renderer"):
        FeedbackTrainConfig(synthesizer="nerf").check()


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "handsim.cli", *args], capture_output=True, text=True
    )


def test_cli_trains_the_synthesizer_and_the_updater(clean_data, tmp_path):
    """`handsim train synthesizer|updater` run one epoch; the updater uses either synthesizer."""
    common = [
        "--data", str(clean_data), "--epochs", "1", "--max-frames", "8", "--batch-size", "4",
        "--size", "32", "--fc", "8", "--filters", "2", "--threads", "1", "-q",
    ]  # fmt: skip
    out = _cli("train", "synthesizer", "--out", str(tmp_path / "s"), *common)
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert summary["kind"] == "synthesizer" and summary["epochs_done"] == 1
    metrics = json.loads((tmp_path / "s" / "metrics.json").read_text())
    assert {"median_px_error_mm", "mean_px_error_mm"} <= set(metrics["history"][0])
    learned = ["--synthesizer", "learned", "--synthesizer-checkpoint", str(tmp_path / "s")]
    for synth in (["--synthesizer", "renderer"], learned):
        run = tmp_path / synth[1]
        out = _cli("train", "updater", "--out", str(run), "--predictor", "none", *synth, *common)
        assert out.returncode == 0, out.stderr
        summary = json.loads(out.stdout)
        assert summary["kind"] == "updater" and len(summary["val_error_mm_per_iteration"]) == 3
        assert (run / "best.pt").is_file() and (run / "last.pt").is_file()
    out = _cli("train", "deepprior++", "--out", str(tmp_path / "d"), "--lam", "0.5", *common[:2])
    assert out.returncode == 2 and "--lam: not allowed with deepprior++" in out.stderr
    out = _cli("train", "updater", "--out", str(tmp_path / "u2"), "--synthesizer", "learned",
               *common)  # fmt: skip
    assert out.returncode != 0 and "needs synthesizer_checkpoint" in out.stderr


def test_feedback_estimator(clean_data, tmp_path):
    """Updates of an untrained (zero) updater keep DeepPrior++'s estimate; k + 1 poses."""
    from handsim.estimators import DeepPriorEstimator, FeedbackEstimator

    torch.set_num_threads(1)
    config = FeedbackTrainConfig(**{**TINY, "size": 128, "epochs": 1, "lr": 0.0,
                                    "max_frames": 4})  # fmt: skip
    train_updater([clean_data], tmp_path / "u", config, progress=False, log=lambda s: None)
    frames = load_frames(clean_data, max_frames=1)
    # No update gains anything (all zero): validation chose 0 updates as the default.
    assert FeedbackEstimator(tmp_path / "u").iterations == 0
    est = FeedbackEstimator(tmp_path / "u", iterations=2)
    assert "iterations=2" in repr(est)
    center = est.first.localizer.localize(frames.depth(0), frames.K[0])
    poses = est.predict_iterations(frames.depth(0), frames.K[0], center)
    assert len(poses) == 3 and poses[0].shape == (21, 3)
    for p in poses[1:]:
        np.testing.assert_allclose(p, poses[0], atol=1e-6)
    ours = est.predict(frames.depth(0), frames.K[0]).keypoints_cam
    theirs = DeepPriorEstimator().predict(frames.depth(0), frames.K[0]).keypoints_cam
    np.testing.assert_allclose(ours, theirs, atol=1e-5)
    from handsim.estimators.feedback.evaluate import iteration_errors

    report = iteration_errors(est, clean_data, split="all", max_frames=2, iterations=1)
    assert report["frames"] == 2 and len(report["mean_error_mm"]) == 2
    assert report["mean_error_mm"][1] == pytest.approx(report["mean_error_mm"][0], abs=1e-3)
    est.set_side(True)
    assert est.predict(np.zeros((48, 64), np.float32), frames.K[0]).valid is False
    est.close()
    with pytest.raises(
        InvalidCheckpoint, match="holds a 'synthesizer' network; expected a updater"
    ):
        s = FeedbackTrainConfig(kind="synthesizer", epochs=1, size=128, fc=8, filters=2,
                                max_frames=4)  # fmt: skip
        from handsim.estimators.feedback.train import train_synthesizer

        train_synthesizer([clean_data], tmp_path / "s", s, progress=False, log=lambda x: None)
        FeedbackEstimator(tmp_path / "s")


def _random_synthesizer(path):
    """A learned synthesizer of random weights (128 px, 0.25 m), saved as a checkpoint."""
    from handsim.estimators.deepprior.checkpoint import save_checkpoint

    torch.manual_seed(0)
    model_config = {"arch": "synthesizer", "size": 128, "fc": 8, "filters": 2}
    model = build_feedback_model(model_config)
    config = {"model": model_config, "cube_m": CUBE, "kind": "synthesizer"}
    save_checkpoint(path, {"model": model.state_dict()}, config)
    return str(path)


@pytest.mark.parametrize("synthesizer", ["renderer", "learned"])
def test_a_batch_gives_each_frames_own_updates(clean_data, tmp_path, synthesizer):
    """A batch equals the per-frame path (both sides); a frame without a hand is invalid."""
    from handsim.estimators import FeedbackEstimator

    torch.set_num_threads(1)
    ckpt = _random_synthesizer(tmp_path / "s.pt") if synthesizer == "learned" else None
    est = FeedbackEstimator(synthesizer=synthesizer, synthesizer_checkpoint=ckpt, iterations=2)
    frames = load_frames(clean_data, max_frames=3)
    depths = np.stack([frames.depth(i) for i in range(3)] + [np.zeros_like(frames.depth(0))])
    Ks = np.concatenate([frames.K[:3], frames.K[:1]])  # noqa: N806
    for is_left in (False, True):
        est.set_side(is_left)
        batch = est.predict_iterations_batch(depths, Ks)
        assert len(batch) == 4 and batch[3] is None
        for i in range(3):
            one = est.predict_iterations(depths[i], Ks[i])
            assert len(batch[i]) == 3
            for a, b in zip(batch[i], one, strict=True):
                np.testing.assert_allclose(a, b, atol=1e-5)
        # The updates move the pose (the shipped updater is trained), so the check has teeth.
        assert np.abs(batch[0][2] - batch[0][0]).max() > 1e-3
        estimates = est.predict_batch(depths, Ks)
        assert [e.valid for e in estimates] == [True, True, True, False]
        np.testing.assert_allclose(estimates[1].keypoints_cam, batch[1][-1])
    with pytest.raises(InvalidEstimatorInput, match=r"Ks must be \(4, 3, 3\)"):
        est.predict_batch(depths, Ks[:, :2])
    est.close()


def test_importing_the_package_does_not_import_torch():
    """handsim.estimators.feedback and its synthesizer module stay free of torch."""
    code = (
        "import sys, handsim.estimators.feedback, handsim.estimators.feedback.synth; "
        "print('torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
