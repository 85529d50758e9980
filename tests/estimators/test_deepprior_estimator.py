"""DeepPriorEstimator's tracking: the detector runs once per track, and again when it is lost."""

import numpy as np
import pytest
import torch

from handsim.estimators.deepprior import checkpoint as C
from handsim.estimators.deepprior.estimator import DeepPriorEstimator
from handsim.estimators.deepprior.models import build_model

K_CV = np.array([[60.0, 0.0, 31.5], [0.0, 60.0, 23.5], [0.0, 0.0, 1.0]])


def _estimator(tmp_path, **kwargs):
    config = {
        "model": {"arch": "resnet", "size": 32, "fc": 16, "width": 0.125, "prior_dim": 4},
        "cube_m": 0.25,
        "kind": "deepprior++",
    }
    torch.manual_seed(0)
    C.save_checkpoint(
        tmp_path / "n.pt", {"model": build_model(config["model"]).state_dict()}, config
    )
    est = DeepPriorEstimator(tmp_path / "n.pt", localizer=None, detector="com", **kwargs)
    calls = []
    detect = est.localizer.base.localize
    est.localizer.base.localize = lambda d, k: calls.append(1) or detect(d, k)
    return est, calls


def _hand(u0=22):
    v, u = np.mgrid[0:48, 0:64]
    depth = np.zeros((48, 64), np.float32)
    depth[((u - u0) / 9.0) ** 2 + ((v - 20) / 12.0) ** 2 < 1] = 0.45
    return depth


def test_tracking_skips_the_detector_until_the_hand_is_lost(tmp_path):
    """track=True: one detection per track; reset, a lost hand and a side change detect again."""
    est, calls = _estimator(tmp_path, track=True)
    for _ in range(3):
        assert est.predict(_hand(), K_CV).valid
    assert len(calls) == 1
    est.reset()
    est.predict(_hand(), K_CV)
    assert len(calls) == 2
    # Nothing in view: the tracked cube is empty, the detector finds nothing either.
    assert not est.predict(np.zeros((48, 64), np.float32), K_CV).valid
    assert len(calls) == 3
    est.predict(_hand(), K_CV)  # after a miss: detect
    assert len(calls) == 4
    est.set_side(True)
    est.predict(_hand(), K_CV)
    assert len(calls) == 5
    assert "track=True" in repr(est)


def test_without_tracking_every_frame_is_detected(tmp_path):
    """The default detects in every frame, and the first tracked frame equals it."""
    est, calls = _estimator(tmp_path)
    first = est.predict(_hand(), K_CV).keypoints_cam
    est.predict(_hand(), K_CV)
    assert len(calls) == 2
    tracker, _ = _estimator(tmp_path, track=True)
    np.testing.assert_array_equal(tracker.predict(_hand(), K_CV).keypoints_cam, first)


def test_one_frame_refinement_equals_the_batched_one(tmp_path):
    """RefinedLocalizer.refine (one frame, unbatched) gives refine_batch's centres.

    Exactly at batch 1 (the same arithmetic); to float32 rounding of the network in batches.
    """
    from handsim.estimators.deepprior.estimator import RefinedLocalizer

    config = {"model": {"arch": "localizer", "size": 32, "fc": 16}, "cube_m": 0.25}
    torch.manual_seed(1)
    C.save_checkpoint(
        tmp_path / "l.pt", {"model": build_model(config["model"]).state_dict()}, config
    )
    loc = RefinedLocalizer(tmp_path / "l.pt", iterations=3, detector="com")
    depths = [_hand(u0) for u0 in (18, 22, 30, 40)]
    starts = np.array([loc.base.localize(d, K_CV) for d in depths])
    Ks = np.repeat(K_CV[None], 4, axis=0)  # noqa: N806
    one = np.array([loc.refine(d, K_CV, c) for d, c in zip(depths, starts, strict=True)])
    np.testing.assert_array_equal(one, loc.refine_batch(depths, Ks, starts, batch_size=1))
    np.testing.assert_allclose(one, loc.refine_batch(depths, Ks, starts), rtol=0, atol=1e-7)
    assert np.abs(one - starts).max() > 1e-3  # the network moved them


