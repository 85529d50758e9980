"""Anatomy against hand-made poses: keypoints from a hand model written down here retarget.

The 21 keypoints are built without handsim's skeleton or forward kinematics, from published
anthropometry and joint angles chosen for each pose:

- joint centres in the palm after Buchholz, Armstrong & Goldstein (1992, Ergonomics 35:261) as
  laid out in the hand model of Sancho-Bru et al.: the finger CMCs 0.073 hand lengths distal of
  the wrist and 0.126, 0, -0.129, -0.223 hand breadths across (radial positive), the
  metacarpals fanning out to MCPs at 0.252, 0, -0.206, -0.402 hand breadths, 0.447, 0.446, 0.409
  and 0.368 hand lengths distal; the thumb CMC 0.196 hand breadths radial at the CMC level and
  0.06 hand lengths palmar;
- phalanx lengths as fractions of hand length (Buchholz et al. 1992);
- a transverse metacarpal arch (ring and little MCPs 2 and 5 mm palmar at 180 mm) [estimate];
- every finger a planar chain: abduction turns its plane about the palm normal, flexions bend
  it palmar; the thumb's metacarpal leaves its CMC at a radial and a palmar angle and its
  MCP and IP flex it toward the ulnar side (clinically, the thumb flexes across the palm and
  abducts away from it).

The source hand (180 mm long, 80 mm broad) differs in size and proportions from the target, so
neither the scale nor the palm fits exactly; the fit must still come out anatomically: no
joint is asked to go past its limits (no PIP hyperextension, no abduction clamp) beyond the
tolerances stated below.
"""

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HandParams
from handsim.hand.pose import HandPose, joint_index
from handsim.hand.retarget import Retargeter

HL, HB = 0.180, 0.080  # source hand length and breadth, metres
FINGERS = ("index", "middle", "ring", "little")
_CMC = {"index": (0.126, 0.073), "middle": (0.0, 0.073), "ring": (-0.129, 0.073)}
_CMC["little"] = (-0.223, 0.073)
# MCP: (across, hand breadths; distal, hand lengths; palmar, metres at 180 mm).
_MCP = {
    "index": (0.252, 0.447, 0.0),
    "middle": (0.0, 0.446, 0.0),
    "ring": (-0.206, 0.409, 0.002),
    "little": (-0.402, 0.368, 0.005),
}
_PHALANGES = {  # proximal, middle, distal (to the tip), hand lengths
    "index": (0.265, 0.143, 0.097),
    "middle": (0.277, 0.170, 0.108),
    "ring": (0.259, 0.165, 0.107),
    "little": (0.206, 0.117, 0.093),
}
_THUMB_CMC = np.array([0.196 * HB, 0.073 * HL, 0.06 * HL])
_THUMB = (0.251, 0.196, 0.158)  # metacarpal, proximal, distal (to the tip), hand lengths
X, Y, Z = np.eye(3)  # radial, distal, palmar


def _finger(name: str, abd: float, mcp: float, pip: float, dip: float) -> np.ndarray:
    """MCP, PIP, DIP and tip of a finger; angles in degrees (abduction toward the thumb)."""
    across, distal, palmar = _MCP[name]
    base = np.array([across * HB, distal * HL, palmar])
    a = np.deg2rad(abd)
    d = np.sin(a) * X + np.cos(a) * Y
    points, phi = [base], 0.0
    for length, flex in zip(_PHALANGES[name], (mcp, pip, dip), strict=True):
        phi += np.deg2rad(flex)
        points.append(points[-1] + length * HL * (np.cos(phi) * d + np.sin(phi) * Z))
    return np.array(points)


def _thumb(radial: float, palmar: float, mcp: float, ip: float) -> np.ndarray:
    """CMC, MCP, IP and tip of the thumb; degrees.

    ``radial``: the metacarpal's angle from the hand axis toward the radial side in the palm
    plane; ``palmar``: its angle out of the palm plane; ``mcp``, ``ip``: flexion toward the
    ulnar side (the clinical convention: the thumb flexes across the palm, parallel to it, and
    abducts away from it).
    """
    r, p = np.deg2rad(radial), np.deg2rad(palmar)
    u = np.cos(p) * (np.sin(r) * X + np.cos(r) * Y) + np.sin(p) * Z
    f = -X - (-X @ u) * u
    f /= np.linalg.norm(f)
    points, phi = [_THUMB_CMC, _THUMB_CMC + _THUMB[0] * HL * u], 0.0
    for length, flex in zip(_THUMB[1:], (mcp, ip), strict=True):
        phi += np.deg2rad(flex)
        points.append(points[-1] + length * HL * (np.cos(phi) * u + np.sin(phi) * f))
    return np.array(points)


def _hand(thumb: tuple, fingers: dict) -> np.ndarray:
    """(21, 3) keypoints in handsim's order: wrist, thumb CMC..tip, fingers MCP..tip."""
    digits = [_thumb(*thumb)] + [_finger(f, *fingers[f]) for f in FINGERS]
    return np.concatenate([np.zeros((1, 3)), *digits])


