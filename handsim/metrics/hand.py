"""Hand keypoint metrics, Dexter+Object hand-object errors and error breakdowns.

Hand keypoints (canonical order of :data:`handsim.hand.keypoints.KEYPOINT_NAMES`; any ``J`` works)
------------------------------------------------------------------------------------------------
- Joint error: the 3D Euclidean distance between a predicted and a ground-truth keypoint.
- ``visible`` (optional, ``(N, J)`` bool): joints marked ``False`` are not evaluated; they may
  hold non-finite values and appear as NaN in per-joint error arrays. A frame with no evaluated
  joint gets a NaN frame error and is left out of every frame statistic (also out of the
  denominator of F(tau)); at least one joint of the set must be evaluated. (DeepPrior++'s
  ``handpose_evaluation.py``, which masks with NaN too, would count such a frame as a failure
  of F(tau).)
- Frame errors: the mean and the max over the evaluated joints of a frame.
- Mean and median error of a set: over all evaluated (frame, joint) pairs, pooled (the median is
  DeepPrior++'s ``getMedianError``). Without a mask the mean equals DeepPrior++'s
  ``getMeanError``; with one, ``getMeanError`` averages per-frame means instead (a frame with
  few visible joints weighs as much as a full one) and differs.
- F(tau): the fraction of evaluated frames whose MAX joint error is ``<= tau`` (inclusive), the
  "worst-case accuracy" of Taylor et al. 2012 (Vitruvian Manifold) and the "fraction of frames
  within distance" curve of Oberweger's thesis; DeepPrior++ ``getNumFramesWithinMaxDist`` uses
  ``<=`` too.
- PCK(tau): the fraction of all evaluated joints (pooled over frames and joints) with error
  ``<= tau``. Zimmermann & Brox 2017 average per-keypoint PCKs instead; the two agree when
  every joint is evaluated in every frame.
- Curves are sampled on the grid ``tau = 0, 1, ..., 80`` mm (:func:`threshold_grid_mm`;
  ``tau_max_mm`` and ``step_mm`` can be changed). AUC = trapezoid rule on that grid divided by
  the grid's span (Zimmermann & Brox ``calc_auc``: ``trapz(y, x) / trapz(1, x)``), in
  ``[0, 1]``. On a step curve the trapezoid rule counts an error ``e`` in ``(k h, (k+1) h]``
  (grid step ``h``) as if it were ``(k + 1/2) h``; e.g. frame max errors of 10 and 30.5 mm give
  an F(tau) AUC over 0-80 mm of ``((80 - 9.5) + (80 - 30.5)) / (2 * 80) = 0.75``.
- Per-frame error arrays accept ``+inf`` as "no estimate": such a frame fails at every tau.

Dexter+Object (D+O) hand-object error
-------------------------------------
The D+O dataset (Sridhar et al., "Real-time Joint Tracking of a Hand Manipulating an Object
from RGB-D Input", ECCV 2016) annotates the 5 fingertips and corners of the manipulated cuboid
(3 corners in the annotations that Oberweger et al. released with the generalized feedback
loop, TPAMI 2019: "21 hand joints (tips are index 4, 8, 12, 16, 20) and 3 object corners").
What :func:`dexter_object_errors_mm` implements, per frame:

- hand error = mean 3D error over the 5 fingertips (keypoints 4, 8, 12, 16, 20), as the
  Dexter 1 benchmark defines its fingertip error ("the average Euclidean distance of all
  estimated 3D fingertip locations from the 5 ground truth 3D positions");
- object error = mean 3D error over the ``K`` given box corners (``K = 3`` on D+O; a handsim
  object has 8, :attr:`handsim.world.YCBObject.corners_m`);
- combined error = mean over all ``5 + K`` per-point errors, every point weighted equally, i.e.
  ``(5 * hand + K * object) / (5 + K)``.

The paper's exact pooling of the combined number was not verified here; the hand and object
parts are returned separately, so the equal-weight alternative ``(hand + object) / 2`` can be
formed from them. RGB hand-only methods (Zimmermann & Brox 2017, Mueller et al. 2018) report only
the fingertip PCK AUC on D+O.

Breakdowns
----------
- Occlusion buckets (:func:`errors_by_occlusion`): given bucket edges ``e_0 < ... < e_B`` in
  ``[0, 1]`` (default ``0, 0.2, 0.4, 0.6, 0.8, 1.0``), bucket ``b`` holds the frames with
  ``e_b <= occlusion < e_{b+1}``; the last bucket is closed (``occlusion == e_B`` is in it).
  NaN / ``+inf`` / ``None`` errors are misses: counted in ``n_missed``, left out of the
  statistics.
- Per joint (:func:`errors_by_joint`): statistics of each joint's evaluated errors.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.metrics._common import (
    DEFAULT_OCCLUSION_EDGES,
    FINGERTIP_INDICES,
    MM_PER_M,
    TAU_MAX_MM,
    TAU_STEP_MM,
    InvalidMetricInput,
    _array,
    _check_error_values,
    _check_finite_at,
    _errors_with_misses,
    _frame_errors,
    _point_pairs,
    _positive,
    _thresholds,
    _visible_mask,
)

# Hand keypoints ----------------------------------------------------------------------------------


def keypoint_errors_mm(pred_m: Any, gt_m: Any, visible: Any = None) -> np.ndarray:
    """3D error of every keypoint.

    Args:
        pred_m: (N, J, 3) predicted keypoints, metres, any common frame (camera frame).
        gt_m: (N, J, 3) ground-truth keypoints, metres, same frame and order.
        visible: optional (N, J) bool mask; ``False`` joints are not evaluated (and may hold
            non-finite values).

    Returns:
        (N, J) float64 Euclidean errors, mm; NaN where not evaluated.

    Raises:
        InvalidMetricInput: on a shape mismatch, an empty set or a non-finite evaluated value.
    """
    pred, gt = _point_pairs("pred_m", pred_m, "gt_m", gt_m)
    mask = _visible_mask(visible, pred.shape[:2])
    _check_finite_at("pred_m", pred, mask)
    _check_finite_at("gt_m", gt, mask)
    # Masked joints may hold NaN / inf: zero them before subtracting (no invalid-value warning).
    m = mask[..., None]
    errors = np.linalg.norm(np.where(m, pred, 0.0) - np.where(m, gt, 0.0), axis=-1) * MM_PER_M
    errors[~mask] = np.nan
    return errors


def _frame_reduce(errors_mm: np.ndarray, reduce: str) -> np.ndarray:
    evaluated = ~np.isnan(errors_mm)
    out = np.full(errors_mm.shape[0], np.nan)
    rows = np.any(evaluated, axis=1)
    if np.any(rows):
        fn = np.nanmean if reduce == "mean" else np.nanmax
        out[rows] = fn(errors_mm[rows], axis=1)
    return out


def frame_mean_error_mm(pred_m: Any, gt_m: Any, visible: Any = None) -> np.ndarray:
    """Mean 3D keypoint error of each frame.

    Args:
        pred_m: (N, J, 3) predicted keypoints, metres.
        gt_m: (N, J, 3) ground-truth keypoints, metres.
        visible: optional (N, J) bool mask of the evaluated joints.

    Returns:
        (N,) float64 mean over the evaluated joints, mm; NaN for a frame without one.

    Raises:
        InvalidMetricInput: as :func:`keypoint_errors_mm`.
    """
    return _frame_reduce(keypoint_errors_mm(pred_m, gt_m, visible), "mean")


def frame_max_error_mm(pred_m: Any, gt_m: Any, visible: Any = None) -> np.ndarray:
    """Largest 3D keypoint error of each frame (the quantity behind F(tau)).

    Args:
        pred_m: (N, J, 3) predicted keypoints, metres.
        gt_m: (N, J, 3) ground-truth keypoints, metres.
        visible: optional (N, J) bool mask of the evaluated joints.

    Returns:
        (N,) float64 max over the evaluated joints, mm; NaN for a frame without one.

    Raises:
        InvalidMetricInput: as :func:`keypoint_errors_mm`.
    """
    return _frame_reduce(keypoint_errors_mm(pred_m, gt_m, visible), "max")


MAX_TAU_MM = 10_000.0
"""Largest threshold of the hand curves, mm (10 m)."""

MAX_THRESHOLDS = 100_000
"""Most thresholds in a curve (so a tiny ``step_mm`` cannot allocate gigabytes)."""


def threshold_grid_mm(tau_max_mm: float = TAU_MAX_MM, step_mm: float = TAU_STEP_MM) -> np.ndarray:
    """The uniform threshold grid ``0, step, ..., tau_max`` of the hand curves.

    Args:
        tau_max_mm: last threshold, mm (> 0, a whole multiple of ``step_mm``).
        step_mm: spacing, mm (> 0).

    Returns:
        (T,) float64 thresholds, mm, ``T = tau_max / step + 1`` (81 by default).

    Raises:
        InvalidMetricInput: if a value is not positive or ``tau_max_mm`` is not a multiple of
            ``step_mm``.
    """
    tau_max = _positive("tau_max_mm", tau_max_mm)
    step = _positive("step_mm", step_mm)
    if tau_max > MAX_TAU_MM:
        raise InvalidMetricInput(
            f"tau_max_mm must be <= {MAX_TAU_MM:g} mm; received {tau_max_mm!r}"
        )
    n = tau_max / step
    if n > MAX_THRESHOLDS:
        raise InvalidMetricInput(
            f"tau_max_mm / step_mm must be at most {MAX_THRESHOLDS} thresholds; received "
            f"tau_max_mm={tau_max_mm!r}, step_mm={step_mm!r} ({n:.3g} thresholds)"
        )
    if abs(n - round(n)) > 1e-9 * max(1.0, n):
        raise InvalidMetricInput(
            f"tau_max_mm must be a whole multiple of step_mm; received tau_max_mm={tau_max_mm}, "
            f"step_mm={step_mm}"
        )
    return np.linspace(0.0, tau_max, int(round(n)) + 1)


def fraction_of_frames_within(frame_max_errors_mm: Any, thresholds_mm: Any) -> np.ndarray:
    """F(tau): the fraction of frames whose largest joint error is ``<= tau``.

    Args:
        frame_max_errors_mm: (N,) per-frame max joint errors, mm (:func:`frame_max_error_mm`);
            NaN frames (no evaluated joint) are left out, ``+inf`` (no estimate) fails every
            threshold.
        thresholds_mm: (T,) thresholds ``tau``, mm, ``>= 0``.

    Returns:
        (T,) float64 fractions in [0, 1].

    Raises:
        InvalidMetricInput: on a negative or non-finite threshold, a negative error or no
            evaluated frame.
    """
    e = _frame_errors("frame_max_errors_mm", frame_max_errors_mm)
    t = _thresholds("thresholds_mm", thresholds_mm)
    e = e[~np.isnan(e)]
    return np.mean(e[None, :] <= t[:, None], axis=1)


def pck(joint_errors_mm: Any, thresholds_mm: Any) -> np.ndarray:
    """PCK(tau): the fraction of all evaluated joints with error ``<= tau``.

    Args:
        joint_errors_mm: per-joint errors, mm, any shape (e.g. (N, J) from
            :func:`keypoint_errors_mm`), pooled; NaN = not evaluated, ``+inf`` = no estimate.
        thresholds_mm: (T,) thresholds, mm, ``>= 0``.

    Returns:
        (T,) float64 fractions in [0, 1].

    Raises:
        InvalidMetricInput: on a negative threshold or error, or no evaluated joint.
    """
    e = _array("joint_errors_mm", joint_errors_mm).ravel()
    _check_error_values("joint_errors_mm", e)
    e = e[~np.isnan(e)]
    if e.size == 0:
        raise InvalidMetricInput(
            "joint_errors_mm must hold at least one evaluated (non-NaN) joint; received none"
        )
    t = _thresholds("thresholds_mm", thresholds_mm)
    return np.mean(e[None, :] <= t[:, None], axis=1)


def curve_auc(thresholds: Any, values: Any) -> float:
    """Area under a curve by the trapezoid rule, divided by the threshold span.

    Args:
        thresholds: (T,) strictly increasing thresholds (any unit), ``T >= 2``.
        values: (T,) finite curve values at the thresholds (fractions for F(tau) / PCK).

    Returns:
        ``trapz(values, thresholds) / (thresholds[-1] - thresholds[0])``; in [0, 1] for
        fractions.

    Raises:
        InvalidMetricInput: on mismatched lengths, fewer than 2 points, a non-increasing grid or
            a non-finite value.
    """
    x = _array("thresholds", thresholds)
    y = _array("values", values)
    if x.ndim != 1 or y.shape != x.shape or x.size < 2:
        raise InvalidMetricInput(
            f"thresholds and values must be 1-D of the same length >= 2; received shapes "
            f"{x.shape} and {y.shape}"
        )
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise InvalidMetricInput("thresholds and values must be finite; received a NaN or inf")
    if np.any(np.diff(x) <= 0):
        raise InvalidMetricInput(f"thresholds must be strictly increasing; received {x.tolist()}")
    area = float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))
    return area / float(x[-1] - x[0])


def _joint_names(n_joints: int, joint_names: Sequence[str] | None) -> tuple[str, ...]:
    if joint_names is None:
        if n_joints == len(KEYPOINT_NAMES):
            return tuple(KEYPOINT_NAMES)
        return tuple(f"joint_{k}" for k in range(n_joints))
    names = tuple(str(n) for n in joint_names)
    if len(names) != n_joints or len(set(names)) != n_joints:
        raise InvalidMetricInput(
            f"joint_names must be {n_joints} distinct names (one per joint); received "
            f"{len(names)} names, {len(set(names))} distinct"
        )
    return names


@dataclasses.dataclass(frozen=True)
class HandPoseReport:
    """Hand keypoint metrics of a set of frames (JSON-serializable; see the module docstring).

    Attributes:
        n_frames: frames in the set.
        n_frames_evaluated: frames with at least one evaluated joint (the F(tau) denominator).
        n_joints_evaluated: evaluated (frame, joint) pairs (the PCK denominator).
        mean_mm: mean joint error over all evaluated joints, mm.
        median_mm: median joint error over all evaluated joints, mm.
        mean_max_mm: mean over evaluated frames of the per-frame max error, mm.
        per_joint_mean_mm: joint name -> mean error of that joint, mm (``None`` if never
            evaluated).
        thresholds_mm: the tau grid, mm.
        f_tau: F(tau) on the grid (fraction of frames with max error <= tau).
        pck: PCK(tau) on the grid (fraction of joints with error <= tau).
        auc_f_tau: trapezoid AUC of F(tau) over the grid, in [0, 1].
        auc_pck: trapezoid AUC of PCK(tau) over the grid, in [0, 1].
    """

    n_frames: int
    n_frames_evaluated: int
    n_joints_evaluated: int
    mean_mm: float
    median_mm: float
    mean_max_mm: float
    per_joint_mean_mm: dict[str, float | None]
    thresholds_mm: list[float]
    f_tau: list[float]
    pck: list[float]
    auc_f_tau: float
    auc_pck: float

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serializable dict of every field."""
        return dataclasses.asdict(self)


