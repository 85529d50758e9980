"""Pose samplers: uniform within the limits with anatomical couplings, postural synergies.

Anatomical couplings (:func:`sample_uniform` with ``coupled=True``)
------------------------------------------------------------------

1. **DIP = 2/3 PIP** (Rijpkema & Girard 1991, used by Lin et al. 2000): each
   finger's DIP is ``DIP_PIP_RATIO * PIP`` plus Gaussian noise of ``DIP_NOISE_DEG`` = 5 deg
   standard deviation clipped at 2 sigma (10 deg), then clipped to the DIP limits. The noise is an
   engineering choice [E]: the rule is a mean relation, not an identity.
2. **MCP abduction shrinks with MCP flexion**: the collateral ligaments of the finger MCP
   joints are slack in extension and taut in flexion (cam-shaped metacarpal heads), so spread is
   largest with the finger straight and nearly nil in a fist [anatomy, well known; numbers E].
   The abduction range is ``JOINT_LIMITS * f`` with ``f = 1 - (1 - ABD_RANGE_AT_FULL_FLEXION) *
   clip(mcp_flex / 90 deg, 0, 1)``: full range at 0 deg and below (hyperextension), 20 % of it
   at 90 deg; abduction is drawn uniformly within the shrunk range.
3. **Neighbouring fingers are not independent** (shared flexor bellies of the middle, ring and
   little fingers and the extensor juncturae; Häger-Ross & Schieber 2000 measured the ring
   finger as the least independent [M]). The rule bounds a finger's flexion against the *mean*
   of its two neighbours: the ring finger stays within ``INTERFINGER_MAX_DEVIATION_DEG["ring"]``
   = 55 deg of the mean of middle and little, and the middle finger within 65 deg of the mean
   of index and ring, for MCP flexion and for PIP flexion separately [E]. Pairwise bounds were
   rejected because they forbid easy gestures (victory, horns, "call me": a finger straight
   next to a curled one); the mean rule forbids what hands find hard, e.g. the ring finger
   straight while middle and little are in a fist. Flexions are drawn by rejection, so they
   are uniform over the constrained region. Index and little are otherwise free, the thumb is
   uniform within its limits.

With ``coupled=False`` every angle is independent and uniform within its limits.

Synergy basis
-------------

Santello, Flanders & Soechting (1998) recorded 15 joint angles while subjects shaped the hand
to many imagined objects; the first two principal components explained over 80 % of the variance
(J. Neurosci. 18:10105). No such recordings ship with handsim, so :func:`synergy_basis` follows
their protocol on a *synthetic* library: the postures of every grasp in :data:`GRASP_TYPES` at
11 closures from 0.5 to 1.0 (that is, holding objects from the largest to the smallest size of
each type; 143 postures). It is a PCA of handsim's own grasp table, not of human data: the
numbers below describe this library and are not a measurement.

- PC1 explains 56.0 % of the variance, PC1 + PC2 73.4 %, the first 3 83.4 % and the first 5
  94.8 % (asserted in the tests). Santello's >80 % for two components came from real hands
  grasping many objects; this library mixes 13 grasp types of distinct shapes, which spreads
  the variance over a third component.
- PC1 is PIP and DIP flexion of all four fingers together (loadings 0.22 to 0.43, MCP small):
  wrapping versus pad grasps. PC2 is MCP flexion of the middle, ring and little fingers with
  thumb flexion. Compared with GraspIt's human eigengrasps over the 12 finger flexions (GraspIt
  file ``human_eigen_cgdb_refined.xml``; :data:`GRASPIT_EG1_FINGER_FLEXION`): PC1 is
  GraspIt's EG2 ("PIP/DIP versus MCP", ``|cos| = 0.92``) rather than EG1 (``|cos| = 0.28``);
  EG1, finger MCP flexion together, is closest to PC2 (``|cos| = 0.83``). The two planes agree:
  span(PC1, PC2) holds 86 % of EG1's norm and 94 % of EG2's. The order differs because the
  library's largest contrast is between grasp types, not object sizes.
"""

from __future__ import annotations

import dataclasses
import functools
import types
from collections.abc import Mapping, Sequence

import numpy as np

from handsim._validate import show
from handsim.errors import InvalidPose
from handsim.hand._sampling import (
    _DIP,
    _HI,
    _LO,
    _MCP_ABD,
    _MCP_FLEX,
    _PIP,
    _THUMB,
    _batch_pose,
    _check_count,
    _check_positive,
    _check_rng,
)
from handsim.hand.pose import NUM_ANGLES, HandPose
from handsim.hand.pose_library import GRASP_TYPES

__all__ = [
    "DIP_PIP_RATIO",
    "DIP_NOISE_DEG",
    "ABD_RANGE_AT_FULL_FLEXION",
    "INTERFINGER_MAX_DEVIATION_DEG",
    "abduction_range_fraction",
    "sample_uniform",
    "SynergyBasis",
    "synergy_basis",
    "synergy_pose",
    "sample_synergy",
    "GRASPIT_EG1_FINGER_FLEXION",
]


