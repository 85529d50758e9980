"""Render the depth pictures of docs/hand.md: the capsule look and the skin side by side.

Run: ``python docs/img/make_hand_images.py`` (writes ``docs/img/hand_*.png``).
"""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from handsim.hand.model import HandParams  # noqa: E402
from handsim.hand.pose_sources import gesture  # noqa: E402
from handsim.world.camera import CameraIntrinsics  # noqa: E402
from handsim.world.render import DepthRenderer  # noqa: E402
from handsim.world.scene import CameraSpec, Scene, SceneSpec  # noqa: E402

OUT = Path(__file__).parent
WRIST = np.array([0.0, -0.05, 0.25])
# (file suffix, gesture, wrist rotation vector, camera eye relative to the wrist)
VIEWS = (
    ("back", "open", (0.0, 0.0, 0.0), (0.0, 0.05, -0.40)),
    ("palm", "open", (0.0, 0.0, 0.0), (0.0, 0.05, 0.40)),
    ("fist", "fist", (0.0, 0.0, 0.0), (0.25, 0.05, -0.30)),
    ("pinch", "pinch", (0.0, 0.0, 0.0), (0.30, 0.10, -0.25)),
)


def _depth_image(surface: str, name: str, rotvec, eye) -> np.ndarray:
    intr = CameraIntrinsics(fx=600.0, fy=600.0, cx=160.0, cy=200.0, width=320, height=400)
    target = WRIST + np.array([0.0, 0.07, 0.0])
    cam = CameraSpec.look_at("cam", intr, tuple(WRIST + eye), tuple(target), up=(0.0, 1.0, 0.0))
    scene = Scene(SceneSpec(hand=HandParams(surface=surface), cameras=(cam,), table=False))
    pose = gesture(name).replace(wrist_pos=WRIST, wrist_rotvec=np.array(rotvec))
    scene.reset(pose)
    with DepthRenderer(scene.model, "cam", intr) as renderer:
        depth, _ = renderer.render(scene.data)
    seen = depth > 0
    # Shade the depth map by its surface normals (a light at the camera) so that relief shows;
    # the depth itself is what the camera measures, nothing else is drawn.
    fx = intr.fx
    dz_du = np.gradient(depth, axis=1) * fx / np.maximum(depth, 1e-6)
    dz_dv = np.gradient(depth, axis=0) * fx / np.maximum(depth, 1e-6)
    normal_z = 1.0 / np.sqrt(1.0 + dz_du**2 + dz_dv**2)
    lo, hi = depth[seen].min(), depth[seen].max()
    near = (hi - depth) / max(hi - lo, 1e-6)
    image = np.zeros(depth.shape, np.uint8)
    image[seen] = np.clip(30 + 170 * normal_z[seen] + 55 * near[seen], 0, 255).astype(np.uint8)
    return image


def main() -> None:
    """Write one side-by-side PNG (capsules | skin) per view."""
    for suffix, name, rotvec, eye in VIEWS:
        pair = [_depth_image(s, name, rotvec, np.array(eye)) for s in ("capsules", "skin")]
        sheet = np.concatenate([pair[0], np.full((pair[0].shape[0], 8), 255, np.uint8), pair[1]], 1)
        path = OUT / f"hand_{suffix}.png"
        cv2.imwrite(str(path), sheet)
        print(f"written: {path}")


if __name__ == "__main__":
    main()
