"""Evaluation metrics of hand and object pose estimates (pure NumPy; plots with matplotlib Agg).

Units
-----
Every input is SI: keypoints and model points in metres, poses as (4, 4) homogeneous
``T_cam_from_obj`` transforms in metres (``docs/conventions.md``). Every error this module
returns is reported in millimetres (names end in ``_mm``) or pixels (``_px``); thresholds are
given in the same units. Fractions (accuracies, F(tau), PCK, AUC) are in ``[0, 1]``, not percent.

Modules: :mod:`~handsim.metrics.hand` (hand keypoints, Dexter+Object, breakdowns by occlusion
and joint), :mod:`~handsim.metrics.objects` (object pose) and :mod:`~handsim.metrics.plots`
(curves); every public name is importable from :mod:`handsim.metrics`.

Every report is a frozen dataclass of plain Python values (floats, ints, lists, dicts,
``None`` for an undefined statistic), so ``json.dumps(report.to_dict(), allow_nan=False)``
works.

Bad input raises :class:`InvalidMetricInput` (a :class:`~handsim.errors.HandSimError` and a
``ValueError``) saying what was expected and what was received.
"""

from handsim.metrics._common import (
    ADD_FRACTION,
    DEFAULT_OCCLUSION_EDGES,
    FINGERTIP_INDICES,
    MM_PER_M,
    REPROJECTION_THRESHOLD_PX,
    TAU_MAX_MM,
    TAU_STEP_MM,
    YCBV_AUC_MAX_MM,
    InvalidMetricInput,
)
from handsim.metrics.hand import (
    BucketStats,
    DexterObjectReport,
    HandObjectErrors,
    HandPoseReport,
    JointStats,
    curve_auc,
    dexter_object_errors_mm,
    errors_by_joint,
    errors_by_occlusion,
    evaluate_dexter_object,
    evaluate_hand_poses,
    fraction_of_frames_within,
    frame_max_error_mm,
    frame_mean_error_mm,
    keypoint_errors_mm,
    pck,
    threshold_grid_mm,
)
from handsim.metrics.objects import (
    ObjectPoseReport,
    add_error_mm,
    add_or_adi_error_mm,
    add_sym_error_mm,
    add_threshold_mm,
    adi_error_mm,
    evaluate_object_poses,
    is_add_correct,
    is_reprojection_correct,
    mssd_error_mm,
    reprojection_error_px,
    transform_points,
    ycbv_accuracy_curve,
    ycbv_auc,
)
from handsim.metrics.plots import plot_f_tau, plot_pck

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
