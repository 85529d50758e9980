"""Two hands at once: streams routed by their `hand`, the side check, events naming the hand."""

import json

import numpy as np
import pytest

from handsim.envs.teleop import (
    InvalidStream,
    InvalidTeleopConfig,
    OperatorStream,
    TeleopConfig,
    TeleopLoop,
    TwoHandTeleopLoop,
    UdpReceiver,
    load_stream,
    load_streams,
    read_rollout,
    save_streams,
    streams_from_expert,
    write_rollout,
)
from handsim.envs.teleop.sampling import LiveSampler
from handsim.envs.teleop.sender import send_streams
from handsim.envs.teleop.two_hands import parse_streams, route_streams

ENV_ID = "handsim/PressTwoHands-v0"


@pytest.fixture(scope="module")
def expert():
    """The two-hand press expert's streams (right, left), seed 0."""
    return streams_from_expert(ENV_ID, 0)


@pytest.fixture(scope="module")
def loop():
    """One two-hand loop for the module's episodes."""
    with TwoHandTeleopLoop(ENV_ID) as lp:
        yield lp


def _keypoints(stream, side):
    """The stream as keypoints only (the side check skips pose streams), with ``side``."""
    return OperatorStream(
        stream.times_s, stream.keypoints_world, None, side, None, None, f"{stream.side} as {side}"
    )


def _press_events(episode):
    return sorted((e.hand, e.target) for e in episode.events if e.kind == "button_press")


def test_the_expert_replayed_on_both_hands_succeeds_and_events_name_the_hand(loop, expert):
    """Both hands press their own button; each press names the hand that pressed."""
    right, left = expert
    assert (right.side, left.side) == ("right", "left")
    episode = loop.run(expert, 0)
    assert episode.metrics["success"] and episode.metrics["unintended_presses"] == 0
    assert _press_events(episode) == [("left", "button_0"), ("right", "button_2")]
    for side in ("right", "left"):
        hand = episode.metrics["hands"][side]
        assert hand["streamed"] and hand["tracking_error_mm"] < 5.0
        assert hand["penetration_max_mm"] < 3.0
    # Routing is by the streams' sides, not their order, nor a dict's.
    swapped = loop.run([left, right], 0)
    by_dict = loop.run({"left": left, "right": right}, 0)
    for other in (swapped, by_dict):
        assert other.metrics["hands"] == episode.metrics["hands"]
        assert _press_events(other) == _press_events(episode)


def test_one_hand_streamed_the_other_holds_still(loop, expert):
    """A right stream alone: only the right button is pressed; no two-hand success."""
    episode = loop.run(expert[:1], 0)
    assert not episode.metrics["success"]
    assert _press_events(episode) == [("right", "button_2")]
    assert not episode.metrics["hands"]["left"]["streamed"]
    assert episode.metrics["hands"]["left"]["jitter_mm"] < 0.05  # held at its start


def test_a_stream_whose_geometry_is_the_other_side_is_refused(loop, expert):
    """Left keypoints labelled right (and the reverse) are refused, naming the fix."""
    right, left = expert
    with pytest.raises(
        InvalidStream,
        match=r"left as right says hand='right', but its keypoints are a left hand in \d of "
        r"\d frames checked .*set the stream's 'hand' to 'left'",
    ):
        loop.run([_keypoints(left, "right"), _keypoints(right, "left")], 0)
    # Correctly labelled keypoint streams pass the check and drive the hands.
    episode = loop.run([_keypoints(right, "right"), _keypoints(left, "left")], 0)
    assert episode.metrics["success"]


def test_routing_errors_say_what_is_valid(expert):
    """Two streams of one side, a dict key against its stream, a function without a side."""
    right, _ = expert
    with pytest.raises(InvalidStream, match=r"two streams of the right hand .*one right and one"):
        route_streams([right, right])
    with pytest.raises(InvalidStream, match=r"given for the left hand is a right hand's"):
        route_streams({"left": right})
    with pytest.raises(InvalidStream, match=r"function stream carries no side: .*dict by side"):
        route_streams([lambda i: None])
    with pytest.raises(InvalidStream, match=r"hand='middle' is not valid; one of right, left"):
        route_streams({"middle": lambda i: None})


def test_function_streams_pinch_with_the_left_hand_only(loop, expert):
    """Functions by side: the left hand pinches, the right does not: the event says left."""
    right, left = expert
    kp_left, kp_right = left.keypoints_world[0].copy(), right.keypoints_world[0]

    def pinching(i):
        kp = kp_left.copy()
        if i >= 5:
            kp[8] = kp[4] + [0.01, 0.0, 0.0]
        return kp

    episode = loop.run({"left": pinching, "right": lambda i: kp_right}, 0, max_steps=10)
    pinches = [(e.kind, e.hand, e.step) for e in episode.events if e.kind.startswith("pinch")]
    assert pinches == [("pinch_start", "left", 5)]


