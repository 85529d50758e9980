"""The estimator protocol: Estimate validation, the protocols, hand_center, estimate_errors."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.errors import InvalidEstimate, InvalidEstimatorInput, InvalidKeypoints
from handsim.estimator import (
    HAND_CENTER_INDICES,
    Estimate,
    Estimator,
    EstimatorBase,
    PrivilegedEstimator,
    estimate_errors,
    hand_center,
    validate_batch_input,
    validate_depth_input,
)
from handsim.frame import ObjectLabel
from handsim.world.symmetry import Symmetry

K = np.array([[241.42, 0.0, 160.0], [0.0, 241.42, 120.0], [0.0, 0.0, 1.0]])


def _keypoints(seed: int = 0) -> np.ndarray:
    """21 distinct keypoints around 0.5 m in front of the camera."""
    return np.random.default_rng(seed).normal([0.0, 0.0, 0.5], 0.05, size=(21, 3))


def _pose(rotvec=(0.0, 0.0, 0.0), t=(0.0, 0.0, 0.5)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def _label(instance: int, name: str, T: np.ndarray) -> ObjectLabel:
    return ObjectLabel(instance, name, None, T, np.zeros((8, 3)), 1.0, 100, 100)


def _frame(keypoints: np.ndarray, objects=()) -> SimpleNamespace:
    """The fields of a Frame that estimate_errors reads."""
    return SimpleNamespace(keypoints_cam=keypoints, objects=tuple(objects))


# Estimate ----------------------------------------------------------------------------------------


def test_estimate_stores_read_only_float64_copies():
    """Arrays are copied, float64 and read-only; the centre defaults to hand_center."""
    kp = _keypoints().astype(np.float32)
    est = Estimate(keypoints_cam=kp, object_poses={np.int64(2): _pose()})
    assert est.keypoints_cam.dtype == np.float64 and not est.keypoints_cam.flags.writeable
    kp[0] = 99.0
    assert est.keypoints_cam[0, 0] != 99.0
    np.testing.assert_array_equal(est.center_cam, hand_center(est.keypoints_cam))
    assert list(est.object_poses) == [2] and type(next(iter(est.object_poses))) is int
    with pytest.raises(ValueError):
        est.center_cam[0] = 1.0


def test_explicit_center_is_kept():
    """A given center_cam is not replaced by the keypoints' centre."""
    est = Estimate(keypoints_cam=_keypoints(), center_cam=(0.1, 0.2, 0.3))
    np.testing.assert_array_equal(est.center_cam, [0.1, 0.2, 0.3])


def test_invalid_estimate_carries_nothing():
    """Estimate(valid=False) is the 'no estimate' value; it refuses content."""
    est = Estimate(valid=False)
    assert not est.valid and est.keypoints_cam is None and est.object_poses == {}
    with pytest.raises(InvalidEstimate, match=r"invalid estimate .* carries nothing; received "):
        Estimate(keypoints_cam=_keypoints(), valid=False)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({}, r"valid estimate needs keypoints_cam, center_cam or object_poses; received none"),
        (
            {"keypoints_cam": np.zeros((20, 3))},
            r"keypoints_cam must have shape \(21, 3\); "
            r"received shape \(20, 3\)",
        ),
        ({"keypoints_cam": np.full((21, 3), np.nan)}, r"keypoints_cam must be finite; received"),
        ({"keypoints_cam": "abc"}, r"keypoints_cam must be a \(21, 3\) array of numbers"),
        ({"center_cam": (0.0, 0.0)}, r"center_cam must have shape \(3,\); received shape \(2,\)"),
        ({"center_cam": (0.0, np.inf, 1.0)}, r"center_cam must be finite"),
        ({"confidence": np.ones(21), "center_cam": (0, 0, 1)}, r"confidence .* needs keypoints"),
        (
            {"keypoints_cam": _keypoints(), "confidence": np.full(21, 1.5)},
            r"confidence must lie in \[0, 1\]; received min 1.5",
        ),
        (
            {"keypoints_cam": _keypoints(), "confidence": np.ones(20)},
            r"confidence must have shape \(21,\)",
        ),
        ({"object_poses": {-1: _pose()}}, r"keys must be object instance indices .* received -1"),
        ({"object_poses": {0: np.eye(3)}}, r"object_poses\[0\] must have shape \(4, 4\)"),
        ({"object_poses": {0: 2 * np.eye(4)}}, r"last row \(0, 0, 0, 1\)"),
        ({"object_poses": {0: np.diag([2.0, 1.0, 1.0, 1.0])}}, r"must be a rotation"),
        ({"object_poses": {0: np.diag([-1.0, 1.0, 1.0, 1.0])}}, r"must be a rotation .* det -1"),
        ({"object_poses": [np.eye(4)]}, r"object_poses must be a dict .* received list"),
        ({"center_cam": (0, 0, 1), "valid": 1}, r"valid must be a bool; received 1"),
    ],
)
def test_estimate_rejects_bad_fields(kwargs, message):
    """Every malformed field raises InvalidEstimate saying what was expected and received."""
    with pytest.raises(InvalidEstimate, match=message):
        Estimate(**kwargs)


