"""The state stream back to the page: scene glb, then body poses, over a real local WebSocket."""

import contextlib
import json
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from handsim.envs.teleop import (
    TeleopConfig,
    TeleopLoop,
    UdpReceiver,
    WebSocketReceiver,
    stream_from_expert,
)
from handsim.envs.teleop.live import control_message
from handsim.envs.teleop.streams import InvalidStream
from handsim.envs.teleop.xr_state import StatePublisher
from handsim.world.gltf import body_poses

websockets_client = pytest.importorskip("websockets.sync.client")


def _packets(stream):
    for k, kp in enumerate(stream.keypoints_world):
        yield json.dumps(
            {"seq": k, "format": "handsim21", "up_axis": "z", "keypoints": kp.tolist()}
        )


def _run_until(loop, publisher, done, seed=0):
    """Run short episodes (the same seed keeps the scene) until ``done()`` (at most 60 s)."""
    end = time.monotonic() + 60
    while not done():
        assert time.monotonic() < end, publisher.counters
        loop.run(lambda i: None, seed, max_steps=10, realtime=True, on_step=publisher.on_step)


def test_a_subscribed_page_gets_the_scene_then_states_that_match_the_simulation():
    """A subscriber receives the glb (one node per body) and per-step poses of those bodies."""
    stream = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
    with (
        WebSocketReceiver(0) as rx,
        TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop,
        StatePublisher(rx, loop.env) as publisher,
        websockets_client.connect(f"ws://127.0.0.1:{rx.port}") as page,
    ):
        page.send(json.dumps({"type": "subscribe"}))
        for message in _packets(stream):
            page.send(message)
        assert rx.wait_for(len(stream), 30.0), rx.counters
        assert rx.counters["malformed"] == 0  # the subscription is not a malformed packet
        # The glb is made on the sender thread at the first step: wait for it (a loaded machine
        # may take longer than a short episode), then take the scene and drop the warm-up.
        _run_until(loop, publisher, lambda: publisher.counters["scenes_sent"] == 1)
        header: dict = {}
        glb = b""
        with contextlib.suppress(TimeoutError):
            while True:
                message = page.recv(timeout=1)
                if isinstance(message, bytes):
                    glb = message
                elif json.loads(message)["type"] == "scene":
                    header = json.loads(message)
        states: list[dict] = []

        def read() -> None:
            # The newest state always goes out: the last step's arrives in the end.
            while not states or states[-1]["step"] < 40:
                states.append(json.loads(page.recv(timeout=20)))

        reader = threading.Thread(target=read)
        reader.start()
        episode = loop.run(
            publisher.newest_keypoints,
            0,
            max_steps=40,
            realtime=True,
            stop_at_success=False,
            on_step=publisher.on_step,
        )
        reader.join(timeout=30)
        scene = loop.env.unwrapped.scene
        last_poses = body_poses(scene.data, [scene.model.body(n).id for n in header["bodies"]])
    assert episode.metrics["steps"] == 40
    assert glb[:4] == b"glTF" and len(glb) == header["glb_bytes"]
    assert "rh_palm" in header["bodies"] and "press_button_0" in header["bodies"]
    assert len(states) >= 5 and {s["scene_id"] for s in states} == {header["scene_id"]}
    assert {s["type"] for s in states} == {"state"}
    steps = [s["step"] for s in states]
    assert steps == sorted(steps) and len(set(steps)) == len(steps)
    poses = np.array(states[-1]["poses"]).reshape(-1, 7)
    assert poses.shape == (len(header["bodies"]), 7)
    # The last state is the simulation's last step, to the 5 decimals sent.
    np.testing.assert_allclose(poses, last_poses, atol=1e-5)
    assert np.allclose(np.linalg.norm(poses[:, 3:], axis=1), 1.0, atol=1e-4)
    assert states[-1]["seq"] == len(stream) - 1
    tracked = [p for p in states[-1]["tracked"] if p is not None]
    assert len(states[-1]["tracked"]) == 21 and len(tracked) == 21
    # The anchor moved the stream (replayed in the world frame: no offset).
    assert np.allclose(states[-1]["offset_m"], 0.0, atol=1e-9)
    assert publisher.counters["scenes_sent"] == 1 and publisher.export_error is None


def test_without_a_subscriber_nothing_is_encoded_and_the_state_needs_a_websocket():
    """No page subscribed: on_step returns at once; a UDP receiver has no way back."""
    with (
        WebSocketReceiver(0) as rx,
        TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop,
        StatePublisher(rx, loop.env) as publisher,
    ):
        loop.run(lambda i: None, 0, max_steps=5, on_step=publisher.on_step)
        assert publisher.counters == {
            "subscribers": 0,
            "scenes_sent": 0,
            "states_sent": 0,
            "send_errors": 0,
        }
    with UdpReceiver(0) as udp, pytest.raises(InvalidStream, match="must be a WebSocketReceiver"):
        StatePublisher(udp, None)


