"""Does the updater learn a correction? Loss and architecture controls on a run's cached pool.

    python benchmarks/feedback_learning_check.py RUN_DIR DATA_DIR [DATA_DIR ...] \
        --loss hinge|mse [--bn] [--no-truth] [--steps 1000] [--lr 1e-3]

Reads a ``handsim train updater`` run folder (its crop centres, its first pool chunk of
rendered starting poses and the pool in its ``last.pt``) and trains a fresh updater of the
run's size on the same batches (seed 0) with one thing changed at a time: the loss (the
paper's hinge, or the squared distance to the truth) and batch normalization after each
convolution (``--bn``), and whether the truth's starting poses (where the update must be zero)
are trained on (``--no-truth``). Every 100 steps it prints the mean joint error of the predictor's
starting poses of the last 500 training frames before and after one update; those 500
predictor starts are never trained on (the same frames' other starts are).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from handsim.estimators.feedback.models import build_feedback_model
from handsim.estimators.feedback.train import (
    FeedbackTrainConfig,
    _frames,
    _images,
    _updater_centers,
    feedback_loss,
)


def main() -> int:
    """Train the control updater and print its held-out error every 100 steps."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("data", nargs="+")
    parser.add_argument("--loss", choices=("hinge", "mse"), required=True)
    parser.add_argument("--bn", action="store_true", help="batch norm after each convolution")
    parser.add_argument(
        "--no-truth", action="store_true", help="leave the truth's starts (zero update) out"
    )
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--save", type=Path, default=None, help="write the updater here (.pt)")
    parser.add_argument("--lr", type=float, default=1e-3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    run = FeedbackTrainConfig(**json.loads((args.run / "run.json").read_text())["config"])
    train, _ = _frames(args.data, run)
    images = _images(train, _updater_centers(train, run, args.run, "train", 1), run)
    state = torch.load(args.run / "last.pt", weights_only=True)
    synth = np.load(args.run / "pool_00000000.npy", mmap_mode="r")
    n_frames = len(train)
    idx = state["pool_idx"].numpy()[: len(synth)]
    start = state["pool_start"].numpy()[: len(synth)]
    model = build_feedback_model(run.model_config())
    if args.bn:
        layers: list[nn.Module] = []
        for m in model.path:
            layers.append(m)
            if isinstance(m, nn.Conv2d):
                layers.append(nn.BatchNorm2d(m.out_channels))
        model.path = nn.Sequential(*layers)
    optimizer = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=run.weight_decay)
    # The pool's second block is the predictor's starts; its last 500 are held out.
    held = np.arange(2 * n_frames - 500, 2 * n_frames)
    trainable = np.setdiff1d(np.arange(len(idx)), held)
    if args.no_truth:  # the pool's first block: the truth of every frame
        trainable = trainable[trainable >= n_frames]
    rng = np.random.default_rng(0)

    def batch(b: np.ndarray) -> tuple[torch.Tensor, ...]:
        i = idx[b]
        return (
            torch.from_numpy(images.crops[i, None]),
            torch.from_numpy(synth[b, None].astype(np.float32)),
            torch.from_numpy(start[b]),
            torch.from_numpy(images.truth[i]),
        )

    def error_mm(p: torch.Tensor, t: torch.Tensor) -> float:
        return float((p - t).reshape(-1, 21, 3).norm(dim=-1).mean() * run.cube_m / 2 * 1000)

    t0 = time.time()
    for step in range(args.steps):
        model.train()
        d, y, p0, t = batch(rng.choice(trainable, run.batch_size, replace=False))
        u = model(d, y)
        if args.loss == "hinge":
            loss = feedback_loss(p0 + u, p0, t, run.lam).mean()
        else:
            loss = (p0 + u - t).square().sum(1).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if step % 100 == 0 or step == args.steps - 1:
            model.eval()
            with torch.no_grad():
                d, y, p0, t = batch(held)
                u = model(d, y)
            print(
                f"step {step}: held-out predictor starts {error_mm(p0, t):.2f} -> "
                f"{error_mm(p0 + u, t):.2f} mm, mean |update| {float(u.norm(dim=1).mean()):.4f} "
                f"(normalized), {time.time() - t0:.0f} s",
                flush=True,
            )
    if args.save is not None:
        if args.bn:
            raise SystemExit("--save: the estimator's updater has no batch norm; drop --bn")
        from handsim.estimators.deepprior.checkpoint import save_checkpoint

        config = {"model": run.model_config(), "cube_m": run.cube_m, "kind": "updater",
                  "synthesizer": run.synthesizer, "iterations": 1,
                  "canonical_side": run.canonical_side}  # fmt: skip
        save_checkpoint(args.save, {"model": model.state_dict()}, config)
    return 0


if __name__ == "__main__":
    sys.exit(main())
