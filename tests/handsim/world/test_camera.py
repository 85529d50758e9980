"""Cameras: exact intrinsics in MuJoCo, the OpenCV convention, analytic depth."""

import mujoco
import numpy as np
import pytest

from handsim.errors import UnknownName
from handsim.world.camera import (
    CAMERA_PRESETS,
    CameraIntrinsics,
    InvalidCamera,
    T_cam_from_world,
    add_camera,
    camera_preset,
    look_at_quat_wxyz,
)
from handsim.world.render import DepthRenderer, RenderError


def _scene(intrinsics, eye=(0.0, -1.0, 0.5), target=(0.0, 0.0, 0.5)):
    spec = mujoco.MjSpec()
    spec.visual.global_.offwidth = intrinsics.width
    spec.visual.global_.offheight = intrinsics.height
    add_camera(spec.worldbody, "cam", intrinsics, eye, look_at_quat_wxyz(eye, target))
    return spec


# Every preset at its own size, and scaled sizes (smaller, non-square pixels, larger).
_RENDER_SIZES = [(name, None) for name in CAMERA_PRESETS] + [
    ("icvl", (160, 120)),
    ("sr300", (160, 120)),
    ("icvl", (84, 84)),
    ("sr300", (800, 600)),
]


@pytest.mark.parametrize(("preset", "size"), _RENDER_SIZES)
def test_points_render_where_opencv_projects_them(preset, size):
    """Small spheres land within 0.5 px of K's projection, principal point included.

    At a scaled size too: the image is rendered at that size with the scaled K.
    """
    intrinsics = camera_preset(preset)
    if size is not None:
        intrinsics = intrinsics.scaled(*size)
    rng = np.random.default_rng(0)
    eye = np.array([0.2, -0.8, 0.6])
    spec = _scene(intrinsics, eye=eye, target=(0.0, 0.0, 0.4))
    # Points spread over the image, 0.4-1.2 m in front of the camera.
    model0 = spec.compile()
    data0 = mujoco.MjData(model0)
    mujoco.mj_forward(model0, data0)
    T = T_cam_from_world(data0, 0)
    points_cam = []
    for _ in range(6):
        z = rng.uniform(0.4, 1.2)
        u = rng.uniform(0.15, 0.85) * intrinsics.width
        v = rng.uniform(0.15, 0.85) * intrinsics.height
        points_cam.append(
            [(u - intrinsics.cx) / intrinsics.fx * z, (v - intrinsics.cy) / intrinsics.fy * z, z]
        )
    points_cam = np.array(points_cam)
    R, t = T[:3, :3], T[:3, 3]
    for k, p in enumerate(points_cam):
        radius = 2.5 * p[2] / intrinsics.fx  # about 2.5 px on the image
        spec.worldbody.add_geom(
            name=f"s{k}", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[radius, 0, 0], pos=R.T @ (p - t)
        )
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with DepthRenderer(model, "cam", intrinsics) as renderer:
        _, geom_id = renderer.render(data)
    expected = intrinsics.project(points_cam)
    for k in range(len(points_cam)):
        v, u = np.nonzero(geom_id == model.geom(f"s{k}").id)
        assert u.size > 5
        assert abs(u.mean() - expected[k, 0]) < 0.5 and abs(v.mean() - expected[k, 1]) < 0.5


