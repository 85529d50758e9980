"""The Frame: keypoint visibility and occluders, object labels, occlusion ratio, contacts."""

import numpy as np
import pytest
import trimesh

from handsim.frame import OCCLUDER_NONE, OCCLUDER_SELF, FrameRenderer
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.hand.pose_sources import gesture
from handsim.world.camera import CameraIntrinsics, camera_preset
from handsim.world.mesh_import import load_object
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    CameraSpec,
    InvalidScene,
    ObjectPlacement,
    Scene,
    SceneSpec,
)

ICVL = camera_preset("icvl")
PANEL_HALF_M = np.array([0.05, 0.01, 0.12])  # an axis-aligned panel: 10 x 2 x 24 cm


@pytest.fixture(scope="module")
def panel(tmp_path_factory):
    """An imported box mesh with known, axis-aligned faces."""
    path = tmp_path_factory.mktemp("panel") / "panel.stl"
    trimesh.creation.box(extents=2 * PANEL_HALF_M).export(path)
    return load_object(path, name="panel", mass_kg=0.2, decomposition="convex_hull")


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    """A 3 cm cube mesh."""
    path = tmp_path_factory.mktemp("cube") / "cube.stl"
    trimesh.creation.box(extents=(0.03, 0.03, 0.03)).export(path)
    return load_object(path, name="cube", mass_kg=0.05, decomposition="convex_hull")


TIPS = [KEYPOINT_NAMES.index(f"{f}_tip") for f in ("index", "middle", "ring", "little")]
STANDING = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0)  # object y axis -> world z


def _flat_hand_facing(camera_y: float):
    """A flat right hand at (0, 0.5, 0.2), fingers up (+z), palm toward -y."""
    # Hand x (radial) -> world +x, y (distal) -> +z, z (palmar) -> -y.
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_matrix(np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T)
    return gesture("open").replace(
        wrist_pos=np.array([0.0, 0.5, 0.1]), wrist_rotvec=rot.as_rotvec()
    )


def test_flat_hand_facing_the_camera_is_fully_visible():
    """Every keypoint of a flat hand seen from the palm side is in frame and visible."""
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(_flat_hand_facing(0.0))
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0))
    assert frame.in_frame.all()
    assert frame.visible.all(), [KEYPOINT_NAMES[k] for k in np.nonzero(~frame.visible)[0]]
    assert np.all(frame.occluder == OCCLUDER_NONE)
    np.testing.assert_allclose(frame.keypoints_px, ICVL.project(frame.keypoints_cam))


def test_box_between_camera_and_fingertip_occludes_it(cube):
    """A box on the ray to the index tip hides it, with the box as occluder."""
    eye = np.array([0.0, 0.0, 0.19])
    cam = CameraSpec.look_at("front", ICVL, tuple(eye), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(_flat_hand_facing(0.0))
    tip = scene.binding.keypoints(scene.data)[KEYPOINT_NAMES.index("index_tip")]
    # A 3 cm cube on the ray from the camera to the tip, 5 cm in front of the tip.
    ray = (tip - eye) / np.linalg.norm(tip - eye)
    box_pos = tip - 0.05 * ray
    spec = SceneSpec(
        cameras=(cam,),
        table=False,
        objects=(ObjectPlacement("cube", tuple(box_pos), mesh=cube),),
    )
    scene = Scene(spec)
    scene.reset(_flat_hand_facing(0.0))
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0), hand_occlusion=True)
    k = KEYPOINT_NAMES.index("index_tip")
    assert frame.in_frame[k] and not frame.visible[k]
    assert frame.occluder[k] == 0  # object instance 0
    wrist = KEYPOINT_NAMES.index("wrist")
    assert frame.visible[wrist] and frame.occluder[wrist] == OCCLUDER_NONE
    assert 0.0 < frame.hand_occlusion_ratio < 1.0


def test_fist_seen_from_the_back_hides_its_fingertips():
    """Fingertips curled into the palm are self-occluded when the back of the hand faces us."""
    from scipy.spatial.transform import Rotation

    # Palm toward +y (away from the camera at y = 0), fingers up.
    rot = Rotation.from_matrix(np.array([[-1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]]).T)
    pose = gesture("fist").replace(
        wrist_pos=np.array([0.0, 0.5, 0.1]), wrist_rotvec=rot.as_rotvec()
    )
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.17), (0.0, 0.5, 0.17))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(pose)
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0))
    assert frame.in_frame[TIPS].all()
    assert not frame.visible[TIPS].any()
    assert np.all(frame.occluder[TIPS] == OCCLUDER_SELF)


