"""``handsim view ROLLOUT``: play a teleop rollout back as MP4 or GIF (or a rerun recording)."""

from __future__ import annotations

import argparse
from pathlib import Path

from handsim.cli._args import add_quiet, number, positive_int, progress_bar

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    if args.rerun:
        from handsim.envs.teleop.view import log_rollout_rerun

        print(f"rerun recording: {log_rollout_rerun(args.rollout, args.rerun)}")
        return 0
    from handsim.envs.teleop.loop import read_rollout
    from handsim.envs.teleop.view import render_rollout

    _, arrays = read_rollout(args.rollout)
    n = (len(arrays["qpos"]) + args.every - 1) // args.every
    out = args.out or Path(args.rollout).with_suffix(".mp4")
    with progress_bar(n, "view", "frame", enabled=not args.quiet) as bar:
        path = render_rollout(
            args.rollout, out, fps=args.fps, every=args.every, progress=bar.update
        )
    print(f"video: {path}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``handsim view``."""
    p = sub.add_parser(
        "view",
        help="render a teleop rollout to MP4 or GIF",
        description="Render a rollout written by 'handsim teleop replay --rollout' (or "
        "handsim.envs.teleop.write_rollout): capture depth with the operator's (green) and "
        "estimated (magenta) skeletons beside a colour view of the physical scene.",
    )
    p.add_argument("rollout", type=Path, help="the rollout (.npz)")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="video file, .mp4 or .gif (default: the rollout's name with .mp4)",
    )
    p.add_argument(
        "--every", type=positive_int, default=1, help="draw every N-th step (default: 1)"
    )
    p.add_argument(
        "--fps",
        type=number(0, 240, lo_open=True),
        default=None,
        help="frames per second, in (0, 240] (default: the control rate / --every)",
    )
    p.add_argument(
        "--rerun",
        type=Path,
        default=None,
        metavar="OUT.rrd",
        help="instead, log the 3D keypoints to a rerun recording (needs the "
        "optional rerun-sdk: pip install 'handsim[rerun]')",
    )
    add_quiet(p)
    p.set_defaults(func=_run)
