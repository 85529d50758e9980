"""Keypoint-order converters between handsim's canonical 21 keypoints and common hand formats.

handsim's canonical order is the MediaPipe / OpenPose 21-point hand (:data:`KEYPOINT_NAMES`)::

    0 wrist
    1-4   thumb  CMC, MCP, IP, tip
    5-8   index  MCP, PIP, DIP, tip
    9-12  middle MCP, PIP, DIP, tip
    13-16 ring   MCP, PIP, DIP, tip
    17-20 little MCP, PIP, DIP, tip

Keypoints are arrays of shape ``(..., N, D)``: any leading batch shape, ``N`` points in the
order of the format, ``D`` coordinates (``D = 3`` for metres in any frame, ``D = 2`` for
pixels; any ``D >= 1`` works). Conversions never change units or frames, and left and right
hands use the same order (nothing is mirrored).

Formats (``FORMATS[name]`` holds the names of a format's points in its own order):

``mediapipe21``
    Identity. Source: MediaPipe ``HandLandmark`` enum ("The 21 hand landmarks", WRIST = 0,
    THUMB_CMC = 1 ... PINKY_TIP = 20); names and indices checked.
``openpose21``
    Same order as mediapipe21; OpenPose publishes indices only, so the canonical names are
    used. Source: OpenPose ``doc/02_output.md`` (hand output figure) and the CMU Panoptic
    HandDB keypoint list in mmpose ``configs/_base_/datasets/panoptic_hand2d.py`` (wrist,
    thumb1-4, forefinger1-4, middle_finger1-4, ring_finger1-4, pinky_finger1-4).
``msra21``
    MSRA15 (Sun et al., CVPR 2015): wrist, then index, middle, ring, little, thumb, each
    ``mcp, pip, dip, tip``. Source: the dataset readme
    (``cvpr15_MSRAHandGestureDB_readme.txt``), which lists the 21 names verbatim;
    cross-checked with V2V-PoseNet ``vis/msra/draw_2Dskeleton_MSRA.m``. The readme names the
    thumb chain ``thumb_mcp, thumb_pip, thumb_dip, thumb_tip``; those are its four points from
    base to tip and are mapped to canonical ``thumb_cmc, thumb_mcp, thumb_ip, thumb_tip``.
``bighand21``
    BigHand2.2M / HANDS 2017 / F-PHAB: ``Wrist, TMCP, IMCP, MMCP, RMCP, PMCP``, then ``PIP,
    DIP, TIP`` of T, I, M, R, P. Source: the HANDS 2017 challenge convention as written in
    xkunwu/depth-hand (``join_name``) and F-PHAB converters. The thumb's ``TMCP, TPIP,
    TDIP`` are its chain from base to tip and are mapped to canonical ``thumb_cmc,
    thumb_mcp, thumb_ip``, as for MSRA.
``icvl16``
    ICVL (Tang et al., CVPR 2014): palm, then thumb, index, middle, ring, pinky, each
    ``root, mid, tip``. Order source: DeepPrior++ ``ICVLHandposeEvaluation`` (joint names
    ``C, T1-T3, I1-I3, M1-M3, R1-R3, P1-P3``) and V2V-PoseNet
    ``vis/icvl/draw_2Dskeleton_ICVL.m`` (V2V calls point 0 "wrist", DeepPrior++ "C"; it is
    the crop centre, so it is treated as the palm centre). The fingers' ``root, mid, tip``
    are PIP, DIP and tip: in the ICVL test labels the index's root -> mid and mid -> tip
    segments are 28.7 and 18.6 mm long, the lengths of the middle and distal phalanges, not
    of the proximal one. The thumb's are, by the same count from the base, MCP, IP and tip.
``nyu14``
    The 14 of NYU's 36 joints used by the Tompson et al. / DeepPrior / V2V / A2J evaluations:
    NYU indices ``[0, 3, 6, 9, 12, 15, 18, 21, 24, 25, 27, 30, 31, 32]``
    (DeepPrior++ ``NYUImporter.restrictedJointsEval``; the same list is in the
    awesome-hand-pose-estimation evaluation README). Joint names are from mmpose
    ``configs/_base_/datasets/nyu.py``. DeepPrior++ ``NYUHandposeEvaluation`` labels them
    ``P1 P2 R1 R2 M1 M2 I1 I2 T1 T2 T3 W1 W2 C``, and V2V-PoseNet
    ``vis/nyu/draw_2Dskeleton_NYU.m`` labels them pinky tip/mid, ring, middle, index, thumb
    tip/mid/root, wrist back, wrist, palm. So F1..F4 are pinky, ring, middle and index.
    Canonical mapping: ``Fk_KNU3_A`` is the tip, ``Fk_KNU2_B`` is the PIP, ``TH_KNU3_A``,
    ``TH_KNU3_B`` and ``TH_KNU2_B`` are the thumb tip, IP and MCP, ``PALM_1`` and ``PALM_2``
    are the two wrist points (about 29 mm apart in the labels; taken as the ulnar and radial
    sides of the wrist, in NYU's ulnar-to-radial finger order; their exact anatomical meaning
    is not documented) and ``PALM_3`` is the palm centre. The meaning of KNU/A/B
    (KNU3/2/1 = distal/middle/proximal phalanx, B = base of that bone) is from community
    notes (zanecodes/thesis ``docs/nyu_dataset.md``), not from the dataset authors.
``openxr26``
    ``XrHandJointEXT`` of XR_EXT_hand_tracking: PALM = 0, WRIST = 1, thumb METACARPAL,
    PROXIMAL, DISTAL, TIP = 2-5, then index, middle, ring, little METACARPAL, PROXIMAL,
    INTERMEDIATE, DISTAL, TIP = 6-25. Source: the Khronos registry page for
    ``XrHandJointEXT`` (enum values). A joint is located at the proximal end of the bone it
    is named after, so THUMB_METACARPAL = thumb CMC, INDEX_PROXIMAL = index MCP,
    INDEX_INTERMEDIATE = index PIP, INDEX_DISTAL = index DIP. The palm is "at the center of
    the middle finger's metacarpal bone". That phrase is the spec's as quoted in Godot's
    OpenXRHand docs; the spec section itself was not read.

Points missing from the canonical set (:data:`EXTRA_POINT_NAMES`) are sites of the hand, fixed
in the palm and placed by :data:`EXTRA_POINT_RULES`, affine combinations of the wrist and the
MCPs (weights sum to 1, so the rules hold in any frame):

* ``palm_centre`` (``icvl16`` palm, ``nyu14`` PALM_3) = mean of the wrist and the four MCPs;
* ``wrist_ulnar``, ``wrist_radial`` (``nyu14`` PALM_1, PALM_2) = wrist -/+
  :data:`NYU_WRIST_HALF_SPAN` * (index MCP - little MCP);
* ``<finger>_cmc`` (``openxr26`` METACARPAL of the fingers) = wrist +
  :data:`METACARPAL_BASE_FRACTION` [finger] * (MCP - wrist);
* ``middle_metacarpal_centre`` (``openxr26`` PALM) = midpoint of the middle CMC and MCP.

:func:`to_format` copies them from the hand's points (:data:`HAND_POINT_NAMES`, read from the
sites or from forward kinematics) or computes them by the same rules from the 21 keypoints.
For 2D (pixel) keypoints the rules are applied in the image plane, which differs slightly from
projecting the 3D points under a perspective camera.

:func:`from_format` returns NaN for canonical points a format lacks; :func:`present_mask`
tells which points are present. The only non-copied canonical point is the ``nyu14`` wrist,
the midpoint of PALM_1 and PALM_2. See ``docs/keypoints.md`` for every format's joints and sources.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from handsim.errors import InvalidKeypoints, UnknownName
from handsim.hand.pose import FINGERS

__all__ = [
    "EXTRA_POINT_NAMES",
    "EXTRA_POINT_RULES",
    "FORMATS",
    "HAND_POINT_NAMES",
    "KEYPOINT_NAMES",
    "METACARPAL_BASE_FRACTION",
    "NYU_WRIST_HALF_SPAN",
    "format_flags",
    "from_format",
    "present_mask",
    "to_format",
]


KEYPOINT_NAMES: tuple[str, ...] = (
    "wrist",
    "thumb_cmc",
    "thumb_mcp",
    "thumb_ip",
    "thumb_tip",
    *(f"{finger}_{joint}" for finger in FINGERS for joint in ("mcp", "pip", "dip", "tip")),
)
"""Names of the 21 canonical keypoints, in canonical order."""

METACARPAL_BASE_FRACTION: Mapping[str, float] = MappingProxyType(
    {"index": 0.19, "middle": 0.16, "ring": 0.21, "little": 0.30}
)
"""Where each finger's metacarpal base (CMC joint) sits on the wrist -> MCP segment.

