"""Argument types, progress bars and strict JSON shared by the ``handsim`` commands.

Every value is checked while the command line is parsed, so a bad one ends in argparse's usage
error (exit status 2, no traceback) that lists the valid values. Every numeric option of every
command uses :func:`integer` or :func:`number` with its range: this module is the one place
where command-line numbers are checked.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = [
    "add_quiet",
    "choice_help",
    "integer",
    "number",
    "object_name",
    "output_folder",
    "positive_int",
    "non_negative_int",
    "non_negative_float",
    "positive_float",
    "probability",
    "port",
    "seed",
    "progress_bar",
    "strict_json",
]


def choice_help(text: str, valid: tuple[str, ...] | list[str], default: object = None) -> str:
    """``text`` followed by the valid values (and the default), for an option's ``help``."""
    tail = f"; one of: {', '.join(valid)}"
    if default is not None:
        tail += f" (default: {default})"
    return text + tail


def add_quiet(parser: argparse.ArgumentParser, what: str = "no progress bars") -> None:
    """``-q``/``--quiet``, accepted by every command alike (progress bars go to stderr)."""
    parser.add_argument("-q", "--quiet", action="store_true", help=f"{what} (they go to stderr)")


def object_name(value: str) -> str:
    """An object name (canonical, short alias or MJCF body name) -> its canonical name."""
    from handsim.world.registry import OBJECTS

    try:
        return OBJECTS.canonical(value)
    except KeyError as err:  # UnknownName lists the valid names
        raise argparse.ArgumentTypeError(str(err.args[0] if err.args else err)) from None


def _text(bound: float) -> str:
    return str(bound) if isinstance(bound, int) else f"{bound:g}"


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{_text(lo)}, {_text(hi)}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {_text(lo)}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {_text(hi)}"
    return ""


def output_folder(value: str) -> Path:
    """An argparse ``type``: a folder the command can create or write into.

    Refused, with the reason: a path that is a file, a path inside a file, and a folder (or its
    nearest existing parent) that this user cannot write. Whether an existing folder may be
    used (empty, the same dataset) is the command's own check.
    """
    path = Path(value)
    if not value:
        raise argparse.ArgumentTypeError("expected an output folder; received ''")
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{value!r} is a file, not a folder; give a folder")
    parent = path
    while not parent.exists():
        if parent.parent == parent:
            break
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise argparse.ArgumentTypeError(
            f"{value!r} cannot be made: {str(parent)!r} is a file, not a folder"
        )
    if parent.exists() and not os.access(parent, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(
            f"{value!r} cannot be written: {str(parent)!r} is not writable by this user"
        )
    return path


def integer(lo: int | None = None, hi: int | None = None, why: str = "") -> Callable[[str], int]:
    """An argparse ``type``: an integer in ``[lo, hi]`` (``None``: unbounded on that side).

    Args:
        lo: smallest valid value.
        hi: largest valid value.
        why: a short reason for the range, added to the error message.

    Returns:
        The parser; a bad value raises ``argparse.ArgumentTypeError`` whose message gives the
        valid range and the value received.
    """
    rng = _interval(lo, hi, False, False)
    what = f"an integer {rng}".rstrip()
    tail = f" ({why})" if why else ""

    def parse(value: str) -> int:
        try:
            number_ = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}; received {value!r}") from None
        if (lo is not None and number_ < lo) or (hi is not None and number_ > hi):
            raise argparse.ArgumentTypeError(f"expected {what}{tail}; received {value!r}")
        return number_

    parse.__name__ = f"integer {rng}".rstrip()
    return parse


def number(
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    why: str = "",
) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in the interval from ``lo`` to ``hi``.

    Args:
        lo: lower bound (``None``: unbounded).
        hi: upper bound (``None``: unbounded).
        lo_open: exclude ``lo`` itself.
        hi_open: exclude ``hi`` itself.
        why: a short reason for the range, added to the error message.

    Returns:
        The parser; NaN, infinities and values out of range raise
        ``argparse.ArgumentTypeError`` whose message gives the valid range.
    """
    rng = _interval(lo, hi, lo_open, hi_open)
    # Both bounds imply finiteness; say "finite" where an infinity would otherwise fit.
    what = f"a number {rng}" if lo is not None and hi is not None else f"a finite number {rng}"
    what = what.rstrip()
    tail = f" ({why})" if why else ""

    def parse(value: str) -> float:
        try:
            number_ = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}; received {value!r}") from None
        bad = not math.isfinite(number_)
        if lo is not None:
            bad = bad or number_ < lo or (lo_open and number_ == lo)
        if hi is not None:
            bad = bad or number_ > hi or (hi_open and number_ == hi)
        if bad:
            raise argparse.ArgumentTypeError(f"expected {what}{tail}; received {value!r}")
        return number_

    parse.__name__ = what
    return parse


positive_int = integer(1)
"""An integer >= 1."""
non_negative_int = integer(0)
"""An integer >= 0."""
non_negative_float = number(0.0)
"""A finite number >= 0."""
positive_float = number(0.0, lo_open=True)
"""A finite number > 0."""
probability = number(0.0, 1.0)
"""A number in [0, 1]."""
port = integer(1, 65535, "a TCP/UDP port")
"""A network port."""
seed = integer(0, 2**63 - 1, "a seed, as GenerationConfig takes")
"""A seed: an integer in [0, 2**63 - 1]."""


def progress_bar(total: int, desc: str, unit: str, *, enabled: bool = True) -> Any:
    """A tqdm bar on stderr with rate and ETA (``enabled=False``: a silent stand-in)."""
    from tqdm import tqdm

    # No monitor thread (it only adjusts stalled bars): `generate` forks its workers only from
    # a process with one thread.
    tqdm.monitor_interval = 0
    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        disable=not enabled,
        dynamic_ncols=True,
        smoothing=0.1,
    )


def strict_json(value: Any) -> str:
    """``value`` as indented strict JSON: non-finite floats become ``null``, never ``NaN``."""
    from handsim.metrics._common import to_strict_json

    return json.dumps(to_strict_json(value), indent=2, allow_nan=False)
