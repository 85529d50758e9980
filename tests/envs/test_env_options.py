"""Observation options, rendering for people, vector envs, experts through wrappers, bad actions."""

import multiprocessing as mp
import os
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import handsim.envs
from handsim.envs.base import (
    DEPTH_MAX_M,
    InvalidAction,
    depth_colormap,
)
from handsim.envs.config import InvalidEnvConfig
from handsim.envs.hand_pose import HandPoseEnv
from handsim.envs.workers import PIN_ENV_VAR, pin_vector_worker
from handsim.errors import HandSimError
from handsim.frame import Frame
from handsim.world.camera import camera_preset
from handsim.world.scene import OBJECT_LABEL_OFFSET

ENV_IDS = handsim.envs.ENV_IDS
FAST = {"handsim/GraspClutter-v0": {"num_objects": (3, 3)}}


def _make(env_id, **kwargs):
    return gym.make(env_id, **{**FAST.get(env_id, {}), **kwargs})


# State modes ---------------------------------------------------------------------------------


@pytest.mark.parametrize("obs_mode", ["state", "privileged_state"])
def test_state_modes_render_nothing_without_labels(obs_mode):
    """No renderer is made and there are no labels unless labels=True asks for them."""
    env = _make("handsim/Grasp-v0", objects="mustard_bottle", obs_mode=obs_mode)
    _, info = env.reset(seed=0)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert "labels" not in info and env.unwrapped.frame is None
    assert env.unwrapped._frame_renderer is None
    assert "n_contact_parts" in info  # the task's labels come from the physics
    env.close()
    env = _make("handsim/Grasp-v0", objects="mustard_bottle", obs_mode=obs_mode, labels=True)
    _, info = env.reset(seed=0)
    assert isinstance(env.unwrapped.frame, Frame) and bool(info["labels"]["valid"])
    env.close()


@pytest.mark.parametrize("obs_mode", ["depth", "depth+segmentation"])
def test_images_without_labels_equal_images_with_labels(obs_mode):
    """labels=False skips the label work only: the same seed gives the same images."""
    out = []
    for labels in (True, False):
        env = _make("handsim/Grasp-v0", objects="mustard_bottle", obs_mode=obs_mode,
                    sensor="structured_light", labels=labels)  # fmt: skip
        obs, info = env.reset(seed=3)
        env.action_space.seed(3)
        obs, _, _, _, info = env.step(env.action_space.sample())
        out.append((obs, info.get("labels")))
        env.close()
    (a, frame_a), (b, frame_b) = out
    assert frame_a is not None and frame_b is None
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])


def test_contact_parts_from_physics_match_the_frame():
    """The reward's contact count read from MuJoCo equals the Frame's contact labels."""
    env = _make("handsim/Grasp-v0", objects="005_tomato_soup_can")
    env.reset(seed=0)
    expert = env.get_wrapper_attr("make_expert")()
    counts = []
    for _ in range(300):
        action = expert.act(env.get_wrapper_attr("expert_state")()).vector
        _, _, terminated, truncated, info = env.step(action)
        target = info["target_instance"]
        frame = env.unwrapped.frame
        from_frame = {c.hand_part for c in frame.contacts if c.instance == target}
        assert info["n_contact_parts"] == len(from_frame)
        counts.append(info["n_contact_parts"])
        if terminated or truncated or sum(c >= 2 for c in counts) >= 5:
            break
    assert max(counts) >= 2  # the grasp touched the can
    env.close()


@pytest.mark.parametrize("env_id", ["handsim/Grasp-v0", "handsim/GraspClutter-v0"])
def test_privileged_state_object_poses_are_the_world_poses(env_id):
    """object_poses rows equal each object's world pose (checked against the Frame's labels)."""
    env = _make(env_id, obs_mode="privileged_state", labels=True)
    obs, info = env.reset(seed=1)
    obs, _, _, _, info = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)
    frame = env.unwrapped.frame
    n = len(frame.objects)
    assert obs["object_present"].tolist() == [1] * n + [0] * (env.unwrapped.max_objects - n)
    T_world_cam = np.linalg.inv(frame.T_cam_from_world)  # noqa: N806
    for label in frame.objects:
        T = T_world_cam @ label.T_cam_from_obj  # noqa: N806
        row = obs["object_poses"][label.instance]
        np.testing.assert_allclose(row[:3], T[:3, 3], atol=1e-9)
        R = np.empty(9)  # noqa: N806
        mujoco.mju_quat2Mat(R, row[3:])
        np.testing.assert_allclose(R.reshape(3, 3), T[:3, :3], atol=1e-9)
    assert np.all(obs["object_poses"][n:] == 0)
    assert "proprio" in obs and "depth" not in obs
    env.close()


