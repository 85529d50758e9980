"""Pictures of handsim's data: depth, segmentation, skeletons, estimates, contact sheets, videos.

Images are BGR ``uint8`` arrays (OpenCV's order), ready for ``cv2.imwrite``;
:class:`VideoWriter` converts to RGB for the MP4 encoder.

- :func:`depth_colormap`: depth in metres as a colour map, with a scale bar in metres;
- :func:`draw_segmentation`: segmentation labels in fixed colours (:data:`LABEL_BGR`);
- :func:`draw_skeleton`: the 21 keypoints and their bones (:data:`HAND_BONES`), with the
  keypoint styles of :data:`KEYPOINT_STYLES` (visible, hidden by an object, hidden by the hand);
- :func:`draw_estimate`: an estimate against the truth on the depth image (two skeletons);
- :func:`draw_frame_panels`: a Frame as depth | segmentation + skeleton, side by side;
- :func:`draw_frame`, :func:`contact_sheet`: the demo's pictures;
- :class:`VideoWriter`: MP4 files (needs the ``video`` extra: ``imageio``, ``imageio-ffmpeg``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from handsim.errors import HandSimError
from handsim.frame import OCCLUDER_NONE, OCCLUDER_SELF, Frame
from handsim.world.scene import OBJECT_LABEL_OFFSET, SEGMENT_LABELS

if TYPE_CHECKING:
    from handsim.estimator import Estimate

__all__ = [
    "LABEL_BGR",
    "HAND_BONES",
    "KEYPOINT_STYLES",
    "SCALE_BAR_WIDTH",
    "TRUTH_BGR",
    "ESTIMATE_BGR",
    "OUTLINE_BGR",
    "InvalidImageInput",
    "depth_colormap",
    "depth_range_m",
    "draw_segmentation",
    "project_points",
    "draw_skeleton",
    "draw_estimate",
    "draw_frame_panels",
    "draw_frame",
    "frame_legend",
    "contact_sheet",
    "VideoWriter",
]

LABEL_BGR = np.array(
    [
        (0, 0, 0), (90, 90, 90), (150, 130, 120), (50, 110, 170), (60, 180, 230),
        (40, 120, 255), (60, 220, 120),
        (230, 200, 60), (230, 120, 200), (160, 100, 240),
        (80, 80, 230), (230, 90, 70), (70, 200, 200), (200, 200, 70), (150, 230, 150),
    ],
    dtype=np.float64,
)  # fmt: skip
"""BGR colour per segmentation label: background, table, backdrop, forearm, palm, thumb..little,
then objects."""

_OBJECT_LABEL = OBJECT_LABEL_OFFSET

HAND_BONES: tuple[tuple[int, int], ...] = (
    (0, 1), (1, 2), (2, 3), (3, 4),
    (0, 5), (5, 6), (6, 7), (7, 8),
    (5, 9), (9, 10), (10, 11), (11, 12),
    (9, 13), (13, 14), (14, 15), (15, 16),
    (13, 17), (0, 17), (17, 18), (18, 19), (19, 20),
)  # fmt: skip
"""Pairs of keypoint indices drawn as bones: MediaPipe's ``HAND_CONNECTIONS`` (21 lines: the
five finger chains from the wrist and the palm's MCP row), in the canonical keypoint order."""

KEYPOINT_STYLES: dict[str, tuple[str, tuple[int, int, int]]] = {
    "visible": ("filled dot in the skeleton's colour", (255, 255, 255)),
    "object": ("tilted cross, red", (0, 0, 255)),
    "self": ("tilted cross, yellow", (0, 255, 255)),
}
"""How :func:`draw_skeleton` marks a keypoint: visible, hidden by an object (or the scene),
hidden by the hand itself; (description, BGR colour of the marker)."""

TRUTH_BGR: tuple[int, int, int] = (80, 220, 80)
"""Colour of the ground-truth skeleton in :func:`draw_estimate` (green)."""
ESTIMATE_BGR: tuple[int, int, int] = (255, 80, 255)
"""Colour of the estimated skeleton in :func:`draw_estimate` (magenta)."""

OUTLINE_BGR: tuple[int, int, int] = (0, 0, 0)
"""Border of skeletons drawn on a depth colour map (black: turbo has none of it in its range)."""
SCALE_BAR_WIDTH = 56
"""Width in pixels of the scale bar :func:`depth_colormap` appends on the right."""

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_MAX_PX = 1e5  # cv2 takes int coordinates; far-off points are clipped, lines still point there


