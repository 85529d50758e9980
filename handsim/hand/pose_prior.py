"""A Gaussian prior over natural hand postures, for maximum a posteriori retargeting.

:class:`PosePrior` holds the mean ``mu`` (21,) and covariance ``Sigma`` (21, 21) of the 21
joint angles and their whitening matrix ``W`` (``W^T W = Sigma^-1``), so that
``|W (angles - mu)|^2`` is the prior's negative log-density up to a constant. With it,
:class:`~handsim.hand.retarget.Retargeter` minimises

    ``sum_i |FK_i(angles) - kp_i|^2 / sigma^2 + |W (angles - mu)|^2``

(``sigma``: the tracker's per-axis keypoint noise) instead of the keypoint error alone: the
noise of 21 keypoints is weighed against how natural the posture is, in every frame, with no
lag (the DeepPrior idea of a low-dimensional pose prior, in the fit instead of the network).

:func:`default_pose_prior` is fitted to handsim's own posture corpus, the one its data
generation samples from: the 13 GRASP-taxonomy types of
:data:`~handsim.hand.pose_sources.GRASP_TYPES` at closures 0 (the open preshape) to 1 in
steps of 0.1, and the 14 :data:`~handsim.hand.pose_sources.GESTURES`; a floor of
``floor_rad`` (default 0.1 rad) is added to every angle's standard deviation, since the corpus
is a set of curves and a real hand moves off them.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from handsim.errors import InvalidPose
from handsim.hand.pose import NUM_ANGLES

__all__ = [
    "PosePrior",
    "default_pose_prior",
    "corpus_angles",
    "DEFAULT_FLOOR_RAD",
    "KeypointNoiseEstimator",
]

DEFAULT_FLOOR_RAD = 0.1
"""Standard deviation added to every angle of the corpus's covariance, radians."""
_CORPUS_CLOSURES = np.linspace(0.0, 1.0, 11)