def test_object_only_estimate_is_valid():
    """An estimate with object poses only is valid and has no hand centre."""
    est = Estimate(object_poses={0: _pose()})
    assert est.valid and est.center_cam is None and est.keypoints_cam is None


# hand_center -------------------------------------------------------------------------------------


def test_hand_center_is_the_mean_of_wrist_and_mcps():
    """The centre is the mean of keypoints 0, 5, 9, 13, 17 and works on batches."""
    kp = _keypoints()
    assert HAND_CENTER_INDICES == (0, 5, 9, 13, 17)
    expected = (kp[0] + kp[5] + kp[9] + kp[13] + kp[17]) / 5
    np.testing.assert_allclose(hand_center(kp), expected, rtol=0, atol=1e-15)
    batch = np.stack([kp, kp + 1.0])
    np.testing.assert_allclose(hand_center(batch), [expected, expected + 1.0], atol=1e-15)
    moved = kp.copy()
    moved[[4, 8, 12, 16, 20]] += 0.1  # fingertips do not move the centre
    np.testing.assert_array_equal(hand_center(moved), hand_center(kp))


def test_hand_center_rejects_other_shapes():
    """A wrong keypoint shape raises InvalidKeypoints."""
    with pytest.raises(InvalidKeypoints, match=r"\(\.\.\., 21, 3\) keypoints .* shape \(14, 3\)"):
        hand_center(np.zeros((14, 3)))


# Protocols ---------------------------------------------------------------------------------------


class _Fixed(EstimatorBase):
    """Returns a fixed centre; counts its calls."""

    def __init__(self) -> None:
        self.calls = 0

    def predict(self, depth, K):  # noqa: N803
        self.calls += 1
        validate_depth_input(depth, K)
        return Estimate(center_cam=(0.0, 0.0, float(depth.max())))


class _Privileged(_Fixed):
    def observe_truth(self, frame) -> None:
        self.truth = frame


def test_protocols_are_structural():
    """Any object with the methods is an Estimator; observe_truth makes it privileged."""
    assert isinstance(_Fixed(), Estimator)
    assert not isinstance(_Fixed(), PrivilegedEstimator)
    assert isinstance(_Privileged(), PrivilegedEstimator)
    assert not isinstance(object(), Estimator)

    class _NoReset:
        def predict(self, depth, K): ...  # noqa: N803

        def predict_batch(self, depths, Ks): ...  # noqa: N803

    assert not isinstance(_NoReset(), Estimator)


