"""DeepPrior preprocessing: plane removal, blob CoM, crop round trips, exact augmentation, PCA."""

import math

import numpy as np
import pytest

from handsim.estimators.deepprior import preprocess as P

K = np.array([[240.0, 0.0, 160.0], [0.0, 240.0, 120.0], [0.0, 0.0, 1.0]])
H, W = 240, 320


def _project(points):
    return np.stack(
        [
            K[0, 0] * points[:, 0] / points[:, 2] + K[0, 2],
            K[1, 1] * points[:, 1] / points[:, 2] + K[1, 2],
        ],
        axis=1,
    )


def _table_and_box(table_z=0.8, tilt=0.3, box_center=(0.02, -0.01, 0.55), half=0.03):
    """A tilted table plane and a box (the 'hand') in front of it."""
    v, u = np.mgrid[0:H, 0:W].astype(float)
    rx, ry = (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]
    # Plane z = table_z + tilt * y  ->  z = table_z / (1 - tilt * ry)
    depth = (table_z / (1.0 - tilt * ry)).astype(np.float32)
    cx, cy, cz = box_center
    f = K[0, 0] * half / cz
    uc, vc = K[0, 2] + K[0, 0] * cx / cz, K[1, 2] + K[1, 1] * cy / cz
    inside = (np.abs(u - uc) <= f) & (np.abs(v - vc) <= f)
    depth[inside] = cz
    return depth, np.array(box_center), rx


def test_plane_removal_keeps_the_hand_and_drops_the_table():
    """RANSAC removes the table; the nearest-blob CoM lands on the box, not the table."""
    depth, center, _ = _table_and_box()
    cleaned = P.remove_plane(depth, K)
    assert np.all(cleaned[depth == np.float32(0.55)] > 0)
    assert np.count_nonzero(cleaned) == np.count_nonzero(depth == np.float32(0.55))
    com = P.nearest_blob_com(cleaned, K)
    np.testing.assert_allclose(com, center, atol=2e-3)


def test_plane_removal_leaves_a_hand_alone_in_view():
    """A small flat patch alone in view (a palm) is not removed as a 'plane' (spread test)."""
    depth, _, _ = _table_and_box()
    depth[depth != np.float32(0.55)] = 0
    cleaned = P.remove_plane(depth, K)
    np.testing.assert_array_equal(cleaned, depth)


def test_localizer_without_a_blob_is_invalid():
    """An empty depth image gives Estimate(valid=False)."""
    est = P.PlaneRemovedLocalizer().predict(np.zeros((H, W), np.float32), K)
    assert not est.valid


def test_normalize_round_trip():
    """denormalize(normalize(p)) == p, for batches and single frames."""
    rng = np.random.default_rng(0)
    kp = rng.normal([0, 0, 0.5], 0.05, size=(4, 21, 3))
    c = rng.normal([0, 0, 0.5], 0.01, size=(4, 3))
    cube = np.array([0.25, 0.3, 0.2, 0.25])
    norm = np.stack([P.normalize_keypoints(kp[i], c[i], cube[i]) for i in range(4)])
    np.testing.assert_allclose(P.denormalize_keypoints(norm, c, cube), kp, atol=1e-12)
    one = P.normalize_keypoints(kp[0], c[0], 0.25)
    np.testing.assert_allclose(P.denormalize_keypoints(one, c[0], 0.25), kp[0], atol=1e-12)


def test_crop_maps_the_cube_onto_the_crop_and_back():
    """The cube's face projects onto the crop's border; the inverse map returns image pixels."""
    c = np.array([0.03, -0.02, 0.5])
    M = P.crop_matrix(c, K, 0.25, 128)
    corners = np.array([[c[0] - 0.125, c[1] - 0.125, c[2]], [c[0] + 0.125, c[1] + 0.125, c[2]]])
    px = P.crop_pixels(corners, K, M)
    np.testing.assert_allclose(px[1] - px[0], [128.0, 128.0], atol=1e-9)
    np.testing.assert_allclose(P.crop_pixels(c[None], K, M)[0], [63.5, 63.5], atol=1e-9)
    inv = np.vstack([np.linalg.inv(np.vstack([M, [0, 0, 1]]))[:2]])
    uv = _project(corners)
    back = px @ inv[:, :2].T + inv[:, 2]
    np.testing.assert_allclose(back, uv, atol=1e-9)


