"""`handsim teleop` and `handsim view` from the command line: help, a replay, errors."""

import json
import re
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
            ["--udp", "--websocket", "--host", "127.0.0.1", "--duration", "--hand"]
            + ["right, left", "--rate-hz", "--delay-ms", "--predict-ms", "--rollout"],
        ),
        (
            ["teleop", "sweep", "--help"],
            ["--noise-mm", "0,5,10", "--filters", "none,one_euro", "--episodes", "--out"]
            + ["--grasp-intent", "--pose-filter", "{on,off,wrist,auto}"],
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
    # Seed 1 of the random press task is a button or the slider: either reports its events.
    acts = [e for e in metrics["event_log"] if e["kind"] in ("button_press", "slider")]
    assert acts and 0 < acts[0]["t_s"] <= metrics["time_to_success_s"]
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
        (["teleop", "live", "--udp", "9000", "--rate-hz", "200"], "--rate-hz: expected a number"),
        (["teleop", "replay", "x.json", "--rate-hz", "0"], "--rate-hz: expected a number"),
        (["teleop", "live", "--udp", "9000", "--predict-ms", "500"], "--predict-ms"),
        (["teleop", "live", "--udp", "9000", "--predict-ms", "soon"], "or auto"),
        # 'both' is valid since two hands (live --hand both); any other side is not.
        (["teleop", "live", "--udp", "9000", "--hand", "middle"], "invalid choice: 'middle'"),
    ],
)
def test_bad_options_are_usage_errors(argv, message, capsys):
    """Invalid option values are argparse usage errors listing what is valid."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert message in capsys.readouterr().err


def _free_port(kind):
    import socket

    with socket.socket(socket.AF_INET, kind) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_serve_starts_and_serves_the_page_over_http(tmp_path):
    """`handsim teleop serve` runs (it crashed on an unknown keyword) and serves the page."""
    import socket
    import time
    import urllib.request

    port = _free_port(socket.SOCK_STREAM)
    proc = subprocess.Popen(
        [sys.executable, "-m", "handsim.cli", "teleop", "serve", "--port", str(port)]
        + ["--websocket", "8765", "--duration", "60"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        page = None
        for _ in range(300):
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2) as r:
                    page = r.read().decode()
                    break
            except OSError:
                if proc.poll() is not None:
                    break
                time.sleep(0.1)
        assert page is not None, proc.communicate(timeout=10)
        assert "<script" in page
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/config.json", timeout=2) as r:
            assert json.loads(r.read())["ws_port"] == 8765
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=30)
    assert f"http://127.0.0.1:{port}/" in out
    assert "Traceback" not in err


def test_live_runs_for_the_requested_duration_past_the_episode_limit(tmp_path):
    """`live --duration 6` on Press-v0 (a 5 s episode) runs 6 s, says so, reports latency."""
    import socket
    import threading

    from handsim.envs.teleop import stream_from_expert
    from handsim.envs.teleop.sender import send_stream

    stream = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
    port = _free_port(socket.SOCK_DGRAM)
    out = tmp_path / "out"
    rollout = tmp_path / "live.npz"
    proc = subprocess.Popen(
        [sys.executable, "-m", "handsim.cli", "teleop", "live", "--udp", str(port)]
        + ["--task", "press", "--duration", "6", "--wait", "60", "--out", str(out)]
        + ["--rollout", str(rollout), "--grasp-intent", "on", "--pose-filter", "wrist"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    done = threading.Event()

    def send():
        while not done.is_set() and proc.poll() is None:
            send_stream(stream, port)  # seq restarts each time: a new stream, followed

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        done.set()
        sender.join(timeout=10)
    assert proc.returncode == 0, stderr
    assert re.search(r"measured (49|50)\.\d Hz", stderr)
    assert "so that --duration 6 s runs in one episode" in stderr
    metrics = json.loads((out / "teleop.json").read_text())
    assert metrics["steps"] == 300 and metrics["control_dt_s"] == 0.02
    assert metrics["latency_clock"] == "unix"
    assert 0 < metrics["latency_p50_ms"] <= metrics["latency_p95_ms"] < 200
    assert "latency_p95_ms" in stdout
    # The options reach the loop; the panel has no objects to grasp.
    assert metrics["config"]["grasp_intent"] is True
    assert metrics["config"]["pose_filter"] == "wrist"
    assert metrics["intent_grasp_s"] == 0.0 and "intent_grasp_s" in stdout
    from handsim.envs.teleop import read_rollout

    meta, arrays = read_rollout(rollout)
    assert arrays["qpos"].shape[0] == 300 and meta["env_id"] == "handsim/Press-v0"
    video = tmp_path / "live.gif"  # the recorded session plays back
    assert main(["view", str(rollout), "--out", str(video), "--every", "50", "--quiet"]) == 0
    assert video.stat().st_size > 1000


def test_replay_and_sweep_take_the_grasp_intent_and_the_wrist_pose_filter(tmp_path):
    """`replay` and `sweep` with --grasp-intent on and --pose-filter wrist, as subprocesses.

    The expert's grasp replayed with the intent spends time in it; the sweep's table has the
    intent's columns and its report the settings.
    """
    stream = tmp_path / "grasp.npz"
    cli = [sys.executable, "-m", "handsim.cli", "teleop"]
    subprocess.run(
        [*cli, "generate", str(stream), "--task", "grasp"], check=True, capture_output=True
    )
    out = tmp_path / "replay"
    done = subprocess.run(
        [*cli, "replay", str(stream), "--task", "grasp", "--out", str(out)]
        + ["--grasp-intent", "on", "--pose-filter", "wrist"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    metrics = json.loads((out / "teleop.json").read_text())
    assert metrics["config"]["grasp_intent"] is True
    assert metrics["config"]["pose_filter"] == "wrist"
    assert metrics["intent_grasp_s"] > 0.5 and metrics["intent_onsets"] >= 1
    assert "intent_grasp_s" in done.stdout
    sweep = tmp_path / "sweep"
    done = subprocess.run(
        [*cli, "sweep", "--task", "press", "--noise-mm", "0", "--latency", "0"]
        + ["--dropout", "0", "--filters", "none", "--episodes", "1", "--quiet"]
        + ["--grasp-intent", "on", "--pose-filter", "wrist", "--out", str(sweep)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    report = json.loads((sweep / "sweep.json").read_text())
    assert report["grasp_intent"] is True and report["pose_filter"] == "wrist"
    assert report["rows"][0]["intent_grasp_s"] == 0.0
    assert "intent_s" in done.stdout


def test_replay_takes_the_closure_assist_and_refuses_it_without_the_intent(tmp_path):
    """`replay --grasp-intent on --closure-assist on` reports the assist; alone it is refused.

    With 5 mm of noise: the assist's gate keeps the intent off with clean tracking.
    """
    stream = tmp_path / "grasp.npz"
    cli = [sys.executable, "-m", "handsim.cli", "teleop"]
    subprocess.run(
        [*cli, "generate", str(stream), "--task", "grasp", "--seed", "8"],
        check=True,
        capture_output=True,
    )
    out = tmp_path / "replay"
    done = subprocess.run(
        [*cli, "replay", str(stream), "--task", "grasp", "--seed", "8", "--out", str(out)]
        + ["--grasp-intent", "on", "--closure-assist", "on", "--noise-mm", "5"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    metrics = json.loads((out / "teleop.json").read_text())
    assert metrics["config"]["closure_assist"] is True
    assert metrics["closure_assist_s"] > 0.2 and "closure_assist_s" in done.stdout
    refused = subprocess.run(
        [*cli, "replay", str(stream), "--task", "grasp", "--closure-assist", "on"],
        capture_output=True,
        text=True,
    )
    assert refused.returncode != 0
    assert "--grasp-intent on --closure-assist on" in refused.stderr


def test_replay_and_sweep_take_the_pose_prior(tmp_path):
    """`replay --pose-prior on --keypoint-sigma-mm 8` and `sweep --pose-prior on`, as subprocesses.

    The config records the prior; a negative sigma is refused with the valid range.
    """
    stream = tmp_path / "press.npz"
    cli = [sys.executable, "-m", "handsim.cli", "teleop"]
    subprocess.run(
        [*cli, "generate", str(stream), "--task", "press", "--seed", "1"],
        check=True,
        capture_output=True,
    )
    out = tmp_path / "replay"
    done = subprocess.run(
        [*cli, "replay", str(stream), "--task", "press", "--seed", "1", "--out", str(out)]
        + ["--noise-mm", "10", "--pose-prior", "on", "--keypoint-sigma-mm", "8"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    config = json.loads((out / "teleop.json").read_text())["config"]
    assert config["pose_prior"] is True and config["keypoint_sigma_mm"] == 8.0
    sweep = tmp_path / "sweep"
    done = subprocess.run(
        [*cli, "sweep", "--task", "press", "--noise-mm", "5", "--latency", "0"]
        + ["--dropout", "0", "--filters", "none", "--episodes", "1", "--quiet"]
        + ["--pose-prior", "on", "--out", str(sweep)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    report = json.loads((sweep / "sweep.json").read_text())
    assert report["pose_prior"] is True and report["keypoint_sigma_mm"] is None
    refused = subprocess.run(
        [*cli, "replay", str(stream), "--pose-prior", "on", "--keypoint-sigma-mm", "-1"],
        capture_output=True,
        text=True,
    )
    assert refused.returncode != 0 and "--keypoint-sigma-mm" in refused.stderr


def test_replay_and_sweep_take_the_steady_grip_and_an_estimated_sigma(tmp_path):
    """`--grip-steady on --pose-prior on --keypoint-sigma-mm auto --pose-filter auto`, run.

    The config records both; the metrics hold the estimated noise (about the faults' 10 mm);
    a steady grip without the grip stabiliser is refused, naming the option that fits.
    """
    stream = tmp_path / "press.npz"
    cli = [sys.executable, "-m", "handsim.cli", "teleop"]
    subprocess.run(
        [*cli, "generate", str(stream), "--task", "press", "--seed", "1"],
        check=True,
        capture_output=True,
    )
    out = tmp_path / "replay"
    options = ["--grip-steady", "on", "--pose-prior", "on", "--keypoint-sigma-mm", "auto"]
    done = subprocess.run(
        [*cli, "replay", str(stream), "--task", "press", "--seed", "1", "--out", str(out)]
        + ["--noise-mm", "10", *options, "--pose-filter", "auto"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    metrics = json.loads((out / "teleop.json").read_text())
    assert metrics["config"]["grip_steady"] is True
    assert metrics["config"]["keypoint_sigma_mm"] == "auto"
    assert metrics["config"]["pose_filter"] == "auto"
    assert 8.0 < metrics["keypoint_sigma_mm"] < 12.0
    sweep = tmp_path / "sweep"
    done = subprocess.run(
        [*cli, "sweep", "--task", "press", "--noise-mm", "5", "--latency", "0"]
        + ["--dropout", "0", "--filters", "none", "--episodes", "1", "--quiet"]
        + [*options[:2], "--out", str(sweep)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((sweep / "sweep.json").read_text())["grip_steady"] is True
    refused = subprocess.run(
        [*cli, "replay", str(stream), "--grip-steady", "on", "--grip-hold", "off"],
        capture_output=True,
        text=True,
    )
    assert refused.returncode != 0 and "--grip-hold on" in refused.stderr
