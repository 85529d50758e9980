"""How the hand is turned toward the camera: the view distributions of the kinematic source.

Each function draws the hand's rotation in the camera frame, ``R_cam_from_hand`` (3 x 3; the
camera frame is OpenCV's: x right, y down, z forward; the hand frame is handsim's: +x radial
for a right hand, +y distal, +z palmar). The camera looks at the palm, so the direction from
the palm to the camera is the camera's -z.

``third_person`` (a sensor in front of a person who holds the hand up to it)
    The hand's rotation as NYU's test set shows it (8 252 frames of a right hand before a
    Kinect; measured on the published test labels): in :data:`PALM_FRACTION` of the draws the
    palm faces the camera, turned from face-on by a rotation drawn about
    :data:`THIRD_PERSON_PALM_MEAN_ROTVEC_DEG` (camera frame: the palm tilted 33 deg on average,
    top toward the camera and turned about the vertical) with the covariance
    :data:`THIRD_PERSON_PALM_COV_DEG2`; otherwise the back or the side faces it
    (:data:`THIRD_PERSON_BACK_MEAN_ROTVEC_DEG`, :data:`THIRD_PERSON_BACK_COV_DEG2`, a broad
    spread from edge-on to the back). Each is a Gaussian in the tangent space of the mean
    rotation (rotation vectors, deg), cut at a Mahalanobis distance of
    :data:`THIRD_PERSON_MAX_SIGMA` (tails redrawn). The figures come from each NYU frame's
    hand frame (wrist, ulnar and radial wrist points and palm centre, read the same way from
    handsim's keypoints), split by the nearer of the palm-on and back-on poses. Fingers point
    into the lens only as often as NYU's do (5 % of frames within 22 deg of the line of sight).
``egocentric`` (a head-mounted camera)
    The camera is near the eyes, pitched down by :data:`EGO_CAMERA_PITCH_DEG`; the hand is in
    front at arm's length, fingers forward, palm down, then turned as a forearm turns: a roll
    about the fingers' axis (:data:`EGO_ROLL_DEG`, positive turns the thumb up), the fingers
    raised or lowered (:data:`EGO_PITCH_DEG`) and swung left or right (:data:`EGO_YAW_DEG`).
    The camera sees the back of the hand, or its thumb side when the hand is turned up. The
    forearm points down in the image (within :data:`EGO_FOREARM_FROM_DOWN_DEG`): the arm
    comes in from the bottom, as in a head-mounted camera's view; other draws are redrawn.
``random``
    A uniform rotation over SO(3) (for robustness studies; not in the presets).

"Palm normal" is the normal read from the keypoints (:mod:`handsim.data.stats`), 7 deg from the
hand's +z. Rotations are drawn for a right hand; a left hand gets the mirror image of the draw
(the image flipped left to right), so the two sides have mirrored distributions.
"""

from __future__ import annotations

import functools

import numpy as np

from handsim.data.config import InvalidGenerationConfig

__all__ = [
    "HAND_VIEWS",
    "PALM_FRACTION",
    "THIRD_PERSON_PALM_MEAN_ROTVEC_DEG",
    "THIRD_PERSON_PALM_COV_DEG2",
    "THIRD_PERSON_BACK_MEAN_ROTVEC_DEG",
    "THIRD_PERSON_BACK_COV_DEG2",
    "THIRD_PERSON_MAX_SIGMA",
    "EGO_CAMERA_PITCH_DEG",
    "EGO_ROLL_DEG",
    "EGO_PITCH_DEG",
    "EGO_YAW_DEG",
    "EGO_FOREARM_FROM_DOWN_DEG",
    "hand_rotation_in_camera",
    "mirror_rotation",
]

