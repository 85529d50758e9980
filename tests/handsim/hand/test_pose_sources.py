"""Tests of handsim.hand.pose_sources: samplers, couplings, synergies, grasps, gestures, motions."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handsim.errors import HandSimError, InvalidPose, UnknownName
from handsim.hand import pose_sources as ps
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HAND_SIZES, HandParams
from handsim.hand.pose import DIGITS, FINGERS, JOINT_LIMITS, HandPose, joint_index

LO, HI = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
TIP = {"thumb": 4, "index": 8, "middle": 12, "ring": 16, "little": 20}
BASE = {"thumb": 2, "index": 5, "middle": 9, "ring": 13, "little": 17}
MEDIUM = HAND_SIZES["medium"]


def cols(joint: str) -> list[int]:
    """Angle indices of ``<finger>_<joint>`` for index, middle, ring, little."""
    return [joint_index(f"{f}_{joint}") for f in FINGERS]


@pytest.fixture(scope="module")
def fk() -> ForwardKinematics:
    """Forward kinematics of the medium right hand."""
    return ForwardKinematics(HandParams())


@pytest.fixture(scope="module")
def straight(fk) -> dict[str, float]:
    """Tip-to-base distance of each digit of the flat hand, metres."""
    k = fk.keypoints(HandPose.neutral())
    return {d: float(np.linalg.norm(k[TIP[d]] - k[BASE[d]])) for d in DIGITS}


def extension(fk, straight, pose: HandPose) -> dict[str, float]:
    """Tip-to-base distance of each digit relative to the flat hand (1 = straight)."""
    k = fk.keypoints(pose)
    return {d: float(np.linalg.norm(k[TIP[d]] - k[BASE[d]])) / straight[d] for d in DIGITS}


def assert_valid(pose: HandPose) -> None:
    """Finite and within the joint limits."""
    assert np.all(np.isfinite(pose.vector))
    assert pose.within_limits(), pose.violations()[:3]


# Samplers: limits and determinism -----------------------------------------------------------

SAMPLERS = {
    "uniform": lambda rng: ps.sample_uniform(rng, 64),
    "uniform_uncoupled": lambda rng: ps.sample_uniform(rng, 64, coupled=False),
    "synergy_2": lambda rng: ps.sample_synergy(rng, 64),
    "synergy_21_wide": lambda rng: ps.sample_synergy(rng, 64, num_synergies=21, scale=3.0),
    "grasp": lambda rng: ps.sample_grasp(rng, 64)[0],
    "grasp_noisy_open": lambda rng: ps.sample_grasp(
        rng, 64, closure_range=(0.0, 1.0), noise_deg=20.0
    )[0],
    "gesture_noisy": lambda rng: ps.gesture("fist", rng=rng, noise_deg=10.0),
    "motion": lambda rng: ps.random_motion(
        rng, 1.5, 0.01, sources=ps.MOTION_SOURCES, wrist_range_m=0.1, wrist_rotation_rad=1.0
    ),
}


@pytest.mark.parametrize("name", SAMPLERS)
def test_sampler_output_is_finite_and_within_limits(name):
    """Every sampler stays inside JOINT_LIMITS, even with large noise or scale."""
    assert_valid(SAMPLERS[name](np.random.default_rng(3)))


@pytest.mark.parametrize("name", SAMPLERS)
def test_sampler_is_deterministic_per_seed(name):
    """Same seed -> bit-identical poses; another seed -> different poses."""
    a = SAMPLERS[name](np.random.default_rng(7)).vector
    b = SAMPLERS[name](np.random.default_rng(7)).vector
    c = SAMPLERS[name](np.random.default_rng(8)).vector
    np.testing.assert_array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(a, c)


def test_samplers_return_batches_at_the_origin():
    """Batch shape (n,), wrist at the origin with identity rotation."""
    rng = np.random.default_rng(0)
    for pose in (ps.sample_uniform(rng, 5), ps.sample_synergy(rng, 5), ps.sample_grasp(rng, 5)[0]):
        assert pose.batch_shape == (5,)
        assert not pose.wrist_pos.any() and not pose.wrist_rotvec.any()


# Anatomical couplings -----------------------------------------------------------------------


@pytest.fixture(scope="module")
def coupled() -> np.ndarray:
    """(20000, 21) coupled uniform samples, radians."""
    return ps.sample_uniform(np.random.default_rng(11), 20000).angles


@pytest.fixture(scope="module")
def uncoupled() -> np.ndarray:
    """(20000, 21) independent uniform samples, radians."""
    return ps.sample_uniform(np.random.default_rng(11), 20000, coupled=False).angles


def test_dip_follows_two_thirds_of_pip(coupled, uncoupled):
    """DIP = 2/3 PIP + noise of 5 deg std clipped at 10 deg (and DIP clipped at 0)."""
    pip, dip = coupled[:, cols("pip_flex")], coupled[:, cols("dip_flex")]
    dev = np.rad2deg(dip - 2.0 / 3.0 * pip)
    assert np.all((np.abs(dev) <= 2 * ps.DIP_NOISE_DEG + 1e-9) | (dip == 0.0))
    free = pip > np.deg2rad(16.0)  # 2/3 * 16 > 10: never clipped at 0
    assert abs(dev[free].mean()) < 0.2
    assert 4.6 < dev[free].std() < 5.0  # 5 deg clipped at 2 sigma: 4.80 deg
    # Uncoupled samples ignore the rule.
    r = np.corrcoef(uncoupled[:, joint_index("index_pip_flex")], uncoupled[:, 8])[0, 1]
    assert abs(r) < 0.05
    assert np.corrcoef(pip[:, 0], dip[:, 0])[0, 1] > 0.97


def test_abduction_range_shrinks_with_mcp_flexion(coupled, uncoupled):
    """|abd| <= f(MCP flexion) * limit, f falling from 1 (extended) to 0.2 (90 deg)."""
    flex, abd = coupled[:, cols("mcp_flex")], coupled[:, cols("mcp_abd")]
    frac = ps.abduction_range_fraction(flex)
    lo, hi = LO[cols("mcp_abd")], HI[cols("mcp_abd")]
    assert np.all(abd >= frac * lo - 1e-12) and np.all(abd <= frac * hi + 1e-12)
    np.testing.assert_allclose(
        ps.abduction_range_fraction(np.deg2rad([-20, 0, 45, 90])), [1, 1, 0.6, 0.2]
    )
    span = hi - lo
    bent = flex > np.deg2rad(80)
    straight_ = flex < 0.0
    assert np.all(np.abs(abd[bent]) <= 0.3 * np.broadcast_to(span, abd.shape)[bent])
    assert (
        np.max(np.abs(abd[straight_]) / np.broadcast_to(np.maximum(-lo, hi), abd.shape)[straight_])
        > 0.95
    )
    # Without coupling full spread occurs in a fist.
    u_flex, u_abd = uncoupled[:, cols("mcp_flex")], uncoupled[:, cols("mcp_abd")]
    assert np.any(
        np.abs(u_abd[u_flex > np.deg2rad(80)])
        > 0.4 * np.broadcast_to(span, u_abd.shape)[u_flex > np.deg2rad(80)]
    )


def neighbour_deviation_deg(flex: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(middle, ring) deviation from the mean of their neighbours, degrees."""
    i, m, r, li = np.rad2deg(flex).T
    return np.abs(m - (i + r) / 2), np.abs(r - (m + li) / 2)


