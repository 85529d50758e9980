"""The learned estimators behind the :class:`~handsim.estimator.Estimator` protocol.

:class:`DeepPriorEstimator` runs the whole pipeline on one depth image: RANSAC plane removal and
the nearest blob's centre of mass (:class:`~.preprocess.PlaneRemovedLocalizer`), the refinement
CNN applied ``refine_iterations`` times (it moves the centre to the predicted middle-finger
MCP), the 3D cube crop, the pose network and the exact inverse of the label normalization.

Side: a pose checkpoint trained in the canonical right-hand frame (its config's
``canonical_side``, written by ``handsim train``) gets a left hand's frame mirrored
(:func:`~.preprocess.mirror_depth`, :func:`~.preprocess.mirror_intrinsics`) before the whole
pipeline and its keypoints mirrored back. The side is the estimator's state: ``is_left`` at
construction or :meth:`DeepPriorEstimator.set_side` (which
:class:`~handsim.envs.wrappers.EstimatorLoop` calls at every reset with the env's hand).
Checkpoints without the flag (trained on both sides as they come) are run unmirrored.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from handsim.errors import InvalidEstimatorParams
from handsim.estimator import Estimate, EstimatorBase, validate_depth_input

from .preprocess import (
    CUBE_M,
    PlaneRemovedLocalizer,
    crop_depth,
    crop_matrix,
    denormalize_keypoints,
    mirror_depth,
    mirror_intrinsics,
    mirror_points,
)

__all__ = ["DETECTORS", "TRACK_MIN_FILL", "DeepPriorEstimator", "RefinedLocalizer"]


def _as_input(x: np.ndarray, device: str) -> Any:
    """(B, 1, S, S) crops as a channels-last tensor on ``device`` (the networks' layout)."""
    import torch

    return torch.from_numpy(x).to(device=device, memory_format=torch.channels_last)


TRACK_MIN_FILL = 0.05
"""Tracking keeps a centre while at least this fraction of a 32 x 32 crop of its cube holds
depth inside the cube (a hand fills ~30 % of it; the cube on empty space or far behind, 0)."""


def _fill(depth_m: np.ndarray, K: np.ndarray, center: np.ndarray, cube_m: float) -> float:  # noqa: N803
    """Fraction of a 32 x 32 crop of the cube at ``center`` with depth inside the cube."""
    if not (np.all(np.isfinite(center)) and center[2] > cube_m / 2):
        return 0.0  # a centre behind or at the camera holds nothing
    crop = crop_depth(depth_m, crop_matrix(center, K, cube_m, 32), center[2], cube_m, 32)
    return float(np.count_nonzero(crop < 1.0)) / crop.size


DETECTORS = ("plane", "com", "learned")
"""First hand centres: ``"plane"`` (RANSAC plane removal, then the nearest blob's centre of
mass; works on a table), ``"com"`` (DeepPrior's centre of mass of the nearest depth slab,
cheaper, for a hand nearest to the camera) or ``"learned"`` (the shipped whole-image hand
detector, :class:`~.detector.LearnedDetector`: finds the hand behind an object or at the end of
a forearm). A detector checkpoint's path is also accepted."""


def _first_centre(detector: str | os.PathLike[str], device: str) -> Any:
    """The detector object of a :data:`DETECTORS` name or a detector checkpoint path."""
    from handsim.estimators.com import CenterOfMassLocalizer

    from .checkpoint import InvalidCheckpoint
    from .detector import LearnedDetector

    if detector == "plane":
        return PlaneRemovedLocalizer()
    if detector == "com":
        return CenterOfMassLocalizer()
    if detector == "learned":
        return LearnedDetector("detector", device)
    if isinstance(detector, str | os.PathLike) and (
        os.path.isdir(detector) or str(detector).endswith(".pt")
    ):
        return LearnedDetector(detector, device)
    raise InvalidCheckpoint(
        f"detector must be one of {', '.join(DETECTORS)} or a detector checkpoint (a .pt or a "
        f"`handsim train detector` run folder); received {detector!r}"
    )


class RefinedLocalizer(EstimatorBase):
    """Hand centre: a first centre (:data:`DETECTORS`), then the refinement CNN, iterated.

    **Guard.** On a hand the iteration converges: after its steps the network asks for a
    last move of a few millimetres (median 4.5 to 15.8 mm on the sets of handsim-bench-v1). Where
    an arm is in view with nothing behind it, the network can instead walk the centre up the
    arm, about 10 cm a step, and still ask for more than 14 cm at the end. With ``guard`` on
    (the default), the network is run once more at the refined centre; if it would move the
    centre by more than half the cube edge (the hand it sees is not in the middle of its
    crop), the refinement has not converged and the first centre is kept.

    Args:
        checkpoint: a localizer checkpoint (shipped name ``"localizer"`` or a path), or
            ``None`` for the first centre alone.
        iterations: refinement steps.
        device: torch device.
        detector: the first centre (:data:`DETECTORS`, or a detector checkpoint path;
            default ``"learned"``).
        guard: keep the first centre when the refinement has not converged (one more network
            call per frame); ``False``: the refined centre as it is.

    Raises:
        InvalidCheckpoint: for an unknown detector or a checkpoint that cannot be loaded.
        InvalidEstimatorParams: for a ``guard`` that is not a bool.
    """

    def __init__(
        self,
        checkpoint: str | os.PathLike[str] | None = "localizer",
        *,
        iterations: int = 3,
        device: str = "cpu",
        detector: str | os.PathLike[str] = "learned",
        guard: bool = True,
    ) -> None:
        from .checkpoint import load_model
        from .models import inference_forward

        if not isinstance(guard, bool):
            raise InvalidEstimatorParams(
                f"guard must be True (keep the first centre when the refinement does not "
                f"converge) or False; received {guard!r}"
            )
        self.guard = guard
        self.base = _first_centre(detector, device)
        self.detector = str(detector)
        self.iterations = int(iterations)
        self.device = device
        self.model = None
        self.cube_m, self.size = CUBE_M, 64
        if checkpoint is not None:
            self.model, config = load_model(checkpoint, device)
            self._forward = inference_forward(self.model)
            self.cube_m = float(config["cube_m"])
            self.size = int(config["model"]["size"])
        self.checkpoint = None if checkpoint is None else str(checkpoint)

    def __repr__(self) -> str:
        return (
            f"RefinedLocalizer(checkpoint={self.checkpoint!r}, iterations={self.iterations}, "
            f"detector={self.detector!r}, guard={self.guard})"
        )

    def _offsets_m(self, depths: list[np.ndarray], Ks: Any, centers: np.ndarray) -> np.ndarray:  # noqa: N803
        """(B, 3) the network's moves of ``centers`` (B, 3), metres, one call."""
        import torch

        x = np.stack(
            [
                crop_depth(
                    d, crop_matrix(c, k, self.cube_m, self.size), c[2], self.cube_m, self.size
                )
                for d, k, c in zip(depths, Ks, centers, strict=True)
            ]
        )
        with torch.inference_mode():
            off = self._forward(_as_input(x[:, None], self.device))
        return off.double().cpu().numpy() * (self.cube_m / 2.0)

    def _unconverged(self, residual_m: np.ndarray) -> np.ndarray:
        """(B,) bool: the move still asked for at the refined centre exceeds half the cube."""
        return np.linalg.norm(residual_m, axis=-1) > self.cube_m / 2.0

    def path(
        self,
        depth_m: np.ndarray,
        K: np.ndarray,  # noqa: N803
        center: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """Where the refinement goes from ``center``: for measuring it and its guard.

        Returns:
            ``(centres, residual_m, lost)``: (iterations + 1, 3) ``center`` and each step's
            centre, metres; (3,) the move the network still asks for at the last; whether
            the guard keeps ``center`` (the move exceeds half the cube).
        """
        centres = [np.array(center, dtype=np.float64)]
        if self.model is None:
            return np.stack(centres), np.zeros(3), False
        for _ in range(self.iterations):
            centres.append(centres[-1] + self._offsets_m([depth_m], [K], centres[-1][None])[0])
        residual_m = self._offsets_m([depth_m], [K], centres[-1][None])[0]
        return np.stack(centres), residual_m, bool(self._unconverged(residual_m[None])[0])

    def refine(self, depth_m: np.ndarray, K: np.ndarray, center: np.ndarray) -> np.ndarray:  # noqa: N803
        """Apply the refinement CNN ``iterations`` times from ``center`` (metres).

        The same arithmetic as :meth:`refine_batch` for one frame, without its batching.
        With :attr:`guard`, ``center`` itself when the refinement has not converged.
        """
        start = np.array(center, dtype=np.float64)
        c = start.copy()
        if self.model is None or self.iterations == 0:
            return c
        for _ in range(self.iterations):
            c += self._offsets_m([depth_m], [K], c[None])[0]
        if self.guard and self._unconverged(self._offsets_m([depth_m], [K], c[None]))[0]:
            return start
        return c

    def refine_batch(
        self,
        depths_m: Any,
        K: np.ndarray,  # noqa: N803
        centers: np.ndarray,
        batch_size: int = 256,
    ) -> np.ndarray:
        """:meth:`refine` for many frames at once, one network call per batch and iteration.

        Args:
            depths_m: N (H, W) depth images, metres (a sequence, or a callable ``i -> depth``).
            K: (N, 3, 3) intrinsics.
            centers: (N, 3) starting centres, metres.
            batch_size: frames per network call.

        Returns:
            (N, 3) refined centres, metres (with :attr:`guard`, the starting centre of a frame
            whose refinement has not converged).
        """
        start = np.array(centers, dtype=np.float64)
        c = start.copy()
        if self.model is None or len(c) == 0 or self.iterations == 0:
            return c
        depth = depths_m if callable(depths_m) else depths_m.__getitem__
        steps = self.iterations + (1 if self.guard else 0)
        for step in range(steps):
            for lo in range(0, len(c), batch_size):
                idx = range(lo, min(lo + batch_size, len(c)))
                off = self._offsets_m([depth(i) for i in idx], K[lo : idx.stop], c[idx])
                if step < self.iterations:
                    c[lo : idx.stop] += off
                else:  # the guard's look at the refined centres
                    lost = self._unconverged(off)
                    c[lo : idx.stop][lost] = start[lo : idx.stop][lost]
        return c

    def localize(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray | None:  # noqa: N803
        """(3,) refined centre, metres, or ``None`` (unchecked input)."""
        c = self.base.localize(depth_m, K)
        return None if c is None else self.refine(depth_m, K, c)

    def predict(self, depth: np.ndarray, K: np.ndarray) -> Estimate:  # noqa: N803
        """``Estimate(center_cam=...)`` or ``Estimate(valid=False)``."""
        depth_m, K_cv = validate_depth_input(depth, K)  # noqa: N806
        c = self.localize(depth_m, K_cv)
        return Estimate(valid=False) if c is None else Estimate(center_cam=c)


class DeepPriorEstimator(EstimatorBase):
    """DeepPrior / DeepPrior++ on depth images: 21 keypoints in the camera frame.

    Args:
        checkpoint: the pose network: ``"deepprior++"``, ``"deepprior"`` (shipped weights) or
            a checkpoint path (``NAME.pt`` with ``NAME.json``, or a training folder).
        localizer: the refinement CNN's checkpoint (default: the shipped one), or ``None`` to
            crop at the plane-removed centre of mass.
        refine_iterations: refinement steps of the localizer; ``None`` (default): as the
            network's training crops were centred (its checkpoint's ``crop``; 3 for a
            checkpoint without one). 0: the detector's centre as it is.
        refine_guard: keep the detector's centre when the refinement has not converged
            (:class:`RefinedLocalizer`'s ``guard``: it walked off the hand, e.g. up an arm).
        device: torch device (``"cpu"`` or ``"cuda"``).
        detector: the localizer's first centre (:data:`DETECTORS`): ``"learned"`` (default,
            the whole-image hand detector: finds the hand behind an object or past a
            forearm), ``"plane"`` (plane removal and the nearest blob; cheaper, for a hand
            nearest to the camera on a table), ``"com"`` (DeepPrior's original detector; with
            ``localizer=None`` the pipeline of the DeepPrior paper) or a detector checkpoint.
        threads: CPU threads of torch and of OpenCV (process-wide settings; ``None``: leave
            theirs). On a CPU shared with other jobs, 1 is fastest: threads that wait for
            each other cost more than they gain on one frame's small arrays.
        canonical_side: mirror left hands into the right-hand frame the network works in;
            ``None`` (default): the checkpoint's ``canonical_side`` flag (``False`` when it has
            none: checkpoints trained before the flag saw both sides as they came).
        is_left: the side of the hands this estimator is given (:meth:`set_side` changes it).
        track: start each frame's refinement from the previous frame's refined centre instead
            of the detector, as a tracker does (needs ``refine_iterations`` >= 1). The
            detector runs again after :meth:`reset`, after a frame without an estimate,
            when the side changes, and when the tracked centre has lost the hand (under
            :data:`TRACK_MIN_FILL` of its cube's crop holds depth inside the cube).

    Raises:
        InvalidCheckpoint: for a checkpoint that cannot be loaded, or a ``canonical_side`` or
            ``is_left`` that is not a bool.
        InvalidEstimatorParams: for a ``refine_guard`` that is not a bool, or ``track``
            without refinement.
    """

    def __init__(
        self,
        checkpoint: str | os.PathLike[str] = "deepprior++",
        *,
        localizer: str | os.PathLike[str] | None = "localizer",
        refine_iterations: int | None = None,
        refine_guard: bool = True,
        device: str = "cpu",
        threads: int | None = None,
        detector: str | os.PathLike[str] = "learned",
        canonical_side: bool | None = None,
        is_left: bool = False,
        track: bool = False,
    ) -> None:
        import torch

        from .checkpoint import InvalidCheckpoint, load_model
        from .models import inference_forward

        if canonical_side is not None and not isinstance(canonical_side, bool):
            raise InvalidCheckpoint(
                f"canonical_side must be True, False or None (the checkpoint's flag); received "
                f"{canonical_side!r}"
            )

        if not isinstance(refine_guard, bool):
            raise InvalidEstimatorParams(
                f"refine_guard must be True (keep the detector's centre when the refinement "
                f"does not converge) or False; received {refine_guard!r}"
            )
        if threads is not None:
            import cv2

            torch.set_num_threads(int(threads))
            cv2.setNumThreads(int(threads))
        self.checkpoint = str(checkpoint)
        self.device = device
        self.model, config = load_model(checkpoint, device)
        self._forward = inference_forward(self.model)
        self.cube_m = float(config["cube_m"])
        self.size = int(config["model"]["size"])
        stored = config.get("canonical_side", False)
        self.canonical_side = bool(stored) if canonical_side is None else canonical_side
        if refine_iterations is None:
            refine_iterations = int((config.get("crop") or {}).get("refine_iterations", 3))
        self.localizer = RefinedLocalizer(
            localizer,
            iterations=refine_iterations,
            device=device,
            detector=detector,
            guard=refine_guard,
        )
        self.track = bool(track)
        if self.track and self.localizer.iterations == 0:
            raise InvalidEstimatorParams(
                "track=True refines the previous frame's centre, and refine_iterations=0 (the "
                "default for a network trained at the detector's centres) has no refinement: "
                "the centre would not follow the hand. Give refine_iterations >= 1, or "
                "track=False (the detector in every frame)"
            )
        self._tracked: np.ndarray | None = None
        self.is_left = False
        self.set_side(is_left)

    def reset(self) -> None:
        """Forget the tracked centre (a new episode starts with the detector)."""
        self._tracked = None

    def set_side(self, is_left: bool) -> None:
        """The side of the next frames: ``True`` for a left hand.

        Raises:
            InvalidEstimatorParams: if ``is_left`` is not a bool.
        """
        if not isinstance(is_left, bool | np.bool_):
            raise InvalidEstimatorParams(
                f"is_left must be a bool (True for a left hand); received {is_left!r}"
            )
        if bool(is_left) != self.is_left:
            self._tracked = None  # a centre of the other frame
        self.is_left = bool(is_left)

    def __repr__(self) -> str:
        return (
            f"DeepPriorEstimator(checkpoint={self.checkpoint!r}, "
            f"localizer={self.localizer.checkpoint!r}, "
            f"refine_iterations={self.localizer.iterations}, "
            f"refine_guard={self.localizer.guard}, detector={self.localizer.detector!r}, "
            f"canonical_side={self.canonical_side}, "
            f"track={self.track})"
        )

    def _center(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray | None:  # noqa: N803
        """The crop centre: refined from the tracked centre while it holds the hand, else found."""
        if self.track and self._tracked is not None:
            center = self.localizer.refine(depth_m, K, self._tracked)
            if _fill(depth_m, K, center, self.cube_m) >= TRACK_MIN_FILL:
                return center
        return self.localizer.localize(depth_m, K)

    def predict_at(self, depth_m: np.ndarray, K: np.ndarray, center: np.ndarray) -> np.ndarray:  # noqa: N803
        """(21, 3) keypoints, metres, from a crop at ``center`` (unchecked input)."""
        import torch

        M = crop_matrix(center, K, self.cube_m, self.size)  # noqa: N806
        x = crop_depth(depth_m, M, center[2], self.cube_m, self.size)
        with torch.inference_mode():
            y = self._forward(_as_input(x[None, None], self.device))
        return denormalize_keypoints(
            y[0].double().cpu().numpy().reshape(21, 3), center, self.cube_m
        )

    def predict(self, depth: np.ndarray, K: np.ndarray) -> Estimate:  # noqa: N803
        """Estimate one frame (``Estimate(valid=False)`` when no hand blob is found).

        Args:
            depth: (H, W) float32 depth, metres, 0 = no measurement.
            K: (3, 3) intrinsics.

        Returns:
            ``Estimate(keypoints_cam=(21, 3) metres)``.
        """
        depth_m, K_cv = validate_depth_input(depth, K)  # noqa: N806
        mirror = self.canonical_side and self.is_left
        if mirror:  # the left hand as the right hand it mirrors
            depth_m, K_cv = mirror_depth(depth_m), mirror_intrinsics(K_cv, depth_m.shape[1])  # noqa: N806
        center = self._center(depth_m, K_cv)
        self._tracked = center
        if center is None:
            return Estimate(valid=False)
        keypoints = self.predict_at(depth_m, K_cv, center)
        return Estimate(keypoints_cam=mirror_points(keypoints) if mirror else keypoints)

    def info(self) -> dict[str, Any]:
        """What the estimator runs (for reports)."""
        return {
            "checkpoint": self.checkpoint,
            "localizer": self.localizer.checkpoint,
            "detector": self.localizer.detector,
            "refine_iterations": self.localizer.iterations,
            "refine_guard": self.localizer.guard,
            "cube_m": self.cube_m,
            "size": self.size,
            "canonical_side": self.canonical_side,
            "track": self.track,
        }