def _pad_to_pad(fingers: dict, natural: tuple) -> tuple:
    """Thumb angles that put the thumb tip 15 mm palmar of the index tip (pads touching)."""
    index = _finger("index", *fingers["index"])
    phi = np.deg2rad(sum(fingers["index"][1:]))
    a = np.deg2rad(fingers["index"][0])
    d = np.sin(a) * X + np.cos(a) * Y
    pad_normal = -np.sin(phi) * d + np.cos(phi) * Z
    goal = index[-1] + 0.015 * pad_normal

    def residual(x):
        return np.concatenate([(_thumb(*x)[-1] - goal) / 1e-3, 0.01 * (x - natural)])

    return tuple(least_squares(residual, np.array(natural, dtype=float)).x)


_STRAIGHT = {f: (0.0, 0.0, 0.0, 0.0) for f in FINGERS}
_FIST = {f: (0.0, 85.0, 100.0, 65.0) for f in FINGERS}
_PINCH_FINGERS = {
    "index": (0.0, 45.0, 55.0, 35.0),
    "middle": (0.0, 35.0, 50.0, 33.0),
    "ring": (-3.0, 45.0, 60.0, 40.0),
    "little": (-6.0, 55.0, 65.0, 43.0),
}
_TRIPOD_FINGERS = {
    "index": (3.0, 45.0, 50.0, 33.0),
    "middle": (-3.0, 45.0, 50.0, 33.0),
    "ring": (-5.0, 60.0, 70.0, 45.0),
    "little": (-8.0, 65.0, 75.0, 50.0),
}
# Spread: 85 % of the mean maximal angles between neighbouring fingers (index-middle 17.2,
# middle-ring 14.3, ring-little 32.1 deg; Chatzioglou et al. 2024, Anat Cell Biol 57:172),
# middle finger straight.
_SPREAD = {
    "index": (0.85 * 17.2, 0.0, 0.0, 0.0),
    "middle": (0.0, 0.0, 0.0, 0.0),
    "ring": (-0.85 * 14.3, 0.0, 0.0, 0.0),
    "little": (-0.85 * (14.3 + 32.1), 0.0, 0.0, 0.0),
}

POSES = {
    # A relaxed flat hand: joints a few degrees flexed, not locked straight.
    "flat": ((35.0, 15.0, 5.0, 5.0), {f: (0.0, 3.0, 5.0, 3.0) for f in FINGERS}),
    "straight": ((30.0, 10.0, 0.0, 0.0), _STRAIGHT),
    "spread": ((60.0, 10.0, 0.0, 5.0), _SPREAD),
    "fist": ((15.0, 45.0, 45.0, 40.0), _FIST),
    "point": ((15.0, 45.0, 45.0, 40.0), {**_FIST, "index": (0.0, 0.0, 5.0, 3.0)}),
    "hook": ((35.0, 15.0, 5.0, 5.0), {f: (0.0, 0.0, 90.0, 60.0) for f in FINGERS}),
    "cylinder_grip": (
        (20.0, 50.0, 25.0, 20.0),
        {f: (0.0, 45.0, 55.0, 37.0) for f in FINGERS},
    ),
    "pinch": (_pad_to_pad(_PINCH_FINGERS, (20.0, 45.0, 20.0, 20.0)), _PINCH_FINGERS),
    "tripod": (_pad_to_pad(_TRIPOD_FINGERS, (20.0, 45.0, 20.0, 20.0)), _TRIPOD_FINGERS),
}

MEAN_RESIDUAL_MM = 3.0
"""Bound on each pose's mean fit error over the 21 keypoints, at the target hand's size, mm."""
STRAIGHT_TOLERANCE_DEG = 3.0
"""How far past a limit an exactly straight finger may ask to go (a palm that differs by 2 mm
tilts the fitted finger: straight fingers ask for up to 2.0 deg of PIP hyperextension)."""
_AT_A_LIMIT = ("straight", "spread")  # poses with joints exactly at a limit (straight fingers)


def _world(keypoints: np.ndarray, seed: int) -> np.ndarray:
    """The keypoints under a random rigid motion (the pose is found in any frame)."""
    rng = np.random.default_rng(seed)
    rot = Rotation.random(random_state=seed)
    return rot.apply(keypoints) + rng.uniform(-0.3, 0.3, 3)