The MCP minus the metacarpal's length (Buchholz, Armstrong & Goldstein 1992: 0.374, 0.373,
0.336, 0.295 of hand length for index to little) along the wrist -> MCP line, as a fraction of
that line, for handsim's default hand proportions.
"""

NYU_WRIST_HALF_SPAN: float = 0.25
"""NYU's two wrist points: wrist -/+ this times (index MCP - little MCP).

The two points are about 29 mm apart in NYU's annotations; on handsim's default hand the index
and little MCPs are 58.8 mm apart, so 0.25 puts the points 29.4 mm apart, on the ulnar and
radial sides of the wrist.
"""

EXTRA_POINT_NAMES: tuple[str, ...] = (
    "palm_centre",
    "wrist_ulnar",
    "wrist_radial",
    *(f"{finger}_cmc" for finger in FINGERS),
    "middle_metacarpal_centre",
)
"""Points of other formats that the canonical 21 lack; the hand carries a site for each."""

HAND_POINT_NAMES: tuple[str, ...] = KEYPOINT_NAMES + EXTRA_POINT_NAMES
"""Every point the hand carries a site for: the 21 keypoints, then :data:`EXTRA_POINT_NAMES`."""

EXTRA_POINT_RULES: Mapping[str, Mapping[str, float]] = MappingProxyType(
    {
        "palm_centre": MappingProxyType(
            {"wrist": 0.2, **{f"{finger}_mcp": 0.2 for finger in FINGERS}}
        ),
        "wrist_ulnar": MappingProxyType(
            {"wrist": 1.0, "index_mcp": -NYU_WRIST_HALF_SPAN, "little_mcp": NYU_WRIST_HALF_SPAN}
        ),
        "wrist_radial": MappingProxyType(
            {"wrist": 1.0, "index_mcp": NYU_WRIST_HALF_SPAN, "little_mcp": -NYU_WRIST_HALF_SPAN}
        ),
        **{
            f"{finger}_cmc": MappingProxyType(
                {
                    "wrist": 1.0 - METACARPAL_BASE_FRACTION[finger],
                    f"{finger}_mcp": METACARPAL_BASE_FRACTION[finger],
                }
            )
            for finger in FINGERS
        },
        # Halfway between the middle metacarpal's base and its head (the MCP).
        "middle_metacarpal_centre": MappingProxyType(
            {
                "wrist": (1.0 - METACARPAL_BASE_FRACTION["middle"]) / 2.0,
                "middle_mcp": (1.0 + METACARPAL_BASE_FRACTION["middle"]) / 2.0,
            }
        ),
    }
)
"""Each extra point as an affine combination of canonical points (weights sum to 1).

