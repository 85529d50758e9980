"""The demo (the README's main job) runs headless and writes its outputs."""

import json

import cv2
import numpy as np

from handsim.cli.demo import DEMO_GESTURES, run_demo
from handsim.hand.model import HAND_SIZES
from handsim.viz import SCALE_BAR_WIDTH, frame_legend


def test_demo_writes_contact_sheet_and_summary(tmp_path):
    """Gesture contact sheet (6 hands), noisy labelled depth frames, and a consistent summary."""
    summary = run_demo(tmp_path, width=48, height=48)
    sheet = cv2.imread(str(tmp_path / "gestures.png"))
    rows, cols = 2 * len(HAND_SIZES), len(DEMO_GESTURES)
    assert sheet.shape == (rows * 48, cols * 48, 3)
    assert sheet.std() > 10  # rendered hands, not a blank image
    assert json.loads((tmp_path / "summary.json").read_text()) == summary
    assert "contact sheet" in (tmp_path / "summary.txt").read_text()
    frames = cv2.imread(str(tmp_path / "frames.png"))
    legend = frame_legend(4 * 320)  # the key of the marks and colours, under the frames
    assert frames.shape == (2 * 240 + len(legend), 4 * 320, 3) and frames.std() > 10
    assert np.array_equal(frames[2 * 240 :], legend)
    panels = cv2.imread(str(tmp_path / "frame_panels.png"))
    assert panels.shape == (240, 2 * 320 + SCALE_BAR_WIDTH, 3) and panels.std() > 10
    stats = summary["labelled_frames"]
    assert stats["frames"] == 8 and 0 < stats["keypoints_visible"] <= stats["keypoints_in_frame"]
    assert len(summary["hands"]) == rows
    for hand in summary["hands"]:
        # Holds end with every joint near its target (contacts in fist/pinch stop a few deg
        # short) and the wrist on its mocap target.
        assert hand["max_joint_error_deg_after_hold"] < 10.0
        assert hand["max_wrist_error_mm_after_hold"] < 5.0


def test_demo_command_adds_the_closed_loop(tmp_path, capsys):
    """`handsim demo` also runs the oracle in the loop of Grasp-v0 and writes its plots."""
    from handsim.cli import main

    out = tmp_path / "demo"
    args = ["--size", "32", "--closed-loop-episodes", "1", "--dataset-frames", "4"]
    args += ["--learned-episodes", "1"]
    assert main(["demo", "--out", str(out), *args]) == 0
    text = (out / "summary.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    summary = json.loads(text)
    loop = summary["closed_loop"]
    assert set(loop) == {"feedback_off", "feedback_on", "paths"}
    assert 8 < loop["feedback_off"]["kp_mean_mm"] < 25  # 10 mm per axis: ~16 mm in 3D
    for kind in ("json", "f_tau", "success"):
        assert cv2.haveImageReader(loop["paths"][kind]) or kind == "json"
    captured = capsys.readouterr()
    assert "closed loop, handsim/Grasp-v0" in captured.out
    for bar in ("demo: hands", "demo: labelled frames", "demo: closed loop"):
        assert bar in captured.err  # tqdm progress bars with rate and ETA
    assert "<" in captured.err and "/s" in captured.err
    assert (out / "closed_loop" / "worst_frame_feedback_off.png").exists()
    # The shipped DeepPrior++ in the same loop: keypoints from the depth image alone.
    learned = summary["closed_loop_deepprior++"]
    assert set(learned) == {"feedback_off", "feedback_on", "paths"}
    assert 0 < learned["feedback_off"]["kp_mean_mm"] < 200
    assert "shipped DeepPrior++" in captured.out
    # The occlusion-heavy dataset: complete, and its histogram printed.
    dataset = summary["dataset"]
    assert dataset["frames"] == 4 and sum(dataset["occlusion_histogram"]["counts"]) == 4
    assert (out / "dataset" / "manifest.json").exists()
    assert "occlusion-heavy dataset: 4 frames" in captured.out
    # The teleop sweep: 2 noise levels x 2 latencies, its table and plot.
    rows = summary["teleop"]["rows"]
    assert [(r["noise_mm"], r["latency_frames"]) for r in rows] == [
        (0.0, 0),
        (0.0, 3),
        (10.0, 0),
        (10.0, 3),
    ]
    assert rows[0]["success_rate"] == 1.0
    assert (out / "teleop" / "success_vs_noise.png").exists()
    assert "teleop sweep, handsim/Press-v0" in captured.out
    assert "hand occlusion ratio" in captured.out
