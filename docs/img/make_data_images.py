"""The contact sheet and distribution figures of every preset, for docs/data.md.

Run: ``python docs/img/make_data_images.py [--frames 200] [--workers 2]`` (writes
``docs/img/data_<preset>.png`` and prints one table row per preset). Each preset is made with
``handsim generate --preset P --frames N --seed 0`` and read back with ``handsim dataset info
--plot``, exactly as a user would.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from handsim.data.config import PRESETS
from handsim.data.shards import ShardReader

OUT = Path(__file__).parent


def _handsim(*args: str) -> dict:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    run = subprocess.run(
        [sys.executable, "-m", "handsim.cli", *args, "-q"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    return json.loads(run.stdout)


def main() -> None:
    """Make every preset, write its contact sheet, print its row."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--presets", nargs="*", default=list(PRESETS))
    args = parser.parse_args()
    print(
        "| preset | frames/s | hand-object contact | occlusion median | no visible keypoint "
        "| constant-mean-pose (nyu14) | redraws |"
    )
    print("|---|---|---|---|---|---|---|")
    for preset in args.presets:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp) / preset
            start = time.perf_counter()
            made = _handsim(
                "generate", "--preset", preset, "--frames", str(args.frames), "--seed", "0",
                "--workers", str(args.workers), "--out", str(folder),
            )  # fmt: skip
            rate = args.frames / (time.perf_counter() - start)
            info = _handsim("dataset", "info", str(folder), "--plot")
            sheet = cv2.imread(str(folder / "contact_sheet.png"))
            cv2.imwrite(str(OUT / f"data_{preset}.png"), sheet)
            ratios, none_visible = [], []
            for path in sorted(folder.glob("shard-*.h5")):
                reader = ShardReader(path)
                ratios.append(np.nan_to_num(reader.labels("hand_occlusion_ratio")))
                none_visible.append(reader.labels("visible").sum(axis=1) == 0)
                reader.close()
            dist = info["distribution"]
            print(
                f"| `{preset}` | {rate:.1f} | {100 * dist['contact_rate']:.0f} % | "
                f"{np.median(np.concatenate(ratios)):.2f} | "
                f"{100 * np.mean(np.concatenate(none_visible)):.1f} % | "
                f"{dist['constant_pose_error_mm']:.1f} mm | {made.get('redraws', {})} |"
            )
            shutil.rmtree(folder)


if __name__ == "__main__":
    main()
