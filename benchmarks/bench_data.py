"""Dataset generation and reading: frames/s, worker scaling, bytes per frame, read rate, memory.

Measured in one run, on this machine:

- kinematic generation (preset ``hand-only``, 320 x 240, all labels) with 1 and 2 workers, and
  their ratio (``--worker-frames``, long enough that a worker's start-up, about 1 s, is a small
  part), and their frames per CPU-second (the workers' start-up included): on a loaded machine
  the wall-clock ratio says how many free cores there were, the CPU ratio what 2 workers cost
  per frame;
- a small job as users run it (``--only job``): ``hand-only`` with ``--job-frames`` (600)
  frames and the default shard size, 1 and 2 workers, each run in a fresh process: the
  ``generate()`` call alone (after the imports) and the whole ``handsim generate`` command;
  the ratio 2 / 1 worker in each of ``--job-rounds`` (3) interleaved rounds (median, min,
  max), and the free cores measured after each round (two spinning processes over one); in
  each round also the command with 1 frame (the job's fixed part) and a process that loads
  only the dependencies of a frame, and from them the best ratio 2 workers can reach with
  that fixed part and the job size at which it reaches 1.7 (see ``_job_ratios``); handsim's
  bytecode is compiled first, as pip installs it;
- Grasp-v0 rollouts of the grasp expert (preset ``grasp-rollouts``) with 1 worker;
- MuJoCo's plain depth render rate (``mujoco.Renderer`` with depth on) of the same scenes: the
  generated frames replayed from their labels (hand side, length and pose, camera pose; checked
  against the stored depth), and the ratio of generation with one worker to it: cold (a fresh
  process), warm (a second run in the same process) and in ``--rounds`` rounds of a warm run
  and the replay of its frames one after the other (median, min, max: the machine's speed
  varies from second to second, so a ratio is best taken from runs close in time); these runs
  write shards of the preset's size (250 frames), as ``handsim generate`` does; also a fixed
  view of an open hand, the unit used before the replay; ``--only ratio`` measures just these,
  and the warm rate without sensor noise;
- bytes per stored frame against raw float32 depth + labels;
- read rate of :class:`~handsim.data.torch_dataset.HandSimDataset` through a ``DataLoader``
  with 2 workers and batches of 32: a plain shuffle, the block batch sampler
  (``dataset.batch_sampler(32)``), and ``dataset.loader(32)`` with every key and with depth
  plus every label (see ``_read_fps``);
- peak RSS (``resource.getrusage`` in a child process) of generation runs of M and 10 M frames
  (``--memory``, M = ``--memory-frames``).

The machine may be shared: compare the ratios, each measured in one run; the load average is
recorded with them.

Usage: ``python benchmarks/bench_data.py [--frames 800] [--rollout-frames 120] [--memory]
[--memory-frames 1000] [--worker-frames 10000] [--rounds 5] [--job-frames 600]
[--job-rounds 3] [--only all|read|memory|workers|job|ratio]``; writes
``benchmarks/results/bench_data.json`` (``bench_data_<part>.json`` for one part).
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

os.environ.setdefault("MUJOCO_GL", "egl")


_CPU_S: dict[str, float] = {}
"""CPU seconds of the last :func:`_generate` run (this process and its reaped workers)."""


def _cpu_s() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)  # pool workers, once joined
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _generate(
    frames: int, workers: int, out: Path, preset: str = "hand-only", **overrides: object
) -> float:
    from handsim.data.generation import PRESETS, GenerationConfig, generate

    # 8 shards for the worker runs (work for both workers) unless the caller gives the size.
    overrides.setdefault("frames_per_shard", max(1, frames // 8))
    config = GenerationConfig.from_mapping(PRESETS[preset], frames=frames, **overrides)
    cpu, start = _cpu_s(), time.perf_counter()
    generate(config, out, workers=workers)
    _CPU_S["last"] = _cpu_s() - cpu
    return frames / (time.perf_counter() - start)


def _plain_render_fps(frames: int) -> float:
    """MuJoCo's own depth render of a hand scene of the same size (no labels, no noise)."""
    import mujoco

    from handsim.hand.pose_sources import gesture
    from handsim.world.camera import camera_preset
    from handsim.world.scene import CameraSpec, Scene, SceneSpec

    intr = camera_preset("icvl")
    cam = CameraSpec.look_at("camera", intr, (0.0, -0.5, 0.45), (0.0, 0.0, 0.3))
    scene = Scene(SceneSpec(cameras=(cam,), table=False))
    scene.reset(gesture("open").replace(wrist_pos=np.array([0.0, 0.0, 0.3])))
    renderer = mujoco.Renderer(scene.model, intr.height, intr.width)
    renderer.enable_depth_rendering()
    cpu, start = _cpu_s(), time.perf_counter()
    for _ in range(frames):
        renderer.update_scene(scene.data, camera="camera")
        renderer.render()
    fps = frames / (time.perf_counter() - start)
    _CPU_S["plain"] = _cpu_s() - cpu  # the renderer's threads included
    renderer.close()
    return fps