@pytest.mark.parametrize("distance", [0.3, 0.6, 1.0, 1.5])
def test_plane_renders_at_its_depth(distance):
    """A plane facing the camera at a known distance reads back within 0.5 mm everywhere."""
    intrinsics = camera_preset("icvl")
    spec = _scene(intrinsics, eye=(0.0, 0.0, 0.0), target=(0.0, 1.0, 0.0))
    spec.worldbody.add_geom(
        name="wall", type=mujoco.mjtGeom.mjGEOM_BOX, size=[5, 0.01, 5], pos=[0, distance + 0.01, 0]
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with DepthRenderer(model, "cam", intrinsics) as renderer:
        depth, geom_id = renderer.render(data)
    assert depth.dtype == np.float32 and depth.shape == (240, 320)
    assert np.all(geom_id == model.geom("wall").id)
    assert np.abs(depth - distance).max() < 0.5e-3


def test_background_has_zero_depth_and_no_geom():
    """Pixels that see nothing are 0 m deep and labelled -1."""
    intrinsics = camera_preset("icvl")
    spec = _scene(intrinsics)
    spec.worldbody.add_geom(
        name="ball", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.05, 0, 0], pos=[0, 0, 0.5]
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with DepthRenderer(model, "cam", intrinsics) as renderer:
        depth, geom_id = renderer.render(data)
    assert geom_id[0, 0] == -1 and depth[0, 0] == 0.0
    assert depth[120, 160] == pytest.approx(0.95, abs=1e-3)


@pytest.mark.parametrize("extra_geoms", [0, 300])
def test_both_read_back_paths_give_depth_ids_values_and_the_depth_range(extra_geoms):
    """Under 255 scene geoms (compiled pass over the red byte) and over (24-bit colour index).

    Two balls at 0.95 m and 0.65 m: their depth, ids and ``geom_values``; a ``depth_range_m``
    that leaves out the nearer one makes its pixels background (depth 0, the fill value).
    """
    intrinsics = camera_preset("icvl")
    spec = _scene(intrinsics)
    sphere = mujoco.mjtGeom.mjGEOM_SPHERE
    spec.worldbody.add_geom(name="far", type=sphere, size=[0.05, 0, 0], pos=[0.1, 0, 0.5])
    spec.worldbody.add_geom(name="near", type=sphere, size=[0.05, 0, 0], pos=[-0.1, -0.3, 0.5])
    for k in range(extra_geoms):  # out of view, behind the camera
        spec.worldbody.add_geom(type=sphere, size=[0.001, 0, 0], pos=[0.001 * k, -2.0, 0.5])
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    far, near = model.geom("far").id, model.geom("near").id
    values = np.arange(model.ngeom, dtype=np.int16) + 10
    with DepthRenderer(model, "cam", intrinsics) as renderer:
        depth, geom_id = renderer.render(data)
        depth_v, labels = renderer.render(data, geom_values=values, fill=3)
        depth_r, labels_r = renderer.render(
            data, geom_values=values, fill=3, depth_range_m=(0.8, 2.0)
        )
        assert renderer._scene.ngeom > 255 if extra_geoms else renderer._scene.ngeom < 255
    assert set(np.unique(geom_id)) == {-1, far, near}
    assert np.all(depth[geom_id == -1] == 0.0)
    assert depth[geom_id == far].min() == pytest.approx(0.95, abs=2e-3)
    assert depth[geom_id == near].min() == pytest.approx(0.65, abs=2e-3)
    np.testing.assert_array_equal(depth_v, depth)
    np.testing.assert_array_equal(labels, np.where(geom_id >= 0, values[geom_id], 3))
    assert labels.dtype == np.int16
    kept = geom_id == far
    np.testing.assert_array_equal(depth_r, np.where(kept, depth, 0.0))
    np.testing.assert_array_equal(labels_r, np.where(kept, labels, 3))


def test_collision_group_is_invisible():
    """Geoms in group 3 (the hand's collision geoms) are not rendered."""
    intrinsics = camera_preset("icvl")
    spec = _scene(intrinsics)
    spec.worldbody.add_geom(
        name="hidden", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.1, 0, 0], pos=[0, 0, 0.5], group=3
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with DepthRenderer(model, "cam", intrinsics) as renderer:
        depth, geom_id = renderer.render(data)
    assert np.all(geom_id == -1) and np.all(depth == 0.0)


def test_backproject_inverts_project():
    """Back-projecting a depth image gives points that project to their own pixels."""
    intrinsics = camera_preset("sr300")
    depth = np.full((480, 640), 0.7)
    points = intrinsics.backproject(depth)
    v, u = np.indices(depth.shape)
    np.testing.assert_allclose(intrinsics.project(points), np.stack([u, v], -1), atol=1e-9)


@pytest.mark.parametrize("size", [(160, 120), (84, 84), (1280, 960), (641, 479)])
def test_scaled_intrinsics_are_exact(size):
    """scaled(): fx' = fx s, cx' = (cx + 0.5) s - 0.5 (pixel centres at integers), exactly.

    A ray through pixel coordinate u lands at (u + 0.5) s - 0.5: the image's outer edges (-0.5
    and W - 0.5) stay the outer edges; the field of view and working range are kept.
    """
    sensor = camera_preset("sr300")
    w, h = size
    sx, sy = w / sensor.width, h / sensor.height
    scaled = sensor.scaled(w, h)
    assert (scaled.width, scaled.height) == size
    assert (scaled.fx, scaled.fy) == (sensor.fx * sx, sensor.fy * sy)
    assert (scaled.cx, scaled.cy) == ((sensor.cx + 0.5) * sx - 0.5, (sensor.cy + 0.5) * sy - 0.5)
    assert scaled.range_m == sensor.range_m and scaled.name == f"sr300@{w}x{h}"
    rng = np.random.default_rng(0)
    rays = np.column_stack([rng.uniform(-0.6, 0.6, (50, 2)), np.ones(50)]) * rng.uniform(
        0.2, 2.0, (50, 1)
    )
    np.testing.assert_allclose(
        scaled.project(rays), (sensor.project(rays) + 0.5) * [sx, sy] - 0.5, atol=1e-9
    )
    edges = np.array([[-0.5 - sensor.cx, -0.5 - sensor.cy, sensor.fx]]) / sensor.fx
    edges[0, 1] *= sensor.fx / sensor.fy
    np.testing.assert_allclose(scaled.project(edges), [[-0.5, -0.5]], atol=1e-9)
    assert scaled.fovy_deg == pytest.approx(sensor.fovy_deg, rel=1e-12)
    back = scaled.scaled(sensor.width, sensor.height)
    np.testing.assert_allclose(back.K, sensor.K, rtol=1e-12, atol=1e-9)
    assert back.name == "sr300@640x480"
    assert sensor.scaled(640, 480) is sensor


def test_scaled_refuses_bad_sizes():
    """scaled() says what a size must be."""
    icvl = camera_preset("icvl")
    with pytest.raises(InvalidCamera, match=r"scaled\(\) needs integer width and height"):
        icvl.scaled(160.0, 120)
    with pytest.raises(InvalidCamera, match=r"width and height must be in \[1, 8192\] pixels"):
        icvl.scaled(0, 120)


def test_K_and_field_of_view():
    """K holds the preset's values; the NYU Carmine sees about 44.5 deg vertically."""
    nyu = camera_preset("nyu_carmine")
    np.testing.assert_allclose(nyu.K, [[588.036865, 0, 320], [0, 587.075073, 240], [0, 0, 1]])
    assert nyu.fovy_deg == pytest.approx(44.5, abs=0.1)


def test_errors():
    """Bad presets, intrinsics, placements and render set-ups say what is wrong."""
    with pytest.raises(UnknownName, match=r"unknown camera preset 'kinect'; valid presets: nyu"):
        camera_preset("kinect")
    with pytest.raises(InvalidCamera, match=r"fx and fy must be positive"):
        CameraIntrinsics(320, 240, -1.0, 241.0, 160, 120)
    with pytest.raises(InvalidCamera, match=r"width and height must be integers"):
        CameraIntrinsics(320.0, 240, 241.0, 241.0, 160, 120)
    with pytest.raises(InvalidCamera, match=r"eye and target coincide"):
        look_at_quat_wxyz((0, 0, 1), (0, 0, 1))
    with pytest.raises(InvalidCamera, match=r"parallel to up"):
        look_at_quat_wxyz((0, 0, 1), (0, 0, 0))
    intrinsics = camera_preset("sr300")
    spec = mujoco.MjSpec()
    add_camera(
        spec.worldbody, "cam", intrinsics, (0, -1, 0), look_at_quat_wxyz((0, -1, 0), (0, 0, 0))
    )
    model = spec.compile()
    with pytest.raises(UnknownName, match=r"camera 'top' is not in the model; cameras: cam"):
        DepthRenderer(model, "top", intrinsics)
    with pytest.raises(
        RenderError,
        match=r"offscreen buffer is 640 x 480 pixels but the camera needs 1280 x 960; set",
    ):
        DepthRenderer(model, "cam", CameraIntrinsics(1280, 960, 900.0, 900.0, 640, 480))


def test_working_range():
    """Presets carry their sensor's working range; the scene's far clip plane is the range's."""
    from handsim.world.scene import Scene, SceneSpec, third_person_camera

    assert camera_preset("nyu_carmine").range_m == (0.35, 4.0)
    assert camera_preset("icvl").range_m == (0.15, 1.0)
    assert camera_preset("sr300").range_m == (0.2, 1.5)
    for bad in ((0.5, 0.2), (0.0, 1.0), (0.1, np.inf), (1.0,), "far"):
        with pytest.raises(InvalidCamera, match=r"range_m must be \(near, far\)"):
            CameraIntrinsics(320, 240, 241.0, 241.0, 160, 120, "x", bad)
    scene = Scene(SceneSpec(cameras=(third_person_camera(camera_preset("sr300")),)))
    extent = scene.model.stat.extent
    assert scene.model.vis.map.zfar * extent == pytest.approx(1.5)
    assert scene.model.vis.map.znear * extent == pytest.approx(0.01)


def test_canvas_beyond_the_image_equals_a_larger_sensors_render():
    """Tiles with a shifted principal point give exactly a 3x larger sensor's image (BOP)."""
    intr = camera_preset("icvl")
    big = CameraIntrinsics(
        3 * intr.width, 3 * intr.height, intr.fx, intr.fy, intr.cx + intr.width,
        intr.cy + intr.height, "big", intr.range_m,
    )  # fmt: skip

    def model(intrinsics):
        spec = mujoco.MjSpec()
        spec.visual.global_.offwidth, spec.visual.global_.offheight = big.width, big.height
        # Boxes in the image, across its border and beyond it on every side.
        for x, y in [(0.03, 0.02), (0.5, 0.3), (-0.6, -0.1), (0.7, -0.55), (0.66, 0.0)]:
            body = spec.worldbody.add_body(pos=[x, y, 1.0])
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.1, 0.07, 0.05])
        add_camera(spec.worldbody, "cam", intrinsics, np.zeros(3), np.array([0, 1.0, 0, 0]))
        m = spec.compile()
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        return m, d

    m, d = model(intr)
    with DepthRenderer(m, "cam", intr) as renderer:
        w, h = intr.width, intr.height
        canvas = renderer.render_segmentation_canvas(d, (-w, -h, 2 * w, 2 * h))
        # Boxes across the border, each rendered as windows shifted by whole pixels.
        boxes = [(-50, 100, w + 7, 2 * h - 3), (-137, -61, 40, 90), (w - 30, h - 20, 2 * w, h + 5)]
        parts = [renderer.render_segmentation_canvas(d, box) for box in boxes]
        inside = renderer.render_segmentation_canvas(d, (0, 0, w, h))
        np.testing.assert_array_equal(inside, renderer.render_segmentation(d))
        intrinsic = m.cam_intrinsic.copy()
    np.testing.assert_array_equal(m.cam_intrinsic, intrinsic)  # restored
    m_big, d_big = model(big)
    with DepthRenderer(m_big, "cam", big) as renderer:
        reference = renderer.render_segmentation(d_big)
    assert all(np.count_nonzero(reference == g) > 1000 for g in range(5))
    np.testing.assert_array_equal(canvas, reference)
    for (u0, v0, u1, v1), part in zip(boxes, parts, strict=True):
        np.testing.assert_array_equal(part, reference[h + v0 : h + v1, w + u0 : w + u1])
