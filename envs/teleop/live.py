"""Live operator streams: JSON frames over UDP or WebSocket.

Packet schema (one JSON object per UDP datagram or WebSocket text/binary message, UTF-8):

==============  ========================================================================
key             meaning
==============  ========================================================================
``seq``         int in [0, 2**53) (JavaScript's exact integers), increasing per sender and
                hand. A packet whose ``seq`` is at most :data:`MAX_SEQ_GAP` behind the
                last accepted one (or equal to it) is out of order and dropped; a jump of
                more than :data:`MAX_SEQ_GAP` either way, or a packet more than
                :data:`STREAM_GAP_S` after the last one, starts a new stream (a restarted
                sender, a corrupted counter): it is accepted and counted as ``seq_reset``.
``t``           sender time, seconds (optional). Unix time (``time.time()``,
                ``(performance.timeOrigin + performance.now()) / 1000`` in a browser)
                lets the loop measure the end-to-end latency; any other clock gives
                the latency relative to the fastest packet.
``hand``        ``"right"`` (default) or ``"left"``.
``format``      a keypoint format of :data:`~handsim.envs.teleop.streams.STREAM_FORMATS`
                except ``pose27`` (default ``handsim21``).
``units``       ``"m"`` (default) or ``"mm"``.
``up_axis``     ``"z"``, ``"y"`` or ``"-y"`` (default by format, as in files).
``keypoints``   ``[[x, y, z], ...]`` in the format's order; ``null`` rows = not tracked.
``radii``       optional, one radius per joint (OpenXR / WebXR); checked, then ignored.
==============  ========================================================================

A WebSocket message that is a JSON object with a ``type`` (under 256 bytes) is a control
message, not a packet (:func:`control_message`): ``{"type": "subscribe"}`` asks for the
simulation's state back on that connection (:mod:`~handsim.envs.teleop.xr_state`).

A packet larger than ``max_packet_bytes`` (default 65536), not UTF-8 JSON, or not matching the
schema (wrong shape, non-finite or absurd values, fewer than 4 tracked points) is dropped and
counted by reason in :attr:`LiveReceiver.counters`; nothing a sender sends stops the loop.

Limits: a WebSocket message longer than ``max_packet_bytes`` is refused from its frame header,
before its payload is read (``websockets`` closes that connection with code 1009, "message too
big"; the sender reconnects); at most ``max_connections`` (default 8) WebSocket clients are
served at once, the others get HTTP 503 and are closed at once, and a client that has not
finished its handshake within 2 s is dropped, so idle connections cannot pile up threads. The
UDP socket asks the kernel for a receive buffer of ``udp_buffer_bytes`` (default 1 MiB, about
1500 packets of 700 bytes); on Linux the datagrams the kernel dropped because that buffer was
full are counted as ``kernel_dropped`` (``SO_RXQ_OVFL``).

Receivers bind to ``127.0.0.1`` by default. Any other address must be given explicitly and
issues a :class:`UserWarning` (the loop then accepts hand poses from the network).
WebSocket uses the maintained ``websockets`` package (``pip install 'handsim[teleop]'``).
"""

from __future__ import annotations

import abc
import collections
import contextlib
import json
import logging
import math
import socket
import sys
import threading
import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from handsim.envs.teleop.streams import (
    STREAM_FORMATS,
    UP_AXES,
    InvalidStream,
    _points_format,
    default_up_axis,
    frame_to_world,
)
from handsim.errors import HandSimError

__all__ = [
    "LIVE_FORMATS",
    "DEFAULT_HOST",
    "MAX_PACKET_BYTES",
    "InvalidPacket",
    "LiveFrame",
    "parse_packet",
    "LiveReceiver",
    "UdpReceiver",
    "WebSocketReceiver",
    "LOCAL_HOSTS",
    "MAX_SEQ",
    "MAX_SEQ_GAP",
    "STREAM_GAP_S",
    "MAX_CONNECTIONS",
    "UDP_BUFFER_BYTES",
    "HANDS",
]

