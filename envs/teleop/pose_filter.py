"""Joint-space smoothing of the retargeted hand pose, tuned for interaction.

Retargeted from keypoints with 10 mm of noise per axis, the hand's pose is far noisier than the
keypoints suggest: the wrist moves 6 mm per axis and turns 7 deg (mean) from frame to frame,
and a finger joint 0.2 to 0.6 rad (the grasp expert's held pose, seed 0, 100 noisy fits). A
physical hand that follows that shakes whatever it holds. :class:`PoseFilter` smooths the fit
in joint space with the One Euro filter (Casiez, Roussel and Vogel, CHI 2012; the speed-based
low-pass of :mod:`~handsim.envs.teleop.filters`), each part in its own units: the wrist
position (Hz per m/s), the wrist rotation on SO(3) (the step toward the new rotation is a
fraction of the rotation between them, Hz per rad/s) and the 21 joint angles (Hz per rad/s).
A hand at rest is smoothed hard; a reach lightly.

Filtering the fit rather than the keypoints suits noise that the fit amplifies: a keypoint
filter must be heavy enough for the worst joint, while here each part gets its own cut-off.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from handsim.envs.teleop.filters import InvalidFilter, OneEuroFilter, _alpha, _positive

__all__ = [
    "PoseFilter",
    "POSE_FILTER_DEFAULTS",
    "make_pose_filter",
    "ADAPTIVE_REFERENCE_M",
    "ADAPTIVE_MAX_SCALE",
]

ADAPTIVE_REFERENCE_M = 0.01
"""The keypoint noise the default cut-offs are tuned for, metres per axis (10 mm)."""
ADAPTIVE_MAX_SCALE = 30.0
"""The largest factor on the cut-offs of the noise-adaptive filter (30 Hz from 1 Hz)."""

POSE_FILTER_DEFAULTS: dict[str, float] = {
    "min_cutoff_hz": 1.0,
    "rot_cutoff_hz": 1.0,
    "beta_m_s": 0.0,
    "beta_rot": 0.0,
    "beta_joint": 0.25,
    "d_cutoff_hz": 1.0,
}
"""One Euro's rest cut-off (1 Hz, its authors' default) for every part. The wrist's speed
terms are 0: the noise of a 10 mm fit moves the wrist about 0.4 m/s and turns it about
6 rad/s from frame to frame, as fast as the task's own motion, so its speed cannot tell motion
from noise. A finger's closure (about 4 rad/s) doubles its joints' cut-off (Hz per rad/s)."""


class PoseFilter:
    """One Euro filter on a 27-DoF pose ``[wrist_pos 3, wrist_rotvec 3, angles 21]``.

    Args:
        rate_hz: the control rate, Hz.
        min_cutoff_hz: cut-off at rest of the wrist position and the joint angles, Hz.
        rot_cutoff_hz: cut-off at rest of the wrist rotation, Hz.
        beta_m_s: the wrist position's cut-off increase per m/s of speed, Hz.
        beta_rot: the wrist rotation's cut-off increase per rad/s, Hz.
        beta_joint: a joint angle's cut-off increase per rad/s, Hz.
        d_cutoff_hz: cut-off of the speeds' smoothing, Hz.
        wrist_only: smooth the wrist only; the 21 joint angles pass unchanged.

    Raises:
        InvalidFilter: a non-positive rate or cut-off, a negative beta.
    """

    def __init__(
        self,
        rate_hz: float,
        *,
        min_cutoff_hz: float = POSE_FILTER_DEFAULTS["min_cutoff_hz"],
        rot_cutoff_hz: float = POSE_FILTER_DEFAULTS["rot_cutoff_hz"],
        beta_m_s: float = POSE_FILTER_DEFAULTS["beta_m_s"],
        beta_rot: float = POSE_FILTER_DEFAULTS["beta_rot"],
        beta_joint: float = POSE_FILTER_DEFAULTS["beta_joint"],
        d_cutoff_hz: float = POSE_FILTER_DEFAULTS["d_cutoff_hz"],
        wrist_only: bool = False,
        adaptive: bool = False,
    ) -> None:
        self._position = OneEuroFilter(
            rate_hz, min_cutoff_hz=min_cutoff_hz, beta=beta_m_s, d_cutoff_hz=d_cutoff_hz
        )
        self._angles = OneEuroFilter(
            rate_hz, min_cutoff_hz=min_cutoff_hz, beta=beta_joint, d_cutoff_hz=d_cutoff_hz
        )
        self.min_cutoff_hz = float(min_cutoff_hz)
        self.wrist_only = bool(wrist_only)
        self.adaptive = bool(adaptive)
        self.rot_cutoff_hz = _positive("rot_cutoff_hz", rot_cutoff_hz)
        self._base_cutoffs = (self.min_cutoff_hz, self.rot_cutoff_hz)
        self.cutoff_scale = 1.0
        """The factor on the rest cut-offs (:meth:`set_keypoint_noise`)."""
        self.beta_rot = _positive("beta_rot", beta_rot, zero_ok=True)
        self._dt = 1.0 / float(rate_hz)
        self._alpha_d = _alpha(_positive("d_cutoff_hz", d_cutoff_hz), self._dt)
        self.reset()

    def __repr__(self) -> str:
        return (
            f"PoseFilter(rate_hz={1 / self._dt:g}, min_cutoff_hz={self.min_cutoff_hz:g}, "
            f"rot_cutoff_hz={self.rot_cutoff_hz:g}, "
            f"beta_m_s={self._position.beta:g}, beta_rot={self.beta_rot:g}, "
            f"beta_joint={self._angles.beta:g}, wrist_only={self.wrist_only})"
        )

    def set_keypoint_noise(self, sigma_m: float) -> None:
        """Scale the rest cut-offs for keypoints of noise ``sigma_m`` (metres per axis).

        A first-order low-pass passes noise in proportion to the square root of its cut-off,
        so the cut-offs tuned for :data:`ADAPTIVE_REFERENCE_M` of noise are multiplied by
        ``(reference / sigma_m)^2``: the filtered pose shakes about as much at any noise,
        and cleaner tracking is followed with less lag. The factor lies in
        ``[1, ADAPTIVE_MAX_SCALE]`` (never heavier than the tuning; at its top, 30 Hz at a
        50 Hz rate, the filter barely acts).
        """
        if not self.adaptive:
            return
        ratio = ADAPTIVE_REFERENCE_M / max(float(sigma_m), 1e-9)
        self.cutoff_scale = float(np.clip(ratio * ratio, 1.0, ADAPTIVE_MAX_SCALE))
        position, rotation = self._base_cutoffs
        self.min_cutoff_hz = self._position.min_cutoff_hz = position * self.cutoff_scale
        self._angles.min_cutoff_hz = position * self.cutoff_scale
        self.rot_cutoff_hz = rotation * self.cutoff_scale

    def reset(self) -> None:
        """Forget the state (the next pose passes unchanged)."""
        self._position.reset()
        self._angles.reset()
        self._rot: Rotation | None = None
        self._rot_raw: Rotation | None = None
        self._speed = 0.0

    def __call__(self, pose: np.ndarray) -> np.ndarray:
        """The filtered pose (27,) for the fitted ``pose`` (27,)."""
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (27,) or not np.all(np.isfinite(pose)):
            raise InvalidFilter(
                f"PoseFilter takes a finite 27-DoF pose vector; received shape {pose.shape}"
            )
        out = np.empty(27)
        out[:3] = self._position(pose[:3])
        out[6:] = pose[6:] if self.wrist_only else self._angles(pose[6:])
        rot = Rotation.from_rotvec(pose[3:6])
        if self._rot is None:
            self._rot = self._rot_raw = rot
            out[3:6] = pose[3:6]
            return out
        assert self._rot_raw is not None
        speed = (self._rot_raw.inv() * rot).magnitude() / self._dt
        self._speed += self._alpha_d * (speed - self._speed)
        a = float(_alpha(self.rot_cutoff_hz + self.beta_rot * self._speed, self._dt))
        step = (self._rot.inv() * rot).as_rotvec()
        self._rot = self._rot * Rotation.from_rotvec(a * step)
        self._rot_raw = rot
        out[3:6] = self._rot.as_rotvec()
        return out


def make_pose_filter(
    rate_hz: float, *, wrist_only: bool = False, adaptive: bool = False, **params: float
) -> PoseFilter:
    """A :class:`PoseFilter` with ``params`` (keys of :data:`POSE_FILTER_DEFAULTS`).

    ``wrist_only`` smooths the wrist and passes the joint angles unchanged.

    Raises:
        InvalidFilter: an unknown parameter or a value out of range.
    """
    unknown = sorted(set(params) - set(POSE_FILTER_DEFAULTS))
    if unknown:
        raise InvalidFilter(
            f"pose filter parameters {unknown} are not valid; choose from "
            f"{', '.join(POSE_FILTER_DEFAULTS)}"
        )
    return PoseFilter(rate_hz, wrist_only=wrist_only, adaptive=adaptive, **params)
