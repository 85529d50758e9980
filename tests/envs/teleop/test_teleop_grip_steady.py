"""The grip stabiliser's steady hold: a held digit takes the running mean, not one frame."""

import gymnasium as gym
import numpy as np
import pytest

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.teleop import TeleopConfig
from handsim.envs.teleop.grip import GripStabiliser
from handsim.envs.teleop.loop import InvalidTeleopConfig

INDEX = 6 + np.array([5, 6, 7, 8])  # mcp_flex, mcp_abd, pip_flex, dip_flex in the 27-vector
INDEX_FLEX = INDEX[[0, 2, 3]]
MIDDLE = 6 + np.array([9, 10, 11, 12])


class _Data:
    ncon = 0


class _Binding:
    def __init__(self) -> None:
        self.angles = np.zeros(21)

    def pose(self, data):
        return type("Pose", (), {"angles": self.angles.copy()})()


@pytest.fixture(scope="module")
def base():
    """A Grasp-v0 env after its reset (the stabiliser reads its scene)."""
    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    yield env.unwrapped
    env.close()


def _grip(base, steady):
    grip = GripStabiliser(base, 0.02, steady=steady)  # 0.15 s running mean
    grip.touching = lambda data: np.array([False, True, False, False, False])
    grip._binding = _Binding()
    grip._binding.angles[INDEX - 6] = [0.5, 0.0, 0.7, 0.4]  # the index stopped by the object
    return grip


def _held_then_spike(grip):
    """Hold the index at its surface for 20 frames, then one frame's noise: +0.5 rad."""
    target = np.zeros(27)
    target[INDEX] = [0.55, 0.05, 0.75, 0.45]
    for _ in range(20):
        grip(target, _Data())
    spike = target.copy()
    spike[INDEX] += 0.5
    spike[MIDDLE] += 0.5  # a free digit
    return target, grip(spike, _Data())


def test_steady_grip_ignores_one_frames_spike_on_a_held_digit(base):
    """A spike past the press: at once without steady, its running mean's share with it.

    The share is 1 - exp(-0.02 / 0.15) = 12.5 %; ``"hand"`` steadies a free digit too.
    """
    alpha = 1.0 - np.exp(-0.02 / 0.15)
    target, out = _held_then_spike(_grip(base, False))
    np.testing.assert_allclose(out[INDEX], target[INDEX] + 0.5)
    target, out = _held_then_spike(_grip(base, True))
    assert np.all(out[INDEX] - target[INDEX] < alpha * 0.5 + 0.01)
    assert np.all(out[INDEX] - target[INDEX] > 0.0)  # the mean closes: the press rises
    np.testing.assert_allclose(out[MIDDLE], target[MIDDLE] + 0.5)  # a free digit: as tracked
    target, out = _held_then_spike(_grip(base, "hand"))
    assert np.all(out[MIDDLE] - target[MIDDLE] < alpha * 0.5 + 0.01)  # the hand holds: steady


def test_steady_grip_still_releases_when_the_hand_opens(base):
    """Opening beyond the band releases a held digit with steady on, as without it."""
    grip = _grip(base, True)
    target = np.zeros(27)
    target[INDEX] = [0.55, 0.05, 0.75, 0.45]
    for _ in range(20):
        grip(target, _Data())
    opened = target.copy()
    opened[INDEX_FLEX] = -0.2
    for _ in range(40):
        out = grip(opened, _Data())
    assert not grip.latched().any()
    np.testing.assert_allclose(out[INDEX], opened[INDEX])


def test_config_validates_grip_steady():
    """``grip_steady`` is False, True or 'hand', and needs the grip stabiliser."""
    assert TeleopConfig(grip_steady="hand").grip_steady == "hand"
    with pytest.raises(InvalidTeleopConfig, match="grip_steady='yes' is not valid; choose"):
        TeleopConfig(grip_steady="yes")
    with pytest.raises(InvalidTeleopConfig, match="grip_steady acts on the grip stabiliser"):
        TeleopConfig(grip_steady=True, grip_hold=False)
