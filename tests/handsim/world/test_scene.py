"""Scenes: compilation, placements, cameras and segmentation labels."""

import contextlib

import mujoco
import numpy as np
import pytest

from handsim.errors import UnknownName
from handsim.hand.model import hand_params
from handsim.world.camera import T_cam_from_world, camera_preset
from handsim.world.render import DepthRenderer, shared_render_context
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    CameraSpec,
    InvalidScene,
    ObjectPlacement,
    Scene,
    SceneSpec,
    egocentric_camera,
    sample_placements,
    sample_viewpoint,
    third_person_camera,
)

OBJECTS = ("005_tomato_soup_can", "003_cracker_box", "024_bowl")


@pytest.fixture(scope="module")
def scene():
    """A hand above three sampled objects, seen by a third-person and an egocentric camera."""
    placements = sample_placements(np.random.default_rng(0), OBJECTS)
    return Scene(
        SceneSpec(
            objects=placements,
            cameras=(third_person_camera(camera_preset("icvl")), egocentric_camera()),
        )
    )


def test_placements_rest_without_overlap(scene):
    """Sampled objects start without touching each other and stay put under gravity."""
    model, data = scene.model, scene.data
    object_bodies = {model.body(body).id for body, _ in scene.objects}
    for c in data.contact[: data.ncon]:
        pair = {model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]}
        assert not pair <= object_bodies, "objects overlap at the start"
    start = {body: data.body(body).xpos.copy() for body, _ in scene.objects}
    # Hold the hand still above the table while the objects settle.
    for _ in range(int(0.5 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    for body, _ in scene.objects:
        assert np.linalg.norm(data.body(body).xpos - start[body]) < 0.003
    assert sum(w.number for w in data.warning) == 0
    scene.reset()


def test_segmentation_labels_every_part_seen(scene):
    """The third-person view labels the table, the palm, fingers and every object instance."""
    cam = scene.camera("third_person")
    with DepthRenderer(scene.model, cam.name, cam.intrinsics) as renderer:
        depth, geom_id = renderer.render(scene.data)
    labels = scene.segment(geom_id)
    seen = set(np.unique(labels).tolist())
    for name in ("background", "table", "palm", "index", "middle"):
        assert SEGMENT_LABELS.index(name) in seen, name
    for k in range(len(scene.objects)):
        assert OBJECT_LABEL_OFFSET + k in seen
    assert np.all(depth[labels == 0] == 0) and np.all(depth[labels > 0] > 0)


def test_a_renderer_leaves_the_model_as_it_was(scene):
    """The renderer makes its context without a shadow map but restores the model's setting."""
    cam = scene.camera("third_person")
    before = scene.model.vis.quality.shadowsize
    with DepthRenderer(scene.model, cam.name, cam.intrinsics) as renderer:
        renderer.render(scene.data)
    assert scene.model.vis.quality.shadowsize == before


def test_renderers_sharing_a_context_render_what_separate_ones_render(scene):
    """Renderers handing one OpenGL context on (shared_render_context) give equal images."""
    cam = scene.camera("third_person")
    # Another hand size (as many meshes: re-uploaded), then the scene with objects (a new
    # render context), then the first model again.
    small = Scene(SceneSpec(hand=hand_params(0.16), cameras=(cam,)))
    large = Scene(SceneSpec(hand=hand_params(0.21), cameras=(cam,)))
    scenes = (small, large, scene, small)

    def images(shared: bool) -> list:
        out = []
        with shared_render_context() if shared else contextlib.nullcontext():
            for s in scenes:
                renderer = DepthRenderer(s.model, cam.name, cam.intrinsics)
                out.append(renderer.render(s.data))
                renderer.close()
        return out

    for separate, shared in zip(images(False), images(True), strict=True):
        for a, b in zip(separate, shared, strict=True):
            np.testing.assert_array_equal(a, b)
    assert large.model.nmesh == small.model.nmesh != scene.model.nmesh


def test_closing_a_renderer_leaves_another_renderer_intact(scene):
    """A renderer closed while another one's context is current frees its own GL objects.

    Two renderers in one process (an env's and a feedback estimator's synthesizer): closing
    the first right after the second rendered once deleted the second's framebuffer and
    meshes (GL names are per context, freed in the current one), so it returned stale images.
    """
    cam = scene.camera("third_person")
    hand = Scene(SceneSpec(hand=hand_params(0.17), cameras=(cam,)))
    with DepthRenderer(hand.model, cam.name, cam.intrinsics) as kept:
        first = DepthRenderer(scene.model, cam.name, cam.intrinsics)
        first.render(scene.data)
        before = kept.render(hand.data)  # the kept renderer's context is now current
        first.close()
        after = kept.render(hand.data)
        hand.set_hand_length(0.2)  # a changed scene must show in the next image
        kept.upload_meshes(hand.hand_mesh_ids)
        larger = kept.render(hand.data)
    np.testing.assert_array_equal(before[0], after[0])
    np.testing.assert_array_equal(before[1], after[1])
    assert np.count_nonzero(larger[0]) > np.count_nonzero(before[0])


def test_geom_labels_follow_bodies(scene):
    """Hand geoms carry their digit's label, object geoms their instance label."""
    model = scene.model
    assert scene.geom_labels[model.geom("rh_index_distal_visual_0").id] == SEGMENT_LABELS.index(
        "index"
    )
    assert scene.geom_labels[model.geom("rh_palm_collision_0").id] == SEGMENT_LABELS.index("palm")
    assert scene.geom_labels[model.geom("table").id] == SEGMENT_LABELS.index("table")
    body, _ = scene.objects[2]
    assert scene.geom_labels[model.geom(f"{body}_visual").id] == OBJECT_LABEL_OFFSET + 2


def _target_pixel(scene_or_spec, cam_name, target):
    scene = scene_or_spec
    cam_id = scene.model.camera(cam_name).id
    T = T_cam_from_world(scene.data, cam_id)
    p = T[:3, :3] @ np.asarray(target) + T[:3, 3]
    return p, scene.camera(cam_name).intrinsics.project(p)


def test_cameras_look_at_their_target(scene):
    """Third-person and egocentric cameras put the hand target at the image centre."""
    for name in ("third_person", "egocentric"):
        p, uv = _target_pixel(scene, name, (0.0, 0.0, 0.12))
        intr = scene.camera(name).intrinsics
        assert p[2] > 0
        assert abs(uv[0] - intr.cx) < 1.0 and abs(uv[1] - intr.cy) < 1.0
    # The egocentric camera is above the hands and on the user's side.
    ego = scene.camera("egocentric")
    assert ego.pos_m[2] > 0.4 and ego.pos_m[1] < 0.0


def test_viewpoints_are_seeded_and_inside_their_shell():
    """Same seed, same viewpoint; distances and elevations stay in range."""
    a = sample_viewpoint(np.random.default_rng(3))
    b = sample_viewpoint(np.random.default_rng(3))
    assert a == b
    rng = np.random.default_rng(4)
    for _ in range(50):
        cam = sample_viewpoint(rng, distance_range_m=(0.5, 0.6), target_jitter_m=0.0)
        offset = np.asarray(cam.pos_m) - np.array([0.0, 0.0, 0.12])
        assert 0.5 - 1e-9 <= np.linalg.norm(offset) <= 0.6 + 1e-9
        elevation = np.degrees(np.arcsin(offset[2] / np.linalg.norm(offset)))
        assert 15 - 1e-6 <= elevation <= 75 + 1e-6


def test_placements_are_seeded():
    """Same seed, same placements; objects rest at their stable height."""
    a = sample_placements(np.random.default_rng(5), OBJECTS)
    b = sample_placements(np.random.default_rng(5), OBJECTS)
    assert a == b
    assert all(p.pos_m[2] > 0 for p in a)


def test_repeated_objects_get_instance_names():
    """Two instances of one object get distinct bodies and labels."""
    placements = sample_placements(np.random.default_rng(6), ["tomato_soup_can"] * 2)
    scene = Scene(SceneSpec(hand=None, objects=placements))
    assert [body for body, _ in scene.objects] == [
        "obj_005_tomato_soup_can",
        "obj_005_tomato_soup_can_1",
    ]


def test_errors():
    """Inconsistent scenes are refused with messages that say how to fix them."""
    cam = third_person_camera()
    with pytest.raises(InvalidScene, match=r"camera names must be unique"):
        SceneSpec(cameras=(cam, cam))
    with pytest.raises(InvalidScene, match=r"at least one camera"):
        SceneSpec(cameras=())
    with pytest.raises(UnknownName, match=r"teapot"):
        SceneSpec(objects=(ObjectPlacement("teapot", (0.0, 0.0, 0.1)),))
    with pytest.raises(InvalidScene, match=r"could not place .* use fewer objects or a larger"):
        sample_placements(
            np.random.default_rng(0), ["003_cracker_box"] * 3, region_m=((0, 0.01), (0, 0.01))
        )
    with pytest.raises(InvalidScene, match=r"distance_range_m must be \(low, high\)"):
        sample_viewpoint(np.random.default_rng(0), distance_range_m=(0.8, 0.4))
    scene = Scene(SceneSpec(hand=None, table=False))
    with pytest.raises(InvalidScene, match=r"no camera 'top' in this scene; cameras: third_person"):
        scene.camera("top")
    assert isinstance(
        CameraSpec.look_at("c", camera_preset("icvl"), (0, -1, 0), (0, 0, 0)), CameraSpec
    )


def _hand_frame(scene):
    """(keypoints in the camera, hand mask, depth) of the scene's current state."""
    from handsim.frame import FrameRenderer

    with FrameRenderer(scene, "camera") as renderer:
        frame = renderer.render(np.random.default_rng(0))
    return frame.keypoints_cam, frame.segmentation >= SEGMENT_LABELS.index("palm"), frame.depth


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("length_m", [0.15, 0.22])
def test_a_rescaled_hand_is_the_hand_built_at_that_length(side, length_m):
    """set_hand_length gives the keypoints (exactly), pixels and depth of a scene built so."""
    from handsim.hand.pose_sources import gesture

    cam = CameraSpec.look_at("camera", camera_preset("icvl"), (0.0, -0.45, 0.5), (0, 0, 0.3))
    pose = gesture("pinch").replace(wrist_pos=(0.0, 0.0, 0.25), wrist_rotvec=(0.3, 2.8, 0.2))
    built = Scene(SceneSpec(hand=hand_params(length_m, side), cameras=(cam,), table=True))
    rescaled = Scene(SceneSpec(hand=hand_params("medium", side), cameras=(cam,), table=True))
    rescaled.set_hand_length(0.2)  # from whatever length it has: no drift
    rescaled.set_hand_length(length_m)
    assert rescaled.hand.params == built.hand.params == rescaled.spec.hand
    assert rescaled.hand_rescaled and not built.hand_rescaled
    for s in (built, rescaled):
        s.binding.set_pose(s.data, pose)
    kp_a, mask_a, depth_a = _hand_frame(built)
    kp_b, mask_b, depth_b = _hand_frame(rescaled)
    np.testing.assert_allclose(kp_b, kp_a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rescaled.model.geom_size, built.model.geom_size, rtol=0.02)
    # The skins differ only in their triangles (each built on a grid of fixed size).
    assert (mask_a & mask_b).sum() / (mask_a | mask_b).sum() > 0.99
    both = mask_a & mask_b
    assert np.median(np.abs(depth_a[both] - depth_b[both])) < 2e-4


def test_a_renderer_made_before_a_rescale_draws_the_rescaled_skin():
    """FrameRenderer scales the skin it uploaded as it draws: an upload's pixels and depth."""
    from handsim.frame import FrameRenderer
    from handsim.hand.pose_sources import gesture
    from handsim.world.render import DepthRenderer, RenderError

    intr = camera_preset("icvl")
    cam = CameraSpec.look_at("camera", intr, (0.0, -0.45, 0.5), (0, 0, 0.3))
    scene = Scene(
        SceneSpec(hand=hand_params("medium", "left"), cameras=(cam,), table=False, skin_lod=True)
    )
    scene.reset(gesture("fist").replace(wrist_pos=(0.0, 0.0, 0.25), wrist_rotvec=(0.3, 2.8, 0.2)))
    built_m = scene.hand.params.hand_length
    skin = scene.hand_skin_geom_ids
    # The skin's 16, their coarse level of detail's 16 and the forearm's.
    assert len(skin) == len(scene.hand_mesh_ids) == 33
    assert set(scene.model.geom_dataid[skin]) == set(scene.hand_mesh_ids)
    with FrameRenderer(scene, "camera", skin_detail="full") as kept:
        for length_m in (0.15, 0.22, built_m):
            scene.set_hand_length(length_m)
            depth_kept = kept.render(np.random.default_rng(0)).depth
            with DepthRenderer(scene.model, "camera", intr) as fresh:  # uploads the new skin
                depth_fresh, _ = fresh.render(scene.data)
            np.testing.assert_array_equal(depth_kept > 0, depth_fresh > 0)
            assert np.count_nonzero(depth_fresh) > 500
            np.testing.assert_allclose(depth_kept, depth_fresh, rtol=0, atol=2e-6)
    # The coarse skin is rescaled alike: against a renderer made after the rescale.
    with FrameRenderer(scene, "camera", skin_detail="coarse") as kept:
        for length_m in (0.15, 0.22, built_m):
            scene.set_hand_length(length_m)
            depth_kept = kept.render(np.random.default_rng(0)).depth
            with FrameRenderer(scene, "camera", skin_detail="coarse") as fresh:
                depth_fresh = fresh.render(np.random.default_rng(0)).depth
            assert kept.last_skin_detail == fresh.last_skin_detail == "coarse"
            np.testing.assert_array_equal(depth_kept > 0, depth_fresh > 0)
            np.testing.assert_allclose(depth_kept, depth_fresh, rtol=0, atol=2e-6)
        renderer = kept.renderer
        with pytest.raises(RenderError, match=r"factor must be a positive number; received 0"):
            renderer.scale_geoms([0], 0)
        with pytest.raises(RenderError, match=r"geom ids must be in \[0, \d+\); received -1"):
            renderer.scale_geoms([-1], 1.1)


def test_a_rescaled_scene_is_for_kinematic_use_only():
    """Physics, MJCF export and a second spec of the rescaled hand are refused, saying why."""
    from handsim.envs.physics import HandDriver
    from handsim.errors import InvalidHandParams

    scene = Scene(SceneSpec(cameras=(third_person_camera(camera_preset("icvl")),)))
    scene.set_hand_length(scene.hand.params.hand_length)  # the same length: nothing changes
    assert not scene.hand_rescaled
    HandDriver(scene)
    with pytest.raises(InvalidHandParams, match=r"must be in \[0.14, 0.235\] m .* received 0.5"):
        scene.set_hand_length(0.5)
    version = scene.hand_geometry_version
    scene.set_hand_length(0.17)
    assert scene.hand_geometry_version == version + 1
    with pytest.raises(InvalidScene, match=r"rescaled in place .* Scene\(scene.spec\)"):
        HandDriver(scene)
    with pytest.raises(InvalidScene, match=r"to_xml: the hand was rescaled in place"):
        scene.to_xml()
    with pytest.raises(InvalidHandParams, match=r"rescaled from 0.189 m .* build Hand"):
        scene.hand.compile()
    Scene(scene.spec).to_xml()  # the spec holds the new length: a scene built for it
    with pytest.raises(InvalidScene, match="needs a scene with a hand"):
        Scene(SceneSpec(hand=None)).set_hand_length(0.17)


def test_backdrop_is_validated():
    """An unknown background is refused with the valid names."""
    with pytest.raises(
        InvalidScene,
        match=r"background must be one of 'none', 'wall', 'torso', 'clutter'; received 'sky'",
    ):
        SceneSpec(background="sky")
    with pytest.raises(InvalidScene, match=r"background must be one of .*; received 1"):
        SceneSpec(background=1)


def _farthest_m(scene, eye, target):
    """The farthest geom bounding-box corner (all geoms) along the horizontal line of sight."""
    ahead = np.asarray(target, dtype=float) - eye
    ahead[2] = 0.0
    ahead /= np.linalg.norm(ahead)
    model, data = scene.model, scene.data
    far = -np.inf
    for g in range(model.ngeom):
        if model.geom(g).name.startswith("backdrop"):
            continue
        centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        signs = np.array(np.meshgrid(*[(-1, 1)] * 3)).reshape(3, -1).T
        corners = (centre + signs * half) @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g]
        far = max(far, float(((corners - eye) @ ahead).max()))
    return far


@pytest.mark.parametrize("background", ["wall", "torso", "clutter"])
def test_the_backdrop_fills_only_empty_pixels(background):
    """Placed beyond the scene along the line of sight, the backdrop hides nothing.

    Every pixel of the scene without it is the same with it; the rest is the backdrop's.
    """
    placements = sample_placements(np.random.default_rng(1), OBJECTS[:2])
    icvl = camera_preset("icvl")
    rng = np.random.default_rng(3)
    views = [third_person_camera(icvl, name="camera"), egocentric_camera(icvl, name="camera")]
    views += [sample_viewpoint(rng, icvl, name="camera") for _ in range(4)]
    seen_backdrop = 0
    for cam in views:
        plain = Scene(SceneSpec(objects=placements, cameras=(cam,)))
        backed = Scene(SceneSpec(objects=placements, cameras=(cam,), background=background))
        eye = np.asarray(cam.pos_m)
        target = (0.0, 0.0, 0.12)
        backed.place_backdrop(eye, target, _farthest_m(backed, eye, target) + 0.01)
        with shared_render_context():
            with DepthRenderer(plain.model, "camera", icvl) as renderer:
                depth0, geoms0 = renderer.render(plain.data)
                labels0 = plain.segment(geoms0)
            with DepthRenderer(backed.model, "camera", icvl) as renderer:
                depth1, geoms1 = renderer.render(backed.data)
                labels1 = backed.segment(geoms1)
        scene_px = labels0 > 0
        np.testing.assert_array_equal(labels1[scene_px], labels0[scene_px])
        np.testing.assert_array_equal(depth1[scene_px], depth0[scene_px])
        backdrop = labels1 == SEGMENT_LABELS.index("backdrop")
        assert np.array_equal(backdrop, ~scene_px & (labels1 > 0))
        seen_backdrop += np.count_nonzero(backdrop)
    assert seen_backdrop > 0


def test_the_default_backdrop_stands_beyond_the_table_and_the_arm():
    """Unplaced, the backdrop faces the first camera 0.3 m beyond the table's far edge.

    The third-person view sees the hand, arm and table in front of it (a Carmine: the wall
    is beyond the 1 m range of the ICVL sensor).
    """
    cam = third_person_camera(camera_preset("nyu_carmine"), name="camera")
    plain = Scene(SceneSpec(cameras=(cam,)))
    backed = Scene(SceneSpec(cameras=(cam,), background="wall"))
    with shared_render_context():
        with DepthRenderer(plain.model, "camera", cam.intrinsics) as renderer:
            labels0 = plain.segment(renderer.render(plain.data)[1])
        with DepthRenderer(backed.model, "camera", cam.intrinsics) as renderer:
            labels1 = backed.segment(renderer.render(backed.data)[1])
    np.testing.assert_array_equal(labels1[labels0 > 0], labels0[labels0 > 0])
    assert SEGMENT_LABELS.index("arm") in labels0
    assert np.count_nonzero(labels1 == SEGMENT_LABELS.index("backdrop")) > 0