def test_privileged_state_without_objects_is_state():
    """HandPose-v0 has no objects: privileged_state has the keys of state."""
    a = _make("handsim/HandPose-v0", obs_mode="state").observation_space
    b = _make("handsim/HandPose-v0", obs_mode="privileged_state").observation_space
    assert a == b


# Image options -------------------------------------------------------------------------------


def test_width_height_render_at_that_size_and_the_labels_follow():
    """width/height render at that size with the scaled K; the labels are the image's.

    The same seed gives the same scene: keypoints in the camera frame are equal, their pixels
    are the full image's mapped by ``(u + 0.5) s - 0.5``, and a keypoint visible in both images
    lands on the same hand part in both segmentations.
    """
    kwargs = {"objects": "mustard_bottle", "obs_mode": "depth+segmentation"}
    full = _make("handsim/Grasp-v0", **kwargs)
    small = _make("handsim/Grasp-v0", width=160, height=120, **kwargs)
    obs_full, info_full = full.reset(seed=2)
    obs_small, info_small = small.reset(seed=2)
    sensor = camera_preset("icvl")
    assert small.unwrapped.obs_intrinsics == sensor.scaled(160, 120)
    a, b = full.unwrapped.frame, small.unwrapped.frame
    np.testing.assert_array_equal(b.K, sensor.scaled(160, 120).K)
    for key in ("depth", "segmentation"):
        assert obs_small[key].shape == (120, 160)
    assert b.depth.shape == b.segmentation.shape == (120, 160)
    np.testing.assert_array_equal(obs_small["segmentation"], b.segmentation)
    np.testing.assert_allclose(b.keypoints_cam, a.keypoints_cam, atol=1e-12)
    np.testing.assert_allclose(b.keypoints_px, (a.keypoints_px + 0.5) * 0.5 - 0.5, atol=1e-9)
    np.testing.assert_allclose(info_small["labels"]["keypoints_px"], b.keypoints_px)
    # Away from part boundaries (a uniform 3 x 3 patch in the small image), a keypoint's pixel
    # shows the same label in both images; visibility agrees for every keypoint here.
    np.testing.assert_array_equal(a.visible, b.visible)
    checked = 0
    for k in np.flatnonzero(a.in_frame & b.in_frame):
        (ua, va), (ub, vb) = np.rint(a.keypoints_px[k]).astype(int), np.rint(b.keypoints_px[k])
        patch = b.segmentation[int(vb) - 1 : int(vb) + 2, int(ub) - 1 : int(ub) + 2]
        if np.all(patch == patch[1, 1]):
            assert a.segmentation[va, ua] == patch[1, 1]
            checked += 1
    assert checked >= 6
    # Masks: the object covers a quarter of the pixels (to its boundary), the same fraction.
    (oa,), (ob,) = a.objects, b.objects
    assert ob.px_count_visib == pytest.approx(oa.px_count_visib / 4, rel=0.1)
    assert ob.visib_fract == pytest.approx(oa.visib_fract, abs=0.05)
    full.close()
    small.close()


def test_one_size_keeps_the_aspect_ratio():
    """Only width (or height) given: the other follows the sensor's aspect ratio."""
    env = _make("handsim/HandPose-v0", width=160)
    assert env.observation_space["depth"].shape == (120, 160)
    env = _make("handsim/HandPose-v0", height=60)
    assert env.observation_space["depth"].shape == (60, 80)


