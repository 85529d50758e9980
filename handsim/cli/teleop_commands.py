"""What the ``handsim teleop`` sub-commands do: build the loop from the parsed options and run it.

:mod:`handsim.cli.teleop` defines the sub-commands and their options and dispatches here
(``replay``, ``live``, ``sweep``, ``generate``, ``send``, ``serve``); the two-hand paths are in
:mod:`handsim.cli.teleop_two`.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path
from typing import Any

from handsim.cli._args import progress_bar, strict_json

__all__: list[str] = []

_HANDS = ("right", "left")
_DEFAULT_LIVE_RATE_HZ = 90.0  # a headset's rate, when the stream cannot be measured
_POSE_FILTER_VALUES: dict[str, bool | str] = {
    "on": True,
    "off": False,
    "wrist": "wrist",
    "auto": "auto",
}


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


def _hand_options(args: argparse.Namespace) -> dict[str, Any]:
    """The physical hand's options, shared by one loop and a sweep."""
    return {
        "grip_hold": args.grip_hold == "on",
        "grip_steady": {"on": True, "off": False, "hand": "hand"}[args.grip_steady],
        "pose_filter": _POSE_FILTER_VALUES[args.pose_filter],
        "grasp_intent": args.grasp_intent == "on",
        "closure_assist": args.closure_assist == "on",
        "pose_prior": args.pose_prior == "on",
        "keypoint_sigma_mm": args.keypoint_sigma_mm,
    }


def _config(args: argparse.Namespace, record: bool = False) -> Any:
    from handsim.envs.teleop import TeleopConfig

    return TeleopConfig(
        mode=args.mode,
        faults=_faults(args),
        filter=args.filter,
        filter_params=_filter_params(args.filter, args),
        anchor=args.anchor,
        sensor=args.sensor,
        **_hand_options(args),
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
            **_hand_options(args),
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
