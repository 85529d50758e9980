"""The joint-space pose filter: passes what is still, smooths noise, handles SO(3), errors."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.envs.teleop import TeleopConfig
from handsim.envs.teleop.filters import InvalidFilter
from handsim.envs.teleop.pose_filter import PoseFilter, make_pose_filter


def _pose(rng, angle_rad=1.0):
    pose = np.r_[rng.normal(0, 0.1, 3), Rotation.random(random_state=1).as_rotvec(), np.zeros(21)]
    pose[3:6] *= angle_rad / np.linalg.norm(pose[3:6])
    pose[6:] = rng.uniform(0.0, 0.8, 21)
    return pose


def test_a_still_pose_passes_unchanged():
    """The first pose and a constant pose come through exactly."""
    pose = _pose(np.random.default_rng(0))
    f = PoseFilter(50.0)
    for _ in range(5):
        np.testing.assert_allclose(f(pose), pose, atol=1e-12)


def test_noise_on_a_still_hand_is_cut_in_every_part():
    """Noise like a 10 mm keypoint fit's (6 mm, 7 deg, 0.3 rad per frame) shrinks 2x or more."""
    rng = np.random.default_rng(1)
    truth = _pose(rng)
    f = PoseFilter(50.0)
    raw, out = [], []
    for _ in range(300):
        noisy = truth.copy()
        noisy[:3] += rng.normal(0, 0.006, 3)
        noisy[3:6] = (
            Rotation.from_rotvec(rng.normal(0, 0.07, 3)) * Rotation.from_rotvec(truth[3:6])
        ).as_rotvec()
        noisy[6:] += rng.normal(0, 0.3, 21)
        raw.append(noisy)
        out.append(f(noisy))
    raw, out = np.array(raw)[50:], np.array(out)[50:]

    def turn(x):
        return (
            Rotation.from_rotvec(x[:, 3:6]) * Rotation.from_rotvec(truth[3:6]).inv()
        ).magnitude()

    assert np.std(out[:, :3] - truth[:3]) < 0.5 * np.std(raw[:, :3] - truth[:3])
    assert np.mean(turn(out)) < 0.5 * np.mean(turn(raw))
    assert np.std(out[:, 6:] - truth[6:]) < 0.5 * np.std(raw[:, 6:] - truth[6:])


def test_rotation_is_filtered_across_the_rotvec_wrap():
    """A hand turned about pi (its rotation vector flips sign) is not dragged through identity."""
    f = PoseFilter(50.0)
    pose = np.zeros(27)
    axis = np.array([0.0, 0.0, 1.0])
    for k in range(40):
        pose[3:6] = axis * (np.pi - 0.05 + 0.1 * (k % 2))  # alternates across pi
        pose[3:6] = Rotation.from_rotvec(pose[3:6]).as_rotvec()
        out = f(pose)
        angle = Rotation.from_rotvec(out[3:6]) * Rotation.from_rotvec(axis * np.pi).inv()
        assert angle.magnitude() < 0.1


def test_a_move_is_followed():
    """A step of the wrist by 10 cm is followed to within 1 mm in 1 s."""
    f = PoseFilter(50.0)
    pose = np.zeros(27)
    f(pose)
    pose[0] = 0.1
    for _ in range(50):
        out = f(pose)
    assert abs(out[0] - 0.1) < 1e-3


def test_bad_input_and_parameters_are_refused():
    """Wrong shapes, unknown parameters and bad values name what is valid."""
    with pytest.raises(InvalidFilter, match=r"finite 27-DoF pose vector; received shape \(21,\)"):
        PoseFilter(50.0)(np.zeros(21))
    with pytest.raises(InvalidFilter, match=r"\['gain'\] are not valid; choose from min_cutoff"):
        make_pose_filter(50.0, gain=1.0)
    with pytest.raises(InvalidFilter, match="beta_rot must be a finite number >= 0"):
        make_pose_filter(50.0, beta_rot=-1.0)
    with pytest.raises(InvalidFilter, match="choose from min_cutoff_hz"):
        TeleopConfig(pose_filter_params={"cutoff": 1.0})


def test_adaptive_cutoffs_follow_the_keypoint_noise():
    """``adaptive``: the rest cut-offs times ``(10 mm / sigma)^2``, in [1, 30].

    Half the noise raises the cut-offs 4 times, and the filtered angles shake as much as
    with the full noise at the tuned cut-off (a first-order low-pass passes
    ``sqrt(a / (2 - a))`` of white noise: 0.250 at 1 Hz, 0.496 at 4 Hz, at 50 Hz).
    """
    flt = PoseFilter(50.0, adaptive=True, beta_joint=0.0, d_cutoff_hz=1.0)
    for sigma_m, scale in ((0.01, 1.0), (0.005, 4.0), (0.0, 30.0), (0.02, 1.0)):
        flt.set_keypoint_noise(sigma_m)
        assert flt.cutoff_scale == pytest.approx(scale)
        assert flt.min_cutoff_hz == pytest.approx(scale) and flt.rot_cutoff_hz == pytest.approx(
            scale
        )
    fixed = PoseFilter(50.0)
    fixed.set_keypoint_noise(0.0)  # not adaptive: unchanged
    assert fixed.cutoff_scale == 1.0 and fixed.min_cutoff_hz == 1.0
    rng = np.random.default_rng(0)
    shakes = []
    for sigma_m in (0.01, 0.005):
        flt = PoseFilter(50.0, adaptive=True, beta_joint=0.0)
        flt.set_keypoint_noise(sigma_m)
        noise = 100 * sigma_m * rng.standard_normal((4000, 27))  # angles' noise tracks sigma
        out = np.array([flt(np.r_[np.zeros(6), n[6:]]) for n in noise])
        shakes.append(np.std(out[200:, 6:]))
    assert shakes[1] == pytest.approx(shakes[0], rel=0.1)


def test_channel_sets_the_adaptive_filter_from_the_noise():
    """``pose_filter="auto"``: the channel's filter is scaled for the faults' noise (5 mm: 4)."""
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)
    from handsim.envs.teleop import FaultConfig
    from handsim.envs.teleop.channel import HandChannel
    from handsim.envs.teleop.loop import InvalidTeleopConfig

    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    config = TeleopConfig(faults=FaultConfig(noise_mm=5.0), pose_filter="auto")
    channel = HandChannel(config, env.unwrapped.scene, 0.02, np.random.default_rng(0))
    assert channel.pose_smoother.cutoff_scale == pytest.approx(4.0)
    env.close()
    with pytest.raises(InvalidTeleopConfig, match="'wrist' \\(the wrist only\\) or 'auto'"):
        TeleopConfig(pose_filter="adaptive")
