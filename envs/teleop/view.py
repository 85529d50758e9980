"""Play a recorded teleop rollout back as a video (``handsim view``).

Each video frame puts two panels side by side: on the left the capture camera's depth (camera
mode; colour-mapped, :func:`handsim.viz.depth_colormap`) with the operator's true skeleton
(green) and the estimate (magenta); in direct mode, where nothing was captured, the operator's
(green) and the tracked (magenta, after faults and filter) skeletons projected into the task's
camera on a dark panel. On the right, a colour view of the physical scene, re-rendered from
the recorded states (the env is rebuilt from the rollout's id, arguments and seed).
"""

from __future__ import annotations

import pathlib
from collections.abc import Callable
from typing import Any

import cv2
import gymnasium as gym
import mujoco
import numpy as np

from handsim import viz
from handsim.envs.teleop.loop import read_rollout
from handsim.envs.teleop.streams import InvalidStream

__all__ = ["render_rollout", "VIDEO_SUFFIXES", "log_rollout_rerun"]

VIDEO_SUFFIXES: tuple[str, ...] = (".mp4", ".gif")
_PANEL = (320, 240)


def _project(K: np.ndarray, T: np.ndarray, points_world: np.ndarray) -> np.ndarray:  # noqa: N803
    cam = points_world @ T[:3, :3].T + T[:3, 3]
    return viz.project_points(K, cam)