@pytest.mark.parametrize(
    ("message", "expected"),
    [
        ('{"type": "subscribe"}', {"type": "subscribe"}),
        (b'{"type": "subscribe"}', {"type": "subscribe"}),
        ('{"seq": 0, "keypoints": []}', None),  # a hand packet
        ('{"type": 3}', None),
        ("[1, 2]", None),
        ("not json", None),
        ('{"type": "subscribe", "pad": "' + "x" * 300 + '"}', None),  # too long to be one
    ],
)
def test_control_messages_are_told_from_hand_packets(message, expected):
    """Small JSON objects with a string ``type`` are control messages; the rest are packets."""
    assert control_message(message) == expected


def test_teleop_live_over_websocket_streams_the_state_back(tmp_path):
    """`handsim teleop live --websocket` (a subprocess) streams the state to a subscribed page.

    The page gets the scene and then states; teleop.json counts them.
    """
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    stream = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
    cli = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "handsim.cli",
            "teleop",
            "live",
            "--task",
            "press",
            "--websocket",
            str(port),
            "--duration",
            "4",
            "--wait",
            "60",
            "--out",
            str(tmp_path),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    kinds: list[str] = []
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                page = websockets_client.connect(f"ws://127.0.0.1:{port}")
                break
            except OSError:
                assert time.monotonic() < deadline and cli.poll() is None, cli.stdout.read()
                time.sleep(0.2)
        with page:
            page.send(json.dumps({"type": "subscribe"}))
            for message in _packets(stream):
                page.send(message)
            with contextlib.suppress(Exception):  # the CLI ends and closes the connection
                while len(kinds) < 20:
                    message = page.recv(timeout=60)
                    binary = isinstance(message, bytes)
                    kinds.append("glb" if binary else json.loads(message)["type"])
        output, _ = cli.communicate(timeout=120)
    finally:
        if cli.poll() is None:
            cli.kill()
    assert cli.returncode == 0, output
    assert kinds[:3] == ["scene", "glb", "state"] and kinds.count("state") >= 10, kinds
    summary = json.loads((tmp_path / "teleop.json").read_text())
    assert summary["state_stream"]["subscribers"] == 1
    assert summary["state_stream"]["states_sent"] >= 10
    assert summary["packets"]["malformed"] == 0


def test_a_reset_that_draws_another_object_sends_the_new_scene():
    """A new object set on reset is a new scene: the page gets both, in order.

    Seed 0 draws the marker, seed 1 the mustard bottle; every state names the scene whose
    bodies it lists.
    """
    kwargs = {"objects": ["006_mustard_bottle", "040_large_marker"]}
    with (
        WebSocketReceiver(0) as rx,
        TeleopLoop("handsim/Grasp-v0", env_kwargs=kwargs) as loop,
        StatePublisher(rx, loop.env) as publisher,
        websockets_client.connect(f"ws://127.0.0.1:{rx.port}") as page,
    ):
        page.send(json.dumps({"type": "subscribe"}))
        while publisher.counters["subscribers"] == 0:
            time.sleep(0.01)
        for k, seed in enumerate((0, 1), 1):
            sent = publisher.counters["states_sent"]
            _run_until(
                loop,
                publisher,
                lambda k=k, sent=sent: (
                    publisher.counters["scenes_sent"] == k
                    and publisher.counters["states_sent"] > sent + 2
                ),
                seed=seed,
            )
        scenes, states = [], []
        with contextlib.suppress(TimeoutError):
            while True:
                message = page.recv(timeout=2)
                if isinstance(message, str):
                    doc = json.loads(message)
                    (scenes if doc["type"] == "scene" else states).append(doc)
    assert [s["scene_id"] for s in scenes] == [1, 2]
    assert scenes[0]["bodies"][-1] == "obj_040_large_marker"
    assert scenes[1]["bodies"][-1] == "obj_006_mustard_bottle"
    assert {s["scene_id"] for s in states} == {1, 2}
    n_bodies = {s["scene_id"]: len(s["bodies"]) for s in scenes}
    assert all(len(s["poses"]) == 7 * n_bodies[s["scene_id"]] for s in states)


def test_on_step_reports_what_the_anchor_added_for_live_and_file_streams():
    """operator_world - anchor_offset_m is the stream as given, for live functions and files."""
    stream = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
    raw = stream.keypoints_world[0] + np.array([0.3, -0.2, 0.5])  # elsewhere in the room
    with TeleopLoop(
        "handsim/Press-v0", TeleopConfig(anchor="start"), env_kwargs={"task": "button"}
    ) as loop:
        live: list[dict] = []
        loop.run(lambda i: raw, 0, max_steps=3, on_step=lambda i, r: live.append(r))
        moved = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
        from_file: list[dict] = []
        loop.run(moved, 0, max_steps=3, on_step=lambda i, r: from_file.append(r))
    assert len(live) == 3
    for record in live:
        np.testing.assert_allclose(record["operator_world"] - record["anchor_offset_m"], raw)
    assert np.linalg.norm(live[0]["anchor_offset_m"]) > 0.1
    resampled = moved.resample(1.0 / loop.control_dt).keypoints_world
    for k, record in enumerate(from_file, 1):
        np.testing.assert_allclose(
            record["operator_world"] - record["anchor_offset_m"], resampled[k], atol=1e-12
        )
