"""Live packets over real local UDP and WebSocket sockets: accepted, dropped and counted."""

import json
import socket
import warnings

import numpy as np
import pytest

from handsim.envs.teleop import InvalidPacket, UdpReceiver, WebSocketReceiver, parse_packet
from handsim.envs.teleop.sender import packet, send_stream
from handsim.envs.teleop.streams import stream_from_poses


def _kp(seed=0):
    return np.random.default_rng(seed).normal(0.0, 0.05, (21, 3))


def _good(seq, kp=None):
    return packet(seq, 0.01 * seq, _kp(seq) if kp is None else kp)


BAD = [
    (b"\xff\xfe", "malformed"),
    (b"{not json", "malformed"),
    (b"[1, 2]", "malformed"),
    (json.dumps({"seq": -1, "keypoints": [[0, 0, 0]] * 21}).encode(), "malformed"),
    (json.dumps({"seq": 1, "keypoints": [[0, 0, 0]] * 20}).encode(), "malformed"),
    (json.dumps({"seq": 1, "keypoints": [[0, 0, "x"]] * 21}).encode(), "malformed"),
    (json.dumps({"seq": 1, "format": "bvh", "keypoints": []}).encode(), "malformed"),
    (json.dumps({"seq": 1, "keypoints": [None] * 21}).encode(), "malformed"),
    (json.dumps({"seq": 1, "keypoints": [[1e6, 0, 0]] * 21}).encode(), "malformed"),
    (b'{"seq": 1, "keypoints": [[NaN, 0, 0]]}', "malformed"),
    (b"x" * 70000, "oversized"),
]


def test_parse_packet_accepts_the_schema_and_converts_formats():
    """Parse packet accepts the schema and converts formats."""
    kp = _kp()
    frame = parse_packet(_good(3, kp))
    assert frame.seq == 3
    np.testing.assert_allclose(frame.keypoints_world, kp, atol=1e-6)
    # WebXR in millimetres, y up: 25 joints.
    from handsim.hand.keypoints import to_format

    pts = np.random.default_rng(1).normal(0.0, 0.05, (29, 3))
    xr = to_format(pts, "openxr26")[1:] @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T
    doc = {
        "seq": 0,
        "format": "webxr25",
        "units": "mm",
        "keypoints": (xr * 1e3).tolist(),
        "radii": [0.01] * 25,
    }
    frame = parse_packet(json.dumps(doc))
    np.testing.assert_allclose(frame.keypoints_world, pts[:21], atol=1e-9)


@pytest.mark.parametrize(("data", "reason"), BAD)
def test_parse_packet_rejects_bad_packets(data, reason):
    """Parse packet rejects bad packets."""
    with pytest.raises(InvalidPacket) as info:
        parse_packet(data)
    assert info.value.reason == reason


def _send_udp(port, datagrams):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for d in datagrams:
            sock.sendto(d, ("127.0.0.1", port))


def test_udp_receiver_counts_drops_and_keeps_the_newest():
    """Udp receiver counts drops and keeps the newest."""
    with UdpReceiver(0) as rx:
        assert rx.host == "127.0.0.1" and rx.port > 0
        _send_udp(rx.port, [_good(1)])
        assert rx.wait_for(1, 5.0)
        # bad packets, then an old seq (out of order), then a new one
        _send_udp(rx.port, [d for d, _ in BAD if len(d) < 65000] + [_good(0), _good(5)])
        assert rx.wait_for(2, 5.0)
        for _ in range(200):
            if rx.counters["received"] >= 1 + len(BAD) - 1 + 2:
                break
            rx.wait_for(10**9, 0.01)
        np.testing.assert_allclose(rx.latest().keypoints_world, _kp(5), atol=1e-6)
    c = rx.counters
    assert c["accepted"] == 2
    assert c["out_of_order"] == 1
    assert c["malformed"] == len(BAD) - 1
    assert c["received"] == c["accepted"] + c["out_of_order"] + c["malformed"] + c["oversized"]


def test_udp_oversized_datagram_is_dropped():
    """Udp oversized datagram is dropped."""
    with UdpReceiver(0, max_packet_bytes=500) as rx:
        _send_udp(rx.port, [_good(1)])  # about 700 bytes
        _send_udp(rx.port, [b"{}"])
        for _ in range(300):
            if rx.counters["received"] >= 2:
                break
            rx.wait_for(10**9, 0.01)
    assert rx.counters["oversized"] == 1 and rx.counters["accepted"] == 0


def test_websocket_receiver_with_a_real_client():
    """Websocket receiver with a real client."""
    from websockets.sync.client import connect

    with WebSocketReceiver(0) as rx:
        with connect(f"ws://127.0.0.1:{rx.port}", max_size=None) as ws:
            ws.send(_good(1).decode())
            ws.send("{broken")
            ws.send("x" * 70000)  # oversized: dropped, the connection stays open
            ws.send(_good(1).decode())  # repeated seq
            ws.send(_good(2))  # binary message
        assert rx.wait_for(2, 5.0)
        for _ in range(300):
            if rx.counters["received"] >= 5:
                break
            rx.wait_for(10**9, 0.01)
    assert rx.counters == {
        "received": 5,
        "accepted": 2,
        "malformed": 1,
        "oversized": 1,
        "out_of_order": 1,
    }


def test_sender_streams_a_file_over_udp_and_websocket():
    """Sender streams a file over udp and websocket."""
    poses = np.zeros((10, 27))
    poses[:, 0] = np.linspace(0, 0.05, 10)
    poses[:, 2] = 0.15
    stream = stream_from_poses(poses, 0.01)
    with UdpReceiver(0) as rx:
        assert send_stream(stream, rx.port, realtime=False) == 10
        assert rx.wait_for(10, 5.0)
    np.testing.assert_allclose(rx.latest().keypoints_world, stream.keypoints_world[-1], atol=1e-6)
    with WebSocketReceiver(0) as rx:
        assert send_stream(stream, rx.port, protocol="websocket", realtime=False) == 10
        assert rx.wait_for(10, 5.0)


def test_binding_beyond_localhost_warns():
    """Binding beyond localhost warns."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rx = UdpReceiver(0, host="0.0.0.0")
    assert any("not only on this machine" in str(w.message) for w in caught)
    assert rx.host == "0.0.0.0"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        UdpReceiver(0)  # the default host does not warn
