"""The WebXR bridge page: served, and in headless Chromium it streams its replay into the loop."""

import json
import shutil
import subprocess
import threading
import urllib.error
import urllib.request

import pytest

from handsim.envs.teleop import TeleopLoop, WebSocketReceiver, save_stream, stream_from_expert
from handsim.envs.teleop.web import make_server

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A recorded press (the expert's stream of seed 0) as a JSON stream file."""
    stream = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
    return stream, save_stream(stream, tmp_path_factory.mktemp("rec") / "press.json")


def _get(url):
    with urllib.request.urlopen(url, timeout=10) as response:
        return response.read()


def test_the_page_config_and_recording_are_served(recording):
    """`/` is the page, `/config.json` names the WebSocket port, `/replay.json` the frames."""
    stream, path = recording
    server = make_server(0, 9999, replay=path)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        page = _get(base + "/").decode()
        assert '<script type="module" src="static/page.js">' in page
        script = _get(base + "/static/page.js").decode()  # the page's code, with its WebXR
        assert "XRHandJoint" in script and "getJointPose" in script
        assert json.loads(_get(base + "/config.json")) == {"ws_port": 9999, "has_replay": True}
        replay = json.loads(_get(base + "/replay.json"))
        assert len(replay["frames"]) == len(stream) and replay["fps"] == pytest.approx(50.0)
        with pytest.raises(urllib.error.HTTPError, match="404"):
            _get(base + "/etc/passwd")
    finally:
        server.shutdown()
        server.server_close()


@pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (apt-get install chromium)")
def test_headless_chromium_streams_the_replay_into_the_loop(recording, tmp_path):
    """The page loads in headless Chromium, connects, and its replay drives the press."""
    stream, path = recording
    with (
        WebSocketReceiver(0) as rx,
        TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop,
    ):
        server = make_server(0, rx.port, replay=path)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        loop.env.reset(seed=0)
        url = f"http://127.0.0.1:{server.server_address[1]}/"
        browser = subprocess.Popen(
            [
                CHROMIUM,
                "--headless=new",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--disable-dev-shm-usage",
                f"--user-data-dir={tmp_path / 'profile'}",
                url,
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            assert rx.wait_for(1, 90.0), f"no packet from the page: {rx.counters}"

            def newest(_):
                frame = rx.latest()
                return None if frame is None else frame.keypoints_world

            metrics = loop.run(newest, 0, max_steps=len(stream) + 25, realtime=True).metrics
            assert rx.wait_for(len(stream), 30.0)
        finally:
            browser.terminate()
            browser.wait(timeout=30)
            server.shutdown()
            server.server_close()
    assert rx.counters["accepted"] == len(stream)
    assert rx.counters["malformed"] == rx.counters["out_of_order"] == 0
    assert metrics["steps"] > 20 and metrics["tracking_error_mm"] < 30.0
