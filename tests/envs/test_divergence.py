"""Divergence: caught in the step it happens, never returned as valid, and the episode stops."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.base import RESET_ATTEMPTS
from handsim.envs.physics import (
    DIVERGENCE_LEVER_RATIO,
    DIVERGENCE_OBJECT_FACTOR,
    DIVERGENCE_SPEED_M_S,
    HandDriver,
    PhysicsDiverged,
    divergence_speed_bounds,
)
from handsim.errors import HandSimError

ENV_IDS = ["handsim/HandPose-v0", "handsim/Grasp-v0", "handsim/GraspClutter-v0"]
FAST = {"handsim/GraspClutter-v0": {"num_objects": (3, 3)}}


def _hand_bounds(env):
    """(54,) bounds of the proprio vector's velocity half (27 values) for this episode's hand."""
    scene = env.unwrapped.scene
    root = scene.model.body(scene.hand.root_body).id
    bounds = divergence_speed_bounds(scene.model, scene.hand.params.hand_length, root)
    binding = scene.binding
    root = binding.root_dof
    return np.concatenate([bounds[root : root + 6], bounds[binding.joint_dof]])


def test_speed_bounds_scale_with_the_hand():
    """Linear DoFs get the speed bound, rotational ones that speed at a phalanx-sized lever."""
    env = gym.make("handsim/Grasp-v0", objects="025_mug", hand_size=0.2)
    env.reset(seed=0)
    model = env.unwrapped.scene.model
    bounds = divergence_speed_bounds(model, 0.2)
    angular = DIVERGENCE_SPEED_M_S / (DIVERGENCE_LEVER_RATIO * 0.2)
    for j in range(model.njnt):
        adr = model.jnt_dofadr[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            np.testing.assert_array_equal(bounds[adr : adr + 3], DIVERGENCE_SPEED_M_S)
            np.testing.assert_array_equal(bounds[adr + 3 : adr + 6], angular)
        else:
            assert bounds[adr] == angular
    assert divergence_speed_bounds(model, 0.15).max() > bounds.max()
    # The mug's DoFs get twice the bounds once the hand's DoFs are told from the objects'.
    root = model.body(env.unwrapped.scene.hand.root_body).id
    split = divergence_speed_bounds(model, 0.2, root)
    objects = model.body_rootid[model.dof_bodyid] != root
    assert objects.sum() == 6
    np.testing.assert_array_equal(split[objects], DIVERGENCE_OBJECT_FACTOR * bounds[objects])
    np.testing.assert_array_equal(split[~objects], bounds[~objects])
    env.close()


def _object_state(env, z_m, vel):
    """Place the target object at height z_m with velocity vel (6,) and step once."""
    scene = env.unwrapped.scene
    model, data = scene.model, scene.data
    body = scene.objects[0][0]
    joint = model.body(body).jntadr[0]
    data.qpos[model.jnt_qposadr[joint] + 2] = z_m
    data.qvel[model.jnt_dofadr[joint] : model.jnt_dofadr[joint] + 6] = vel
    mujoco.mj_forward(model, data)
    *_, truncated, info = env.step(env.unwrapped.target.vector)
    return truncated, info["physics_diverged"]


def test_a_fast_but_valid_object_is_not_divergence():
    """An object falling off the table, or struck into a fast spin, is valid physics.

    Measured with benchmarks/divergence_check.py on GraspClutter-v0 bang-bang episodes: every
    flag that did not end in a blow-up was an object knocked off the table, falling on (there
    is no floor) past the hand's 5 m/s.
    """
    env = gym.make("handsim/Grasp-v0", objects="025_mug", obs_mode="state")
    env.reset(seed=0)
    # 6 m below the table after a fall from 1 m above it: sqrt(2 g 7 m) = 11.7 m/s.
    fall = np.array([0.0, 0.0, -11.0, 0.0, 0.0, 0.0])
    assert _object_state(env, -6.0, fall) == (False, False)
    env.reset(seed=0)
    hand = env.unwrapped.scene.hand.params.hand_length
    spin = 1.5 * DIVERGENCE_SPEED_M_S / (DIVERGENCE_LEVER_RATIO * hand)  # 1.5x the hand's bound
    assert _object_state(env, 0.3, [0.0, 0.0, 0.0, 0.0, 0.0, spin]) == (False, False)
    env.close()


def test_an_object_blowing_up_is_divergence():
    """At the table, an object at 100 m/s (or spinning at 10^4 rad/s) has left valid physics."""
    env = gym.make("handsim/Grasp-v0", objects="025_mug", obs_mode="state")
    for vel in ([0.0, 0.0, -100.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1e4, 0.0, 0.0]):
        env.reset(seed=0)
        assert _object_state(env, 0.3, vel) == (True, True)
    env.close()


def _bang_bang(env_id, seed, hand_size, steps):
    """Alternate each action component between its bounds at random; check every step."""
    env = gym.make(env_id, hand_size=hand_size, obs_mode="state", **FAST.get(env_id, {}))
    obs, _ = env.reset(seed=seed)
    bounds = _hand_bounds(env)
    lo, hi = env.action_space.low, env.action_space.high
    rng = np.random.default_rng(seed)
    for step in range(steps):
        previous = obs
        obs, reward, terminated, truncated, info = env.step(np.where(rng.random(27) < 0.5, lo, hi))
        if info["physics_diverged"]:
            assert truncated and not terminated and reward == 0.0
            # The flagged step is the one in which the state blew up: MuJoCo warned, or the
            # state it ended in is past the bounds (the observation shows the last valid one).
            data = env.unwrapped.scene.data
            driver = env.unwrapped.driver
            warned = driver._divergence_count() > 0
            exploded = not np.all(np.abs(data.qvel) <= driver.speed_bounds())
            assert warned or exploded
            for key in obs:
                np.testing.assert_array_equal(obs[key], previous[key])
            with pytest.raises(PhysicsDiverged, match="call reset"):
                env.step(env.action_space.sample())
            env.reset(seed=seed)
            env.step(env.action_space.sample())  # a reset episode steps again
            env.close()
            return step
        # Every observation returned as valid is within the bounds.
        assert np.all(np.abs(obs["proprio"][27:]) <= bounds)
        if terminated or truncated:
            break
    env.close()
    return None


@pytest.mark.parametrize("seed", [101, 103])
def test_bang_bang_divergence_is_flagged_the_step_it_happens(seed):
    """The large hand (0.235 m) under random bang-bang actions (the issue's case).

    Every step returned as valid is within the bounds, and a blow-up (seeds 101 and 103 blew
    up at steps 29 and 8 when this was written) truncates the step in which it happens.
    """
    _bang_bang("handsim/HandPose-v0", seed, 0.235, 40)


def test_injected_blow_up_is_flagged_in_that_step():
    """Velocities past the bound (finite, MuJoCo does not warn) truncate that very step."""
    env = gym.make("handsim/HandPose-v0", obs_mode="state")
    obs, _ = env.reset(seed=0)
    env.step(env.action_space.sample())
    scene = env.unwrapped.scene
    dof = scene.binding.joint_dof[3]
    scene.data.qvel[dof] = 1e4
    _, _, _, truncated, info = env.step(env.unwrapped.target.vector)
    assert truncated and info["physics_diverged"]
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_stepping_after_divergence_raises_until_reset(env_id):
    """Every env refuses to step a diverged episode, with a HandSimError that says to reset."""
    env = gym.make(env_id, obs_mode="state", **FAST.get(env_id, {}))
    env.reset(seed=0)
    env.unwrapped.scene.data.qvel[:] = 1e30
    *_, truncated, info = env.step(env.action_space.sample())
    assert truncated and info["physics_diverged"]
    for _ in range(2):
        with pytest.raises(HandSimError, match=r"diverged at step 1 .*call reset\(\)"):
            env.step(env.action_space.sample())
    _, info = env.reset(seed=1)
    *_, info = env.step(env.action_space.sample())
    assert not info["physics_diverged"]
    env.close()


def test_set_state_recovers_a_diverged_episode():
    """Restoring a saved state is as good as a reset."""
    env = gym.make("handsim/HandPose-v0", obs_mode="state")
    env.reset(seed=0)
    state = env.unwrapped.get_state()
    env.unwrapped.scene.data.qvel[:] = 1e30
    assert env.step(env.action_space.sample())[-1]["physics_diverged"]
    env.unwrapped.set_state(state)
    assert not env.step(env.action_space.sample())[-1]["physics_diverged"]
    env.close()


def test_driver_refuses_to_step_after_divergence():
    """The scripted-episode loop shares the driver and its refusal."""
    env = gym.make("handsim/HandPose-v0", obs_mode="state")
    env.reset(seed=0)
    driver = HandDriver(env.unwrapped.scene)
    env.unwrapped.scene.data.qvel[:] = np.nan
    assert driver.step(10)
    with pytest.raises(PhysicsDiverged, match="call reset"):
        driver.step(10)
    env.close()


@pytest.mark.parametrize("hand_size", ["small", "large"])
def test_random_action_soak_does_not_diverge(hand_size):
    """Uniform random pose actions for 300 steps (6 s) stay stable and within the bounds."""
    env = gym.make("handsim/HandPose-v0", hand_size=hand_size, obs_mode="state")
    env.reset(seed=0)
    env.action_space.seed(0)
    bounds = _hand_bounds(env)
    for _ in range(300):
        obs, _, terminated, truncated, info = env.step(env.action_space.sample())
        assert not info["physics_diverged"]
        assert np.all(np.abs(obs["proprio"][27:]) <= bounds)
        if terminated or truncated:
            env.reset()
    env.close()


def test_a_reset_whose_settling_diverges_draws_again(monkeypatch):
    """A diverging settle never yields an episode that cannot be stepped; it is drawn again."""
    calls = []
    step = HandDriver.step

    def first_settle_diverges(self, n):
        calls.append(n)
        if len(calls) == 1:
            self.diverged = True
            return True
        return step(self, n)

    monkeypatch.setattr(HandDriver, "step", first_settle_diverges)
    env = gym.make("handsim/HandPose-v0", obs_mode="state")
    env.reset(seed=0)
    *_, info = env.step(env.action_space.sample())
    assert not info["physics_diverged"] and len(calls) == 3  # two settles, one step
    env.close()


def test_a_reset_that_keeps_diverging_says_so(monkeypatch):
    """After RESET_ATTEMPTS diverging draws, reset raises a PhysicsDiverged that says why."""

    def always_diverges(self, n):
        self.diverged = True
        return True

    monkeypatch.setattr(HandDriver, "step", always_diverges)
    env = gym.make("handsim/HandPose-v0", obs_mode="state")
    with pytest.raises(PhysicsDiverged, match=f"diverged while settling {RESET_ATTEMPTS} drawn"):
        env.reset(seed=0)
    env.close()
