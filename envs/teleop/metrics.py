"""Per-episode teleoperation metrics: what a user of the VR interaction would feel.

- **success** and **time to success** (s): the task's ``info["is_success"]``, first step.
- **interpenetration** (mm): per step, the deepest contact penetration between the physical
  hand's collision geoms and anything else (objects, panel, table), ``max(0, -dist)`` of
  MuJoCo's contacts; the episode's maximum, and the mean over the steps with a hand contact.
- **slip** (mm): the largest slip of the grasped object in the palm frame during a hold
  (grasp tasks: ``info["slip_m"]``); NaN where the task has none or nothing was held.
- **fingertip jitter** (mm): the RMS of the five physical fingertips' positions above
  :data:`JITTER_CUTOFF_HZ` (:func:`high_frequency_rms_mm`: minus a zero-phase Butterworth
  low-pass, averaged over tips and axes) — the shaking a user sees.
- **lag** (s): the shift that best aligns the physical hand's keypoint velocities with the
  operator's (:func:`lag_frames`, normalized cross-correlation over 0 to
  :data:`MAX_LAG_S`), times the control period.
- **unintended presses**: presses of buttons other than the target (``Press-v0``).
- **tracking error** (mm): mean distance between the physical hand's keypoints and the
  operator's (the operator's hand size may differ, so it has a floor).
"""

from __future__ import annotations

import math

import numpy as np

from handsim.metrics import FINGERTIP_INDICES

__all__ = [
    "JITTER_CUTOFF_HZ",
    "MAX_LAG_S",
    "FINGERTIPS",
    "high_frequency_rms_mm",
    "lag_frames",
    "hand_penetration_m",
    "hand_geom_mask",
]

JITTER_CUTOFF_HZ = 5.0
"""Motion above this frequency counts as jitter, Hz (voluntary hand motion is mostly below)."""
MAX_LAG_S = 0.5
"""Largest lag searched by the cross-correlation, seconds."""
FINGERTIPS: tuple[int, ...] = FINGERTIP_INDICES
"""Keypoint indices of the five fingertips (:data:`handsim.metrics.FINGERTIP_INDICES`)."""


def high_frequency_rms_mm(
    x_m: np.ndarray, dt_s: float, cutoff_hz: float = JITTER_CUTOFF_HZ
) -> float:
    """RMS of a trajectory's content above ``cutoff_hz``, mm, averaged over its channels.

    The content above the cutoff is the trajectory minus its zero-phase low-pass (a 4th-order
    Butterworth filter run forward and backward, ``scipy.signal.sosfiltfilt``), so slow
    voluntary motion leaves nothing and the ends need no window.

    Args:
        x_m: (T, ...) positions over time, metres (channels with NaN are skipped).
        dt_s: sample period, seconds.
        cutoff_hz: frequencies above this count, Hz.

    Returns:
        The RMS in mm (NaN for fewer than 16 samples or a cutoff at or above Nyquist).
    """
    from scipy.signal import butter, sosfiltfilt

    x = np.asarray(x_m, dtype=np.float64).reshape(len(x_m), -1)
    n = len(x)
    nyquist = 0.5 / dt_s
    if n < 16 or cutoff_hz >= nyquist:
        return math.nan
    ok = np.all(np.isfinite(x), axis=0)
    if not ok.any():
        return math.nan
    x = x[:, ok]
    sos = butter(4, cutoff_hz, fs=1.0 / dt_s, output="sos")
    # Pad by three periods of the cutoff (odd extension) so the ends settle.
    pad = min(n - 1, int(math.ceil(3.0 / (cutoff_hz * dt_s))))
    high = x - sosfiltfilt(sos, x, axis=0, padlen=pad)
    return float(np.sqrt(np.mean(high**2)) * 1e3)


def lag_frames(reference: np.ndarray, follower: np.ndarray, max_lag: int) -> int:
    """The delay of ``follower`` behind ``reference`` that maximizes their velocity correlation.

    Args:
        reference: (T, ...) the operator's positions over time.
        follower: (T, ...) the same points of the physical hand.
        max_lag: largest delay tried, frames (>= 0).

    Returns:
        The delay in frames, in ``[0, max_lag]``: ``follower[t] = reference[t - k]`` gives
        ``k`` exactly (channels with NaN are skipped; a motionless reference gives 0).
    """
    a = np.asarray(reference, dtype=np.float64).reshape(len(reference), -1)
    b = np.asarray(follower, dtype=np.float64).reshape(len(follower), -1)
    ok = np.all(np.isfinite(a), axis=0) & np.all(np.isfinite(b), axis=0)
    va, vb = np.diff(a[:, ok], axis=0), np.diff(b[:, ok], axis=0)
    n = len(va)
    best, best_score = 0, -math.inf
    for k in range(min(max_lag, n - 2) + 1):
        x, y = va[: n - k], vb[k:]
        x = x - x.mean(axis=0)
        y = y - y.mean(axis=0)
        denom = math.sqrt(float(np.sum(x * x)) * float(np.sum(y * y)))
        if denom <= 1e-18:
            continue
        score = float(np.sum(x * y)) / denom
        if score > best_score + 1e-12:
            best, best_score = k, score
    return best


def hand_geom_mask(model: object, hand_root_body: int) -> np.ndarray:
    """(ngeom,) bool: geoms of the hand (bodies under its root) that collide."""
    root = model.body_rootid[model.geom_bodyid]
    collides = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    return (root == model.body_rootid[hand_root_body]) & collides


def hand_penetration_m(data: object, hand_geoms: np.ndarray) -> tuple[float, bool]:
    """The deepest penetration of a hand geom into any other geom now, and any contact.

    Returns ``(depth_m, touching)``: metres (0 without contact), and whether the hand touches
    anything.

    Args:
        data: ``mujoco.MjData`` after a step (contacts computed).
        hand_geoms: :func:`hand_geom_mask`.
    """
    ncon = data.ncon
    if ncon == 0:
        return 0.0, False
    geoms = data.contact.geom[:ncon]
    h1, h2 = hand_geoms[geoms[:, 0]], hand_geoms[geoms[:, 1]]
    touching = h1 ^ h2
    if not touching.any():
        return 0.0, False
    dist = data.contact.dist[:ncon][touching]
    return float(max(0.0, -dist.min())), True
