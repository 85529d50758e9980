"""Object pose metrics: ADD, ADI / ADD-S, ADD(-S), ADD-sym, MSSD, reprojection, YCB-Video AUC.

Object pose (poses are ``T_cam_from_obj``; model points in the object frame)
----------------------------------------------------------------------------
- ADD (Hinterstoisser et al., ACCV 2012): mean over model points ``x`` of
  ``|T_est x - T_gt x|``.
- ADI / ADD-S (Hinterstoisser 2012; "ADD-S" in PoseCNN, Xiang et al. 2018): for each
  GROUND-TRUTH-posed point, the distance to the NEAREST ESTIMATE-posed point, averaged
  (``scipy.spatial.cKDTree`` on the estimated points, queried with the ground-truth points, as
  the BOP toolkit's ``adi``). Not symmetric in its arguments.
- ADD(-S): ADI for symmetric objects, ADD otherwise. Which symmetries count is the
  ``modality`` parameter (:meth:`~handsim.world.YCBObject.symmetry_of`). ``"texture"``
  (default): the object looks the same in colour, ``obj.symmetry.kind != "none"``: in handsim
  the master chef can, bowl and marker (continuous) and the wood block, foam brick and both
  clamps (discrete), i.e. the BOP ycbv set {1, 13, 16, 18, 19, 20, 21}. ``"depth"``: the
  shape alone, for estimators that see depth only: also the tomato soup and tuna cans
  (plain cylinders, continuous) and the plain boxes (cracker, sugar, pudding, gelatin, potted
  meat: half turns about their axes). PoseCNN's ADD-S set is {13, 16, 19, 20, 21}; pass
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
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from handsim.metrics._common import (
    ADD_FRACTION,
    MM_PER_M,
    REPROJECTION_THRESHOLD_PX,
    YCBV_AUC_MAX_MM,
    AucRule,
    InvalidMetricInput,
    _array,
    _error_or_miss,
    _errors_with_misses,
    _positive,
    _thresholds,
)
from handsim.world.camera import CameraIntrinsics
from handsim.world.symmetry import SYMMETRY_MODALITIES, Symmetry, SymmetryModality

# Object pose -----------------------------------------------------------------------------------


RIGID_TOL = 1e-4
"""Largest entry of ``R^T R - I`` accepted in a pose's rotation block."""


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
    rot = arr[:3, :3]
    # Float32 poses are rotations to ~1e-7; a scale or shear would move the model points.
    if not np.allclose(rot.T @ rot, np.eye(3), atol=RIGID_TOL) or np.linalg.det(rot) <= 0:
        raise InvalidMetricInput(
            f"{name} must be a rigid transform: its 3x3 block a rotation (R^T R = I within "
            f"{RIGID_TOL:g}, det R = +1); received R^T R =\n{np.round(rot.T @ rot, 6)}\nand det "
            f"R = {np.linalg.det(rot):.6g} (a scale, shear or reflection)"
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
    from scipy.spatial import cKDTree

    dist, _ = cKDTree(p_est).query(p_gt, k=1)
    return float(np.mean(dist) * MM_PER_M)


def _is_symmetric(obj: Any, symmetric: bool | None, modality: str = "texture") -> bool:
    if modality not in SYMMETRY_MODALITIES:
        raise InvalidMetricInput(
            f"modality must be one of {SYMMETRY_MODALITIES}; received {modality!r}"
        )
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
    if modality == "depth" and isinstance(getattr(obj, "depth_symmetry", None), Symmetry):
        sym = obj.depth_symmetry
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
    modality: SymmetryModality = "texture",
) -> float:
    """ADD(-S): ADI for a symmetric object, ADD otherwise.

    Args:
        T_est: (4, 4) estimated ``T_cam_from_obj``, metres.
        T_gt: (4, 4) ground-truth ``T_cam_from_obj``, metres.
        obj: a :class:`~handsim.world.YCBObject` (or anything with ``model_points_m`` and
            ``symmetry``).
        symmetric: override; default ``obj.symmetry_of(modality).kind != "none"``.
        modality: which symmetries count: ``"texture"`` (colour, BOP's) or ``"depth"`` (the
            shape alone: also plain cans and boxes); module docstring.

    Returns:
        The error, mm.

    Raises:
        InvalidMetricInput: on a bad transform or object.
    """
    pts = _object_points(obj)
    if _is_symmetric(obj, symmetric, modality):
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
    modality: SymmetryModality = "texture",
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
        symmetric: override of ADD(-S)'s choice; default
            ``obj.symmetry_of(modality).kind != "none"``.
        modality: which symmetries count for ADD(-S): ``"texture"`` or ``"depth"``.
        fraction: ADD(-S) correctness threshold as a fraction of the diameter (0.1).
        threshold_px: reprojection correctness threshold, px (5).
        auc_rule: integration rule of the YCB-Video AUCs (see :func:`ycbv_auc`).

    Returns:
        The :class:`ObjectPoseReport`.

    Raises:
        InvalidMetricInput: on different frame counts, an empty set, a bad transform or object.
    """
    pts = _object_points(obj)
    is_sym = _is_symmetric(obj, symmetric, modality)
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
