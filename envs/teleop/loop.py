"""The teleoperation loop: an operator stream drives the physical hand through a tracker.

Per control step of the task env (``obs_mode="state"``: the task itself renders nothing):

1. **operator**: the stream's next frame (file or generated stream resampled to the control
   rate, or the newest live packet) gives the operator's keypoints, world frame.
2. **capture** (``mode="camera"``): the operator hand, a render-only hand in a capture scene of
   its own (the task's objects mirrored into it every step, so they occlude it; nothing in it
   collides with the task), is posed from the stream (27-DoF poses directly; keypoint streams
   are first retargeted onto it) and rendered by the capture camera with the sensor model
   (:class:`~handsim.frame.renderer.FrameRenderer`, 320 x 240 ICVL by default).
3. **estimator** (``mode="camera"``): any :class:`~handsim.estimator.Estimator` estimates the
   keypoints from that depth (a :class:`~handsim.estimator.PrivilegedEstimator` such as the
   oracle first receives the frame's truth); the estimate goes to the world frame. In
   ``mode="direct"`` steps 2-3 are skipped: a headset already reports joints.
4. **faults** (:class:`~handsim.envs.teleop.faults.FaultInjector`): noise, bias, latency,
   jitter, occlusion, dropout (held or extrapolated).
5. **filter** (:mod:`~handsim.envs.teleop.filters`): One Euro, exponential or none.
6. **retarget** (:class:`~handsim.hand.retarget.Retargeter`, warm-started, partial keypoints,
   floating scale) onto the physical hand, optionally smoothed in joint space
   (:class:`~handsim.envs.teleop.pose_filter.PoseFilter`), then the grip stabiliser
   (:class:`~handsim.envs.teleop.grip.GripStabiliser`); the pose is the env's action
   (``"pose"`` control).
7. **physics**: the env steps; contacts give the interpenetration, and the interaction
   events (:mod:`~handsim.envs.teleop.events`) are detected.

:meth:`TeleopLoop.run` returns a :class:`TeleopEpisode` with the metrics of
:mod:`handsim.envs.teleop.metrics`, the mean time of every stage, and (``record=True``) the
arrays that :func:`write_rollout` saves for ``handsim view``.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
import weakref
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from handsim.envs.teleop import metrics as tm
from handsim.envs.teleop.capture import Capture, world_from_cam
from handsim.envs.teleop.channel import HandChannel
from handsim.envs.teleop.events import EventDetector, InteractionEvent
from handsim.envs.teleop.faults import FaultConfig
from handsim.envs.teleop.filters import FILTERS, make_filter
from handsim.envs.teleop.handedness import SIDE_CHECK_FRAMES, check_side, fully_tracked
from handsim.envs.teleop.intent import INTENT_DEFAULTS
from handsim.envs.teleop.pose_filter import make_pose_filter
from handsim.envs.teleop.rollout import ROLLOUT_VERSION, read_rollout, write_rollout
from handsim.envs.teleop.sampling import LiveSampler
from handsim.envs.teleop.streams import InvalidStream, OperatorStream
from handsim.errors import HandSimError
from handsim.estimator import Estimate, Estimator, PrivilegedEstimator

__all__ = [
    "MODES",
    "ANCHORS",
    "STAGES",
    "TeleopConfig",
    "TeleopEpisode",
    "TeleopLoop",
    "InvalidTeleopConfig",
    "write_rollout",
    "read_rollout",
    "ROLLOUT_VERSION",
    "POSE_FILTERS",
    "GRIP_STEADY",
    "MAX_CONTROL_RATE_HZ",
    "PHYSICS_DT_S",
    "BehindRealTime",
    "frame_skip_for",
]

MODES: tuple[str, ...] = ("direct", "camera")
"""``direct``: the stream's keypoints are the tracking; ``camera``: capture + estimator."""
ANCHORS: tuple[str, ...] = ("none", "start")
"""``start``: move the stream so its first wrist is at the physical hand's start wrist."""
STAGES: tuple[str, ...] = ("capture", "estimator", "faults", "filter", "retarget", "physics")
"""The timed stages of a step."""
GRIP_STEADY: tuple[bool | str, ...] = (False, True, "hand")
"""Values of :attr:`TeleopConfig.grip_steady`: off, held digits, the whole hand while held."""
POSE_FILTERS: tuple[bool | str, ...] = (False, True, "wrist", "auto")
"""Values of :attr:`TeleopConfig.pose_filter`: off, the whole pose, the wrist only, the whole
pose with cut-offs that follow the keypoint noise."""
PHYSICS_DT_S = 0.002
"""The envs' physics step, seconds (500 Hz)."""
MAX_CONTROL_RATE_HZ = 120.0
"""Fastest stream rate the loop follows one control step per packet (a headset's 120 Hz)."""
_DEFAULT_CONTROL_DT_S = 0.02  # the envs' default frame_skip=10: their episode limits' unit
_BEHIND_FRACTION = 0.9  # real-time factor under which a live loop warns
_BEHIND_WINDOW_S = 1.0


