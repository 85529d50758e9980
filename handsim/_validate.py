"""Argument checks shared by the public constructors and functions.

Each check takes the argument's name, the value received and the error class to raise (a
:class:`~handsim.errors.HandSimError` subclass of the calling module); the message names the
argument, shows what was received and says what is valid. Booleans are not numbers here and
complex numbers, NaN and infinities are refused unless a range allows infinities.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable
from typing import Any

import numpy as np

from handsim.errors import HandSimError

__all__ = [
    "boolean",
    "choice",
    "integer",
    "is_real",
    "real_array",
    "real_scalar",
    "show",
    "to_real_array",
]


def show(value: object, limit: int = 80) -> str:
    """``repr`` of a received value, shortened for error messages."""
    if isinstance(value, np.ndarray) and value.size > 8:
        text = f"array of shape {value.shape} and dtype {value.dtype}"
    else:
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def is_real(value: object) -> bool:
    """Whether ``value`` is a real number (int, float, numpy real; not bool, not complex)."""
    if isinstance(value, (bool, np.bool_)):
        return False
    return isinstance(value, (numbers.Real, np.integer, np.floating))


def _range_text(lo: float, hi: float, lo_open: bool, hi_open: bool) -> str:
    if lo == -math.inf and hi == math.inf:
        return "a finite number"
    if hi == math.inf:
        return f"a finite number {'>' if lo_open else '>='} {lo:g}"
    if lo == -math.inf:
        return f"a finite number {'<' if hi_open else '<='} {hi:g}"
    left = "(" if lo_open else "["
    right = ")" if hi_open else "]"
    return f"in {left}{lo:g}, {hi:g}{right}"


def real_scalar(
    name: str,
    value: Any,
    error: type[HandSimError],
    *,
    lo: float = -math.inf,
    hi: float = math.inf,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
) -> float:
    """``value`` as a finite float in the range, or ``error`` naming ``name``.

    0-d numpy arrays are accepted; bools, strings, complex numbers, NaN and infinities are not.
    """
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    valid = _range_text(lo, hi, lo_open, hi_open) + (f" ({unit})" if unit else "")
    if not is_real(value):
        raise error(f"{name} must be {valid}, got {show(value)} ({type(value).__name__})")
    x = float(value)
    ok = math.isfinite(x) and (x > lo if lo_open else x >= lo) and (x < hi if hi_open else x <= hi)
    if not ok:
        raise error(f"{name} must be {valid}, got {show(value)}")
    return x


def integer(
    name: str,
    value: Any,
    error: type[HandSimError],
    *,
    lo: int | None = None,
    hi: int | None = None,
) -> int:
    """``value`` as an int in ``[lo, hi]`` (bools and floats refused), or ``error``."""
    if lo is not None and hi is not None:
        valid = f"an int in [{lo}, {hi}]"
    elif lo is not None:
        valid = f"an int >= {lo}"
    elif hi is not None:
        valid = f"an int <= {hi}"
    else:
        valid = "an int"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        raise error(f"{name} must be {valid}, got {show(value)} ({type(value).__name__})")
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise error(f"{name} must be {valid}, got {v}")
    return v


def boolean(name: str, value: Any, error: type[HandSimError]) -> bool:
    """``value`` if it is a bool (``True``/``False`` or a numpy bool), else ``error``."""
    if not isinstance(value, (bool, np.bool_)):
        raise error(f"{name} must be True or False, got {show(value)} ({type(value).__name__})")
    return bool(value)


def choice(name: str, value: Any, options: Iterable[str], error: type[HandSimError]) -> str:
    """``value`` if it is one of the strings ``options``, else ``error`` listing them."""
    opts = tuple(options)
    if not isinstance(value, str) or value not in opts:
        raise error(f"{name} must be one of {opts}, got {show(value)}")
    return value


def real_array(
    name: str,
    value: Any,
    error: type[HandSimError],
    *,
    shape: tuple[int | None, ...] | None = None,
    max_abs: float = math.inf,
    unit: str = "",
) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape`` (``None`` = any length), or ``error``.

    Refuses strings, objects, bools, complex values, NaN, infinities and entries whose
    magnitude exceeds ``max_abs``.
    """
    want = (
        ""
        if shape is None
        else " of shape ("
        + ", ".join("N" if s is None else str(s) for s in shape)
        + ("," if len(shape) == 1 else "")
        + ")"
    )
    bound = "" if max_abs == math.inf else f" with |x| <= {max_abs:g}"
    valid = f"finite numbers{want}{bound}" + (f" ({unit})" if unit else "")
    try:
        arr = np.asarray(value)
    except Exception as err:  # noqa: BLE001 - ragged or exotic inputs
        raise error(f"{name} must be {valid}, got {show(value)}") from err
    if arr.dtype == object:
        # A list of numpy scalars or numbers may still be numeric.
        try:
            arr = np.asarray(arr.tolist(), dtype=np.float64)
        except (TypeError, ValueError):
            raise error(f"{name} must be {valid}, got {show(value)}") from None
    if arr.dtype.kind not in "iuf":
        raise error(f"{name} must be {valid}, got {show(value)} (dtype {arr.dtype})")
    if shape is not None and (
        arr.ndim != len(shape)
        or any(s is not None and s != a for s, a in zip(shape, arr.shape, strict=True))
    ):
        raise error(f"{name} must be {valid}, got shape {arr.shape}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise error(f"{name} must be {valid}, got non-finite values: {show(value)}")
    if max_abs != math.inf and arr.size and float(np.max(np.abs(arr))) > max_abs:
        raise error(f"{name} must be {valid}, got {show(value)}")
    return arr


def to_real_array(value: Any) -> np.ndarray:
    """``value`` as a float64 array; ``ValueError`` for strings, complex, ragged or objects.

    For callers that raise their own error with their own message (shape and range checks
    stay with them); NaN and infinities pass.
    """
    try:
        arr = np.asarray(value)
    except Exception as err:  # noqa: BLE001 - ragged or exotic inputs
        raise ValueError(f"not an array of numbers ({type(value).__name__})") from err
    if arr.dtype == object:
        try:
            arr = np.asarray(arr.tolist(), dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"not an array of numbers ({type(value).__name__})") from None
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"not an array of real numbers (dtype {arr.dtype})")
    return arr.astype(np.float64)
