"""Tests for handsim.hand.keypoints: index mappings, derived points, round trips and errors."""

from __future__ import annotations

import re

import numpy as np
import pytest

from handsim.errors import HandSimError, InvalidKeypoints, UnknownName
from handsim.hand.keypoints import (
    FORMATS,
    HAND_POINT_NAMES,
    KEYPOINT_NAMES,
    METACARPAL_BASE_FRACTION,
    from_format,
    present_mask,
    to_format,
)

# Canonical indices, spelled out so the expectations below do not reuse the module's tables.
WRIST, T_CMC, T_MCP, T_IP, T_TIP = 0, 1, 2, 3, 4
I_MCP, I_PIP, I_DIP, I_TIP = 5, 6, 7, 8
M_MCP, M_PIP, M_DIP, M_TIP = 9, 10, 11, 12
R_MCP, R_PIP, R_DIP, R_TIP = 13, 14, 15, 16
L_MCP, L_PIP, L_DIP, L_TIP = 17, 18, 19, 20

# Per format: for each of its points, the canonical index it copies, or None if derived.
EXPECTED_SOURCES: dict[str, list[int | None]] = {
    "mediapipe21": list(range(21)),
    "openpose21": list(range(21)),
    # wrist, index, middle, ring, little, thumb; each base -> tip (MSRA readme).
    "msra21": [WRIST, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 1, 2, 3, 4],
    # Wrist, TMCP IMCP MMCP RMCP PMCP, then PIP DIP TIP of T I M R P (HANDS 2017).
    "bighand21": [WRIST, T_CMC, I_MCP, M_MCP, R_MCP, L_MCP]
    + [T_MCP, T_IP, T_TIP, I_PIP, I_DIP, I_TIP, M_PIP, M_DIP, M_TIP]
    + [R_PIP, R_DIP, R_TIP, L_PIP, L_DIP, L_TIP],
    # palm, then root/mid/tip of thumb (MCP, IP, tip) and of index, middle, ring, pinky
    # (PIP, DIP, tip: the data's segment lengths fit these joints).
    "icvl16": [None, T_MCP, T_IP, T_TIP, I_PIP, I_DIP, I_TIP, M_PIP, M_DIP, M_TIP]
    + [R_PIP, R_DIP, R_TIP, L_PIP, L_DIP, L_TIP],
    # NYU joints 0 3 6 9 12 15 18 21 24 25 27 30 31 32: F1 (pinky) .. F4 (index) tip and
    # PIP, thumb tip/IP/MCP, the two wrist points, palm centre.
    "nyu14": [L_TIP, L_PIP, R_TIP, R_PIP, M_TIP, M_PIP, I_TIP, I_PIP]
    + [T_TIP, T_IP, T_MCP, None, None, None],
    # XrHandJointEXT 0..25.
    "openxr26": [None, WRIST, T_CMC, T_MCP, T_IP, T_TIP]
    + [None, I_MCP, I_PIP, I_DIP, I_TIP]
    + [None, M_MCP, M_PIP, M_DIP, M_TIP]
    + [None, R_MCP, R_PIP, R_DIP, R_TIP]
    + [None, L_MCP, L_PIP, L_DIP, L_TIP],
}

ALL_FORMATS = sorted(EXPECTED_SOURCES)
VALID = "bighand21, icvl16, mediapipe21, msra21, nyu14, openpose21, openxr26"


def _encoded(n_points: int, lead: tuple[int, ...] = (), dim: int = 3) -> np.ndarray:
    """Keypoints whose coordinates encode their point index (and batch position)."""
    idx = np.arange(n_points, dtype=float)[:, None] * np.array([1.0, 100.0, -1.0][:dim])
    batch = np.arange(int(np.prod(lead)), dtype=float).reshape(lead + (1, 1)) * 1000.0
    return idx + batch


def _random(lead: tuple[int, ...] = (), dim: int = 3, n_points: int = 21) -> np.ndarray:
    return np.random.default_rng(7).normal(size=lead + (n_points, dim))


def test_keypoint_names_are_the_mediapipe_order() -> None:
    """KEYPOINT_NAMES lists wrist, thumb CMC..tip, then MCP..tip of index to little."""
    expected = ["wrist", "thumb_cmc", "thumb_mcp", "thumb_ip", "thumb_tip"] + [
        f"{f}_{j}"
        for f in ("index", "middle", "ring", "little")
        for j in ("mcp", "pip", "dip", "tip")
    ]
    assert KEYPOINT_NAMES == tuple(expected)
    assert KEYPOINT_NAMES[8] == "index_tip"
    assert KEYPOINT_NAMES[20] == "little_tip"


