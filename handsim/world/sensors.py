"""Depth-sensor noise models: seeded, composable, applied to a clean rendered depth image.

Every model is a frozen dataclass with ``apply(depth_m, intrinsics, rng) -> depth_m``: input and
output are (H, W) float32 depth along the optical axis in metres, ``0.0`` = no measurement; the
input is not modified, so the clean and the noisy depth of a frame can both be kept. Models
compose with :class:`Compose`. Each step below names the paper it follows.

The models compute in float32 (the structured-light model's per-pixel steps in compiled
loops, the rest with OpenCV and per-thread scratch arrays instead of fresh temporaries) and
draw random numbers only where they are used: per valid pixel, per edge pixel. Gaussian
draws use Box-Muller (float64 radius, so the tails reach 8.5 sigma). Outputs are
deterministic for a seed.

:class:`StructuredLight` (PrimeSense Carmine / Kinect v1 style), in this order:

1. lateral jitter: each pixel samples the clean depth at a position displaced by
   N(0, ``lateral_jitter_px``) pixels along each axis (nearest neighbour, clamped to the image),
   as in Handa et al. 2014. Nearest-neighbour sampling only sees the rounded displacement
   ``rint(N(0, s))``, so the pair of rounded displacements is drawn directly from its exact
   distribution, ``P(k) = Phi((k + 1/2) / s) - Phi((k - 1/2) / s)`` per axis (cut at 10 s): a
   random byte per pixel picks the pair from a table, a second byte settles the few bytes
   (4 % at 0.5 px) that straddle two pairs, and a float64 uniform the rare rest. A wide jitter
   (``s`` above about 1.6 px, where many bytes would straddle) rounds Gaussian draws instead;
2. projector shadow: with the projector ``baseline_m`` to the camera's ``+x``, a pixel is
   invalid when a nearer surface hides it from the projector. In a row, the projector column of
   pixel u is ``u - fx b / z``; scanning from the right, a pixel is lit only if its projector
   column is left of every column claimed to its right. A pixel more than
   ``d_max - d_min + 1`` columns to the right (``d = fx b / z``, the disparity, over the image)
   can never claim it: the scan is a running maximum of ``d - u`` from the right. The band
   lies on the ``-x`` side of foreground objects and is ``fx b (1/z_fg - 1/z_bg)`` pixels
   wide;
3. disparity noise and quantization: disparity ``d = fx b / z`` gets Gaussian noise and is
   rounded to ``disparity_step_px`` (1/8 px). The Gaussian's sigma is chosen so that the total
   axial noise (Gaussian plus quantization, ``step^2 / 12``) equals Nguyen, Izadi & Lovell 2012's
   measured ``sigma_z(z, theta) = 1.2 mm + 1.9 mm/m^2 (z - 0.4 m)^2
   + 0.1 mm m^0.5 / sqrt(z) * theta^2 / (pi/2 - theta)^2``, with theta the incidence angle of
   step 4;
4. grazing-angle dropout: pixels whose surface normal is more than ``max_incidence_deg`` from
   the viewing ray are invalid. The normal is the cross product of the central differences of
   the back-projected lit points, evaluated in closed form (see :func:`incidence_angle`); a
   pixel whose four neighbours are not all lit and on its surface has none and is kept;
5. range limits: depths outside ``[min_range_m, max_range_m]`` are invalid.

(Steps 4 and 5 only remove pixels, so the implementation applies 4 before 3, which needs its
angle, and draws the noise of step 3 for the remaining pixels only.)

:class:`TimeOfFlight` (ICVL / MSRA Creative-camera style): flying pixels (a pixel next to a depth
edge larger than ``edge_threshold_m`` takes, with ``flying_pixel_prob``, a random blend of the
two surfaces), Gaussian axial noise ``sigma_m``, random dropouts (each valid pixel lost
independently with ``dropout_prob``; for small probabilities drawn as a binomial number of
losses at distinct uniformly chosen pixels, the same distribution), range limits.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import threading
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from handsim._validate import boolean, real_scalar, show
from handsim.errors import HandSimError, UnknownName
from handsim.world.camera import CameraIntrinsics

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

    The normal is the cross product of the central differences of the back-projected points
    along u and along v, evaluated in closed form (see :func:`_secant2_incidence`).

    Args:
        depth_m: (H, W) depth, metres, 0 = none.
        intrinsics: camera intrinsics.
        max_step: neighbours whose depth differs by more than this fraction of the depth lie
            on another surface (a depth edge, not a slope) and give no normal.

    Returns:
        (H, W) angle in radians; 0 where no normal can be estimated.
    """
    depth = np.ascontiguousarray(depth_m, dtype=np.float64)
    h, w = depth.shape
    if h < 3 or w < 3:
        return np.zeros((h, w))
    x = (np.arange(w) - intrinsics.cx) / intrinsics.fx
    y = ((np.arange(h) - intrinsics.cy) / intrinsics.fy)[:, None]
    x, y = np.broadcast_arrays(x, y)
    none, secant2 = _secant2_incidence(
        depth, intrinsics, x.copy(), y.copy(), 1.0 + x * x + y * y, max_step, _Scratch()
    )
    cos = np.minimum(np.sqrt(1.0 / secant2), 1.0)  # <= 1 but for rounding
    return np.where(none, 0.0, np.arccos(cos))


