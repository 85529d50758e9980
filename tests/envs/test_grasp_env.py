"""Grasp-v0 and GraspClutter-v0: the task, its arguments and physical grasps in the env."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.config import InvalidEnvConfig
from handsim.envs.grasping import InvalidGraspState
from handsim.errors import UnknownName
from handsim.world.scene import OBJECT_LABEL_OFFSET


def test_grasp_expert_lifts_and_the_episode_terminates_with_success():
    """The expert lifts a can; the episode ends with success and one success reward."""
    env = gym.make("handsim/Grasp-v0", objects="tomato_soup_can")
    env.reset(seed=0)
    expert = env.unwrapped.make_expert()
    success_rewards = 0.0
    for _ in range(400):
        _, _, terminated, truncated, info = env.step(
            expert.act(env.unwrapped.expert_state()).vector
        )
        success_rewards += info["reward_success"]
        if terminated or truncated:
            break
    assert terminated and info["is_success"] and success_rewards == 10.0
    assert info["lift_m"] >= 0.10 and info["slip_m"] < 0.01 and info["hold_s"] >= 2.0 - 1e-9
    assert info["n_contact_parts"] >= 3
    env.close()


@pytest.mark.parametrize("env_id", sorted(k for k in gym.registry if k.startswith("handsim/")))
def test_every_env_defaults_to_skin_friction(env_id):
    """Without object_friction, each object's contacts have skin on its material."""
    from handsim.envs.physics import skin_friction

    env = gym.make(env_id, **({"num_objects": (3, 3)} if "Clutter" in env_id else {}))
    assert env.unwrapped.config.object_friction == "skin"
    env.reset(seed=0)
    scene = env.unwrapped.scene
    model = scene.model
    for body, obj in scene.objects:  # none in HandPose-v0 and Press-v0
        geoms = (model.geom_bodyid == model.body(body).id) & (model.geom_contype != 0)
        np.testing.assert_array_equal(model.geom_friction[geoms, 0], skin_friction(obj.name))
        assert (model.geom_priority[geoms] == 1).all() and (model.geom_condim[geoms] == 4).all()
    env.close()


@pytest.mark.parametrize("friction", ["mujoco", "skin", 0.5])
def test_object_friction_reaches_the_physics_and_the_expert(friction):
    """object_friction sets every object's contact friction; a number also sizes the grip."""
    from handsim.envs.physics import skin_friction

    env = gym.make("handsim/Grasp-v0", objects="cracker_box", object_friction=friction)
    env.reset(seed=0)
    scene = env.unwrapped.scene
    body, obj = scene.objects[0]
    model = scene.model
    geoms = (model.geom_bodyid == model.body(body).id) & (model.geom_contype != 0)
    expected = {"mujoco": 1.0, "skin": skin_friction(obj.name), 0.5: 0.5}[friction]
    np.testing.assert_array_equal(model.geom_friction[geoms, 0], expected)
    assert (model.geom_priority[geoms] == (0 if friction == "mujoco" else 1)).all()
    assert (model.geom_condim[geoms] == (3 if friction == "mujoco" else 4)).all()
    expert = env.unwrapped.make_expert()
    assert expert.friction == (0.5 if friction == 0.5 else skin_friction(obj.name))
    env.reset(seed=1)  # the scene is kept between episodes: the friction stays
    np.testing.assert_array_equal(scene.model.geom_friction[geoms, 0], expected)
    env.close()


def test_grasps_are_physical_in_the_env():
    """No equality constraint of the env's model involves an object body."""
    env = gym.make("handsim/GraspClutter-v0", num_objects=3)
    env.reset(seed=0)
    model = env.unwrapped.scene.model
    object_bodies = {model.body(body).id for body, _ in env.unwrapped.scene.objects}
    for i in range(model.neq):
        assert model.eq_obj1id[i] not in object_bodies and model.eq_obj2id[i] not in object_bodies
    env.close()


def test_clutter_target_label_names_the_target():
    """The target label is the first object label + the target's instance (num_objects)."""
    env = gym.make("handsim/GraspClutter-v0", num_objects=(4, 4), obs_mode="depth+segmentation")
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        base = env.unwrapped
        assert len(base.scene.objects) == 4
        assert obs["target_label"][0] == OBJECT_LABEL_OFFSET + info["target_instance"]
        assert info["target_instance"] == base.target_instance
    env.close()


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"num_objects": 7}, InvalidEnvConfig, "1 <= low <= high <= 6; received \\(7, 7\\)"),
        ({"num_objects": "many"}, InvalidEnvConfig, "an int or a \\(low, high\\) pair"),
        (
            {"num_objects": 3, "objects": ["mug", "bowl"]},
            InvalidEnvConfig,
            "needs at least 3 object names; received 2",
        ),
        ({"objects": "tomato_soup_cna"}, UnknownName, "Did you mean 'tomato_soup_can'"),
    ],
)
def test_clutter_arguments(kwargs, error, message):
    """Bad clutter arguments say what is valid."""
    with pytest.raises(error, match=message):
        gym.make("handsim/GraspClutter-v0", **kwargs)


def test_hand_pose_env_refuses_objects():
    """HandPose-v0 has no objects; passing some says so."""
    with pytest.raises(TypeError, match="HandPose-v0 has no objects"):
        gym.make("handsim/HandPose-v0", objects="mug")


def test_sparse_reward_is_zero_until_success():
    """Sparse rewards are 0 while the object rests on the table."""
    env = gym.make("handsim/Grasp-v0", objects="mug", reward_type="sparse")
    env.reset(seed=0)
    rewards = [env.step(np.asarray(env.unwrapped.target.vector))[1] for _ in range(5)]
    assert rewards == [0.0] * 5
    env.close()


def test_an_estimated_hand_pose_leaves_proprioception_true():
    """expert_state(hand_pose=estimate) replaces the perceived pose, not the joint sensors."""
    env = gym.make("handsim/Grasp-v0", objects="mustard_bottle", obs_mode="state")
    env.reset(seed=0)
    base = env.unwrapped
    truth = base.expert_state()
    np.testing.assert_array_equal(truth.joint_angles_rad, truth.hand_pose.angles)
    estimate = truth.hand_pose.replace(angles=truth.hand_pose.angles + 0.2)
    state = base.expert_state(hand_pose=estimate)
    np.testing.assert_array_equal(state.hand_pose.angles, estimate.angles)
    np.testing.assert_array_equal(state.joint_angles_rad, truth.joint_angles_rad)
    with pytest.raises(InvalidGraspState, match=r"joint_angles_rad must be a finite \(21,\) array"):
        dataclasses.replace(truth, joint_angles_rad=np.zeros(20))
    env.close()
