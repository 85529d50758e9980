"""The ``handsim`` command-line program."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from handsim.cli import closed_loop, demo, info

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="handsim",
        description="Simulated 27-DoF human hand with depth sensing for hand pose estimation.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for command in (demo, closed_loop, info):
        command.add_parser(sub)
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