def test_formats_registry() -> None:
    """Every format is registered, read-only, with as many unique names as its suffix says."""
    assert sorted(FORMATS) == ALL_FORMATS
    for fmt, names in FORMATS.items():
        assert isinstance(names, tuple)
        assert len(names) == len(EXPECTED_SOURCES[fmt]) == int(re.findall(r"\d+$", fmt)[0])
        assert len(set(names)) == len(names)
    with pytest.raises(TypeError):
        FORMATS["mine"] = ("wrist",)  # type: ignore[index]


def test_format_point_names_follow_their_sources() -> None:
    """Point names are spelled as in each format's source."""
    assert FORMATS["mediapipe21"][:2] == ("WRIST", "THUMB_CMC")
    assert FORMATS["mediapipe21"][5] == "INDEX_FINGER_MCP"
    assert FORMATS["mediapipe21"][17] == "PINKY_MCP"
    assert FORMATS["openpose21"] == KEYPOINT_NAMES
    assert FORMATS["msra21"][:2] == ("wrist", "index_mcp")
    assert FORMATS["msra21"][13:18] == (
        "little_mcp",
        "little_pip",
        "little_dip",
        "little_tip",
        "thumb_mcp",
    )
    assert FORMATS["bighand21"][:7] == ("Wrist", "TMCP", "IMCP", "MMCP", "RMCP", "PMCP", "TPIP")
    assert FORMATS["bighand21"][-1] == "PTIP"
    assert FORMATS["icvl16"][:4] == ("palm", "thumb_root", "thumb_mid", "thumb_tip")
    assert FORMATS["icvl16"][-1] == "pinky_tip"
    assert FORMATS["nyu14"] == (
        "F1_KNU3_A", "F1_KNU2_B", "F2_KNU3_A", "F2_KNU2_B", "F3_KNU3_A", "F3_KNU2_B",
        "F4_KNU3_A", "F4_KNU2_B", "TH_KNU3_A", "TH_KNU3_B", "TH_KNU2_B",
        "PALM_1", "PALM_2", "PALM_3",
    )  # fmt: skip
    assert FORMATS["openxr26"][:3] == (
        "XR_HAND_JOINT_PALM_EXT",
        "XR_HAND_JOINT_WRIST_EXT",
        "XR_HAND_JOINT_THUMB_METACARPAL_EXT",
    )
    assert FORMATS["openxr26"][8] == "XR_HAND_JOINT_INDEX_INTERMEDIATE_EXT"
    assert FORMATS["openxr26"][25] == "XR_HAND_JOINT_LITTLE_TIP_EXT"


@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_to_format_index_mapping(fmt: str) -> None:
    """Each copied point lands at the format position its source gives."""
    canonical = _encoded(21, lead=(2,))
    out = to_format(canonical, fmt)
    assert out.shape == (2, len(EXPECTED_SOURCES[fmt]), 3)
    for j, c in enumerate(EXPECTED_SOURCES[fmt]):
        if c is not None:
            np.testing.assert_array_equal(out[:, j], canonical[:, c], err_msg=f"{fmt}[{j}]")


@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_from_format_index_mapping_and_mask(fmt: str) -> None:
    """from_format inverts the mapping, NaN-fills absent points and present_mask agrees."""
    sources = EXPECTED_SOURCES[fmt]
    given = _encoded(len(sources), lead=(2,))
    out = from_format(given, fmt)
    assert out.shape == (2, 21, 3)
    mask = present_mask(fmt)
    assert mask.shape == (21,) and mask.dtype == bool
    for c in range(21):
        copies = [j for j, s in enumerate(sources) if s == c]
        if fmt == "nyu14" and c == WRIST:
            copies = [11, 12]  # the midpoint of the two NYU wrist points is the wrist
        assert mask[c] == bool(copies), KEYPOINT_NAMES[c]
        if copies:
            np.testing.assert_array_equal(out[:, c], given[:, copies].mean(axis=1))
        else:
            assert np.isnan(out[:, c]).all(), KEYPOINT_NAMES[c]


