"""Shared pieces of the pose sources: joint index sets and argument checks (private)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TypeVar

import numpy as np

from handsim._validate import is_real, show
from handsim.errors import InvalidPose, UnknownName
from handsim.hand.pose import FINGERS, JOINT_LIMITS, JOINT_NAMES, HandPose

_J = {name: i for i, name in enumerate(JOINT_NAMES)}
_LO = JOINT_LIMITS[:, 0]
_HI = JOINT_LIMITS[:, 1]


def _idx(joint: str) -> list[int]:
    """Indices of ``<finger>_<joint>`` for the four fingers, radial to ulnar."""
    return [_J[f"{f}_{joint}"] for f in FINGERS]


_MCP_FLEX = _idx("mcp_flex")
_MCP_ABD = _idx("mcp_abd")
_PIP = _idx("pip_flex")
_DIP = _idx("dip_flex")
_THUMB = [_J[n] for n in JOINT_NAMES if n.startswith("thumb_")]


# Validation helpers ------------------------------------------------------------------------


def _check_rng(rng: object) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise InvalidPose(
            f"rng must be a numpy.random.Generator (e.g. numpy.random.default_rng(0)); "
            f"received {type(rng).__name__}"
        )
    return rng


MAX_SAMPLES = 1_000_000
"""Largest number of poses one call returns (a batch or a motion), so memory stays sane."""


def _check_count(n: object) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InvalidPose(f"n must be an integer >= 1 (number of poses); received {show(n)}")
    if n > MAX_SAMPLES:
        raise InvalidPose(f"n must be at most {MAX_SAMPLES} (number of poses); received {n}")
    return int(n)


def _check_positive(value: object, name: str, unit: str) -> float:
    v = float(value) if is_real(value) else math.nan  # type: ignore[arg-type]
    if not (math.isfinite(v) and v > 0.0):
        raise InvalidPose(f"{name} must be a finite number > 0 {unit}; received {value!r}")
    return v


def _check_nonnegative(value: object, name: str, unit: str) -> float:
    v = float(value) if is_real(value) else math.nan  # type: ignore[arg-type]
    if not (math.isfinite(v) and v >= 0.0):
        raise InvalidPose(f"{name} must be a finite number >= 0 {unit}; received {value!r}")
    return v


def _batch_pose(angles: np.ndarray) -> HandPose:
    """Wrist at the origin, identity rotation, for angles of shape (..., 21)."""
    batch = angles.shape[:-1]
    return HandPose(np.zeros(batch + (3,)), np.zeros(batch + (3,)), angles)


_T = TypeVar("_T")


def _lookup(registry: Mapping[str, _T], name: object, what: str) -> _T:
    if not isinstance(name, str) or name not in registry:
        raise UnknownName(f"unknown {what} {name!r}; valid names: {', '.join(registry)}")
    return registry[name]


def _add_noise(angles: np.ndarray, rng: np.random.Generator | None, noise_deg: float) -> np.ndarray:
    noise_deg = _check_nonnegative(noise_deg, "noise_deg", "(degrees)")
    if noise_deg == 0.0:
        return angles
    if rng is None:
        raise InvalidPose(
            f"noise_deg = {noise_deg} needs rng, a numpy.random.Generator; received rng=None"
        )
    rng = _check_rng(rng)
    noisy = angles + np.deg2rad(rng.normal(0.0, noise_deg, size=angles.shape))
    return np.clip(noisy, _LO, _HI)


def _check_range(value: object, name: str, lo: float, hi: float, unit: str) -> tuple[float, float]:
    try:
        a, b = (float(v) if is_real(v) else math.nan for v in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        a = b = math.nan
    if not (math.isfinite(a) and math.isfinite(b) and lo <= a <= b <= hi):
        raise InvalidPose(
            f"{name} must be (low, high) with {lo} <= low <= high <= {hi} {unit}; "
            f"received {value!r}"
        )
    return a, b