def test_half_covered_object_has_visib_fract_one_half(panel):
    """A panel whose edge lies in the plane of the camera and a can's axis hides half of it."""
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.05), (0.0, 1.0, 0.05))
    objects = (
        # The can's axis is its y axis: stand it up.
        ObjectPlacement("005_tomato_soup_can", (0.0, 0.6, 0.05), STANDING),
        # The panel's +x face at x = 0, 0.3 m from the camera, tall enough to cover the can.
        ObjectPlacement("panel", (-PANEL_HALF_M[0], 0.3, 0.05), mesh=panel),
    )
    scene = Scene(SceneSpec(cameras=(cam,), objects=objects, table=False))
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0))
    can, box = frame.objects
    assert can.name == "005_tomato_soup_can"
    assert can.visib_fract == pytest.approx(0.5, abs=0.02)
    assert box.visib_fract == pytest.approx(1.0)
    # Pose and corners in the camera frame: the can is 0.6 m ahead on the optical axis.
    np.testing.assert_allclose(can.T_cam_from_obj[:3, 3], [0.0, 0.0, 0.6], atol=1e-3)
    np.testing.assert_allclose(can.corners_cam.mean(axis=0), can.T_cam_from_obj[:3, 3], atol=1e-3)


def test_contacts_between_hand_and_object(panel):
    """A fingertip pressed into an object yields a contact labelled with its digit and a force."""
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    base = Scene(SceneSpec(cameras=(cam,), table=False))
    base.reset(_flat_hand_facing(0.0))
    tip = base.binding.keypoints(base.data)[KEYPOINT_NAMES.index("middle_tip")]
    # The panel's bottom face 2 mm below the middle fingertip.
    box_pos = tip + np.array([0.0, 0.0, PANEL_HALF_M[2] - 0.002])
    scene = Scene(
        SceneSpec(
            cameras=(cam,),
            table=False,
            objects=(ObjectPlacement("panel", tuple(box_pos), mesh=panel),),
        )
    )
    scene.reset(_flat_hand_facing(0.0))
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0))
    parts = {c.hand_part for c in frame.contacts}
    assert SEGMENT_LABELS.index("middle") in parts
    assert all(c.instance == 0 for c in frame.contacts)
    assert max(c.normal_force_n for c in frame.contacts) > 0


def test_frame_is_read_only_and_seeded():
    """Frame arrays cannot be written; the same seed gives the same noisy depth."""
    from handsim.world.sensors import StructuredLight

    cam = CameraSpec.look_at("front", ICVL, (0.0, -0.2, 0.4), (0.0, 0.0, 0.1))
    scene = Scene(SceneSpec(cameras=(cam,)))
    with FrameRenderer(scene, "front", StructuredLight()) as renderer:
        a = renderer.render(np.random.default_rng(1), keep_clean=True)
        b = renderer.render(np.random.default_rng(1))
    np.testing.assert_array_equal(a.depth, b.depth)
    assert b.depth_clean is None and a.depth_clean is not None
    with pytest.raises(ValueError, match="read-only"):
        a.depth[0, 0] = 1.0
    assert a.handedness == "right" and a.hand_length_m == pytest.approx(0.189)


def test_silhouette_shortcut_matches_rendering_each_object_alone():
    """Skipping the silhouette render for unoccluded objects gives BOP's exact counts."""
    from handsim.world.scene import sample_placements, sample_viewpoint

    rng = np.random.default_rng(11)
    placements = sample_placements(rng, ("005_tomato_soup_can", "003_cracker_box", "025_mug"))
    for _ in range(4):
        cam = sample_viewpoint(rng, ICVL, name="view")
        scene = Scene(SceneSpec(objects=placements, cameras=(cam,)))
        with FrameRenderer(scene, "view") as renderer:
            frame = renderer.render(rng)
            canvas = (-ICVL.width, -ICVL.height, 2 * ICVL.width, 2 * ICVL.height)
            for label in frame.objects:
                # BOP counts the whole silhouette, on a canvas 3 times the image's size.
                alone = renderer._render_only(
                    scene.data, renderer._object_geoms[label.instance], canvas
                )
                seen = scene.geom_labels[np.maximum(alone, 0)]
                expected = int(
                    np.count_nonzero((alone >= 0) & (seen == OBJECT_LABEL_OFFSET + label.instance))
                )
                assert label.px_count_all == expected


