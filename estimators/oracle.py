"""An oracle estimator: the ground truth with configurable noise, bias, dropout and latency.

It answers "what does an estimator with X mm of error do to the task?" without training one.
It is a :class:`~handsim.estimator.PrivilegedEstimator`: the closed-loop wrapper calls
``observe_truth(frame)`` with the step's ground-truth :class:`~handsim.frame.record.Frame` and then
``predict(depth, K)``, whose depth is ignored. ``predict`` before any ``observe_truth`` of the
episode raises :class:`~handsim.errors.EstimatorStateError`.

Error model, per ``predict`` (all in the OpenCV camera frame, metres):

1. dropout: with probability ``dropout`` the estimate is ``Estimate(valid=False)``;
2. latency: the truth is the one observed ``latency_steps`` ``observe_truth`` calls ago; the
   first ``latency_steps`` steps of an episode repeat the episode's first truth;
3. keypoints: ``truth + n + bias`` with ``n ~ N(0, noise_mm^2)`` independently per keypoint and
   axis; the centre is :func:`~handsim.estimator.hand_center` of the noisy keypoints, so its
   noise std is ``noise_mm / sqrt(5)`` per axis (plus the bias);
4. objects (every instance of the truth): ``T_est = [R_n R_gt | t_gt + d]`` and ``R_n =
   exp(w)``, ``w ~ N(0, object_noise_deg^2)`` per camera axis (a rotation about the object
   origin). The translation error ``d`` depends on ``object_noise_kind``: ``"axis"`` (the
   default) draws ``N(0, object_noise_mm^2)`` independently per camera axis, so its 3-D length
   averages about 1.6 ``object_noise_mm`` (a chi distribution with 3 degrees of freedom);
   ``"3d"`` gives an error of exactly ``object_noise_mm`` in 3-D, in a uniformly random
   direction. The bias applies to the hand only.

Noise is drawn at ``predict`` time from the oracle's generator, in a fixed order (dropout,
keypoints, objects by instance), so two oracles with the same seed fed the same frames give
identical estimates. ``reset()`` clears the latency buffer and the truth but keeps the generator
running (episodes differ; reseed by building a new oracle).
"""

from __future__ import annotations

import collections
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from handsim._validate import is_real
from handsim.errors import EstimatorStateError, InvalidEstimatorInput, InvalidEstimatorParams
from handsim.estimator import N_KEYPOINTS, Estimate, EstimatorBase, validate_depth_input
from handsim.metrics import MM_PER_M

if TYPE_CHECKING:
    from handsim.frame import Frame

__all__ = ["OracleEstimator"]

OBJECT_NOISE_KINDS: tuple[str, ...] = ("axis", "3d")
"""How ``OracleEstimator.object_noise_mm`` is read: a std per camera axis, or an exact 3-D
error."""


