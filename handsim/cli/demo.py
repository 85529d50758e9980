"""``handsim demo``: hands of three sizes and both sides play a gesture sequence under physics.

Writes to the output folder:

- ``gestures.png``: contact sheet, one row per hand (size x side), one column per gesture,
  rendered at the end of each gesture's hold;
- ``summary.txt`` and ``summary.json``: per hand the model figures (mass, build time) and how
  well the physics hand tracked its targets (joint error at the end of each hold, wrist error),
  and the simulation speed;
- ``frames.png``: noisy structured-light depth frames of a hand among YCB-like objects from
  random viewpoints, coloured by segmentation (shade = depth), keypoints drawn as filled dots
  when visible and as crosses when occluded (red: by an object, yellow: by the hand itself);
- ``frame_panels.png``: the first of those frames as depth (colour map with a scale bar in
  metres) beside its segmentation with the skeleton (:func:`handsim.viz.draw_frame_panels`).

``handsim demo`` also writes ``teleop/``: a small teleoperation sweep on ``Press-v0`` (noise 0
and 10 mm x latency 0 and 3 frames; :mod:`handsim.envs.teleop.sweep`) with its table and plots.

Progress bars (rate, ETA) go to stderr; ``summary.json`` is strict JSON (``null``, never ``NaN``).

Runs headless (``MUJOCO_GL=egl``) with nothing downloaded.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from handsim.cli._args import add_quiet, integer, non_negative_int, progress_bar, strict_json
from handsim.frame import FrameRenderer
from handsim.hand.model import HAND_SIZES, Hand, HandParams
from handsim.hand.pose_sources import gesture, smooth_motion
from handsim.world.camera import camera_preset
from handsim.world.scene import Scene, SceneSpec, sample_placements, sample_viewpoint
from handsim.world.sensors import StructuredLight

# OpenCV, SciPy's rotations and handsim.viz load when the demo runs: `handsim` builds every
# command's parser, and a `handsim generate` should not pay for them.

__all__ = ["DEMO_GESTURES", "DEMO_GRASP_OBJECTS", "run_demo", "add_parser"]

DEMO_GESTURES: tuple[str, ...] = (
    "open",
    "fist",
    "point",
    "pinch",
    "ok",
    "thumbs_up",
    "victory",
    "spread",
    "relaxed",
)
_CONTROL_DT = 0.01  # s, target update period
_HOLD_S = 0.4
_WRIST_POS = np.array([0.0, 0.0, 0.3])


def _hand_frame_rotation_rotvec() -> np.ndarray:
    from scipy.spatial.transform import Rotation

    # Fingers up, palm toward the camera at -y: hand x (radial) -> world +x, y (distal) ->
    # world +z, z (palmar) -> world -y.
    columns = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]).T
    return Rotation.from_matrix(columns).as_rotvec()


@dataclasses.dataclass
class _HandRun:
    label: str
    params: HandParams
    build_s: float
    mass_kg: float
    frames: list[np.ndarray]
    joint_error_deg: list[float]
    wrist_error_mm: list[float]
    sim_s: float
    wall_s: float


def _scene(hand: Hand, width: int, height: int) -> mujoco.MjSpec:
    spec = mujoco.MjSpec()
    spec.modelname = "demo"
    spec.visual.global_.offwidth = width
    spec.visual.global_.offheight = height
    spec.worldbody.add_light(pos=[0.0, -0.6, 0.8], dir=[0.0, 0.6, -0.5], diffuse=[0.7, 0.7, 0.7])
    spec.worldbody.add_light(pos=[0.0, -0.8, 0.3], dir=[0.0, 1.0, 0.0], diffuse=[0.4, 0.4, 0.4])
    spec.worldbody.add_camera(
        name="front", pos=[0.0, -0.5, 0.39], xyaxes=[1, 0, 0, 0, 0, 1], fovy=40.0
    )
    hand.attach_to(spec)
    return spec


def _play(params: HandParams, gestures: Sequence[str], width: int, height: int) -> _HandRun:
    start = time.perf_counter()
    hand = Hand(params)
    build_s = time.perf_counter() - start
    model = _scene(hand, width, height).compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    renderer = mujoco.Renderer(model, height, width)

    rotvec = _hand_frame_rotation_rotvec()
    keyframes = [
        gesture(name).replace(wrist_pos=_WRIST_POS, wrist_rotvec=rotvec) for name in gestures
    ]
    if params.side == "left":
        keyframes = [k.mirrored() for k in keyframes]
    binding.set_pose(data, keyframes[0])

    steps_per_control = round(_CONTROL_DT / model.opt.timestep)
    frames, joint_err, wrist_err = [], [], []
    wall = time.perf_counter()
    previous = keyframes[0]
    for key in keyframes:
        motion = smooth_motion([previous, key], _CONTROL_DT)
        hold = int(round(_HOLD_S / _CONTROL_DT))
        targets = [motion[i] for i in range(motion.batch_shape[0])] + [key] * hold
        for target in targets:
            binding.set_target(data, target)
            mujoco.mj_step(model, data, nstep=steps_per_control)
        reached = binding.pose(data)
        joint_err.append(float(np.rad2deg(np.abs(reached.angles - key.angles)).max()))
        wrist_err.append(float(1000 * np.linalg.norm(reached.wrist_pos - key.wrist_pos)))
        renderer.update_scene(data, camera="front")
        frames.append(renderer.render().copy())
        previous = key
    wall_s = time.perf_counter() - wall
    renderer.close()
    mass = float(model.body_subtreemass[model.body(hand.root_body).id])
    label = f"{params.side} {params.hand_length * 1000:.0f} mm"
    return _HandRun(label, params, build_s, mass, frames, joint_err, wrist_err, data.time, wall_s)


_FRAME_OBJECTS = ("005_tomato_soup_can", "003_cracker_box", "025_mug", "011_banana")
_FRAME_GESTURES = ("open", "pinch", "point", "fist", "ok", "relaxed", "victory", "spread")


def _labelled_frames(seed: int = 0, bar=None) -> tuple[np.ndarray, dict, np.ndarray]:
    """Noisy labelled frames of a hand among objects, their statistics, the first one's panels."""
    from handsim.viz import draw_frame, draw_frame_panels

    rng = np.random.default_rng(seed)
    intrinsics = camera_preset("icvl")
    placements = sample_placements(rng, _FRAME_OBJECTS)
    tiles, visible, total, panels = [], 0, 0, None
    for i, name in enumerate(_FRAME_GESTURES):
        camera = sample_viewpoint(rng, intrinsics, name="view", distance_range_m=(0.45, 0.7))
        scene = Scene(SceneSpec(objects=placements, cameras=(camera,)))
        # Palm down over the objects, fingers toward +y.
        pose = gesture(name).replace(
            wrist_pos=np.array([0.0, -0.08 + 0.01 * i, 0.14]), wrist_rotvec=np.array([0, np.pi, 0])
        )
        scene.reset(pose)
        with FrameRenderer(scene, "view", StructuredLight()) as renderer:
            frame = renderer.render(rng)
        tiles.append(draw_frame(frame))
        if panels is None:
            panels = draw_frame_panels(frame)
        visible += int(frame.visible.sum())
        total += int(frame.in_frame.sum())
        if bar is not None:
            bar.update(1)
    rows = [np.hstack(tiles[:4]), np.hstack(tiles[4:])]
    stats = {"frames": len(tiles), "keypoints_in_frame": total, "keypoints_visible": visible}
    return np.vstack(rows), stats, panels