# 1. Uniform sampling with anatomical couplings ---------------------------------------------

DIP_PIP_RATIO = 2.0 / 3.0
"""Mean DIP flexion / PIP flexion (Rijpkema & Girard 1991)."""
DIP_NOISE_DEG = 5.0
"""Standard deviation (deg) of the DIP deviation from ``DIP_PIP_RATIO * PIP``, before clipping
at 2 sigma [E]."""
ABD_RANGE_AT_FULL_FLEXION = 0.2
"""Fraction of the MCP abduction range left at 90 deg of MCP flexion [E]."""
INTERFINGER_MAX_DEVIATION_DEG: Mapping[str, float] = types.MappingProxyType(
    {"middle": 65.0, "ring": 55.0}
)
"""Largest difference (deg) between a finger's MCP (and PIP) flexion and the mean of its two
neighbours' [E]."""


def _interfinger_ok(flex: np.ndarray) -> np.ndarray:
    """(m, 4) finger flexions (rad, index..little) -> (m,) bool, the neighbour rule holds."""
    index, middle, ring, little = flex.T
    dev_middle = np.abs(middle - 0.5 * (index + ring))
    dev_ring = np.abs(ring - 0.5 * (middle + little))
    return (dev_middle <= np.deg2rad(INTERFINGER_MAX_DEVIATION_DEG["middle"])) & (
        dev_ring <= np.deg2rad(INTERFINGER_MAX_DEVIATION_DEG["ring"])
    )


def _sample_flexions(rng: np.random.Generator, n: int, cols: list[int]) -> np.ndarray:
    """(n, 4) flexions uniform within the limits of ``cols``, subject to the neighbour rule."""
    lo, hi = _LO[cols], _HI[cols]
    out = np.empty((0, 4))
    # Acceptance is about 0.8, so batches of 2n rarely need a second round.
    while len(out) < n:
        cand = rng.uniform(lo, hi, size=(2 * n + 16, 4))
        out = np.concatenate([out, cand[_interfinger_ok(cand)]])
    return out[:n]


def abduction_range_fraction(mcp_flex: np.ndarray) -> np.ndarray:
    """Fraction of the MCP abduction range available at a given MCP flexion (coupling rule 2).

    Args:
        mcp_flex: (...) MCP flexion, radians.

    Returns:
        (...) fraction in [:data:`ABD_RANGE_AT_FULL_FLEXION`, 1].
    """
    t = np.clip(np.asarray(mcp_flex, dtype=np.float64) / (np.pi / 2), 0.0, 1.0)
    return 1.0 - (1.0 - ABD_RANGE_AT_FULL_FLEXION) * t


def sample_uniform(rng: np.random.Generator, n: int, *, coupled: bool = True) -> HandPose:
    """Random hand postures, uniform within the joint limits.

    Args:
        rng: random generator; the same state gives identical poses.
        n: number of poses (>= 1).
        coupled: apply the anatomical couplings of the module docstring (DIP = 2/3 PIP with
            noise, MCP abduction range shrinking with MCP flexion, neighbouring-finger
            flexion bounds). With False every angle is independent.

    Returns:
        A batch of ``n`` poses: angles (n, 21) radians within limits, wrist at the origin.

    Raises:
        InvalidPose: if ``rng`` is not a Generator or ``n < 1``.
    """
    rng = _check_rng(rng)
    n = _check_count(n)
    if not isinstance(coupled, (bool, np.bool_)):
        raise InvalidPose(f"coupled must be True or False; received {show(coupled)}")
    if not coupled:
        return _batch_pose(rng.uniform(_LO, _HI, size=(n, NUM_ANGLES)))
    angles = np.empty((n, NUM_ANGLES))
    angles[:, _THUMB] = rng.uniform(_LO[_THUMB], _HI[_THUMB], size=(n, len(_THUMB)))
    angles[:, _MCP_FLEX] = _sample_flexions(rng, n, _MCP_FLEX)
    angles[:, _PIP] = _sample_flexions(rng, n, _PIP)
    noise = np.clip(
        rng.normal(0.0, DIP_NOISE_DEG, size=(n, 4)), -2 * DIP_NOISE_DEG, 2 * DIP_NOISE_DEG
    )
    dip = DIP_PIP_RATIO * angles[:, _PIP] + np.deg2rad(noise)
    angles[:, _DIP] = np.clip(dip, _LO[_DIP], _HI[_DIP])
    frac = abduction_range_fraction(angles[:, _MCP_FLEX])
    u = rng.uniform(0.0, 1.0, size=(n, 4))
    angles[:, _MCP_ABD] = frac * (_LO[_MCP_ABD] + u * (_HI[_MCP_ABD] - _LO[_MCP_ABD]))
    return _batch_pose(angles)


# 2. Postural synergies ---------------------------------------------------------------------