LIVE_FORMATS: tuple[str, ...] = tuple(f for f in STREAM_FORMATS if f != "pose27")
DEFAULT_HOST = "127.0.0.1"
LOCAL_HOSTS: tuple[str, ...] = ("127.0.0.1", "localhost", "::1")
MAX_PACKET_BYTES = 65536
_MAX_ABS_M = 100.0
HANDS: tuple[str, ...] = ("right", "left")
"""Values of a packet's ``hand``."""
MAX_SEQ = 2**53
"""``seq`` must be below this (the integers a JavaScript number holds exactly)."""
MAX_SEQ_GAP = 64
"""A ``seq`` jump larger than this (either way) starts a new stream instead of being dropped
as out of order: about 0.5 s of packets at 120 Hz, far more reordering than a network does,
and a sender restarted after that long is followed at once."""
STREAM_GAP_S = 0.5
"""A packet more than this after its hand's last accepted one starts a new stream whatever its
``seq`` (a sender restarted within :data:`MAX_SEQ_GAP` packets of its old count)."""
MAX_CONNECTIONS = 8
"""WebSocket clients served at once (more get HTTP 503)."""
UDP_BUFFER_BYTES = 1 << 20
"""Receive buffer asked of the kernel for the UDP socket, bytes."""
_HANDSHAKE_TIMEOUT_S = 2.0
# Linux's socket option that attaches the count of datagrams dropped for a full buffer.
_SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)
_MAX_CONTROL_BYTES = 256


class InvalidPacket(HandSimError, ValueError):
    """A live packet does not match the schema; ``reason`` is its counter's name."""

    def __init__(self, message: str, reason: str = "malformed") -> None:
        super().__init__(message)
        self.reason = reason


class LiveFrame:
    """One accepted packet.

    Attributes:
        seq: the sender's sequence number.
        t: sender time, seconds (NaN when absent).
        received_s: receiver's ``time.time()`` at arrival, seconds (Unix time).
        keypoints_world: (21, 3) float64, world frame, metres (NaN rows: not tracked).
        side: ``"right"`` or ``"left"`` (the packet's ``hand``).
    """

    __slots__ = ("seq", "t", "received_s", "keypoints_world", "side")

    def __init__(
        self,
        seq: int,
        t: float,
        received_s: float,
        keypoints_world: np.ndarray,
        side: str = "right",
    ):
        self.seq, self.t, self.received_s = seq, t, received_s
        self.keypoints_world = keypoints_world
        self.side = side


def parse_packet(data: bytes | str, max_packet_bytes: int = MAX_PACKET_BYTES) -> LiveFrame:
    """Parse one packet (schema in the module docstring).

    Raises:
        InvalidPacket: with ``reason`` ``"oversized"`` or ``"malformed"``.
    """
    raw = data.encode() if isinstance(data, str) else bytes(data)
    if len(raw) > max_packet_bytes:
        raise InvalidPacket(f"packet of {len(raw)} bytes exceeds {max_packet_bytes}", "oversized")
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as err:
        raise InvalidPacket(f"not UTF-8 JSON: {err}") from None
    if not isinstance(doc, dict):
        raise InvalidPacket(f"a packet must be a JSON object; received {type(doc).__name__}")
    seq = doc.get("seq")
    if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < MAX_SEQ:
        raise InvalidPacket(f"seq must be an int in [0, 2**53); received {seq!r}")
    t = doc.get("t")
    if t is None:
        t = math.nan
    elif isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
        raise InvalidPacket(f"t must be a finite number of seconds; received {t!r}")
    side = doc.get("hand", "right")
    if side not in HANDS:
        raise InvalidPacket(f"hand={side!r} is not valid; one of right, left")
    fmt = doc.get("format", "handsim21")
    if fmt not in LIVE_FORMATS:
        raise InvalidPacket(f"format={fmt!r} is not valid; one of {', '.join(LIVE_FORMATS)}")
    up = doc.get("up_axis", default_up_axis(fmt))
    if up not in UP_AXES:
        raise InvalidPacket(f"up_axis={up!r} is not valid; one of {', '.join(UP_AXES)}")
    units = doc.get("units", "m")
    if units not in ("m", "mm"):
        raise InvalidPacket(f"units={units!r} is not valid; one of m, mm")
    n = _points_format(fmt)[1]
    rows = doc.get("keypoints")
    if not isinstance(rows, list) or len(rows) != n:
        raise InvalidPacket(f"keypoints must be a list of {n} [x, y, z] rows for {fmt!r}")
    pts = np.full((n, 3), np.nan)
    for j, row in enumerate(rows):
        if row is None:
            continue
        if (
            not isinstance(row, list)
            or len(row) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in row)
        ):
            raise InvalidPacket(f"keypoints[{j}] must be [x, y, z] numbers or null")
        pts[j] = row
    scale = 1e-3 if units == "mm" else 1.0
    if not np.all(np.isfinite(pts) | np.isnan(pts).all(axis=1, keepdims=True)):
        raise InvalidPacket("keypoints must be finite")
    if np.any(np.abs(np.nan_to_num(pts)) * scale > _MAX_ABS_M):
        raise InvalidPacket(f"keypoints beyond {_MAX_ABS_M} m (check units)")
    radii = doc.get("radii")
    if radii is not None:
        if (
            not isinstance(radii, list)
            or len(radii) != n
            or not all(
                r is None or (isinstance(r, (int, float)) and not isinstance(r, bool) and r >= 0)
                for r in radii
            )
        ):
            raise InvalidPacket(f"radii must be {n} numbers >= 0 (or null)")
    kp = frame_to_world(pts, fmt, up, scale)
    if np.count_nonzero(np.all(np.isfinite(kp), axis=1)) < 4:
        raise InvalidPacket("fewer than 4 tracked keypoints")
    return LiveFrame(seq, float(t), time.time(), kp, side)


