"""Retargeting: keypoints of a tracked hand (any size, any subset) -> the 27-DoF pose of a hand.

The keypoints may come from a tracker, an estimator or another hand model of the same side,
in :data:`~handsim.hand.KEYPOINT_NAMES` order, in any frame (the pose comes out in that frame).
Formats with fewer points (NYU-14, ICVL-16, ...) go through
:func:`handsim.hand.keypoints.from_format` first; its NaN rows mark the absent points.

Model: the fitted hand's keypoint ``i`` is ``t + s R q_i(angles)``, where ``q_i`` is the target
hand's keypoint in its own hand frame (analytic forward kinematics), ``R`` the wrist rotation,
``t`` the wrist position and ``s`` the size of the source hand relative to the target hand.
The pose returned is ``(t, R, angles)`` on the target hand; ``s`` is reported as ``scale``.

Method: damped least squares (Levenberg-Marquardt) on the present keypoints (1 mm residual
unit), with analytic Jacobians (a hinge moves a keypoint by ``axis x (keypoint - hinge
origin)``), wrist-rotation updates on the rotation group, and the joint limits of
:data:`~handsim.hand.pose.JOINT_LIMITS` as bounds (joints at a bound that the gradient pushes
outward are held; every step is clipped into the limits). A weak prior (1e-3 per radian)
toward zero keeps angles defined that the keypoints do not determine (a fully flexed finger's
abduction, a finger with no keypoint). Options:

- ``pose_prior`` and ``keypoint_sigma_m`` (constructor): a maximum a posteriori fit with a
  Gaussian prior over natural postures (:mod:`~handsim.hand.pose_prior`) in place of the weak
  prior; the keypoint residuals are weighed by the tracker's noise ``keypoint_sigma_m``, the
  prior enters as 21 more residual rows ``W (angles - mu)`` (Jacobian ``W``).

- ``fit_wrist`` (default on): the wrist position floats; off, it is pinned at the wrist
  keypoint (which must then be present).
- ``fit_scale`` (default on): the scale floats; off, it is fixed at ``initial_scale`` or, by
  default, at the ratio of the input's bone lengths to the target hand's (all present bones).
- warm start: ``initial`` (e.g. the previous frame's pose) and ``initial_scale``;
  :meth:`Retargeter.sequence` warm-starts every frame from the previous one.
- ``check_side``: the keypoints are also fitted mirrored (that is, as the other side) and
  rejected when the mirrored fit is better: a comparison of two fits, not a threshold.

Cold starts align the palm points (wrist, thumb CMC, MCPs) with a flat target hand by a
similarity transform (Umeyama). With fewer than three palm points, or when that fit stays more
than 15 mm from the keypoints (a local minimum, about 0.4% of random poses), all present points
are aligned with a flat, a half-closed and a closed hand and the best of those fits is kept.

Speed and accuracy (``python benchmarks/bench_hand.py --only retarget``: 200 frames of 90 Hz
streams of random in-limit poses, medium hand, 5 mm Gaussian noise on every keypoint, one core
of a 2-core machine shared with other jobs, load average ~10): warm-started 1.0 ms per frame
at best (median 2.0 and 7.9 ms in two runs; other processes inflate the medians), cold 1.4 to
1.8 ms at best (median 10 and 14 ms). The fitted hand is 5.4 mm from the true keypoints (the
noisy input is 8.0 mm from them), with a mean angle error of 9.2 to 9.6 deg; clean keypoints
round-trip exactly. NYU-14 and ICVL-16 labels with the same noise give 7.4 and 9.7 to 10.1 mm
over all 21 keypoints. The side check refused 200 of 200 noisy right hands offered to a left
hand and 0 of 500 offered to a right hand. ``mink`` (differential IK, one QP per step) was
measured on the same warm-started fits with the scale fixed: 9 to 24 times slower (48 to 54 ms
median) at the same accuracy (4.9 to 5.0 mm against 4.8 mm), so handsim keeps its own solver.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from handsim.errors import InvalidKeypoints, InvalidPose
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.pose import (
    DIGITS,
    JOINT_LIMITS,
    JOINT_NAMES,
    NUM_ANGLES,
    HandPose,
    LimitViolation,
)
from handsim.hand.pose_prior import PosePrior
from handsim.hand.skeleton import HandParams, Skeleton

__all__ = ["Retargeter", "RetargetResult", "BONES"]

# (parent keypoint, child keypoint) of each bone.
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
_BONE_INDEX = np.array(BONES)
_PALM = np.array([0, 1, 5, 9, 13, 17])
_PRIOR_WEIGHT = 1e-3
# Residual unit: 1 mm of keypoint error weighs as much as 1 rad of prior.
_POSITION_SIGMA_M = 1e-3
_MAX_ITERATIONS = 100
_SIDE_CHECK_ITERATIONS = 30
# Mean keypoint error (at the target hand's size) above which a cold fit is retried from more
# starts; 5 mm keypoint noise fits to about 5 mm.
_RESTART_ERROR_M = 0.015
# Stop when a step lowers the cost (mm^2) by less than _COST_TOL + _RELATIVE_COST_TOL * cost
# while converging linearly: far below what the keypoints' own noise decides. Quadratic
# convergence (exact keypoints) runs on to the rounding floor.
_COST_TOL = 1e-2
_RELATIVE_COST_TOL = 1e-2
_STEP_TOL = 1e-10
# Unknowns: translation (3), rotation increment (3), scale (1), angles (21).
_T, _W, _S, _A = slice(0, 3), slice(3, 6), 6, slice(7, 7 + NUM_ANGLES)
_NX = 7 + NUM_ANGLES
_LOWER, _UPPER = JOINT_LIMITS[:, 0].copy(), JOINT_LIMITS[:, 1].copy()
_MIRROR = np.array([-1.0, 1.0, 1.0])
_FLEXION = np.array([name.endswith("_flex") for name in JOINT_NAMES], dtype=float)


@dataclasses.dataclass(frozen=True)
class RetargetResult:
    """Outcome of one retargeting.

    Attributes:
        pose: the fitted pose (angles within limits), in the keypoints' frame.
        clamped: joints whose unconstrained fit was outside the limits, with the requested value.
        keypoint_error_m: mean distance between the fitted hand's keypoints and the present
            input keypoints scaled to the target hand's size, metres.
        scale: size of the source hand relative to the target hand.
        direction_error_rad: mean angle between fitted and input bone directions, over the
            bones with both ends present, radians (NaN when none is).
        other_side_error_m: ``keypoint_error_m`` of the mirrored fit (the keypoints read as the
            other hand side), metres; ``None`` unless the side was checked.
        iterations: Levenberg-Marquardt iterations of the bounded fit.
    """

    pose: HandPose
    clamped: tuple[LimitViolation, ...]
    keypoint_error_m: float
    scale: float
    direction_error_rad: float
    other_side_error_m: float | None = None
    iterations: int = 0


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrices of (..., 3) vectors."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (Rodrigues)."""
    theta = float(np.sqrt(w @ w))
    k = _skew(w)
    if theta < 1e-8:
        return np.eye(3) + k + 0.5 * k @ k
    return np.eye(3) + (np.sin(theta) / theta) * k + ((1 - np.cos(theta)) / theta**2) * (k @ k)


