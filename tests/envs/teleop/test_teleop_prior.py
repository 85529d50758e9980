"""The teleop loop's pose prior: a maximum a posteriori retargeting of the tracked keypoints."""

import gymnasium as gym
import numpy as np
import pytest

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.teleop import FaultConfig, TeleopConfig
from handsim.envs.teleop.channel import HandChannel
from handsim.envs.teleop.loop import InvalidTeleopConfig
from handsim.hand.pose_prior import default_pose_prior


def test_config_validates_the_prior_and_its_noise():
    """``pose_prior`` is a bool, ``keypoint_sigma_mm`` None or a number >= 0 (mm)."""
    assert TeleopConfig(pose_prior=True, keypoint_sigma_mm=10.0).pose_prior
    for bad in ({"pose_prior": "on"}, {"pose_prior": True, "keypoint_sigma_mm": -1.0}):
        with pytest.raises(InvalidTeleopConfig, match="keypoint_sigma_mm None .* or a number"):
            TeleopConfig(**bad)


def test_channel_retargets_with_the_prior_weighed_by_the_fault_noise():
    """The channel's retargeter has the default prior, weighed by the faults' noise.

    ``keypoint_sigma_mm`` overrides the noise; without ``pose_prior`` it is least squares.
    """
    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    scene = env.unwrapped.scene
    rng = np.random.default_rng(0)
    noisy = TeleopConfig(faults=FaultConfig(noise_mm=10.0), pose_prior=True)
    retarget = HandChannel(noisy, scene, 0.02, rng).retargeter
    assert retarget.pose_prior is default_pose_prior()
    assert retarget.keypoint_sigma_m == pytest.approx(0.01)
    given = TeleopConfig(faults=FaultConfig(noise_mm=10.0), pose_prior=True, keypoint_sigma_mm=4)
    assert HandChannel(given, scene, 0.02, rng).retargeter.keypoint_sigma_m == pytest.approx(0.004)
    plain = HandChannel(TeleopConfig(), scene, 0.02, rng).retargeter
    assert plain.pose_prior is None and plain.keypoint_sigma_m is None
    env.close()


def test_channel_with_the_prior_steadies_the_retargeted_flexion():
    """A held grasp tracked with 10 mm of noise: the channel's targets shake 3 times less."""
    from handsim.hand.kinematics import ForwardKinematics
    from handsim.hand.pose import JOINT_NAMES, HandPose
    from handsim.hand.pose_library import GRASP_TYPES

    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    scene = env.unwrapped.scene
    fk = ForwardKinematics(scene.hand.params)
    pose = HandPose(np.array([0.0, 0.0, 0.3]), np.zeros(3), GRASP_TYPES["tripod"].angles(0.6))
    flex = np.array([n.endswith("_flex") for n in JOINT_NAMES])
    stds = {}
    for prior in (False, True):
        faults = FaultConfig(noise_mm=10.0)
        channel = HandChannel(
            TeleopConfig(faults=faults, pose_prior=prior), scene, 0.02, np.random.default_rng(1)
        )
        times = dict.fromkeys(("faults", "filter", "retarget"), 0.0)
        targets = []
        for _ in range(40):
            channel.track(fk.keypoints(pose), times, 0.0)
            targets.append(channel.target[6:])
        stds[prior] = np.std(targets[5:], axis=0)[flex].mean()
    env.close()
    # Measured: about 0.35 rad without the prior, 0.1 rad with it.
    assert stds[True] < 0.5 * stds[False]


def test_noise_estimator_recovers_white_noise_on_a_moving_hand():
    """The second-difference estimate is within 10 % of the noise from 1 to 10 mm.

    A hand swaying 5 cm at 0.5 Hz (0.5 m/s^2) adds 0.12 mm; a lost frame restarts the differences;
    fewer than ``min_frames`` differences give ``None``.
    """
    from handsim.errors import InvalidPose
    from handsim.hand.pose_prior import KeypointNoiseEstimator

    rng = np.random.default_rng(0)
    t = np.arange(60) * 0.02
    motion = 0.05 * np.sin(np.pi * t)[:, None, None] * np.ones((1, 21, 3))
    for sigma in (0.0, 0.001, 0.005, 0.01):
        est = KeypointNoiseEstimator()
        for k, frame in enumerate(motion):
            if k == 30:
                est.update(None)  # lost: the held frame does not count
            est.update(frame + sigma * rng.standard_normal((21, 3)))
        assert est.sigma_m == pytest.approx(sigma, rel=0.1, abs=2e-4)
    short = KeypointNoiseEstimator(min_frames=10)
    for frame in motion[:11]:
        short.update(frame)
    assert short.sigma_m is None  # 9 second differences
    short.update(motion[11])
    assert short.sigma_m is not None
    with pytest.raises(InvalidPose, match="window must be an int >= 3 frames; received 2"):
        KeypointNoiseEstimator(window=2)


def test_channel_estimates_the_prior_noise_from_the_stream():
    """``keypoint_sigma_mm="auto"``: the plain fit until the noise shows, then the prior.

    The adaptive pose filter (``pose_filter="auto"``) smooths as tuned until then.

    Tracked with 10 mm of noise, after one second the prior is weighed for about 10 mm; with
    exact keypoints the fit stays the plain one (sigma 0).
    """
    from handsim.hand.kinematics import ForwardKinematics
    from handsim.hand.pose import HandPose
    from handsim.hand.pose_library import GRASP_TYPES

    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    scene = env.unwrapped.scene
    fk = ForwardKinematics(scene.hand.params)
    pose = HandPose(np.array([0.0, 0.0, 0.3]), np.zeros(3), GRASP_TYPES["tripod"].angles(0.6))
    for noise_mm, expected_m in ((10.0, 0.01), (0.0, 0.0)):
        config = TeleopConfig(
            faults=FaultConfig(noise_mm=noise_mm),
            pose_prior=True,
            keypoint_sigma_mm="auto",
            pose_filter="auto",
        )
        channel = HandChannel(config, scene, 0.02, np.random.default_rng(1))
        assert channel.sigma_m == 0.0 and channel.retargeter.keypoint_sigma_m == 0.0
        assert channel.pose_smoother.cutoff_scale == 1.0  # unknown noise: smoothed as tuned
        times = dict.fromkeys(("faults", "filter", "retarget"), 0.0)
        for _ in range(50):
            channel.track(fk.keypoints(pose), times, 0.0)
        assert channel.sigma_m == pytest.approx(expected_m, rel=0.15)
        assert channel.retargeter.keypoint_sigma_m == pytest.approx(expected_m, rel=0.15)
        assert channel.metrics(0.02)["keypoint_sigma_mm"] == pytest.approx(1e3 * expected_m, 0.15)
        # The adaptive pose filter follows: as tuned at 10 mm, 30 times faster without noise.
        assert channel.pose_smoother.cutoff_scale == pytest.approx(1.0 if noise_mm else 30.0, 0.3)
    assert TeleopConfig(pose_prior=True, keypoint_sigma_mm="auto").keypoint_sigma_mm == "auto"
    with pytest.raises(InvalidTeleopConfig, match="'auto' \\(estimated from the stream\\)"):
        TeleopConfig(pose_prior=True, keypoint_sigma_mm="guess")
    env.close()