HAND_VIEWS = ("third_person", "egocentric", "random")
"""The views of :func:`hand_rotation_in_camera`."""
PALM_FRACTION = 0.805
"""Third person: fraction of draws with the palm (not the back or side) toward the camera
(NYU's test set: 6 639 of 8 252 frames)."""
THIRD_PERSON_PALM_MEAN_ROTVEC_DEG = (22.7, -24.6, 0.9)
"""Third person, palm toward the camera: the mean turn from face-on (fingers up), a rotation
vector in the camera frame, deg."""
THIRD_PERSON_PALM_COV_DEG2 = ((717.0, 60.0, 118.0), (60.0, 746.0, 413.0), (118.0, 413.0, 775.0))
"""Third person, palm toward the camera: covariance of the turn about its mean, deg^2."""
THIRD_PERSON_BACK_MEAN_ROTVEC_DEG = (39.9, 41.8, 47.4)
"""Third person, back or side toward the camera: the mean turn from back-on, deg."""
THIRD_PERSON_BACK_COV_DEG2 = (
    (1393.0, -881.0, -981.0),
    (-881.0, 1265.0, 860.0),
    (-981.0, 860.0, 1413.0),
)
"""Third person, back or side toward the camera: covariance of the turn about its mean, deg^2."""
THIRD_PERSON_MAX_SIGMA = 3.0
"""Third person: turns farther than this Mahalanobis distance from the mean are redrawn."""
EGO_CAMERA_PITCH_DEG = (25.0, 60.0)
"""Egocentric: the head-mounted camera's downward pitch, uniform in this range, deg."""
EGO_ROLL_DEG = (-30.0, 90.0)
"""Egocentric: forearm roll from palm down, uniform; positive turns the thumb up, deg."""
EGO_PITCH_DEG = (-30.0, 15.0)
"""Egocentric: fingers raised (positive) or lowered from horizontal, uniform, deg."""
EGO_YAW_DEG = 30.0
"""Egocentric: fingers swung left or right from straight ahead, uniform within +-, deg."""
EGO_FOREARM_FROM_DOWN_DEG = 60.0
"""Egocentric: the forearm's direction in the image lies within this of straight down (the arm
comes in from the bottom of a head-mounted camera's image); other draws are redrawn, deg."""

# Palm toward the camera, fingers up in the image (thumb on the image's right for a right
# hand); the back toward the camera is the same turned half a turn about the fingers.
_PALM_TO_CAMERA = np.diag([1.0, -1.0, -1.0])
_BACK_TO_CAMERA = np.diag([-1.0, -1.0, 1.0])
# Egocentric, in a level head frame (x right, y down, z forward): fingers forward, palm down,
# thumb (radial) to the left.
_PALM_DOWN_FORWARD = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
_MIRROR_X = np.diag([-1.0, 1.0, 1.0])