@pytest.mark.parametrize("joint", ["mcp_flex", "pip_flex"])
def test_neighbouring_fingers_are_bounded(coupled, uncoupled, joint):
    """Middle within 65 deg and ring within 55 deg of their neighbours' mean flexion."""
    dev_m, dev_r = neighbour_deviation_deg(coupled[:, cols(joint)])
    assert dev_m.max() <= 65.0 + 1e-9 and dev_r.max() <= 55.0 + 1e-9
    assert dev_r.max() > 50.0  # the bound is reached, not over-constrained
    u_m, u_r = neighbour_deviation_deg(uncoupled[:, cols(joint)])
    assert (u_r > 55.0).mean() > 0.05 and (u_m > 65.0).mean() > 0.01


@pytest.mark.parametrize("name", ["victory", "rock", "call_me", "three", "point", "fist"])
def test_everyday_gestures_satisfy_the_neighbour_rule(name):
    """The mean-of-neighbours rule admits the easy gestures (documented design choice)."""
    angles = ps.gesture(name).angles
    for joint in ("mcp_flex", "pip_flex"):
        dev_m, dev_r = neighbour_deviation_deg(angles[cols(joint)][None])
        assert dev_m[0] <= 65.0 and dev_r[0] <= 55.0


def test_coupled_flexion_is_otherwise_uniform(coupled):
    """Index flexion (free apart from the middle's rule) covers its whole range."""
    index = np.rad2deg(coupled[:, joint_index("index_mcp_flex")])
    assert index.min() < -18 and index.max() > 88
    hist, _ = np.histogram(index, bins=5)
    assert hist.min() > 0.6 * hist.max()


# Synergies ----------------------------------------------------------------------------------


def test_synergy_basis_is_an_orthonormal_pca():
    """Orthonormal components, descending variance ratios summing to one, read-only arrays."""
    b = ps.synergy_basis()
    np.testing.assert_allclose(b.components @ b.components.T, np.eye(21), atol=1e-10)
    assert np.all(np.diff(b.explained_variance_ratio) <= 1e-12)
    assert b.explained_variance_ratio.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(b.std**2 / (b.std**2).sum(), b.explained_variance_ratio)
    assert "143 grasp postures" in b.source
    assert ps.synergy_basis() is b
    with pytest.raises(ValueError):
        b.mean[0] = 1.0


def test_synergy_variance_figures_match_the_docstring():
    """PC1 56.0 %, 2 PCs 73.4 %, 3 PCs 83.4 %, 5 PCs 94.8 % of the library variance."""
    cum = np.cumsum(ps.synergy_basis().explained_variance_ratio)
    np.testing.assert_allclose(cum[[0, 1, 2, 4]], [0.560, 0.734, 0.834, 0.948], atol=0.001)


