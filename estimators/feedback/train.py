"""Training of the feedback loop's networks (``handsim train synthesizer|updater``).

Both runs follow ``handsim train``'s rules (:mod:`handsim.estimators.deepprior.train`): the run
folder holds ``run.json`` (the config; another config is refused), ``last.pt`` after every epoch
(model, optimizer, epoch, history, torch's random state, and for the updater its pool of
starting poses) and ``best.pt`` when validation improves, each with a JSON config beside it,
read with ``weights_only=True``; the same command again resumes after the last finished epoch.

**Synthesizer** (:func:`train_synthesizer`): the learned synthesizer maps the normalized true
pose of a frame to its depth crop (at the middle MCP, with DeepPrior's online augmentation:
the labels follow the image exactly); the loss is the mean squared difference of the crops.
Validation reports the median and mean pixel error in mm (all pixels, as in the thesis, and
the pixels where either crop shows something).

**Updater** (:func:`train_updater`): the loss of a starting pose ``P'`` of an image ``D`` with
true pose ``P`` is ``max(0, |P'' - P| - lambda |P' - P|)`` with ``P'' = P' + updater(D,
synth(P'))`` (normalized poses, ``lambda = 0.6``): an update must bring the pose at least
``1 - lambda`` of the way closer. Each image starts with a pool of starting poses: the truth
(the update must be zero; ``truth_starts=False`` leaves it out), the predictor's output, and
Gaussian perturbations of both; every
second epoch, the updater's own outputs ``P''`` of a sample of the pool are added, with poses
drawn from the current error distribution (a Gaussian fitted to ``P'' - P``). Each pool entry's
synthesized crop is made once, when it is added (the synthesizer is fixed).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from handsim.errors import HandSimError

from ..deepprior.checkpoint import save_checkpoint, save_resume_state
from ..deepprior.data import CropDataset, FrameSet, load_frames
from ..deepprior.preprocess import CUBE_M, MIDDLE_MCP, crop_depth, crop_matrix, normalize_keypoints
from ..deepprior.train import open_run

__all__ = [
    "SYNTHESIZERS",
    "updater_optimizer",
    "FeedbackTrainConfig",
    "InvalidFeedbackConfig",
    "feedback_loss",
    "frame_sides",
    "train_synthesizer",
    "train_updater",
]

SYNTHESIZERS = ("renderer", "learned")
"""Synthesizers of the updater's training and of the estimator."""


class InvalidFeedbackConfig(HandSimError, ValueError):
    """A feedback training option is invalid, or a run folder holds a different run."""


