"""Gymnasium environments of handsim (imported as ``handsim.envs``).

Importing this package registers the envs; make them with ``gymnasium.make``::

    import gymnasium as gym
    import handsim.envs  # noqa: F401 (registers the ids)

    env = gym.make("handsim/Grasp-v0", objects="mustard_bottle", obs_mode="depth+state")

========================  ==================================================  =============
id                        task                                                episode steps
========================  ==================================================  =============
handsim/HandPose-v0       the hand alone reaches a goal hand pose             150 (3 s)
handsim/Grasp-v0          grasp one object on a table, lift 10 cm, hold 2 s   400 (8 s)
handsim/GraspClutter-v0   the same for a named target among 3-6 objects       400 (8 s)
handsim/Press-v0          press a push button or move a slider on a panel     250 (5 s)
handsim/PressTwoHands-v0  press two buttons at once, one with each hand       250 (5 s)
========================  ==================================================  =============

Episode lengths are at the default ``frame_skip=10`` (50 Hz control).

Vector envs: ``gym.make_vec("handsim/Grasp-v0", num_envs=2, vectorization_mode="async")``
works with the default start method (fork on Linux) and with
``vector_kwargs={"context": "spawn"}`` or ``"forkserver"``; OpenGL contexts are made in the
process that renders (:mod:`handsim.envs.base`). With ``AsyncVectorEnv`` and spawned workers
use the ``module:id`` form, ``gym.make("handsim.envs:handsim/Grasp-v0")``, which registers the
ids in the worker.

Scripted experts through ``gym.make``'s wrappers: ``env.get_wrapper_attr("make_expert")()`` (or
``env.unwrapped.make_expert()``); Gymnasium 1.x does not forward attributes.
"""

from gymnasium.envs.registration import register

ENV_IDS: tuple[str, ...] = (
    "handsim/HandPose-v0",
    "handsim/Grasp-v0",
    "handsim/GraspClutter-v0",
    "handsim/Press-v0",
)
"""Every registered one-hand id (27-D actions)."""
TWO_HAND_ENV_IDS: tuple[str, ...] = ("handsim/PressTwoHands-v0",)
"""The registered two-hand ids (a right and a left hand; 54-D actions, right then left)."""

register(
    id="handsim/HandPose-v0",
    entry_point="handsim.envs.hand_pose:HandPoseEnv",
    max_episode_steps=150,
)
register(
    id="handsim/Grasp-v0",
    entry_point="handsim.envs.grasp:GraspEnv",
    max_episode_steps=400,
)
register(
    id="handsim/GraspClutter-v0",
    entry_point="handsim.envs.grasp:GraspClutterEnv",
    max_episode_steps=400,
)
register(
    id="handsim/Press-v0",
    entry_point="handsim.envs.press:PressEnv",
    max_episode_steps=250,
)
register(
    id="handsim/PressTwoHands-v0",
    entry_point="handsim.envs.press_two_hands:TwoHandPressEnv",
    max_episode_steps=250,
)
