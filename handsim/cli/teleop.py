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
    seed,
)

# What each sub-command does; this module builds their options (kept importable from here).
from handsim.cli.teleop_commands import (  # noqa: F401
    _DEFAULT_LIVE_RATE_HZ,
    _HANDS,
    _POSE_FILTER_VALUES,
    _config,
    _estimator,
    _faults,
    _filter_params,
    _finish,
    _generate,
    _hand_options,
    _live,
    _measured_rate_hz,
    _print_metrics,
    _replay,
    _send,
    _serve,
    _sweep,
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
_LIVE_HANDS = (*_HANDS, "both")


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


def _sigma_mm(text: str) -> float | str:
    return "auto" if text == "auto" else _noise_mm(text)


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
        "--grip-steady",
        choices=("on", "off", "hand"),
        default="off",
        help="with --grip-hold on: a held digit takes the running mean of its targets (0.15 s) "
        "instead of each frame's; 'hand': every digit while one is held (default: off)",
    )
    p.add_argument(
        "--pose-filter",
        choices=_POSE_FILTER_CHOICES,
        default="off",
        help="smooth the retargeted hand pose in joint space (One Euro per part: wrist "
        "position, wrist rotation, joint angles; 'wrist': the wrist only; 'auto': the whole "
        "pose, its cut-offs raised as the keypoint noise (--keypoint-sigma-mm) falls below "
        "10 mm; default: off)",
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
        "--pose-prior",
        choices=("on", "off"),
        default="off",
        help="retarget with a prior over natural hand postures (a maximum a posteriori fit; "
        "the grasp taxonomy and gestures), the keypoints weighed by --keypoint-sigma-mm "
        "(default: off)",
    )
    p.add_argument(
        "--keypoint-sigma-mm",
        type=_sigma_mm,
        default=None,
        help="with --pose-prior on: the tracked keypoints' noise, mm per axis, [0, 1000], or "
        "'auto' (estimated from the tracked stream's jitter; for live streams) (default: the "
        "fault noise --noise-mm of the run or sweep cell)",
    )
    p.add_argument(
        "--seed",
        type=seed,
        default=0,
        help="episode seed (the scene) and fault seed (default: 0)",
    )
    add_quiet(p)


_POSE_FILTER_CHOICES = ("on", "off", "wrist", "auto")


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
