"""Invariants over every registered env id (STYLE rule 21) and the shared control rules."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import handsim.envs
from handsim.data.arrays import LABEL_SCHEMA, empty_label_arrays
from handsim.envs.config import OBS_MODES, WORKSPACE_M, InvalidEnvConfig
from handsim.envs.hand_pose import HandPoseEnv
from handsim.hand.pose import JOINT_LIMITS
from handsim.hand.pose_sources import MAX_WRIST_SPEED

ENV_IDS = handsim.envs.ENV_IDS
# Small, quick defaults for every id (clutter needs several objects).
FAST = {"handsim/GraspClutter-v0": {"num_objects": (3, 3)}}


def _make(env_id, **kwargs):
    return gym.make(env_id, **{**FAST.get(env_id, {}), **kwargs})


def _rollout(env_id, seed, steps=8, **kwargs):
    env = _make(env_id, **kwargs)
    obs, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [(obs, None, info["labels"])]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        out.append((obs, reward, info["labels"]))
    env.close()
    return out


def _same_labels(a, b):
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)


def test_every_id_is_registered():
    """Importing handsim.envs registers every id of ENV_IDS."""
    for env_id in ENV_IDS:
        assert env_id in gym.registry


@pytest.mark.parametrize("obs_mode", OBS_MODES)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env(env_id, obs_mode):
    """Gymnasium's env checker passes for every id and observation mode."""
    env = _make(env_id, obs_mode=obs_mode)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_gives_identical_rollouts(env_id):
    """Two rollouts with the same seed (noisy sensor included) are bit-identical."""
    a = _rollout(env_id, 3, sensor="structured_light", obs_mode="depth+segmentation")
    b = _rollout(env_id, 3, sensor="structured_light", obs_mode="depth+segmentation")
    for (obs_a, reward_a, frame_a), (obs_b, reward_b, frame_b) in zip(a, b, strict=True):
        for key in obs_a:
            np.testing.assert_array_equal(obs_a[key], obs_b[key])
        assert reward_a == reward_b
        assert _same_labels(frame_a, frame_b)
    c = _rollout(env_id, 4, steps=0, sensor="structured_light")
    assert not np.array_equal(a[0][0]["depth"], c[0][0]["depth"])


