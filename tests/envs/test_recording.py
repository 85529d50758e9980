"""Expert rollouts recorded with Minari itself, loaded back with ``minari.load_dataset``."""

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

from handsim.data.arrays import LABEL_SCHEMA
from handsim.envs.recording import default_dataset_id, record_minari
from handsim.errors import HandSimError

minari = pytest.importorskip("minari")
pytest.importorskip("jax")  # Minari's DataCollector


def test_default_dataset_id_follows_minari_naming():
    """Env ids map to Minari's namespace/name-vN ids; other ids are refused."""
    assert default_dataset_id("handsim/GraspClutter-v0") == "handsim/grasp-clutter-expert-v0"
    with pytest.raises(HandSimError, match="registered handsim id such as 'handsim/Grasp-v0'"):
        default_dataset_id("CartPole-v1")


def test_grasp_rollouts_load_back_with_labels_in_infos(tmp_path, monkeypatch):
    """Observations, actions, rewards and every label array of every step survive the trip.

    The reward is the sum of the recorded reward terms.
    """
    result = record_minari(
        "handsim/Grasp-v0",
        episodes=2,
        out_dir=tmp_path,
        env_kwargs={"objects": ("tomato_soup_can",)},
        max_episode_steps=12,
    )
    assert result["episodes"] == 2 and result["steps"] == 24
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    dataset = minari.load_dataset(result["dataset_id"])
    assert dataset.total_episodes == 2
    for episode in dataset.iterate_episodes():
        n = len(episode.actions)
        assert n == 12 and episode.observations["depth"].shape == (n + 1, 240, 320)
        labels = episode.infos["labels"]
        assert set(labels) == set(LABEL_SCHEMA)
        for key, (shape, dtype, _) in LABEL_SCHEMA.items():
            assert labels[key].shape == (n + 1, *shape) and labels[key].dtype == dtype, key
        assert labels["valid"].all()
        terms = [k for k in episode.infos if k.startswith("reward_")]
        total = sum(episode.infos[k][1:] for k in terms)
        np.testing.assert_allclose(episode.rewards, total)
    with pytest.raises(HandSimError, match="already exists"):
        record_minari("handsim/Grasp-v0", episodes=1, out_dir=tmp_path)


def test_cli_export_minari_refuses_a_folder_and_records_an_env(tmp_path):
    """A folder is a one-line usage error (exit 2); an env id records and prints strict JSON.

    The output folder is given relative to the working directory, as a user types it.
    """
    cmd = [sys.executable, "-m", "handsim.cli.main", "export", "minari"]
    bad = subprocess.run([*cmd, str(tmp_path), str(tmp_path / "m")], capture_output=True, text=True)
    assert bad.returncode == 2 and "SOURCE must be one of handsim/Grasp-v0" in bad.stderr
    evil = subprocess.run(
        [*cmd, "handsim/HandPose-v0", "m", "--dataset-id", "../../evil"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert evil.returncode == 2 and "Traceback" not in evil.stderr
    assert "dataset_id must be a Minari id 'namespace/name-vN'" in evil.stderr
    assert "received '../../evil'" in evil.stderr and not (tmp_path / "m").exists()
    ok = subprocess.run(
        [*cmd, "handsim/HandPose-v0", "m", "--episodes", "1"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert ok.returncode == 0, ok.stderr
    report = json.loads(ok.stdout)
    assert report["dataset_id"] == "handsim/hand-pose-expert-v0" and report["episodes"] == 1
    assert report["path"] == str(tmp_path / "m" / "handsim" / "hand-pose-expert-v0")


def test_data_collector_sees_every_expert_action_in_the_action_space(tmp_path, monkeypatch):
    """Minari's DataCollector warns about no action or observation of the expert's episode."""
    import gymnasium as gym
    from minari import DataCollector

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    env = DataCollector(gym.make("handsim/HandPose-v0", max_episode_steps=20))
    env.reset(seed=0)
    expert = env.get_wrapper_attr("make_expert")()
    expert_state = env.get_wrapper_attr("expert_state")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(expert.action(expert_state()))
            done = terminated or truncated
    env.close()
    assert [str(w.message) for w in caught if "not in" in str(w.message)] == []