def test_synergy_pc1_closes_all_fingers_and_compares_with_graspit():
    """PC1 flexes every PIP and DIP; |cos| with GraspIt EG1 0.28 / EG2 0.92, PC2 ~ EG1 0.83."""
    comps = ps.synergy_basis().components
    flex_cols = [
        joint_index(f"{f}_{j}") for f in FINGERS for j in ("mcp_flex", "pip_flex", "dip_flex")
    ]
    pc1 = comps[0]
    assert np.all(pc1[cols("pip_flex")] > 0.3) and np.all(pc1[cols("dip_flex")] > 0.2)
    eg1 = ps.GRASPIT_EG1_FINGER_FLEXION.reshape(-1)
    eg2 = np.array(
        [[0.207, -0.336, -0.208], [0.186, -0.356, -0.334], [0.027, -0.387, -0.267]]
        + [[-0.193, -0.344, -0.264]]
    ).reshape(-1)

    def cos(a, b):
        return abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b)

    assert cos(pc1[flex_cols], eg1) == pytest.approx(0.28, abs=0.01)
    assert cos(pc1[flex_cols], eg2) == pytest.approx(0.92, abs=0.01)
    assert cos(comps[1][flex_cols], eg1) == pytest.approx(0.83, abs=0.01)


def test_synergy_reconstruction_of_the_library():
    """All 21 components reconstruct a grasp exactly; error falls with more components."""
    b = ps.synergy_basis()
    library = np.concatenate([g.angles(np.linspace(0.5, 1, 11)) for g in ps.GRASP_TYPES.values()])
    pose = HandPose(np.zeros((len(library), 3)), np.zeros((len(library), 3)), library)
    np.testing.assert_allclose(ps.synergy_pose(b.project(pose, 21)).angles, library, atol=1e-10)
    errors = [
        np.sqrt(
            np.mean((b.mean + (b.project(pose, k) * b.std[:k]) @ b.components[:k] - library) ** 2)
        )
        for k in (1, 2, 5, 10)
    ]
    assert all(np.diff(errors) < 0)
    assert np.rad2deg(errors[2]) < 6.0  # 5 synergies: a few degrees RMS


def test_sample_synergy_spans_the_first_components():
    """Unclipped samples lie in mean + span(PC1..PCk) with coefficient std = scale."""
    b = ps.synergy_basis()
    pose = ps.sample_synergy(np.random.default_rng(5), 4000, num_synergies=3, scale=0.5)
    inside = np.all((pose.angles > LO + 1e-9) & (pose.angles < HI - 1e-9), axis=1)
    assert inside.mean() > 0.5
    coef = b.project(pose[inside], 21)
    np.testing.assert_allclose(coef[:, 3:], 0.0, atol=1e-9)
    np.testing.assert_allclose(coef[:, :3].std(axis=0), 0.5, rtol=0.1)


# Grasp taxonomy -----------------------------------------------------------------------------

REQUIRED_GRASPS = (
    "large_diameter",
    "small_diameter",
    "medium_wrap",
    "power_sphere",
    "adducted_thumb",
    "lateral_pinch",
    "prismatic_4_finger",
    "tripod",
    "precision_sphere",
)


def test_grasp_registry_holds_the_required_types_with_metadata():
    """At least the 8 required GRASP types, each with valid class, opposition and thumb."""
    assert set(REQUIRED_GRASPS) <= set(ps.GRASP_TYPES)
    assert len(ps.GRASP_TYPES) >= 12
    for name, g in ps.GRASP_TYPES.items():
        assert g.name == name
        assert g.grasp_class in ("power", "intermediate", "precision")
        assert g.opposition in ("palm", "pad", "side")
        assert g.thumb in ("abducted", "adducted")
        assert set(g.digits) <= set(DIGITS) and g.digits
        assert g.object_size_m[0] >= g.object_size_m[1] >= 0.0
        assert g.description and g.objects
    classes = {g.grasp_class for g in ps.GRASP_TYPES.values()}
    assert classes == {"power", "intermediate", "precision"}
    assert ps.GRASP_TYPES["lateral_pinch"].opposition == "side"
    assert ps.GRASP_TYPES["adducted_thumb"].thumb == "adducted"
    with pytest.raises(TypeError):
        ps.GRASP_TYPES["x"] = ps.GRASP_TYPES["tripod"]  # type: ignore[index]


@pytest.mark.parametrize("name", list(ps.GRASP_TYPES))
def test_grasp_postures_within_limits_and_anchored(name):
    """Every closure is within limits; closures 0, 0.5, 1 are the preshape and the anchors."""
    g = ps.GRASP_TYPES[name]
    closures = np.linspace(0.0, 1.0, 21)
    pose = ps.grasp_pose(name, closures)
    assert pose.batch_shape == (21,)
    assert_valid(pose)
    np.testing.assert_allclose(ps.grasp_pose(name, 0.0).angles, g.preshape, atol=1e-12)
    np.testing.assert_allclose(ps.grasp_pose(name, 0.5).angles, g.large, atol=1e-12)
    np.testing.assert_allclose(ps.grasp_pose(name, 1.0).angles, g.small, atol=1e-12)
    # Continuity: no jump between neighbouring closures.
    assert np.abs(np.diff(pose.angles, axis=0)).max() < np.deg2rad(12)


