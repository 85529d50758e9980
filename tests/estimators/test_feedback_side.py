"""The feedback loop's side-canonical frame: training crops, the synthesizer, the estimator."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from handsim.data.generation import GenerationConfig, generate
from handsim.estimators.deepprior.checkpoint import InvalidCheckpoint, save_checkpoint
from handsim.estimators.deepprior.data import load_frames
from handsim.estimators.deepprior.preprocess import (
    MIDDLE_MCP,
    mirror_depth,
    mirror_intrinsics,
    mirror_points,
)
from handsim.estimators.feedback.models import build_feedback_model
from handsim.estimators.feedback.synth import RendererSynthesizer
from handsim.estimators.feedback.train import FeedbackTrainConfig, _images


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """12 clean hand-only frames, one per episode, both sides."""
    out = tmp_path_factory.mktemp("side")
    config = GenerationConfig(
        frames=12, frames_per_shard=12, frames_per_episode=1, seed=7,
        num_objects_range=(0, 0), viewpoints=("third_person",), sensor="none",
        hand_length_range_m=(0.18, 0.18),
    )  # fmt: skip
    generate(config, out)
    return out


def _updater(path, canonical_side=True):
    """An updater checkpoint with random (non-zero) weights: its updates are not zero."""
    torch.manual_seed(0)
    model_config = {"arch": "updater", "size": 128, "fc": 16, "filters": 2}
    model = build_feedback_model(model_config)
    with torch.no_grad():
        model.head[-1].weight.normal_(0, 0.05)
    config = {"model": model_config, "cube_m": 0.25, "kind": "updater", "iterations": 2,
              "synthesizer": "renderer", "canonical_side": canonical_side}  # fmt: skip
    save_checkpoint(path, {"model": model.state_dict()}, config)
    return path


def test_training_crops_are_right_hands_the_renderer_draws(data):
    """Canonical training images: left frames mirrored, drawn as right hands at the truth."""
    frames = load_frames(data, canonical_side=True)
    assert frames.is_left.any() and not frames.is_left.all()
    centers = frames.keypoints_cam[:, MIDDLE_MCP]
    images = _images(frames, centers, FeedbackTrainConfig())
    assert not images.left.any()  # every hand is drawn as a right hand
    assert np.isnan(images.lengths).all()  # the size is fitted, as at inference
    with RendererSynthesizer() as synth:
        for i in np.flatnonzero(frames.is_left)[:3]:
            crops, _ = synth(images.truth[i : i + 1], centers[i : i + 1], images.K[i],
                             frames.hand_length_m[i], images.left[i : i + 1])  # fmt: skip
            hand = crops[0] < 1.0
            diff_mm = np.abs(crops[0] - images.crops[i])[hand] * 0.25 / 2 * 1000
            assert hand.sum() > 500
            assert np.median(diff_mm) < 2.0, i
            # A left hand drawn there does not match: the side matters.
            wrong, _ = synth(images.truth[i : i + 1], centers[i : i + 1], images.K[i],
                             frames.hand_length_m[i], np.array([True]))  # fmt: skip
            both = (wrong[0] < 1.0) | hand
            assert np.median(np.abs(wrong[0] - images.crops[i])[both]) * 125 > 2 * np.median(
                diff_mm
            )


def test_a_left_frame_and_its_mirror_give_mirrored_updates(data, tmp_path):
    """A left frame, and its mirror image seen as a right hand: every update mirrored."""
    from handsim.estimators import FeedbackEstimator

    torch.set_num_threads(1)
    frames = load_frames(data)
    est = FeedbackEstimator(_updater(tmp_path / "u.pt"), iterations=2)
    assert est.canonical_side
    i = int(np.flatnonzero(frames.is_left)[0])
    depth, K = frames.depth(i), frames.K[i]  # noqa: N806
    est.set_side(True)
    left = est.predict_iterations(depth, K)
    est.set_side(False)
    right = est.predict_iterations(mirror_depth(depth), mirror_intrinsics(K, depth.shape[1]))
    assert len(left) == 3
    assert np.abs(left[2] - left[0]).max() > 1e-3  # the updates move the pose
    for a, b in zip(left, right, strict=True):
        np.testing.assert_allclose(a, mirror_points(b), atol=1e-5)
    # The updates bring the pose back in the frame as seen: near the left hand, not its mirror.
    truth = frames.keypoints_cam[i]
    assert (
        np.linalg.norm(left[0] - truth, axis=1).mean()
        < np.linalg.norm(mirror_points(left[0]) - truth, axis=1).mean()
    )
    est.close()


def test_an_updater_of_another_frame_than_the_predictor_is_refused(tmp_path):
    """A non-canonical updater behind the canonical DeepPrior++ says what to do."""
    from handsim.estimators import FeedbackEstimator

    with pytest.raises(InvalidCheckpoint, match="canonical_side=False, the predictor"):
        FeedbackEstimator(_updater(tmp_path / "u.pt", canonical_side=False))


def test_evaluate_command_reports_each_update_per_set(tmp_path):
    """`python -m handsim.estimators.feedback.evaluate` on a tiny benchmark: per set, per bucket."""
    bench = tmp_path / "bench"
    made = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "benchmark", "make", "--out", str(bench),
         "--frames-per-set", "2", "-q"], capture_output=True, text=True,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    out = tmp_path / "it.json"
    cmd = [sys.executable, "-m", "handsim.estimators.feedback.evaluate", "--updater",
           str(_updater(tmp_path / "u.pt")), "--bench", str(bench), "--iterations", "1",
           "--sets", "hand_third_person", "hand_object", "--out", str(out)]  # fmt: skip
    run = subprocess.run(cmd, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    report = json.loads(out.read_text())
    assert set(report["sets"]) == {"hand_third_person", "hand_object"}
    for s in report["sets"].values():
        assert s["frames"] == 2
        assert len(s["mean_error_mm"]) == (2 if s["missed"] < 2 else 0)
    assert report["iterations"] == 1 and len(report["by_occlusion"]) == 5
    assert sum(b["frames"] for b in report["by_occlusion"]) == 4
    assert "hand_object" in run.stdout and "frames/s" in run.stdout
    bad = subprocess.run([*cmd[:-5], "--sets", "nope", "--out", str(out)],
                         capture_output=True, text=True)  # fmt: skip
    assert bad.returncode == 2 and "has no set nope" in bad.stderr
    # The shipped feedback estimator by name in `handsim benchmark run`.
    run = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "benchmark", "run", "--estimator", "feedback",
         "--bench", str(bench), "--episodes", "0", "--out", str(tmp_path / "r"), "-q"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    result = json.loads((tmp_path / "r" / "benchmark.json").read_text())
    assert result["estimator"]["spec"] == "feedback"
    assert result["offline"]["all"]["n_frames"] == 12


def test_the_updaters_layers_keep_their_weights_while_its_last_layer_is_zero():
    """No gradient reaches the layers below the zero last layer: weight decay must not eat them.

    (Adam's L2 decay, scaled up by Adam to full steps, took them to zero within an epoch.)
    """
    from handsim.estimators.feedback.train import updater_optimizer

    torch.manual_seed(0)
    model = build_feedback_model({"arch": "updater", "size": 32, "fc": 8, "filters": 2})
    before = model.path[2].weight.detach().clone()
    optimizer = updater_optimizer(model, FeedbackTrainConfig(lr=1e-3, weight_decay=1e-4))
    d = torch.rand(4, 1, 32, 32)
    for _ in range(200):
        loss = model(d, d).square().sum()  # zero output: zero gradient everywhere
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    after = model.path[2].weight.detach()
    assert float((after - before).abs().max()) < 1e-3 * float(before.abs().mean())
    old = torch.optim.Adam(model.parameters(), lr=1e-3, weight_decay=1e-4)
    for _ in range(200):
        loss = model(d, d).square().sum()
        old.zero_grad()
        loss.backward()
        old.step()
    # The control: Adam with L2 decay shrinks them.
    assert float(model.path[2].weight.detach().abs().mean()) < 0.5 * float(before.abs().mean())


def test_the_shipped_updater_fits_its_budget_and_the_predictors_frame():
    """float16, at most 4 MB, side-canonical as DeepPrior++; `feedback` loads it."""
    from handsim.estimators import FeedbackEstimator
    from handsim.estimators.feedback.checkpoint import SHIPPED_UPDATER

    assert SHIPPED_UPDATER.stat().st_size <= 4 * 1024 * 1024
    state = torch.load(SHIPPED_UPDATER, weights_only=True)
    assert all(v.dtype == torch.float16 for v in state["model"].values())
    est = FeedbackEstimator()  # the shipped updater
    assert (
        est.canonical_side
        and est.iterations
        == json.loads(SHIPPED_UPDATER.with_suffix(".json").read_text())["iterations"]
    )
    est.close()


def test_the_pool_without_the_truth_keeps_its_perturbations(data, tmp_path):
    """truth_starts=False drops the truth's block of the pool and nothing else."""
    from handsim.estimators.feedback.train import train_updater

    torch.set_num_threads(1)
    tiny = dict(kind="updater", epochs=1, batch_size=8, size=32, fc=8, filters=2,
                predictor=None, max_frames=8, seed=1, localizer=None)  # fmt: skip
    quiet = {"progress": False, "log": lambda s: None}
    runs = {}
    for truth in (True, False):
        config = FeedbackTrainConfig(**tiny, truth_starts=truth)
        metrics = train_updater([data], tmp_path / str(truth), config, **quiet)
        runs[truth] = torch.load(tmp_path / str(truth) / "last.pt", weights_only=True)
        assert metrics["starts"] == (["truth"] if truth else [])
    n = 8
    assert len(runs[True]["pool_start"]) == 2 * n and len(runs[False]["pool_start"]) == n
    torch.testing.assert_close(runs[False]["pool_start"], runs[True]["pool_start"][n:])


def test_cli_updater_options_of_the_side_canonical_recipe(data, tmp_path):
    """`handsim train updater` takes --no-truth-starts, --localizer none, --max-val-frames."""
    common = ["--data", str(data), "--epochs", "1", "--max-frames", "8", "--batch-size", "4",
              "--size", "32", "--fc", "8", "--threads", "1", "-q"]  # fmt: skip
    out = tmp_path / "u"
    run = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "train", "updater", "--out", str(out), *common,
         "--filters", "2", "--predictor", "none", "--localizer", "none", "--no-truth-starts",
         "--max-val-frames", "2"], capture_output=True, text=True,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    config = json.loads((out / "run.json").read_text())["config"]
    assert config["truth_starts"] is False and config["localizer"] is None
    assert config["max_val_frames"] == 2 and config["canonical_side"] is True
    assert json.loads(run.stdout)["val_frames"] == 2
    bad = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "train", "deepprior++", "--out", str(tmp_path / "d"),
         *common[:2], "--no-truth-starts"], capture_output=True, text=True,
    )  # fmt: skip
    assert bad.returncode == 2 and "--no-truth-starts: not allowed with deepprior++" in bad.stderr


