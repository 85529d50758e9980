"""Import time of ``handsim`` and ``handsim.envs`` against ``import mujoco``, in one run.

Each import is timed in a fresh interpreter (``time.perf_counter`` around the ``import``
statement only, so interpreter start-up is not counted). The runs are interleaved (mujoco,
handsim, handsim.envs, numpy, then again) ``--runs`` times, and the median of each is reported
with its ratio to ``import mujoco`` (MuJoCo and NumPy are the floor: handsim needs both). The
children write and use bytecode caches (``PYTHONDONTWRITEBYTECODE`` is removed from their
environment, and one untimed round comes first), as an installed package does: without
``.pyc`` files every handsim module is compiled from source on each import.

Each handsim import is also checked for the modules that load where they are used (meshes,
KD-trees, compiled kernels, image operations), never on import: the names found are listed
under ``<module>_heavy_modules`` (an empty list is the goal).

Usage: ``python benchmarks/bench_import.py [--runs 9] [--out FILE.json]``; writes
``benchmarks/results/bench_import.json`` by default.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

_MODULES = ("mujoco", "handsim", "handsim.envs", "numpy")
_HEAVY = ("torch", "trimesh", "networkx", "scipy.spatial", "scipy.sparse", "numba", "cv2")

_CHILD = """
import time
start = time.perf_counter()
import {module}
elapsed = time.perf_counter() - start
import json, sys
print(json.dumps({{"s": elapsed, "heavy": [m for m in {heavy!r} if m in sys.modules]}}))
"""


def _time_import(module: str, env: dict[str, str]) -> dict:
    code = _CHILD.format(module=module, heavy=_HEAVY)
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    """Time the imports and write the JSON report."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=9, help="timed runs of each import (>= 5)")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).parent / "results" / "bench_import.json",
        help="JSON report path",
    )
    args = parser.parse_args()
    if args.runs < 5:
        parser.error(f"--runs must be >= 5 (a median of fewer is noise); got {args.runs}")
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env.setdefault("MUJOCO_GL", "egl")
    for module in _MODULES:  # untimed: writes the .pyc files, warms the file cache
        _time_import(module, env)
    times: dict[str, list[float]] = {m: [] for m in _MODULES}
    heavy: dict[str, list[str]] = {}
    for _ in range(args.runs):
        for module in _MODULES:
            result = _time_import(module, env)
            times[module].append(result["s"])
            heavy[module] = result["heavy"]
    median = {m: statistics.median(t) for m, t in times.items()}
    report: dict[str, object] = {
        "runs": args.runs,
        "load_average_1min": os.getloadavg()[0],
        "python": sys.version.split()[0],
    }
    for module in _MODULES:
        key = module.replace(".", "_")
        report[f"{key}_median_s"] = round(median[module], 4)
        report[f"{key}_min_s"] = round(min(times[module]), 4)
        report[f"{key}_over_mujoco"] = round(median[module] / median["mujoco"], 2)
        if module.startswith("handsim"):
            report[f"{key}_heavy_modules"] = heavy[module]
    for module in _MODULES:
        print(
            f"import {module:<13} median {median[module]:.3f} s  (min {min(times[module]):.3f} s)"
            f"  = {median[module] / median['mujoco']:.2f} x import mujoco"
        )
    for module in ("handsim", "handsim.envs"):
        print(f"import {module}: heavy modules loaded: {heavy[module] or 'none'}")
    print(f"load average (1 min): {report['load_average_1min']:.2f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
