"""``handsim/Press-v0``: press a push button or move a slider on a panel (VR-style controls).

The panel holds three spring-loaded push buttons and one slider, the commonest controls of VR
interfaces; :class:`PressExpert` is its scripted operator (point with the index finger, press,
release; or push the slider's knob sideways).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import mujoco
import numpy as np
from gymnasium import spaces
from scipy.spatial.transform import Rotation

from handsim.envs.base import HandSimEnv
from handsim.envs.config import EnvConfig, InvalidEnvConfig
from handsim.envs.experts import ExpertError, PoseActions
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HandParams
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import (
    GESTURES,
    MAX_JOINT_SPEED,
    MAX_WRIST_ANGULAR_SPEED,
    MAX_WRIST_SPEED,
    smooth_motion,
)
from handsim.world.scene import SEGMENT_LABELS

__all__ = [
    "PressEnv",
    "PressExpert",
    "PressState",
    "PRESS_TASKS",
    "N_BUTTONS",
    "BUTTON_TRAVEL_M",
    "PRESS_THRESHOLD_M",
    "RELEASE_THRESHOLD_M",
    "BUTTON_STIFFNESS_N_M",
    "SLIDER_RANGE_M",
    "SLIDER_TOLERANCE_M",
    "SLIDER_HOLD_S",
    "PANEL_TOP_M",
]

PRESS_TASKS: tuple[str, ...] = ("button", "slider", "random")
"""``task`` values: press the target button, move the slider to its goal, or either per episode."""
N_BUTTONS = 3
BUTTON_TRAVEL_M = 0.008
"""How far a button can be pushed in, metres."""
PRESS_THRESHOLD_M = 0.005
"""A button counts as pressed when pushed in this far, metres."""
RELEASE_THRESHOLD_M = 0.003
"""A pressed button counts as released when it rises above this, metres (hysteresis)."""
BUTTON_STIFFNESS_N_M = 200.0
"""Button spring, N/m (1 N at the press threshold, like a tactile switch)."""
SLIDER_RANGE_M = 0.07
"""The slider's knob moves in [-0.07, 0.07] m along x from the panel centre."""
SLIDER_TOLERANCE_M = 0.01
"""The slider task succeeds with the knob within this of its goal, metres ..."""
SLIDER_HOLD_S = 0.2
"""... for this long, seconds."""
PANEL_TOP_M = 0.03
"""Height of the panel's top face above the table, metres."""

_PANEL_HALF_M = (0.12, 0.07, PANEL_TOP_M / 2)
_PANEL_Y_M = 0.06
_BUTTON_X_M = (-0.07, 0.0, 0.07)
_BUTTON_Y_M = -0.03  # relative to the panel centre (the row nearer the user)
_SLIDER_Y_M = 0.035
_CAP_RADIUS_M = 0.012
_CAP_HALF_HEIGHT_M = 0.003
_CAP_GAP_M = 0.001  # clearance under a fully pushed cap: caps never touch the panel
_KNOB_HALF_M = (0.008, 0.012, 0.012)
_SLIDER_FRICTION_N = 0.3
_PANEL_LABEL = SEGMENT_LABELS.index("table")


def _cap_rest_bottom_m() -> float:
    return PANEL_TOP_M + BUTTON_TRAVEL_M + _CAP_GAP_M


def button_top_m() -> float:
    """Height of a button's top at rest above the table, metres."""
    return _cap_rest_bottom_m() + 2 * _CAP_HALF_HEIGHT_M


