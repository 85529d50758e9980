"""Strict JSON: what the reports and the command line print (no ``NaN``, no numpy types)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["to_strict_json"]


def to_strict_json(value: Any) -> Any:
    """A copy of ``value`` that strict JSON parsers accept: non-finite floats become ``None``.

    Dicts, lists and tuples are converted recursively; numpy scalars and arrays become Python
    numbers and lists. Use with ``json.dumps(..., allow_nan=False)``.
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
