"""Retargeting: 21 keypoints (any hand size) -> the 27-DoF pose of a handsim hand.

The keypoints may come from a tracker, an estimator or another hand model of the same side,
in :data:`~handsim.hand.KEYPOINT_NAMES` order, in any frame (the pose comes out in that frame).

Method:

1. ``wrist_pos`` is the wrist keypoint (the origin of the hand frame by definition).
2. The wrist rotation is initialized by Kabsch alignment of the wrist-to-{thumb CMC, four MCP}
   vectors of the input with those of the target hand (scale-free).
3. The input is scaled about the wrist by the ratio of the target hand's summed bone lengths
   to the input's (bone lengths do not depend on the pose), so a source hand of another size
   gives the same angles rather than distorted ones. Rotation and the 21 angles are then fitted
   together by bounded least squares on the 20 keypoint positions (1 mm residual unit). A weak
   prior (1e-3 per radian) toward zero keeps abduction defined when a finger is fully flexed.
4. The fit is bounded by :data:`~handsim.hand.pose.JOINT_LIMITS`. Where it ends on a bound, an
   unbounded refit from there tells how far past the limit the input asked that joint to go;
   those joints are reported as clamped.

Accuracy (``python benchmarks/bench_hand.py``, 50 random poses within limits, medium hand):
clean keypoints round-trip to < 0.001 mm mean keypoint error; with 5 mm isotropic Gaussian
noise on every keypoint (mean displacement ~8 mm) the fitted hand is 6.8 mm from the true
keypoints on average, with a mean joint-angle error of 10.4 deg (distal joints, with their short
bones, take most of it). About 17 ms per frame on one CPU core.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from handsim.errors import InvalidKeypoints
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HandParams, Skeleton
from handsim.hand.pose import JOINT_LIMITS, JOINT_NAMES, NUM_ANGLES, HandPose, LimitViolation

__all__ = ["Retargeter", "RetargetResult", "BONES"]

# (parent keypoint, child keypoint) of each direction that is fitted.
BONES: tuple[tuple[int, int], ...] = (
    (0, 1),
    (0, 5),
    (0, 9),
    (0, 13),
    (0, 17),
    (1, 2),
    (2, 3),
    (3, 4),
) + tuple((b + k, b + k + 1) for b in (5, 9, 13, 17) for k in range(3))
_PALM = np.array([1, 5, 9, 13, 17])
_PRIOR_WEIGHT = 1e-3
# Residual unit: 1 mm of keypoint error weighs as much as 1 rad of prior.
_POSITION_SIGMA_M = 1e-3
_FD_STEP = 1e-6
_CHIRALITY_MARGIN = 0.25


@dataclasses.dataclass(frozen=True)
class RetargetResult:
    """Outcome of one retargeting.

    Attributes:
        pose: the fitted pose (angles within limits).
        clamped: joints whose unconstrained fit was outside the limits, with the requested value.
        keypoint_error_m: mean distance between the fitted hand's keypoints and the input
            scaled to the target hand's size, metres.
        scale: estimated size of the source hand relative to the target hand.
        direction_error_rad: mean angle between fitted and input bone directions, radians.
    """

    pose: HandPose
    clamped: tuple[LimitViolation, ...]
    keypoint_error_m: float
    scale: float
    direction_error_rad: float


def _directions(keypoints: np.ndarray) -> np.ndarray:
    idx = np.array(BONES)
    v = keypoints[..., idx[:, 1], :] - keypoints[..., idx[:, 0], :]
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _bone_length_sum(keypoints: np.ndarray) -> float:
    idx = np.array(BONES)
    return float(np.linalg.norm(keypoints[idx[:, 1]] - keypoints[idx[:, 0]], axis=-1).sum())


def _kabsch(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Rotation R (3, 3) minimizing sum |R source_i - target_i|^2."""
    u, _, vt = np.linalg.svd(target.T @ source)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