The wrist and the MCPs are fixed in the palm, so these points are too: the hand's sites sit
exactly where the rules put them (:func:`handsim.hand.skeleton.extra_point_positions`), and
:func:`to_format` gives the same positions from the 21 keypoints as from the sites.
"""

_INDEX = {name: i for i, name in enumerate(KEYPOINT_NAMES)}

# A rule is a tuple of (source index, weight) pairs; None marks a point with no source.
_Rule = tuple[tuple[int, float], ...]


@dataclass(frozen=True)
class _Format:
    names: tuple[str, ...]
    sources: tuple[int, ...]  # one per format point: its index in HAND_POINT_NAMES
    from_rules: tuple[_Rule | None, ...]  # one per canonical point, over format points


def _combo(weights: Mapping[str, float]) -> _Rule:
    return tuple((_INDEX[name], float(w)) for name, w in weights.items())


_HAND_INDEX = {name: i for i, name in enumerate(HAND_POINT_NAMES)}
# Rules that give every hand point from the 21 keypoints.
_EXTEND_RULES: tuple[_Rule, ...] = tuple(((i, 1.0),) for i in range(len(KEYPOINT_NAMES))) + tuple(
    _combo(EXTRA_POINT_RULES[name]) for name in EXTRA_POINT_NAMES
)


def _build(
    names: tuple[str, ...],
    sources: tuple[str, ...],
    recover: Mapping[str, Mapping[str, float]] | None = None,
) -> _Format:
    """Build a format from its point names and, per point, the hand point it is.

    A canonical point is recovered by :func:`from_format` from the format point that is it,
    or by a ``recover`` rule (canonical name -> weights over format point names); all other
    canonical points are absent.
    """
    from_rules: list[_Rule | None] = [None] * len(KEYPOINT_NAMES)
    for j, source in enumerate(sources):
        k = _HAND_INDEX[source]
        if k < len(KEYPOINT_NAMES) and from_rules[k] is None:
            from_rules[k] = ((j, 1.0),)
    position = {name: j for j, name in enumerate(names)}
    for canonical, weights in (recover or {}).items():
        from_rules[_INDEX[canonical]] = tuple((position[n], float(w)) for n, w in weights.items())
    if len(names) != len(sources):
        raise AssertionError("one source per format point")
    return _Format(names, tuple(_HAND_INDEX[n] for n in sources), tuple(from_rules))


_MEDIAPIPE_NAMES = (
    "WRIST",
    "THUMB_CMC",
    "THUMB_MCP",
    "THUMB_IP",
    "THUMB_TIP",
    *(
        f"{finger}_{joint}"
        for finger in ("INDEX_FINGER", "MIDDLE_FINGER", "RING_FINGER", "PINKY")
        for joint in ("MCP", "PIP", "DIP", "TIP")
    ),
)

_MSRA_NAMES = (
    "wrist",
    *(
        f"{finger}_{joint}"
        for finger in ("index", "middle", "ring", "little", "thumb")
        for joint in ("mcp", "pip", "dip", "tip")
    ),
)
_MSRA_SOURCES = (
    "wrist",
    *(f"{finger}_{joint}" for finger in FINGERS for joint in ("mcp", "pip", "dip", "tip")),
    "thumb_cmc",
    "thumb_mcp",
    "thumb_ip",
    "thumb_tip",
)

_BIGHAND_NAMES = (
    "Wrist",
    *(f"{f}MCP" for f in "TIMRP"),
    *(f"{f}{joint}" for f in "TIMRP" for joint in ("PIP", "DIP", "TIP")),
)
_BIGHAND_SOURCES = (
    "wrist",
    "thumb_cmc",
    *(f"{finger}_mcp" for finger in FINGERS),
    "thumb_mcp",
    "thumb_ip",
    "thumb_tip",
    *(f"{finger}_{joint}" for finger in FINGERS for joint in ("pip", "dip", "tip")),
)

_ICVL_NAMES = (
    "palm",
    *(
        f"{finger}_{joint}"
        for finger in ("thumb", "index", "middle", "ring", "pinky")
        for joint in ("root", "mid", "tip")
    ),
)
_ICVL_SOURCES = (
    "palm_centre",
    "thumb_mcp",
    "thumb_ip",
    "thumb_tip",
    *(f"{finger}_{joint}" for finger in FINGERS for joint in ("pip", "dip", "tip")),
)

_NYU_NAMES = (
    *(f"F{k}_{part}" for k in range(1, 5) for part in ("KNU3_A", "KNU2_B")),
    "TH_KNU3_A",
    "TH_KNU3_B",
    "TH_KNU2_B",
    "PALM_1",
    "PALM_2",
    "PALM_3",
)
_NYU_SOURCES = (
    *(f"{finger}_{joint}" for finger in reversed(FINGERS) for joint in ("tip", "pip")),
    "thumb_tip",
    "thumb_ip",
    "thumb_mcp",
    "wrist_ulnar",
    "wrist_radial",
    "palm_centre",
)

_OPENXR_NAMES = tuple(
    f"XR_HAND_JOINT_{joint}_EXT"
    for joint in (
        "PALM",
        "WRIST",
        *(f"THUMB_{b}" for b in ("METACARPAL", "PROXIMAL", "DISTAL", "TIP")),
        *(
            f"{finger.upper()}_{b}"
            for finger in FINGERS
            for b in ("METACARPAL", "PROXIMAL", "INTERMEDIATE", "DISTAL", "TIP")
        ),
    )
)
_OPENXR_SOURCES = (
    "middle_metacarpal_centre",
    "wrist",
    "thumb_cmc",
    "thumb_mcp",
    "thumb_ip",
    "thumb_tip",
    *(
        s
        for finger in FINGERS
        for s in (
            f"{finger}_cmc",
            f"{finger}_mcp",
            f"{finger}_pip",
            f"{finger}_dip",
            f"{finger}_tip",
        )
    ),
)

_SPECS: dict[str, _Format] = {
    "bighand21": _build(_BIGHAND_NAMES, _BIGHAND_SOURCES),
    "icvl16": _build(_ICVL_NAMES, _ICVL_SOURCES),
    "mediapipe21": _build(_MEDIAPIPE_NAMES, KEYPOINT_NAMES),
    "msra21": _build(_MSRA_NAMES, _MSRA_SOURCES),
    # The two NYU wrist points lie symmetrically about the wrist: their midpoint is the wrist.
    "nyu14": _build(_NYU_NAMES, _NYU_SOURCES, {"wrist": {"PALM_1": 0.5, "PALM_2": 0.5}}),
    "openpose21": _build(KEYPOINT_NAMES, KEYPOINT_NAMES),
    "openxr26": _build(_OPENXR_NAMES, _OPENXR_SOURCES),
}

FORMATS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {name: spec.names for name, spec in sorted(_SPECS.items())}
)
"""Registered formats: format name -> names of its points, in the format's own order."""