def run_demo(
    out_dir: str | Path = "handsim-demo",
    *,
    width: int = 200,
    height: int = 200,
    progress: bool = False,
) -> dict:
    """Run the demo and write its outputs.

    Args:
        out_dir: output folder (created if missing).
        width: width of each rendered frame, pixels.
        height: height of each rendered frame, pixels.
        progress: show progress bars (rate, ETA) on stderr.

    Returns:
        The summary that is also written to ``summary.json``.
    """
    import cv2

    from handsim.viz import contact_sheet, frame_legend

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    hands = [(length, side) for length in HAND_SIZES.values() for side in ("right", "left")]
    runs = []
    with progress_bar(len(hands), "demo: hands", "hand", enabled=progress) as bar:
        for length, side in hands:
            runs.append(
                _play(HandParams(hand_length=length, side=side), DEMO_GESTURES, width, height)
            )
            bar.update(1)
    sheet = contact_sheet([r.frames for r in runs], [r.label for r in runs], DEMO_GESTURES)
    cv2.imwrite(str(out / "gestures.png"), sheet)

    summary = {
        "gestures": list(DEMO_GESTURES),
        "hold_s": _HOLD_S,
        "hands": [
            {
                "label": r.label,
                "hand_length_m": r.params.hand_length,
                "side": r.params.side,
                "mass_kg": round(r.mass_kg, 4),
                "build_ms": round(1000 * r.build_s, 2),
                "max_joint_error_deg_after_hold": round(max(r.joint_error_deg), 3),
                "max_wrist_error_mm_after_hold": round(max(r.wrist_error_mm), 3),
                "sim_s": round(r.sim_s, 3),
                "realtime_factor": round(r.sim_s / r.wall_s, 2),
            }
            for r in runs
        ],
    }
    n_frames = len(_FRAME_GESTURES)
    with progress_bar(n_frames, "demo: labelled frames", "frame", enabled=progress) as bar:
        frames, frame_stats, panels = _labelled_frames(bar=bar)
    cv2.imwrite(str(out / "frames.png"), np.vstack([frames, frame_legend(frames.shape[1])]))
    cv2.imwrite(str(out / "frame_panels.png"), panels)
    summary["labelled_frames"] = frame_stats
    (out / "summary.json").write_text(strict_json(summary))
    lines = [
        "handsim demo: gesture sequence under physics (soft wrist weld, position-actuated fingers)",
        f"gestures: {', '.join(DEMO_GESTURES)} (hold {_HOLD_S} s each)",
        "",
        f"{'hand':<16}{'mass kg':>9}{'build ms':>10}{'joint err deg':>15}{'wrist err mm':>14}"
        f"{'x realtime':>12}",
    ]
    for h in summary["hands"]:
        lines.append(
            f"{h['label']:<16}{h['mass_kg']:>9.3f}{h['build_ms']:>10.1f}"
            f"{h['max_joint_error_deg_after_hold']:>15.2f}{h['max_wrist_error_mm_after_hold']:>14.2f}"
            f"{h['realtime_factor']:>12.1f}"
        )
    lines += [
        "",
        f"labelled noisy depth frames: {frame_stats['frames']} views, "
        f"{frame_stats['keypoints_visible']} of {frame_stats['keypoints_in_frame']} keypoints "
        "in view are visible",
        "",
        f"contact sheet: {out / 'gestures.png'}",
        f"depth frames: {out / 'frames.png'}, {out / 'frame_panels.png'}",
    ]
    (out / "summary.txt").write_text("\n".join(lines) + "\n")
    return summary


