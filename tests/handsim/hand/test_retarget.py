"""Retargeting 21 keypoints to the 27-DoF pose."""

import numpy as np
import pytest

from handsim.errors import InvalidKeypoints
from handsim.hand.keypoints import from_format, to_format
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_LIMITS, HandPose, joint_index
from handsim.hand.retarget import Retargeter


def _random_poses(rng, n):
    margin = np.deg2rad(2.0)  # keep away from the limits, where clamping is tested separately
    return [
        HandPose(
            rng.uniform(-0.3, 0.3, 3),
            rng.uniform(-np.pi, np.pi, 3),
            rng.uniform(JOINT_LIMITS[:, 0] + margin, JOINT_LIMITS[:, 1] - margin),
        )
        for _ in range(n)
    ]


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("hand_length", [0.15, 0.189, 0.23])
def test_round_trip_at_the_same_size(side, hand_length):
    """FK -> retarget -> FK is exact to < 1 mm within limits, both sides, three sizes."""
    params = HandParams(hand_length=hand_length, side=side)
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    errors = []
    for pose in _random_poses(np.random.default_rng(0), 8):
        result = retarget(fk.keypoints(pose))
        errors.append(np.linalg.norm(fk.keypoints(result.pose) - fk.keypoints(pose), axis=-1))
        assert result.clamped == ()
        assert result.scale == pytest.approx(1.0, abs=1e-9)
        np.testing.assert_allclose(result.pose.wrist_pos, pose.wrist_pos)
    assert np.mean(errors) < 1e-3
    assert np.max(errors) < 1e-3


def test_angles_are_preserved_across_hand_sizes():
    """Keypoints of a larger hand retarget to the same angles on a smaller one."""
    source, target = HandParams(hand_length=0.225), HandParams(hand_length=0.15)
    fk, retarget = ForwardKinematics(source), Retargeter(target)
    for pose in _random_poses(np.random.default_rng(1), 8):
        result = retarget(fk.keypoints(pose))
        assert result.scale == pytest.approx(0.225 / 0.15, rel=1e-6)
        np.testing.assert_allclose(result.pose.angles, pose.angles, atol=np.deg2rad(0.1))


def test_noisy_keypoints_give_a_bounded_fit():
    """5 mm isotropic noise gives a fit closer to the truth than the noisy input (~8 mm).

    The benchmark reports the figures.
    """
    params = HandParams()
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    rng = np.random.default_rng(2)
    errors = []
    for pose in _random_poses(rng, 10):
        truth = fk.keypoints(pose)
        noisy = truth + rng.normal(scale=0.005, size=truth.shape)
        result = retarget(noisy)
        assert result.pose.within_limits()
        errors.append(np.linalg.norm(fk.keypoints(result.pose) - truth, axis=-1).mean())
    # The noisy input itself is ~8 mm (1.6 sigma) from the truth on average.
    assert np.mean(errors) < 0.008


def test_out_of_limit_input_is_clamped_and_reported():
    """Joints asked past a limit are clamped, and reported with the requested value."""
    params = HandParams()
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    angles = np.deg2rad(np.full(21, 20.0))
    angles[joint_index("index_pip_flex")] = np.deg2rad(130.0)
    angles[joint_index("middle_mcp_flex")] = np.deg2rad(-35.0)
    wanted = HandPose(np.zeros(3), np.zeros(3), angles)
    result = retarget(fk.keypoints(wanted))
    assert result.pose.within_limits()
    reported = {v.joint: np.rad2deg(v.value_rad) for v in result.clamped}
    assert reported["index_pip_flex"] == pytest.approx(130.0, abs=0.1)
    assert reported["middle_mcp_flex"] == pytest.approx(-35.0, abs=0.1)
    assert result.pose.angle("index_pip_flex") == pytest.approx(JOINT_LIMITS[7, 1])


def test_sequence_warm_starts():
    """A sequence retargets frame by frame, each warm-started from the last."""
    params = HandParams()
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    start, end = _random_poses(np.random.default_rng(3), 2)
    t = np.linspace(0, 1, 5)[:, None]
    poses = HandPose(
        start.wrist_pos + t * (end.wrist_pos - start.wrist_pos),
        np.broadcast_to(start.wrist_rotvec, (5, 3)),
        start.angles + t * (end.angles - start.angles),
    )
    results = retarget.sequence(fk.keypoints(poses))
    assert len(results) == 5
    fitted = np.stack([r.pose.angles for r in results])
    np.testing.assert_allclose(fitted, poses.angles, atol=1e-4)