def _replay_plain_render_fps(folder: Path) -> float:
    """MuJoCo's plain depth render of the generated frames themselves (no labels, no noise).

    Every frame of the dataset in ``folder`` (hand alone) is set up again from its labels: a
    scene with the frame's hand (side, length, 27-DoF pose) and its camera pose; only
    ``mujoco.Renderer``'s ``update_scene`` and depth ``render`` are timed. So the comparison
    is with the same scenes as generated: the same hands, poses and viewpoints, which decide
    how many pixels the hand covers.
    """
    import mujoco
    from scipy.spatial.transform import Rotation

    from handsim.data.arrays import VIEWPOINT_CODES
    from handsim.data.kinematic import alone_shoulder_m
    from handsim.data.manifest import Manifest
    from handsim.data.shards import ShardReader
    from handsim.hand.model import hand_params
    from handsim.hand.pose import HandPose
    from handsim.world.camera import R_MJCAM_FROM_CV, camera_preset
    from handsim.world.scene import SEGMENT_LABELS, CameraSpec, Scene, SceneSpec

    BACKDROP_LABEL = SEGMENT_LABELS.index("backdrop")  # noqa: N806

    manifest = Manifest.read(folder)
    intr = camera_preset(manifest.config["camera"])
    labels = {
        key: []
        for key in ("hand_pose", "hand_length_m", "is_left", "T_cam_from_world", "viewpoint")
    }
    for record in manifest.shards.values():
        reader = ShardReader(folder / record.name)
        for key in labels:
            labels[key].append(reader.labels(key))
        reader.close()
    labels = {key: np.concatenate(value) for key, value in labels.items()}
    first_shard = ShardReader(folder / manifest.shards[min(manifest.shards)].name)
    clean = "depth_clean" if "depth_clean" in first_shard[0] else "depth"
    first = [
        (first_shard[i][clean], first_shard[i]["segmentation"])
        for i in range(min(CHECKED_FRAMES, len(first_shard)))
    ]
    first_shard.close()
    checks: list[tuple[float, float]] = []
    cam = CameraSpec.look_at("camera", intr, (0.0, -0.5, 0.45), (0.0, 0.0, 0.3))
    scenes, renderers = {}, {}
    for side in ("right", "left"):
        scenes[side] = Scene(
            SceneSpec(hand=hand_params("medium", side), cameras=(cam,), table=False)
        )
        renderers[side] = mujoco.Renderer(scenes[side].model, intr.height, intr.width)
        renderers[side].enable_depth_rendering()
    elapsed, cpu = 0.0, 0.0
    for i in range(len(labels["hand_pose"])):
        side = "left" if labels["is_left"][i] else "right"
        scene, renderer = scenes[side], renderers[side]
        length = float(labels["hand_length_m"][i])
        if length != scene.hand.params.hand_length:
            scene.set_hand_length(length)
            for mesh in scene.hand_mesh_ids:
                mujoco.mjr_uploadMesh(scene.model, renderer._mjr_context, mesh)
        T = labels["T_cam_from_world"][i]  # noqa: N806
        R = T[:3, :3].T @ R_MJCAM_FROM_CV  # noqa: N806 (world from MuJoCo's camera axes)
        camera_id = scene.model.camera("camera").id
        scene.model.cam_pos[camera_id] = -T[:3, :3].T @ T[:3, 3]
        scene.model.cam_quat[camera_id] = np.roll(Rotation.from_matrix(R).as_quat(), 1)
        scene.binding.set_pose(scene.data, HandPose.from_vector(labels["hand_pose"][i]))
        # The upper arm toward the shoulder, as the kinematic source draws it for a hand alone.
        view = VIEWPOINT_CODES[int(labels["viewpoint"][i])]
        eye = scene.model.cam_pos[camera_id].copy()
        scene.binding.point_upper_arm(scene.data, alone_shoulder_m(view, side == "left", eye))
        cpu0, start = _cpu_s(), time.perf_counter()
        renderer.update_scene(scene.data, camera="camera")
        depth_m = renderer.render()
        elapsed += time.perf_counter() - start
        cpu += _cpu_s() - cpu0
        if i < CHECKED_FRAMES:  # the replay is the generated scene: same hand pixels, depth
            stored, segmentation = first[i]
            near_m, far_m = intr.range_m
            # What the labels keep: the camera's range (the far plane, background, just below).
            seen = (depth_m >= near_m) & (depth_m < 0.999 * far_m)
            # The backdrop's place is not in the labels: the replay draws the hand and arm.
            labelled = (segmentation > 0) & (segmentation != BACKDROP_LABEL)
            both = seen & labelled & (stored > 0)
            checks.append(
                (
                    np.count_nonzero(seen & labelled) / max(np.count_nonzero(seen | labelled), 1),
                    float(np.median(np.abs(depth_m[both] - stored[both]))) * 1e3,
                )
            )
    for renderer in renderers.values():
        renderer.close()
    _CPU_S["replay"] = cpu
    REPLAY_CHECK["hand_mask_iou_min"] = min(c[0] for c in checks)
    REPLAY_CHECK["median_abs_depth_diff_mm_max"] = max(c[1] for c in checks)
    return len(labels["hand_pose"]) / elapsed


