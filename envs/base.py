"""What every handsim env shares: configuration, the scene, control, observation, rendering.

:class:`HandSimEnv` is the base of the registered envs. It validates its keyword arguments once
(:class:`EnvConfig`), builds a :class:`~handsim.world.Scene` per episode (rebuilt only when the
hand or the object list changes; object placements and camera poses are written into the
compiled model), steps MuJoCo ``frame_skip`` times per action, renders one labelled
:class:`~handsim.frame.record.Frame` per step and splits it: images into the observation, labels
into ``info["labels"]`` (the Frame's label arrays, :func:`~handsim.data.arrays.frame_to_arrays`).
The Frame itself is :attr:`HandSimEnv.frame`.

Control (``control_mode``):

- ``"pose"``: the action is an absolute 27-DoF target ``[wrist_pos (3) m, wrist_rotvec (3) rad,
  angles (21) rad]`` (:class:`~handsim.hand.pose.HandPose` order, world frame). The wrist target
  moves the mocap body the hand is softly welded to; the angles are the position actuators'
  targets. Bounds: the wrist inside :data:`WORKSPACE_M`, each rotation-vector component in
  [-pi, pi], each angle within its joint limits. Out-of-bound actions are clipped. The mocap
  body moves toward the wrist target at most :data:`WRIST_TRACKING_SPEED` m/s and
  :data:`WRIST_TRACKING_ANGULAR_SPEED` rad/s (an arm cannot teleport the hand; a far target
  is reached over several steps).
- ``"delta"``: the action is in [-1, 1]^27 and moves the current target by at most
  :data:`~handsim.hand.pose_sources.MAX_WRIST_SPEED` m/s, :data:`DELTA_ANGULAR_SPEED` rad/s (wrist
  rotation, world axes) and :data:`DELTA_JOINT_SPEED` rad/s (each joint) times the control
  period; the result is clipped to the ``"pose"`` bounds. Out-of-range actions are clipped.

A two-hand env (:attr:`HandSimEnv.two_hands`, e.g. ``handsim/PressTwoHands-v0``) has a right
and a left hand (:class:`~handsim.world.scene.SceneSpec` ``hands=``): its action is the two
hands' 27-vectors, right then left (54,), each as above; ``target_pose``, ``proprio`` and the
state's ``target`` hold both hands in the same order.

A bad action raises :class:`InvalidAction` (a :class:`~handsim.errors.HandSimError` and a
``ValueError``): the wrong shape, NaN/Inf values, a complex, boolean or non-numeric dtype.
Divergence is checked at the end of every step (:class:`HandDriver`: a MuJoCo instability
warning, a non-finite state, or a velocity above a bound scaled to the hand). The step in which
it happens returns the last valid observation with ``truncated=True`` and
``info["physics_diverged"] = True``; observations are never non-finite and never carry
exploded velocities. Stepping again raises :class:`PhysicsDiverged` until ``reset()`` (or
``set_state``).

Processes: OpenGL contexts are made lazily, in the process that renders, and an env that finds
itself in a new process (a fork of a process that had rendered) drops the inherited contexts
without touching them and makes its own. ``import handsim`` also sets ``LP_NUM_THREADS=0``
(unless set) so that Mesa's software rasterizer keeps no worker threads that a forked child
would wait for; vector envs therefore work with the ``fork``, ``spawn`` and ``forkserver`` start
methods. A Gymnasium vector worker is pinned to one CPU (:mod:`handsim.envs.workers`: Linux
otherwise often runs two workers on one CPU).
"""

from __future__ import annotations

import abc
import dataclasses
import os
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from scipy.spatial.transform import Rotation

from handsim.data.arrays import empty_label_arrays, frame_to_arrays
from handsim.envs.config import (
    _HAS_DISPLAY,
    RENDER_MODES,
    WORKSPACE_M,
    EnvConfig,
    InvalidEnvConfig,
)
from handsim.envs.physics import (
    HandDriver,
    PhysicsDiverged,
    set_skin_friction,
)

