"""Training data from env rollouts: the ``"rollout"`` source of :mod:`handsim.data.generation`.

:class:`RolloutSource` drives ``handsim/Grasp-v0``, ``handsim/GraspClutter-v0`` or
``handsim/HandPose-v0`` with the env's own scripted expert (``make_expert``) and labels every
``frame_stride``-th step of each episode, from the reset state on: hand-object frames with
physical contact (the contacts and their normal forces are in the labels). The core reaches it
by name (``GenerationConfig(source="rollout", env_id=...)``, or the ``grasp-rollouts`` preset)
and never imports this module itself.

Per episode, drawn from the shard's generator and so seeded and recorded like the kinematic
source: the hand length (uniform in ``hand_length_range_m`` on a 2 mm grid, so a hand is built
once per length), the side (left with probability ``left_fraction``), the camera viewpoint and
the env's reset seed (objects, placements and the task). The env viewpoints ``third_person``,
``egocentric`` and ``random`` are fixed for the episode, as a mounted sensor would be. The env
renders nothing itself (``obs_mode="state"``); the kept steps are rendered by the env's frame
renderer with the hand occlusion ratio, so the occlusion range and buckets apply as for the
kinematic source. Frames with fewer than
:data:`~handsim.data.generation.MIN_KEYPOINTS_IN_FRAME` keypoints in the image are skipped.

Occlusion by the held object (viewpoint ``through_object``): a physics step cannot be drawn
again, its viewpoint can. Every kept step draws up to :data:`VIEWS_PER_STEP` cameras beyond
the object nearest the hand, as seen from one of the hand's keypoints
(:func:`through_object_views`), at a distance in ``distance_range_m``, above the table and
beyond the camera's and the sensor's near range; each is rendered and the first frame the
occlusion control accepts is kept. A step none of whose views is accepted gives no frame (the
physics goes on); :attr:`RolloutSource.steps_without_view` counts them. The buckets apply to
every kept frame, those of the approach (object not yet held) included: the object lies
between camera and hand then too.

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
import mujoco
import numpy as np

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.data.arrays import frame_to_arrays
from handsim.data.generation import MIN_KEYPOINTS_IN_FRAME, CannotDraw, InvalidGenerationConfig
from handsim.data.kinematic import (
    MIN_EYE_HEIGHT_M,
    beyond_near,
    camera_on_line,
    near_geoms,
    near_range_m,
    through_object_direction,
)
from handsim.envs.config import VIEWPOINTS
from handsim.errors import HandSimError
from handsim.estimator import hand_center
from handsim.world.camera import camera_preset
from handsim.world.render import RENDERED_GEOM_GROUPS
from handsim.world.scene import OBJECT_LABEL_OFFSET

if TYPE_CHECKING:
    from handsim.data.generation import GenerationConfig
    from handsim.world.scene import Scene

__all__ = [
    "ROLLOUT_ENV_IDS",
    "ROLLOUT_VIEWPOINTS",
    "VIEWS_PER_STEP",
    "RolloutSource",
    "through_object_views",
]

ROLLOUT_ENV_IDS: tuple[str, ...] = (
    "handsim/Grasp-v0",
    "handsim/GraspClutter-v0",
    "handsim/HandPose-v0",
)
"""Envs the rollout source can drive (each has a scripted expert)."""
ROLLOUT_VIEWPOINTS: tuple[str, ...] = (*VIEWPOINTS, "through_object")
"""Viewpoints of the rollout source: the env's (fixed per episode) and ``through_object``."""
VIEWS_PER_STEP = 8
"""Camera placements drawn per kept step of a ``through_object`` episode before the step is
left without a frame."""


def _above_table(direction: np.ndarray, height_m: float, reach_m: float) -> np.ndarray:
    """``direction`` raised just enough that its ray stays above the table for ``reach_m``.

    A hand above the object (a grasp from the top) puts the line through the object into
    the table; the ray is raised (its heading kept) so that the eye stays
    :data:`~handsim.data.kinematic.MIN_EYE_HEIGHT_M` above the table top at ``reach_m``
    from the hand: the drawn distance plus the near range, the farthest
    :func:`~handsim.data.kinematic.beyond_near` may move it back.

    Args:
        direction: (3,) ray direction from the hand, world frame (any length).
        height_m: the hand's height above the table top (world z), metres.
        reach_m: distance along the ray that must stay above the table, metres.

    Returns:
        (3,) unit direction.
    """
    direction = direction / np.linalg.norm(direction)
    lowest = min((MIN_EYE_HEIGHT_M - height_m) / reach_m, 1.0)
    heading = np.hypot(direction[0], direction[1])
    if direction[2] >= lowest or heading == 0.0:
        return direction
    scale = np.sqrt(1.0 - lowest**2) / heading
    return np.array([direction[0] * scale, direction[1] * scale, lowest])


