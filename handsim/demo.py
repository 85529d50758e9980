"""``handsim demo``: hands of three sizes and both sides play a gesture sequence under physics.

Writes to the output folder:

- ``gestures.png``: contact sheet, one row per hand (size x side), one column per gesture,
  rendered at the end of each gesture's hold;
- ``summary.txt`` and ``summary.json``: per hand the model figures (mass, build time) and how
  well the physics hand tracked its targets (joint error at the end of each hold, wrist error),
  and the simulation speed;
- ``frames.png``: noisy structured-light depth frames of a hand among YCB-like objects from
  random viewpoints, coloured by segmentation (shade = depth), keypoints drawn as filled dots
  when visible and as crosses when occluded (red: by an object, yellow: by the hand itself).

Runs headless (``MUJOCO_GL=egl``) with nothing downloaded.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Sequence
from pathlib import Path

import cv2
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from handsim.camera import camera_preset
from handsim.frame import OCCLUDER_SELF, Frame, FrameRenderer
from handsim.hand import HAND_SIZES, Hand, HandParams
from handsim.pose_sources import gesture, smooth_motion
from handsim.scene import Scene, SceneSpec, sample_placements, sample_viewpoint
from handsim.sensors import StructuredLight

__all__ = ["DEMO_GESTURES", "run_demo"]

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


def _hand_frame_rotation() -> Rotation:
    # Fingers up, palm toward the camera at -y: hand x (radial) -> world +x, y (distal) ->
    # world +z, z (palmar) -> world -y.
    columns = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]).T
    return Rotation.from_matrix(columns)


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

    rotvec = _hand_frame_rotation().as_rotvec()
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


def _contact_sheet(runs: Sequence[_HandRun], gestures: Sequence[str]) -> np.ndarray:
    rows = []
    for run in runs:
        tiles = []
        for name, frame in zip(gestures, run.frames, strict=True):
            tile = cv2.cvtColor(frame, cv2.COLOR_RGB2BGR)
            cv2.putText(tile, name, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
            tiles.append(tile)
        row = np.hstack(tiles)
        cv2.putText(
            row, run.label, (6, row.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 255), 1
        )
        rows.append(row)
    return np.vstack(rows)


_FRAME_OBJECTS = ("005_tomato_soup_can", "003_cracker_box", "025_mug", "011_banana")
_FRAME_GESTURES = ("open", "pinch", "point", "fist", "ok", "relaxed", "victory", "spread")
# BGR colour per segmentation label: background, table, palm, thumb..little, then objects.
_LABEL_BGR = np.array(
    [
        (0, 0, 0), (90, 90, 90), (60, 180, 230), (40, 120, 255), (60, 220, 120),
        (230, 200, 60), (230, 120, 200), (160, 100, 240),
        (80, 80, 230), (230, 90, 70), (70, 200, 200), (200, 200, 70), (150, 230, 150),
    ],
    dtype=np.float64,
)  # fmt: skip


def _frame_tile(frame: Frame) -> np.ndarray:
    labels = np.minimum(frame.segmentation, len(_LABEL_BGR) - 1)
    depth = frame.depth
    valid = depth > 0
    near, far = np.percentile(depth[valid], [2, 98]) if valid.any() else (0.0, 1.0)
    shade = 1.0 - 0.6 * np.clip((depth - near) / max(far - near, 1e-6), 0.0, 1.0)
    tile = (_LABEL_BGR[labels] * shade[..., None] * valid[..., None]).astype(np.uint8)
    for k in range(21):
        if not frame.in_frame[k]:
            continue
        u, v = (int(round(c)) for c in frame.keypoints_px[k])
        if frame.visible[k]:
            cv2.circle(tile, (u, v), 3, (255, 255, 255), -1)
        else:
            colour = (0, 255, 255) if frame.occluder[k] == OCCLUDER_SELF else (0, 0, 255)
            cv2.drawMarker(tile, (u, v), colour, cv2.MARKER_TILTED_CROSS, 8, 2)
    return tile


def _labelled_frames(seed: int = 0) -> tuple[np.ndarray, dict]:
    """Noisy labelled frames of a hand among objects, and their visibility statistics."""
    rng = np.random.default_rng(seed)
    intrinsics = camera_preset("icvl")
    placements = sample_placements(rng, _FRAME_OBJECTS)
    tiles, visible, total = [], 0, 0
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
        tiles.append(_frame_tile(frame))
        visible += int(frame.visible.sum())
        total += int(frame.in_frame.sum())
    rows = [np.hstack(tiles[:4]), np.hstack(tiles[4:])]
    stats = {"frames": len(tiles), "keypoints_in_frame": total, "keypoints_visible": visible}
    return np.vstack(rows), stats


def run_demo(out_dir: str | Path = "handsim-demo", *, width: int = 200, height: int = 200) -> dict:
    """Run the demo and write its outputs.

    Args:
        out_dir: output folder (created if missing).
        width: width of each rendered frame, pixels.
        height: height of each rendered frame, pixels.

    Returns:
        The summary that is also written to ``summary.json``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    runs = [
        _play(HandParams(hand_length=length, side=side), DEMO_GESTURES, width, height)
        for length in HAND_SIZES.values()
        for side in ("right", "left")
    ]
    sheet = _contact_sheet(runs, DEMO_GESTURES)
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
    frames, frame_stats = _labelled_frames()
    cv2.imwrite(str(out / "frames.png"), frames)
    summary["labelled_frames"] = frame_stats
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
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
        f"depth frames: {out / 'frames.png'}",
    ]
    (out / "summary.txt").write_text("\n".join(lines) + "\n")
    return summary