def add_panel(spec: mujoco.MjSpec) -> None:
    """Add the panel (bodies ``press_panel``, ``press_button_<k>``, ``press_slider``) to a spec.

    Buttons are slide joints along ``z`` (``press_button_<k>_joint``, range
    ``[-BUTTON_TRAVEL_M, 0]``, a spring of :data:`BUTTON_STIFFNESS_N_M` toward 0, gravity
    compensated); the slider's knob is a slide joint along ``x`` (``press_slider_joint``) with
    dry friction, so it stays where it is left. Caps and knob float 1 mm above the panel, so
    they touch only the hand.
    """
    panel = spec.worldbody.add_body(name="press_panel", pos=[0.0, _PANEL_Y_M, 0.0])
    panel.add_geom(
        name="press_panel_base",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=_PANEL_HALF_M,
        pos=[0.0, 0.0, PANEL_TOP_M / 2],
        rgba=[0.25, 0.27, 0.3, 1.0],
    )
    panel.add_geom(
        name="press_slider_track",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[SLIDER_RANGE_M + _KNOB_HALF_M[0], 0.002, 0.0005],
        pos=[0.0, _SLIDER_Y_M, PANEL_TOP_M + 0.0005],
        rgba=[0.1, 0.1, 0.1, 1.0],
        contype=0,
        conaffinity=0,
    )
    cap_z = _cap_rest_bottom_m() + _CAP_HALF_HEIGHT_M
    for k, x in enumerate(_BUTTON_X_M):
        body = panel.add_body(name=f"press_button_{k}", pos=[x, _BUTTON_Y_M, 0.0])
        body.gravcomp = 1.0
        body.add_joint(
            name=f"press_button_{k}_joint",
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=[0.0, 0.0, 1.0],
            range=[-BUTTON_TRAVEL_M, 0.0],
            limited=mujoco.mjtLimited.mjLIMITED_TRUE,
            stiffness=[BUTTON_STIFFNESS_N_M, 0.0, 0.0],
            damping=[2.0, 0.0, 0.0] if _ARRAY_DAMPING else 2.0,
        )
        body.add_geom(
            name=f"press_button_{k}_cap",
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[_CAP_RADIUS_M, _CAP_HALF_HEIGHT_M, 0.0],
            pos=[0.0, 0.0, cap_z],
            mass=0.01,
            rgba=[0.85, 0.2, 0.15, 1.0],
        )
    knob = panel.add_body(name="press_slider", pos=[0.0, _SLIDER_Y_M, 0.0])
    knob.add_joint(
        name="press_slider_joint",
        type=mujoco.mjtJoint.mjJNT_SLIDE,
        axis=[1.0, 0.0, 0.0],
        range=[-SLIDER_RANGE_M, SLIDER_RANGE_M],
        limited=mujoco.mjtLimited.mjLIMITED_TRUE,
        damping=[3.0, 0.0, 0.0] if _ARRAY_DAMPING else 3.0,
        frictionloss=_SLIDER_FRICTION_N,
    )
    knob.add_geom(
        name="press_slider_knob",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=_KNOB_HALF_M,
        pos=[0.0, 0.0, PANEL_TOP_M + _CAP_GAP_M + _KNOB_HALF_M[2]],
        mass=0.02,
        rgba=[0.2, 0.45, 0.85, 1.0],
    )


def _damping_is_array() -> bool:
    joint = mujoco.MjSpec().worldbody.add_body().add_joint()
    return np.ndim(joint.damping) > 0


_ARRAY_DAMPING = _damping_is_array()


@dataclasses.dataclass(frozen=True)
class PressState:
    """What the press expert sees.

    Attributes:
        time_s: time since the episode start, seconds.
        hand_pose: the measured or estimated 27-DoF hand pose, world frame.
        keypoints_world: (21, 3) hand keypoints, world frame, metres.
        button_top_world: (3, 3) top centre of each button at rest, world frame, metres.
        slider_world: (3,) centre of the slider's knob, world frame, metres.
        target: ``"button_<k>"`` or ``"slider"``.
        slider_goal_world: (3,) where the knob's centre must go, world frame, metres.
    """

    time_s: float
    hand_pose: HandPose
    keypoints_world: np.ndarray
    button_top_world: np.ndarray
    slider_world: np.ndarray
    target: str
    slider_goal_world: np.ndarray