def test_reused_silhouettes_equal_fresh_renders():
    """Silhouettes kept while objects rest give the counts a fresh renderer computes."""
    from handsim.hand.pose_sources import GESTURES
    from handsim.world.scene import sample_placements, third_person_camera

    rng = np.random.default_rng(5)
    placements = sample_placements(rng, ("005_tomato_soup_can", "003_cracker_box", "025_mug"))
    scene = Scene(SceneSpec(objects=placements, cameras=(third_person_camera(ICVL),)))
    counts = []
    with FrameRenderer(scene, "third_person") as reused:
        for i, name in enumerate(list(GESTURES)[:6]):
            # The hand sweeps over the objects; the last step also moves an object.
            if i == 5:
                scene.data.qpos[scene.model.body(scene.objects[0][0]).jntadr[0]] += 0.03
            scene.binding.set_pose(
                scene.data,
                gesture(name).replace(
                    wrist_pos=np.array([-0.12 + 0.05 * i, 0.0, 0.1]),
                    wrist_rotvec=np.array([0.0, np.pi, 0.0]),
                ),
            )
            kept = reused.render(rng)
            with FrameRenderer(scene, "third_person") as fresh:
                new = fresh.render(rng)
            counts.append([(o.px_count_all, o.px_count_visib) for o in kept.objects])
            assert counts[-1] == [(o.px_count_all, o.px_count_visib) for o in new.objects]
    # The sweep did occlude something (else the test would prove nothing).
    assert any(all_px > visib for row in counts for all_px, visib in row)


# Labels that cannot lie: the camera's working range and visibility evidence.


def test_far_object_is_not_seen_and_the_hand_stays_labelled():
    """An object 1 km (or 50 m) away changes nothing the camera sees of the hand.

    Clip planes come from the camera's working range, not from the model's extent.
    """
    with FrameRenderer(Scene(SceneSpec()), "third_person") as renderer:
        reference = renderer.render(np.random.default_rng(0))
    assert reference.visible.any() and reference.depth.any()
    for distance_m in (1e3, 50.0):
        spec = SceneSpec(objects=(ObjectPlacement("mustard_bottle", (distance_m, 0.0, 0.1)),))
        with FrameRenderer(Scene(spec), "third_person") as renderer:
            frame = renderer.render(np.random.default_rng(0))
        np.testing.assert_array_equal(frame.visible, reference.visible)
        np.testing.assert_array_equal(frame.segmentation, reference.segmentation)
        np.testing.assert_allclose(frame.depth, reference.depth, atol=1e-4)
        assert frame.objects[0].px_count_all == 0 and frame.objects[0].visib_fract == 0.0


def _range_camera(near_m: float, far_m: float) -> CameraSpec:
    intrinsics = CameraIntrinsics(320, 240, 241.42, 241.42, 160.0, 120.0, "r", (near_m, far_m))
    return CameraSpec.look_at("front", intrinsics, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))


@pytest.mark.parametrize(
    ("near_m", "far_m", "other_camera"), [(0.1, 0.4, False), (0.6, 2.0, False), (0.1, 0.4, True)]
)
def test_hand_out_of_range_has_no_depth_and_no_visible_keypoint(near_m, far_m, other_camera):
    """A hand 0.5 m away, beyond the far end or inside the near end: nothing is visible.

    A pixel without depth is never evidence of visibility. A second camera with a longer range
    (which sets the scene's far clip plane) changes nothing.
    """
    cameras = (_range_camera(near_m, far_m),)
    if other_camera:
        cameras += (CameraSpec.look_at("far", ICVL, (0.0, 0.0, 0.5), (0.0, 0.5, 0.19)),)
    scene = Scene(SceneSpec(cameras=cameras, table=False))
    scene.reset(_flat_hand_facing(0.0))
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0), keep_clean=True)
    assert frame.in_frame.all()
    assert not frame.depth_clean.any() and not frame.segmentation.any()
    assert not frame.visible.any()
    assert np.all(frame.occluder == OCCLUDER_NONE)