CHECKED_FRAMES = 20
"""Frames of the first shard whose replay is compared with the stored depth."""
REPLAY_CHECK: dict[str, float] = {}
"""Agreement of the replayed frames with the stored ones: IoU of the replayed hand pixels and
the labelled ones, and the median depth difference (the stored depth has the sensor's noise
unless the dataset keeps the clean one)."""


def _read_fps(folder: Path, mode: str, seconds: float = 10.0) -> float:
    """Samples/s of a DataLoader with 2 persistent workers and batches of 32.

    Modes: ``shuffle`` (every key, plain shuffled sampler, default collate), ``blocks`` (every
    key, the block batch sampler), ``loader`` (every key, ``dataset.loader``: batches read and
    made in one call) and ``loader_labels`` (``dataset.loader`` with depth and every label,
    no segmentation image).
    """
    import torch

    from handsim.data.arrays import LABEL_SCHEMA
    from handsim.data.torch_dataset import HandSimDataset

    common = {"num_workers": 2, "persistent_workers": True}
    if mode == "loader_labels":
        data = HandSimDataset(folder, keys=("depth", *LABEL_SCHEMA))
    else:
        data = HandSimDataset(folder)
    if mode == "shuffle":
        loader = torch.utils.data.DataLoader(data, batch_size=32, shuffle=True, **common)
    elif mode == "blocks":
        loader = torch.utils.data.DataLoader(data, batch_sampler=data.batch_sampler(32), **common)
    else:
        loader = data.loader(32, **common)
    for _ in loader:  # warm-up: worker start-up and each worker's first shard reads
        pass
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for batch in loader:
            n += len(batch["depth"])
    return n / (time.perf_counter() - start)


def _read_cpu_rate(folder: Path, labels_only: bool, passes: int = 3) -> float:
    """Samples per CPU-second of ``dataset.batch`` in this process, on one thread.

    What one DataLoader worker can make on a core of its own, whatever the machine's load.
    """
    import torch

    from handsim.data.arrays import LABEL_SCHEMA
    from handsim.data.torch_dataset import HandSimDataset

    torch.set_num_threads(1)
    data = HandSimDataset(folder, keys=("depth", *LABEL_SCHEMA) if labels_only else None)
    batches = list(data.batch_sampler(32)) * passes
    data.batch(batches[0])  # open the shards, read the labels
    start = time.process_time()
    for indices in batches:
        data.batch(indices)
    return sum(map(len, batches)) / (time.process_time() - start)