class _Scratch:
    """Reusable scratch arrays, by name and dtype, grown to the largest size asked for.

    Fresh large arrays cost page faults each call (the allocator hands freed memory back to
    the system); the noise models keep one of these per thread (:func:`_scratch`) and write
    their intermediate images into it. Arrays returned to callers are never taken from it.

    Attributes:
        capacity: smallest number of elements allocated (the image size), so that arrays of
            a varying length (one element per valid pixel) are not reallocated as it grows.
    """

    def __init__(self, capacity: int = 0) -> None:
        self.capacity = capacity
        self._arrays: dict[tuple[str, np.dtype], np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: type = np.float32) -> np.ndarray:
        """A C-contiguous array of that shape (contents undefined) named ``name``."""
        size = math.prod(shape)
        key = (name, np.dtype(dtype))
        array = self._arrays.get(key)
        if array is None or array.size < size:
            array = self._arrays[key] = np.empty(max(size, self.capacity), dtype=dtype)
        return array[:size].reshape(shape)


_THREAD_LOCAL = threading.local()


def _scratch(image_size: int) -> _Scratch:
    """This thread's scratch arrays, with a capacity of at least ``image_size`` elements."""
    scratch = getattr(_THREAD_LOCAL, "scratch", None)
    if scratch is None:
        scratch = _THREAD_LOCAL.scratch = _Scratch()
    scratch.capacity = max(scratch.capacity, image_size)
    return scratch