def test_keypoints_behind_the_camera_have_nan_pixels():
    """A camera among the fingers looking down: the fingertips are behind it."""
    intrinsics = CameraIntrinsics(320, 240, 241.42, 241.42, 160.0, 120.0, "r", (0.01, 2.0))
    # The flat hand's fingers point up (+z) from z = 0.1; the camera at z = 0.2 looks down.
    cam = CameraSpec.look_at("down", intrinsics, (0.0, 0.45, 0.2), (0.0, 0.45, 0.0), up=(0, 1, 0))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(_flat_hand_facing(0.0))
    with FrameRenderer(scene, "down") as renderer:
        frame = renderer.render(np.random.default_rng(0))
    behind = frame.keypoints_cam[:, 2] <= 0
    assert behind[TIPS].all() and not behind.all()
    assert np.isnan(frame.keypoints_px[behind]).all()
    assert np.isfinite(frame.keypoints_px[~behind]).all()
    assert not frame.in_frame[behind].any() and not frame.visible[behind].any()


class _DropEverything:
    """A sensor that returns no depth at all (every pixel dropped out)."""

    def apply(self, depth_m, intrinsics, rng):
        return np.zeros_like(depth_m)


def test_visibility_is_decided_on_the_clean_render():
    """Dropouts in the sensor's depth at the keypoints' pixels do not change visibility."""
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(_flat_hand_facing(0.0))
    with FrameRenderer(scene, "front") as renderer:
        clean = renderer.render(np.random.default_rng(0))
    with FrameRenderer(scene, "front", sensor=_DropEverything()) as renderer:
        dropped = renderer.render(np.random.default_rng(0), keep_clean=True)
    assert not dropped.depth.any() and dropped.depth_clean.any()
    assert dropped.visible.all()
    np.testing.assert_array_equal(dropped.visible, clean.visible)
    np.testing.assert_array_equal(dropped.occluder, clean.occluder)


class _Offset:
    """A sensor that adds a constant to every measured depth."""

    def __init__(self, offset_m: float, hole: tuple[int, int] | None = None):
        self.offset_m, self.hole = offset_m, hole

    def apply(self, depth_m, intrinsics, rng):
        out = np.where(depth_m > 0, depth_m + np.float32(self.offset_m), np.float32(0.0))
        if self.hole is not None:  # a 5 x 5 dropout around one pixel (u, v)
            u, v = self.hole
            out[v - 2 : v + 3, u - 2 : u + 3] = 0.0
        return out.astype(np.float32)


def test_visible_sensor_says_where_the_sensor_returned_the_keypoint():
    """visible_sensor: visible, and the noisy depth at its pixel is valid and agrees (10 mm)."""
    from handsim.frame import SENSOR_AGREEMENT_M

    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(_flat_hand_facing(0.0))

    def render(sensor):
        with FrameRenderer(scene, "front", sensor=sensor) as renderer:
            return renderer.render(np.random.default_rng(0))

    clean = render(None)
    assert clean.visible.all()
    np.testing.assert_array_equal(clean.visible_sensor, clean.visible)
    assert not render(_DropEverything()).visible_sensor.any()
    within = render(_Offset(0.8 * SENSOR_AGREEMENT_M))
    np.testing.assert_array_equal(within.visible_sensor, within.visible)
    beyond = render(_Offset(1.2 * SENSOR_AGREEMENT_M))
    assert beyond.visible.all() and not beyond.visible_sensor.any()
    # A dropout over one fingertip's pixels: that keypoint alone is lost to the sensor.
    tip = KEYPOINT_NAMES.index("index_tip")
    u, v = np.rint(clean.keypoints_px[tip]).astype(int)
    holed = render(_Offset(0.0, hole=(u, v)))
    expected = np.ones(21, dtype=bool)
    expected[tip] = False
    np.testing.assert_array_equal(holed.visible_sensor, expected)
    np.testing.assert_array_equal(holed.visible, clean.visible)


