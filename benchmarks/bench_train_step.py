"""Training steps per second of the pose networks, on synthetic batches (no data pipeline).

One training step of ``handsim train`` (forward, Huber loss, backward, Adam) on random
128 x 128 crops, for DeepPrior++ at several widths and batch sizes, on one device. On CUDA the
forward pass runs in bfloat16 (``--amp``, as ``handsim train --amp``) with cuDNN's autotuner and
TF32 on, as in training. It separates the network's cost from the data pipeline's: an epoch of
N frames cannot take less than N / (samples/s) seconds, whatever the loader workers do.

Each configuration runs ``--warmup`` steps, then ``--steps`` timed steps (synchronised before
and after on CUDA). Figures are samples per second; the ratios between widths come from this
one run.

``--profile N`` also prints the N most expensive operators of a few steps of each
configuration (``torch.profiler``; device time on CUDA), to find where a step's time goes.

Usage: ``python benchmarks/bench_train_step.py [--device cuda] [--widths 0.25 1]
[--batches 128 512] [--steps 30] [--profile 15]``. Writes
``benchmarks/results/bench_train_step.json``.

Measured on one NVIDIA H200 (2026-11-28, torch 2.11.0+cu130, bf16): width 1 at 9 354 / 10 483
samples/s (batch 128 / 512), width 0.25 at 10 783 / 14 732.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path


def step_rate(
    width: float, batch: int, device: str, steps: int, warmup: int, profile: int = 0
) -> dict:
    """Samples/s of one configuration (and its top ``profile`` operators, printed)."""
    import torch

    from handsim.estimators.deepprior.models import build_model

    config = {"arch": "resnet", "size": 128, "fc": 1024, "dropout": 0.3, "prior_dim": 30}
    model = build_model({**config, "width": width}).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3, weight_decay=1e-4)
    loss_fn = torch.nn.HuberLoss(delta=0.05)
    x = torch.randn(batch, 1, 128, 128, device=device)
    y = torch.randn(batch, 63, device=device) * 0.1
    cuda = device.startswith("cuda")

    def sync() -> None:
        if cuda:
            torch.cuda.synchronize()

    def step() -> None:
        with torch.autocast("cuda", dtype=torch.bfloat16, enabled=cuda):
            pred = model(x)
        loss = loss_fn(pred.float(), y)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        loss.item()  # as handsim train does each step

    for i in range(warmup + steps):
        if i == warmup:
            sync()
            t0 = time.perf_counter()
        step()
    sync()
    dt = (time.perf_counter() - t0) / steps
    if profile:
        from torch.profiler import ProfilerActivity
        from torch.profiler import profile as torch_profile

        activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])
        with torch_profile(activities=activities) as prof:
            for _ in range(5):
                step()
            sync()
        key = "cuda_time_total" if cuda else "cpu_time_total"
        print(prof.key_averages().table(sort_by=key, row_limit=profile), flush=True)
    return {"width": width, "batch": batch, "ms_per_step": dt * 1e3, "samples_per_s": batch / dt}


def main() -> None:
    """Time every configuration and write the JSON."""
    import torch

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--widths", type=float, nargs="+", default=[0.25, 1.0])
    parser.add_argument("--batches", type=int, nargs="+", default=[128, 512])
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=10)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--profile", type=int, default=0, help="print the top N operators")
    default_out = Path("benchmarks/results/bench_train_step.json")
    parser.add_argument("--out", type=Path, default=default_out)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if args.device.startswith("cuda"):
        torch.backends.cudnn.benchmark = True
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True
        name = torch.cuda.get_device_name(args.device)
    else:
        name = platform.processor() or platform.machine()
    rows = []
    for width in args.widths:
        for batch in args.batches:
            row = step_rate(width, batch, args.device, args.steps, args.warmup, args.profile)
            rows.append(row)
            print(
                f"width {width:g}, batch {batch}: {row['ms_per_step']:.2f} ms/step, "
                f"{row['samples_per_s']:.0f} samples/s",
                flush=True,
            )
    base = rows[0]["samples_per_s"]
    for row in rows:
        row["ratio_to_first"] = row["samples_per_s"] / base
    result = {"device": args.device, "device_name": name, "torch": torch.__version__, "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"written: {args.out}")


if __name__ == "__main__":
    main()
