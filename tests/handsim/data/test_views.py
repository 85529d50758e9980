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


def test_third_person_palm_or_back_within_the_cone():
    """The palm normal lies within the cone of the line of sight, palm and back about half."""
    angles = _angle_deg(_palm_normal_in_camera(_draws("third_person")), TO_CAMERA)
    facing = np.minimum(angles, 180.0 - angles)
    assert facing.max() <= views.THIRD_PERSON_CONE_DEG + 1e-9
    # Uniform over the cap: cos(facing) uniform in [cos 60, 1], its median at cos = 0.75.
    assert abs(np.median(np.cos(np.radians(facing))) - 0.75) < 0.02
    assert abs(np.mean(angles < 90.0) - views.PALM_FRACTION) < 0.03


def test_third_person_fingers_up_or_sideways_and_seldom_into_the_lens():
    """Fingers point up in the image or sideways, never into the lens.

    Sideways at most, tilted by the cone: 110 deg from up. The distal axis stays 30 deg from
    the lens direction, less the palm normal's 7 deg lean.
    """
    R = _draws("third_person")  # noqa: N806
    distal = R[:, :, 1]
    from_up = np.degrees(np.arctan2(np.abs(distal[:, 0]), -distal[:, 1]))
    # The roll cut at 90 deg, plus at most atan(0.354) = 19.5 deg from the 60 deg tilt.
    assert from_up.max() < 110.0
    assert np.median(from_up) < 35.0
    assert _angle_deg(distal, TO_CAMERA).min() > 20.0


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


def test_rendered_third_person_frames_keep_the_cone():
    """In rendered hand-alone frames the keypoints' palm angle stays in the cone.

    To 2 deg: the camera aims at a point near, not at, the palm centre. The labels say the view
    and pose source.
    """
    config = GenerationConfig.from_mapping(
        PRESETS["hand-only"], viewpoints=("third_person",), sensor="none"
    )
    frames = _frames(config, episodes=4, frames=5)
    kp = np.stack([f["keypoints_cam"] for f in frames])
    left = np.array([bool(f["is_left"]) for f in frames])
    angles = palm_angles_deg(kp, left)
    assert np.minimum(angles, 180.0 - angles).max() < views.THIRD_PERSON_CONE_DEG + 2.0
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
