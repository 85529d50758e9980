"""MuJoCo Warp's batched renderer against the OpenGL reference (CPU device, small frames)."""

import os
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from handsim.hand import hand_params
from handsim.hand.pose import HandPose
from handsim.hand.samplers import sample_uniform
from handsim.world.camera import camera_preset, look_at_quat_wxyz
from handsim.world.registry import OBJECT_NAMES
from handsim.world.render import DepthRenderer
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    CameraSpec,
    Scene,
    SceneSpec,
    sample_placements,
)
from handsim.world.warp_render import WarpDepthRenderer, WarpRenderError, warp_available

CURVED = [
    int(t)
    for t in (
        mujoco.mjtGeom.mjGEOM_SPHERE,
        mujoco.mjtGeom.mjGEOM_CAPSULE,
        mujoco.mjtGeom.mjGEOM_ELLIPSOID,
        mujoco.mjtGeom.mjGEOM_CYLINDER,
    )
]
TESSELLATION_M = 5e-3
PRESETS = ("nyu_carmine", "icvl", "msra", "sr300")
needs_warp = pytest.mark.skipif(
    not warp_available(), reason="mujoco-warp is not installed (pip install 'handsim[gpu]')"
)


@pytest.fixture(scope="module", autouse=True)
def _warp_cache(tmp_path_factory):
    # Compiled kernels go to a per-run folder unless the caller keeps a cache.
    os.environ.setdefault("WARP_CACHE_PATH", str(tmp_path_factory.mktemp("warp_cache")))


def _scene(preset: str, objects: tuple[str, ...], seed: int) -> Scene:
    intr = camera_preset(preset).scaled(64, 48)
    cam = CameraSpec.look_at("camera", intr, (0.0, -0.6, 0.4), (0.0, 0.0, 0.1))
    rng = np.random.default_rng(seed)
    placements = sample_placements(rng, objects) if objects else ()
    spec = SceneSpec(
        hand=hand_params("medium", "right"), objects=placements, cameras=(cam,), table=True
    )
    return Scene(spec)


def _poses(scene: Scene, n: int, seed: int) -> list[mujoco.MjData]:
    rng = np.random.default_rng(seed)
    angles = sample_uniform(rng, n).angles
    datas = []
    for i in range(n):
        data = mujoco.MjData(scene.model)
        wrist = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), 0.2])
        pose = HandPose(wrist, rng.normal(0.0, 0.5, 3), angles[i])
        scene.binding.set_pose(data, pose, kinematics_only=True)
        mujoco.mj_forward(scene.model, data)
        datas.append(data)
    return datas


