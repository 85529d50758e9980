"""The served page in headless Chromium: an emulated headset sees the hand and the objects.

An emulated headset enters a session, streams its hand into the loop, and the screenshot shows
the simulated hand, the object and the ghost.

Chromium is driven through the DevTools protocol over its WebSocket (the ``websockets``
package); the page's test hook (``?xrtest=1``) emulates ``navigator.xr`` with a scripted hand.
"""

import base64
import contextlib
import itertools
import json
import pathlib
import shutil
import socket
import subprocess
import sys
import threading
import time
import urllib.request

import cv2
import numpy as np
import pytest

from handsim.envs.teleop import (
    TeleopConfig,
    TeleopLoop,
    WebSocketReceiver,
    save_stream,
    stream_from_expert,
)
from handsim.envs.teleop.web import make_server, static_files
from handsim.envs.teleop.xr_state import StatePublisher

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
websockets_client = pytest.importorskip("websockets.sync.client")


def test_the_page_its_scripts_and_three_js_are_served_and_nothing_else():
    """`/` loads three.js from /static (no CDN); the vendored files and licence are served."""
    files = static_files()
    assert {
        "/static/page.js",
        "/static/xr_emulation.js",
        "/static/three/three.module.min.js",
        "/static/three/three.core.min.js",
        "/static/three/addons/loaders/GLTFLoader.js",
        "/static/three/addons/controls/OrbitControls.js",
        "/static/three/LICENSE",
    } <= set(files)
    # Only what the page uses is vendored (~1 MB).
    assert sum(map(len, files.values())) < 1_200_000
    server = make_server(0, 9999)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        page = urllib.request.urlopen(base + "/", timeout=10).read().decode()
        assert (
            "./static/three/three.module.min.js" in page
            and "http" not in page.split("importmap", 1)[1].split("</script>", 1)[0]
        )
        with urllib.request.urlopen(base + "/static/page.js", timeout=10) as response:
            assert response.headers["Content-Type"].startswith("text/javascript")
            assert b"GLTFLoader" in response.read()
        licence = urllib.request.urlopen(base + "/static/three/LICENSE", timeout=10).read()
        assert b"MIT License" in licence
        for bad in ("/static/../web.py", "/static/three/", "/static/nothing.js"):
            with pytest.raises(urllib.error.HTTPError, match="404"):
                urllib.request.urlopen(base + bad, timeout=10)
    finally:
        server.shutdown()
        server.server_close()


