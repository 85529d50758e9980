"""Benchmark: time and peak memory of ``load_object`` on large and awkward meshes.

Run: ``python benchmarks/bench_mesh_import.py [--faces 2000000] [--out FILE.json]``.

Each case runs in a fresh child process (so its peak resident memory, ``ru_maxrss``, is its
own) and reports wall time, peak RSS of the child and of CoACD's grandchild, the faces kept
and the warnings raised:

- ``big_<N>``: a rippled torus (8.4 cm, a dense-scan stand-in) of about ``--faces`` faces
  as binary PLY, default options (decimated to the face budget, CoACD under its time limit);
- ``big_<N>_hull``: the same with ``decomposition="convex_hull"``;
- ``sphere_82k``: an 82k-face icosphere (the hull diameter's worst case: every vertex is on
  the hull);
- ``open_tube_64``: a 64-face open tube with CoACD (which runs for minutes on it), stopped by
  ``coacd_timeout_s``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh


def _bumpy_torus(faces: int, major_m: float = 0.03, minor_m: float = 0.012) -> trimesh.Trimesh:
    """A watertight torus with ripples, about ``faces`` triangles (a dense-scan stand-in)."""
    n = int(np.sqrt(faces / 2))
    u, v = np.meshgrid(
        np.linspace(0, 2 * np.pi, n, endpoint=False),
        np.linspace(0, 2 * np.pi, n, endpoint=False),
        indexing="ij",
    )
    r = minor_m * (1.0 + 0.05 * np.sin(9 * u) * np.sin(7 * v))
    x = (major_m + r * np.cos(v)) * np.cos(u)
    y = (major_m + r * np.cos(v)) * np.sin(u)
    z = r * np.sin(v)
    vertices = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = i * n + j, ((i + 1) % n) * n + j
    c, d = ((i + 1) % n) * n + (j + 1) % n, i * n + (j + 1) % n
    tris = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    return trimesh.Trimesh(vertices, tris, process=False)


def _one(path: str, kwargs: dict) -> None:
    """Child: import one mesh and print a JSON line with the figures."""
    import warnings

    from handsim.world.mesh_import import load_object

    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        obj = load_object(path, name="bench", mass_kg=0.2, **kwargs)
    wall = time.perf_counter() - start
    print(
        json.dumps(
            {
                "wall_s": round(wall, 2),
                "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
                "peak_rss_children_mib": round(
                    resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
                ),
                "faces_kept": len(obj.visual_mesh.faces),
                "collision_pieces": len(obj.collision_meshes),
                "diameter_m": obj.diameter_m,
                "warnings": [str(w.message).split(": ", 1)[-1][:160] for w in caught],
            }
        )
    )


def main() -> None:
    """Write the meshes, import each in a child process, print and save the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--faces", type=int, default=2_000_000)
    parser.add_argument("--out", default="benchmarks/results/mesh_import.json")
    parser.add_argument("--one", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        _one(args.one[0], json.loads(args.one[1]))
        return

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        big = Path(tmp, "big.ply")
        _bumpy_torus(args.faces).export(big)
        sphere = Path(tmp, "sphere.ply")
        s = trimesh.creation.icosphere(subdivisions=6, radius=0.04)
        s.export(sphere)
        tube = trimesh.creation.cylinder(radius=0.02, height=0.05, sections=32)
        tube.update_faces(np.abs(tube.face_normals[:, 2]) < 0.5)
        tube.remove_unreferenced_vertices()
        tube_path = Path(tmp, "tube.ply")
        tube.export(tube_path)
        n_big = len(trimesh.load(big, process=False, force="mesh").faces)
        cases = {
            f"big_{n_big}": (big, {}),
            f"big_{n_big}_hull": (big, {"decomposition": "convex_hull"}),
            f"sphere_{len(s.faces)}": (sphere, {"decomposition": "convex_hull"}),
            f"open_tube_{len(tube.faces)}": (tube_path, {"decomposition": "coacd"}),
        }
        for name, (path, kwargs) in cases.items():
            run = subprocess.run(
                [sys.executable, __file__, "--one", str(path), json.dumps(kwargs)],
                capture_output=True,
                text=True,
                check=True,
            )
            results[name] = {"kwargs": kwargs, **json.loads(run.stdout.strip().splitlines()[-1])}
            print(name, json.dumps(results[name]), flush=True)
    # The machine is shared: record its load so that the times can be read in context.
    results["load_average_1min_at_end"] = round(os.getloadavg()[0], 2)
    results["cpu_count"] = os.cpu_count()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
