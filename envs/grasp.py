"""``handsim/Grasp-v0`` and ``handsim/GraspClutter-v0``: pick up an object and hold it lifted."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from gymnasium import spaces

from handsim.envs.base import HandSimEnv
from handsim.envs.config import EnvConfig, InvalidEnvConfig
from handsim.envs.grasping import (
    FALL_HEIGHT_M,
    LIFT_HEIGHT_M,
    GraspExpert,
    GraspState,
    LiftTracker,
    start_pose,
)
from handsim.estimator import hand_center
from handsim.hand.pose import HandPose
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    InvalidScene,
    ObjectPlacement,
    sample_placements,
)

__all__ = ["GraspEnv", "GraspClutterEnv"]

_SINGLE_REGION_M = ((-0.08, 0.08), (-0.04, 0.08))
_CLUTTER_REGION_M = ((-0.22, 0.22), (-0.08, 0.22))


class GraspEnv(HandSimEnv):
    """Grasp one object on a table, lift it by 10 cm and hold it for 2 s.

    ## Description
    A physical right (or left) hand, its wrist softly welded to a mocap target and its 21
    joints position-actuated, starts open above the table on the user's side (``-y``) of a
    YCB-like object drawn from ``objects`` (all 21 YCB-Video objects by default), placed in a
    stable resting pose with a random yaw near the table centre. Grasps are physical: contact
    and friction only (see :mod:`handsim.envs.grasping`).

    ## Action Space
    ``Box(27)`` float32, as in :class:`~handsim.envs.hand_pose.HandPoseEnv`: wrist target
    position (m) and rotation vector (rad), then the 21 ``<side>_<joint>_act`` targets (rad);
    absolute (``"pose"``) or normalized deltas (``"delta"``), see :mod:`handsim.envs.base`.

    ## Observation Space
    ``Dict``: ``depth`` / ``segmentation`` / ``proprio`` / ``object_poses`` and
    ``object_present`` (``"privileged_state"``) by ``obs_mode`` (see
    :class:`~handsim.envs.base.HandSimEnv`) and ``target_label``:
    (1,) int16 in [8, 13], the segmentation label of the object to lift (8 + its instance).
    Except in ``"privileged_state"``, the object poses and every other label are in
    ``info["labels"]`` only.

    ## Rewards
    Dense (``reward_type="dense"``), the sum of:

    - ``reward_reach = -d``: ``d`` = distance from the hand centre (mean of the wrist and the
      four finger MCP keypoints) to the target's origin, metres;
    - ``reward_contact = 0.1 n``: ``n`` = number of hand parts (palm, five digits) touching
      the target;
    - ``reward_lift = min(h / 0.1, 1)`` for a rise ``h >= 0`` of the target above its rest
      height, metres;
    - ``reward_success = 10`` at the step the lift-and-hold succeeds.

    Sparse: ``reward_success = 1`` at that step, else 0. ``info`` also has ``is_success``,
    ``lift_m``, ``slip_m`` and ``turn_rad`` (the object's largest displacement and rotation in
    the palm frame during the hold window, :class:`~handsim.envs.grasping.LiftTracker`),
    ``hold_s``, ``n_contact_parts`` and ``target_instance``.

    ## Starting State
    :func:`handsim.envs.grasping.start_pose`: open hand, palm down, 0.22 m from the object
    toward the user, jittered by 2 cm and 5 deg; the physics then settles for 0.1 s.

    ## Episode End
    Terminated when the lift succeeds (risen >= 0.10 m, then held 2 s with < 1 cm slip and
    < 10 deg turn in the palm frame, both from the hold window's first step;
    :class:`~handsim.envs.grasping.LiftTracker`) or when the target falls off the
    table (its origin below z = -0.05 m). Truncated after ``max_episode_steps`` (400 = 8 s) or
    on physics divergence (``info["physics_diverged"]``).

    ## Arguments
    ``objects`` (a name, a list of names, or ``"ycbv"``) and the shared arguments of
    :class:`~handsim.envs.config.EnvConfig`.

    ## Version History

    - v0: initial version. Added later under v0, every default unchanged: ``labels``,
      ``width``/``height``, ``depth_format``, ``channel_axis`` (opt-in ``(1, H, W)`` images),
      ``render_width``/``render_height`` and ``obs_mode="privileged_state"``. The image
      observation keeps its ``(H, W)`` float32 default: the estimators, the closed loop and
      the datasets take that form, so the channel axis is an option rather than a new version.
      Rendering only: ``rgb_array``/``depth_array`` come from a viewer camera framing the hand
      and objects (``depth_array``: (H, W) metres; ``depth_rgb_array``: colour), ``"human"`` is
      declared only with a display; in the state modes there are no labels unless
      ``labels=True``. Info only: the labels are ``info["labels"]`` (arrays, the same keys at
      reset, every step and a diverged step, for Minari) instead of a ``Frame`` in
      ``info["frame"]``; the Frame is ``env.unwrapped.frame``. Success test: the hold also
      fails when the object turns 10 deg or more in the palm frame (``info["turn_rad"]``), and
      slip and turn are measured over the whole window from its first step; a window that
      slipped or turned is not restarted while the object stays lifted (before, a new window
      with a new reference opened at the slipping step).
    """

    max_objects = 1

    def __init__(self, *, objects: object = "ycbv", **kwargs: Any) -> None:
        super().__init__(EnvConfig.from_kwargs(objects=objects, min_objects=1, **kwargs))
        self.target_instance = 0
        self.tracker: LiftTracker | None = None

    # Episode ---------------------------------------------------------------------------------

    def _episode_names(self, rng: np.random.Generator) -> tuple[list[str], int]:
        """Object names of this episode and the target's index among them."""
        pool = self.config.objects
        return [pool[rng.integers(len(pool))]], 0

    def _placement_region(self) -> tuple[tuple[float, float], tuple[float, float]]:
        return _SINGLE_REGION_M

    def _episode_objects(self, rng: np.random.Generator) -> tuple[ObjectPlacement, ...]:
        # Large objects may not all fit: draw another set (the draws stay seeded).
        for _ in range(20):
            names, self.target_instance = self._episode_names(rng)
            try:
                return sample_placements(rng, names, region_m=self._placement_region())
            except InvalidScene:
                continue
        raise InvalidEnvConfig(
            f"could not place {len(names)} of the objects {self.config.objects} on the table "
            "in 20 draws; use fewer or smaller objects"
        )

    def _reset_task(self, rng: np.random.Generator) -> HandPose:
        obj = self.scene.objects[self.target_instance][1]
        T = self._object_pose(self.target_instance)
        self.tracker = None  # made after the settling steps (the rest height is measured then)
        others = tuple(
            (other, self._object_pose(k))
            for k, (_, other) in enumerate(self.scene.objects)
            if k != self.target_instance
        )
        return start_pose(rng, T, self.scene.hand.params, obj=obj, obstacles=others)

    def _object_pose(self, instance: int) -> np.ndarray:
        body = self.scene.model.body(self.scene.objects[instance][0]).id
        data = self.scene.data
        T = np.eye(4)
        T[:3, :3] = data.xmat[body].reshape(3, 3)
        T[:3, 3] = data.xpos[body]
        return T

    def _begin_task(self) -> None:
        rest_height = self._object_pose(self.target_instance)[2, 3]
        self.tracker = LiftTracker(rest_height)
        self._episode_start_s = float(self.scene.data.time)

    # Observation, reward ---------------------------------------------------------------------

    def _task_observation_space(self) -> dict[str, spaces.Space]:
        top = OBJECT_LABEL_OFFSET + GraspClutterEnv.max_objects - 1
        return {"target_label": spaces.Box(OBJECT_LABEL_OFFSET, top, (1,), np.int16)}

    def _task_observation(self) -> dict[str, np.ndarray]:
        return {"target_label": np.array([OBJECT_LABEL_OFFSET + self.target_instance], np.int16)}

    def _contact_parts(self) -> int:
        """Hand parts touching the target (the frame's contacts), read from the physics."""
        scene, data = self.scene, self.scene.data
        if data.ncon == 0:
            return 0
        geoms = data.contact.geom[: data.ncon]
        bodies = scene.model.geom_bodyid[geoms]
        labels = scene.geom_labels[geoms]
        target = scene.model.body(scene.objects[self.target_instance][0]).id
        is_hand = (labels >= SEGMENT_LABELS.index("palm")) & (labels < OBJECT_LABEL_OFFSET)
        parts = set(labels[:, 0][is_hand[:, 0] & (bodies[:, 1] == target)].tolist())
        parts |= set(labels[:, 1][is_hand[:, 1] & (bodies[:, 0] == target)].tolist())
        return len(parts)

    def _task_info(self) -> dict[str, Any]:
        outcome = self.tracker.outcome()
        return {
            "is_success": bool(self.tracker.success),
            "lift_m": float(
                self._object_pose(self.target_instance)[2, 3] - self.tracker.rest_height_m
            ),
            "slip_m": outcome.slip_m,
            "turn_rad": outcome.turn_rad,
            "hold_s": outcome.hold_s,
            "n_contact_parts": self._contact_parts(),
            "target_instance": self.target_instance,
        }

    def _reward_terms(self) -> tuple[str, ...]:
        if self.config.reward_type == "dense":
            return ("reward_reach", "reward_contact", "reward_lift", "reward_success")
        return ("reward_success",)

    def _task_reward(self) -> tuple[dict[str, float], bool, dict[str, Any]]:
        scene, data = self.scene, self.scene.data
        was_success = self.tracker.success
        time_s = data.time - self._episode_start_s
        success = self.tracker.update_from_sim(scene, self.target_instance, time_s)
        obj_pos = self._object_pose(self.target_instance)[:3, 3]
        just_succeeded = success and not was_success
        info = self._task_info()
        if self.config.reward_type == "dense":
            center = hand_center(scene.binding.keypoints(data))
            terms = {
                "reward_reach": -float(np.linalg.norm(center - obj_pos)),
                "reward_contact": 0.1 * info["n_contact_parts"],
                "reward_lift": float(np.clip(info["lift_m"] / LIFT_HEIGHT_M, 0.0, 1.0)),
                "reward_success": 10.0 * just_succeeded,
            }
        else:
            terms = {"reward_success": float(just_succeeded)}
        fallen = obj_pos[2] < FALL_HEIGHT_M
        return terms, bool(success or fallen), info

    # Experts ---------------------------------------------------------------------------------

    def expert_state(
        self,
        hand_pose: HandPose | None = None,
        keypoints_world: np.ndarray | None = None,
        T_world_from_obj: np.ndarray | None = None,
    ) -> GraspState:
        """The grasp expert's state: the truth, or the given (estimated) values in its place.

        The joint angles the hand's own sensors read (``joint_angles_rad``) stay the truth: an
        estimated hand pose replaces what is perceived, not proprioception.
        """
        time_s = float(self.scene.data.time - self._episode_start_s)
        truth = GraspState.from_sim(self.scene, self.target_instance, time_s)
        estimated = {
            "hand_pose": hand_pose,
            "keypoints_world": keypoints_world,
            "T_world_from_obj": T_world_from_obj,
        }
        estimated = {k: v for k, v in estimated.items() if v is not None}
        return dataclasses.replace(truth, **estimated) if estimated else truth

    def make_expert(
        self, rng: np.random.Generator | None = None, state: GraspState | None = None
    ) -> GraspExpert:
        """A :class:`~handsim.envs.grasping.GraspExpert` planned for this episode's target.

        Args:
            rng: the expert's generator (``None``: no speed jitter).
            state: the state it plans from (default: the truth, :meth:`expert_state`).
        """
        obj = self.scene.objects[self.target_instance][1]
        # A number is the physics' friction: the grip is sized for it (else for skin).
        friction = self.config.object_friction
        expert = GraspExpert(
            obj,
            self.scene.hand.params,
            rng=rng,
            friction=friction if isinstance(friction, float) else None,
        )
        expert.reset(state if state is not None else self.expert_state())
        return expert