def test_a_keypoint_is_visible_only_on_its_own_part():
    """Every visible keypoint's pixel (or a neighbour) shows its own hand part near its depth."""
    from handsim.frame.renderer import _NEIGHBOURS, _keypoint_parts

    scene = Scene(SceneSpec())
    parts = _keypoint_parts(scene)
    with FrameRenderer(scene, "third_person") as renderer:
        for seed, name in enumerate(("open", "fist", "pinch", "point")):
            scene.reset(gesture(name).replace(wrist_pos=np.array([0.0, -0.05, 0.15])))
            frame = renderer.render(np.random.default_rng(seed))
            assert frame.visible.sum() >= 5, name
            for k in np.nonzero(frame.visible)[0]:
                u, v = np.rint(frame.keypoints_px[k]).astype(int)
                rows = np.clip(v + _NEIGHBOURS[:, 0], 0, 479)
                cols = np.clip(u + _NEIGHBOURS[:, 1], 0, 639)
                own = np.isin(frame.segmentation[rows, cols], parts[k])
                depth = frame.depth[rows, cols]
                near = np.abs(depth - frame.keypoints_cam[k, 2]) < 0.03
                assert np.any(own & near & (depth > 0)), KEYPOINT_NAMES[k]


def _clutter_scene(seed: int):
    from handsim.world.scene import sample_placements, third_person_camera

    rng = np.random.default_rng(seed)
    names = ("005_tomato_soup_can", "003_cracker_box", "025_mug", "011_banana")
    placements = sample_placements(rng, names)
    return Scene(SceneSpec(objects=placements, cameras=(third_person_camera(ICVL),)))


def test_silhouette_motion_bound_holds_for_every_model_point():
    """_moved_px bounds the image motion of every model point of a rigidly moved object."""
    from scipy.spatial.transform import Rotation

    scene = _clutter_scene(3)
    rng = np.random.default_rng(0)
    with FrameRenderer(scene, "third_person") as renderer:
        frame = renderer.render(rng)
        for label, (_, obj) in zip(frame.objects, scene.objects, strict=True):
            T = label.T_cam_from_obj
            points = np.asarray(obj.model_points_m)
            for step_m in (1e-5, 1e-4, 3e-3):
                dR = Rotation.from_rotvec(rng.normal(size=3) * step_m * 5).as_matrix()
                dt = rng.normal(size=3) * step_m
                T2 = T.copy()
                T2[:3, :3] = dR @ T[:3, :3]
                T2[:3, 3] = T[:3, 3] + dt
                before = obj.corners_m @ T[:3, :3].T + T[:3, 3]
                after = obj.corners_m @ T2[:3, :3].T + T2[:3, 3]
                bound = renderer._moved_px(before, after)
                moved = ICVL.project(points @ T2[:3, :3].T + T2[:3, 3]) - ICVL.project(
                    points @ T[:3, :3].T + T[:3, 3]
                )
                assert np.max(np.abs(moved)) <= bound * (1 + 1e-9)
                assert bound < 10 * np.max(np.abs(moved)) + 1e-12  # not uselessly loose


