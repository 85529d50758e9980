"""Object silhouettes for BOP's ``visib_fract``: rendered alone, reused while an object is still.

The machinery behind the object labels of :class:`~handsim.frame.renderer.FrameRenderer`
(its module docstring states the rules): each object's silhouette as an image crop, the bound on
how far an object moved in the image that decides when a silhouette is reused, and the renders
of objects alone. :class:`FrameRenderer` inherits it from :class:`_ObjectSilhouettes`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import mujoco
import numpy as np

from handsim.world.scene import OBJECT_LABEL_OFFSET, SEGMENT_LABELS

__all__: list[str] = []

_KERNEL_3X3 = np.ones((3, 3), np.uint8)
_HIDDEN_GROUP = 5  # a geom group no camera renders
# A neighbouring hand/object surface up to this far behind an object still counts as a
# possible occluder (conservative: it only costs a silhouette render).
_OCCLUSION_MARGIN_M = 0.005
_PALM_LABEL = SEGMENT_LABELS.index("palm")


class _Mask(NamedTuple):
    """A binary mask stored as the crop ``pixels`` whose top-left pixel is ``(u0, v0)``."""

    u0: int
    v0: int
    pixels: np.ndarray

    def count(self) -> int:
        """Pixels in the mask."""
        return int(np.count_nonzero(self.pixels))

    def count_where(self, labels: np.ndarray, label: int) -> int:
        """Pixels of the mask where the (H, W) image ``labels`` equals ``label``.

        The mask may reach beyond the image (a border-cut object's whole silhouette); only
        its part inside the image can match.
        """
        h, w = self.pixels.shape
        v0, u0 = max(self.v0, 0), max(self.u0, 0)
        v1, u1 = min(self.v0 + h, labels.shape[0]), min(self.u0 + w, labels.shape[1])
        if v1 <= v0 or u1 <= u0:
            return 0
        crop = labels[v0:v1, u0:u1]
        pixels = self.pixels[v0 - self.v0 : v1 - self.v0, u0 - self.u0 : u1 - self.u0]
        return int(np.count_nonzero(pixels & (crop == label)))


def _pixel_box(
    lo: np.ndarray, hi: np.ndarray, width: int, height: int, margin: int, canvas: bool = False
) -> tuple[int, int, int, int]:
    """Pixel box ``(u0, v0, u1, v1)``, end exclusive, of the pixel centres in ``[lo, hi]``.

    ``lo`` and ``hi`` are (2,) pixel coordinates ``(u, v)`` (may be infinite); the box is widened
    by ``margin`` pixels and clipped to the image, or with ``canvas`` to BOP's canvas (the
    image and one image size beyond it on every side: ``[-W, 2W) x [-H, 2H)``).
    """
    # Four numbers: Python's math is several times cheaper than NumPy's calls here.
    box = []
    for value, size, end in zip(
        (*lo.tolist(), *hi.tolist()), (width, height) * 2, (False, False, True, True), strict=True
    ):
        first, last = (-size, 2 * size) if canvas else (0, size)
        value = min(max(value, first - 1 - margin), last + margin)  # finite (an inf is clipped)
        edge = math.ceil(value) + margin + 1 if end else math.floor(value) - margin
        box.append(min(max(edge, first), last))
    return box[0], box[1], box[2], box[3]


class _ObjectSilhouettes:
    """The object-silhouette part of :class:`~handsim.frame.renderer.FrameRenderer` (a base class).

    It uses the renderer's ``scene``, ``intrinsics``, ``renderer``, ``silhouette_tolerance_px``,
    ``_object_geoms``, ``_geom_instance``, ``_silhouette_masks`` and ``_silhouette_corners``,
    which :class:`~handsim.frame.renderer.FrameRenderer` sets up.
    """

    def _render_only(
        self,
        data: mujoco.MjData,
        visible_geoms: np.ndarray,
        region: tuple[int, int, int, int] | None = None,
    ) -> np.ndarray:
        """Geom-id image (of ``region``) with every geom hidden except ``visible_geoms``.

        ``region`` may reach beyond the image (:meth:`DepthRenderer.render_segmentation_canvas`);
        default: the image.
        """
        groups = self.scene.model.geom_group
        saved = groups.copy()
        hide = np.ones(len(groups), dtype=bool)
        hide[visible_geoms] = False
        groups[hide] = _HIDDEN_GROUP
        if region is None:
            region = (0, 0, self.intrinsics.width, self.intrinsics.height)
        try:
            return self.renderer.render_segmentation_canvas(data, region)
        finally:
            groups[:] = saved

    def _moved_px(self, before: np.ndarray, after: np.ndarray) -> np.ndarray | float:
        """Upper bound on how far any point of an object moved in the image, pixels.

        ``before`` and ``after`` are (..., 8, 3) box corners of objects in the camera frame (NaN
        rows give NaN). The motion between them is rigid, so a point's displacement is an
        affine function of its body-frame position and its length is largest at a corner: every
        point moved by at most ``D`` = the largest corner displacement. A point ``(x, y, z)``
        moved by ``(dx, dy, dz)`` moves in the image by ``fx * (dx - (x / z) dz) / z'`` along u
        (``z'``: its new depth), so by at most ``fx * D * (1 + |x / z|) / z'``; ``|x / z|`` (a
        ratio of affine functions) and ``z'`` take their extremes over the box at corners.
        An object partly behind the camera gets ``inf``.
        """
        before, after = np.asarray(before), np.asarray(after)
        moved_m = np.sqrt(np.max(np.sum((after - before) ** 2, axis=-1), axis=-1))
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.max(np.abs(before[..., :2] / before[..., 2:]), axis=-2)
            scale = np.maximum(
                self.intrinsics.fx * (1 + slope[..., 0]), self.intrinsics.fy * (1 + slope[..., 1])
            )
            bound = scale * moved_m / np.min(after[..., 2], axis=-1)
        behind = np.any(before[..., 2] <= 0.0, axis=-1) | np.any(after[..., 2] <= 0.0, axis=-1)
        bound = np.where(behind, np.inf, np.where(moved_m == 0.0, 0.0, bound))
        return float(bound) if bound.ndim == 0 else bound

    def _silhouettes(
        self,
        data: mujoco.MjData,
        labels: np.ndarray,
        depth_m: np.ndarray,
        corners_cam: np.ndarray,
        boxes: list[tuple[np.ndarray, np.ndarray]],
    ) -> list[_Mask]:
        """Silhouette mask of each object rendered alone (BOP's ``mask``), as image crops.

        A silhouette depends only on the object's pose relative to the camera. It is reused
        while no point of the object has moved by more than ``silhouette_tolerance_px`` in the
        image since it was made (:meth:`_moved_px`): a pixel of a rendered mask changes only
        when the silhouette's edge crosses its centre, so the reused mask differs from a fresh
        render only in pixels whose centres lie within the tolerance of the edge (the mask's
        boundary pixels). Objects resting under a moving hand, which still move by tens of
        micrometres a step, then cost no render. Otherwise, an object whose visible region
        nowhere borders a nearer hand or other object, nor the image's border, is not occluded
        or cut (its silhouette is connected, so a hidden part would border its occluder or
        cross the border): its silhouette is its visible region, with no render. The others
        are rendered alone; objects whose projected boxes do not overlap share one render, of
        their boxes' pixels only. A silhouette cut by the image's border is rendered whole on
        BOP's canvas (the image and one image size beyond it on every side); an object whose
        box misses the image altogether gets an empty silhouette (nothing of it is visible).
        """
        import cv2

        h, w = labels.shape
        masks: list[_Mask | None] = [None] * len(boxes)
        kernel = _KERNEL_3X3
        pending = []
        # NaN (no silhouette yet) compares False.
        kept = self._moved_px(self._silhouette_corners, corners_cam) <= self.silhouette_tolerance_px
        for k, (lo, hi) in enumerate(boxes):
            if kept[k]:
                masks[k] = self._silhouette_masks[k]
                continue
            # The box's pixels and a one-pixel ring around them (the object is inside the box).
            u0, v0, u1, v1 = _pixel_box(lo, hi, w, h, margin=1)
            if u1 <= u0 or v1 <= v0:
                masks[k] = _Mask(0, 0, np.zeros((0, 0), dtype=bool))
                continue
            crop_labels = labels[v0:v1, u0:u1]
            own = crop_labels == OBJECT_LABEL_OFFSET + k
            if not own.any():
                pending.append(k)  # fully hidden, or too small to see
                continue
            if (
                (u0 == 0 and own[:, 0].any())
                or (v0 == 0 and own[0].any())
                or (u1 == w and own[:, -1].any())
                or (v1 == h and own[-1].any())
            ):
                pending.append(k)  # cut by the border: the rest lies outside the image
                continue
            ring = cv2.dilate(own.view(np.uint8), kernel).view(bool) & ~own
            foreign = ring & (crop_labels >= _PALM_LABEL)
            if foreign.any():
                # Depth of the neighbouring object pixels at each ring pixel.
                crop_depth = depth_m[v0:v1, u0:u1]
                near = cv2.dilate(np.where(own, crop_depth, np.float32(0.0)), kernel)
                if np.any(crop_depth[foreign] < near[foreign] + _OCCLUSION_MARGIN_M):
                    pending.append(k)
                    continue
            masks[k] = _Mask(u0, v0, own)
        while pending:
            group, taken = [], []
            for k in pending:
                lo, hi = boxes[k]
                if all(np.any(hi < tlo) or np.any(lo > thi) for tlo, thi in taken):
                    group.append(k)
                    taken.append((lo, hi))
            # Read only the group's projected box (the corner boxes enclose the objects).
            lo = np.min([boxes[k][0] for k in group], axis=0)
            hi = np.max([boxes[k][1] for k in group], axis=0)
            u0, v0, u1, v1 = _pixel_box(lo, hi, w, h, margin=0, canvas=True)
            geom_ids = self._render_only(
                data, np.concatenate([self._object_geoms[k] for k in group]), (u0, v0, u1, v1)
            )
            seen = self._geom_instance[geom_ids]
            for k in group:
                ku0, kv0, ku1, kv1 = _pixel_box(*boxes[k], w, h, margin=0, canvas=True)
                ku0, kv0 = max(ku0, u0), max(kv0, v0)
                ku1, kv1 = max(min(ku1, u1), ku0), max(min(kv1, v1), kv0)
                masks[k] = _Mask(ku0, kv0, seen[kv0 - v0 : kv1 - v0, ku0 - u0 : ku1 - u0] == k)
            pending = [k for k in pending if k not in group]
        for k, mask in enumerate(masks):
            if not kept[k]:
                mask.pixels.setflags(write=False)
                self._silhouette_masks[k] = mask
                self._silhouette_corners[k] = corners_cam[k]
        return masks
