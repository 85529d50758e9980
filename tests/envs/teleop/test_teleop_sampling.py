"""Timestamp-aware sampling of live packets: interpolation, prediction, latency, control rate."""

import math
import time
import warnings

import numpy as np
import pytest

from handsim.envs.teleop import InvalidStream, UdpReceiver
from handsim.envs.teleop.loop import (
    BehindRealTime,
    InvalidTeleopConfig,
    TeleopLoop,
    frame_skip_for,
)
from handsim.envs.teleop.sampling import LiveSampler
from handsim.envs.teleop.sender import packet

SPEED_M_S = 0.5  # the hand moves along x at this speed


def _feed(rx, n=10, rate_hz=90.0, age_s=0.0, side="right"):
    """Packets of a hand moving along x, the newest stamped ``age_s`` ago (Unix time)."""
    now = time.time()
    base = np.random.default_rng(0).normal(0.0, 0.05, (21, 3))
    for k in range(n):
        t = now - age_s - (n - 1 - k) / rate_hz
        kp = base.copy()
        kp[:, 0] += SPEED_M_S * (t - now)  # x (m) tells the sender instant
        rx.handle(packet(k, t, kp, side))
    return base, now


def _time_of(kp, base, now):
    return now + float(np.mean(kp[:, 0] - base[:, 0]) / SPEED_M_S)


def test_without_delay_or_prediction_the_newest_packet_is_applied():
    """Delay and prediction 0: the newest packet exactly (nothing is extrapolated)."""
    rx = UdpReceiver(0)
    base, now = _feed(rx)
    sampler = LiveSampler(rx)
    assert _time_of(sampler(0), base, now) == pytest.approx(now, abs=1e-5)


def test_delay_interpolates_and_prediction_extrapolates_by_the_sender_clock(monkeypatch):
    """A 15 ms delay samples 15 ms back (between packets); 30 ms prediction 30 ms ahead."""
    frozen = time.time()
    monkeypatch.setattr(time, "time", lambda: frozen)  # packets arrive and are sampled at once
    rx = UdpReceiver(0)
    base, now = _feed(rx)
    late = LiveSampler(rx, delay_s=0.015)
    assert _time_of(late(0), base, now) == pytest.approx(now - 0.015, abs=1e-5)
    ahead = LiveSampler(rx, predict_s=0.03)
    assert _time_of(ahead(0), base, now) == pytest.approx(now + 0.03, abs=1e-5)


def test_latency_is_per_packet_from_its_timestamp_to_its_application(monkeypatch):
    """Packets sent 40 ms ago: latency 40 ms on the Unix clock, counted once per packet."""
    frozen = time.time()
    monkeypatch.setattr(time, "time", lambda: frozen)
    rx = UdpReceiver(0)
    _feed(rx, n=3, age_s=0.04)
    sampler = LiveSampler(rx)
    sampler(0)
    sampler.applied()
    sampler(1)  # the same newest packet: not a new latency sample
    sampler.applied()
    summary = sampler.summary()
    assert summary["latency_clock"] == "unix" and len(sampler.latencies_s) == 1
    assert summary["latency_p50_ms"] == pytest.approx(40.0, abs=1e-3)
    # A sender on its own clock: latency relative to the fastest packet.
    rx = UdpReceiver(0)
    for k in range(3):
        rx.handle(packet(k, 1000.0 + k / 90, np.zeros((21, 3))))
    sampler = LiveSampler(rx)
    sampler(0)
    sampler.applied()
    assert sampler.clock == "relative" and sampler.latencies_s[0] == pytest.approx(0, abs=1e-6)


def test_the_other_hand_is_ignored_and_settings_are_checked():
    """A right-hand sampler does not see left-hand packets; bad settings name the range."""
    rx = UdpReceiver(0)
    _feed(rx, side="left")
    assert LiveSampler(rx, "right")(0) is None and LiveSampler(rx, "left")(0) is not None
    with pytest.raises(InvalidStream, match=r"predict_s must be a number of seconds in \[0, 0.1\]"):
        LiveSampler(rx, predict_s=0.5)
    with pytest.raises(InvalidStream, match="side='both' is not valid; one of right, left"):
        LiveSampler(rx, "both")


@pytest.mark.parametrize(
    ("rate_hz", "frame_skip"), [(50, 10), (50.2, 10), (72, 6), (90, 5), (120, 4), (10, 50)]
)
def test_physics_sub_steps_are_sized_to_the_stream_rate(rate_hz, frame_skip):
    """The control period is the largest multiple of 2 ms not longer than the stream's."""
    assert frame_skip_for(rate_hz) == frame_skip
    assert 1 / (frame_skip * 0.002) >= rate_hz / 1.005


def test_control_rate_and_episode_limit():
    """At 90 Hz the env steps at 100 Hz and its 8 s episode keeps 8 s; bad rates are refused."""
    with TeleopLoop("handsim/Grasp-v0", control_rate_hz=90) as loop:
        assert loop.control_dt == pytest.approx(0.01)
        assert loop.env.spec.max_episode_steps == 800
    with TeleopLoop("handsim/Grasp-v0", episode_s=20.0) as loop:
        assert loop.control_dt == pytest.approx(0.02)
        assert loop.env.spec.max_episode_steps == 1000
    with pytest.raises(
        InvalidTeleopConfig, match=r"control_rate_hz must be a number in \(0, 120\]"
    ):
        TeleopLoop("handsim/Grasp-v0", control_rate_hz=240)


def test_a_loop_behind_real_time_warns():
    """A stream that takes 40 ms a step at 50 Hz control: the loop warns, once."""

    def slow(_):
        time.sleep(0.04)
        return None

    with TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            m = loop.run(slow, 0, max_steps=60, realtime=True).metrics
    behind = [w for w in caught if issubclass(w.category, BehindRealTime)]
    assert len(behind) == 1 and "% of real time" in str(behind[0].message)
    assert m["realtime_factor"] < 0.9 and not math.isnan(m["realtime_factor"])


def test_a_sender_clock_that_steps_back_gives_the_newest_packet():
    """Timestamps out of order (seq in order): no interpolation across them, the newest."""
    rx = UdpReceiver(0)
    kps = [np.full((21, 3), 0.01 * k) for k in range(3)]
    for k, t in enumerate((1000.0, 1000.02, 1000.01)):
        rx.handle(packet(k, t, kps[k]))
    np.testing.assert_allclose(LiveSampler(rx, delay_s=0.05)(0), kps[2], atol=1e-6)


def test_auto_prediction_follows_the_measured_latency(monkeypatch):
    """predict_s='auto': after packets 40 ms old, the next sample is predicted 40 ms ahead."""
    now = [time.time()]
    monkeypatch.setattr(time, "time", lambda: now[0])
    rx = UdpReceiver(0)
    base, sent = _feed(rx, n=3, age_s=0.04)
    sampler = LiveSampler(rx, predict_s="auto")
    sampler(0)  # no latency measured yet: no prediction
    sampler.applied()
    assert sampler.latencies_s == [pytest.approx(0.04, abs=1e-6)]
    kp = sampler(1)
    # The newest packet is 40 ms old: extrapolated 40 ms, the hand where it is now.
    assert _time_of(kp, base, sent) == pytest.approx(sent - 0.04 + 0.04, abs=1e-5)
    assert sampler.summary()["predict_auto"] is True
    with pytest.raises(
        InvalidStream, match='predict_s must be a number of seconds in .* or "auto"'
    ):
        LiveSampler(rx, predict_s="soon")
