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
from handsim.world.scene import CameraSpec, Scene, SceneSpec, sample_placements
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