DEMO_GRASP_OBJECTS = ("005_tomato_soup_can", "006_mustard_bottle", "025_mug")
"""Objects of the demo's closed-loop evaluation on ``handsim/Grasp-v0``."""


def _demo_closed_loop(out: Path, episodes: int, progress: bool = False) -> dict:
    """The oracle (10 mm noise on keypoints and object position) in the loop of Grasp-v0."""
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)
    from handsim.envs.closed_loop import evaluate_closed_loop, write_report
    from handsim.estimators import OracleEstimator

    env_id = "handsim/Grasp-v0"
    total = 2 * episodes * (gym.spec(env_id).max_episode_steps or 0)
    with progress_bar(total, "demo: closed loop", "step", enabled=progress) as bar:
        report = evaluate_closed_loop(
            env_id,
            lambda: OracleEstimator(noise_mm=10.0, object_noise_mm=10.0, rng=0),
            episodes=episodes,
            env_kwargs={"objects": list(DEMO_GRASP_OBJECTS), "sensor": "structured_light"},
            progress=bar.update,
            media_dir=out / "closed_loop",
        )
    report["estimator"] = {"name": "oracle", **report["estimator"]}
    paths = write_report(report, out / "closed_loop")
    return {"report": report, "paths": {k: str(v) for k, v in paths.items()}}


def _demo_learned_loop(out: Path, episodes: int, progress: bool = False) -> dict:
    """The shipped DeepPrior++ (with the refined localizer) in the loop of Grasp-v0."""
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)
    from handsim.envs.closed_loop import evaluate_closed_loop, write_report
    from handsim.estimators import DeepPriorEstimator

    env_id = "handsim/Grasp-v0"
    total = 2 * episodes * (gym.spec(env_id).max_episode_steps or 0)
    with progress_bar(total, "demo: closed loop, DeepPrior++", "step", enabled=progress) as bar:
        report = evaluate_closed_loop(
            env_id,
            lambda: DeepPriorEstimator("deepprior++", threads=1),
            episodes=episodes,
            env_kwargs={"objects": list(DEMO_GRASP_OBJECTS), "sensor": "structured_light"},
            progress=bar.update,
            media_dir=out / "closed_loop_deepprior++",
        )
    report["estimator"] = {"name": "deepprior++", **report["estimator"]}
    paths = write_report(report, out / "closed_loop_deepprior++")
    return {"report": report, "paths": {k: str(v) for k, v in paths.items()}}