def test_estimator_base_predict_batch_loops_in_order():
    """The default predict_batch calls predict once per image, in batch order."""
    est = _Fixed()
    depths = np.stack([np.full((4, 5), z, np.float32) for z in (0.5, 0.7, 0.9)])
    out = est.predict_batch(depths, np.stack([K] * 3))
    assert est.calls == 3
    assert [e.center_cam[2] for e in out] == pytest.approx([0.5, 0.7, 0.9])
    with pytest.raises(NotImplementedError, match="must implement predict"):
        EstimatorBase().predict(depths[0], K)


@pytest.mark.parametrize(
    ("depth", "k", "message"),
    [
        (np.zeros((2, 3, 4)), K, r"depth must be an \(H, W\) image .* shape \(2, 3, 4\)"),
        (np.array([[0.5, np.nan]]), K, r"finite metres >= 0 .* received nan at pixel \(v=0, u=1\)"),
        (np.array([[0.5, -0.1]]), K, r"received -0.1 at pixel"),
        (np.ones((2, 2)), np.eye(2), r"K must be a finite \(3, 3\) intrinsic matrix"),
        (np.ones((2, 2)), np.diag([-1.0, 1.0, 1.0]), r"fx, fy > 0"),
    ],
)
def test_validate_depth_input_rejects_bad_input(depth, k, message):
    """Bad depth images and matrices raise InvalidEstimatorInput."""
    with pytest.raises(InvalidEstimatorInput, match=message):
        validate_depth_input(depth, k)


def test_validate_batch_input_checks_the_batch_size():
    """Ks must hold one matrix per image."""
    with pytest.raises(InvalidEstimatorInput, match=r"Ks must be \(2, 3, 3\), one matrix per"):
        validate_batch_input(np.ones((2, 4, 4)), np.stack([K] * 3))
    with pytest.raises(InvalidEstimatorInput, match=r"\(B, H, W\) batch .* shape \(4, 4\)"):
        validate_batch_input(np.ones((4, 4)), K)


# estimate_errors ---------------------------------------------------------------------------------


def test_ten_mm_offset_gives_ten_mm_errors():
    """Every keypoint 10 mm off along x: mean, max and centre errors are exactly 10 mm."""
    kp = _keypoints()
    errors = estimate_errors(Estimate(keypoints_cam=kp + [0.010, 0.0, 0.0]), _frame(kp))
    assert errors["kp_mean_mm"] == pytest.approx(10.0, abs=1e-9)
    assert errors["kp_max_mm"] == pytest.approx(10.0, abs=1e-9)
    assert errors["center_mm"] == pytest.approx(10.0, abs=1e-9)


def test_one_keypoint_off_separates_mean_and_max():
    """One fingertip 21 mm off: mean 1 mm, max 21 mm, centre unchanged (0 mm)."""
    kp = _keypoints()
    est = kp.copy()
    est[8] += [0.0, 0.0, 0.021]
    errors = estimate_errors(Estimate(keypoints_cam=est), _frame(kp))
    assert errors["kp_mean_mm"] == pytest.approx(1.0, abs=1e-9)
    assert errors["kp_max_mm"] == pytest.approx(21.0, abs=1e-9)
    assert errors["center_mm"] == pytest.approx(0.0, abs=1e-9)


def test_invalid_estimate_gives_nan():
    """An invalid estimate has NaN for every error, objects included."""
    frame = _frame(_keypoints(), [_label(0, "box", _pose())])
    errors = estimate_errors(Estimate(valid=False), frame)
    assert math.isnan(errors["kp_mean_mm"]) and math.isnan(errors["kp_max_mm"])
    assert math.isnan(errors["center_mm"])
    assert math.isnan(errors["add_mm"][0]) and math.isnan(errors["adi_mm"][0])


def test_centre_only_estimate_has_nan_keypoint_errors():
    """A localizer's estimate (centre only) gets a centre error and NaN keypoint errors."""
    kp = _keypoints()
    c = hand_center(kp) + [0.0, 0.003, -0.004]
    errors = estimate_errors(Estimate(center_cam=c), _frame(kp))
    assert errors["center_mm"] == pytest.approx(5.0, abs=1e-9)
    assert math.isnan(errors["kp_mean_mm"])


