"""The learned hand detector: the whole depth image to the hand's first centre.

The plane-removed centre of mass (:class:`~.preprocess.PlaneRemovedLocalizer`) takes the largest
blob of the nearest depth slab. That is the hand when the hand is nearest to the camera; on
hand-object frames it is often the object in front of the hand, and in egocentric views the
forearm, and the refinement CNN, which sees one cube around that centre, cannot find a hand
that is not in its crop.

:class:`HandDetector <.models.HandDetector>` sees the whole image at :data:`INPUT_W` x
:data:`INPUT_H` (nearest-neighbour subsampling of any camera's image) and scores every cell of
a :data:`GRID_W` x :data:`GRID_H` grid (a cell is :data:`STRIDE` x :data:`STRIDE` input pixels):
the logit that the middle-finger MCP projects into it (a softmax over the cells: one hand per
image), the MCP's position in the cell and its depth. :class:`LearnedDetector` back-projects
the best cell's position and depth with the camera's intrinsics: the centre the refinement CNN
starts from (``RefinedLocalizer(detector="learned")``).

Coordinates: an image column ``u`` (pixel centres at integers, image width ``W``) is ``s = (u +
0.5) * INPUT_W / W`` in input pixels (pixel edges at integers), the cell ``floor(s / STRIDE)``
and the position in the cell ``s / STRIDE - cell``; rows alike.

:func:`train_detector` fits it (``handsim train detector``): softmax cross-entropy over the
cells, plus L1 on the position (cells) and depth (decimetres) at the true cell, with random
image shifts and depth offsets; resumable like the other networks.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from handsim.errors import HandSimError

from .preprocess import MIDDLE_MCP

__all__ = [
    "INPUT_W",
    "INPUT_H",
    "STRIDE",
    "GRID_W",
    "GRID_H",
    "DEPTH_MAX_M",
    "detector_input",
    "detector_targets",
    "decode",
    "LearnedDetector",
    "DetectorTrainConfig",
    "InvalidDetectorConfig",
    "train_detector",
]

INPUT_W, INPUT_H = 128, 96
"""The detector's input image, pixels (a 4:3 camera image subsampled)."""

STRIDE = 4
"""Input pixels per grid cell (each way)."""

GRID_W, GRID_H = INPUT_W // STRIDE, INPUT_H // STRIDE
"""The detector's output grid, cells."""

DEPTH_MAX_M = 1.5
"""Depth beyond this is left out of the input (as the plane-removed detector's clip)."""

_DEPTH_UNIT_M = 0.1  # the depth output is in decimetres: of the order of the cell outputs


def _sample_index(n_in: int, n_out: int) -> np.ndarray:
    """Source pixel of each output pixel: the one under its centre."""
    return np.minimum(((np.arange(n_out) + 0.5) * n_in / n_out).astype(np.int64), n_in - 1)


def detector_input(depth_m: np.ndarray) -> np.ndarray:
    """(2, INPUT_H, INPUT_W) float32: depth / DEPTH_MAX_M and the measured mask.

    Args:
        depth_m: (H, W) depth, metres, 0 = no measurement (or (N, H, W): (N, 2, ...)).
    """
    depth_m = np.asarray(depth_m)
    rows = _sample_index(depth_m.shape[-2], INPUT_H)
    cols = _sample_index(depth_m.shape[-1], INPUT_W)
    small = depth_m[..., rows[:, None], cols[None, :]].astype(np.float32)
    valid = (small > 0) & (small < DEPTH_MAX_M)
    depth = np.where(valid, small / np.float32(DEPTH_MAX_M), np.float32(0.0))
    return np.stack([depth, valid.astype(np.float32)], axis=-3)