class InvalidImageInput(HandSimError, ValueError):
    """An array given to a drawing function has the wrong shape or type."""


def _depth_array(depth_m: Any) -> np.ndarray:
    """(H, W) float32 metres from (H, W) or (1, H, W) float metres or uint16 millimetres."""
    depth = np.asarray(depth_m)
    if depth.ndim == 3 and depth.shape[0] == 1:
        depth = depth[0]
    if depth.ndim == 3 and depth.shape[-1] == 1:
        depth = depth[..., 0]
    if depth.ndim != 2 or depth.dtype.kind not in "fiu":
        raise InvalidImageInput(
            f"depth must be an (H, W) or (1, H, W) array of metres (float) or millimetres "
            f"(uint16); received shape {depth.shape}, dtype {depth.dtype}"
        )
    if depth.dtype == np.uint16:
        return depth.astype(np.float32) / np.float32(1000.0)
    depth = depth.astype(np.float32)
    return np.where(np.isfinite(depth), depth, np.float32(0.0))


def depth_range_m(depth_m: Any) -> tuple[float, float]:
    """The default colour-map range of a depth image: 1st and 99th percentile of valid pixels.

    Args:
        depth_m: depth as :func:`depth_colormap` takes it.

    Returns:
        ``(near_m, far_m)``, metres (``(0, 1)`` without valid pixels); pass them to
        :func:`depth_colormap` or :func:`draw_estimate` to keep the colours of a video steady.
    """
    return _depth_range(_depth_array(depth_m), None, None)


def _depth_range(depth: np.ndarray, near_m: float | None, far_m: float | None) -> tuple[float, ...]:
    if near_m is None or far_m is None:
        valid = depth[depth > 0]
        lo, hi = np.percentile(valid, [1, 99]) if valid.size else (0.0, 1.0)
        near_m = float(lo) if near_m is None else near_m
        far_m = float(hi) if far_m is None else far_m
    if not (np.isfinite(near_m) and np.isfinite(far_m)):
        raise InvalidImageInput(f"near_m and far_m must be finite; received {near_m}, {far_m}")
    if far_m <= near_m:
        far_m = near_m + 1e-3
    return float(near_m), float(far_m)


def depth_colormap(
    depth_m: Any,
    *,
    near_m: float | None = None,
    far_m: float | None = None,
    colormap: int = cv2.COLORMAP_TURBO,
    scale_bar: bool = True,
    upscale: int = 1,
) -> np.ndarray:
    """Depth as a colour map (near blue, far red); pixels without a measurement are black.

    Args:
        depth_m: (H, W) or (1, H, W) depth, float metres (``0`` = no measurement) or uint16
            millimetres.
        near_m: depth of the first colour, metres (default: 1st percentile of valid pixels).
        far_m: depth of the last colour, metres (default: 99th percentile).
        colormap: an OpenCV colour map (``cv2.COLORMAP_*``).
        scale_bar: append a :data:`SCALE_BAR_WIDTH`-pixel bar on the right with ticks in metres;
            image columns keep their pixel coordinates.
        upscale: integer magnification (nearest neighbour), e.g. 2 for videos of 320x240
            sensors; pixel ``(u, v)`` lands at ``(upscale * (u + 0.5) - 0.5, ...)``.

    Returns:
        (H * upscale, W * upscale, 3) uint8 BGR image, plus :data:`SCALE_BAR_WIDTH` columns
        with the scale bar.

    Raises:
        InvalidImageInput: for an array that is not a depth image or a bad ``upscale``.
    """
    depth = _depth_array(depth_m)
    if not isinstance(upscale, (int, np.integer)) or isinstance(upscale, bool) or upscale < 1:
        raise InvalidImageInput(f"upscale must be an integer >= 1; received {upscale!r}")
    near, far = _depth_range(depth, near_m, far_m)
    level = np.clip((depth - near) * np.float32(255 / (far - near)), 0.0, 255.0)
    image = cv2.applyColorMap(level.astype(np.uint8), colormap)
    image[depth <= 0] = 0
    if upscale > 1:
        height, width = depth.shape
        size = (width * upscale, height * upscale)
        image = cv2.resize(image, size, interpolation=cv2.INTER_NEAREST)
    if not scale_bar:
        return image
    height = image.shape[0]
    bar = np.zeros((height, SCALE_BAR_WIDTH, 3), np.uint8)
    top, bottom = 10, max(height - 10, 11)
    ramp = np.linspace(0, 255, bottom - top).astype(np.uint8)[:, None]
    bar[top:bottom, 4:16] = cv2.applyColorMap(ramp, colormap)[:, :1]
    scale = max(0.3, min(0.4, height / 600))
    for fraction in (0.0, 0.5, 1.0):
        y = int(round(top + fraction * (bottom - top - 1)))
        cv2.line(bar, (16, y), (20, y), (255, 255, 255), 1)
        label = f"{near + fraction * (far - near):.2f}"
        cv2.putText(bar, label, (21, y + 4), _FONT, scale, (255, 255, 255), 1, cv2.LINE_AA)
    cv2.putText(bar, "m", (21, bottom - 14), _FONT, scale, (200, 200, 200), 1, cv2.LINE_AA)
    return np.hstack([image, bar])


