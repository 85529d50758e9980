"""Frame labels as a flat dict of fixed-shape NumPy arrays, and back.

One schema serves env ``info``, dataset shards and exports: the same keys, shapes and dtypes at
reset, at every step and on a diverged step (then filled with :func:`empty_label_arrays` and
``valid = False``). Unused entries are filled, never NaN (so two equal frames give equal arrays
and Gymnasium's and Minari's checks can compare them): floats 0, integers -1, booleans False,
``hand_occlusion_ratio`` -1 when it was not computed. The only NaN is a pixel of a keypoint
behind the camera (``keypoints_px``; ``in_frame`` is False there). Shapes do not depend on how
many objects or contacts a frame has: objects are padded to :data:`MAX_OBJECTS` slots
(``object_valid`` marks the used ones) and contacts to :data:`MAX_CONTACTS` (``contact_count``
says how many are used; extra contacts are dropped, strongest normal force kept). Images
(depth, segmentation) are not labels: they are added only with ``images=True``.

===========================  ==========  =======  ======  ======================================
key                          shape       dtype    unit    meaning
===========================  ==========  =======  ======  ======================================
``valid``                    ()          bool             labels describe a rendered frame
``K``                        (3, 3)      float64  px      intrinsics (OpenCV)
``T_cam_from_world``         (4, 4)      float64  m       world to camera (OpenCV frame)
``keypoints_cam``            (21, 3)     float64  m       keypoints, camera frame
``keypoints_px``             (21, 2)     float64  px      ``(u, v)``; NaN behind the camera
``in_frame``                 (21,)       bool             in front of the camera and in the image
``visible``                  (21,)       bool             visibility (:mod:`handsim.frame`)
``visible_sensor``           (21,)       bool             visible, and the sensor's depth agrees
``occluder``                 (21,)       int32            -1 none, -2 self, -3 scene, k object k
``hand_pose``                (27,)       float64  m, rad  27-DoF pose, world frame
``hand_length_m``            ()          float64  m       wrist crease to middle fingertip
``is_left``                  ()          bool             left hand
``hand_occlusion_ratio``     ()          float64          hand without forearm; -1 if not computed
``object_valid``             (N,)        bool             slot holds an object
``object_ycbv_id``           (N,)        int16            YCB-Video id, -1 imported or empty
``object_T_cam_from_obj``    (N, 4, 4)   float64  m       object pose, camera frame
``object_corners_cam``       (N, 8, 3)   float64  m       box corners, camera frame
``object_visib_fract``       (N,)        float64          BOP visible fraction
``object_px_count_all``      (N,)        int32    px      whole silhouette of the object alone (BOP)
``object_px_count_visib``    (N,)        int32    px      pixels where the full render sees it
``contact_count``            ()          int16            used contact slots
``contact_hand_part``        (C,)        int8             segmentation label of the hand part
``contact_instance``         (C,)        int16            object instance
``contact_pos_cam``          (C, 3)      float64  m       contact position, camera frame
``contact_normal_force_n``   (C,)        float64  N       normal force
===========================  ==========  =======  ======  ======================================

``N`` = :data:`MAX_OBJECTS`, ``C`` = :data:`MAX_CONTACTS`. Object slot ``k`` is object instance
``k`` (segmentation label ``10 + k``). With ``images=True``: ``depth`` (H, W) float32 metres
(0 = no measurement), ``segmentation`` (H, W) int16 and, when the frame has it, ``depth_clean``.

Dataset shards add how each frame was drawn (:data:`DRAW_LABEL_SCHEMA`; not in env ``info``,
which has no such draw). A source that does not set them (rollouts), and shards written before
they existed, read -1:

===========================  ==========  =======  ======  ======================================
key                          shape       dtype    unit    meaning
===========================  ==========  =======  ======  ======================================
``pose_source``              ()          int8             index in :data:`POSE_SOURCE_CODES`
``viewpoint``                ()          int8             index in :data:`VIEWPOINT_CODES`
===========================  ==========  =======  ======  ======================================

Labels added after data was first written (:data:`ADDED_LABELS`) are filled when data that
predates them is read (:func:`fill_added_labels`): ``visible_sensor`` becomes a copy of
``visible``, which is what ``visible`` meant then (decided on the clean render only).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from handsim.errors import HandSimError
from handsim.hand.pose import HandPose

if TYPE_CHECKING:
    from handsim.frame import Frame

__all__ = [
    "MAX_OBJECTS",
    "MAX_CONTACTS",
    "LABEL_SCHEMA",
    "POSE_SOURCE_CODES",
    "VIEWPOINT_CODES",
    "DRAW_LABEL_SCHEMA",
    "InvalidLabelArrays",
    "frame_to_arrays",
    "arrays_to_frame",
    "empty_label_arrays",
    "check_label_arrays",
    "ADDED_LABELS",
    "fill_added_labels",
]

MAX_OBJECTS = 8
"""Object slots in the array form (GraspClutter-v0 places at most 6)."""
MAX_CONTACTS = 32
"""Contact slots in the array form."""

_N, _C = MAX_OBJECTS, MAX_CONTACTS

LABEL_SCHEMA: dict[str, tuple[tuple[int, ...], np.dtype, str]] = {
    "valid": ((), np.dtype(bool), ""),
    "K": ((3, 3), np.dtype(np.float64), "px"),
    "T_cam_from_world": ((4, 4), np.dtype(np.float64), "m"),
    "keypoints_cam": ((21, 3), np.dtype(np.float64), "m"),
    "keypoints_px": ((21, 2), np.dtype(np.float64), "px"),
    "in_frame": ((21,), np.dtype(bool), ""),
    "visible": ((21,), np.dtype(bool), ""),
    "visible_sensor": ((21,), np.dtype(bool), ""),
    "occluder": ((21,), np.dtype(np.int32), ""),
    "hand_pose": ((27,), np.dtype(np.float64), "m, rad"),
    "hand_length_m": ((), np.dtype(np.float64), "m"),
    "is_left": ((), np.dtype(bool), ""),
    "hand_occlusion_ratio": ((), np.dtype(np.float64), ""),
    "object_valid": ((_N,), np.dtype(bool), ""),
    "object_ycbv_id": ((_N,), np.dtype(np.int16), ""),
    "object_T_cam_from_obj": ((_N, 4, 4), np.dtype(np.float64), "m"),
    "object_corners_cam": ((_N, 8, 3), np.dtype(np.float64), "m"),
    "object_visib_fract": ((_N,), np.dtype(np.float64), ""),
    "object_px_count_all": ((_N,), np.dtype(np.int32), "px"),
    "object_px_count_visib": ((_N,), np.dtype(np.int32), "px"),
    "contact_count": ((), np.dtype(np.int16), ""),
    "contact_hand_part": ((_C,), np.dtype(np.int8), ""),
    "contact_instance": ((_C,), np.dtype(np.int16), ""),
    "contact_pos_cam": ((_C, 3), np.dtype(np.float64), "m"),
    "contact_normal_force_n": ((_C,), np.dtype(np.float64), "N"),
}
"""Label key -> (shape, dtype, unit) of the array form (table in the module docstring)."""


POSE_SOURCE_CODES = ("gesture", "grasp", "synergy", "uniform", "motion")
"""Pose source names by their code in the ``pose_source`` label (codes never change)."""
VIEWPOINT_CODES = ("third_person", "egocentric", "random", "through_object")
"""Viewpoint names by their code in the ``viewpoint`` label (codes never change)."""
DRAW_LABEL_SCHEMA: dict[str, tuple[tuple[int, ...], np.dtype, str]] = {
    "pose_source": ((), np.dtype(np.int8), ""),
    "viewpoint": ((), np.dtype(np.int8), ""),
}
"""Shard label key -> (shape, dtype, unit) of how a frame was drawn; -1 when unknown."""

ADDED_LABELS: dict[str, str] = {"visible_sensor": "visible"}
"""Labels added to the schema later -> the label whose values fill them in older data."""


def fill_added_labels(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Add, in place, the :data:`ADDED_LABELS` that ``arrays`` (older data) lacks; returns it.

    Works on one frame's arrays and on ``(N, ...)`` stacks alike.
    """
    for key, source in ADDED_LABELS.items():
        if key not in arrays and source in arrays:
            arrays[key] = np.array(arrays[source], dtype=LABEL_SCHEMA[key][1])
    return arrays


