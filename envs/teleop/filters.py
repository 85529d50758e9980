"""Smoothing filters for tracked keypoints: the One Euro filter and an exponential average.

The One Euro filter (Casiez, Roussel and Vogel, "1 Euro Filter: A Simple Speed-based Low-pass
Filter for Noisy Input in Interactive Systems", CHI 2012) is a first-order low-pass filter
whose cutoff rises with the signal's speed: slow motion is smoothed hard (little jitter), fast
motion lightly (little lag). Per sample, with period ``Te``:

- ``alpha(fc) = 1 / (1 + tau / Te)``, ``tau = 1 / (2 pi fc)``;
- the derivative ``dx = (x - x_prev_raw) / Te`` is smoothed with cutoff ``d_cutoff_hz``;
- the cutoff is ``fc = min_cutoff_hz + beta * |dx_hat|``;
- the output is ``x_hat = x_hat_prev + alpha(fc) (x - x_hat_prev)``.

Both filters run on every coordinate independently (e.g. 21 x 3 keypoint coordinates). A NaN
input (an untracked keypoint) leaves that coordinate's state unchanged and gives NaN; the next
finite value continues from the held state. The first sample passes unchanged, and so does a
constant input (the update form above returns the state exactly when ``x`` equals it).
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from handsim.errors import HandSimError

__all__ = [
    "FILTERS",
    "KeypointFilter",
    "OneEuroFilter",
    "ExponentialFilter",
    "NoFilter",
    "make_filter",
    "InvalidFilter",
]

FILTERS: tuple[str, ...] = ("none", "one_euro", "ema")
"""Filter names of :func:`make_filter`."""


class InvalidFilter(HandSimError, ValueError):
    """A filter parameter is out of range or the filter name is unknown."""


class KeypointFilter(Protocol):
    """What the teleop loop calls: ``reset()`` per episode and ``__call__`` per sample."""

    def reset(self) -> None:
        """Forget the state."""
        ...

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample (any shape, the same every call); returns a new array."""
        ...


def _positive(name: str, value: float, *, zero_ok: bool = False) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value < 0 or (value == 0 and not zero_ok):
        bound = ">= 0" if zero_ok else "> 0"
        raise InvalidFilter(f"{name} must be a finite number {bound}; received {value!r}")
    return float(value)


def _alpha(cutoff_hz: np.ndarray | float, dt_s: float) -> np.ndarray | float:
    tau = 1.0 / (2.0 * math.pi * cutoff_hz)
    return 1.0 / (1.0 + tau / dt_s)


