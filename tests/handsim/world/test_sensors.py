"""Depth-sensor noise models against analytic expectations."""

import numpy as np
import pytest

from handsim.errors import UnknownName
from handsim.world.camera import camera_preset
from handsim.world.sensors import (
    Compose,
    InvalidSensor,
    NoNoise,
    StructuredLight,
    TimeOfFlight,
    incidence_angle,
    nguyen_sigma_z,
    sensor_model,
)

NYU = camera_preset("nyu_carmine")
ICVL = camera_preset("icvl")


def _plane(intrinsics, z):
    return np.full((intrinsics.height, intrinsics.width), z, dtype=np.float32)


@pytest.mark.parametrize("z", [0.5, 1.0])
def test_structured_light_noise_matches_nguyen(z):
    """On a fronto-parallel plane the depth std equals Nguyen's sigma_z within 10 %."""
    clean = _plane(NYU, z)
    noisy = StructuredLight().apply(clean, NYU, np.random.default_rng(0))
    # Central pixels: the viewing ray is within ~10 deg of the plane normal.
    crop = (slice(190, 290), slice(240, 400))
    errors = (noisy[crop] - clean[crop]).ravel()
    incidence = incidence_angle(clean, NYU)[crop]
    expected = float(np.mean(nguyen_sigma_z(z, incidence)))
    assert np.all(noisy[crop] > 0)
    assert abs(errors.mean()) < 0.2 * expected
    assert errors.std() == pytest.approx(expected, rel=0.10)


def test_nguyen_values():
    """sigma_z is 1.2 mm at 0.5 m, 1.9 mm at 1 m, 3.5 mm at 1.5 m at normal incidence."""
    np.testing.assert_allclose(
        nguyen_sigma_z(np.array([0.5, 1.0, 1.5])), [0.001219, 0.001884, 0.003499], atol=1e-6
    )
    assert nguyen_sigma_z(1.0, np.deg2rad(60)) > nguyen_sigma_z(1.0, 0.0)


def test_projector_shadow_band_is_on_the_minus_x_side_with_the_predicted_width():
    """A box at 0.6 m before a wall at 1.0 m casts a fx b (1/0.6 - 1/1.0) px shadow on its left."""
    depth = _plane(NYU, 1.0)
    depth[200:280, 300:380] = 0.6
    sensor = StructuredLight(lateral_jitter_px=0.0)
    noisy = sensor.apply(depth, NYU, np.random.default_rng(1))
    row = noisy[240]
    width = NYU.fx * sensor.baseline_m * (1 / 0.6 - 1 / 1.0)
    shadow = np.nonzero(row == 0)[0]
    assert shadow.size == pytest.approx(width, abs=2)
    assert shadow.max() < 300 and shadow.min() > 300 - width - 3  # left of the box
    assert np.all(row[380:600] > 0)  # nothing on the right side


def test_grazing_surfaces_are_dropped():
    """A plane seen at 80 deg incidence is dropped; one at 30 deg is kept."""
    v, u = np.indices((NYU.height, NYU.width))

    def tilted(angle_deg):
        # Plane through (0, 0, 1) m whose normal is tilted about the camera's y axis.
        t = np.tan(np.deg2rad(angle_deg))
        denominator = 1.0 + t * (u - NYU.cx) / NYU.fx
        # Rays that never meet the plane see nothing.
        depth = np.where(denominator > 0.1, 1.0 / np.maximum(denominator, 0.1), 0.0)
        return depth.astype(np.float32)

    sensor = StructuredLight(lateral_jitter_px=0.0)
    centre = (slice(200, 280), slice(300, 340))
    steep = sensor.apply(tilted(80.0), NYU, np.random.default_rng(2))
    mild = sensor.apply(tilted(30.0), NYU, np.random.default_rng(2))
    assert np.mean(steep[centre] == 0) > 0.95
    assert np.mean(mild[centre] == 0) < 0.01


