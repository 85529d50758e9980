"""`handsim teleop` with two hands, run as subprocesses: generate, replay, send and live."""

import json
import socket
import subprocess
import sys
import threading

import pytest


def _cli(*argv, timeout=180):
    return subprocess.run(
        [sys.executable, "-m", "handsim.cli", "teleop", *map(str, argv)],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.fixture(scope="module")
def two_file(tmp_path_factory):
    """A two-hand stream file written by `teleop generate --task press2`."""
    path = tmp_path_factory.mktemp("two") / "two.json"
    done = _cli("generate", path, "--task", "press2")
    assert done.returncode == 0, done.stderr
    assert "right 82 frames, left 82 frames" in done.stdout
    return path


def test_replay_a_two_hand_file_and_two_files(two_file, tmp_path):
    """One file holding both hands, or one file per hand (any order): both hands press."""
    doc = json.loads(two_file.read_text())
    right, left = tmp_path / "right.json", tmp_path / "left.json"
    right.write_text(json.dumps(doc["hands"][0]))
    left.write_text(json.dumps(doc["hands"][1]))
    for files in ([two_file], [left, right]):
        out = tmp_path / f"out{len(files)}"
        done = _cli("replay", *files, "--task", "press2", "--out", out)
        assert done.returncode == 0, done.stderr
        assert "right hand" in done.stdout and "left hand" in done.stdout
        metrics = json.loads((out / "teleop.json").read_text())
        assert metrics["success"] and set(metrics["hands"]) == {"right", "left"}
        presses = {(e["hand"], e["target"]) for e in metrics["event_log"]}
        assert presses == {("right", "button_2"), ("left", "button_0")}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--task", "press"], r"holds two hands, but handsim/Press-v0 has one: .*--task press2"),
        (["--task", "press2", "--mode", "camera"], r"two hands run in mode='direct'"),
    ],
)
def test_replay_errors_are_one_line(two_file, argv, message):
    """A two-hand file with a one-hand task, or in camera mode: one line saying what fits."""
    import re

    done = _cli("replay", two_file, *argv, "--estimator", "oracle")
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert re.search(message, done.stderr), done.stderr


def test_send_sends_both_hands_of_a_two_hand_file(two_file):
    """`teleop send` of a two-hand file: each packet carries its hand, both arrive."""
    from handsim.envs.teleop import UdpReceiver

    with UdpReceiver(0) as rx:
        done = _cli("send", two_file, "--udp", rx.port, "--speed", "4", timeout=60)
        assert done.returncode == 0, done.stderr
        assert "sent 164 packets" in done.stdout
        assert rx.wait_for(164, 5.0), rx.counters
        assert rx.latest("right") is not None and rx.latest("left") is not None
        assert rx.latest("left").keypoints_world[0, 0] < rx.latest("right").keypoints_world[0, 0]


def test_live_both_hands_routes_packets_by_their_hand(two_file, tmp_path):
    """`live --hand both` drives each hand from the packets of its side."""
    from handsim.envs.teleop import load_streams
    from handsim.envs.teleop.sender import send_streams

    streams = load_streams(two_file)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "live"
    proc = subprocess.Popen(
        [sys.executable, "-m", "handsim.cli", "teleop", "live", "--udp", str(port)]
        + ["--task", "press2", "--hand", "both", "--duration", "3", "--wait", "60"]
        + ["--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    done = threading.Event()

    def send():
        while not done.is_set() and proc.poll() is None:
            send_streams(streams, port)  # seq restarts each time: a new stream, followed

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        stdout, stderr = proc.communicate(timeout=180)
    finally:
        done.set()
        sender.join(timeout=30)
    assert proc.returncode == 0, stderr
    metrics = json.loads((out / "teleop.json").read_text())
    assert metrics["steps"] == 150
    for side in ("right", "left"):
        hand = metrics["hands"][side]
        assert hand["streamed"] and hand["packets_used"] > 60, hand
        assert hand["latency_clock"] == "unix" and hand["latency_p50_ms"] < 200, hand
    assert "right hand" in stdout and "left hand" in stdout
    # A one-hand --hand with a two-hand task is refused, naming --hand both.
    bad = _cli("live", "--udp", port, "--task", "press2", "--wait", "0")
    assert bad.returncode == 2 and "live: --hand both" in bad.stderr, bad.stderr