def _log(rot: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix, angle in [0, pi] (scipy's, at 1/20 of its cost)."""
    quat, rotvec = np.empty(4), np.empty(3)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rot, dtype=np.float64).ravel())
    mujoco.mju_quat2Vel(rotvec, quat, 1.0)
    return rotvec


def _umeyama(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Similarity ``target ~ s R source + t``: returns (R (3, 3), s, t (3,))."""
    mu_s, mu_t = source.mean(axis=0), target.mean(axis=0)
    a, b = source - mu_s, target - mu_t
    u, sig, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    rot = u @ np.diag([1.0, 1.0, d]) @ vt
    var = float(np.sum(a * a))
    s = float((sig[0] + sig[1] + d * sig[2]) / var) if var > 0 else 1.0
    return rot, s, mu_t - s * rot @ mu_s


class _ChainKinematics:
    """Keypoints in the hand frame and their angle Jacobian, the five digits in parallel.

    Each digit is a chain of three bodies with up to two hinges each (a missing hinge has angle
    index -1 and contributes nothing); every keypoint but the tip is a body origin.
    """

    def __init__(self, skeleton: Skeleton) -> None:
        # scipy.spatial loads when a retargeter is built, not on `import handsim`.
        from scipy.spatial.transform import Rotation

        bodies = skeleton.bodies
        chains = [[i for i, b in enumerate(bodies) if b.part == d] for d in DIGITS]
        if any(len(c) != 3 for c in chains) or bodies[0].parent != -1:
            raise AssertionError("retargeting expects three bodies per digit")
        self.off_rot = np.zeros((5, 3, 3, 3))
        self.off_pos = np.zeros((5, 3, 3))
        self.angle_index = np.full((5, 3, 2), -1, dtype=np.intp)
        k_mat = np.zeros((5, 3, 2, 3, 3))
        axes = np.zeros((5, 3, 2, 3))
        axes[..., 0] = 1.0
        for c, chain in enumerate(chains):
            for b, body_index in enumerate(chain):
                body = bodies[body_index]
                expected_parent = 0 if b == 0 else chain[b - 1]
                if body.parent != expected_parent:
                    raise AssertionError("retargeting expects serial digit chains")
                q = body.quat_wxyz
                self.off_rot[c, b] = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
                self.off_pos[c, b] = body.pos
                for slot, (angle_index, axis) in enumerate(body.joints):
                    self.angle_index[c, b, slot] = angle_index
                    axes[c, b, slot] = axis
        k_mat[:] = _skew(axes)
        self.axes = axes
        self.off_axes0 = (self.off_rot @ axes[:, :, 0, :, None])[..., 0]
        self.k = k_mat
        self.kk = k_mat @ k_mat
        tips = {body: p for body, p in skeleton.keypoints}
        self.tip_local = np.stack([tips[chain[2]] for chain in chains])  # (5, 3)
        # Order check: keypoint 1 + 4 c + b is body b of chain c (b < 3), then the tip.
        for c, chain in enumerate(chains):
            for b in range(3):
                body_index, pos = skeleton.keypoints[1 + 4 * c + b]
                if body_index != chain[b] or np.any(pos != 0):
                    raise AssertionError("keypoints must be the digit bodies' origins")
        self.valid = self.angle_index >= 0
        self._safe_index = np.where(self.valid, self.angle_index, 0)
        # Jacobian scatter: keypoint k of chain c depends on the hinges of bodies b < k.
        rows, cols, sel = [], [], []
        for c in range(5):
            for k in range(4):
                for b in range(3):
                    for slot in range(2):
                        if b < k and self.valid[c, b, slot]:
                            rows.append(1 + 4 * c + k)
                            cols.append(self.angle_index[c, b, slot])
                            sel.append((c, k, b, slot))
        self._rows = np.array(rows)
        self._cols = np.array(cols)
        self._sel = tuple(np.array(sel).T)

    def __call__(self, angles: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Keypoints (21, 3) in the hand frame and, on request, their angle Jacobian (21, 3, 21)."""
        theta = angles[self._safe_index]
        theta[~self.valid] = 0.0
        sin = np.sin(theta)[..., None, None]
        cos = np.cos(theta)[..., None, None]
        hinge = self.k * sin + self.kk * (1.0 - cos) + _EYE  # (5, 3, 2, 3, 3)
        first = self.off_rot @ hinge[:, :, 0]  # (5, 3, 3, 3)
        local = first @ hinge[:, :, 1]  # each body's rotation relative to its parent
        origins = np.empty((5, 4, 3))
        before = np.empty((5, 3, 3, 3))  # world_from_parent of each body
        rot = _EYE5
        pos = np.zeros((5, 3))
        for b in range(3):
            before[:, b] = rot
            pos = pos + (rot @ self.off_pos[:, b, :, None])[..., 0]
            origins[:, b] = pos
            rot = rot @ local[:, b]
        origins[:, 3] = pos + (rot @ self.tip_local[..., None])[..., 0]
        q = np.empty((21, 3))
        q[0] = 0.0
        q[1:] = origins.reshape(20, 3)
        if not jacobian:
            return q, None
        # Hinge axes in the hand frame: slot 0 after the body's fixed offset, slot 1 after that
        # and hinge 0.
        axes = np.empty((5, 3, 2, 3))
        axes[:, :, 0] = (before @ self.off_axes0[..., None])[..., 0]
        axes[:, :, 1] = (before @ (first @ self.axes[:, :, 1, :, None]))[..., 0]
        c_, k_, b_, s_ = self._sel
        a = axes[c_, b_, s_]
        lever = origins[c_, k_] - origins[c_, b_]
        jac = np.zeros((21, NUM_ANGLES, 3))
        jac[self._rows, self._cols] = _cross(a, lever)
        return q, jac.transpose(0, 2, 1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (np.cross costs more for small arrays)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


_EYE = np.eye(3)
_EYE5 = np.broadcast_to(np.eye(3), (5, 3, 3))


@dataclasses.dataclass
class _State:
    t: np.ndarray
    rot: np.ndarray
    s: float
    angles: np.ndarray


class Retargeter:
    """Fits the 27-DoF pose of one handsim hand to keypoints (all 21, or any subset).

    Args:
        hand: the target hand (parameters or skeleton).
        pose_prior: a Gaussian over natural postures
            (:func:`~handsim.hand.pose_prior.default_pose_prior`): the fit becomes maximum a
            posteriori, ``sum_i |FK_i - kp_i|^2 / keypoint_sigma_m^2 + |W (angles - mu)|^2``,
            in place of the weak prior toward zero. Default ``None``: least squares.
        keypoint_sigma_m: the keypoints' noise, metres per axis (required with a prior; 0:
            exact keypoints, the fit is the default least squares).

    Raises:
        InvalidPose: ``pose_prior`` is not a :class:`~handsim.hand.pose_prior.PosePrior`.
        InvalidKeypoints: a prior without a valid ``keypoint_sigma_m``.
    """

    def __init__(
        self,
        hand: HandParams | Skeleton,
        *,
        pose_prior: PosePrior | None = None,
        keypoint_sigma_m: float | None = None,
    ) -> None:
        """Precompute the target hand's kinematics and flat-hand template."""
        if pose_prior is not None and not isinstance(pose_prior, PosePrior):
            raise InvalidPose(
                f"pose_prior must be a PosePrior (e.g. default_pose_prior()) or None; received "
                f"{type(pose_prior).__name__}"
            )
        if pose_prior is not None and (
            isinstance(keypoint_sigma_m, bool)
            or not isinstance(keypoint_sigma_m, (int, float))
            or not np.isfinite(keypoint_sigma_m)
            or keypoint_sigma_m < 0
        ):
            raise InvalidKeypoints(
                "a pose prior weighs the keypoints by their noise: keypoint_sigma_m must be a "
                f"number >= 0 (metres, per axis; e.g. 0.01); received {keypoint_sigma_m!r}"
            )
        self.pose_prior = pose_prior
        self.keypoint_sigma_m = None if pose_prior is None else float(keypoint_sigma_m)
        # The prior in the solver's unit (1 mm residuals): (sigma / 1 mm)^2 Sigma^-1.
        self._prior_precision: np.ndarray | None = None
        self._prior_mean = np.zeros(NUM_ANGLES)
        # Noise-free keypoints (sigma 0) outweigh any prior: the plain fit, exactly.
        if pose_prior is not None and self.keypoint_sigma_m > 0:
            weight = (self.keypoint_sigma_m / _POSITION_SIGMA_M) ** 2
            self._prior_precision = weight * pose_prior.precision
            self._prior_mean = pose_prior.mean_rad.copy()
        self.fk = ForwardKinematics(hand)
        self.params = self.fk.skeleton.params
        self._chains = _ChainKinematics(self.fk.skeleton)
        self._template, _ = self._chains(np.zeros(NUM_ANGLES), False)
        # Flat, half-closed and closed postures for cold starts from sparse keypoints.
        self._postures = []
        for fraction in (0.0, 0.4, 0.8):
            angles = np.clip(fraction * _UPPER * _FLEXION, _LOWER, _UPPER)
            self._postures.append((angles, self._chains(angles, False)[0]))
        self._bone_lengths = np.linalg.norm(
            self._template[_BONE_INDEX[:, 1]] - self._template[_BONE_INDEX[:, 0]], axis=-1
        )

    # Input -------------------------------------------------------------------------------

    def _validate(self, keypoints: object, mask: object) -> tuple[np.ndarray, np.ndarray]:
        try:
            kp = np.asarray(keypoints)
        except (TypeError, ValueError):  # ragged
            kp = np.asarray(None)
        if kp.dtype.kind not in "iuf":
            raise InvalidKeypoints(
                f"retargeting expects a (21, 3) array of real numbers (metres); received "
                f"{type(keypoints).__name__} {str(keypoints)[:40]!r}"
            )
        kp = kp.astype(np.float64)
        if kp.shape != (21, 3):
            raise InvalidKeypoints(
                f"retargeting expects keypoints of shape (21, 3) in KEYPOINT_NAMES order, metres; "
                f"received shape {kp.shape}. Convert other orders with handsim.hand.keypoints."
            )
        if mask is None:
            # from_format's convention: a row that is all NaN is an absent point.
            present = ~np.all(np.isnan(kp), axis=1)
        else:
            present = np.asarray(mask)
            if present.shape != (21,) or present.dtype != bool:
                raise InvalidKeypoints(
                    f"mask must be a (21,) bool array (True = keypoint present); received "
                    f"shape {present.shape}, dtype {present.dtype}"
                )
        bad = present & ~np.all(np.isfinite(kp), axis=1)
        if np.any(bad):
            raise InvalidKeypoints(
                "retargeting expects finite keypoints; received NaN or Inf at indices "
                f"{np.nonzero(bad)[0].tolist()} (mark absent points with all-NaN rows or mask)"
            )
        if np.count_nonzero(present) < 4:
            raise InvalidKeypoints(
                f"retargeting needs at least 4 present keypoints; received "
                f"{np.count_nonzero(present)} (indices {np.nonzero(present)[0].tolist()})"
            )
        both = present[_BONE_INDEX[:, 0]] & present[_BONE_INDEX[:, 1]]
        lengths = np.linalg.norm(kp[_BONE_INDEX[:, 1]] - kp[_BONE_INDEX[:, 0]], axis=-1)
        short = both & (lengths < 1e-4)
        if np.any(short):
            raise InvalidKeypoints(
                "retargeting expects distinct keypoints; bones "
                f"{[BONES[i] for i in np.nonzero(short)[0]]} have zero length"
            )
        return kp, present

    def _bone_scale(self, kp: np.ndarray, present: np.ndarray) -> float | None:
        both = present[_BONE_INDEX[:, 0]] & present[_BONE_INDEX[:, 1]]
        if not np.any(both):
            return None
        b = _BONE_INDEX[both]
        return float(
            np.linalg.norm(kp[b[:, 1]] - kp[b[:, 0]], axis=-1).sum()
            / self._bone_lengths[both].sum()
        )

    def _cold_starts(
        self, kp: np.ndarray, present: np.ndarray, extended: bool = False
    ) -> list[_State]:
        """Initial states for a cold start.

        The palm points aligned with the flat hand or, with fewer than three palm points (or
        ``extended``), all present points aligned with a flat, a half-closed and a closed hand.
        """
        palm = _PALM[present[_PALM]]
        if palm.size >= 3 and not extended:
            points, postures = palm, self._postures[:1]
        else:
            points, postures = np.nonzero(present)[0], self._postures
        bone = self._bone_scale(kp, present)
        starts = []
        for angles, template in postures:
            rot, s, t = _umeyama(template[points], kp[points])
            if bone is not None:
                s = bone
                t = kp[points].mean(axis=0) - s * rot @ template[points].mean(axis=0)
            starts.append(_State(t, rot, s, angles.copy()))
        return starts

    # Solver ------------------------------------------------------------------------------

    def _solve(
        self,
        state: _State,
        kp: np.ndarray,
        present: np.ndarray,
        free: np.ndarray,
        bounded: bool,
        max_iterations: int = _MAX_ITERATIONS,
    ) -> tuple[_State, float, int]:
        """Levenberg-Marquardt from ``state``; ``free`` (28,) marks the unknowns fitted."""
        target = kp[present]
        idx = np.nonzero(present)[0]
        inv_sigma = 1.0 / _POSITION_SIGMA_M
        lower = np.where(bounded, _LOWER, -np.inf)
        upper = np.where(bounded, _UPPER, np.inf)

        precision = self._prior_precision
        mean = self._prior_mean

        def prior_cost(angles: np.ndarray) -> float:
            if precision is None:
                return _PRIOR_WEIGHT**2 * angles @ angles
            d = angles - mean
            return float(d @ precision @ d)

        m = idx.size
        jac = np.zeros((m, 3, _NX))
        jac[:, :, _T] = _EYE * inv_sigma

        def residual(st: _State) -> tuple[float, np.ndarray, np.ndarray]:
            q, dq = self._chains(st.angles, True)
            rq = q[idx] @ st.rot.T  # (m, 3)
            r = (st.t + st.s * rq - target) * inv_sigma
            cost = float(np.dot(r.ravel(), r.ravel()) + prior_cost(st.angles))
            j = jac.copy()
            # d(exp(w) v)/dw = -[v]x for v = s R q.
            v = rq * (st.s * inv_sigma)
            j[:, 0, 4], j[:, 0, 5] = v[:, 2], -v[:, 1]
            j[:, 1, 3], j[:, 1, 5] = -v[:, 2], v[:, 0]
            j[:, 2, 3], j[:, 2, 4] = v[:, 1], -v[:, 0]
            j[:, :, _S] = rq * inv_sigma
            j[:, :, _A] = st.rot @ dq[idx] * (st.s * inv_sigma)
            return cost, r.ravel(), j.reshape(3 * m, _NX)

        cost, r, jac_now = residual(state)
        lam = 1e-3
        iterations = 0
        all_free = bool(free.all())
        for iterations in range(1, max_iterations + 1):  # noqa: B007
            grad = jac_now.T @ r
            hess = jac_now.T @ jac_now
            if precision is None:
                grad[_A] += _PRIOR_WEIGHT**2 * state.angles
                hess[_A, _A][np.diag_indices(NUM_ANGLES)] += _PRIOR_WEIGHT**2
            else:
                # The prior's residual rows W (angles - mu) have the Jacobian W.
                grad[_A] += precision @ (state.angles - mean)
                hess[_A, _A] += precision
            active = free
            if bounded:
                held = ((state.angles <= _LOWER) & (grad[_A] > 0)) | (
                    (state.angles >= _UPPER) & (grad[_A] < 0)
                )
                if held.any():
                    active = free.copy()
                    active[_A] &= ~held
            if all_free and active is free:
                h, g = hess, grad
            else:
                h, g = hess[np.ix_(active, active)], grad[active]
            diag = h[np.diag_indices(len(g))] + 1e-9
            improved = False
            while lam < 1e12:
                damped = h.copy()
                damped[np.diag_indices(len(g))] += lam * diag
                try:
                    step_active = np.linalg.solve(damped, -g)
                except np.linalg.LinAlgError:
                    lam *= 10.0
                    continue
                if active is free and all_free:
                    step = step_active
                else:
                    step = np.zeros(_NX)
                    step[active] = step_active
                trial = _State(
                    state.t + step[_T],
                    _exp(step[_W]) @ state.rot,
                    state.s + step[_S],
                    np.clip(state.angles + step[_A], lower, upper),
                )
                trial_cost, trial_r, trial_jac = residual(trial)
                if trial_cost <= cost and trial.s > 0:
                    improved = True
                    break
                lam *= 4.0
            if not improved:
                break
            reduction = cost - trial_cost
            linear = reduction < 0.5 * cost
            state, cost, r, jac_now = trial, trial_cost, trial_r, trial_jac
            lam = max(lam / 5.0, 1e-12)
            small = reduction < _COST_TOL + _RELATIVE_COST_TOL * cost
            if (linear and small) or np.max(np.abs(step)) < _STEP_TOL:
                break
        return state, cost, iterations

    # Public ------------------------------------------------------------------------------

    def _fit(
        self,
        kp: np.ndarray,
        present: np.ndarray,
        initial: HandPose | None,
        initial_scale: float | None,
        fit_wrist: bool,
        fit_scale: bool,
        max_iterations: int = _MAX_ITERATIONS,
        restart: bool = True,
    ) -> tuple[_State, float, int]:
        if initial is None:
            starts = self._cold_starts(kp, present)
        else:
            rot = _exp(np.asarray(initial.wrist_rotvec, dtype=np.float64))
            angles = np.clip(np.asarray(initial.angles, dtype=np.float64), _LOWER, _UPPER)
            t, s = np.asarray(initial.wrist_pos, dtype=np.float64).copy(), 1.0
            if initial_scale is None:
                # Scale and wrist position that best place the initial posture on the input
                # (linear least squares), so a stream need not carry its scale along.
                rq = self._chains(angles, False)[0][present] @ rot.T
                y = kp[present]
                a, b = rq - rq.mean(axis=0), y - y.mean(axis=0)
                s = float(np.sum(a * b) / np.sum(a * a))
                if not np.isfinite(s) or s <= 0:
                    s = self._bone_scale(kp, present) or 1.0
                t = y.mean(axis=0) - s * rq.mean(axis=0)
            starts = [_State(t, rot, s, angles)]
        free = np.ones(_NX, dtype=bool)
        free[_T] = fit_wrist
        free[_S] = fit_scale
        best = None
        for round_ in range(2):
            for start in starts:
                if initial_scale is not None:
                    start.s = float(initial_scale)
                if not fit_wrist:
                    start.t = kp[0].copy()
                if not fit_scale and initial_scale is None:
                    bone = self._bone_scale(kp, present)
                    start.s = 1.0 if bone is None else bone
                fit = self._solve(start, kp, present, free, True, max_iterations)
                if best is None or fit[1] < best[1]:
                    best = fit
            # A cold fit this far off is usually a local minimum (0.4% of random poses from
            # the flat-hand start): try the flat, half-closed and closed starts on all points.
            if round_ or not restart or initial is not None or len(starts) > 1:
                break
            if self._error(best[0], kp, present) <= _RESTART_ERROR_M:
                break
            starts = self._cold_starts(kp, present, extended=True)
        return best

    def __call__(
        self,
        keypoints: object,
        initial: HandPose | None = None,
        *,
        mask: object = None,
        fit_wrist: bool = True,
        fit_scale: bool = True,
        initial_scale: float | None = None,
        check_side: bool = True,
        report_clamped: bool = True,
    ) -> RetargetResult:
        """Retarget one frame.

        Args:
            keypoints: (21, 3) keypoints of a hand of the same side, metres, any frame;
                absent points as all-NaN rows (as :func:`~handsim.hand.keypoints.from_format`
                gives them) or marked by ``mask``.
            initial: warm start (e.g. the previous frame's pose); default: a cold start from
                the palm points.
            mask: (21,) bool, True where a keypoint is present; default: the rows that are not
                all NaN.
            fit_wrist: let the wrist position float (default); off, it is pinned at the wrist
                keypoint, which must be present.
            fit_scale: let the source hand's scale float (default); off, it is fixed at
                ``initial_scale`` or, without it, at the ratio of the present bones' lengths to
                the target hand's.
            initial_scale: warm start of the scale (e.g. the previous frame's ``scale``), or
                the fixed scale with ``fit_scale=False`` (1.0: the source is this hand's size).
            check_side: also fit the keypoints mirrored and reject them when the mirrored fit
                (the other hand side) is better. It costs a second, cold fit.
            report_clamped: refit joints at their limits without bounds to report the
                requested values (``clamped``); off, ``clamped`` is empty.

        Returns:
            The fitted pose in the keypoints' frame, with the clamped joints and fit errors.

        Raises:
            InvalidKeypoints: wrong shape, a present keypoint that is not finite, fewer than 4
                present keypoints, coincident keypoints, no wrist keypoint with
                ``fit_wrist=False``, or keypoints of the other hand side (with ``check_side``).
            InvalidPose: if ``initial`` is not one :class:`HandPose` or None.
        """
        kp, present = self._validate(keypoints, mask)
        if initial is not None and not (
            isinstance(initial, HandPose) and initial.batch_shape == ()
        ):
            raise InvalidPose(
                f"initial must be one HandPose (e.g. the previous frame's result.pose) or None; "
                f"received {type(initial).__name__} {str(initial)[:40]!r}: for a named posture "
                "pass gesture(name)"
            )
        if not fit_wrist and not present[0]:
            raise InvalidKeypoints(
                "fit_wrist=False pins the wrist at the wrist keypoint, but keypoint 0 (wrist) "
                "is absent; pass fit_wrist=True"
            )
        state, _, iterations = self._fit(kp, present, initial, initial_scale, fit_wrist, fit_scale)
        error = self._error(state, kp, present)
        other_error = None
        if check_side:
            mirrored = kp * _MIRROR
            # Capped, and from more starts only when this side's fit is poor itself: a mirrored
            # fit that is worse than it could be only errs toward accepting the keypoints.
            other, _, _ = self._fit(
                mirrored,
                present,
                None,
                None,
                fit_wrist,
                fit_scale,
                _SIDE_CHECK_ITERATIONS,
                restart=error > _RESTART_ERROR_M,
            )
            other_error = self._error(other, mirrored, present)
            if other_error < error:
                side = self.params.side
                other_side = "left" if side == "right" else "right"
                raise InvalidKeypoints(
                    f"the keypoints look like a {other_side} hand but the target hand is "
                    f"{side} (mean fit error {1000 * other_error:.1f} mm as a {other_side} hand, "
                    f"{1000 * error:.1f} mm as a {side} hand); retarget onto a {other_side} "
                    "hand, or mirror the keypoints"
                )

        clamped: tuple[LimitViolation, ...] = ()
        at_bound = (state.angles <= _LOWER + 1e-6) | (state.angles >= _UPPER - 1e-6)
        if report_clamped and np.any(at_bound):
            # Refit without bounds from the bounded fit (so it stays on the same solution
            # branch) to see how far past its limits the input asks each joint to go.
            free = np.ones(_NX, dtype=bool)
            free[_T] = fit_wrist
            free[_S] = fit_scale
            start = dataclasses.replace(state, angles=state.angles.copy())
            unbounded, _, _ = self._solve(start, kp, present, free, bounded=False)
            # Hinge angles are 2 pi periodic; compare their principal values with the limits.
            wanted = np.mod(unbounded.angles + np.pi, 2 * np.pi) - np.pi
            outside = (wanted < _LOWER - 1e-4) | (wanted > _UPPER + 1e-4)
            clamped = tuple(
                LimitViolation(JOINT_NAMES[j], float(wanted[j]), float(_LOWER[j]), float(_UPPER[j]))
                for j in np.nonzero(outside & at_bound)[0]
            )
        rotvec = _log(state.rot)
        pose = HandPose(state.t, rotvec, np.clip(state.angles, _LOWER, _UPPER))
        fitted = self._fitted(state)
        both = present[_BONE_INDEX[:, 0]] & present[_BONE_INDEX[:, 1]]
        if np.any(both):
            b = _BONE_INDEX[both]
            u = fitted[b[:, 1]] - fitted[b[:, 0]]
            v = kp[b[:, 1]] - kp[b[:, 0]]
            cosines = np.sum(u * v, axis=-1) / (
                np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1)
            )
            direction_error = float(np.mean(np.arccos(np.clip(cosines, -1.0, 1.0))))
        else:
            direction_error = float("nan")
        return RetargetResult(
            pose=pose,
            clamped=clamped,
            keypoint_error_m=error,
            scale=float(state.s),
            direction_error_rad=direction_error,
            other_side_error_m=other_error,
            iterations=iterations,
        )

    def _fitted(self, state: _State) -> np.ndarray:
        q, _ = self._chains(state.angles, False)
        return state.t + state.s * q @ state.rot.T

    def _error(self, state: _State, kp: np.ndarray, present: np.ndarray) -> float:
        d = self._fitted(state)[present] - kp[present]
        return float(np.mean(np.linalg.norm(d, axis=-1)) / state.s)

    def sequence(
        self,
        keypoints: object,
        mask: object = None,
        *,
        fit_wrist: bool = True,
        fit_scale: bool = True,
        check_side: bool = True,
    ) -> list[RetargetResult]:
        """Retarget a sequence, warm-starting each frame (pose and scale) from the previous one.

        Args:
            keypoints: (T, 21, 3) keypoints, metres (absent points as all-NaN rows).
            mask: (T, 21) or (21,) bool, True where present; default: rows not all NaN.
            fit_wrist: let the wrist position float.
            fit_scale: let the scale float.
            check_side: check the side on the first frame (a stream does not change side).

        Returns:
            One result per frame.
        """
        kp = np.asarray(keypoints, dtype=np.float64)
        if kp.ndim != 3 or kp.shape[1:] != (21, 3):
            raise InvalidKeypoints(
                f"a keypoint sequence must have shape (T, 21, 3); received shape {kp.shape}"
            )
        masks = [None] * len(kp) if mask is None else np.broadcast_to(mask, (len(kp), 21))
        results: list[RetargetResult] = []
        previous: RetargetResult | None = None
        for t, frame in enumerate(kp):
            result = self(
                frame,
                initial=None if previous is None else previous.pose,
                initial_scale=None if previous is None else previous.scale,
                mask=masks[t],
                fit_wrist=fit_wrist,
                fit_scale=fit_scale,
                check_side=check_side and previous is None,
            )
            results.append(result)
            previous = result
        return results
