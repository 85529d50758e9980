"""Validation error of pose checkpoints with their stored batch-norm statistics and recomputed.

Run: ``python benchmarks/deepprior_bn_check.py RUN_DIR CKPT [CKPT ...] [--every 8]``.

``RUN_DIR`` is a ``handsim train`` run folder: its ``run.json`` names the datasets and its
``centers_val.npy`` holds the validation crop centres (the localizer's). Each checkpoint (a
path, a run folder or a shipped name such as ``deepprior++``) is evaluated on every
``--every``-th validation frame twice: with the statistics it stores, and after
:func:`handsim.estimators.deepprior.train.precise_bn` over 4000 of the run's training frames
(augmented as in the run, cropped at the true middle MCP). A large
difference means the stored statistics do not fit the weights.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from handsim.estimators.deepprior.checkpoint import load_model  # noqa: E402
from handsim.estimators.deepprior.data import CropDataset, load_frames  # noqa: E402
from handsim.estimators.deepprior.train import _evaluate, precise_bn  # noqa: E402


class _Every(torch.utils.data.Dataset):
    """Every ``step``-th item of a dataset (its ``cube_m`` kept for the error in mm)."""

    def __init__(self, dataset: CropDataset, step: int) -> None:
        self.dataset, self.cube_m = dataset, dataset.cube_m
        self.indices = range(0, len(dataset), step)

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, torch.Tensor]:
        return self.dataset[self.indices[i]]


def main() -> None:
    """Evaluate each checkpoint with its stored and its recomputed batch-norm statistics."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("run", type=Path, help="a handsim train run folder")
    parser.add_argument("checkpoints", nargs="+", help="checkpoints to evaluate")
    parser.add_argument("--every", type=int, default=8, help="every N-th validation frame")
    parser.add_argument("--batch-size", type=int, default=64)
    args = parser.parse_args()
    run = json.loads((args.run / "run.json").read_text())
    config = run["config"]
    val_frames = load_frames(run["data"], "val")
    centers = np.load(args.run / "centers_val.npy")
    val = _Every(
        CropDataset(
            val_frames, centers, target="pose", cube_m=config["cube_m"], size=config["size"]
        ),
        args.every,
    )
    train_frames = load_frames(run["data"], "train", max_frames=4000)
    train = CropDataset(
        train_frames, None, target="pose", cube_m=config["cube_m"], size=config["size"],
        seed=config["seed"], rotation=config["rotation"], scale=config["scale"],
        translation=config["translation"], offset_sigma_m=config["offset_sigma_m"],
    )  # fmt: skip
    for name in args.checkpoints:
        model, _ = load_model(name)
        stored = _evaluate(model, val, args.batch_size, "cpu")["mean_error_mm"]
        precise_bn(model, train, args.batch_size)
        recomputed = _evaluate(model, val, args.batch_size, "cpu")["mean_error_mm"]
        print(
            f"{name}: {stored:.1f} mm with its stored statistics, {recomputed:.1f} mm recomputed "
            f"({len(val)} validation frames)",
            flush=True,
        )


if __name__ == "__main__":
    main()
