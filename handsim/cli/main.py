"""The ``handsim`` command-line program.

Exit status: 0 on success, 2 for a bad command line (argparse's usage error, listing the valid
values) or a :class:`~handsim.errors.HandSimError` raised while running (one line
``handsim: error: ...`` on stderr, no traceback; ``--debug`` or ``HANDSIM_DEBUG=1`` re-raises
it with its traceback).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from handsim.cli import benchmark, closed_loop, data, demo, info, learn, teleop, view
from handsim.errors import HandSimError

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    """The ``handsim`` argument parser with every command."""
    import handsim

    parser = argparse.ArgumentParser(
        prog="handsim",
        description="Simulated 27-DoF human hand with depth sensing for hand pose estimation.",
        epilog="Run 'handsim COMMAND --help' for a command's options and their valid values.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {handsim.__version__}")
    parser.add_argument(
        "--debug",
        action="store_true",
        help="show the traceback of an error (also: environment variable HANDSIM_DEBUG=1)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for command in (demo, closed_loop, benchmark, data, info, teleop, view, learn):
        command.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``handsim`` program.

    Args:
        argv: arguments (default: ``sys.argv[1:]``).

    Returns:
        The process exit status (argparse's own errors exit with 2 via ``SystemExit``).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return args.func(args)
    except BrokenPipeError:
        # The reader went away (e.g. `handsim info | head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except HandSimError as err:
        if args.debug or os.environ.get("HANDSIM_DEBUG", "") not in ("", "0"):
            raise
        message = str(err.args[0]) if isinstance(err, KeyError) and err.args else str(err)
        print(f"{parser.prog}: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