@pytest.mark.parametrize("name", list(ps.GRASP_TYPES))
def test_grasps_close_as_closure_grows(fk, name):
    """Touching fingers flex more at each anchor (0 -> 0.5 -> 1); fingertips near the wrist."""
    g = ps.GRASP_TYPES[name]
    fingers = [f for f in g.digits if f != "thumb"]
    idx = [joint_index(f"{f}_{j}") for f in fingers for j in ("mcp_flex", "pip_flex", "dip_flex")]
    flex = [ps.grasp_pose(name, c).angles[idx].sum() for c in (0.0, 0.5, 1.0)]
    assert flex[0] < flex[1] < flex[2]
    k = fk.keypoints(ps.grasp_pose(name, np.array([0.0, 1.0])))
    reach = np.linalg.norm(k[:, [TIP[f] for f in FINGERS]], axis=-1).mean(axis=1)
    assert reach[1] < reach[0]


@pytest.mark.parametrize(
    "name", [n for n, g in ps.GRASP_TYPES.items() if g.grasp_class == "precision"]
)
def test_precision_grasp_aperture_shrinks(fk, name):
    """Thumb-index tip distance (the aperture) falls with closure."""
    k = fk.keypoints(ps.grasp_pose(name, np.array([0.0, 0.5, 1.0])))
    aperture = np.linalg.norm(k[:, TIP["thumb"]] - k[:, TIP["index"]], axis=-1)
    assert aperture[0] > aperture[1] > aperture[2]
    assert aperture[2] < 0.06


def test_pinch_grasps_bring_the_thumb_to_the_index(fk):
    """Palmar pinch closes pad to pad; lateral pinch puts the thumb on the index side."""
    k = fk.keypoints(ps.grasp_pose("palmar_pinch", 1.0))
    assert np.linalg.norm(k[TIP["thumb"]] - k[TIP["index"]]) < 0.02
    k = fk.keypoints(ps.grasp_pose("lateral_pinch", 1.0))
    middle_phalanx = 0.5 * (k[6] + k[7])
    assert np.linalg.norm(k[TIP["thumb"]] - middle_phalanx) < 0.035


@pytest.mark.parametrize(
    ("name", "large", "small"),
    [
        ("large_diameter", (42, 42, 28), (54, 56, 38)),
        ("medium_wrap", (59, 66, 44), (68, 80, 54)),
        ("small_diameter", (62, 92, 62), (57, 108, 76)),
        ("power_sphere", (37, 37, 24), (47, 48, 33)),
        ("prismatic_4_finger", (55, 15, 10), (60, 35, 23)),
    ],
)
def test_mean_finger_flexion_matches_the_documented_table(name, large, small):
    """Mean MCP / PIP / DIP over the four fingers at closure 0.5 and 1 (module docstring)."""
    for closure, expected in ((0.5, large), (1.0, small)):
        a = np.rad2deg(ps.grasp_pose(name, closure).angles)
        means = [a[cols(j)].mean() for j in ("mcp_flex", "pip_flex", "dip_flex")]
        np.testing.assert_allclose(means, expected, atol=0.5)


def test_grasp_noise_is_seeded_and_clipped():
    """Noise changes the posture, stays within limits and needs a generator."""
    clean = ps.grasp_pose("tripod", 0.7).angles
    noisy = ps.grasp_pose("tripod", 0.7, rng=np.random.default_rng(1), noise_deg=5.0)
    assert_valid(noisy)
    assert not np.allclose(noisy.angles, clean)
    assert np.rad2deg(np.abs(noisy.angles - clean)).max() < 25.0


def test_sample_grasp_labels_match_the_postures():
    """Each sampled pose is its labelled grasp type at some closure in the range (no noise)."""
    poses, labels = ps.sample_grasp(
        np.random.default_rng(2),
        40,
        names=["tripod", "fixed_hook"],
        closure_range=(0.6, 0.9),
        noise_deg=0.0,
    )
    assert set(labels) == {"tripod", "fixed_hook"} and len(labels) == 40
    grid = np.linspace(0.6, 0.9, 301)
    for pose, label in zip(poses, labels, strict=True):
        table = ps.GRASP_TYPES[label].angles(grid)
        assert np.abs(table - pose.angles).max(axis=1).min() < 2e-3


# Gestures -----------------------------------------------------------------------------------

REQUIRED_GESTURES = (
    "open",
    "fist",
    "point",
    "pinch",
    "ok",
    "thumbs_up",
    "victory",
    "spread",
    "relaxed",
    "call_me",
    "rock",
    "three",
)

# Fingers that are straight in each gesture; the others must be curled.
EXTENDED = {
    "open": set(FINGERS),
    "spread": set(FINGERS),
    "fist": set(),
    "point": {"index"},
    "thumbs_up": set(),
    "gun": {"index"},
    "victory": {"index", "middle"},
    "three": {"index", "middle", "ring"},
    "four": set(FINGERS),
    "call_me": {"little"},
    "rock": {"index", "little"},
}
THUMB_OUT = {"open", "spread", "thumbs_up", "call_me", "gun"}