def _secant2_incidence(
    depth: np.ndarray,
    intrinsics: CameraIntrinsics,
    x: np.ndarray,
    y: np.ndarray,
    ray2: np.ndarray,
    max_step: float,
    scratch: _Scratch,
) -> tuple[np.ndarray, np.ndarray]:
    """``1 / cos^2`` of the incidence angle, from the four neighbours of each pixel.

    With ``P = z (x, y, 1)``, ``x = (u - cx) / fx``, ``y = (v - cy) / fy``, the central
    differences ``P(u+1) - P(u-1)`` and ``P(v+1) - P(v-1)`` have the cross product
    ``n ~ (-p, -q, 1 + x p + y q)`` with ``p = fx (z_r - z_l) / (z_r + z_l)`` and
    ``q = fy (z_d - z_u) / (z_d + z_u)``, and ``n . (x, y, 1) = 1``, so
    ``1 / cos^2 = |n|^2 (1 + x^2 + y^2)``: no 3-vectors are formed. The image is processed as
    one flat array (neighbours at offsets +-1 and +-W); the border pixels, whose flat
    neighbours wrap around, get no normal.

    Args:
        depth: (H, W) C-contiguous depth, 0 = none (float32 or float64; the result has its
            dtype), H and W >= 3.
        intrinsics: camera intrinsics.
        x: (H, W) normalised image x, C-contiguous, of the depth's dtype.
        y: (H, W) normalised image y, likewise.
        ray2: (H, W) ``1 + x^2 + y^2``, likewise.
        max_step: see :func:`incidence_angle`.
        scratch: where the intermediates and the results live.

    Returns:
        ``(none, secant2)``, (H, W): where no normal exists (a normal needs the pixel and its
        four neighbours to have depth and every neighbour to be within ``max_step`` of the
        pixel's depth), and ``1 / cos^2``, 1 where there is no normal.
    """
    h, w = depth.shape
    size, dtype = h * w, depth.dtype
    flat = depth.reshape(-1)
    inner = slice(w + 1, size - w - 1)
    centre = flat[inner]
    left, right = flat[w : size - w - 2], flat[w + 2 : size - w]
    up, down = flat[1 : size - 2 * w - 1], flat[2 * w + 1 : size - 1]
    none_image = scratch.get("no_normal", (h, w), np.bool_)
    secant2_image = scratch.get("secant2", (h, w), dtype)
    none, secant2 = none_image.reshape(-1)[inner], secant2_image.reshape(-1)[inner]
    n = centre.size
    near = scratch.get("near", (n,), dtype)
    far = scratch.get("far", (n,), dtype)
    tmp = scratch.get("tmp", (n,), dtype)
    q = scratch.get("q", (n,), dtype)
    test = scratch.get("test", (n,), np.bool_)
    # A normal needs |neighbour - centre| <= max_step centre for all four neighbours, and all
    # of them with depth: the nearest and the farthest are in the band, the nearest is > 0.
    np.minimum(np.minimum(left, right, out=near), np.minimum(up, down, out=tmp), out=near)
    np.maximum(np.maximum(left, right, out=far), np.maximum(up, down, out=tmp), out=far)
    np.less_equal(near, 0, out=none)
    none |= np.less(near, np.multiply(centre, 1.0 - max_step, out=tmp), out=test)
    none |= np.greater(far, np.multiply(centre, 1.0 + max_step, out=tmp), out=test)
    none_image[:, 0] = none_image[:, -1] = True  # flat neighbours wrap around the rows
    none_image[0] = none_image[-1] = True
    with np.errstate(divide="ignore", invalid="ignore"):
        p = _divide_scaled(
            np.subtract(right, left, out=secant2), np.add(right, left, out=tmp), intrinsics.fx
        )
        q = _divide_scaled(np.subtract(down, up, out=q), np.add(down, up, out=tmp), intrinsics.fy)
        n_z = np.multiply(x.reshape(-1)[inner], p, out=near)
        n_z += np.multiply(y.reshape(-1)[inner], q, out=tmp)
        n_z += 1.0
        np.square(p, out=secant2)
        secant2 += np.square(q, out=q)
        secant2 += np.square(n_z, out=n_z)
        secant2 *= ray2.reshape(-1)[inner]
    np.copyto(secant2_image, 1.0, where=none_image)
    return none_image, secant2_image


def _divide_scaled(numerator: np.ndarray, denominator: np.ndarray, scale: float) -> np.ndarray:
    """``scale * numerator / denominator`` into ``numerator`` (1-D), in one pass (cv2.divide)."""
    import cv2

    column = (-1, 1)  # OpenCV would read a short 1-D array as a scalar
    result = cv2.divide(
        numerator.reshape(column),
        denominator.reshape(column),
        dst=numerator.reshape(column),
        scale=scale,
    )
    if not np.shares_memory(result, numerator):
        numerator[...] = result.reshape(numerator.shape)
    return numerator


_NORMAL_MAX_STEP = 0.05
"""A neighbour more than this fraction of the depth away lies on another surface (no normal)."""


