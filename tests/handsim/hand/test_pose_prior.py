"""The Gaussian pose prior and the maximum a posteriori retargeting that uses it."""

import numpy as np
import pytest

from handsim.errors import InvalidKeypoints, InvalidPose
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_LIMITS, NUM_ANGLES, HandPose
from handsim.hand.pose_prior import PosePrior, corpus_angles, default_pose_prior
from handsim.hand.pose_sources import sample_grasp
from handsim.hand.retarget import Retargeter

_PALM = [0, 1, 5, 9, 13, 17]


def test_default_prior_is_the_corpus_mean_and_covariance_plus_the_floor():
    """The mean and covariance are the corpus's (+ floor^2 on the diagonal); W^T W = Sigma^-1."""
    corpus = corpus_angles()
    assert corpus.shape == (13 * 11 + 14, NUM_ANGLES)
    prior = default_pose_prior()
    np.testing.assert_allclose(prior.mean_rad, corpus.mean(axis=0))
    np.testing.assert_allclose(
        prior.covariance_rad2, np.cov(corpus, rowvar=False) + 0.01 * np.eye(NUM_ANGLES)
    )
    np.testing.assert_allclose(
        prior.whitening.T @ prior.whitening @ prior.covariance_rad2, np.eye(NUM_ANGLES), atol=1e-9
    )
    assert np.all((prior.mean_rad >= JOINT_LIMITS[:, 0]) & (prior.mean_rad <= JOINT_LIMITS[:, 1]))
    assert default_pose_prior() is prior  # cached
    assert prior.mahalanobis(prior.mean_rad) == 0.0
    with pytest.raises(ValueError):
        prior.mean_rad[0] = 1.0  # read-only


def test_prior_errors():
    """Bad shapes, a singular covariance and a negative floor are refused with what is valid."""
    with pytest.raises(InvalidPose, match=r"\(21,\) mean and a \(21, 21\) covariance"):
        PosePrior(np.zeros(20), np.eye(21))
    with pytest.raises(InvalidPose, match="positive definite.*add a floor"):
        PosePrior(np.zeros(21), np.diag([0.0] + [1.0] * 20))
    with pytest.raises(InvalidPose, match="symmetric"):
        PosePrior(np.zeros(21), np.eye(21) + np.triu(np.ones((21, 21)), 1))
    with pytest.raises(InvalidPose, match=r"\(n, 21\) finite angles"):
        PosePrior.from_angles(np.zeros((1, 21)))
    with pytest.raises(InvalidPose, match="floor_rad must be a number >= 0"):
        PosePrior.from_angles(np.zeros((3, 21)), floor_rad=-1.0)
    with pytest.raises(InvalidPose, match="pose_prior must be a PosePrior"):
        Retargeter(HandParams(), pose_prior="corpus")
    with pytest.raises(InvalidKeypoints, match="keypoint_sigma_m must be a number >= 0"):
        Retargeter(HandParams(), pose_prior=default_pose_prior())


def test_prior_alone_gives_its_mean():
    """Analytic case: the palm points alone (no keypoint depends on an angle) fit to mu.

    Least squares stays at its weak prior's zero.
    """
    params = HandParams()
    fk = ForwardKinematics(params)
    prior = default_pose_prior()
    truth = HandPose(np.array([0.1, -0.2, 0.4]), np.array([0.3, -0.5, 1.0]), corpus_angles()[40])
    mask = np.zeros(21, bool)
    mask[_PALM] = True
    fitted = Retargeter(params, pose_prior=prior, keypoint_sigma_m=0.01)(
        fk.keypoints(truth), mask=mask, check_side=False
    )
    np.testing.assert_allclose(fitted.pose.angles, prior.mean_rad, atol=1e-6)
    np.testing.assert_allclose(fitted.pose.wrist_pos, truth.wrist_pos, atol=1e-9)
    plain = Retargeter(params)(fk.keypoints(truth), mask=mask, check_side=False)
    np.testing.assert_allclose(plain.pose.angles, 0.0, atol=1e-6)
    # sigma 0: exact keypoints outweigh the prior, the fit is least squares to the last bit.
    exact = Retargeter(params, pose_prior=prior, keypoint_sigma_m=0.0)
    for kp in (fk.keypoints(truth), fk.keypoints(truth) + 0.01):
        a = exact(kp, check_side=False).pose.vector
        np.testing.assert_array_equal(a, Retargeter(params)(kp, check_side=False).pose.vector)