def test_object_errors_use_add_adi_and_symmetry():
    """A 4 mm shift gives ADD 4 mm; a turn about a can's axis costs ADD but not ADI/ADD(-S)."""
    rng = np.random.default_rng(1)
    theta = rng.uniform(0, 2 * np.pi, 4000)
    height = rng.uniform(-0.05, 0.05, 4000)
    can_points = np.stack([0.03 * np.cos(theta), 0.03 * np.sin(theta), height], axis=1)
    can = SimpleNamespace(model_points_m=can_points, symmetry=Symmetry.continuous((0, 0, 1)))
    box = SimpleNamespace(model_points_m=rng.uniform(-0.05, 0.05, (500, 3)), symmetry=Symmetry())
    T_can = _pose((0.3, 0.0, 0.0), (0.1, 0.0, 0.6))  # noqa: N806
    T_box = _pose((0.0, 0.2, 0.0), (-0.1, 0.0, 0.6))  # noqa: N806
    frame = _frame(_keypoints(), [_label(0, "can", T_can), _label(1, "box", T_box)])
    turned = T_can @ _pose((0.0, 0.0, 0.5), (0.0, 0.0, 0.0))  # 0.5 rad about the can's axis
    shifted = T_box.copy()
    shifted[:3, 3] += [0.0, 0.004, 0.0]
    errors = estimate_errors(
        Estimate(object_poses={0: turned, 1: shifted}), frame, objects=[can, box]
    )
    assert errors["add_mm"][1] == pytest.approx(4.0, abs=1e-9)
    assert errors["add_or_adi_mm"][1] == errors["add_mm"][1]  # no symmetry: ADD
    # ADD of a 0.5 rad turn on a 30 mm radius: chord 2 r sin(0.25) = 14.8 mm.
    assert errors["add_mm"][0] == pytest.approx(2 * 30 * np.sin(0.25), rel=1e-6)
    assert errors["adi_mm"][0] < 1.5  # nearest-neighbour spacing of the samples
    assert errors["add_or_adi_mm"][0] == errors["adi_mm"][0]  # continuous symmetry: ADI
    # Without that instance in the estimate: NaN.
    partial = estimate_errors(Estimate(object_poses={1: shifted}), frame, objects=[can, box])
    assert math.isnan(partial["add_mm"][0]) and partial["add_mm"][1] == pytest.approx(4.0)


def test_object_errors_name_the_problem():
    """Unknown instances and objects without a built-in model raise with the fix."""
    frame = _frame(_keypoints(), [_label(0, "my_mesh", _pose())])
    with pytest.raises(InvalidEstimate, match=r"instances \[3\] that the frame does not have"):
        estimate_errors(Estimate(object_poses={3: _pose()}), frame)
    with pytest.raises(InvalidEstimatorInput, match=r"'my_mesh'\) is not a built-in .* objects="):
        estimate_errors(Estimate(object_poses={0: _pose()}), frame)
    with pytest.raises(InvalidEstimatorInput, match=r"one YCBObject per frame object .* \(1\)"):
        estimate_errors(Estimate(object_poses={0: _pose()}), frame, objects=[])