def control_message(message: bytes | str) -> dict[str, Any] | None:
    """A page's control message (a JSON object with a ``type``, under 256 bytes), else ``None``.

    Control messages (``{"type": "subscribe"}``: the state back, see
    :mod:`~handsim.envs.teleop.xr_state`) are not hand packets: they are neither counted nor
    parsed as keypoints.
    """
    if len(message) > _MAX_CONTROL_BYTES:
        return None
    try:
        doc = json.loads(message)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None
    return doc if isinstance(doc, dict) and isinstance(doc.get("type"), str) else None


class LiveReceiver(abc.ABC):
    """Base of the receivers: the newest accepted frames per hand and the drop counters.

    Attributes:
        counters: ``received``, ``accepted``, ``malformed``, ``oversized``, ``out_of_order``,
            ``seq_reset`` (accepted packets that started a new stream), ``kernel_dropped``
            (UDP datagrams the kernel dropped, where measurable) and ``refused_connections``
            (WebSocket clients over the limit).
        history: per hand, the last :data:`HISTORY` accepted frames, oldest first (read
            under :attr:`lock`; :class:`~handsim.envs.teleop.sampling.LiveSampler` does).
    """

    HISTORY = 32
    """Accepted frames kept per hand (timestamp-aware resampling reads them)."""

    def __init__(self, host: str, port: int, max_packet_bytes: int = MAX_PACKET_BYTES) -> None:
        if not isinstance(host, str) or not host:
            raise InvalidStream(f"host must be an address; received {host!r}")
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise InvalidStream(
                f"port must be an int in [0, 65535] (0: any free); received {port!r}"
            )
        if (
            isinstance(max_packet_bytes, bool)
            or not isinstance(max_packet_bytes, int)
            or max_packet_bytes < 64
        ):
            raise InvalidStream(
                f"max_packet_bytes must be an int >= 64; received {max_packet_bytes!r}"
            )
        if host not in LOCAL_HOSTS:
            warnings.warn(
                f"the teleop receiver listens on {host}, not only on this machine: anyone who "
                "can reach it can drive the hand",
                UserWarning,
                stacklevel=3,
            )
        self.host, self.port = host, port
        self.max_packet_bytes = int(max_packet_bytes)
        self.counters = dict.fromkeys(
            (
                "received",
                "accepted",
                "malformed",
                "oversized",
                "out_of_order",
                "seq_reset",
                "kernel_dropped",
                "refused_connections",
            ),
            0,
        )
        self.lock = threading.Lock()
        self.history: dict[str, collections.deque[LiveFrame]] = {
            h: collections.deque(maxlen=self.HISTORY) for h in HANDS
        }
        self._latest: LiveFrame | None = None
        self._last_seq: dict[str, int] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def count(self, reason: str, n: int = 1) -> None:
        """Add ``n`` to a counter (thread-safe)."""
        with self.lock:
            self.counters[reason] += n

    def handle(self, data: bytes | str) -> None:
        """Parse one packet and keep it if valid (counted either way); never raises."""
        self.count("received")
        try:
            frame = parse_packet(data, self.max_packet_bytes)
        except InvalidPacket as err:
            self.count(err.reason)
            return
        except Exception:  # noqa: BLE001 (a packet must never stop the loop)
            self.count("malformed")
            return
        with self.lock:
            last = self._last_seq.get(frame.side)
            history = self.history[frame.side]
            quiet = bool(history) and frame.received_s - history[-1].received_s > STREAM_GAP_S
            if last is not None and (abs(frame.seq - last) > MAX_SEQ_GAP or quiet):
                # A new stream (restarted sender or a corrupted counter), not a freeze.
                self.counters["seq_reset"] += 1
                self.history[frame.side].clear()
            elif last is not None and frame.seq <= last:
                self.counters["out_of_order"] += 1
                return
            self._last_seq[frame.side] = frame.seq
            self._latest = frame
            self.history[frame.side].append(frame)
            self.counters["accepted"] += 1

    def latest(self, side: str | None = None) -> LiveFrame | None:
        """The newest accepted frame of ``side`` (``None``: of either hand; ``None`` if none)."""
        with self.lock:
            if side is None:
                return self._latest
            h = self.history[side]
            return h[-1] if h else None

    def wait_for(self, n_accepted: int, timeout_s: float) -> bool:
        """Block until ``n_accepted`` frames were accepted or ``timeout_s`` passed."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self.counters["accepted"] >= n_accepted:
                return True
            time.sleep(0.005)
        return self.counters["accepted"] >= n_accepted

    def __enter__(self) -> LiveReceiver:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @abc.abstractmethod
    def start(self) -> None:
        """Bind and start receiving in a background thread."""

    @abc.abstractmethod
    def close(self) -> None:
        """Stop receiving and release the port (idempotent)."""


class UdpReceiver(LiveReceiver):
    """Receives packets as UDP datagrams.

    Args:
        port: UDP port (0: a free one; read :attr:`port` after :meth:`start`).
        host: address to bind (default ``127.0.0.1``; others warn).
        max_packet_bytes: larger datagrams are dropped as ``oversized``.
        buffer_bytes: receive buffer asked of the kernel, bytes (the kernel may grant less, up
            to ``net.core.rmem_max``; read :attr:`buffer_bytes` after :meth:`start`).

    Attributes:
        buffer_bytes: after :meth:`start`, the buffer the kernel granted (Linux reports twice
            the usable size, its bookkeeping included).
        drops_measurable: whether the kernel reports its drops (Linux ``SO_RXQ_OVFL``).
    """

    def __init__(
        self,
        port: int,
        host: str = DEFAULT_HOST,
        max_packet_bytes: int = MAX_PACKET_BYTES,
        buffer_bytes: int = UDP_BUFFER_BYTES,
    ) -> None:
        super().__init__(host, port, max_packet_bytes)
        if isinstance(buffer_bytes, bool) or not isinstance(buffer_bytes, int) or buffer_bytes < 1:
            raise InvalidStream(f"buffer_bytes must be an int >= 1; received {buffer_bytes!r}")
        self.buffer_bytes = buffer_bytes
        self.drops_measurable = False
        self._sock: socket.socket | None = None

    def start(self) -> None:
        """Bind the socket and start the receiving thread."""
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self.buffer_bytes)
            sock.bind((self.host, self.port))
        except OSError as err:
            sock.close()
            raise InvalidStream(f"cannot bind UDP {self.host}:{self.port}: {err}") from None
        self.buffer_bytes = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        try:
            sock.setsockopt(socket.SOL_SOCKET, _SO_RXQ_OVFL, 1)
            self.drops_measurable = sys.platform.startswith("linux")
        except OSError:
            self.drops_measurable = False
        sock.settimeout(0.05)
        self._sock = sock
        self.port = sock.getsockname()[1]
        self._thread = threading.Thread(target=self._run, name="handsim-udp", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        sock = self._sock
        ancillary = socket.CMSG_SPACE(4) if self.drops_measurable else 0
        dropped_before = 0
        while not self._stop.is_set():
            try:
                data, cmsgs, _, _ = sock.recvmsg(self.max_packet_bytes + 1, ancillary)
            except TimeoutError:
                continue
            except OSError:
                break
            for level, kind, payload in cmsgs:
                if level == socket.SOL_SOCKET and kind == _SO_RXQ_OVFL and len(payload) >= 4:
                    # The kernel's running count of drops on this socket (uint32).
                    total = int.from_bytes(payload[:4], sys.byteorder)
                    if total > dropped_before:
                        self.count("kernel_dropped", total - dropped_before)
                        dropped_before = total
            self.handle(data)

    def close(self) -> None:
        """Stop the thread and close the socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None