@dataclasses.dataclass(frozen=True)
class FeedbackTrainConfig:
    """One training run of the synthesizer or the updater (``run.json``; resume needs the same).

    Attributes:
        kind: ``synthesizer`` or ``updater``.
        epochs: training epochs.
        batch_size: batch size.
        lr: Adam learning rate (cosine decay to a tenth).
        weight_decay: Adam weight decay.
        cube_m: cube edge, metres.
        size: crop side, pixels.
        fc: fully connected units.
        filters: convolution filters (see :mod:`handsim.estimators.feedback.models`).
        lam: the loss's lambda (updater).
        synthesizer: ``renderer`` or ``learned`` (updater).
        synthesizer_checkpoint: the learned synthesizer's run folder or ``.pt`` (with
            ``synthesizer=learned``).
        predictor: DeepPrior checkpoint whose outputs are starting poses (a shipped name or
            a path), or ``None`` for the truth and its perturbations only (updater).
        perturb_sigma_m: standard deviation of the Gaussian perturbations, per coordinate,
            metres (updater).
        perturbations: perturbed copies of each of the truth and the prediction (updater).
        iterations: most updates applied in validation (updater); the number (0 to this) with
            the lowest validation error is saved with ``best.pt``, the estimator's default.
        offset_sigma_m: standard deviation of the crop centre's offset from the middle MCP,
            metres (one draw per frame; with ``localizer=None`` and for the synthesizer).
        localizer: the updater's crop centres: this localizer's refined centres (a shipped
            name or a path), as the estimator crops at inference; ``None``: the middle MCP
            plus the offset above.
        truth_starts: the truth itself is a starting pose of every image (the paper's pool;
            its update must be zero). Its perturbations are starting poses either way.
        canonical_side: the updater works in the right-hand frame (left frames mirrored, as
            DeepPrior++ with ``canonical_side``; the renderer draws right hands).
        max_frames: use at most this many training frames (0: all).
        max_val_frames: validate the updater on at most this many frames, evenly spaced over
            the validation split (0: all).
        seed: random seed.
    """

    kind: str = "updater"
    epochs: int = 10
    batch_size: int = 64
    lr: float = 1e-3
    weight_decay: float = 1e-4
    cube_m: float = CUBE_M
    size: int = 128
    fc: int = 1024
    filters: int = 32
    lam: float = 0.6
    synthesizer: str = "renderer"
    synthesizer_checkpoint: str | None = None
    predictor: str | None = "deepprior++"
    perturb_sigma_m: float = 0.01
    perturbations: int = 1
    iterations: int = 2
    offset_sigma_m: float = 0.005
    localizer: str | None = "localizer"
    canonical_side: bool = True
    truth_starts: bool = True
    max_frames: int = 0
    max_val_frames: int = 0
    seed: int = 0

    def model_config(self) -> dict[str, Any]:
        """The config of :func:`~handsim.estimators.feedback.models.build_feedback_model`."""
        return {"arch": self.kind, "size": self.size, "fc": self.fc, "filters": self.filters}

    def check(self) -> None:
        """Raise :class:`InvalidFeedbackConfig` for an invalid option (listing what is valid)."""
        if self.kind not in ("synthesizer", "updater"):
            raise InvalidFeedbackConfig(
                f"kind must be synthesizer or updater; received {self.kind!r}"
            )
        if self.synthesizer not in SYNTHESIZERS:
            raise InvalidFeedbackConfig(
                f"synthesizer must be one of {', '.join(SYNTHESIZERS)}; received "
                f"{self.synthesizer!r}"
            )
        if self.kind == "updater" and self.synthesizer == "learned":
            if not self.synthesizer_checkpoint:
                raise InvalidFeedbackConfig(
                    "synthesizer=learned needs synthesizer_checkpoint (the run folder of "
                    "`handsim train synthesizer`)"
                )
        if self.size % 16 or not 16 <= self.size <= 512:
            raise InvalidFeedbackConfig(
                f"size must be a multiple of 16 in [16, 512] pixels; received {self.size}"
            )
        if self.kind == "synthesizer" and (self.size & (self.size - 1)):
            raise InvalidFeedbackConfig(
                f"the synthesizer's size must be a power of two (8 * 2**k); received {self.size}"
            )
        ranges = {
            "lr": (self.lr, 0.0, 1.0),
            "weight_decay": (self.weight_decay, 0.0, 1.0),
            "cube_m": (self.cube_m, 1e-3, 1.0),
            "lam": (self.lam, 0.0, 1.0),
            "perturb_sigma_m": (self.perturb_sigma_m, 0.0, 0.5),
            "offset_sigma_m": (self.offset_sigma_m, 0.0, 0.5),
            "perturbations": (self.perturbations, 0, 100),
            "iterations": (self.iterations, 1, 20),
            "max_val_frames": (self.max_val_frames, 0, 10**9),
        }
        for name, (value, lo, hi) in ranges.items():
            if not lo <= value <= hi:
                raise InvalidFeedbackConfig(f"{name} must be in [{lo}, {hi}]; received {value}")