def test_import_handsim_never_imports_warp():
    """The optional extra stays out of the core's imports."""
    code = (
        "import sys, handsim, handsim.world, handsim.data; "
        "print(sorted(m for m in ('warp', 'mujoco_warp') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


# Every object type once, spread over the camera presets.
GROUPS = [tuple(OBJECT_NAMES[i :: len(PRESETS)]) for i in range(len(PRESETS))]


@needs_warp
@pytest.mark.parametrize(("preset", "objects"), list(zip(PRESETS, GROUPS, strict=True)))
def test_depth_and_segmentation_match_opengl(preset, objects):
    """Depth and geom ids agree with the OpenGL reference for hand, objects and table."""
    scene = _scene(preset, objects, seed=3)
    intr = scene.spec.cameras[0].intrinsics
    datas = _poses(scene, 2, seed=4)
    warp = WarpDepthRenderer(scene.model, "camera", intr, nworld=len(datas), device="cpu")
    depth_w, ids_w = warp.render(datas)
    seen = set()
    with DepthRenderer(scene.model, "camera", intr) as gl:
        for k, data in enumerate(datas):
            depth_g, ids_g = gl.render(data)
            assert (ids_w[k] == ids_g).mean() >= 0.99
            both = (ids_w[k] >= 0) & (ids_g >= 0)
            # OpenGL draws curved primitives (the arm's capsule) tessellated, the ray caster
            # exactly: they agree to the tessellation's error only. Hand skin, objects
            # (meshes) and the table (box) are the same triangles and faces in both.
            curved = np.isin(scene.model.geom_type[np.maximum(ids_g, 0)], CURVED)
            error_m = np.abs(depth_w[k] - depth_g)
            assert (error_m[both & ~curved] < 1e-3).mean() >= 0.99
            assert (error_m[both & curved] < TESSELLATION_M).mean() >= 0.99
            seen |= set(np.unique(ids_g[ids_g >= 0]).tolist())
    names = [scene.model.geom(g).name for g in seen]
    # The skinned hand and at least one object were in view, so they were compared.
    assert any(n.startswith(("rh_", "lh_")) and "_visual" in n for n in names)
    assert any(n.startswith("obj_") for n in names)


@needs_warp
def test_a_render_returns_arrays_the_next_render_leaves_alone():
    """The images are the caller's: a later render of other states does not overwrite them."""
    scene = _scene("sr300", ("025_mug",), seed=1)
    intr = scene.spec.cameras[0].intrinsics
    warp = WarpDepthRenderer(scene.model, "camera", intr, nworld=2, device="cpu")
    depth_a, ids_a = warp.render(_poses(scene, 2, seed=2))
    kept = depth_a.copy(), ids_a.copy()
    depth_b, ids_b = warp.render(_poses(scene, 2, seed=3))
    np.testing.assert_array_equal(depth_a, kept[0])
    np.testing.assert_array_equal(ids_a, kept[1])
    assert (ids_a != ids_b).any()


@needs_warp
def test_each_world_has_its_own_camera_pose():
    """A camera moved per world (as data generation does) renders as OpenGL sees it."""
    scene = _scene("sr300", ("025_mug",), seed=1)
    intr = scene.spec.cameras[0].intrinsics
    datas = _poses(scene, 2, seed=2)
    model, cam = scene.model, scene.model.camera("camera").id
    eyes = [(0.0, -0.6, 0.4), (0.3, -0.4, 0.5)]
    images = []
    with DepthRenderer(model, "camera", intr) as gl:
        for data, eye in zip(datas, eyes, strict=True):
            model.cam_pos[cam] = eye
            model.cam_quat[cam] = look_at_quat_wxyz(np.array(eye), np.array((0.0, 0.0, 0.1)))
            mujoco.mj_camlight(model, data)
            images.append(gl.render(data))
    warp = WarpDepthRenderer(model, "camera", intr, nworld=2, device="cpu")
    depth_w, ids_w = warp.render(datas)
    for k, (depth_g, ids_g) in enumerate(images):
        assert (ids_w[k] == ids_g).mean() >= 0.99
        both = (ids_w[k] >= 0) & (ids_g >= 0)
        assert both.sum() > 100
        assert (np.abs(depth_w[k] - depth_g)[both] < 5e-3).mean() >= 0.99
    assert (ids_w[0] != ids_w[1]).mean() > 0.1  # the two views differ


@needs_warp
def test_errors_name_what_is_valid():
    """Bad input is refused with a message naming what is valid."""
    scene = _scene("sr300", (), seed=0)
    intr = scene.spec.cameras[0].intrinsics
    with pytest.raises(WarpRenderError, match="nworld must be an integer >= 1"):
        WarpDepthRenderer(scene.model, "camera", intr, nworld=0, device="cpu")
    with pytest.raises(WarpRenderError, match="added for a 64 x 48 image"):
        WarpDepthRenderer(scene.model, "camera", camera_preset("sr300"), nworld=1, device="cpu")
    with pytest.raises(KeyError, match="cameras: camera"):
        WarpDepthRenderer(scene.model, "nope", intr, nworld=1, device="cpu")
    with pytest.raises(WarpRenderError, match="unknown Warp device 'tpu'; valid: 'cpu'"):
        WarpDepthRenderer(scene.model, "camera", intr, nworld=1, device="tpu")
    warp = WarpDepthRenderer(scene.model, "camera", intr, nworld=2, device="cpu")
    with pytest.raises(WarpRenderError, match="one MjData per world, 2; received 1"):
        warp.render([mujoco.MjData(scene.model)])


# Each preset with a backdrop too: the clutter's and torso's boxes and cylinders, the wall.
BACKGROUNDS = ("clutter", "torso", "wall", "none")
EYE_M = np.array([0.0, -0.6, 0.4])
PALM = SEGMENT_LABELS.index("palm")  # labels from PALM on: the hand proper, then objects


def _frame_renderers(scene: Scene):
    """The OpenGL frame renderer and the same one rendering through MuJoCo Warp."""
    from handsim.frame import FrameRenderer
    from handsim.world.warp_render import WarpSceneRenderer

    gl = FrameRenderer(scene, "camera", skin_detail="full")
    intr = scene.spec.cameras[0].intrinsics
    through_warp = WarpSceneRenderer(scene.model, "camera", intr, device="cpu")
    warp = FrameRenderer(scene, "camera", skin_detail="full", renderer=through_warp)
    return gl, warp


def _hand_behind(scene: Scene, k: int, rng: np.random.Generator) -> None:
    """Pose the hand 8-12 cm behind object ``k`` as the camera sees it (partly hidden)."""
    mujoco.mj_forward(scene.model, scene.data)
    obj = scene.data.xpos[scene.model.body(scene.objects[k][0]).id].copy()
    away = obj - EYE_M
    away[2] = 0.0
    palm = obj + away / np.linalg.norm(away) * rng.uniform(0.08, 0.12)
    palm[2] = max(obj[2], 0.06) + rng.uniform(0.0, 0.04)
    angles = sample_uniform(rng, 1).angles[0]
    scene.binding.set_pose(scene.data, HandPose(palm, rng.normal(0.0, 0.8, 3), angles))
    scene.binding.point_upper_arm(scene.data, np.array([0.18, 0.55, 0.3]))


@needs_warp
@pytest.mark.parametrize(
    ("preset", "objects", "background"), list(zip(PRESETS, GROUPS, BACKGROUNDS, strict=True))
)
def test_frame_labels_match_opengl(preset, objects, background):
    """The labels of a Warp render agree with OpenGL's, identical where the images agree.

    Every object type (the 21 over the presets), the table and the backdrops' primitives,
    the hand partly behind an object: >= 99 % of hand and object pixels within 1 mm,
    segmentation >= 99 %; keypoints and object poses identical; per keypoint, visibility
    and occluder identical where the two images agree around its pixel; object pixel
    counts, visib_fract and the hand occlusion ratio identical where the renders they are
    counted on agree.
    """
    intr = camera_preset(preset).scaled(64, 48)
    cam = CameraSpec.look_at("camera", intr, tuple(EYE_M), (0.0, 0.0, 0.1))
    rng = np.random.default_rng(11)
    spec = SceneSpec(
        hand=hand_params("medium", "right"),
        objects=sample_placements(rng, objects),
        cameras=(cam,),
        table=True,
        background=background,
    )
    scene = Scene(spec)
    scene.place_backdrop(EYE_M, np.zeros(3), 0.8)
    gl, warp = _frame_renderers(scene)
    h, w = intr.height, intr.width
    canvas = (-w, -h, 2 * w, 2 * h)
    compared = {"keypoints": 0, "objects": 0, "ratios": 0}
    occluded = backdrop_px = 0
    for k in range(len(objects)):
        scene.set_hand_length(0.17 + 0.01 * k)  # the skin rescaled on the device too
        _hand_behind(scene, k, rng)
        a = gl.render(np.random.default_rng(0), hand_occlusion=True)
        b = warp.render(np.random.default_rng(0), hand_occlusion=True)
        seg_a, seg_b = a.segmentation, b.segmentation
        seen = (seg_a != 0) | (seg_b != 0)
        assert (seg_a == seg_b)[seen].mean() >= 0.99
        # Hand (palm, digits) and object pixels: skin and object meshes, the same triangles.
        both = (seg_a >= PALM) & (seg_b >= PALM)
        assert (np.abs(a.depth - b.depth)[both] < 1e-3).mean() >= 0.99
        np.testing.assert_array_equal(a.keypoints_px, b.keypoints_px)
        np.testing.assert_array_equal(a.in_frame, b.in_frame)
        for oa, ob in zip(a.objects, b.objects, strict=True):
            np.testing.assert_array_equal(oa.T_cam_from_obj, ob.T_cam_from_obj)
            np.testing.assert_array_equal(oa.corners_cam, ob.corners_cam)
        # Keypoints whose 3 x 3 neighbourhood looks the same in both images.
        agree = (seg_a == seg_b) & (np.abs(a.depth - b.depth) < 1e-3)
        agree = np.pad(agree, 1, constant_values=True)
        for j in np.flatnonzero(a.in_frame):
            u, v = (int(x) for x in np.rint(a.keypoints_px[j]))
            if agree[v : v + 3, u : u + 3].all():
                assert a.visible[j] == b.visible[j] and a.occluder[j] == b.occluder[j], j
                compared["keypoints"] += 1
        # Silhouettes on BOP's canvas, and the hand with the objects hidden, from each.
        for i, (oa, ob) in enumerate(zip(a.objects, b.objects, strict=True)):
            geoms = gl._object_geoms[i]
            same = np.array_equal(
                gl._render_only(scene.data, geoms, canvas),
                warp._render_only(scene.data, geoms, canvas),
            )
            if same and np.array_equal(
                seg_a == OBJECT_LABEL_OFFSET + i, seg_b == OBJECT_LABEL_OFFSET + i
            ):
                assert (oa.px_count_all, oa.px_count_visib) == (ob.px_count_all, ob.px_count_visib)
                assert oa.visib_fract == ob.visib_fract
                compared["objects"] += 1
        hand_geoms = np.flatnonzero(gl._is_hand_geom)
        hand_a = gl._render_only(scene.data, hand_geoms)
        hand_b = warp._render_only(scene.data, hand_geoms)
        if np.array_equal(hand_a, hand_b) and np.array_equal(seg_a >= PALM, seg_b >= PALM):
            assert a.hand_occlusion_ratio == b.hand_occlusion_ratio
            compared["ratios"] += 1
        assert abs(a.hand_occlusion_ratio - b.hand_occlusion_ratio) < 0.05
        occluded += a.hand_occlusion_ratio > 0.0
        backdrop_px += int(np.sum(seg_a == SEGMENT_LABELS.index("backdrop")))
    gl.close()
    warp.close()
    # The identities above were exercised, on a hand that objects hid.
    assert compared["keypoints"] >= 10 and compared["objects"] >= 1
    assert occluded >= 1
    assert (backdrop_px > 0) == (background != "none")


@needs_warp
def test_postprocess_on_the_device_matches_numpy():
    """Ids, the working range and the label values mapped on the device: numpy's result."""
    scene = _scene("sr300", ("025_mug", "003_cracker_box"), seed=1)
    intr = scene.spec.cameras[0].intrinsics
    datas = _poses(scene, 2, seed=5)
    warp = WarpDepthRenderer(scene.model, "camera", intr, nworld=2, device="cpu")
    warp.render(datas)
    raw_depth, seg = warp.raw_images()
    # A range that cuts through the scene: pixels on both sides of it and inside.
    near, far = (float(np.percentile(raw_depth[raw_depth > 0], q)) for q in (30, 70))
    values = scene.geom_labels.astype(np.int16)
    depth_m, labels = warp.render(datas, depth_range_m=(near, far), geom_values=values, fill=0)
    ids = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
    background = (ids < 0) | (raw_depth < np.float32(near)) | (raw_depth > np.float32(far))
    assert background.any() and (~background).any()
    assert ((ids >= 0) & (raw_depth < np.float32(near))).any()
    assert ((ids >= 0) & (raw_depth > np.float32(far))).any()
    np.testing.assert_array_equal(depth_m, np.where(background, np.float32(0), raw_depth))
    np.testing.assert_array_equal(labels, np.where(background, 0, values[np.maximum(ids, 0)]))
    assert labels.dtype == np.int16 and depth_m.dtype == np.float32
    _, plain = warp.render(datas, depth_range_m=(near, far))
    np.testing.assert_array_equal(plain, np.where(background, -1, ids))
    with pytest.raises(WarpRenderError, match=r"geom_values must be \(\d+,\) integers"):
        warp.render(datas, geom_values=np.zeros(3))


PLANE_XML = """
<mujoco>
  <visual><global offwidth="64" offheight="48"/></visual>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <geom name="block" type="box" size="0.1 0.1 0.1" pos="0 0 0.1"/>
    <camera name="camera" pos="0 -1 1" xyaxes="1 0 0 0 0.7 0.7" resolution="64 48"/>
  </worldbody>
</mujoco>
"""


@needs_warp
def test_scene_renderer_refuses_bad_input():
    """The OpenGL renderer's checks, and a plane it cannot hide: refused, saying why."""
    from handsim.world.warp_render import WarpSceneRenderer

    scene = _scene("sr300", ("025_mug",), seed=0)
    intr = scene.spec.cameras[0].intrinsics
    renderer = WarpSceneRenderer(scene.model, "camera", intr, device="cpu")
    with pytest.raises(WarpRenderError, match="factor must be a positive number; received 0"):
        renderer.scale_geoms(scene.hand_skin_geom_ids, 0)
    with pytest.raises(WarpRenderError, match=r"geom ids must be in \[0, \d+\)"):
        renderer.scale_geoms([scene.model.ngeom], 1.1)
    renderer.close()
    with pytest.raises(WarpRenderError, match=r"render\(\) called after close\(\)"):
        renderer.render(scene.data)
    model = mujoco.MjModel.from_xml_string(PLANE_XML)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    renderer = WarpSceneRenderer(model, "camera", intr, device="cpu")
    model.geom_group[model.geom("floor").id] = 5
    with pytest.raises(WarpRenderError, match="a plane cannot be hidden on MuJoCo Warp.*floor"):
        renderer.render(data)
