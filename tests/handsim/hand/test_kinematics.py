"""Forward kinematics in NumPy against MuJoCo's sites."""

import itertools

import mujoco
import numpy as np
import pytest

from handsim.hand.kinematics import ForwardKinematics, axis_angle_matrices
from handsim.hand.model import HAND_SIZES, Hand, HandParams
from handsim.hand.pose import JOINT_LIMITS, HandPose


@pytest.mark.parametrize(
    ("size", "side"), list(itertools.product(HAND_SIZES.values(), ("right", "left")))
)
def test_keypoints_match_mujoco_sites(size, side):
    """NumPy FK agrees with MuJoCo's keypoint sites to < 1e-6 m for random poses."""
    hand = Hand(HandParams(hand_length=size, side=side, palm_breadth=0.42 * size))
    model = hand.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    rng = np.random.default_rng(0)
    n = 20
    poses = HandPose(
        rng.uniform(-0.5, 0.5, (n, 3)),
        rng.uniform(-np.pi, np.pi, (n, 3)),
        rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1], (n, 21)),
    )
    fk = ForwardKinematics(hand.params).keypoints(poses)
    assert fk.shape == (n, 21, 3)
    for i in range(n):
        binding.set_pose(data, poses[i])
        assert np.abs(fk[i] - binding.keypoints(data)).max() < 1e-6


def test_batch_shapes_and_single_pose_agree():
    """A batched FK call equals the single-pose call for each element."""
    fk = ForwardKinematics(HandParams())
    rng = np.random.default_rng(1)
    poses = HandPose.from_vector(rng.normal(size=(2, 3, 27)) * 0.3)
    batch = fk.keypoints(poses)
    assert batch.shape == (2, 3, 21, 3)
    np.testing.assert_allclose(batch[1, 2], fk.keypoints(poses[1, 2]), atol=1e-15)


def test_rigid_motion_of_the_wrist_moves_all_keypoints_rigidly():
    """Moving the wrist moves every keypoint by the same rigid transform."""
    fk = ForwardKinematics(HandParams())
    angles = np.deg2rad(np.linspace(0, 40, 21))
    local = fk.keypoints(HandPose(np.zeros(3), np.zeros(3), angles))
    moved = fk.keypoints(
        HandPose(np.array([0.1, -0.2, 0.3]), np.array([0.0, 0.0, np.pi / 2]), angles)
    )
    rot_z = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(moved, local @ rot_z.T + [0.1, -0.2, 0.3], atol=1e-12)


def test_axis_angle_matrices_are_rotations():
    """Rodrigues matrices are proper rotations that fix their axis."""
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    rots = axis_angle_matrices(axis, np.linspace(-3, 3, 7))
    np.testing.assert_allclose(
        rots @ rots.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (7, 3, 3)), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(rots), 1.0)
    np.testing.assert_allclose(rots @ axis, np.broadcast_to(axis, (7, 3)), atol=1e-12)