_BUSY = b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"


class WebSocketReceiver(LiveReceiver):
    """Receives packets as WebSocket messages (``max_connections`` clients), with ``websockets``.

    Args:
        port: TCP port (0: a free one; read :attr:`port` after :meth:`start`).
        host: address to bind (default ``127.0.0.1``; others warn).
        max_packet_bytes: a longer message is refused from its header (counted as
            ``oversized``; the connection is closed with code 1009).
        max_connections: clients served at once; more get HTTP 503 (``refused_connections``).
    """

    def __init__(
        self,
        port: int,
        host: str = DEFAULT_HOST,
        max_packet_bytes: int = MAX_PACKET_BYTES,
        max_connections: int = MAX_CONNECTIONS,
    ) -> None:
        super().__init__(host, port, max_packet_bytes)
        if (
            isinstance(max_connections, bool)
            or not isinstance(max_connections, int)
            or max_connections < 1
        ):
            raise InvalidStream(
                f"max_connections must be an int >= 1; received {max_connections!r}"
            )
        self.max_connections = max_connections
        self._server: Any = None
        self._open = 0
        self._control_handler: Callable[[Any, dict[str, Any]], None] | None = None
        self._early_controls: list[tuple[Any, dict[str, Any]]] = []

    def set_control_handler(self, handler: Callable[[Any, dict[str, Any]], None] | None) -> None:
        """Send the control messages to ``handler``, those that came before it too.

        ``handler(connection, doc)`` gets each :func:`control_message` (a page's subscription
        to the state: :class:`~handsim.envs.teleop.xr_state.StatePublisher`). Without a handler
        the latest 64 are kept for the next one.
        """
        with self.lock:
            self._control_handler = handler
            early, self._early_controls = self._early_controls, []
        if handler is not None:
            for connection, doc in early:
                handler(connection, doc)

    def _control(self, connection: Any, doc: dict[str, Any]) -> None:
        with self.lock:
            handler = self._control_handler
            if handler is None:
                self._early_controls = [*self._early_controls[-63:], (connection, doc)]
                return
        handler(connection, doc)

    def start(self) -> None:
        """Start the server in a background thread."""
        try:
            from websockets.exceptions import ConnectionClosed
            from websockets.sync.server import serve
        except ImportError:
            raise InvalidStream(
                "the WebSocket receiver needs the 'websockets' package: pip install "
                "'handsim[teleop]'"
            ) from None

        def handler(connection: Any) -> None:
            try:
                for message in connection:
                    control = control_message(message)
                    if control is None:
                        self.handle(message)
                    else:
                        self._control(connection, control)
            except ConnectionClosed as closed:
                if closed.sent is not None and closed.sent.code == 1009:
                    self.count("received")
                    self.count("oversized")
            except Exception:  # noqa: BLE001, S110 (a client must never stop the loop)
                pass

        try:
            # max_size: websockets refuses a longer message from its frame header, before
            # reading the payload, and closes that connection (1009).
            self._server = serve(
                handler,
                self.host,
                self.port,
                max_size=self.max_packet_bytes,
                open_timeout=_HANDSHAKE_TIMEOUT_S,
                logger=_QUIET,
            )
        except OSError as err:
            raise InvalidStream(f"cannot bind WebSocket {self.host}:{self.port}: {err}") from None
        server = self._server
        inner = server.handler

        def limited(sock: socket.socket, addr: Any) -> None:
            # One thread per accepted socket is websockets' model; refusing here, before the
            # handshake, keeps idle clients from holding three threads each.
            with self.lock:
                full = self._open >= self.max_connections
                if not full:
                    self._open += 1
            if full:
                self.count("refused_connections")
                with contextlib.suppress(OSError):
                    sock.sendall(_BUSY)
                sock.close()
                with server.lock:
                    server.handler_threads.discard(threading.current_thread())
                return
            try:
                inner(sock, addr)
            finally:
                with self.lock:
                    self._open -= 1

        self._server.handler = limited
        self.port = self._server.socket.getsockname()[1]
        self._thread = threading.Thread(
            target=self._server.serve_forever, name="handsim-websocket", daemon=True
        )
        self._thread.start()

    def close(self) -> None:
        """Stop the server and close its connections."""
        if self._server is not None:
            self._server.shutdown()
            self._server = None
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None


_QUIET = logging.getLogger("handsim.teleop.websocket")
_QUIET.addHandler(logging.NullHandler())
_QUIET.propagate = False