def test_present_points_per_format() -> None:
    """The canonical points each format lacks, by name."""
    absent = {
        fmt: [KEYPOINT_NAMES[c] for c in np.flatnonzero(~present_mask(fmt))] for fmt in FORMATS
    }
    assert absent == {
        "bighand21": [],
        "icvl16": ["wrist", "thumb_cmc", "index_mcp", "middle_mcp", "ring_mcp", "little_mcp"],
        "mediapipe21": [],
        "msra21": [],
        "nyu14": ["thumb_cmc", "index_mcp", "index_dip", "middle_mcp", "middle_dip"]
        + ["ring_mcp", "ring_dip", "little_mcp", "little_dip"],
        "openpose21": [],
        "openxr26": [],
    }


@pytest.mark.parametrize("fmt", ["mediapipe21", "openpose21"])
def test_identity_formats(fmt: str) -> None:
    """mediapipe21 and openpose21 are the canonical order and return copies."""
    canonical = _random(lead=(3,))
    out = to_format(canonical, fmt)
    np.testing.assert_array_equal(out, canonical)
    assert not np.shares_memory(out, canonical)
    np.testing.assert_array_equal(from_format(canonical, fmt), canonical)
    assert present_mask(fmt).all()


@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_round_trip_canonical_format_canonical(fmt: str) -> None:
    """Round trip canonical -> fmt -> canonical is exact on the present points."""
    canonical = _random(lead=(3, 2))
    back = from_format(to_format(canonical, fmt), fmt)
    mask = present_mask(fmt)
    np.testing.assert_allclose(back[..., mask, :], canonical[..., mask, :], rtol=0, atol=1e-12)
    assert np.isnan(back[..., ~mask, :]).all()


@pytest.mark.parametrize("fmt", ["bighand21", "mediapipe21", "msra21", "openpose21"])
def test_round_trip_format_canonical_format_for_permutations(fmt: str) -> None:
    """Round trip fmt -> canonical -> fmt is exact for pure reorderings."""
    given = _random(lead=(4,))
    np.testing.assert_array_equal(to_format(from_format(given, fmt), fmt), given)


def test_palm_centre_is_mean_of_wrist_and_finger_mcps() -> None:
    """ICVL palm and NYU PALM_3 are the mean of wrist and the four finger MCPs."""
    kp = _random(lead=(5,))
    palm = kp[:, [WRIST, I_MCP, M_MCP, R_MCP, L_MCP]].mean(axis=1)
    np.testing.assert_allclose(to_format(kp, "icvl16")[:, 0], palm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(to_format(kp, "nyu14")[:, 13], palm, rtol=0, atol=1e-12)


def test_openxr_metacarpal_bases_and_palm() -> None:
    """OpenXR finger metacarpal bases sit one metacarpal length before the MCP; palm mid-way."""
    assert dict(METACARPAL_BASE_FRACTION) == {
        "index": 0.19,
        "middle": 0.16,
        "ring": 0.21,
        "little": 0.30,
    }
    kp = _random(lead=(5,))
    out = to_format(kp, "openxr26")
    wrist = kp[:, WRIST]
    for xr_index, mcp, a in (
        (6, I_MCP, 0.19),
        (11, M_MCP, 0.16),
        (16, R_MCP, 0.21),
        (21, L_MCP, 0.3),
    ):
        base = wrist + a * (kp[:, mcp] - wrist)
        np.testing.assert_allclose(out[:, xr_index], base, rtol=0, atol=1e-12)
    middle_base = out[:, 11]
    np.testing.assert_allclose(out[:, 0], (middle_base + kp[:, M_MCP]) / 2, rtol=0, atol=1e-12)


def test_nyu_wrist_points() -> None:
    """The NYU wrist points lie ulnar and radial of the wrist; from_format takes their midpoint."""
    kp = _random(lead=(5,))
    out = to_format(kp, "nyu14")
    across = kp[:, I_MCP] - kp[:, L_MCP]
    np.testing.assert_allclose(out[:, 11], kp[:, WRIST] - 0.25 * across, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[:, 12], kp[:, WRIST] + 0.25 * across, rtol=0, atol=1e-12)
    np.testing.assert_allclose(from_format(out, "nyu14")[:, WRIST], kp[:, WRIST], atol=1e-12)
    nyu = _random(n_points=14)
    nyu[11], nyu[12] = [0.0, 0.0, 0.5], [0.2, 0.4, 0.7]
    np.testing.assert_allclose(from_format(nyu, "nyu14")[WRIST], [0.1, 0.2, 0.6])


@pytest.mark.parametrize("side", ["right", "left"])
def test_every_format_point_is_a_site_of_the_hand(side: str) -> None:
    """Sites, forward kinematics and to_format from the 21 keypoints agree for every format."""
    import mujoco

    from handsim.hand.kinematics import ForwardKinematics
    from handsim.hand.model import Hand, HandParams
    from handsim.hand.pose import JOINT_LIMITS, HandPose

    hand = Hand(HandParams(hand_length=0.2, side=side))
    model = hand.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    assert len(binding.point_site_ids) == len(HAND_POINT_NAMES) == 29
    rng = np.random.default_rng(0)
    fk = ForwardKinematics(hand.params)
    for _ in range(3):
        pose = HandPose(
            rng.uniform(-0.2, 0.2, 3),
            rng.uniform(-2, 2, 3),
            rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]),
        )
        binding.set_pose(data, pose)
        points = binding.points(data)
        np.testing.assert_allclose(points, fk.points(pose), atol=1e-9)
        for fmt in FORMATS:
            np.testing.assert_allclose(
                to_format(points, fmt), to_format(points[:21], fmt), rtol=0, atol=1e-12
            )
    # NYU's two wrist points are about 29 mm apart in its labels; here 29.4 mm at 189 mm.
    nyu = to_format(fk.points(HandPose.neutral()), "nyu14")
    assert np.linalg.norm(nyu[11] - nyu[12]) == pytest.approx(0.0294 * 0.2 / 0.189, abs=5e-4)


