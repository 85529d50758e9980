"""`handsim teleop` and `handsim view` from the command line: help, a replay, errors."""

import json
import subprocess
import sys

import pytest

from handsim.cli import main


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["teleop", "--help"], ["replay", "live", "sweep", "generate", "send", "serve"]),
        (
            ["teleop", "replay", "--help"],
            [
                "--noise-mm",
                "--latency",
                "--dropout",
                "--filter",
                "one_euro",
                "--mode",
                "direct, camera",
                "--anchor",
                "hold, extrapolate",
                "--rollout",
            ],
        ),
        (
            ["teleop", "live", "--help"],
            ["--udp", "--websocket", "--host", "127.0.0.1", "--duration"],
        ),
        (
            ["teleop", "sweep", "--help"],
            ["--noise-mm", "0,5,10", "--filters", "none,one_euro", "--episodes", "--out"],
        ),
        (["teleop", "serve", "--help"], ["--port", "--websocket", "--replay"]),
        (["view", "--help"], ["--out", ".mp4 or .gif", "--every", "--rerun"]),
    ],
)
def test_help_lists_options_and_valid_values(argv, expected):
    """Every command's --help lists its options with their valid values."""
    out = subprocess.run(
        [sys.executable, "-m", "handsim.cli", *argv], capture_output=True, text=True, check=True
    ).stdout
    for text in expected:
        assert text in out, text


def test_generate_replay_and_view(tmp_path, capsys):
    """A generated stream replays through the loop from the CLI, and its rollout plays back."""
    stream = tmp_path / "press.npz"
    assert main(["teleop", "generate", str(stream), "--task", "press", "--seed", "1"]) == 0
    rollout = tmp_path / "roll.npz"
    args = [
        "teleop",
        "replay",
        str(stream),
        "--task",
        "press",
        "--seed",
        "1",
        "--out",
        str(tmp_path / "out"),
        "--rollout",
        str(rollout),
        "--filter",
        "one_euro",
    ]
    assert main(args) == 0
    metrics = json.loads((tmp_path / "out" / "teleop.json").read_text())
    assert metrics["success"] is True and metrics["env_id"] == "handsim/Press-v0"
    assert (
        main(["view", str(rollout), "--out", str(tmp_path / "v.gif"), "--every", "10", "--quiet"])
        == 0
    )
    assert (tmp_path / "v.gif").stat().st_size > 1000
    assert "success" in capsys.readouterr().out


def test_replay_a_headset_recording_in_openxr_format(tmp_path, capsys):
    """An OpenXR-26 file (y up, millimetres, the headset's own origin) replays and presses."""
    import numpy as np

    from handsim.envs.teleop import stream_from_expert
    from handsim.hand.keypoints import to_format
    from handsim.hand.kinematics import ForwardKinematics
    from handsim.hand.model import hand_params
    from handsim.hand.pose import HandPose

    stream = stream_from_expert("handsim/Press-v0", 2, env_kwargs={"task": "button"})
    points = ForwardKinematics(hand_params("medium")).points(HandPose.from_vector(stream.poses))
    xr = to_format(points, "openxr26")
    y_up = xr @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T + [0.2, 1.1, -0.4]
    frames = [
        {"t": 0.011 * i, "keypoints": (1e3 * f).round(3).tolist(), "radii": [8.0] * 26}
        for i, f in enumerate(y_up)
    ]
    path = tmp_path / "quest.json"
    path.write_text(json.dumps({"format": "openxr26", "units": "mm", "frames": frames}))
    out = tmp_path / "out"
    assert (
        main(["teleop", "replay", str(path), "--task", "press", "--seed", "2", "--out", str(out)])
        == 0
    )
    metrics = json.loads((out / "teleop.json").read_text())
    assert metrics["success"] and metrics["unintended_presses"] == 0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["teleop", "replay", "missing.json"], "does not exist"),
        (["view", "missing.npz"], "rollout 'missing.npz' does not exist"),
    ],
)
def test_errors_are_one_line(argv, message, capsys):
    """Bad input ends with status 2 and one line naming the problem."""
    assert main(argv) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["teleop", "replay", "x.json", "--filter", "kalman"], "unknown filter 'kalman'"),
        (["teleop", "replay", "x.json", "--task", "door"], "unknown task 'door'"),
        (["teleop", "replay", "x.json", "--dropout", "2"], "expected a number in [0, 1]"),
        (["teleop", "live"], "one of the arguments --udp --websocket is required"),
        (["teleop", "sweep", "--latency", "0,x"], "--latency"),
    ],
)
def test_bad_options_are_usage_errors(argv, message, capsys):
    """Invalid option values are argparse usage errors listing what is valid."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert message in capsys.readouterr().err