def _check_depth(
    depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: object = np.random.Generator
) -> np.ndarray:
    """The depth as float32 (the caller's array itself when it already is one: never write).

    ``intrinsics`` must be a :class:`CameraIntrinsics` and ``rng`` (when the model draws) a
    NumPy generator: a preset's name, a bare K or a missing generator are refused here.
    """
    if not isinstance(intrinsics, CameraIntrinsics):
        raise InvalidSensor(
            "intrinsics must be a CameraIntrinsics (e.g. camera_preset('icvl')), not a preset "
            f"name or a bare K; received {type(intrinsics).__name__}"
        )
    if rng is not np.random.Generator and not isinstance(rng, np.random.Generator):
        raise InvalidSensor(
            "rng must be a numpy.random.Generator (e.g. numpy.random.default_rng(0)): the noise "
            f"is drawn from it; received {type(rng).__name__}"
        )
    depth = np.asarray(depth_m)
    if depth.dtype.kind not in "iuf":
        raise InvalidSensor(f"depth must be real numbers in metres; received dtype {depth.dtype}")
    if depth.shape != (intrinsics.height, intrinsics.width):
        raise InvalidSensor(
            f"depth must have shape (H, W) = ({intrinsics.height}, {intrinsics.width}) to match "
            f"the camera; received {depth.shape}"
        )
    # min and max propagate NaN, so this also rejects NaN and +-inf.
    if not (depth.min() >= 0 and depth.max() < np.inf):
        raise InvalidSensor("depth must be finite and >= 0 m (0 = no measurement)")
    return np.ascontiguousarray(depth, dtype=np.float32)


# Sane upper bounds of the sensor parameters (beyond them a value is a mistake).
_UPPER = {
    "baseline_m": 10.0,
    "disparity_step_px": 100.0,
    "lateral_jitter_px": 100.0,
    "min_range_m": 1000.0,
    "max_range_m": 1000.0,
    "sigma_m": 10.0,
    "edge_threshold_m": 1000.0,
}


def _check_fields(model: object) -> None:
    """Type checks of a sensor dataclass: bool fields are bools, the others finite numbers."""
    for field in dataclasses.fields(model):  # type: ignore[arg-type]
        value = getattr(model, field.name)
        if isinstance(field.default, bool):
            boolean(field.name, value, InvalidSensor)
            continue
        real_scalar(field.name, value, InvalidSensor, hi=_UPPER.get(field.name, math.inf))
        object.__setattr__(model, field.name, float(value))


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
class _PixelGrid:
    """Per-camera constants (read-only arrays, cached by :func:`_pixel_grid`)."""

    x: np.ndarray  # (H, W) float32 (u - cx) / fx
    y: np.ndarray  # (H, W) float32 (v - cy) / fy
    ray2: np.ndarray  # (H, W) float32 1 + x^2 + y^2


@functools.lru_cache(maxsize=8)
def _pixel_grid(intrinsics: CameraIntrinsics) -> _PixelGrid:
    h, w = intrinsics.height, intrinsics.width
    v, u = np.indices((h, w), dtype=np.int16)
    x = ((u - intrinsics.cx) / intrinsics.fx).astype(np.float32)
    y = ((v - intrinsics.cy) / intrinsics.fy).astype(np.float32)
    grid = _PixelGrid(x=x, y=y, ray2=1.0 + x * x + y * y)
    for field in dataclasses.fields(grid):
        getattr(grid, field.name).setflags(write=False)
    return grid


_UNDECIDED = np.array([[-32768, -32768]], dtype=np.int16).view(np.int32)[0, 0]


def _jitter_reach(sigma: float, limit: int) -> int:
    """Largest displacement drawn: ``min(limit, ceil(10 s + 1/2))``, at least 1 (pixels)."""
    return max(1, min(int(limit), math.ceil(10.0 * sigma + 0.5)))


