"""What a dataset's hands and views look like: palm angles, mixes and the constant-pose error.

``handsim dataset info`` prints :func:`dataset_stats`. The figures, and how they compare with
real datasets:

Palm angle
    The angle between the palm's normal (toward the palm side) and the line of sight from the
    palm centre to the camera, degrees: 0 = the palm faces the camera, 180 = the back of the
    hand does, 90 = the hand is seen edge-on. The normal is read from the keypoints in the
    camera frame: ``(index_mcp - wrist) x (little_mcp - wrist)``, negated for a left hand
    (:func:`palm_angles_deg`). The *facing angle* ``min(a, 180 - a)`` is the angle of the
    palm's plane normal, either side, to the line of sight.
Constant-mean-pose error
    How much orientation and pose prior a dataset holds (:func:`constant_pose_error_mm`): the
    mean pose of the dataset's own ``nyu14`` joints relative to the **palm centre** (NYU's
    ``PALM_3``, the canonical ``palm_centre`` point), placed at each frame's true palm centre
    in the camera frame, without rotation; the error is the mean distance over the 14 joints
    (the palm centre's own 0 included) and the frames, in mm. Left hands are mirrored into
    right ones first (x -> -x in the camera frame), as learned estimators do. On the published
    test labels, the same figure is 51.3 mm for NYU (14 joints) and 22.5 mm for ICVL (16
    joints); without any prior it would be the joints' mean distance from the centre (NYU
    76.4 mm), :func:`mean_joint_distance_mm` here.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from handsim.data.arrays import POSE_SOURCE_CODES, VIEWPOINT_CODES
from handsim.errors import HandSimError
from handsim.hand.keypoints import FORMATS, KEYPOINT_NAMES, to_format

__all__ = [
    "PALM_ANGLE_BINS_DEG",
    "InvalidStatsInput",
    "palm_normals",
    "palm_angles_deg",
    "constant_pose_error_mm",
    "mean_joint_distance_mm",
    "dataset_stats",
]

PALM_ANGLE_BINS_DEG = tuple(range(0, 181, 15))
"""Bin edges of the palm-angle histogram, degrees."""
_CENTRE = "PALM_3"  # nyu14's palm centre
_WRIST, _INDEX_MCP, _LITTLE_MCP = (
    KEYPOINT_NAMES.index(n) for n in ("wrist", "index_mcp", "little_mcp")
)


class InvalidStatsInput(HandSimError, ValueError):
    """Keypoints or sides of the wrong shape for the dataset statistics."""


def _check(keypoints_cam: np.ndarray, is_left: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    kp = np.asarray(keypoints_cam, dtype=np.float64)
    left = np.asarray(is_left, dtype=bool)
    if kp.ndim != 3 or kp.shape[1:] != (21, 3) or left.shape != (kp.shape[0],):
        raise InvalidStatsInput(
            "expected keypoints_cam of shape (N, 21, 3) and is_left of shape (N,); received "
            f"{kp.shape} and {left.shape}"
        )
    if not np.all(np.isfinite(kp)):
        raise InvalidStatsInput("keypoints_cam must be finite (metres, camera frame)")
    return kp, left


def palm_normals(keypoints_cam: np.ndarray, is_left: np.ndarray) -> np.ndarray:
    """Unit normals of the palm toward its palmar side, camera frame.

    Args:
        keypoints_cam: (N, 21, 3) keypoints, metres, camera frame (canonical order).
        is_left: (N,) bool, left hands.

    Returns:
        (N, 3) float64 unit vectors.

    Raises:
        InvalidStatsInput: for wrong shapes or non-finite keypoints.
    """
    kp, left = _check(keypoints_cam, is_left)
    wrist = kp[:, _WRIST]
    # Right hand: index MCP radial, little MCP ulnar, both distal: the cross product is palmar.
    normal = np.cross(kp[:, _INDEX_MCP] - wrist, kp[:, _LITTLE_MCP] - wrist)
    normal[left] *= -1.0
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def palm_angles_deg(keypoints_cam: np.ndarray, is_left: np.ndarray) -> np.ndarray:
    """Angle between the palm normal and the line of sight to the camera, degrees.

    Args:
        keypoints_cam: (N, 21, 3) keypoints, metres, camera frame (canonical order).
        is_left: (N,) bool, left hands.

    Returns:
        (N,) float64 in [0, 180]: 0 the palm faces the camera, 180 the back does.

    Raises:
        InvalidStatsInput: for wrong shapes or non-finite keypoints.
    """
    kp, _ = _check(keypoints_cam, is_left)
    normal = palm_normals(kp, is_left)
    centre = to_format(kp, "nyu14")[:, FORMATS["nyu14"].index(_CENTRE)]
    to_camera = -centre / np.linalg.norm(centre, axis=1, keepdims=True)
    cos = np.clip(np.sum(normal * to_camera, axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def _nyu14_from_centre(keypoints_cam: np.ndarray, is_left: np.ndarray) -> np.ndarray:
    """(N, 14, 3) nyu14 joints minus the palm centre, left hands mirrored, metres."""
    kp, left = _check(keypoints_cam, is_left)
    joints = to_format(kp, "nyu14")
    joints = joints - joints[:, FORMATS["nyu14"].index(_CENTRE)][:, None]
    joints[left, :, 0] *= -1.0
    return joints


def constant_pose_error_mm(keypoints_cam: np.ndarray, is_left: np.ndarray) -> float:
    """Mean error of the dataset's mean ``nyu14`` pose placed at each frame's palm centre, mm.

    See the module docstring for the definition (left hands mirrored; the palm centre's own
    zero error is in the mean over the 14 joints).

    Args:
        keypoints_cam: (N, 21, 3) keypoints, metres, camera frame (canonical order), N >= 1.
        is_left: (N,) bool, left hands.

    Raises:
        InvalidStatsInput: for wrong shapes, no frames or non-finite keypoints.
    """
    rel = _nyu14_from_centre(keypoints_cam, is_left)
    if len(rel) == 0:
        raise InvalidStatsInput("the constant-pose error needs at least one frame")
    return float(1000.0 * np.linalg.norm(rel - rel.mean(axis=0), axis=2).mean())


def mean_joint_distance_mm(keypoints_cam: np.ndarray, is_left: np.ndarray) -> float:
    """Mean distance of the ``nyu14`` joints from the palm centre, mm (the no-prior error)."""
    rel = _nyu14_from_centre(keypoints_cam, is_left)
    if len(rel) == 0:
        raise InvalidStatsInput("the mean joint distance needs at least one frame")
    return float(1000.0 * np.linalg.norm(rel, axis=2).mean())


def _mix(codes: np.ndarray, names: tuple[str, ...]) -> dict[str, float]:
    """Fraction of frames per name (``unknown`` for code -1), names with frames only."""
    out = {}
    for code, name in [(-1, "unknown"), *enumerate(names)]:
        count = int(np.sum(codes == code))
        if count:
            out[name] = round(count / len(codes), 4)
    return out


def _angles(angles_deg: np.ndarray) -> dict[str, Any]:
    facing = np.minimum(angles_deg, 180.0 - angles_deg)
    counts, _ = np.histogram(angles_deg, bins=PALM_ANGLE_BINS_DEG)
    return {
        "bins_deg": list(PALM_ANGLE_BINS_DEG),
        "counts": counts.tolist(),
        "palm_toward_camera": round(float(np.mean(angles_deg < 90.0)), 4),
        "facing_angle_quantiles_deg": {
            f"p{q}": round(float(np.percentile(facing, q)), 1) for q in (10, 50, 90, 99)
        },
        "facing_angle_max_deg": round(float(facing.max()), 1),
    }


def dataset_stats(folder: str | os.PathLike[str]) -> dict[str, Any]:
    """The hands and views of a dataset folder (JSON-able; every shard of its manifest).

    Returns:
        ``frames``; ``left_fraction``; ``pose_sources`` and ``viewpoints`` (fraction of frames
        per name, ``unknown`` for frames that do not say); ``palm_angle`` (histogram over
        :data:`PALM_ANGLE_BINS_DEG`, the fraction with the palm toward the camera, quantiles
        and maximum of the facing angle), also per viewpoint (``palm_angle_by_viewpoint``);
        ``contact_rate`` (fraction of frames with a hand-object contact); ``occlusion`` (a
        histogram of the hand occlusion ratio in tenths, frames where it was computed);
        ``constant_pose_error_mm`` (also per viewpoint, each view's frames with their own mean
        pose: ``constant_pose_error_mm_by_viewpoint``) and ``mean_joint_distance_mm`` on
        ``nyu14`` (module docstring).

    Raises:
        InvalidManifest: for a folder without a readable manifest.
        InvalidShard: for an unreadable shard (named).
    """
    from handsim.data.manifest import Manifest
    from handsim.data.shards import InvalidShard, ShardReader

    folder = Path(folder)
    manifest = Manifest.read(folder)
    keys = ("keypoints_cam", "is_left", "pose_source", "viewpoint", "contact_count")
    keys += ("hand_occlusion_ratio",)
    parts: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for record in sorted(manifest.shards.values(), key=lambda r: r.name):
        reader = ShardReader(folder / record.name)
        try:
            if len(reader) != record.frames:
                raise InvalidShard(
                    f"{folder / record.name} holds {len(reader)} frames but the manifest says "
                    f"{record.frames}: the folder was changed after it was made; run `handsim "
                    "dataset check` on it"
                )
            for key in keys:
                parts[key].append(reader.labels(key))
        finally:
            reader.close()
    if not parts["is_left"] or sum(len(p) for p in parts["is_left"]) == 0:
        return {"frames": 0}
    data = {k: np.concatenate(v) for k, v in parts.items()}
    kp, left = data["keypoints_cam"], data["is_left"]
    angles = palm_angles_deg(kp, left)
    by_view, error_by_view = {}, {}
    for code, name in enumerate(VIEWPOINT_CODES):
        chosen = data["viewpoint"] == code
        if chosen.any():
            by_view[name] = _angles(angles[chosen])
            error_by_view[name] = round(constant_pose_error_mm(kp[chosen], left[chosen]), 2)
    ratio = data["hand_occlusion_ratio"]
    computed = ratio[ratio >= 0.0]
    occlusion, _ = np.histogram(computed, bins=np.linspace(0.0, 1.0, 11))
    return {
        "frames": len(left),
        "left_fraction": round(float(left.mean()), 4),
        "pose_sources": _mix(data["pose_source"], POSE_SOURCE_CODES),
        "viewpoints": _mix(data["viewpoint"], VIEWPOINT_CODES),
        "palm_angle": _angles(angles),
        "palm_angle_by_viewpoint": by_view,
        "contact_rate": round(float(np.mean(data["contact_count"] > 0)), 4),
        "occlusion": {
            "bins": [round(float(b), 1) for b in np.linspace(0.0, 1.0, 11)],
            "counts": occlusion.tolist(),
            "frames": len(computed),
        },
        "constant_pose_error_mm": round(constant_pose_error_mm(kp, left), 2),
        "constant_pose_error_mm_by_viewpoint": error_by_view,
        "mean_joint_distance_mm": round(mean_joint_distance_mm(kp, left), 2),
    }
