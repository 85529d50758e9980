"""Two hands at once: one stream per hand, routed by its side, driving a two-hand task.

OpenXR and WebXR track both hands; a two-hand task env (``handsim/PressTwoHands-v0``: a right
and a left physical hand, 54-D actions) takes both. :class:`TwoHandTeleopLoop` runs the loop of
:class:`~handsim.envs.teleop.loop.TeleopLoop` once per hand and steps the physics once for both:

- **routing**: every stream carries its side (a file's or a packet's ``hand``;
  :attr:`OperatorStream.side`, :attr:`LiveSampler.side`), and goes to the hand of that side.
  Two streams of one side are refused; a hand without a stream holds its start pose.
- **side check**: a stream whose geometry is the other side than its ``hand`` says is refused
  (:func:`~handsim.envs.teleop.handedness.check_side`: files on up to 5 fully tracked frames,
  live streams on their first 5), as for one hand.
- **anchor** (``anchor="start"``): one offset for both hands, from the first hand that has a
  stream (its first wrist onto its physical start wrist), since both come from one tracking
  space: the hands keep where they are relative to each other.
- per hand: faults (each hand its own generator), filter, retargeting onto its own hand, the
  pose filter (``pose_filter``), the grasp intent (``grasp_intent``) and the grip
  stabiliser, the one-hand loop's path (:class:`~handsim.envs.teleop.channel.HandChannel`);
  one
  :class:`~handsim.envs.teleop.events.EventDetector` for both, so every event names its hand.

``direct`` mode only (a headset reports joints); the capture camera of ``camera`` mode renders
one operator hand.

A two-hand stream file is a JSON object with ``"hands"``: a list of stream objects (the keys of
a one-hand file, each with its ``hand``); keys beside ``"hands"`` (``format``, ``units``,
``up_axis``, ``fps``) are defaults for each. :func:`load_streams` reads it (and a one-hand file
as one stream), :func:`save_streams` writes it, :func:`streams_from_expert` records a two-hand
task's scripted expert.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pathlib
import time
import warnings
import weakref
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from handsim.envs.teleop import metrics as tm
from handsim.envs.teleop.channel import HandChannel
from handsim.envs.teleop.events import EventDetector
from handsim.envs.teleop.handedness import SIDE_CHECK_FRAMES, check_side, fully_tracked
from handsim.envs.teleop.loop import (
    _BEHIND_FRACTION,
    _BEHIND_WINDOW_S,
    STAGES,
    BehindRealTime,
    InvalidTeleopConfig,
    TeleopConfig,
    TeleopEpisode,
    TeleopLoop,
)
from handsim.envs.teleop.sampling import LiveSampler
from handsim.envs.teleop.streams import (
    InvalidStream,
    OperatorStream,
    load_stream,
    parse_stream,
    stream_from_poses,
    stream_to_doc,
)

__all__ = [
    "TwoHandTeleopLoop",
    "load_streams",
    "save_streams",
    "parse_streams",
    "route_streams",
    "streams_from_expert",
    "HANDS_KEY",
]

HANDS_KEY = "hands"
"""The key of a two-hand stream file that lists its hands' streams."""
_DEFAULT_KEYS = ("format", "units", "up_axis", "fps")

Source = OperatorStream | LiveSampler | Callable[[int], np.ndarray | None]


def parse_streams(doc: dict[str, Any], source: str = "<dict>") -> tuple[OperatorStream, ...]:
    """The streams of a two-hand stream object (module docstring), or of a one-hand one.

    Raises:
        InvalidStream: for a malformed entry (naming ``hands[i]``) or two of one side.
    """
    if not isinstance(doc, dict):
        raise InvalidStream(f"stream {source}: expected a JSON object; received {type(doc)}")
    if HANDS_KEY not in doc:
        return (parse_stream(doc, source),)
    entries = doc[HANDS_KEY]
    if not isinstance(entries, list) or not 1 <= len(entries) <= 2:
        raise InvalidStream(
            f"stream {source}: 'hands' must be a list of one or two stream objects (each with "
            f"its 'hand': 'right' or 'left'); received {str(entries)[:60]!r}"
        )
    defaults = {k: doc[k] for k in _DEFAULT_KEYS if k in doc}
    streams = []
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict):
            raise InvalidStream(
                f"stream {source}: hands[{i}] must be a stream object; received "
                f"{type(entry).__name__}"
            )
        streams.append(parse_stream({**defaults, **entry}, f"{source} hands[{i}]"))
    route_streams(streams)  # refuses two of one side
    return tuple(streams)


