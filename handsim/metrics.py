"""Evaluation metrics of hand and object pose estimates (pure NumPy; plots with matplotlib Agg).

Units
-----
Every input is SI: keypoints and model points in metres, poses as (4, 4) homogeneous
``T_cam_from_obj`` transforms in metres (``docs/conventions.md``). Every error this module
returns is reported in millimetres (names end in ``_mm``) or pixels (``_px``); thresholds are
given in the same units. Fractions (accuracies, F(tau), PCK, AUC) are in ``[0, 1]``, not percent.

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

Object pose (poses are ``T_cam_from_obj``; model points in the object frame)
----------------------------------------------------------------------------
- ADD (Hinterstoisser et al., ACCV 2012): mean over model points ``x`` of
  ``|T_est x - T_gt x|``.
- ADI / ADD-S (Hinterstoisser 2012; "ADD-S" in PoseCNN, Xiang et al. 2018): for each
  GROUND-TRUTH-posed point, the distance to the NEAREST ESTIMATE-posed point, averaged
  (``scipy.spatial.cKDTree`` on the estimated points, queried with the ground-truth points, as
  the BOP toolkit's ``adi``). Not symmetric in its arguments.
- ADD(-S): ADI for symmetric objects, ADD otherwise. An object is symmetric when
  ``obj.symmetry.kind != "none"``: in handsim the master chef can, bowl and marker
  (continuous) and the wood block, foam brick and both clamps (discrete), i.e. the BOP ycbv set
  {1, 13, 16, 18, 19, 20, 21}. PoseCNN's ADD-S set is {13, 16, 19, 20, 21}; pass
  ``symmetric=`` to override.
- ADD-sym and MSSD use the symmetry transforms ``S`` of :meth:`Symmetry.transforms` (continuous
  symmetries discretized into ``n_continuous`` steps): ADD-sym = ``min_S mean_x |T_est x -
  T_gt S x|``; MSSD (BOP 2019, Hodan et al. 2020) = ``min_S max_x |T_est x - T_gt S x|``.
- 2D reprojection error (Brachmann et al., CVPR 2016): the mean pixel distance between the
  projections (:meth:`handsim.world.camera.CameraIntrinsics.project`) of all model points posed by
  ``T_est`` and by ``T_gt``. An estimate that puts a point at ``z <= 0`` has an infinite error
  (it does not project); a ground truth that does is invalid input.
- Correct pose: ADD(-S) ``< 0.1 * diameter`` and reprojection ``< 5 px``, both STRICT. The
  ``0.1`` is Hinterstoisser's ``k_m``; the threshold is computed as
  ``diameter_m * 1000 * fraction`` (:func:`add_threshold_mm`).
- YCB-Video AUC (PoseCNN): the accuracy-threshold curve ``acc(t)`` = fraction of ALL frames
  whose error is ``<= t``, ``t`` in ``[0, 100]`` mm; errors above 100 mm, frames without an
  estimate (``None`` / NaN) and ``+inf`` are misses and stay in the denominator. Area divided by
  100 mm. Two integration rules (:func:`ycbv_auc`):

  - ``"posecnn"`` (default): the YCB_Video_toolbox ``VOCap`` of ``plot_accuracy_keyframe.m``
    (also copied by DenseFusion / PVN3D ``cal_auc``): with the hits sorted ``d_1 <= ... <=
    d_k`` and ``acc_j = j / n``, area ``= sum_j (d_j - d_{j-1}) acc_j + (0.1 m - d_k) acc_k``
    (``d_0 = 0``). Each step is credited from the previous error on, so for distinct errors the
    result is the exact area plus ``d_k / (n * 100 mm)``.
  - ``"exact"``: the exact area under the step curve, ``mean_frames max(0, 1 - e / 100 mm)``
    (misses count 0).

  PoseCNN's tables report the AUC of ADD and of ADD-S (ADI for every object); PVN3D-style
  tables add the AUC of ADD(-S). Papers print ``100 * AUC``.

Breakdowns
----------
- Occlusion buckets (:func:`errors_by_occlusion`): given bucket edges ``e_0 < ... < e_B`` in
  ``[0, 1]`` (default ``0, 0.2, 0.4, 0.6, 0.8, 1.0``), bucket ``b`` holds the frames with
  ``e_b <= occlusion < e_{b+1}``; the last bucket is closed (``occlusion == e_B`` is in it).
  NaN / ``+inf`` / ``None`` errors are misses: counted in ``n_missed``, left out of the
  statistics.
- Per joint (:func:`errors_by_joint`): statistics of each joint's evaluated errors.

Every report is a frozen dataclass of plain Python values (floats, ints, lists, dicts,
``None`` for an undefined statistic), so ``json.dumps(report.to_dict(), allow_nan=False)``
works.

Bad input raises :class:`InvalidMetricInput` (a :class:`~handsim.errors.HandSimError` and a
``ValueError``) saying what was expected and what was received.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
from scipy.spatial import cKDTree

from handsim._validate import is_real
from handsim.errors import HandSimError
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.world.camera import CameraIntrinsics
from handsim.world.objects import Symmetry

__all__ = [
    "InvalidMetricInput",
    # constants
    "MM_PER_M",
    "TAU_MAX_MM",
    "TAU_STEP_MM",
    "FINGERTIP_INDICES",
    "ADD_FRACTION",
    "REPROJECTION_THRESHOLD_PX",
    "YCBV_AUC_MAX_MM",
    "DEFAULT_OCCLUSION_EDGES",
    # hand keypoints
    "keypoint_errors_mm",
    "frame_mean_error_mm",
    "frame_max_error_mm",
    "threshold_grid_mm",
    "fraction_of_frames_within",
    "pck",
    "curve_auc",
    "HandPoseReport",
    "evaluate_hand_poses",
    # hand-object (Dexter+Object)
    "HandObjectErrors",
    "DexterObjectReport",
    "dexter_object_errors_mm",
    "evaluate_dexter_object",
    # object pose
    "transform_points",
    "add_error_mm",
    "adi_error_mm",
    "add_or_adi_error_mm",
    "add_sym_error_mm",
    "mssd_error_mm",
    "reprojection_error_px",
    "add_threshold_mm",
    "is_add_correct",
    "is_reprojection_correct",
    "ycbv_accuracy_curve",
    "ycbv_auc",
    "ObjectPoseReport",
    "evaluate_object_poses",
    # breakdowns
    "BucketStats",
    "JointStats",
    "errors_by_occlusion",
    "errors_by_joint",
    # plots
    "plot_f_tau",
    "plot_pck",
]


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


def _check_finite_at(name: str, arr: np.ndarray, mask: np.ndarray) -> None:
    bad = ~np.all(np.isfinite(arr), axis=-1) & mask
    if np.any(bad):
        raise InvalidMetricInput(
            f"{name} has a non-finite value at {_first_bad(bad)}; expected finite metres at "
            "every evaluated joint (mark joints without a label False in `visible`)"
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


# Object pose -----------------------------------------------------------------------------------


def _pose(name: str, T: Any) -> np.ndarray:  # noqa: N803 (the standard name of a transform)
    if T is None:
        raise InvalidMetricInput(
            f"{name} must be a (4, 4) transform; received None (frames without an estimate are "
            "misses: pass them to evaluate_object_poses or ycbv_auc)"
        )
    arr = _array(name, T)
    if arr.shape != (4, 4):
        raise InvalidMetricInput(
            f"{name} must be a (4, 4) homogeneous transform T_cam_from_obj in metres; received "
            f"shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise InvalidMetricInput(f"{name} must be finite; received a NaN or inf entry:\n{arr}")
    if not np.allclose(arr[3], (0.0, 0.0, 0.0, 1.0), atol=1e-9):
        raise InvalidMetricInput(
            f"{name} must have the last row (0, 0, 0, 1); received {arr[3].tolist()}"
        )
    return arr


def _model_points(points: Any) -> np.ndarray:
    pts = _array("model_points_m", points)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
        raise InvalidMetricInput(
            f"model_points_m must be an (M, 3) array with M >= 1, metres, object frame; "
            f"received shape {pts.shape}"
        )
    if not np.all(np.isfinite(pts)):
        raise InvalidMetricInput("model_points_m must be finite; received a NaN or inf")
    return pts


def transform_points(T: Any, points_m: Any) -> np.ndarray:  # noqa: N803
    """Apply one or several rigid transforms to points.

    Args:
        T: (4, 4) or (N, 4, 4) transforms, e.g. ``T_cam_from_obj``, metres.
        points_m: (M, 3) points in the source frame (e.g. ``obj.corners_m``), metres.

    Returns:
        (M, 3) or (N, M, 3) float64 points in the target frame, metres.

    Raises:
        InvalidMetricInput: on bad shapes or non-finite values.
    """
    pts = _model_points(points_m)
    arr = _array("T", T)
    if arr.shape == (4, 4):
        arr = _pose("T", arr)
        return pts @ arr[:3, :3].T + arr[:3, 3]
    if arr.ndim != 3 or arr.shape[1:] != (4, 4):
        raise InvalidMetricInput(
            f"T must be a (4, 4) or (N, 4, 4) transform array; received shape {arr.shape}"
        )
    for i, t in enumerate(arr):
        _pose(f"T[{i}]", t)
    return np.einsum("nij,mj->nmi", arr[:, :3, :3], pts) + arr[:, None, :3, 3]


def _posed_pair(
    T_est: Any,  # noqa: N803
    T_gt: Any,  # noqa: N803
    model_points_m: Any,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    est = _pose("T_est", T_est)
    gt = _pose("T_gt", T_gt)
    pts = _model_points(model_points_m)
    return est, gt, pts @ est[:3, :3].T + est[:3, 3], pts @ gt[:3, :3].T + gt[:3, 3]


def add_error_mm(T_est: Any, T_gt: Any, model_points_m: Any) -> float:  # noqa: N803
    """ADD: mean distance between the model points posed by the estimate and the truth.

    Args:
        T_est: (4, 4) estimated ``T_cam_from_obj``, metres.
        T_gt: (4, 4) ground-truth ``T_cam_from_obj``, metres.
        model_points_m: (M, 3) model points, object frame, metres.

    Returns:
        ``mean_x |T_est x - T_gt x|``, mm.

    Raises:
        InvalidMetricInput: on a bad transform or point array.
    """
    _, _, p_est, p_gt = _posed_pair(T_est, T_gt, model_points_m)
    return float(np.mean(np.linalg.norm(p_est - p_gt, axis=1)) * MM_PER_M)


def adi_error_mm(T_est: Any, T_gt: Any, model_points_m: Any) -> float:  # noqa: N803
    """ADI / ADD-S: mean distance from each ground-truth-posed point to the nearest estimate.

    Args:
        T_est: (4, 4) estimated ``T_cam_from_obj``, metres.
        T_gt: (4, 4) ground-truth ``T_cam_from_obj``, metres.
        model_points_m: (M, 3) model points, object frame, metres.

    Returns:
        ``mean_{x} min_{y} |T_gt x - T_est y|`` over the model points, mm.

    Raises:
        InvalidMetricInput: on a bad transform or point array.
    """
    _, _, p_est, p_gt = _posed_pair(T_est, T_gt, model_points_m)
    dist, _ = cKDTree(p_est).query(p_gt, k=1)
    return float(np.mean(dist) * MM_PER_M)


def _is_symmetric(obj: Any, symmetric: bool | None) -> bool:
    if symmetric is not None:
        if not isinstance(symmetric, (bool, np.bool_)):
            raise InvalidMetricInput(
                f"symmetric must be True, False or None; received {symmetric!r}"
            )
        return bool(symmetric)
    sym = getattr(obj, "symmetry", None)
    if not isinstance(sym, Symmetry):
        raise InvalidMetricInput(
            f"obj must have a `symmetry` (handsim.world.Symmetry) or symmetric= must be given; "
            f"received {type(obj).__name__}"
        )
    return sym.kind != "none"


def _object_points(obj: Any) -> np.ndarray:
    if not hasattr(obj, "model_points_m"):
        raise InvalidMetricInput(
            f"obj must be a YCBObject (or have model_points_m, diameter_m and symmetry); "
            f"received {type(obj).__name__}"
        )
    return _model_points(obj.model_points_m)


def add_or_adi_error_mm(
    T_est: Any,  # noqa: N803
    T_gt: Any,  # noqa: N803
    obj: Any,
    *,
    symmetric: bool | None = None,
) -> float:
    """ADD(-S): ADI for a symmetric object, ADD otherwise.

    Args:
        T_est: (4, 4) estimated ``T_cam_from_obj``, metres.
        T_gt: (4, 4) ground-truth ``T_cam_from_obj``, metres.
        obj: a :class:`~handsim.world.YCBObject` (or anything with ``model_points_m`` and
            ``symmetry``).
        symmetric: override; default ``obj.symmetry.kind != "none"``.

    Returns:
        The error, mm.

    Raises:
        InvalidMetricInput: on a bad transform or object.
    """
    pts = _object_points(obj)
    if _is_symmetric(obj, symmetric):
        return adi_error_mm(T_est, T_gt, pts)
    return add_error_mm(T_est, T_gt, pts)


def _symmetry_distances(
    T_est: Any,  # noqa: N803
    T_gt: Any,  # noqa: N803
    model_points_m: Any,
    symmetry: Symmetry,
    n_continuous: int,
) -> np.ndarray:
    if not isinstance(symmetry, Symmetry):
        raise InvalidMetricInput(
            f"symmetry must be a handsim.world.Symmetry; received {type(symmetry).__name__}"
        )
    if not (isinstance(n_continuous, int | np.integer) and n_continuous >= 1):
        raise InvalidMetricInput(f"n_continuous must be an integer >= 1; received {n_continuous!r}")
    _, gt, p_est, _ = _posed_pair(T_est, T_gt, model_points_m)
    pts = _model_points(model_points_m)
    # T_gt S for every symmetry S; distances of shape (n_sym, M).
    gt_sym = gt[None] @ symmetry.transforms(int(n_continuous))
    p_gt = np.einsum("sij,mj->smi", gt_sym[:, :3, :3], pts) + gt_sym[:, None, :3, 3]
    return np.linalg.norm(p_est[None] - p_gt, axis=-1)


def add_sym_error_mm(
    T_est: Any,  # noqa: N803
    T_gt: Any,  # noqa: N803
    model_points_m: Any,
    symmetry: Symmetry,
    *,
    n_continuous: int = 36,
) -> float:
    """ADD minimized over the object's symmetries: ``min_S mean_x |T_est x - T_gt S x|``.

    Args:
        T_est: (4, 4) estimated ``T_cam_from_obj``, metres.
        T_gt: (4, 4) ground-truth ``T_cam_from_obj``, metres.
        model_points_m: (M, 3) model points, object frame, metres.
        symmetry: the object's :class:`~handsim.world.Symmetry`.
        n_continuous: steps a continuous symmetry is discretized into.

    Returns:
        The error, mm (equals ADD without symmetry).

    Raises:
        InvalidMetricInput: on a bad transform, point array, symmetry or step count.
    """
    d = _symmetry_distances(T_est, T_gt, model_points_m, symmetry, n_continuous)
    return float(np.min(np.mean(d, axis=1)) * MM_PER_M)


def mssd_error_mm(
    T_est: Any,  # noqa: N803
    T_gt: Any,  # noqa: N803
    model_points_m: Any,
    symmetry: Symmetry,
    *,
    n_continuous: int = 36,
) -> float:
    """MSSD (BOP): ``min_S max_x |T_est x - T_gt S x|``.

    Args:
        T_est: (4, 4) estimated ``T_cam_from_obj``, metres.
        T_gt: (4, 4) ground-truth ``T_cam_from_obj``, metres.
        model_points_m: (M, 3) model points, object frame, metres.
        symmetry: the object's :class:`~handsim.world.Symmetry`.
        n_continuous: steps a continuous symmetry is discretized into.

    Returns:
        The error, mm.

    Raises:
        InvalidMetricInput: on a bad transform, point array, symmetry or step count.
    """
    d = _symmetry_distances(T_est, T_gt, model_points_m, symmetry, n_continuous)
    return float(np.min(np.max(d, axis=1)) * MM_PER_M)


def reprojection_error_px(
    T_est: Any,  # noqa: N803
    T_gt: Any,  # noqa: N803
    model_points_m: Any,
    intrinsics: CameraIntrinsics,
) -> float:
    """2D reprojection error: mean pixel distance of the projected model points.

    Args:
        T_est: (4, 4) estimated ``T_cam_from_obj`` (OpenCV camera frame), metres.
        T_gt: (4, 4) ground-truth ``T_cam_from_obj``, metres.
        model_points_m: (M, 3) model points, object frame, metres.
        intrinsics: the camera's :class:`~handsim.world.camera.CameraIntrinsics`.

    Returns:
        Mean over the model points of the pixel distance between their projections, px;
        ``inf`` if the estimate puts a point at ``z <= 0``.

    Raises:
        InvalidMetricInput: on a bad transform, point array or camera, or if the ground truth
            puts a point at ``z <= 0``.
    """
    if not isinstance(intrinsics, CameraIntrinsics):
        raise InvalidMetricInput(
            f"intrinsics must be a handsim.world.camera.CameraIntrinsics; received "
            f"{type(intrinsics).__name__}"
        )
    _, _, p_est, p_gt = _posed_pair(T_est, T_gt, model_points_m)
    if np.any(p_gt[:, 2] <= 0):
        raise InvalidMetricInput(
            f"T_gt puts model points at z <= 0 (behind the camera; minimum z "
            f"{p_gt[:, 2].min():.4g} m); expected every ground-truth point in front of it"
        )
    if np.any(p_est[:, 2] <= 0):
        return math.inf
    uv = intrinsics.project(p_est) - intrinsics.project(p_gt)
    return float(np.mean(np.linalg.norm(uv, axis=1)))


def add_threshold_mm(diameter_m: float, fraction: float = ADD_FRACTION) -> float:
    """The ADD(-S) correctness threshold ``diameter_m * 1000 * fraction``, mm.

    Args:
        diameter_m: object diameter (largest distance between two model vertices), metres.
        fraction: the fraction of the diameter (Hinterstoisser's ``k_m`` = 0.1).

    Returns:
        The threshold, mm (20.0 for a 0.2 m object).

    Raises:
        InvalidMetricInput: if the diameter or fraction is not positive.
    """
    return _positive("diameter_m", diameter_m) * MM_PER_M * _positive("fraction", fraction)


def is_add_correct(
    error_mm: float | None, diameter_m: float, fraction: float = ADD_FRACTION
) -> bool:
    """Whether an ADD(-S) error is STRICTLY below ``fraction`` of the diameter.

    Args:
        error_mm: ADD / ADI / ADD(-S) error, mm; ``None`` / NaN / ``inf`` (no estimate) is
            incorrect.
        diameter_m: object diameter, metres.
        fraction: the fraction of the diameter (0.1).

    Returns:
        ``error_mm < add_threshold_mm(diameter_m, fraction)``.

    Raises:
        InvalidMetricInput: on a negative error or a non-positive diameter or fraction.
    """
    threshold = add_threshold_mm(diameter_m, fraction)
    e = _error_or_miss("error_mm", error_mm)
    return bool(e < threshold)


def is_reprojection_correct(
    error_px: float | None, threshold_px: float = REPROJECTION_THRESHOLD_PX
) -> bool:
    """Whether a 2D reprojection error is STRICTLY below ``threshold_px`` (5 px).

    Args:
        error_px: 2D reprojection error, px; ``None`` / NaN / ``inf`` (no estimate) is
            incorrect.
        threshold_px: the threshold, px.

    Returns:
        ``error_px < threshold_px``.

    Raises:
        InvalidMetricInput: on a negative error or a non-positive threshold.
    """
    threshold = _positive("threshold_px", threshold_px)
    e = _error_or_miss("error_px", error_px)
    return bool(e < threshold)


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


def ycbv_accuracy_curve(errors_mm: Any, thresholds_mm: Any) -> np.ndarray:
    """The YCB-Video accuracy curve: fraction of ALL frames with error ``<= t``.

    Args:
        errors_mm: (N,) per-frame ADD or ADD-S errors, mm; ``None`` / NaN / ``inf`` = miss
            (stays in the denominator, never counts as a hit).
        thresholds_mm: (T,) thresholds, mm, ``>= 0``.

    Returns:
        (T,) float64 fractions in [0, 1].

    Raises:
        InvalidMetricInput: on an empty set, a negative error or threshold.
    """
    e = _errors_with_misses("errors_mm", errors_mm)
    t = _thresholds("thresholds_mm", thresholds_mm)
    return np.mean(e[None, :] <= t[:, None], axis=1)


def ycbv_auc(
    errors_mm: Any, *, max_mm: float = YCBV_AUC_MAX_MM, rule: AucRule = "posecnn"
) -> float:
    """YCB-Video AUC of ADD or ADD-S over ``[0, max_mm]`` (PoseCNN), in [0, 1].

    Args:
        errors_mm: (N,) per-frame errors, mm; ``None`` / NaN / ``inf`` = miss (a frame without
            an estimate); errors above ``max_mm`` are misses too; misses stay in the
            denominator.
        max_mm: the curve's last threshold, mm (100 mm = 0.1 m).
        rule: ``"posecnn"`` (YCB_Video_toolbox ``VOCap``) or ``"exact"`` (exact area under the
            step curve); see the module docstring.

    Returns:
        The area divided by ``max_mm``; multiply by 100 for the numbers printed in papers.

    Raises:
        InvalidMetricInput: on an empty set, a negative error, a non-positive ``max_mm`` or an
            unknown rule.
    """
    if rule not in ("posecnn", "exact"):
        raise InvalidMetricInput(f"rule must be 'posecnn' or 'exact'; received {rule!r}")
    top = _positive("max_mm", max_mm)
    e = _errors_with_misses("errors_mm", errors_mm)
    n = e.size
    if rule == "exact":
        return float(np.mean(np.clip(1.0 - e / top, 0.0, 1.0)))
    d = np.sort(e)
    d = d[d <= top]
    if d.size == 0:
        return 0.0
    acc = np.arange(1, d.size + 1, dtype=np.float64) / n
    mrec = np.concatenate([[0.0], d, [top]])
    mpre = np.concatenate([[0.0], acc, [acc[-1]]])
    # VOCap credits each interval (mrec[i-1], mrec[i]] with the accuracy at its right end.
    i = np.nonzero(mrec[1:] != mrec[:-1])[0] + 1
    return float(np.sum((mrec[i] - mrec[i - 1]) * mpre[i]) / top)


@dataclasses.dataclass(frozen=True)
class ObjectPoseReport:
    """Object pose metrics of a set of frames of one object (JSON-serializable).

    Per-frame lists hold ``None`` for a frame without an estimate.

    Attributes:
        object_name: the object's name.
        n_frames: frames in the set.
        n_missed: frames without an estimate.
        symmetric: whether ADD(-S) used ADI.
        diameter_mm: object diameter, mm.
        add_mm: per-frame ADD, mm.
        adi_mm: per-frame ADI (ADD-S), mm.
        add_s_mm: per-frame ADD(-S), mm.
        reprojection_px: per-frame 2D reprojection error, px (``None`` without intrinsics).
        mean_add_s_mm: mean ADD(-S) over the estimated frames, mm (``None`` if none).
        accuracy_add_s: fraction of ALL frames with ADD(-S) < fraction * diameter.
        accuracy_reprojection: fraction of ALL frames with reprojection < threshold
            (``None`` without intrinsics).
        auc_add: YCB-Video AUC of ADD, in [0, 1].
        auc_adi: YCB-Video AUC of ADD-S (ADI), in [0, 1].
        auc_add_s: YCB-Video AUC of ADD(-S), in [0, 1].
        auc_rule: the integration rule of the AUCs.
    """

    object_name: str
    n_frames: int
    n_missed: int
    symmetric: bool
    diameter_mm: float
    add_mm: list[float | None]
    adi_mm: list[float | None]
    add_s_mm: list[float | None]
    reprojection_px: list[float | None] | None
    mean_add_s_mm: float | None
    accuracy_add_s: float
    accuracy_reprojection: float | None
    auc_add: float
    auc_adi: float
    auc_add_s: float
    auc_rule: str

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serializable dict of every field (``inf`` reprojections become ``None``)."""
        out = dataclasses.asdict(self)
        if out["reprojection_px"] is not None:
            out["reprojection_px"] = [
                None if v is None or math.isinf(v) else v for v in out["reprojection_px"]
            ]
        return out


def _is_miss_pose(T: Any) -> bool:  # noqa: N803
    if T is None:
        return True
    arr = _array("T_est", T)
    return arr.shape == (4, 4) and bool(np.any(np.isnan(arr)))


def evaluate_object_poses(
    T_est: Sequence[Any] | np.ndarray,  # noqa: N803
    T_gt: Sequence[Any] | np.ndarray,  # noqa: N803
    obj: Any,
    *,
    intrinsics: CameraIntrinsics | None = None,
    symmetric: bool | None = None,
    fraction: float = ADD_FRACTION,
    threshold_px: float = REPROJECTION_THRESHOLD_PX,
    auc_rule: AucRule = "posecnn",
) -> ObjectPoseReport:
    """Every object pose metric of a set of frames of one object.

    Args:
        T_est: N estimated ``T_cam_from_obj`` (4, 4), metres; ``None`` or a matrix with a NaN
            entry marks a frame without an estimate (a miss).
        T_gt: N ground-truth ``T_cam_from_obj`` (4, 4), metres.
        obj: a :class:`~handsim.world.YCBObject` (or anything with ``name``,
            ``model_points_m``, ``diameter_m`` and ``symmetry``).
        intrinsics: camera intrinsics for the 2D reprojection error (skipped if ``None``).
        symmetric: override of ADD(-S)'s choice; default ``obj.symmetry.kind != "none"``.
        fraction: ADD(-S) correctness threshold as a fraction of the diameter (0.1).
        threshold_px: reprojection correctness threshold, px (5).
        auc_rule: integration rule of the YCB-Video AUCs (see :func:`ycbv_auc`).

    Returns:
        The :class:`ObjectPoseReport`.

    Raises:
        InvalidMetricInput: on different frame counts, an empty set, a bad transform or object.
    """
    pts = _object_points(obj)
    is_sym = _is_symmetric(obj, symmetric)
    diameter_m = getattr(obj, "diameter_m", None)
    threshold_mm = add_threshold_mm(diameter_m, fraction)  # type: ignore[arg-type]
    threshold_px = _positive("threshold_px", threshold_px)
    est_list = list(T_est)
    gt_list = list(T_gt)
    if len(est_list) != len(gt_list):
        raise InvalidMetricInput(
            f"T_est and T_gt must have one pose per frame; received {len(est_list)} and "
            f"{len(gt_list)}"
        )
    if not gt_list:
        raise InvalidMetricInput("expected at least one frame; received 0 poses")
    add, adi, add_s, reproj = [], [], [], []
    for k, (est, gt) in enumerate(zip(est_list, gt_list, strict=True)):
        gt = _pose(f"T_gt[{k}]", gt)
        if _is_miss_pose(est):
            add.append(None)
            adi.append(None)
            add_s.append(None)
            reproj.append(None)
            continue
        est = _pose(f"T_est[{k}]", est)
        a = add_error_mm(est, gt, pts)
        s = adi_error_mm(est, gt, pts)
        add.append(a)
        adi.append(s)
        add_s.append(s if is_sym else a)
        if intrinsics is not None:
            reproj.append(reprojection_error_px(est, gt, pts, intrinsics))
    hits = [e for e in add_s if e is not None]
    n = len(gt_list)
    accuracy_reprojection = None
    if intrinsics is not None:
        accuracy_reprojection = sum(e is not None and e < threshold_px for e in reproj) / n
    return ObjectPoseReport(
        object_name=str(getattr(obj, "name", "object")),
        n_frames=n,
        n_missed=n - len(hits),
        symmetric=is_sym,
        diameter_mm=float(diameter_m) * MM_PER_M,
        add_mm=add,
        adi_mm=adi,
        add_s_mm=add_s,
        reprojection_px=reproj if intrinsics is not None else None,
        mean_add_s_mm=float(np.mean(hits)) if hits else None,
        accuracy_add_s=sum(e is not None and e < threshold_mm for e in add_s) / n,
        accuracy_reprojection=accuracy_reprojection,
        auc_add=ycbv_auc(add, rule=auc_rule),
        auc_adi=ycbv_auc(adi, rule=auc_rule),
        auc_add_s=ycbv_auc(add_s, rule=auc_rule),
        auc_rule=auc_rule,
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


# Plots -----------------------------------------------------------------------------------------


def _png_path(path: str | os.PathLike[str]) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidMetricInput(
            f"path must be a str or os.PathLike ending in .png; received {path!r}"
        )
    p = Path(path)
    if p.suffix.lower() != ".png":
        raise InvalidMetricInput(f"path must end in .png; received {str(p)!r}")
    p.parent.mkdir(parents=True, exist_ok=True)
    return p


def _check_methods(methods: Mapping[str, Any]) -> None:
    if not isinstance(methods, Mapping) or len(methods) == 0:
        raise InvalidMetricInput(
            "methods must be a non-empty mapping of method name -> errors or report; received "
            f"{methods!r}"
        )


def _save_curves(
    curves: list[tuple[str, np.ndarray, np.ndarray]],
    path: Path,
    *,
    xlabel: str,
    ylabel: str,
    title: str | None,
) -> Path:
    # The object-oriented API with an Agg canvas: no pyplot state, no GUI backend.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.0, 4.5), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for label, x, y in curves:
        ax.plot(x, 100.0 * y, linewidth=2.0, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_xlim(curves[0][1][0], curves[0][1][-1])
    ax.set_ylim(0.0, 100.0)
    ax.grid(True)
    ax.legend(loc="lower right")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, format="png")
    return path


def plot_f_tau(
    methods: Mapping[str, HandPoseReport | Any],
    path: str | os.PathLike[str],
    *,
    tau_max_mm: float = TAU_MAX_MM,
    step_mm: float = TAU_STEP_MM,
    title: str | None = None,
) -> Path:
    """Plot F(tau) (fraction of frames with max joint error <= tau) of one or more methods.

    Args:
        methods: method name -> a :class:`HandPoseReport` (its own grid is used), (N,) per-frame
            max errors in mm, or (N, J) per-joint errors in mm (NaN = not evaluated). All on
            one axes, with a legend giving each AUC.
        path: output PNG file (parent folders are created).
        tau_max_mm: last threshold for array inputs, mm.
        step_mm: threshold spacing for array inputs, mm.
        title: optional axes title.

    Returns:
        The path of the written PNG.

    Raises:
        InvalidMetricInput: on no method, a path not ending in ``.png`` or bad errors.
    """
    _check_methods(methods)
    threshold_grid_mm(tau_max_mm, step_mm)  # checked even when only reports are given
    if title is not None and not isinstance(title, str):
        raise InvalidMetricInput(f"title must be a str or None; received {title!r}")
    out = _png_path(path)
    curves = []
    for name, value in methods.items():
        if isinstance(value, HandPoseReport):
            taus, f = np.asarray(value.thresholds_mm), np.asarray(value.f_tau)
        else:
            e = _array(f"methods[{name!r}]", value)
            if e.ndim == 2:
                e = _frame_reduce(e, "max")
            taus = threshold_grid_mm(tau_max_mm, step_mm)
            f = fraction_of_frames_within(e, taus)
        curves.append((f"{name} (AUC {curve_auc(taus, f):.3f})", taus, f))
    return _save_curves(
        curves,
        out,
        xlabel="Distance threshold tau / mm",
        ylabel="Frames with max joint error <= tau / %",
        title=title,
    )


def plot_pck(
    methods: Mapping[str, HandPoseReport | Any],
    path: str | os.PathLike[str],
    *,
    tau_max_mm: float = TAU_MAX_MM,
    step_mm: float = TAU_STEP_MM,
    title: str | None = None,
) -> Path:
    """Plot PCK(tau) (fraction of joints with error <= tau) of one or more methods.

    Args:
        methods: method name -> a :class:`HandPoseReport` (its own grid is used) or per-joint
            errors in mm of any shape (NaN = not evaluated). All on one axes, with a legend
            giving each AUC.
        path: output PNG file (parent folders are created).
        tau_max_mm: last threshold for array inputs, mm.
        step_mm: threshold spacing for array inputs, mm.
        title: optional axes title.

    Returns:
        The path of the written PNG.

    Raises:
        InvalidMetricInput: on no method, a path not ending in ``.png`` or bad errors.
    """
    _check_methods(methods)
    threshold_grid_mm(tau_max_mm, step_mm)  # checked even when only reports are given
    if title is not None and not isinstance(title, str):
        raise InvalidMetricInput(f"title must be a str or None; received {title!r}")
    out = _png_path(path)
    curves = []
    for name, value in methods.items():
        if isinstance(value, HandPoseReport):
            taus, p = np.asarray(value.thresholds_mm), np.asarray(value.pck)
        else:
            taus = threshold_grid_mm(tau_max_mm, step_mm)
            p = pck(value, taus)
        curves.append((f"{name} (AUC {curve_auc(taus, p):.3f})", taus, p))
    return _save_curves(
        curves,
        out,
        xlabel="Distance threshold tau / mm",
        ylabel="Joints with error <= tau / %",
        title=title,
    )