class _DevTools:
    """The few DevTools protocol calls the test needs, on one page target."""

    def __init__(self, port: int, timeout_s: float = 60.0) -> None:
        end = time.monotonic() + timeout_s
        while True:
            try:
                targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json"))
                page = next(t for t in targets if t["type"] == "page")
                break
            except (OSError, StopIteration):
                if time.monotonic() > end:
                    raise
                time.sleep(0.2)
        self._connection = websockets_client.connect(page["webSocketDebuggerUrl"], max_size=None)
        self.ids = itertools.count(1)

    def __enter__(self):
        self.ws = self._connection.__enter__()
        return self

    def __exit__(self, *exc):
        self._connection.__exit__(*exc)

    def call(self, method: str, **params):
        n = next(self.ids)
        self.ws.send(json.dumps({"id": n, "method": method, "params": params}))
        while True:
            doc = json.loads(self.ws.recv(timeout=60))
            if doc.get("id") == n:
                if "error" in doc:
                    raise RuntimeError(f"{method}: {doc['error']}")
                return doc["result"]

    def eval(self, expression: str):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        return result["result"].get("value")

    def wait(self, expression: str, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self.eval(expression):
                return True
            time.sleep(0.2)
        return False

    def screenshot(self) -> np.ndarray:
        """The page, (H, W, 3) uint8 RGB, after two more frames were drawn."""
        n = self.eval("window.handsim.framesRendered")
        self.wait(f"window.handsim.framesRendered >= {n + 2}", 10)
        png = self.call("Page.captureScreenshot", format="png")["data"]
        bgr = cv2.imdecode(np.frombuffer(base64.b64decode(png), np.uint8), cv2.IMREAD_COLOR)
        return bgr[:, :, ::-1].copy()


class _Stop(Exception):
    pass


_PAGE_STATE = (
    "JSON.stringify({mode: handsim.mode, sent: handsim.sent, scenes: handsim.scenesLoaded, "
    "states: handsim.statesApplied, errors: handsim.errors, "
    "xrFrames: window.handsimXrTest ? handsimXrTest.frames : 0, where: handsim.where(), "
    "drawn: handsim.drawn, passthrough: !!handsim.passthrough})"
)


def _open_page(tmp_path, query, ready, *, replay=None):
    """Open the page in headless Chromium on a live Grasp-v0 (mustard bottle) with the state.

    Waits for ``ready`` (JS), freezes the view and screenshots it whole and without each part.

    Returns:
        ``(page, packets, stream, full, shots)``: the page's counters, the receiver's and the
        publisher's counters, the screenshot (H, W, 3) RGB and one per hidden part.
    """
    env_kwargs = {"objects": ["006_mustard_bottle"]}
    stop = threading.Event()
    with (
        WebSocketReceiver(0) as rx,
        TeleopLoop("handsim/Grasp-v0", TeleopConfig(anchor="start"), env_kwargs=env_kwargs) as loop,
        StatePublisher(rx, loop.env) as publisher,
    ):
        loop.env.reset(seed=0)

        def stream(i):
            if stop.is_set():
                raise _Stop
            return publisher.newest_keypoints(i)

        def run():
            # Episodes end at the task's limit (8 s): run them until the test is done.
            with contextlib.suppress(_Stop):
                while True:
                    loop.run(
                        stream, 0, realtime=True, stop_at_success=False, on_step=publisher.on_step
                    )

        runner = threading.Thread(target=run, daemon=True)
        runner.start()
        server = make_server(0, rx.port, replay=replay)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        url = f"http://127.0.0.1:{server.server_address[1]}/{query}"
        profile = tmp_path / "profile"
        browser = subprocess.Popen(
            [
                CHROMIUM,
                "--headless=new",
                "--no-sandbox",
                "--no-first-run",
                "--disable-dev-shm-usage",
                "--enable-unsafe-swiftshader",
                "--use-angle=swiftshader",
                "--window-size=800,600",
                "--remote-debugging-port=0",
                f"--user-data-dir={profile}",
                url,
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            port_file = pathlib.Path(profile / "DevToolsActivePort")
            end = time.monotonic() + 60
            while not port_file.exists() or not port_file.read_text().strip():
                assert time.monotonic() < end, "Chromium wrote no DevToolsActivePort"
                time.sleep(0.1)
            with _DevTools(int(port_file.read_text().split()[0])) as devtools:
                ok = devtools.wait(ready, 120)
                page = json.loads(devtools.eval(_PAGE_STATE))
                assert ok, page
                packets = dict(rx.counters)
                # Freeze the view (no new states) so that only the hidden part changes.
                devtools.eval("handsim.hold = true")
                full = devtools.screenshot()
                shots = {}
                for part in ("hand", "objects", "ghost"):
                    devtools.eval(f"handsim.setVisible('{part}', false)")
                    shots[part] = devtools.screenshot()
                    devtools.eval(f"handsim.setVisible('{part}', true)")
                (tmp_path / "page.png").write_bytes(cv2.imencode(".png", full[:, :, ::-1])[1])
        finally:
            stop.set()
            browser.terminate()
            browser.wait(timeout=30)
            server.shutdown()
            server.server_close()
            runner.join(timeout=10)
    return page, packets, dict(publisher.counters), full, shots


def _assert_hand_object_and_ghost_drawn(full, shots):
    """Each part covers enough pixels, of its colour (found by hiding it)."""

    def covered(part):
        diff = np.abs(full.astype(int) - shots[part].astype(int)).sum(axis=2) > 30
        return diff, full[diff].mean(axis=0) if diff.any() else np.zeros(3)

    hand, hand_rgb = covered("hand")
    bottle, bottle_rgb = covered("objects")
    ghost, ghost_rgb = covered("ghost")
    h, w = full.shape[:2]
    assert hand.sum() > 0.01 * h * w, f"hand pixels: {hand.sum()}"
    assert bottle.sum() > 0.003 * h * w, f"object pixels: {bottle.sum()}"
    assert ghost.sum() > 0.001 * h * w, f"ghost pixels: {ghost.sum()}"
    # Their colours: skin (red > green > blue), mustard yellow (blue far below), cyan ghost.
    r, g, b = hand_rgb
    assert r > g > b and r > 90, hand_rgb
    r, g, b = bottle_rgb
    assert r > 1.5 * b and g > 1.5 * b, bottle_rgb
    r, g, b = ghost_rgb
    assert g > r and b > r, ghost_rgb


@pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (apt-get install chromium)")
@pytest.mark.parametrize("mode", ["immersive-vr", "immersive-ar"])
def test_an_emulated_headset_enters_streams_and_sees_the_hand_and_the_object(tmp_path, mode):
    """Enter VR or AR with the scripted hand: packets in, states back, pixels drawn.

    The screenshot holds the physical hand's, the mustard bottle's and the ghost's pixels (each
    found as the pixels that change when the page hides that part); AR drops the background.
    """
    ready = f"window.handsim && handsim.mode === '{mode}' && handsim.statesApplied > 25"
    page, packets, stream, full, shots = _open_page(tmp_path, f"?xrtest=1&enter={mode}", ready)
    assert page["passthrough"] == (mode == "immersive-ar")
    # The world is placed so the physical hand lies over the operator's (the ghost's) wrist.
    where = page["where"]
    assert np.linalg.norm(np.subtract(where["palm"], where["ghostWrist"])) < 0.05, where
    assert page["errors"] == [] and page["scenes"] >= 1 and page["xrFrames"] > 25
    # The page's packets drove the loop, all valid.
    assert packets["accepted"] > 25 and packets["malformed"] == packets["oversized"] == 0
    assert stream["states_sent"] > 25
    # Drawn between two received states (display-rate interpolation; a loaded page skips some).
    drawn = page["drawn"]
    assert drawn["from_step"] <= drawn["to_step"] and 0 <= drawn["alpha"] <= 1, drawn
    _assert_hand_object_and_ghost_drawn(full, shots)


@pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (apt-get install chromium)")
def test_without_a_headset_the_browser_view_shows_the_replayed_scene(tmp_path):
    """No XR: the orbit view shows the scene while the page replays a recording into the loop."""
    recording = save_stream(
        stream_from_expert("handsim/Grasp-v0", 0, env_kwargs={"objects": ["006_mustard_bottle"]}),
        tmp_path / "grasp.json",
    )
    ready = "window.handsim && handsim.sent > 60 && handsim.statesApplied > 25"
    page, packets, stream, full, shots = _open_page(tmp_path, "", ready, replay=recording)
    assert page["mode"] == "browser" and page["xrFrames"] == 0 and page["errors"] == []
    assert packets["accepted"] > 60 and packets["malformed"] == 0
    assert stream["states_sent"] > 25
    _assert_hand_object_and_ghost_drawn(full, shots)


def test_every_file_of_the_page_is_package_data():
    """The package-data globs of pyproject.toml cover the page and every vendored file.

    A wheel without them would serve a page that cannot load three.js.
    """
    import fnmatch

    import tomllib

    root = pathlib.Path(__file__).resolve().parents[3]
    globs = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"
    ]["handsim.envs.teleop"]
    folder = root / "envs" / "teleop"
    files = [p.relative_to(folder).as_posix() for p in (folder / "web").rglob("*") if p.is_file()]
    assert "web/static/three/three.module.min.js" in files

    def matches(path: str, glob: str) -> bool:  # setuptools: '*' stays inside one folder
        parts, pattern = path.split("/"), glob.split("/")
        return len(parts) == len(pattern) and all(map(fnmatch.fnmatchcase, parts, pattern))

    missing = [f for f in files if not any(matches(f, g) for g in globs)]
    assert not missing, f"not in package-data: {missing}"


@pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (apt-get install chromium)")
def test_the_page_waits_for_the_loop_and_follows_it_when_it_restarts(tmp_path):
    """Opened before any loop runs, the page connects when one starts, and again after it ends.

    The second loop (another task on the same port) sends its own scene, which the page loads.
    """
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        ws_port = probe.getsockname()[1]
    server = make_server(0, ws_port)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    profile = tmp_path / "profile"
    browser = subprocess.Popen(
        [
            CHROMIUM,
            "--headless=new",
            "--no-sandbox",
            "--no-first-run",
            "--disable-dev-shm-usage",
            "--enable-unsafe-swiftshader",
            "--use-angle=swiftshader",
            "--window-size=400,300",
            "--remote-debugging-port=0",
            f"--user-data-dir={profile}",
            f"http://127.0.0.1:{server.server_address[1]}/",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    loaded = []
    try:
        port_file = pathlib.Path(profile / "DevToolsActivePort")
        end = time.monotonic() + 60
        while not port_file.exists() or not port_file.read_text().strip():
            assert time.monotonic() < end, "Chromium wrote no DevToolsActivePort"
            time.sleep(0.1)
        with _DevTools(int(port_file.read_text().split()[0])) as devtools:
            assert devtools.wait("window.handsim && handsim.framesRendered > 3", 60)
            time.sleep(1.5)  # the page has tried and failed to connect
            assert devtools.eval("handsim.connections") == 0
            for run, task in enumerate(("handsim/Press-v0", "handsim/Grasp-v0"), 1):
                with (
                    WebSocketReceiver(ws_port) as rx,
                    TeleopLoop(task) as loop,
                    StatePublisher(rx, loop.env) as publisher,
                ):
                    before = devtools.eval("handsim.statesApplied")
                    ready = (
                        f"handsim.connections === {run} && handsim.scenesLoaded === {run} && "
                        f"handsim.statesApplied > {before}"
                    )
                    for _ in range(100):  # up to 20 s of 10-step episodes
                        step = publisher.on_step
                        loop.run(lambda i: None, 0, max_steps=10, realtime=True, on_step=step)
                        if devtools.eval(ready):
                            break
                    assert devtools.eval(ready), devtools.eval(_PAGE_STATE)
                    loaded.append(devtools.eval("handsim.where().palm !== undefined"))
    finally:
        browser.terminate()
        browser.wait(timeout=30)
        server.shutdown()
        server.server_close()
    assert loaded == [True, True]


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (apt-get install chromium)")
def test_the_two_commands_show_the_scene_in_headless_chromium(tmp_path):
    """The two commands (subprocesses) and the emulated headset: the page draws the loop's scene.

    `teleop live --websocket` runs the task, `teleop serve` the page; the screenshot shows the
    hand and the object.
    """
    ws_port, http_port = _free_port(), _free_port()
    cli = [sys.executable, "-m", "handsim.cli", "teleop"]
    live = subprocess.Popen(
        [*cli, "live", "--websocket", str(ws_port), "--duration", "20", "--wait", "120"]
        + ["--out", str(tmp_path / "live")],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    serve = subprocess.Popen(
        [*cli, "serve", "--port", str(http_port), "--websocket", str(ws_port)]
        + ["--duration", "120"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    profile = tmp_path / "profile"
    browser = None
    try:
        end = time.monotonic() + 60
        while True:
            assert serve.poll() is None, serve.stdout.read()
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{http_port}/config.json", timeout=1)
                break
            except OSError:
                assert time.monotonic() < end, "teleop serve never answered"
                time.sleep(0.2)
        browser = subprocess.Popen(
            [
                CHROMIUM,
                "--headless=new",
                "--no-sandbox",
                "--enable-unsafe-swiftshader",
                "--use-angle=swiftshader",
                "--window-size=800,600",
                "--remote-debugging-port=0",
                f"--user-data-dir={profile}",
                f"http://127.0.0.1:{http_port}/?xrtest=1&enter=immersive-vr",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        port_file = pathlib.Path(profile / "DevToolsActivePort")
        while not port_file.exists() or not port_file.read_text().strip():
            assert time.monotonic() < end + 60, "Chromium wrote no DevToolsActivePort"
            time.sleep(0.1)
        with _DevTools(int(port_file.read_text().split()[0])) as devtools:
            ready = "window.handsim && handsim.mode === 'immersive-vr' && handsim.statesApplied > 9"
            assert devtools.wait(ready, 120), devtools.eval(_PAGE_STATE)
            devtools.eval("handsim.hold = true")
            full = devtools.screenshot()
            shots = {}
            for part in ("hand", "objects", "ghost"):
                devtools.eval(f"handsim.setVisible('{part}', false)")
                shots[part] = devtools.screenshot()
                devtools.eval(f"handsim.setVisible('{part}', true)")
    finally:
        for process in (browser, serve, live):
            if process is not None and process.poll() is None:
                process.terminate()
                process.wait(timeout=30)
    hand = np.abs(full.astype(int) - shots["hand"].astype(int)).sum(axis=2) > 30
    objects = np.abs(full.astype(int) - shots["objects"].astype(int)).sum(axis=2) > 30
    assert hand.sum() > 0.01 * hand.size and objects.sum() > 0.001 * objects.size


@pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (apt-get install chromium)")
@pytest.mark.parametrize("source", ["headset", "replay"])
def test_two_hands_drive_both_hands_and_both_ghosts_are_drawn(tmp_path, source):
    """Both hands from the page: each as its own packet; the page draws two ghosts.

    `headset`: the emulated headset with two hands and `?hand=both`; `replay`: no headset, the
    page replays a two-hand recording (`serve --replay`). The two-hand loop routes the packets
    by their `hand`; the state carries the left hand's ghost (`tracked_hands`), drawn over the
    physical left hand, in the ghost's cyan.
    """
    from handsim.envs.teleop import TwoHandTeleopLoop, save_streams, streams_from_expert
    from handsim.envs.teleop.sampling import LiveSampler

    replay = None
    query = "?xrtest=1&xrhands=both&hand=both&enter=immersive-vr"
    mode = "immersive-vr"
    if source == "replay":
        streams = streams_from_expert("handsim/PressTwoHands-v0", 0)
        replay = save_streams(streams, tmp_path / "two.json")
        query, mode = "", "browser"

    stop = threading.Event()
    with (
        WebSocketReceiver(0) as rx,
        TwoHandTeleopLoop("handsim/PressTwoHands-v0", TeleopConfig(anchor="start")) as loop,
        StatePublisher(rx, loop.env) as publisher,
    ):
        loop.env.reset(seed=0)
        samplers = {side: LiveSampler(rx, side) for side in ("right", "left")}

        def follow(side):
            def stream(i):
                if stop.is_set():
                    raise _Stop
                return samplers[side](i)

            return stream

        def run():
            with contextlib.suppress(_Stop):
                while True:
                    loop.run(
                        {side: follow(side) for side in samplers},
                        0,
                        realtime=True,
                        stop_at_success=False,
                        on_step=publisher.on_step,
                    )

        runner = threading.Thread(target=run, daemon=True)
        runner.start()
        server = make_server(0, rx.port, replay=replay)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        url = f"http://127.0.0.1:{server.server_address[1]}/{query}"
        profile = tmp_path / "profile"
        browser = subprocess.Popen(
            [CHROMIUM, "--headless=new", "--no-sandbox", "--no-first-run",
             "--disable-dev-shm-usage", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
             "--window-size=800,600", "--remote-debugging-port=0",
             f"--user-data-dir={profile}", url],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
        try:
            port_file = pathlib.Path(profile / "DevToolsActivePort")
            end = time.monotonic() + 60
            while not port_file.exists() or not port_file.read_text().strip():
                assert time.monotonic() < end, "Chromium wrote no DevToolsActivePort"
                time.sleep(0.1)
            with _DevTools(int(port_file.read_text().split()[0])) as devtools:
                ready = (
                    f"window.handsim && handsim.mode === '{mode}' && "
                    "handsim.statesApplied > 25 && handsim.where().leftGhostWrist !== undefined"
                )
                ok = devtools.wait(ready, 120)
                page = json.loads(devtools.eval(_PAGE_STATE))
                assert ok, page
                sides = {side: len(rx.history[side]) for side in ("right", "left")}
                devtools.eval("handsim.hold = true")
                full = devtools.screenshot()
                shots = {}
                for part in ("ghost:left", "ghost"):
                    devtools.eval(f"handsim.setVisible('{part}', false)")
                    shots[part] = devtools.screenshot()
                    devtools.eval(f"handsim.setVisible('{part}', true)")
                (tmp_path / "page.png").write_bytes(cv2.imencode(".png", full[:, :, ::-1])[1])
        finally:
            stop.set()
            browser.terminate()
            browser.wait(timeout=30)
            server.shutdown()
            server.server_close()
            runner.join(timeout=10)
    assert page["errors"] == [] and rx.counters["malformed"] == 0
    assert sides["right"] > 0 and sides["left"] > 0, sides  # each hand's own packets
    where = page["where"]
    # Each physical hand lies under its own ghost (one anchor for both hands).
    assert np.linalg.norm(np.subtract(where["palm"], where["ghostWrist"])) < 0.06, where
    assert np.linalg.norm(np.subtract(where["leftPalm"], where["leftGhostWrist"])) < 0.06, where
    assert where["leftGhostWrist"][0] < where["ghostWrist"][0] - 0.1, where
    h, w = full.shape[:2]
    left = np.abs(full.astype(int) - shots["ghost:left"].astype(int)).sum(axis=2) > 30
    both = np.abs(full.astype(int) - shots["ghost"].astype(int)).sum(axis=2) > 30
    # Each ghost is drawn: hiding the left one changes at least 0.1 % of the image, and hiding
    # the right one as well changes at least 0.1 % more (its size depends on the pose held).
    assert left.sum() > 0.001 * h * w, left.sum()
    assert both.sum() - left.sum() > 0.001 * h * w, (left.sum(), both.sum())
    r, g, b = full[left].mean(axis=0)
    assert g > r and b > r, (r, g, b)
