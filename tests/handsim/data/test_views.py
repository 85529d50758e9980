"""Tests of handsim.data.views: how the kinematic source turns a hand toward the camera."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.data import views
from handsim.data.config import PRESETS, GenerationConfig, InvalidGenerationConfig
from handsim.data.kinematic import KinematicSource
from handsim.data.stats import palm_angles_deg
from handsim.data.views import hand_rotation_in_camera, mirror_rotation

DRAWS = 4000
TO_CAMERA = np.array([0.0, 0.0, -1.0])  # the camera looks at the palm along its +z


def _draws(view, is_left=False, n=DRAWS, seed=0):
    rng = np.random.default_rng(seed)
    return np.stack([hand_rotation_in_camera(rng, view, is_left) for _ in range(n)])


def _palm_normal_in_camera(R):  # noqa: N803
    # The keypoints' palm normal in the hand frame is the preimage of +z under _palm_to_z.
    normal_hand = views._palm_to_z().T @ np.array([0.0, 0.0, 1.0])
    return R @ normal_hand


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


@pytest.mark.parametrize("view", views.HAND_VIEWS)
def test_draws_are_proper_rotations(view):
    """Every draw, either side, is orthonormal with determinant +1."""
    for is_left in (False, True):
        R = _draws(view, is_left, n=200)  # noqa: N806
        np.testing.assert_allclose(
            R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
        )
        np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


def _turns_about_mean(R, mean_deg, face):  # noqa: N803
    """Rotation vectors (deg) of each draw's turn about a mode's mean, for the draws of it."""
    mean = Rotation.from_rotvec(np.radians(mean_deg))
    turn = mean.inv() * Rotation.from_matrix(R @ (face @ views._palm_to_z()).T)
    return np.degrees(turn.as_rotvec())


def _mahalanobis2(turn_deg, cov_deg2):
    return np.einsum("ni,ij,nj->n", turn_deg, np.linalg.inv(np.asarray(cov_deg2)), turn_deg)


def test_third_person_draws_recover_the_measured_modes():
    """Palm toward the camera in PALM_FRACTION of draws; each mode's mean and covariance.

    A draw belongs to the palm mode when its turn lies within the palm mode's 3-sigma cut (few
    back draws do); the turns about each mode's mean have mean 0 and the stated covariance.
    """
    R = _draws("third_person", n=8000)  # noqa: N806
    palm_turn = _turns_about_mean(R, views.THIRD_PERSON_PALM_MEAN_ROTVEC_DEG, views._PALM_TO_CAMERA)
    back_turn = _turns_about_mean(R, views.THIRD_PERSON_BACK_MEAN_ROTVEC_DEG, views._BACK_TO_CAMERA)
    palm = _mahalanobis2(palm_turn, views.THIRD_PERSON_PALM_COV_DEG2) <= 9.0 + 1e-6
    assert abs(palm.mean() - views.PALM_FRACTION) < 0.02
    for turn, cov in (
        (palm_turn[palm], views.THIRD_PERSON_PALM_COV_DEG2),
        (back_turn[~palm], views.THIRD_PERSON_BACK_COV_DEG2),
    ):
        sd = np.sqrt(np.diag(cov))
        np.testing.assert_array_less(np.abs(turn.mean(axis=0)), 0.1 * sd)
        # The cut at 3 sigma narrows a 3-D Gaussian's spread by 4 %.
        np.testing.assert_allclose(turn.std(axis=0), 0.96 * sd, rtol=0.08)
        # Nothing beyond the cut: the Mahalanobis distance of every turn is at most 3.
        assert _mahalanobis2(turn, cov).max() <= views.THIRD_PERSON_MAX_SIGMA**2 + 1e-6


def test_third_person_palm_angles_as_measured_on_nyu():
    """The keypoints' palm angle to the camera axis as in NYU's test labels.

    NYU (8 252 frames, measured with the same hand frame): 80 % palm toward the camera,
    angle quantiles 10/50/90 % = 18/37/123 deg; the fingers within 22 deg of the lens in 5 %.
    Articulation is not in this test (rotations only), so the bands are wide.
    """
    R = _draws("third_person")  # noqa: N806
    angles = _angle_deg(_palm_normal_in_camera(R), TO_CAMERA)
    assert 0.76 < np.mean(angles < 90.0) < 0.85
    p10, p50, p90 = np.percentile(angles, [10, 50, 90])
    assert 10.0 < p10 < 28.0 and 28.0 < p50 < 55.0 and 105.0 < p90 < 140.0
    into_lens = _angle_deg(R[:, :, 1], TO_CAMERA)
    assert 0.02 < np.mean(into_lens < 25.0) < 0.10


def test_egocentric_sees_the_back_of_the_hand_with_fingers_away():
    """From behind and above: the back of the hand (or its side) faces the camera.

    Never the palm face-on, and the fingers point away from the camera.
    """
    R = _draws("egocentric")  # noqa: N806
    angles = _angle_deg(_palm_normal_in_camera(R), TO_CAMERA)
    assert np.mean(angles > 90.0) > 0.85
    assert angles.min() > 45.0
    assert np.all(R[:, 2, 1] > 0.0)  # the distal axis has a +z (away) component
    # The forearm (-distal) comes in from the bottom of the image: within 60 deg of down.
    forearm = -R[:, :2, 1]
    from_down = np.degrees(np.arctan2(np.abs(forearm[:, 0]), forearm[:, 1]))
    assert from_down.max() <= views.EGO_FOREARM_FROM_DOWN_DEG + 1e-9


def test_random_view_is_uniform_over_so3():
    """`random` (on request): every axis of the hand uniform on the sphere (moments 0, 1/3)."""
    R = _draws("random")  # noqa: N806
    for axis in range(3):
        z = R[:, 2, axis]
        assert abs(z.mean()) < 0.03 and abs(np.mean(z**2) - 1.0 / 3.0) < 0.02


@pytest.mark.parametrize("view", views.HAND_VIEWS)
def test_a_left_hand_is_the_mirror_image_of_a_right_hand(view):
    """The same generator state gives a left hand the right hand's draw mirrored."""
    right, left = _draws(view, False, n=50, seed=3), _draws(view, True, n=50, seed=3)
    np.testing.assert_allclose(left, [mirror_rotation(R) for R in right], atol=1e-15)


