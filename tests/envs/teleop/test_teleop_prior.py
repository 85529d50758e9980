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