@functools.lru_cache(maxsize=16)
def _jitter_table(sigma: float, limit: int) -> tuple[np.ndarray, ...] | None:
    """Tables to draw a displacement pair ``(rint(N(0, s)), rint(N(0, s)))`` from random bytes.

    Each component is clamped to ``[-K, K]``, ``K = min(limit, ceil(10 s + 1/2))``: past
    ``limit`` the image clamps it anyway, and past 10 s lies 1e-23 of probability. The pairs are
    sorted by decreasing probability, and a uniform ``U`` picks the first pair whose cumulative
    probability exceeds it. ``U`` is drawn a byte at a time: a first byte ``c`` puts it in
    ``[c / 256, (c + 1) / 256)``, which decides the pair for most bytes; a second byte narrows
    it to 1/65536, and the rare remaining cases take a float64 uniform within that.

    Args:
        sigma: standard deviation, pixels.
        limit: largest useful displacement, pixels.

    Returns:
        ``(table, fine_table, cdf, pairs)`` or ``None`` when over a quarter of the first bytes
        would not decide (a wide jitter): table (256,) and fine_table (65536,) int32, the pair
        for each byte or byte pair (two int16 packed as the (..., 2) int16 layout of the
        offsets) or ``_UNDECIDED``; cdf, the cumulative probabilities; pairs, the packed pairs
        in that order.
    """
    k_max = _jitter_reach(sigma, limit)
    scale = 1.0 / (sigma * math.sqrt(2.0))
    below = [0.5 * math.erfc(-(j + 0.5) * scale) for j in range(-k_max, k_max)]
    p_axis = np.diff([0.0, *below, 1.0])  # P(k), k = -K..K, with the tails at +-K
    prob = np.outer(p_axis, p_axis).ravel()
    order = np.argsort(-prob, kind="stable")
    k = np.arange(-k_max, k_max + 1)
    du, dv = np.meshgrid(k, k, indexing="ij")
    pairs = np.stack([du.ravel(), dv.ravel()], axis=-1)[order].astype(np.int16)
    pairs = pairs.view(np.int32).ravel()
    cdf = np.cumsum(prob[order])[:-1]
    tables = []
    for cells in (256, 65536):
        bounds = np.arange(cells + 1) / cells
        first = np.searchsorted(cdf, bounds[:-1], side="right")  # cdf values <= c / cells
        last = np.searchsorted(cdf, bounds[1:], side="left")  # cdf values < (c + 1) / cells
        if cells == 256 and np.count_nonzero(first != last) > 64:
            return None
        tables.append(np.where(first == last, pairs[first], _UNDECIDED).astype(np.int32))
    for array in (*tables, cdf, pairs):
        array.setflags(write=False)
    return (*tables, cdf, pairs)