def feedback_loss(updated: Any, start: Any, truth: Any, lam: float = 0.6) -> Any:
    """``max(0, |P'' - P| - lam |P' - P|)`` per sample (B,), for (B, 63) torch tensors."""
    import torch

    return torch.relu((updated - truth).norm(dim=1) - lam * (start - truth).norm(dim=1))


def frame_sides(
    folders: str | os.PathLike[str] | list[str | os.PathLike[str]],
    split: str = "all",
    *,
    max_frames: int | None = None,
) -> np.ndarray:
    """(N,) bool ``is_left`` of the frames that ``load_frames`` reads, in the same order.

    The sides of :func:`~handsim.estimators.deepprior.data.load_frames`' frames, same arguments.
    """
    from handsim.data.manifest import Manifest
    from handsim.data.shards import ShardReader
    from handsim.data.splits import folder_splits, split_mask

    if isinstance(folders, (str, os.PathLike)):
        folders = [folders]
    parts: list[np.ndarray] = []
    for folder in folders:
        manifest = Manifest.read(folder)
        splits = folder_splits(folder, manifest) if split != "all" else {}
        for record in sorted(manifest.shards.values(), key=lambda s: s.name):
            reader = ShardReader(Path(folder) / record.name)
            keep = split_mask(splits, reader.labels("episode"), split, f"--data {folder}")
            keep &= reader.labels("valid").astype(bool)
            parts.append(reader.labels("is_left")[keep].astype(bool))
            reader.close()
    sides = np.concatenate(parts) if parts else np.zeros(0, bool)
    return sides if max_frames is None else sides[:max_frames]


# Shared run machinery ---------------------------------------------------------------------------


def _subset(frames: FrameSet, idx: np.ndarray) -> FrameSet:
    fields = {f.name: getattr(frames, f.name)[idx] for f in dataclasses.fields(frames)}
    return FrameSet(**fields)


def _frames(data: list, config: FeedbackTrainConfig) -> tuple[FrameSet, FrameSet]:
    """Training and validation frames (left hands mirrored with ``canonical_side``)."""
    max_frames = config.max_frames or None
    canonical = config.kind == "updater" and config.canonical_side
    train = load_frames(data, "train", max_frames=max_frames, canonical_side=canonical)
    val_max = None if max_frames is None else max(8, max_frames // 8)
    val = load_frames(data, "val", max_frames=val_max, canonical_side=canonical)
    if config.kind == "updater" and 0 < config.max_val_frames < len(val):
        # Evenly spaced, so that every folder of --data is validated on.
        val = _subset(val, np.linspace(0, len(val) - 1, config.max_val_frames).round().astype(int))
    return train, val


def _centers(frames: FrameSet, config: FeedbackTrainConfig, salt: int) -> np.ndarray:
    """Crop centres: the middle MCP plus one fixed Gaussian offset per frame."""
    rng = np.random.default_rng([config.seed, salt])
    offset = rng.normal(0.0, config.offset_sigma_m, size=(len(frames), 3))
    return frames.keypoints_cam[:, MIDDLE_MCP] + offset


def _crops(frames: FrameSet, centers: np.ndarray, config: FeedbackTrainConfig) -> np.ndarray:
    return np.stack(
        [
            crop_depth(
                frames.depth(i),
                crop_matrix(centers[i], frames.K[i], config.cube_m, config.size),
                centers[i, 2],
                config.cube_m,
                config.size,
            )
            for i in range(len(frames))
        ]
    )


def _lr_schedule(config: FeedbackTrainConfig, total_steps: int) -> Callable[[int], float]:
    def lr_at(step: int) -> float:  # cosine from lr to lr / 10
        return config.lr * (
            0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min(step, total_steps) / total_steps))
        )

    return lr_at


def _resume(last: Path, model: Any, optimizer: Any, log: Callable) -> dict[str, Any] | None:
    import torch

    if not last.is_file():
        return None
    state = torch.load(last, map_location="cpu", weights_only=True)
    model.load_state_dict(state["model"])
    optimizer.load_state_dict(state["optimizer"])
    torch.set_rng_state(state["torch_rng"])
    log(f"resuming {last.parent} after epoch {int(state['epoch'])}")
    return state


