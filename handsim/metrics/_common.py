"""What every metric shares: units, thresholds, the input error, argument checks, strict JSON."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from handsim._validate import is_real
from handsim.errors import HandSimError


class InvalidMetricInput(HandSimError, ValueError):
    """Metric input has the wrong shape, a non-finite or negative value, or is empty."""


MM_PER_M = 1000.0
"""Millimetres per metre (errors are reported in mm)."""

TAU_MAX_MM = 80.0
"""Largest threshold of the hand F(tau) and PCK curves and of their AUC, mm."""

TAU_STEP_MM = 1.0
"""Spacing of the hand threshold grid, mm (trapezoid AUC on this grid)."""

FINGERTIP_INDICES: tuple[int, ...] = (4, 8, 12, 16, 20)
"""Canonical indices of the thumb, index, middle, ring and little fingertips."""

ADD_FRACTION = 0.1
"""A pose is correct when ADD(-S) < ADD_FRACTION * diameter (Hinterstoisser's k_m)."""

REPROJECTION_THRESHOLD_PX = 5.0
"""A pose is correct when the 2D reprojection error is < this many pixels."""

YCBV_AUC_MAX_MM = 100.0
"""Largest threshold of the YCB-Video ADD / ADD-S accuracy curve (0.1 m), mm."""

DEFAULT_OCCLUSION_EDGES: tuple[float, ...] = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
"""Default occlusion bucket edges (occlusion ratio in [0, 1])."""

AucRule = Literal["posecnn", "exact"]


# Validation helpers ----------------------------------------------------------------------------


def _array(name: str, x: Any) -> np.ndarray:
    try:
        raw = np.asarray(x)
        if raw.dtype == object:
            raw = np.asarray(raw.tolist(), dtype=np.float64)
        if raw.dtype.kind not in "biuf":
            raise TypeError(f"dtype {raw.dtype}; strings and complex numbers are not valid")
        return raw.astype(np.float64)
    except (TypeError, ValueError) as err:
        raise InvalidMetricInput(
            f"{name} must be an array of numbers; received {type(x).__name__} ({err})"
        ) from None


def _keypoint_array(name: str, x: Any) -> np.ndarray:
    arr = _array(name, x)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InvalidMetricInput(
            f"{name} must be an (N, J, 3) array of keypoints in metres; received shape "
            f"{arr.shape} (add a batch axis with x[None] for a single frame)"
        )
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise InvalidMetricInput(
            f"{name} must hold at least one frame and one joint; received shape {arr.shape}"
        )
    return arr


def _visible_mask(visible: Any, shape: tuple[int, int]) -> np.ndarray:
    if visible is None:
        return np.ones(shape, dtype=bool)
    try:
        mask = np.asarray(visible)
    except ValueError:
        raise InvalidMetricInput(
            f"visible must be an (N, J) = {shape} boolean mask; received a ragged "
            f"{type(visible).__name__}"
        ) from None
    if mask.dtype.kind not in "biuf":
        raise InvalidMetricInput(
            f"visible must be an (N, J) = {shape} boolean mask; received dtype {mask.dtype}"
        )
    if mask.shape != shape:
        raise InvalidMetricInput(
            f"visible must be an (N, J) = {shape} mask; received shape {mask.shape}"
        )
    if mask.dtype != bool:
        if not np.all(np.isin(mask, (0, 1))):
            raise InvalidMetricInput(
                "visible must be boolean (or 0/1); received values other than 0 and 1"
            )
        mask = mask.astype(bool)
    return mask


def _first_bad(bad: np.ndarray) -> str:
    idx = tuple(int(i) for i in np.argwhere(bad)[0])
    if len(idx) == 2:
        return f"frame {idx[0]}, joint {idx[1]}"
    return f"index {idx}"


MAX_COORDINATE_M = 1e6
"""Largest keypoint coordinate a metric accepts, metres: beyond, the errors in mm overflow
(1e300 m gave an infinite mean) and the value is a unit mistake anyway."""


def _check_finite_at(name: str, arr: np.ndarray, mask: np.ndarray) -> None:
    bad = ~np.all(np.isfinite(arr), axis=-1) & mask
    if np.any(bad):
        raise InvalidMetricInput(
            f"{name} has a non-finite value at {_first_bad(bad)}; expected finite metres at "
            "every evaluated joint (mark joints without a label False in `visible`)"
        )
    with np.errstate(invalid="ignore"):
        huge = np.any(np.abs(arr) > MAX_COORDINATE_M, axis=-1) & mask
    if np.any(huge):
        raise InvalidMetricInput(
            f"{name} has a value beyond {MAX_COORDINATE_M:g} m at {_first_bad(huge)}; expected "
            "keypoints in metres (a unit mistake?)"
        )


def _point_pairs(pred_name: str, pred: Any, gt_name: str, gt: Any) -> tuple[np.ndarray, np.ndarray]:
    p = _keypoint_array(pred_name, pred)
    g = _keypoint_array(gt_name, gt)
    if p.shape != g.shape:
        raise InvalidMetricInput(
            f"{pred_name} and {gt_name} must have the same shape (N, J, 3); received "
            f"{p.shape} and {g.shape}"
        )
    return p, g


def _frame_errors(name: str, errors: Any) -> np.ndarray:
    """Per-frame errors: 1-D, NaN = not evaluated, +inf = no estimate, else >= 0."""
    e = _array(name, errors)
    if e.ndim != 1:
        raise InvalidMetricInput(
            f"{name} must be a 1-D array of per-frame errors in mm; received shape {e.shape}"
        )
    _check_error_values(name, e)
    if e.size == 0 or np.all(np.isnan(e)):
        raise InvalidMetricInput(
            f"{name} must hold at least one evaluated (non-NaN) frame; received {e.size} "
            f"frames, {int(np.sum(~np.isnan(e)))} evaluated"
        )
    return e


def _check_error_values(name: str, e: np.ndarray) -> None:
    if np.any(e == -np.inf) or np.any(e[~np.isnan(e)] < 0):
        raise InvalidMetricInput(
            f"{name} must be >= 0 (NaN = not evaluated, +inf = no estimate); received minimum "
            f"{np.nanmin(e)}"
        )


def _thresholds(name: str, taus: Any) -> np.ndarray:
    t = _array(name, taus)
    if t.ndim != 1 or t.size == 0:
        raise InvalidMetricInput(
            f"{name} must be a non-empty 1-D array of thresholds; received shape {t.shape}"
        )
    if not np.all(np.isfinite(t)):
        raise InvalidMetricInput(f"{name} must be finite; received {t.tolist()}")
    if np.any(t < 0):
        raise InvalidMetricInput(f"{name} must be >= 0; received minimum {t.min()}")
    return t


def _positive(name: str, value: float) -> float:
    try:
        if not is_real(value):
            raise TypeError(name)
        v = float(value)
    except (TypeError, ValueError):
        raise InvalidMetricInput(f"{name} must be a positive number; received {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise InvalidMetricInput(f"{name} must be a positive finite number; received {value!r}")
    return v


def _error_or_miss(name: str, error: float | None) -> float:
    """An error value, ``inf`` for a miss (None / NaN / inf)."""
    if error is None:
        return math.inf
    try:
        e = float(error)
    except (TypeError, ValueError):
        raise InvalidMetricInput(f"{name} must be a number or None; received {error!r}") from None
    if math.isnan(e):
        return math.inf
    if e < 0:
        raise InvalidMetricInput(f"{name} must be >= 0 (or None for a miss); received {e}")
    return e


def _errors_with_misses(name: str, errors: Any) -> np.ndarray:
    """1-D errors with None / NaN / inf mapped to inf (a miss)."""
    if isinstance(errors, np.ndarray):
        values = errors
        if values.ndim != 1:
            raise InvalidMetricInput(
                f"{name} must be a 1-D sequence of per-frame errors; received shape {values.shape}"
            )
        seq = values.tolist()
    elif isinstance(errors, Sequence) and not isinstance(errors, str):
        seq = list(errors)
    else:
        raise InvalidMetricInput(
            f"{name} must be a sequence of per-frame errors (None / NaN for a miss); received "
            f"{type(errors).__name__}"
        )
    if len(seq) == 0:
        raise InvalidMetricInput(f"{name} must hold at least one frame; received 0")
    return np.array([_error_or_miss(name, e) for e in seq], dtype=np.float64)


def to_strict_json(value: Any) -> Any:
    """A copy of ``value`` that strict JSON parsers accept: non-finite floats become ``None``.

    Dicts, lists and tuples are converted recursively; numpy scalars and arrays become Python
    numbers and lists. Use with ``json.dumps(..., allow_nan=False)`` (reports, the command
    line's output).
    """
    if isinstance(value, dict):
        return {str(k): to_strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_strict_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_strict_json(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value