def test_map_fit_is_a_stationary_point_of_its_cost():
    """At an interior MAP fit the finite-difference gradient of the MAP cost vanishes.

    So the analytic prior rows and their Jacobian W are consistent with the cost.
    """
    params = HandParams()
    fk = ForwardKinematics(params)
    prior = default_pose_prior()
    sigma_m = 0.01
    retarget = Retargeter(params, pose_prior=prior, keypoint_sigma_m=sigma_m)
    rng = np.random.default_rng(3)
    truth = HandPose(np.zeros(3), np.zeros(3), corpus_angles()[60])
    kp = fk.keypoints(truth) + rng.normal(0.0, sigma_m, (21, 3))
    fit = retarget(kp, initial=truth, check_side=False, report_clamped=False)
    margin = 1e-3
    interior = (fit.pose.angles > JOINT_LIMITS[:, 0] + margin) & (
        fit.pose.angles < JOINT_LIMITS[:, 1] - margin
    )
    assert interior.sum() >= 15

    def cost(angles):
        pose = HandPose(fit.pose.wrist_pos, fit.pose.wrist_rotvec, angles)
        model = fit.pose.wrist_pos + fit.scale * (fk.keypoints(pose) - fit.pose.wrist_pos)
        d = (angles - prior.mean_rad) @ prior.whitening.T
        return np.sum((model - kp) ** 2) / sigma_m**2 + d @ d

    h = 1e-6
    prior_grad = 2 * prior.precision @ (fit.pose.angles - prior.mean_rad)
    for j in np.nonzero(interior)[0]:
        step = np.zeros(NUM_ANGLES)
        step[j] = h
        grad = (cost(fit.pose.angles + step) - cost(fit.pose.angles - step)) / (2 * h)
        # The solver stops once a step gains < 1 % of the cost (about 63 here): a gradient
        # of 0.5/rad against a curvature of ~100/rad^2 is 0.005 rad from the optimum, while
        # the prior's own pull is tens per rad.
        assert abs(grad) < 0.5, (j, grad)
    assert np.max(np.abs(prior_grad[interior])) > 10.0


def test_clean_corpus_poses_stay_close():
    """Without noise (sigma 10 mm) the prior biases corpus poses by a few degrees at most."""
    params = HandParams()
    fk = ForwardKinematics(params)
    retarget = Retargeter(params, pose_prior=default_pose_prior(), keypoint_sigma_m=0.01)
    errors_deg, kp_errors_m = [], []
    for angles in corpus_angles()[::8]:
        pose = HandPose(np.zeros(3), np.zeros(3), angles)
        fit = retarget(fk.keypoints(pose), check_side=False)
        errors_deg.append(np.degrees(np.abs(fit.pose.angles - angles)).mean())
        kp_errors_m.append(fit.keypoint_error_m)
    assert np.mean(errors_deg) < 5.0 and np.max(errors_deg) < 10.0
    assert np.mean(kp_errors_m) < 0.003


def test_prior_lowers_the_angle_error_of_noisy_held_out_poses():
    """With 10 mm of keypoint noise the MAP fit's angle error is well below least squares'.

    On grasps the prior was not fitted to: random closures, 3 deg of angle noise, random wrists.
    """
    params = HandParams()
    fk = ForwardKinematics(params)
    plain = Retargeter(params)
    prior = Retargeter(params, pose_prior=default_pose_prior(), keypoint_sigma_m=0.01)
    rng = np.random.default_rng(7)
    poses, _ = sample_grasp(rng, 30, closure_range=(0.0, 1.0), noise_deg=3.0)
    err_plain, err_prior = [], []
    for angles in poses.angles:
        pose = HandPose(rng.normal(0, 0.1, 3), rng.normal(0, 0.5, 3), angles)
        kp = fk.keypoints(pose) + rng.normal(0.0, 0.01, (21, 3))
        for fitter, errors in ((plain, err_plain), (prior, err_prior)):
            fit = fitter(kp, initial=pose, check_side=False, report_clamped=False)
            errors.append(np.degrees(np.abs(fit.pose.angles - angles)).mean())
    # Measured: about 16 deg without the prior, 6 deg with it.
    assert np.mean(err_prior) < 0.5 * np.mean(err_plain)
