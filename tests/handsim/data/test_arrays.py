"""Tests of handsim.data.arrays: the flat array form of a Frame, its schema and its inverse."""

import numpy as np
import pytest

from handsim.data.arrays import (
    LABEL_SCHEMA,
    MAX_CONTACTS,
    MAX_OBJECTS,
    InvalidLabelArrays,
    arrays_to_frame,
    check_label_arrays,
    empty_label_arrays,
    frame_to_arrays,
)
from handsim.frame import Frame, FrameRenderer
from handsim.hand.pose_sources import gesture
from handsim.world.scene import ObjectPlacement, Scene, SceneSpec

OBJECTS = ("005_tomato_soup_can", "003_cracker_box", "024_bowl")


@pytest.fixture(scope="module")
def frames():
    """Two frames: the hand among three objects, and the hand pressed into the soup can."""
    placements = (
        ObjectPlacement(OBJECTS[0], (0.0, 0.0, 0.051)),
        ObjectPlacement(OBJECTS[1], (0.25, 0.1, 0.036)),
        ObjectPlacement(OBJECTS[2], (-0.22, 0.05, 0.03)),
    )
    scene = Scene(SceneSpec(objects=placements))
    rng = np.random.default_rng(0)
    out = []
    # Palm down over the can, low enough that the fingers touch it (contacts).
    for z in (0.25, 0.1):
        pose = gesture("open").replace(
            wrist_pos=np.array([0.0, -0.07, z]), wrist_rotvec=np.array([0.0, np.pi, 0.0])
        )
        scene.reset(pose)
        with FrameRenderer(scene, "third_person") as renderer:
            out.append(renderer.render(rng, hand_occlusion=True, keep_clean=True))
    return out


def test_arrays_follow_the_schema(frames):
    """Every key of the schema, with its shape and dtype, and nothing else without images."""
    for frame in frames:
        arrays = frame_to_arrays(frame)
        assert set(arrays) == set(LABEL_SCHEMA)
        check_label_arrays(arrays)
        assert arrays["valid"]
        assert arrays["object_valid"].sum() == len(frame.objects) == 3
        assert not arrays["object_valid"][3:].any()


def test_arrays_hold_the_frame_values(frames):
    """Slots hold the objects by instance; contacts keep their order and forces."""
    frame = frames[1]
    assert frame.contacts, "the hand pressed into the can must touch it"
    arrays = frame.to_arrays()
    for obj in frame.objects:
        np.testing.assert_array_equal(
            arrays["object_T_cam_from_obj"][obj.instance], obj.T_cam_from_obj
        )
        assert arrays["object_ycbv_id"][obj.instance] == obj.ycbv_id
    n = int(arrays["contact_count"])
    assert n == min(len(frame.contacts), MAX_CONTACTS)
    assert [int(p) for p in arrays["contact_hand_part"][:n]] == [
        c.hand_part for c in frame.contacts[:n]
    ]
    assert (arrays["contact_hand_part"][n:] == -1).all()
    np.testing.assert_array_equal(arrays["hand_pose"], frame.hand_pose.vector)
    assert arrays["hand_occlusion_ratio"] == frame.hand_occlusion_ratio


def test_round_trip_is_exact(frames):
    """Frame -> arrays (with images) -> Frame is equal, and so is arrays -> Frame -> arrays."""
    for frame in frames:
        arrays = frame.to_arrays(images=True)
        back = Frame.from_arrays(arrays, camera=frame.camera)
        assert back == frame
        again = back.to_arrays(images=True)
        assert set(again) == set(arrays)
        for key, value in arrays.items():
            np.testing.assert_array_equal(again[key], value, err_msg=key)


def test_arrays_are_copies(frames):
    """The arrays are writeable copies: changing them leaves the Frame alone."""
    frame = frames[0]
    arrays = frame.to_arrays(images=True)
    arrays["keypoints_cam"][:] = 0.0
    arrays["depth"][:] = 0.0
    assert frame.keypoints_cam.any() and frame.depth.any()


def test_empty_arrays_are_the_fill_of_an_invalid_step():
    """The diverged-step fill has the schema's structure, valid False and no fake measurement."""
    arrays = empty_label_arrays()
    check_label_arrays(arrays)
    assert not arrays["valid"]
    assert not any(np.isnan(v).any() for v in arrays.values() if v.dtype.kind == "f")
    assert not arrays["keypoints_cam"].any() and not arrays["T_cam_from_world"].any()
    assert arrays["hand_occlusion_ratio"] == -1.0
    assert not arrays["visible"].any() and not arrays["object_valid"].any()
    assert arrays["contact_count"] == 0
    with pytest.raises(InvalidLabelArrays, match="fill of an invalid"):
        arrays_to_frame(arrays)


def test_unused_slots_are_filled_not_nan(frames):
    """Only a keypoint behind the camera may give NaN; equal frames give equal arrays."""
    for frame in frames:
        arrays = frame.to_arrays()
        for key, value in arrays.items():
            if key != "keypoints_px" and value.dtype.kind == "f":
                assert not np.isnan(value).any(), key
        assert (
            np.isnan(arrays["keypoints_px"]).any(axis=1).tolist()
            == (frame.keypoints_cam[:, 2] <= 0).tolist()
        )
        if frame.hand_occlusion_ratio is None:
            assert arrays["hand_occlusion_ratio"] == -1.0


def test_schema_errors_say_what_is_wrong(frames):
    """Missing keys, wrong shapes and wrong dtypes are named."""
    arrays = frames[0].to_arrays()
    with pytest.raises(InvalidLabelArrays, match="must be a mapping"):
        check_label_arrays([1, 2])
    missing = dict(arrays)
    del missing["visible"]
    with pytest.raises(InvalidLabelArrays, match="lack visible"):
        arrays_to_frame(missing)
    wrong = dict(arrays, keypoints_cam=np.zeros((20, 3)))
    with pytest.raises(
        InvalidLabelArrays, match=r"'keypoints_cam' must be float64 of shape \(21, 3\)"
    ):
        check_label_arrays(wrong)
    wrong = dict(arrays, occluder=arrays["occluder"].astype(np.int64))
    with pytest.raises(InvalidLabelArrays, match="'occluder' must be int32"):
        check_label_arrays(wrong)


def test_more_objects_than_slots_are_refused(frames):
    """A frame with more objects than MAX_OBJECTS cannot be put in the fixed-shape form."""
    import dataclasses

    frame = frames[0]
    crowded = dataclasses.replace(frame, objects=frame.objects * 3)
    assert len(crowded.objects) > MAX_OBJECTS
    with pytest.raises(InvalidLabelArrays, match="at most MAX_OBJECTS=8"):
        frame_to_arrays(crowded)
