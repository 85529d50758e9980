"""The WebXR page of ``handsim teleop serve``: streams a tracked hand, draws the simulation.

The page (``web/index.html`` and ``web/static/page.js``, with three.js r185 vendored in
``web/static/three/``: no CDN, it works offline on a LAN) opens a WebSocket to the teleop loop
(``handsim teleop live --websocket PORT``), subscribes to the simulation's state
(:mod:`~handsim.envs.teleop.xr_state`: the scene as a glb, then body poses every control step)
and draws the table, the objects, the buttons and the physical hand, with the tracked hand as a
cyan ghost. Then

- in a headset's browser, after "Enter VR" (``immersive-vr``) or "Enter AR" (``immersive-ar``,
  passthrough), it reads the 25 WebXR Hand Input joints of the chosen hand (``?hand=right``,
  default) every XR frame and sends them as ``webxr25`` packets (``up_axis`` ``"y"``, metres,
  with joint radii), and draws the scene where the operator's hand is;
- without a headset it shows the scene with an orbit camera and replays the file given to
  ``serve --replay`` at its own rate, as ``handsim21`` packets (also the "Replay recording"
  button).

:func:`make_server` serves ``/`` (the page), ``/static/...`` (the page's scripts and three.js),
``/config.json`` (``{"ws_port", "has_replay"}``) and ``/replay.json`` (the recording:
``{"fps", "hand", "frames": [{"t", "keypoints"}]}``, world frame). The page connects to
``ws://<the page's host>:<ws_port>`` (``?ws=PORT`` overrides).

Test hook: ``?xrtest=1`` loads ``static/xr_emulation.js`` first, an emulated headset (a
``navigator.xr`` with one scripted right hand, rendering into the page's canvas), and
``?enter=immersive-vr`` (or ``immersive-ar``) enters a session without a click; the page's
counters are ``window.handsim``. Neither is loaded without its flag.

WebXR needs a secure context: on a Quest over USB, ``adb reverse tcp:8000 tcp:8000`` and
``adb reverse tcp:8765 tcp:8765`` make both ports the headset's localhost, so nothing is
exposed to the network.
"""

from __future__ import annotations

import http.server
import importlib.resources
import json
import math
import pathlib
import threading
import time
import warnings
from typing import Any

from handsim.envs.teleop.live import LOCAL_HOSTS
from handsim.envs.teleop.streams import InvalidStream

__all__ = ["make_server", "serve", "page_html", "static_files"]


_CONTENT_TYPES = {
    ".js": "text/javascript; charset=utf-8",
    ".md": "text/markdown; charset=utf-8",
    "": "text/plain; charset=utf-8",  # LICENSE
}


def page_html() -> bytes:
    """The page's HTML."""
    return importlib.resources.files("handsim.envs.teleop").joinpath("web/index.html").read_bytes()


def static_files() -> dict[str, bytes]:
    """The page's static files by URL path (``/static/page.js``, ``/static/three/...``)."""
    files: dict[str, bytes] = {}

    def walk(folder: Any, prefix: str) -> None:
        for entry in folder.iterdir():
            if entry.is_dir():
                walk(entry, f"{prefix}{entry.name}/")
            elif pathlib.PurePosixPath(entry.name).suffix in _CONTENT_TYPES:
                files[f"{prefix}{entry.name}"] = entry.read_bytes()

    walk(importlib.resources.files("handsim.envs.teleop").joinpath("web/static"), "/static/")
    return files


def _replay_doc(path: pathlib.Path) -> dict[str, Any]:
    # A two-hand file (handsim.envs.teleop.two_hands) also lists both hands under "hands";
    # the page sends each hand's frame as its own packet.
    from handsim.envs.teleop.two_hands import load_streams

    streams = load_streams(path)
    stream = streams[0]
    dt = float(stream.times_s[1] - stream.times_s[0]) if len(stream) > 1 else 1 / 50

    def frames(s: Any) -> list[dict[str, Any]]:
        return [
            {
                "t": float(t),
                "keypoints": [
                    None if not all(map(math.isfinite, p)) else [round(float(v), 6) for v in p]
                    for p in kp
                ],
            }
            for t, kp in zip(s.times_s - s.times_s[0], s.keypoints_world, strict=True)
        ]

    doc = {"fps": 1.0 / dt, "hand": stream.side, "frames": frames(stream)}
    if len(streams) > 1:
        doc["hands"] = [{"hand": s.side, "frames": frames(s)} for s in streams]
    return doc


def make_server(
    http_port: int = 8000,
    ws_port: int = 8765,
    *,
    host: str = "127.0.0.1",
    replay: str | pathlib.Path | None = None,
) -> http.server.ThreadingHTTPServer:
    """An HTTP server of the page (not started: call ``serve_forever`` in a thread).

    Args:
        http_port: the page's port (0: a free one, read ``server.server_address``).
        ws_port: the WebSocket port the page streams to.
        host: address to bind (default ``127.0.0.1``; others warn).
        replay: a stream file the page replays without a headset.

    Raises:
        InvalidStream: for an unreadable replay file or a port that cannot be bound.
    """
    if host not in LOCAL_HOSTS:
        warnings.warn(
            f"the WebXR page is served on {host}, reachable from the network",
            UserWarning,
            stacklevel=2,
        )
    page = page_html()
    static = static_files()  # a fixed set: no path from a request reaches the file system
    replay_bytes = json.dumps(_replay_doc(pathlib.Path(replay))).encode() if replay else None
    config = json.dumps({"ws_port": int(ws_port), "has_replay": replay is not None}).encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 (the http.server name)
            path = self.path.split("?", 1)[0]
            routes = {
                "/": (page, "text/html; charset=utf-8"),
                "/index.html": (page, "text/html; charset=utf-8"),
                "/config.json": (config, "application/json"),
            }
            if replay_bytes is not None:
                routes["/replay.json"] = (replay_bytes, "application/json")
            if path in static:
                kind = _CONTENT_TYPES[pathlib.PurePosixPath(path).suffix]
                routes[path] = (static[path], kind)
            if path not in routes:
                self.send_error(404, "not found")
                return
            body, kind = routes[path]
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format: str, *args: Any) -> None:  # noqa: A002
            pass  # quiet: the loop's own output matters

    try:
        return http.server.ThreadingHTTPServer((host, http_port), Handler)
    except OSError as err:
        raise InvalidStream(f"cannot serve http://{host}:{http_port}: {err}") from None


def serve(
    http_port: int = 8000,
    ws_port: int = 8765,
    *,
    host: str = "127.0.0.1",
    replay: str | pathlib.Path | None = None,
    duration_s: float = 0.0,
) -> int:
    """Serve the page until Ctrl-C (or ``duration_s`` seconds); returns the exit status."""
    server = make_server(http_port, ws_port, host=host, replay=replay)
    port = server.server_address[1]
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    print(
        f"WebXR page: http://{host}:{port}/ (streams to ws://{host}:{ws_port}; run "
        f"'handsim teleop live --websocket {ws_port}' to drive the hand)"
    )
    try:
        if duration_s > 0:
            time.sleep(duration_s)
        else:
            while True:
                time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        server.shutdown()
        server.server_close()
    return 0