@pytest.mark.parametrize("limit_deg", [45.0, 60.0, 75.0])
def test_the_dropout_keeps_exactly_the_pixels_incidence_angle_allows(limit_deg):
    """The compiled dropout computes the normals :func:`incidence_angle` (NumPy) does.

    Random boxes and slopes, no jitter or shadow: a pixel keeps depth iff it has depth and its
    incidence angle is within the limit (pixels within 1e-4 rad of the limit not compared).
    """
    rng = np.random.default_rng(11)
    v, u = np.indices((ICVL.height, ICVL.width))
    depth = np.zeros((ICVL.height, ICVL.width))
    for _ in range(12):
        r, c = rng.integers(0, ICVL.height - 40), rng.integers(0, ICVL.width - 60)
        slope_u, slope_v = rng.uniform(-0.01, 0.01, 2)  # m per pixel
        box = (slice(r, r + rng.integers(10, 40)), slice(c, c + rng.integers(10, 60)))
        depth[box] = rng.uniform(0.8, 1.5) + slope_u * (u[box] - c) + slope_v * (v[box] - r)
    depth = depth.astype(np.float32)
    sensor = StructuredLight(lateral_jitter_px=0.0, shadow=False, max_incidence_deg=limit_deg)
    out = sensor.apply(depth, ICVL, np.random.default_rng(0))
    angle = incidence_angle(depth, ICVL)
    limit = np.deg2rad(limit_deg)
    compared = np.abs(angle - limit) > 1e-4
    expected = (depth > 0) & (angle <= limit)
    assert np.count_nonzero(expected) > 1000 and np.count_nonzero(~expected & (depth > 0)) > 100
    np.testing.assert_array_equal((out > 0)[compared], expected[compared])


def test_range_limits_and_missing_depth_stay_missing():
    """Depth beyond the range and pixels without depth come out as 0."""
    depth = _plane(NYU, 5.0)
    depth[:, :100] = 0.0
    out = StructuredLight().apply(depth, NYU, np.random.default_rng(3))
    assert np.all(out == 0)


def test_models_are_seeded_pure_and_float32():
    """Same seed, same output; the clean input is untouched; outputs are float32."""
    clean = _plane(ICVL, 0.5)
    clean[100:140, 150:170] = 0.4
    before = clean.copy()
    for model in (NoNoise(), StructuredLight(), TimeOfFlight()):
        a = model.apply(clean, ICVL, np.random.default_rng(7))
        b = model.apply(clean, ICVL, np.random.default_rng(7))
        np.testing.assert_array_equal(a, b)
        assert a.dtype == np.float32
        np.testing.assert_array_equal(clean, before)


def test_tof_flying_pixels_only_at_edges():
    """ToF pixels between the two surfaces appear only next to the depth edge."""
    depth = _plane(ICVL, 0.8)
    depth[:, :160] = 0.4
    sensor = TimeOfFlight(sigma_m=0.0, dropout_prob=0.0, flying_pixel_prob=1.0)
    out = sensor.apply(depth, ICVL, np.random.default_rng(4))
    between = (out > 0.41) & (out < 0.79)
    cols = np.unique(np.nonzero(between)[1])
    assert cols.size > 0 and set(cols.tolist()) <= {159}
    assert np.all(out[:, :159] == pytest.approx(0.4)) and np.all(out[:, 161:] == pytest.approx(0.8))


def test_tof_noise_and_dropouts():
    """ToF axial noise has its sigma; dropouts remove about their probability of pixels."""
    clean = _plane(ICVL, 0.5)
    out = TimeOfFlight(sigma_m=0.003, dropout_prob=0.05).apply(
        clean, ICVL, np.random.default_rng(5)
    )
    kept = out > 0
    assert np.mean(~kept) == pytest.approx(0.05, abs=0.01)
    assert (out[kept] - 0.5).std() == pytest.approx(0.003, rel=0.05)


def test_compose_applies_in_order():
    """Compose of none and ToF equals ToF alone with the same seed."""
    clean = _plane(ICVL, 0.5)
    tof = TimeOfFlight()
    a = Compose([NoNoise(), tof]).apply(clean, ICVL, np.random.default_rng(6))
    b = tof.apply(clean, ICVL, np.random.default_rng(6))
    np.testing.assert_array_equal(a, b)


def test_errors():
    """Bad parameters, shapes and names say what is expected."""
    with pytest.raises(UnknownName, match=r"unknown sensor model 'lidar'; valid models: none"):
        sensor_model("lidar")
    assert isinstance(sensor_model("tof", sigma_m=0.001), TimeOfFlight)
    with pytest.raises(InvalidSensor, match=r"baseline_m must be a positive number"):
        StructuredLight(baseline_m=0.0)
    with pytest.raises(InvalidSensor, match=r"need 0 <= min_range_m < max_range_m"):
        StructuredLight(min_range_m=2.0, max_range_m=1.0)
    with pytest.raises(InvalidSensor, match=r"dropout_prob must be a probability in \[0, 1\]"):
        TimeOfFlight(dropout_prob=1.5)
    with pytest.raises(InvalidSensor, match=r"max_incidence_deg must be in \(0, 90\]"):
        StructuredLight(max_incidence_deg=120.0)
    with pytest.raises(InvalidSensor, match=r"shape \(H, W\) = \(240, 320\).*received \(10, 10\)"):
        NoNoise().apply(np.zeros((10, 10)), ICVL, np.random.default_rng())
    with pytest.raises(InvalidSensor, match=r"finite and >= 0 m"):
        NoNoise().apply(np.full((240, 320), np.nan), ICVL, np.random.default_rng())
    for bad in (np.nan, np.inf, -0.5):  # one pixel anywhere, among valid depth
        depth = np.zeros((240, 320), dtype=np.float32)
        depth[100:140, 100:140] = 0.8
        depth[239, 0] = bad
        for model in (StructuredLight(), TimeOfFlight()):
            with pytest.raises(InvalidSensor, match=r"finite and >= 0 m"):
                model.apply(depth, ICVL, np.random.default_rng())
    with pytest.raises(InvalidSensor, match=r"shape \(H, W\) = \(240, 320\)"):
        StructuredLight().apply(np.zeros((240, 321)), ICVL, np.random.default_rng())