class InvalidLabelArrays(HandSimError, ValueError):
    """Label arrays do not follow :data:`LABEL_SCHEMA` (missing key, wrong shape or dtype)."""


def empty_label_arrays() -> dict[str, np.ndarray]:
    """Label arrays of no frame (``valid = False``): the fill of a diverged step.

    Floats are 0 (the pose and the transforms too: a zero matrix is no transform), booleans
    False, integers -1 except the counts (0), ``hand_occlusion_ratio`` -1. Readers check
    ``valid`` (and ``object_valid``, ``contact_count`` for the slots).
    """
    # Copies of one template: an env makes these every step.
    return {key: array.copy() for key, array in _EMPTY_LABEL_ARRAYS.items()}


def _make_empty_label_arrays() -> dict[str, np.ndarray]:
    out = {}
    for key, (shape, dtype, _) in LABEL_SCHEMA.items():
        if dtype.kind == "f":
            out[key] = np.zeros(shape, dtype)
        elif dtype.kind == "b":
            out[key] = np.zeros(shape, dtype)
        else:
            out[key] = np.full(shape, -1, dtype)
    out["contact_count"] = np.zeros((), np.int16)
    out["object_px_count_all"][:] = 0
    out["object_px_count_visib"][:] = 0
    out["hand_occlusion_ratio"][()] = -1.0
    return out