@pytest.mark.parametrize("reward_type", ["dense", "sparse"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reward_is_the_sum_of_its_info_terms(env_id, reward_type):
    """Reward == sum(info["reward_*"]) at every step."""
    env = _make(env_id, reward_type=reward_type)
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(5):
        _, reward, _, _, info = env.step(env.action_space.sample())
        terms = [v for k, v in info.items() if k.startswith("reward_")]
        assert terms and reward == pytest.approx(sum(terms), abs=0, rel=1e-12)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_observations_do_not_share_memory_and_labels_stay_out(env_id):
    """Consecutive observations are separate arrays; labels are in info, not in obs."""
    env = _make(env_id, obs_mode="depth+segmentation")
    obs0, info = env.reset(seed=1)
    obs1, *_ = env.step(env.action_space.sample())
    for key in obs0:
        assert not np.shares_memory(obs0[key], obs1[key])
    assert "labels" not in obs0 and info["labels"]["keypoints_cam"].shape == (21, 3)
    assert not {"depth", "segmentation"} & info["labels"].keys()  # no images in the labels
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_state_round_trip_reproduces_the_observation(env_id):
    """get_state then set_state gives back the observation of that state."""
    env = _make(env_id, obs_mode="depth+state")
    env.reset(seed=2)
    env.action_space.seed(2)
    obs, *_ = env.step(env.action_space.sample())
    state = env.unwrapped.get_state()
    env.step(env.action_space.sample())
    again = env.unwrapped.set_state(state)
    for key in obs:
        np.testing.assert_array_equal(obs[key], again[key])
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_bad_actions(env_id):
    """NaN/Inf and wrong shapes raise ValueError; out-of-bound actions are clipped."""
    env = _make(env_id)
    env.reset(seed=0)
    action = env.action_space.sample()
    with pytest.raises(ValueError, match="NaN or Inf values at indices \\[4\\]"):
        env.step(np.where(np.arange(27) == 4, np.nan, action))
    with pytest.raises(ValueError, match="must have shape \\(27,\\).*received shape \\(26,\\)"):
        env.step(action[:26])
    _, _, _, _, info = env.step(np.full(27, 100.0))
    target = info["target_pose"]
    assert target[2] == WORKSPACE_M[2][1]
    assert np.all(target[6:] == [hi for _, hi in JOINT_LIMITS])
    env.close()


def test_delta_control_moves_the_target_at_the_documented_speed():
    """A unit delta moves the wrist target by MAX_WRIST_SPEED * control_dt; zero keeps it."""
    env = gym.make("handsim/HandPose-v0", control_mode="delta")
    _, info = env.reset(seed=0)
    start = info["target_pose"]
    _, _, _, _, info = env.step(np.zeros(27))
    np.testing.assert_allclose(info["target_pose"], start, atol=1e-12)
    action = np.zeros(27)
    action[0] = 1.0
    _, _, _, _, info = env.step(action)
    dt = env.unwrapped.control_dt
    assert info["target_pose"][0] - start[0] == pytest.approx(MAX_WRIST_SPEED * dt)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_physics_divergence_truncates_with_a_flag(env_id):
    """A non-finite state truncates the episode; the observation stays finite."""
    env = _make(env_id, obs_mode="depth+state")
    env.reset(seed=0)
    env.unwrapped.scene.data.qvel[:] = 1e30
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert truncated and not terminated and info["physics_diverged"]
    assert all(np.all(np.isfinite(v)) for v in obs.values())
    env.close()


def _structure(info):
    """Keys and value types of an info, nested (what Minari's DataCollector requires equal)."""
    return {
        k: _structure(v) if isinstance(v, dict) else (type(v), getattr(v, "shape", None),
                                                      getattr(v, "dtype", None))
        for k, v in info.items()
    }  # fmt: skip


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("reward_type", ["dense", "sparse"])
def test_info_has_one_structure_at_reset_step_and_divergence(env_id, reward_type):
    """One info structure at reset, every step and a diverged step.

    Same keys, types, shapes and dtypes; the labels follow LABEL_SCHEMA and are never NaN-filled
    (Gymnasium's and Minari's checks compare them).
    """
    env = _make(env_id, reward_type=reward_type)
    _, info = env.reset(seed=0)
    reference = _structure(info)
    assert set(info["labels"]) == set(LABEL_SCHEMA) and bool(info["labels"]["valid"])
    terms = [k for k in info if k.startswith("reward_")]
    assert terms and all(info[k] == 0.0 for k in terms)
    _, reward, *_, info = env.step(env.action_space.sample())
    assert _structure(info) == reference
    assert reward == pytest.approx(sum(info[k] for k in terms))
    labels = info["labels"]
    assert not np.isnan(labels["object_T_cam_from_obj"]).any()
    assert not np.isnan(labels["contact_pos_cam"]).any()
    env.unwrapped.scene.data.qvel[:] = 1e30
    *_, truncated, info = env.step(env.action_space.sample())
    assert truncated and info["physics_diverged"] and not info["is_success"]
    assert _structure(info) == reference
    assert not bool(info["labels"]["valid"]) and env.unwrapped.frame is None
    for key, value in empty_label_arrays().items():
        np.testing.assert_array_equal(info["labels"][key], value)
    env.close()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"obs_mode": "rgb"}, "obs_mode='rgb' is not valid; choose one of depth, depth"),
        ({"control_mode": "torque"}, "control_mode='torque' is not valid; choose one of pose"),
        ({"reward_type": "shaped"}, "reward_type='shaped' is not valid; choose one of dense"),
        ({"camera": "kinect"}, "camera='kinect' is not valid; choose one of "),
        ({"viewpoint": "top"}, "viewpoint='top' is not valid; choose one of third_person"),
        ({"sensor": "lidar"}, "sensor='lidar' is not valid; choose one of none"),
        ({"handedness": "both"}, "handedness='both' is not valid; choose one of right"),
        ({"hand_size": "huge"}, "hand_size='huge' is not a size; use one of small, medium"),
        ({"hand_size": (0.2, 0.15)}, "has low > high"),
        ({"hand_size": 0.5}, "hand_length"),
        ({"frame_skip": 0}, "frame_skip must be a positive integer; received 0"),
        ({"render_mode": "video"}, "render_mode='video' is not valid; choose one of rgb_array"),
        ({"object_friction": "ice"}, r"object_friction='ice' is not valid; choose one of mujoco"),
        ({"object_friction": 0.0}, r"object_friction=0.0 .* or a sliding friction in \(0, 10\]"),
    ],
)
def test_invalid_arguments_say_what_is_valid(kwargs, message):
    """Every shared argument is validated with an error listing the valid values."""
    with pytest.raises(ValueError, match=message):
        gym.make("handsim/HandPose-v0", **kwargs)


