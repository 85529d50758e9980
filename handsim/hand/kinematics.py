"""Forward kinematics of the hand in NumPy, vectorized over a batch of poses.

Built from the same :class:`~handsim.hand.Skeleton` as the MuJoCo model, it composes each
body's fixed offset with its hinges (outermost first, every hinge at the body origin), exactly
as MuJoCo does; keypoints agree with the model's sites to float precision (tested < 1e-6 m).
"""

from __future__ import annotations

import numpy as np

from handsim.errors import InvalidPose
from handsim.hand.keypoints import EXTRA_POINT_NAMES
from handsim.hand.pose import HandPose
from handsim.hand.skeleton import HandParams, Skeleton, build_skeleton, extra_point_positions

__all__ = ["ForwardKinematics", "axis_angle_matrices"]


def axis_angle_matrices(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices about one fixed unit axis (Rodrigues), vectorized over angles.

    Args:
        axis: (3,) unit axis.
        angle: (N,) angles, radians.

    Returns:
        (N, 3, 3) rotation matrices.
    """
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    kk = k @ k
    s = np.sin(angle)[:, None, None]
    c = np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * kk


class ForwardKinematics:
    """Keypoints (and body frames) of a hand for a batch of 27-DoF poses.

    Args:
        hand: hand parameters or a prebuilt skeleton.
    """

    def __init__(self, hand: HandParams | Skeleton) -> None:
        # scipy.spatial loads when kinematics are built, not on `import handsim`.
        from scipy.spatial.transform import Rotation

        self.skeleton = hand if isinstance(hand, Skeleton) else build_skeleton(hand)
        bodies = self.skeleton.bodies
        self._offset_rot = np.stack(
            [Rotation.from_quat(np.roll(b.quat_wxyz, -1)).as_matrix() for b in bodies]
        )
        self._offset_pos = np.stack([b.pos for b in bodies])
        self._parents = [b.parent for b in bodies]
        self._joints = [b.joints for b in bodies]
        self._kp_body = np.array([i for i, _ in self.skeleton.keypoints], dtype=np.intp)
        self._kp_local = np.stack([p for _, p in self.skeleton.keypoints])
        extra = extra_point_positions(self.skeleton)
        self._extra_local = np.stack([extra[name] for name in EXTRA_POINT_NAMES])

    def body_frames(self, pose: HandPose) -> tuple[np.ndarray, np.ndarray]:
        """World pose of every body.

        Args:
            pose: a single pose or a batch (any batch shape).

        Returns:
            ``(R, t)``: (..., B, 3, 3) rotations ``world_from_body`` and (..., B, 3) origins,
            metres, for the B bodies in skeleton order.

        Raises:
            InvalidPose: if ``pose`` is not a :class:`HandPose`.
        """
        if not isinstance(pose, HandPose):
            raise InvalidPose(
                f"pose must be a HandPose (a single pose or a batch); received "
                f"{type(pose).__name__} {str(pose)[:40]!r}: make one with HandPose.from_vector, "
                "gesture(name) or grasp_pose(name)"
            )
        from scipy.spatial.transform import Rotation

        batch = pose.batch_shape
        angles = pose.angles.reshape(-1, pose.angles.shape[-1])
        n = angles.shape[0]
        root_rot = Rotation.from_rotvec(pose.wrist_rotvec.reshape(-1, 3)).as_matrix()
        root_pos = pose.wrist_pos.reshape(-1, 3)
        num_bodies = len(self._parents)
        rots = np.empty((n, num_bodies, 3, 3))
        poss = np.empty((n, num_bodies, 3))
        for b, parent in enumerate(self._parents):
            if parent < 0:
                parent_rot, parent_pos = root_rot, root_pos
            else:
                parent_rot, parent_pos = rots[:, parent], poss[:, parent]
            rot = parent_rot @ self._offset_rot[b]
            poss[:, b] = parent_pos + parent_rot @ self._offset_pos[b]
            for angle_index, axis in self._joints[b]:
                rot = rot @ axis_angle_matrices(axis, angles[:, angle_index])
            rots[:, b] = rot
        return rots.reshape(batch + (num_bodies, 3, 3)), poss.reshape(batch + (num_bodies, 3))

    def keypoints(self, pose: HandPose) -> np.ndarray:
        """The 21 keypoints in the world frame.

        Args:
            pose: a single pose or a batch.

        Returns:
            (..., 21, 3) keypoint positions, metres, in :data:`~handsim.hand.KEYPOINT_NAMES`
            order.
        """
        rots, poss = self.body_frames(pose)
        r = rots[..., self._kp_body, :, :]
        t = poss[..., self._kp_body, :]
        return t + np.einsum("...kij,kj->...ki", r, self._kp_local)

    def points(self, pose: HandPose) -> np.ndarray:
        """Every hand point: the 21 keypoints, then the other formats' extra points.

        Args:
            pose: a single pose or a batch.

        Returns:
            (..., 29, 3) positions, metres, in
            :data:`~handsim.hand.keypoints.HAND_POINT_NAMES` order.
        """
        rots, poss = self.body_frames(pose)
        r = rots[..., self._kp_body, :, :]
        t = poss[..., self._kp_body, :]
        keypoints = t + np.einsum("...kij,kj->...ki", r, self._kp_local)
        palm_rot, palm_pos = rots[..., 0, :, :], poss[..., 0, :]
        extra = palm_pos[..., None, :] + np.einsum("...ij,kj->...ki", palm_rot, self._extra_local)
        return np.concatenate([keypoints, extra], axis=-2)