def _scan_from_the_right(depth, intrinsics, baseline_m):
    """Reference projector-shadow mask, a Python scan of the definition.

    A pixel is lit iff its projector column is left of every column claimed to its right.
    """
    fb = intrinsics.fx * baseline_m
    lit = np.zeros(depth.shape, dtype=bool)
    for v in range(depth.shape[0]):
        smallest = np.inf
        for u in range(depth.shape[1] - 1, -1, -1):
            z = float(depth[v, u])
            col = u - fb / z if z > 0 else np.inf
            lit[v, u] = z > 0 and col < smallest
            smallest = min(smallest, col)
    return lit


def test_projector_shadow_equals_the_scan_from_the_right():
    """Random boxes and holes: the dropped pixels are exactly those the scan leaves unlit."""
    rng = np.random.default_rng(8)
    depth = np.full((ICVL.height, ICVL.width), 1.8, dtype=np.float32)
    for _ in range(25):
        v, u = rng.integers(0, ICVL.height - 20), rng.integers(0, ICVL.width - 30)
        hh, ww = rng.integers(3, 40), rng.integers(2, 60)
        depth[v : v + hh, u : u + ww] = rng.choice([0.0, rng.uniform(0.4, 1.7)])
    sensor = StructuredLight(lateral_jitter_px=0.0, max_incidence_deg=90.0)
    out = sensor.apply(depth, ICVL, np.random.default_rng(0))
    np.testing.assert_array_equal(out > 0, _scan_from_the_right(depth, ICVL, sensor.baseline_m))


@pytest.mark.parametrize("sigma", [0.5, 3.0])
def test_jitter_displacements_are_rounded_gaussians(sigma):
    """Lateral-jitter offsets follow rint(N(0, s)) on each axis, independently.

    Both samplers: the table (0.5 px) and the wide jitter (3 px); offsets stay within the image.
    """
    from scipy.stats import norm

    from handsim.world.sensors import _jitter_offsets, _Scratch

    rng = np.random.default_rng(9)
    out = np.empty((240, 320, 2), dtype=np.int16)
    scratch = _Scratch()
    draws = np.concatenate(
        [_jitter_offsets(rng, sigma, out, scratch).reshape(-1, 2).copy() for _ in range(5)]
    )
    assert np.abs(draws).max() <= 320
    k = np.arange(-3, 4) if sigma < 1 else np.arange(-6, 7)
    expected = norm.cdf((k + 0.5) / sigma) - norm.cdf((k - 0.5) / sigma)
    for axis in (0, 1):
        freq = np.array([np.mean(draws[:, axis] == j) for j in k])
        tolerance = 5 * np.sqrt(expected * (1 - expected) / len(draws)) + 1e-6
        assert np.all(np.abs(freq - expected) <= tolerance)
    both_zero = np.mean((draws[:, 0] == 0) & (draws[:, 1] == 0))
    p0 = expected[k == 0][0]
    assert both_zero == pytest.approx(p0 * p0, abs=5 * np.sqrt(p0 * p0 / len(draws)))


