"""Training data from env rollouts: the ``"rollout"`` source of :mod:`handsim.data.generation`.

:class:`RolloutSource` drives ``handsim/Grasp-v0``, ``handsim/GraspClutter-v0`` or
``handsim/HandPose-v0`` with the env's own scripted expert (``make_expert``) and labels every
``frame_stride``-th step of each episode, from the reset state on: hand-object frames with
physical contact (the contacts and their normal forces are in the labels). The core reaches it
by name (``GenerationConfig(source="rollout", env_id=...)``, or the ``grasp-rollouts`` preset)
and never imports this module itself.

Per episode, drawn from the shard's generator and so seeded and recorded like the kinematic
source: the hand length (uniform in ``hand_length_range_m`` on a 2 mm grid, so a hand is built
once per length), the side (left with probability ``left_fraction``), the camera viewpoint (one
of the env viewpoints ``third_person``, ``egocentric`` or ``random``, fixed for the episode as a
mounted sensor would be) and the env's reset seed (objects, placements and the task). The env
renders nothing itself (``obs_mode="state"``); the kept steps are rendered by the env's frame
renderer with the hand occlusion ratio, so the occlusion range and buckets apply as for the
kinematic source. Frames with fewer than
:data:`~handsim.data.generation.MIN_KEYPOINTS_IN_FRAME` keypoints in the image are skipped.

An episode ends at the env's termination or truncation (success, a fallen object, the time
limit, diverged physics), or when ``frames_per_episode`` frames are kept; an episode whose
expert finds no plan raises :class:`~handsim.data.config.CannotDraw` (``"grasp"``): the shard
counts it and draws the next episode. The visible-keypoint cap applies as for kinematic frames.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import gymnasium as gym
import numpy as np

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.data.arrays import frame_to_arrays
from handsim.data.generation import MIN_KEYPOINTS_IN_FRAME, CannotDraw, InvalidGenerationConfig
from handsim.envs.config import VIEWPOINTS
from handsim.errors import HandSimError
from handsim.world.camera import camera_preset

if TYPE_CHECKING:
    from handsim.data.generation import GenerationConfig

__all__ = ["ROLLOUT_ENV_IDS", "RolloutSource"]

ROLLOUT_ENV_IDS: tuple[str, ...] = (
    "handsim/Grasp-v0",
    "handsim/GraspClutter-v0",
    "handsim/HandPose-v0",
)
"""Envs the rollout source can drive (each has a scripted expert)."""


class RolloutSource:
    """Frames of env episodes driven by the env's expert (see the module docstring).

    Args:
        config: the generation config (``source="rollout"``, ``env_id`` one of
            :data:`ROLLOUT_ENV_IDS`).

    Raises:
        InvalidGenerationConfig: for a field this source cannot honour (named).
    """

    def __init__(self, config: GenerationConfig) -> None:
        self.check_config(config)
        self.config = config
        self.intrinsics = camera_preset(config.camera)
        self._env: gym.Env | None = None

    @classmethod
    def check_config(cls, config: GenerationConfig) -> None:
        """Raise :class:`InvalidGenerationConfig` for a field rollouts cannot honour."""
        env_id = config.env_id
        if env_id not in ROLLOUT_ENV_IDS:
            raise InvalidGenerationConfig(
                f"env_id must be one of {', '.join(ROLLOUT_ENV_IDS)} for source 'rollout'; "
                f"received {env_id!r}"
            )
        bad = [v for v in config.viewpoints if v not in VIEWPOINTS]
        if bad:
            raise InvalidGenerationConfig(
                f"viewpoints {bad} are not env viewpoints; source 'rollout' takes "
                f"{', '.join(VIEWPOINTS)}"
            )
        lo, hi = config.num_objects_range
        needed = {
            "handsim/Grasp-v0": "(1, 1) (one object)",
            "handsim/HandPose-v0": "(0, 0) (no objects)",
        }
        ok = {
            "handsim/Grasp-v0": (lo, hi) == (1, 1),
            "handsim/HandPose-v0": (lo, hi) == (0, 0),
            "handsim/GraspClutter-v0": 1 <= lo and hi <= min(6, len(config.objects)),
        }[env_id]
        if not ok:
            valid = needed.get(env_id, "1 <= low <= high <= min(6, number of objects)")
            raise InvalidGenerationConfig(
                f"num_objects_range must be {valid} for {env_id}; received {(lo, hi)}"
            )
        if hi == 0 and (config.occlusion_range[0] > 0 or config.occlusion_buckets is not None):
            raise InvalidGenerationConfig(
                f"{env_id} has no objects, so the hand occlusion ratio is 0: occlusion_range "
                "and occlusion_buckets need an env with objects"
            )

    def _make_env(self) -> gym.Env:
        c = self.config
        kwargs: dict = {
            "camera": c.camera,
            "sensor": c.sensor,
            "obs_mode": "state",
            "labels": False,
            "hand_size": c.hand_length_range_m,
        }
        if c.env_id != "handsim/HandPose-v0":
            kwargs["objects"] = list(c.objects)
        if c.env_id == "handsim/GraspClutter-v0":
            kwargs["num_objects"] = tuple(c.num_objects_range)
        return gym.make(c.env_id, **kwargs)

    def episode(
        self, rng: np.random.Generator, accept: Callable[[float, int], bool], frames: int
    ) -> Iterator[dict[str, np.ndarray]]:
        """Yield the arrays (images included) of up to ``frames`` accepted frames of one episode.

        Args:
            rng: the episode's generator (episode draws, env seed, sensor noise).
            accept: called with the hand occlusion ratio and the number of visible keypoints;
                False skips the step's frame.
            frames: most frames to yield.

        Raises:
            CannotDraw: ``"grasp"`` when the expert finds no grasp of the episode's object
                (the shard redraws the episode).
        """
        c = self.config
        if self._env is None:
            self._env = self._make_env()
        env, base = self._env, self._env.unwrapped
        lo, hi = c.hand_length_range_m
        length = float(np.clip(np.round(rng.uniform(lo, hi) / 0.002) * 0.002, lo, hi))
        side = "left" if rng.random() < c.left_fraction else "right"
        view = str(rng.choice(c.viewpoints))
        # The env draws these per episode from its config: pin them to this episode's draws.
        base.config = dataclasses.replace(
            base.config, hand_size_m=(length, length), handedness=side, viewpoint=view
        )
        seed = int(rng.integers(2**63))
        env.reset(seed=seed)
        try:
            expert = base.make_expert(np.random.default_rng(seed))
        except HandSimError as err:  # e.g. no collision-free grasp of this object
            raise CannotDraw("grasp", str(err)) from err
        renderer = base.frame_renderer
        occlusion = bool(base.scene.objects)
        kept, step = 0, 0
        while kept < frames:
            if step % c.frame_stride == 0:
                frame = renderer.render(rng, keep_clean=c.paired_clean, hand_occlusion=occlusion)
                ratio = frame.hand_occlusion_ratio or 0.0
                visible = int(frame.visible.sum())
                if frame.in_frame.sum() >= MIN_KEYPOINTS_IN_FRAME and accept(ratio, visible):
                    arrays = frame_to_arrays(frame, images=True)
                    arrays["hand_occlusion_ratio"][()] = ratio
                    kept += 1
                    yield arrays
            action = expert.act(base.expert_state()).vector
            _, _, terminated, truncated, _ = env.step(action)
            step += 1
            if terminated or truncated:
                return

    def close(self) -> None:
        """Close the env (its renderers)."""
        if self._env is not None:
            self._env.close()
            self._env = None