def test_icvl_finger_segments_are_middle_and_distal_phalanges() -> None:
    """ICVL index root -> mid -> tip: 28.7 and 18.6 mm in the data; the same bones here."""
    from handsim.hand.kinematics import ForwardKinematics
    from handsim.hand.model import HandParams
    from handsim.hand.pose import HandPose

    icvl = to_format(ForwardKinematics(HandParams()).keypoints(HandPose.neutral()), "icvl16")
    root, mid, tip = icvl[4:7]
    assert 1000 * np.linalg.norm(mid - root) == pytest.approx(28.7, abs=3.0)
    assert 1000 * np.linalg.norm(tip - mid) == pytest.approx(18.6, abs=3.0)


@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_conversion_commutes_with_rigid_motion(fmt: str) -> None:
    """Derived points are affine, so conversion commutes with a rigid motion."""
    kp = _random(lead=(2,))
    angle = 0.7
    rot = np.array(
        [[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0, 0, 1]]
    )
    shift = np.array([0.3, -1.2, 2.0])
    np.testing.assert_allclose(
        to_format(kp @ rot.T + shift, fmt), to_format(kp, fmt) @ rot.T + shift, atol=1e-12
    )


@pytest.mark.parametrize("fmt", ALL_FORMATS)
@pytest.mark.parametrize("lead", [(), (4,), (2, 3)])
@pytest.mark.parametrize("dim", [2, 3])
def test_batch_shapes_and_dimensions(fmt: str, lead: tuple[int, ...], dim: int) -> None:
    """Any leading batch shape and coordinate dimension converts point-wise."""
    n_fmt = len(FORMATS[fmt])
    canonical = _encoded(21, lead=lead, dim=dim)
    out = to_format(canonical, fmt)
    assert out.shape == lead + (n_fmt, dim)
    # Each batch element converts independently of the others.
    flat_in = canonical.reshape(-1, 21, dim)
    flat_out = out.reshape(-1, n_fmt, dim)
    for b in range(flat_in.shape[0]):
        np.testing.assert_array_equal(flat_out[b], to_format(flat_in[b], fmt))
    back = from_format(out, fmt)
    assert back.shape == lead + (21, dim)


def test_pixel_keypoints_map_like_3d() -> None:
    """2D keypoints convert like the first two coordinates of 3D ones."""
    kp3 = _random(lead=(3,))
    for fmt in ALL_FORMATS:
        np.testing.assert_allclose(to_format(kp3[..., :2], fmt), to_format(kp3, fmt)[..., :2])


def test_dtypes() -> None:
    """Float dtypes are kept; integers and lists become float64."""
    kp32 = _random().astype(np.float32)
    assert to_format(kp32, "openxr26").dtype == np.float32
    assert from_format(to_format(kp32, "nyu14"), "nyu14").dtype == np.float32
    ints = np.arange(21 * 2).reshape(21, 2)
    out = to_format(ints, "msra21")
    assert out.dtype == np.float64
    assert out[17].tolist() == [2.0, 3.0]  # MSRA thumb base = canonical thumb_cmc
    assert to_format(ints.tolist(), "msra21").tolist() == out.tolist()


def test_inputs_are_not_modified() -> None:
    """Conversions never write into their input."""
    kp = _random(lead=(2,))
    before = kp.copy()
    to_format(kp, "openxr26")
    from_format(to_format(kp, "nyu14"), "nyu14")
    np.testing.assert_array_equal(kp, before)