def test_gesture_registry():
    """At least the required gestures, each with a description and read-only angles."""
    assert set(REQUIRED_GESTURES) <= set(ps.GESTURES)
    assert len(ps.GESTURES) >= 14
    for name, g in ps.GESTURES.items():
        assert g.name == name and g.description
        assert g.angles.shape == (21,) and not g.angles.flags.writeable


@pytest.mark.parametrize("name", list(ps.GESTURES))
def test_gestures_are_within_limits(name):
    """A single pose, within limits, at the origin."""
    pose = ps.gesture(name)
    assert pose.batch_shape == ()
    assert_valid(pose)


@pytest.mark.parametrize("name", list(EXTENDED))
def test_gesture_finger_states(fk, straight, name):
    """Named fingers are straight (>= 95 % of their length), the others curled (<= 50 %)."""
    ext = extension(fk, straight, ps.gesture(name))
    for f in FINGERS:
        if f in EXTENDED[name]:
            assert ext[f] >= 0.95, f
        else:
            assert ext[f] <= 0.5, f
    k = fk.keypoints(ps.gesture(name))
    thumb_reach = np.linalg.norm(k[TIP["thumb"]]) / MEDIUM
    if name in THUMB_OUT:
        assert ext["thumb"] >= 0.95 and thumb_reach > 0.65
    else:
        assert thumb_reach < 0.55


def test_fist_fingertips_are_near_the_palm(fk):
    """In a fist every fingertip is within 0.4 hand lengths of the wrist (open: >= 0.8)."""
    tips = [TIP[f] for f in FINGERS]
    fist = np.linalg.norm(fk.keypoints(ps.gesture("fist"))[tips], axis=-1) / MEDIUM
    flat = np.linalg.norm(fk.keypoints(ps.gesture("open"))[tips], axis=-1) / MEDIUM
    assert fist.max() < 0.4 and flat.min() > 0.8


def test_spread_and_relaxed(fk):
    """Spread fans index and little > 40 deg apart; relaxed flexes more toward the little finger."""
    k = fk.keypoints(ps.gesture("spread"))
    d_index, d_little = k[TIP["index"]] - k[BASE["index"]], k[TIP["little"]] - k[BASE["little"]]
    angle = np.degrees(
        np.arccos(d_index @ d_little / np.linalg.norm(d_index) / np.linalg.norm(d_little))
    )
    assert angle > 40.0
    a = np.rad2deg(ps.gesture("relaxed").angles)
    for joint in ("mcp_flex", "pip_flex"):
        assert np.all(np.diff(a[cols(joint)]) > 0) and np.all(
            (a[cols(joint)] >= 10) & (a[cols(joint)] <= 60)
        )


def distal_gap(params: HandParams, pose: HandPose) -> float:
    """Skin gap between the thumb and index distal capsules, metres (< 0 = overlap)."""
    model = ForwardKinematics(params)
    rot, pos = model.body_frames(pose)
    names = [b.name for b in model.skeleton.bodies]
    points, radii = [], []
    for body in ("thumb_distal", "index_distal"):
        i = names.index(body)
        (cap,) = model.skeleton.bodies[i].geoms
        s = np.linspace(0.0, 1.0, 401)[:, None]
        points.append(pos[i] + (cap.start + s * (cap.end - cap.start)) @ rot[i].T)
        radii.append(cap.radius)
    dist = np.linalg.norm(points[0][:, None] - points[1][None], axis=-1).min()
    return float(dist - sum(radii))


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("size", list(HAND_SIZES))
@pytest.mark.parametrize("name", ["pinch", "ok"])
def test_thumb_meets_index_in_pinch_and_ok(name, size, side):
    """Thumb and index tips 15 mm apart (two skin radii, scaled) and the pads touch (+-1 mm)."""
    params = HandParams(hand_length=HAND_SIZES[size], side=side)
    pose = ps.gesture(name)
    k = ForwardKinematics(params).keypoints(pose)
    scale = HAND_SIZES[size] / MEDIUM
    assert np.linalg.norm(k[TIP["thumb"]] - k[TIP["index"]]) == pytest.approx(
        0.015 * scale, abs=0.001
    )
    assert -0.001 < distal_gap(params, pose) < 0.001


def test_ok_keeps_the_other_fingers_extended(fk, straight):
    """OK: middle, ring and little nearly straight; pinch: they are loosely curled."""
    ok = extension(fk, straight, ps.gesture("ok"))
    pinch = extension(fk, straight, ps.gesture("pinch"))
    assert min(ok["middle"], ok["ring"], ok["little"]) > 0.95
    assert max(pinch["ring"], pinch["little"]) < 0.85


def test_gesture_noise():
    """Noise is seeded, within limits; the registry constant is not modified."""
    before = ps.GESTURES["point"].angles.copy()
    a = ps.gesture("point", rng=np.random.default_rng(0), noise_deg=4.0)
    b = ps.gesture("point", rng=np.random.default_rng(0), noise_deg=4.0)
    np.testing.assert_array_equal(a.angles, b.angles)
    assert_valid(a)
    np.testing.assert_array_equal(ps.GESTURES["point"].angles, before)


# Smooth motion ------------------------------------------------------------------------------