def test_the_hand_made_poses_are_plausible():
    """Every pose's thumb angles lie in a human range; pinch and tripod touch pad to pad."""
    for name, (thumb, fingers) in POSES.items():
        radial, palmar, mcp, ip = thumb
        assert 0 <= radial <= 70 and 0 <= palmar <= 70, name
        assert -10 <= mcp <= 60 and -15 <= ip <= 80, name
        for finger, (abd, *flexions) in fingers.items():
            assert -40 <= abd <= 20 and all(0 <= f <= 100 for f in flexions), (name, finger)
    for name in ("pinch", "tripod"):
        kp = _hand(*POSES[name])
        assert np.linalg.norm(kp[4] - kp[8]) == pytest.approx(0.015, abs=1e-4)


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("name", list(POSES))
def test_hand_made_poses_retarget_without_clamping(name, side):
    """Each pose fits within MEAN_RESIDUAL_MM and asks no joint to pass its limits.

    Measured on the medium hand, right and left alike: mean errors 1.0 to 2.3 mm, the scale
    within 1.3 % of the two hands' length ratio, finger flexions within 12.1 deg and the
    thumb's MCP and IP flexions within 3.6 deg of the written ones.

    The abduction of a finger flexed more than 60 deg at the MCP is not counted: it turns the
    finger nearly about its own axis, so the keypoints do not determine it (a fist's little
    fingertip a few millimetres aside asks for 19 deg more radial abduction than the limit).
    """
    keypoints = _hand(*POSES[name])
    if side == "left":
        keypoints = keypoints * [-1.0, 1.0, 1.0]
    result = Retargeter(HandParams(side=side))(_world(keypoints, seed=len(name)))
    assert result.keypoint_error_m < MEAN_RESIDUAL_MM * 1e-3
    assert result.scale == pytest.approx(HL / 0.189, rel=0.03)
    thumb, fingers = POSES[name]
    tolerance = np.deg2rad(STRAIGHT_TOLERANCE_DEG) if name in _AT_A_LIMIT else 0.0
    for clamp in result.clamped:
        finger, _, kind = clamp.joint.partition("_")
        if kind == "mcp_abd" and finger in fingers and fingers[finger][1] > 60.0:
            continue
        past = max(clamp.lower_rad - clamp.value_rad, clamp.value_rad - clamp.upper_rad)
        assert past < tolerance, clamp
    angles = np.rad2deg(result.pose.angles)
    for finger in FINGERS:
        for joint, k in (("mcp_flex", 1), ("pip_flex", 2), ("dip_flex", 3)):
            fitted = angles[joint_index(f"{finger}_{joint}")]
            assert fitted == pytest.approx(fingers[finger][k], abs=15.0), (finger, joint)
    assert angles[joint_index("thumb_mcp_flex")] == pytest.approx(thumb[2], abs=6.0)
    assert angles[joint_index("thumb_ip_flex")] == pytest.approx(thumb[3], abs=6.0)


# The MANO mean hand's wrist, thumb CMC and finger MCPs in handsim's hand frame (x radial,
# y distal, z palmar), metres: the joint positions of D-Grasp's mano_mean.urdf (Christen et
# al. 2022) for the MANO model fitted to hand scans (Romero, Tzionas & Black 2017).
_MANO_PALM = (
    np.array(
        [
            [0.0, 0.0, 0.0],
            [25.8, 24.1, 15.5],
            [20.7, 88.1, 5.2],
            [-3.4, 94.7, 1.5],
            [-26.7, 81.7, 4.0],
            [-43.2, 68.8, 9.9],
        ]
    )
    * 1e-3
)
_PALM_POINTS = [0, 1, 5, 9, 13, 17]  # wrist, thumb CMC, index..little MCP


def _similarity_residual_mm(points: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per-point distance after the best similarity fit of ``points`` onto ``reference``, mm.

    Distances are at the size of ``points`` (the reference scaled onto them).
    """
    mp, mr = points.mean(axis=0), reference.mean(axis=0)
    a, b = points - mp, reference - mr
    u, s, vt = np.linalg.svd(b.T @ a)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ d @ vt
    scale = np.trace(np.diag(s) @ d) / (a**2).sum()
    fitted = scale * a @ rot.T + mr
    return np.linalg.norm(fitted - reference, axis=1) / scale * 1e3


def test_palm_shape_against_published_hands():
    """The palm's six keypoints match MANO's mean hand and Buchholz's joint centres.

    Measured (medium hand, mean over the six points; wrist, thumb CMC): against MANO 4.99 mm
    (6.1, 8.9), against the Buchholz layout of this file 1.95 mm (1.9, 1.1). MANO's wrist
    joint sits about 10 mm proximal of the wrist crease, so part of its residual is a
    different wrist, not a different palm.
    """
    fk = ForwardKinematics(HandParams())
    palm = fk.keypoints(HandPose.neutral())[_PALM_POINTS]
    mano = _similarity_residual_mm(palm, _MANO_PALM)
    buchholz = _similarity_residual_mm(palm, _hand(*POSES["straight"])[_PALM_POINTS])
    assert mano.mean() < 5.5 and buchholz.mean() < 2.5
    assert np.linalg.norm(palm[1]) == pytest.approx(0.0224, abs=5e-4)  # thumb CMC to wrist
