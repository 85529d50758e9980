"""handsim: a MuJoCo simulation of a 27-DoF human hand for depth-based hand pose estimation.

``import handsim`` never imports torch (estimators live in ``handsim.estimators``).
Without a display and without ``MUJOCO_GL`` set, it selects MuJoCo's headless EGL backend
(this must happen before MuJoCo is first imported), and it sets ``LP_NUM_THREADS=0`` unless set,
so that a process forked after rendering can render (Mesa's llvmpipe keeps no worker threads).
"""

import os

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"
# Mesa's software rasterizer (llvmpipe) renders in the calling thread: a process forked after
# rendering (a vector env's worker) would otherwise wait forever for the parent's threads.
os.environ.setdefault("LP_NUM_THREADS", "0")

# ruff: noqa: E402 (the backend is chosen before MuJoCo is imported)

from handsim.errors import (
    EstimatorStateError,
    HandSimError,
    InvalidEstimate,
    InvalidEstimatorInput,
    InvalidEstimatorParams,
    InvalidHandParams,
    InvalidKeypoints,
    InvalidPose,
    UnknownName,
)
from handsim.estimator import (
    Estimate,
    Estimator,
    EstimatorBase,
    PrivilegedEstimator,
    estimate_errors,
    hand_center,
)
from handsim.frame import Frame, FrameRenderer, ObjectLabel
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HAND_PHYSICS_OPTIONS, Hand, HandBinding
from handsim.hand.pose import (
    JOINT_LIMITS,
    JOINT_LIMITS_DEG,
    JOINT_NAMES,
    HandPose,
    LimitViolation,
)
from handsim.hand.pose_prior import PosePrior, default_pose_prior
from handsim.hand.pose_sources import (
    GESTURES,
    GRASP_TYPES,
    gesture,
    grasp_pose,
    random_motion,
    sample_grasp,
    sample_synergy,
    sample_uniform,
    smooth_motion,
    synergy_basis,
)
from handsim.hand.retarget import Retargeter, RetargetResult
from handsim.hand.skeleton import HAND_SIZES, HandParams, build_skeleton, hand_params
from handsim.metrics import (
    evaluate_dexter_object,
    evaluate_hand_poses,
    evaluate_object_poses,
    plot_f_tau,
    plot_pck,
)
from handsim.world.camera import CAMERA_PRESETS, CameraIntrinsics, camera_preset
from handsim.world.mesh_import import load_object
from handsim.world.objects import YCBObject, add_object
from handsim.world.registry import OBJECT_NAMES, OBJECTS, get_object
from handsim.world.render import DepthRenderer
from handsim.world.scene import (
    SEGMENT_LABELS,
    CameraSpec,
    ObjectPlacement,
    Scene,
    SceneSpec,
    egocentric_camera,
    sample_placements,
    sample_viewpoint,
    third_person_camera,
)
from handsim.world.sensors import StructuredLight, TimeOfFlight, sensor_model
from handsim.world.symmetry import Symmetry

__version__ = "0.1.0"

__all__ = [
    # errors
    "HandSimError",
    "InvalidHandParams",
    "InvalidKeypoints",
    "InvalidPose",
    "UnknownName",
    "InvalidEstimate",
    "InvalidEstimatorInput",
    "InvalidEstimatorParams",
    "EstimatorStateError",
    # the estimator protocol (implementations live in handsim.estimators)
    "Estimate",
    "Estimator",
    "EstimatorBase",
    "PrivilegedEstimator",
    "estimate_errors",
    "hand_center",
    # the hand model
    "HAND_PHYSICS_OPTIONS",
    "HAND_SIZES",
    "KEYPOINT_NAMES",
    "Hand",
    "HandBinding",
    "HandParams",
    "build_skeleton",
    "hand_params",
    # poses and kinematics
    "JOINT_LIMITS",
    "JOINT_LIMITS_DEG",
    "JOINT_NAMES",
    "HandPose",
    "LimitViolation",
    "ForwardKinematics",
    "Retargeter",
    "RetargetResult",
    "PosePrior",
    "default_pose_prior",
    # metrics
    "evaluate_dexter_object",
    "evaluate_hand_poses",
    "evaluate_object_poses",
    "plot_f_tau",
    "plot_pck",
    # objects
    "OBJECTS",
    "OBJECT_NAMES",
    "Symmetry",
    "YCBObject",
    "add_object",
    "get_object",
    "load_object",
    # cameras and rendering
    "CAMERA_PRESETS",
    "CameraIntrinsics",
    "camera_preset",
    "DepthRenderer",
    # scenes, sensors, frames
    "Frame",
    "FrameRenderer",
    "ObjectLabel",
    "SEGMENT_LABELS",
    "CameraSpec",
    "ObjectPlacement",
    "Scene",
    "SceneSpec",
    "egocentric_camera",
    "sample_placements",
    "sample_viewpoint",
    "third_person_camera",
    "StructuredLight",
    "TimeOfFlight",
    "sensor_model",
    # pose sources
    "GESTURES",
    "GRASP_TYPES",
    "gesture",
    "grasp_pose",
    "random_motion",
    "sample_grasp",
    "sample_synergy",
    "sample_uniform",
    "smooth_motion",
    "synergy_basis",
]
