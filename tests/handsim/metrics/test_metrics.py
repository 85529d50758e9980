"""Tests of handsim.metrics on hand-computed cases, invariants and bad input."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.errors import HandSimError
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.metrics import (
    FINGERTIP_INDICES,
    BucketStats,
    InvalidMetricInput,
    add_error_mm,
    add_or_adi_error_mm,
    add_sym_error_mm,
    add_threshold_mm,
    adi_error_mm,
    curve_auc,
    dexter_object_errors_mm,
    errors_by_joint,
    errors_by_occlusion,
    evaluate_dexter_object,
    evaluate_hand_poses,
    evaluate_object_poses,
    fraction_of_frames_within,
    frame_max_error_mm,
    frame_mean_error_mm,
    is_add_correct,
    is_reprojection_correct,
    keypoint_errors_mm,
    mssd_error_mm,
    pck,
    plot_f_tau,
    plot_pck,
    reprojection_error_px,
    threshold_grid_mm,
    transform_points,
    ycbv_accuracy_curve,
    ycbv_auc,
)
from handsim.world.camera import CameraIntrinsics
from handsim.world.registry import get_object
from handsim.world.symmetry import NO_SYMMETRY, Symmetry

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
# 512 px focal length: offsets of k / 512 m at z = 1 m shift pixels by exactly k.
CAM = CameraIntrinsics(640, 480, 512.0, 512.0, 320.0, 240.0)


def pose(rotvec=(0.0, 0.0, 0.0), t=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A (4, 4) rigid transform from a rotation vector (rad) and a translation (m)."""
    T = np.eye(4)  # noqa: N806
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def ring(n: int = 12, radius: float = 0.05) -> np.ndarray:
    """N points on a circle about the y axis (a rotationally symmetric synthetic object)."""
    a = 2.0 * np.pi * np.arange(n) / n
    return np.stack([radius * np.cos(a), np.zeros(n), radius * np.sin(a)], axis=1)


def toy_object(points, symmetry=NO_SYMMETRY, diameter_m=0.2, name="toy"):
    """A duck-typed object with the attributes the object metrics read."""
    return types.SimpleNamespace(
        name=name,
        model_points_m=np.asarray(points, float),
        diameter_m=diameter_m,
        symmetry=symmetry,
    )


