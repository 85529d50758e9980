"""CenterOfMassLocalizer: analytic depth images, its failure mode, and rendered hands."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.errors import InvalidEstimatorInput, InvalidEstimatorParams
from handsim.estimator import Estimator, PrivilegedEstimator, hand_center
from handsim.estimators import CenterOfMassLocalizer
from handsim.world.camera import camera_preset

ICVL = camera_preset("icvl")
NYU = camera_preset("nyu_carmine")


def _rays(intr) -> np.ndarray:
    """(H, W, 3) ray of every pixel, scaled to z = 1 (OpenCV camera frame)."""
    v, u = np.indices((intr.height, intr.width), dtype=np.float64)
    return np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1)


def _disk(intr, center_m, radius_m, background_m=None) -> np.ndarray:
    """Depth of a fronto-parallel disk at ``center_m``, over a plane at ``background_m``."""
    rays = _rays(intr)
    z0 = center_m[2]
    on_disk = np.linalg.norm(rays[..., :2] * z0 - center_m[:2], axis=-1) <= radius_m
    depth = np.full(rays.shape[:2], 0.0 if background_m is None else background_m)
    depth[on_disk] = z0
    return depth.astype(np.float32)


def _sphere(intr, center_m, radius_m, background_m) -> np.ndarray:
    """Depth of a sphere (front surface) over a plane at ``background_m``."""
    d = _rays(intr)
    c = np.asarray(center_m)
    b = d @ c
    dd = np.sum(d * d, axis=-1)
    disc = b**2 - dd * (c @ c - radius_m**2)
    hit = disc >= 0
    depth = np.full(d.shape[:2], background_m)
    depth[hit] = (b[hit] - np.sqrt(disc[hit])) / dd[hit]  # z of the near hit (ray z = 1)
    return depth.astype(np.float32)


def test_localizer_is_a_plain_estimator():
    """It satisfies Estimator, not PrivilegedEstimator (it never sees the truth)."""
    loc = CenterOfMassLocalizer()
    assert isinstance(loc, Estimator) and not isinstance(loc, PrivilegedEstimator)


@pytest.mark.parametrize("background_m", [None, 1.2, 2.5])
def test_disk_centre_is_recovered(background_m):
    """A 5 cm disk facing the camera at 0.6 m: centre within 1 mm; background ignored.

    The image of a fronto-parallel disk is a disk centred on the projection of its centre, so
    the pixel centre of mass back-projected at the disk's depth is the centre itself (up to
    pixel quantization, far below 1 mm with ~1000 pixels). A wall at 1.2 m (within range,
    beyond the 250 mm cube) and one at 2.5 m (beyond max_depth_m) are both left out.
    """
    center = np.array([0.04, -0.03, 0.6])
    depth = _disk(ICVL, center, 0.05, background_m)
    est = CenterOfMassLocalizer().predict(depth, ICVL.K)
    assert est.valid and est.keypoints_cam is None
    assert np.linalg.norm(est.center_cam - center) < 1e-3


def test_sphere_centre_is_biased_to_its_visible_surface():
    """A sphere's estimate lies on the ray to its centre, at the median depth of its visible cap.

    Seen from distance ``D``, a sphere of radius ``r`` fills the image disk ``tan(phi) <=
    r / sqrt(D^2 - r^2)`` (``phi``: angle from the ray to the centre). Pixels are uniform in
    ``tan(phi)^2``, so the median pixel has ``tan(phi)^2`` half the maximum; its ray meets the
    sphere at ``t = D cos(phi) - sqrt(r^2 - D^2 sin(phi)^2)``, ``t cos(phi)`` along the centre
    ray: about ``r / sqrt(2)`` in front of the centre (2.4 mm more here, from perspective).
    This is the same surface bias that puts the estimate in front of a hand's joint centres.
    The 1 mm tolerance covers pixel quantization and the small shift of the image centroid of
    a sphere 4 deg off the optical axis (0.3 mm).
    """
    center, radius = np.array([-0.05, 0.02, 0.7]), 0.06
    est = CenterOfMassLocalizer().predict(_sphere(NYU, center, radius, 1.3), NYU.K)
    distance = np.linalg.norm(center)
    tan2_median = radius**2 / (distance**2 - radius**2) / 2
    cos_phi = 1 / np.sqrt(1 + tan2_median)
    t = distance * cos_phi - np.sqrt(radius**2 - distance**2 * (1 - cos_phi**2))
    expected = center / distance * t * cos_phi
    assert np.linalg.norm(est.center_cam - expected) < 1e-3
    assert distance - t * cos_phi == pytest.approx(radius / np.sqrt(2), abs=3e-3)


def test_nearer_surface_captures_the_estimate():
    """The documented failure: a surface nearer than the hand (more than a cube in front) wins."""
    hand = np.array([0.0, 0.0, 0.8])
    depth = _disk(ICVL, hand, 0.06)
    rays = _rays(ICVL)
    near = np.linalg.norm(rays[..., :2] * 0.4 - [0.1, 0.05], axis=-1) <= 0.03
    depth[near] = 0.4  # e.g. an object held toward the camera, 40 cm in front of the hand
    est = CenterOfMassLocalizer().predict(depth, ICVL.K)
    np.testing.assert_allclose(est.center_cam, [0.1, 0.05, 0.4], atol=1e-3)


def test_no_or_too_few_pixels_gives_an_invalid_estimate():
    """An empty image, only far pixels, or a blob under min_pixels: Estimate(valid=False)."""
    loc = CenterOfMassLocalizer(min_pixels=100)
    empty = np.zeros((ICVL.height, ICVL.width), np.float32)
    assert not loc.predict(empty, ICVL.K).valid
    assert not loc.predict(np.full_like(empty, 3.0), ICVL.K).valid  # beyond max_depth_m
    tiny = empty.copy()
    tiny[100:105, 100:105] = 0.5  # 25 pixels
    assert not loc.predict(tiny, ICVL.K).valid
    assert CenterOfMassLocalizer(min_pixels=20).predict(tiny, ICVL.K).valid


def test_batch_equals_single_predictions():
    """predict_batch gives the estimates of predict, in order."""
    depths = np.stack([_disk(ICVL, np.array([x, 0.0, 0.5]), 0.05, 1.5) for x in (-0.05, 0.0, 0.05)])
    loc = CenterOfMassLocalizer()
    batch = loc.predict_batch(depths, np.stack([ICVL.K] * 3))
    for est, depth in zip(batch, depths, strict=True):
        np.testing.assert_array_equal(est.center_cam, loc.predict(depth, ICVL.K).center_cam)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"cube_mm": 0}, r"cube_mm must be a finite number > 0; received 0"),
        ({"cube_mm": "big"}, r"cube_mm must be a number > 0; received 'big'"),
        ({"max_depth_m": -1.0}, r"max_depth_m must be a finite number > 0"),
        ({"min_pixels": 0}, r"min_pixels must be an int >= 1; received 0"),
        ({"min_pixels": 10.5}, r"min_pixels must be an int >= 1; received 10.5"),
        ({"max_iterations": True}, r"max_iterations must be an int >= 1; received True"),
    ],
)
def test_invalid_arguments_name_the_valid_range(kwargs, message):
    """Bad constructor arguments raise InvalidEstimatorParams."""
    with pytest.raises(InvalidEstimatorParams, match=message):
        CenterOfMassLocalizer(**kwargs)


def test_bad_input_is_rejected():
    """A NaN depth or a 3-D image raises InvalidEstimatorInput."""
    depth = np.zeros((4, 4), np.float32)
    depth[1, 2] = np.nan
    with pytest.raises(InvalidEstimatorInput, match=r"received nan at pixel \(v=1, u=2\)"):
        CenterOfMassLocalizer().predict(depth, ICVL.K)
    with pytest.raises(InvalidEstimatorInput, match=r"\(H, W\) image"):
        CenterOfMassLocalizer().predict(np.zeros((1, 4, 4)), ICVL.K)


# Rendered hands ----------------------------------------------------------------------------------

# Hand axes -> world: radial x -> +x, distal y -> +z (fingers up), palmar z -> -y (palm toward a
# camera on the -y side).
_FINGERS_UP = Rotation.from_matrix(np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T)
_TURNED = Rotation.from_euler("z", 180, degrees=True) * _FINGERS_UP  # back of the hand


def _render_hand(rotation: Rotation, forearm: bool):
    """A clean ICVL frame of an open right hand alone, 0.5 m in front of the camera."""
    from handsim.frame import FrameRenderer
    from handsim.hand.model import HandParams
    from handsim.hand.pose_sources import gesture
    from handsim.world.scene import CameraSpec, Scene, SceneSpec

    cam = CameraSpec.look_at("front", ICVL, (0.0, -0.5, 0.2), (0.0, 0.0, 0.2))
    scene = Scene(SceneSpec(hand=HandParams(forearm=forearm), cameras=(cam,), table=False))
    pose = gesture("open").replace(wrist_pos=(0.0, 0.0, 0.13), wrist_rotvec=rotation.as_rotvec())
    scene.reset(pose)
    with FrameRenderer(scene, "front") as renderer:
        return renderer.render(np.random.default_rng(0)), scene


@pytest.mark.parametrize("forearm", [True, False], ids=["forearm", "no_forearm"])
@pytest.mark.parametrize("rotation", [_FINGERS_UP, _TURNED], ids=["palm", "back"])
def test_open_hand_facing_the_camera(rotation, forearm):
    """An open hand alone at 0.5 m: centre error < 30 mm, surface bias within a palm thickness.

    The CoM sees skin, not joints, so its error against hand_center has two parts:

    - depth: the visible palm / back skin is one palm half-thickness ``t / 2`` (13.5 mm for
      the default hand) in front of the wrist and MCP centres, and the thinner fingers less;
      so the estimate is in front (``dz < 0``) by at most ``t / 2`` plus ~1 mm of pixels;
    - in the image plane: the pixel centroid is pulled distally by the fingers and
      proximally by the forearm stub (the part of it inside the 250 mm cube); for an open hand
      these nearly balance and leave ~0.1 hand lengths (~19 mm) along the hand's axis.

    Together about sqrt(13.5^2 + 19^2) = 23 mm; measured 17-22 mm. The 30 mm bound adds
    margin for hand-model changes and is far below the errors of a real defect (a wrong
    back-projection, units or axis is off by 100 mm or more). Posture matters: a fist with
    the forearm stub is ~65 mm off, as the forearm then outweighs the hand (see the module
    docstring of handsim.estimators.com).
    """
    frame, scene = _render_hand(rotation, forearm)
    est = CenterOfMassLocalizer().predict(frame.depth, frame.K)
    offset_mm = (est.center_cam - hand_center(frame.keypoints_cam)) * 1000
    assert np.linalg.norm(offset_mm) < 30.0, offset_mm
    # The palm box's z half size (as handsim.frame's keypoint radii take it).
    palm = next(b for b in scene.hand.skeleton.bodies if b.part == "palm")
    palm_half_thickness_mm = max(g.half_size[2] for g in palm.geoms if hasattr(g, "half_size"))
    palm_half_thickness_mm *= 1000
    assert -(palm_half_thickness_mm + 1.0) < offset_mm[2] < 0.0, offset_mm


def test_hand_alone_is_segmented_exactly_from_depth():
    """Without a forearm the hand fits the cube: its CoM from depth equals the mask's CoM.

    So the depth-only segmentation (nearest slab, then the cube) keeps exactly the hand's
    pixels when the hand is alone; the errors of the test above are the method's, not bugs.
    """
    from handsim.world.scene import SEGMENT_LABELS

    frame, _ = _render_hand(_FINGERS_UP, forearm=False)
    hand = (frame.segmentation >= SEGMENT_LABELS.index("palm")) & (frame.depth > 0)
    v, u = np.nonzero(hand)
    mask_com = np.linalg.solve(frame.K, [u.mean(), v.mean(), 1.0]) * np.median(frame.depth[hand])
    est = CenterOfMassLocalizer().predict(frame.depth, frame.K)
    assert np.linalg.norm(est.center_cam - mask_com) < 1e-4


def _ref_localize(depth_m, K_cv, cube_m=0.25, max_depth_m=1.5, min_pixels=100):  # noqa: N803
    """The centre of mass as first written (np.linalg.solve, (N, 3) points): the reference."""

    def com(u, v, z, keep):
        if np.count_nonzero(keep) < min_pixels:
            return None
        pixel = np.array([u[keep].mean(), v[keep].mean(), 1.0])
        return np.linalg.solve(K_cv, pixel) * float(np.median(z[keep]))

    measured = (depth_m > 0) & (depth_m <= max_depth_m)
    if np.count_nonzero(measured) < min_pixels:
        return None
    keep = measured & (depth_m <= float(depth_m[measured].min()) + cube_m)
    v, u = np.nonzero(measured)
    z = depth_m[v, u].astype(np.float64)
    rays = np.linalg.solve(K_cv, np.stack([u, v, np.ones_like(u)]).astype(float))
    points = (rays * z).T
    center = com(u, v, z, keep[v, u])
    for _ in range(10):
        if center is None:
            return None
        new = com(u, v, z, np.all(np.abs(points - center) <= cube_m / 2, axis=1))
        if new is not None and np.linalg.norm(new - center) < 1e-4:
            return new
        center = new
    return center


def test_the_fast_centre_of_mass_equals_the_reference():
    """K^-1 products and in-place cube tests give the reference's centres to float rounding."""
    rng = np.random.default_rng(11)
    loc = CenterOfMassLocalizer()
    K = ICVL.K.copy()  # noqa: N806
    K[0, 1] = 0.5  # with skew
    for i in range(12):
        center = rng.normal([0.0, 0.0, 0.6], [0.05, 0.05, 0.15])
        depth = _sphere(ICVL, center, rng.uniform(0.03, 0.09), rng.choice([0.0, 1.2, 2.0]))
        depth += rng.normal(0, 0.004, depth.shape).astype(np.float32) * (depth > 0)
        depth[rng.random(depth.shape) < 0.1] = 0
        if i % 3 == 0:  # a nearer object beside the sphere
            depth[:40, :60] = center[2] - 0.1
        for k in (ICVL.K, K):
            expected = _ref_localize(depth, k)
            got = loc.localize(depth, k)
            assert (got is None) == (expected is None)
            if expected is not None:
                np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
