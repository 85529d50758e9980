"""The row of docs/feedback.md: input crop, rendered crop of DeepPrior++'s estimate, difference.

Run: ``python docs/img/make_feedback_images.py`` (writes ``docs/img/feedback_synth.png``): a
hand-only frame (third person, structured light, seed 11) generated on the fly, the shipped
DeepPrior++ and localizer, and handsim's renderer as the synthesizer (the paper's figure 5.2).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from handsim.data.generation import GenerationConfig, generate  # noqa: E402
from handsim.estimators import DeepPriorEstimator  # noqa: E402
from handsim.estimators.deepprior.data import load_frames  # noqa: E402
from handsim.estimators.deepprior.preprocess import (  # noqa: E402
    crop_depth,
    crop_matrix,
    normalize_keypoints,
)
from handsim.estimators.feedback.synth import RendererSynthesizer  # noqa: E402
from handsim.estimators.feedback.train import frame_sides  # noqa: E402

OUT = Path(__file__).parent


def _grey(crop: np.ndarray) -> np.ndarray:
    """Normalized depth [-1, 1] -> 8-bit, near bright, background black."""
    img = np.where(crop >= 1.0, 0, np.clip((1.0 - crop) * 127.5, 0, 255))
    return cv2.resize(img.astype(np.uint8), (256, 256), interpolation=cv2.INTER_NEAREST)


def main() -> None:
    """Write docs/img/feedback_synth.png (three 256 x 256 panels)."""
    with tempfile.TemporaryDirectory() as tmp:
        config = GenerationConfig(
            frames=4, frames_per_episode=1, seed=11, num_objects_range=(0, 0),
            viewpoints=("third_person",), sensor="structured_light",
        )  # fmt: skip
        generate(config, tmp)
        frames, sides = load_frames(tmp), frame_sides(tmp)
    est = DeepPriorEstimator()
    depth, K = frames.depth(0), frames.K[0]  # noqa: N806
    center = est.localizer.localize(depth, K)
    keypoints = est.predict_at(depth, K, center)
    crop = crop_depth(depth, crop_matrix(center, K), center[2])
    with RendererSynthesizer() as synth:
        pose = normalize_keypoints(keypoints, center, synth.cube_m).reshape(1, 63)
        rendered, _ = synth(pose, center[None], K, frames.hand_length_m[0], sides[:1])
    diff = np.abs(rendered[0] - crop)
    diff_img = cv2.resize(
        np.clip(diff * 255.0, 0, 255).astype(np.uint8), (256, 256), interpolation=cv2.INTER_NEAREST
    )
    row = np.hstack([_grey(crop), _grey(rendered[0]), diff_img])
    cv2.imwrite(str(OUT / "feedback_synth.png"), row)
    err = np.linalg.norm(keypoints - frames.keypoints_cam[0], axis=1).mean() * 1000
    print(f"DeepPrior++ error on this frame: {err:.1f} mm")


if __name__ == "__main__":
    main()
