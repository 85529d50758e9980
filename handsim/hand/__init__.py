"""The hand: model, poses and limits, kinematics, retargeting, pose sources, keypoint formats.

=======================  ==========================================================================
module                   holds
=======================  ==========================================================================
:mod:`.skeleton`         :class:`HandParams`, presets, the kinematic :class:`Skeleton` (anatomy)
:mod:`.model`            :class:`Hand` (MJCF via ``mujoco.MjSpec``), :class:`HandBinding`
:mod:`.pose`             :class:`HandPose`, the 27-vector, joint names and limits
:mod:`.kinematics`       NumPy forward kinematics of the 21 keypoints (batched)
:mod:`.retarget`         21 keypoints of any hand size to a 27-DoF pose
:mod:`.pose_prior`       a Gaussian over natural postures, for MAP retargeting
:mod:`.pose_sources`     seeded poses: uniform, synergies, grasp taxonomy, gestures, motions
:mod:`.keypoints`        the keypoint order and converters to and from other datasets' formats
=======================  ==========================================================================
"""

from handsim.hand.keypoints import FORMATS, KEYPOINT_NAMES, from_format, to_format
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HAND_PHYSICS_OPTIONS, Hand, HandBinding
from handsim.hand.pose import (
    JOINT_LIMITS,
    JOINT_LIMITS_DEG,
    JOINT_NAMES,
    NUM_DOF,
    HandPose,
    LimitViolation,
)
from handsim.hand.pose_prior import PosePrior, default_pose_prior
from handsim.hand.retarget import Retargeter, RetargetResult
from handsim.hand.skeleton import HAND_SIZES, HandParams, Skeleton, build_skeleton, hand_params

__all__ = [
    "FORMATS",
    "KEYPOINT_NAMES",
    "from_format",
    "to_format",
    "ForwardKinematics",
    "HAND_PHYSICS_OPTIONS",
    "HAND_SIZES",
    "Hand",
    "HandBinding",
    "HandParams",
    "Skeleton",
    "build_skeleton",
    "hand_params",
    "JOINT_LIMITS",
    "JOINT_LIMITS_DEG",
    "JOINT_NAMES",
    "NUM_DOF",
    "HandPose",
    "LimitViolation",
    "Retargeter",
    "RetargetResult",
    "PosePrior",
    "default_pose_prior",
]