def load_streams(path: str | os.PathLike[str]) -> tuple[OperatorStream, ...]:
    """Read a two-hand stream file (``.json``, module docstring) or a one-hand file (any).

    Raises:
        InvalidStream: as :func:`~handsim.envs.teleop.streams.load_stream`, and for two
            streams of one side.
    """
    p = pathlib.Path(path)
    if p.suffix.lower() == ".json" and p.is_file():
        try:
            doc = json.loads(p.read_text())
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
            doc = None  # load_stream names what is wrong
        if isinstance(doc, dict) and HANDS_KEY in doc:
            return parse_streams(doc, str(p))
    return (load_stream(p),)


def save_streams(streams: Sequence[OperatorStream], path: str | os.PathLike[str]) -> pathlib.Path:
    """Write streams (one per side) as one two-hand JSON file; returns its path.

    Raises:
        InvalidStream: for a path not ending in ``.json``, or two streams of one side.
    """
    p = pathlib.Path(path)
    if p.suffix.lower() != ".json":
        raise InvalidStream(f"a two-hand stream file is JSON: {str(p)!r} must end in .json")
    route_streams(streams)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps({HANDS_KEY: [stream_to_doc(s) for s in streams]}))
    return p


def route_streams(streams: Sequence[Source] | Mapping[str, Source]) -> dict[str, Source]:
    """Streams by the side they carry (a mapping: by its keys, checked against the streams').

    Raises:
        InvalidStream: two streams of one side, a side not ``right``/``left``, or a mapping
            key that disagrees with its stream's side.
    """
    if isinstance(streams, Mapping):
        items = list(streams.items())
    else:
        if isinstance(streams, (OperatorStream, LiveSampler)) or callable(streams):
            streams = [streams]
        items = []
        for s in streams:
            side = getattr(s, "side", None)
            if side is None:
                raise InvalidStream(
                    "a function stream carries no side: pass the streams as a dict by side, "
                    "e.g. {'right': f, 'left': g}"
                )
            items.append((side, s))
    routed: dict[str, Source] = {}
    for side, s in items:
        if side not in ("right", "left"):
            raise InvalidStream(f"hand={side!r} is not valid; one of right, left")
        own = getattr(s, "side", side)
        if own != side:
            raise InvalidStream(f"the stream given for the {side} hand is a {own} hand's")
        if side in routed:
            names = [getattr(x, "source", None) or "a stream" for x in (routed[side], s)]
            raise InvalidStream(
                f"two streams of the {side} hand ({names[0]}; {names[1]}): one stream per "
                "hand, one right and one left (set each stream's 'hand')"
            )
        routed[side] = s
    return routed


def streams_from_expert(
    env_id: str = "handsim/PressTwoHands-v0",
    seed: int = 0,
    *,
    env_kwargs: dict[str, Any] | None = None,
    max_steps: int | None = None,
) -> tuple[OperatorStream, ...]:
    """A two-hand task's scripted expert of one episode, as one ``pose27`` stream per hand.

    Replayed through :class:`TwoHandTeleopLoop` on the same seed without faults, the physical
    hands repeat the expert's episode.
    """
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)

    env = gym.make(env_id, **{"obs_mode": "state", **(env_kwargs or {})})
    try:
        base = env.unwrapped
        if not getattr(base, "two_hands", False):
            raise InvalidTeleopConfig(
                f"{env_id} is a one-hand env: use stream_from_expert (handsim.envs.teleop)"
            )
        env.reset(seed=seed)
        expert = base.make_expert(np.random.default_rng(seed))
        limit = max_steps or (env.spec.max_episode_steps if env.spec else None) or 400
        sides = base.sides
        poses = {s: [base.scene.hand_binding(s).pose(base.scene.data).vector] for s in sides}
        for _ in range(limit):
            action = np.clip(
                expert.action(base.expert_state()), env.action_space.low, env.action_space.high
            )
            for k, side in enumerate(sides):
                poses[side].append(action[27 * k : 27 * (k + 1)].astype(np.float64))
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
        return tuple(
            stream_from_poses(
                np.stack(poses[side]),
                base.control_dt,
                side=side,
                hand_length_m=base.scene.hand_binding(side).hand.params.hand_length,
                source=f"expert:{env_id} seed {seed} ({side})",
            )
            for side in sides
        )
    finally:
        env.close()


@dataclasses.dataclass
class _HandView:
    """One hand of a two-hand scene as the one-hand helpers see a scene (the grip stabiliser)."""

    model: Any
    data: Any
    hand: Any
    binding: Any
    objects: Any


