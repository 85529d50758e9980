"""Two-hand scenes: SceneSpec(hands=...), unique names, labels, frames and both hands driven."""

import dataclasses

import mujoco
import numpy as np
import pytest

from handsim.envs.config import InvalidEnvConfig
from handsim.envs.physics import HandDriver
from handsim.frame import OCCLUDER_SELF, FrameRenderer
from handsim.hand.model import HandParams, hand_params
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import gesture
from handsim.world.camera import camera_preset
from handsim.world.scene import (
    HAND_PART_LABELS,
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    CameraSpec,
    InvalidScene,
    ObjectPlacement,
    Scene,
    SceneSpec,
)

RIGHT, LEFT = hand_params("medium", "right"), hand_params("small", "left")
ICVL = camera_preset("icvl")
CAM = CameraSpec.look_at("top", ICVL, (0.0, -0.35, 0.75), (0.0, 0.0, 0.1))
CAN = ObjectPlacement("005_tomato_soup_can", (0.0, 0.2, 0.0511))


def _palm_down(x: float, shape: str = "open") -> HandPose:
    return gesture(shape).replace(
        wrist_pos=np.array([x, -0.12, 0.15]), wrist_rotvec=np.array([0.0, np.pi, 0.0])
    )


@pytest.fixture(scope="module")
def two():
    """A right and a left hand over the table with a can, seen from above."""
    return Scene(SceneSpec(hands=(RIGHT, LEFT), objects=(CAN,), cameras=(CAM,)))


def test_spec_hands_sets_hand_and_keeps_the_one_hand_spec():
    """hands= makes hand the first of them; a one-hand spec is unchanged (hands None)."""
    spec = SceneSpec(hands=(RIGHT, LEFT))
    assert spec.hand == RIGHT and spec.hands == (RIGHT, LEFT)
    assert spec.all_hands == (RIGHT, LEFT)
    assert SceneSpec(hand=LEFT, hands=(LEFT, RIGHT)).hand == LEFT
    one = SceneSpec(hand=LEFT)
    assert one.hands is None and one.all_hands == (LEFT,)
    assert SceneSpec(hand=None).all_hands == ()
    assert SceneSpec() == SceneSpec(hand=HandParams())


@pytest.mark.parametrize(
    ("hands", "hand", "match"),
    [
        ((RIGHT, hand_params("large", "right")), None, r"different sides .* \['right', 'right'\]"),
        ((), None, r"hands must be a tuple of one or two HandParams"),
        ((RIGHT, LEFT, RIGHT), None, r"one or two HandParams .* received"),
        (("right", "left"), None, r"one or two HandParams"),
        ((RIGHT, LEFT), LEFT, r"disagrees with hands\[0\].* give the hands with hands= alone"),
    ],
)
def test_spec_refuses_bad_hands(hands, hand, match):
    """Wrong hands say what is valid."""
    kwargs = {} if hand is None else {"hand": hand}
    with pytest.raises(InvalidScene, match=match):
        SceneSpec(hands=hands, **kwargs)


def test_every_name_is_unique_and_each_hand_is_prefixed(two):
    """Bodies, joints, geoms, sites, actuators and welds of both hands: unique, side-prefixed."""
    model = two.model
    kinds = {
        "body": model.nbody,
        "joint": model.njnt,
        "geom": model.ngeom,
        "site": model.nsite,
        "actuator": model.nu,
        "equality": model.neq,
        "mesh": model.nmesh,
    }
    for kind, n in kinds.items():
        names = [getattr(model, kind)(i).name for i in range(n)]
        named = [x for x in names if x]
        assert len(named) == len(set(named)), kind
    assert model.nu == 2 * len(two.hand.actuator_names) and model.nmocap == 2
    for hand, prefix in zip(two.hands, ("rh_", "lh_"), strict=True):
        assert hand.prefix == prefix
        assert all(n.startswith(prefix) for n in hand.actuator_names)
    assert [b.hand.params for b in two.bindings] == [RIGHT, LEFT]
    assert two.hand_binding("left") is two.bindings[1] and two.binding is two.bindings[0]


def test_labels_by_name(two):
    """The first hand keeps the one-hand labels, the other hand's follow the objects."""
    n = OBJECT_LABEL_OFFSET + 1  # one object
    assert two.label_names[:OBJECT_LABEL_OFFSET] == SEGMENT_LABELS
    assert two.label_names[OBJECT_LABEL_OFFSET] == two.objects[0][0]
    assert two.label_names[n:] == tuple(f"left_{p}" for p in HAND_PART_LABELS)
    assert two.label("palm") == SEGMENT_LABELS.index("palm")
    assert two.label("left_palm") == n + 1
    model = two.model
    for binding, side in ((two.bindings[0], ""), (two.bindings[1], "left_")):
        # The palm body carries the palm and the upper arm (drawn, labelled arm).
        geoms = np.flatnonzero(model.geom_bodyid == binding.palm_id)
        want = {two.label(f"{side}palm"), two.label(f"{side}arm")}
        assert set(two.geom_labels[geoms].tolist()) == want
    forearm = model.geom("lh_forearm_visual_0").id
    assert two.geom_labels[forearm] in (two.label("left_palm"), two.label("left_arm"))
    upper = model.geom("lh_upper_arm_visual_0").id
    assert two.geom_labels[upper] == two.label("left_arm")
    with pytest.raises(InvalidScene, match=r"no segmentation label 'right_palm'.*left_palm"):
        two.label("right_palm")
    one = Scene(SceneSpec(hand=LEFT, cameras=(CAM,)))
    assert one.label_names == SEGMENT_LABELS and len(one.bindings) == 1
    with pytest.raises(InvalidScene, match=r"no 'right' hand; its hands: left .*hands="):
        one.hand_binding("right")