def test_object_errors_equal_the_metrics_and_reuse_one_tree_per_object():
    """ADD, ADI and ADD(-S) equal handsim.metrics (symmetric objects too); trees are cached."""
    from handsim.estimator import _model_tree
    from handsim.metrics import add_error_mm, add_or_adi_error_mm, adi_error_mm
    from handsim.world.registry import OBJECTS, get_object

    rng = np.random.default_rng(3)
    # Two continuous symmetries, a discrete one and none (building all 21 takes ~40 s).
    names = ["002_master_chef_can", "024_bowl", "061_foam_brick", "003_cracker_box"]
    assert set(names) <= set(OBJECTS)
    labels, poses, models = [], {}, []
    for k, name in enumerate(names):
        T_gt = _pose(tuple(rng.normal(scale=0.5, size=3)), (0.1 * k, 0.0, 0.6))  # noqa: N806
        labels.append(_label(k, name, T_gt))
        poses[k] = T_gt @ _pose(tuple(rng.normal(scale=0.2, size=3)), tuple(rng.normal(0, 0.01, 3)))
        models.append(get_object(name))
    frame = _frame(_keypoints(), labels)
    errors = estimate_errors(Estimate(object_poses=poses), frame)
    for k, model in enumerate(models):
        T_gt = labels[k].T_cam_from_obj  # noqa: N806
        pts = model.model_points_m
        assert errors["add_mm"][k] == pytest.approx(add_error_mm(poses[k], T_gt, pts), abs=1e-9)
        assert errors["adi_mm"][k] == pytest.approx(adi_error_mm(poses[k], T_gt, pts), abs=1e-9)
        assert errors["add_or_adi_mm"][k] == pytest.approx(
            add_or_adi_error_mm(poses[k], T_gt, model), abs=1e-9
        )
        assert _model_tree(model)[1] is _model_tree(model)[1]


def test_estimate_errors_and_hand_center_refuse_what_they_cannot_measure():
    """No frame, a non-Estimate, keypoints with NaN at the centre: named errors, not NaN."""
    from handsim.errors import InvalidEstimatorInput, InvalidKeypoints
    from handsim.estimator import Estimate, InvalidEstimate, estimate_errors, hand_center

    with pytest.raises(InvalidEstimatorInput, match=r"frame must be the ground-truth Frame .*None"):
        estimate_errors(Estimate(valid=False), None)
    with pytest.raises(InvalidEstimate, match=r"estimate must be an Estimate .*dict"):
        estimate_errors({"keypoints_cam": None}, None)
    kp = np.full((21, 3), np.nan)
    with pytest.raises(InvalidKeypoints, match=r"needs finite wrist and finger MCP keypoints"):
        hand_center(kp)
    kp[:] = 0.1
    kp[8] = np.nan  # a fingertip is not part of the centre
    np.testing.assert_allclose(hand_center(kp), [0.1, 0.1, 0.1])


def test_validate_depth_input_accepts_and_refuses_as_the_per_pixel_check():
    """The two-reduction depth check and the scalar K check decide as the reference masks."""
    rng = np.random.default_rng(4)
    for value in (np.nan, np.inf, -np.inf, -1e-30, -0.0, 0.0, 3.0, np.float32(1e38)):
        for dtype in (np.float32, np.float64):
            depth = rng.uniform(0.0, 2.0, (6, 7)).astype(dtype)
            depth[rng.integers(6), rng.integers(7)] = value
            ref_bad = ~np.isfinite(depth.astype(np.float32)) | (depth.astype(np.float32) < 0)
            if ref_bad.any():
                v, u = np.argwhere(ref_bad)[0]
                with pytest.raises(InvalidEstimatorInput, match=rf"pixel \(v={v}, u={u}\)"):
                    validate_depth_input(depth, K)
            else:
                validate_depth_input(depth, K)
    for last in ([0.0, 0.0, 1.0], [1e-8, -1e-8, 1.00001], [2e-8, 0.0, 1.0], [0.0, 0.0, 1.0001]):
        k = np.array(K, dtype=np.float64)
        k[2] = last
        if np.allclose(k[2], (0.0, 0.0, 1.0)):
            validate_depth_input(np.ones((2, 2)), k)
        else:
            with pytest.raises(InvalidEstimatorInput, match=r"\[0, 0, 1\]\] with fx, fy > 0"):
                validate_depth_input(np.ones((2, 2)), k)
