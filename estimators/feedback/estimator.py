"""The feedback estimator: localizer -> DeepPrior++ -> k updates ``P <- P + updater(D, synth(P))``.

:class:`FeedbackEstimator` runs the pipeline of
:class:`~handsim.estimators.deepprior.estimator.DeepPriorEstimator` (plane removal, refined
localizer, crop, pose network) for the first pose, then applies the trained updater
``iterations`` times, each time comparing the input crop with the synthesizer's crop of the
current pose: handsim's renderer (``renderer``, the exact hand model; the retargeting is
warm-started from the previous iteration) or the learned synthesizer (``learned``). The hand's
length (unknown: fitted to each pose) and side (:meth:`FeedbackEstimator.set_side`) tell the
renderer which hand to draw.

Side: an updater trained side-canonical (its config's ``canonical_side``, as DeepPrior++'s)
gets a left hand's frame mirrored into the right-hand frame before the whole pipeline; the
renderer then draws the right hand that mirrors it, and the keypoints are mirrored back.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from handsim.estimator import (
    Estimate,
    EstimatorBase,
    validate_batch_input,
    validate_depth_input,
)

from ..deepprior.preprocess import (
    crop_depth,
    crop_matrix,
    denormalize_keypoints,
    mirror_depth,
    mirror_intrinsics,
    mirror_points,
)

__all__ = ["FeedbackEstimator"]


class FeedbackEstimator(EstimatorBase):
    """DeepPrior++ refined by the feedback loop (Oberweger et al., ICCV 2015).

    Args:
        updater: the updater's checkpoint: ``"feedback"`` (the shipped weights), a ``handsim
            train updater`` run folder or a ``.pt``.
        predictor: the first pose's network (``"deepprior++"``: shipped weights, or a path).
        localizer: the refinement CNN's checkpoint, or ``None``.
        synthesizer: ``"renderer"`` or ``"learned"``.
        synthesizer_checkpoint: the learned synthesizer's checkpoint (with ``"learned"``).
        iterations: updates; default: the updater's (chosen on validation when training).
        hand_length_m: the hand's length, metres; default: fitted to each pose.
        is_left: the hand's side (see :meth:`set_side`).
        device: torch device.
        detector: the localizer's first centre (``DeepPriorEstimator``'s ``detector``:
            ``"learned"``, ``"plane"``, ``"com"`` or a detector checkpoint).

    Raises:
        InvalidCheckpoint: for a checkpoint that cannot be loaded or does not fit the others.
        InvalidSynthesizerInput: for an unknown synthesizer.
    """

    def __init__(
        self,
        updater: str | os.PathLike[str] = "feedback",
        *,
        predictor: str | os.PathLike[str] = "deepprior++",
        localizer: str | os.PathLike[str] | None = "localizer",
        synthesizer: str = "renderer",
        synthesizer_checkpoint: str | None = None,
        iterations: int | None = None,
        hand_length_m: float | None = None,
        is_left: bool = False,
        device: str = "cpu",
        detector: str | os.PathLike[str] = "learned",
    ) -> None:
        from ..deepprior.checkpoint import InvalidCheckpoint
        from ..deepprior.estimator import DeepPriorEstimator
        from .checkpoint import load_feedback_model
        from .synth import make_synthesizer

        self.first = DeepPriorEstimator(
            predictor, localizer=localizer, device=device, detector=detector
        )
        self.updater, config = load_feedback_model(updater, "updater", device)
        size = int(config["model"]["size"])
        if size != self.first.size or abs(float(config["cube_m"]) - self.first.cube_m) > 1e-9:
            raise InvalidCheckpoint(
                f"updater {updater} works on {size} px crops of a {config['cube_m']} m cube, the "
                f"predictor on {self.first.size} px of {self.first.cube_m} m; train them alike"
            )
        self.canonical_side = bool(config.get("canonical_side", False))
        if self.canonical_side != self.first.canonical_side:
            raise InvalidCheckpoint(
                f"updater {updater} has canonical_side={self.canonical_side}, the predictor "
                f"{predictor} {self.first.canonical_side}: the updater must work in the "
                "predictor's frame (train it with that predictor)"
            )
        if iterations is not None and (not isinstance(iterations, int) or iterations < 0):
            raise InvalidCheckpoint(f"iterations must be an int >= 0; received {iterations!r}")
        self.iterations = int(config.get("iterations", 2)) if iterations is None else iterations
        self.synthesizer_kind = synthesizer
        self.synth = make_synthesizer(
            synthesizer, synthesizer_checkpoint, cube_m=self.first.cube_m, size=size, device=device
        )
        self.hand_length_m = math.nan if hand_length_m is None else float(hand_length_m)
        self.is_left = bool(is_left)
        self.device = device
        self.updater_checkpoint = str(updater)

    def __repr__(self) -> str:
        return (
            f"FeedbackEstimator(updater={self.updater_checkpoint!r}, "
            f"predictor={self.first.checkpoint!r}, synthesizer={self.synthesizer_kind!r}, "
            f"iterations={self.iterations})"
        )

    def set_side(self, is_left: bool) -> None:
        """The side of the hand in the next frames (the renderer draws that hand)."""
        self.is_left = bool(is_left)

    def predict_iterations(
        self,
        depth_m: np.ndarray,
        K: np.ndarray,  # noqa: N803
        center: np.ndarray | None = None,
        iterations: int | None = None,
    ) -> list[np.ndarray] | None:
        """(21, 3) keypoints, metres, after 0 (the predictor), 1, ..., k updates.

        Args:
            depth_m: (H, W) float32 depth, metres (unchecked), as the camera saw it.
            K: (3, 3) intrinsics.
            center: (3,) crop centre, metres, in the frame as seen (default: the localizer's).
            iterations: updates (default: :attr:`iterations`).

        Returns:
            k + 1 keypoint arrays in the frame as seen, or ``None`` when the localizer finds
            no hand blob.
        """
        mirror = self.canonical_side and self.is_left
        if mirror:  # the left hand as the right hand it mirrors
            K = mirror_intrinsics(K, depth_m.shape[1])  # noqa: N806
            depth_m = mirror_depth(depth_m)
            center = None if center is None else mirror_points(center)
        if center is None:
            center = self.first.localizer.localize(depth_m, K)
            if center is None:
                return None
        poses = self._iterate(
            depth_m[None], K[None], np.asarray(center, np.float64)[None], iterations
        )
        return [mirror_points(p[0]) for p in poses] if mirror else [p[0] for p in poses]

    def predict_iterations_batch(
        self,
        depths_m: np.ndarray,
        Ks: np.ndarray,  # noqa: N803
        centers: np.ndarray | None = None,
        iterations: int | None = None,
    ) -> list[list[np.ndarray] | None]:
        """:meth:`predict_iterations` for a batch of frames of the current side.

        Each network (the localizer's refinement, the pose network, the updater, and the
        learned synthesizer) runs once per batch and step; the renderer synthesizer draws the
        crops one after the other (one OpenGL context, no batched rendering).

        Args:
            depths_m: (B, H, W) float32 depths, metres (unchecked), as the camera saw them.
            Ks: (B, 3, 3) intrinsics.
            centers: (B, 3) crop centres, metres (default: the localizer's).
            iterations: updates (default: :attr:`iterations`).

        Returns:
            B entries: ``predict_iterations``' k + 1 keypoint arrays, or ``None`` for a frame
            where the localizer finds no hand blob.
        """
        depths_m = np.asarray(depths_m)
        Ks = np.asarray(Ks, np.float64)  # noqa: N806
        mirror = self.canonical_side and self.is_left
        if mirror:
            Ks = mirror_intrinsics(Ks, depths_m.shape[2])  # noqa: N806
            depths_m = mirror_depth(depths_m)
            centers = None if centers is None else mirror_points(np.asarray(centers))
        if centers is None:
            loc = self.first.localizer
            found = [loc.base.localize(d, k) for d, k in zip(depths_m, Ks, strict=True)]
            keep = np.array([c is not None for c in found], bool)
            centers = np.zeros((len(depths_m), 3))
            if keep.any():
                centers[keep] = loc.refine_batch(
                    depths_m[keep], Ks[keep], np.stack([c for c in found if c is not None])
                )
        else:
            centers = np.asarray(centers, np.float64).reshape(len(depths_m), 3)
            keep = np.ones(len(depths_m), bool)
        out: list[list[np.ndarray] | None] = [None] * len(depths_m)
        if keep.any():
            poses = self._iterate(depths_m[keep], Ks[keep], centers[keep], iterations)
            for j, i in enumerate(np.flatnonzero(keep)):
                frame = [p[j] for p in poses]
                out[i] = [mirror_points(p) for p in frame] if mirror else frame
        return out

    def _iterate(
        self,
        depths_m: np.ndarray,
        Ks: np.ndarray,  # noqa: N803
        centers: np.ndarray,
        iterations: int | None,
    ) -> list[np.ndarray]:
        """The loop on a batch, in the network's frame: k + 1 (B, 21, 3) keypoint arrays."""
        import torch

        k = self.iterations if iterations is None else int(iterations)
        b = len(centers)
        draw_left = np.full(b, self.is_left and not self.canonical_side)
        cube, size = self.first.cube_m, self.first.size
        x = np.stack(
            [
                crop_depth(d, crop_matrix(c, K, cube, size), c[2], cube, size)
                for d, K, c in zip(depths_m, Ks, centers, strict=True)  # noqa: N806
            ]
        )
        d = torch.from_numpy(x[:, None]).to(self.device)
        with torch.inference_mode():
            pose = self.first.model(d.contiguous(memory_format=torch.channels_last))
        pose = pose.float().cpu().numpy()
        out = [pose]
        warm = None
        for _ in range(k):
            crops, warm = self.synth(pose, centers, Ks, self.hand_length_m, draw_left, warm)
            with torch.inference_mode():
                y = torch.from_numpy(crops[:, None]).to(self.device)
                pose = pose + self.updater(d, y).float().cpu().numpy()
            out.append(pose)
        return [denormalize_keypoints(p.reshape(b, 21, 3), centers, cube) for p in out]

    def predict(self, depth: np.ndarray, K: np.ndarray) -> Estimate:  # noqa: N803
        """Estimate one frame (``Estimate(valid=False)`` when no hand blob is found).

        Args:
            depth: (H, W) float32 depth, metres, 0 = no measurement.
            K: (3, 3) intrinsics.

        Returns:
            ``Estimate(keypoints_cam=(21, 3) metres)`` after :attr:`iterations` updates.
        """
        depth_m, K_cv = validate_depth_input(depth, K)  # noqa: N806
        poses = self.predict_iterations(depth_m, K_cv)
        return Estimate(valid=False) if poses is None else Estimate(keypoints_cam=poses[-1])

    def predict_batch(self, depths: np.ndarray, Ks: np.ndarray) -> list[Estimate]:  # noqa: N803
        """Estimate a batch of frames of the current side (:meth:`predict_iterations_batch`).

        Args:
            depths: (B, H, W) float32 depths, metres, 0 = no measurement.
            Ks: (B, 3, 3) intrinsics.

        Returns:
            B estimates (``Estimate(valid=False)`` where no hand blob is found).

        Raises:
            InvalidEstimatorInput: on an invalid batch.
        """
        depths_m, Ks_cv = validate_batch_input(depths, Ks)  # noqa: N806
        poses = self.predict_iterations_batch(depths_m, Ks_cv)
        return [
            Estimate(valid=False) if p is None else Estimate(keypoints_cam=p[-1]) for p in poses
        ]

    def close(self) -> None:
        """Free the synthesizer's renderers."""
        self.synth.close()

    def info(self) -> dict[str, Any]:
        """What the estimator runs (for reports)."""
        return {
            **self.first.info(),
            "updater": self.updater_checkpoint,
            "synthesizer": self.synthesizer_kind,
            "iterations": self.iterations,
            "updater_canonical_side": self.canonical_side,
        }
