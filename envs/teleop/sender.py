"""A small sender of live operator packets: replays a stream over UDP or WebSocket.

``handsim teleop send FILE --udp PORT`` (or ``--websocket PORT``) sends a stream file's frames
as the JSON packets of :mod:`handsim.envs.teleop.live` at the stream's own rate, each stamped
with the Unix time it is sent (``t``) and the stream's ``hand``; a tracker
bridge can do the same with :func:`packet` and a socket. Example, in Python::

    from handsim.envs.teleop.sender import send_stream
    from handsim.envs.teleop import load_stream

    send_stream(load_stream("hand.json"), 9000, protocol="udp")
"""

from __future__ import annotations

import json
import math
import socket
import time
from collections.abc import Callable, Iterator

import numpy as np

from handsim.envs.teleop.live import DEFAULT_HOST
from handsim.envs.teleop.streams import InvalidStream, OperatorStream

__all__ = ["packet", "packets", "send_stream", "send_streams", "PROTOCOLS"]

PROTOCOLS: tuple[str, ...] = ("udp", "websocket")


def packet(seq: int, t: float, keypoints_world: np.ndarray, hand: str = "right") -> bytes:
    """One packet (``handsim21`` keypoints, world frame, metres; NaN rows become ``null``)."""
    rows = [
        None if not np.all(np.isfinite(p)) else [round(float(v), 6) for v in p]
        for p in np.asarray(keypoints_world, dtype=np.float64)
    ]
    doc = {
        "seq": int(seq),
        "t": round(float(t), 6),
        "format": "handsim21",
        "up_axis": "z",
        "hand": hand,
        "keypoints": rows,
    }
    return json.dumps(doc, separators=(",", ":")).encode()


def packets(stream: OperatorStream) -> Iterator[tuple[float, bytes]]:
    """``(t, packet)`` for every frame of ``stream`` (``seq`` counts from 0, stream time)."""
    for seq, (t, kp) in enumerate(zip(stream.times_s, stream.keypoints_world, strict=True)):
        yield float(t), packet(seq, t, kp, stream.side)


def _stamped(stream: OperatorStream) -> Iterator[tuple[float, Callable[[], bytes]]]:
    # Stamped with Unix time when sent, so the receiver can measure end-to-end latency.
    for seq, (t, kp) in enumerate(zip(stream.times_s, stream.keypoints_world, strict=True)):
        yield float(t), (lambda seq=seq, kp=kp: packet(seq, time.time(), kp, stream.side))


def send_stream(
    stream: OperatorStream,
    port: int,
    *,
    protocol: str = "udp",
    host: str = DEFAULT_HOST,
    realtime: bool = True,
    speed: float = 1.0,
) -> int:
    """Send every frame of ``stream`` to a receiver.

    Args:
        stream: the frames to send.
        port: the receiver's port.
        protocol: ``"udp"`` or ``"websocket"`` (``ws://host:port``).
        host: the receiver's address.
        realtime: keep the stream's timing (else as fast as possible).
        speed: playback speed factor (> 0) when ``realtime``.

    Returns:
        The number of packets sent.

    Raises:
        InvalidStream: for an unknown protocol or a receiver that cannot be reached.
    """
    if protocol not in PROTOCOLS:
        raise InvalidStream(f"protocol={protocol!r} is not valid; one of {', '.join(PROTOCOLS)}")
    if not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed > 0):
        raise InvalidStream(f"speed must be a number > 0; received {speed!r}")
    start = time.perf_counter()
    t0 = float(stream.times_s[0])
    sent = 0

    def pace(t: float) -> None:
        if realtime:
            wait = start + (t - t0) / speed - time.perf_counter()
            if wait > 0:
                time.sleep(wait)

    if protocol == "udp":
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_DGRAM) as sock:
            for t, make in _stamped(stream):
                pace(t)
                sock.sendto(make(), (host, port))
                sent += 1
        return sent
    try:
        from websockets.sync.client import connect
    except ImportError:
        raise InvalidStream(
            "sending over WebSocket needs the 'websockets' package: pip install 'handsim[teleop]'"
        ) from None
    try:
        with connect(f"ws://{host}:{port}", max_size=None) as ws:
            for t, make in _stamped(stream):
                pace(t)
                ws.send(make().decode())
                sent += 1
    except OSError as err:
        raise InvalidStream(f"cannot reach ws://{host}:{port}: {err}") from None
    return sent


def send_streams(
    streams: list[OperatorStream] | tuple[OperatorStream, ...],
    port: int,
    **kwargs: object,
) -> int:
    """Send streams of both hands at once (each at its own pace, one thread each).

    Each packet carries its stream's ``hand``, so the receiver routes it to that hand. Takes
    the keyword arguments of :func:`send_stream`; returns the packets sent in all.

    Raises:
        InvalidStream: as :func:`send_stream` (the first error of any stream).
    """
    import threading

    sent: list[int] = []
    errors: list[BaseException] = []

    def one(stream: OperatorStream) -> None:
        try:
            sent.append(send_stream(stream, port, **kwargs))  # type: ignore[arg-type]
        except BaseException as err:  # noqa: BLE001 (re-raised in the caller's thread)
            errors.append(err)

    threads = [threading.Thread(target=one, args=(s,), daemon=True) for s in streams]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return sum(sent)
