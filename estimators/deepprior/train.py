"""Training of DeepPrior, DeepPrior++ and the refinement localizer (``handsim train``).

:func:`train` fits one network on the ``train`` split of handsim dataset folders and validates
on their ``val`` split. It is resumable: every epoch writes ``last.pt`` (model, optimizer, epoch,
history) and, when validation improves, ``best.pt`` (model only), each with its JSON config;
running the same command again continues after the last finished epoch (a killed run loses at
most the epoch in progress). ``metrics.json`` holds the history and the final figures.

Loss: Huber (``delta`` in normalized units, 0.05 = 6.25 mm for the 250 mm cube) on the
normalized labels; Adam with weight decay; ``torch.manual_seed(seed)`` and per-sample
augmentation seeds make a run deterministic on one device and thread count.

Pose networks crop at the true middle-finger MCP unless ``localizer`` names a localizer
checkpoint: then at its refined centre, as at inference. The prior is the PCA of the normalized,
augmented training poses (``pca.npz``; its explained-variance curve goes into ``metrics.json``).

Side: with ``canonical_side`` (the default) left hands' frames are mirrored into the right-hand
frame as they are read (:func:`~.data.load_frames`), so the network learns one chirality; the
checkpoint's config records ``canonical_side`` and the estimator mirrors left inputs likewise.
One network fitted on both chiralities as they come averages them and folds the palm.

Batch normalization: after every epoch the running statistics are recomputed as plain averages
over :data:`PRECISE_BN_BATCHES` training batches ("precise BN"). The momentum-averaged
statistics that training leaves lag the weights and follow the last few batches; with them the
validation error of the shipped DeepPrior++ swung between 41 and 116 mm from epoch to epoch, and
an epoch of fine-tuning measured 78.7 mm as stored against 40.8 mm with its statistics
recomputed (same weights, 485 validation frames).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import multiprocessing
import os
import time
from collections.abc import Callable
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import numpy as np

from handsim.errors import HandSimError

from .checkpoint import (
    load_checkpoint,
    load_resume_state,
    resolve_checkpoint,
    save_checkpoint,
    save_resume_state,
)
from .data import CropDataset, FrameSet, load_frames
from .preprocess import CUBE_M, MIDDLE_MCP, fit_pca
from .preprocess import sample_augmentation as _sample

__all__ = [
    "KINDS",
    "PRECISE_BN_BATCHES",
    "TrainConfig",
    "InvalidTrainConfig",
    "train",
    "open_run",
    "localizer_centers",
    "precise_bn",
]

KINDS = ("deepprior", "deepprior++", "localizer")
"""What ``handsim train`` trains."""

BONE_PAIRS = tuple((0 if j % 4 == 1 else j - 1, j) for j in range(1, 21)) + (
    (5, 9),
    (9, 13),
    (13, 17),
    (5, 17),
)
"""The keypoint pairs of the bone-length term: each keypoint with its parent, then the palm's
transverse links between the index, middle, ring and little MCPs (and index to little)."""

PRECISE_BN_BATCHES = 32
"""Training batches whose plain average gives the batch-norm statistics after each epoch."""


class InvalidTrainConfig(HandSimError, ValueError):
    """A training option is invalid, or a run folder holds a different run."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """One training run (saved as ``run.json`` in the run folder; resume needs the same).

    Attributes:
        kind: ``deepprior``, ``deepprior++`` or ``localizer``.
        arch: DeepPrior's network: ``shallow``, ``deep`` or ``multiscale`` (``deepprior`` only).
        prior_dim: prior bottleneck dimension, 0 for direct regression.
        epochs: training epochs.
        batch_size: batch size.
        lr: Adam learning rate (decayed by 10x over the run, cosine).
        weight_decay: Adam weight decay.
        huber_delta: Huber loss threshold, normalized units.
        bone_loss: weight of the bone-length term (0: none; pose networks only): the mean
            absolute difference between predicted and true lengths of the hand's 20 bones and
            the palm's four transverse links (index to little MCP), normalized units.
        cube_m: cube edge, metres.
        size: crop side, pixels (localizer default 64).
        fc: fully connected units.
        width: DeepPrior++'s conv filter factor (1 = the paper's widths).
        dropout: dropout of the fully connected layers.
        rotation, scale, translation: online augmentations.
        offset_sigma_m: centre offset standard deviation, metres.
        localizer: localizer checkpoint whose centres the pose network is cropped at.
        detector: the first centre the localizer refines (``RefinedLocalizer``'s
            ``detector``: ``plane``, ``com``, ``learned`` or a detector checkpoint), as at
            inference.
        refine_iterations: the localizer's refinement steps from the detector's centre (0: the
            detector's centre as it is). Recorded in the checkpoint (``crop``): the estimator
            crops as the network was trained.
        init: checkpoint whose weights the run starts from (a run folder, a ``.pt`` path or a
            shipped name), e.g. to fine-tune shipped weights; its network must be this run's.
        max_frames: use at most this many training frames (0: all).
        seed: random seed.
        canonical_side: mirror left hands into the right-hand frame (training and inference);
            ``False`` trains on both sides as they come (for the side study).
    """

    kind: str = "deepprior++"
    arch: str = "deep"
    prior_dim: int = 30
    epochs: int = 20
    batch_size: int = 64
    lr: float = 1e-3
    weight_decay: float = 1e-4
    huber_delta: float = 0.05
    bone_loss: float = 0.0
    cube_m: float = CUBE_M
    size: int = 128
    fc: int = 1024
    width: float = 1.0
    dropout: float = 0.3
    rotation: bool = True
    scale: bool = True
    translation: bool = True
    offset_sigma_m: float = 0.005
    localizer: str | None = None
    detector: str = "plane"
    refine_iterations: int = 3
    init: str | None = None
    max_frames: int = 0
    seed: int = 0
    canonical_side: bool = True

    def model_config(self) -> dict[str, Any]:
        """The :func:`~.models.build_model` config of this run."""
        if self.kind == "localizer":
            return {"arch": "localizer", "size": self.size, "fc": self.fc, "dropout": self.dropout}
        arch = "resnet" if self.kind == "deepprior++" else self.arch
        config = {
            "arch": arch,
            "size": self.size,
            "fc": self.fc,
            "dropout": self.dropout,
            "prior_dim": self.prior_dim,
        }
        if arch == "resnet":
            config["width"] = self.width
        return config


def _check(config: TrainConfig) -> None:
    if config.kind not in KINDS:
        raise InvalidTrainConfig(
            f"kind must be one of {', '.join(KINDS)}; received {config.kind!r}"
        )
    if config.arch not in ("shallow", "deep", "multiscale"):
        raise InvalidTrainConfig(
            f"arch must be shallow, deep or multiscale; received {config.arch!r}"
        )
    # 512 is four times DeepPrior's 128; a larger crop only allocates (100 000 asked for TBs).
    if config.size % 32 or not 32 <= config.size <= 512:
        raise InvalidTrainConfig(
            f"size must be a multiple of 32 in [32, 512] pixels; received {config.size}"
        )
    if not 0 <= config.prior_dim <= 63:
        raise InvalidTrainConfig(f"prior_dim must be in [0, 63]; received {config.prior_dim}")
    # Finite, in range: NaN passes every comparison but ``not``, so test ``not lo <= x <= hi``.
    ranges = {
        "lr": (config.lr, 0.0, 1.0, "in [0, 1] (0 keeps the initial weights)"),
        "weight_decay": (config.weight_decay, 0.0, 1.0, "in [0, 1]"),
        "cube_m": (config.cube_m, 0.0, 1.0, "in (0, 1] metres"),
        "offset_sigma_m": (config.offset_sigma_m, 0.0, 0.5, "in [0, 0.5] metres"),
        "width": (config.width, 0.0, 8.0, "in (0, 8]"),
        "bone_loss": (config.bone_loss, 0.0, 100.0, "in [0, 100]"),
    }
    for name, (value, lo, hi, valid) in ranges.items():
        positive = name in ("cube_m", "width")
        if not lo <= value <= hi or (positive and value == lo):
            raise InvalidTrainConfig(f"{name} must be {valid}; received {value}")
    if config.bone_loss and config.kind == "localizer":
        raise InvalidTrainConfig("bone_loss is for the pose networks; the localizer has no bones")
    steps = config.refine_iterations
    if not isinstance(steps, int) or not 0 <= steps <= 10:
        raise InvalidTrainConfig(
            f"refine_iterations must be an integer in [0, 10]; received {steps!r}"
        )


_FRAMES: FrameSet | None = None  # the frames of localizer_centers, inherited by forked workers


@functools.lru_cache(maxsize=2)
def _refiner(checkpoint: str, iterations: int, device: str) -> Any:
    """The localizer of one :func:`localizer_centers` call, loaded once, not per chunk."""
    from .estimator import RefinedLocalizer

    # Only its refinement is used: the first centres come from _detector.
    return RefinedLocalizer(checkpoint, iterations=iterations, device=device, detector="plane")


@functools.lru_cache(maxsize=2)
def _detector(detector: str, device: str) -> Any:
    """The first-centre detector of one :func:`localizer_centers` call, made once."""
    from .estimator import _first_centre

    return _first_centre(detector, device)


def _chunk_centers(
    indices: range, checkpoint: str | None, iterations: int, detector: str, device: str
) -> tuple[np.ndarray, np.ndarray]:
    """Crop centres and ``found`` of the frames ``indices`` (see :func:`localizer_centers`)."""
    from .detector import DEPTH_MAX_M, LearnedDetector

    f = _FRAMES
    assert f is not None
    base = _detector(detector, device)
    if isinstance(base, LearnedDetector):  # one network call for the chunk
        depths = [f.depth(i) for i in indices]
        # As LearnedDetector.localize: no centre without a measured pixel in its range.
        seen = [bool(np.any((d > 0) & (d < DEPTH_MAX_M))) for d in depths]
        located = base.localize_batch(depths, f.K[indices.start : indices.stop])
        coms = [c if ok else None for c, ok in zip(located, seen, strict=True)]
    else:
        coms = [base.localize(f.depth(i), f.K[i]) for i in indices]
    found = np.array([c is not None for c in coms], dtype=bool)
    centers = f.keypoints_cam[indices.start : indices.stop, MIDDLE_MCP].copy()
    if found.any():
        centers[found] = np.stack([c for c in coms if c is not None])
        if checkpoint:
            idx = np.flatnonzero(found) + indices.start
            centers[found] = _refiner(checkpoint, iterations, device).refine_batch(
                lambda j: f.depth(int(idx[j])), f.K[idx], centers[found]
            )
    return centers, found


def _chunk_centers_cpu(task: tuple) -> tuple[np.ndarray, np.ndarray]:
    import torch

    torch.set_num_threads(1)  # one process per core
    return _chunk_centers(*task, "cpu")


def localizer_centers(
    frames: FrameSet,
    checkpoint: str | None,
    iterations: int = 3,
    *,
    workers: int = 0,
    device: str = "cpu",
    detector: str = "plane",
) -> tuple[np.ndarray, np.ndarray]:
    """Crop centres of every frame: the detector's centre, refined by ``checkpoint`` if given.

    Frames go in chunks of 256, each located and refined as one batch, so the centres do not
    depend on ``workers`` (on one device).

    Args:
        frames: the frames.
        checkpoint: localizer checkpoint, or ``None`` for the plane-removed CoM alone.
        iterations: refinement steps.
        workers: processes (forked, on Linux) that fit the planes and run the refinement
            network on the CPU, one thread each; 0 or 1: this process, on ``device``.
        device: torch device of the refinement network when ``workers`` is 0 or 1.
        detector: the first centre (``RefinedLocalizer``'s ``detector``; default: the
            plane-removed centre of mass).

    Returns:
        ``(centers (N, 3) metres, found (N,) bool)``; a frame without a blob gets the true
        middle MCP and ``found = False``.
    """
    global _FRAMES
    n = len(frames)
    chunks = [range(s, min(s + 256, n)) for s in range(0, n, 256)]
    _FRAMES = frames
    try:
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            tasks = [(c, checkpoint, iterations, detector) for c in chunks]
            with multiprocessing.get_context("fork").Pool(workers) as pool:
                parts = pool.map(_chunk_centers_cpu, tasks, chunksize=1)
        else:
            parts = [_chunk_centers(c, checkpoint, iterations, detector, device) for c in chunks]
    finally:
        _FRAMES = None
        _refiner.cache_clear()
        _detector.cache_clear()  # a checkpoint retrained at the same path is read again
    if not parts:
        return np.zeros((0, 3)), np.zeros(0, dtype=bool)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def bone_length_error(pred: Any, target: Any, a: Any, b: Any) -> Any:
    """Mean ``| |pred_a - pred_b| - |target_a - target_b| |`` over the pairs ``(a, b)``.

    A loss on the joints alone is met, under doubt about the hand's roll, by the mean of the
    hypotheses, whose palm is narrower than any of them; this term asks for a hand whose
    bones have their true lengths.

    Args:
        pred: (B, 63) normalized keypoints, flattened (21, 3).
        target: (B, 63) the same, true.
        a: (P,) first keypoint index of each pair.
        b: (P,) second keypoint index of each pair.
    """
    p, t = pred.view(len(pred), -1, 3), target.view(len(target), -1, 3)
    length_pred = (p[:, a] - p[:, b]).norm(dim=-1)
    length_true = (t[:, a] - t[:, b]).norm(dim=-1)
    return (length_pred - length_true).abs().mean()


def _augmented_poses(frames: FrameSet, config: TrainConfig, copies: int = 2) -> np.ndarray:
    """(copies * N, 63) normalized keypoints under the training augmentation (for the PCA)."""
    from .preprocess import normalize_keypoints, rotate_keypoints

    rng = np.random.default_rng([config.seed, 12345])
    out = []
    flags = {"rotation": config.rotation, "scale": config.scale, "translation": config.translation}
    for _ in range(copies):
        for i in range(len(frames)):
            p = _sample(rng, offset_sigma_m=config.offset_sigma_m, **flags)
            kp = frames.keypoints_cam[i]
            c = kp[MIDDLE_MCP] + np.asarray(p.offset_m)
            rot = rotate_keypoints(kp, frames.K[i], c, p.angle_rad)
            out.append(normalize_keypoints(rot, c, config.cube_m * p.scale).reshape(-1))
    return np.asarray(out)


def precise_bn(
    model: Any,
    dataset: Any,
    batch_size: int,
    device: str = "cpu",
    batches: int = PRECISE_BN_BATCHES,
    seed: int = 0,
) -> None:
    """Recompute the batch-norm running statistics of ``model`` over training batches.

    Each batch-norm layer's mean and variance become the plain averages of their per-batch
    values over ``batches`` batches of ``batch_size`` crops drawn (seeded) from ``dataset``;
    nothing else changes (dropout stays off, no gradient, torch's random state untouched).
    A model without batch normalization is left as it is.
    """
    import torch

    norms = [m for m in model.modules() if isinstance(m, torch.nn.modules.batchnorm._BatchNorm)]
    if not norms:
        return
    was_training = model.training
    momenta = [m.momentum for m in norms]
    model.eval()
    for m in norms:
        m.reset_running_stats()
        m.momentum = None  # None: a cumulative (plain) average
        m.train()
    order = np.random.default_rng(seed).permutation(len(dataset))[: batches * batch_size]
    with torch.no_grad():
        for start in range(0, len(order), batch_size):
            chunk = order[start : start + batch_size]
            if len(chunk) < 2 and start > 0:
                break  # batch norm cannot take a batch of one (and it would add nothing)
            model(torch.stack([dataset[int(i)][0] for i in chunk]).to(device))
    for m, momentum in zip(norms, momenta, strict=True):
        m.momentum = momentum
    model.train(was_training)


def _evaluate(model: Any, dataset: CropDataset, batch_size: int, device: str) -> dict:
    """Mean error on a dataset without augmentation, mm."""
    import torch

    model.eval()
    errors = []
    with torch.inference_mode():
        for start in range(0, len(dataset), batch_size):
            items = [dataset[i] for i in range(start, min(start + batch_size, len(dataset)))]
            x = torch.stack([a for a, _ in items]).to(device)
            y = torch.stack([b for _, b in items]).to(device)
            pred = model(x)
            d = (pred - y).reshape(len(items), -1, 3).norm(dim=-1)
            errors.append(d.cpu().numpy() * dataset.cube_m / 2.0 * 1000.0)
    e = np.concatenate(errors)
    return {"mean_error_mm": float(e.mean()), "frames": int(len(e))}


def _load_init(model: Any, config: TrainConfig, ckpt_config: dict, log: Callable) -> None:
    """Load ``config.init``'s weights into ``model`` (float32), checking it is the same network."""
    state, init_config = load_checkpoint(config.init)
    theirs = {k: init_config.get(k) for k in ("kind", "model", "cube_m")}
    ours = {k: ckpt_config[k] for k in ("kind", "model", "cube_m")}
    if theirs != ours:
        differ = ", ".join(
            f"{k}: {theirs[k]!r} there, {ours[k]!r} here" for k in ours if theirs[k] != ours[k]
        )
        raise InvalidTrainConfig(
            f"--init {config.init} holds another network ({differ}); give this run the same "
            "network options or another checkpoint"
        )
    model.load_state_dict(
        {k: v.float() if v.is_floating_point() else v for k, v in state["model"].items()}
    )
    log(f"starting from the weights of {resolve_checkpoint(config.init)}")


def open_run(out: Path, config: Any, data: list, error: type[HandSimError]) -> None:
    """Create the run folder ``out`` and its ``run.json``; refuse one made with other options.

    ``config`` is the run's dataclass config; ``error`` the exception type to raise.
    """
    out.mkdir(parents=True, exist_ok=True)
    run_json = out / "run.json"
    run = {"config": dataclasses.asdict(config), "data": [str(Path(d).resolve()) for d in data]}
    if run_json.is_file():
        previous = json.loads(run_json.read_text())
        # An option added after the run was made has its default there.
        defaults = {f.name: f.default for f in dataclasses.fields(config)}
        before = {k: previous["config"].get(k, defaults.get(k)) for k in run["config"]}
        if before != run["config"]:
            changed = sorted(k for k in run["config"] if before[k] != run["config"][k])
            raise error(
                f"{out} holds a run with other options ({', '.join(changed)}); use a new --out "
                "or the same options to resume"
            )
    run_json.write_text(json.dumps(run, indent=2) + "\n")


def train(
    data: list[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    config: TrainConfig,
    *,
    device: str = "cpu",
    loader_workers: int = 0,
    amp: bool = False,
    val_every: int = 1,
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Train (or resume) one network; returns the final metrics (also ``out/metrics.json``).

    Args:
        data: dataset folders (``handsim generate``).
        out: run folder (created; an existing run with the same config is resumed).
        config: the run.
        device: torch device.
        loader_workers: DataLoader processes that crop and augment (0: this process); as many
            processes read the shards and compute the crop centres (plane fits and the
            localizer's refinement, on the CPU). On the CPU the result does not depend on it.
        amp: on CUDA, run the forward pass in bfloat16 (mixed precision; the loss and the
            weights stay float32). Ignored on the CPU.
        val_every: validate every this many epochs (and after the last).
        progress: show a tqdm bar per epoch.
        log: where to print one line per validation.

    Raises:
        InvalidTrainConfig: for bad options or a folder that holds a different run.
    """
    import torch
    from torch.utils.data import DataLoader
    from tqdm import tqdm

    from .models import PriorLayer, build_model

    _check(config)
    out = Path(out)
    open_run(out, config, data, InvalidTrainConfig)
    torch.manual_seed(config.seed)
    np.random.seed(config.seed % 2**32)
    if loader_workers:
        import cv2

        # OpenCV's thread pool does not survive a fork (its workers hang); one process per
        # core needs no threads. Restored when the run completes.
        opencv_threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
    if device.startswith("cuda"):
        torch.backends.cudnn.benchmark = True
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True

    max_frames = config.max_frames or None
    canonical = config.canonical_side
    train_frames = load_frames(
        data, "train", max_frames=max_frames, canonical_side=canonical, workers=loader_workers
    )
    val_frames = load_frames(
        data,
        "val",
        max_frames=None if max_frames is None else max(8, max_frames // 8),
        canonical_side=canonical,
        workers=loader_workers,
    )
    log(f"frames: train {len(train_frames)}, val {len(val_frames)}")
    model_config = config.model_config()
    ckpt_config = {
        "model": model_config,
        "cube_m": config.cube_m,
        "kind": config.kind,
        "canonical_side": config.canonical_side,
    }
    if config.kind != "localizer" and config.localizer:
        # How the training crops were centred: the estimator's default pipeline.
        ckpt_config["crop"] = {
            "detector": config.detector,
            "localizer": config.localizer,
            "refine_iterations": config.refine_iterations,
        }
    flags = {"rotation": config.rotation, "scale": config.scale, "translation": config.translation}

    def cached_centers(frames: FrameSet, split: str, checkpoint: str | None) -> np.ndarray:
        # Localizing every frame takes minutes on a CPU: a resumed run reads them back.
        path = out / f"centers_{split}.npy"
        if path.is_file():
            centers = np.load(path)
            if centers.shape == (len(frames), 3):
                return centers
        centers, _ = localizer_centers(
            frames,
            checkpoint,
            config.refine_iterations,
            workers=loader_workers,
            device=device,
            detector=config.detector,
        )
        np.save(path, centers)
        return centers

    if config.kind == "localizer":
        centers = cached_centers(train_frames, "train", None)
        val_centers = cached_centers(val_frames, "val", None)
        target = "localizer"
    elif config.localizer:
        centers = cached_centers(train_frames, "train", config.localizer)
        val_centers = cached_centers(val_frames, "val", config.localizer)
        target = "pose"
    else:
        centers = val_centers = None
        target = "pose"
    train_set = CropDataset(
        train_frames,
        centers,
        target=target,
        cube_m=config.cube_m,
        size=config.size,
        offset_sigma_m=config.offset_sigma_m,
        seed=config.seed,
        # The localizer also starts near the MCP half of the time, so it can be iterated.
        alt_centers=train_frames.keypoints_cam[:, MIDDLE_MCP] if target == "localizer" else None,
        **flags,
    )
    val_set = CropDataset(
        val_frames, val_centers, target=target, cube_m=config.cube_m, size=config.size
    )

    model = build_model(model_config).to(device)
    pca = None
    if config.kind != "localizer":
        poses = _augmented_poses(train_frames, config)
        pca = fit_pca(poses, max(config.prior_dim, 1))
        np.savez(out / "pca.npz", **pca)
        prior = [m for m in model.modules() if isinstance(m, PriorLayer)]
        if prior:
            prior[0].init_from_pca(pca["mean"], pca["components"][: config.prior_dim])
    last = out / "last.pt"
    if config.init is not None and not last.is_file():
        _load_init(model, config, ckpt_config, log)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    steps_per_epoch = math.ceil(len(train_set) / config.batch_size)
    total_steps = max(1, steps_per_epoch * config.epochs)

    def lr_at(step: int) -> float:  # cosine from lr to lr / 10
        return config.lr * (
            0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min(step, total_steps) / total_steps))
        )

    start_epoch, best, history, elapsed = 0, math.inf, [], 0.0
    if last.is_file():
        state = load_resume_state(last, model, optimizer, device)
        start_epoch, best = state["epoch"], state["best_val_mm"]
        history, elapsed = state["history"], state["elapsed_s"]
        log(f"resuming {out} after epoch {start_epoch}")
    loss_fn = torch.nn.HuberLoss(delta=config.huber_delta)
    bone_a, bone_b = (torch.as_tensor(v, device=device) for v in zip(*BONE_PAIRS, strict=True))
    use_amp = bool(amp) and device.startswith("cuda")
    for epoch in range(start_epoch, config.epochs):
        t0 = time.perf_counter()
        model.train()
        train_set.epoch = epoch
        order = torch.Generator().manual_seed(config.seed * 1000 + epoch)
        loader = DataLoader(
            train_set,
            batch_size=config.batch_size,
            shuffle=True,
            generator=order,
            drop_last=False,
            num_workers=loader_workers,
            pin_memory=device.startswith("cuda"),
            prefetch_factor=4 if loader_workers else None,
        )
        total, count, wait_s = 0.0, 0, 0.0
        bar = tqdm(
            loader,
            desc=f"{config.kind} epoch {epoch + 1}/{config.epochs}",
            disable=not progress,
            leave=False,
        )
        t_data = time.perf_counter()
        for step, (x, y) in enumerate(bar):
            wait_s += time.perf_counter() - t_data
            for group in optimizer.param_groups:
                group["lr"] = lr_at(epoch * steps_per_epoch + step)
            x, y = x.to(device, non_blocking=True), y.to(device, non_blocking=True)
            with torch.autocast("cuda", dtype=torch.bfloat16) if use_amp else nullcontext():
                pred = model(x)
            loss = loss_fn(pred.float(), y)
            if config.bone_loss:
                loss = loss + config.bone_loss * bone_length_error(pred.float(), y, bone_a, bone_b)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += loss.item() * len(x)
            count += len(x)
            bar.set_postfix(loss=f"{total / count:.5f}")
            t_data = time.perf_counter()
        bar.close()
        entry: dict[str, Any] = {
            "epoch": epoch + 1,
            "train_loss": total / max(count, 1),
            # Time the GPU/CPU waited for crops: large means more --loader-workers.
            "data_wait_s": round(wait_s, 3),
        }
        precise_bn(model, train_set, config.batch_size, device, seed=config.seed * 1000 + epoch)
        if (epoch + 1) % val_every == 0 or epoch + 1 == config.epochs:
            val = _evaluate(model, val_set, config.batch_size, device)
            entry["val_mean_error_mm"] = val["mean_error_mm"]
            if val["mean_error_mm"] < best:
                best = val["mean_error_mm"]
                save_checkpoint(out / "best.pt", {"model": model.state_dict()}, ckpt_config)
        elapsed += time.perf_counter() - t0
        entry["elapsed_s"] = elapsed
        history.append(entry)
        save_resume_state(
            last, model, optimizer, epoch=epoch + 1, best_val_mm=best, history=history,
            elapsed_s=elapsed, config=ckpt_config,
        )  # fmt: skip
        log(json.dumps(entry))  # after the checkpoint: a run killed from here loses nothing
    metrics = {
        "kind": config.kind,
        "config": dataclasses.asdict(config),
        "train_frames": len(train_frames),
        "val_frames": len(val_frames),
        "epochs_done": len(history),
        "best_val_mean_error_mm": best,
        "train_time_s": elapsed,
        "device": device,
        "amp_bf16": use_amp,
        "torch_threads": torch.get_num_threads(),
        "history": history,
    }
    if pca is not None:
        metrics["pca_explained_variance"] = [float(v) for v in pca["explained"]]
        metrics["pca_cumulative"] = [float(v) for v in np.cumsum(pca["explained"])]
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    if loader_workers:
        cv2.setNumThreads(opencv_threads)
    return metrics