def test_incidence_angle_matches_the_cross_product_of_central_differences():
    """The closed-form incidence equals the cross product of the points' central differences.

    Also no normal across depth edges and holes, as in the explicit computation.
    """
    v, u = np.indices((NYU.height, NYU.width))
    # A sphere of radius 0.3 m centred 1 m in front of the camera, on a wall at 1.5 m.
    x, y = (u - NYU.cx) / NYU.fx, (v - NYU.cy) / NYU.fy
    a, b, c = x * x + y * y + 1.0, -2.0, 1.0 - 0.3**2
    disc = b * b - 4 * a * c
    depth = np.where(disc > 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), 1.5)
    depth[100:110, 400:420] = 0.0
    points = NYU.backproject(depth)
    du = np.zeros_like(points)
    dv = np.zeros_like(points)
    du[:, 1:-1] = points[:, 2:] - points[:, :-2]
    dv[1:-1] = points[2:] - points[:-2]
    normal = np.cross(du, dv)
    cos = np.abs(np.sum(normal * points, axis=-1)) / np.maximum(
        np.linalg.norm(normal, axis=-1) * np.linalg.norm(points, axis=-1), 1e-12
    )
    reference = np.arccos(np.clip(cos, 0.0, 1.0))
    ok = np.zeros(depth.shape, dtype=bool)
    centre = depth[1:-1, 1:-1]
    ok[1:-1, 1:-1] = centre > 0
    for neighbour in (depth[2:, 1:-1], depth[:-2, 1:-1], depth[1:-1, 2:], depth[1:-1, :-2]):
        ok[1:-1, 1:-1] &= (neighbour > 0) & (np.abs(neighbour - centre) <= 0.05 * centre)
    reference = np.where(ok, reference, 0.0)
    np.testing.assert_allclose(incidence_angle(depth, NYU), reference, atol=1e-9)
    assert np.any(reference > np.deg2rad(75))  # the sphere's rim is grazing


def test_inputs_are_copied_to_fresh_float32_outputs():
    """Every model returns a new writable float32 array and leaves its input untouched.

    float64, read-only and non-contiguous inputs are accepted (an empty Compose too); the output
    shares no memory with them and is the same for the same values in float32 or float64.
    """
    clean64 = np.full((ICVL.height, ICVL.width), 0.5)
    clean64[60:120, 100:180] = 0.45
    read_only = clean64.astype(np.float32)
    read_only.setflags(write=False)
    strided = np.asfortranarray(clean64)
    for model in (NoNoise(), StructuredLight(), TimeOfFlight(), Compose([])):
        outputs = []
        for clean in (clean64, read_only, strided):
            before = clean.copy()
            out = model.apply(clean, ICVL, np.random.default_rng(3))
            assert out.dtype == np.float32 and out.flags.c_contiguous and out.flags.writeable
            assert not np.shares_memory(out, clean)
            np.testing.assert_array_equal(clean, before)
            outputs.append(out)
        for out in outputs[1:]:
            np.testing.assert_array_equal(out, outputs[0])


def test_models_give_the_same_output_from_several_threads():
    """Concurrent calls (each thread has its own scratch arrays) equal sequential ones."""
    from concurrent.futures import ThreadPoolExecutor

    clean = _plane(NYU, 0.8)
    clean[150:300, 200:400] = 0.6
    jobs = [(model, seed) for model in (StructuredLight(), TimeOfFlight()) for seed in range(6)]

    def run(job):
        model, seed = job
        return model.apply(clean, NYU, np.random.default_rng(seed))

    sequential = [run(job) for job in jobs]
    with ThreadPoolExecutor(max_workers=4) as pool:
        concurrent = list(pool.map(run, jobs))
    for a, b in zip(sequential, concurrent, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("probability", [0.02, 0.3])
def test_tof_dropout_rate(probability):
    """Dropouts remove about their probability of pixels and leave the others unchanged.

    Small probabilities are sampled as a binomial count of distinct pixels, large ones with a
    uniform per pixel.
    """
    clean = _plane(ICVL, 0.5)
    out = TimeOfFlight(sigma_m=0.0, dropout_prob=probability).apply(
        clean, ICVL, np.random.default_rng(10)
    )
    assert np.mean(out == 0) == pytest.approx(probability, abs=0.01)
    assert np.all((out == 0) | np.isclose(out, 0.5))


@pytest.mark.parametrize("name", ["structured_light", "tof", "none"])
def test_apply_refuses_a_preset_name_a_bare_k_or_no_generator(name):
    """Every model: intrinsics that are not CameraIntrinsics, rng None, a boolean image."""
    intr = camera_preset("icvl")
    depth = np.full((intr.height, intr.width), 0.5, np.float32)
    model = sensor_model(name)
    rng = np.random.default_rng(0)
    with pytest.raises(InvalidSensor, match=r"intrinsics must be a CameraIntrinsics .*str"):
        model.apply(depth, "icvl", rng)
    with pytest.raises(InvalidSensor, match=r"intrinsics must be a CameraIntrinsics .*ndarray"):
        model.apply(depth, intr.K, rng)
    if name != "none":  # the clean model draws nothing
        with pytest.raises(InvalidSensor, match=r"rng must be a numpy.random.Generator .*None"):
            model.apply(depth, intr, None)
    with pytest.raises(InvalidSensor, match=r"depth must be real numbers in metres; .*bool"):
        model.apply(depth > 0, intr, rng)