def test_each_hand_matches_a_one_hand_scene(two):
    """Each hand's keypoints and frame labels equal a one-hand scene's for the same pose."""
    right_pose, left_pose = _palm_down(0.13, "point"), _palm_down(-0.13, "fist")
    two.reset(right_pose, other_pose=left_pose)
    for params, pose in ((RIGHT, right_pose), (LEFT, left_pose)):
        one = Scene(SceneSpec(hand=params, objects=(CAN,), cameras=(CAM,)))
        one.reset(pose)
        binding = two.hand_binding(params.side)
        np.testing.assert_allclose(binding.keypoints(two.data), one.binding.keypoints(one.data))
        np.testing.assert_allclose(binding.points(two.data), one.binding.points(one.data))
        # In the hand's own frame too (wrist origin, hand axes).
        rot = two.data.xmat[binding.palm_id].reshape(3, 3)
        own = (binding.keypoints(two.data) - two.data.xpos[binding.palm_id]) @ rot
        one_rot = one.data.xmat[one.binding.palm_id].reshape(3, 3)
        ref = (one.binding.keypoints(one.data) - one.data.xpos[one.binding.palm_id]) @ one_rot
        np.testing.assert_allclose(own, ref, atol=1e-12)
    # The frame labels the first hand as a one-hand scene does, the other hand by its names.
    one = Scene(SceneSpec(hand=RIGHT, objects=(CAN,), cameras=(CAM,)))
    one.reset(right_pose)
    rng = np.random.default_rng(0)
    with FrameRenderer(two, "top") as r2, FrameRenderer(one, "top") as r1:
        f2, f1 = r2.render(rng), r1.render(np.random.default_rng(0))
    np.testing.assert_allclose(f2.keypoints_cam, f1.keypoints_cam, atol=1e-12)
    np.testing.assert_array_equal(f2.visible, f1.visible)
    np.testing.assert_array_equal(f2.occluder, f1.occluder)
    hand_labels = [two.label(p) for p in ("palm", *HAND_PART_LABELS[2:])]
    left_labels = [two.label(f"left_{p}") for p in HAND_PART_LABELS[1:]]
    seg2, seg1 = f2.segmentation, f1.segmentation
    right_px = np.isin(seg2, hand_labels)
    np.testing.assert_array_equal(right_px, np.isin(seg1, hand_labels))
    assert np.isin(seg2, left_labels).sum() > 500  # the left hand is in view, as itself
    assert not np.isin(seg1, left_labels).any()
    assert [o.instance for o in f2.objects] == [0]


def test_the_other_hand_occluding_is_self_occlusion():
    """The left hand between the camera and the right hand hides it as 'self', not an object."""
    cam = CameraSpec.look_at("down", ICVL, (0.0, 0.0, 0.7), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    scene = Scene(SceneSpec(hands=(RIGHT, LEFT), cameras=(cam,), table=False))
    right = gesture("open").replace(
        wrist_pos=np.array([0.0, -0.08, 0.1]), wrist_rotvec=np.array([0.0, np.pi, 0.0])
    )
    left = gesture("open").replace(
        wrist_pos=np.array([0.0, -0.1, 0.25]), wrist_rotvec=np.array([0.0, np.pi, 0.0])
    )
    scene.reset(right, other_pose=left)
    with FrameRenderer(scene, "down") as renderer:
        frame = renderer.render(np.random.default_rng(0), hand_occlusion=True)
    hidden = frame.in_frame & ~frame.visible
    assert hidden.sum() >= 10, frame.visible
    # Never an object instance (there is none): the other hand is the person's own.
    assert not np.any(frame.occluder >= 0)
    assert np.sum(frame.occluder[hidden] == OCCLUDER_SELF) >= 10
    assert len(frame.objects) == 0
    assert frame.hand_occlusion_ratio > 0.5


def test_both_hands_are_driven_by_one_driver(two):
    """One driver steps both hands, each toward its own target (and refuses a missing side)."""
    two.reset(_palm_down(0.13), other_pose=_palm_down(-0.13))
    driver = HandDriver(two)
    right_goal = _palm_down(0.15, "fist").replace(wrist_pos=np.array([0.15, -0.1, 0.2]))
    left_goal = _palm_down(-0.15, "point").replace(wrist_pos=np.array([-0.15, -0.14, 0.22]))
    driver.set_target(right_goal)
    driver.set_target(left_goal, side="left")
    assert driver.target is driver.target_of("right")
    for _ in range(75):  # 1.5 s
        assert not driver.step(10)
    for side, goal in (("right", right_goal), ("left", left_goal)):
        reached = two.hand_binding(side).pose(two.data)
        np.testing.assert_allclose(reached.wrist_pos, goal.wrist_pos, atol=0.01)
        assert np.abs(reached.angles - goal.clip().angles).max() < 0.15
    assert sum(w.number for w in two.data.warning) == 0
    with pytest.raises(InvalidEnvConfig, match=r"side='middle' is not a hand.*right, left"):
        driver.set_target(right_goal, side="middle")


def test_set_hand_length_keeps_the_spec_consistent(two):
    """Rescaling the first hand of a two-hand scene updates hand and hands[0] alike."""
    scene = Scene(SceneSpec(hands=(RIGHT, LEFT), cameras=(CAM,)))
    scene.set_hand_length(0.2)
    assert scene.spec.hand == scene.spec.hands[0] == scene.hand.params
    assert scene.spec.hands[1] == LEFT and scene.hands[0] is scene.hand
    assert dataclasses.replace(scene.spec).hand.hand_length == 0.2
    mujoco.mj_forward(scene.model, scene.data)