# render() for people (the viewer camera); its names stay importable from here.
from handsim.envs.viewer import (  # noqa: F401
    _DEPTH_RENDER_MODES,
    _SHADOW_LIGHT,
    _VIEWER_AZIMUTH_DEG,
    _VIEWER_ELEVATION_DEG,
    _VIEWER_LIFT_MARGIN_M,
    ViewerRendering,
    depth_colormap,
)
from handsim.envs.workers import pin_vector_worker
from handsim.errors import HandSimError
from handsim.frame import Frame, FrameRenderer
from handsim.hand.model import (
    hand_params,
)
from handsim.hand.pose import JOINT_LIMITS, HandPose
from handsim.hand.pose_sources import MAX_WRIST_SPEED
from handsim.world.camera import CameraIntrinsics, camera_preset
from handsim.world.scene import (
    HAND_PART_LABELS,
    OBJECT_LABEL_OFFSET,
    CameraSpec,
    ObjectPlacement,
    Scene,
    SceneSpec,
    egocentric_camera,
    sample_viewpoint,
    third_person_camera,
)
from handsim.world.sensors import sensor_model

__all__ = [
    "HandSimEnv",
    "RESET_ATTEMPTS",
    "without_images",
    "DEPTH_MAX_M",
    "DELTA_ANGULAR_SPEED",
    "DELTA_JOINT_SPEED",
    "InvalidAction",
    "depth_colormap",
    "scaled_intrinsics",
]

DEPTH_MAX_M = 10.0
"""Upper bound of the depth observation, metres."""
DELTA_ANGULAR_SPEED = 3.0
"""Wrist rotation per unit delta action, rad/s."""
DELTA_JOINT_SPEED = 6.0
"""Joint motion per unit delta action, rad/s."""
SETTLE_S = 0.1
"""Physics time run at reset so objects and the hand settle before the first observation."""

_POSE_LO = np.concatenate([[w[0] for w in WORKSPACE_M], [-np.pi] * 3, JOINT_LIMITS[:, 0]])
_POSE_HI = np.concatenate([[w[1] for w in WORKSPACE_M], [np.pi] * 3, JOINT_LIMITS[:, 1]])


class InvalidAction(HandSimError, ValueError):
    """An action passed to ``step`` has the wrong shape, dtype or a non-finite value."""


def without_images(frame: Frame) -> Frame:
    """The Frame's labels alone (its images dropped)."""
    return dataclasses.replace(frame, depth=None, depth_clean=None, segmentation=None)


def _plain(value: Any) -> Any:
    """A NumPy scalar as the Python scalar of its kind (infos keep one type per key)."""
    if isinstance(value, np.generic):
        return value.item()
    return value


RESET_ATTEMPTS = 5
"""Episodes drawn at a reset before giving up when each one's settling diverges."""


# GL objects inherited through fork: kept referenced so that they are never freed (freeing would
# call into the parent's OpenGL contexts).
_INHERITED_GL: list[object] = []


def scaled_intrinsics(intrinsics: CameraIntrinsics, width: int, height: int) -> CameraIntrinsics:
    """Intrinsics of the same camera with a ``width`` x ``height`` image.

    :meth:`CameraIntrinsics.scaled <handsim.world.camera.CameraIntrinsics.scaled>`: pixel centres
    at integers, ``fx' = fx * width / W``, ``cx' = (cx + 0.5) * width / W - 0.5``.
    """
    return intrinsics.scaled(width, height)