def evaluate_hand_poses(
    pred_m: Any,
    gt_m: Any,
    *,
    visible: Any = None,
    joint_names: Sequence[str] | None = None,
    tau_max_mm: float = TAU_MAX_MM,
    step_mm: float = TAU_STEP_MM,
) -> HandPoseReport:
    """Every hand keypoint metric of a set of frames.

    Args:
        pred_m: (N, J, 3) predicted keypoints, metres.
        gt_m: (N, J, 3) ground-truth keypoints, metres.
        visible: optional (N, J) bool mask of the evaluated joints.
        joint_names: J names for ``per_joint_mean_mm``; default
            :data:`~handsim.hand.keypoints.KEYPOINT_NAMES` when ``J == 21``, else ``joint_<k>``.
        tau_max_mm: last threshold of the curves and the AUC, mm.
        step_mm: threshold spacing, mm.

    Returns:
        The :class:`HandPoseReport`.

    Raises:
        InvalidMetricInput: on bad keypoints, mask, names or grid, or when no joint is
            evaluated.
    """
    errors = keypoint_errors_mm(pred_m, gt_m, visible)
    names = _joint_names(errors.shape[1], joint_names)
    taus = threshold_grid_mm(tau_max_mm, step_mm)
    evaluated = errors[~np.isnan(errors)]
    if evaluated.size == 0:
        raise InvalidMetricInput(
            "no joint is evaluated: `visible` is False everywhere; expected at least one True"
        )
    frame_max = _frame_reduce(errors, "max")
    f_tau = fraction_of_frames_within(frame_max, taus)
    pck_curve = pck(errors, taus)
    per_joint = errors_by_joint(errors, names)
    return HandPoseReport(
        n_frames=int(errors.shape[0]),
        n_frames_evaluated=int(np.sum(~np.isnan(frame_max))),
        n_joints_evaluated=int(evaluated.size),
        mean_mm=float(np.mean(evaluated)),
        median_mm=float(np.median(evaluated)),
        mean_max_mm=float(np.nanmean(frame_max)),
        per_joint_mean_mm={name: stats.mean_mm for name, stats in per_joint.items()},
        thresholds_mm=[float(t) for t in taus],
        f_tau=[float(v) for v in f_tau],
        pck=[float(v) for v in pck_curve],
        auc_f_tau=curve_auc(taus, f_tau),
        auc_pck=curve_auc(taus, pck_curve),
    )