def _spec(fmt: object) -> _Format:
    if isinstance(fmt, str) and fmt in _SPECS:
        return _SPECS[fmt]
    raise UnknownName(f"unknown keypoint format {fmt!r}; valid formats: {', '.join(FORMATS)}")


def _as_points(keypoints: ArrayLike, n_points: int, what: str) -> NDArray[np.floating]:
    arr = np.asarray(keypoints)
    if arr.dtype.kind not in "iuf":
        raise InvalidKeypoints(
            f"expected real numeric {what} (int or float), got dtype {arr.dtype}"
        )
    if arr.ndim < 2 or arr.shape[-2] != n_points or arr.shape[-1] < 1:
        raise InvalidKeypoints(
            f"expected {what} of shape (..., {n_points}, D) with D >= 1, got shape {arr.shape}"
        )
    return arr if arr.dtype.kind == "f" else arr.astype(np.float64)


def _apply(arr: NDArray[np.floating], rules: tuple[_Rule | None, ...]) -> NDArray[np.floating]:
    out = np.empty(arr.shape[:-2] + (len(rules), arr.shape[-1]), dtype=arr.dtype)
    for i, rule in enumerate(rules):
        if rule is None:
            out[..., i, :] = np.nan
        elif len(rule) == 1 and rule[0][1] == 1.0:
            out[..., i, :] = arr[..., rule[0][0], :]
        else:
            # Gather only the sources, so a NaN elsewhere cannot leak in through a 0 weight.
            out[..., i, :] = sum(w * arr[..., j, :] for j, w in rule)
    return out


