"""Live operator streams: JSON frames over UDP or WebSocket.

Packet schema (one JSON object per UDP datagram or WebSocket text/binary message, UTF-8):

==============  ========================================================================
key             meaning
==============  ========================================================================
``seq``         int >= 0, increasing per sender; a packet whose ``seq`` is not greater
                than the last accepted one is out of order and dropped.
``t``           sender time, seconds (optional, informational).
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

Receivers bind to ``127.0.0.1`` by default. Any other address must be given explicitly and
issues a :class:`UserWarning` (the loop then accepts hand poses from the network).
WebSocket uses the maintained ``websockets`` package (``pip install 'handsim[teleop]'``).
"""

from __future__ import annotations

import abc
import contextlib
import json
import math
import socket
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
]

LIVE_FORMATS: tuple[str, ...] = tuple(f for f in STREAM_FORMATS if f != "pose27")
DEFAULT_HOST = "127.0.0.1"
LOCAL_HOSTS: tuple[str, ...] = ("127.0.0.1", "localhost", "::1")
MAX_PACKET_BYTES = 65536
_MAX_ABS_M = 100.0
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
        received_s: receiver's ``time.monotonic()`` at arrival, seconds.
        keypoints_world: (21, 3) float64, world frame, metres (NaN rows: not tracked).
    """

    __slots__ = ("seq", "t", "received_s", "keypoints_world")

    def __init__(self, seq: int, t: float, received_s: float, keypoints_world: np.ndarray):
        self.seq, self.t, self.received_s = seq, t, received_s
        self.keypoints_world = keypoints_world


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
    if isinstance(seq, bool) or not isinstance(seq, int) or seq < 0:
        raise InvalidPacket(f"seq must be an int >= 0; received {seq!r}")
    t = doc.get("t", math.nan)
    if isinstance(t, bool) or not isinstance(t, (int, float)):
        raise InvalidPacket(f"t must be a number of seconds; received {t!r}")
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
    return LiveFrame(seq, float(t), time.monotonic(), kp)


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
    """Base of the receivers: the latest accepted frame and the drop counters.

    Attributes:
        counters: ``received``, ``accepted``, ``malformed``, ``oversized``, ``out_of_order``.
    """

    def __init__(self, host: str, port: int, max_packet_bytes: int = MAX_PACKET_BYTES) -> None:
        if not isinstance(host, str) or not host:
            raise InvalidStream(f"host must be an address; received {host!r}")
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise InvalidStream(
                f"port must be an int in [0, 65535] (0: any free); received {port!r}"
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
            ("received", "accepted", "malformed", "oversized", "out_of_order"), 0
        )
        self._lock = threading.Lock()
        self._latest: LiveFrame | None = None
        self._last_seq = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def handle(self, data: bytes | str) -> None:
        """Parse one packet and keep it if valid (counted either way); never raises."""
        with self._lock:
            self.counters["received"] += 1
        try:
            frame = parse_packet(data, self.max_packet_bytes)
        except InvalidPacket as err:
            with self._lock:
                self.counters[err.reason] += 1
            return
        except Exception:  # noqa: BLE001 (a packet must never stop the loop)
            with self._lock:
                self.counters["malformed"] += 1
            return
        with self._lock:
            if frame.seq <= self._last_seq:
                self.counters["out_of_order"] += 1
                return
            self._last_seq = frame.seq
            self._latest = frame
            self.counters["accepted"] += 1

    def latest(self) -> LiveFrame | None:
        """The newest accepted frame (``None`` before the first)."""
        with self._lock:
            return self._latest

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
    """

    def __init__(
        self, port: int, host: str = DEFAULT_HOST, max_packet_bytes: int = MAX_PACKET_BYTES
    ) -> None:
        super().__init__(host, port, max_packet_bytes)
        self._sock: socket.socket | None = None

    def start(self) -> None:
        """Bind the socket and start the receiving thread."""
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
        except OSError as err:
            sock.close()
            raise InvalidStream(f"cannot bind UDP {self.host}:{self.port}: {err}") from None
        sock.settimeout(0.05)
        self._sock = sock
        self.port = sock.getsockname()[1]
        self._thread = threading.Thread(target=self._run, name="handsim-udp", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        sock = self._sock
        while not self._stop.is_set():
            try:
                data, _ = sock.recvfrom(self.max_packet_bytes + 1)
            except TimeoutError:
                continue
            except OSError:
                break
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


class WebSocketReceiver(LiveReceiver):
    """Receives packets as WebSocket messages (any number of clients), with ``websockets``.

    Args:
        port: TCP port (0: a free one; read :attr:`port` after :meth:`start`).
        host: address to bind (default ``127.0.0.1``; others warn).
        max_packet_bytes: larger messages are dropped as ``oversized`` (the connection stays).
    """

    def __init__(
        self, port: int, host: str = DEFAULT_HOST, max_packet_bytes: int = MAX_PACKET_BYTES
    ) -> None:
        super().__init__(host, port, max_packet_bytes)
        self._server: Any = None
        self._control_handler: Callable[[Any, dict[str, Any]], None] | None = None
        self._early_controls: list[tuple[Any, dict[str, Any]]] = []

    def set_control_handler(self, handler: Callable[[Any, dict[str, Any]], None] | None) -> None:
        """Send the control messages to ``handler``, those that came before it too.

        ``handler(connection, doc)`` gets each :func:`control_message` (a page's subscription
        to the state: :class:`~handsim.envs.teleop.xr_state.StatePublisher`). Without a handler
        the latest 64 are kept for the next one.
        """
        with self._lock:
            self._control_handler = handler
            early, self._early_controls = self._early_controls, []
        if handler is not None:
            for connection, doc in early:
                handler(connection, doc)

    def _control(self, connection: Any, doc: dict[str, Any]) -> None:
        with self._lock:
            handler = self._control_handler
            if handler is None:
                self._early_controls = [*self._early_controls[-63:], (connection, doc)]
                return
        handler(connection, doc)

    def start(self) -> None:
        """Start the server in a background thread."""
        try:
            from websockets.sync.server import serve
        except ImportError:
            raise InvalidStream(
                "the WebSocket receiver needs the 'websockets' package: pip install "
                "'handsim[teleop]'"
            ) from None

        def handler(connection: Any) -> None:
            with contextlib.suppress(Exception):
                for message in connection:
                    control = control_message(message)
                    if control is None:
                        self.handle(message)
                    else:
                        self._control(connection, control)

        try:
            # max_size=None: an oversized message is counted and dropped here, and the
            # connection stays open (websockets would close it).
            self._server = serve(handler, self.host, self.port, max_size=None)
        except OSError as err:
            raise InvalidStream(f"cannot bind WebSocket {self.host}:{self.port}: {err}") from None
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
