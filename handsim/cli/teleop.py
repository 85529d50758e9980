"""``handsim teleop``: drive the physical hand from operator streams, with tracking faults.

Sub-commands:

- ``replay FILE``: a stream file (NPZ / JSON; OpenXR, WebXR, MediaPipe, keypoints or poses)
  through the loop; prints the metrics, writes ``teleop.json`` and, with ``--rollout``, a
  rollout for ``handsim view``.
- ``live --udp PORT | --websocket PORT``: live JSON packets through the loop, in real time.
- ``sweep``: noise x latency x dropout x filter grid -> ``sweep.csv``, ``sweep.json``, plots.
- ``generate OUT``: write a task's scripted-expert episode as a stream file (a sample to replay).
- ``send FILE --udp PORT | --websocket PORT``: send a stream file as live packets.
- ``serve``: the WebXR page (a headset's browser streams its hand joints to ``live``).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path
from typing import Any

from handsim.cli._args import (
    add_quiet,
    choice_help,
    integer,
    number,
    port,
    positive_int,
    probability,
    progress_bar,
    seed,
    strict_json,
)

__all__ = ["add_parser", "TASKS"]

TASKS: dict[str, str] = {
    "grasp": "handsim/Grasp-v0",
    "press": "handsim/Press-v0",
    "press2": "handsim/PressTwoHands-v0",
}
"""Short task names of ``--task`` (a full registered id also works)."""
_MODES = ("direct", "camera")
_FILTERS = ("none", "one_euro", "ema")
_ANCHORS = ("none", "start")
_SENSORS = ("none", "structured_light", "tof")
_DROPOUT_MODES = ("hold", "extrapolate")
_HANDS = ("right", "left")
_LIVE_HANDS = (*_HANDS, "both")
_DEFAULT_LIVE_RATE_HZ = 90.0  # a headset's rate, when the stream cannot be measured


# Delays in frames: the range FaultConfig accepts.
_frames = integer(0, 10_000, "frames of delay")
# Upper bounds: past them a value is a typo, not a setting (a tracker 1 m off tracks nothing,
# a session longer than a day or a filter cutoff above 1 kHz controls nothing at <= 120 Hz).
_noise_mm = number(0, 1000)
_bias_mm = number(-1000, 1000)
_cutoff_hz = number(0, 1000, lo_open=True)
_beta = number(0, 10_000)
_session_s = number(0, 86_400)
_wait_s = number(0, 3600)
_speed = number(0, 1000, lo_open=True)


def _task(text: str) -> str:
    if text in TASKS:
        return TASKS[text]
    import handsim.envs

    ids = (*handsim.envs.ENV_IDS, *handsim.envs.TWO_HAND_ENV_IDS)
    if text in ids:
        return text
    raise argparse.ArgumentTypeError(
        f"unknown task {text!r}; one of {', '.join(TASKS)} or a registered id ({', '.join(ids)})"
    )


def _list(kind: Any, what: str) -> Any:
    def parse(text: str) -> list:
        try:
            return [kind(v) for v in text.split(",") if v.strip()]
        except argparse.ArgumentTypeError as err:
            raise argparse.ArgumentTypeError(f"{what}: {err}") from None

    return parse


def _predict_ms(text: str) -> float | str:
    if text == "auto":
        return text
    try:
        return number(0, 100)(text)
    except argparse.ArgumentTypeError as err:
        raise argparse.ArgumentTypeError(f"{err}, or auto") from None


def _filter_name(text: str) -> str:
    if text not in _FILTERS:
        raise argparse.ArgumentTypeError(f"unknown filter {text!r}; one of {', '.join(_FILTERS)}")
    return text


def _add_loop_options(p: argparse.ArgumentParser, *, grid: bool = False) -> None:
    p.add_argument(
        "--task",
        type=_task,
        default="handsim/Grasp-v0",
        help="the task: grasp, press, press2 (two hands) or a registered id (default: grasp)",
    )
    p.add_argument(
        "--mode",
        choices=_MODES,
        default="direct",
        help=choice_help(
            "direct: the stream's joints are the tracking; camera: capture camera + estimator",
            _MODES,
            "direct",
        ),
    )
    from handsim.cli.closed_loop import estimator_arg

    p.add_argument(
        "--estimator",
        type=estimator_arg,
        default="oracle",
        help="camera mode's estimator: oracle (truth) or module:Class[:kwargs-json] "
        "(default: oracle)",
    )
    p.add_argument(
        "--sensor",
        choices=_SENSORS,
        default="none",
        help=choice_help("capture camera's sensor model", _SENSORS, "none"),
    )
    if not grid:
        p.add_argument(
            "--noise-mm",
            type=_noise_mm,
            default=0.0,
            help="Gaussian keypoint noise, std per axis, mm (default: 0)",
        )
        p.add_argument(
            "--latency",
            type=_frames,
            default=0,
            help="latency, frames at the control rate (default: 0)",
        )
        p.add_argument(
            "--dropout",
            type=probability,
            default=0.0,
            help="probability that a frame is lost, [0, 1] (default: 0)",
        )
        p.add_argument(
            "--filter",
            type=_filter_name,
            default="none",
            help=choice_help("smoothing", _FILTERS, "none"),
        )
    p.add_argument(
        "--bias-mm",
        type=_bias_mm,
        nargs=3,
        default=(0.0, 0.0, 0.0),
        metavar=("X", "Y", "Z"),
        help="constant keypoint offset, world, mm",
    )
    p.add_argument(
        "--dropout-mode",
        choices=_DROPOUT_MODES,
        default="hold",
        help=choice_help("lost frames are", _DROPOUT_MODES, "hold"),
    )
    p.add_argument(
        "--jitter",
        type=_frames,
        default=0,
        help="largest extra random delay per frame, frames (default: 0)",
    )
    p.add_argument(
        "--occlusion-rate",
        type=probability,
        default=0.0,
        help="probability per frame that an occluder hides part of the hand (default: 0)",
    )
    p.add_argument(
        "--min-cutoff-hz",
        # 0 Hz would freeze the filtered stream at its first sample.
        type=_cutoff_hz,
        default=1.0,
        help="One Euro filter: cutoff at rest, Hz, (0, 1000] (default: 1.0)",
    )
    p.add_argument(
        "--beta",
        type=_beta,
        default=10.0,
        help="One Euro filter: cutoff increase per m/s of speed (default: 10)",
    )
    p.add_argument(
        "--alpha",
        # 0 would keep the first sample forever.
        type=number(0, 1, lo_open=True),
        default=0.5,
        help="ema filter: weight of the new sample, (0, 1] (default: 0.5)",
    )
    p.add_argument(
        "--grip-hold",
        choices=("on", "off"),
        default="on",
        help="grip stabiliser: a digit touching an object stops at its surface and opens only "
        "when the tracked digit clearly opens; nothing is attached (default: on)",
    )
    p.add_argument(
        "--pose-filter",
        choices=_POSE_FILTER_CHOICES,
        default="off",
        help="smooth the retargeted hand pose in joint space (One Euro per part: wrist "
        "position, wrist rotation, joint angles; 'wrist': the wrist only; default: off)",
    )
    p.add_argument(
        "--grasp-intent",
        choices=("on", "off"),
        default="off",
        help="drive the fingers from a grasp intent while the hand grasps an object (a "
        "closure measure of ten keypoints with hysteresis; the finger targets the tracked "
        "angles averaged since the grasp began); nothing is attached (default: off)",
    )
    p.add_argument(
        "--closure-assist",
        choices=("on", "off"),
        default="off",
        help="with --grasp-intent on: each digit of the grasp closes toward the object until "
        "it touches, instead of following the tracked flexion; nothing is attached (default: "
        "off)",
    )
    p.add_argument(
        "--seed",
        type=seed,
        default=0,
        help="episode seed (the scene) and fault seed (default: 0)",
    )
    add_quiet(p)


_POSE_FILTER_CHOICES = ("on", "off", "wrist")
_POSE_FILTER_VALUES: dict[str, bool | str] = {"on": True, "off": False, "wrist": "wrist"}


def _faults(args: argparse.Namespace, **levels: Any) -> Any:
    from handsim.envs.teleop import FaultConfig

    return FaultConfig(
        noise_mm=levels.get("noise_mm", getattr(args, "noise_mm", 0.0)),
        latency_frames=levels.get("latency_frames", getattr(args, "latency", 0)),
        dropout=levels.get("dropout", getattr(args, "dropout", 0.0)),
        bias_mm=tuple(args.bias_mm),
        dropout_mode=args.dropout_mode,
        jitter_frames=args.jitter,
        occlusion_rate=args.occlusion_rate,
    )


def _filter_params(name: str, args: argparse.Namespace) -> dict[str, float]:
    if name == "one_euro":
        return {"min_cutoff_hz": args.min_cutoff_hz, "beta": args.beta}
    if name == "ema":
        return {"alpha": args.alpha}
    return {}


def _estimator(args: argparse.Namespace) -> Any:
    if args.mode != "camera":
        return None
    from handsim.cli.closed_loop import EstimatorSpec

    if isinstance(args.estimator, EstimatorSpec):
        return args.estimator.make()
    if args.estimator == "oracle":
        from handsim.estimators import OracleEstimator

        return OracleEstimator(rng=args.seed)
    from handsim.estimators import CenterOfMassLocalizer

    return CenterOfMassLocalizer()


def _config(args: argparse.Namespace, record: bool = False) -> Any:
    from handsim.envs.teleop import TeleopConfig

    return TeleopConfig(
        mode=args.mode,
        faults=_faults(args),
        filter=args.filter,
        filter_params=_filter_params(args.filter, args),
        anchor=args.anchor,
        sensor=args.sensor,
        grip_hold=args.grip_hold == "on",
        pose_filter=_POSE_FILTER_VALUES[args.pose_filter],
        grasp_intent=args.grasp_intent == "on",
        closure_assist=args.closure_assist == "on",
        record=record,
        seed=args.seed,
    )


def _print_metrics(metrics: dict[str, Any]) -> None:
    keys = (
        "success",
        "time_to_success_s",
        "penetration_max_mm",
        "penetration_mean_mm",
        "slip_max_mm",
        "jitter_mm",
        "lag_s",
        "unintended_presses",
        "tracking_error_mm",
        "grip_hold_s",
        "intent_grasp_s",
        "closure_assist_s",
        "success_assisted",
        "intent_onsets",
        "steps",
        "dropped_frames",
        "steps_per_s",
        "realtime_factor",
        "latency_p50_ms",
        "latency_p95_ms",
        "residual_latency_p50_ms",
        "residual_latency_p95_ms",
        "latency_clock",
    )
    for k in keys:
        if k not in metrics:
            continue
        v = metrics[k]
        print(f"  {k:22s} {v:.3f}" if isinstance(v, float) else f"  {k:22s} {v}")
    stages = ", ".join(f"{k} {v:.2f}" for k, v in metrics["stage_ms"].items())
    print(f"  {'stage_ms':22s} {stages}")
    events = ", ".join(f"{k} {v}" for k, v in metrics.get("events", {}).items() if v)
    print(f"  {'events':22s} {events or 'none'}")
    from handsim.cli.teleop_two import print_hands

    print_hands(metrics)


def _finish(args: argparse.Namespace, loop: Any, episode: Any, extra: dict[str, Any]) -> int:
    from handsim.envs.teleop import write_rollout

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = {"event_log": [e.to_dict() for e in episode.events]}
    (out / "teleop.json").write_text(strict_json({**episode.metrics, **extra, **log}))
    print(f"{episode.metrics['env_id']} ({loop.config.label()}):")
    _print_metrics(episode.metrics)
    if args.rollout:
        path = write_rollout(args.rollout, episode, loop)
        print(f"rollout: {path} (play it with: handsim view {path})")
    print(f"metrics: {out / 'teleop.json'}")
    return 0


def _replay(args: argparse.Namespace) -> int:
    from handsim.cli.teleop_two import replay_streams, replay_two
    from handsim.envs.teleop import TeleopLoop
    from handsim.envs.teleop.loop import MAX_CONTROL_RATE_HZ

    streams = replay_streams(args.task, args.file)
    config = _config(args, record=bool(args.rollout))
    if len(streams) > 1:
        loop, episode = replay_two(args, streams, config)
        with loop:
            return _finish(args, loop, episode, {"stream": [str(f) for f in args.file]})
    stream = streams[0]
    env_kwargs = {"handedness": stream.side}
    rate = args.rate_hz or min(stream.rate_hz(), MAX_CONTROL_RATE_HZ)
    with TeleopLoop(
        args.task,
        config,
        estimator=_estimator(args),
        env_kwargs=env_kwargs,
        control_rate_hz=rate,
    ) as loop:
        episode = loop.run(stream, args.seed, max_steps=args.max_steps)
        return _finish(args, loop, episode, {"stream": str(args.file[0])})


def _measured_rate_hz(receiver: Any, side: str, timeout_s: float = 1.0) -> float | None:
    """The stream's rate from its first packets' sender times (arrival times without ``t``)."""
    import time

    import numpy as np

    end = time.monotonic() + timeout_s
    while time.monotonic() < end and len(receiver.history[side]) < 12:
        time.sleep(0.01)
    with receiver.lock:
        frames = list(receiver.history[side])
    if len(frames) < 3:
        return None
    t = np.array([f.t if np.isfinite(f.t) else f.received_s for f in frames])
    period = float(np.median(np.diff(t)))
    return 1.0 / period if period > 0 else None


def _live(args: argparse.Namespace) -> int:
    from handsim.cli.teleop_two import check_two_hands
    from handsim.envs.teleop import TeleopLoop, TwoHandTeleopLoop, UdpReceiver, WebSocketReceiver
    from handsim.envs.teleop.loop import MAX_CONTROL_RATE_HZ, BehindRealTime
    from handsim.envs.teleop.sampling import LiveSampler

    two = args.hand == "both"
    check_two_hands(args.task, two, f"--hand {args.hand}")

    if args.udp is not None:
        receiver = UdpReceiver(args.udp, host=args.host)
    else:
        receiver = WebSocketReceiver(args.websocket, host=args.host)
    config = _config(args, record=bool(args.rollout))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        receiver.start()
    for w in caught:
        print(f"handsim: warning: {w.message}", file=sys.stderr)
    proto = "udp" if args.udp is not None else "websocket"
    publisher = None
    try:
        print(
            f"listening on {proto}://{args.host}:{receiver.port} for {args.duration:g} s "
            f"({args.hand} hand)",
            file=sys.stderr,
        )
        if args.wait > 0 and not receiver.wait_for(1, args.wait):
            print(
                f"handsim: no valid packet in {args.wait:g} s; counters {receiver.counters}",
                file=sys.stderr,
            )
            return 1
        other = "left" if args.hand == "right" else "right"
        mine, theirs = receiver.history.get(args.hand), receiver.history[other]
        if args.wait > 0 and not two and theirs and not mine:
            print(
                f"handsim: warning: the packets so far are of the {other} hand and --hand is "
                f"{args.hand}: they are ignored (use --hand {other})",
                file=sys.stderr,
            )
        rate = args.rate_hz
        if rate is None:
            # Both hands: the rate of the side that is streaming (the right if both are).
            side = args.hand if not two else ("right" if receiver.history["right"] else "left")
            measured = _measured_rate_hz(receiver, side) if args.wait > 0 else None
            rate = min(measured or _DEFAULT_LIVE_RATE_HZ, MAX_CONTROL_RATE_HZ)
            how = f"measured {measured:.1f} Hz" if measured else "no stream to measure"
        else:
            how = "--rate-hz"
        with (TwoHandTeleopLoop if two else TeleopLoop)(
            args.task,
            config,
            estimator=_estimator(args),
            env_kwargs={} if two else {"handedness": args.hand},
            control_rate_hz=min(rate, MAX_CONTROL_RATE_HZ),
            episode_s=args.duration,
        ) as loop:
            steps = max(1, int(round(args.duration / loop.control_dt)))
            limit = loop.env.spec.max_episode_steps
            print(
                f"control at {1 / loop.control_dt:.1f} Hz ({how}; "
                f"{loop.env_kwargs['frame_skip']} physics steps of 2 ms each); the task's "
                f"episode limit is {limit} steps ({limit * loop.control_dt:g} s) so that "
                f"--duration {args.duration:g} s runs in one episode",
                file=sys.stderr,
            )
            predict = args.predict_ms if args.predict_ms == "auto" else args.predict_ms / 1e3
            samplers = [
                LiveSampler(receiver, side, delay_s=args.delay_ms / 1e3, predict_s=predict)
                for side in (_HANDS if two else (args.hand,))
            ]

            def show(message: Any, *_: Any, **__: Any) -> None:
                print(f"handsim: warning: {message}", file=sys.stderr)

            on_step = None
            if isinstance(receiver, WebSocketReceiver):
                # The page ('teleop serve') draws the simulation from this state stream.
                from handsim.envs.teleop.xr_state import StatePublisher

                publisher = StatePublisher(receiver, loop.env)
                on_step = publisher.on_step
            with warnings.catch_warnings():
                warnings.simplefilter("always", BehindRealTime)
                warnings.showwarning = show
                episode = loop.run(
                    samplers if two else samplers[0],
                    args.seed,
                    max_steps=steps,
                    realtime=True,
                    stop_at_success=False,
                    on_step=on_step,
                )
            packets = dict(receiver.counters)
            accepted = max(packets["accepted"], 1)
            extra: dict[str, Any] = {
                "packets": packets,
                "packets_used_fraction": sum(s.packets_used for s in samplers) / accepted,
            }
            if publisher is not None:
                extra["state_stream"] = dict(publisher.counters)
            return _finish(args, loop, episode, extra)
    finally:
        if publisher is not None:
            publisher.close()
        receiver.close()
        print(f"packets: {receiver.counters}", file=sys.stderr)


def _sweep(args: argparse.Namespace) -> int:
    from handsim.envs.teleop import FaultConfig
    from handsim.envs.teleop.sweep import run_sweep, write_sweep

    base = _faults(args, noise_mm=0.0, latency_frames=0, dropout=0.0)
    n_points = len(args.noise_mm) * len(args.latency) * len(args.dropout) * len(args.filters)
    total = n_points * args.episodes
    factory = (lambda: _estimator(args)) if args.mode == "camera" else None
    with progress_bar(total, "teleop sweep", "episode", enabled=not args.quiet) as bar:
        report = run_sweep(
            args.task,
            noise_mm=args.noise_mm,
            latency_frames=args.latency,
            dropout=args.dropout,
            filters=args.filters,
            episodes=args.episodes,
            seed=args.seed,
            mode=args.mode,
            estimator_factory=factory,
            base_faults=base if isinstance(base, FaultConfig) else None,
            operator=args.operator,
            grip_hold=args.grip_hold == "on",
            pose_filter=_POSE_FILTER_VALUES[args.pose_filter],
            grasp_intent=args.grasp_intent == "on",
            closure_assist=args.closure_assist == "on",
            filter_params={f: _filter_params(f, args) for f in args.filters},
            progress=bar.update,
        )
    paths = write_sweep(report, args.out)
    print(
        f"{'noise_mm':>8} {'latency':>7} {'dropout':>7} {'filter':>9} {'success':>7} "
        f"{'jitter_mm':>9} {'lag_s':>6} {'pen_max_mm':>10} {'grip_hold_s':>11} "
        f"{'intent_s':>8}"
    )
    for r in report["rows"]:
        print(
            f"{r['noise_mm']:8.1f} {r['latency_frames']:7d} {r['dropout']:7.2f} "
            f"{r['filter']:>9} {100 * r['success_rate']:6.0f}% {r['jitter_mm']:9.2f} "
            f"{r['lag_s']:6.2f} {r['penetration_max_mm']:10.2f} {r['grip_hold_s']:11.2f} "
            f"{r['intent_grasp_s']:8.2f}"
        )
    for kind, path in paths.items():
        print(f"{kind}: {path}")
    return 0


def _generate(args: argparse.Namespace) -> int:
    from handsim.cli.teleop_two import generate_two, two_hand_task
    from handsim.envs.teleop import save_stream, stream_from_expert

    if two_hand_task(args.task):
        return generate_two(args)
    stream = stream_from_expert(args.task, args.seed)
    path = save_stream(stream, args.out)
    print(f"{path}: {len(stream)} frames, {stream.duration_s:.2f} s, {stream.source}")
    return 0


def _send(args: argparse.Namespace) -> int:
    from handsim.envs.teleop.sender import send_streams
    from handsim.envs.teleop.two_hands import load_streams

    streams = load_streams(args.file)
    protocol, port = ("udp", args.udp) if args.udp is not None else ("websocket", args.websocket)
    # Both hands of a two-hand file at once, each packet with its hand.
    n = send_streams(streams, port, protocol=protocol, host=args.host, speed=args.speed)
    print(f"sent {n} packets to {protocol}://{args.host}:{port}")
    return 0


def _serve(args: argparse.Namespace) -> int:
    from handsim.envs.teleop.web import serve

    return serve(
        http_port=args.port,
        ws_port=args.websocket,
        host=args.host,
        replay=args.replay,
        duration_s=args.duration,
    )


def _port_group(p: argparse.ArgumentParser, required: bool = True) -> None:
    group = p.add_mutually_exclusive_group(required=required)
    group.add_argument("--udp", type=port, metavar="PORT", help="UDP port, 1 to 65535")
    group.add_argument(
        "--websocket",
        type=port,
        metavar="PORT",
        help="WebSocket port (needs handsim[teleop])",
    )
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address (default: 127.0.0.1; any other address is reachable from "
        "the network and gives a warning)",
    )


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``handsim teleop`` and its sub-commands."""
    teleop = sub.add_parser(
        "teleop",
        help="drive the physical hand from tracked pose streams, with tracking faults",
        description=__doc__.split("\n\n")[0].split(": ", 1)[1],
    )
    cmds = teleop.add_subparsers(dest="teleop_command", metavar="SUBCOMMAND", required=True)

    p = cmds.add_parser(
        "replay",
        help="replay a stream file through the loop",
        description="Replay a stream file (NPZ or JSON: keypoints in any "
        "supported format, OpenXR 26 / WebXR 25 joints, MediaPipe "
        "world landmarks, or 27-DoF poses) through the teleop "
        "loop and print the metrics.",
    )
    p.add_argument(
        "file",
        type=Path,
        nargs="+",
        help="stream file (.json or .npz; see docs/teleop.md); two hands: a two-hand file, or "
        "two files (one per hand), with a two-hand --task (press2)",
    )
    _add_loop_options(p)
    p.add_argument(
        "--anchor",
        choices=_ANCHORS,
        default="start",
        help=choice_help(
            "move the stream so its first wrist is at the hand's start", _ANCHORS, "start"
        ),
    )
    p.add_argument(
        "--max-steps",
        type=positive_int,
        default=None,
        help="stop after this many steps (default: the episode limit)",
    )
    p.add_argument(
        "--rate-hz",
        type=number(0, 120, lo_open=True),
        default=None,
        help="control rate, Hz, in (0, 120] (default: the stream's own rate, at most 120)",
    )
    p.add_argument("--out", default="teleop_out", help="output folder (default: teleop_out)")
    p.add_argument(
        "--rollout", default=None, help="also write the rollout (.npz) for 'handsim view'"
    )
    p.set_defaults(func=_replay)

    p = cmds.add_parser(
        "live",
        help="drive the hand from live UDP / WebSocket packets",
        description="Receive live JSON packets (docs/teleop.md) and run the "
        "loop in real time for --duration seconds.",
    )
    _port_group(p)
    _add_loop_options(p)
    p.add_argument(
        "--anchor",
        choices=_ANCHORS,
        default="start",
        help=choice_help(
            "move the stream so its first wrist is at the hand's start", _ANCHORS, "start"
        ),
    )
    p.add_argument("--duration", type=_session_s, default=10.0, help="seconds to run (default: 10)")
    p.add_argument(
        "--wait",
        type=_wait_s,
        default=30.0,
        help="seconds to wait for the first valid packet (0: do not wait; default: 30)",
    )
    p.add_argument(
        "--hand",
        choices=_LIVE_HANDS,
        default="right",
        help=choice_help(
            "the hand to drive (packets of the other hand are ignored); both: each "
            "packet drives its 'hand' (a two-hand --task: press2)",
            _LIVE_HANDS,
            "right",
        ),
    )
    p.add_argument(
        "--rate-hz",
        type=number(0, 120, lo_open=True),
        default=None,
        help="control rate, Hz, in (0, 120] (default: the stream's, measured from its first "
        "packets, at most 120; 90 if it cannot be measured)",
    )
    p.add_argument(
        "--delay-ms",
        type=number(0, 100),
        default=0.0,
        help="sample the stream this far behind its newest packet, ms, [0, 100] (smoother, "
        "later; default: 0)",
    )
    p.add_argument(
        "--predict-ms",
        type=_predict_ms,
        default=0.0,
        help="extrapolate the stream this far ahead to compensate latency, ms, [0, 100], or "
        "auto: by the measured end-to-end latency (default: 0)",
    )
    p.add_argument("--out", default="teleop_out", help="output folder (default: teleop_out)")
    p.add_argument(
        "--rollout", default=None, help="also record the session as a rollout (.npz) to view"
    )
    p.set_defaults(func=_live)

    p = cmds.add_parser(
        "sweep",
        help="degradation grid -> CSV, JSON and plots",
        description="Run the task under every combination of noise, latency, dropout and "
        "filter, operated by the reactive operator (the task's expert planning from the "
        "displayed state, late by the latency plus a 150-250 ms reaction delay) or by the "
        "expert's replayed streams; write sweep.csv, sweep.json and plots of success and jitter.",
    )
    _add_loop_options(p, grid=True)
    p.add_argument(
        "--operator",
        choices=("reactive", "replay"),
        default="reactive",
        help=choice_help(
            "reactive: plans from the displayed state; replay: the expert's recorded stream",
            ("reactive", "replay"),
            "reactive",
        ),
    )
    p.add_argument(
        "--noise-mm",
        type=_list(_noise_mm, "--noise-mm"),
        default=[0.0, 5.0, 10.0],
        help="noise levels, mm, comma-separated (default: 0,5,10)",
    )
    p.add_argument(
        "--latency",
        type=_list(_frames, "--latency"),
        default=[0, 3],
        help="latencies, frames, comma-separated (default: 0,3)",
    )
    p.add_argument(
        "--dropout",
        type=_list(probability, "--dropout"),
        default=[0.0, 0.1],
        help="dropout rates, comma-separated (default: 0,0.1)",
    )
    p.add_argument(
        "--filters",
        type=_list(_filter_name, "--filters"),
        default=["none", "one_euro"],
        help=f"filters, comma-separated, of {', '.join(_FILTERS)} (default: none,one_euro)",
    )
    p.add_argument(
        "--episodes", type=positive_int, default=2, help="episodes per grid point (default: 2)"
    )
    p.add_argument("--out", default="teleop_sweep", help="output folder (default: teleop_sweep)")

    p.set_defaults(func=_sweep)

    p = cmds.add_parser(
        "generate",
        help="write a scripted-expert episode as a stream file",
        description="Run the task's scripted expert and write its commands as "
        "a pose27 stream file (.json or .npz) to replay.",
    )
    p.add_argument("out", type=Path, help="output file (.json or .npz)")
    p.add_argument(
        "--task",
        type=_task,
        default="handsim/Grasp-v0",
        help="grasp, press, press2 (two hands: a two-hand .json) or a registered id "
        "(default: grasp)",
    )
    p.add_argument("--seed", type=seed, default=0, help="episode seed (default: 0)")
    add_quiet(p, "accepted by every command; generate shows no progress bars")
    p.set_defaults(func=_generate)

    p = cmds.add_parser(
        "send",
        help="send a stream file as live packets (a test sender)",
        description="Send a stream file's frames as live JSON packets at its own rate.",
    )
    p.add_argument("file", type=Path, help="stream file (.json or .npz)")
    _port_group(p)
    p.add_argument(
        "--speed", type=_speed, default=1.0, help="playback speed factor, > 0 (default: 1)"
    )
    add_quiet(p, "accepted by every command; send shows no progress bars")
    p.set_defaults(func=_send)

    p = cmds.add_parser(
        "serve",
        help="serve the WebXR page that streams a headset's hand",
        description="Serve a static WebXR page: in a headset's browser it reads "
        "the WebXR Hand Input joints and streams them over the "
        "WebSocket of 'handsim teleop live --websocket PORT' (run it "
        "beside); without a headset it replays a recorded file.",
    )
    p.add_argument("--port", type=port, default=8000, help="HTTP port of the page (default: 8000)")
    p.add_argument(
        "--websocket",
        type=port,
        default=8765,
        help="WebSocket port the page streams to (default: 8765)",
    )
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address (default: 127.0.0.1; others warn: a headset on the network "
        "needs the machine's address)",
    )
    p.add_argument(
        "--replay",
        type=Path,
        default=None,
        help="stream file the page replays when no headset is present",
    )
    p.add_argument(
        "--duration",
        type=_session_s,
        default=0.0,
        help="stop after this many seconds (0: until Ctrl-C)",
    )
    add_quiet(p, "accepted by every command; serve shows no progress bars")
    p.set_defaults(func=_serve)
