"""handsim's renderer as the feedback loop's synthesizer: a pose estimate -> its depth crop.

:class:`RendererSynthesizer` turns 21 keypoints (an estimate, camera frame) into the crop that a
hand in that pose would give: the keypoints are retargeted onto a handsim hand of the frame's
size and side (:class:`~handsim.hand.retarget.Retargeter`, warm-started from the previous
iteration's pose when given), the skinned hand is rendered alone (no table, no objects), and its
depth goes through DeepPrior's normalization
(:func:`~handsim.estimators.deepprior.preprocess.crop_depth`): ``(d - z_c) / (cube / 2)``, no
depth and beyond the cube +1.

The crop is rendered at its own size, not cut from a full image: the scene's camera sits at the
world origin with the OpenCV axes (so a pose in the camera frame is a pose in the world), and
its intrinsics are set per crop to ``K_crop = M K`` with ``M`` the crop's affine map
(:func:`~handsim.estimators.deepprior.preprocess.crop_matrix`): crop pixel ``(i, j)`` sees the
ray of image point ``M^-1 (i, j)``, which DeepPrior's nearest-neighbour crop samples at the
nearest image pixel. One scene per side is built on first use; the hand size changes by
:meth:`~handsim.world.scene.Scene.set_hand_length` (about a millisecond).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from handsim.errors import HandSimError, InvalidKeypoints
from handsim.hand.model import HAND_LENGTH_RANGE_M, HandParams
from handsim.hand.pose import HandPose
from handsim.hand.retarget import Retargeter
from handsim.world.camera import CameraIntrinsics
from handsim.world.render import DepthRenderer
from handsim.world.scene import CameraSpec, Scene, SceneSpec

from ..deepprior.preprocess import CROP_SIZE, CUBE_M, crop_matrix, denormalize_keypoints

__all__ = [
    "InvalidSynthesizerInput",
    "LearnedSynthesizerRunner",
    "RendererSynthesizer",
    "crop_intrinsics",
    "make_synthesizer",
]

# MuJoCo camera looking along its -z with +y up, turned half a turn about x: the OpenCV axes.
_OPENCV_QUAT_WXYZ = (0.0, 1.0, 0.0, 0.0)
_PIXEL_PITCH_M = 6e-6  # handsim.world.camera's sensor pitch: cam_intrinsic is in metres
_REFERENCE_LENGTH_M = 0.189  # the hand the retargeter fits; other sizes by its scale


class InvalidSynthesizerInput(HandSimError, ValueError):
    """Poses, centres, intrinsics, sizes or sides of a synthesizer call do not fit together."""


def crop_intrinsics(center_cam: np.ndarray, K: np.ndarray, cube_m: float, size: int) -> np.ndarray:  # noqa: N803
    """(3, 3) intrinsics of a camera that renders the crop of ``center_cam`` directly.

    Args:
        center_cam: (3,) crop centre, metres, camera frame.
        K: (3, 3) intrinsics of the full image.
        cube_m: cube edge, metres.
        size: crop side, pixels.

    Returns:
        ``[[M K]; [0, 0, 1]]`` with ``M`` the crop's (2, 3) affine map (no rotation).
    """
    M = crop_matrix(center_cam, K, cube_m, size)  # noqa: N806
    out = np.eye(3)
    out[:2] = M @ K
    return out


@dataclasses.dataclass
class _Side:
    scene: Scene
    renderer: DepthRenderer
    retargeter: Retargeter
    cam_id: int
    built_length_m: float
    version: int


class RendererSynthesizer:
    """Depth crops of pose estimates rendered with handsim's hand (an exact synthesizer).

    Args:
        cube_m: cube edge, metres (the pose network's).
        size: crop side, pixels.
        forearm: draw the forearm (as the data does).

    Raises:
        InvalidSynthesizerInput: for a cube or size out of range.
    """

    def __init__(self, *, cube_m: float = CUBE_M, size: int = CROP_SIZE, forearm: bool = True):
        if not (isinstance(size, int) and 8 <= size <= 1024):
            raise InvalidSynthesizerInput(f"size must be an int in [8, 1024] px; received {size!r}")
        if not (np.isfinite(cube_m) and 0.0 < cube_m <= 1.0):
            raise InvalidSynthesizerInput(f"cube_m must be in (0, 1] m; received {cube_m!r}")
        self.cube_m, self.size, self.forearm = float(cube_m), int(size), bool(forearm)
        self._sides: dict[str, _Side] = {}

    def _side(self, side: str) -> _Side:
        if side not in self._sides:
            params = HandParams(hand_length=_REFERENCE_LENGTH_M, side=side, forearm=self.forearm)
            s = self.size
            intr = CameraIntrinsics(s, s, float(s), float(s), (s - 1) / 2, (s - 1) / 2)
            cam = CameraSpec("synth", intr, (0.0, 0.0, 0.0), _OPENCV_QUAT_WXYZ)
            scene = Scene(SceneSpec(hand=params, cameras=(cam,), table=False))
            self._sides[side] = _Side(
                scene=scene,
                renderer=DepthRenderer(scene.model, "synth", intr),
                retargeter=Retargeter(params),
                cam_id=int(scene.model.camera("synth").id),
                built_length_m=_REFERENCE_LENGTH_M,
                version=scene.hand_geometry_version,
            )
        return self._sides[side]

    def close(self) -> None:
        """Free the renderers."""
        for side in self._sides.values():
            side.renderer.close()
        self._sides.clear()

    def fit(
        self,
        keypoints_cam: np.ndarray,
        hand_length_m: float,
        is_left: bool = False,
        initial: HandPose | None = None,
    ) -> tuple[HandPose | None, float]:
        """Fit a hand of this side to (21, 3) keypoints (metres, camera frame).

        Args:
            keypoints_cam: the keypoints.
            hand_length_m: the hand's length, metres, or NaN to fit it too (then clipped to
                the valid range of :class:`~handsim.hand.model.HandParams`).
            is_left: a left hand.
            initial: warm start.

        Returns:
            ``(pose, hand_length_m)``; the pose is ``None`` when the keypoints cannot be
            retargeted (coincident points).
        """
        side = self._side("left" if is_left else "right")
        known = bool(np.isfinite(hand_length_m))
        try:
            result = side.retargeter(
                keypoints_cam,
                initial,
                fit_scale=not known,
                initial_scale=float(hand_length_m) / _REFERENCE_LENGTH_M if known else None,
                check_side=False,
                report_clamped=False,
            )
        except InvalidKeypoints:
            return None, float(hand_length_m) if known else _REFERENCE_LENGTH_M
        if known:
            return result.pose, float(hand_length_m)
        lo, hi = HAND_LENGTH_RANGE_M
        return result.pose, float(np.clip(result.scale * _REFERENCE_LENGTH_M, lo, hi))

    def render(
        self,
        pose: HandPose | None,
        center_cam: np.ndarray,
        K: np.ndarray,  # noqa: N803
        hand_length_m: float,
        is_left: bool = False,
    ) -> np.ndarray:
        """The (size, size) float32 normalized crop of ``pose`` (all +1 for ``None``).

        Args:
            pose: hand pose in the camera frame (OpenCV axes, metres).
            center_cam: (3,) crop centre, metres.
            K: (3, 3) intrinsics of the full image.
            hand_length_m: hand length, metres.
            is_left: a left hand.
        """
        if pose is None:
            return np.ones((self.size, self.size), np.float32)
        side = self._side("left" if is_left else "right")
        scene = side.scene
        scene.set_hand_length(float(hand_length_m))
        if scene.hand_geometry_version != side.version:
            side.renderer.scale_geoms(
                scene.hand_skin_geom_ids, float(hand_length_m) / side.built_length_m
            )
            side.version = scene.hand_geometry_version
        kc = crop_intrinsics(center_cam, K, self.cube_m, self.size)
        half = (self.size - 1) / 2.0
        scene.model.cam_intrinsic[side.cam_id] = _PIXEL_PITCH_M * np.array(
            [kc[0, 0], kc[1, 1], half - kc[0, 2], half - kc[1, 2]]
        )
        scene.binding.set_pose(scene.data, pose, kinematics_only=True)
        depth, _ = side.renderer.render(scene.data)
        z_c = np.float32(center_cam[2])
        norm = (depth - z_c) / np.float32(self.cube_m / 2.0)
        norm[(depth <= 0) | (norm > 1.0)] = 1.0
        np.clip(norm, -1.0, 1.0, out=norm)
        return norm

    def __call__(
        self,
        poses_norm: np.ndarray,
        centers_cam: np.ndarray,
        K: np.ndarray,  # noqa: N803
        hand_length_m: np.ndarray,
        is_left: np.ndarray | None = None,
        initial: list[HandPose | None] | None = None,
    ) -> tuple[np.ndarray, list[HandPose | None]]:
        """Synthesize a batch of crops from normalized poses.

        Args:
            poses_norm: (B, 63) or (B, 21, 3) normalized keypoints (``(p - c) / (cube / 2)``).
            centers_cam: (B, 3) crop centres, metres, camera frame.
            K: (B, 3, 3) or (3, 3) intrinsics of the full images.
            hand_length_m: (B,) or scalar hand lengths, metres; NaN: fit the size to the pose.
            is_left: (B,) bool, left hands (default: right hands).
            initial: B warm starts (e.g. the poses this returned at the previous iteration).

        Returns:
            ``(crops, poses)``: (B, size, size) float32 normalized crops and the B fitted
            poses (``None`` where the keypoints could not be retargeted; that crop is all +1).

        Raises:
            InvalidSynthesizerInput: for shapes that do not agree or values that are not finite.
        """
        p = np.asarray(poses_norm, dtype=np.float64)
        b = len(p)
        try:
            p = p.reshape(b, 21, 3)
            c = np.broadcast_to(np.asarray(centers_cam, np.float64), (b, 3))
            k = np.broadcast_to(np.asarray(K, np.float64), (b, 3, 3))
            lengths = np.broadcast_to(np.asarray(hand_length_m, np.float64), (b,))
            left = np.broadcast_to(np.zeros(b, bool) if is_left is None else is_left, (b,))
        except ValueError as err:
            raise InvalidSynthesizerInput(
                "expected poses (B, 63), centres (B, 3), K (B, 3, 3) or (3, 3), hand lengths "
                f"(B,) and sides (B,) for B = {b}: {err}"
            ) from None
        if initial is not None and len(initial) != b:
            raise InvalidSynthesizerInput(
                f"initial must hold one pose (or None) per crop, {b}; received {len(initial)}"
            )
        for name, arr in (("poses", p), ("centres", c), ("K", k)):
            if not np.all(np.isfinite(arr)):
                raise InvalidSynthesizerInput(f"{name} must be finite; received NaN or Inf")
        keypoints = denormalize_keypoints(p, c, self.cube_m)
        crops = np.empty((b, self.size, self.size), np.float32)
        poses: list[HandPose | None] = []
        for i in range(b):
            warm = None if initial is None else initial[i]
            pose, length = self.fit(keypoints[i], lengths[i], bool(left[i]), warm)
            crops[i] = self.render(pose, c[i], k[i], length, bool(left[i]))
            poses.append(pose)
        return crops, poses

    def __enter__(self) -> RendererSynthesizer:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class LearnedSynthesizerRunner:
    """The learned synthesizer behind the same call as :class:`RendererSynthesizer`.

    Args:
        checkpoint: a ``handsim train synthesizer`` run folder or ``.pt`` path.
        device: torch device.

    Raises:
        InvalidCheckpoint: for a checkpoint that cannot be loaded or is not a synthesizer.
    """

    def __init__(self, checkpoint: str, device: str = "cpu") -> None:
        from .checkpoint import load_feedback_model

        self.model, config = load_feedback_model(checkpoint, "synthesizer", device)
        self.cube_m = float(config["cube_m"])
        self.size = int(config["model"]["size"])
        self.device = device

    def __call__(
        self,
        poses_norm: np.ndarray,
        centers_cam: np.ndarray,
        K: np.ndarray,  # noqa: N803
        hand_length_m: np.ndarray,
        is_left: np.ndarray | None = None,
        initial: list | None = None,
    ) -> tuple[np.ndarray, list[None]]:
        """(B, S, S) float32 crops of (B, 63) normalized poses (the other inputs are unused)."""
        import torch

        p = np.asarray(poses_norm, dtype=np.float32).reshape(len(poses_norm), -1)
        with torch.inference_mode():
            crops = self.model(torch.from_numpy(p).to(self.device))[:, 0]
        return crops.float().cpu().numpy(), [None] * len(p)

    def close(self) -> None:
        """Nothing to free (the same interface as :class:`RendererSynthesizer`)."""


def make_synthesizer(
    kind: str,
    checkpoint: str | None = None,
    *,
    cube_m: float = CUBE_M,
    size: int = CROP_SIZE,
    device: str = "cpu",
) -> RendererSynthesizer | LearnedSynthesizerRunner:
    """``renderer`` (:class:`RendererSynthesizer`) or ``learned`` (``checkpoint`` needed).

    Raises:
        InvalidSynthesizerInput: for another kind, a missing checkpoint, or a learned
            synthesizer of another cube or crop size.
    """
    if kind == "renderer":
        return RendererSynthesizer(cube_m=cube_m, size=size)
    if kind != "learned":
        raise InvalidSynthesizerInput(f"synthesizer must be renderer or learned; received {kind!r}")
    if not checkpoint:
        raise InvalidSynthesizerInput(
            "the learned synthesizer needs a checkpoint: the run folder of `handsim train "
            "synthesizer`"
        )
    runner = LearnedSynthesizerRunner(checkpoint, device)
    if runner.size != size or abs(runner.cube_m - cube_m) > 1e-9:
        raise InvalidSynthesizerInput(
            f"synthesizer {checkpoint} makes {runner.size} px crops of a {runner.cube_m} m cube; "
            f"this loop needs {size} px and {cube_m} m"
        )
    return runner
