"""Tests of the 27-DoF pose type, joint order and limits."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.errors import HandSimError, InvalidPose
from handsim.hand.pose import (
    JOINT_LIMITS,
    JOINT_LIMITS_DEG,
    JOINT_NAMES,
    NUM_DOF,
    HandPose,
    joint_index,
)


def test_joint_order_follows_design():
    """The 21 angles in docs/conventions.md order: thumb CMC/MCP/IP, each finger MCP, PIP, DIP."""
    assert len(JOINT_NAMES) == 21
    assert JOINT_NAMES[:5] == (
        "thumb_cmc_flex",
        "thumb_cmc_abd",
        "thumb_mcp_flex",
        "thumb_mcp_abd",
        "thumb_ip_flex",
    )
    for k, finger in enumerate(("index", "middle", "ring", "little")):
        assert JOINT_NAMES[5 + 4 * k : 9 + 4 * k] == (
            f"{finger}_mcp_flex",
            f"{finger}_mcp_abd",
            f"{finger}_pip_flex",
            f"{finger}_dip_flex",
        )


def test_limits_are_ordered_and_contain_the_flat_hand():
    """Every range is non-empty, contains 0, and the degree and radian tables agree."""
    assert JOINT_LIMITS.shape == (21, 2)
    assert np.all(JOINT_LIMITS[:, 0] < JOINT_LIMITS[:, 1])
    assert np.all((JOINT_LIMITS[:, 0] <= 0) & (JOINT_LIMITS[:, 1] >= 0))
    np.testing.assert_allclose(np.rad2deg(JOINT_LIMITS), JOINT_LIMITS_DEG)
    assert JOINT_LIMITS_DEG[joint_index("index_pip_flex")].tolist() == [0.0, 110.0]


def test_vector_round_trip_single_and_batch():
    """27-vector -> HandPose -> 27-vector is exact, for any batch shape."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=(4, 5, NUM_DOF))
    pose = HandPose.from_vector(v)
    assert pose.batch_shape == (4, 5)
    np.testing.assert_array_equal(pose.vector, v)
    np.testing.assert_array_equal(pose[1, 2].vector, v[1, 2])
    assert len(pose) == 4


def test_quat_wxyz_matches_rotvec():
    """quat_wxyz is the rotation vector in MuJoCo's (w, x, y, z) order."""
    rotvec = np.array([0.3, -0.2, 1.1])
    pose = HandPose.neutral(wrist_rotvec=rotvec)
    quat_xyzw = Rotation.from_rotvec(rotvec).as_quat()
    np.testing.assert_allclose(pose.quat_wxyz, np.roll(quat_xyzw, 1))


def test_from_angles_and_angle_by_name():
    """Named angles land at their index; unnamed ones are zero."""
    pose = HandPose.from_angles({"index_pip_flex": 1.0})
    assert pose.angle("index_pip_flex") == 1.0
    assert np.count_nonzero(pose.angles) == 1


def test_clip_and_violations():
    """Violations name the offending joints; clip() clamps them to their limits."""
    angles = np.zeros(21)
    angles[joint_index("index_pip_flex")] = np.deg2rad(130)
    angles[joint_index("middle_mcp_abd")] = np.deg2rad(-25)
    pose = HandPose(np.zeros(3), np.zeros(3), angles)
    assert not pose.within_limits()
    names = [v.joint for v in pose.violations()]
    assert names == ["index_pip_flex", "middle_mcp_abd"]
    clipped = pose.clip()
    assert clipped.within_limits()
    assert clipped.angle("index_pip_flex") == pytest.approx(np.deg2rad(110))
    assert clipped.angle("middle_mcp_abd") == pytest.approx(np.deg2rad(-20))


def test_mirrored_is_an_involution():
    """Mirroring twice is the identity and keeps the angles."""
    pose = HandPose.from_vector(np.random.default_rng(1).normal(size=NUM_DOF))
    np.testing.assert_allclose(pose.mirrored().mirrored().vector, pose.vector)
    np.testing.assert_array_equal(pose.mirrored().angles, pose.angles)


def test_errors_are_handsim_errors():
    """Pose errors are HandSimErrors and ValueErrors."""
    assert issubclass(InvalidPose, HandSimError)
    assert issubclass(InvalidPose, ValueError)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (
            lambda: HandPose.from_vector(np.zeros(26)),
            r"shape \(\.\.\., 27\).*received shape \(26,\)",
        ),
        (lambda: HandPose(np.zeros(2), np.zeros(3), np.zeros(21)), r"wrist_pos must have shape"),
        (lambda: HandPose(np.zeros(3), np.zeros(3), np.zeros(20)), r"angles must have shape"),
        (
            lambda: HandPose(np.zeros(3), np.array([0, np.nan, 0]), np.zeros(21)),
            r"wrist_rotvec contains NaN or Inf",
        ),
        (
            lambda: HandPose(np.zeros((2, 3)), np.zeros((3, 3)), np.zeros((2, 21))),
            r"must share their batch shape",
        ),
        (lambda: joint_index("index_pip"), r"unknown joint 'index_pip'; valid joints: thumb_cmc"),
        (
            lambda: HandPose.from_angles({"index_pip_flex": 2.5}).validate(),
            r"index_pip_flex = 143\.24 deg is outside \[0\.0, 110\.0\] deg.*HandPose\.clip",
        ),
    ],
)
def test_error_messages(make, message):
    """Every pose error says what was expected and what was received."""
    with pytest.raises(InvalidPose, match=message):
        make()


def test_len_of_single_pose_raises():
    """len() of a single pose is an error, not 27 or 3."""
    with pytest.raises(TypeError, match="not a batch"):
        len(HandPose.neutral())


@pytest.mark.parametrize(
    ("vector", "message"),
    [
        ("abc", r"must be real numbers of shape \(\.\.\., 27\).*received str of dtype <U3"),
        (np.zeros(27, dtype=complex), r"must be real numbers .*received ndarray of dtype complex"),
        ([[0.0] * 27, [0.0] * 5], r"must be real numbers .*received list of dtype object"),
    ],
)
def test_from_vector_refuses_what_is_not_real_numbers(vector, message):
    """A string, complex values or a ragged list: InvalidPose, never a silent real part."""
    with pytest.raises(InvalidPose, match=message):
        HandPose.from_vector(vector)


@pytest.mark.parametrize(
    ("pose", "message"),
    [
        ("open", r"set_pose takes a HandPose \(e.g. gesture\('open'\).*received str"),
        (None, r"set_pose takes a HandPose .*received NoneType"),
        (np.zeros(27), r"set_pose takes a HandPose .*received ndarray"),
        (
            HandPose.from_vector(np.zeros((2, 27))),
            r"set_pose takes one pose; received a batch of shape \(2,\)",
        ),
    ],
)
def test_set_pose_takes_one_pose(pose, message):
    """A gesture's name, None, a bare vector or a batch: InvalidPose saying what to pass."""
    import mujoco

    from handsim.hand.model import Hand, hand_params

    hand = Hand(hand_params("medium", "right"))
    model = hand.compile()
    data = mujoco.MjData(model)
    with pytest.raises(InvalidPose, match=message):
        hand.bind(model).set_pose(data, pose)
    with pytest.raises(InvalidPose, match=message.replace("set_pose", "set_target")):
        hand.bind(model).set_target(data, pose)
