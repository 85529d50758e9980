"""``handsim/PressTwoHands-v0``: a two-hand control: press two buttons at once, one per hand.

The panel of ``handsim/Press-v0`` with both hands physical: the right hand presses the right
button and the left hand the left one, together, as on a machine's two-hand control (both
actuated within :data:`SYNC_S` of each other and held together; ISO 13851 calls this
synchronous actuation). It is the smallest task that needs two hands at once, so it tests
that both are driven, routed to their own side, and detected separately (events name the hand).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from handsim.envs.experts import pose_action
from handsim.envs.press import (
    _BUTTON_Y_M,
    _PANEL_Y_M,
    N_BUTTONS,
    PRESS_THRESHOLD_M,
    RELEASE_THRESHOLD_M,
    PressEnv,
    PressExpert,
    PressState,
)
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import GESTURES

__all__ = ["TwoHandPressEnv", "TwoHandPressExpert", "SYNC_S", "TARGET_BUTTONS"]

SYNC_S = 0.5
"""Largest time between the two hands' presses, seconds (a two-hand control's synchrony)."""
TARGET_BUTTONS: dict[str, int] = {"right": N_BUTTONS - 1, "left": 0}
"""The button each hand presses: the right hand the right one, the left hand the left one."""
_START_X_M = 0.1  # each hand's start, this far to its own side of the panel centre


class TwoHandPressEnv(PressEnv):
    """Press the left button with the left hand and the right button with the right, together.

    ## Description
    The panel of :class:`~handsim.envs.press.PressEnv` (three push buttons, 7 cm apart, and a
    slider), with a right and a left physical hand (:attr:`two_hands`). Success: the right
    hand's target ``press_button_2`` and the left hand's ``press_button_0`` are both pressed
    (pushed in 5 mm) at the same step, their presses begun within :data:`SYNC_S` (0.5 s) of
    each other. Presses of the middle button are **unintended presses**. Which finger presses
    is not checked: a button pushed in is pressed.

    ## Action Space
    ``Box(54)`` float32: the right hand's 27-DoF target, then the left hand's (each as in
    :class:`~handsim.envs.hand_pose.HandPoseEnv`, ``"pose"`` or ``"delta"``).

    ## Observation Space
    ``Dict``: ``depth`` / ``segmentation`` (the left hand's labels follow the objects':
    ``left_arm`` 10 ... ``left_little`` 16, :attr:`~handsim.world.scene.Scene.label_names`) /
    ``proprio`` (108,) (the right hand's 54, then the left's) by ``obs_mode``, and ``panel``:
    (4,) float64 = how far each button is pushed in (m) and the knob's position (m).

    ## Rewards
    Dense: ``reward_reach = -(d_right + d_left)`` (each hand's index fingertip to its target
    button's top, metres), ``reward_progress`` (the mean over the two targets of depth /
    threshold, each at most 1), ``reward_unintended = -1`` per press of the middle button and
    ``reward_success = 10`` at the step of success. Sparse: ``reward_success = 1`` then.
    ``info`` also has ``is_success``, ``button_depth_m`` (3,), ``pressed`` (3,),
    ``press_events``, ``unintended_presses`` and ``press_gap_s`` (the time between the two
    targets' held presses, -1 unless both are held: NaN would make equal infos unequal).

    ## Starting State
    Both hands open and relaxed, palm down, 18 cm in front of the button row and 12 cm above
    the table, 10 cm to either side of the panel centre, each jittered by 1 cm.

    ## Episode End
    Terminated at success; truncated after ``max_episode_steps`` (250 = 5 s) or on physics
    divergence.

    ## Arguments
    The shared arguments of :class:`~handsim.envs.config.EnvConfig` (``handedness`` stays
    ``"right"``: both hands are there).

    ## Version History

    - v0: initial version.
    """

    two_hands = True

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(task="button", **kwargs)
        self._press_step = np.full(N_BUTTONS, -1, dtype=np.int64)

    def _reset_task(self, rng: np.random.Generator) -> HandPose:
        super()._reset_task(rng)
        self.task_target = f"button_{TARGET_BUTTONS['right']}"
        self._press_step[:] = -1
        self._step_count = 0
        return self._start(rng, 1.0)

    def _other_hand_start(self, rng: np.random.Generator) -> HandPose:
        return self._start(rng, -1.0)

    def _start(self, rng: np.random.Generator, sign: float) -> HandPose:
        jitter = rng.uniform(-0.01, 0.01, size=3)
        wrist = np.array([self._panel_x + sign * _START_X_M, _PANEL_Y_M + _BUTTON_Y_M - 0.18, 0.12])
        return HandPose(wrist + jitter, (0.0, math.pi, 0.0), GESTURES["relaxed"].angles)

    def _task_observation_space(self) -> dict[str, spaces.Space]:
        return {"panel": spaces.Box(-1.0, 1.0, (4,), np.float64)}

    def _task_observation(self) -> dict[str, np.ndarray]:
        return {"panel": np.append(self.button_depth_m(), self.slider_m())}

    def _press_gap_s(self) -> float:
        steps = self._press_step[[TARGET_BUTTONS["right"], TARGET_BUTTONS["left"]]]
        if np.any(steps < 0):
            return -1.0
        return float(abs(steps[0] - steps[1]) * self.control_dt)

    def _task_info(self) -> dict[str, Any]:
        return {
            "is_success": bool(self.success),
            "button_depth_m": self.button_depth_m(),
            "pressed": self._pressed.copy(),
            "press_events": int(self.press_events),
            "unintended_presses": int(self.unintended_presses),
            "press_gap_s": self._press_gap_s(),
        }

    def _task_reward(self) -> tuple[dict[str, float], bool, dict[str, Any]]:
        self._step_count += 1
        depth = self.button_depth_m()
        was = self._pressed.copy()
        self._pressed = np.where(was, depth > RELEASE_THRESHOLD_M, depth >= PRESS_THRESHOLD_M)
        new = self._pressed & ~was
        self._press_step[new] = self._step_count
        self._press_step[~self._pressed] = -1  # a released button's press is over
        targets = [TARGET_BUTTONS["right"], TARGET_BUTTONS["left"]]
        unintended = int(sum(new[k] for k in range(N_BUTTONS) if k not in targets))
        self.press_events += int(new.sum())
        self.unintended_presses += unintended
        was_success = self.success
        gap = self._press_gap_s()
        # Both held now, begun within SYNC_S of each other.
        self.success = self.success or 0.0 <= gap <= SYNC_S + 1e-9
        just = self.success and not was_success
        if self.config.reward_type == "dense":
            tops = self.button_tops_world()
            reach = sum(
                float(np.linalg.norm(self.scene.hand_binding(side).keypoints(self.scene.data)[8]
                                     - tops[button]))
                for side, button in TARGET_BUTTONS.items()
            )  # fmt: skip
            progress = float(np.mean(np.minimum(depth[targets] / PRESS_THRESHOLD_M, 1.0)))
            terms = {
                "reward_reach": -reach,
                "reward_progress": progress,
                "reward_unintended": -float(unintended),
                "reward_success": 10.0 * just,
            }
        else:
            terms = {"reward_success": float(just)}
        return terms, bool(self.success), self._task_info()

    # Experts ---------------------------------------------------------------------------------

    def hand_state(self, side: str, hand_pose: HandPose | None = None) -> PressState:
        """The press expert's state of one hand: the truth, or the given pose in its place."""
        data = self.scene.data
        binding = self.scene.hand_binding(side)
        return PressState(
            time_s=float(data.time - self._episode_start_s),
            hand_pose=hand_pose if hand_pose is not None else binding.pose(data),
            keypoints_world=binding.keypoints(data),
            button_top_world=self.button_tops_world(),
            slider_world=self.slider_world(),
            target=f"button_{TARGET_BUTTONS[side]}",
            slider_goal_world=self.slider_world(self.slider_goal_m),
        )

    def expert_state(
        self, hand_pose: HandPose | None = None, keypoints_world: np.ndarray | None = None
    ) -> dict[str, PressState]:
        """Each hand's press expert state (the truth), by side."""
        del hand_pose, keypoints_world
        return {side: self.hand_state(side) for side in self.sides}

    def make_expert(
        self,
        rng: np.random.Generator | None = None,
        state: dict[str, PressState] | None = None,
    ) -> TwoHandPressExpert:
        """A :class:`TwoHandPressExpert` planned for this episode."""
        experts = {
            b.hand.params.side: PressExpert(b.hand.params, self.control_dt, rng=rng)
            for b in self.scene.bindings
        }
        expert = TwoHandPressExpert(experts)
        expert.reset(state if state is not None else self.expert_state())
        return expert


class TwoHandPressExpert:
    """Both hands' :class:`~handsim.envs.press.PressExpert`, each on its own button, at once.

    Args:
        experts: one press expert per side (``"right"``, ``"left"``).
    """

    def __init__(self, experts: dict[str, PressExpert]) -> None:
        self.experts = experts

    def reset(self, state: dict[str, PressState]) -> None:
        """Plan each hand's path from its state."""
        for side, expert in self.experts.items():
            expert.reset(state[side])

    @property
    def done(self) -> bool:
        """Whether both paths were played to their end."""
        return all(e.done for e in self.experts.values())

    def act(self, state: dict[str, PressState]) -> dict[str, HandPose]:
        """The next absolute target of each hand, by side (world frame)."""
        return {side: expert.act(state[side]) for side, expert in self.experts.items()}

    def action(self, state: dict[str, PressState]) -> np.ndarray:
        """The next targets as the ``"pose"`` action: (54,) float32, right then left."""
        poses = self.act(state)
        return np.concatenate([pose_action(poses["right"]), pose_action(poses["left"])])