def test_human_render_mode_needs_a_display(monkeypatch):
    """render_mode='human' without a display fails at construction, saying what to use."""
    monkeypatch.delenv("DISPLAY", raising=False)
    # "human" is declared only with a display, so gym.make would substitute Gymnasium's
    # HumanRendering wrapper; the env itself refuses it.
    with pytest.raises(InvalidEnvConfig, match="needs a display"):
        HandPoseEnv(render_mode="human")


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_render_modes(env_id):
    """rgb_array and depth_rgb_array give (H, W, 3) uint8; depth_array (H, W) float32 metres."""
    for mode in ("rgb_array", "depth_rgb_array", "depth_array"):
        env = _make(env_id, render_mode=mode)
        env.reset(seed=0)
        image = env.render()
        h, w = env.unwrapped.config.render_height, env.unwrapped.config.render_width
        if mode == "depth_array":
            assert image.shape == (h, w) and image.dtype == np.float32 and image.max() > 0
        else:
            assert image.shape == (h, w, 3) and image.dtype == np.uint8 and image.std() > 0
        env.close()


def test_close_frees_the_renderer_and_is_idempotent():
    """close() releases the renderers; a second close() is harmless; reset() rebuilds."""
    env = gym.make("handsim/HandPose-v0")
    env.reset(seed=0)
    env.close()
    assert env.unwrapped.frame_renderer is None and env.unwrapped.scene is None
    env.close()
    obs, _ = env.reset(seed=0)
    assert obs["depth"].max() > 0
    env.close()


def test_step_before_reset_raises():
    """step() before reset() says to reset."""
    env = gym.make("handsim/HandPose-v0", disable_env_checker=True)
    with pytest.raises(gym.error.ResetNeeded, match="call reset\\(\\) before step\\(\\)"):
        env.unwrapped.step(np.zeros(27))


@pytest.mark.parametrize("vector_kind", ["sync", "async"])
def test_vector_envs(vector_kind):
    """Sync and async vector envs step two HandPose envs (each in its own process if async).

    Async workers are spawned (a process forked after its parent made an EGL context hangs);
    the ``module:id`` form imports handsim.envs in each worker so the id is registered there.
    """
    fns = [lambda: gym.make("handsim.envs:handsim/HandPose-v0") for _ in range(2)]
    if vector_kind == "sync":
        envs = gym.vector.SyncVectorEnv(fns)
    else:
        envs = gym.vector.AsyncVectorEnv(fns, context="spawn")
    obs, _ = envs.reset(seed=[0, 1])
    assert obs["depth"].shape == (2, 240, 320)
    assert not np.array_equal(obs["goal"][0], obs["goal"][1])
    obs, reward, terminated, truncated, _ = envs.step(envs.action_space.sample())
    assert reward.shape == (2,) and np.all(np.isfinite(obs["depth"]))
    envs.close()


def test_random_viewpoint_and_hand_size_range_are_seeded():
    """Per-episode draws (viewpoint, hand size, handedness) follow the seed."""
    kwargs = {"viewpoint": "random", "hand_size": (0.16, 0.21), "handedness": "random"}
    env = gym.make("handsim/HandPose-v0", **kwargs)
    _, a = env.reset(seed=7)
    _, b = env.reset(seed=8)
    _, c = env.reset(seed=7)
    assert _same_labels(a["labels"], c["labels"])
    assert not np.array_equal(a["labels"]["T_cam_from_world"], b["labels"]["T_cam_from_world"])
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_expert_actions_are_float32_inside_the_action_space(env_id):
    """expert.action(state) is what env.step expects: (27,) float32, contained in the space."""
    env = _make(env_id, obs_mode="state")
    env.reset(seed=0)
    expert = env.unwrapped.make_expert()
    for _ in range(40):
        action = expert.action(env.unwrapped.expert_state())
        assert action.dtype == np.float32 and env.action_space.contains(action)
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    env.close()


def test_gesture_expert_reaches_the_goal():
    """The gesture expert drives HandPose-v0 to within 10 mm of its goal keypoints."""
    env = gym.make("handsim/HandPose-v0")
    for seed in range(3):
        env.reset(seed=seed)
        expert = env.unwrapped.make_expert()
        for _ in range(150):
            action = expert.act(env.unwrapped.expert_state()).vector
            _, reward, _, truncated, info = env.step(action)
            if truncated:
                break
        assert info["is_success"], (seed, info["keypoint_distance_m"])
    env.close()


def test_episode_length_is_set_with_max_episode_steps():
    """gym.make(..., max_episode_steps=N) truncates after N steps."""
    env = gym.make("handsim/HandPose-v0", max_episode_steps=3)
    env.reset(seed=0)
    truncated = [env.step(env.action_space.sample())[3] for _ in range(3)]
    assert truncated == [False, False, True]
    env.close()