def test_threads_sets_torch_and_opencv(tmp_path):
    """threads=N sets both libraries' CPU threads (the preprocessing runs in OpenCV)."""
    import cv2

    before = torch.get_num_threads(), cv2.getNumThreads()
    try:
        _estimator(tmp_path, threads=1)
        assert (torch.get_num_threads(), cv2.getNumThreads()) == (1, 1)
    finally:
        torch.set_num_threads(before[0])
        cv2.setNumThreads(before[1])


def test_a_hand_alone_is_found_at_the_detectors_centre():
    """HandPose-v0 (a hand alone, its gesture formed): cropped at the plane detector's centre.

    The shipped refinement CNN walks up the arm on these frames (docs/deepprior.md, "A hand
    alone"); the guard (the default) sees that three steps have not converged and keeps the
    detector's centre, as ``refine_iterations=0`` (the shipped networks' default) does: the
    hand centre within 8 cm (measured: 44.5 mm at this step; with the three refinement steps
    unguarded 287.7 mm).
    """
    import gymnasium as gym

    import handsim.envs  # noqa: F401
    from handsim.estimator import hand_center

    env = gym.make("handsim/HandPose-v0", obs_mode="depth", sensor="none", camera="icvl")
    try:
        obs, _ = env.reset(seed=0)
        base = env.unwrapped
        expert = base.make_expert(np.random.default_rng(0))
        for _ in range(20):
            obs, *_ = env.step(expert.act(base.expert_state()).vector)
        truth = base.frame.keypoints_cam
        K = base.obs_intrinsics.K  # noqa: N806
        centre_mm = {}
        for name, kwargs in {
            "detector": {"refine_iterations": 0},
            "guarded": {"refine_iterations": 3},
            "unguarded": {"refine_iterations": 3, "refine_guard": False},
        }.items():
            estimate = DeepPriorEstimator(
                "deepprior++", threads=1, detector="plane", **kwargs
            ).predict(obs["depth"], K)
            centre = hand_center(estimate.keypoints_cam) - hand_center(truth)
            centre_mm[name] = 1000 * np.linalg.norm(centre)
    finally:
        env.close()
    assert centre_mm["detector"] < 80.0
    assert centre_mm["guarded"] == centre_mm["detector"]  # the same crop
    assert centre_mm["unguarded"] > 200.0


def _hand_and_arm():
    """A hand (disk at 0.45 m) and an "arm" strip from it up the image, receding to 0.7 m."""
    depth = _hand()
    v, u = np.mgrid[0:48, 0:64]
    arm = (np.abs(u - 22) < 4) & (v < 14)
    depth[arm] = (0.45 + (14 - v) * 0.018)[arm]
    return depth


def _localizer(tmp_path, guard=True):
    from handsim.estimators.deepprior.estimator import RefinedLocalizer

    config = {"model": {"arch": "localizer", "size": 32, "fc": 16}, "cube_m": 0.25}
    torch.manual_seed(1)
    C.save_checkpoint(
        tmp_path / "l.pt", {"model": build_model(config["model"]).state_dict()}, config
    )
    return RefinedLocalizer(tmp_path / "l.pt", iterations=3, detector="com", guard=guard)


def _mean_shift(x):
    """A refinement that converges: to the centroid of the crop's pixels inside the cube.

    ``x``: (B, 1, S, S) normalized crops; returns (B, 3) offsets in half-cube units (the
    crop's half side is half the cube at the centre's depth).
    """
    out = []
    for crop in x[:, 0].numpy():
        v, u = np.nonzero(crop < 1.0)
        half = (crop.shape[0] - 1) / 2.0
        out.append([(u.mean() - half) / half, (v.mean() - half) / half, crop[v, u].mean()])
    return torch.tensor(out, dtype=torch.float32)