# Synthesizer ------------------------------------------------------------------------------------


def _synth_errors(model: Any, dataset: CropDataset, batch_size: int) -> dict[str, float]:
    import torch

    model.eval()
    all_px, shown = [], []
    with torch.inference_mode():
        for start in range(0, len(dataset), batch_size):
            items = [dataset[i] for i in range(start, min(start + batch_size, len(dataset)))]
            crops = torch.stack([a for a, _ in items])
            pred = model(torch.stack([b for _, b in items]))
            err = (pred - crops).abs() * (dataset.cube_m / 2.0 * 1000.0)
            all_px.append(err.flatten().numpy())
            shown.append(err[(crops < 1) | (pred < 0.99)].numpy())
    a, s = np.concatenate(all_px), np.concatenate(shown)
    return {
        "median_px_error_mm": float(np.median(a)),
        "mean_px_error_mm": float(a.mean()),
        "hand_median_px_error_mm": float(np.median(s)) if len(s) else math.nan,
        "hand_mean_px_error_mm": float(s.mean()) if len(s) else math.nan,
    }


def train_synthesizer(
    data: list[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    config: FeedbackTrainConfig,
    *,
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Train (or resume) the learned synthesizer; returns the metrics (``out/metrics.json``).

    Raises:
        InvalidFeedbackConfig: for bad options or a folder that holds a different run.
    """
    import torch
    from torch.utils.data import DataLoader
    from tqdm import tqdm

    from .models import build_feedback_model

    config.check()
    if config.kind != "synthesizer":
        raise InvalidFeedbackConfig(
            f"train_synthesizer needs kind='synthesizer'; got {config.kind!r}"
        )
    out = Path(out)
    open_run(out, config, data, InvalidFeedbackConfig)
    torch.manual_seed(config.seed)
    train_frames, val_frames = _frames(data, config)
    log(f"frames: train {len(train_frames)}, val {len(val_frames)}")
    flags = {"rotation": True, "scale": False, "translation": True}
    train_set = CropDataset(
        train_frames, cube_m=config.cube_m, size=config.size, seed=config.seed,
        offset_sigma_m=config.offset_sigma_m, **flags,
    )  # fmt: skip
    val_set = CropDataset(val_frames, cube_m=config.cube_m, size=config.size)
    model = build_feedback_model(config.model_config())
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    steps = math.ceil(len(train_set) / config.batch_size)
    lr_at = _lr_schedule(config, max(1, steps * config.epochs))
    ckpt_config = {"model": config.model_config(), "cube_m": config.cube_m, "kind": "synthesizer"}
    last = out / "last.pt"
    start_epoch, best, history, elapsed = 0, math.inf, [], 0.0
    state = _resume(last, model, optimizer, log)
    if state is not None:
        start_epoch, best = int(state["epoch"]), float(state["best_val_mm"])
        history, elapsed = json.loads(str(state["history"])), float(state["elapsed_s"])
    for epoch in range(start_epoch, config.epochs):
        t0 = time.perf_counter()
        model.train()
        train_set.epoch = epoch
        order = torch.Generator().manual_seed(config.seed * 1000 + epoch)
        loader = DataLoader(train_set, batch_size=config.batch_size, shuffle=True, generator=order)
        total, count = 0.0, 0
        bar = tqdm(loader, desc=f"synthesizer epoch {epoch + 1}/{config.epochs}",
                   disable=not progress, leave=False)  # fmt: skip
        for step, (crops, poses) in enumerate(bar):
            for group in optimizer.param_groups:
                group["lr"] = lr_at(epoch * steps + step)
            loss = torch.nn.functional.mse_loss(model(poses), crops)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += loss.item() * len(crops)
            count += len(crops)
            bar.set_postfix(loss=f"{total / count:.5f}")
        bar.close()
        val = _synth_errors(model, val_set, config.batch_size)
        entry = {"epoch": epoch + 1, "train_loss": total / max(count, 1), **val}
        if val["mean_px_error_mm"] < best:
            best = val["mean_px_error_mm"]
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
        "kind": "synthesizer", "config": dataclasses.asdict(config),
        "train_frames": len(train_frames), "val_frames": len(val_frames),
        "epochs_done": len(history), "best_val_mean_px_error_mm": best,
        "train_time_s": elapsed, "history": history,
    }  # fmt: skip
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    return metrics


# Updater ----------------------------------------------------------------------------------------


@dataclasses.dataclass
class _Images:
    """The updater's images: input crops, true poses and what the synthesizer needs."""

    crops: np.ndarray  # (N, S, S) float32
    truth: np.ndarray  # (N, 63) float32, normalized
    centers: np.ndarray  # (N, 3) metres
    K: np.ndarray  # (N, 3, 3)
    lengths: np.ndarray  # (N,) metres
    left: np.ndarray  # (N,) bool


def _images(frames: FrameSet, centers: np.ndarray, config: FeedbackTrainConfig) -> _Images:
    truth = normalize_keypoints(frames.keypoints_cam, centers, config.cube_m).reshape(-1, 63)
    # As at inference the hand's size is unknown (fitted to each pose), and a mirrored left
    # hand is drawn as the right hand it mirrors.
    return _Images(
        _crops(frames, centers, config), truth.astype(np.float32), centers,
        frames.K, np.full(len(frames), np.nan), frames.is_left & ~frames.mirrored,
    )  # fmt: skip


def _updater_centers(
    frames: FrameSet, config: FeedbackTrainConfig, out: Path, split: str, salt: int
) -> np.ndarray:
    """The predictor's crop centres (cached in the run folder), or the offset middle MCP.

    Centred as the predictor's own training crops were (its checkpoint's ``crop``: the
    detector's centre refined by ``localizer`` that many times), which is where
    :class:`~.estimator.FeedbackEstimator` crops at inference; a predictor without the record
    (or none) was trained at the plane detector's centres refined three times.
    """
    from ..deepprior.checkpoint import load_checkpoint
    from ..deepprior.train import localizer_centers

    if config.localizer is None:
        return _centers(frames, config, salt)
    path = out / f"centers_{split}.npy"
    if path.is_file():
        centers = np.load(path)
        if centers.shape == (len(frames), 3):
            return centers
    crop = (load_checkpoint(config.predictor)[1].get("crop") if config.predictor else None) or {}
    # A frame without a hand blob gets the true middle MCP (the estimator would miss it).
    centers, _ = localizer_centers(
        frames,
        config.localizer,
        int(crop.get("refine_iterations", 3)),
        detector=crop.get("detector", "plane"),
    )
    np.save(path, centers)
    return centers


def _pool_crops(
    out: Path,
    synth: Any,
    images: _Images,
    idx: np.ndarray,
    start: np.ndarray,
    have: np.ndarray | None = None,
) -> np.ndarray:
    """The synthesized crops of pool entries ``idx``/``start``: cached chunks, then the rest.

    Chunk files ``pool_OFFSET.npy`` hold the crops of the entries from OFFSET on; a resumed run
    reads them instead of rendering its pool again (minutes on a CPU). A chunk written by a run
    killed before its checkpoint starts at the pool's end and is rendered over. ``have``: the
    crops of the first entries, already in memory.
    """
    parts = [] if have is None else [have]
    done = sum(len(p) for p in parts)
    while done < len(idx) and (out / f"pool_{done:08d}.npy").is_file():
        part = np.load(out / f"pool_{done:08d}.npy")
        parts.append(part[: len(idx) - done])
        done += len(parts[-1])
    if done < len(idx):
        new = _synthesize(synth, images, idx[done:], start[done:])
        np.save(out / f"pool_{done:08d}.npy", new)
        parts.append(new)
    return np.concatenate(parts)


def _predict(predictor: Any, crops: np.ndarray, batch_size: int) -> np.ndarray:
    import torch

    out = []
    with torch.inference_mode():
        for s in range(0, len(crops), batch_size):
            out.append(predictor(torch.from_numpy(crops[s : s + batch_size, None])).float().numpy())
    return np.concatenate(out).astype(np.float32)


def _synthesize(synth: Any, images: _Images, idx: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(M, S, S) float16 synthesized crops of ``poses`` on images ``idx``, in chunks of 64."""
    out = np.empty((len(idx), images.crops.shape[1], images.crops.shape[2]), np.float16)
    for s in range(0, len(idx), 64):
        i = idx[s : s + 64]
        crops, _ = synth(
            poses[s : s + 64], images.centers[i], images.K[i], images.lengths[i], images.left[i]
        )
        out[s : s + 64] = crops
    return out


def _run_updates(
    model: Any, synth: Any, images: _Images, starts: np.ndarray, iterations: int, batch: int
) -> list[np.ndarray]:
    """Poses after 0, 1, ..., ``iterations`` updates from ``starts`` (each (N, 63))."""
    import torch

    model.eval()
    poses = [starts.astype(np.float32)]
    idx = np.arange(len(starts))
    for _ in range(iterations):
        current = poses[-1]
        synthesized = _synthesize(synth, images, idx, current).astype(np.float32)
        nxt = np.empty_like(current)
        with torch.inference_mode():
            for s in range(0, len(idx), batch):
                d = torch.from_numpy(images.crops[s : s + batch, None])
                y = torch.from_numpy(synthesized[s : s + batch, None])
                nxt[s : s + batch] = current[s : s + batch] + model(d, y).numpy()
        poses.append(nxt)
    return poses


def _pose_error_mm(poses: np.ndarray, truth: np.ndarray, cube_m: float) -> float:
    d = np.linalg.norm((poses - truth).reshape(len(poses), 21, 3), axis=-1)
    return float(d.mean() * cube_m / 2.0 * 1000.0)


def updater_optimizer(model: Any, config: FeedbackTrainConfig) -> Any:
    """AdamW: weight decay decoupled from Adam's scaling.

    The updater's last layer starts at zero, so at first no gradient reaches the layers below
    it; with Adam's L2 decay their only gradient is the decay term, which Adam scales up to
    full ``lr`` steps: every weight below the last layer shrank towards zero within an epoch.
    """
    import torch

    return torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)


def train_updater(
    data: list[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    config: FeedbackTrainConfig,
    *,
    device: str = "cpu",
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Train (or resume) the updater; returns the metrics (``out/metrics.json``).

    ``metrics.json`` has the validation error (mean over joints, mm) after each iteration:
    ``val_error_mm_per_iteration[0]`` is the starting poses' (the predictor's) error. ``best.pt``
    is the epoch and number of updates with the lowest validation error (its JSON's
    ``iterations``).

    Raises:
        InvalidFeedbackConfig: for bad options or a folder that holds a different run.
        InvalidCheckpoint: for a predictor or synthesizer checkpoint that cannot be loaded.
    """
    import torch
    from tqdm import tqdm

    from ..deepprior.checkpoint import load_model
    from .models import build_feedback_model
    from .synth import make_synthesizer

    config.check()
    if config.kind != "updater":
        raise InvalidFeedbackConfig(f"train_updater needs kind='updater'; got {config.kind!r}")
    out = Path(out)
    open_run(out, config, data, InvalidFeedbackConfig)
    torch.manual_seed(config.seed)
    train_frames, val_frames = _frames(data, config)
    log(f"frames: train {len(train_frames)}, val {len(val_frames)}")
    t0 = time.perf_counter()
    train_img = _images(
        train_frames, _updater_centers(train_frames, config, out, "train", 1), config
    )
    val_img = _images(val_frames, _updater_centers(val_frames, config, out, "val", 2), config)
    log(f"crop centres in {time.perf_counter() - t0:.1f} s")
    synth = make_synthesizer(
        config.synthesizer, config.synthesizer_checkpoint, cube_m=config.cube_m,
        size=config.size, device=device,
    )  # fmt: skip
    n = len(train_frames)
    sigma = config.perturb_sigma_m / (config.cube_m / 2.0)
    rng = np.random.default_rng([config.seed, 3])
    heads = ["truth"]
    starts_base = [train_img.truth]
    if config.predictor:
        predictor, pconfig = load_model(config.predictor, "cpu")
        if (
            int(pconfig["model"]["size"]) != config.size
            or abs(pconfig["cube_m"] - config.cube_m) > 1e-9
        ):
            raise InvalidFeedbackConfig(
                f"predictor {config.predictor} crops {pconfig['model']['size']} px of a "
                f"{pconfig['cube_m']} m cube; give the updater the same --size and --cube-mm"
            )
        if bool(pconfig.get("canonical_side", False)) != config.canonical_side:
            raise InvalidFeedbackConfig(
                f"predictor {config.predictor} has canonical_side="
                f"{bool(pconfig.get('canonical_side', False))}, the updater "
                f"{config.canonical_side}; the updater must see the predictor's frame"
            )
        starts_base.append(_predict(predictor, train_img.crops, config.batch_size))
        val_starts = _predict(predictor, val_img.crops, config.batch_size)
        heads.append("predictor")
    else:
        val_rng = np.random.default_rng([config.seed, 4])
        val_starts = (val_img.truth + val_rng.normal(0, sigma, val_img.truth.shape)).astype(
            np.float32
        )
    pool_idx = [np.arange(n)] * len(starts_base)
    pool_start = list(starts_base)
    for base in starts_base:
        for _ in range(config.perturbations):
            pool_idx.append(np.arange(n))
            pool_start.append((base + rng.normal(0, sigma, base.shape)).astype(np.float32))
    if not config.truth_starts:  # drop the first block, the truth (its perturbations stay)
        pool_idx, pool_start, heads = pool_idx[1:], pool_start[1:], heads[1:]
    idx_all = np.concatenate(pool_idx)
    start_all = np.concatenate(pool_start).astype(np.float32)

    model = build_feedback_model(config.model_config()).to(device)
    optimizer = updater_optimizer(model, config)
    ckpt_config = {
        "model": config.model_config(), "cube_m": config.cube_m, "kind": "updater",
        "synthesizer": config.synthesizer, "iterations": config.iterations,
        "canonical_side": config.canonical_side,
    }  # fmt: skip
    last = out / "last.pt"
    start_epoch, best, history, elapsed = 0, math.inf, [], 0.0
    state = _resume(last, model, optimizer, log)
    if state is not None:
        start_epoch, best = int(state["epoch"]), float(state["best_val_mm"])
        history, elapsed = json.loads(str(state["history"])), float(state["elapsed_s"])
        idx_all = state["pool_idx"].numpy()
        start_all = state["pool_start"].numpy()
    t0 = time.perf_counter()
    synth_all = _pool_crops(out, synth, train_img, idx_all, start_all)
    log(f"pool: {len(idx_all)} starting poses synthesized in {time.perf_counter() - t0:.1f} s")
    # Steps per epoch grow with the pool; the schedule runs on epochs.
    for epoch in range(start_epoch, config.epochs):
        t0 = time.perf_counter()
        model.train()
        for group in optimizer.param_groups:
            group["lr"] = config.lr * (
                0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * epoch / config.epochs))
            )
        order = torch.randperm(
            len(idx_all), generator=torch.Generator().manual_seed(config.seed * 1000 + epoch)
        ).numpy()
        total, count = 0.0, 0
        bar = tqdm(range(0, len(order), config.batch_size), disable=not progress, leave=False,
                   desc=f"updater epoch {epoch + 1}/{config.epochs}")  # fmt: skip
        for s in bar:
            b = order[s : s + config.batch_size]
            i = idx_all[b]
            d = torch.from_numpy(train_img.crops[i, None]).to(device)
            y = torch.from_numpy(synth_all[b, None].astype(np.float32)).to(device)
            p0 = torch.from_numpy(start_all[b]).to(device)
            truth = torch.from_numpy(train_img.truth[i]).to(device)
            loss = feedback_loss(p0 + model(d, y), p0, truth, config.lam).mean()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += loss.item() * len(b)
            count += len(b)
            bar.set_postfix(loss=f"{total / count:.5f}")
        bar.close()
        entry: dict[str, Any] = {"epoch": epoch + 1, "train_loss": total / max(count, 1)}
        if (epoch + 1) % 2 == 0 and epoch + 1 < config.epochs:
            # The updater's own outputs on a sample of the pool, and poses drawn from its
            # current error distribution, become starting poses.
            grow = np.random.default_rng([config.seed, 5, epoch])
            pick = grow.choice(len(idx_all), size=min(n, len(idx_all)), replace=False)
            i = idx_all[pick]
            sub = _Images(train_img.crops[i], train_img.truth[i], train_img.centers[i],
                          train_img.K[i], train_img.lengths[i], train_img.left[i])  # fmt: skip
            updated = _run_updates(model, synth, sub, start_all[pick], 1, config.batch_size)[1]
            err = updated - train_img.truth[i]
            cov = np.cov(err.T) if len(err) > 2 * err.shape[1] else np.diag(err.var(axis=0))
            drawn_idx = grow.integers(0, n, size=len(pick))
            drawn = train_img.truth[drawn_idx] + grow.multivariate_normal(
                err.mean(axis=0), cov, size=len(pick), method="eigh"
            )
            idx_all = np.concatenate([idx_all, i, drawn_idx])
            start_all = np.concatenate([start_all, updated, drawn]).astype(np.float32)
            synth_all = _pool_crops(out, synth, train_img, idx_all, start_all, synth_all)
            entry["pool"] = int(len(idx_all))
        per_iter = _run_updates(
            model, synth, val_img, val_starts, config.iterations, config.batch_size
        )
        errors = [_pose_error_mm(p, val_img.truth, config.cube_m) for p in per_iter]
        entry["val_error_mm_per_iteration"] = errors
        # The estimator's default number of updates: the best on validation (0 to k).
        chosen = int(np.argmin(errors))
        entry["val_best_iterations"] = chosen
        if errors[chosen] < best:
            best = errors[chosen]
            save_checkpoint(
                out / "best.pt",
                {"model": model.state_dict()},
                {**ckpt_config, "iterations": chosen},
            )
        elapsed += time.perf_counter() - t0
        entry["elapsed_s"] = elapsed
        history.append(entry)
        save_resume_state(
            last, model, optimizer, epoch=epoch + 1, best_val_mm=best, history=history,
            elapsed_s=elapsed, config=ckpt_config,
            extra={
                "pool_idx": torch.from_numpy(idx_all),
                "pool_start": torch.from_numpy(start_all),
            },
        )  # fmt: skip
        log(json.dumps(entry))  # after the checkpoint: a run killed from here loses nothing
    synth.close()
    last_errors = history[-1]["val_error_mm_per_iteration"] if history else []
    metrics = {
        "kind": "updater", "config": dataclasses.asdict(config), "starts": heads,
        "train_frames": n, "val_frames": len(val_frames), "epochs_done": len(history),
        "best_val_mean_error_mm": best, "val_error_mm_per_iteration": last_errors,
        "train_time_s": elapsed, "device": device, "history": history,
    }  # fmt: skip
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    return metrics
