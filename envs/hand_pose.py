"""``handsim/HandPose-v0``: the hand alone in front of the camera reaches a goal hand pose."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from scipy.spatial.transform import Rotation

from handsim.envs.base import _POSE_HI, _POSE_LO, HandSimEnv
from handsim.envs.config import EnvConfig
from handsim.envs.experts import GestureExpert, HandState
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import GESTURES, gesture

__all__ = ["HandPoseEnv"]

HAND_HOME_M = np.array([0.0, -0.08, 0.12])
"""Centre of the start and goal wrist positions, world frame, metres."""
PALM_DOWN_ROTVEC = np.array([0.0, np.pi, 0.0])
"""Hand frame -> world: palm (hand +z) facing down, fingers (hand +y) toward +y."""


class HandPoseEnv(HandSimEnv):
    """Reach a goal hand pose.

    ## Description
    A physical hand (27 DoF: a free wrist softly welded to a mocap target, 21 position-actuated
    joints) floats in front of a depth camera; there is no table and no object. Each episode
    draws a goal: a gesture of :data:`~handsim.hand.pose_sources.GESTURES` with 2 deg angle noise,
    its wrist within 3 cm and 30 deg of the start. The hand must reach it.

    ## Action Space
    ``Box(27)`` float32, see :mod:`handsim.envs.base` for both control modes:

    ======  ============================================  =====  =========================
    index   element                                       unit   ``"pose"`` bounds
    ======  ============================================  =====  =========================
    0-2     wrist target position (mocap ``rh_mocap``)    m      :data:`WORKSPACE_M`
    3-5     wrist target rotation vector                  rad    [-pi, pi] each
    6-26    ``<side>_<joint>_act`` targets (JOINT_NAMES)  rad    joint limits (JOINT_LIMITS)
    ======  ============================================  =====  =========================

    ## Observation Space
    ``Dict``: ``depth`` / ``segmentation`` / ``proprio`` by ``obs_mode`` (see
    :class:`~handsim.envs.base.HandSimEnv`; ``"privileged_state"`` equals ``"state"`` here: there
    are no objects) and ``goal``: (27,) float64 goal pose vector
    (world frame). Labels (keypoints, visibility, ...) are in ``info["labels"]``, never in the
    observation.

    ## Rewards
    ``d`` = mean distance between the 21 keypoints and the goal's keypoints, metres.

    - dense: ``reward_distance = -10 d`` plus ``reward_success = 1`` when ``d <`` 10 mm;
    - sparse: ``reward_success`` only (1 when ``d <`` 10 mm, else 0).

    The reward equals the sum of the ``info["reward_*"]`` terms. ``info`` also has
    ``keypoint_distance_m`` and ``is_success``.

    ## Starting State
    The ``"open"`` gesture, palm down, wrist at :data:`HAND_HOME_M` with 2 cm and 15 deg jitter;
    the physics then settles for 0.1 s.

    ## Episode End
    Not terminated; truncated after ``max_episode_steps`` (150 = 3 s at the default frame
    skip) or on physics divergence (``info["physics_diverged"]``).

    ## Arguments
    ``hand_size``, ``handedness``, ``camera``, ``viewpoint``, ``sensor``, ``obs_mode``,
    ``control_mode``, ``reward_type``, ``frame_skip``, ``render_mode``, ``labels``, ``width``,
    ``height``, ``depth_format``, ``channel_axis``, ``render_width``, ``render_height``: see
    :class:`~handsim.envs.config.EnvConfig` (the reference with every valid value is
    ``docs/envs.md``).

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
      ``info["frame"]``; the Frame is ``env.unwrapped.frame``.
    """

    use_table = False
    success_distance_m = 0.010

    def __init__(self, **kwargs: Any) -> None:
        if "objects" in kwargs:
            raise TypeError("HandPose-v0 has no objects; remove the 'objects' argument")
        super().__init__(EnvConfig.from_kwargs(**kwargs))
        self.goal = HandPose.neutral()
        self._goal_keypoints = np.zeros((21, 3))
        self._fk: ForwardKinematics | None = None

    def _task_observation_space(self) -> dict[str, spaces.Space]:
        return {"goal": spaces.Box(_POSE_LO, _POSE_HI, (27,), np.float64)}

    def _task_observation(self) -> dict[str, np.ndarray]:
        return {"goal": np.clip(self.goal.vector, _POSE_LO, _POSE_HI)}

    def _placed(self, rng: np.random.Generator, angles: np.ndarray, pos_m: float, rot_deg: float):
        jitter = Rotation.from_rotvec(rng.normal(size=3) * np.deg2rad(rot_deg) / np.sqrt(3))
        rotvec = (jitter * Rotation.from_rotvec(PALM_DOWN_ROTVEC)).as_rotvec()
        wrist = HAND_HOME_M + rng.uniform(-pos_m, pos_m, size=3)
        return HandPose(wrist, rotvec, angles)

    def _reset_task(self, rng: np.random.Generator) -> HandPose:
        start = self._placed(rng, gesture("open").angles, 0.02, 15.0)
        name = list(GESTURES)[rng.integers(len(GESTURES))]
        angles = gesture(name, rng=rng, noise_deg=2.0).angles
        jitter = Rotation.from_rotvec(rng.normal(size=3) * np.deg2rad(30.0) / np.sqrt(3))
        self.goal = HandPose(
            start.wrist_pos + rng.uniform(-0.03, 0.03, size=3),
            (jitter * Rotation.from_rotvec(start.wrist_rotvec)).as_rotvec(),
            angles,
        ).clip()
        self.goal_name = name
        self._fk = ForwardKinematics(self.scene.hand.params)
        self._goal_keypoints = self._fk.keypoints(self.goal)
        return start

    def keypoint_distance_m(self) -> float:
        """Mean distance of the hand's 21 keypoints to the goal's, metres."""
        keypoints = self.scene.binding.keypoints(self.scene.data)
        return float(np.linalg.norm(keypoints - self._goal_keypoints, axis=1).mean())

    def _reward_terms(self) -> tuple[str, ...]:
        if self.config.reward_type == "dense":
            return ("reward_success", "reward_distance")
        return ("reward_success",)

    def _task_info(self) -> dict[str, Any]:
        d = self.keypoint_distance_m()
        return {"keypoint_distance_m": d, "is_success": bool(d < self.success_distance_m)}

    def _task_reward(self) -> tuple[dict[str, float], bool, dict[str, Any]]:
        info = self._task_info()
        terms = {"reward_success": float(info["is_success"])}
        if self.config.reward_type == "dense":
            terms["reward_distance"] = -10.0 * info["keypoint_distance_m"]
        return terms, False, info

    # Experts -----------------------------------------------------------------------------

    def expert_state(
        self, hand_pose: HandPose | None = None, keypoints_world: np.ndarray | None = None
    ) -> HandState:
        """The expert's state: the truth, or the given (estimated) pose and keypoints."""
        data = self.scene.data
        return HandState(
            time_s=float(data.time),
            hand_pose=hand_pose if hand_pose is not None else self.scene.binding.pose(data),
            keypoints_world=(
                keypoints_world
                if keypoints_world is not None
                else self.scene.binding.keypoints(data)
            ),
        )

    def make_expert(
        self, rng: np.random.Generator | None = None, state: HandState | None = None
    ) -> GestureExpert:
        """A :class:`~handsim.envs.experts.GestureExpert` planned to this episode's goal.

        Args:
            rng: the expert's generator (default: drawn from the env's).
            state: the state it plans from (default: the truth, :meth:`expert_state`).
        """
        if rng is None:
            rng = np.random.default_rng(self.np_random.integers(2**63))
        expert = GestureExpert(self.control_dt, rng=rng)
        expert.reset(state if state is not None else self.expert_state(), self.goal)
        return expert