def render_rollout(
    rollout: str | pathlib.Path,
    out: str | pathlib.Path,
    *,
    fps: float | None = None,
    every: int = 1,
    progress: Callable[[int], None] | None = None,
) -> pathlib.Path:
    """Render a rollout of :func:`~handsim.envs.teleop.loop.write_rollout` to MP4 or GIF.

    Args:
        rollout: the ``.npz`` rollout.
        out: the video path, ``.mp4`` (needs ``handsim[video]``) or ``.gif``.
        fps: frames per second (default: the control rate divided by ``every``).
        every: draw every ``every``-th step.
        progress: called with 1 per drawn frame.

    Returns:
        The video's path.

    Raises:
        InvalidStream: for an unreadable rollout or an unknown video suffix.
    """
    out_path = pathlib.Path(out)
    if out_path.suffix.lower() not in VIDEO_SUFFIXES:
        raise InvalidStream(
            f"the video must end in {' or '.join(VIDEO_SUFFIXES)}; received {out_path.name!r}"
        )
    if not isinstance(every, int) or every < 1:
        raise InvalidStream(f"every must be an int >= 1; received {every!r}")
    meta, arrays = read_rollout(rollout)
    import handsim.envs  # noqa: F401 (registers the ids)

    kwargs = {
        **meta["env_kwargs"],
        "render_mode": "rgb_array",
        "render_width": _PANEL[0],
        "render_height": _PANEL[1],
    }
    env = gym.make(meta["env_id"], **kwargs)
    frames = []
    try:
        env.reset(seed=meta["seed"])
        base = env.unwrapped
        model, data = base.scene.model, base.scene.data
        if arrays["qpos"].shape[1] != model.nq:
            raise InvalidStream(
                f"rollout {rollout}: qpos has {arrays['qpos'].shape[1]} values, "
                f"the rebuilt scene {model.nq}"
            )
        camera_mode = "depth_mm" in arrays
        if not camera_mode:
            from handsim.world.camera import T_cam_from_world

            cam_id = model.camera("camera").id
            T = T_cam_from_world(data, cam_id)  # noqa: N806
            K = base.intrinsics.K  # noqa: N806
            size = (base.intrinsics.width, base.intrinsics.height)
        n = len(arrays["qpos"])
        depth_range = None
        if camera_mode:
            # One colour range for the video, around the operator hand.
            z = arrays["truth_cam"][..., 2]
            z = z[np.isfinite(z)]
            depth_range = (max(float(z.min()) - 0.1, 0.05), float(z.max()) + 0.2)
        for t in range(0, n, every):
            data.qpos[:] = arrays["qpos"][t]
            data.mocap_pos[:] = arrays["mocap_pos"][t]
            data.mocap_quat[:] = arrays["mocap_quat"][t]
            mujoco.mj_forward(model, data)
            colour = np.ascontiguousarray(env.render()[..., ::-1])
            if camera_mode:
                depth = arrays["depth_mm"][t].astype(np.float32) * 1e-3
                near, far = depth_range
                left = viz.depth_colormap(depth, near_m=near, far_m=far, scale_bar=False)
                K = arrays["K"]  # noqa: N806
                truth = viz.project_points(K, arrays["truth_cam"][t])
                estimate = viz.project_points(K, arrays["estimate_cam"][t])
                top = "capture depth"
            else:
                left = np.full((size[1], size[0], 3), 30, np.uint8)
                truth = _project(K, T, arrays["operator_world"][t])
                estimate = _project(K, T, arrays["tracked_world"][t])
                top = "direct (no capture)"
            pairs = [(truth, estimate)]
            if not camera_mode and "operator_world_left" in arrays:  # a two-hand rollout
                pairs.append(
                    (
                        _project(K, T, arrays["operator_world_left"][t]),
                        _project(K, T, arrays["tracked_world_left"][t]),
                    )
                )
            # Black borders (the estimate's under the truth) keep both visible on the colour map.
            border = viz.OUTLINE_BGR
            for truth, estimate in pairs:
                left = viz.draw_skeleton(left, estimate, colour=border, thickness=3, radius=4)
                left = viz.draw_skeleton(left, truth, colour=viz.TRUTH_BGR, outline=border)
                left = viz.draw_skeleton(left, estimate, colour=viz.ESTIMATE_BGR)
            left = cv2.resize(left, _PANEL, interpolation=cv2.INTER_NEAREST)
            text = [top, "green: operator", "magenta: tracked"]
            for i, line in enumerate(text):
                cv2.putText(
                    left,
                    line,
                    (5, 14 + 14 * i),
                    cv2.FONT_HERSHEY_SIMPLEX,
                    0.4,
                    (255, 255, 255),
                    1,
                    cv2.LINE_AA,
                )
            state = "success" if arrays["success"][t] else ""
            cv2.putText(
                colour,
                f"t = {t * meta['control_dt_s']:.2f} s {state}",
                (5, 14),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.4,
                (0, 0, 0),
                1,
                cv2.LINE_AA,
            )
            frames.append(np.concatenate([left, colour], axis=1))
            if progress is not None:
                progress(1)
    finally:
        env.close()
    rate = fps if fps is not None else 1.0 / (meta["control_dt_s"] * every)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    if out_path.suffix.lower() == ".mp4":
        with viz.VideoWriter(out_path, fps=rate) as writer:
            for frame in frames:
                writer.append(frame)
    else:
        from PIL import Image

        images = [Image.fromarray(f[..., ::-1]) for f in frames]
        images[0].save(
            out_path,
            save_all=True,
            append_images=images[1:],
            duration=int(round(1000 / rate)),
            loop=0,
        )
    return out_path


def log_rollout_rerun(rollout: str | pathlib.Path, out: str | pathlib.Path) -> pathlib.Path:
    """Log a rollout's 3D keypoints (operator, tracked, physical) to a rerun recording (.rrd).

    Needs the optional ``rerun-sdk`` package (``pip install 'handsim[rerun]'``).

    Raises:
        InvalidStream: without ``rerun-sdk`` or for an unreadable rollout.
    """
    try:
        import rerun as rr
    except ImportError:
        raise InvalidStream(
            "--rerun needs the optional 'rerun-sdk' package: pip install 'handsim[rerun]'"
        ) from None
    meta, arrays = read_rollout(rollout)
    rr.init("handsim_teleop", spawn=False)
    dt = meta["control_dt_s"]
    colours: dict[str, Any] = {
        "operator_world": [80, 220, 80],
        "tracked_world": [255, 80, 255],
        "physical_world": [80, 160, 255],
    }
    for t in range(len(arrays["qpos"])):
        rr.set_time("time", duration=t * dt)
        for key, colour in colours.items():
            pts = arrays[key][t]
            ok = np.all(np.isfinite(pts), axis=1)
            rr.log(f"hand/{key.removesuffix('_world')}", rr.Points3D(pts[ok], colors=colour))
    out_path = pathlib.Path(out)
    rr.save(str(out_path))
    return out_path
