"""The bone-length term of `handsim train` (``--bone-loss``): its value, pairs, run and refusals."""

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from handsim.estimators.deepprior.train import (
    BONE_PAIRS,
    InvalidTrainConfig,
    TrainConfig,
    bone_length_error,
    train,
)
from handsim.hand.keypoints import KEYPOINT_NAMES

TINY = dict(
    kind="deepprior++", epochs=1, batch_size=8, size=32, fc=16, width=0.125, prior_dim=4,
    max_frames=16, seed=3,
)  # fmt: skip


def _pairs():
    a, b = zip(*BONE_PAIRS, strict=True)
    return torch.tensor(a), torch.tensor(b)


def test_bone_pairs_are_the_skeleton_tree_and_the_palm_links():
    """20 bones (each keypoint with its parent), then the palm's four transverse links."""
    bones, palm = BONE_PAIRS[:20], BONE_PAIRS[20:]
    assert sorted(child for _, child in bones) == list(range(1, 21))  # every keypoint once
    from_wrist = sorted(KEYPOINT_NAMES[c] for p, c in bones if p == 0)
    assert from_wrist == ["index_mcp", "little_mcp", "middle_mcp", "ring_mcp", "thumb_cmc"]
    assert all(p == c - 1 for p, c in bones if p != 0)  # along each finger
    assert [(KEYPOINT_NAMES[a], KEYPOINT_NAMES[b]) for a, b in palm] == [
        ("index_mcp", "middle_mcp"), ("middle_mcp", "ring_mcp"), ("ring_mcp", "little_mcp"),
        ("index_mcp", "little_mcp"),
    ]  # fmt: skip


def test_bone_length_error_is_zero_for_the_truth_and_rigid_motions():
    """Lengths do not see where the hand is or how it is turned."""
    rng = np.random.default_rng(0)
    truth = torch.tensor(rng.normal(size=(4, 21, 3)) * 0.2)
    a, b = _pairs()
    assert bone_length_error(truth.reshape(4, 63), truth.reshape(4, 63), a, b) == 0.0
    rot = torch.tensor(
        [[np.cos(0.7), -np.sin(0.7), 0.0], [np.sin(0.7), np.cos(0.7), 0.0], [0.0, 0.0, 1.0]]
    )
    moved = truth @ rot.T + torch.tensor([0.1, -0.2, 0.3], dtype=truth.dtype)
    error = bone_length_error(moved.reshape(4, 63), truth.reshape(4, 63), a, b)
    assert error == pytest.approx(0.0, abs=1e-12)


def test_bone_length_error_of_a_scaled_hand_is_the_mean_bone_length_times_the_scale():
    """Analytic: a prediction twice the truth's size misses every length by that length."""
    rng = np.random.default_rng(1)
    truth = torch.tensor(rng.normal(size=(3, 21, 3)))
    a, b = _pairs()
    lengths = (truth[:, a] - truth[:, b]).norm(dim=-1)
    error = bone_length_error(2.0 * truth.reshape(3, 63), truth.reshape(3, 63), a, b)
    assert error.item() == pytest.approx(lengths.mean().item(), rel=1e-12)


def test_a_run_with_the_bone_term_records_it_and_differs_from_one_without(tiny_data, tmp_path):
    """The weight reaches the loss and the run's records."""
    plain = train([tiny_data], tmp_path / "plain", TrainConfig(**TINY), progress=False)
    boned = train(
        [tiny_data], tmp_path / "bone", TrainConfig(**TINY, bone_loss=0.5), progress=False
    )
    assert boned["config"]["bone_loss"] == 0.5 and plain["config"]["bone_loss"] == 0.0
    assert plain["history"][0]["train_loss"] != boned["history"][0]["train_loss"]
    assert json.loads((tmp_path / "bone" / "run.json").read_text())["config"]["bone_loss"] == 0.5


def test_bone_loss_out_of_range_or_for_the_localizer_is_refused(tmp_path):
    """The Python surface refuses before any work, with what is valid."""
    with pytest.raises(InvalidTrainConfig, match=r"bone_loss must be in \[0, 100\]; received -1"):
        train([tmp_path], tmp_path / "r", TrainConfig(**TINY, bone_loss=-1.0), progress=False)
    localizer = {**TINY, "kind": "localizer", "bone_loss": 1.0}
    with pytest.raises(InvalidTrainConfig, match="bone_loss is for the pose networks"):
        train([tmp_path], tmp_path / "r", TrainConfig(**localizer), progress=False)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("kind", ["localizer", "detector", "updater"])
def test_cli_bone_loss_is_one_error_line_for_networks_without_bones(kind, tmp_path):
    """`handsim train KIND --bone-loss` as a user runs it, for the networks without bones."""
    cmd = [sys.executable, "-m", "handsim.cli", "train", kind, "--data", str(tmp_path),
           "--out", str(tmp_path / "r"), "--bone-loss", "0.1"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "argument --bone-loss: not allowed with" in done.stderr
    assert not (tmp_path / "r").exists()