class HandSimEnv(ViewerRendering, gym.Env, abc.ABC):
    """Base of handsim's envs (not registered itself); see the module docstring.

    Observation keys by ``obs_mode``:

    - ``depth`` (modes with ``depth``): ``(H, W)``, or ``(1, H, W)`` with ``channel_axis=True``;
      float32 metres in [0, :data:`DEPTH_MAX_M`] (``depth_format="float32_m"``) or uint16
      millimetres in [0, 10000] (``"uint16_mm"``); 0 = no measurement. ``H, W`` are ``height``
      and ``width`` (default: the camera preset's resolution).
    - ``segmentation`` (``"depth+segmentation"``): the same shape, int16 labels
      (:data:`~handsim.world.scene.SEGMENT_LABELS`, objects from 10).
    - ``proprio`` (modes with ``state``): (54,) float64 = the hand's measured pose vector (27)
      and velocities (27: wrist linear m/s and angular rad/s, then joint rad/s).
    - ``object_poses`` (``"privileged_state"``, envs with objects): ``(max_objects, 7)``
      float64, one row per object instance: position (3, metres) and orientation
      ``quat_wxyz`` (4) of the object's body frame in the world frame; rows of absent
      instances are zero. ``object_present``: ``(max_objects,)`` int8, 1 for a present
      instance.
    - each task's own keys (its goal or target).

    ``info`` has the same keys, Python types and array shapes at reset, at every step and on a
    diverged step (so Minari's ``DataCollector(record_infos=True)`` records it):
    ``time_s``, ``target_pose`` (27,), ``physics_diverged``, every ``reward_*`` term of the
    ``reward_type`` (0 at reset and on divergence), the task's keys and, when ``labels`` is on,
    ``labels``: the step's :class:`~handsim.frame.record.Frame` as arrays
    (:data:`~handsim.data.arrays.LABEL_SCHEMA`; the invalid fill with ``valid = False`` on a
    diverged step). The Frame itself (with its images) is :attr:`frame` (``None`` without
    labels or after a divergence); with ``labels`` off no label work is done, and in the state
    modes nothing is rendered. :attr:`obs_intrinsics` are the intrinsics of the observation
    images: the camera renders at ``width`` x ``height`` (its ``K`` scaled), so they are the
    frame's ``K`` too.

    Subclasses implement :meth:`_episode_objects`, :meth:`_reset_task`, :meth:`_task_reward`
    and may add task observation keys with :meth:`_task_observation_space` and
    :meth:`_task_observation`.
    """

    metadata = {
        "render_modes": list(RENDER_MODES),
        "render_fps": 50,
    }
    max_objects: int = 0
    """Largest number of objects an episode can have (sets the segmentation bound)."""
    two_hands: bool = False
    """A right and a left hand (module docstring); ``handedness`` must stay ``"right"``."""
    use_table: bool = True

    def __init__(self, config: EnvConfig) -> None:
        self.config = config
        self.render_mode = config.render_mode
        if self.render_mode == "human" and not _HAS_DISPLAY:
            raise InvalidEnvConfig(
                "render_mode='human' needs a display (DISPLAY is not set); use 'rgb_array' or "
                "'depth_array' headless"
            )
        # The camera renders at the requested size (its K scaled; no resize afterwards): a
        # smaller image costs less, and the labels are those of the image.
        self.intrinsics = camera_preset(config.camera).scaled(config.width, config.height)
        """Intrinsics of the rendered images (``width`` x ``height``), the frame's ``K``."""
        self.obs_intrinsics = self.intrinsics
        """Intrinsics of the observation images (the same as :attr:`intrinsics`)."""
        self.sensor = sensor_model(config.sensor)
        self.control_dt = config.frame_skip * 0.002
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.control_dt))}
        shape = (config.height, config.width)
        if config.channel_axis:
            shape = (1, *shape)
        obs: dict[str, spaces.Space] = {}
        if "depth" in config.obs_mode:
            if config.depth_format == "uint16_mm":
                top = int(round(DEPTH_MAX_M * 1000))
                obs["depth"] = spaces.Box(0, top, shape, np.uint16)
            else:
                obs["depth"] = spaces.Box(0.0, DEPTH_MAX_M, shape, np.float32)
        if self.two_hands and config.handedness != "right":
            raise InvalidEnvConfig(
                f"handedness={config.handedness!r}: a two-hand env has both hands (right, "
                "then left); leave handedness at 'right'"
            )
        n_hands = 2 if self.two_hands else 1
        if config.obs_mode == "depth+segmentation":
            top = OBJECT_LABEL_OFFSET + max(self.max_objects, 1) - 1
            if self.two_hands:  # the left hand's labels follow the objects
                top = OBJECT_LABEL_OFFSET + self.max_objects + len(HAND_PART_LABELS) - 1
            obs["segmentation"] = spaces.Box(0, top, shape, np.int16)
        if "state" in config.obs_mode:
            obs["proprio"] = spaces.Box(-np.inf, np.inf, (54 * n_hands,), np.float64)
        if config.obs_mode == "privileged_state" and self.max_objects > 0:
            obs["object_poses"] = spaces.Box(-np.inf, np.inf, (self.max_objects, 7), np.float64)
            obs["object_present"] = spaces.Box(0, 1, (self.max_objects,), np.int8)
        obs.update(self._task_observation_space())
        self.observation_space = spaces.Dict(obs)
        if config.control_mode == "pose":
            lo, hi = np.tile(_POSE_LO, n_hands), np.tile(_POSE_HI, n_hands)
            self.action_space = spaces.Box(
                lo.astype(np.float32), hi.astype(np.float32), (27 * n_hands,), np.float32
            )
        else:
            self.action_space = spaces.Box(-1.0, 1.0, (27 * n_hands,), np.float32)
        self._delta_scale = self.control_dt * np.concatenate(
            [[MAX_WRIST_SPEED] * 3, [DELTA_ANGULAR_SPEED] * 3, [DELTA_JOINT_SPEED] * 21]
        )
        self.scene: Scene | None = None
        self._scene_key: tuple | None = None
        self._frame_renderer: FrameRenderer | None = None
        self._rgb_renderer: mujoco.Renderer | None = None
        self._gl_pid = os.getpid()
        self.worker_cpu = pin_vector_worker()
        """The CPU this process was pinned to as a vector-env worker, or ``None``
        (:mod:`handsim.envs.workers`)."""
        self._viewer: Any = None
        self._viewer_camera: mujoco.MjvCamera | None = None
        self._viewer_range_m = (0.1, 2.0)
        self.driver: HandDriver | None = None
        self.frame: Frame | None = None
        self._last_obs: dict[str, np.ndarray] | None = None
        self.elapsed_steps = 0

    @property
    def target(self) -> HandPose:
        """The current 27-DoF target the hand is driven toward (world frame)."""
        return self.driver.target

    @property
    def sides(self) -> tuple[str, ...]:
        """The hands' sides in action order (``("right", "left")`` in a two-hand env)."""
        return tuple(b.hand.params.side for b in self.scene.bindings)

    def _targets_vector(self) -> np.ndarray:
        """Every hand's 27-vector target, in action order."""
        return np.concatenate([self.driver.target_of(s).vector for s in self.sides])

    # Hooks of the tasks --------------------------------------------------------------------

    def _episode_objects(self, rng: np.random.Generator) -> tuple[ObjectPlacement, ...]:
        """Objects of this episode with their placements."""
        return ()

    @abc.abstractmethod
    def _reset_task(self, rng: np.random.Generator) -> HandPose:
        """Draw the task (goal, target) for the new scene; return the hand's start pose."""

    def _other_hand_start(self, rng: np.random.Generator) -> HandPose:
        """A two-hand env's left hand start pose (called after :meth:`_reset_task`)."""
        raise NotImplementedError("a two-hand env defines its left hand's start pose")

    def _begin_task(self) -> None:
        """Start the task's bookkeeping once the scene has settled (before the first frame)."""

    @abc.abstractmethod
    def _reward_terms(self) -> tuple[str, ...]:
        """Names of the ``reward_*`` terms under this ``reward_type``."""

    @abc.abstractmethod
    def _task_info(self) -> dict[str, Any]:
        """The task's ``info`` entries: the same keys and Python types at every step."""

    @abc.abstractmethod
    def _task_reward(self) -> tuple[dict[str, float], bool, dict[str, Any]]:
        """``(reward terms, terminated, task info)`` after a step."""

    def _task_observation_space(self) -> dict[str, spaces.Space]:
        return {}

    def _task_observation(self) -> dict[str, np.ndarray]:
        return {}

    # OpenGL, per process ---------------------------------------------------------------------

    def _own_process(self) -> None:
        """Drop GL objects inherited through fork (never touching them); see the module doc."""
        pid = os.getpid()
        if pid == self._gl_pid:
            return
        for obj in (self._frame_renderer, self._rgb_renderer, self._viewer):
            if obj is not None:
                _INHERITED_GL.append(obj)
        self._frame_renderer = None
        self._rgb_renderer = None
        self._viewer = None
        self._gl_pid = pid

    @property
    def frame_renderer(self) -> FrameRenderer | None:
        """The scene's frame renderer, made on first use in this process (``None`` before reset).

        A renderer is made only when something is rendered: never in the state modes without
        labels.
        """
        self._own_process()
        if self._frame_renderer is None and self.scene is not None:
            self._frame_renderer = FrameRenderer(
                self.scene, "camera", self.sensor, skin_detail=self.config.skin_detail
            )
        return self._frame_renderer

    def _close_renderers(self) -> None:
        self._own_process()
        if self._frame_renderer is not None:
            self._frame_renderer.close()
            self._frame_renderer = None
        self._close_rgb()

    # Scene ---------------------------------------------------------------------------------

    def _camera_spec(self, rng: np.random.Generator) -> CameraSpec:
        if self.config.viewpoint == "third_person":
            return third_person_camera(self.intrinsics, name="camera")
        if self.config.viewpoint == "egocentric":
            return egocentric_camera(self.intrinsics, name="camera")
        return sample_viewpoint(rng, self.intrinsics, name="camera")

    def _build_scene(self, rng: np.random.Generator) -> None:
        lo, hi = self.config.hand_size_m
        length = float(rng.uniform(lo, hi)) if hi > lo else lo
        side = self.config.handedness
        if side == "random":
            side = "right" if rng.random() < 0.5 else "left"
        placements = self._episode_objects(rng)
        camera = self._camera_spec(rng)
        key = (length, side, tuple(p.name for p in placements))
        if key != self._scene_key:
            self._close_renderers()
            hands = None
            if self.two_hands:
                hands = (hand_params(length, "right"), hand_params(length, "left"))
            spec = SceneSpec(
                hand=hand_params(length, side),
                hands=hands,
                objects=placements,
                cameras=(camera,),
                table=self.use_table,
                skin_lod=self.config.skin_detail != "full",  # a coarse skin only if drawn
            )
            self.scene = Scene(spec)
            self._scene_key = key
            friction = self.config.object_friction
            if friction != "mujoco":
                set_skin_friction(self.scene, None if friction == "skin" else friction)
        scene = self.scene
        mujoco.mj_resetData(scene.model, scene.data)
        cam = scene.model.camera("camera").id
        scene.model.cam_pos[cam] = camera.pos_m
        scene.model.cam_quat[cam] = camera.quat_wxyz
        for (body, _), placement in zip(scene.objects, placements, strict=True):
            adr = scene.model.jnt_qposadr[scene.model.body(body).jntadr[0]]
            scene.data.qpos[adr : adr + 3] = placement.pos_m
            scene.data.qpos[adr + 3 : adr + 7] = placement.quat_wxyz
        mujoco.mj_forward(scene.model, scene.data)

    # Gymnasium API ------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start an episode: draw the scene and the task from the env's generator.

        Returns:
            ``(observation, info)``; ``info["labels"]`` holds the ground-truth labels (absent
            with ``labels=False``).
        """
        super().reset(seed=seed)
        rng = self.np_random
        # A draw whose settling diverges is drawn again (from the same generator, so seeded
        # resets stay reproducible); it never becomes an episode that cannot be stepped.
        for _ in range(RESET_ATTEMPTS):
            self._build_scene(rng)
            start = self._reset_task(rng)
            self.scene.binding.set_pose(self.scene.data, start)
            other = self._other_hand_start(rng) if self.two_hands else None
            if other is not None:
                self.scene.bindings[1].set_pose(self.scene.data, other)
            self.driver = HandDriver(self.scene)
            self.driver.set_target(start)
            if other is not None:
                self.driver.set_target(other, self.sides[1])
            if not self.driver.step(int(round(SETTLE_S / self.scene.model.opt.timestep))):
                break
        else:
            raise PhysicsDiverged(
                f"the physics diverged while settling {RESET_ATTEMPTS} drawn episodes in a row "
                "at reset; check the env's arguments (hand size, objects) or reset with "
                "another seed"
            )
        self.elapsed_steps = 0
        self._frame_viewer()
        self._begin_task()
        obs = self._observe()
        terms = dict.fromkeys(self._reward_terms(), 0.0)
        return obs, self._info(terms, self._task_info())

    def _check_action(self, action: object) -> np.ndarray:
        n = self.action_space.shape[0]
        layout = "[wrist_pos 3, wrist_rotvec 3, angles 21]"
        if n != 27:
            layout = f"the right hand's {layout}, then the left hand's"
        expected = f"have shape ({n},) ({layout}) and a real numeric dtype"
        try:
            array = np.asarray(action)
        except (TypeError, ValueError):
            raise InvalidAction(f"the action must {expected}; received {action!r}") from None
        if array.dtype.kind == "c":
            raise InvalidAction(
                f"the action must {expected}; received a complex array ({array.dtype}); "
                "complex values are not cut to their real part"
            )
        if array.dtype.kind not in "iuf":
            raise InvalidAction(
                f"the action must {expected}; received dtype {array.dtype} "
                f"({type(action).__name__})"
            )
        if array.shape != (n,):
            raise InvalidAction(f"the action must {expected}; received shape {array.shape}")
        array = array.astype(np.float64)
        if not np.all(np.isfinite(array)):
            bad = np.nonzero(~np.isfinite(array))[0].tolist()
            raise InvalidAction(f"the action has NaN or Inf values at indices {bad}")
        return array

    def _apply_action(self, action: np.ndarray) -> None:
        sides = self.sides if self.two_hands else (None,)
        for k, side in enumerate(sides):
            part = action[27 * k : 27 * (k + 1)]
            if self.config.control_mode == "pose":
                vector = np.clip(part, _POSE_LO, _POSE_HI)
            else:
                step = np.clip(part, -1.0, 1.0) * self._delta_scale
                current = (self.target if side is None else self.driver.target_of(side)).vector
                rot = Rotation.from_rotvec(step[3:6]) * Rotation.from_rotvec(current[3:6])
                vector = current + step
                vector[3:6] = rot.as_rotvec()
                vector = np.clip(vector, _POSE_LO, _POSE_HI)
            self.driver.set_target(HandPose.from_vector(vector), side)

    def step(
        self, action: np.ndarray
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Apply one action for ``frame_skip`` physics steps, render and label the result.

        Out-of-bound values are clipped to the action space (see the module docstring).

        Raises:
            InvalidAction: (a ``ValueError``) for an action of the wrong shape or dtype
                (complex, boolean, non-numeric) or with NaN/Inf values.
        """
        if self.scene is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        if self.driver.diverged:
            raise PhysicsDiverged(
                f"the physics diverged at step {self.elapsed_steps} of this episode, which was "
                "truncated (info['physics_diverged']); call reset() before stepping again"
            )
        self._apply_action(self._check_action(action))
        diverged = self.driver.step(self.config.frame_skip)
        self.elapsed_steps += 1
        if diverged:
            # Same keys and types as any step: the labels are the invalid fill.
            self.frame = None
            obs = {k: v.copy() for k, v in self._last_obs.items()}
            terms = dict.fromkeys(self._reward_terms(), 0.0)
            task = {**self._last_task_info, "is_success": False}
            return obs, 0.0, False, True, self._info(terms, task, diverged=True)
        obs = self._observe()
        terms, terminated, task = self._task_reward()
        reward = float(sum(terms.values()))
        return obs, reward, terminated, False, self._info(terms, task)

    def _image(self, image: np.ndarray) -> np.ndarray:
        return image[None] if self.config.channel_axis else image

    def _observe(self) -> dict[str, np.ndarray]:
        config = self.config
        depth = segmentation = None
        if config.labels:
            self.frame = self.frame_renderer.render(self.np_random)
            depth, segmentation = self.frame.depth, self.frame.segmentation
        else:
            self.frame = None
            if "depth" in config.obs_mode:
                # Images without labels: one draw, no label work.
                # Drawn as a labelled frame is (the same skin level of detail).
                depth_clean, geom_id = self.frame_renderer.render_images()
                depth = self.sensor.apply(depth_clean, self.intrinsics, self.np_random)
                if config.obs_mode == "depth+segmentation":
                    segmentation = self.scene.segment(geom_id)
        obs: dict[str, np.ndarray] = {}
        if "depth" in config.obs_mode:
            depth = self._image(depth)
            if config.depth_format == "uint16_mm":
                # In float64: float32 products round some x.5 mm values the wrong way.
                mm = np.rint(np.minimum(depth, np.float32(DEPTH_MAX_M)).astype(np.float64) * 1e3)
                obs["depth"] = mm.astype(np.uint16)
            else:
                obs["depth"] = np.minimum(depth, np.float32(DEPTH_MAX_M))
        if config.obs_mode == "depth+segmentation":
            obs["segmentation"] = self._image(np.asarray(segmentation, dtype=np.int16))
        if "state" in config.obs_mode:
            obs["proprio"] = self._proprio()
        if "object_poses" in self.observation_space.spaces:
            obs.update(self._object_poses())
        obs.update(self._task_observation())
        self._last_obs = obs
        return {k: v.copy() for k, v in obs.items()}

    def _proprio(self) -> np.ndarray:
        data, out = self.scene.data, []
        for binding in self.scene.bindings:
            root = binding.root_dof
            velocities = np.concatenate([data.qvel[root : root + 6], data.qvel[binding.joint_dof]])
            out += [binding.pose(data).vector, velocities]
        return np.concatenate(out)

    def _object_poses(self) -> dict[str, np.ndarray]:
        poses = np.zeros((self.max_objects, 7))
        present = np.zeros(self.max_objects, dtype=np.int8)
        data = self.scene.data
        for k, (body, _) in enumerate(self.scene.objects):
            b = self.scene.model.body(body).id
            poses[k, :3] = data.xpos[b]
            poses[k, 3:] = data.xquat[b]
            present[k] = 1
        return {"object_poses": poses, "object_present": present}

    def _info(
        self, terms: dict[str, float], task: dict[str, Any], *, diverged: bool = False
    ) -> dict[str, Any]:
        self._last_task_info = task
        info: dict[str, Any] = {
            "time_s": float(self.scene.data.time),
            "target_pose": self._targets_vector(),
            "physics_diverged": diverged,
            **{k: float(v) for k, v in terms.items()},
            **{k: _plain(v) for k, v in task.items()},
        }
        if self.config.labels:
            info["labels"] = (
                frame_to_arrays(self.frame) if self.frame is not None else empty_label_arrays()
            )
        return info

    # State round trip ---------------------------------------------------------------------

    def get_state(self) -> dict[str, np.ndarray]:
        """The physics state and the current target (for :meth:`set_state`)."""
        data = self.scene.data
        return {
            "time": np.array(data.time),
            "qpos": data.qpos.copy(),
            "qvel": data.qvel.copy(),
            "act": data.act.copy(),
            "ctrl": data.ctrl.copy(),
            "mocap_pos": data.mocap_pos.copy(),
            "mocap_quat": data.mocap_quat.copy(),
            "qacc_warmstart": data.qacc_warmstart.copy(),
            "target": self._targets_vector(),
        }

    def set_state(self, state: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Restore a state of the same scene; returns the observation of that state.

        Raises:
            InvalidEnvConfig: if the state is not a mapping of :meth:`get_state`'s keys to
                finite arrays that fit this episode's scene (checked before anything changes).
        """
        data = self.scene.data
        arrays = ("qpos", "qvel", "act", "ctrl", "mocap_pos", "mocap_quat", "qacc_warmstart")
        keys = ("time", *arrays, "target")
        if not isinstance(state, Mapping):
            raise InvalidEnvConfig(
                f"state must be a dict from get_state() with keys {', '.join(keys)}; received "
                f"{type(state).__name__}"
            )
        missing = [k for k in keys if k not in state]
        if missing:
            raise InvalidEnvConfig(
                f"state lacks {', '.join(missing)}; a state from get_state() has {', '.join(keys)}"
            )
        values = {}
        for key in keys:
            try:
                value = np.asarray(state[key])
            except (TypeError, ValueError):
                value = np.asarray(None)
            if key == "target":
                shape = (27 * len(self.scene.bindings),)
            else:
                shape = () if key == "time" else getattr(data, key).shape
            if value.dtype.kind not in "iuf" or not np.all(np.isfinite(value)):
                raise InvalidEnvConfig(
                    f"state[{key!r}] must be finite real numbers; received {str(state[key])[:60]!r}"
                )
            if value.shape != shape:
                raise InvalidEnvConfig(
                    f"state[{key!r}] has shape {value.shape}, this scene needs {shape}; states "
                    "only transfer within one scene"
                )
            values[key] = value
        targets = values["target"].reshape(-1, 27)
        for key in arrays:
            getattr(data, key)[:] = values[key]
        data.time = float(values["time"])
        mujoco.mj_forward(self.scene.model, data)
        # A fresh driver: the restored state may follow a divergence.
        self.driver = HandDriver(self.scene, forwarded=True)
        for side, vector in zip(self.sides, targets, strict=True):
            self.driver.set_target(HandPose.from_vector(vector), side)
        return self._observe()

    def close(self) -> None:
        """Free the renderers (idempotent)."""
        self._close_renderers()
        self.scene = None
        self._scene_key = None