@dataclasses.dataclass(frozen=True, eq=False)
class PosePrior:
    """A Gaussian over the 21 joint angles.

    Attributes:
        mean_rad: (21,) mean posture, radians, :data:`~handsim.hand.pose.JOINT_NAMES` order.
        covariance_rad2: (21, 21) symmetric positive definite covariance, rad^2.
        source: where the postures came from.
    """

    mean_rad: np.ndarray
    covariance_rad2: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        """Validate and derive the whitening and the precision (read-only arrays)."""
        mean = np.asarray(self.mean_rad, dtype=np.float64)
        cov = np.asarray(self.covariance_rad2, dtype=np.float64)
        if mean.shape != (NUM_ANGLES,) or cov.shape != (NUM_ANGLES, NUM_ANGLES):
            raise InvalidPose(
                f"a pose prior needs a ({NUM_ANGLES},) mean and a ({NUM_ANGLES}, {NUM_ANGLES}) "
                f"covariance in radians; received shapes {mean.shape} and {cov.shape}"
            )
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise InvalidPose("a pose prior's mean and covariance must be finite")
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-12):
            raise InvalidPose("a pose prior's covariance must be symmetric")
        values, vectors = np.linalg.eigh(cov)
        if values[0] <= 0.0:
            raise InvalidPose(
                "a pose prior's covariance must be positive definite; its smallest eigenvalue "
                f"is {values[0]:.3g} rad^2 (add a floor: PosePrior.from_angles(..., floor_rad=0.1))"
            )
        # W = diag(1/sqrt(lambda)) V^T: W^T W = Sigma^-1, rows along the principal directions.
        whitening = vectors.T / np.sqrt(values)[:, None]
        precision = whitening.T @ whitening
        for name, value in (
            ("mean_rad", mean),
            ("covariance_rad2", cov),
            ("whitening", whitening),
            ("precision", precision),
        ):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    whitening: np.ndarray = dataclasses.field(init=False, repr=False)
    """(21, 21) ``W`` with ``W^T W = Sigma^-1``, 1/rad."""
    precision: np.ndarray = dataclasses.field(init=False, repr=False)
    """(21, 21) ``Sigma^-1``, 1/rad^2."""

    @classmethod
    def from_angles(
        cls, angles: np.ndarray, *, floor_rad: float = DEFAULT_FLOOR_RAD, source: str = ""
    ) -> PosePrior:
        """The mean and covariance of postures, each angle's variance raised by ``floor_rad^2``.

        Args:
            angles: (n, 21) postures, radians (n >= 2).
            floor_rad: standard deviation added to every angle, radians (> 0 keeps the
                covariance invertible where the postures do not vary).
            source: where the postures came from.

        Raises:
            InvalidPose: for a wrong shape, non-finite angles or a negative floor.
        """
        a = np.asarray(angles, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != NUM_ANGLES or len(a) < 2 or not np.all(np.isfinite(a)):
            raise InvalidPose(
                f"a pose prior is fitted to (n, {NUM_ANGLES}) finite angles in radians, n >= 2; "
                f"received shape {a.shape}"
            )
        if not (isinstance(floor_rad, (int, float)) and np.isfinite(floor_rad) and floor_rad >= 0):
            raise InvalidPose(f"floor_rad must be a number >= 0 (radians); received {floor_rad!r}")
        cov = np.cov(a, rowvar=False) + float(floor_rad) ** 2 * np.eye(NUM_ANGLES)
        return cls(a.mean(axis=0), cov, source)

    def mahalanobis(self, angles: np.ndarray) -> np.ndarray:
        """``|W (angles - mu)|``: distance of postures from the mean in standard deviations.

        Args:
            angles: (..., 21) radians.

        Returns:
            (...,) distances (dimensionless).
        """
        d = (np.asarray(angles, dtype=np.float64) - self.mean_rad) @ self.whitening.T
        return np.sqrt(np.sum(d * d, axis=-1))


def corpus_angles() -> np.ndarray:
    """(n, 21) the postures :func:`default_pose_prior` is fitted to, radians.

    The 13 grasp types at closures 0, 0.1, ..., 1 and the 14 gestures (see the module
    docstring); deterministic.
    """
    from handsim.hand.pose_library import GESTURES, GRASP_TYPES

    grasps = [g.angles(_CORPUS_CLOSURES) for g in GRASP_TYPES.values()]
    gestures = [g.angles[None] for g in GESTURES.values()]
    return np.concatenate(grasps + gestures)


@functools.cache
def default_pose_prior(floor_rad: float = DEFAULT_FLOOR_RAD) -> PosePrior:
    """The prior fitted to :func:`corpus_angles`, computed once per floor and cached.

    Args:
        floor_rad: standard deviation added to every angle, radians.
    """
    corpus = corpus_angles()
    return PosePrior.from_angles(
        corpus,
        floor_rad=floor_rad,
        source=(
            f"{len(corpus)} postures: 13 GRASP-taxonomy types x {len(_CORPUS_CLOSURES)} "
            "closures in [0, 1] and the 14 gestures (handsim.hand.pose_sources), "
            f"+ {floor_rad:g} rad per angle"
        ),
    )


class KeypointNoiseEstimator:
    """The tracked keypoints' noise, metres per axis, estimated from the stream's own jitter.

    A live stream does not say how noisy it is, and a prior weighed for the wrong noise costs
    the fit (weighed for 10 mm on exact keypoints it bends grasps toward the corpus). For
    white noise of std ``sigma`` per axis the second difference ``x[t] - 2 x[t-1] + x[t-2]``
    has std ``sqrt(6) sigma``, while a hand's own motion adds only its acceleration times the
    frame period squared (5 m/s^2 at 50 Hz: 2 mm, an estimate of 1.2 mm on exact keypoints,
    for which the prior weighs 70 times less than for 10 mm). The estimate is the median
    absolute second difference of every tracked coordinate over the last ``window`` frames
    (the median: a fast motion's peaks do not count) over that of a Gaussian,
    ``0.6745 sqrt(6)``. A lost (held) frame restarts the differences. Noise that changes
    slowly (correlated from frame to frame) hardly shows in a second difference and is
    underestimated.

    Args:
        window: frames kept, >= 3.
        min_frames: frames of second differences needed before :attr:`sigma_m` is known.
    """

    _GAUSS = 0.6744897501960817 * np.sqrt(6.0)

    def __init__(self, window: int = 50, min_frames: int = 10) -> None:
        if isinstance(window, bool) or not isinstance(window, int) or window < 3:
            raise InvalidPose(f"window must be an int >= 3 frames; received {window!r}")
        self.window = window
        self.min_frames = max(1, min(int(min_frames), window))
        self._history: list[np.ndarray] = []
        self._d2: list[np.ndarray] = []

    def update(self, keypoints: np.ndarray | None, dropped: bool = False) -> None:
        """Add one tracked frame: (N, 3) metres, NaN rows untracked (``None``: lost)."""
        if keypoints is None or dropped:
            self._history.clear()
            return
        self._history = [*self._history[-2:], np.asarray(keypoints, dtype=np.float64)]
        if len(self._history) == 3:
            a, b, c = self._history
            d2 = np.abs(c - 2.0 * b + a).ravel()
            self._d2 = [*self._d2[-(self.window - 1) :], d2[np.isfinite(d2)]]

    @property
    def sigma_m(self) -> float | None:
        """The noise estimate, metres per axis (``None`` before ``min_frames``)."""
        if len(self._d2) < self.min_frames:
            return None
        values = np.concatenate(self._d2)
        return float(np.median(values) / self._GAUSS) if values.size else None