def test_crop_depth_normalization_and_missing_values():
    """(d - z_c) / (cube / 2); missing and far -> +1, near -> -1."""
    depth = np.zeros((H, W), np.float32)
    c = np.array([0.0, 0.0, 0.5])
    depth[100:140, 140:180] = 0.55
    depth[110:120, 150:160] = 0.30  # nearer than the cube: -1
    depth[125:130, 165:170] = 0.90  # beyond the cube: +1
    M = P.crop_matrix(c, K, 0.25, 128)
    crop = P.crop_depth(depth, M, 0.5, 0.25, 128)
    assert crop.dtype == np.float32 and crop.shape == (128, 128)
    assert crop.min() == -1.0 and crop.max() == 1.0
    allowed = np.array([-1.0, 1.0, (0.55 - 0.5) / 0.125])
    values = np.unique(crop)
    assert np.all(np.isclose(values[:, None], allowed[None], atol=1e-6).any(axis=1)), values
    assert crop[0, 0] == 1.0  # missing


@pytest.mark.parametrize("angle_deg", [0.0, 37.0, -120.0, 180.0])
@pytest.mark.parametrize("scale", [1.0, 1.05])
def test_augmentation_labels_are_exact(angle_deg, scale):
    """Each keypoint, drawn as a depth blob, lands where its transformed label says.

    The crop pixel of the transformed label (its normalized x, y projected) holds the
    normalized depth of the label's z.
    """
    rng = np.random.default_rng(1)
    center = np.array([0.02, 0.01, 0.5])
    kp = center + rng.uniform(-0.07, 0.07, size=(21, 3))
    depth = np.zeros((H, W), np.float32)
    uv = np.rint(_project(kp)).astype(int)
    kp_snapped = np.stack(
        [
            (uv[:, 0] - K[0, 2]) * kp[:, 2] / K[0, 0],
            (uv[:, 1] - K[1, 2]) * kp[:, 2] / K[1, 1],
            kp[:, 2],
        ],
        axis=1,
    )
    for (u, v), z in zip(uv, kp[:, 2], strict=True):
        depth[v - 1 : v + 2, u - 1 : u + 2] = z
    params = P.AugmentParams(math.radians(angle_deg), scale, (0.004, -0.003, 0.006))
    crop, labels, c, cube = P.augment(depth, K, kp_snapped, center, params)
    assert cube == pytest.approx(0.25 * scale)
    np.testing.assert_allclose(c, center + [0.004, -0.003, 0.006])
    rotated = P.denormalize_keypoints(labels, c, cube)
    M = P.crop_matrix(c, K, cube, 128, params.angle_rad)
    px = P.crop_pixels(kp_snapped, K, M)
    px_labels = P.crop_pixels(rotated, K, P.crop_matrix(c, K, cube, 128))
    np.testing.assert_allclose(px_labels, px, atol=1e-9)  # the label follows the image
    for (x, y), label in zip(px, labels, strict=True):
        xi, yi = int(round(x)), int(round(y))
        if 0 <= xi < 128 and 0 <= yi < 128:
            assert crop[yi, xi] == pytest.approx(label[2], abs=1e-5)


def test_rotation_by_zero_is_identity_and_full_turn_returns():
    """Rotation by 0 and by 2 pi is the identity; +a then -a returns."""
    rng = np.random.default_rng(2)
    kp = rng.normal([0, 0, 0.5], 0.04, size=(21, 3))
    c = kp[9]
    np.testing.assert_allclose(P.rotate_keypoints(kp, K, c, 0.0), kp, atol=1e-12)
    np.testing.assert_allclose(P.rotate_keypoints(kp, K, c, 2 * math.pi), kp, atol=1e-12)
    half = P.rotate_keypoints(P.rotate_keypoints(kp, K, c, 1.0), K, c, -1.0)
    np.testing.assert_allclose(half, kp, atol=1e-12)


def test_sample_augmentation_respects_flags_and_ranges():
    """Disabled augmentations draw nothing; the others follow their distributions."""
    rng = np.random.default_rng(3)
    off = P.sample_augmentation(rng, rotation=False, scale=False, translation=False)
    assert off == P.AugmentParams()
    draws = [P.sample_augmentation(rng) for _ in range(500)]
    angles = np.array([d.angle_rad for d in draws])
    assert angles.min() >= -math.pi and angles.max() <= math.pi
    assert np.std([d.scale for d in draws]) == pytest.approx(0.02, rel=0.2)
    assert np.std([d.offset_m for d in draws]) == pytest.approx(0.005, rel=0.2)