_EMPTY_LABEL_ARRAYS = _make_empty_label_arrays()


def frame_to_arrays(frame: Frame, *, images: bool = False) -> dict[str, np.ndarray]:
    """The flat array form of a Frame (:data:`LABEL_SCHEMA`; images on request).

    Args:
        frame: a rendered :class:`~handsim.frame.record.Frame`.
        images: also return ``depth``, ``segmentation`` and (if present) ``depth_clean``.

    Returns:
        New arrays (never views of the Frame's read-only arrays).

    Raises:
        InvalidLabelArrays: if the frame has more than :data:`MAX_OBJECTS` objects.
    """
    if len(frame.objects) > MAX_OBJECTS:
        raise InvalidLabelArrays(
            f"the array form holds at most MAX_OBJECTS={MAX_OBJECTS} objects; the frame has "
            f"{len(frame.objects)}"
        )
    out = empty_label_arrays()
    out["valid"][()] = True
    out["K"][:] = frame.K
    out["T_cam_from_world"][:] = frame.T_cam_from_world
    out["keypoints_cam"][:] = frame.keypoints_cam
    out["keypoints_px"][:] = frame.keypoints_px
    out["in_frame"][:] = frame.in_frame
    out["visible"][:] = frame.visible
    # A Frame read from older data has no sensor visibility: its visible is that meaning.
    out["visible_sensor"][:] = (
        frame.visible if frame.visible_sensor is None else frame.visible_sensor
    )
    out["occluder"][:] = frame.occluder
    out["hand_pose"][:] = frame.hand_pose.vector
    out["hand_length_m"][()] = frame.hand_length_m
    out["is_left"][()] = frame.handedness == "left"
    if frame.hand_occlusion_ratio is not None:
        out["hand_occlusion_ratio"][()] = frame.hand_occlusion_ratio
    for obj in frame.objects:
        k = obj.instance
        if not 0 <= k < MAX_OBJECTS:
            raise InvalidLabelArrays(
                f"object instance {k} does not fit the {MAX_OBJECTS} object slots"
            )
        out["object_valid"][k] = True
        out["object_ycbv_id"][k] = -1 if obj.ycbv_id is None else obj.ycbv_id
        out["object_T_cam_from_obj"][k] = obj.T_cam_from_obj
        out["object_corners_cam"][k] = obj.corners_cam
        out["object_visib_fract"][k] = obj.visib_fract
        out["object_px_count_all"][k] = obj.px_count_all
        out["object_px_count_visib"][k] = obj.px_count_visib
    contacts = frame.contacts
    if len(contacts) > MAX_CONTACTS:  # keep the strongest, in their order
        keep = np.argsort([-c.normal_force_n for c in contacts], kind="stable")[:MAX_CONTACTS]
        contacts = tuple(contacts[i] for i in sorted(keep))
    out["contact_count"][()] = len(contacts)
    for i, c in enumerate(contacts):
        out["contact_hand_part"][i] = c.hand_part
        out["contact_instance"][i] = c.instance
        out["contact_pos_cam"][i] = c.pos_cam
        out["contact_normal_force_n"][i] = c.normal_force_n
    if images:
        out["depth"] = np.array(frame.depth, dtype=np.float32)
        out["segmentation"] = np.array(frame.segmentation, dtype=np.int16)
        if frame.depth_clean is not None:
            out["depth_clean"] = np.array(frame.depth_clean, dtype=np.float32)
    return out


