"""The two-hand paths of ``handsim teleop``: replay, live, generate and send with both hands.

``replay`` takes a two-hand stream file (JSON with ``"hands"``) or two files, one per side;
``live --hand both`` follows both hands' packets; ``generate --task press2`` writes a two-hand
file; ``send`` sends both hands of such a file at once. Each needs a two-hand task
(``--task press2``, ``handsim/PressTwoHands-v0``). Kept apart from :mod:`handsim.cli.teleop`,
which dispatches here.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from handsim.errors import HandSimError

__all__ = [
    "two_hand_task",
    "check_two_hands",
    "replay_streams",
    "replay_two",
    "print_hands",
    "generate_two",
]


class TwoHandsNeeded(HandSimError, ValueError):
    """Two hands' streams and the task disagree (a one-hand task, or a two-hand one)."""


def two_hand_task(env_id: str) -> bool:
    """Whether ``env_id`` is a two-hand task."""
    import handsim.envs

    return env_id in handsim.envs.TWO_HAND_ENV_IDS


def check_two_hands(env_id: str, two: bool, what: str) -> None:
    """Refuse two hands' input with a one-hand task, and the reverse, saying what to pass.

    Raises:
        TwoHandsNeeded: naming the tasks that fit.
    """
    import handsim.envs

    if two and not two_hand_task(env_id):
        raise TwoHandsNeeded(
            f"{what} holds two hands, but {env_id} has one: use a two-hand task (--task press2, "
            f"or {', '.join(handsim.envs.TWO_HAND_ENV_IDS)})"
        )
    if not two and two_hand_task(env_id):
        raise TwoHandsNeeded(
            f"{env_id} has two hands, but {what} holds one: give both hands (a two-hand file or "
            "two files; live: --hand both), or a one-hand task (--task grasp, press)"
        )


def replay_streams(env_id: str, files: list[Path]) -> list[Any]:
    """The streams of ``replay``'s files (one or two; a file may hold both hands).

    Raises:
        TwoHandsNeeded: more than two files, or hands that do not fit the task.
        InvalidStream: an unreadable file.
    """
    from handsim.envs.teleop.two_hands import load_streams

    if len(files) > 2:
        raise TwoHandsNeeded(
            f"replay takes one stream file, or two (one per hand); received {len(files)}"
        )
    streams = [s for f in files for s in load_streams(f)]
    check_two_hands(env_id, len(streams) > 1, " and ".join(map(str, files)))
    return streams


def replay_two(args: argparse.Namespace, streams: list[Any], config: Any) -> tuple[Any, Any]:
    """Replay both hands' streams through the two-hand loop: ``(loop, episode)`` (loop open).

    Raises:
        InvalidStream: two streams of one side.
    """
    from handsim.envs.teleop.loop import MAX_CONTROL_RATE_HZ
    from handsim.envs.teleop.two_hands import TwoHandTeleopLoop, route_streams

    route_streams(streams)
    rate = args.rate_hz or min(min(s.rate_hz() for s in streams), MAX_CONTROL_RATE_HZ)
    loop = TwoHandTeleopLoop(args.task, config, control_rate_hz=rate)
    try:
        episode = loop.run(streams, args.seed, max_steps=args.max_steps)
    except BaseException:
        loop.close()
        raise
    return loop, episode


def print_hands(metrics: dict[str, Any]) -> None:
    """Each hand's figures of a two-hand episode."""
    keys = ("tracking_error_mm", "jitter_mm", "lag_s", "penetration_max_mm", "dropped_frames")
    for side, figures in metrics.get("hands", {}).items():
        shown = ", ".join(
            f"{k} {figures[k]:.3f}" if isinstance(figures[k], float) else f"{k} {figures[k]}"
            for k in keys
        )
        streamed = "" if figures.get("streamed", True) else " (no stream: held its start)"
        print(f"  {side + ' hand':22s} {shown}{streamed}")
        if "latency_p50_ms" in figures:
            print(
                f"  {'':22s} latency_p50_ms {figures['latency_p50_ms']:.3f}, latency_p95_ms "
                f"{figures['latency_p95_ms']:.3f}"
            )


def generate_two(args: argparse.Namespace) -> int:
    """Write a two-hand task's expert episode as a two-hand stream file (JSON)."""
    from handsim.envs.teleop.two_hands import save_streams, streams_from_expert

    streams = streams_from_expert(args.task, args.seed)
    path = save_streams(streams, Path(args.out))
    sides = ", ".join(f"{s.side} {len(s)} frames" for s in streams)
    print(f"{path}: {sides}, {streams[0].duration_s:.2f} s, expert:{args.task} seed {args.seed}")
    return 0