def test_reused_silhouette_differs_from_a_fresh_render_only_on_its_boundary():
    """Objects moved by less than the tolerance keep their masks, with no render.

    A kept mask matches a fresh render of the object alone except at boundary pixels, and the
    counts differ by no more than the differing pixels.
    """
    import cv2
    import mujoco

    scene = _clutter_scene(4)
    rng = np.random.default_rng(0)
    model, data = scene.model, scene.data
    with FrameRenderer(scene, "third_person") as reused:
        reused.render(rng)
        renders = []
        original = reused.renderer.render_segmentation
        reused.renderer.render_segmentation = lambda *a, **k: renders.append(1) or original(*a, **k)
        adr = [model.jnt_qposadr[model.body(b).jntadr[0]] for b, _ in scene.objects]
        for _ in range(5):
            for a in adr:  # tens of micrometres, as resting objects jitter
                data.qpos[a : a + 3] += rng.normal(size=3) * 2e-5
            mujoco.mj_forward(model, data)
            kept = reused.render(rng)
            with FrameRenderer(scene, "third_person", silhouette_tolerance_px=0.0) as fresh:
                new = fresh.render(rng)
                for k, (a, b) in enumerate(zip(kept.objects, new.objects, strict=True)):
                    # On BOP's canvas: the image and one image size beyond it on every side.
                    mask = reused._silhouette_masks[k]
                    H, W = new.segmentation.shape  # noqa: N806
                    cached = np.zeros((3 * H, 3 * W), dtype=bool)
                    h, w = mask.pixels.shape
                    cached[H + mask.v0 : H + mask.v0 + h, W + mask.u0 : W + mask.u0 + w] = (
                        mask.pixels
                    )
                    alone = fresh._render_only(data, fresh._object_geoms[k], (-W, -H, 2 * W, 2 * H))
                    truth = (alone >= 0) & (
                        scene.geom_labels[np.maximum(alone, 0)] == OBJECT_LABEL_OFFSET + k
                    )
                    assert truth.sum() == b.px_count_all
                    kernel = np.ones((3, 3), np.uint8)
                    grown = cv2.dilate(truth.view(np.uint8), kernel).view(bool)
                    shrunk = cv2.erode(truth.view(np.uint8), kernel).view(bool)
                    boundary = grown & ~shrunk
                    differ = cached ^ truth
                    assert not (differ & ~boundary).any()
                    assert abs(a.px_count_all - b.px_count_all) <= differ.sum()
                    assert abs(a.px_count_visib - b.px_count_visib) <= differ.sum()
        moved = max(
            reused._moved_px(reused._silhouette_corners[k], kept.objects[k].corners_cam)
            for k in range(len(adr))
        )
    assert moved > 0.0
    assert not renders  # every silhouette was reused


def test_silhouette_tolerance_is_checked():
    """A tolerance outside [0, 0.5) pixels is refused, naming the argument."""
    from handsim.world.scene import InvalidScene

    scene = Scene(SceneSpec())
    for bad in (-0.1, 0.5, "0.1", True, float("nan")):
        with pytest.raises(InvalidScene, match="silhouette_tolerance_px"):
            FrameRenderer(scene, "third_person", silhouette_tolerance_px=bad)


@pytest.fixture(scope="module")
def screen(tmp_path_factory):
    """A 30 x 1 x 30 cm board, large enough to hide a whole hand."""
    path = tmp_path_factory.mktemp("screen") / "screen.stl"
    trimesh.creation.box(extents=(0.3, 0.01, 0.3)).export(path)
    return load_object(path, name="screen", mass_kg=0.2, decomposition="convex_hull")


def test_hand_occlusion_ratio_leaves_the_forearm_out(screen):
    """A board hiding the hand from the wrist crease up scores >= 0.95, forearm in view or not."""
    eye_z, hand_y = 0.19, 0.5
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, eye_z), (0.0, hand_y, eye_z))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(_flat_hand_facing(0.0))  # wrist crease at z = 0.1, forearm down toward z = 0
    with FrameRenderer(scene, "front") as renderer:
        bare = renderer.render(np.random.default_rng(0), hand_occlusion=True)
    assert bare.hand_occlusion_ratio == pytest.approx(0.0, abs=1e-9)
    # The board's lower edge on the ray from the camera to 5 mm below the crease on the palm
    # surface (~14 mm in front of the wrist's centre): the forearm below it stays in view.
    front_y, palm_y, edge_z = 0.4, hand_y - 0.014, 0.095
    lower_edge_z = eye_z + (edge_z - eye_z) * front_y / palm_y
    board = ObjectPlacement("screen", (0.0, front_y + 0.005, lower_edge_z + 0.15), mesh=screen)
    scene = Scene(SceneSpec(cameras=(cam,), objects=(board,), table=False))
    scene.reset(_flat_hand_facing(0.0))
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0), hand_occlusion=True)
    # The palm label below the board: the forearm stub of the palm skin only.
    forearm_px = np.count_nonzero(frame.segmentation == SEGMENT_LABELS.index("palm"))
    assert forearm_px > 300
    assert not frame.visible.any()
    assert frame.hand_occlusion_ratio >= 0.95