class BehindRealTime(UserWarning):
    """A real-time loop ran slower than real time (the hand lags the operator more and more)."""


def frame_skip_for(rate_hz: float) -> int:
    """Physics steps per control step for a stream of ``rate_hz``.

    The control rate is the fastest multiple of the physics period not slower than the stream,
    so every packet is applied (90 Hz: 5 steps, 100 Hz control; 120 Hz: 4 steps, 125 Hz;
    50 Hz: 10 steps); a rate within 0.5 % of a multiple takes it (a measured 50.2 Hz: 50 Hz).

    Raises:
        InvalidTeleopConfig: unless ``0 < rate_hz <= 120``.
    """
    if (
        isinstance(rate_hz, bool)
        or not isinstance(rate_hz, (int, float))
        or not 0 < rate_hz <= MAX_CONTROL_RATE_HZ
    ):
        raise InvalidTeleopConfig(
            f"control_rate_hz must be a number in (0, {MAX_CONTROL_RATE_HZ:g}] Hz; received "
            f"{rate_hz!r} (a faster stream is resampled to {MAX_CONTROL_RATE_HZ:g} Hz)"
        )
    # Within 0.5 % of a multiple counts as it: a measured 50.2 Hz is a 50 Hz stream.
    return max(1, int(math.floor(1.005 / (rate_hz * PHYSICS_DT_S))))


class InvalidTeleopConfig(HandSimError, ValueError):
    """A teleop setting is invalid."""