GRASPIT_EG1_FINGER_FLEXION: np.ndarray = np.array(
    [
        [-0.413, -0.042, -0.008],
        [-0.515, -0.025, -0.013],
        [-0.530, 0.016, -0.066],
        [-0.451, -0.170, -0.075],
    ]
)
"""(4, 3) GraspIt human-hand eigengrasp EG1 restricted to finger flexion: rows index, middle,
ring, little; columns MCP, PIP, DIP (GraspIt's ``human_eigen_cgdb_refined.xml``)."""
GRASPIT_EG1_FINGER_FLEXION.setflags(write=False)

_SYNERGY_CLOSURES = np.linspace(0.5, 1.0, 11)


@dataclasses.dataclass(frozen=True, eq=False)
class SynergyBasis:
    """A PCA basis of hand postures.

    Attributes:
        mean: (21,) mean posture, radians.
        components: (21, 21) unit principal directions as rows, by decreasing variance. The
            sign is chosen so that the summed finger flexion loading (MCP, PIP, DIP) is
            positive: a positive coefficient closes the fingers.
        std: (21,) standard deviation along each component, radians.
        explained_variance_ratio: (21,) fraction of the total variance per component.
        source: where the postures came from.
    """

    mean: np.ndarray
    components: np.ndarray
    std: np.ndarray
    explained_variance_ratio: np.ndarray
    source: str

    def project(self, pose: HandPose, num_synergies: int) -> np.ndarray:
        """Coefficients of poses on the first components, in units of ``std``.

        Args:
            pose: a pose or a batch.
            num_synergies: number of components, 1 to 21.

        Returns:
            (..., num_synergies) coefficients.
        """
        k = _check_num_synergies(num_synergies)
        return ((pose.angles - self.mean) @ self.components[:k].T) / self.std[:k]


def _check_num_synergies(k: object) -> int:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= NUM_ANGLES:
        raise InvalidPose(f"num_synergies must be an integer in [1, {NUM_ANGLES}]; received {k!r}")
    return int(k)


@functools.cache
def synergy_basis() -> SynergyBasis:
    """The postural-synergy basis (PCA of the grasp library; see the module docstring).

    Returns:
        The basis, computed once and cached; its arrays are read-only.
    """
    library = np.concatenate([g.angles(_SYNERGY_CLOSURES) for g in GRASP_TYPES.values()])
    mean = library.mean(axis=0)
    _, sing, vt = np.linalg.svd(library - mean, full_matrices=False)
    flexion = _MCP_FLEX + _PIP + _DIP
    vt = vt * np.where(vt[:, flexion].sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
    var = sing**2 / (len(library) - 1)
    arrays = (mean, vt, np.sqrt(var), var / var.sum())
    for a in arrays:
        a.setflags(write=False)
    return SynergyBasis(
        *arrays,
        source=(
            f"PCA of {len(library)} grasp postures: {len(GRASP_TYPES)} GRASP-taxonomy types x "
            f"{len(_SYNERGY_CLOSURES)} closures in [0.5, 1] (handsim.hand.pose_sources.GRASP_TYPES)"
        ),
    )


def synergy_pose(coefficients: Sequence[float] | np.ndarray) -> HandPose:
    """Posture from synergy coefficients.

    Args:
        coefficients: (..., k) coefficients of the first k components, in units of each
            component's standard deviation (1 <= k <= 21).

    Returns:
        Poses with angles ``mean + sum_i c_i std_i component_i``, clipped to the limits.

    Raises:
        InvalidPose: for a wrong shape or non-finite coefficients.
    """
    c = np.asarray(coefficients, dtype=np.float64)
    if c.ndim == 0 or not 1 <= c.shape[-1] <= NUM_ANGLES or not np.all(np.isfinite(c)):
        raise InvalidPose(
            f"coefficients must be finite with shape (..., k), 1 <= k <= {NUM_ANGLES}; "
            f"received shape {c.shape}"
        )
    basis = synergy_basis()
    k = c.shape[-1]
    angles = basis.mean + (c * basis.std[:k]) @ basis.components[:k]
    return _batch_pose(np.clip(angles, _LO, _HI))


def sample_synergy(
    rng: np.random.Generator, n: int, *, num_synergies: int = 2, scale: float = 1.0
) -> HandPose:
    """Random postures in the span of the first synergies.

    Coefficients are independent normal with standard deviation ``scale`` (in units of each
    component's own standard deviation), so ``scale = 1`` reproduces the library's spread
    along those components; the angles are clipped to the limits.

    Args:
        rng: random generator.
        n: number of poses (>= 1).
        num_synergies: number of leading components used, 1 to 21.
        scale: standard deviation of the coefficients (> 0).

    Returns:
        A batch of n poses, wrist at the origin.

    Raises:
        InvalidPose: for a bad ``rng``, ``n``, ``num_synergies`` or ``scale``.
    """
    rng = _check_rng(rng)
    n = _check_count(n)
    k = _check_num_synergies(num_synergies)
    scale = _check_positive(scale, "scale", "(coefficient standard deviation)")
    return synergy_pose(rng.normal(0.0, scale, size=(n, k)))