def test_two_hand_files_round_trip_and_errors(tmp_path, expert):
    """save_streams/load_streams keep both hands; a one-hand file reads as one stream."""
    path = save_streams(expert, tmp_path / "two.json")
    back = load_streams(path)
    assert [s.side for s in back] == ["right", "left"]
    for a, b in zip(back, expert, strict=True):
        np.testing.assert_allclose(a.poses, b.poses, atol=1e-12)
    doc = json.loads(path.read_text())
    assert [h["hand"] for h in doc["hands"]] == ["right", "left"]
    one = tmp_path / "one.json"
    one.write_text(json.dumps(doc["hands"][1]))
    assert [s.side for s in load_streams(one)] == ["left"] and load_stream(one).side == "left"
    with pytest.raises(InvalidStream, match=r"'hands' must be a list of one or two stream"):
        parse_streams({"hands": {"right": {}}}, "x.json")
    with pytest.raises(InvalidStream, match=r"x.json hands\[1\]: missing the array .keypoints."):
        parse_streams({"hands": [doc["hands"][0], {"hand": "left"}]}, "x.json")
    # Defaults beside "hands" apply to each; two of one side are refused.
    both_right = {"format": "pose27", "hands": [doc["hands"][0], doc["hands"][0]]}
    with pytest.raises(InvalidStream, match=r"two streams of the right hand"):
        parse_streams(both_right, "x.json")
    with pytest.raises(InvalidStream, match=r"a two-hand stream file is JSON"):
        save_streams(expert, tmp_path / "two.npz")


def test_loops_refuse_the_wrong_number_of_hands():
    """The one-hand loop refuses a two-hand env and the reverse; two hands need direct mode."""
    with pytest.raises(InvalidTeleopConfig, match=r"has two hands: run it with .*TwoHandTeleop"):
        TeleopLoop(ENV_ID)
    with pytest.raises(InvalidTeleopConfig, match=r"Press-v0 has one hand: use TeleopLoop"):
        TwoHandTeleopLoop("handsim/Press-v0")
    with pytest.raises(InvalidTeleopConfig, match=r"mode='camera': two hands run in mode='direct"):
        TwoHandTeleopLoop(ENV_ID, TeleopConfig(mode="camera"))


def test_recorded_two_hand_rollout(tmp_path, expert):
    """record=True keeps both hands' keypoints; the rollout reads back with both."""
    with TwoHandTeleopLoop(ENV_ID, TeleopConfig(record=True)) as lp:
        episode = lp.run(expert, 0)
        path = write_rollout(tmp_path / "r.npz", episode, lp)
    meta, arrays = read_rollout(path)
    steps = episode.metrics["steps"]
    assert arrays["physical_world"].shape == arrays["physical_world_left"].shape == (steps, 21, 3)
    assert arrays["mocap_pos"].shape == (steps, 2, 3)
    assert {e["hand"] for e in meta["events"]} == {"right", "left"}
    # The left hand's physical keypoints are left of the right hand's (world x).
    assert arrays["physical_world_left"][:, 0, 0].max() < arrays["physical_world"][:, 0, 0].min()
    # `handsim view` plays it: both physical hands, both hands' skeletons.
    from handsim.envs.teleop.view import render_rollout

    video = render_rollout(path, tmp_path / "r.gif", every=40)
    assert video.stat().st_size > 1000


def test_live_packets_are_routed_by_their_hand(expert):
    """Both hands' packets over one UDP socket, each sampler following its side."""
    import threading

    class StartsTheSender(LiveSampler):
        # The streams (1.6 s) start when the loop first samples, after its reset: a reset
        # slowed by a busy machine then costs no packets.
        def __call__(self, step):
            if sender.ident is None:  # not started yet
                sender.start()
                assert rx.wait_for(4, 5.0)
            return super().__call__(step)

    with UdpReceiver(0) as rx, TwoHandTeleopLoop(ENV_ID, TeleopConfig(anchor="start")) as lp:
        sender = threading.Thread(target=send_streams, args=(expert, rx.port), daemon=True)
        samplers = [StartsTheSender(rx, "left"), StartsTheSender(rx, "right")]
        episode = lp.run(samplers, 0, max_steps=90, realtime=True, stop_at_success=False)
        sender.join(timeout=10)
    hands = episode.metrics["hands"]
    for side in ("right", "left"):
        assert hands[side]["packets_used"] >= 40, hands[side]
        assert hands[side]["tracking_error_mm"] < 30.0
    assert {e.hand for e in episode.events if e.kind == "button_press"} == {"right", "left"}


def test_the_page_serves_a_two_hand_recording_with_both_hands(tmp_path, expert):
    """`serve --replay` of a two-hand file: /replay.json lists both hands for the page."""
    import threading
    import urllib.request

    from handsim.envs.teleop.web import make_server

    path = save_streams(expert, tmp_path / "two.json")
    server = make_server(0, 9999, replay=path)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/replay.json"
        doc = json.loads(urllib.request.urlopen(url, timeout=10).read())
    finally:
        server.shutdown()
        server.server_close()
    assert [h["hand"] for h in doc["hands"]] == ["right", "left"]
    assert len(doc["hands"][1]["frames"]) == len(expert[1]) and doc["hand"] == "right"
    left = np.array(doc["hands"][1]["frames"][0]["keypoints"])
    np.testing.assert_allclose(left, expert[1].keypoints_world[0], atol=1e-6)


def test_the_pose_filter_smooths_each_hand(expert):
    """With 10 mm of tracking noise, pose_filter=True steadies both hands (each its own filter)."""
    from handsim.envs.teleop.faults import FaultConfig

    jitter = {}
    for on in (False, True):
        cfg = TeleopConfig(faults=FaultConfig(noise_mm=10.0), pose_filter=on)
        with TwoHandTeleopLoop(ENV_ID, cfg) as lp:
            hands = lp.run(expert, 0).metrics["hands"]
        jitter[on] = {side: hands[side]["jitter_mm"] for side in ("right", "left")}
    for side in ("right", "left"):
        assert jitter[True][side] < 0.5 * jitter[False][side], jitter