def check_label_arrays(arrays: Mapping[str, np.ndarray]) -> None:
    """Raise :class:`InvalidLabelArrays` unless ``arrays`` follows :data:`LABEL_SCHEMA`."""
    if not isinstance(arrays, Mapping):
        raise InvalidLabelArrays(
            f"label arrays must be a mapping of name -> array; received {type(arrays).__name__}"
        )
    missing = [k for k in LABEL_SCHEMA if k not in arrays]
    if missing:
        raise InvalidLabelArrays(f"label arrays lack {', '.join(missing)} (see LABEL_SCHEMA)")
    for key, (shape, dtype, _) in LABEL_SCHEMA.items():
        value = np.asarray(arrays[key])
        if value.shape != shape or value.dtype != dtype:
            raise InvalidLabelArrays(
                f"label {key!r} must be {dtype} of shape {shape}; received {value.dtype} of "
                f"shape {value.shape}"
            )


def arrays_to_frame(
    arrays: Mapping[str, np.ndarray],
    *,
    camera: str = "camera",
    object_names: Mapping[int, str] | None = None,
) -> Frame:
    """The Frame of an array form (inverse of :func:`frame_to_arrays`).

    The round trip is exact (the Frame's own dtypes). Strings are not part of the array form:
    the camera name is given, and object names come from ``object_names`` (instance -> name)
    or, for YCB-Video objects, from their id.

    Args:
        arrays: label arrays (:data:`LABEL_SCHEMA`), with ``depth`` and ``segmentation`` if the
            Frame's images are wanted (zero-size images otherwise).
        camera: the Frame's camera name.
        object_names: names of imported objects by instance.

    Raises:
        InvalidLabelArrays: if the arrays do not follow the schema or ``valid`` is False.
    """
    from handsim.frame.record import Contact, Frame, ObjectLabel, _read_only
    from handsim.world.registry import OBJECTS

    arrays = fill_added_labels(dict(arrays))
    check_label_arrays(arrays)
    if not bool(arrays["valid"]):
        raise InvalidLabelArrays("these label arrays are the fill of an invalid (diverged) step")
    names = {spec.ycbv_id: name for name, spec in OBJECTS.items()}
    objects = []
    for k in np.flatnonzero(arrays["object_valid"]):
        ycbv_id = int(arrays["object_ycbv_id"][k])
        name = (object_names or {}).get(int(k)) or names.get(ycbv_id, f"object_{k}")
        objects.append(
            ObjectLabel(
                instance=int(k),
                name=name,
                ycbv_id=None if ycbv_id < 0 else ycbv_id,
                T_cam_from_obj=_read_only(arrays["object_T_cam_from_obj"][k]),
                corners_cam=_read_only(arrays["object_corners_cam"][k]),
                visib_fract=float(arrays["object_visib_fract"][k]),
                px_count_all=int(arrays["object_px_count_all"][k]),
                px_count_visib=int(arrays["object_px_count_visib"][k]),
            )
        )
    contacts = tuple(
        Contact(
            hand_part=int(arrays["contact_hand_part"][i]),
            instance=int(arrays["contact_instance"][i]),
            pos_cam=_read_only(arrays["contact_pos_cam"][i]),
            normal_force_n=float(arrays["contact_normal_force_n"][i]),
        )
        for i in range(int(arrays["contact_count"]))
    )
    ratio = float(arrays["hand_occlusion_ratio"])
    empty = np.zeros((0, 0), np.float32)
    clean = arrays.get("depth_clean")
    return Frame(
        camera=camera,
        K=_read_only(arrays["K"]),
        T_cam_from_world=_read_only(arrays["T_cam_from_world"]),
        depth=_read_only(arrays.get("depth", empty)),
        depth_clean=None if clean is None else _read_only(clean),
        segmentation=_read_only(arrays.get("segmentation", empty.astype(np.int16))),
        keypoints_cam=_read_only(arrays["keypoints_cam"]),
        keypoints_px=_read_only(arrays["keypoints_px"]),
        in_frame=_read_only(arrays["in_frame"]),
        visible=_read_only(arrays["visible"]),
        visible_sensor=_read_only(arrays["visible_sensor"]),
        occluder=_read_only(arrays["occluder"]),
        hand_pose=HandPose.from_vector(np.asarray(arrays["hand_pose"])),
        hand_length_m=float(arrays["hand_length_m"]),
        handedness="left" if bool(arrays["is_left"]) else "right",
        objects=tuple(objects),
        hand_occlusion_ratio=None if not ratio >= 0 else ratio,  # -1 (or NaN: old shards)
        contacts=contacts,
    )
