"""EstimatorLoop (estimators inside env steps, feedback) and the closed-loop evaluation."""

import json

import cv2
import gymnasium as gym
import numpy as np
import pytest

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.cli import main
from handsim.envs.closed_loop import evaluate_closed_loop, write_report
from handsim.envs.config import InvalidEnvConfig
from handsim.envs.wrappers import EstimatorLoop
from handsim.estimators import CenterOfMassLocalizer, OracleEstimator
from handsim.viz import SCALE_BAR_WIDTH


def _loop(estimator, feedback=False, **kwargs):
    env = EstimatorLoop(gym.make("handsim/HandPose-v0", **kwargs), estimator, feedback=feedback)
    return env


def test_exact_oracle_has_zero_error_and_counts_frames():
    """A noise-free oracle reproduces the truth; running statistics count every frame."""
    env = _loop(OracleEstimator(rng=0))
    _, info = env.reset(seed=0)
    for _ in range(3):
        _, _, _, _, info = env.step(env.action_space.sample())
    np.testing.assert_allclose(info["estimate"].keypoints_cam, info["frame"].keypoints_cam)
    assert info["estimate_errors"]["kp_mean_mm"] == pytest.approx(0.0, abs=1e-9)
    assert info["estimator_stats"]["n_frames"] == 4 and info["estimator_stats"]["n_valid"] == 4
    assert info["estimator_time_s"] >= 0
    env.close()


def test_loop_needs_depth_and_an_estimator():
    """A state-only env or an object without the protocol is refused with the fix."""
    with pytest.raises(InvalidEnvConfig, match="needs depth observations.*use 'depth'"):
        _loop(OracleEstimator(rng=0), obs_mode="state")
    with pytest.raises(InvalidEnvConfig, match="object is not an Estimator: it needs predict"):
        _loop(object())


def test_feedback_hands_the_estimate_to_the_expert():
    """With feedback the expert's keypoints are the estimate's (here: biased by 20 mm)."""
    bias = OracleEstimator(bias_mm=(20.0, 0.0, 0.0), rng=0)
    for feedback, expected_mm in ((False, 0.0), (True, 20.0)):
        env = _loop(bias, feedback=feedback)
        env.reset(seed=1)
        env.step(env.action_space.sample())
        state = env.expert_state()
        truth = env.unwrapped.expert_state()
        offset_mm = 1000 * np.linalg.norm(state.keypoints_world - truth.keypoints_world, axis=1)
        np.testing.assert_allclose(offset_mm, expected_mm, atol=1e-6)
        env.close()


def test_dropout_gives_nan_errors_and_the_truth_before_any_estimate():
    """Invalid estimates have NaN errors; without any valid estimate the expert sees the truth."""
    env = _loop(OracleEstimator(dropout=1.0, rng=0), feedback=True)
    _, info = env.reset(seed=0)
    assert not info["estimate"].valid and np.isnan(info["estimate_errors"]["kp_mean_mm"])
    state = env.expert_state()
    np.testing.assert_array_equal(
        state.keypoints_world, env.unwrapped.expert_state().keypoints_world
    )
    env.close()


def test_localizer_in_the_loop_reports_a_centre_error():
    """The centre-of-mass localizer gives a finite centre error and no keypoint error."""
    env = _loop(CenterOfMassLocalizer())
    _, info = env.reset(seed=0)
    errors = info["estimate_errors"]
    assert np.isnan(errors["kp_mean_mm"]) and 0 <= errors["center_mm"] < 100
    env.close()


def test_feedback_changes_the_rollout():
    """A biased estimate moves the hand when the expert acts on it, not when it only watches."""
    finals = {}
    for feedback in (False, True):
        env = _loop(OracleEstimator(bias_mm=(30.0, 0.0, 0.0), rng=0), feedback=feedback)
        env.reset(seed=2)
        expert = env.make_expert(np.random.default_rng(0))
        for _ in range(60):
            env.step(expert.act(env.expert_state()).vector)
        finals[feedback] = env.unwrapped.expert_state().hand_pose.wrist_pos
        env.close()
    assert np.linalg.norm(finals[True] - finals[False]) > 0.005


def test_closed_loop_report_and_plots(tmp_path):
    """evaluate_closed_loop reports both modes; write_report writes JSON and two PNGs."""
    steps = []
    report = evaluate_closed_loop(
        "handsim/HandPose-v0",
        lambda: OracleEstimator(noise_mm=5.0, rng=0),
        episodes=1,
        env_kwargs={"obs_mode": "depth"},
        progress=steps.append,
        media_dir=tmp_path / "media",
    )
    off, on = report["modes"]["feedback_off"], report["modes"]["feedback_on"]
    for mode in (off, on):
        assert mode["n_frames"] == 151 and 0 <= mode["success_rate"] <= 1
        assert 3 < mode["kp_mean_mm"] < 12  # 5 mm per axis: about 8 mm in 3D
        assert sum(b["n_frames"] for b in mode["by_occlusion"]) == mode["n_frames"]
        (episode,) = mode["episodes"]
        assert len(episode["kp_mean_mm"]) == 151 and episode["object"] is None
        assert np.mean(episode["kp_mean_mm"]) == pytest.approx(mode["kp_mean_mm"])
        worst = mode["media"]["worst_frame"]
        assert worst["kp_max_mm"] >= max(episode["kp_mean_mm"])  # a frame's max >= its mean
        assert cv2.imread(worst["path"]).shape == (480, 640 + SCALE_BAR_WIDTH, 3)  # at 2x
        assert mode["media"]["videos"] == []
    # Progress adds up to modes x episodes x max_episode_steps (150).
    assert sum(steps) == 2 * 150
    assert report["estimator"]["repr"].startswith("OracleEstimator(noise_mm=5.0")
    paths = write_report(report, tmp_path)
    assert json.loads(paths["json"].read_text())["env_id"] == "handsim/HandPose-v0"
    assert paths["f_tau"].stat().st_size > 0 and paths["success"].stat().st_size > 0
    assert paths["error_over_time"].stat().st_size > 0
    with pytest.raises(ValueError, match="episodes must be an int >= 1; received 0"):
        evaluate_closed_loop("handsim/HandPose-v0", OracleEstimator, episodes=0)
    with pytest.raises(ValueError, match="video=True needs a media_dir"):
        evaluate_closed_loop("handsim/HandPose-v0", OracleEstimator, video=True)


def test_closed_loop_cli(tmp_path, capsys):
    """`handsim closed-loop` writes its report and prints success per mode."""
    status = main(
        [
            "closed-loop",
            "--env",
            "handsim/HandPose-v0",
            "--episodes",
            "1",
            "--sensor",
            "none",
            "--out",
            str(tmp_path),
        ]
    )
    assert status == 0
    assert "feedback_on" in capsys.readouterr().out
    assert (tmp_path / "closed_loop.json").exists() and (tmp_path / "success.png").exists()


def test_loop_tells_an_estimator_with_set_side_the_hand_it_sees():
    """At every reset an estimator's optional set_side gets the episode's side."""

    class SideAware(CenterOfMassLocalizer):
        sides: list = []

        def set_side(self, is_left):
            self.sides.append(is_left)

    est = SideAware()
    for side in ("left", "right"):
        env = _loop(est, handedness=side)
        env.reset(seed=0)
        env.close()
    assert est.sides == [True, False]
