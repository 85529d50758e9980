"""handsim/PressTwoHands-v0: the env invariants with two hands, its task and its expert."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import handsim.envs
from handsim.envs.config import InvalidEnvConfig
from handsim.envs.press_two_hands import SYNC_S, TARGET_BUTTONS
from handsim.world.scene import HAND_PART_LABELS, OBJECT_LABEL_OFFSET

ENV_ID = "handsim/PressTwoHands-v0"


def _expert_episode(env, seed, hold_left=False):
    base = env.unwrapped
    _, info = env.reset(seed=seed)
    expert = base.make_expert(np.random.default_rng(seed))
    start_left = base.driver.target_of("left").vector.astype(np.float32)
    for _ in range(250):
        action = expert.action(base.expert_state())
        if hold_left:
            action[27:] = start_left
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    return info


def test_registered_apart_from_the_one_hand_ids():
    """The two-hand id is registered, and not among the one-hand ids (27-D actions)."""
    assert ENV_ID in gym.registry and ENV_ID in handsim.envs.TWO_HAND_ENV_IDS
    assert ENV_ID not in handsim.envs.ENV_IDS


@pytest.mark.parametrize("obs_mode", ["state", "depth+segmentation"])
def test_check_env(obs_mode):
    """Gymnasium's checker passes; actions, proprio and targets hold both hands."""
    env = gym.make(ENV_ID, obs_mode=obs_mode)
    check_env(env.unwrapped, skip_render_check=True)
    assert env.action_space.shape == (54,)
    if obs_mode == "state":
        obs, info = env.reset(seed=0)
        assert obs["proprio"].shape == (108,) and info["target_pose"].shape == (54,)
        assert env.unwrapped.sides == ("right", "left")
    env.close()


def test_expert_presses_both_buttons_at_once():
    """Both hands' experts together succeed, every seed tried, with no unintended press."""
    env = gym.make(ENV_ID, obs_mode="state")
    for seed in range(3):
        info = _expert_episode(env, seed)
        assert info["is_success"], seed
        assert info["pressed"][list(TARGET_BUTTONS.values())].all()
        assert info["press_gap_s"] <= SYNC_S and info["unintended_presses"] == 0
    env.close()


def test_one_hand_alone_does_not_succeed():
    """The right hand pressing its button while the left stays back is no success."""
    env = gym.make(ENV_ID, obs_mode="state")
    info = _expert_episode(env, 0, hold_left=True)
    assert not info["is_success"]
    assert info["pressed"][TARGET_BUTTONS["right"]] or info["press_events"] >= 1
    assert not info["pressed"][TARGET_BUTTONS["left"]] and info["press_gap_s"] == -1.0
    env.close()


def test_same_seed_and_reward_sum_and_segmentation_of_both_hands():
    """Bit-identical same-seed rollouts; reward = sum of terms; both hands labelled."""
    runs = []
    for _ in range(2):
        env = gym.make(ENV_ID, obs_mode="depth+segmentation", width=160, height=120)
        obs, _ = env.reset(seed=3)
        env.action_space.seed(3)
        out = [obs]
        for _ in range(3):
            obs, reward, _, _, info = env.step(env.action_space.sample())
            terms = [v for k, v in info.items() if k.startswith("reward_")]
            assert reward == pytest.approx(sum(terms), abs=0, rel=1e-12)
            out.append(obs)
        runs.append(out)
        scene = env.unwrapped.scene
        env.close()
    for a, b in zip(*runs, strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    seg = runs[0][0]["segmentation"]
    assert np.isin(seg, [scene.label(p) for p in ("palm", "index")]).any()
    left = [scene.label(f"left_{p}") for p in HAND_PART_LABELS]
    assert left[0] == OBJECT_LABEL_OFFSET  # no objects: the left hand's labels start at 10
    assert np.isin(seg, left[1:]).any()
    assert seg.max() <= env.observation_space["segmentation"].high.max()


def test_state_round_trip_keeps_both_targets():
    """get_state/set_state restores the observation and both hands' targets."""
    env = gym.make(ENV_ID, obs_mode="state")
    env.reset(seed=2)
    env.action_space.seed(2)
    obs, *_ = env.step(env.action_space.sample())
    state = env.unwrapped.get_state()
    assert state["target"].shape == (54,)
    env.step(env.action_space.sample())
    again = env.unwrapped.set_state(state)
    for key in obs:
        np.testing.assert_array_equal(obs[key], again[key])
    driver = env.unwrapped.driver
    np.testing.assert_array_equal(driver.target_of("left").vector, state["target"][27:])
    env.close()


def test_bad_actions_and_arguments_say_what_is_valid():
    """A 27-D action and a left handedness are refused, naming the two-hand layout."""
    env = gym.make(ENV_ID, obs_mode="state")
    env.reset(seed=0)
    action = env.action_space.sample()
    with pytest.raises(ValueError, match=r"shape \(54,\) \(the right hand's .*then the left"):
        env.step(action[:27])
    with pytest.raises(ValueError, match=r"NaN or Inf values at indices \[30\]"):
        env.step(np.where(np.arange(54) == 30, np.nan, action))
    env.close()
    with pytest.raises(InvalidEnvConfig, match=r"handedness='left': a two-hand env has both"):
        gym.make(ENV_ID, handedness="left")