@dataclasses.dataclass(frozen=True)
class TeleopConfig:
    """Settings of the loop.

    Attributes:
        mode: one of :data:`MODES`.
        faults: tracking faults.
        filter: one of :data:`~handsim.envs.teleop.filters.FILTERS`.
        filter_params: the filter's parameters (e.g. ``{"min_cutoff_hz": 1.0, "beta": 10.0}``).
        anchor: one of :data:`ANCHORS`.
        sensor: the capture camera's sensor model (``camera`` mode): ``none``,
            ``structured_light`` or ``tof``.
        camera: the capture camera preset (``camera`` mode).
        grip_hold: stabilise grips (:class:`~handsim.envs.teleop.grip.GripStabiliser`: a
            digit touching an object stops at its surface and opens only when the tracked
            digit clearly opens). Nothing is attached; the time it holds is ``grip_hold_s``
            in the metrics.
        grip_steady: with the grip stabiliser, a held digit takes the running mean of its
            targets (0.15 s) instead of each frame's (``True``; its flexion the press, which
            rises as the mean closes, its spread joints the mean); ``"hand"``: while any digit
            is held, the free digits take the running mean too; ``False`` (default): a
            tracked target past the press comes through at once. Nothing is attached.
        pose_filter: smooth the retargeted pose in joint space
            (:class:`~handsim.envs.teleop.pose_filter.PoseFilter`, One Euro per part):
            ``False`` (off), ``True`` (the wrist and the fingers), ``"wrist"`` (the wrist
            only; the fingers as fitted) or ``"auto"`` (the whole pose, its rest cut-offs
            multiplied by ``(10 mm / sigma)^2``, in [1, 30], for keypoint noise ``sigma``:
            ``keypoint_sigma_mm``, the faults' ``noise_mm`` when ``None``, estimated from the
            stream with ``"auto"``; :meth:`PoseFilter.set_keypoint_noise
            <handsim.envs.teleop.pose_filter.PoseFilter.set_keypoint_noise>`).
        pose_filter_params: its parameters (e.g. ``{"min_cutoff_hz": 1.0}``).
        grasp_intent: drive the fingers from a per-hand grasp intent while the hand grasps
            an object (:class:`~handsim.envs.teleop.intent.GraspIntent`: a closure measure
            of ten keypoints with hysteresis; while it grasps, a digit on the object presses
            from its contact flexion and the others follow the tracked angles averaged since
            the onset). Nothing is attached; the seconds in
            grasp intent, its onsets and releases are ``intent_grasp_s``,
            ``intent_onsets`` and ``intent_releases``.
        intent_params: its parameters (keys of
            :data:`~handsim.envs.teleop.intent.INTENT_DEFAULTS`).
        closure_assist: with the grasp intent, each digit of the object's grasp type that
            does not touch it yet closes toward it at the type's pace until it touches, then
            presses from its contact (``close_s`` of the intent's parameters:
            :data:`~handsim.envs.teleop.intent.CLOSE_S` unless given); and the intent starts
            only while the tracked flexion is noisy (``noise_gate_rad``:
            :data:`~handsim.envs.teleop.intent.NOISE_GATE_RAD` unless given; with clean
            tracking the operator's own fingers grasp). Nothing is attached;
            the seconds the assist drove a digit are ``closure_assist_s`` (per digit:
            ``closure_assist_digit_s``) and a success while it did is ``success_assisted``.
        pose_prior: retarget with a prior over natural postures (maximum a posteriori:
            :func:`~handsim.hand.pose_prior.default_pose_prior`, the grasp taxonomy and the
            gestures), the keypoints weighed by their noise ``keypoint_sigma_mm``.
        keypoint_sigma_mm: the tracked keypoints' noise the prior is weighed against, mm
            per axis (``None``: the faults' ``noise_mm``; 0 turns the prior off; ``"auto"``:
            estimated from the tracked stream's own jitter,
            :class:`~handsim.hand.pose_prior.KeypointNoiseEstimator`, looked at every
            :data:`~handsim.envs.teleop.channel.SIGMA_UPDATE_FRAMES` frames; the plain fit
            until known). The value in use at the end is the metric ``keypoint_sigma_mm``.
        record: keep the per-step arrays for :func:`write_rollout`.
        seed: seed of the faults and the sensor noise (episode ``s`` uses ``seed + s``).
    """

    mode: str = "direct"
    faults: FaultConfig = dataclasses.field(default_factory=FaultConfig)
    filter: str = "none"
    filter_params: dict[str, float] = dataclasses.field(default_factory=dict)
    anchor: str = "none"
    sensor: str = "none"
    camera: str = "icvl"
    grip_hold: bool = True
    grip_steady: bool | str = False
    pose_filter: bool | str = False
    pose_filter_params: dict[str, float] = dataclasses.field(default_factory=dict)
    grasp_intent: bool = False
    intent_params: dict[str, float] = dataclasses.field(default_factory=dict)
    closure_assist: bool = False
    pose_prior: bool = False
    keypoint_sigma_mm: float | str | None = None
    record: bool = False
    seed: int = 0

    def __post_init__(self) -> None:
        for name, valid in (
            ("mode", MODES),
            ("filter", FILTERS),
            ("anchor", ANCHORS),
            ("sensor", ("none", "structured_light", "tof")),
        ):
            if getattr(self, name) not in valid:
                raise InvalidTeleopConfig(
                    f"{name}={getattr(self, name)!r} is not valid; choose one of {', '.join(valid)}"
                )
        if not isinstance(self.faults, FaultConfig):
            raise InvalidTeleopConfig(
                f"faults must be a FaultConfig; received {type(self.faults).__name__}"
            )
        if self.pose_filter not in POSE_FILTERS:
            raise InvalidTeleopConfig(
                f"pose_filter={self.pose_filter!r} is not valid; choose False (off), True (the "
                "wrist and the fingers), 'wrist' (the wrist only) or 'auto' (the whole pose, "
                "cut-offs following the keypoint noise)"
            )
        make_filter(self.filter, 50.0, **self.filter_params)  # raises InvalidFilter
        make_pose_filter(50.0, **self.pose_filter_params)
        unknown = sorted(set(self.intent_params) - set(INTENT_DEFAULTS))
        if unknown:
            raise InvalidTeleopConfig(
                f"intent_params {unknown} are not valid; choose from {', '.join(INTENT_DEFAULTS)}"
            )
        sigma = self.keypoint_sigma_mm
        if not isinstance(self.pose_prior, bool) or (
            sigma is not None
            and sigma != "auto"
            and (
                isinstance(sigma, bool)
                or not isinstance(sigma, (int, float))
                or not math.isfinite(sigma)
                or sigma < 0
            )
        ):
            raise InvalidTeleopConfig(
                f"pose_prior must be True or False and keypoint_sigma_mm None (the faults' "
                f"noise_mm), 'auto' (estimated from the stream) or a number >= 0 (mm); "
                f"received {self.pose_prior!r} and {sigma!r}"
            )
        if self.grip_steady not in GRIP_STEADY:
            raise InvalidTeleopConfig(
                f"grip_steady={self.grip_steady!r} is not valid; choose False (off), True (a "
                "held digit takes its running mean) or 'hand' (every digit while one is held)"
            )
        if self.grip_steady and not self.grip_hold:
            raise InvalidTeleopConfig(
                "grip_steady acts on the grip stabiliser's held digits: set grip_hold=True "
                "with it (CLI: --grip-hold on)"
            )
        if self.closure_assist and not self.grasp_intent:
            raise InvalidTeleopConfig(
                "closure_assist acts while the grasp intent grasps: set grasp_intent=True with "
                "it (CLI: --grasp-intent on --closure-assist on)"
            )

    def label(self) -> str:
        """A short description (plot legends, tables)."""
        f = self.faults
        return (
            f"{self.mode}, noise {f.noise_mm:g} mm, latency {f.latency_frames}, dropout "
            f"{f.dropout:g}, filter {self.filter}"
        )