def to_format(keypoints: ArrayLike, fmt: str) -> NDArray[np.floating]:
    """Convert canonical keypoints (or all hand points) to the order of another format.

    Given the hand's points read from its sites (``(..., 29, D)`` in
    :data:`HAND_POINT_NAMES` order: :meth:`handsim.hand.model.HandBinding.points`,
    :meth:`handsim.hand.kinematics.ForwardKinematics.points`), every format point is copied
    from the hand. Given the 21 canonical keypoints, the extra points (palm centre, NYU wrist
    points, finger metacarpal bases, OpenXR palm) are computed by :data:`EXTRA_POINT_RULES`,
    which put them where the hand's sites are. NaN inputs propagate only into the points
    computed from them.

    Args:
        keypoints: Canonical keypoints, shape ``(..., 21, D)``, or hand points, shape
            ``(..., 29, D)``, with ``D >= 1``, e.g. metres (``D = 3``) or pixels (``D = 2``;
            under a perspective camera, extra points computed from pixels differ slightly
            from projected sites). Integers are converted to float64; float dtypes are kept.
        fmt: Target format, a key of :data:`FORMATS`.

    Returns:
        A new array of shape ``(..., N_fmt, D)`` in the target format's order, in the
        same units and frame as the input.

    Raises:
        UnknownName: ``fmt`` is not a registered format.
        InvalidKeypoints: ``keypoints`` is not a real numeric array of shape
            ``(..., 21, D)`` or ``(..., 29, D)``.
    """
    spec = _spec(fmt)
    arr = np.asarray(keypoints)
    if arr.ndim >= 2 and arr.shape[-2] == len(HAND_POINT_NAMES):
        points = _as_points(arr, len(HAND_POINT_NAMES), "hand points")
        return points[..., list(spec.sources), :].copy()
    n = len(KEYPOINT_NAMES)
    if arr.dtype.kind in "iuf" and (arr.ndim < 2 or arr.shape[-2] != n or arr.shape[-1] < 1):
        raise InvalidKeypoints(
            f"expected canonical keypoints of shape (..., {n}, D) or hand points of shape "
            f"(..., {len(HAND_POINT_NAMES)}, D) with D >= 1, got shape {arr.shape}"
        )
    canonical = _as_points(arr, n, "canonical keypoints")
    rules = tuple(_EXTEND_RULES[k] for k in spec.sources)
    return _apply(canonical, rules)


