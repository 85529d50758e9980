"""OracleEstimator: noise statistics, bias, dropout, latency, determinism, argument errors."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.errors import EstimatorStateError, InvalidEstimatorInput, InvalidEstimatorParams
from handsim.estimator import Estimator, PrivilegedEstimator, estimate_errors, hand_center
from handsim.estimators import OracleEstimator
from handsim.frame import FrameRenderer, ObjectLabel
from handsim.world.camera import camera_preset
from handsim.world.symmetry import Symmetry

ICVL = camera_preset("icvl")
DEPTH = np.zeros((ICVL.height, ICVL.width), np.float32)
K = ICVL.K
# An object model for the ADD/ADI of estimate_errors: 3 points, no symmetry.
BOX = SimpleNamespace(model_points_m=np.eye(3), symmetry=Symmetry())


def _truth(offset_m: float = 0.0, n_objects: int = 2) -> SimpleNamespace:
    """The Frame fields the oracle reads: keypoints and object poses (shifted by offset_m)."""
    kp = np.random.default_rng(0).normal([0.0, 0.0, 0.5], 0.05, (21, 3)) + offset_m
    objects = []
    for k in range(n_objects):
        T = np.eye(4)  # noqa: N806
        T[:3, :3] = Rotation.from_rotvec([0.1 * k, 0.2, 0.0]).as_matrix()
        T[:3, 3] = [0.1 * k, 0.0, 0.6 + offset_m]
        objects.append(ObjectLabel(k, f"obj{k}", None, T, np.zeros((8, 3)), 1.0, 1, 1))
    return SimpleNamespace(keypoints_cam=kp, objects=tuple(objects))


def _draw(oracle: OracleEstimator, truth, n: int) -> list:
    estimates = []
    for _ in range(n):
        oracle.observe_truth(truth)
        estimates.append(oracle.predict(DEPTH, K))
    return estimates


def test_oracle_is_a_privileged_estimator():
    """The oracle satisfies both protocols."""
    oracle = OracleEstimator()
    assert isinstance(oracle, Estimator) and isinstance(oracle, PrivilegedEstimator)


def test_noise_free_oracle_returns_the_truth():
    """Without noise, keypoints and object poses equal the truth (and every error is 0)."""
    truth = _truth()
    (est,) = _draw(OracleEstimator(rng=0), truth, 1)
    np.testing.assert_array_equal(est.keypoints_cam, truth.keypoints_cam)
    np.testing.assert_allclose(est.center_cam, hand_center(truth.keypoints_cam), atol=1e-15)
    for label in truth.objects:
        np.testing.assert_allclose(est.object_poses[label.instance], label.T_cam_from_obj)
    errors = estimate_errors(est, truth, objects=[BOX] * 2)
    assert errors["kp_max_mm"] == 0.0 and errors["center_mm"] < 1e-12
    assert errors["add_mm"] == {0: 0.0, 1: 0.0}


def test_keypoint_noise_has_the_requested_std():
    """noise_mm is the per-axis std of every keypoint (within 10 %), with zero mean."""
    truth = _truth()
    est = _draw(OracleEstimator(noise_mm=5.0, rng=1), truth, 400)
    err_mm = np.stack([e.keypoints_cam for e in est]) * 1000 - truth.keypoints_cam * 1000
    std = err_mm.reshape(-1, 3).std(axis=0)
    np.testing.assert_allclose(std, 5.0, rtol=0.1)
    np.testing.assert_allclose(err_mm.reshape(-1, 3).mean(axis=0), 0.0, atol=0.2)
    # The centre averages 5 keypoints: its per-axis std is noise_mm / sqrt(5).
    centre_err_mm = np.stack([e.center_cam for e in est]) * 1000
    centre_err_mm -= hand_center(truth.keypoints_cam) * 1000
    np.testing.assert_allclose(centre_err_mm.std(axis=0), 5.0 / np.sqrt(5), rtol=0.1)


def test_bias_is_added_exactly():
    """bias_mm shifts every keypoint and the centre exactly (camera frame); not the objects."""
    truth = _truth()
    (est,) = _draw(OracleEstimator(bias_mm=(1.0, -2.0, 3.0), rng=0), truth, 1)
    bias_m = np.array([0.001, -0.002, 0.003])
    np.testing.assert_allclose(est.keypoints_cam - truth.keypoints_cam, np.tile(bias_m, (21, 1)))
    np.testing.assert_allclose(est.center_cam - hand_center(truth.keypoints_cam), bias_m)
    np.testing.assert_allclose(est.object_poses[0], truth.objects[0].T_cam_from_obj)


def test_object_noise_has_the_requested_std():
    """Object translation and rotation-vector noise have the requested stds (within 10 %)."""
    truth = _truth(n_objects=1)
    est = _draw(OracleEstimator(object_noise_mm=2.0, object_noise_deg=3.0, rng=2), truth, 2000)
    T_gt = truth.objects[0].T_cam_from_obj  # noqa: N806
    T_est = np.stack([e.object_poses[0] for e in est])  # noqa: N806
    np.testing.assert_allclose((T_est[:, :3, 3] - T_gt[:3, 3]).std(axis=0) * 1000, 2.0, rtol=0.1)
    R_noise = T_est[:, :3, :3] @ T_gt[:3, :3].T  # noqa: N806 (the oracle's left perturbation)
    rotvec_deg = np.rad2deg(Rotation.from_matrix(R_noise).as_rotvec())
    np.testing.assert_allclose(rotvec_deg.std(axis=0), 3.0, rtol=0.1)
    np.testing.assert_allclose(est[0].keypoints_cam, truth.keypoints_cam)  # hand untouched


def test_object_noise_per_axis_or_in_3d():
    """Axis noise is a std per axis (3-D mean ~1.6 sigma), 3d an exact 3-D error; bad kinds."""
    truth = _truth(n_objects=1)
    t_gt = truth.objects[0].T_cam_from_obj[:3, 3]
    axis = _draw(OracleEstimator(object_noise_mm=10.0, rng=4), truth, 2000)
    err_axis = np.linalg.norm([e.object_poses[0][:3, 3] - t_gt for e in axis], axis=1) * 1000
    # Mean of a chi(3) distribution: 2 sqrt(2 / pi) sigma = 1.596 sigma.
    np.testing.assert_allclose(err_axis.mean(), 15.96, rtol=0.05)
    exact = _draw(OracleEstimator(object_noise_mm=10.0, object_noise_kind="3d", rng=4), truth, 500)
    offsets = np.array([e.object_poses[0][:3, 3] - t_gt for e in exact]) * 1000
    np.testing.assert_allclose(np.linalg.norm(offsets, axis=1), 10.0)
    np.testing.assert_allclose(offsets.mean(axis=0), 0.0, atol=1.0)  # no preferred direction
    with pytest.raises(InvalidEstimatorParams, match="object_noise_kind must be one of"):
        OracleEstimator(object_noise_kind="sphere")


def test_dropout_fraction():
    """With dropout p, a fraction p of the estimates is invalid (4 sigma binomial band)."""
    n, p = 4000, 0.3
    est = _draw(OracleEstimator(dropout=p, rng=3), _truth(), n)
    fraction = np.mean([not e.valid for e in est])
    assert abs(fraction - p) < 4 * np.sqrt(p * (1 - p) / n)
    assert all(e.keypoints_cam is None for e in est if not e.valid)
    assert not any(e.valid for e in _draw(OracleEstimator(dropout=1.0, rng=0), _truth(), 50))
    assert all(e.valid for e in _draw(OracleEstimator(dropout=0.0, rng=0), _truth(), 50))


def test_latency_returns_the_truth_of_k_steps_ago():
    """latency_steps=2 returns the truth of 2 steps ago, repeating the episode's first at start.

    reset forgets the buffer: predict then needs a new truth, and the next episode starts over.
    """
    oracle = OracleEstimator(latency_steps=2, rng=0)
    base = _truth().keypoints_cam

    def run(offsets):
        seen = []
        for offset in offsets:
            oracle.observe_truth(_truth(offset))
            seen.append(oracle.predict(DEPTH, K).keypoints_cam[0, 0] - base[0, 0])
        return np.round(seen, 9)

    np.testing.assert_array_equal(run([0.0, 1.0, 2.0, 3.0, 4.0, 5.0]), [0, 0, 0, 1, 2, 3])
    oracle.reset()
    with pytest.raises(EstimatorStateError):
        oracle.predict(DEPTH, K)
    np.testing.assert_array_equal(run([10.0, 11.0, 12.0]), [10, 10, 10])


def test_same_seed_gives_identical_estimates():
    """Same seed and truths give identical estimates; reset keeps the generator running.

    So two episodes of one oracle differ, and a Generator and its int seed are interchangeable.
    """
    kwargs = dict(noise_mm=4.0, dropout=0.2, object_noise_mm=1.0, object_noise_deg=2.0)
    a, b = OracleEstimator(**kwargs, rng=7), OracleEstimator(**kwargs, rng=7)
    ea, eb = _draw(a, _truth(), 30), _draw(b, _truth(), 30)
    for x, y in zip(ea, eb, strict=True):
        assert x.valid == y.valid
        if x.valid:
            np.testing.assert_array_equal(x.keypoints_cam, y.keypoints_cam)
            np.testing.assert_array_equal(x.object_poses[1], y.object_poses[1])
    a.reset()
    again = _draw(a, _truth(), 30)
    first_valid = next(i for i in range(30) if ea[i].valid and again[i].valid)
    assert not np.array_equal(ea[first_valid].keypoints_cam, again[first_valid].keypoints_cam)
    c = _draw(OracleEstimator(**kwargs, rng=np.random.default_rng(7)), _truth(), 1)[0]
    assert c.valid == ea[0].valid  # a Generator and its int seed are interchangeable


def test_predict_before_observe_truth_raises():
    """A predict without an observed truth says that observe_truth must come first."""
    with pytest.raises(EstimatorStateError, match=r"call observe_truth\(frame\) before predict"):
        OracleEstimator().predict(DEPTH, K)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"noise_mm": -1.0}, r"noise_mm must be a finite number >= 0; received -1.0"),
        ({"noise_mm": float("nan")}, r"noise_mm must be a finite number >= 0"),
        ({"noise_mm": "big"}, r"noise_mm must be a number >= 0; received 'big'"),
        ({"bias_mm": (1.0, 2.0)}, r"bias_mm must be 3 finite numbers .* received \(1.0, 2.0\)"),
        ({"dropout": 1.5}, r"dropout is a probability and must lie in \[0, 1\]; received 1.5"),
        ({"dropout": -0.1}, r"dropout must be a finite number >= 0"),
        ({"latency_steps": 1.5}, r"latency_steps must be an int >= 0 .* received 1.5"),
        ({"latency_steps": -1}, r"latency_steps must be an int >= 0 .* received -1"),
        ({"latency_steps": True}, r"latency_steps must be an int >= 0 .* received True"),
        ({"object_noise_mm": -2}, r"object_noise_mm must be a finite number >= 0"),
        ({"object_noise_deg": -2}, r"object_noise_deg must be a finite number >= 0"),
        ({"rng": "seed"}, r"rng must be a numpy.random.Generator, an int seed or None"),
    ],
)
def test_invalid_arguments_name_the_valid_range(kwargs, message):
    """Bad constructor arguments raise InvalidEstimatorParams with the valid range."""
    with pytest.raises(InvalidEstimatorParams, match=message):
        OracleEstimator(**kwargs)


def test_bad_truth_and_batches_are_rejected():
    """observe_truth needs (21, 3) keypoints; predict_batch handles one frame at a time."""
    oracle = OracleEstimator(rng=0)
    with pytest.raises(InvalidEstimatorInput, match=r"finite \(21, 3\) keypoints_cam"):
        oracle.observe_truth(SimpleNamespace(keypoints_cam=np.zeros((14, 3)), objects=()))
    oracle.observe_truth(_truth())
    (est,) = oracle.predict_batch(DEPTH[None], K[None])
    assert est.valid
    with pytest.raises(EstimatorStateError, match=r"batches of 1; received a batch of 2"):
        oracle.predict_batch(np.stack([DEPTH, DEPTH]), np.stack([K, K]))
    with pytest.raises(InvalidEstimatorInput, match=r"depth must be an \(H, W\) image"):
        oracle.predict(DEPTH[None], K)


def test_oracle_on_a_rendered_frame_has_the_configured_error():
    """On a rendered Frame, a 10 mm bias gives 10 mm errors and exact object poses ADD 0."""
    from handsim.world.scene import CameraSpec, ObjectPlacement, Scene, SceneSpec

    cam = CameraSpec.look_at("front", ICVL, (0.0, -0.5, 0.3), (0.0, 0.0, 0.1))
    spec = SceneSpec(cameras=(cam,), objects=(ObjectPlacement("061_foam_brick", (0.1, 0, 0.03)),))
    scene = Scene(spec)
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0))
    oracle = OracleEstimator(bias_mm=(0.0, 6.0, 8.0), rng=0)
    oracle.observe_truth(frame)
    errors = estimate_errors(oracle.predict(frame.depth, frame.K), frame)
    assert errors["kp_mean_mm"] == pytest.approx(10.0, abs=1e-9)
    assert errors["center_mm"] == pytest.approx(10.0, abs=1e-9)
    assert errors["add_mm"] == {0: pytest.approx(0.0, abs=1e-9)}