@dataclasses.dataclass
class _Channel:
    """One hand's stream and records around its shared path (:class:`HandChannel`)."""

    side: str
    binding: Any
    frames: Callable[[int], np.ndarray | None]
    hand: HandChannel
    hand_geoms: np.ndarray
    sampler: LiveSampler | None = None
    rec: dict[str, list] = dataclasses.field(default_factory=dict)


class TwoHandTeleopLoop(TeleopLoop):
    """Runs teleoperation episodes of a two-hand task env (module docstring).

    Args: those of :class:`~handsim.envs.teleop.loop.TeleopLoop`; ``env_id`` a two-hand id
    (``handsim/PressTwoHands-v0``), ``config.mode`` ``"direct"``.

    Raises:
        InvalidTeleopConfig: camera mode, or a one-hand env.
    """

    def __init__(
        self,
        env_id: str = "handsim/PressTwoHands-v0",
        config: TeleopConfig | None = None,
        **kwargs: Any,
    ) -> None:
        if config is not None and config.mode != "direct":
            raise InvalidTeleopConfig(
                f"mode={config.mode!r}: two hands run in mode='direct' (the capture camera "
                "renders one operator hand)"
            )
        super().__init__(env_id, config, **kwargs)
        if not getattr(self.env.unwrapped, "two_hands", False):
            self.close()
            raise InvalidTeleopConfig(
                f"{env_id} has one hand: use TeleopLoop, or a two-hand env "
                "(handsim.envs.TWO_HAND_ENV_IDS)"
            )
        self._checked_two: weakref.WeakSet[OperatorStream] = weakref.WeakSet()

    def run(  # type: ignore[override]
        self,
        streams: Sequence[Source] | Mapping[str, Source] | Source,
        seed: int = 0,
        *,
        max_steps: int | None = None,
        realtime: bool = False,
        stop_at_success: bool = True,
        on_step: Callable[[int, dict[str, Any]], None] | None = None,
    ) -> TeleopEpisode:
        """Run one episode, each stream driving the hand of its side.

        Args:
            streams: :class:`OperatorStream` s and :class:`LiveSampler` s (each routed by its
                ``side``), or a dict by side (also of functions ``step -> (21, 3) keypoints or
                None``). A hand without a stream holds its start pose.
            seed: the env's episode seed.
            max_steps: stop after this many steps (default: the episode limit, or the longest
                stream if longer).
            realtime: pace the steps at the control rate (live streams).
            stop_at_success: end the episode at the task's success.
            on_step: called after every step with the step number and ``{"operator_world",
                "tracked_world"`` (the first hand's), ``"anchor_offset_m", "success", "hands"``
                (``{side: {"operator_world", "tracked_world"}}``)``}``.

        Returns:
            The episode: the task's metrics at the top level (``success``,
            ``time_to_success_s``, ``unintended_presses``, ``events``, ``steps`` ...) and per
            hand in ``metrics["hands"][side]`` (``tracking_error_mm``, ``jitter_mm``,
            ``operator_jitter_mm``, ``lag_s``, ``penetration_max_mm``, ``dropped_frames``,
            ``grip_hold_s``, ``streamed``, and a live sampler's latency summary); events name
            their hand. With ``config.record``: ``qpos``, ``mocap_pos``, ``mocap_quat``,
            ``success`` and, per hand, ``operator_world``, ``tracked_world``,
            ``physical_world`` (T, 21, 3) (the first hand's under these names, the left
            hand's with ``_left`` appended) for :func:`~handsim.envs.teleop.loop.write_rollout`.

        Raises:
            InvalidStream: two streams of one side, or a stream whose geometry is the other
                side than its ``hand``.
        """
        cfg = self.config
        env, base = self.env, self.env.unwrapped
        routed = route_streams(streams)
        env.reset(seed=seed)
        dt = self.control_dt
        limit = (env.spec.max_episode_steps if env.spec is not None else None) or 1000
        scene, data = base.scene, base.scene.data
        sides = base.sides
        unknown = [s for s in routed if s not in sides]
        if unknown:
            raise InvalidStream(f"no {unknown[0]} hand in {self.env_id}; its hands: {sides}")
        anchor: list[np.ndarray] = []  # one offset for both hands, world frame, m
        longest = 0
        for side in sides:  # files: the anchor from the first hand (in action order)
            s = routed.get(side)
            if isinstance(s, OperatorStream) and cfg.anchor == "start" and not anchor:
                start = scene.hand_binding(side).keypoints(data)[0]
                anchor.append(start - s.first_wrist_m())
        channels = []
        for k, side in enumerate(sides):
            binding = scene.hand_binding(side)
            frames, sampler, n = self._frames(routed.get(side), side, binding, anchor, dt)
            longest = max(longest, n)
            view = _HandView(scene.model, data, binding.hand, binding, scene.objects)
            channels.append(
                _Channel(
                    side=side,
                    binding=binding,
                    frames=frames,
                    # Each hand its own fault generator.
                    hand=HandChannel(cfg, view, dt, np.random.default_rng([cfg.seed + seed, k])),
                    hand_geoms=tm.hand_geom_mask(scene.model, binding.palm_id),
                    sampler=sampler,
                    rec={k: [] for k in ("operator", "tracked", "physical", "dropped", "pen")},
                )
            )
        steps = max_steps or max(limit, longest - 1)
        detector = EventDetector(base, dt)
        times = dict.fromkeys(STAGES, 0.0)
        success: list[bool] = []
        rec: dict[str, list] = {"qpos": [], "mocap_pos": [], "mocap_quat": []}
        first_success, unintended, n_done = None, math.nan, 0
        success_assisted = False
        start_wall = time.perf_counter()
        window, warned = (start_wall, 0), False
        info: dict[str, Any] = {}
        for i in range(1, steps + 1):
            tracked_by_side: dict[str, np.ndarray | None] = {}
            for ch in channels:
                tick = time.perf_counter()
                operator_kp = ch.frames(i)
                tracked, dropped = None, True
                if operator_kp is not None:
                    tracked, dropped, _ = ch.hand.track(operator_kp, times, tick)
                tracked_by_side[ch.side] = tracked
                ch.rec["operator"].append(
                    operator_kp if operator_kp is not None else np.full((21, 3), np.nan)
                )
                ch.rec["tracked"].append(
                    tracked if tracked is not None else np.full((21, 3), np.nan)
                )
                ch.rec["dropped"].append(dropped)
            t5 = time.perf_counter()
            action = np.concatenate(
                [ch.hand.action(tracked_by_side[ch.side], data) for ch in channels]
            )
            _, _, terminated, truncated, info = env.step(action)
            times["physics"] += time.perf_counter() - t5
            for ch in channels:
                if ch.sampler is not None:
                    ch.sampler.applied()
                ch.rec["physical"].append(ch.binding.keypoints(data))
                ch.rec["pen"].append(tm.hand_penetration_m(data, ch.hand_geoms)[0])
            detector.update(i, tracked_by_side, data, info)
            n_done = i
            success.append(bool(info.get("is_success", False)))
            if cfg.record:
                rec["qpos"].append(data.qpos.copy())
                rec["mocap_pos"].append(data.mocap_pos.copy())
                rec["mocap_quat"].append(data.mocap_quat.copy())
            if "unintended_presses" in info:
                unintended = float(info["unintended_presses"])
            if first_success is None and success[-1]:
                first_success = i
                success_assisted = any(ch.hand.assisted() for ch in channels)
            if on_step is not None:
                first = channels[0]
                on_step(
                    i,
                    {
                        "operator_world": first.rec["operator"][-1],
                        "tracked_world": tracked_by_side[first.side],
                        "anchor_offset_m": anchor[0] if anchor else np.zeros(3),
                        "success": success[-1],
                        "hands": {
                            ch.side: {
                                "operator_world": ch.rec["operator"][-1],
                                "tracked_world": tracked_by_side[ch.side],
                            }
                            for ch in channels
                        },
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
                        warnings.warn(
                            f"the two-hand teleop loop runs at {100 * factor:.0f} % of real "
                            f"time ({1 / dt:.0f} Hz control): the hands fall behind the "
                            "operator; use a lower rate or a faster machine",
                            BehindRealTime,
                            stacklevel=2,
                        )
                    window = (now, i)
            if (terminated and stop_at_success) or truncated:
                break
        wall = time.perf_counter() - start_wall
        hands: dict[str, dict[str, Any]] = {}
        tips = list(tm.FINGERTIPS)
        pts = [0, *tips]
        for ch in channels:
            operator = np.array(ch.rec["operator"])
            physical = np.array(ch.rec["physical"])
            dists = np.linalg.norm(physical - operator, axis=-1)
            streamed = bool(np.isfinite(operator).any())
            hands[ch.side] = {
                "streamed": ch.side in routed,
                "tracking_error_mm": (
                    float(np.nanmean(dists) * 1e3) if np.isfinite(dists).any() else math.nan
                ),
                "jitter_mm": tm.high_frequency_rms_mm(physical[:, tips], dt),
                "operator_jitter_mm": (
                    tm.high_frequency_rms_mm(operator[:, tips], dt) if streamed else math.nan
                ),
                "lag_s": (
                    tm.lag_frames(operator[:, pts], physical[:, pts], int(round(tm.MAX_LAG_S / dt)))
                    * dt
                    if n_done > 8 and streamed
                    else math.nan
                ),
                "penetration_max_mm": float(max(ch.rec["pen"]) * 1e3) if n_done else math.nan,
                "dropped_frames": int(np.sum(ch.rec["dropped"])) if ch.side in routed else 0,
                **ch.hand.metrics(dt),
            }
            if ch.sampler is not None:
                hands[ch.side].update(ch.sampler.summary())
        metrics = {
            "env_id": self.env_id,
            "seed": seed,
            "config": {**dataclasses.asdict(cfg), "faults": cfg.faults.to_dict()},
            "estimator": None,
            "success": first_success is not None,
            "time_to_success_s": first_success * dt if first_success is not None else math.nan,
            "success_assisted": bool(success_assisted),
            "unintended_presses": unintended,
            "steps": n_done,
            "control_dt_s": dt,
            "physics_diverged": bool(info.get("physics_diverged", False)),
            "steps_per_s": n_done / wall if wall > 0 else math.nan,
            "realtime_factor": n_done * dt / wall if wall > 0 else math.nan,
            "stage_ms": {k: (v / n_done * 1e3 if n_done else math.nan) for k, v in times.items()},
            "events": detector.counts(),
            "hands": hands,
            # The one-hand summary keys, for tables: the worse hand's, the sum of drops.
            "tracking_error_mm": _nanmax(h["tracking_error_mm"] for h in hands.values()),
            "penetration_max_mm": _nanmax(h["penetration_max_mm"] for h in hands.values()),
            "dropped_frames": sum(h["dropped_frames"] for h in hands.values()),
        }
        arrays: dict[str, np.ndarray] = {}
        if cfg.record:
            arrays = {k: np.array(v) for k, v in rec.items()}
            arrays["success"] = np.array(success, dtype=bool)
            for k, ch in enumerate(channels):
                suffix = "" if k == 0 else f"_{ch.side}"
                arrays[f"operator_world{suffix}"] = np.array(ch.rec["operator"])
                arrays[f"tracked_world{suffix}"] = np.array(ch.rec["tracked"])
                arrays[f"physical_world{suffix}"] = np.array(ch.rec["physical"])
                arrays[f"dropped{suffix}"] = np.array(ch.rec["dropped"], dtype=bool)
                arrays[f"penetration_m{suffix}"] = np.array(ch.rec["pen"])
        return TeleopEpisode(metrics, arrays, detector.events)

    def _frames(
        self,
        source: Source | None,
        side: str,
        binding: Any,
        anchor: list[np.ndarray],
        dt: float,
    ) -> tuple[Callable[[int], np.ndarray | None], LiveSampler | None, int]:
        """``(step -> keypoints or None, the live sampler or None, frames)`` of one hand."""
        if source is None:
            return (lambda i: None), None, 0
        if isinstance(source, OperatorStream):
            name = source.source or f"the {side} stream"
            if source.poses is None and source not in self._checked_two:
                check_side(source.keypoints_world, side, name)
                self._checked_two.add(source)
            s = source.resample(1.0 / dt)
            if anchor:
                s = s.translated(anchor[0])
            kp, n = s.keypoints_world, len(s)
            # After the stream's end the operator holds still (its last frame).
            return (lambda i: kp[min(i, n - 1)]), None, n
        to_check: list[np.ndarray] = []
        anchoring = self.config.anchor == "start"
        data = self.env.unwrapped.scene.data

        def frames(i: int) -> np.ndarray | None:
            kp = source(i)
            if kp is None:
                return None
            kp = np.asarray(kp, dtype=np.float64)
            if len(to_check) < SIDE_CHECK_FRAMES and fully_tracked(kp):
                to_check.append(kp)
                if len(to_check) == SIDE_CHECK_FRAMES:
                    check_side(np.stack(to_check), side, f"the live {side} stream")
            if anchoring:
                if not anchor and np.all(np.isfinite(kp[0])):
                    anchor.append(binding.keypoints(data)[0] - kp[0])
                if anchor:
                    kp = kp + anchor[0]
            return kp

        return frames, source if isinstance(source, LiveSampler) else None, 0


def _nanmax(values: Any) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return max(finite) if finite else math.nan
