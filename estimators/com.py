"""Hand localization by the centre of mass of the nearest depth (DeepPrior's detector).

The localizer of DeepPrior / DeepPrior++ (Oberweger et al.; ``HandDetector`` and its
``refineCoMIterative``): the hand is found from depth alone, before any network runs, and the
fixed 3D cube that the learned estimators crop is centred on its output.

Algorithm, on one depth image (metres, 0 = no measurement):

1. measured pixels: depth in ``(0, max_depth_m]``;
2. ``z_min`` = the nearest measured depth; keep the pixels with depth in
   ``[z_min, z_min + cube]`` (``cube = cube_mm`` / 1000 m);
3. centre of mass: the mean pixel ``(u, v)`` of the kept pixels and their median depth ``z``,
   back-projected with ``K`` to the camera frame;
4. refinement, up to ``max_iterations`` times: keep the measured pixels whose back-projected
   point lies inside the axis-aligned cube of side ``cube`` centred on the current centre, and
   recompute step 3; stop when the centre moves less than 0.1 mm.

The estimate is ``Estimate(center_cam=...)`` without keypoints; ``Estimate(valid=False)`` when
fewer than ``min_pixels`` pixels are kept at any step.

What it estimates: the centre of the visible surface of whatever lies nearest, not the
:func:`~handsim.estimator.hand_center` of the keypoints. On a hand alone it differs from that by
a systematic offset of centimetres: the visible surface is in front of the joint centres (by
the palm's half thickness, 13.5 mm, for a hand facing the camera; by up to half the palm's
breadth for a hand seen edge-on), and the fingers and the forearm stub pull the image centroid
along the hand's axis. Measured on clean ICVL renders of the default hand alone, hand centre at
0.5 m: an open hand facing the camera 17-22 mm; 14 gestures x 6 random orientations, mean
(90th percentile) 53 (83) mm with the forearm stub and 30 (43) mm without, mostly a depth
offset (mean ``dz`` -33 and -25 mm); a fist with the forearm stub ~65 mm, as the forearm
outweighs the fist. The learned estimators regress the hand relative to this centre, so a
consistent offset costs them little; an inconsistent one (posture-dependent) they must absorb.

Assumption: **the hand is the nearest thing in view**, and nothing else lies within ``cube`` of
it. It breaks when a table, an object, the other hand or the user's body is nearer to the
camera than the hand (egocentric views of a hand on a table, a held object in front of the
fingers: the centre lands on the object), and it is biased when such a surface lies within the
cube around the hand (a hand resting on the table pulls the centre into the table plane).
Isolated noise pixels nearer than the hand also move ``z_min``; they make step 2 keep the wrong
slab only when they are more than ``cube`` in front of the hand.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from handsim._validate import is_real
from handsim.errors import InvalidEstimatorParams
from handsim.estimator import Estimate, EstimatorBase, validate_depth_input
from handsim.metrics import MM_PER_M

__all__ = ["CenterOfMassLocalizer"]

# The refinement has converged when the centre moves less than this, metres.
_CONVERGED_M = 1e-4


def _positive(name: str, value: Any) -> float:
    try:
        if not is_real(value):
            raise TypeError(name)
        v = float(value)
    except (TypeError, ValueError):
        raise InvalidEstimatorParams(f"{name} must be a number > 0; received {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise InvalidEstimatorParams(f"{name} must be a finite number > 0; received {value!r}")
    return v


def _positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise InvalidEstimatorParams(f"{name} must be an int >= 1; received {value!r}")
    if value > 10**9:
        raise InvalidEstimatorParams(f"{name} must be an int <= 10**9; received {value!r}")
    return int(value)


class CenterOfMassLocalizer(EstimatorBase):
    """Hand centre from the centre of mass of the nearest depth (module docstring).

    Stateless and pure NumPy.

    Args:
        cube_mm: side of the 3D cube around the hand, mm (DeepPrior: 250 mm on NYU / ICVL /
            MSRA, 300 mm for large hands).
        max_depth_m: depths beyond this are ignored, metres (DeepPrior's detector: 1.5 m).
        min_pixels: fewest pixels a hand may cover; fewer gives ``Estimate(valid=False)``.
        max_iterations: most refinement steps.

    Raises:
        InvalidEstimatorParams: for a non-positive or non-finite size or depth, or a count that
            is not an int >= 1.
    """

    def __init__(
        self,
        *,
        cube_mm: float = 250.0,
        max_depth_m: float = 1.5,
        min_pixels: int = 100,
        max_iterations: int = 10,
    ) -> None:
        self.cube_mm = _positive("cube_mm", cube_mm)
        self.max_depth_m = _positive("max_depth_m", max_depth_m)
        self.min_pixels = _positive_int("min_pixels", min_pixels)
        self.max_iterations = _positive_int("max_iterations", max_iterations)

    def __repr__(self) -> str:
        return (
            f"CenterOfMassLocalizer(cube_mm={self.cube_mm}, max_depth_m={self.max_depth_m}, "
            f"min_pixels={self.min_pixels}, max_iterations={self.max_iterations})"
        )

    def predict(self, depth: np.ndarray, K: np.ndarray) -> Estimate:  # noqa: N803
        """Localize the hand in one depth image.

        Args:
            depth: (H, W) float32 depth along the optical axis, metres, 0 = no measurement.
            K: (3, 3) intrinsic matrix.

        Returns:
            ``Estimate(center_cam=(3,) metres, camera frame)``, or ``Estimate(valid=False)``
            when fewer than ``min_pixels`` pixels are in range.

        Raises:
            InvalidEstimatorInput: on an invalid depth image or K.
        """
        depth_m, K_cv = validate_depth_input(depth, K)  # noqa: N806
        center_cam = self.localize(depth_m, K_cv)
        if center_cam is None:
            return Estimate(valid=False)
        return Estimate(center_cam=center_cam)

    def localize(self, depth_m: np.ndarray, K_cv: np.ndarray) -> np.ndarray | None:  # noqa: N803
        """The centre of mass, without input checks (call :meth:`predict` for checked input).

        Args:
            depth_m: (H, W) float32 depth, metres, 0 = no measurement.
            K_cv: (3, 3) float64 intrinsic matrix.

        Returns:
            (3,) float64 centre in the camera frame, metres, or ``None`` if too few pixels.
        """
        cube_m = self.cube_mm / MM_PER_M
        measured = (depth_m > 0) & (depth_m <= self.max_depth_m)
        uv = cv2.findNonZero(measured.view(np.uint8))  # row-major, as np.nonzero
        if uv is None or len(uv) < self.min_pixels:
            return None
        uv = uv.reshape(-1, 2)
        z32 = depth_m[uv[:, 1], uv[:, 0]]
        z_min = float(z32.min())
        keep = z32 <= z_min + cube_m
        u, v, z = uv[:, 0].astype(np.float64), uv[:, 1].astype(np.float64), z32.astype(np.float64)
        # Camera-frame points of the measured pixels: K^-1 (u, v, 1) z (handles skew too),
        # one coordinate array each: the cube test below runs on contiguous arrays in place.
        K_inv = np.linalg.inv(K_cv)  # noqa: N806
        x = (K_inv[0, 0] * u + K_inv[0, 1] * v + K_inv[0, 2]) * z
        y = (K_inv[1, 0] * u + K_inv[1, 1] * v + K_inv[1, 2]) * z
        center = self._centre_of_mass(u, v, z, keep, K_inv)
        half = cube_m / 2.0
        tmp, inside = np.empty_like(z), np.empty(len(z), dtype=bool)
        for _ in range(self.max_iterations):
            if center is None:
                return None
            for i, coord in enumerate((x, y, z)):  # keep: |p - center| <= half on every axis
                np.subtract(coord, center[i], out=tmp)
                np.abs(tmp, out=tmp)
                np.less_equal(tmp, half, out=keep if i == 0 else inside)
                if i:
                    keep &= inside
            new_center = self._centre_of_mass(u, v, z, keep, K_inv)
            if new_center is not None and np.linalg.norm(new_center - center) < _CONVERGED_M:
                return new_center
            center = new_center
        return center

    def _centre_of_mass(
        self,
        u: np.ndarray,
        v: np.ndarray,
        z: np.ndarray,
        keep: np.ndarray,
        K_inv: np.ndarray,  # noqa: N803
    ) -> np.ndarray | None:
        """Mean pixel and median depth of the kept pixels, back-projected (or None)."""
        if np.count_nonzero(keep) < self.min_pixels:
            return None
        pixel = np.array([u[keep].mean(), v[keep].mean(), 1.0])
        return K_inv @ pixel * _median(z[keep])


def _median(a: np.ndarray) -> float:
    """``np.median`` of a 1-D float array without NaN (its partition and mean, without checks)."""
    k = len(a) // 2
    if len(a) % 2:
        return float(np.partition(a, k)[k])
    part = np.partition(a, (k - 1, k))
    return float((part[k - 1] + part[k]) / 2.0)
