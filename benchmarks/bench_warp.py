"""MuJoCo Warp's batched depth + segmentation against the OpenGL renderer, frames/s.

Measured in one run: a hand with objects on the table (``--objects`` of them), camera preset
``--camera`` at ``--width x --height``, ``--batch`` worlds per launch with random hand poses;
the Warp backend's rate with its breakdown (upload of poses, kinematics, BVH refit + ray cast,
readback to the host, geom-id/depth post-processing) after the kernels are compiled (the
compile time is reported on its own), and the OpenGL :class:`~handsim.world.render.DepthRenderer`
rate of the same frames one at a time, with their ratio.

With ``--generate N``: end to end to shards on disk instead, ``handsim generate --backend
warp`` of ``--preset`` (default ``hand-only``) at ``--gen-camera`` (N frames, ``--batch`` per
launch for a hand alone), after a first run that compiles the kernels, with the breakdown per
frame, and the OpenGL backend's rate on the same config in the same run. A hand alone
(batched): draws (pose, view, camera and host kinematics); the renderer's stages; labels;
noise; the rest (shard writing, the manifest and the loop). Hand-object presets (a frame per
launch, the OpenGL path's source and labels): the renderer's stages, summed over the frame's
renders (the image, the hand with the objects hidden, silhouettes; their number per frame is
reported), and the rest (grasp planning and draws, labels, noise, writing).

Without a CUDA device the Warp figure is the CPU device's, and the output says so: no GPU
figure is ever estimated.

Usage: ``WARP_CACHE_PATH=/tmp/warp_cache python benchmarks/bench_warp.py [--batch 16]
[--rounds 5] [--device cpu|cuda] [--camera sr300] [--width 320] [--height 240] [--objects 3]
[--generate FRAMES [--gen-camera icvl] [--preset hand-only]] [--no-opengl]``; writes
``benchmarks/results/bench_warp.json`` (``bench_warp_generate.json`` with ``--generate``).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import mujoco
import numpy as np

from handsim.hand import hand_params
from handsim.hand.pose import HandPose
from handsim.hand.samplers import sample_uniform
from handsim.world.camera import camera_preset
from handsim.world.registry import OBJECT_NAMES
from handsim.world.render import DepthRenderer
from handsim.world.scene import CameraSpec, Scene, SceneSpec, sample_placements
from handsim.world.warp_render import WarpDepthRenderer, warp_available


def _datas(scene: Scene, n: int, rng: np.random.Generator) -> list[mujoco.MjData]:
    angles = sample_uniform(rng, n).angles
    datas = []
    for i in range(n):
        data = mujoco.MjData(scene.model)
        wrist = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), 0.2])
        scene.binding.set_pose(
            data, HandPose(wrist, rng.normal(0, 0.5, 3), angles[i]), kinematics_only=True
        )
        mujoco.mj_forward(scene.model, data)
        datas.append(data)
    return datas


def _end_to_end(args: argparse.Namespace) -> dict:
    """Frames/s of ``generate`` to shards, warp (with its breakdown) and OpenGL, one run."""
    import shutil
    import tempfile

    import warp as wp

    from handsim.data.config import PRESETS, GenerationConfig
    from handsim.data.generation import generate
    from handsim.data.warp_source import WarpKinematicSource, batched
    from handsim.world.warp_render import WarpSceneRenderer

    preset = PRESETS[args.preset]
    config = GenerationConfig.from_mapping(
        preset, frames=args.generate, camera=args.gen_camera, seed=1
    )
    timed = WarpKinematicSource if batched(config) else WarpSceneRenderer
    root = Path(tempfile.mkdtemp(prefix="bench_warp_"))
    try:
        t0 = time.perf_counter()
        small = GenerationConfig.from_mapping(preset, frames=min(args.batch, 4), seed=2)
        generate(small, root / "warm", backend="warp", device=args.device, batch=args.batch)
        first_s = time.perf_counter() - t0
        timed.timings_s = stages = {}
        t0 = time.perf_counter()
        generate(config, root / "warp", backend="warp", device=args.device, batch=args.batch)
        warp_s = time.perf_counter() - t0
        timed.timings_s = None
        gl_s = None
        if not args.no_opengl:
            generate(small, root / "gl-warm")  # the OpenGL path's one-off set-up (numba, skin)
            t0 = time.perf_counter()
            generate(config, root / "opengl")
            gl_s = time.perf_counter() - t0
    finally:
        shutil.rmtree(root, ignore_errors=True)
    warp_device = wp.get_device(args.device)
    device = str(warp_device)
    gpu = device.startswith("cuda")
    n = args.generate
    renders = stages.pop("renders", None)
    per_frame = {k: round(1e3 * v / n, 3) for k, v in stages.items()}
    rest = "rest_writing_manifest_loop" if renders is None else "rest_draws_labels_noise_writing"
    per_frame[rest] = round(1e3 * (warp_s - sum(stages.values())) / n, 3)
    return {
        "mode": f"end to end to shards (handsim generate, preset {args.preset})",
        "renders_per_frame": None if renders is None else round(renders / n, 2),
        "device": device,
        "device_name": warp_device.name,
        "gpu": gpu,
        "note": "" if gpu else "no CUDA device: the Warp figure is the CPU device's",
        "batch": args.batch,
        "camera": args.gen_camera,
        "sensor": config.sensor,
        "frames": n,
        "warm_up_s_incl_compile_or_cache_load": round(first_s, 2),
        "warp_frames_per_s": round(n / warp_s, 1),
        "warp_breakdown_ms_per_frame": per_frame,
        "opengl_frames_per_s": None if gl_s is None else round(n / gl_s, 1),
        "warp_over_opengl": None if gl_s is None else round(gl_s / warp_s, 3),
        "load_average": os.getloadavg(),
        "versions": {"mujoco": mujoco.__version__, "warp": wp.config.version},
    }


def main() -> None:
    """Measure both renderers on the same frames and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--device", default=None, help="Warp device (default: Warp's default)")
    parser.add_argument("--camera", default="sr300")
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--objects", type=int, default=3)
    parser.add_argument("--generate", type=int, default=0, metavar="FRAMES")
    parser.add_argument("--gen-camera", default="icvl")
    parser.add_argument("--preset", default="hand-only", help="--generate: the preset")
    parser.add_argument("--out", default=None)
    parser.add_argument(
        "--no-opengl", action="store_true", help="measure Warp alone (no OpenGL context here)"
    )
    args = parser.parse_args()
    if not warp_available():
        raise SystemExit("mujoco-warp is not installed: pip install 'handsim[gpu]'")
    if args.generate:
        result = _end_to_end(args)
        out = Path(args.out or "benchmarks/results/bench_warp_generate.json")
        print(json.dumps(result, indent=2))
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result, indent=2) + "\n")
        return
    args.out = args.out or "benchmarks/results/bench_warp.json"
    import warp as wp

    rng = np.random.default_rng(0)
    intr = camera_preset(args.camera).scaled(args.width, args.height)
    cam = CameraSpec.look_at("camera", intr, (0.0, -0.6, 0.4), (0.0, 0.0, 0.1))
    names = [OBJECT_NAMES[i] for i in rng.choice(len(OBJECT_NAMES), args.objects, replace=False)]
    spec = SceneSpec(
        hand=hand_params("medium", "right"),
        objects=sample_placements(rng, names),
        cameras=(cam,),
        table=True,
    )
    scene = Scene(spec)
    datas = _datas(scene, args.batch, rng)

    t0 = time.perf_counter()
    warp = WarpDepthRenderer(scene.model, "camera", intr, nworld=args.batch, device=args.device)
    warp.render(datas)  # compiles (or loads from WARP_CACHE_PATH) the kernels
    first_s = time.perf_counter() - t0
    device = str(warp.device)
    gpu = warp.device.is_cuda
    stages: dict[str, float] = {}
    t0 = time.perf_counter()
    for _ in range(args.rounds):
        warp.render(datas, timings_s=stages)
    warp_s = time.perf_counter() - t0
    frames = args.rounds * args.batch
    warp_fps = frames / warp_s

    gl_fps = None
    if not args.no_opengl:
        with DepthRenderer(scene.model, "camera", intr) as gl:
            gl.render(datas[0])
            t0 = time.perf_counter()
            for _ in range(args.rounds):
                for data in datas:
                    gl.render(data)
            gl_fps = frames / (time.perf_counter() - t0)

    result = {
        "device": device,
        "device_name": warp.device.name,
        "gpu": gpu,
        "note": "" if gpu else "no CUDA device: the Warp figure is the CPU device's",
        "batch": args.batch,
        "image": f"{args.width}x{args.height}",
        "camera": args.camera,
        "objects": names,
        "frames": frames,
        "first_render_s_incl_compile_or_cache_load": round(first_s, 2),
        "warp_frames_per_s": round(warp_fps, 1),
        "warp_breakdown_ms_per_frame": {k: round(1e3 * v / frames, 3) for k, v in stages.items()},
        "opengl_frames_per_s": None if gl_fps is None else round(gl_fps, 1),
        "warp_over_opengl": None if gl_fps is None else round(warp_fps / gl_fps, 3),
        "load_average": os.getloadavg(),
        "versions": {"mujoco": mujoco.__version__, "warp": wp.config.version},
    }
    print(json.dumps(result, indent=2))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