def _demo_teleop(out: Path, episodes: int, progress: bool = False) -> dict:
    """A small teleop sweep on Press-v0: noise 0 and 10 mm x latency 0 and 3 frames, direct."""
    from handsim.envs.teleop.sweep import run_sweep, write_sweep

    with progress_bar(4 * episodes, "demo: teleop sweep", "episode", enabled=progress) as bar:
        report = run_sweep(
            "handsim/Press-v0",
            noise_mm=(0.0, 10.0),
            latency_frames=(0, 3),
            dropout=(0.0,),
            filters=("none",),
            episodes=episodes,
            env_kwargs={"task": "button"},
            progress=bar.update,
        )
    paths = write_sweep(report, out / "teleop")
    return {"report": report, "paths": {k: str(v) for k, v in paths.items()}}


def _demo_dataset(folder: Path, frames: int, *, progress: bool) -> dict:
    """A small occlusion-heavy dataset (the preset, noisy depth) and its occlusion histogram."""
    from handsim.data.generation import PRESETS, GenerationConfig, generate

    config = GenerationConfig.from_mapping(
        PRESETS["occlusion-heavy"], frames=frames, frames_per_shard=max(1, frames // 2)
    )
    bar = progress_bar(frames, "occlusion-heavy dataset", "frame", enabled=progress)
    done = [0]

    def advance(n: int, _total: int) -> None:
        bar.update(n - done[0])
        done[0] = n

    try:
        manifest = generate(config, folder, workers=2, progress=advance)
    finally:
        bar.close()
    size = sum(s.bytes for s in manifest.shards.values())
    return {
        "path": str(folder),
        "frames": manifest.frames,
        "shards": len(manifest.shards),
        "bytes_per_frame": size / max(1, manifest.frames),
        "occlusion_histogram": manifest.occlusion_histogram,
    }


def _run(args: argparse.Namespace) -> int:
    # The core demo (hands, frames) cannot import the envs (layers); the CLI adds the loop.
    summary = run_demo(args.out, width=args.size, height=args.size, progress=not args.quiet)
    out = Path(args.out)
    lines = [(out / "summary.txt").read_text().rstrip("\n"), ""]
    if args.closed_loop_episodes > 0:
        loop = _demo_closed_loop(out, args.closed_loop_episodes, progress=not args.quiet)
        summary["closed_loop"] = {
            name: {
                "success_rate": mode["success_rate"],
                "kp_mean_mm": mode["kp_mean_mm"],
                "f_tau_auc": mode["f_tau_auc"],
            }
            for name, mode in loop["report"]["modes"].items()
        }
        summary["closed_loop"]["paths"] = loop["paths"]
        lines.append(
            f"closed loop, handsim/Grasp-v0, oracle with 10 mm noise, "
            f"{args.closed_loop_episodes} episode(s) per mode on {', '.join(DEMO_GRASP_OBJECTS)}:"
        )
        for name, mode in loop["report"]["modes"].items():
            lines.append(
                f"  {name.replace('_', ' '):<13} success {100 * mode['success_rate']:5.1f} %, "
                f"mean keypoint error {mode['kp_mean_mm']:.1f} mm, F(tau) AUC "
                f"{mode['f_tau_auc']:.3f}"
            )
        lines.append(f"closed-loop plots: {loop['paths']['f_tau']}, {loop['paths']['success']}")
    if args.learned_episodes > 0:
        loop = _demo_learned_loop(out, args.learned_episodes, progress=not args.quiet)
        summary["closed_loop_deepprior++"] = {
            name: {
                "success_rate": mode["success_rate"],
                "kp_mean_mm": mode["kp_mean_mm"],
                "f_tau_auc": mode["f_tau_auc"],
                "estimator_time_mean_s": mode["estimator_time_mean_s"],
            }
            for name, mode in loop["report"]["modes"].items()
        }
        summary["closed_loop_deepprior++"]["paths"] = loop["paths"]
        lines.append(
            f"closed loop, handsim/Grasp-v0, shipped DeepPrior++ (learned, from the depth image), "
            f"{args.learned_episodes} episode(s) per mode:"
        )
        for name, mode in loop["report"]["modes"].items():
            lines.append(
                f"  {name.replace('_', ' '):<13} success {100 * mode['success_rate']:5.1f} %, "
                f"mean keypoint error {mode['kp_mean_mm']:.1f} mm, F(tau) AUC "
                f"{mode['f_tau_auc']:.3f}, {1000 * mode['estimator_time_mean_s']:.0f} ms/frame"
            )
        lines.append(f"DeepPrior++ closed-loop plots: {loop['paths']['f_tau']}")
    if args.teleop_episodes > 0:
        teleop = _demo_teleop(out, args.teleop_episodes, progress=not args.quiet)
        summary["teleop"] = {
            "rows": [
                {k: v for k, v in row.items() if k != "episodes_detail"}
                for row in teleop["report"]["rows"]
            ],
            "paths": teleop["paths"],
        }
        lines.append(
            f"teleop sweep, handsim/Press-v0 (press a button), direct mode, "
            f"{args.teleop_episodes} episode(s) per point:"
        )
        for row in teleop["report"]["rows"]:
            lines.append(
                f"  noise {row['noise_mm']:4.1f} mm, latency {row['latency_frames']} frames: "
                f"success {100 * row['success_rate']:5.1f} %, fingertip jitter "
                f"{row['jitter_mm']:.2f} mm, lag {row['lag_s']:.2f} s"
            )
        lines.append(
            f"teleop plots: {teleop['paths']['success_vs_noise']}, "
            f"{teleop['paths']['jitter_vs_noise']}"
        )
    if args.dataset_frames > 0:
        dataset = _demo_dataset(out / "dataset", args.dataset_frames, progress=not args.quiet)
        summary["dataset"] = dataset
        hist = dataset["occlusion_histogram"]
        lines.append(
            f"occlusion-heavy dataset: {dataset['frames']} frames in {dataset['shards']} shards, "
            f"{dataset['bytes_per_frame'] / 1000:.1f} kB per frame, at {dataset['path']}"
        )
        lines.append("  hand occlusion ratio   frames")
        for lo, hi, n in zip(hist["edges"][:-1], hist["edges"][1:], hist["counts"], strict=True):
            bar = "#" * round(40 * n / max(1, dataset["frames"]))
            lines.append(f"  {lo:4.2f} - {hi:4.2f}          {n:6d}  {bar}")
    (out / "summary.json").write_text(strict_json(summary))
    (out / "summary.txt").write_text("\n".join(lines) + "\n")
    print((out / "summary.txt").read_text(), end="")
    return 0 if summary["hands"] else 1


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``handsim demo`` to the program's subcommands."""
    demo = sub.add_parser(
        "demo",
        help="play gestures with hands of three sizes and both sides; write a contact sheet",
        description="Build hands of three sizes and both sides, play a gesture sequence under "
        "physics, render labelled noisy depth frames of a hand among objects, run the oracle "
        "estimator and the shipped DeepPrior++ in the loop of handsim/Grasp-v0 with feedback "
        "off and on, run a small teleop sweep on handsim/Press-v0, generate a small "
        "occlusion-heavy dataset, and write the contact sheets, plots, the dataset and a summary "
        "to the output folder.",
    )
    demo.add_argument("--out", default="handsim-demo", help="output folder (default: %(default)s)")
    demo.add_argument(
        "--size",
        # Each tile is rendered at this size; gestures.png holds 6 x 9 of them.
        type=integer(32, 1024),
        default=200,
        help="tile size in pixels, in [32, 1024] (default: 200)",
    )
    demo.add_argument(
        "--closed-loop-episodes",
        type=non_negative_int,
        default=3,
        help="episodes per feedback mode of the Grasp-v0 closed loop; 0 skips it (default: 3)",
    )
    demo.add_argument(
        "--learned-episodes",
        type=non_negative_int,
        default=1,
        help="episodes per feedback mode of the shipped DeepPrior++ in the Grasp-v0 closed "
        "loop; 0 skips it (default: 1)",
    )
    demo.add_argument(
        "--teleop-episodes",
        type=non_negative_int,
        default=1,
        help="episodes per point of the Press-v0 teleop sweep (noise 0 and 10 mm x latency 0 "
        "and 3 frames); 0 skips it (default: 1)",
    )
    demo.add_argument(
        "--dataset-frames",
        type=non_negative_int,
        default=200,
        help="frames of the occlusion-heavy dataset it generates; 0 skips it (default: 200)",
    )
    add_quiet(demo)
    demo.set_defaults(func=_run)