def _non_negative(name: str, value: Any) -> float:
    try:
        if not is_real(value):
            raise TypeError(name)
        v = float(value)
    except (TypeError, ValueError):
        raise InvalidEstimatorParams(f"{name} must be a number >= 0; received {value!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise InvalidEstimatorParams(f"{name} must be a finite number >= 0; received {value!r}")
    return v


MAX_NOISE_MM = 1000.0
"""Largest noise (std) accepted, mm: a metre per axis already puts the estimate off any hand
and object (1e300 mm overflowed into a NaN wrist)."""


def _noise_mm(name: str, value: Any) -> float:
    v = _non_negative(name, value)
    if v > MAX_NOISE_MM:
        raise InvalidEstimatorParams(
            f"{name} must be at most {MAX_NOISE_MM:g} mm (a std per axis); received {value!r}"
        )
    return v


class OracleEstimator(EstimatorBase):
    """The ground truth of the last observed frame, perturbed (see the module docstring).

    Args:
        noise_mm: std of the Gaussian keypoint noise per axis, mm (0 to 1000).
        bias_mm: (3,) constant offset added to every keypoint, camera frame, mm.
        dropout: probability of ``Estimate(valid=False)`` per ``predict``, in [0, 1].
        latency_steps: delay of the returned truth, in ``observe_truth`` calls (int >= 0).
        object_noise_mm: object translation noise, mm (0 to 1000): the std per camera axis
            (``object_noise_kind="axis"``) or the exact 3-D error (``"3d"``).
        object_noise_deg: std of each rotation-vector component of the object rotation noise,
            degrees (>= 0).
        rng: a ``numpy.random.Generator``, or an int seed; ``None`` seeds from OS entropy.
        object_noise_kind: ``"axis"`` or ``"3d"`` (see ``object_noise_mm``).

    Raises:
        InvalidEstimatorParams: for a negative or non-finite noise, a bias that is not 3
            finite numbers, a dropout outside [0, 1], a latency that is not an int >= 0, or an
            rng that is neither a Generator, an int nor ``None``, or an unknown
            ``object_noise_kind``.
    """

    def __init__(
        self,
        *,
        noise_mm: float = 0.0,
        bias_mm: tuple[float, float, float] = (0.0, 0.0, 0.0),
        dropout: float = 0.0,
        latency_steps: int = 0,
        object_noise_mm: float = 0.0,
        object_noise_deg: float = 0.0,
        rng: np.random.Generator | int | None = None,
        object_noise_kind: str = "axis",
    ) -> None:
        self.noise_mm = _noise_mm("noise_mm", noise_mm)
        try:
            bias = np.array(bias_mm)
            bias = bias.astype(np.float64) if bias.dtype.kind in "iuf" else np.full(0, np.nan)
        except (TypeError, ValueError):
            bias = np.full(0, np.nan)
        if bias.shape != (3,) or not np.all(np.isfinite(bias)):
            raise InvalidEstimatorParams(
                f"bias_mm must be 3 finite numbers (x, y, z in the camera frame, mm); received "
                f"{bias_mm!r}"
            )
        bias.setflags(write=False)
        self.bias_mm = bias
        self.dropout = _non_negative("dropout", dropout)
        if self.dropout > 1:
            raise InvalidEstimatorParams(
                f"dropout is a probability and must lie in [0, 1]; received {dropout!r}"
            )
        if (
            isinstance(latency_steps, bool)
            or not isinstance(latency_steps, int | np.integer)
            or latency_steps < 0
        ):
            raise InvalidEstimatorParams(
                f"latency_steps must be an int >= 0 (steps of delay); received {latency_steps!r}"
            )
        if latency_steps > 10_000:
            raise InvalidEstimatorParams(
                f"latency_steps must be at most 10000 steps; received {latency_steps!r}"
            )
        self.latency_steps = int(latency_steps)
        self.object_noise_mm = _noise_mm("object_noise_mm", object_noise_mm)
        self.object_noise_deg = _non_negative("object_noise_deg", object_noise_deg)
        if object_noise_kind not in OBJECT_NOISE_KINDS:
            raise InvalidEstimatorParams(
                f"object_noise_kind must be one of {OBJECT_NOISE_KINDS} (a std per camera axis, "
                f"or an exact 3-D error); received {object_noise_kind!r}"
            )
        self.object_noise_kind = object_noise_kind
        if isinstance(rng, int | np.integer) and not isinstance(rng, bool) and rng < 0:
            raise InvalidEstimatorParams(f"rng must be a seed >= 0 when an int; received {rng!r}")
        if rng is None or (isinstance(rng, int | np.integer) and not isinstance(rng, bool)):
            rng = np.random.default_rng(rng)
        if not isinstance(rng, np.random.Generator):
            raise InvalidEstimatorParams(
                f"rng must be a numpy.random.Generator, an int seed or None; received "
                f"{type(rng).__name__}"
            )
        self.rng = rng
        # (keypoints_cam (21, 3), {instance: T_cam_from_obj}) of the last latency + 1 truths.
        self._truths: collections.deque[tuple[np.ndarray, dict[int, np.ndarray]]]
        self._truths = collections.deque(maxlen=self.latency_steps + 1)

    def __repr__(self) -> str:
        return (
            f"OracleEstimator(noise_mm={self.noise_mm}, bias_mm={tuple(self.bias_mm.tolist())}, "
            f"dropout={self.dropout}, latency_steps={self.latency_steps}, "
            f"object_noise_mm={self.object_noise_mm}, object_noise_deg={self.object_noise_deg}, "
            f"object_noise_kind={self.object_noise_kind!r})"
        )

    def reset(self) -> None:
        """Start a new episode: forget the observed truths; the generator keeps running."""
        self._truths.clear()

    def observe_truth(self, frame: Frame) -> None:
        """Receive this step's ground truth (the closed-loop wrapper calls it before predict).

        Args:
            frame: the ground-truth frame; its ``keypoints_cam`` and ``objects`` are copied.

        Raises:
            InvalidEstimatorInput: if ``frame`` has no (21, 3) ``keypoints_cam``.
        """
        kp = np.array(getattr(frame, "keypoints_cam", None), dtype=np.float64)
        if kp.shape != (N_KEYPOINTS, 3) or not np.all(np.isfinite(kp)):
            raise InvalidEstimatorInput(
                f"observe_truth expects a handsim Frame with finite ({N_KEYPOINTS}, 3) "
                f"keypoints_cam; received {type(frame).__name__} with keypoints of shape "
                f"{kp.shape}"
            )
        poses = {
            int(label.instance): np.array(label.T_cam_from_obj, dtype=np.float64)
            for label in getattr(frame, "objects", ())
        }
        self._truths.append((kp, poses))

    def predict(self, depth: np.ndarray, K: np.ndarray) -> Estimate:  # noqa: N803
        """The delayed, perturbed truth (``depth`` and ``K`` are checked, then ignored).

        Args:
            depth: (H, W) float32 depth, metres, 0 = no measurement (unused).
            K: (3, 3) intrinsic matrix (unused).

        Returns:
            The estimate: keypoints, centre and every object's pose, or
            ``Estimate(valid=False)`` on dropout.

        Raises:
            EstimatorStateError: if no truth was observed since the last ``reset`` (or ever).
            InvalidEstimatorInput: on an invalid depth image or K.
        """
        validate_depth_input(depth, K)
        if not self._truths:
            raise EstimatorStateError(
                "OracleEstimator.predict needs the ground truth: call observe_truth(frame) "
                "before predict on each step (the closed-loop wrapper does this for any "
                "PrivilegedEstimator); no truth has been observed since the last reset"
            )
        # Until latency + 1 truths are buffered, element 0 is the episode's first truth.
        truth_kp, truth_poses = self._truths[0]
        rng = self.rng
        if rng.random() < self.dropout:
            return Estimate(valid=False)
        noise_m = rng.normal(0.0, self.noise_mm / MM_PER_M, size=(N_KEYPOINTS, 3))
        keypoints = truth_kp + noise_m + self.bias_mm / MM_PER_M
        poses = {}
        rot_std_rad = math.radians(self.object_noise_deg)
        for instance in sorted(truth_poses):
            T = truth_poses[instance].copy()  # noqa: N806 (the standard name of a transform)
            if self.object_noise_kind == "axis":
                T[:3, 3] += rng.normal(0.0, self.object_noise_mm / MM_PER_M, size=3)
            else:
                direction = rng.normal(size=3)
                T[:3, 3] += self.object_noise_mm / MM_PER_M * direction / np.linalg.norm(direction)
            rotvec = rng.normal(0.0, rot_std_rad, size=3)
            # scipy.spatial loads here, not with the module: the CLI imports this module.
            from scipy.spatial.transform import Rotation

            T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix() @ T[:3, :3]
            poses[instance] = T
        return Estimate(keypoints_cam=keypoints, object_poses=poses)

    def predict_batch(self, depths: np.ndarray, Ks: np.ndarray) -> list[Estimate]:  # noqa: N803
        """One-element batches only: the oracle follows one stream of truths.

        Args:
            depths: (1, H, W) float32 depth, metres.
            Ks: (1, 3, 3) intrinsic matrix.

        Returns:
            A list with the one estimate of :meth:`predict`.

        Raises:
            EstimatorStateError: for a batch of more than one frame (use one oracle per env)
                or before any ``observe_truth``.
            InvalidEstimatorInput: on an invalid batch.
        """
        depths_arr = np.asarray(depths)
        if depths_arr.ndim == 3 and depths_arr.shape[0] != 1:
            raise EstimatorStateError(
                f"OracleEstimator follows one stream of truths and predicts batches of 1; "
                f"received a batch of {depths_arr.shape[0]} (use one oracle per environment)"
            )
        return super().predict_batch(depths, Ks)
