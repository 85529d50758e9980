"""Tracking faults injected between the operator's hand and what the teleop loop receives.

:class:`FaultConfig` holds the settings; :class:`FaultInjector` applies them frame by frame
(seeded, so two injectors with the same seed fed the same frames give the same output). For
sample ``i`` of the stream (keypoints ``x_i``, (21, 3), world frame, metres), in this order:

1. **latency and jitter**: the sample delivered is ``x_d`` with
   ``d = i - latency_frames - j_i``, ``j_i`` uniform in ``{0, ..., jitter_frames}``; ``d``
   never goes back in time (a late sample does not overtake a newer one: ``d_i >= d_{i-1}``)
   and is at least 0 (the first frames repeat the first sample). Without jitter the output is
   the input shifted by exactly ``latency_frames``.
2. **occlusion**: with probability ``occlusion_rate`` per frame (when none is under way) an
   occluder, a sphere of radius ``occluder_radius_m``, appears ``occluder_distance_m`` in front
   of a random keypoint on its line of sight to the ``viewpoint_m`` (the tracking camera) and
   stays for ``occlusion_frames`` frames; keypoints whose line of sight passes through it are
   not tracked (NaN).
3. **noise and bias**: Gaussian noise of std ``noise_mm`` per axis and keypoint, plus the
   constant ``bias_mm`` (3,), world frame.
4. **dropout**: with probability ``dropout`` the frame is lost (as when fewer than
   :data:`MIN_TRACKED` keypoints remain after the occlusion); the output is then the last
   output (``dropout_mode="hold"``) or its constant-velocity extrapolation from the last two
   outputs and their frame gap (``"extrapolate"``, for at most
   :data:`MAX_EXTRAPOLATION_FRAMES` frames, then held).

A lost frame is flagged (``dropped``) so the loop can count it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from handsim.errors import HandSimError

__all__ = [
    "FaultConfig",
    "FaultInjector",
    "InvalidFaults",
    "DROPOUT_MODES",
    "MIN_TRACKED",
    "MAX_EXTRAPOLATION_FRAMES",
    "sight_blocked",
]

DROPOUT_MODES: tuple[str, ...] = ("hold", "extrapolate")
"""What replaces a lost frame: the last output, or its constant-velocity extrapolation."""
MIN_TRACKED = 4
"""A frame with fewer tracked keypoints is lost (the retargeter needs at least 4)."""
MAX_EXTRAPOLATION_FRAMES = 10
"""Longest run of lost frames that is extrapolated; later ones hold the last value."""
_MAX_FRAMES = 10_000


class InvalidFaults(HandSimError, ValueError):
    """A fault setting is out of range."""


def _number(name: str, value: Any, lo: float, hi: float = math.inf) -> float:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if not ok or not math.isfinite(float(value)) or not lo <= float(value) <= hi:
        rng = f"[{lo}, {hi}]" if math.isfinite(hi) else f">= {lo}"
        raise InvalidFaults(f"{name} must be a finite number {rng}; received {value!r}")
    return float(value)


def _frames(name: str, value: Any) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, np.integer))
        or not (0 <= value <= _MAX_FRAMES)
    ):
        raise InvalidFaults(
            f"{name} must be an int in [0, {_MAX_FRAMES}] frames; received {value!r}"
        )
    return int(value)


@dataclasses.dataclass(frozen=True)
class FaultConfig:
    """Tracking faults (module docstring); the defaults inject nothing.

    Attributes:
        noise_mm: std of the Gaussian keypoint noise per axis, mm.
        bias_mm: (3,) constant offset of every keypoint, world frame, mm.
        dropout: probability that a frame is lost, in [0, 1].
        dropout_mode: one of :data:`DROPOUT_MODES`.
        latency_frames: delay, frames of the stream (at the sim rate).
        jitter_frames: largest extra random delay per frame, frames.
        occlusion_rate: probability per frame that an occlusion starts, in [0, 1].
        occlusion_frames: duration of an occlusion, frames (>= 1).
        occluder_radius_m: radius of the occluding sphere, metres.
        occluder_distance_m: distance of the occluder in front of the keypoint it hides, metres.
        viewpoint_m: (3,) the tracking camera's position, world frame, metres (the capture
            camera in camera mode).
    """

    noise_mm: float = 0.0
    bias_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dropout: float = 0.0
    dropout_mode: str = "hold"
    latency_frames: int = 0
    jitter_frames: int = 0
    occlusion_rate: float = 0.0
    occlusion_frames: int = 10
    occluder_radius_m: float = 0.03
    occluder_distance_m: float = 0.08
    viewpoint_m: tuple[float, float, float] = (0.0, 0.52, 0.42)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "noise_mm", _number("noise_mm", self.noise_mm, 0.0, 1000.0))
        set_(self, "bias_mm", _vector("bias_mm", self.bias_mm))
        set_(self, "dropout", _number("dropout", self.dropout, 0.0, 1.0))
        if self.dropout_mode not in DROPOUT_MODES:
            raise InvalidFaults(
                f"dropout_mode={self.dropout_mode!r} is not valid; choose one "
                f"of {', '.join(DROPOUT_MODES)}"
            )
        set_(self, "latency_frames", _frames("latency_frames", self.latency_frames))
        set_(self, "jitter_frames", _frames("jitter_frames", self.jitter_frames))
        set_(self, "occlusion_rate", _number("occlusion_rate", self.occlusion_rate, 0.0, 1.0))
        set_(self, "occlusion_frames", _frames("occlusion_frames", self.occlusion_frames))
        if self.occlusion_frames < 1:
            raise InvalidFaults("occlusion_frames must be >= 1; received 0")
        set_(
            self,
            "occluder_radius_m",
            _number("occluder_radius_m", self.occluder_radius_m, 0.0, 1.0),
        )
        set_(
            self,
            "occluder_distance_m",
            _number("occluder_distance_m", self.occluder_distance_m, 0.0, 10.0),
        )
        set_(self, "viewpoint_m", _vector("viewpoint_m", self.viewpoint_m, scale=1.0))

    def to_dict(self) -> dict[str, Any]:
        """The settings as plain JSON values."""
        return {
            k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()
        }


def _vector(name: str, value: Any, scale: float = 1.0) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.full(0, np.nan)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InvalidFaults(f"{name} must be 3 finite numbers (x, y, z); received {value!r}")
    return tuple(float(v) * scale for v in arr)  # type: ignore[return-value]


def sight_blocked(
    points: np.ndarray, viewpoint: np.ndarray, center: np.ndarray, radius: float
) -> np.ndarray:
    """Which points' line of sight to ``viewpoint`` passes through a sphere.

    Args:
        points: (N, 3) points, metres.
        viewpoint: (3,) eye, metres.
        center: (3,) sphere centre, metres.
        radius: sphere radius, metres.

    Returns:
        (N,) bool; NaN points are not blocked.
    """
    d = viewpoint - points  # segment point -> eye
    length2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
    s = np.clip(np.einsum("ij,ij->i", center - points, d) / length2, 0.0, 1.0)
    closest = points + s[:, None] * d
    dist = np.linalg.norm(closest - center, axis=1)
    return np.nan_to_num(dist, nan=np.inf) < radius


class FaultInjector:
    """Applies a :class:`FaultConfig` to a stream, one frame at a time.

    Args:
        config: the faults.
        rng: a Generator or an int seed.
    """

    def __init__(self, config: FaultConfig, rng: np.random.Generator | int | None = 0) -> None:
        if not isinstance(config, FaultConfig):
            raise InvalidFaults(f"config must be a FaultConfig; received {type(config).__name__}")
        self.config = config
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self._viewpoint = np.asarray(config.viewpoint_m)
        self.reset()

    def reset(self) -> None:
        """Start a new episode (the generator keeps running)."""
        self._history: list[np.ndarray] = []
        self._delivered = 0
        self._outputs: list[tuple[int, np.ndarray]] = []  # last two (frame, output)
        self._lost_run = 0
        self._frame = -1
        self._occluder: tuple[np.ndarray, int] | None = None  # (centre, frames left)
        self.n_dropped = 0
        self.n_occluded_frames = 0

    def __call__(self, keypoints: np.ndarray) -> tuple[np.ndarray, bool]:
        """Push the operator's true keypoints of this frame; get what the tracker delivers.

        Args:
            keypoints: (21, 3) operator keypoints, world frame, metres (NaN: not tracked).

        Returns:
            ``(keypoints, dropped)``: (21, 3) delivered keypoints (NaN: not tracked) and
            whether this frame was lost (then the keypoints are held or extrapolated, or all
            NaN before any output).
        """
        cfg, rng = self.config, self.rng
        self._history.append(np.asarray(keypoints, dtype=np.float64))
        i = len(self._history) - 1
        jitter = int(rng.integers(0, cfg.jitter_frames + 1)) if cfg.jitter_frames else 0
        d = min(max(i - cfg.latency_frames - jitter, self._delivered, 0), i)
        self._delivered = d
        # Keep only what a later frame may still deliver.
        x = self._history[d].copy()
        lost = False
        if cfg.occlusion_rate > 0:
            if self._occluder is None and rng.random() < cfg.occlusion_rate:
                tracked = np.nonzero(np.all(np.isfinite(x), axis=1))[0]
                if tracked.size:
                    k = x[tracked[rng.integers(tracked.size)]]
                    to_eye = self._viewpoint - k
                    to_eye /= max(float(np.linalg.norm(to_eye)), 1e-9)
                    self._occluder = (k + cfg.occluder_distance_m * to_eye, cfg.occlusion_frames)
            if self._occluder is not None:
                center, left = self._occluder
                x[sight_blocked(x, self._viewpoint, center, cfg.occluder_radius_m)] = np.nan
                self.n_occluded_frames += 1
                self._occluder = (center, left - 1) if left > 1 else None
        if cfg.noise_mm > 0:
            x += rng.normal(0.0, cfg.noise_mm * 1e-3, size=x.shape)
        if any(cfg.bias_mm):
            x += np.asarray(cfg.bias_mm) * 1e-3
        if cfg.dropout > 0 and rng.random() < cfg.dropout:
            lost = True
        if np.count_nonzero(np.all(np.isfinite(x), axis=1)) < MIN_TRACKED:
            lost = True
        self._frame += 1
        if lost:
            self.n_dropped += 1
            self._lost_run += 1
            x = self._replacement()
        else:
            self._lost_run = 0
            self._outputs = [*self._outputs[-1:], (self._frame, x)]
        if len(self._history) > cfg.latency_frames + cfg.jitter_frames + 2:
            drop = len(self._history) - (cfg.latency_frames + cfg.jitter_frames + 2)
            self._history = self._history[drop:]
            self._delivered -= drop
        return x, lost

    def _replacement(self) -> np.ndarray:
        if not self._outputs:
            return np.full((21, 3), np.nan)
        i_last, last = self._outputs[-1]
        if (
            self.config.dropout_mode == "extrapolate"
            and len(self._outputs) == 2
            and self._lost_run <= MAX_EXTRAPOLATION_FRAMES
        ):
            i_prev, prev = self._outputs[0]
            return last + (self._frame - i_last) * (last - prev) / (i_last - i_prev)
        return last.copy()