class PressExpert(PoseActions):
    """Points with the index finger and presses the target button, or pushes the slider.

    At :meth:`reset` it plans a minimum-jerk path (:func:`~handsim.hand.pose_sources.smooth_motion`)
    of a pointing hand (gesture ``point``), pitched down so the index tip is its lowest point:
    above the target, down through the press threshold (button) or beside the knob and along
    the slider to the goal, then back up. :meth:`act` plays it back (open loop).

    Args:
        hand: the physical hand's parameters.
        dt: control period, seconds.
        speed: fraction of the natural speed limits, in (0, 1].
        rng: random generator (draws nothing today; kept for the expert interface).
    """

    def __init__(
        self,
        hand: HandParams,
        dt: float,
        *,
        speed: float = 0.4,
        rng: np.random.Generator | None = None,
    ) -> None:
        if not dt > 0:
            raise ExpertError(f"dt must be > 0 seconds; received {dt}")
        if not 0 < speed <= 1:
            raise ExpertError(f"speed must lie in (0, 1]; received {speed}")
        self.hand, self.dt, self.speed = hand, float(dt), float(speed)
        self.rng = rng
        self._fk = ForwardKinematics(hand)
        self._angles = GESTURES["point"].angles.copy()
        self._rotvec, self._tip = self._pointing()
        self._path: HandPose | None = None
        self._step = 0

    def _pointing(self) -> tuple[np.ndarray, np.ndarray]:
        """Wrist rotation (palm down, pitched) and the index tip's offset from the wrist."""
        sign = 1.0 if self.hand.side == "right" else -1.0
        for pitch_deg in (35.0, 45.0, 55.0, 65.0):
            rot = Rotation.from_rotvec([-math.radians(pitch_deg), 0.0, 0.0]) * Rotation.from_rotvec(
                [0.0, math.pi, 0.0]
            )
            kp = self._fk.keypoints(HandPose(np.zeros(3), rot.as_rotvec(), self._angles))
            others = np.delete(kp, [7, 8], axis=0)
            if others[:, 2].min() - kp[8, 2] >= 0.02:
                break
        del sign
        return rot.as_rotvec(), kp[8]

    def _wrist_for_tip(self, tip_m: np.ndarray) -> HandPose:
        return HandPose(np.asarray(tip_m) - self._tip, self._rotvec, self._angles)

    def reset(self, state: PressState) -> None:
        """Plan the path from the perceived pose."""
        start = state.hand_pose.clip()
        if state.target.startswith("button_"):
            top = state.button_top_world[int(state.target.split("_")[1])]
            above = self._wrist_for_tip(top + [0.0, 0.0, 0.04])
            down = self._wrist_for_tip(top - [0.0, 0.0, PRESS_THRESHOLD_M + 0.003])
            keys = [start, above, down, above]
            holds = [0.0, 0.15, 0.25]
        elif state.target == "slider":
            knob, goal = state.slider_world, state.slider_goal_world
            side = 1.0 if goal[0] >= knob[0] else -1.0
            reach = _KNOB_HALF_M[0] + 0.011
            z = PANEL_TOP_M + _CAP_GAP_M + 0.012
            beside = np.array([knob[0] - side * (reach + 0.012), knob[1], z])
            end = np.array([goal[0] - side * reach, knob[1], z])
            keys = [
                start,
                self._wrist_for_tip(beside + [0, 0, 0.04]),
                self._wrist_for_tip(beside),
                self._wrist_for_tip(end),
                self._wrist_for_tip(end + [0, 0, 0.05]),
            ]
            holds = [0.0, 0.1, 0.1, 0.3]
        else:
            raise ExpertError(f"unknown target {state.target!r}")
        s = self.speed
        self._path = smooth_motion(
            keys,
            self.dt,
            max_joint_speed=s * MAX_JOINT_SPEED,
            max_wrist_speed=s * MAX_WRIST_SPEED,
            max_wrist_angular_speed=s * MAX_WRIST_ANGULAR_SPEED,
            hold=[*holds, 0.3],
        )
        self._step = 0

    @property
    def done(self) -> bool:
        """Whether the path was played to its end."""
        return self._path is not None and self._step >= len(self._path)

    def act(self, state: PressState) -> HandPose:
        """The next absolute target (world frame).

        Raises:
            ExpertError: before :meth:`reset`.
        """
        if self._path is None:
            raise ExpertError("PressExpert.act() called before reset(state)")
        pose = self._path[min(self._step, len(self._path) - 1)]
        self._step += 1
        return pose


