"""Tests of handsim.data.stats: palm angles and the constant-mean-pose error, analytic cases."""

import numpy as np
import pytest

from handsim.data import views
from handsim.data.stats import (
    InvalidStatsInput,
    constant_pose_error_mm,
    mean_joint_distance_mm,
    palm_angles_deg,
    palm_normals,
)
from handsim.hand.keypoints import FORMATS, to_format
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import hand_params
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import gesture

CENTRE = FORMATS["nyu14"].index("PALM_3")


def _keypoints(side="right", name="fist"):
    """(21, 3) keypoints of a medium hand in its own frame (wrist at the origin), metres."""
    angles = gesture(name).angles
    return ForwardKinematics(hand_params("medium", side)).keypoints(
        HandPose(np.zeros(3), np.zeros(3), angles)
    )


def _in_camera(kp_hand, R_cam_from_hand, depth_m=0.5):  # noqa: N803
    """Keypoints turned into the camera and moved so that the palm centre is on the axis."""
    kp = kp_hand @ R_cam_from_hand.T
    centre = to_format(kp, "nyu14")[CENTRE]
    return kp - centre + np.array([0.0, 0.0, depth_m])


def _tilt(angle_deg):
    return views._axis_angle(np.array([1.0, 0.0, 0.0]), np.radians(angle_deg))


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("tilt_deg", [0.0, 25.0, 60.0])
def test_palm_angle_is_the_tilt_from_facing_the_camera(side, tilt_deg):
    """The views' palm-to-camera rotation tilted by t reads t (palm) and 180 - t (back)."""
    left = side == "left"
    palm = views._PALM_TO_CAMERA @ views._palm_to_z()
    back = views._BACK_TO_CAMERA @ views._palm_to_z()
    for base, expected in ((palm, tilt_deg), (back, 180.0 - tilt_deg)):
        R = _tilt(tilt_deg) @ base  # noqa: N806
        R = views.mirror_rotation(R) if left else R  # noqa: N806
        kp = _in_camera(_keypoints(side), R)[None]
        np.testing.assert_allclose(palm_angles_deg(kp, np.array([left])), [expected], atol=1e-6)


def test_palm_normal_sign_follows_the_side():
    """A left hand's palm normal is the mirror of the right's (the same sign convention)."""
    right = palm_normals(_keypoints("right")[None], np.array([False]))[0]
    left = palm_normals(_keypoints("left")[None], np.array([True]))[0]
    np.testing.assert_allclose(left, right * [-1.0, 1.0, 1.0], atol=1e-12)
    assert right[2] > 0.99  # palmar: the hand frame's +z, within 7 deg


def test_one_repeated_pose_has_no_error():
    """Frames of one pose at different places: the mean pose is exact (0 mm)."""
    kp = _in_camera(_keypoints(), np.eye(3))
    frames = np.stack([kp + shift for shift in ([0, 0, 0], [0.1, -0.05, 0.2], [-0.2, 0, 0.4])])
    assert constant_pose_error_mm(frames, np.zeros(3, bool)) == pytest.approx(0.0, abs=1e-9)


def test_two_point_mirrored_poses_err_by_their_mean_distance():
    """A pose and its reflection through the palm centre err by their mean joint distance.

    The mean pose is then the centre itself.
    """
    kp = _in_camera(_keypoints(), np.eye(3))
    centre = to_format(kp, "nyu14")[CENTRE]
    frames = np.stack([kp, 2.0 * centre - kp])
    rel = to_format(kp, "nyu14") - centre
    expected = 1000.0 * np.linalg.norm(rel, axis=1).mean()
    left = np.zeros(2, bool)
    assert constant_pose_error_mm(frames, left) == pytest.approx(expected, rel=1e-12)
    assert mean_joint_distance_mm(frames, left) == pytest.approx(expected, rel=1e-12)


def test_left_hands_are_mirrored_into_right_ones():
    """A right hand and the left hand that is its mirror image in the camera: 0 mm."""
    R = _tilt(30.0) @ views._PALM_TO_CAMERA  # noqa: N806
    right = _in_camera(_keypoints("right"), R)
    left = _in_camera(_keypoints("left"), views.mirror_rotation(R))
    np.testing.assert_allclose(left, right * [-1.0, 1.0, 1.0], atol=1e-12)
    frames = np.stack([right, left])
    assert constant_pose_error_mm(frames, np.array([False, True])) == pytest.approx(0, abs=1e-9)
    assert constant_pose_error_mm(frames, np.array([False, False])) > 10.0


@pytest.mark.parametrize(
    ("kp", "left", "match"),
    [
        (np.zeros((2, 20, 3)), np.zeros(2, bool), r"expected keypoints_cam of shape \(N, 21, 3\)"),
        (np.zeros((2, 21, 3)), np.zeros(3, bool), r"and is_left of shape \(N,\); received"),
        (np.full((1, 21, 3), np.nan), np.zeros(1, bool), "must be finite"),
        (np.zeros((0, 21, 3)), np.zeros(0, bool), "needs at least one frame"),
    ],
)
def test_bad_input_says_what_is_expected(kp, left, match):
    """Wrong shapes, NaN and no frames raise InvalidStatsInput with what is valid."""
    with pytest.raises(InvalidStatsInput, match=match):
        constant_pose_error_mm(kp, left)
