"""handsim/Press-v0: the scripted press and slide succeed; buttons, springs and counts behave."""

import gymnasium as gym
import numpy as np
import pytest

import handsim.envs  # noqa: F401
from handsim.envs.config import InvalidEnvConfig
from handsim.envs.press import BUTTON_TRAVEL_M, N_BUTTONS, PRESS_THRESHOLD_M


def _episode(task, seed, expert_target=None):
    env = gym.make("handsim/Press-v0", task=task, obs_mode="state")
    try:
        obs, info = env.reset(seed=seed)
        base = env.unwrapped
        if expert_target is not None:
            base.task_target = expert_target  # the expert aims elsewhere than the task
        expert = base.make_expert()
        if expert_target is not None:
            base.task_target = f"button_{info['target_index']}"
        depths, rewards, infos = [], [], [info]
        while True:
            obs, reward, term, trunc, info = env.step(expert.act(base.expert_state()).vector)
            depths.append(info["button_depth_m"])
            rewards.append((reward, info))
            infos.append(info)
            assert env.observation_space.contains(obs)
            if term or trunc:
                break
        return infos, np.array(depths), rewards
    finally:
        env.close()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scripted_press_succeeds_without_unintended_presses(seed):
    """Scripted press succeeds without unintended presses."""
    infos, depths, rewards = _episode("button", seed)
    last = infos[-1]
    assert last["is_success"] and last["unintended_presses"] == 0
    k = last["target_index"]
    assert depths[:, k].max() >= PRESS_THRESHOLD_M
    assert np.all(depths >= 0) and np.all(depths <= BUTTON_TRAVEL_M + 1e-3)
    others = [j for j in range(N_BUTTONS) if j != k]
    assert depths[:, others].max() < PRESS_THRESHOLD_M
    for reward, info in rewards:
        terms = sum(v for key, v in info.items() if key.startswith("reward_"))
        assert reward == pytest.approx(terms)


@pytest.mark.parametrize("seed", [0, 1])
def test_scripted_slide_succeeds(seed):
    """Scripted slide succeeds."""
    infos, _, _ = _episode("slider", seed)
    last = infos[-1]
    assert last["target_index"] == 3 and last["is_success"]
    assert abs(last["slider_m"] - last["slider_goal_m"]) < 0.01


def test_pressing_another_button_counts_as_unintended():
    """Pressing another button counts as unintended."""
    env = gym.make("handsim/Press-v0", task="button", obs_mode="state")
    _, info = env.reset(seed=0)
    env.close()
    target = info["target_index"]
    wrong = f"button_{(target + 1) % N_BUTTONS}"
    infos, _, _ = _episode("button", 0, expert_target=wrong)
    assert infos[-1]["unintended_presses"] == 1
    assert not infos[-1]["is_success"]


def test_buttons_spring_back_up_and_start_up():
    """Buttons spring back up and start up."""
    env = gym.make("handsim/Press-v0", task="button", obs_mode="state")
    obs, info = env.reset(seed=3)
    assert np.all(info["button_depth_m"] < 1e-4) and not info["pressed"].any()
    base = env.unwrapped
    data = base.scene.data
    data.qpos[base._button_qpos[0]] = -BUTTON_TRAVEL_M
    hold = base.target.vector
    for _ in range(25):
        _, _, _, _, info = env.step(hold)
    assert info["button_depth_m"][0] < 1e-3  # the spring pushed it back up
    env.close()


def test_task_observation_and_random_task_draws_both_kinds():
    """Task observation and random task draws both kinds."""
    env = gym.make("handsim/Press-v0", obs_mode="state")
    targets = set()
    for seed in range(12):
        obs, info = env.reset(seed=seed)
        targets.add(info["target_index"])
        assert obs["task"][:4].sum() == 1.0
    env.close()
    assert 3 in targets and targets & {0, 1, 2}


def test_invalid_task():
    """Invalid task."""
    with pytest.raises(InvalidEnvConfig, match="task='knob' is not valid; choose one of button"):
        gym.make("handsim/Press-v0", task="knob")