def through_object_views(
    scene: Scene, near_m: float, distance_range_m: tuple[float, float]
) -> Callable[[np.random.Generator], bool]:
    """A function that places the scene's camera ``"camera"`` beyond an object from the hand.

    Every call draws a view: one of the hand's 21 keypoints (from the palm, a top grasp's
    object hides nothing above the table; from a finger wrapped around it, the object hides
    that finger and those beside it), a distance in ``distance_range_m`` and a direction from
    the keypoint through the object nearest the hand centre
    (:func:`~handsim.data.kinematic.through_object_direction`), raised where it would meet the
    table (:func:`_above_table`). The camera looks at the keypoint from there, moved back
    beyond ``near_m`` (:func:`~handsim.data.kinematic.beyond_near`).

    Args:
        scene: a scene with a hand, objects and a camera named ``"camera"``; the function
            reads its current state (call it after every step).
        near_m: the near range of the camera and sensor, metres.
        distance_range_m: camera distance from the keypoint, metres.

    Returns:
        ``place(rng) -> bool``: True when the camera was placed (its pose written to the
        model and ``data.cam_xpos``), False (the camera untouched) when the view would be
        below the table top or when the first surface its line of sight to the keypoint meets
        is not an object's (the line was raised away from the object or turned beside it).
    """
    model, data = scene.model, scene.data
    cam = model.camera("camera").id
    bodies = np.array([model.body(name).id for name, _ in scene.objects], dtype=np.intp)
    geoms = near_geoms(scene)
    # mj_ray sees the geom groups the cameras render.
    rendered = np.zeros(6, dtype=np.uint8)
    rendered[list(RENDERED_GEOM_GROUPS)] = 1
    hit = np.zeros(1, dtype=np.int32)

    def place(rng: np.random.Generator) -> bool:
        keypoints = scene.binding.keypoints(data)
        objects = data.xpos[bodies]
        obj = objects[np.argmin(np.linalg.norm(objects - hand_center(keypoints), axis=1))]
        point = keypoints[rng.integers(len(keypoints))]
        distance = rng.uniform(*distance_range_m)
        direction = through_object_direction(rng, point, obj)
        direction = _above_table(direction, point[2], distance + near_m)
        eye, quat = camera_on_line(point, direction, distance)
        eye = beyond_near(scene, geoms, eye, point, near_m)
        if eye is None:
            return False
        # A raised line may miss the object (a hand high above it), a turned one pass beside
        # a thin one: no render for a view whose line of sight does not meet an object first.
        sight = point - eye
        reach = mujoco.mj_ray(model, data, eye, sight, rendered, 1, -1, hit)
        if not 0.0 <= reach < 1.0 or scene.geom_labels[hit[0]] < OBJECT_LABEL_OFFSET:
            return False
        model.cam_pos[cam], model.cam_quat[cam] = eye, quat
        mujoco.mj_camlight(model, data)
        return True

    return place


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
        self.steps_without_view = 0
        """Kept steps of ``through_object`` episodes none of whose views was accepted."""
        self.views_rendered = 0
        """Frames rendered, those the occlusion control refused included."""

    @classmethod
    def check_config(cls, config: GenerationConfig) -> None:
        """Raise :class:`InvalidGenerationConfig` for a field rollouts cannot honour."""
        env_id = config.env_id
        if env_id not in ROLLOUT_ENV_IDS:
            raise InvalidGenerationConfig(
                f"env_id must be one of {', '.join(ROLLOUT_ENV_IDS)} for source 'rollout'; "
                f"received {env_id!r}"
            )
        bad = [v for v in config.viewpoints if v not in ROLLOUT_VIEWPOINTS]
        if bad:
            raise InvalidGenerationConfig(
                f"viewpoints {bad} are not rollout viewpoints; source 'rollout' takes "
                f"{', '.join(ROLLOUT_VIEWPOINTS)}"
            )
        lo, hi = config.num_objects_range
        if hi == 0 and "through_object" in config.viewpoints:
            raise InvalidGenerationConfig(
                f"viewpoint 'through_object' needs objects; {env_id} has none (use "
                "handsim/Grasp-v0 or handsim/GraspClutter-v0, or another viewpoint)"
            )
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
            "skin_detail": c.skin_detail,
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
        through = view == "through_object"
        # The env draws these per episode from its config: pin them to this episode's draws.
        # (A through-object camera is placed per frame; the env's fixed one is not used.)
        base.config = dataclasses.replace(
            base.config,
            hand_size_m=(length, length),
            handedness=side,
            viewpoint="third_person" if through else view,
        )
        seed = int(rng.integers(2**63))
        env.reset(seed=seed)
        try:
            expert = base.make_expert(np.random.default_rng(seed))
        except HandSimError as err:  # e.g. no collision-free grasp of this object
            raise CannotDraw("grasp", str(err)) from err
        renderer = base.frame_renderer
        occlusion = bool(base.scene.objects)
        views = None
        if through:
            near_m = near_range_m(self.intrinsics, base.sensor)
            views = through_object_views(base.scene, near_m, c.distance_range_m)
        kept, step = 0, 0
        while kept < frames:
            if step % c.frame_stride == 0:
                for _ in range(VIEWS_PER_STEP if through else 1):
                    if through and not views(rng):
                        continue
                    frame = renderer.render(
                        rng, keep_clean=c.paired_clean, hand_occlusion=occlusion
                    )
                    self.views_rendered += 1
                    ratio = frame.hand_occlusion_ratio or 0.0
                    visible = int(frame.visible.sum())
                    if frame.in_frame.sum() >= MIN_KEYPOINTS_IN_FRAME and accept(ratio, visible):
                        arrays = frame_to_arrays(frame, images=True)
                        arrays["hand_occlusion_ratio"][()] = ratio
                        kept += 1
                        yield arrays
                        break
                else:
                    self.steps_without_view += int(through)
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