def _peak_rss_mib(frames: int, out: Path) -> float:
    """Peak RSS of a child process that generates ``frames`` frames (hand-only), MiB.

    The child's own high-water mark (``VmHWM``, reset by ``exec``): Linux's ``ru_maxrss`` keeps
    the RSS the forked child shared with this process, which after the read runs is larger.
    """
    code = (
        "import resource, sys\n"
        "from handsim.data.generation import PRESETS, GenerationConfig, generate\n"
        f"c = GenerationConfig.from_mapping(PRESETS['hand-only'], frames={frames}, "
        "frames_per_shard=250)\n"
        "generate(c, sys.argv[1])\n"
        "try:\n"
        "    hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM:')][0]\n"
        "    print(int(hwm.split()[1]) / 1024)\n"
        "except OSError:\n"
        "    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n"
    )
    out_text = subprocess.run(
        [sys.executable, "-c", code, str(out)], capture_output=True, text=True, check=True
    ).stdout
    return float(out_text.strip().splitlines()[-1])


_JOB_CHILD = """
import json, sys, time
from handsim.data.generation import PRESETS, GenerationConfig, generate
config = GenerationConfig.from_mapping(PRESETS["hand-only"], frames=int(sys.argv[1]))
start = time.perf_counter()
generate(config, sys.argv[3], workers=int(sys.argv[2]))
print(json.dumps({"s": time.perf_counter() - start}))
"""


def _children_cpu_s() -> float:
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return children.ru_utime + children.ru_stime


def _job_s(frames: int, workers: int, out: Path, cli: bool) -> tuple[float, float]:
    """Wall seconds of one ``hand-only`` job of ``frames`` frames in a fresh process.

    ``cli``: the whole ``handsim generate`` command (interpreter, imports, writing, exit); else
    the ``generate()`` call alone, after the imports (a program that already imported handsim).
    Also the CPU seconds of the whole process and its workers (imports included).
    """
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    cpu = _children_cpu_s()
    if cli:
        command = [sys.executable, "-m", "handsim.cli", "generate", "--preset", "hand-only"]
        command += ["--frames", str(frames), "--workers", str(workers), "--out", str(out)]
        start = time.perf_counter()
        subprocess.run(command + ["--quiet"], check=True, env=env, capture_output=True)
        return time.perf_counter() - start, _children_cpu_s() - cpu
    command = [sys.executable, "-c", _JOB_CHILD, str(frames), str(workers), str(out)]
    done = subprocess.run(command, check=True, env=env, capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])["s"], _children_cpu_s() - cpu


_FLOOR_MODULE = """
import gc, importlib, json, time

cpu_s = {}
for name in ("numpy", "mujoco", "h5py", "cv2", "scipy.spatial.transform", "numba"):
    start = time.process_time()
    importlib.import_module(name)
    cpu_s[name] = time.process_time() - start
import numba


@numba.njit(cache=True)
def one(x):
    return x + 1


start = time.process_time()
one(1)
cpu_s["numba set-up"] = time.process_time() - start
print(json.dumps(cpu_s))
gc.freeze()  # the exit skips its collection, as handsim's program does
"""
"""What any process that makes a frame loads, and numba's set-up (one loop from its cache);
prints the CPU seconds of each import, in this order."""


def _floor_s(folder: Path) -> tuple[float, float, dict[str, float]]:
    """Wall and CPU seconds of a process that only loads the frames' dependencies.

    NumPy, MuJoCo, h5py, OpenCV, scipy.spatial (the hand's rotations) and numba, set up by
    loading one compiled loop from its cache: the part of a job's fixed start that no change
    to handsim removes. Also the CPU seconds of each import in that process (in that order).
    """
    (folder / "floor_deps.py").write_text(_FLOOR_MODULE)
    command = [sys.executable, "-c", "import floor_deps"]
    env = {**os.environ, "PYTHONPATH": str(folder)}
    subprocess.run(command, check=True, env=env, cwd=folder, capture_output=True)  # numba
    cpu = _children_cpu_s()
    start = time.perf_counter()
    done = subprocess.run(command, check=True, env=env, cwd=folder, capture_output=True)
    wall = time.perf_counter() - start
    return wall, _children_cpu_s() - cpu, json.loads(done.stdout.decode().splitlines()[-1])


def _spin_rate(seconds: float = 0.5) -> float:
    """Iterations per second of a pure-Python loop (one core's speed just now)."""
    n, end = 0, time.perf_counter() + seconds
    while time.perf_counter() < end:
        n += 1
    return n / seconds