def hands(offsets_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 21, 3) ground truth and a prediction displaced along x by offsets_m[n, j] metres."""
    offsets_m = np.asarray(offsets_m, float)
    rng = np.random.default_rng(0)
    gt = rng.uniform(-0.1, 0.1, size=(*offsets_m.shape, 3)) + np.array([0.0, 0.0, 0.5])
    pred = gt.copy()
    pred[..., 0] += offsets_m
    return pred, gt


# Hand keypoints ----------------------------------------------------------------------------------


def test_keypoint_errors_are_euclidean_in_mm():
    """Joint errors are 3D distances converted to millimetres."""
    gt = np.zeros((2, 2, 3))
    pred = np.array([[[0.003, 0.004, 0.0], [0.0, 0.0, 0.01]], [[0.0, 0.0, 0.0], [0.0, 0.02, 0.0]]])
    np.testing.assert_allclose(keypoint_errors_mm(pred, gt), [[5.0, 10.0], [0.0, 20.0]])
    np.testing.assert_allclose(frame_mean_error_mm(pred, gt), [7.5, 10.0])
    np.testing.assert_allclose(frame_max_error_mm(pred, gt), [10.0, 20.0])


def test_visibility_mask_skips_joints_and_frames():
    """Masked joints are NaN (and may be non-finite); a frame without joints is NaN."""
    gt = np.zeros((3, 2, 3))
    pred = np.zeros((3, 2, 3))
    pred[0, 0, 0] = 0.01
    pred[0, 1, 0] = 0.05
    gt[0, 1] = np.nan
    visible = np.array([[True, False], [True, True], [False, False]])
    errors = keypoint_errors_mm(pred, gt, visible)
    assert errors[0, 0] == pytest.approx(10.0)
    assert np.isnan(errors[0, 1]) and np.all(np.isnan(errors[2]))
    frame_max = frame_max_error_mm(pred, gt, visible)
    np.testing.assert_allclose(frame_max[:2], [10.0, 0.0])
    assert np.isnan(frame_max[2])
    # The unevaluated frame is out of the F(tau) denominator.
    np.testing.assert_allclose(fraction_of_frames_within(frame_max, [0.0, 10.0]), [0.5, 1.0])


def test_f_tau_hand_computed_and_inclusive():
    """F(tau) counts frames with max error <= tau, inclusive at the threshold."""
    f = fraction_of_frames_within([10.0, 30.5], [0.0, 9.0, 10.0, 30.0, 30.5, 31.0, 80.0])
    np.testing.assert_array_equal(f, [0.0, 0.0, 0.5, 0.5, 1.0, 1.0, 1.0])


def test_f_tau_counts_inf_as_failure():
    """A frame without an estimate (+inf) stays in the denominator and never succeeds."""
    np.testing.assert_array_equal(
        fraction_of_frames_within([5.0, math.inf], [10.0, 80.0]), [0.5, 0.5]
    )


def test_pck_hand_computed():
    """PCK pools every evaluated joint of every frame."""
    errors = np.array([[5.0, 15.0], [25.0, np.nan]])
    np.testing.assert_allclose(
        pck(errors, [0.0, 5.0, 15.0, 24.9, 25.0]), [0, 1 / 3, 2 / 3, 2 / 3, 1]
    )


def test_threshold_grid_is_0_to_80_by_1_mm():
    """The default grid has 81 thresholds 0, 1, ..., 80 mm."""
    grid = threshold_grid_mm()
    np.testing.assert_array_equal(grid, np.arange(81.0))
    np.testing.assert_array_equal(threshold_grid_mm(10.0, 2.5), [0.0, 2.5, 5.0, 7.5, 10.0])


def test_curve_auc_trapezoid_hand_computed():
    """The AUC is the trapezoid area divided by the threshold span."""
    assert curve_auc([0.0, 1.0, 2.0], [0.0, 1.0, 1.0]) == pytest.approx(0.75)
    assert curve_auc([0.0, 4.0], [1.0, 1.0]) == pytest.approx(1.0)


def test_f_tau_and_pck_auc_hand_computed():
    """F(tau) AUC of max errors 10 and 30.5 mm is 0.75; PCK AUC of errors 0 and 80 is 0.503125."""
    taus = threshold_grid_mm()
    # Trapezoid on the 1 mm grid counts 10 as 9.5 and 30.5 as 30.5: (70.5 + 49.5) / 160.
    assert curve_auc(taus, fraction_of_frames_within([10.0, 30.5], taus)) == pytest.approx(0.75)
    # 0 mm succeeds everywhere (1), 80 mm only at the last grid point (0.5 / 80).
    assert curve_auc(taus, pck([[0.0, 80.0]], taus)) == pytest.approx((1.0 + 0.5 / 80.0) / 2.0)


def test_evaluate_hand_poses_end_to_end():
    """The report of two frames with known errors has exact values and serializes to JSON."""
    offsets = np.zeros((2, 21))
    offsets[0, 4] = 0.010  # frame 0: thumb tip 10 mm off
    offsets[1, 8] = 0.0305  # frame 1: index tip 30.5 mm off
    pred, gt = hands(offsets)
    report = evaluate_hand_poses(pred, gt)
    assert report.n_frames == report.n_frames_evaluated == 2
    assert report.n_joints_evaluated == 42
    assert report.mean_mm == pytest.approx(40.5 / 42)
    assert report.median_mm == pytest.approx(0.0, abs=1e-9)
    assert report.mean_max_mm == pytest.approx(20.25)
    assert report.auc_f_tau == pytest.approx(0.75)
    assert report.per_joint_mean_mm["thumb_tip"] == pytest.approx(5.0)
    assert report.per_joint_mean_mm["index_tip"] == pytest.approx(15.25)
    assert list(report.per_joint_mean_mm) == list(KEYPOINT_NAMES)
    assert report.thresholds_mm[-1] == 80.0 and len(report.f_tau) == len(report.pck) == 81
    assert report.f_tau[10] == 0.5 and report.f_tau[31] == 1.0
    # 40 of 42 joints are exact: PCK(0) = 40 / 42.
    assert report.pck[0] == pytest.approx(40 / 42)
    json.dumps(report.to_dict(), allow_nan=False)


def test_evaluate_hand_poses_names_for_other_joint_counts():
    """With J != 21 the joints are named joint_<k> unless names are given."""
    pred, gt = np.zeros((1, 3, 3)), np.zeros((1, 3, 3))
    assert list(evaluate_hand_poses(pred, gt).per_joint_mean_mm) == [
        "joint_0",
        "joint_1",
        "joint_2",
    ]
    named = evaluate_hand_poses(pred, gt, joint_names=["a", "b", "c"])
    assert list(named.per_joint_mean_mm) == ["a", "b", "c"]


# Dexter+Object ---------------------------------------------------------------------------------


def test_dexter_object_combined_error_definition():
    """Combined = mean over 5 fingertips + K corners; hand and object parts are separate."""
    offsets = np.zeros((1, 21))
    offsets[0, list(FINGERTIP_INDICES)] = 0.010  # every fingertip 10 mm off
    offsets[0, 0] = 0.5  # the wrist is not part of the D+O error
    pred, gt = hands(offsets)
    corners_gt = np.zeros((1, 3, 3))
    corners_pred = corners_gt + np.array([0.0, 0.020, 0.0])  # the 3 D+O corners 20 mm off
    errs = dexter_object_errors_mm(pred, gt, corners_pred, corners_gt)
    assert errs.hand_mm[0] == pytest.approx(10.0)
    assert errs.object_mm[0] == pytest.approx(20.0)
    assert errs.combined_mm[0] == pytest.approx((5 * 10.0 + 3 * 20.0) / 8)
    # The 5 fingertips alone give the same numbers.
    tips = list(FINGERTIP_INDICES)
    errs5 = dexter_object_errors_mm(pred[:, tips], gt[:, tips], corners_pred, corners_gt)
    assert errs5.combined_mm[0] == pytest.approx(13.75)


def test_dexter_object_with_8_box_corners_of_a_pose():
    """The 8 corners of a handsim object posed by T_cam_from_obj work as the object part."""
    corners = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.03, 0.03) for z in (-1, 1)])
    corners = corners * np.array([1.0, 1.0, 0.02])
    T_gt = pose(t=(0.0, 0.0, 0.6))  # noqa: N806
    T_est = pose(t=(0.0, 0.0, 0.61))  # noqa: N806
    c_gt = transform_points(np.stack([T_gt, T_gt]), corners)
    c_est = transform_points(np.stack([T_est, T_est]), corners)
    assert c_gt.shape == (2, 8, 3)
    pred, gt = hands(np.zeros((2, 21)))
    report = evaluate_dexter_object(pred, gt, c_est, c_gt)
    assert report.n_corners == 8
    assert report.mean_hand_mm == pytest.approx(0.0)
    assert report.mean_object_mm == pytest.approx(10.0)
    assert report.mean_combined_mm == pytest.approx(8 * 10.0 / 13)
    json.dumps(report.to_dict(), allow_nan=False)


# Object pose -----------------------------------------------------------------------------------


def test_identity_pose_has_zero_errors():
    """An exact estimate has zero ADD, ADI, ADD-sym, MSSD and reprojection error."""
    pts = ring()
    T = pose((0.1, 0.2, 0.3), (0.01, -0.02, 0.5))  # noqa: N806
    sym = Symmetry.continuous((0.0, 1.0, 0.0))
    assert add_error_mm(T, T, pts) == 0.0
    assert adi_error_mm(T, T, pts) == 0.0
    assert add_sym_error_mm(T, T, pts, sym) == pytest.approx(0.0, abs=1e-9)
    assert mssd_error_mm(T, T, pts, NO_SYMMETRY) == pytest.approx(0.0, abs=1e-9)
    assert reprojection_error_px(T, T, pts, CAM) == 0.0


def test_pure_translation_gives_its_length():
    """A translation error t moves every point by |t|: ADD = MSSD = |t|."""
    pts = ring()
    T_gt = pose(t=(0.0, 0.0, 0.5))  # noqa: N806
    T_est = pose(t=(0.003, 0.004, 0.5))  # noqa: N806
    assert add_error_mm(T_est, T_gt, pts) == pytest.approx(5.0)
    assert mssd_error_mm(T_est, T_gt, pts, NO_SYMMETRY) == pytest.approx(5.0)


def test_adi_never_exceeds_add():
    """The nearest estimated point is never farther than the corresponding one (ADI <= ADD)."""
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(200, 3)) * 0.05
    for _ in range(10):
        T_gt = pose(rng.normal(size=3), rng.normal(size=3) * 0.1 + (0, 0, 0.5))  # noqa: N806
        T_est = pose(rng.normal(size=3), rng.normal(size=3) * 0.1 + (0, 0, 0.5))  # noqa: N806
        assert adi_error_mm(T_est, T_gt, pts) <= add_error_mm(T_est, T_gt, pts) + 1e-9


def test_symmetric_ring_add_large_adi_zero():
    """A 30 degree turn of a 12-point ring about its axis: ADD is a chord, ADI is 0."""
    pts = ring(12, 0.05)
    T_gt = pose(t=(0.0, 0.0, 0.5))  # noqa: N806
    T_est = T_gt @ pose((0.0, np.deg2rad(30.0), 0.0))  # noqa: N806
    chord_mm = 2 * 50.0 * np.sin(np.deg2rad(15.0))
    assert add_error_mm(T_est, T_gt, pts) == pytest.approx(chord_mm)
    assert adi_error_mm(T_est, T_gt, pts) == pytest.approx(0.0, abs=1e-9)
    sym = Symmetry.from_rotations([Rotation.from_euler("y", 30, degrees=True).as_matrix()])
    assert add_sym_error_mm(T_est, T_gt, pts, sym) == pytest.approx(0.0, abs=1e-9)
    assert mssd_error_mm(T_est, T_gt, pts, sym) == pytest.approx(0.0, abs=1e-9)
    assert mssd_error_mm(T_est, T_gt, pts, NO_SYMMETRY) == pytest.approx(chord_mm)


def test_bowl_add_large_adi_small_under_symmetry_rotation():
    """The bowl turned 37 degrees about its axis: ADD is large, ADI and ADD-sym are ~0."""
    bowl = get_object("024_bowl")
    assert bowl.symmetry.kind == "continuous"
    T_gt = pose((0.3, 0.0, 0.1), (0.02, -0.01, 0.6))  # noqa: N806
    T_est = T_gt @ pose(np.deg2rad(37.0) * np.asarray(bowl.symmetry.axis))  # noqa: N806
    add = add_error_mm(T_est, T_gt, bowl.model_points_m)
    adi = adi_error_mm(T_est, T_gt, bowl.model_points_m)
    assert add > 30.0
    assert adi < 3.0  # surface-sampling density, not pose error
    assert add_or_adi_error_mm(T_est, T_gt, bowl) == pytest.approx(adi)
    assert add_or_adi_error_mm(T_est, T_gt, bowl, symmetric=False) == pytest.approx(add)
    sym_add = add_sym_error_mm(T_est, T_gt, bowl.model_points_m, bowl.symmetry, n_continuous=360)
    assert sym_add == pytest.approx(0.0, abs=1e-6)
    assert is_add_correct(add_or_adi_error_mm(T_est, T_gt, bowl), bowl.diameter_m)
    assert not is_add_correct(add, bowl.diameter_m)


def test_a_soup_can_turned_about_its_axis_is_symmetric_in_depth_only():
    """ADD(-S) with modality="depth" uses ADI for the plain can; "texture" (default) ADD."""
    can = get_object("005_tomato_soup_can")
    T_gt = pose((0.3, 0.0, 0.1), (0.02, -0.01, 0.6))  # noqa: N806
    T_est = T_gt @ pose(np.deg2rad(50.0) * np.asarray(can.symmetry_of("depth").axis))  # noqa: N806
    add = add_error_mm(T_est, T_gt, can.model_points_m)
    adi = adi_error_mm(T_est, T_gt, can.model_points_m)
    assert add > 20.0 and adi < 3.0
    assert add_or_adi_error_mm(T_est, T_gt, can) == pytest.approx(add)
    assert add_or_adi_error_mm(T_est, T_gt, can, modality="depth") == pytest.approx(adi)
    depth = evaluate_object_poses([T_est], [T_gt], can, modality="depth")
    texture = evaluate_object_poses([T_est], [T_gt], can)
    assert depth.symmetric and not texture.symmetric
    assert depth.add_s_mm[0] == pytest.approx(adi) and texture.add_s_mm[0] == pytest.approx(add)
    with pytest.raises(InvalidMetricInput, match="modality must be one of"):
        add_or_adi_error_mm(T_est, T_gt, can, modality="rgb")


def test_non_symmetric_object_uses_add():
    """ADD(-S) of an object without symmetry is ADD."""
    obj = toy_object(ring())
    T_gt = pose(t=(0.0, 0.0, 0.5))  # noqa: N806
    T_est = T_gt @ pose((0.0, np.deg2rad(30.0), 0.0))  # noqa: N806
    assert add_or_adi_error_mm(T_est, T_gt, obj) == pytest.approx(
        add_error_mm(T_est, T_gt, obj.model_points_m)
    )


def test_add_correct_is_strict_at_a_tenth_of_the_diameter():
    """An ADD of exactly 0.1 * diameter is not correct; just below is."""
    assert add_threshold_mm(0.2) == 20.0
    assert not is_add_correct(20.0, 0.2)
    assert is_add_correct(np.nextafter(20.0, 0.0), 0.2)
    # End to end: a point at the origin moved by 0.02 m gives ADD = 20 mm exactly.
    add = add_error_mm(pose(t=(0.02, 0.0, 0.0)), np.eye(4), [[0.0, 0.0, 0.0]])
    assert add == 20.0
    assert not is_add_correct(add, 0.2)
    assert not is_add_correct(None, 0.2) and not is_add_correct(math.nan, 0.2)


def test_reprojection_error_hand_computed_and_strict_at_5_px():
    """Shifting the object by 5/512 m at 1 m shifts every pixel by exactly 5 px: not correct."""
    pts = np.array([[0.0625, 0.125, 0.0], [-0.25, 0.0, 0.0], [0.0, -0.0625, 0.0]])
    T_gt = pose(t=(0.0, 0.0, 1.0))  # noqa: N806
    err = reprojection_error_px(pose(t=(5 / 512, 0.0, 1.0)), T_gt, pts, CAM)
    assert err == 5.0
    assert not is_reprojection_correct(err)
    just_below = reprojection_error_px(pose(t=(4.5 / 512, 0.0, 1.0)), T_gt, pts, CAM)
    assert just_below == 4.5 and is_reprojection_correct(just_below)
    assert is_reprojection_correct(np.nextafter(5.0, 0.0))


def test_reprojection_of_an_estimate_behind_the_camera_is_infinite():
    """An estimate that puts points behind the camera does not project: error inf."""
    pts = ring()
    err = reprojection_error_px(pose(t=(0.0, 0.0, -1.0)), pose(t=(0.0, 0.0, 1.0)), pts, CAM)
    assert err == math.inf and not is_reprojection_correct(err)


# YCB-Video AUC ---------------------------------------------------------------------------------


def test_ycbv_auc_hand_computed_with_a_miss():
    """Errors 20 and 50 mm plus a miss: PoseCNN VOCap 0.6, exact area 1.3 / 3."""
    errors = [20.0, 50.0, None]
    # VOCap: 20 * 1/3 + 30 * 2/3 + 50 * 2/3 = 60 of 100.
    assert ycbv_auc(errors) == pytest.approx(0.6)
    assert ycbv_auc(errors, rule="exact") == pytest.approx((0.8 + 0.5 + 0.0) / 3)
    # For distinct errors VOCap = exact + d_max / (n * 100 mm).
    assert ycbv_auc(errors) == pytest.approx(ycbv_auc(errors, rule="exact") + 50.0 / 300.0)


def test_ycbv_auc_misses_stay_in_the_denominator():
    """None, NaN, inf and errors above 0.1 m all count as misses in the denominator."""
    assert ycbv_auc([20.0]) == pytest.approx(1.0)
    for miss in (None, math.nan, math.inf, 150.0):
        assert ycbv_auc([20.0, miss]) == pytest.approx(0.5)
        assert ycbv_auc([20.0, miss], rule="exact") == pytest.approx(0.4)
    assert ycbv_auc([None, None]) == 0.0
    assert ycbv_auc(np.array([0.0, 0.0])) == pytest.approx(1.0)


def test_ycbv_accuracy_curve_counts_misses():
    """The accuracy curve divides by every frame, misses included."""
    curve = ycbv_accuracy_curve([20.0, 50.0, None, math.nan], [0.0, 20.0, 50.0, 100.0])
    np.testing.assert_allclose(curve, [0.0, 0.25, 0.5, 0.5])


def test_evaluate_object_poses_with_misses():
    """Misses (None / NaN matrix) are in every denominator; the report is JSON-serializable."""
    obj = toy_object(ring(), diameter_m=0.1)
    T_gt = pose(t=(0.0, 0.0, 1.0))  # noqa: N806
    estimates = [
        T_gt,  # exact
        pose(t=(0.02, 0.0, 1.0)),  # 20 mm off: ADD wrong (threshold 10 mm)
        None,
        np.full((4, 4), np.nan),
    ]
    report = evaluate_object_poses(estimates, [T_gt] * 4, obj, intrinsics=CAM)
    assert report.n_frames == 4 and report.n_missed == 2
    assert not report.symmetric
    assert report.add_mm[:2] == pytest.approx([0.0, 20.0]) and report.add_mm[2:] == [None, None]
    assert report.accuracy_add_s == pytest.approx(0.25)
    assert report.accuracy_reprojection == pytest.approx(0.25)
    assert report.mean_add_s_mm == pytest.approx(10.0)
    assert report.auc_add == pytest.approx(ycbv_auc([0.0, 20.0, None, None]))
    assert report.diameter_mm == pytest.approx(100.0)
    json.dumps(report.to_dict(), allow_nan=False)


def test_evaluate_object_poses_symmetric_uses_adi():
    """For a symmetric object ADD(-S) is ADI, and its AUC ignores the symmetry turn."""
    sym = Symmetry.continuous((0.0, 1.0, 0.0))
    obj = toy_object(ring(), symmetry=sym)
    T_gt = pose(t=(0.0, 0.0, 1.0))  # noqa: N806
    report = evaluate_object_poses([T_gt @ pose((0.0, np.pi / 6, 0.0))], [T_gt], obj)
    assert report.symmetric
    assert report.add_s_mm[0] == pytest.approx(0.0, abs=1e-9)
    assert report.add_mm[0] > 20.0
    assert report.accuracy_add_s == 1.0
    assert report.reprojection_px is None and report.accuracy_reprojection is None


# Breakdowns ------------------------------------------------------------------------------------


def test_errors_by_occlusion_buckets():
    """Buckets are [lo, hi) with the last one closed; misses are counted, not averaged."""
    errors = [1.0, 2.0, 3.0, 4.0, 5.0, None]
    occlusion = [0.0, 0.1, 0.2, 0.5, 1.0, 0.99]
    buckets = errors_by_occlusion(errors, occlusion)
    assert [(b.lower, b.upper) for b in buckets] == [
        (0.0, 0.2),
        (0.2, 0.4),
        (0.4, 0.6),
        (0.6, 0.8),
        (0.8, 1.0),
    ]
    assert [b.n_frames for b in buckets] == [2, 1, 1, 0, 2]
    assert buckets[0] == BucketStats(0.0, 0.2, 2, 0, 1.5, 1.5, 2.0)
    assert buckets[3].mean is None and buckets[3].median is None
    assert buckets[4].n_missed == 1 and buckets[4].mean == 5.0
    json.dumps([b.to_dict() for b in buckets], allow_nan=False)
    custom = errors_by_occlusion([1.0, 3.0], [0.25, 0.75], edges=[0.0, 0.5, 1.0])
    assert [b.mean for b in custom] == [1.0, 3.0]


def test_errors_by_joint():
    """Per-joint statistics skip unevaluated entries; a never-evaluated joint has None."""
    errors = np.array([[1.0, np.nan, 4.0], [3.0, np.nan, 8.0]])
    stats = errors_by_joint(errors, ["a", "b", "c"])
    assert stats["a"].mean_mm == 2.0 and stats["a"].n == 2
    assert stats["b"].n == 0 and stats["b"].mean_mm is None
    assert stats["c"].max_mm == 8.0 and stats["c"].median_mm == 6.0
    json.dumps({k: v.to_dict() for k, v in stats.items()}, allow_nan=False)
    assert list(errors_by_joint(np.zeros((1, 21)))) == list(KEYPOINT_NAMES)


# Plots -----------------------------------------------------------------------------------------


def test_plots_write_png(tmp_path):
    """F(tau) and PCK plots of several methods are written as non-empty PNGs."""
    offsets = np.zeros((2, 21))
    offsets[1, 4] = 0.02
    report = evaluate_hand_poses(*hands(offsets))
    rng = np.random.default_rng(2)
    joint_errors = rng.uniform(0.0, 60.0, size=(50, 21))
    methods = {"oracle": report, "noisy": joint_errors, "per-frame max": joint_errors.max(axis=1)}
    for fn, name in ((plot_f_tau, "f_tau.png"), (plot_pck, "sub/pck.png")):
        methods_here = methods if fn is plot_f_tau else {"oracle": report, "noisy": joint_errors}
        path = fn(methods_here, tmp_path / name, title="test")
        assert path == tmp_path / name
        data = path.read_bytes()
        assert len(data) > 1000 and data.startswith(PNG_MAGIC)


def test_import_does_not_load_matplotlib_or_torch():
    """Importing handsim.metrics loads neither matplotlib (lazy, plots only) nor torch."""
    code = (
        "import sys, handsim.metrics; "
        "assert 'matplotlib' not in sys.modules and 'torch' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# Bad input -------------------------------------------------------------------------------------


def test_error_class_is_a_handsim_value_error():
    """InvalidMetricInput is a HandSimError and a ValueError."""
    assert issubclass(InvalidMetricInput, HandSimError)
    assert issubclass(InvalidMetricInput, ValueError)


Z = np.zeros((2, 21, 3))
NAN_GT = Z.copy()
NAN_GT[1, 3, 0] = np.nan


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (
            lambda: keypoint_errors_mm(Z, np.zeros((2, 20, 3))),
            r"pred_m and gt_m must have the same shape \(N, J, 3\); received "
            r"\(2, 21, 3\) and \(2, 20, 3\)",
        ),
        (
            lambda: keypoint_errors_mm(np.zeros((21, 3)), np.zeros((21, 3))),
            r"pred_m must be an \(N, J, 3\) array of keypoints in metres; received shape "
            r"\(21, 3\) \(add a batch axis",
        ),
        (
            lambda: keypoint_errors_mm(np.zeros((0, 21, 3)), np.zeros((0, 21, 3))),
            r"pred_m must hold at least one frame and one joint; received shape \(0, 21, 3\)",
        ),
        (
            lambda: keypoint_errors_mm(Z, NAN_GT),
            r"gt_m has a non-finite value at frame 1, joint 3; expected finite metres at every "
            r"evaluated joint",
        ),
        (
            lambda: keypoint_errors_mm(Z, Z, np.ones((2, 20), bool)),
            r"visible must be an \(N, J\) = \(2, 21\) mask; received shape \(2, 20\)",
        ),
        (
            lambda: keypoint_errors_mm(Z, Z, np.full((2, 21), 2)),
            r"visible must be boolean \(or 0/1\); received values other than 0 and 1",
        ),
        (
            lambda: evaluate_hand_poses(Z, Z, visible=np.zeros((2, 21), bool)),
            r"no joint is evaluated: `visible` is False everywhere",
        ),
        (
            lambda: evaluate_hand_poses(Z, Z, joint_names=["a"]),
            r"joint_names must be 21 distinct names \(one per joint\); received 1 names",
        ),
        (
            lambda: fraction_of_frames_within([1.0, 2.0], [10.0, -1.0]),
            r"thresholds_mm must be >= 0; received minimum -1.0",
        ),
        (
            lambda: fraction_of_frames_within([1.0], [np.nan]),
            r"thresholds_mm must be finite; received \[nan\]",
        ),
        (
            lambda: fraction_of_frames_within([], [1.0]),
            r"frame_max_errors_mm must hold at least one evaluated \(non-NaN\) frame; received "
            r"0 frames, 0 evaluated",
        ),
        (
            lambda: fraction_of_frames_within([np.nan], [1.0]),
            r"received 1 frames, 0 evaluated",
        ),
        (
            lambda: fraction_of_frames_within([[1.0]], [1.0]),
            r"frame_max_errors_mm must be a 1-D array of per-frame errors in mm; received shape "
            r"\(1, 1\)",
        ),
        (
            lambda: fraction_of_frames_within([-3.0], [1.0]),
            r"frame_max_errors_mm must be >= 0 \(NaN = not evaluated, \+inf = no estimate\); "
            r"received minimum -3.0",
        ),
        (
            lambda: pck([np.nan, np.nan], [1.0]),
            r"joint_errors_mm must hold at least one evaluated \(non-NaN\) joint; received none",
        ),
        (
            lambda: pck([1.0], []),
            r"thresholds_mm must be a non-empty 1-D array of thresholds; received shape \(0,\)",
        ),
        (
            lambda: curve_auc([0.0, 1.0], [1.0]),
            r"thresholds and values must be 1-D of the same length >= 2; received shapes "
            r"\(2,\) and \(1,\)",
        ),
        (
            lambda: curve_auc([0.0, 0.0], [1.0, 1.0]),
            r"thresholds must be strictly increasing; received \[0.0, 0.0\]",
        ),
        (
            lambda: curve_auc([0.0, 1.0], [1.0, np.nan]),
            r"thresholds and values must be finite; received a NaN or inf",
        ),
        (
            lambda: threshold_grid_mm(80.0, 3.0),
            r"tau_max_mm must be a whole multiple of step_mm; received tau_max_mm=80.0, "
            r"step_mm=3.0",
        ),
        (
            lambda: threshold_grid_mm(-80.0),
            r"tau_max_mm must be a positive finite number; received -80.0",
        ),
        (
            lambda: threshold_grid_mm(80.0, "x"),
            r"step_mm must be a positive number; received 'x'",
        ),
        (
            lambda: dexter_object_errors_mm(
                np.zeros((1, 6, 3)), np.zeros((1, 6, 3)), np.zeros((1, 3, 3)), np.zeros((1, 3, 3))
            ),
            r"pred_hand_m must hold 21 canonical keypoints or the 5 fingertips "
            r"\(N, 21 or 5, 3\); received shape \(1, 6, 3\)",
        ),
        (
            lambda: dexter_object_errors_mm(Z, Z, np.zeros((3, 3, 3)), np.zeros((3, 3, 3))),
            r"the hand and corner arrays must have the same number of frames; received 2 and 3",
        ),
        (
            lambda: dexter_object_errors_mm(Z, Z, np.zeros((2, 3, 3)), np.zeros((2, 8, 3))),
            r"pred_corners_m and gt_corners_m must have the same shape \(N, J, 3\); received "
            r"\(2, 3, 3\) and \(2, 8, 3\)",
        ),
        (
            lambda: add_error_mm(np.eye(3), np.eye(4), ring()),
            r"T_est must be a \(4, 4\) homogeneous transform T_cam_from_obj in metres; received "
            r"shape \(3, 3\)",
        ),
        (
            lambda: add_error_mm(None, np.eye(4), ring()),
            r"T_est must be a \(4, 4\) transform; received None \(frames without an estimate are "
            r"misses",
        ),
        (
            lambda: add_error_mm(np.eye(4), np.full((4, 4), np.nan), ring()),
            r"T_gt must be finite; received a NaN or inf entry",
        ),
        (
            lambda: adi_error_mm(np.eye(4), np.ones((4, 4)), ring()),
            r"T_gt must have the last row \(0, 0, 0, 1\); received \[1.0, 1.0, 1.0, 1.0\]",
        ),
        (
            lambda: add_error_mm(np.eye(4), np.eye(4), np.zeros((0, 3))),
            r"model_points_m must be an \(M, 3\) array with M >= 1, metres, object frame; "
            r"received shape \(0, 3\)",
        ),
        (
            lambda: add_error_mm(np.eye(4), np.eye(4), [[np.nan, 0.0, 0.0]]),
            r"model_points_m must be finite; received a NaN or inf",
        ),
        (
            lambda: add_or_adi_error_mm(np.eye(4), np.eye(4), object()),
            r"obj must be a YCBObject \(or have model_points_m, diameter_m and symmetry\); "
            r"received object",
        ),
        (
            lambda: add_or_adi_error_mm(
                np.eye(4), np.eye(4), types.SimpleNamespace(model_points_m=ring())
            ),
            r"obj must have a `symmetry` \(handsim.world.Symmetry\) or symmetric= must be given",
        ),
        (
            lambda: add_sym_error_mm(np.eye(4), np.eye(4), ring(), "continuous"),
            r"symmetry must be a handsim.world.Symmetry; received str",
        ),
        (
            lambda: mssd_error_mm(np.eye(4), np.eye(4), ring(), NO_SYMMETRY, n_continuous=0),
            r"n_continuous must be an integer >= 1; received 0",
        ),
        (
            lambda: reprojection_error_px(np.eye(4), np.eye(4), ring(), np.eye(3)),
            r"intrinsics must be a handsim.world.camera.CameraIntrinsics; received ndarray",
        ),
        (
            lambda: reprojection_error_px(pose(t=(0, 0, 1)), pose(t=(0, 0, -1)), ring(), CAM),
            r"T_gt puts model points at z <= 0 \(behind the camera; minimum z -1.05 m\); expected "
            r"every ground-truth point in front of it",
        ),
        (
            lambda: is_add_correct(-1.0, 0.1),
            r"error_mm must be >= 0 \(or None for a miss\); received -1.0",
        ),
        (
            lambda: is_add_correct(1.0, 0.0),
            r"diameter_m must be a positive finite number; received 0.0",
        ),
        (
            lambda: is_add_correct("x", 0.1),
            r"error_mm must be a number or None; received 'x'",
        ),
        (
            lambda: is_reprojection_correct(1.0, threshold_px=-5.0),
            r"threshold_px must be a positive finite number; received -5.0",
        ),
        (
            lambda: ycbv_auc([]),
            r"errors_mm must hold at least one frame; received 0",
        ),
        (
            lambda: ycbv_auc([1.0, -2.0]),
            r"errors_mm must be >= 0 \(or None for a miss\); received -2.0",
        ),
        (
            lambda: ycbv_auc([1.0], rule="trapezoid"),
            r"rule must be 'posecnn' or 'exact'; received 'trapezoid'",
        ),
        (
            lambda: ycbv_auc(np.zeros((2, 2))),
            r"errors_mm must be a 1-D sequence of per-frame errors; received shape \(2, 2\)",
        ),
        (
            lambda: ycbv_auc(3.0),
            r"errors_mm must be a sequence of per-frame errors \(None / NaN for a miss\); "
            r"received float",
        ),
        (
            lambda: ycbv_accuracy_curve([1.0], [-0.5]),
            r"thresholds_mm must be >= 0; received minimum -0.5",
        ),
        (
            lambda: evaluate_object_poses([np.eye(4)], [np.eye(4)] * 2, toy_object(ring())),
            r"T_est and T_gt must have one pose per frame; received 1 and 2",
        ),
        (
            lambda: evaluate_object_poses([], [], toy_object(ring())),
            r"expected at least one frame; received 0 poses",
        ),
        (
            lambda: evaluate_object_poses([np.eye(4)], [None], toy_object(ring())),
            r"T_gt\[0\] must be a \(4, 4\) transform; received None",
        ),
        (
            lambda: transform_points(np.zeros((2, 3, 3)), ring()),
            r"T must be a \(4, 4\) or \(N, 4, 4\) transform array; received shape \(2, 3, 3\)",
        ),
        (
            lambda: errors_by_occlusion([1.0, 2.0], [0.5]),
            r"occlusion must have one ratio per frame, shape \(2,\); received \(1,\)",
        ),
        (
            lambda: errors_by_occlusion([1.0], [1.5]),
            r"occlusion ratios must be finite and in \[0.0, 1.0\] \(the edges\); received range "
            r"\[1.5, 1.5\]",
        ),
        (
            lambda: errors_by_occlusion([1.0], [0.5], edges=[0.0, 0.5, 0.5, 1.0]),
            r"edges must be >= 2 strictly increasing values in \[0, 1\]; received "
            r"\[0.0, 0.5, 0.5, 1.0\]",
        ),
        (
            lambda: errors_by_occlusion([], []),
            r"errors must hold at least one frame; received 0",
        ),
        (
            lambda: errors_by_joint(np.zeros(3)),
            r"joint_errors_mm must be an \(N, J\) array with N, J >= 1; received shape \(3,\)",
        ),
        (
            lambda: errors_by_joint(-np.ones((1, 2))),
            r"joint_errors_mm must be >= 0 \(NaN = not evaluated, \+inf = no estimate\); "
            r"received minimum -1.0",
        ),
        (
            lambda: plot_f_tau({}, "/tmp/met/never.png"),
            r"methods must be a non-empty mapping of method name -> errors or report; "
            r"received \{\}",
        ),
        (
            lambda: plot_pck({"a": [1.0]}, "/tmp/met/never.pdf"),
            r"path must end in .png; received '/tmp/met/never.pdf'",
        ),
        (
            lambda: keypoint_errors_mm([["a"]], Z),
            r"pred_m must be an array of numbers; received list",
        ),
    ],
)
def test_bad_input_messages(call, match):
    """Every invalid input raises InvalidMetricInput with a message saying what was wrong."""
    with pytest.raises(InvalidMetricInput, match=match):
        call()