def test_errors():
    """Bad keypoints are refused with messages that say what is wrong."""
    params = HandParams()
    retarget = Retargeter(params)
    good = ForwardKinematics(params).keypoints(HandPose.neutral())
    with pytest.raises(InvalidKeypoints, match=r"shape \(21, 3\).*received shape \(20, 3\)"):
        retarget(good[:20])
    bad = good.copy()
    bad[4, 1] = np.nan
    with pytest.raises(InvalidKeypoints, match=r"NaN or Inf at indices \[4\]"):
        retarget(bad)
    same = good.copy()
    same[8] = same[7]
    with pytest.raises(InvalidKeypoints, match=r"bones \[\(7, 8\)\] have zero length"):
        retarget(same)
    left = ForwardKinematics(HandParams(side="left")).keypoints(HandPose.neutral())
    with pytest.raises(
        InvalidKeypoints, match=r"look like a left hand but the target hand is right"
    ):
        retarget(left)
    with pytest.raises(InvalidKeypoints, match=r"shape \(T, 21, 3\)"):
        retarget.sequence(good)


# Real trackers: analytic Jacobians, floating wrist and scale, partial keypoints, side check.


def test_analytic_jacobian_matches_finite_differences():
    """The chain kinematics equal ForwardKinematics; their Jacobian, central differences."""
    for side in ("right", "left"):
        params = HandParams(side=side)
        retarget, fk = Retargeter(params), ForwardKinematics(params)
        angles = np.random.default_rng(4).uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
        q, jac = retarget._chains(angles, True)
        np.testing.assert_allclose(q, fk.keypoints(HandPose(np.zeros(3), np.zeros(3), angles)))
        step = 1e-6
        for j in range(21):
            d = np.zeros(21)
            d[j] = step
            numeric = (
                retarget._chains(angles + d, False)[0] - retarget._chains(angles - d, False)[0]
            )
            np.testing.assert_allclose(jac[:, :, j], numeric / (2 * step), atol=1e-8)


def test_wrist_and_scale_float_by_default_and_can_be_pinned():
    """A hand of another size shifted off its wrist keypoint fits exactly; pinned options hold."""
    source, target = HandParams(hand_length=0.21), HandParams()
    pose = _random_poses(np.random.default_rng(5), 1)[0]
    kp = ForwardKinematics(source).keypoints(pose)
    retarget = Retargeter(target)
    result = retarget(kp)
    assert result.scale == pytest.approx(0.21 / 0.189, rel=1e-6)
    assert result.keypoint_error_m < 1e-6
    np.testing.assert_allclose(result.pose.wrist_pos, pose.wrist_pos, atol=1e-7)
    pinned = retarget(kp + [0.0, 0.0, 0.0], fit_wrist=False, fit_scale=False, initial_scale=1.0)
    np.testing.assert_array_equal(pinned.pose.wrist_pos, kp[0])
    assert pinned.scale == 1.0
    assert pinned.keypoint_error_m > 1e-3  # a 189 mm hand cannot reach a 210 mm hand's points


@pytest.mark.parametrize("fmt", ["nyu14", "icvl16", "bighand21", "openxr26"])
def test_formats_with_fewer_points_retarget(fmt):
    """NYU-14 and ICVL-16 (through from_format) drive the hand; clean labels fit exactly."""
    params = HandParams()
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    for pose in _random_poses(np.random.default_rng(6), 4):
        kp = from_format(to_format(fk.points(pose), fmt), fmt)
        result = retarget(kp)
        assert result.keypoint_error_m < 1e-4
        err = np.linalg.norm(fk.keypoints(result.pose) - fk.keypoints(pose), axis=-1)
        assert err.mean() < 2e-3, (fmt, err.mean())


def test_mask_marks_absent_points_like_nan_rows():
    """A mask gives the same fit as all-NaN rows for the absent points."""
    params = HandParams()
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    pose = _random_poses(np.random.default_rng(7), 1)[0]
    kp = fk.keypoints(pose) + np.random.default_rng(8).normal(scale=0.003, size=(21, 3))
    mask = np.ones(21, dtype=bool)
    mask[[0, 7, 11, 15, 19]] = False
    with_nan = kp.copy()
    with_nan[~mask] = np.nan
    a = retarget(with_nan, report_clamped=False)
    b = retarget(kp + 1.0 * ~mask[:, None], mask=mask, report_clamped=False)  # junk where absent
    np.testing.assert_allclose(a.pose.vector, b.pose.vector, atol=1e-9)


