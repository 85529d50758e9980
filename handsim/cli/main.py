"""The ``handsim`` command-line program.

Exit status: 0 on success, 2 for a bad command line (argparse's usage error, listing the valid
values) or a :class:`~handsim.errors.HandSimError` raised while running (one line
``handsim: error: ...`` on stderr, no traceback; ``--debug`` or ``HANDSIM_DEBUG=1`` re-raises
it with its traceback).
"""

from __future__ import annotations

import argparse
import atexit
import gc
import os
import sys
from collections.abc import Sequence

from handsim.cli import benchmark, closed_loop, data, demo, info, learn, teleop, view
from handsim.errors import HandSimError

__all__ = ["main", "build_parser", "COMMAND_MODULES"]

_MODULES = (demo, closed_loop, benchmark, data, info, teleop, view, learn)
COMMAND_MODULES = {
    "demo": demo,
    "closed-loop": closed_loop,
    "benchmark": benchmark,
    "generate": data,
    "dataset": data,
    "export": data,
    "info": info,
    "teleop": teleop,
    "view": view,
    "train": learn,
    "evaluate": learn,
}
"""The module that adds each command's parser (a test checks it against every module's)."""


def _command_of(argv: Sequence[str]) -> str | None:
    """The command named on a command line: its first word that is not an option."""
    return next((word for word in argv if not word.startswith("-")), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``handsim`` argument parser: with every command, or only ``command``'s module's.

    Building a command's parser imports what its choices list (``closed-loop`` the envs,
    ``train`` the estimators: about 0.07 s of CPU together), so a command line that names a
    known command builds that command's alone; any other gets every command (``--help``,
    an unknown command's error listing the valid ones).
    """
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
    module = COMMAND_MODULES.get(command) if command is not None else None
    for each in _MODULES if module is None else (module,):
        each.add_parser(sub)
    return parser


_exit_collection_skipped = False


def skip_exit_collection() -> None:
    """Make this process's exit skip the garbage collection of everything it loaded.

    Python's exit collects garbage over every object left (numba's, scipy's and MuJoCo's
    modules: about 0.4 s of CPU after a ``handsim generate``) before the OS frees the memory
    anyway. :func:`gc.freeze` as the last exit handler (run first: LIFO) leaves those objects
    out; the exit handlers registered later (closing renderers, files) still run before it,
    and nothing changes while the process runs.
    """
    global _exit_collection_skipped
    if not _exit_collection_skipped:
        atexit.register(gc.freeze)
        _exit_collection_skipped = True


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``handsim`` program.

    Without ``argv`` (the program itself, not a caller in a longer-lived process) the objects
    loaded so far are frozen (:func:`gc.freeze`: the modules stay to the end, and the
    collections of the command's set-up skip them, about 0.05 s of CPU).

    Args:
        argv: arguments (default: ``sys.argv[1:]``).

    Returns:
        The process exit status (argparse's own errors exit with 2 via ``SystemExit``).
    """
    if argv is None:
        gc.freeze()
    skip_exit_collection()
    words = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_of(words))
    args = parser.parse_args(words)
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