class NoFilter:
    """The identity (a copy of the input)."""

    def reset(self) -> None:
        """Nothing to forget."""

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Return a copy of ``x``."""
        return np.array(x, dtype=np.float64)

    def __repr__(self) -> str:
        return "NoFilter()"


class OneEuroFilter:
    """The One Euro filter (module docstring), on every coordinate of the samples.

    Args:
        rate_hz: sample rate, Hz (the sim's control rate).
        min_cutoff_hz: cutoff at rest, Hz (lower: smoother when still, more lag).
        beta: cutoff increase per unit speed, Hz per (m/s) for positions in metres (higher:
            less lag in fast motion).
        d_cutoff_hz: cutoff of the derivative's smoothing, Hz.

    Raises:
        InvalidFilter: for a non-positive rate or cutoff or a negative beta.
    """

    def __init__(
        self,
        rate_hz: float,
        *,
        min_cutoff_hz: float = 1.0,
        beta: float = 10.0,
        d_cutoff_hz: float = 1.0,
    ) -> None:
        self.rate_hz = _positive("rate_hz", rate_hz)
        self.min_cutoff_hz = _positive("min_cutoff_hz", min_cutoff_hz)
        self.beta = _positive("beta", beta, zero_ok=True)
        self.d_cutoff_hz = _positive("d_cutoff_hz", d_cutoff_hz)
        self._dt = 1.0 / self.rate_hz
        self._alpha_d = _alpha(self.d_cutoff_hz, self._dt)
        self.reset()

    def __repr__(self) -> str:
        return (
            f"OneEuroFilter(rate_hz={self.rate_hz:g}, min_cutoff_hz={self.min_cutoff_hz:g}, "
            f"beta={self.beta:g}, d_cutoff_hz={self.d_cutoff_hz:g})"
        )

    def reset(self) -> None:
        """Forget the state (the next sample passes unchanged)."""
        self._x_hat: np.ndarray | None = None
        self._x_raw: np.ndarray | None = None
        self._dx_hat: np.ndarray | None = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample (NaN coordinates: untracked; see the module docstring)."""
        x = np.asarray(x, dtype=np.float64)
        if self._x_hat is None:
            self._x_hat = x.copy()
            self._x_raw = x.copy()
            self._dx_hat = np.zeros_like(x)
            return x.copy()
        ok = np.isfinite(x)
        fresh = ok & ~np.isfinite(self._x_hat)  # first finite value of a coordinate
        dx = np.where(ok & ~fresh, (x - self._x_raw) / self._dt, 0.0)
        dx = np.nan_to_num(dx)
        dx_hat = self._dx_hat + self._alpha_d * (dx - self._dx_hat)
        cutoff = self.min_cutoff_hz + self.beta * np.abs(dx_hat)
        a = _alpha(cutoff, self._dt)
        x_hat = np.where(fresh, x, self._x_hat + a * (x - self._x_hat))
        self._x_hat = np.where(ok, x_hat, self._x_hat)
        self._dx_hat = np.where(ok, dx_hat, self._dx_hat)
        self._x_raw = np.where(ok, x, self._x_raw)
        return np.where(ok, self._x_hat, np.nan)


class ExponentialFilter:
    """Exponential moving average ``x_hat += alpha (x - x_hat)`` on every coordinate.

    Args:
        alpha: weight of the new sample, in (0, 1] (1 = no smoothing).
    """

    def __init__(self, alpha: float = 0.5) -> None:
        a = _positive("alpha", alpha)
        if a > 1:
            raise InvalidFilter(f"alpha must lie in (0, 1]; received {alpha!r}")
        self.alpha = a
        self.reset()

    def __repr__(self) -> str:
        return f"ExponentialFilter(alpha={self.alpha:g})"

    def reset(self) -> None:
        """Forget the state."""
        self._x_hat: np.ndarray | None = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample (NaN coordinates hold their state and give NaN)."""
        x = np.asarray(x, dtype=np.float64)
        if self._x_hat is None:
            self._x_hat = x.copy()
            return x.copy()
        ok = np.isfinite(x)
        fresh = ok & ~np.isfinite(self._x_hat)
        x_hat = np.where(fresh, x, self._x_hat + self.alpha * (x - self._x_hat))
        self._x_hat = np.where(ok, x_hat, self._x_hat)
        return np.where(ok, self._x_hat, np.nan)


def make_filter(name: str, rate_hz: float, **params: float) -> KeypointFilter:
    """A filter by name (:data:`FILTERS`).

    Args:
        name: ``"none"``, ``"one_euro"`` (params ``min_cutoff_hz``, ``beta``,
            ``d_cutoff_hz``) or ``"ema"`` (param ``alpha``).
        rate_hz: sample rate, Hz.
        **params: the filter's parameters (unset: defaults).

    Raises:
        InvalidFilter: for an unknown name or parameter.
    """
    if name not in FILTERS:
        raise InvalidFilter(f"filter={name!r} is not valid; choose one of {', '.join(FILTERS)}")
    try:
        if name == "one_euro":
            return OneEuroFilter(rate_hz, **params)
        if name == "ema":
            return ExponentialFilter(**params)
    except TypeError as err:
        raise InvalidFilter(f"filter {name!r}: {err}") from None
    if params:
        raise InvalidFilter(f"filter 'none' takes no parameters; received {sorted(params)}")
    return NoFilter()