def draw_segmentation(segmentation: Any) -> np.ndarray:
    """Segmentation labels in the colours of :data:`LABEL_BGR` (objects cycle through theirs).

    Args:
        segmentation: (H, W) integer labels (``handsim.world.scene.SEGMENT_LABELS``, objects
            from ``OBJECT_LABEL_OFFSET``, 10).

    Returns:
        (H, W, 3) uint8 BGR image.

    Raises:
        InvalidImageInput: for an array that is not a label image.
    """
    labels = np.asarray(segmentation)
    if labels.ndim == 3 and labels.shape[0] == 1:
        labels = labels[0]
    if labels.ndim != 2 or labels.dtype.kind not in "iu":
        raise InvalidImageInput(
            f"segmentation must be an (H, W) integer array; received shape {labels.shape}, "
            f"dtype {labels.dtype}"
        )
    labels = labels.astype(np.int64)
    n_objects = len(LABEL_BGR) - _OBJECT_LABEL
    index = np.where(
        labels >= _OBJECT_LABEL, _OBJECT_LABEL + (labels - _OBJECT_LABEL) % n_objects, labels
    )
    return LABEL_BGR[np.clip(index, 0, len(LABEL_BGR) - 1)].astype(np.uint8)


def project_points(K: Any, points_cam: Any) -> np.ndarray:  # noqa: N803 (standard name)
    """Pinhole projection of camera-frame points (OpenCV frame, x right, y down, z forward).

    Args:
        K: (3, 3) intrinsic matrix.
        points_cam: (N, 3) points in the camera frame, metres.

    Returns:
        (N, 2) float64 pixels ``(u, v)``; NaN for points at or behind the camera.
    """
    K = np.asarray(K, dtype=np.float64)  # noqa: N806
    points = np.asarray(points_cam, dtype=np.float64)
    if K.shape != (3, 3) or points.ndim != 2 or points.shape[1] != 3:
        raise InvalidImageInput(
            f"project_points needs K (3, 3) and points (N, 3); received {K.shape}, {points.shape}"
        )
    z = points[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K[0, 0] * points[:, 0] / z + K[0, 2]
        v = K[1, 1] * points[:, 1] / z + K[1, 2]
    uv = np.stack([u, v], axis=1)
    uv[~(z > 0)] = np.nan
    return uv


def _pixel(point: np.ndarray) -> tuple[int, int]:
    u, v = np.clip(point, -_MAX_PX, _MAX_PX)
    return int(round(u)), int(round(v))


def draw_skeleton(
    image: np.ndarray,
    keypoints_px: Any,
    *,
    visible: Any = None,
    occluder: Any = None,
    colour: tuple[int, int, int] = (255, 255, 255),
    thickness: int = 1,
    radius: int = 3,
    outline: tuple[int, int, int] | None = None,
) -> np.ndarray:
    """Draw the 21 keypoints and their bones (:data:`HAND_BONES`) on a copy of ``image``.

    Without ``visible`` every keypoint is a filled dot in ``colour`` (an estimate). With it,
    visible keypoints are filled dots and hidden ones are tilted crosses, red when an object
    (or the scene) hides them and yellow when the hand hides itself (:data:`KEYPOINT_STYLES`).
    Keypoints with a non-finite pixel are skipped with their bones.

    Args:
        image: (H, W, 3) uint8 BGR image.
        keypoints_px: (21, 2) pixels ``(u, v)``.
        visible: (21,) bool per keypoint, or ``None``.
        occluder: (21,) int per keypoint (:data:`handsim.frame.record.OCCLUDER_SELF` for the hand,
            anything else but :data:`handsim.frame.record.OCCLUDER_NONE` for an object), or ``None``
            (hidden keypoints are then drawn as hidden by an object).
        colour: BGR colour of bones and visible keypoints.
        thickness: bone thickness, pixels.
        radius: keypoint dot radius, pixels.
        outline: BGR colour of a 1-pixel border around bones and dots (e.g. black), so the
            skeleton stays visible on a colour map that contains its own colour; ``None``: none.

    Returns:
        (H, W, 3) uint8 BGR image.

    Raises:
        InvalidImageInput: for a wrong image or keypoint shape.
    """
    image = np.asarray(image)
    points = np.asarray(keypoints_px, dtype=np.float64)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise InvalidImageInput(
            f"image must be (H, W, 3) uint8; received shape {image.shape}, dtype {image.dtype}"
        )
    if points.shape != (21, 2):
        raise InvalidImageInput(f"keypoints_px must be (21, 2); received {points.shape}")
    out = np.ascontiguousarray(image.copy())
    finite = np.all(np.isfinite(points), axis=1)
    if outline is not None:
        # The border first, two pixels wider, so the skeleton's own strokes lie on top of it.
        for a, b in HAND_BONES:
            if finite[a] and finite[b]:
                pa, pb = _pixel(points[a]), _pixel(points[b])
                cv2.line(out, pa, pb, outline, thickness + 2, cv2.LINE_AA)
        for k in np.flatnonzero(finite):
            cv2.circle(out, _pixel(points[k]), radius + 1, outline, -1, cv2.LINE_AA)
    for a, b in HAND_BONES:
        if finite[a] and finite[b]:
            cv2.line(out, _pixel(points[a]), _pixel(points[b]), colour, thickness, cv2.LINE_AA)
    for k in np.flatnonzero(finite):
        centre = _pixel(points[k])
        if visible is None or bool(np.asarray(visible)[k]):
            cv2.circle(out, centre, radius, colour, -1, cv2.LINE_AA)
            continue
        who = OCCLUDER_NONE if occluder is None else int(np.asarray(occluder)[k])
        style = "self" if who == OCCLUDER_SELF else "object"
        marker = KEYPOINT_STYLES[style][1]
        cv2.drawMarker(out, centre, marker, cv2.MARKER_TILTED_CROSS, 2 * radius + 3, 2)
    return out


def _caption(image: np.ndarray, lines: Sequence[str], colours: Sequence[tuple]) -> None:
    scale = 0.4 if image.shape[0] >= 200 else 0.3
    for i, (text, colour) in enumerate(zip(lines, colours, strict=True)):
        y = 14 + 14 * i
        cv2.putText(image, text, (5, y), _FONT, scale, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(image, text, (5, y), _FONT, scale, colour, 1, cv2.LINE_AA)


def draw_estimate(
    depth_m: Any,
    frame: Frame,
    estimate: Estimate | None,
    *,
    near_m: float | None = None,
    far_m: float | None = None,
    scale_bar: bool = True,
    title: str | None = None,
    upscale: int = 1,
) -> np.ndarray:
    """An estimate against the truth: both skeletons on the colour-mapped depth image.

    The truth (:data:`TRUTH_BGR`) is drawn with the visibility styles of
    :func:`draw_skeleton`; the estimate (:data:`ESTIMATE_BGR`) as plain dots and bones, or a
    ring at its hand centre for a localizer. Both have a black border: the turbo colour map
    has green and magenta-like hues of its own. A caption gives the mean keypoint error (mm).

    Args:
        depth_m: (H, W) or (1, H, W) depth of the frame's camera (the resolution of
            ``frame.K``), float metres or uint16 millimetres; e.g. an env's ``obs["depth"]``
            (an env's Frame is ``env.unwrapped.frame``).
        frame: the ground truth of the same view.
        estimate: an :class:`~handsim.estimator.Estimate` (camera frame), or ``None``.
        near_m: near end of the colour map, metres (default: from the image).
        far_m: far end of the colour map, metres.
        scale_bar: append the depth scale bar.
        title: first caption line (e.g. the estimator and its settings).
        upscale: integer magnification of the image (see :func:`depth_colormap`).

    Returns:
        (H * upscale, W * upscale, 3) uint8 BGR image, plus :data:`SCALE_BAR_WIDTH` columns
        with the scale bar.
    """
    image = depth_colormap(
        depth_m, near_m=near_m, far_m=far_m, scale_bar=scale_bar, upscale=upscale
    )

    def to_image(px: np.ndarray) -> np.ndarray:
        return upscale * (px + 0.5) - 0.5

    truth_px = to_image(np.where(frame.in_frame[:, None], frame.keypoints_px, np.nan))
    estimate_px = None
    if estimate is not None and estimate.valid and estimate.keypoints_cam is not None:
        estimate_px = to_image(project_points(frame.K, estimate.keypoints_cam))
        # The estimate's border goes under the truth, so it never hides a true keypoint.
        image = draw_skeleton(image, estimate_px, colour=OUTLINE_BGR, thickness=3, radius=4)
    image = draw_skeleton(
        image,
        truth_px,
        visible=frame.visible,
        occluder=frame.occluder,
        colour=TRUTH_BGR,
        outline=OUTLINE_BGR,
    )
    lines, colours = ([title], [(255, 255, 255)]) if title else ([], [])
    if estimate is None or not estimate.valid:
        lines.append("estimate: none")
        colours.append(ESTIMATE_BGR)
    elif estimate_px is not None:
        image = draw_skeleton(image, estimate_px, colour=ESTIMATE_BGR)
        error_mm = 1000 * np.linalg.norm(estimate.keypoints_cam - frame.keypoints_cam, axis=1)
        lines.append(f"estimate: mean {error_mm.mean():.1f} mm, max {error_mm.max():.1f} mm")
        colours.append(ESTIMATE_BGR)
    elif estimate.center_cam is not None:
        (centre,) = to_image(project_points(frame.K, estimate.center_cam[None]))
        if np.all(np.isfinite(centre)):
            cv2.circle(image, _pixel(centre), 8, OUTLINE_BGR, 4, cv2.LINE_AA)
            cv2.circle(image, _pixel(centre), 8, ESTIMATE_BGR, 2, cv2.LINE_AA)
        lines.append("estimate: hand centre")
        colours.append(ESTIMATE_BGR)
    lines.append("truth")
    colours.append(TRUTH_BGR)
    _caption(image, lines, colours)
    return image


def draw_frame_panels(
    frame: Frame, *, near_m: float | None = None, far_m: float | None = None
) -> np.ndarray:
    """A Frame as two panels: depth with its scale bar | segmentation with the skeleton.

    Args:
        frame: a rendered :class:`~handsim.frame.record.Frame` with its images.
        near_m: near end of the depth colour map, metres (default: from the image).
        far_m: far end of the depth colour map, metres.

    Returns:
        (H, 2 W + :data:`SCALE_BAR_WIDTH`, 3) uint8 BGR image.

    Raises:
        InvalidImageInput: for a frame without images (e.g. an ``EstimatorLoop``'s
            ``info["frame"]``).
    """
    if frame.depth is None or frame.segmentation is None:
        raise InvalidImageInput(
            "draw_frame_panels needs a Frame with depth and segmentation; received one without "
            "images (an env's info['frame'] has none: use draw_estimate with obs['depth'])"
        )
    depth = depth_colormap(frame.depth, near_m=near_m, far_m=far_m)
    labels = draw_segmentation(frame.segmentation)
    truth_px = np.where(frame.in_frame[:, None], frame.keypoints_px, np.nan)
    labels = draw_skeleton(labels, truth_px, visible=frame.visible, occluder=frame.occluder)
    return np.hstack([depth, labels])


def draw_frame(frame: Frame) -> np.ndarray:
    """A Frame as one picture: segmentation colours shaded by depth, keypoints by visibility.

    Visible keypoints are white dots; occluded ones are crosses, red when an object hides them
    and yellow when the hand hides itself. :func:`frame_legend` draws the key.

    Args:
        frame: a rendered :class:`~handsim.frame.record.Frame`.

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


_LEGEND_LABELS = tuple(
    (SEGMENT_LABELS.index(name), name)
    for name in ("arm", "palm", "thumb", "index", "middle", "ring", "little", "table")
) + ((_OBJECT_LABEL, "objects"),)


def frame_legend(width: int) -> np.ndarray:
    """The key of :func:`draw_frame` pictures, as a strip to put under them.

    Row 1: the keypoint marks (white dot: visible; red cross: hidden by an object or the
    scene; yellow cross: hidden by the hand). Row 2: the segmentation colours (hand parts,
    table, objects; darker = farther).

    Args:
        width: strip width, pixels (that of the picture it goes under).

    Returns:
        (44, width, 3) uint8 BGR image (less high below 560 pixels: shrunk to fit).

    Raises:
        InvalidImageInput: for a width < 1.
    """
    if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 1:
        raise InvalidImageInput(f"width must be an integer >= 1 pixel; received {width!r}")
    # Drawn at 560 pixels, padded to a wider picture or shrunk (text and all) to a narrower one.
    strip = np.full((44, 560, 3), 32, np.uint8)
    marks = (
        ("visible", None),
        ("hidden by an object", KEYPOINT_STYLES["object"][1]),
        ("hidden by the hand", KEYPOINT_STYLES["self"][1]),
    )
    x = 8
    for text, colour in marks:
        if colour is None:
            cv2.circle(strip, (x + 4, 12), 3, (255, 255, 255), -1, cv2.LINE_AA)
        else:
            cv2.drawMarker(strip, (x + 4, 12), colour, cv2.MARKER_TILTED_CROSS, 8, 2)
        cv2.putText(strip, text, (x + 14, 16), _FONT, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
        x += 34 + cv2.getTextSize(text, _FONT, 0.4, 1)[0][0]
    x = 8
    for label, text in _LEGEND_LABELS:
        colour = tuple(int(c) for c in LABEL_BGR[label])
        cv2.rectangle(strip, (x, 27), (x + 9, 36), colour, -1)
        cv2.putText(strip, text, (x + 13, 36), _FONT, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
        x += 28 + cv2.getTextSize(text, _FONT, 0.4, 1)[0][0]
    if width >= 560:
        return np.hstack([strip, np.full((44, int(width) - 560, 3), 32, np.uint8)])
    return cv2.resize(strip, (int(width), max(1, 44 * int(width) // 560)), cv2.INTER_AREA)


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


class VideoWriter:
    """Writes BGR images to an MP4 file (H.264 through ``imageio-ffmpeg``).

    Frames are padded with black on the right and bottom to multiples of 16 pixels (the
    encoder's macro blocks), so every frame is kept pixel for pixel. Every frame must have the
    size of the first. Use as a context manager, or call :meth:`close`.

    Args:
        path: output ``.mp4`` path (its folder is created).
        fps: frames per second.

    Raises:
        HandSimError: when ``imageio``/``imageio-ffmpeg`` are not installed (``pip install
            'handsim[video]'``), or for an ``fps`` that is not positive.
    """

    def __init__(self, path: str | Path, fps: float = 25.0) -> None:
        if not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
            raise InvalidImageInput(f"fps must be a positive number; received {fps!r}")
        try:
            import imageio.v2 as imageio
            import imageio_ffmpeg  # noqa: F401 (the encoder backend)
        except ImportError as err:
            raise HandSimError(
                f"writing MP4 needs imageio and imageio-ffmpeg ({err}); install them with "
                "pip install 'handsim[video]'"
            ) from None
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.n_frames = 0
        self._size: tuple[int, ...] | None = None
        self._writer = imageio.get_writer(
            str(self.path), fps=fps, codec="libx264", macro_block_size=16, quality=7
        )

    def append(self, image_bgr: np.ndarray) -> None:
        """Add one (H, W, 3) uint8 BGR frame."""
        image = np.asarray(image_bgr)
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise InvalidImageInput(
                f"video frames must be (H, W, 3) uint8; received {image.shape}, {image.dtype}"
            )
        if self._size is None:
            self._size = image.shape
        elif image.shape != self._size:
            raise InvalidImageInput(
                f"video frames must all have the first frame's shape {self._size}; received "
                f"{image.shape}"
            )
        h, w = image.shape[:2]
        padded = np.zeros((-(-h // 16) * 16, -(-w // 16) * 16, 3), np.uint8)
        padded[:h, :w] = image[..., ::-1]
        self._writer.append_data(padded)
        self.n_frames += 1

    def close(self) -> None:
        """Finish the file."""
        self._writer.close()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
