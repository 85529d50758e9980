"""`handsim closed-loop`: report files, strict JSON, plots, progress, MP4s with both skeletons."""

import json

import cv2
import pytest

from handsim.cli import main


def _strict(text):
    def refuse(constant):
        raise AssertionError(f"non-strict JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


def test_closed_loop_video_plots_and_strict_json(tmp_path, capsys):
    """--video: an MP4 per mode and episode, a frame per observation; plots; null, not NaN.

    The localizer has no keypoints, so its keypoint errors are null in the JSON.
    """
    imageio = pytest.importorskip("imageio.v2")
    status = main(
        ["closed-loop", "--env", "handsim/HandPose-v0", "--episodes", "1", "--sensor", "none"]
        + ["--estimator", "com", "--video", "--out", str(tmp_path)]
    )
    assert status == 0
    captured = capsys.readouterr()
    assert "closed loop" in captured.err and "step/s" in captured.err  # tqdm: rate
    summary = _strict(captured.out.split("\nwritten: ")[0])
    assert summary["feedback_off"]["kp_mean_mm"] is None
    text = (tmp_path / "closed_loop.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    report = _strict(text)
    assert report["estimator"]["name"] == "com"
    assert report["estimator"]["repr"].startswith("CenterOfMassLocalizer(cube_mm=")
    for kind in ("f_tau", "success", "error_over_time", "error_by_occlusion", "success_by_object"):
        image = cv2.imread(str(tmp_path / f"{kind}.png"))
        assert image is not None and image.std() > 5, kind
    for name, mode in report["modes"].items():
        (episode,) = mode["episodes"]
        (video,) = mode["media"]["videos"]
        path = tmp_path / "video" / f"{name}_ep000.mp4"
        assert video["path"] == str(path) and video["n_frames"] == episode["steps"] + 1
        reader = imageio.get_reader(str(path))
        frames = [f for f in reader]
        assert len(frames) == episode["steps"] + 1 == 151
        # 320x240 drawn at 2x: 640 + scale bar 56 = 696 columns, padded to 704.
        assert frames[0].shape[:2] == (480, 704)
        assert frames[0].std() > 10
        assert str(path) in captured.out
    assert mode["media"]["worst_frame"] is None  # no keypoints, no keypoint error


@pytest.mark.parametrize("name", ["deepprior", "deepprior++"])
def test_closed_loop_shipped_networks_by_name(tmp_path, name):
    """Both shipped pose networks run in the loop by their built-in names, as a user types them."""
    import subprocess
    import sys

    pytest.importorskip("torch")
    result = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "closed-loop", "--env", "handsim/HandPose-v0"]
        + ["--episodes", "1", "--sensor", "none", "--estimator", name, "-q"]
        + ["--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    report = _strict((tmp_path / "closed_loop.json").read_text())
    assert report["estimator"]["checkpoint"] == name
    mode = report["modes"]["feedback_off"]
    assert mode["n_frames_with_keypoints"] == mode["n_frames"] > 0
    assert mode["kp_mean_mm"] > 0 and mode["f_tau_auc"] is not None