@dataclasses.dataclass
class TeleopEpisode:
    """One episode's outcome.

    Attributes:
        metrics: the figures of :mod:`handsim.envs.teleop.metrics` (``success``,
            ``time_to_success_s``, ``penetration_max_mm``, ``penetration_mean_mm``,
            ``slip_max_mm``, ``jitter_mm``, ``operator_jitter_mm``, ``lag_s``,
            ``unintended_presses``, ``tracking_error_mm``, ``grip_hold_s`` (seconds with a
            digit's target held by the grip stabiliser), ``intent_grasp_s``,
            ``intent_onsets``, ``intent_releases`` (the grasp intent), ``steps``,
            ``dropped_frames``, ``steps_per_s``, ``realtime_factor``), ``stage_ms`` (mean
            milliseconds per stage), ``events`` (count per kind) and, for a
            :class:`~handsim.envs.teleop.sampling.LiveSampler` stream, its latency summary
            (``latency_p50_ms``, ``latency_p95_ms``, ``residual_latency_*``,
            ``latency_clock``, ``packets_used``).
        arrays: per-step arrays when recorded (see :func:`write_rollout`), else empty.
        events: the interaction events, in order (:mod:`~handsim.envs.teleop.events`).
    """

    metrics: dict[str, Any]
    arrays: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    events: list[InteractionEvent] = dataclasses.field(default_factory=list)