class Retargeter:
    """Fits the 27-DoF pose of one handsim hand to 21 keypoints.

    Args:
        hand: the target hand (parameters or skeleton).
    """

    def __init__(self, hand: HandParams | Skeleton) -> None:
        """Precompute the target hand's forward kinematics and palm template."""
        self.fk = ForwardKinematics(hand)
        self.params = self.fk.skeleton.params
        template = self.fk.keypoints(HandPose.neutral())
        self._palm_template = template[_PALM]  # hand frame, wrist at origin
        self._chirality = self._palm_chirality(template)
        self._bone_length_sum = _bone_length_sum(template)

    @staticmethod
    def _palm_chirality(keypoints: np.ndarray) -> float:
        # Palm normal (index MCP - little MCP) x (middle MCP - wrist) against the direction to
        # the thumb CMC, which sits palmar of the palm plane: the sine of its elevation is
        # about +0.45 for a right hand and -0.45 for a left hand, whatever the size and pose.
        normal = np.cross(keypoints[5] - keypoints[17], keypoints[9] - keypoints[0])
        thumb = keypoints[1] - keypoints[0]
        return float(np.dot(normal, thumb) / (np.linalg.norm(normal) * np.linalg.norm(thumb)))

    def _validate(self, keypoints: object, check_side: bool = True) -> np.ndarray:
        kp = np.asarray(keypoints, dtype=np.float64)
        if kp.shape != (21, 3):
            raise InvalidKeypoints(
                f"retargeting expects keypoints of shape (21, 3) in KEYPOINT_NAMES order, metres; "
                f"received shape {kp.shape}. Convert other orders with handsim.hand.keypoints."
            )
        if not np.all(np.isfinite(kp)):
            raise InvalidKeypoints(
                "retargeting expects finite keypoints; received NaN or Inf at indices "
                f"{sorted(set(np.nonzero(~np.isfinite(kp))[0].tolist()))}"
            )
        lengths = np.linalg.norm(kp[np.array(BONES)[:, 1]] - kp[np.array(BONES)[:, 0]], axis=-1)
        if np.any(lengths < 1e-4):
            raise InvalidKeypoints(
                "retargeting expects distinct keypoints; bones "
                f"{[BONES[i] for i in np.nonzero(lengths < 1e-4)[0]]} have zero length"
            )
        # Only a clear opposite sign counts (noise of a few mm moves the value by ~0.2).
        if check_side and self._palm_chirality(kp) * np.sign(self._chirality) < -_CHIRALITY_MARGIN:
            other = "left" if self.params.side == "right" else "right"
            raise InvalidKeypoints(
                f"the keypoints look like a {other} hand but the target hand is "
                f"{self.params.side}; retarget onto a {other} hand, or mirror the keypoints"
            )
        return kp

    def _residuals(self, x: np.ndarray, wrist: np.ndarray, target: np.ndarray) -> np.ndarray:
        pose = HandPose(np.broadcast_to(wrist, x.shape[:-1] + (3,)), x[..., :3], x[..., 3:])
        res = (self.fk.keypoints(pose)[..., 1:, :] - target[1:]) / _POSITION_SIGMA_M
        res = res.reshape(x.shape[:-1] + (-1,))
        return np.concatenate([res, _PRIOR_WEIGHT * x[..., 3:]], axis=-1)

    def _jacobian(self, x: np.ndarray, wrist: np.ndarray, target: np.ndarray) -> np.ndarray:
        # Central differences, all 24 parameters in one batched FK call.
        steps = np.eye(x.size) * _FD_STEP
        xs = np.concatenate([x + steps, x - steps])
        r = self._residuals(xs, wrist, target)
        return ((r[: x.size] - r[x.size :]) / (2 * _FD_STEP)).T

    def _solve(self, x0, wrist, target, lower, upper) -> np.ndarray:
        # TRF sizes its first trust region by |x0|; a near-zero start (flat hand, identity
        # rotation) would make it vanishingly small, so the unknowns are offset by 1.
        offset = 1.0
        result = least_squares(
            lambda y: self._residuals(y - offset, wrist, target),
            np.clip(x0, lower, upper) + offset,
            jac=lambda y: self._jacobian(y - offset, wrist, target),
            bounds=(lower + offset, upper + offset),
            method="trf",
            xtol=1e-9,
            ftol=1e-9,
            gtol=1e-9,
            max_nfev=200,
        )
        return result.x - offset

    def __call__(
        self,
        keypoints: object,
        initial: HandPose | None = None,
        *,
        check_side: bool = True,
        report_clamped: bool = True,
    ) -> RetargetResult:
        """Retarget one frame.

        Args:
            keypoints: (21, 3) keypoints of a hand of the same side, metres, any frame.
            initial: warm start (e.g. the previous frame's pose); default: flat hand with the
                Kabsch wrist rotation.
            check_side: reject keypoints that look like the other hand. Turn it off for noisy
                estimates of a hand known to be this side (centimetre noise on a fist can flip
                the palm's apparent orientation).
            report_clamped: refit joints at their limits without bounds to report the
                requested values (``clamped``); off, ``clamped`` is empty and the call is up to
                twice as fast.

        Returns:
            The fitted pose in the keypoints' frame, with the clamped joints and fit errors.

        Raises:
            InvalidKeypoints: wrong shape, non-finite values, coincident keypoints, or keypoints
                of the other hand side (with ``check_side``).
        """
        kp = self._validate(keypoints, check_side)
        wrist = kp[0]
        # Bone lengths do not depend on the pose: their sum gives the source/target size ratio,
        # and the input scaled by it is what the target hand must reach.
        scale = _bone_length_sum(kp) / self._bone_length_sum
        target = wrist + (kp - wrist) / scale
        if initial is None:
            source = self._palm_template / np.linalg.norm(self._palm_template, axis=1)[:, None]
            seen = kp[_PALM] - wrist
            seen = seen / np.linalg.norm(seen, axis=1)[:, None]
            rotvec = Rotation.from_matrix(_kabsch(source, seen)).as_rotvec()
            x0 = np.concatenate([rotvec, np.zeros(NUM_ANGLES)])
        else:
            x0 = np.concatenate([initial.wrist_rotvec, initial.angles])

        lower, upper = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
        free = np.full(3, np.inf)
        x = self._solve(
            x0, wrist, target, np.concatenate([-free, lower]), np.concatenate([free, upper])
        )
        clamped: tuple[LimitViolation, ...] = ()
        at_bound = (x[3:] <= lower + 1e-6) | (x[3:] >= upper - 1e-6)
        if report_clamped and np.any(at_bound):
            # Refit without bounds from the bounded fit (so it stays on the same solution
            # branch) to see how far past its limits the input asks each joint to go.
            wide = np.full(3 + NUM_ANGLES, np.inf)
            x_free = self._solve(x, wrist, target, -wide, wide)
            # Hinge angles are 2 pi periodic; compare their principal values with the limits.
            wanted = np.mod(x_free[3:] + np.pi, 2 * np.pi) - np.pi
            outside = (wanted < lower - 1e-4) | (wanted > upper + 1e-4)
            clamped = tuple(
                LimitViolation(JOINT_NAMES[j], float(wanted[j]), float(lower[j]), float(upper[j]))
                for j in np.nonzero(outside & at_bound)[0]
            )
        pose = HandPose(wrist, x[:3], np.clip(x[3:], lower, upper))
        fitted = self.fk.keypoints(pose)
        cosines = np.clip(np.sum(_directions(fitted) * _directions(kp), axis=-1), -1.0, 1.0)
        return RetargetResult(
            pose=pose,
            clamped=clamped,
            keypoint_error_m=float(np.mean(np.linalg.norm(fitted - target, axis=-1))),
            scale=scale,
            direction_error_rad=float(np.mean(np.arccos(cosines))),
        )

    def sequence(self, keypoints: object) -> list[RetargetResult]:
        """Retarget a sequence, warm-starting each frame from the previous one.

        Args:
            keypoints: (T, 21, 3) keypoints, metres.

        Returns:
            One result per frame.
        """
        kp = np.asarray(keypoints, dtype=np.float64)
        if kp.ndim != 3 or kp.shape[1:] != (21, 3):
            raise InvalidKeypoints(
                f"a keypoint sequence must have shape (T, 21, 3); received shape {kp.shape}"
            )
        results: list[RetargetResult] = []
        previous: HandPose | None = None
        for frame in kp:
            result = self(frame, initial=previous)
            results.append(result)
            previous = result.pose
        return results
