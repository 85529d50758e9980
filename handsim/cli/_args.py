"""Argument types, progress bars and strict JSON shared by the ``handsim`` commands.

Every value is checked while the command line is parsed, so a bad one ends in argparse's usage
error (exit status 2, no traceback) that lists the valid values.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from typing import Any

__all__ = [
    "choice_help",
    "object_name",
    "positive_int",
    "non_negative_int",
    "non_negative_float",
    "probability",
    "progress_bar",
    "strict_json",
]


def choice_help(text: str, valid: tuple[str, ...] | list[str], default: object = None) -> str:
    """``text`` followed by the valid values (and the default), for an option's ``help``."""
    tail = f"; one of: {', '.join(valid)}"
    if default is not None:
        tail += f" (default: {default})"
    return text + tail


def object_name(value: str) -> str:
    """An object name (canonical, short alias or MJCF body name) -> its canonical name."""
    from handsim.world.registry import OBJECTS

    try:
        return OBJECTS.canonical(value)
    except KeyError as err:  # UnknownName lists the valid names
        raise argparse.ArgumentTypeError(str(err.args[0] if err.args else err)) from None


def _number(kind: Callable[[str], Any], value: str, what: str) -> Any:
    try:
        number = kind(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}; received {value!r}") from None
    if isinstance(number, float) and not math.isfinite(number):
        raise argparse.ArgumentTypeError(f"expected {what}; received {value!r}")
    return number


def positive_int(value: str) -> int:
    """An integer >= 1."""
    number = _number(int, value, "an integer >= 1")
    if number < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1; received {value!r}")
    return number


def non_negative_int(value: str) -> int:
    """An integer >= 0."""
    number = _number(int, value, "an integer >= 0")
    if number < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0; received {value!r}")
    return number


def non_negative_float(value: str) -> float:
    """A finite number >= 0."""
    number = _number(float, value, "a finite number >= 0")
    if number < 0:
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0; received {value!r}")
    return number


def probability(value: str) -> float:
    """A number in [0, 1]."""
    number = _number(float, value, "a number in [0, 1]")
    if not 0.0 <= number <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1]; received {value!r}")
    return number


def progress_bar(total: int, desc: str, unit: str, *, enabled: bool = True) -> Any:
    """A tqdm bar on stderr with rate and ETA (``enabled=False``: a silent stand-in)."""
    from tqdm import tqdm

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
    from handsim.envs.closed_loop import to_strict_json

    return json.dumps(to_strict_json(value), indent=2, allow_nan=False)