class TeleopLoop:
    """Runs teleoperation episodes of one task env (see the module docstring).

    Args:
        env_id: a registered handsim id with ``"pose"`` control (e.g. ``handsim/Grasp-v0``,
            ``handsim/Press-v0``).
        config: the loop's settings.
        estimator: the estimator of ``camera`` mode (e.g.
            :class:`~handsim.estimators.oracle.OracleEstimator`); unused in ``direct`` mode.
        env_kwargs: more keyword arguments of ``gym.make`` (``obs_mode`` is ``"state"``).
        control_rate_hz: the stream's rate, Hz, in (0, 120]: the physics sub-steps per control
            step are sized to it (:func:`frame_skip_for`) and the episode limit is scaled to
            keep its duration in seconds. ``None``: the env's default (50 Hz).
        episode_s: raise the task's episode limit to at least this many seconds (a live
            session of ``--duration`` seconds); ``None`` keeps the task's limit.

    Raises:
        InvalidTeleopConfig: camera mode without an estimator, or an estimator that does not
            satisfy the protocol; a rate or duration out of range.
    """

    def __init__(
        self,
        env_id: str = "handsim/Grasp-v0",
        config: TeleopConfig | None = None,
        *,
        estimator: Estimator | None = None,
        env_kwargs: dict[str, Any] | None = None,
        control_rate_hz: float | None = None,
        episode_s: float | None = None,
    ) -> None:
        import handsim.envs  # noqa: F401 (registers the ids)

        self.config = config if config is not None else TeleopConfig()
        if self.config.mode == "camera":
            if estimator is None:
                raise InvalidTeleopConfig(
                    "mode='camera' needs an estimator (e.g. handsim.estimators.oracle."
                    "OracleEstimator()); use mode='direct' to skip the camera"
                )
            if not isinstance(estimator, Estimator):
                raise InvalidTeleopConfig(
                    f"estimator must satisfy handsim.estimator.Estimator "
                    f"(predict, predict_batch, reset); received "
                    f"{type(estimator).__name__}"
                )
        self.estimator = estimator
        self.env_id = env_id
        kwargs = {**(env_kwargs or {}), "obs_mode": "state", "control_mode": "pose"}
        if control_rate_hz is not None or episode_s is not None:
            frame_skip = (
                frame_skip_for(control_rate_hz)
                if control_rate_hz is not None
                else int(kwargs.get("frame_skip", 10))
            )
            kwargs["frame_skip"] = frame_skip
            spec_steps = gym.spec(env_id).max_episode_steps or 1000
            limit_s = kwargs.pop("max_episode_steps", spec_steps) * _DEFAULT_CONTROL_DT_S
            if episode_s is not None:
                if (
                    isinstance(episode_s, bool)
                    or not isinstance(episode_s, (int, float))
                    or not 0 < episode_s <= 86400
                ):
                    raise InvalidTeleopConfig(
                        f"episode_s must be a number of seconds in (0, 86400]; received "
                        f"{episode_s!r}"
                    )
                limit_s = max(limit_s, float(episode_s))
            kwargs["max_episode_steps"] = int(math.ceil(limit_s / (frame_skip * PHYSICS_DT_S)))
        self.env_kwargs = kwargs
        self.env = gym.make(env_id, **self.env_kwargs)
        if getattr(self.env.unwrapped, "two_hands", False) and type(self) is TeleopLoop:
            self.env.close()
            raise InvalidTeleopConfig(
                f"{env_id} has two hands: run it with "
                "handsim.envs.teleop.two_hands.TwoHandTeleopLoop (a stream per hand)"
            )
        self._capture: Capture | None = None
        self._side_checked: weakref.WeakSet[OperatorStream] = weakref.WeakSet()
        self._capture_key: tuple | None = None

    def close(self) -> None:
        """Free the env and the capture renderer."""
        if self._capture is not None:
            self._capture.close()
            self._capture = None
        self.env.close()

    def __enter__(self) -> TeleopLoop:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def control_dt(self) -> float:
        """The env's control period, seconds (the stream is resampled to its rate)."""
        return float(self.env.unwrapped.control_dt)

    def run(
        self,
        stream: OperatorStream | Callable[[int], np.ndarray | None],
        seed: int = 0,
        *,
        max_steps: int | None = None,
        realtime: bool = False,
        stop_at_success: bool = True,
        on_step: Callable[[int, dict[str, Any]], None] | None = None,
    ) -> TeleopEpisode:
        """Run one episode driven by ``stream``.

        Args:
            stream: an :class:`OperatorStream` (resampled to the control rate here), a
                :class:`~handsim.envs.teleop.sampling.LiveSampler` (live: timestamp-aware,
                with the end-to-end latency in the metrics), or a function
                ``step -> (21, 3) keypoints or None`` (``None``: nothing received yet, the
                hand holds still).
            seed: the env's episode seed (use the seed the stream was generated on).
            max_steps: stop after this many steps (default: the env's episode limit, or the
                stream's length if longer; after a stream's last frame the operator holds
                still).
            realtime: pace the steps at the control rate (live streams); a loop slower
                than 90 % of real time over a second warns once (:class:`BehindRealTime`).
            stop_at_success: end the episode at the task's success (the env terminates).
            on_step: called after every physics step with the step number and
                ``{"operator_world", "tracked_world", "anchor_offset_m", "success"}`` ((21, 3)
                keypoints, world frame, m, or ``None``; what the anchor added to the stream,
                (3,) m; bool): e.g. a
                :class:`~handsim.envs.teleop.xr_state.StatePublisher` streaming to the page.

        Returns:
            The episode's metrics (and arrays with ``config.record``).

        Raises:
            InvalidStream: a stream of the other hand side than the task's hand, by its
                ``hand`` or by its geometry (:func:`~handsim.envs.teleop.handedness.check_side`;
                live: on its first fully tracked frames).
        """
        cfg = self.config
        env, base = self.env, self.env.unwrapped
        _, info = env.reset(seed=seed)
        dt = self.control_dt
        limit = (env.spec.max_episode_steps if env.spec is not None else None) or 1000
        frames: Callable[[int], tuple[np.ndarray | None, np.ndarray | None]]
        side = base.scene.hand.params.side
        # What anchor="start" adds to the stream, world frame, m (empty: nothing yet).
        anchor_offset: list[np.ndarray] = []
        if isinstance(stream, OperatorStream):
            name = stream.source or "the stream"
            if stream.side != side:
                raise InvalidStream(
                    f"{name} is a {stream.side} hand, but the task's hand is {side}: make the "
                    f"env with handedness={stream.side!r} (the CLI does), or mirror the stream"
                )
            if stream.poses is None and stream not in self._side_checked:
                check_side(stream.keypoints_world, stream.side, name)
                self._side_checked.add(stream)
            s = stream.resample(1.0 / dt)
            if cfg.anchor == "start":
                start = base.scene.binding.keypoints(base.scene.data)[0]
                anchor_offset = [start - s.first_wrist_m()]
                s = s.translated(anchor_offset[0])
            n_frames = len(s)
            # After the stream's end the operator holds still (its last frame).
            steps = max_steps or max(limit, n_frames - 1)

            def frames(i: int) -> tuple[np.ndarray | None, np.ndarray | None]:
                k = min(i, n_frames - 1)
                return s.keypoints_world[k], (None if s.poses is None else s.poses[k])

            operator_length = s.hand_length_m
        else:
            steps = max_steps or limit
            if isinstance(stream, LiveSampler) and stream.side != side:
                raise InvalidTeleopConfig(
                    f"the live sampler follows the {stream.side} hand, but the task's hand is "
                    f"{side}: make the env with handedness={stream.side!r}"
                )
            # The first fully tracked live frames vote on the stream's side.
            to_check: list[np.ndarray] = []

            def frames(i: int) -> tuple[np.ndarray | None, np.ndarray | None]:
                kp = stream(i)
                if kp is None:
                    return None, None
                kp = np.asarray(kp, dtype=np.float64)
                if len(to_check) < SIDE_CHECK_FRAMES and fully_tracked(kp):
                    to_check.append(kp)
                    if len(to_check) == SIDE_CHECK_FRAMES:
                        check_side(np.stack(to_check), side, "the live stream")
                if cfg.anchor == "start":
                    if not anchor_offset and np.all(np.isfinite(kp[0])):
                        start = base.scene.binding.keypoints(base.scene.data)[0]
                        anchor_offset.append(start - kp[0])
                    if anchor_offset:
                        kp = kp + anchor_offset[0]
                return kp, None

            operator_length = None
        sampler = stream if isinstance(stream, LiveSampler) else None
        params = base.scene.hand.params
        rng = np.random.default_rng(cfg.seed + seed)
        faults_cfg = cfg.faults
        capture = None
        if cfg.mode == "camera":
            key = (operator_length or params.hand_length, params.side, id(base.scene))
            if self._capture is None or self._capture_key != key:
                if self._capture is not None:
                    self._capture.close()
                self._capture = Capture(env, key[0], params.side, cfg)
                self._capture_key = key
            capture = self._capture
            capture.reset()
            faults_cfg = dataclasses.replace(faults_cfg, viewpoint_m=tuple(capture.camera_pos_m))
            self.estimator.reset()
        hand = HandChannel(cfg, base.scene, dt, rng, faults_cfg)
        hand_geoms = tm.hand_geom_mask(
            base.scene.model, base.scene.model.body(base.scene.hand.root_body).id
        )
        times = dict.fromkeys(STAGES, 0.0)
        detector = EventDetector(base, dt)
        rec: dict[str, list[Any]] = {
            k: []
            for k in (
                "operator",
                "tracked",
                "physical",
                "dropped",
                "penetration",
                "touching",
                "success",
                "estimate_cam",
                "truth_cam",
                "depth_mm",
                "qpos",
                "mocap_pos",
                "mocap_quat",
                "slip",
                "retarget_error",
                "intent",
            )
        }
        record = cfg.record
        data = base.scene.data
        first_success = None
        success_assisted = False
        unintended = math.nan
        n_done = 0
        start_wall = time.perf_counter()
        window, warned = (start_wall, 0), False
        terminated = truncated = False
        for i in range(1, steps + 1):
            tick = time.perf_counter()
            operator_kp, operator_pose = frames(i)
            if operator_kp is None:
                tracked, dropped = None, True
            else:
                if capture is not None:
                    capture.pose_operator(operator_pose, operator_kp, data)
                    frame = capture.render(rng)
                    t1 = time.perf_counter()
                    times["capture"] += t1 - tick
                    if isinstance(self.estimator, PrivilegedEstimator):
                        self.estimator.observe_truth(frame)
                    estimate = self.estimator.predict(frame.depth, frame.K)
                    t2 = time.perf_counter()
                    times["estimator"] += t2 - t1
                    measured = _estimate_world(estimate, frame.T_cam_from_world)
                    if record:
                        rec["truth_cam"].append(frame.keypoints_cam.copy())
                        rec["estimate_cam"].append(
                            estimate.keypoints_cam
                            if estimate.valid and estimate.keypoints_cam is not None
                            else np.full((21, 3), np.nan)
                        )
                        rec["depth_mm"].append(
                            np.minimum(np.rint(frame.depth * 1e3), 65535).astype(np.uint16)
                        )
                        if i == 1:
                            rec["K"] = frame.K.copy()
                            rec["T_cam_from_world"] = frame.T_cam_from_world.copy()
                    tick = t2
                else:
                    measured = operator_kp
                tracked, dropped, fit = hand.track(measured, times, tick)
                if record and fit is not None:
                    rec["retarget_error"].append(fit.keypoint_error_m)
            t5 = time.perf_counter()
            _, _, terminated, truncated, info = env.step(hand.action(tracked, data))
            times["physics"] += time.perf_counter() - t5
            if sampler is not None:
                sampler.applied()
            detector.update(i, tracked, data, info)
            n_done = i
            penetration, touching = tm.hand_penetration_m(data, hand_geoms)
            physical = base.scene.binding.keypoints(data)
            rec["operator"].append(
                operator_kp if operator_kp is not None else np.full((21, 3), np.nan)
            )
            rec["tracked"].append(tracked if tracked is not None else np.full((21, 3), np.nan))
            rec["physical"].append(physical)
            rec["dropped"].append(dropped)
            rec["penetration"].append(penetration)
            rec["touching"].append(touching)
            rec["success"].append(bool(info.get("is_success", False)))
            rec["intent"].append(bool(hand.intent is not None and hand.intent.grasping))
            rec["slip"].append(float(info.get("slip_m", math.nan)))
            if record:
                rec["qpos"].append(data.qpos.copy())
                rec["mocap_pos"].append(data.mocap_pos.copy())
                rec["mocap_quat"].append(data.mocap_quat.copy())
            if "unintended_presses" in info:
                unintended = float(info["unintended_presses"])
            if first_success is None and rec["success"][-1]:
                first_success = i
                success_assisted = hand.assisted()
            if on_step is not None:
                on_step(
                    i,
                    {
                        "operator_world": operator_kp,
                        "tracked_world": tracked,
                        "anchor_offset_m": anchor_offset[0] if anchor_offset else np.zeros(3),
                        "success": rec["success"][-1],
                    },
                )
            if realtime:
                now = time.perf_counter()
                wait = start_wall + i * dt - now
                if wait > 0:
                    time.sleep(wait)
                elif now - window[0] >= _BEHIND_WINDOW_S:
                    factor = (i - window[1]) * dt / (now - window[0])
                    if factor < _BEHIND_FRACTION and not warned:
                        warned = True
                        slowest = max(times, key=times.get)
                        warnings.warn(
                            f"the teleop loop runs at {100 * factor:.0f} % of real time "
                            f"({1 / dt:.0f} Hz control; slowest stage: {slowest}, "
                            f"{times[slowest] / i * 1e3:.1f} ms per step): the hand falls "
                            "behind the operator; use mode='direct', a lower rate or a "
                            "faster machine",
                            BehindRealTime,
                            stacklevel=2,
                        )
                    window = (now, i)
            if (terminated and stop_at_success) or truncated:
                break
        wall = time.perf_counter() - start_wall
        operator = np.array(rec["operator"])
        physical = np.array(rec["physical"])
        penetration = np.array(rec["penetration"])
        touching = np.array(rec["touching"], dtype=bool)
        slip = np.array(rec["slip"])
        tips = list(tm.FINGERTIPS)
        pts = [0, *tips]
        dists = np.linalg.norm(physical - operator, axis=-1)
        metrics = {
            "env_id": self.env_id,
            "seed": seed,
            "config": {**dataclasses.asdict(cfg), "faults": cfg.faults.to_dict()},
            "estimator": repr(self.estimator) if cfg.mode == "camera" else None,
            "success": bool(first_success is not None),
            "time_to_success_s": first_success * dt if first_success is not None else math.nan,
            # A success while the closure assist drove a digit (still a physical grasp).
            "success_assisted": bool(success_assisted),
            "penetration_max_mm": float(penetration.max() * 1e3) if n_done else math.nan,
            "penetration_mean_mm": (
                float(penetration[touching].mean() * 1e3) if touching.any() else 0.0
            ),
            "slip_max_mm": (float(np.nanmax(slip) * 1e3) if np.isfinite(slip).any() else math.nan),
            "jitter_mm": tm.high_frequency_rms_mm(physical[:, tips], dt),
            "operator_jitter_mm": tm.high_frequency_rms_mm(operator[:, tips], dt),
            "lag_s": (
                tm.lag_frames(operator[:, pts], physical[:, pts], int(round(tm.MAX_LAG_S / dt)))
                * dt
                if n_done > 8
                else math.nan
            ),
            "unintended_presses": unintended,
            "tracking_error_mm": (
                float(np.nanmean(dists) * 1e3) if np.isfinite(dists).any() else math.nan
            ),
            **hand.metrics(dt),
            "steps": n_done,
            "control_dt_s": dt,
            "dropped_frames": int(np.sum(rec["dropped"])),
            "physics_diverged": bool(info.get("physics_diverged", False)),
            "steps_per_s": n_done / wall if wall > 0 else math.nan,
            "realtime_factor": n_done * dt / wall if wall > 0 else math.nan,
            "stage_ms": {k: (v / n_done * 1e3 if n_done else math.nan) for k, v in times.items()},
            "events": detector.counts(),
        }
        if sampler is not None:
            metrics.update(sampler.summary())
        arrays: dict[str, np.ndarray] = {}
        if record:
            arrays = {
                "operator_world": operator,
                "tracked_world": np.array(rec["tracked"]),
                "physical_world": physical,
                "dropped": np.array(rec["dropped"], dtype=bool),
                "penetration_m": penetration,
                "success": np.array(rec["success"], dtype=bool),
                "intent": np.array(rec["intent"], dtype=bool),
                "qpos": np.array(rec["qpos"]),
                "mocap_pos": np.array(rec["mocap_pos"]),
                "mocap_quat": np.array(rec["mocap_quat"]),
            }
            if rec["depth_mm"]:
                arrays.update(
                    depth_mm=np.array(rec["depth_mm"]),
                    truth_cam=np.array(rec["truth_cam"]),
                    estimate_cam=np.array(rec["estimate_cam"]),
                    K=rec["K"],
                    T_cam_from_world=rec["T_cam_from_world"],
                )
        return TeleopEpisode(metrics, arrays, detector.events)


def _estimate_world(estimate: Estimate, T_cam_from_world: np.ndarray) -> np.ndarray:  # noqa: N803
    if not estimate.valid or estimate.keypoints_cam is None:
        return np.full((21, 3), np.nan)
    return world_from_cam(np.asarray(T_cam_from_world), np.asarray(estimate.keypoints_cam))