def keyframes() -> list[HandPose]:
    """Four keyframes with finger, wrist translation and wrist rotation changes."""
    return [
        ps.gesture("open"),
        ps.gesture("fist").replace(wrist_pos=np.array([0.1, 0.0, 0.05])),
        ps.gesture("point").replace(wrist_rotvec=np.array([0.0, 0.0, 1.2])),
        ps.grasp_pose("tripod", 0.8).replace(
            wrist_pos=np.array([-0.05, 0.2, 0.0]), wrist_rotvec=np.array([0.5, -0.3, 0.0])
        ),
    ]


def speeds(motion: HandPose, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Finite-difference joint (T-1, 21), wrist (T-1,) and angular (T-1,) speeds."""
    joint = np.abs(np.diff(motion.angles, axis=0)) / dt
    wrist = np.linalg.norm(np.diff(motion.wrist_pos, axis=0), axis=1) / dt
    r = Rotation.from_rotvec(motion.wrist_rotvec)
    angular = (r[:-1].inv() * r[1:]).magnitude() / dt
    return joint, wrist, angular


def keyframe_indices(frames, dt, hold=0.0, **limits) -> list[int]:
    """Sample index of each keyframe in smooth_motion's output (segments rounded up to dt)."""
    durations = ps.segment_durations(frames, **limits)
    steps = [math.ceil(d / dt - 1e-9) for d in durations]
    h = math.ceil(hold / dt - 1e-9)
    return [h * i + sum(steps[:i]) for i in range(len(frames))]


@pytest.mark.parametrize("dt", [0.001, 1 / 60])
def test_smooth_motion_hits_every_keyframe_exactly(dt):
    """Sample 0 is the first keyframe, the last sample the last, and every keyframe is a sample."""
    frames = keyframes()
    motion = ps.smooth_motion(frames, dt)
    np.testing.assert_array_equal(motion[0].vector, frames[0].vector)
    np.testing.assert_array_equal(motion[-1].vector, frames[-1].vector)
    idx = keyframe_indices(frames, dt)
    assert idx[-1] == len(motion) - 1
    for i, f in zip(idx, frames, strict=True):
        np.testing.assert_array_equal(motion[i].vector, f.vector)


def test_smooth_motion_respects_every_speed_limit():
    """Finite-difference speeds never exceed the limits, and the binding limit is nearly reached."""
    dt = 0.001
    limits = dict(max_joint_speed=20.0, max_wrist_speed=0.5, max_wrist_angular_speed=2.0)
    motion = ps.smooth_motion(keyframes(), dt, **limits)
    joint, wrist, angular = speeds(motion, dt)
    assert joint.max() <= 20.0 + 1e-9
    assert wrist.max() <= 0.5 + 1e-9
    assert angular.max() <= 2.0 + 1e-9
    assert max(joint.max() / 20.0, wrist.max() / 0.5, angular.max() / 2.0) > 0.97


def test_smooth_motion_default_limits_and_per_joint_speeds():
    """Defaults: 49 rad/s, 1 m/s, 3 rad/s; a per-joint limit slows only that joint's segment."""
    dt = 0.002
    motion = ps.smooth_motion(keyframes(), dt)
    joint, wrist, angular = speeds(motion, dt)
    assert joint.max() <= ps.MAX_JOINT_SPEED and wrist.max() <= 1.0 and angular.max() <= 3.0
    per_joint = np.full(21, ps.MAX_JOINT_SPEED)
    per_joint[joint_index("index_pip_flex")] = 2.0
    slow = ps.smooth_motion(keyframes(), dt, max_joint_speed=per_joint)
    j, _, _ = speeds(slow, dt)
    assert j[:, joint_index("index_pip_flex")].max() <= 2.0 + 1e-9
    assert len(slow) > len(motion)


def test_closing_the_hand_takes_60_ms():
    """A 90 deg flexion at the default limit lasts 60 ms: 1.875 * (pi/2) / MAX_JOINT_SPEED."""
    assert ps.MAX_JOINT_SPEED == pytest.approx(49.087, abs=1e-3)
    closed = HandPose.from_angles({f"{f}_mcp_flex": np.pi / 2 for f in FINGERS})
    assert ps.segment_durations([HandPose.neutral(), closed])[0] == pytest.approx(0.060)
    far = HandPose.neutral(wrist_pos=(1.0, 0.0, 0.0))
    assert ps.segment_durations([HandPose.neutral(), far])[0] == pytest.approx(1.875)
    assert ps.segment_durations([HandPose.neutral(), far], max_wrist_speed=5.0)[0] == pytest.approx(
        0.375
    )


def test_smooth_motion_is_monotone_and_continuous_between_keyframes():
    """Within a segment each joint moves one way; speed is ~0 at keyframes and peaks mid-way."""
    dt = 0.001
    frames = keyframes()
    motion = ps.smooth_motion(frames, dt)
    idx = keyframe_indices(frames, dt)
    for i0, i1, a, b in zip(idx[:-1], idx[1:], frames[:-1], frames[1:], strict=True):
        seg = motion.angles[i0 : i1 + 1]
        sign = np.sign(b.angles - a.angles)
        assert np.all(np.diff(seg, axis=0) * sign >= -1e-12)
        step = np.abs(np.diff(seg, axis=0)).max(axis=1)
        assert step[0] < 0.02 * step.max() and step[-1] < 0.02 * step.max()
        assert np.argmax(step) == pytest.approx(len(step) / 2, abs=2)
    # The wrist turns about one fixed axis per segment (slerp), monotonically.
    r = Rotation.from_rotvec(motion.wrist_rotvec[idx[2] : idx[3] + 1])
    rel = (r[0].inv() * r).magnitude()
    assert np.all(np.diff(rel) >= -1e-12)


def test_smooth_motion_hold_and_single_keyframe():
    """Hold keeps each keyframe for whole dt steps; one keyframe gives a still motion."""
    dt = 0.01
    frames = keyframes()[:2]
    motion = ps.smooth_motion(frames, dt, hold=0.1)
    for i in range(11):
        np.testing.assert_array_equal(motion[i].vector, frames[0].vector)
    for i in range(1, 11):
        np.testing.assert_array_equal(motion[-i].vector, frames[1].vector)
    assert not np.array_equal(motion[11].vector, frames[0].vector)
    still = ps.smooth_motion([frames[1]], dt, hold=0.05)
    assert still.batch_shape == (6,)
    np.testing.assert_array_equal(still.vector, np.repeat(frames[1].vector[None], 6, axis=0))
    both = ps.smooth_motion(frames, dt, hold=[0.0, 0.02])
    assert len(both) == len(ps.smooth_motion(frames, dt)) + 2


def test_random_motion_length_limits_and_determinism():
    """floor(duration / dt) + 1 samples within joint and speed limits."""
    dt = 0.005
    motion = ps.random_motion(
        np.random.default_rng(4),
        3.0,
        dt,
        sources=ps.MOTION_SOURCES,
        wrist_range_m=0.2,
        wrist_rotation_rad=2.0,
    )
    assert motion.batch_shape == (601,)
    assert_valid(motion)
    joint, wrist, angular = speeds(motion, dt)
    assert joint.max() <= ps.MAX_JOINT_SPEED + 1e-9
    assert wrist.max() <= ps.MAX_WRIST_SPEED + 1e-9
    assert angular.max() <= ps.MAX_WRIST_ANGULAR_SPEED + 1e-6
    assert joint.max() > 1.0  # it moves
    short = ps.random_motion(np.random.default_rng(4), 0.004, dt)
    assert short.batch_shape == (1,)


# Errors -------------------------------------------------------------------------------------


def test_error_types():
    """UnknownName is a KeyError, InvalidPose a ValueError; both are HandSimErrors."""
    assert issubclass(UnknownName, KeyError) and issubclass(UnknownName, HandSimError)
    assert issubclass(InvalidPose, ValueError) and issubclass(InvalidPose, HandSimError)


def test_unknown_names_list_the_valid_ones():
    """Unknown gesture, grasp and motion source names raise UnknownName listing the options."""
    with pytest.raises(
        UnknownName, match=r"unknown gesture 'wave'; valid names: open, relaxed, spread, fist"
    ):
        ps.gesture("wave")
    with pytest.raises(
        UnknownName, match=r"unknown grasp type 'hook'; valid names: large_diameter, medium_wrap"
    ):
        ps.grasp_pose("hook")
    with pytest.raises(
        UnknownName, match=r"unknown grasp type 'hook'; valid names: .*precision_disk"
    ):
        ps.sample_grasp(np.random.default_rng(0), 2, names=["tripod", "hook"])
    with pytest.raises(
        UnknownName,
        match=r"unknown motion source 'mocap'; valid names: gestures, grasps, synergy, uniform",
    ):
        ps.random_motion(np.random.default_rng(0), 1.0, 0.01, sources=["mocap"])


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda: ps.sample_uniform(np.random.default_rng(0), 0),
            r"n must be an integer >= 1 \(number of poses\); received 0",
        ),
        (
            lambda: ps.sample_uniform(np.random.default_rng(0), 2.5),
            r"n must be an integer >= 1 .*received 2.5",
        ),
        (lambda: ps.sample_uniform(0, 3), r"rng must be a numpy.random.Generator .*; received int"),
        (
            lambda: ps.sample_synergy(np.random.default_rng(0), 3, num_synergies=0),
            r"num_synergies must be an integer in \[1, 21\]; received 0",
        ),
        (
            lambda: ps.sample_synergy(np.random.default_rng(0), 3, num_synergies=22),
            r"num_synergies must be an integer in \[1, 21\]; received 22",
        ),
        (
            lambda: ps.sample_synergy(np.random.default_rng(0), 3, scale=0.0),
            r"scale must be a finite number > 0 .*received 0.0",
        ),
        (
            lambda: ps.synergy_pose([np.nan]),
            r"coefficients must be finite with shape \(\.\.\., k\), 1 <= k <= 21; "
            r"received shape \(1,\)",
        ),
        (
            lambda: ps.grasp_pose("tripod", 1.5),
            r"closure must be a scalar or a 1-D array of values in \[0, 1\] .*received 1.5",
        ),
        (lambda: ps.grasp_pose("tripod", -0.1), r"closure must be .*received -0.1"),
        (
            lambda: ps.grasp_pose("tripod", 0.5, noise_deg=2.0),
            r"noise_deg = 2.0 needs rng, a numpy.random.Generator; received rng=None",
        ),
        (
            lambda: ps.gesture("fist", rng=np.random.default_rng(0), noise_deg=-1.0),
            r"noise_deg must be a finite number >= 0 \(degrees\); received -1.0",
        ),
        (
            lambda: ps.sample_grasp(np.random.default_rng(0), 2, closure_range=(0.8, 0.2)),
            r"closure_range must be \(low, high\) with 0.0 <= low <= high <= 1.0 \(closure\); "
            r"received \(0.8, 0.2\)",
        ),
        (
            lambda: ps.sample_grasp(np.random.default_rng(0), 2, names=[]),
            r"names must hold at least one grasp type; received \[\]",
        ),
    ],
)
def test_bad_sampler_arguments_raise_invalid_pose(call, message):
    """Each bad argument names what was expected and what was received."""
    with pytest.raises(InvalidPose, match=message):
        call()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            dict(keyframes=[], dt=0.01),
            r"keyframes must hold at least 1 HandPose; received an empty sequence",
        ),
        (
            dict(keyframes=HandPose.neutral(), dt=0.01),
            r"keyframes must be a sequence of single HandPose objects, not one HandPose",
        ),
        (
            dict(keyframes=[ps.sample_uniform(np.random.default_rng(0), 2)], dt=0.01),
            r"keyframe 0 must be a single HandPose; received batch shape \(2,\)",
        ),
        (
            dict(keyframes=[HandPose.neutral(), "fist"], dt=0.01),
            r"keyframe 1 must be a single HandPose; received str",
        ),
        (
            dict(keyframes=[HandPose.from_angles({"index_pip_flex": 3.0})], dt=0.01),
            r"outside joint limits: index_pip_flex = 171.89 deg",
        ),
        (
            dict(keyframes=[HandPose.neutral()], dt=0.0),
            r"dt must be a finite number > 0 seconds; received 0.0",
        ),
        (
            dict(keyframes=[HandPose.neutral()], dt=-0.01),
            r"dt must be a finite number > 0 seconds; received -0.01",
        ),
        (
            dict(keyframes=[HandPose.neutral()], dt=0.01, max_wrist_speed=6.0),
            r"max_wrist_speed must be at most 5.0 m/s .*received 6.0",
        ),
        (
            dict(keyframes=[HandPose.neutral()], dt=0.01, max_joint_speed=0.0),
            r"max_joint_speed must be > 0 rad/s, a scalar or one per joint \(21,\); received 0.0",
        ),
        (
            dict(keyframes=[HandPose.neutral()], dt=0.01, max_wrist_angular_speed=-1.0),
            r"max_wrist_angular_speed must be a finite number > 0 rad/s; received -1.0",
        ),
        (
            dict(keyframes=[HandPose.neutral()], dt=0.01, hold=-0.1),
            r"hold must be seconds >= 0, a scalar or one per keyframe \(1\); received -0.1",
        ),
        (
            dict(keyframes=[HandPose.neutral()], dt=0.01, hold=[0.1, 0.2]),
            r"hold must be seconds >= 0, a scalar or one per keyframe \(1\); received \[0.1, 0.2\]",
        ),
    ],
)
def test_bad_motion_arguments_raise_invalid_pose(kwargs, message):
    """smooth_motion validates keyframes, dt, limits and holds with explicit messages."""
    with pytest.raises(InvalidPose, match=message):
        ps.smooth_motion(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(duration=0.0), r"duration must be a finite number > 0 seconds; received 0.0"),
        (dict(dt=math.inf), r"dt must be a finite number > 0 seconds; received inf"),
        (
            dict(sources=[]),
            r"sources must name at least one of gestures, grasps, synergy, uniform; received \[\]",
        ),
        (dict(speed_range=(0.0, 1.0)), r"speed_range must have low > 0; received \(0.0, 1.0\)"),
        (
            dict(speed_range=(0.5, 2.0)),
            r"speed_range must be \(low, high\) with 0.0 <= low <= high <= 1.0",
        ),
        (
            dict(hold_range=(0.5,)),
            r"hold_range must be \(low, high\) with 0.0 <= low <= high <= inf seconds; "
            r"received \(0.5,\)",
        ),
        (dict(wrist_rotation_rad=4.0), r"wrist_rotation_rad must be in \[0, pi\]; received 4.0"),
        (
            dict(wrist_range_m=-0.1),
            r"wrist_range_m must be a finite number >= 0 metres; received -0.1",
        ),
    ],
)
def test_bad_random_motion_arguments(kwargs, message):
    """random_motion validates every argument before drawing."""
    args = dict(duration=1.0, dt=0.01) | kwargs
    with pytest.raises(InvalidPose, match=message):
        ps.random_motion(np.random.default_rng(0), **args)


def test_messages_are_plain_text():
    """UnknownName shows its message unquoted (KeyError would quote it)."""
    with pytest.raises(UnknownName) as info:
        ps.gesture("nope")
    assert str(info.value).startswith("unknown gesture 'nope'")
    assert re.search(r"valid names: .*gun", str(info.value))
