"""Depth-sensor noise models: seeded, composable, applied to a clean rendered depth image.

Every model is a frozen dataclass with ``apply(depth_m, intrinsics, rng) -> depth_m``: input and
output are (H, W) float32 depth along the optical axis in metres, ``0.0`` = no measurement; the
input is not modified, so the clean and the noisy depth of a frame can both be kept. Models
compose with :class:`Compose`. Sources are in ``shared/facts/hand_objects_sensors.md`` section 6.

:class:`StructuredLight` (PrimeSense Carmine / Kinect v1 style), in this order:

1. lateral jitter: each pixel samples the clean depth at a position displaced by
   N(0, ``lateral_jitter_px``) pixels (nearest neighbour), as in Handa et al. 2014;
2. projector shadow: with the projector ``baseline_m`` to the camera's ``+x``, a pixel is
   invalid when a nearer surface hides it from the projector. In a row, the projector column of
   pixel u is ``u - fx b / z``; scanning from the right, a pixel is lit only if its projector
   column is left of every column claimed to its right. The band lies on the ``-x`` side of
   foreground objects and is ``fx b (1/z_fg - 1/z_bg)`` pixels wide;
3. disparity noise and quantization: disparity ``d = fx b / z`` gets Gaussian noise and is
   rounded to ``disparity_step_px`` (1/8 px). The Gaussian's sigma is chosen so that the total
   axial noise (Gaussian plus quantization, ``step^2 / 12``) equals Nguyen, Izadi & Lovell 2012's
   measured ``sigma_z(z, theta) = 1.2 mm + 1.9 mm/m^2 (z - 0.4 m)^2
   + 0.1 mm m^0.5 / sqrt(z) * theta^2 / (pi/2 - theta)^2``;
4. grazing-angle dropout: pixels whose surface normal is more than ``max_incidence_deg`` from
   the viewing ray are invalid;
5. range limits: depths outside ``[min_range_m, max_range_m]`` are invalid.

:class:`TimeOfFlight` (ICVL / MSRA Creative-camera style): flying pixels (a pixel next to a depth
edge larger than ``edge_threshold_m`` takes, with ``flying_pixel_prob``, a random blend of the
two surfaces), Gaussian axial noise ``sigma_m``, random dropouts, range limits.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from handsim.camera import CameraIntrinsics
from handsim.errors import HandSimError, UnknownName

__all__ = [
    "SensorModel",
    "NoNoise",
    "StructuredLight",
    "TimeOfFlight",
    "Compose",
    "InvalidSensor",
    "nguyen_sigma_z",
    "incidence_angle",
    "sensor_model",
]


class InvalidSensor(HandSimError, ValueError):
    """A sensor-model parameter or input is invalid."""


class SensorModel(Protocol):
    """A depth-noise model."""

    def apply(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> np.ndarray:
        """Noisy copy of a clean (H, W) depth image in metres (0 = no measurement)."""
        ...


def nguyen_sigma_z(depth_m: np.ndarray, incidence_rad: np.ndarray | float = 0.0) -> np.ndarray:
    """Axial noise of a Kinect-v1-class sensor (Nguyen, Izadi & Lovell 2012).

    Args:
        depth_m: depth, metres.
        incidence_rad: angle between the surface normal and the viewing ray, radians (< pi/2).

    Returns:
        Standard deviation of the depth, metres, same shape as the broadcast inputs.
    """
    z = np.asarray(depth_m, dtype=np.float64)
    theta = np.minimum(np.asarray(incidence_rad, dtype=np.float64), np.deg2rad(89.0))
    base = 0.0012 + 0.0019 * (z - 0.4) ** 2
    angular = 0.0001 / np.sqrt(np.maximum(z, 1e-6)) * theta**2 / (np.pi / 2 - theta) ** 2
    return base + angular


def incidence_angle(
    depth_m: np.ndarray, intrinsics: CameraIntrinsics, max_step: float = 0.05
) -> np.ndarray:
    """Angle between the surface normal (from depth gradients) and the viewing ray.

    Args:
        depth_m: (H, W) depth, metres, 0 = none.
        intrinsics: camera intrinsics.
        max_step: neighbours whose depth differs by more than this fraction of the depth lie
            on another surface (a depth edge, not a slope) and give no normal.

    Returns:
        (H, W) angle in radians; 0 where no normal can be estimated.
    """
    depth = np.asarray(depth_m, dtype=np.float64)
    points = intrinsics.backproject(depth)
    du = np.zeros_like(points)
    dv = np.zeros_like(points)
    du[:, 1:-1] = points[:, 2:] - points[:, :-2]
    dv[1:-1] = points[2:] - points[:-2]
    normal = np.cross(du, dv)
    norm = np.linalg.norm(normal, axis=-1)
    ray = points / np.maximum(np.linalg.norm(points, axis=-1, keepdims=True), 1e-12)
    cos = np.abs(np.sum(normal * ray, axis=-1)) / np.maximum(norm, 1e-12)
    angle = np.arccos(np.clip(cos, 0.0, 1.0))
    # A normal needs all four neighbours on the same surface as the pixel.
    ok = np.zeros(depth.shape, dtype=bool)
    centre = depth[1:-1, 1:-1]
    limit = max_step * centre
    ok[1:-1, 1:-1] = centre > 0
    for neighbour in (depth[2:, 1:-1], depth[:-2, 1:-1], depth[1:-1, 2:], depth[1:-1, :-2]):
        ok[1:-1, 1:-1] &= (neighbour > 0) & (np.abs(neighbour - centre) <= limit)
    return np.where(ok & (norm > 0), angle, 0.0)


def _check_depth(depth_m: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    depth = np.asarray(depth_m)
    if depth.shape != (intrinsics.height, intrinsics.width):
        raise InvalidSensor(
            f"depth must have shape (H, W) = ({intrinsics.height}, {intrinsics.width}) to match "
            f"the camera; received {depth.shape}"
        )
    if not np.all(np.isfinite(depth)) or np.any(depth < 0):
        raise InvalidSensor("depth must be finite and >= 0 m (0 = no measurement)")
    return depth.astype(np.float64)


def _range_limit(depth: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return np.where((depth >= lo) & (depth <= hi), depth, 0.0)


def _check_positive(name: str, value: float) -> None:
    if not (np.isfinite(value) and value > 0):
        raise InvalidSensor(f"{name} must be a positive number; received {value!r}")


def _check_range(min_range_m: float, max_range_m: float) -> None:
    if not 0 <= min_range_m < max_range_m:
        raise InvalidSensor(
            f"need 0 <= min_range_m < max_range_m; received {min_range_m}, {max_range_m}"
        )


def _check_probability(name: str, value: float) -> None:
    if not (0.0 <= value <= 1.0):
        raise InvalidSensor(f"{name} must be a probability in [0, 1]; received {value!r}")


@dataclasses.dataclass(frozen=True)
class NoNoise:
    """The clean depth (a copy)."""

    def apply(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> np.ndarray:
        """Return a float32 copy of the clean depth."""
        return _check_depth(depth_m, intrinsics).astype(np.float32)


@dataclasses.dataclass(frozen=True)
class StructuredLight:
    """Structured-light sensor noise (see the module docstring for the steps).

    Attributes:
        baseline_m: projector offset along the camera's +x, metres (75 mm on Kinect v1).
        disparity_step_px: disparity quantization step, pixels.
        lateral_jitter_px: sigma of the lateral sampling jitter, pixels.
        max_incidence_deg: pixels seen more obliquely than this are dropped.
        min_range_m: nearest valid depth, metres.
        max_range_m: farthest valid depth, metres.
        shadow: drop the projector-shadow band.
    """

    baseline_m: float = 0.075
    disparity_step_px: float = 1.0 / 8.0
    lateral_jitter_px: float = 0.5
    max_incidence_deg: float = 75.0
    min_range_m: float = 0.35
    max_range_m: float = 4.0
    shadow: bool = True

    def __post_init__(self) -> None:
        for name in ("baseline_m", "disparity_step_px", "max_range_m"):
            _check_positive(name, getattr(self, name))
        if self.lateral_jitter_px < 0:
            raise InvalidSensor(
                f"lateral_jitter_px must be >= 0; received {self.lateral_jitter_px}"
            )
        if not 0 < self.max_incidence_deg <= 90:
            raise InvalidSensor(
                f"max_incidence_deg must be in (0, 90]; received {self.max_incidence_deg}"
            )
        _check_range(self.min_range_m, self.max_range_m)

    def apply(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> np.ndarray:
        """Noisy copy of a clean depth image.

        Args:
            depth_m: (H, W) clean depth, metres, 0 = none.
            intrinsics: the camera that rendered it.
            rng: random generator.

        Returns:
            (H, W) float32 noisy depth, metres, 0 = no measurement.
        """
        clean = _check_depth(depth_m, intrinsics)
        h, w = clean.shape
        depth = clean
        if self.lateral_jitter_px > 0:
            v, u = np.indices((h, w))
            ju = np.rint(u + rng.normal(0.0, self.lateral_jitter_px, (h, w))).astype(int)
            jv = np.rint(v + rng.normal(0.0, self.lateral_jitter_px, (h, w))).astype(int)
            depth = clean[np.clip(jv, 0, h - 1), np.clip(ju, 0, w - 1)]
        valid = depth > 0
        fb = intrinsics.fx * self.baseline_m
        if self.shadow:
            u = np.arange(w)[None, :]
            col = np.where(valid, u - fb / np.where(valid, depth, 1.0), np.inf)
            # Smallest projector column claimed strictly to the right of each pixel.
            right_min = np.minimum.accumulate(col[:, ::-1], axis=1)[:, ::-1]
            right_min = np.concatenate([right_min[:, 1:], np.full((h, 1), np.inf)], axis=1)
            valid &= col < right_min
        incidence = incidence_angle(np.where(valid, depth, 0.0), intrinsics)
        valid &= incidence <= np.deg2rad(self.max_incidence_deg)
        safe = np.where(valid, depth, 1.0)
        disparity = fb / safe
        sigma_total_px = nguyen_sigma_z(safe, incidence) * fb / safe**2
        sigma_px = np.sqrt(np.maximum(sigma_total_px**2 - self.disparity_step_px**2 / 12.0, 0.0))
        noisy = disparity + rng.normal(0.0, 1.0, (h, w)) * sigma_px
        quantized = np.rint(noisy / self.disparity_step_px) * self.disparity_step_px
        valid &= quantized > 0
        out = np.where(valid, fb / np.where(valid, quantized, 1.0), 0.0)
        return _range_limit(out, self.min_range_m, self.max_range_m).astype(np.float32)


@dataclasses.dataclass(frozen=True)
class TimeOfFlight:
    """Time-of-flight sensor noise (see the module docstring).

    Attributes:
        sigma_m: axial Gaussian noise, metres.
        edge_threshold_m: a depth step larger than this between neighbours is an edge.
        flying_pixel_prob: probability that an edge pixel mixes the two surfaces.
        dropout_prob: probability that any valid pixel is lost.
        min_range_m: nearest valid depth, metres.
        max_range_m: farthest valid depth, metres.
    """

    sigma_m: float = 0.003
    edge_threshold_m: float = 0.02
    flying_pixel_prob: float = 0.5
    dropout_prob: float = 0.01
    min_range_m: float = 0.15
    max_range_m: float = 1.0

    def __post_init__(self) -> None:
        if self.sigma_m < 0:
            raise InvalidSensor(f"sigma_m must be >= 0; received {self.sigma_m}")
        _check_positive("edge_threshold_m", self.edge_threshold_m)
        _check_probability("flying_pixel_prob", self.flying_pixel_prob)
        _check_probability("dropout_prob", self.dropout_prob)
        _check_range(self.min_range_m, self.max_range_m)

    def apply(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> np.ndarray:
        """Noisy copy of a clean depth image (same arguments as :meth:`StructuredLight.apply`)."""
        clean = _check_depth(depth_m, intrinsics)
        h, w = clean.shape
        valid = clean > 0
        # Largest neighbouring depth (4-neighbourhood) tells whether a pixel sits on an edge.
        padded = np.pad(np.where(valid, clean, 0.0), 1, mode="edge")
        neighbours = np.stack(
            [padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]]
        )
        far = neighbours.max(axis=0)
        edge = valid & (far - clean > self.edge_threshold_m)
        flying = edge & (rng.random((h, w)) < self.flying_pixel_prob)
        mix = rng.random((h, w))
        depth = np.where(flying, (1 - mix) * clean + mix * far, clean)
        depth = depth + rng.normal(0.0, self.sigma_m, (h, w))
        valid &= rng.random((h, w)) >= self.dropout_prob
        out = np.where(valid, depth, 0.0)
        return _range_limit(out, self.min_range_m, self.max_range_m).astype(np.float32)


@dataclasses.dataclass(frozen=True)
class Compose:
    """Apply several models in order (each sees the previous one's output).

    Attributes:
        models: the models, first applied first.
    """

    models: Sequence[SensorModel]

    def apply(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> np.ndarray:
        """Apply every model in turn."""
        out = _check_depth(depth_m, intrinsics).astype(np.float32)
        for model in self.models:
            out = model.apply(out, intrinsics, rng)
        return out


_SENSOR_MODELS = {"none": NoNoise, "structured_light": StructuredLight, "tof": TimeOfFlight}


def sensor_model(name: str, **kwargs: object) -> SensorModel:
    """A sensor model by name: ``"none"``, ``"structured_light"`` or ``"tof"``.

    Raises:
        UnknownName: listing the valid names.
    """
    if name not in _SENSOR_MODELS:
        raise UnknownName(
            f"unknown sensor model {name!r}; valid models: {', '.join(_SENSOR_MODELS)}"
        )
    return _SENSOR_MODELS[name](**kwargs)