class GraspClutterEnv(GraspEnv):
    """Grasp a named target among 3-6 objects, lift it by 10 cm and hold it for 2 s.

    ## Description
    As :class:`GraspEnv`, with ``num_objects`` (default 3 to 6) distinct objects drawn from
    ``objects`` and placed without overlap on a wider area of the table; one of them, drawn
    uniformly, is the target. The others occlude the hand and the target from the camera and
    may be in the way.

    ## Action Space
    As :class:`GraspEnv`.

    ## Observation Space
    As :class:`GraspEnv`; ``target_label`` names the target (8 + its instance), and the
    segmentation bound covers six objects.

    ## Rewards
    As :class:`GraspEnv`, for the target.

    ## Starting State
    As :class:`GraspEnv`, relative to the target.

    ## Episode End
    As :class:`GraspEnv`.

    ## Arguments
    ``num_objects``: an int or an inclusive (low, high) range within [1, 6]; ``objects``
    (default ``"ycbv"``) must hold at least ``high`` names; and the shared arguments of
    :class:`~handsim.envs.config.EnvConfig`.

    ## Version History

    - v0: initial version. Added later under v0, every default unchanged: ``labels``,
      ``width``/``height``, ``depth_format``, ``channel_axis`` (opt-in ``(1, H, W)`` images),
      ``render_width``/``render_height`` and ``obs_mode="privileged_state"``. The image
      observation keeps its ``(H, W)`` float32 default: the estimators, the closed loop and
      the datasets take that form, so the channel axis is an option rather than a new version.
      Rendering only: ``rgb_array``/``depth_array`` come from a viewer camera framing the hand
      and objects (``depth_array``: (H, W) metres; ``depth_rgb_array``: colour), ``"human"`` is
      declared only with a display; in the state modes there are no labels unless
      ``labels=True``. Info only: the labels are ``info["labels"]`` (arrays, the same keys at
      reset, every step and a diverged step, for Minari) instead of a ``Frame`` in
      ``info["frame"]``; the Frame is ``env.unwrapped.frame``. Success test: as
      :class:`GraspEnv` (slip and turn over the whole hold window).
    """

    max_objects = 6

    def __init__(
        self, *, objects: object = "ycbv", num_objects: object = (3, 6), **kwargs: Any
    ) -> None:
        if isinstance(num_objects, (int, np.integer)) and not isinstance(num_objects, bool):
            num_objects = (int(num_objects), int(num_objects))
        try:
            lo, hi = num_objects  # type: ignore[misc]
            if not all(
                isinstance(n, (int, np.integer)) and not isinstance(n, bool) for n in (lo, hi)
            ):
                raise TypeError  # a float bound would be truncated
            lo, hi = int(lo), int(hi)
        except (TypeError, ValueError):
            raise InvalidEnvConfig(
                f"num_objects must be an int or a (low, high) pair in [1, 6]; received "
                f"{num_objects!r}"
            ) from None
        if not 1 <= lo <= hi <= self.max_objects:
            raise InvalidEnvConfig(
                f"num_objects must satisfy 1 <= low <= high <= 6; received ({lo}, {hi})"
            )
        self.num_objects = (lo, hi)
        super().__init__(objects=objects, **kwargs)
        repeated = sorted({n for n in self.config.objects if self.config.objects.count(n) > 1})
        if repeated:
            # The pool is drawn without replacement: a repeated name would put copies of one
            # object in the scene, which is documented to hold distinct objects.
            raise InvalidEnvConfig(
                f"objects must name distinct objects (a clutter scene holds distinct ones); "
                f"{', '.join(repeated)} is given more than once in {list(self.config.objects)}"
            )
        if len(self.config.objects) < hi:
            raise InvalidEnvConfig(
                f"num_objects up to {hi} needs at least {hi} object names; received "
                f"{len(self.config.objects)}: {self.config.objects}"
            )

    def _episode_names(self, rng: np.random.Generator) -> tuple[list[str], int]:
        lo, hi = self.num_objects
        n = int(rng.integers(lo, hi + 1))
        pool = self.config.objects
        names = [pool[i] for i in rng.choice(len(pool), size=n, replace=False)]
        return names, int(rng.integers(n))

    def _placement_region(self) -> tuple[tuple[float, float], tuple[float, float]]:
        return _CLUTTER_REGION_M
