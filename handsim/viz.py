"""Pictures of handsim's data: frames with their labels, contact sheets.

Images are BGR ``uint8`` arrays (OpenCV's order), ready for ``cv2.imwrite``.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from handsim.frame import OCCLUDER_SELF, Frame

__all__ = ["LABEL_BGR", "draw_frame", "contact_sheet"]

LABEL_BGR = np.array(
    [
        (0, 0, 0), (90, 90, 90), (60, 180, 230), (40, 120, 255), (60, 220, 120),
        (230, 200, 60), (230, 120, 200), (160, 100, 240),
        (80, 80, 230), (230, 90, 70), (70, 200, 200), (200, 200, 70), (150, 230, 150),
    ],
    dtype=np.float64,
)  # fmt: skip
"""BGR colour per segmentation label: background, table, palm, thumb..little, then objects."""


def draw_frame(frame: Frame) -> np.ndarray:
    """A Frame as one picture: segmentation colours shaded by depth, keypoints by visibility.

    Visible keypoints are white dots; occluded ones are crosses, red when an object hides them
    and yellow when the hand hides itself.

    Args:
        frame: a rendered :class:`~handsim.frame.Frame`.

    Returns:
        (H, W, 3) uint8 BGR image.
    """
    labels = np.minimum(frame.segmentation, len(LABEL_BGR) - 1)
    depth = frame.depth
    valid = depth > 0
    near, far = np.percentile(depth[valid], [2, 98]) if valid.any() else (0.0, 1.0)
    shade = 1.0 - 0.6 * np.clip((depth - near) / max(far - near, 1e-6), 0.0, 1.0)
    tile = (LABEL_BGR[labels] * shade[..., None] * valid[..., None]).astype(np.uint8)
    for k in range(21):
        if not frame.in_frame[k]:
            continue
        u, v = (int(round(c)) for c in frame.keypoints_px[k])
        if frame.visible[k]:
            cv2.circle(tile, (u, v), 3, (255, 255, 255), -1)
        else:
            colour = (0, 255, 255) if frame.occluder[k] == OCCLUDER_SELF else (0, 0, 255)
            cv2.drawMarker(tile, (u, v), colour, cv2.MARKER_TILTED_CROSS, 8, 2)
    return tile


def contact_sheet(
    rows: Sequence[Sequence[np.ndarray]],
    row_labels: Sequence[str],
    tile_labels: Sequence[str],
) -> np.ndarray:
    """Tiles in a grid, each tile captioned and each row labelled at its bottom left.

    Args:
        rows: rows of (H, W, 3) uint8 RGB tiles, all of one size.
        row_labels: one label per row.
        tile_labels: one caption per column.

    Returns:
        (rows * H, columns * W, 3) uint8 BGR image.
    """
    out = []
    for label, tiles in zip(row_labels, rows, strict=True):
        captioned = []
        for name, frame in zip(tile_labels, tiles, strict=True):
            tile = cv2.cvtColor(frame, cv2.COLOR_RGB2BGR)
            cv2.putText(tile, name, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
            captioned.append(tile)
        row = np.hstack(captioned)
        cv2.putText(
            row, label, (6, row.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 255), 1
        )
        out.append(row)
    return np.vstack(out)