def _random_bytes(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` uniform random bytes (uint8) from the generator's raw 64-bit outputs.

    A quarter of the cost of ``rng.bytes`` (which draws 32-bit integers, then copies them twice).
    """
    return rng.bit_generator.random_raw((n + 7) // 8).view(np.uint8)[:n]


def _jitter_offsets(
    rng: np.random.Generator,
    sigma: float,
    out: np.ndarray,
    scratch: _Scratch,
    limit: int | None = None,
) -> np.ndarray:
    """Fill ``out`` with independent ``(rint(N(0, s)), rint(N(0, s)))`` displacement pairs.

    Exact in distribution (up to float64 and the clamp of :func:`_jitter_table`): one random
    byte per pixel through :func:`_jitter_table`, a second byte for the pixels (4 % at 0.5 px)
    whose first does not decide, and a float64 uniform for the few left; a wide jitter rounds
    Gaussian draws instead.

    Args:
        rng: random generator.
        sigma: standard deviation, pixels.
        out: (H, W, 2) C-contiguous int16, filled with (du, dv), each in ``[-K, K]``,
            ``K =`` :func:`_jitter_reach` ``(sigma, limit)``.
        scratch: scratch arrays.
        limit: largest useful displacement, pixels (the image's larger side); default
            ``max(H, W)``.

    Returns:
        ``out``.
    """
    h, w, _ = out.shape
    limit = max(h, w) if limit is None else int(limit)
    tables = _jitter_table(float(sigma), limit)
    if tables is None:
        normal = _standard_normal(rng, scratch.get("jitter", (out.size,)), scratch)
        normal *= np.float32(sigma)
        reach = _jitter_reach(float(sigma), limit)
        np.clip(np.rint(normal, out=normal), -reach, reach, out=normal)
        np.copyto(out.reshape(-1), normal, casting="unsafe")
        return out
    from handsim.world import _kernels

    table, fine_table, cdf, pairs = tables
    cells = _random_bytes(rng, h * w)
    flat = out.view(np.int32).reshape(-1)
    pending = scratch.get("pending", (h * w,), np.int64)
    pending = pending[: _kernels.jitter_lookup(cells, table, _UNDECIDED, flat, pending)]
    if pending.size:
        fine = cells[pending].astype(np.int32)
        fine <<= 8
        fine += _random_bytes(rng, pending.size)
        chosen = fine_table[fine]
        rare = np.flatnonzero(chosen == _UNDECIDED)
        if rare.size:
            uniform = (fine[rare] + rng.random(rare.size)) / 65536.0
            chosen[rare] = pairs[np.searchsorted(cdf, uniform, side="right")]
        flat[pending] = chosen
    return out


def _standard_normal(rng: np.random.Generator, out: np.ndarray, scratch: _Scratch) -> np.ndarray:
    """Fill the float32 vector ``out`` with N(0, 1) draws (Box-Muller).

    Pairs ``r cos(a)``, ``r sin(a)`` with ``r = sqrt(-2 ln(1 - U1))`` from a float64 uniform (so
    the tails reach 8.5 sigma) and ``a = 2 pi U2`` from a float32 one: about twice as fast as
    NumPy's float32 ziggurat here, and exactly Gaussian up to the floating-point resolution.
    """
    n = out.size
    half = (n + 1) // 2
    radius64 = rng.random(half, out=scratch.get("radius64", (half,), np.float64))
    np.log1p(np.negative(radius64, out=radius64), out=radius64)
    radius = np.multiply(radius64, -2.0, out=scratch.get("radius", (half,)))
    np.sqrt(radius, out=radius)
    angle = rng.random(half, dtype=np.float32, out=scratch.get("angle", (half,)))
    angle *= np.float32(2.0 * np.pi)
    np.multiply(np.cos(angle, out=out[:half]), radius, out=out[:half])
    rest = n - half
    np.multiply(np.sin(angle[:rest], out=out[half:]), radius[:rest], out=out[half:])
    return out


@dataclasses.dataclass(frozen=True)
class NoNoise:
    """The clean depth (a copy)."""

    def apply(
        self, depth_m: np.ndarray, intrinsics: CameraIntrinsics, rng: np.random.Generator
    ) -> np.ndarray:
        """Return a float32 copy of the clean depth."""
        return _check_depth(depth_m, intrinsics).copy()


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
        _check_fields(self)
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
        # cv2 and numba load on the first noisy frame, not on `import handsim`.
        import cv2

        from handsim.world import _kernels

        clean = _check_depth(depth_m, intrinsics, rng)
        # Only the box around the pixels with depth is processed (a hand alone covers a few
        # percent of the image): grown by the farthest jitter, every pixel that can get depth,
        # and by one more pixel, the neighbours of each (normals). Outside it no pixel can get
        # depth; pixels without depth cast no projector shadow and get no noise.
        # (OpenCV's bounding box of the nonzero mask: a third of the cost of numpy's any().)
        u, v, seen_w, seen_h = cv2.boundingRect(np.not_equal(clean, 0).view(np.uint8))
        full_h, full_w = clean.shape
        grid = _pixel_grid(intrinsics)
        scratch = _scratch(full_h * full_w)
        fb = np.float32(intrinsics.fx * self.baseline_m)
        if seen_w == 0:
            return np.zeros((full_h, full_w), dtype=np.float32)
        jitter = self.lateral_jitter_px > 0
        limit = max(full_h, full_w)
        reach = _jitter_reach(self.lateral_jitter_px, limit) if jitter else 0
        r0, r1 = max(v - reach - 1, 0), min(v + seen_h + reach + 1, full_h)
        c0, c1 = max(u - reach - 1, 0), min(u + seen_w + reach + 1, full_w)
        h, w = r1 - r0, c1 - c0
        offsets = scratch.get("offsets", (h, w, 2), np.int16)
        if jitter:
            # 1. Lateral jitter: rounded Gaussian displacements, drawn for the box's pixels only.
            _jitter_offsets(rng, self.lateral_jitter_px, offsets, scratch, limit)
        # 2 and 4, compiled: the jittered depth's lit pixels, less those seen at a grazing
        # angle; their flat index in the box, depth and 1 / cos^2 of the incidence.
        index = scratch.get("index", (h * w,), np.int64)
        z, secant2 = scratch.get("z", (h * w,)), scratch.get("secant2", (h * w,))
        max_secant2 = np.inf
        if self.max_incidence_deg < 90:
            max_secant2 = 1.0 / math.cos(math.radians(self.max_incidence_deg)) ** 2
        fx, fy = np.float32(intrinsics.fx), np.float32(intrinsics.fy)
        jittered = scratch.get("jittered", (h, w))
        n = _kernels.lit_pixels(
            clean, r0, c0, offsets, jitter, self.shadow, fb, fx, fy, grid.x, grid.y, grid.ray2,
            _NORMAL_MAX_STEP, np.float32(max_secant2), jittered, index, z, secant2,
        )  # fmt: skip
        # 3 and 5, compiled: disparity noise and quantization, range limits. Nguyen's formula
        # caps theta at 89 deg (as nguyen_sigma_z); lower limits have dropped those pixels.
        normal = _standard_normal(rng, scratch.get("normal", (n,)), scratch)
        max_theta = np.float32(np.deg2rad(89.0) if self.max_incidence_deg > 89 else np.inf)
        step = np.float32(self.disparity_step_px)
        min_m, max_m = np.float32(self.min_range_m), np.float32(self.max_range_m)
        out = np.zeros((full_h, full_w), dtype=np.float32)
        _kernels.disparity_noise(
            index[:n], z[:n], secant2[:n], normal, fb, step, max_theta, min_m, max_m, r0, c0, w, out
        )
        return out


# cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3)), without importing cv2 here.
_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=np.uint8)


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
        _check_fields(self)
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
        import cv2

        clean = _check_depth(depth_m, intrinsics, rng)
        h, w = clean.shape
        scratch = _scratch(h * w)
        valid = np.greater(clean, 0, out=scratch.get("valid", (h, w), np.bool_))
        n = int(np.count_nonzero(valid))
        depth = clean[valid]
        # Largest depth among the pixel and its 4 neighbours (the border repeats the edge pixel):
        # it exceeds the pixel's own depth by more than the threshold only at a depth edge, and
        # it is then the far surface's depth.
        far = cv2.dilate(
            clean, _CROSS, dst=scratch.get("far", (h, w)), borderType=cv2.BORDER_REPLICATE
        )
        far_valid = far[valid]
        far_valid -= depth
        edge_at = np.flatnonzero(far_valid > np.float32(self.edge_threshold_m))
        if edge_at.size:
            flying = edge_at[rng.random(edge_at.size) < self.flying_pixel_prob]
            mix = rng.random(flying.size).astype(np.float32)
            depth[flying] += mix * far_valid[flying]  # (1 - mix) near + mix far
        if self.sigma_m > 0:
            noise = _standard_normal(rng, scratch.get("tmp_n", (n,)), scratch)
            noise *= np.float32(self.sigma_m)
            depth += noise
        drop = scratch.get("drop", (n,), np.bool_)
        np.less(depth, self.min_range_m, out=drop)
        drop |= np.greater(depth, self.max_range_m, out=scratch.get("far", (n,), bool))
        if 0 < self.dropout_prob <= 0.1:
            # Independent losses: a binomial number of them at distinct uniform positions.
            drop[
                rng.choice(n, rng.binomial(n, self.dropout_prob), replace=False, shuffle=False)
            ] = True
        elif self.dropout_prob > 0:
            uniform = rng.random(n, dtype=np.float32, out=scratch.get("tmp_n", (n,)))
            drop |= np.less(uniform, self.dropout_prob, out=scratch.get("lost", (n,), bool))
        np.copyto(depth, 0.0, where=drop)
        out = np.zeros((h, w), dtype=np.float32)
        out[valid] = depth
        return out


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
        out = _check_depth(depth_m, intrinsics, rng).copy()
        for model in self.models:
            out = model.apply(out, intrinsics, rng)
        return out


_SENSOR_MODELS = {"none": NoNoise, "structured_light": StructuredLight, "tof": TimeOfFlight}


def sensor_model(name: str, **kwargs: object) -> SensorModel:
    """A sensor model by name: ``"none"``, ``"structured_light"`` or ``"tof"``.

    Raises:
        UnknownName: listing the valid names.
    """
    if not isinstance(name, str) or name not in _SENSOR_MODELS:
        raise UnknownName(
            f"unknown sensor model {show(name)}; valid models: {', '.join(_SENSOR_MODELS)}"
        )
    cls = _SENSOR_MODELS[name]
    valid = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(kwargs) - set(valid))
    if unknown:
        raise InvalidSensor(
            f"unknown parameter(s) {', '.join(unknown)} for sensor model {name!r}; valid: "
            f"{', '.join(valid) or 'none'}"
        )
    return cls(**kwargs)
