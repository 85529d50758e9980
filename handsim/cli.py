"""The ``handsim`` command-line program."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["main"]


def _demo(args: argparse.Namespace) -> int:
    from handsim.demo import run_demo

    summary = run_demo(args.out, width=args.size, height=args.size)
    print(Path(args.out, "summary.txt").read_text(), end="")
    return 0 if summary["hands"] else 1


def _info(args: argparse.Namespace) -> int:
    import mujoco

    import handsim
    from handsim.hand import HAND_SIZES, Hand
    from handsim.pose import JOINT_LIMITS_DEG, JOINT_NAMES

    model = Hand().compile()
    print(f"handsim {handsim.__version__}, MuJoCo {mujoco.__version__}")
    print(f"hand: nq={model.nq} nv={model.nv} nu={model.nu} bodies={model.nbody - 1}")
    print("size presets: " + ", ".join(f"{k}={v * 1000:.0f} mm" for k, v in HAND_SIZES.items()))
    print("joints (deg):")
    for name, (lo, hi) in zip(JOINT_NAMES, JOINT_LIMITS_DEG, strict=True):
        print(f"  {name:<16} {lo:7.1f} .. {hi:6.1f}")
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="handsim",
        description="Simulated 27-DoF human hand with depth sensing for hand pose estimation.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    demo = sub.add_parser(
        "demo",
        help="play gestures with hands of three sizes and both sides; write a contact sheet",
        description="Build hands of three sizes and both sides, play a gesture sequence under "
        "physics, and write a contact sheet PNG and a summary to the output folder.",
    )
    demo.add_argument("--out", default="handsim-demo", help="output folder (default: %(default)s)")
    demo.add_argument("--size", type=int, default=200, help="tile size in pixels (default: 200)")
    demo.set_defaults(func=_demo)
    info = sub.add_parser("info", help="print versions, hand presets and joint limits")
    info.set_defaults(func=_info)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``handsim`` program.

    Args:
        argv: arguments (default: ``sys.argv[1:]``).

    Returns:
        The process exit status.
    """
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