def from_format(keypoints: ArrayLike, fmt: str) -> NDArray[np.floating]:
    """Convert keypoints from another format to the canonical order.

    Canonical points the format lacks are NaN; :func:`present_mask` lists which points are
    present. Every present point is copied from one format point, except the ``nyu14``
    wrist, which is the midpoint of PALM_1 and PALM_2.

    Args:
        keypoints: Keypoints in the order of ``fmt``, shape ``(..., N_fmt, D)`` with
            ``D >= 1`` (``N_fmt = len(FORMATS[fmt])``). Integers are converted to float64;
            float dtypes are kept.
        fmt: Source format, a key of :data:`FORMATS`.

    Returns:
        A new array of shape ``(..., 21, D)`` in canonical order, in the same units and
        frame as the input, with NaN rows for the absent points.

    Raises:
        UnknownName: ``fmt`` is not a registered format.
        InvalidKeypoints: ``keypoints`` is not a real numeric array of shape
            ``(..., N_fmt, D)``.
    """
    spec = _spec(fmt)
    arr = _as_points(keypoints, len(spec.names), f"{fmt!r} keypoints")
    return _apply(arr, spec.from_rules)


def format_flags(flags: ArrayLike, fmt: str) -> NDArray[np.bool_]:
    """Per-keypoint flags (e.g. ``visible``) carried over to another format's points.

    A format point copied from a canonical keypoint takes its flag; a point computed from
    several (:data:`EXTRA_POINT_RULES`: the palm centre, the NYU wrist points, the metacarpal
    bases) is flagged only when every keypoint it is computed from is.

    Args:
        flags: (..., 21) booleans in canonical order.
        fmt: a key of :data:`FORMATS`.

    Returns:
        A new (..., N_fmt) bool array in the format's order.

    Raises:
        UnknownName: ``fmt`` is not a registered format.
        InvalidKeypoints: ``flags`` is not of shape ``(..., 21)``.
    """
    spec = _spec(fmt)
    arr = np.asarray(flags, dtype=bool)
    if arr.ndim < 1 or arr.shape[-1] != len(KEYPOINT_NAMES):
        raise InvalidKeypoints(
            f"expected flags of shape (..., {len(KEYPOINT_NAMES)}), got shape {arr.shape}"
        )
    return np.stack(
        [arr[..., [j for j, _ in _EXTEND_RULES[k]]].all(axis=-1) for k in spec.sources], axis=-1
    )


def present_mask(fmt: str) -> NDArray[np.bool_]:
    """Tell which canonical keypoints :func:`from_format` recovers for a format.

    Args:
        fmt: A key of :data:`FORMATS`.

    Returns:
        A new boolean array of shape ``(21,)``, True where the canonical point is present
        and False where :func:`from_format` returns NaN.

    Raises:
        UnknownName: ``fmt`` is not a registered format.
    """
    spec = _spec(fmt)
    return np.array([rule is not None for rule in spec.from_rules], dtype=bool)