def test_an_unknown_view_names_the_valid_ones():
    """A bad view raises with the list of views."""
    with pytest.raises(InvalidGenerationConfig, match="view must be one of third_person, ego"):
        hand_rotation_in_camera(np.random.default_rng(0), "overhead", False)


def _frames(config, seed=0, episodes=2, frames=6):
    source = KinematicSource(config)
    try:
        out = []
        for episode in range(episodes):
            rng = np.random.default_rng([seed, episode])
            out += [
                {k: np.array(v) for k, v in a.items()}
                for a in source.episode(rng, lambda ratio, visible: True, frames)
            ]
        return out
    finally:
        source.close()


def test_rendered_third_person_frames_are_labelled_and_mostly_palm_on():
    """Rendered hand-alone frames say their view and pose source; most show the palm."""
    config = GenerationConfig.from_mapping(
        PRESETS["hand-only"], viewpoints=("third_person",), sensor="none"
    )
    frames = _frames(config, episodes=4, frames=5)
    kp = np.stack([f["keypoints_cam"] for f in frames])
    left = np.array([bool(f["is_left"]) for f in frames])
    angles = palm_angles_deg(kp, left)
    assert np.mean(angles < 90.0) >= 0.5
    assert {int(f["viewpoint"]) for f in frames} == {0}
    assert {int(f["pose_source"]) for f in frames} <= {0, 1, 2, 4}  # never uniform


def test_uniform_wrists_and_joint_angles_on_request():
    """viewpoints=('random',) and pose_sources=('uniform',) still give the old draws."""
    config = GenerationConfig(
        num_objects_range=(0, 0), viewpoints=("random",), pose_sources=("uniform",), sensor="none"
    )
    frames = _frames(config, episodes=1, frames=4)
    assert {int(f["viewpoint"]) for f in frames} == {2}
    assert {int(f["pose_source"]) for f in frames} == {3}


def test_the_same_seed_gives_the_same_frames():
    """Two sources, the same generator state: identical images and labels (motions too)."""
    config = GenerationConfig.from_mapping(PRESETS["hand-only"], pose_sources=("motion",))
    first, second = _frames(config, seed=5), _frames(config, seed=5)
    assert len(first) == len(second) == 12
    for a, b in zip(first, second, strict=True):
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_among_objects_the_head_camera_stands_behind_the_wrist_and_above():
    """Egocentric among objects: the eye is back along the forearm (within 30 deg) and above."""
    source = KinematicSource(GenerationConfig(sensor="none"))
    rng = np.random.default_rng(0)
    target = np.array([0.1, 0.0, 0.1])
    try:
        for _ in range(50):
            rotvec = rng.normal(size=3)
            R = Rotation.from_rotvec(rotvec).as_matrix()  # noqa: N806
            eye, _ = source._camera(rng, "egocentric", target, None, rotvec)
            offset = eye - target
            back = -R[:2, 1] / np.linalg.norm(R[:2, 1])
            horizontal = offset[:2] / np.linalg.norm(offset[:2])
            assert np.degrees(np.arccos(np.clip(horizontal @ back, -1, 1))) <= 30.0 + 1e-9
            elevation = np.degrees(np.arctan2(offset[2], np.linalg.norm(offset[:2])))
            assert 40.0 - 1e-9 <= elevation <= 70.0 + 1e-9
    finally:
        source.close()