def test_side_check_compares_both_fits():
    """Noisy hands of the other side are refused, noisy hands of this side accepted."""
    right, left = HandParams(side="right"), HandParams(side="left")
    fk_right, fk_left = ForwardKinematics(right), ForwardKinematics(left)
    retarget = Retargeter(right)
    rng = np.random.default_rng(9)
    for pose in _random_poses(rng, 10):
        noisy_right = fk_right.keypoints(pose) + rng.normal(scale=0.005, size=(21, 3))
        result = retarget(noisy_right, report_clamped=False)
        assert result.other_side_error_m > result.keypoint_error_m
        noisy_left = fk_left.keypoints(pose) + rng.normal(scale=0.005, size=(21, 3))
        with pytest.raises(InvalidKeypoints, match=r"look like a left hand.*mm as a left hand"):
            retarget(noisy_left, report_clamped=False)


def test_warm_start_converges_in_few_iterations():
    """Warm-started from the previous frame, a nearby frame takes fewer iterations than cold."""
    params = HandParams()
    fk, retarget = ForwardKinematics(params), Retargeter(params)
    rng = np.random.default_rng(10)
    cold_its, warm_its = [], []
    for pose in _random_poses(rng, 6):
        truth = fk.keypoints(pose)
        first = retarget(truth + rng.normal(scale=0.005, size=truth.shape), check_side=False)
        second = truth + rng.normal(scale=0.005, size=truth.shape)
        cold_its.append(retarget(second, check_side=False).iterations)
        warm = retarget(second, first.pose, initial_scale=first.scale, check_side=False)
        warm_its.append(warm.iterations)
    assert np.mean(warm_its) < np.mean(cold_its)


def test_partial_input_errors():
    """Too few points, a pinned wrist without a wrist keypoint and a bad mask are refused."""
    params = HandParams()
    retarget = Retargeter(params)
    good = ForwardKinematics(params).keypoints(HandPose.neutral())
    few = np.full((21, 3), np.nan)
    few[[0, 5, 9]] = good[[0, 5, 9]]
    with pytest.raises(InvalidKeypoints, match=r"at least 4 present keypoints; received 3"):
        retarget(few)
    no_wrist = good.copy()
    no_wrist[0] = np.nan
    with pytest.raises(InvalidKeypoints, match=r"fit_wrist=False pins the wrist.*absent"):
        retarget(no_wrist, fit_wrist=False)
    with pytest.raises(InvalidKeypoints, match=r"mask must be a \(21,\) bool array"):
        retarget(good, mask=np.ones(20, dtype=bool))


# A right hand with 5 mm noise (a random in-limit pose) whose flat-hand cold start ends in a
# 34 mm local minimum; rounded to 0.01 mm.
_LOCAL_MINIMUM_KP = [
    [-0.15781, 0.27048, -0.1543], [-0.17384, 0.25127, -0.14588], [-0.19599, 0.22518, -0.11918],
    [-0.22939, 0.19595, -0.11175], [-0.25388, 0.20585, -0.11795], [-0.23995, 0.268, -0.10741],
    [-0.27163, 0.24337, -0.12027], [-0.25032, 0.22255, -0.12188], [-0.23974, 0.22878, -0.11848],
    [-0.23682, 0.28042, -0.119], [-0.28456, 0.25856, -0.12836], [-0.26873, 0.225, -0.13903],
    [-0.24911, 0.23274, -0.14288], [-0.23351, 0.29781, -0.13897], [-0.2807, 0.31269, -0.11638],
    [-0.30217, 0.29709, -0.11584], [-0.30803, 0.26845, -0.12421], [-0.23262, 0.285, -0.15439],
    [-0.26028, 0.25175, -0.15939], [-0.2669, 0.24107, -0.16397], [-0.25771, 0.23474, -0.1715],
]  # fmt: skip


def test_a_poor_cold_fit_is_retried_from_more_starts():
    """A cold fit stuck in a local minimum is retried, and the side check then accepts it."""
    retarget = Retargeter(HandParams())
    kp = np.array(_LOCAL_MINIMUM_KP)
    present = np.ones(21, dtype=bool)
    flat_only = retarget._solve(
        retarget._cold_starts(kp, present)[0], kp, present, np.ones(28, dtype=bool), True
    )[0]
    assert retarget._error(flat_only, kp, present) > 0.03
    result = retarget(kp)
    assert result.keypoint_error_m < 0.008
    assert result.other_side_error_m > 2 * result.keypoint_error_m