@pytest.mark.parametrize("side", ["left", "bottom"])
def test_border_cut_object_counts_its_whole_silhouette(panel, side):
    """A panel half outside the image: px_count_all is its whole projected box (BOP), not 1.0."""
    from matplotlib.path import Path as Polygon
    from scipy.spatial import ConvexHull

    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.05), (0.0, 1.0, 0.05))
    # Centre the panel on the ray of the image's left column / bottom row, 0.4 m ahead.
    d = 0.4
    x = -ICVL.cx / ICVL.fx * d if side == "left" else 0.0
    z = 0.05 - (ICVL.height - 1 - ICVL.cy) / ICVL.fy * d if side == "bottom" else 0.05
    place = ObjectPlacement("panel", (x, d, z), mesh=panel)
    scene = Scene(SceneSpec(cameras=(cam,), objects=(place,), table=False))
    scene.reset(gesture("open").replace(wrist_pos=np.array([0.0, -1.0, 0.0])))  # behind
    with FrameRenderer(scene, "front") as renderer:
        label = renderer.render(np.random.default_rng(0)).objects[0]
    # The silhouette of a box: the convex hull of its 8 projected corners. Count the pixel
    # centres inside it, on the whole canvas and inside the image.
    corners_px = ICVL.project(label.corners_cam)
    hull = corners_px[ConvexHull(corners_px).vertices]
    v, u = np.mgrid[-ICVL.height : 2 * ICVL.height, -ICVL.width : 2 * ICVL.width]
    inside = Polygon(hull).contains_points(np.stack([u.ravel(), v.ravel()], -1)).reshape(u.shape)
    in_image = (u >= 0) & (u < ICVL.width) & (v >= 0) & (v < ICVL.height)
    expected_all, expected_visib = inside.sum(), (inside & in_image).sum()
    perimeter = np.sum(np.linalg.norm(hull - np.roll(hull, 1, axis=0), axis=1))
    assert abs(label.px_count_all - expected_all) <= perimeter
    assert abs(label.px_count_visib - expected_visib) <= perimeter
    assert label.visib_fract == pytest.approx(expected_visib / expected_all, abs=0.02)
    assert 0.4 < label.visib_fract < 0.6  # about half of it is in the image


def test_coarse_skin_keeps_the_keypoints_and_the_depth_within_a_millimetre():
    """The coarse skin poses as the full one: keypoints alike, depth within 1 mm, groups kept."""
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False, skin_lod=True))
    scene.reset(_flat_hand_facing(0.0))
    groups = scene.model.geom_group.copy()
    full_ids, coarse_ids = scene.skin_lod_geom_ids
    assert np.all(groups[full_ids] == 2) and np.all(groups[coarse_ids] == 4)
    with FrameRenderer(scene, "front", skin_detail="full") as renderer:
        full = renderer.render(np.random.default_rng(0), keep_clean=True)
        assert renderer.last_skin_detail == "full"
        renderer.skin_detail = "coarse"
        coarse = renderer.render(np.random.default_rng(0), keep_clean=True)
        assert renderer.last_skin_detail == "coarse"
    np.testing.assert_array_equal(scene.model.geom_group, groups)  # swapped back
    np.testing.assert_array_equal(coarse.keypoints_cam, full.keypoints_cam)
    np.testing.assert_array_equal(coarse.keypoints_px, full.keypoints_px)
    assert coarse.visible.all() and full.visible.all()
    palm = SEGMENT_LABELS.index("palm")
    hand_f = (full.segmentation >= palm) & (full.segmentation < OBJECT_LABEL_OFFSET)
    hand_c = (coarse.segmentation >= palm) & (coarse.segmentation < OBJECT_LABEL_OFFSET)
    assert set(np.unique(coarse.segmentation)) == set(np.unique(full.segmentation))
    close = hand_f & hand_c & (np.abs(coarse.depth_clean - full.depth_clean) <= 0.001)
    assert np.count_nonzero(close) >= 0.95 * np.count_nonzero(hand_f | hand_c)
    assert not np.array_equal(coarse.depth_clean, full.depth_clean)  # another mesh was drawn


@pytest.mark.parametrize(("camera_y", "expected"), [(0.0, "coarse"), (0.36, "full")])
def test_auto_skin_detail_follows_the_hands_projected_size(camera_y, expected):
    """skin_detail="auto" draws the coarse skin while its deviation projects under a pixel."""
    from handsim.frame import LOD_TOLERANCE_PX
    from handsim.hand.skin import skin_deviation_m

    cam = CameraSpec.look_at("front", ICVL, (0.0, camera_y, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False, skin_lod=True))
    scene.reset(_flat_hand_facing(camera_y))
    # The palm faces the camera 0.5 - camera_y away (0.5 m: 0.6 pixel; 0.14 m: over 2).
    deviation_px = skin_deviation_m(scene.hand.params) * ICVL.fx / (0.5 - camera_y)
    assert (deviation_px < LOD_TOLERANCE_PX) == (expected == "coarse")
    with FrameRenderer(scene, "front") as renderer:
        assert renderer.skin_detail == "auto"
        renderer.render(np.random.default_rng(0))
        assert renderer.last_skin_detail == expected