def _free_cores() -> float:
    """Speed-up of two processes spinning at once over one: how many cores were free."""
    import multiprocessing as mp

    one = _spin_rate()
    with mp.get_context("spawn").Pool(2) as pool:
        two = sum(pool.map(_spin_rate, [0.5, 0.5]))
    return two / one


TARGET_2_OVER_1 = 1.7
"""The target: 2 workers at least this many times faster than 1 on the job."""


def _job_ratios(frames: int, rounds: int, tmp: Path) -> dict:
    """2 workers against 1 on a ``frames``-frame job, interleaved in ``rounds`` rounds.

    Each round runs, each in a fresh process: the ``generate()`` call with 1 then 2 workers,
    the ``handsim generate`` command with 1 then 2 workers, the command with 1 frame (the
    job's fixed part: start, set-up, end) and a process that loads only the dependencies
    (:func:`_floor_s`); its ratios are taken in the round (the machine's load changes from
    minute to minute). Also the free cores measured at the end of each round.

    From the round's command times: the fixed part F (the 1-frame run), the time per frame
    f = (T1 - F) / (frames - 1), the best ratio 2 workers can reach when the fixed part is on
    both runs' path, T1 / (F + (T1 - F) / 2), and the job size at which that bound reaches
    :data:`TARGET_2_OVER_1` (0.7 F / (0.15 f) frames for 1.7).
    """
    # As installed by pip: the package's bytecode compiled (this machine may set
    # PYTHONDONTWRITEBYTECODE, which would make every run compile handsim's sources).
    import handsim

    package = Path(handsim.__file__).parent
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(package)], check=True)
    ratios: dict[str, list[float]] = {"api": [], "cli": []}
    seconds: dict[str, list[float]] = {f"{k}_{w}": [] for k in ratios for w in (1, 2)}
    cpu_ratios: list[float] = []
    fixed: dict[str, list[float]] = {
        k: [] for k in ("s", "cpu_s", "floor_s", "floor_cpu_s", "bound", "frames_for_target")
    }
    floor_parts: dict[str, list[float]] = {}
    free = []
    for r in range(rounds):
        for kind in ("api", "cli"):
            one, cpu_one = _job_s(frames, 1, tmp / f"job{r}{kind}1", cli=kind == "cli")
            two, cpu_two = _job_s(frames, 2, tmp / f"job{r}{kind}2", cli=kind == "cli")
            seconds[f"{kind}_1"].append(one)
            seconds[f"{kind}_2"].append(two)
            ratios[kind].append(one / two)
            if kind == "cli":
                cpu_ratios.append(cpu_two / cpu_one)
        one, two = seconds["cli_1"][-1], seconds["cli_2"][-1]
        start_s, start_cpu_s = _job_s(1, 1, tmp / f"job{r}fixed", cli=True)
        floor_s, floor_cpu_s, parts = _floor_s(tmp)
        for name, value in parts.items():
            floor_parts.setdefault(name, []).append(value)
        frame_s = (one - start_s) / (frames - 1)
        fixed["s"].append(start_s)
        fixed["cpu_s"].append(start_cpu_s)
        fixed["floor_s"].append(floor_s)
        fixed["floor_cpu_s"].append(floor_cpu_s)
        fixed["bound"].append(one / (start_s + (one - start_s) / 2))
        need = 2 * (TARGET_2_OVER_1 - 1) / (2 - TARGET_2_OVER_1)
        fixed["frames_for_target"].append(need * start_s / frame_s)
        free.append(_free_cores())
        print(
            f"round {r}: generate() 1 / 2 workers {ratios['api'][-1]:.2f}, "
            f"handsim generate {one:.2f} / {two:.2f} s = {ratios['cli'][-1]:.2f} (CPU 2 / 1 "
            f"worker {cpu_ratios[-1]:.2f}); 1 frame {start_s:.2f} s (CPU {start_cpu_s:.2f}), "
            f"the dependencies alone {floor_s:.2f} s (CPU {floor_cpu_s:.2f}): bound "
            f"{fixed['bound'][-1]:.2f}, {TARGET_2_OVER_1} x from "
            f"{fixed['frames_for_target'][-1]:.0f} frames; free cores {free[-1]:.2f}; "
            f"load {os.getloadavg()[0]:.1f}"
        )
    out: dict = {"job_frames": frames, "job_rounds": rounds}
    for kind, values in ratios.items():
        out[f"job_{kind}_2_over_1_median"] = float(np.median(values))
        out[f"job_{kind}_2_over_1_min"] = min(values)
        out[f"job_{kind}_2_over_1_max"] = max(values)
        out[f"job_{kind}_2_over_1_rounds"] = values
    for key, values in seconds.items():
        out[f"job_{key}_workers_s_median"] = float(np.median(values))
        out[f"job_{key}_workers_s_rounds"] = values
    # CPU of the whole command, 2 workers over 1: the work's cost, whatever the load.
    out["job_cli_cpu_2_over_1_median"] = float(np.median(cpu_ratios))
    for key, values in fixed.items():
        out[f"job_fixed_{key}_median"] = float(np.median(values))
        out[f"job_fixed_{key}_rounds"] = values
    out["job_fixed_floor_import_cpu_s_median"] = {
        name: float(np.median(values)) for name, values in floor_parts.items()
    }
    print("the dependencies' imports, CPU s (median):", out["job_fixed_floor_import_cpu_s_median"])
    out["job_free_cores_rounds"] = free
    return out