def detector_targets(
    keypoints_cam: np.ndarray,
    K: np.ndarray,
    image_size: tuple[int, int],  # noqa: N803
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The middle MCP's cell, position in the cell and depth, for (N, 21, 3) keypoints.

    Args:
        keypoints_cam: (N, 21, 3) keypoints, metres, camera frame.
        K: (N, 3, 3) intrinsics.
        image_size: ``(W, H)`` of the images, pixels.

    Returns:
        ``(cell (N,) int64 row-major index, position (N, 2) in cells (u, v), depth (N,) in
        decimetres)``; an MCP projecting outside the image gets the nearest border cell and a
        position outside ``[0, 1)``.
    """
    p = np.asarray(keypoints_cam, np.float64)[:, MIDDLE_MCP]
    K = np.asarray(K, np.float64)  # noqa: N806
    z = p[:, 2]
    u = K[:, 0, 0] * p[:, 0] / z + K[:, 0, 2]
    v = K[:, 1, 1] * p[:, 1] / z + K[:, 1, 2]
    su = (u + 0.5) * INPUT_W / image_size[0] / STRIDE
    sv = (v + 0.5) * INPUT_H / image_size[1] / STRIDE
    gx = np.clip(np.floor(su), 0, GRID_W - 1).astype(np.int64)
    gy = np.clip(np.floor(sv), 0, GRID_H - 1).astype(np.int64)
    return gy * GRID_W + gx, np.stack([su - gx, sv - gy], axis=-1), z / _DEPTH_UNIT_M


def decode(
    out: np.ndarray,
    K: np.ndarray,
    image_size: tuple[int, int],  # noqa: N803
) -> np.ndarray:
    """(N, 3) centres, metres, from the network's (N, 4, GRID_H, GRID_W) outputs.

    The cell of the highest logit; its position and depth, back-projected with ``K`` (N, 3, 3)
    for images of ``image_size`` ``(W, H)``.
    """
    out = np.asarray(out, np.float64)
    n = len(out)
    cell = out[:, 0].reshape(n, -1).argmax(axis=1)
    gy, gx = np.divmod(cell, GRID_W)
    at = out[np.arange(n), :, gy, gx]  # (N, 4)
    u = STRIDE * (gx + at[:, 1]) * image_size[0] / INPUT_W - 0.5
    v = STRIDE * (gy + at[:, 2]) * image_size[1] / INPUT_H - 0.5
    z = at[:, 3] * _DEPTH_UNIT_M
    K = np.asarray(K, np.float64).reshape(n, 3, 3)  # noqa: N806
    x = (u - K[:, 0, 2]) * z / K[:, 0, 0]
    y = (v - K[:, 1, 2]) * z / K[:, 1, 1]
    return np.stack([x, y, z], axis=-1)


class LearnedDetector:
    """The hand's first centre from :class:`~.models.HandDetector` (one network call).

    Args:
        checkpoint: ``"detector"`` (the shipped weights) or a checkpoint path / run folder.
        device: torch device.

    Raises:
        InvalidCheckpoint: for a checkpoint that cannot be loaded or is not a detector.
    """

    def __init__(
        self, checkpoint: str | os.PathLike[str] = "detector", device: str = "cpu"
    ) -> None:
        from .checkpoint import InvalidCheckpoint, load_model
        from .models import inference_forward

        self.model, config = load_model(checkpoint, device)
        if config["model"].get("arch") != "detector":
            raise InvalidCheckpoint(
                f"checkpoint {checkpoint} holds a {config['model'].get('arch')!r} network, not "
                "a hand detector (train one with `handsim train detector`)"
            )
        self._forward = inference_forward(self.model)
        self.checkpoint = str(checkpoint)
        self.device = device

    def __repr__(self) -> str:
        return f"LearnedDetector(checkpoint={self.checkpoint!r})"

    def localize_batch(self, depths_m: Sequence[np.ndarray], K: np.ndarray) -> np.ndarray:  # noqa: N803
        """(N, 3) centres, metres, of N images of one size (one network call)."""
        import torch

        if len(depths_m) == 0:
            return np.zeros((0, 3))
        x = torch.from_numpy(detector_input(np.stack(depths_m)))
        x = x.to(self.device).contiguous(memory_format=torch.channels_last)
        with torch.inference_mode():
            out = self._forward(x).float().cpu().numpy()
        h, w = np.shape(depths_m[0])
        return decode(out, K, (w, h))

    def localize(self, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray | None:  # noqa: N803
        """(3,) centre, metres, or ``None`` when the image has no measured depth."""
        if not np.any((depth_m > 0) & (depth_m < DEPTH_MAX_M)):
            return None
        return self.localize_batch([depth_m], np.asarray(K)[None])[0]


# Training ---------------------------------------------------------------------------------------


class InvalidDetectorConfig(HandSimError, ValueError):
    """A detector training option is invalid, or a run folder holds a different run."""


@dataclasses.dataclass(frozen=True)
class DetectorTrainConfig:
    """One detector training run (``run.json``; resume needs the same).

    Attributes:
        epochs: training epochs.
        batch_size: batch size.
        lr: Adam learning rate (decayed by 10x over the run, cosine).
        weight_decay: Adam weight decay.
        channels: filters of the grid-resolution convs.
        shift_px: largest random image shift, input pixels (each way, uniform).
        depth_shift_m: largest random depth offset of the whole image, metres (uniform).
        max_frames: use at most this many training frames (0: all).
        seed: random seed.
        canonical_side: left hands mirrored into the right-hand frame, as the pose networks.
    """

    epochs: int = 15
    batch_size: int = 64
    lr: float = 1e-3
    weight_decay: float = 1e-4
    channels: int = 48
    shift_px: int = 16
    depth_shift_m: float = 0.1
    max_frames: int = 0
    seed: int = 0
    canonical_side: bool = True

    def model_config(self) -> dict[str, Any]:
        """The :func:`~.models.build_model` config of this run."""
        return {"arch": "detector", "channels": self.channels}


def _check(config: DetectorTrainConfig) -> None:
    checks = {
        "epochs": (config.epochs, 1, 10_000),
        "batch_size": (config.batch_size, 2, 4096),
        "channels": (config.channels, 4, 512),
        "shift_px": (config.shift_px, 0, INPUT_W // 2),
    }
    for name, (value, lo, hi) in checks.items():
        if not isinstance(value, int) or not lo <= value <= hi:
            raise InvalidDetectorConfig(
                f"{name} must be an integer in [{lo}, {hi}]; received {value!r}"
            )
    for name, value, hi in (
        ("lr", config.lr, 1.0),
        ("weight_decay", config.weight_decay, 1.0),
        ("depth_shift_m", config.depth_shift_m, 0.5),
    ):
        if not 0.0 <= value <= hi:  # also refuses NaN
            raise InvalidDetectorConfig(f"{name} must be in [0, {hi}]; received {value!r}")


def _shift(image: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """``image`` moved by ``(dx, dy)`` pixels, the uncovered border 0 (nothing measured)."""
    out = np.zeros_like(image)
    h, w = image.shape
    src = image[max(0, -dy) : h - max(0, dy), max(0, -dx) : w - max(0, dx)]
    out[max(0, dy) : max(0, dy) + src.shape[0], max(0, dx) : max(0, dx) + src.shape[1]] = src
    return out


class _Images:
    """A split's detector inputs (float16, subsampled once) and targets."""

    def __init__(self, frames: Any) -> None:
        n = len(frames)
        h, w = frames.depth_units.shape[1:]
        self.image_size = (w, h)
        rows, cols = _sample_index(h, INPUT_H), _sample_index(w, INPUT_W)
        self.depth_m = np.empty((n, INPUT_H, INPUT_W), np.float16)
        for lo in range(0, n, 1024):
            part = frames.depth_units[lo : lo + 1024][:, rows[:, None], cols[None, :]]
            scale = frames.depth_scale_m[lo : lo + 1024, None, None]
            self.depth_m[lo : lo + 1024] = part.astype(np.float32) * scale
        self.K = frames.K
        self.keypoints_cam = frames.keypoints_cam
        self.cell, self.position, self.depth_dm = detector_targets(
            frames.keypoints_cam, frames.K, self.image_size
        )

    def __len__(self) -> int:
        return len(self.K)

    def batch(
        self, idx: np.ndarray, rng: np.random.Generator | None, config: DetectorTrainConfig
    ) -> tuple[np.ndarray, ...]:
        """Inputs (B, 2, H, W) and targets (cell, position, depth) of frames ``idx``."""
        depth = self.depth_m[idx].astype(np.float32)
        cell, position, depth_dm = self.cell[idx], self.position[idx], self.depth_dm[idx]
        if rng is not None:
            measured = depth > 0
            dz = rng.uniform(-config.depth_shift_m, config.depth_shift_m, len(idx))
            depth = np.where(measured, np.maximum(depth + dz[:, None, None], 1e-3), 0.0)
            depth_dm = depth_dm + dz / _DEPTH_UNIT_M
            shifts = rng.integers(-config.shift_px, config.shift_px + 1, (len(idx), 2))
            depth = np.stack([_shift(d, dx, dy) for d, (dx, dy) in zip(depth, shifts, strict=True)])
            gy, gx = np.divmod(cell, GRID_W)
            su = gx + position[:, 0] + shifts[:, 0] / STRIDE
            sv = gy + position[:, 1] + shifts[:, 1] / STRIDE
            gx = np.clip(np.floor(su), 0, GRID_W - 1).astype(np.int64)
            gy = np.clip(np.floor(sv), 0, GRID_H - 1).astype(np.int64)
            cell, position = gy * GRID_W + gx, np.stack([su - gx, sv - gy], axis=-1)
        x = detector_input(depth)
        return x, cell, position.astype(np.float32), depth_dm.astype(np.float32)


def _loss(out: Any, cell: Any, position: Any, depth_dm: Any) -> Any:
    import torch

    n = len(out)
    ce = torch.nn.functional.cross_entropy(out[:, 0].reshape(n, -1), cell)
    at = out.flatten(2)[torch.arange(n), 1:, cell]  # (N, 3) at the true cell
    return ce + (at[:, :2] - position).abs().sum(1).mean() + (at[:, 2] - depth_dm).abs().mean()


def _evaluate(model: Any, images: _Images, batch_size: int, device: str) -> dict[str, float]:
    """Distance of the detected centre from the true middle MCP, mm (no augmentation)."""
    import torch

    model.eval()
    centres = []
    with torch.inference_mode():
        for lo in range(0, len(images), batch_size):
            idx = np.arange(lo, min(lo + batch_size, len(images)))
            x = torch.from_numpy(images.batch(idx, None, DetectorTrainConfig())[0]).to(device)
            centres.append(decode(model(x).float().cpu().numpy(), images.K[idx], images.image_size))
    d = np.linalg.norm(np.concatenate(centres) - images.keypoints_cam[:, MIDDLE_MCP], axis=1) * 1000
    return {
        "mean_error_mm": float(d.mean()),
        "median_error_mm": float(np.median(d)),
        "over_50mm": float((d > 50).mean()),
        "frames": len(d),
    }


def train_detector(
    data: list[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    config: DetectorTrainConfig,
    *,
    device: str = "cpu",
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Train (or resume) the hand detector; returns the final metrics (also ``metrics.json``).

    Validation: the mean distance of the detected centre from the true middle MCP (mm) on the
    ``val`` split; ``best.pt`` keeps the best epoch. The images are subsampled once, in memory
    (24 KB a frame).

    Raises:
        InvalidDetectorConfig: for bad options or a folder that holds a different run.
    """
    import torch
    from tqdm import tqdm

    from .checkpoint import load_resume_state, save_checkpoint, save_resume_state
    from .data import load_frames
    from .models import build_model
    from .train import open_run, precise_bn

    _check(config)
    out = Path(out)
    open_run(out, config, data, InvalidDetectorConfig)
    torch.manual_seed(config.seed)
    max_frames = config.max_frames or None
    canonical = config.canonical_side
    frames = load_frames(data, "train", max_frames=max_frames, canonical_side=canonical)
    train_images = _Images(frames)
    del frames
    val_max = None if max_frames is None else max(8, max_frames // 8)
    val_images = _Images(load_frames(data, "val", max_frames=val_max, canonical_side=canonical))
    log(f"frames: train {len(train_images)}, val {len(val_images)}")
    ckpt_config = {
        "model": config.model_config(),
        "kind": "detector",
        "canonical_side": canonical,
        "input": [INPUT_W, INPUT_H],
        "depth_max_m": DEPTH_MAX_M,
    }
    model = build_model(config.model_config()).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    steps_per_epoch = math.ceil(len(train_images) / config.batch_size)
    total_steps = max(1, steps_per_epoch * config.epochs)

    class _BN:  # precise_bn's dataset: unaugmented inputs, one at a time
        def __len__(self) -> int:
            return len(train_images)

        def __getitem__(self, i: int) -> tuple[Any, None]:
            x = train_images.batch(np.array([i]), None, config)[0][0]
            return torch.from_numpy(x), None

    start_epoch, best, history, elapsed = 0, math.inf, [], 0.0
    last = out / "last.pt"
    if last.is_file():
        state = load_resume_state(last, model, optimizer, device)
        start_epoch, best = state["epoch"], state["best_val_mm"]
        history, elapsed = state["history"], state["elapsed_s"]
        log(f"resuming {out} after epoch {start_epoch}")
    for epoch in range(start_epoch, config.epochs):
        t0 = time.perf_counter()
        model.train()
        rng = np.random.default_rng([config.seed, epoch])
        order = rng.permutation(len(train_images))
        total, count = 0.0, 0
        starts = range(0, len(order), config.batch_size)
        desc = f"detector epoch {epoch + 1}/{config.epochs}"
        bar = tqdm(starts, desc=desc, disable=not progress, leave=False)
        for step, lo in enumerate(bar):
            step_all = epoch * steps_per_epoch + step
            lr = config.lr * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * step_all / total_steps)))
            for group in optimizer.param_groups:
                group["lr"] = lr
            idx = order[lo : lo + config.batch_size]
            if len(idx) < 2:
                continue  # batch norm cannot take a batch of one
            batch = train_images.batch(idx, rng, config)
            x, cell, position, depth_dm = (torch.from_numpy(a).to(device) for a in batch)
            loss = _loss(model(x), cell, position, depth_dm)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += loss.item() * len(idx)
            count += len(idx)
            bar.set_postfix(loss=f"{total / count:.4f}")
        bar.close()
        precise_bn(model, _BN(), config.batch_size, device, seed=config.seed * 1000 + epoch)
        val = _evaluate(model, val_images, 256, device)
        if val["mean_error_mm"] < best:
            best = val["mean_error_mm"]
            save_checkpoint(out / "best.pt", {"model": model.state_dict()}, ckpt_config)
        elapsed += time.perf_counter() - t0
        entry = {
            "epoch": epoch + 1,
            "train_loss": total / max(count, 1),
            "val_mean_error_mm": val["mean_error_mm"],
            "val_median_error_mm": val["median_error_mm"],
            "val_over_50mm": val["over_50mm"],
            "elapsed_s": elapsed,
        }
        history.append(entry)
        save_resume_state(
            last, model, optimizer, epoch=epoch + 1, best_val_mm=best, history=history,
            elapsed_s=elapsed, config=ckpt_config,
        )  # fmt: skip
        log(json.dumps(entry))
    metrics = {
        "kind": "detector",
        "config": dataclasses.asdict(config),
        "train_frames": len(train_images),
        "val_frames": len(val_images),
        "epochs_done": len(history),
        "best_val_mean_error_mm": best,
        "train_time_s": elapsed,
        "device": device,
        "history": history,
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    return metrics