class PressEnv(HandSimEnv):
    """Press the target push button, or slide the slider's knob to its goal.

    ## Description
    A panel on the table (``press_panel``, top 3 cm above the table, 24 x 14 cm) holds three
    push buttons (``press_button_0`` to ``_2``, left to right, 7 cm apart, on the row nearer
    the user) and a slider (``press_slider``, on the far row). A button is a 24 mm cap on a
    slide joint with 8 mm of travel and a 200 N/m return spring; it counts as **pressed** when
    pushed in 5 mm (:data:`PRESS_THRESHOLD_M`) and as released above 3 mm (hysteresis). The
    slider's knob slides along ``x`` in [-7, 7] cm with dry friction (it stays where it is
    left). Each episode draws the panel's ``x`` offset (within 2 cm) and the task
    (``task="random"``: a button, drawn uniformly, or the slider, with probability 1/4): press
    the target button, or bring the knob within 1 cm of a goal drawn in [-6, 6] cm at least 3
    cm from its start, for 0.2 s. Presses of the other buttons are **unintended presses**.

    ## Action Space
    ``Box(27)`` float32, as in :class:`~handsim.envs.hand_pose.HandPoseEnv`.

    ## Observation Space
    ``Dict``: ``depth`` / ``segmentation`` / ``proprio`` by ``obs_mode`` (see
    :class:`~handsim.envs.base.HandSimEnv`) and ``task``: (5,) float64 = one-hot target (button
    0, 1, 2, slider) and the slider goal (m, along the panel's x axis from its centre); and
    ``panel``: (4,) float64 = how far each button is pushed in (m, >= 0) and the knob's position
    (m). The panel's geoms are labelled ``table`` in the segmentation.

    ## Rewards
    Dense: ``reward_reach = -d`` (``d``: index fingertip to the target's top, or to the knob,
    metres), ``reward_progress`` (button: depth / threshold, at most 1; slider: ``-|knob -
    goal| / 0.07``), ``reward_unintended = -1`` per unintended press event and
    ``reward_success = 10`` at the step of success. Sparse: ``reward_success = 1`` then. The
    reward is the sum of the ``info["reward_*"]`` terms. ``info`` also has ``is_success``,
    ``target_index`` (0-2: a button, 3: the slider), ``button_depth_m`` (3,), ``pressed``
    (3,), ``slider_m``, ``slider_goal_m``, ``press_events`` and ``unintended_presses`` (counts
    so far).

    ## Starting State
    Open relaxed hand, palm down, 18 cm in front of the panel's button row (toward the user)
    and 12 cm above the table, jittered by 1 cm; buttons up; the knob at a random position.

    ## Episode End
    Terminated at success; truncated after ``max_episode_steps`` (250 = 5 s) or on physics
    divergence.

    ## Arguments
    ``task``: one of :data:`PRESS_TASKS` (default ``"random"``), and the shared arguments of
    :class:`~handsim.envs.config.EnvConfig`.

    ## Version History

    - v0: initial version.
    """

    max_objects = 0

    def __init__(self, *, task: str = "random", **kwargs: Any) -> None:
        if task not in PRESS_TASKS:
            raise InvalidEnvConfig(
                f"task={task!r} is not valid; choose one of {', '.join(PRESS_TASKS)}"
            )
        self.task = task
        super().__init__(EnvConfig.from_kwargs(**kwargs))
        self.task_target = "button_0"
        self.slider_goal_m = 0.0
        self._panel_x = 0.0

    # Scene ---------------------------------------------------------------------------------

    def _build_scene(self, rng: np.random.Generator) -> None:
        super()._build_scene(rng)
        scene = self.scene
        if not getattr(scene, "has_press_panel", False):
            add_panel(scene.mjspec)
            scene.recompile()
            for g in range(scene.model.ngeom):
                if scene.model.geom(g).name.startswith("press_"):
                    scene.geom_labels[g] = _PANEL_LABEL
            scene.has_press_panel = True
        model = scene.model
        self._panel_body = model.body("press_panel").id
        self._button_qpos = np.array(
            [model.jnt_qposadr[model.joint(f"press_button_{k}_joint").id] for k in range(N_BUTTONS)]
        )
        self._slider_qpos = int(model.jnt_qposadr[model.joint("press_slider_joint").id])
        mujoco.mj_resetData(model, scene.data)
        self._panel_x = float(rng.uniform(-0.02, 0.02))
        model.body_pos[self._panel_body] = [self._panel_x, _PANEL_Y_M, 0.0]
        scene.data.qpos[self._slider_qpos] = rng.uniform(-0.06, 0.06)
        mujoco.mj_forward(model, scene.data)

    def _reset_task(self, rng: np.random.Generator) -> HandPose:
        task = self.task
        if task == "random":
            task = "slider" if rng.random() < 0.25 else "button"
        if task == "button":
            self.task_target = f"button_{int(rng.integers(N_BUTTONS))}"
        else:
            self.task_target = "slider"
        knob = float(self.scene.data.qpos[self._slider_qpos])
        for _ in range(100):
            goal = float(rng.uniform(-0.06, 0.06))
            if abs(goal - knob) >= 0.03:
                break
        self.slider_goal_m = goal
        self._pressed = np.zeros(N_BUTTONS, dtype=bool)
        self.press_events = 0
        self.unintended_presses = 0
        self._slider_in_s = 0.0
        self.success = False
        self._episode_start_s = 0.0
        jitter = rng.uniform(-0.01, 0.01, size=3)
        wrist = np.array([self._panel_x, _PANEL_Y_M + _BUTTON_Y_M - 0.18, 0.12]) + jitter
        return HandPose(wrist, (0.0, math.pi, 0.0), GESTURES["relaxed"].angles)

    def _begin_task(self) -> None:
        self._episode_start_s = float(self.scene.data.time)
        self._pressed[:] = self.button_depth_m() >= PRESS_THRESHOLD_M

    # Panel state ---------------------------------------------------------------------------

    def button_depth_m(self) -> np.ndarray:
        """(3,) how far each button is pushed in, metres (>= 0)."""
        return np.maximum(-self.scene.data.qpos[self._button_qpos], 0.0)

    def slider_m(self) -> float:
        """The knob's position along the panel's x axis from its centre, metres."""
        return float(self.scene.data.qpos[self._slider_qpos])

    def button_tops_world(self) -> np.ndarray:
        """(3, 3) top centre of each button at rest, world frame, metres."""
        return np.array(
            [[self._panel_x + x, _PANEL_Y_M + _BUTTON_Y_M, button_top_m()] for x in _BUTTON_X_M]
        )

    def slider_world(self, position_m: float | None = None) -> np.ndarray:
        """(3,) centre of the knob (at ``position_m``, default: now), world frame, metres."""
        x = self.slider_m() if position_m is None else position_m
        z = PANEL_TOP_M + _CAP_GAP_M + _KNOB_HALF_M[2]
        return np.array([self._panel_x + x, _PANEL_Y_M + _SLIDER_Y_M, z])

    # Observation, reward ---------------------------------------------------------------------

    def _task_observation_space(self) -> dict[str, spaces.Space]:
        return {
            "task": spaces.Box(-1.0, 1.0, (5,), np.float64),
            "panel": spaces.Box(-1.0, 1.0, (4,), np.float64),
        }

    def _task_observation(self) -> dict[str, np.ndarray]:
        task = np.zeros(5)
        task[self._target_index()] = 1.0
        task[4] = self.slider_goal_m
        return {"task": task, "panel": np.append(self.button_depth_m(), self.slider_m())}

    def _target_index(self) -> int:
        return N_BUTTONS if self.task_target == "slider" else int(self.task_target.split("_")[1])

    def _reward_terms(self) -> tuple[str, ...]:
        if self.config.reward_type == "dense":
            return ("reward_reach", "reward_progress", "reward_unintended", "reward_success")
        return ("reward_success",)

    def _task_info(self) -> dict[str, Any]:
        return {
            "is_success": bool(self.success),
            "target_index": self._target_index(),
            "button_depth_m": self.button_depth_m(),
            "pressed": self._pressed.copy(),
            "slider_m": self.slider_m(),
            "slider_goal_m": self.slider_goal_m,
            "press_events": int(self.press_events),
            "unintended_presses": int(self.unintended_presses),
        }

    def _task_reward(self) -> tuple[dict[str, float], bool, dict[str, Any]]:
        depth = self.button_depth_m()
        was = self._pressed.copy()
        self._pressed = np.where(was, depth > RELEASE_THRESHOLD_M, depth >= PRESS_THRESHOLD_M)
        new = self._pressed & ~was
        target_button = -1 if self.task_target == "slider" else int(self.task_target.split("_")[1])
        unintended = int(sum(new[k] for k in range(N_BUTTONS) if k != target_button))
        self.press_events += int(new.sum())
        self.unintended_presses += unintended
        was_success = self.success
        if target_button >= 0:
            self.success = self.success or bool(new[target_button])
            goal_point = self.button_tops_world()[target_button]
            progress = min(depth[target_button] / PRESS_THRESHOLD_M, 1.0)
        else:
            inside = abs(self.slider_m() - self.slider_goal_m) < SLIDER_TOLERANCE_M
            self._slider_in_s = self._slider_in_s + self.control_dt if inside else 0.0
            self.success = self.success or self._slider_in_s >= SLIDER_HOLD_S - 1e-9
            goal_point = self.slider_world()
            progress = -abs(self.slider_m() - self.slider_goal_m) / SLIDER_RANGE_M
        just = self.success and not was_success
        if self.config.reward_type == "dense":
            tip = self.scene.binding.keypoints(self.scene.data)[8]
            terms = {
                "reward_reach": -float(np.linalg.norm(tip - goal_point)),
                "reward_progress": float(progress),
                "reward_unintended": -float(unintended),
                "reward_success": 10.0 * just,
            }
        else:
            terms = {"reward_success": float(just)}
        return terms, bool(self.success), self._task_info()

    # Experts ---------------------------------------------------------------------------------

    def expert_state(
        self, hand_pose: HandPose | None = None, keypoints_world: np.ndarray | None = None
    ) -> PressState:
        """The press expert's state: the truth, or the given (estimated) hand in its place."""
        data = self.scene.data
        binding = self.scene.binding
        return PressState(
            time_s=float(data.time - self._episode_start_s),
            hand_pose=hand_pose if hand_pose is not None else binding.pose(data),
            keypoints_world=(
                keypoints_world if keypoints_world is not None else binding.keypoints(data)
            ),
            button_top_world=self.button_tops_world(),
            slider_world=self.slider_world(),
            target=self.task_target,
            slider_goal_world=self.slider_world(self.slider_goal_m),
        )

    def make_expert(
        self, rng: np.random.Generator | None = None, state: PressState | None = None
    ) -> PressExpert:
        """A :class:`PressExpert` planned for this episode's target."""
        expert = PressExpert(self.scene.hand.params, self.control_dt, rng=rng)
        expert.reset(state if state is not None else self.expert_state())
        return expert