def _axis_angle(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rotation matrix of ``angle_rad`` about the unit vector ``axis`` (Rodrigues)."""
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle_rad) * k + (1.0 - np.cos(angle_rad)) * (k @ k)


@functools.cache
def _palm_to_z() -> np.ndarray:
    """The rotation (hand frame) taking the keypoints' palm normal onto the hand's +z.

    The palm normal that :mod:`handsim.data.stats` reads from the keypoints (wrist, index and
    little MCP) leans 7 deg from the hand's +z; the views turn that normal, so the cone holds
    for the figure ``handsim dataset info`` reports. The palm is rigid and every hand is the
    medium one scaled, so one neutral right hand gives it.
    """
    from handsim.hand.kinematics import ForwardKinematics
    from handsim.hand.model import hand_params
    from handsim.hand.pose import NUM_ANGLES, HandPose

    kp = ForwardKinematics(hand_params("medium", "right")).keypoints(
        HandPose(np.zeros(3), np.zeros(3), np.zeros(NUM_ANGLES))
    )
    normal = np.cross(kp[5] - kp[0], kp[17] - kp[0])
    normal /= np.linalg.norm(normal)
    axis = np.cross(normal, [0.0, 0.0, 1.0])
    return _axis_angle(axis / np.linalg.norm(axis), float(np.arccos(normal[2])))


def _rotvec_matrix(rotvec_rad: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(rotvec_rad))
    return np.eye(3) if angle < 1e-12 else _axis_angle(rotvec_rad / angle, angle)


@functools.cache
def _third_person_modes() -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]:
    """Per face: (face pose, mean turn, Cholesky factor of the turn's covariance), radians."""
    modes = []
    for face, mean_deg, cov_deg2 in (
        (_PALM_TO_CAMERA, THIRD_PERSON_PALM_MEAN_ROTVEC_DEG, THIRD_PERSON_PALM_COV_DEG2),
        (_BACK_TO_CAMERA, THIRD_PERSON_BACK_MEAN_ROTVEC_DEG, THIRD_PERSON_BACK_COV_DEG2),
    ):
        chol = np.linalg.cholesky(np.radians(np.radians(np.asarray(cov_deg2))))
        mean = _rotvec_matrix(np.radians(np.asarray(mean_deg)))
        modes.append((face @ _palm_to_z(), mean, chol))
    return tuple(modes)


def _third_person(rng: np.random.Generator) -> np.ndarray:
    palm, back = _third_person_modes()
    face, mean, chol = palm if rng.random() < PALM_FRACTION else back
    while True:  # a Gaussian turn about the mean, its far tails redrawn
        standard = rng.normal(size=3)
        if float(standard @ standard) <= THIRD_PERSON_MAX_SIGMA**2:
            break
    return mean @ _rotvec_matrix(chol @ standard) @ face


def _egocentric(rng: np.random.Generator) -> np.ndarray:
    # Redrawn until the forearm (the hand's -y) points down in the image: turned otherwise, it
    # would run from the wrist toward the eye and hide the hand, which a real arm cannot.
    min_down = np.cos(np.radians(EGO_FOREARM_FROM_DOWN_DEG))
    while True:
        R_cam_from_hand = _egocentric_draw(rng)  # noqa: N806
        forearm = -R_cam_from_hand[:2, 1]  # image x (right) and y (down)
        norm = float(np.linalg.norm(forearm))
        if norm > 1e-9 and forearm[1] >= min_down * norm:
            return R_cam_from_hand


def _egocentric_draw(rng: np.random.Generator) -> np.ndarray:
    pitch_cam = np.radians(rng.uniform(*EGO_CAMERA_PITCH_DEG))
    # The camera's axes in the level head frame: z forward and down by the pitch.
    c, s = np.cos(pitch_cam), np.sin(pitch_cam)
    R_head_from_cam = np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])  # noqa: N806
    roll = _axis_angle(np.array([0.0, 1.0, 0.0]), np.radians(rng.uniform(*EGO_ROLL_DEG)))
    # About the head's x axis, positive raises the fingers (toward -y, up).
    raise_ = _axis_angle(np.array([1.0, 0.0, 0.0]), np.radians(rng.uniform(*EGO_PITCH_DEG)))
    yaw = _axis_angle(np.array([0.0, 1.0, 0.0]), np.radians(rng.uniform(-EGO_YAW_DEG, EGO_YAW_DEG)))
    R_head_from_hand = yaw @ raise_ @ _PALM_DOWN_FORWARD @ roll @ _palm_to_z()  # noqa: N806
    return R_head_from_cam.T @ R_head_from_hand


def _uniform(rng: np.random.Generator) -> np.ndarray:
    # A normalized 4-D Gaussian is a uniform unit quaternion (w, x, y, z).
    w, x, y, z = rng.normal(size=4)
    norm = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def mirror_rotation(R_cam_from_hand: np.ndarray) -> np.ndarray:  # noqa: N803
    """The rotation that shows the other side's hand as the mirror image (image x flipped).

    A left hand's frame is the mirror of a right hand's (+x ulnar), so mirroring the camera's x
    and the hand's x keeps a proper rotation: ``M R M`` with ``M = diag(-1, 1, 1)``.
    """
    return _MIRROR_X @ R_cam_from_hand @ _MIRROR_X


def hand_rotation_in_camera(rng: np.random.Generator, view: str, is_left: bool) -> np.ndarray:
    """Draw the hand's rotation in the camera frame for a view (module docstring).

    Args:
        rng: the generator drawn from.
        view: one of :data:`HAND_VIEWS`.
        is_left: a left hand (the mirror image of a right hand's draw).

    Returns:
        ``R_cam_from_hand``, (3, 3) float64, a proper rotation.

    Raises:
        InvalidGenerationConfig: for a view not in :data:`HAND_VIEWS`.
    """
    if view == "third_person":
        R = _third_person(rng)  # noqa: N806
    elif view == "egocentric":
        R = _egocentric(rng)  # noqa: N806
    elif view == "random":
        R = _uniform(rng)  # noqa: N806
    else:
        raise InvalidGenerationConfig(
            f"view must be one of {', '.join(HAND_VIEWS)}; received {view!r}"
        )
    return mirror_rotation(R) if is_left else R
