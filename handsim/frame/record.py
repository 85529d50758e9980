"""The Frame record: one rendered view with all its labels, shared by envs, datasets and metrics.

:class:`~handsim.frame.renderer.FrameRenderer` makes Frames; its module docstring gives the
rules the labels follow (visibility, occluders, object visibility, occlusion ratio, contacts).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.hand.pose import HandPose

__all__ = [
    "Frame",
    "ObjectLabel",
    "Contact",
    "OCCLUDER_NONE",
    "OCCLUDER_SELF",
    "OCCLUDER_SCENE",
]

OCCLUDER_NONE = -1
"""Nothing in front of the keypoint: it is visible, outside the image or out of range."""
OCCLUDER_SELF = -2
"""Hidden by the hand itself."""
OCCLUDER_SCENE = -3
"""Hidden by the table or other scene geometry."""


@dataclasses.dataclass(frozen=True)
class ObjectLabel:
    """Pose and visibility of one object instance in a frame.

    Attributes:
        instance: index in the scene's object list (segmentation label ``10 + instance``).
        name: object name, e.g. ``"005_tomato_soup_can"``.
        ycbv_id: YCB-Video object id (``None`` for imported meshes).
        T_cam_from_obj: (4, 4) object pose in the OpenCV camera frame, metres.
        corners_cam: (8, 3) bounding-box corners in the camera frame, metres.
        visib_fract: visible fraction of the object's silhouette (BOP), 0 when out of view.
        px_count_all: silhouette pixels of the object alone, on BOP's canvas (the image and
            one image size beyond it on every side).
        px_count_visib: pixels where the full render sees the object.
    """

    instance: int
    name: str
    ycbv_id: int | None
    T_cam_from_obj: np.ndarray  # noqa: N815 (the design's name)
    corners_cam: np.ndarray
    visib_fract: float
    px_count_all: int
    px_count_visib: int


@dataclasses.dataclass(frozen=True)
class Contact:
    """A contact between the hand and an object.

    Attributes:
        hand_part: segmentation label of the hand part (4 palm ... 9 little).
        instance: object instance index.
        pos_cam: (3,) contact position in the camera frame, metres.
        normal_force_n: normal force, newtons.
    """

    hand_part: int
    instance: int
    pos_cam: np.ndarray
    normal_force_n: float


@dataclasses.dataclass(frozen=True)
class Frame:
    """One labelled view (docs/architecture.md, "Data flow"); arrays are read-only copies.

    Attributes:
        camera: camera name.
        K: (3, 3) intrinsic matrix.
        T_cam_from_world: (4, 4) world-to-camera transform (OpenCV frame).
        depth: (H, W) float32 sensor depth, metres, 0 = no measurement.
        depth_clean: (H, W) float32 noise-free depth within the camera's range, metres, 0 =
            nothing seen (``None`` unless requested).
        segmentation: (H, W) int16 labels (:data:`~handsim.world.scene.SEGMENT_LABELS`,
            objects from 10).
        keypoints_cam: (21, 3) keypoints in the camera frame, metres.
        keypoints_px: (21, 2) keypoint pixels ``(u, v)``; NaN for keypoints behind the camera
            (``z <= 0``).
        in_frame: (21,) bool, in front of the camera and inside the image.
        visible: (21,) bool (rule in :mod:`~handsim.frame.renderer`).
        visible_sensor: (21,) bool, visible and seen by the sensor
            (:mod:`~handsim.frame.renderer`); ``None`` in a Frame read from labels that lack it
            (data written before it existed).
        occluder: (21,) int, :data:`OCCLUDER_NONE`, :data:`OCCLUDER_SELF`,
            :data:`OCCLUDER_SCENE` or an object instance index.
        hand_pose: the 27-DoF pose (world frame).
        hand_length_m: hand length, metres.
        handedness: ``"right"`` or ``"left"``.
        objects: per object instance.
        hand_occlusion_ratio: 1 - visible hand pixels / hand pixels without objects, forearm
            left out (:mod:`~handsim.frame.renderer`; ``None`` unless requested).
        contacts: hand-object contacts.
    """

    camera: str
    K: np.ndarray  # noqa: N815
    T_cam_from_world: np.ndarray  # noqa: N815
    depth: np.ndarray
    depth_clean: np.ndarray | None
    segmentation: np.ndarray
    keypoints_cam: np.ndarray
    keypoints_px: np.ndarray
    in_frame: np.ndarray
    visible: np.ndarray
    occluder: np.ndarray
    hand_pose: HandPose
    hand_length_m: float
    handedness: str
    objects: tuple[ObjectLabel, ...]
    hand_occlusion_ratio: float | None
    contacts: tuple[Contact, ...]
    visible_sensor: np.ndarray | None = None

    @property
    def keypoint_names(self) -> tuple[str, ...]:
        """Names of the 21 keypoints, in order."""
        return KEYPOINT_NAMES

    def to_arrays(self, *, images: bool = False) -> dict[str, np.ndarray]:
        """The flat array form of the labels (:data:`handsim.data.arrays.LABEL_SCHEMA`).

        Args:
            images: also include ``depth``, ``segmentation`` and ``depth_clean`` (if present).
        """
        from handsim.data.arrays import frame_to_arrays

        return frame_to_arrays(self, images=images)

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], *, camera: str = "camera") -> Frame:
        """The Frame of an array form (inverse of :meth:`to_arrays`; camera name given)."""
        from handsim.data.arrays import arrays_to_frame

        return arrays_to_frame(arrays, camera=camera)


def _equal(a: object, b: object) -> bool:
    """Exact equality of label values: arrays bitwise (NaN equals NaN), records field-wise."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return (
            a.shape == b.shape
            and a.dtype == b.dtype
            and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
        )
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b)


def _records_equal(self: object, other: object) -> bool:
    if type(other) is not type(self):
        return NotImplemented
    return all(
        _equal(getattr(self, f.name), getattr(other, f.name)) for f in dataclasses.fields(self)
    )


# The generated dataclass __eq__ cannot compare array fields (it would raise).
ObjectLabel.__eq__ = _records_equal  # type: ignore[method-assign]
Contact.__eq__ = _records_equal  # type: ignore[method-assign]
Frame.__eq__ = _records_equal  # type: ignore[method-assign]


def _read_only(array: np.ndarray) -> np.ndarray:
    array = np.array(array)
    array.setflags(write=False)
    return array


def _owned_read_only(array: np.ndarray) -> np.ndarray:
    """``array`` itself, made read-only: for arrays made for one Frame and shared with nothing."""
    array.setflags(write=False)
    return array