def test_uint16_mm_depth_and_channel_axis():
    """uint16_mm is the float depth in rounded millimetres; channel_axis adds a leading 1."""
    kwargs = {"objects": "mustard_bottle", "obs_mode": "depth+segmentation"}
    a = _make("handsim/Grasp-v0", **kwargs)
    b = _make("handsim/Grasp-v0", depth_format="uint16_mm", channel_axis=True, **kwargs)
    obs_a, _ = a.reset(seed=4)
    obs_b, _ = b.reset(seed=4)
    assert obs_b["depth"].dtype == np.uint16 and obs_b["depth"].shape == (1, 240, 320)
    assert obs_b["segmentation"].shape == (1, 240, 320)
    assert b.observation_space.contains(obs_b)
    expected = np.rint(obs_a["depth"].astype(np.float64) * 1000).astype(np.uint16)
    np.testing.assert_array_equal(obs_b["depth"][0], expected)
    np.testing.assert_array_equal(obs_b["segmentation"][0], obs_a["segmentation"])
    assert b.observation_space["depth"].high.max() == DEPTH_MAX_M * 1000
    a.close()
    b.close()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"width": "84"}, r"width must be an integer number of pixels in \[8, 2048\].*'icvl'"),
        ({"width": 0}, r"width must be an integer number of pixels in \[8, 2048\].*received 0"),
        ({"height": 84.0}, r"height must be an integer number of pixels in \[8, 2048\]"),
        ({"height": True}, r"height must be an integer .*received True"),
        ({"render_width": 5}, r"render_width must be an integer .*\[16, 4096\]; received 5"),
        ({"render_height": None}, r"render_height must be an integer"),
        ({"render_quality": "best"}, r"render_quality='best' is not valid; choose one of fast, "),
        ({"depth_format": "mm"}, r"depth_format='mm' is not valid; choose one of float32_m, "),
        ({"channel_axis": "yes"}, r"channel_axis must be True or False; received 'yes'"),
        ({"labels": 1}, r"labels must be True or False; received 1"),
        ({"obs_mode": "pixels"}, r"obs_mode='pixels' is not valid; .*privileged_state"),
        ({"render_mode": "human"}, r"render_mode='human' needs a display .*'depth_array'"),
    ],
)
def test_bad_options_raise_the_config_error(kwargs, match):
    """Each invalid option raises InvalidEnvConfig (a HandSimError) listing what is valid."""
    with pytest.raises(InvalidEnvConfig, match=match):
        HandPoseEnv(**kwargs)  # gym.make would wrap "human" in its HumanRendering


# Stable-Baselines3 ---------------------------------------------------------------------------


def test_sb3_takes_the_depth_observation_with_a_cnn():
    """SB3's env checker passes and MultiInputPolicy puts a NatureCNN on (1, H, W) depth."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_checker import check_env as sb3_check_env
    from stable_baselines3.common.torch_layers import NatureCNN

    env = _make("handsim/HandPose-v0", width=64, height=64, channel_axis=True,
                control_mode="delta")  # fmt: skip
    sb3_check_env(env.unwrapped, warn=False)
    model = PPO("MultiInputPolicy", env, n_steps=8, batch_size=8,
                policy_kwargs={"normalize_images": False}, device="cpu")  # fmt: skip
    extractors = model.policy.features_extractor.extractors
    assert isinstance(extractors["depth"], NatureCNN)
    n_params = sum(p.numel() for p in model.policy.parameters())
    assert n_params < 2_000_000  # not a 76,800-input MLP
    env.close()


@pytest.mark.slow
def test_ppo_with_a_cnn_on_depth_runs_2048_steps():
    """PPO (MultiInputPolicy: NatureCNN on depth) collects and trains on 2048 env steps."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    env = _make("handsim/Grasp-v0", objects="mustard_bottle", width=84, height=84,
                channel_axis=True, control_mode="delta")  # fmt: skip
    model = PPO("MultiInputPolicy", env, n_steps=2048, batch_size=256, n_epochs=1,
                policy_kwargs={"normalize_images": False}, device="cpu", seed=0)  # fmt: skip
    model.learn(total_timesteps=2048)
    assert model.num_timesteps == 2048
    env.close()


# Rendering ----------------------------------------------------------------------------------


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_with_default_arguments(env_id):
    """Gymnasium's checker with its defaults passes, and every declared render mode quietly.

    The one warning left is the checker's advice for Box actions in [-1, 1]: the default
    ``"pose"`` control mode has physical bounds (``"delta"`` is the normalized one).
    """
    env = gym.make(env_id, **FAST.get(env_id, {}))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    env.close()
    messages = [str(w.message) for w in caught]
    assert [m for m in messages if "symmetric and normalized" not in m] == []