def main() -> None:
    """Run the benchmark and write its JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=800, help="frames per generation run")
    parser.add_argument(
        "--rollout-frames", type=int, default=120, help="frames of the Grasp rollout run"
    )
    parser.add_argument("--memory", action="store_true", help="also compare peak RSS (slow)")
    parser.add_argument(
        "--only",
        choices=("all", "read", "memory", "workers", "job", "ratio"),
        default="all",
        help="run one part only",
    )
    parser.add_argument(
        "--memory-frames", type=int, default=1000, help="M of the M vs 10 M memory runs"
    )
    parser.add_argument(
        "--rounds",
        type=int,
        default=5,
        help="rounds of a warm generation run and the replay of its frames",
    )
    parser.add_argument(
        "--worker-frames", type=int, default=10000, help="frames per 1- and 2-worker run"
    )
    parser.add_argument(
        "--job-frames", type=int, default=600, help="frames of the 1- against 2-worker job"
    )
    parser.add_argument(
        "--job-rounds", type=int, default=3, help="interleaved rounds of the job runs"
    )
    args = parser.parse_args()
    from handsim.data.generation import PRESETS, GenerationConfig
    from handsim.data.manifest import Manifest

    results: dict[str, float] = {"load_average_1min_start": os.getloadavg()[0]}
    part = args.only
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # The ratio runs write shards of the preset's size, as `handsim generate` does.
        preset = GenerationConfig.from_mapping(PRESETS["hand-only"])
        shard = {"frames_per_shard": preset.frames_per_shard}
        if part in ("all", "read", "ratio"):
            results["generate_1_worker_fps"] = _generate(args.frames, 1, tmp / "w1", **shard)
            results["generate_1_worker_frames_per_cpu_s"] = args.frames / _CPU_S["last"]
        if part in ("all", "workers"):
            # Long runs: a worker's start-up (~1 s: imports, OpenGL, the hands' skins) is then
            # a small part, as in a real dataset.
            n = args.worker_frames
            results["workers_1_fps"] = _generate(n, 1, tmp / "s1")
            one_cpu = n / _CPU_S["last"]
            results["workers_2_fps"] = _generate(n, 2, tmp / "s2")
            results["workers_2_over_1"] = results["workers_2_fps"] / results["workers_1_fps"]
            # CPU per frame of 2 workers (start-up included) against 1: with two free cores,
            # 2 workers would run at about 2x this of 1 worker's rate.
            results["workers_2_cpu_efficiency"] = n / _CPU_S["last"] / one_cpu
        if part in ("all", "job"):
            # A small job as a user runs it: 2 workers against 1, each run in a fresh process.
            results.update(_job_ratios(args.job_frames, args.job_rounds, tmp))
        if part in ("all", "ratio"):
            # The target's unit: MuJoCo's plain render of the very frames generated.
            results["replayed_plain_render_fps"] = _replay_plain_render_fps(tmp / "w1")
            results.update({f"replay_{k}": v for k, v in REPLAY_CHECK.items()})
            results["generate_over_replayed_render"] = (
                results["generate_1_worker_fps"] / results["replayed_plain_render_fps"]
            )
            results["generate_over_replayed_render_per_cpu_s"] = results[
                "generate_1_worker_frames_per_cpu_s"
            ] / (args.frames / _CPU_S["replay"])
            # A fixed view of an open hand (the figure used before the replay).
            results["plain_depth_render_fps"] = _plain_render_fps(args.frames)
            results["generate_over_plain_render"] = (
                results["generate_1_worker_fps"] / results["plain_depth_render_fps"]
            )
            # Per CPU-second (OpenGL's threads included in both): steadier on a shared machine.
            results["plain_depth_render_frames_per_cpu_s"] = args.frames / _CPU_S["plain"]
            results["generate_over_plain_render_per_cpu_s"] = (
                results["generate_1_worker_frames_per_cpu_s"]
                / results["plain_depth_render_frames_per_cpu_s"]
            )
            # A second run in the same process: its imports, OpenGL and the hands' skins (one
            # per side) are ready, as in a long run.
            results["generate_1_worker_warm_fps"] = _generate(
                args.frames, 1, tmp / "w1_warm", **shard
            )
            results["generate_warm_over_plain_render"] = (
                results["generate_1_worker_warm_fps"] / results["plain_depth_render_fps"]
            )
            results["generate_warm_over_plain_render_per_cpu_s"] = (
                args.frames / _CPU_S["last"] / results["plain_depth_render_frames_per_cpu_s"]
            )
            results["generate_warm_over_replayed_render"] = (
                results["generate_1_worker_warm_fps"] / results["replayed_plain_render_fps"]
            )
        if part in ("all", "ratio"):
            # Rounds of a warm generation run and the replay of its frames, one after the
            # other: each round's ratio is measured under the same machine load.
            ratios = []
            for k in range(args.rounds):
                fps = _generate(args.frames, 1, tmp / f"round{k}", **shard)
                ratios.append(fps / _replay_plain_render_fps(tmp / f"round{k}"))
            results["rounds"] = args.rounds
            results["generate_warm_over_replayed_render_rounds_median"] = float(np.median(ratios))
            results["generate_warm_over_replayed_render_rounds_min"] = min(ratios)
            results["generate_warm_over_replayed_render_rounds_max"] = max(ratios)
        if part == "ratio":
            # Without the structured-light noise model: what the rest of the pipeline costs.
            results["generate_1_worker_warm_no_noise_fps"] = _generate(
                args.frames, 1, tmp / "w1_none", sensor="none", **shard
            )
            results["generate_warm_no_noise_over_plain_render"] = (
                results["generate_1_worker_warm_no_noise_fps"] / results["plain_depth_render_fps"]
            )
        if part in ("all", "ratio"):
            manifest = Manifest.read(tmp / "w1")
            stored = sum(s.bytes for s in manifest.shards.values()) / manifest.frames
            h, w = manifest.image_shape
            from handsim.data.arrays import empty_label_arrays

            raw = 4 * h * w + sum(a.nbytes for a in empty_label_arrays().values())
            results["bytes_per_frame"] = stored
            results["bytes_per_frame_over_raw"] = stored / raw
        if part in ("all", "read"):
            for mode in ("shuffle", "blocks", "loader", "loader_labels"):
                results[f"read_fps_2_workers_{mode}"] = _read_fps(tmp / "w1", mode)
            results["read_samples_per_cpu_s_all"] = _read_cpu_rate(tmp / "w1", False)
            results["read_samples_per_cpu_s_labels"] = _read_cpu_rate(tmp / "w1", True)
        if part == "all":
            results["generate_rollouts_1_worker_fps"] = _generate(
                args.rollout_frames, 1, tmp / "r1", preset="grasp-rollouts"
            )
        if args.memory or part == "memory":
            m = args.memory_frames
            results["memory_frames_m"] = m
            results["peak_rss_mib_m"] = _peak_rss_mib(m, tmp / "m1")
            results["peak_rss_mib_10m"] = _peak_rss_mib(10 * m, tmp / "m10")
            results["peak_rss_10m_over_m"] = results["peak_rss_mib_10m"] / results["peak_rss_mib_m"]
    results["parent_peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    results["load_average_1min_end"] = os.getloadavg()[0]
    for key, value in results.items():
        if isinstance(value, (int, float)):
            print(f"{key:<32} {value:12.3f}")
    name = "bench_data.json" if part == "all" else f"bench_data_{part}.json"
    out = Path(__file__).parent / "results" / name
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"frames": args.frames, **results}, indent=2) + "\n")
    print(f"written {out}")


if __name__ == "__main__":
    main()