# Dexter+Object ---------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class HandObjectErrors:
    """Per-frame Dexter+Object errors (see the module docstring for the definition).

    Attributes:
        hand_mm: (N,) mean error over the 5 fingertips, mm.
        object_mm: (N,) mean error over the K object corners, mm.
        combined_mm: (N,) mean over all 5 + K point errors, mm.
    """

    hand_mm: np.ndarray
    object_mm: np.ndarray
    combined_mm: np.ndarray


def _fingertips(name: str, keypoints: np.ndarray) -> np.ndarray:
    if keypoints.shape[1] == len(KEYPOINT_NAMES):
        return keypoints[:, list(FINGERTIP_INDICES)]
    if keypoints.shape[1] == len(FINGERTIP_INDICES):
        return keypoints
    raise InvalidMetricInput(
        f"{name} must hold 21 canonical keypoints or the 5 fingertips (N, 21 or 5, 3); "
        f"received shape {keypoints.shape}"
    )


def dexter_object_errors_mm(
    pred_hand_m: Any, gt_hand_m: Any, pred_corners_m: Any, gt_corners_m: Any
) -> HandObjectErrors:
    """Per-frame Dexter+Object hand, object and combined errors.

    Args:
        pred_hand_m: (N, 21, 3) predicted canonical keypoints (fingertips 4, 8, 12, 16, 20 are
            used) or (N, 5, 3) fingertips (thumb to little), metres.
        gt_hand_m: ground truth of the same shape, metres.
        pred_corners_m: (N, K, 3) predicted object box corners, metres (K = 3 on D+O, 8 for a
            handsim object: :func:`transform_points` of ``obj.corners_m``).
        gt_corners_m: (N, K, 3) ground-truth corners, same order, metres.

    Returns:
        The :class:`HandObjectErrors`: hand = mean over the 5 fingertips, object = mean over
        the K corners, combined = mean over all 5 + K point errors, all mm.

    Raises:
        InvalidMetricInput: on a shape mismatch, a frame-count mismatch or a non-finite value.
    """
    hand_p, hand_g = _point_pairs("pred_hand_m", pred_hand_m, "gt_hand_m", gt_hand_m)
    tips_p = _fingertips("pred_hand_m", hand_p)
    tips_g = _fingertips("gt_hand_m", hand_g)
    corners_p, corners_g = _point_pairs(
        "pred_corners_m", pred_corners_m, "gt_corners_m", gt_corners_m
    )
    if corners_p.shape[0] != tips_p.shape[0]:
        raise InvalidMetricInput(
            f"the hand and corner arrays must have the same number of frames; received "
            f"{tips_p.shape[0]} and {corners_p.shape[0]}"
        )
    tip_err = keypoint_errors_mm(tips_p, tips_g)
    corner_err = keypoint_errors_mm(corners_p, corners_g)
    both = np.concatenate([tip_err, corner_err], axis=1)
    return HandObjectErrors(
        hand_mm=tip_err.mean(axis=1),
        object_mm=corner_err.mean(axis=1),
        combined_mm=both.mean(axis=1),
    )