@pytest.mark.parametrize("mode", ["depth_array", "depth_rgb_array", "rgb_array"])
def test_passive_checker_is_quiet_on_every_render(mode):
    """gym.make's passive checker sees each render mode return what Gymnasium expects."""
    env = gym.make("handsim/HandPose-v0", render_mode=mode, render_width=64, render_height=48)
    env.reset(seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        image = env.render()  # the first render goes through env_render_passive_checker
        env.step(env.action_space.sample())
        env.render()
    assert image.shape[:2] == (48, 64)
    env.close()


def test_depth_array_is_metres_with_zero_where_nothing_is_hit():
    """depth_array: (H, W) float32 metres along the viewer's axis inside its range, 0 = sky."""
    env = gym.make("handsim/Grasp-v0", render_mode="depth_array", render_width=80,
                   render_height=60)  # fmt: skip
    env.reset(seed=5)
    depth = env.render()
    assert depth.shape == (60, 80) and depth.dtype == np.float32
    near_m, far_m = env.unwrapped._viewer_range_m
    hit = depth > 0
    assert hit.any() and not hit.all()  # the table, hand and objects; the sky beyond the table
    assert np.all(depth[hit] >= 0.5 * near_m) and np.all(depth[hit] <= 1.01 * far_m)
    # The colour map of the same view is the depth_rgb_array picture.
    colour = gym.make("handsim/Grasp-v0", render_mode="depth_rgb_array", render_width=80,
                      render_height=60)  # fmt: skip
    colour.reset(seed=5)
    expected = depth_colormap(depth, near_m, far_m)
    assert np.array_equal(colour.render(), expected)
    env.close()
    colour.close()


@pytest.mark.parametrize("mode", ["rgb_array", "depth_rgb_array"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_viewer_frames_the_hand_and_the_objects(env_id, mode):
    """render() is (render_height, render_width, 3) uint8; the viewer sees hand and objects."""
    env = _make(env_id, render_mode=mode, render_width=160, render_height=120)
    env.reset(seed=5)
    image = env.render()
    assert image.shape == (120, 160, 3) and image.dtype == np.uint8
    assert image.std() > 10  # not blank
    base = env.unwrapped
    with mujoco.Renderer(base.scene.model, 120, 160) as renderer, base.viewer_clip_planes():
        renderer.enable_segmentation_rendering()
        renderer.update_scene(base.scene.data, camera=base._viewer_camera)
        seen = renderer.render()
    seen_geoms = seen[..., 0][seen[..., 1] == mujoco.mjtObj.mjOBJ_GEOM]
    labels = set(base.scene.geom_labels[seen_geoms].tolist())
    assert labels & {2, 3, 4, 5, 6, 7}  # hand parts
    for k in range(len(base.scene.objects)):
        assert OBJECT_LABEL_OFFSET + k in labels
    env.close()


def test_render_quality_high_adds_shadows_to_the_same_picture():
    """With render_quality="high" shadows darken parts of the same picture "fast" draws."""
    images = {}
    for quality in ("fast", "high"):
        env = _make("handsim/Grasp-v0", render_mode="rgb_array", render_width=160,
                    render_height=120, render_quality=quality)  # fmt: skip
        env.reset(seed=5)
        images[quality] = env.render().astype(np.int16)
        env.close()
    darker = images["fast"] - images["high"]
    assert np.count_nonzero(darker.sum(axis=-1) > 30) > 50  # shadowed pixels
    assert np.count_nonzero(darker.sum(axis=-1) < -30) == 0  # shadows only darken
    assert np.median(np.abs(darker)) == 0  # elsewhere the same picture


@pytest.mark.parametrize("mode", ["rgb_array", "depth_rgb_array"])
def test_record_video_writes_an_episode(tmp_path, mode):
    """gymnasium.wrappers.RecordVideo records a short episode in either render mode."""
    pytest.importorskip("moviepy")
    env = gym.make("handsim/HandPose-v0", render_mode=mode, render_width=64,
                   render_height=48, max_episode_steps=4)  # fmt: skip
    env = gym.wrappers.RecordVideo(env, str(tmp_path), episode_trigger=lambda _: True,
                                   disable_logger=True)  # fmt: skip
    env.reset(seed=0)
    truncated = False
    while not truncated:
        _, _, _, truncated, _ = env.step(env.action_space.sample())
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0


# Vector envs --------------------------------------------------------------------------------


def _run_vector(envs):
    try:
        envs.reset_async(seed=0)
        obs, _ = envs.reset_wait(timeout=120)
        envs.step_async(envs.action_space.sample())
        obs, reward, *_ = envs.step_wait(timeout=120)
        return obs, reward
    finally:
        envs.close(terminate=True)


def _rendered_parent_env():
    """Make and render an env in this process first: the case that used to hang on fork."""
    env = gym.make("handsim/HandPose-v0", width=32, height=24)
    env.reset(seed=0)
    env.step(env.action_space.sample())
    return env


@pytest.mark.parametrize("context", ["fork", "spawn", "forkserver"])
def test_async_vector_env_with_every_start_method(context):
    """AsyncVectorEnv works with fork, spawn and forkserver after the parent has rendered."""
    parent = _rendered_parent_env()
    envs = gym.make_vec("handsim/HandPose-v0", num_envs=2, vectorization_mode="async",
                        vector_kwargs={"context": context}, width=32, height=24)  # fmt: skip
    cpus = envs.get_attr("worker_cpu")
    obs, reward = _run_vector(envs)
    assert obs["depth"].shape == (2, 24, 32) and np.all(obs["depth"].max(axis=(1, 2)) > 0)
    assert reward.shape == (2,)
    allowed = sorted(os.sched_getaffinity(0))
    if len(allowed) > 1:  # one worker per CPU
        assert list(cpus) == allowed[:2]
    assert parent.unwrapped.worker_cpu is None  # this process is no worker
    parent.close()


def _pin_in_child(queue):
    queue.put((pin_vector_worker(), pin_vector_worker(), sorted(os.sched_getaffinity(0))))


@pytest.mark.parametrize(
    ("name", "setting", "pinned"),
    [
        ("Worker<AsyncVectorEnv>-3", None, True),
        ("Worker<AsyncVectorEnv>-3", "0", False),
        ("Process-1", None, False),
    ],
)
def test_vector_workers_are_pinned_to_one_cpu(monkeypatch, name, setting, pinned):
    """A Gymnasium worker (by its process name) is pinned to CPU i mod n, unless turned off."""
    allowed = sorted(os.sched_getaffinity(0))
    if setting is None:
        monkeypatch.delenv(PIN_ENV_VAR, raising=False)
    else:
        monkeypatch.setenv(PIN_ENV_VAR, setting)
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_pin_in_child, args=(queue,), name=name)
    child.start()
    child.join(timeout=60)
    first, again, affinity = queue.get(timeout=5)
    if pinned and len(allowed) > 1:
        assert first == again == allowed[3 % len(allowed)]
        assert affinity == [first]
    else:
        assert first is None and again is None
        assert affinity == allowed


def test_make_vec_with_default_arguments():
    """The issue's call: gym.make_vec(..., vectorization_mode="async"), defaults (fork)."""
    parent = _rendered_parent_env()
    envs = gym.make_vec("handsim/Grasp-v0", num_envs=2, vectorization_mode="async")
    obs, _ = _run_vector(envs)
    assert obs["depth"].shape == (2, 240, 320)
    parent.close()


def _step_in_child(env, queue):
    obs, *_ = env.step(env.action_space.sample())
    queue.put(float(obs["depth"].max()))


def test_an_env_forked_after_rendering_makes_its_own_gl_context():
    """A live env used in a forked child drops the inherited renderer and renders."""
    env = _rendered_parent_env()
    inherited = env.unwrapped._frame_renderer
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_step_in_child, args=(env, queue))
    child.start()
    child.join(timeout=120)
    assert child.exitcode == 0
    assert queue.get(timeout=5) > 0
    assert env.unwrapped._frame_renderer is inherited  # the parent's is untouched
    env.step(env.action_space.sample())
    env.close()


# Experts and wrappers -----------------------------------------------------------------------


def test_make_expert_through_gym_make_wrappers():
    """get_wrapper_attr (and env.unwrapped) reach make_expert through gym.make's wrappers."""
    env = gym.make("handsim/HandPose-v0")
    env.reset(seed=0)
    with pytest.raises(AttributeError):
        env.make_expert  # noqa: B018 (Gymnasium 1.x forwards no attributes)
    expert = env.get_wrapper_attr("make_expert")(np.random.default_rng(0))
    state = env.get_wrapper_attr("expert_state")
    distances = []
    for _ in range(100):
        _, _, _, _, info = env.step(expert.act(state()).vector)
        distances.append(info["keypoint_distance_m"])
    assert distances[-1] < distances[0]
    assert type(env.unwrapped.make_expert(np.random.default_rng(0))) is type(expert)
    env.close()


def test_estimator_loop_on_resized_channel_first_uint16_depth():
    """EstimatorLoop on a gym.make env hands the estimator (H, W) metres and the scaled K."""
    from handsim.envs.wrappers import EstimatorLoop
    from handsim.estimators import CenterOfMassLocalizer

    errors = []
    for kwargs in ({}, {"width": 160, "height": 120, "channel_axis": True,
                        "depth_format": "uint16_mm"}):  # fmt: skip
        env = EstimatorLoop(gym.make("handsim/HandPose-v0", **kwargs), CenterOfMassLocalizer())
        _, info = env.reset(seed=0)
        errors.append(info["estimate_errors"]["center_mm"])
        expert = env.make_expert(np.random.default_rng(0))
        env.step(expert.act(env.expert_state()).vector)
        env.close()
    assert np.isfinite(errors).all()
    assert abs(errors[1] - errors[0]) < 10.0  # same centre within 1 cm at half resolution


def test_estimator_loop_refuses_envs_without_labels_and_classes():
    """No labels to score against, or an estimator class, is refused with the fix."""
    from handsim.envs.wrappers import EstimatorLoop
    from handsim.estimators import CenterOfMassLocalizer

    with pytest.raises(InvalidEnvConfig, match="labels=False; make it with labels=True"):
        EstimatorLoop(gym.make("handsim/HandPose-v0", labels=False), CenterOfMassLocalizer())
    with pytest.raises(InvalidEnvConfig, match="received the class CenterOfMassLocalizer"):
        EstimatorLoop(gym.make("handsim/HandPose-v0"), CenterOfMassLocalizer)


# Bad actions --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("action", "match"),
    [
        (np.zeros(27, dtype=complex), r"received a complex array \(complex128\).*not cut"),
        (np.zeros(27) + 0j, r"complex values are not cut to their real part"),
        (np.zeros(27, dtype=bool), r"received dtype bool"),
        (["a"] * 27, r"received dtype <U1"),
        (np.zeros((1, 27)), r"must have shape \(27,\).*received shape \(1, 27\)"),
        (np.zeros(28), r"must have shape \(27,\).*received shape \(28,\)"),
        (np.full(27, np.inf), r"NaN or Inf values at indices \[0, 1"),
        ([0.0] * 26 + [None], r"received dtype object"),
        ([[0.0], [0.0, 1.0]], r"must have shape \(27,\)"),
    ],
)
def test_bad_actions_raise_invalid_action(action, match):
    """Bad actions raise InvalidAction: a HandSimError and a ValueError naming the problem."""
    env = gym.make("handsim/HandPose-v0", obs_mode="state")
    env.reset(seed=0)
    with pytest.raises(InvalidAction, match=match) as caught:
        env.unwrapped.step(action)
    assert isinstance(caught.value, HandSimError) and isinstance(caught.value, ValueError)
    env.close()


def test_out_of_bound_actions_are_clipped():
    """Out-of-bound (finite) actions are clipped to the action space, as documented."""
    env = gym.make("handsim/HandPose-v0", obs_mode="state", control_mode="delta")
    _, info = env.reset(seed=0)
    start = info["target_pose"]
    _, _, _, _, a = env.step(np.full(27, 5.0))
    env.reset(seed=0)
    _, _, _, _, b = env.step(np.full(27, 1.0))
    np.testing.assert_array_equal(a["target_pose"], b["target_pose"])
    assert not np.array_equal(a["target_pose"], start)
    env.close()


@pytest.mark.parametrize("num_objects", [(1.5, 2.5), (1, 2.0), (True, 2), "3"])
def test_clutter_num_objects_refuses_non_integers(num_objects):
    """A float bound is refused, not truncated (it would silently change the episode)."""
    with pytest.raises(InvalidEnvConfig, match=r"num_objects must be an int or a \(low, high\)"):
        gym.make("handsim/GraspClutter-v0", num_objects=num_objects)
