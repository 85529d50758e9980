"""The side check of operator streams: a stream's ``hand`` must match its geometry.

A left hand's keypoints retargeted onto a right hand give a folded, wrong hand without any
error (the press expert's motion made by a left hand: 50.6 mm off per keypoint on a right
hand, 0.7 mm on a left one). The retargeter's side check
(:class:`~handsim.hand.retarget.Retargeter`, ``check_side``) fits the keypoints as they are and
mirrored and compares the two fits. A nearly flat open hand is almost its own mirror image, so
one frame is not decisive: :func:`check_side` votes over up to :data:`SIDE_CHECK_FRAMES` frames
in which all 21 keypoints are tracked and refuses the stream when most say the other side.
"""

from __future__ import annotations

import numpy as np

from handsim.envs.teleop.streams import InvalidStream
from handsim.errors import InvalidKeypoints
from handsim.hand.model import hand_params
from handsim.hand.retarget import Retargeter

__all__ = ["SIDE_CHECK_FRAMES", "check_side", "fully_tracked"]

SIDE_CHECK_FRAMES = 5
"""Frames the side check votes over."""


def fully_tracked(keypoints: np.ndarray) -> np.ndarray:
    """(T,) bool: the frames of (T, 21, 3) keypoints with all 21 points finite."""
    return np.all(np.isfinite(keypoints), axis=(-2, -1))


def check_side(keypoints: np.ndarray, side: str, source: str = "the stream") -> int:
    """Refuse keypoints of the other hand side.

    Args:
        keypoints: (T, 21, 3) frames, metres, any frame of reference; frames with an untracked
            point are skipped, and up to :data:`SIDE_CHECK_FRAMES` frames evenly spread over
            the others are checked.
        side: the side the stream claims, ``"right"`` or ``"left"``.
        source: the stream's name for the message.

    Returns:
        The number of frames checked (0 when no frame is fully tracked: nothing to check).

    Raises:
        InvalidStream: when most checked frames fit the other side better.
    """
    kp = np.asarray(keypoints, dtype=np.float64).reshape(-1, 21, 3)
    full = np.flatnonzero(fully_tracked(kp))
    if full.size == 0:
        return 0
    picks = full[np.unique(np.linspace(0, full.size - 1, SIDE_CHECK_FRAMES).round().astype(int))]
    retargeter = Retargeter(hand_params("medium", side))
    other: list[str] = []
    for i in picks:
        try:
            retargeter(kp[i], check_side=True, report_clamped=False)
        except InvalidKeypoints as err:
            if "look like a" not in str(err):
                raise
            other.append(str(err))
    if 2 * len(other) > len(picks):
        flip = "left" if side == "right" else "right"
        raise InvalidStream(
            f"{source} says hand={side!r}, but its keypoints are a {flip} hand in "
            f"{len(other)} of {len(picks)} frames checked ({other[0]}); set the stream's "
            f"'hand' to {flip!r} (files and packets), choose the {flip} hand (live: --hand "
            f"{flip}), or mirror the keypoints"
        )
    return int(len(picks))