def test_the_recipe_script_trains_the_learned_synthesizer_and_its_updater(data, tmp_path):
    """`SYNTH=learned benchmarks/train_feedback.sh`: synthesizer, then the updater with it."""
    from pathlib import Path

    script = Path(__file__).resolve().parents[2] / "benchmarks" / "train_feedback.sh"
    out = tmp_path / "run"
    (out / "data").mkdir(parents=True)
    (out / "data" / "third").symlink_to(data)
    env = {
        **os.environ, "MUJOCO_GL": "egl", "PYTHON": sys.executable,
        "HANDSIM": f"{sys.executable} -m handsim.cli", "SYNTH": "learned",
        "STAGES": "synthesizer updater", "OBJECT_FRAMES": "0", "EPOCHS": "1", "FILTERS": "2",
        "FC": "8", "SYNTH_FC": "8", "SYNTH_EPOCHS": "1", "SYNTH_FRAMES": "8", "BATCH": "4",
        "VAL_FRAMES": "2", "ITERATIONS": "1",
    }  # fmt: skip
    run = subprocess.run(["bash", str(script), str(out)], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert (out / "synthesizer" / "best.pt").is_file()
    config = json.loads((out / "updater_learned" / "run.json").read_text())["config"]
    assert config["synthesizer"] == "learned"
    assert config["synthesizer_checkpoint"] == str(out / "synthesizer")
    assert config["truth_starts"] is False and config["epochs"] == 1
    assert (out / "updater_learned" / "best.pt").is_file()
    bad = subprocess.run(["bash", str(script), str(out)], env={**env, "SYNTH": "gan"},
                         capture_output=True, text=True)  # fmt: skip
    assert bad.returncode == 2 and "SYNTH must be renderer or learned; received 'gan'" in bad.stderr


def test_the_updaters_crops_are_centred_as_its_predictors(data, tmp_path):
    """The updater trains where the pipeline crops: at its predictor's recorded centres."""
    from handsim.estimators.deepprior.models import build_model
    from handsim.estimators.deepprior.preprocess import PlaneRemovedLocalizer
    from handsim.estimators.deepprior.train import localizer_centers
    from handsim.estimators.feedback.train import _updater_centers

    frames = load_frames(data, canonical_side=True)
    model_config = {"arch": "deep", "size": 128, "fc": 16, "prior_dim": 4}
    state = {"model": build_model(model_config).state_dict()}
    base = {"model": model_config, "cube_m": 0.25, "kind": "deepprior", "canonical_side": True}
    crop = {"detector": "plane", "localizer": "localizer", "refine_iterations": 0}
    save_checkpoint(tmp_path / "unrefined.pt", state, {**base, "crop": crop})
    save_checkpoint(tmp_path / "before.pt", state, base)  # trained before the record
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    config = FeedbackTrainConfig(predictor=str(tmp_path / "unrefined.pt"))
    unrefined = _updater_centers(frames, config, tmp_path / "a", "train", 1)
    plane = PlaneRemovedLocalizer()
    for i in range(len(frames)):
        found = plane.localize(frames.depth(i), frames.K[i])
        expected = frames.keypoints_cam[i, MIDDLE_MCP] if found is None else found
        np.testing.assert_allclose(unrefined[i], expected)
    config = FeedbackTrainConfig(predictor=str(tmp_path / "before.pt"))
    refined = _updater_centers(frames, config, tmp_path / "b", "train", 1)
    np.testing.assert_allclose(refined, localizer_centers(frames, "localizer")[0])
    assert not np.allclose(refined, unrefined)