def test_pca_is_not_whitened_and_reconstructs():
    """Components are orthonormal, the explained ratios sum to 1, full rank reconstructs."""
    rng = np.random.default_rng(4)
    X = rng.normal(size=(200, 10)) @ rng.normal(size=(10, 10))
    pca = P.fit_pca(X, 10)
    comp = pca["components"]
    np.testing.assert_allclose(comp @ comp.T, np.eye(10), atol=1e-10)
    assert pca["explained"].sum() == pytest.approx(1.0)
    assert np.all(np.diff(pca["explained"]) <= 1e-12)
    coeffs = (X - pca["mean"]) @ comp.T
    np.testing.assert_allclose(coeffs @ comp + pca["mean"], X, atol=1e-9)
    # Not whitened: the coefficients' variances are the eigenvalues, not 1.
    assert not np.allclose(coeffs.var(axis=0), 1.0, atol=0.1)


# The localization and crop before they were made faster (in place, OpenCV passes): the
# reference the fast versions must equal (bit for bit where no arithmetic was reordered).


def _ref_remove_plane(depth_m, K, threshold_m=0.008, min_fraction=0.2, min_spread_m=0.06):  # noqa: N803
    out = np.where((depth_m > 0) & (depth_m <= 1.5), depth_m, 0).astype(np.float32)
    v, u = np.nonzero(out[::2, ::2])
    if len(v) < 3:
        return out
    v, u = 2 * v, 2 * u
    z = out[v, u].astype(np.float64)
    pts = np.stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z], axis=1)
    rng = np.random.default_rng(0)
    sub = pts[rng.integers(0, len(pts), size=min(1024, len(pts)))]
    tri = pts[rng.integers(0, len(pts), size=(64, 3))]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(normals, axis=1)
    ok = norm > 1e-12
    if not np.any(ok):
        return out
    normals = normals[ok] / norm[ok, None]
    offsets = -np.einsum("hk,hk->h", normals, tri[ok, 0])
    best = int(np.argmax((np.abs(sub @ normals.T + offsets) < threshold_m).sum(axis=0)))
    n, d = normals[best], offsets[best]
    inl = np.abs(pts @ n + d) < threshold_m
    if np.count_nonzero(inl) >= 3:
        q = pts[inl]
        n = np.linalg.svd(q - q.mean(axis=0), full_matrices=False)[2][-1]
        d = -float(n @ q.mean(axis=0))
        inl = np.abs(pts @ n + d) < threshold_m
    if np.count_nonzero(inl) < min_fraction * len(pts):
        return out
    s = pts[inl][:: max(1, np.count_nonzero(inl) // 2000)]
    if np.linalg.svd(s - s.mean(axis=0), compute_uv=False)[1] / math.sqrt(len(s)) < min_spread_m:
        return out
    n, d = (n, d) if d >= 0 else (-n, -d)
    h, w = out.shape
    ray_dot = (
        n[0] * (np.arange(w) - K[0, 2]) / K[0, 0]
        + (n[1] * (np.arange(h) - K[1, 2]) / K[1, 1])[:, None]
        + n[2]
    )
    out[(out * ray_dot + d < threshold_m) & (out > 0)] = 0
    return out


def _ref_nearest_blob_com(depth_m, K, cube_m=0.25, min_pixels=100):  # noqa: N803
    import cv2

    measured = depth_m > 0
    if np.count_nonzero(measured) < min_pixels:
        return None
    slab = measured & (depth_m <= float(depth_m[measured].min()) + cube_m)
    n, labels = cv2.connectedComponents(slab.astype(np.uint8), connectivity=8)
    sizes = np.bincount(labels[slab], minlength=n)
    sizes[0] = 0
    if n <= 1 or sizes.max() < min_pixels:
        return None
    v, u = np.nonzero(labels == int(np.argmax(sizes)))
    z = float(np.median(depth_m[v, u]))
    return np.array([(u.mean() - K[0, 2]) * z / K[0, 0], (v.mean() - K[1, 2]) * z / K[1, 1], z])


def _scenes():
    """Depth images that take every branch: tables (removed), palms alone, noise, blobs."""
    rng = np.random.default_rng(7)
    for tilt, z in ((0.3, 0.8), (-0.2, 0.7), (0.0, 1.2)):
        depth, _, _ = _table_and_box(table_z=z, tilt=tilt)
        yield depth
        noisy = depth + rng.normal(0, 0.003, depth.shape).astype(np.float32)
        noisy[rng.random(depth.shape) < 0.2] = 0
        yield noisy
        alone = depth.copy()
        alone[depth != np.float32(0.55)] = 0
        yield alone
    for _ in range(4):  # blobs of equal and different sizes at random depths, specks
        depth = np.zeros((H, W), np.float32)
        for _ in range(rng.integers(1, 5)):
            v, u = rng.integers(0, H - 30), rng.integers(0, W - 30)
            s = rng.integers(5, 30)
            depth[v : v + s, u : u + s] = rng.uniform(0.3, 1.0)
        depth[rng.random(depth.shape) < 0.002] = rng.uniform(0.2, 1.4)
        yield depth
    odd = rng.uniform(-0.5, 2.0, (H, W)).astype(np.float32)  # out of range, NaN, inf, -0
    for value, fraction in ((0.0, 0.3), (np.nan, 0.01), (np.inf, 0.01), (1.5, 0.01), (-0.0, 0.01)):
        odd[rng.random(odd.shape) < fraction] = value
    yield odd
    yield np.zeros((H, W), np.float32)
    # The work is done on the measured pixels' bounding box: boxes at odd rows and columns,
    # on the image's borders and corners, one pixel wide, and tables cut by them.
    for rows, cols in (
        ((1, 36), (3, 40)),
        ((0, 20), (0, 20)),
        ((H - 17, H), (W - 31, W)),
        ((101, 102), (7, 300)),
        ((5, 235), (161, 162)),
    ):
        depth = np.zeros((H, W), np.float32)
        depth[rows[0] : rows[1], cols[0] : cols[1]] = rng.uniform(0.4, 0.6)
        yield depth
    table, _, _ = _table_and_box()
    for rows, cols in (((3, 201), (5, 317)), ((40, H), (0, 255))):
        cut = np.zeros_like(table)
        cut[rows[0] : rows[1], cols[0] : cols[1]] = table[rows[0] : rows[1], cols[0] : cols[1]]
        yield cut


def test_fast_plane_removal_and_blob_equal_the_reference_bit_for_bit():
    """remove_plane and nearest_blob_com give exactly the reference's results."""
    for i, depth in enumerate(_scenes()):
        cleaned = P.remove_plane(depth, K)
        expected = _ref_remove_plane(depth, K)
        np.testing.assert_array_equal(cleaned, expected, err_msg=f"scene {i}")
        np.testing.assert_array_equal(np.signbit(cleaned), np.signbit(expected))
        if not np.isfinite(depth).all():
            continue  # the blob's input is cleaned depth
        com, ref = P.nearest_blob_com(cleaned, K), _ref_nearest_blob_com(cleaned, K)
        assert (com is None) == (ref is None), i
        if ref is not None:
            np.testing.assert_array_equal(com, ref, err_msg=f"scene {i}")


def test_localizer_and_float64_depth_equal_the_reference_bit_for_bit():
    """PlaneRemovedLocalizer (one box for both steps) and float64 input give the reference."""
    loc = P.PlaneRemovedLocalizer()
    for i, depth in enumerate(_scenes()):
        if not np.isfinite(depth).all():
            continue  # the localizer's input is checked depth
        ref_clean = _ref_remove_plane(depth, K)
        np.testing.assert_array_equal(P.remove_plane(depth.astype(np.float64), K), ref_clean)
        ref = _ref_nearest_blob_com(ref_clean, K)
        com = loc.localize(depth, K)
        assert (com is None) == (ref is None), i
        if ref is not None:
            np.testing.assert_array_equal(com, ref, err_msg=f"scene {i}")
            clean64 = ref_clean.astype(np.float64)
            np.testing.assert_array_equal(
                P.nearest_blob_com(clean64, K), _ref_nearest_blob_com(clean64, K)
            )


def test_plane_fit_equals_the_reference_to_rounding():
    """The compiled RANSAC picks the reference's plane and refits it to rounding."""
    rng = np.random.default_rng(3)
    for tilt in (0.0, 0.3, 1.2):
        n_true = np.array([0.0, math.sin(tilt), -math.cos(tilt)])
        plane = rng.uniform(-0.3, 0.3, (3000, 3))
        plane -= np.outer(plane @ n_true, n_true)  # on the plane through the origin
        plane += 0.8 * np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.002, plane.shape)
        clutter = rng.uniform([-0.3, -0.3, 0.3], [0.3, 0.3, 0.7], (1000, 3))
        pts = np.vstack([plane, clutter])
        fit = P.fit_plane_ransac(pts)
        # The reference: NumPy's vectorised scoring and an SVD refit.
        r = np.random.default_rng(0)
        sub = pts[r.integers(0, len(pts), size=1024)]
        tri = pts[r.integers(0, len(pts), size=(64, 3))]
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        offsets = -np.einsum("hk,hk->h", normals, tri[:, 0])
        best = int(np.argmax((np.abs(sub @ normals.T + offsets) < 0.008).sum(axis=0)))
        inl = np.abs(pts @ normals[best] + offsets[best]) < 0.008
        q = pts[inl]
        n = np.linalg.svd(q - q.mean(axis=0), full_matrices=False)[2][-1]
        d = -float(n @ q.mean(axis=0))
        sign = np.sign(n @ fit.normal)
        np.testing.assert_allclose(fit.normal, sign * n, atol=1e-12)
        assert fit.offset_m == pytest.approx(sign * d, abs=1e-12)
        assert fit.inliers == np.count_nonzero(np.abs(pts @ n + d) < 0.008)
        assert abs(fit.normal @ n_true) > 0.999


def test_plane_fit_of_degenerate_points_is_none():
    """Fewer than 3 points or only collinear triples give no plane."""
    assert P.fit_plane_ransac(np.zeros((2, 3))) is None
    line = np.outer(np.linspace(0.0, 1.0, 50), [1.0, 2.0, 3.0])
    assert P.fit_plane_ransac(line) is None


def test_fit_generator_draws_as_default_rng():
    """The reused generator of an int seed draws what np.random.default_rng(seed) draws."""
    for seed in (0, 0, np.int64(7), 0, 123456789):
        got = P._generator(seed).integers(0, 1000, size=(4, 3))
        np.testing.assert_array_equal(got, np.random.default_rng(seed).integers(0, 1000, (4, 3)))
    rng = np.random.default_rng(1)
    assert P._generator(rng) is rng
    assert isinstance(P._generator(None), np.random.Generator)
    with pytest.raises(ValueError):
        P._generator(-1)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_median_equals_numpy(dtype):
    """The blob's median is np.median's value, odd and even counts, ties included."""
    rng = np.random.default_rng(5)
    for n in (1, 2, 3, 4, 101, 1000):
        for values in (rng.uniform(0.3, 0.9, n), rng.integers(0, 3, n) * 0.1):
            v = values.astype(dtype)
            got = P._median(v)
            assert got.dtype == dtype
            assert got == np.median(v)


@pytest.mark.parametrize("angle_deg", [0.0, 33.0, -150.0])
def test_crop_matrix_and_crop_equal_the_reference(angle_deg):
    """The scalar crop matrix equals diag(s) @ R with its translation; the crop follows."""
    rng = np.random.default_rng(8)
    depth = rng.uniform(0.3, 0.9, (H, W)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.2] = 0
    for _ in range(10):
        c = rng.normal([0.0, 0.0, 0.5], [0.05, 0.05, 0.1])
        a = math.radians(angle_deg)
        sx, sy = 128 * c[2] / (K[0, 0] * 0.25), 128 * c[2] / (K[1, 1] * 0.25)
        A = np.diag([sx, sy]) @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])  # noqa: N806
        uc = K[:2, :2].diagonal() * c[:2] / c[2] + K[:2, 2]
        ref = np.hstack([A, (63.5 - A @ uc)[:, None]])
        M = P.crop_matrix(c, K, 0.25, 128, a)  # noqa: N806
        np.testing.assert_allclose(M, ref, rtol=1e-14, atol=1e-12)
        import cv2

        crop = cv2.warpAffine(depth, ref, (128, 128), flags=cv2.INTER_NEAREST)
        norm = (crop - np.float32(c[2])) / np.float32(0.125)
        norm[(crop <= 0) | (norm > 1.0)] = 1.0
        np.testing.assert_array_equal(P.crop_depth(depth, M, c[2], 0.25, 128), np.clip(norm, -1, 1))