def test_skin_detail_without_a_coarse_skin_and_bad_values():
    """A scene built without the coarse skin draws the full one; unknown levels are refused."""
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False, skin_lod=False))
    assert scene.skin_lod_geom_ids is None
    scene.reset(_flat_hand_facing(0.0))
    with FrameRenderer(scene, "front", skin_detail="coarse") as renderer:
        renderer.render(np.random.default_rng(0))
        assert renderer.last_skin_detail == "full"
        with pytest.raises(InvalidScene, match=r"skin_detail must be one of 'auto', 'full', "):
            renderer.skin_detail = "medium"
    with pytest.raises(InvalidScene, match=r"skin_detail must be one of .* received 3"):
        FrameRenderer(scene, "front", skin_detail=3)


def test_skin_as_drawn_shows_the_level_render_draws_to_other_renderers():
    """Inside the block the model shows the drawn level (a plain render sees it); then restored."""
    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False, skin_lod=True))
    scene.reset(_flat_hand_facing(0.0))
    full_ids, coarse_ids = scene.skin_lod_geom_ids
    groups = scene.model.geom_group.copy()
    with FrameRenderer(scene, "front") as renderer:
        frame = renderer.render(np.random.default_rng(0), keep_clean=True)
        with renderer.skin_as_drawn() as level:
            assert level == renderer.last_skin_detail == "coarse"
            assert np.all(scene.model.geom_group[coarse_ids] == 2)
            assert np.all(scene.model.geom_group[full_ids] > 4)
            depth, _ = renderer.renderer.render(scene.data)
        np.testing.assert_array_equal(scene.model.geom_group, groups)
        depth_images, _ = renderer.render_images()
    # The same draw: equal wherever the labelled frame's working range keeps a depth.
    kept = frame.depth_clean > 0
    np.testing.assert_array_equal(depth[kept], frame.depth_clean[kept])
    np.testing.assert_array_equal(depth_images, depth)


def test_a_frame_renderer_draws_through_the_renderer_it_is_given():
    """renderer=: the frame renderer draws with it (and closes it); the frame is the same."""
    from handsim.world.render import DepthRenderer

    cam = CameraSpec.look_at("front", ICVL, (0.0, 0.0, 0.19), (0.0, 0.5, 0.19))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(_flat_hand_facing(0.0))
    given = DepthRenderer(scene.model, "front", ICVL)
    with (
        FrameRenderer(scene, "front") as default,
        FrameRenderer(scene, "front", renderer=given) as through,
    ):
        assert through.renderer is given
        a = default.render(np.random.default_rng(0))
        b = through.render(np.random.default_rng(0))
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.segmentation, b.segmentation)


def test_the_package_exports_the_record_and_the_renderer():
    """``handsim.frame`` exports what its two modules define: the same objects."""
    import handsim.frame
    from handsim.frame import record, renderer

    assert set(handsim.frame.__all__) == set(record.__all__) | set(renderer.__all__)
    for module in (record, renderer):
        for name in module.__all__:
            assert getattr(handsim.frame, name) is getattr(module, name), name


def test_renderer_still_exports_the_silhouette_names_as_the_same_objects():
    """The silhouettes' machinery moved to handsim.frame.silhouettes; renderer re-exports it."""
    from handsim.frame import renderer, silhouettes

    names = ("_Mask", "_pixel_box", "_HIDDEN_GROUP", "_KERNEL_3X3", "_OCCLUSION_MARGIN_M")
    for name in (*names, "_PALM_LABEL", "_ObjectSilhouettes"):
        assert getattr(renderer, name) is getattr(silhouettes, name), name
    for method in ("_render_only", "_moved_px", "_silhouettes"):
        assert getattr(renderer.FrameRenderer, method) is getattr(
            silhouettes._ObjectSilhouettes, method
        )