def test_nan_propagates_only_to_dependent_points() -> None:
    """A NaN input only spoils the output points computed from it."""
    kp = _random()
    kp[T_TIP] = np.nan
    out = to_format(kp, "openxr26")
    assert np.isnan(out[5]).all()
    assert np.isfinite(np.delete(out, 5, axis=0)).all()
    kp = _random()
    kp[I_DIP] = np.nan  # NYU has no DIP, so nothing depends on it
    assert np.isfinite(to_format(kp, "nyu14")).all()
    kp = _random()
    kp[WRIST] = np.nan
    out = to_format(kp, "icvl16")
    assert np.isnan(out[0]).all() and np.isfinite(out[1:]).all()
    kp = _random()
    kp[L_MCP] = np.nan  # the NYU wrist points and the palm centre depend on it
    out = to_format(kp, "nyu14")
    assert np.isnan(out[11:]).all() and np.isfinite(out[:11]).all()


@pytest.mark.parametrize("bad", ["nyu", "NYU14", "", None, 3])
def test_unknown_format_is_rejected(bad: object) -> None:
    """Unknown formats raise UnknownName listing the valid formats."""
    message = re.escape(f"unknown keypoint format {bad!r}; valid formats: {VALID}")
    with pytest.raises(UnknownName, match=f"^{message}$"):
        to_format(_random(), bad)  # type: ignore[arg-type]
    with pytest.raises(UnknownName, match=f"^{message}$"):
        from_format(_random(), bad)  # type: ignore[arg-type]
    with pytest.raises(UnknownName, match=f"^{message}$"):
        present_mask(bad)  # type: ignore[arg-type]


def test_unknown_format_error_types() -> None:
    """UnknownName is both a KeyError and a HandSimError."""
    with pytest.raises(UnknownName) as info:
        to_format(_random(), "nyu")
    assert isinstance(info.value, KeyError) and isinstance(info.value, HandSimError)


def test_unknown_format_is_reported_before_shape() -> None:
    """A bad format is reported even when the keypoints are also bad."""
    with pytest.raises(UnknownName, match="unknown keypoint format 'nyu'"):
        to_format(np.zeros(3), "nyu")


@pytest.mark.parametrize(
    ("shape", "shown"),
    [((20, 3), "(20, 3)"), ((21,), "(21,)"), ((21, 0), "(21, 0)"), ((2, 3, 21), "(2, 3, 21)")],
)
def test_to_format_rejects_bad_shapes(shape: tuple[int, ...], shown: str) -> None:
    """to_format needs (..., 21, D) and says what it got."""
    message = re.escape(
        "expected canonical keypoints of shape (..., 21, D) or hand points of shape "
        f"(..., 29, D) with D >= 1, got shape {shown}"
    )
    with pytest.raises(InvalidKeypoints, match=f"^{message}$"):
        to_format(np.zeros(shape), "msra21")


def test_from_format_rejects_bad_shapes() -> None:
    """from_format needs the format's point count and says what it got."""
    message = re.escape(
        "expected 'nyu14' keypoints of shape (..., 14, D) with D >= 1, got shape (4, 21, 3)"
    )
    with pytest.raises(InvalidKeypoints, match=f"^{message}$"):
        from_format(np.zeros((4, 21, 3)), "nyu14")
    message = re.escape(
        "expected 'openxr26' keypoints of shape (..., 26, D) with D >= 1, got shape ()"
    )
    with pytest.raises(InvalidKeypoints, match=f"^{message}$"):
        from_format(1.0, "openxr26")


@pytest.mark.parametrize(
    ("values", "dtype"),
    [
        (np.full((21, 3), "a"), "<U1"),
        (np.zeros((21, 3), dtype=bool), "bool"),
        (np.zeros((21, 3), dtype=complex), "complex128"),
        (np.empty((21, 3), dtype=object), "object"),
    ],
)
def test_non_numeric_keypoints_are_rejected(values: np.ndarray, dtype: str) -> None:
    """Strings, bools, complex and objects are not keypoints."""
    message = re.escape(
        f"expected real numeric canonical keypoints (int or float), got dtype {dtype}"
    )
    with pytest.raises(InvalidKeypoints, match=f"^{message}$"):
        to_format(values, "bighand21")
    with pytest.raises(InvalidKeypoints, match="expected real numeric 'bighand21' keypoints"):
        from_format(values, "bighand21")
