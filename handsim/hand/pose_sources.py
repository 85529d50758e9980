"""Pose sources: anatomical uniform sampling, postural synergies, grasps, gestures and motions.

Every source returns a :class:`~handsim.hand.pose.HandPose` (angles in radians, :data:`JOINT_NAMES`
order, wrist at the origin with identity rotation unless stated) whose angles lie within
:data:`~handsim.hand.pose.JOINT_LIMITS`. Every random draw takes a ``numpy.random.Generator``; the
same generator state gives bit-identical output.

Sources
-------

:func:`sample_uniform`
    Uniform within the joint limits, optionally with anatomical couplings.
:func:`sample_synergy`, :func:`synergy_pose`, :func:`synergy_basis`
    Postural synergies: a PCA basis of the grasp library.
:data:`GRASP_TYPES`, :func:`grasp_pose`, :func:`sample_grasp`
    13 grasp types of the GRASP taxonomy (Feix et al. 2016), each a function of ``closure``.
:data:`GESTURES`, :func:`gesture`
    14 named hand gestures.
:func:`smooth_motion`, :func:`random_motion`
    Minimum-jerk motions through keyframes with human speed limits.

The sources live in :mod:`~handsim.hand.samplers` (uniform with anatomical couplings,
synergies), :mod:`~handsim.hand.pose_library` (grasp taxonomy, gestures) and
:mod:`~handsim.hand.motions` (smooth motions); each module documents its sources. Every name
is importable from here.
"""

from __future__ import annotations

from handsim.hand.motions import (
    MAX_JOINT_SPEED,
    MAX_WRIST_ANGULAR_SPEED,
    MAX_WRIST_SPEED,
    MOTION_SOURCES,
    WRIST_SPEED_CAP,
    minimum_jerk,
    random_motion,
    segment_durations,
    smooth_motion,
)
from handsim.hand.pose_library import (
    GESTURES,
    GRASP_TYPES,
    Gesture,
    GraspType,
    gesture,
    grasp_pose,
    sample_grasp,
)
from handsim.hand.samplers import (
    ABD_RANGE_AT_FULL_FLEXION,
    DIP_NOISE_DEG,
    DIP_PIP_RATIO,
    GRASPIT_EG1_FINGER_FLEXION,
    INTERFINGER_MAX_DEVIATION_DEG,
    SynergyBasis,
    abduction_range_fraction,
    sample_synergy,
    sample_uniform,
    synergy_basis,
    synergy_pose,
)

__all__ = [
    "DIP_PIP_RATIO",
    "DIP_NOISE_DEG",
    "ABD_RANGE_AT_FULL_FLEXION",
    "INTERFINGER_MAX_DEVIATION_DEG",
    "abduction_range_fraction",
    "sample_uniform",
    "SynergyBasis",
    "synergy_basis",
    "synergy_pose",
    "sample_synergy",
    "GRASPIT_EG1_FINGER_FLEXION",
    "GraspType",
    "GRASP_TYPES",
    "grasp_pose",
    "sample_grasp",
    "Gesture",
    "GESTURES",
    "gesture",
    "MAX_JOINT_SPEED",
    "MAX_WRIST_SPEED",
    "WRIST_SPEED_CAP",
    "MAX_WRIST_ANGULAR_SPEED",
    "minimum_jerk",
    "segment_durations",
    "smooth_motion",
    "MOTION_SOURCES",
    "random_motion",
]
