"""Live packets over real local UDP and WebSocket sockets: accepted, dropped and counted."""

import json
import socket
import time
import warnings

import numpy as np
import pytest

from handsim.envs.teleop import InvalidPacket, UdpReceiver, WebSocketReceiver, parse_packet
from handsim.envs.teleop.live import MAX_SEQ_GAP
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
    """Good, broken, repeated and binary messages over a real WebSocket are counted by reason."""
    from websockets.sync.client import connect

    with WebSocketReceiver(0) as rx:
        with connect(f"ws://127.0.0.1:{rx.port}", max_size=None) as ws:
            ws.send(_good(1).decode())
            ws.send("{broken")
            ws.send(_good(1).decode())  # repeated seq
            ws.send(_good(2))  # binary message
        assert rx.wait_for(2, 5.0)
        for _ in range(300):
            if rx.counters["received"] >= 4:
                break
            rx.wait_for(10**9, 0.01)
    assert {k: v for k, v in rx.counters.items() if v} == {
        "received": 4,
        "accepted": 2,
        "malformed": 1,
        "out_of_order": 1,
    }


def _ws_handshake(port):
    """A raw TCP client that completes a WebSocket handshake; returns the socket."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    sock.sendall(
        b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    return sock


def _read_until(sock, marker, limit=4096):
    data = b""
    while marker not in data and len(data) < limit:
        chunk = sock.recv(limit)
        if not chunk:
            break
        data += chunk
    return data


def test_websocket_refuses_an_oversized_message_from_its_header():
    """A 64 MB message is refused from its header (close 1009) before any payload is sent."""
    with WebSocketReceiver(0) as rx:
        sock = _ws_handshake(rx.port)
        assert b"101 Switching Protocols" in _read_until(sock, b"\r\n\r\n")
        # A masked text frame announcing 64 MiB; not one byte of its payload follows.
        sock.sendall(bytes([0x81, 0x80 | 127]) + (64 << 20).to_bytes(8, "big") + b"\0\0\0\0")
        close = _read_until(sock, b"\x03\xf1", limit=64)  # 1009 in a close frame
        assert close[:1] == b"\x88" and b"\x03\xf1" in close
        sock.close()
        # The next connection is served as before.
        from websockets.sync.client import connect

        with connect(f"ws://127.0.0.1:{rx.port}") as ws:
            ws.send(_good(1).decode())
        assert rx.wait_for(1, 5.0)
    assert rx.counters["oversized"] == 1 and rx.counters["accepted"] == 1


def test_websocket_connection_limit_bounds_threads():
    """200 idle clients: 8 are served, 192 get HTTP 503, and the threads stay few."""
    import threading

    before = threading.active_count()
    with WebSocketReceiver(0) as rx:
        clients = [_ws_handshake(rx.port) for _ in range(200)]
        try:
            answers = [_read_until(c, b"\r\n\r\n") for c in clients]
            assert sum(b"101 Switching Protocols" in a for a in answers) == 8
            assert sum(b" 503 " in a for a in answers) == 192
            assert rx.counters["refused_connections"] == 192
            # 8 connections of 3 threads each (handler, reader, keep-alive) and the server, once
            # the short-lived thread that wrote a refusal has returned (it may still be
            # finishing when its client reads the 503).
            deadline = time.monotonic() + 5.0
            while threading.active_count() - before > 8 * 3 + 2 and time.monotonic() < deadline:
                time.sleep(0.01)
            settled = threading.active_count() - before
            assert settled <= 8 * 3 + 2, settled
        finally:
            for c in clients:
                c.close()


def test_seq_is_bounded_and_a_jump_starts_a_new_stream():
    """A stray seq = 10**15 does not freeze the stream; a restarted sender is followed."""
    rx = UdpReceiver(0)
    for seq in (101, 102, 103):
        rx.handle(_good(seq))
    rx.handle(_good(10**15))  # valid, but far ahead: a new stream
    rx.handle(_good(104))  # far behind it: the old sender again, followed at once
    rx.handle(_good(104))  # a repeat
    rx.handle(_good(105))
    rx.handle(_good(105 - MAX_SEQ_GAP))  # behind, within the gap: out of order
    assert rx.latest().seq == 105
    assert rx.counters["seq_reset"] == 2 and rx.counters["out_of_order"] == 2
    assert rx.counters["accepted"] == 6
    with pytest.raises(InvalidPacket, match=r"seq must be an int in \[0, 2\*\*53\)"):
        parse_packet(packet(2**53, 0.0, _kp()))


def test_a_sender_restarted_after_a_pause_is_followed_at_once():
    """A seq of 0 again 0.6 s after seq 30: a new stream (within the gap, but after a pause)."""
    from handsim.envs.teleop.live import STREAM_GAP_S

    rx = UdpReceiver(0)
    rx.handle(_good(30))
    rx.handle(_good(29))  # no pause: out of order
    rx.history["right"][-1].received_s -= STREAM_GAP_S + 0.1  # as if it came 0.6 s ago
    rx.handle(_good(0))
    assert rx.latest().seq == 0
    assert rx.counters["seq_reset"] == 1 and rx.counters["out_of_order"] == 1


def test_packet_hand_is_kept_per_side():
    """Packets of the two hands keep their own seq and history."""
    rx = UdpReceiver(0)
    rx.handle(packet(7, 0.0, _kp(1), "left"))
    rx.handle(packet(1, 0.0, _kp(2), "right"))  # its own counter: not out of order
    assert rx.latest("left").seq == 7 and rx.latest("right").seq == 1
    assert rx.latest().side == "right"
    with pytest.raises(InvalidPacket, match="hand='middle' is not valid; one of right, left"):
        parse_packet(json.dumps({"seq": 1, "hand": "middle", "keypoints": [[0, 0, 0]] * 21}))


def test_udp_buffer_is_sized_and_kernel_drops_are_counted():
    """A slow reader behind a small buffer: the kernel's drops are counted, none go missing."""
    import sys
    import threading
    import time

    with UdpReceiver(0, buffer_bytes=1 << 20) as rx:
        assert rx.buffer_bytes >= 1 << 17  # granted (Linux: up to net.core.rmem_max, doubled)
    gate = threading.Event()
    rx = UdpReceiver(0, buffer_bytes=4096)
    handle = rx.handle

    def slow(data):
        gate.wait()
        handle(data)

    rx.handle = slow
    with rx:
        sent = 300
        _send_udp(rx.port, [_good(i) for i in range(1, sent + 1)])
        time.sleep(0.2)
        gate.set()
        for _ in range(300):  # drain what the buffer held
            received = rx.counters["received"]
            time.sleep(0.02)
            if rx.counters["received"] == received:
                break
        _send_udp(rx.port, [_good(sent + 1000)])  # carries the kernel's drop count
        for _ in range(300):
            if rx.counters["received"] + rx.counters["kernel_dropped"] >= sent + 1:
                break
            time.sleep(0.01)
    c = rx.counters
    if not (sys.platform.startswith("linux") and rx.drops_measurable):
        pytest.skip("the kernel does not report UDP drops here")
    assert c["kernel_dropped"] > 0
    assert c["received"] + c["kernel_dropped"] == sent + 1


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