@dataclasses.dataclass(frozen=True)
class DexterObjectReport:
    """Dexter+Object metrics of a set of frames (JSON-serializable).

    Attributes:
        n_frames: frames in the set.
        n_corners: object corners per frame (K).
        mean_hand_mm: mean over frames of the fingertip error, mm.
        mean_object_mm: mean over frames of the corner error, mm.
        mean_combined_mm: mean over frames of the combined (5 + K point) error, mm.
        median_combined_mm: median over frames of the combined error, mm.
        thresholds_mm: the tau grid, mm.
        fraction_combined_within: fraction of frames with combined error <= tau, on the grid.
        auc_combined: trapezoid AUC of that curve, in [0, 1].
    """

    n_frames: int
    n_corners: int
    mean_hand_mm: float
    mean_object_mm: float
    mean_combined_mm: float
    median_combined_mm: float
    thresholds_mm: list[float]
    fraction_combined_within: list[float]
    auc_combined: float

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serializable dict of every field."""
        return dataclasses.asdict(self)


def evaluate_dexter_object(
    pred_hand_m: Any,
    gt_hand_m: Any,
    pred_corners_m: Any,
    gt_corners_m: Any,
    *,
    tau_max_mm: float = TAU_MAX_MM,
    step_mm: float = TAU_STEP_MM,
) -> DexterObjectReport:
    """Dexter+Object summary of a set of frames.

    Args:
        pred_hand_m: (N, 21 or 5, 3) predicted keypoints or fingertips, metres.
        gt_hand_m: ground truth of the same shape, metres.
        pred_corners_m: (N, K, 3) predicted object corners, metres.
        gt_corners_m: (N, K, 3) ground-truth object corners, metres.
        tau_max_mm: last threshold of the curve and the AUC, mm.
        step_mm: threshold spacing, mm.

    Returns:
        The :class:`DexterObjectReport`.

    Raises:
        InvalidMetricInput: as :func:`dexter_object_errors_mm` and :func:`threshold_grid_mm`.
    """
    errs = dexter_object_errors_mm(pred_hand_m, gt_hand_m, pred_corners_m, gt_corners_m)
    taus = threshold_grid_mm(tau_max_mm, step_mm)
    curve = fraction_of_frames_within(errs.combined_mm, taus)
    return DexterObjectReport(
        n_frames=int(errs.combined_mm.size),
        n_corners=int(np.asarray(gt_corners_m).shape[1]),
        mean_hand_mm=float(errs.hand_mm.mean()),
        mean_object_mm=float(errs.object_mm.mean()),
        mean_combined_mm=float(errs.combined_mm.mean()),
        median_combined_mm=float(np.median(errs.combined_mm)),
        thresholds_mm=[float(t) for t in taus],
        fraction_combined_within=[float(v) for v in curve],
        auc_combined=curve_auc(taus, curve),
    )


# Breakdowns ------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class BucketStats:
    """Error statistics of the frames in one occlusion bucket (JSON-serializable).

    Attributes:
        lower: lower edge of the bucket (inclusive).
        upper: upper edge (exclusive, inclusive for the last bucket).
        n_frames: frames in the bucket.
        n_missed: frames in the bucket without an error value (None / NaN / inf).
        mean: mean error of the other frames, in the unit of the errors (``None`` if none).
        median: median error (``None`` if none).
        max: largest error (``None`` if none).
    """

    lower: float
    upper: float
    n_frames: int
    n_missed: int
    mean: float | None
    median: float | None
    max: float | None

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serializable dict of every field."""
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class JointStats:
    """Error statistics of one joint over the frames where it is evaluated.

    Attributes:
        n: frames where the joint is evaluated.
        mean_mm: mean error, mm (``None`` if ``n == 0``).
        median_mm: median error, mm (``None`` if ``n == 0``).
        max_mm: largest error, mm (``None`` if ``n == 0``).
    """

    n: int
    mean_mm: float | None
    median_mm: float | None
    max_mm: float | None

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serializable dict of every field."""
        return dataclasses.asdict(self)


def errors_by_occlusion(
    errors: Any, occlusion: Any, edges: Sequence[float] = DEFAULT_OCCLUSION_EDGES
) -> list[BucketStats]:
    """Group per-frame errors by occlusion ratio.

    Args:
        errors: (N,) per-frame errors in any unit (e.g. mm); ``None`` / NaN / ``inf`` = miss.
        occlusion: (N,) per-frame occlusion ratios in ``[edges[0], edges[-1]]`` (e.g. the
            Frame's hand occlusion ratio, or ``1 - visib_fract`` of an object).
        edges: B + 1 strictly increasing bucket edges in [0, 1].

    Returns:
        B :class:`BucketStats`, in edge order; bucket ``b`` holds ``edges[b] <= r <
        edges[b+1]``, the last one also ``r == edges[-1]``.

    Raises:
        InvalidMetricInput: on mismatched lengths, an empty set, bad edges or an occlusion
            ratio outside the edges.
    """
    e = _errors_with_misses("errors", errors)
    r = _array("occlusion", occlusion)
    if r.shape != e.shape:
        raise InvalidMetricInput(
            f"occlusion must have one ratio per frame, shape {e.shape}; received {r.shape}"
        )
    ed = _array("edges", edges)
    if (
        ed.ndim != 1
        or ed.size < 2
        or not np.all(np.isfinite(ed))
        or np.any(np.diff(ed) <= 0)
        or ed[0] < 0
        or ed[-1] > 1
    ):
        raise InvalidMetricInput(
            f"edges must be >= 2 strictly increasing values in [0, 1]; received "
            f"{np.atleast_1d(ed).tolist()}"
        )
    if not np.all(np.isfinite(r)) or np.any(r < ed[0]) or np.any(r > ed[-1]):
        raise InvalidMetricInput(
            f"occlusion ratios must be finite and in [{ed[0]}, {ed[-1]}] (the edges); received "
            f"range [{np.nanmin(r)}, {np.nanmax(r)}]"
        )
    bucket = np.clip(np.searchsorted(ed, r, side="right") - 1, 0, ed.size - 2)
    out = []
    for b in range(ed.size - 1):
        sel = e[bucket == b]
        hit = sel[np.isfinite(sel)]
        out.append(
            BucketStats(
                lower=float(ed[b]),
                upper=float(ed[b + 1]),
                n_frames=int(sel.size),
                n_missed=int(sel.size - hit.size),
                mean=float(np.mean(hit)) if hit.size else None,
                median=float(np.median(hit)) if hit.size else None,
                max=float(np.max(hit)) if hit.size else None,
            )
        )
    return out


def errors_by_joint(
    joint_errors_mm: Any, joint_names: Sequence[str] | None = None
) -> dict[str, JointStats]:
    """Per-joint statistics of per-joint errors.

    Args:
        joint_errors_mm: (N, J) errors, mm (:func:`keypoint_errors_mm`); NaN = not evaluated.
        joint_names: J names; default :data:`~handsim.hand.keypoints.KEYPOINT_NAMES` when
            ``J == 21``, else ``joint_<k>``.

    Returns:
        Joint name -> :class:`JointStats`, in joint order.

    Raises:
        InvalidMetricInput: on a bad shape, a negative error or a wrong number of names.
    """
    e = _array("joint_errors_mm", joint_errors_mm)
    if e.ndim != 2 or e.shape[0] == 0 or e.shape[1] == 0:
        raise InvalidMetricInput(
            f"joint_errors_mm must be an (N, J) array with N, J >= 1; received shape {e.shape}"
        )
    _check_error_values("joint_errors_mm", e)
    names = _joint_names(e.shape[1], joint_names)
    out = {}
    for j, name in enumerate(names):
        col = e[:, j][~np.isnan(e[:, j])]
        out[name] = JointStats(
            n=int(col.size),
            mean_mm=float(np.mean(col)) if col.size else None,
            median_mm=float(np.median(col)) if col.size else None,
            max_mm=float(np.max(col)) if col.size else None,
        )
    return out