def test_the_guard_keeps_the_centre_on_the_hand_when_the_refinement_walks(tmp_path):
    """An adversarial refinement that walks up the arm: the guard keeps the detector's centre.

    Each step moves the centre 10 cm up and 10 cm away (0.8 half cubes on y and z), so after
    three steps the network still asks for 141 mm, more than half the 250 mm cube.
    """
    from handsim.estimators.deepprior.estimator import RefinedLocalizer

    depth = _hand_and_arm()
    walk = lambda x: torch.tensor([[0.0, -0.8, 0.8]] * len(x))  # noqa: E731
    guarded, free = _localizer(tmp_path), _localizer(tmp_path, guard=False)
    guarded._forward = free._forward = walk
    start = guarded.base.localize(depth, K_CV)
    kept = guarded.refine(depth, K_CV, start)
    np.testing.assert_array_equal(kept, start)
    # On the blob: its pixel is a measured hand or arm pixel, its depth within the blob's.
    u, v = (K_CV @ (kept / kept[2]))[:2]
    assert depth[int(round(v)), int(round(u))] > 0 and 0.44 < kept[2] < 0.70
    walked = free.refine(depth, K_CV, start)
    np.testing.assert_allclose(walked - start, [0.0, -0.3, 0.3], atol=1e-6)  # off the image
    centres, residual_m, lost = guarded.path(depth, K_CV, start)
    assert lost and centres.shape == (4, 3)
    np.testing.assert_array_equal(centres[-1], walked)
    np.testing.assert_allclose(residual_m, [0.0, -0.1, 0.1], atol=1e-7)
    starts = np.stack([start, start + [0.01, 0.0, 0.0]])
    batch = guarded.refine_batch([depth, depth], np.stack([K_CV, K_CV]), starts)
    np.testing.assert_array_equal(batch, starts)
    assert "guard=True" in repr(guarded) and isinstance(guarded, RefinedLocalizer)


def test_the_guard_is_a_no_op_where_the_refinement_converges(tmp_path):
    """A converging refinement (mean shift to the blob): the same centres with and without.

    It starts 4 cm off the centre of mass (which is its fixed point on a disk) and comes back.
    """
    guarded, free = _localizer(tmp_path), _localizer(tmp_path, guard=False)
    guarded._forward = free._forward = _mean_shift
    depths = [_hand(), _hand(30), _hand_and_arm()]
    off = np.array([0.03, 0.02, 0.02])
    starts = np.array([guarded.base.localize(d, K_CV) + off for d in depths])
    for depth, start in zip(depths, starts, strict=True):
        refined = free.refine(depth, K_CV, start)
        assert np.linalg.norm(refined - start) > 0.02  # it moved back towards the blob
        np.testing.assert_array_equal(guarded.refine(depth, K_CV, start), refined)
        centres, residual_m, lost = guarded.path(depth, K_CV, start)
        assert not lost and np.linalg.norm(residual_m) < 0.02  # converged
        np.testing.assert_array_equal(centres[-1], refined)
    Ks = np.repeat(K_CV[None], 3, axis=0)  # noqa: N806
    np.testing.assert_array_equal(
        guarded.refine_batch(depths, Ks, starts), free.refine_batch(depths, Ks, starts)
    )


def test_the_guard_option_is_checked(tmp_path):
    """The guard options (``guard``, ``refine_guard``) are bools; the estimator reports them."""
    from handsim.errors import InvalidEstimatorParams

    with pytest.raises(InvalidEstimatorParams, match=r"guard must be True .* or False; received 1"):
        _localizer(tmp_path, guard=1)
    with pytest.raises(InvalidEstimatorParams, match="refine_guard must be True .* received 'no'"):
        _estimator(tmp_path, refine_guard="no")
    est, _ = _estimator(tmp_path, refine_guard=False)
    assert "refine_guard=False" in repr(est) and est.info()["refine_guard"] is False
    assert _estimator(tmp_path)[0].localizer.guard is True  # the default
