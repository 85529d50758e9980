"""Timestamp-aware sampling of a live stream, with prediction and end-to-end latency.

A tracker sends packets at its own rate (72, 90, 120 Hz) and the loop steps at the control
rate; taking the newest packet at every step repeats some packets and skips others and
ignores when each was measured. :class:`LiveSampler` instead reads the receiver's recent
packets of one hand (:attr:`~handsim.envs.teleop.live.LiveReceiver.history`) and, at each
control step, returns the hand at a chosen instant of the sender's clock:

- the sender's clock is mapped onto the receiver's by ``offset = min(received - t)`` over the
  packets so far (the clock difference plus the fastest transport: the usual estimate of
  network time-sync; a slower packet only arrives later than that);
- the instant sampled is ``now - offset - delay_s + predict_s``, linearly interpolated between
  the two packets around it; past the newest packet, the last two packets are extrapolated
  at constant velocity by at most ``predict_s`` (the newest packet is held beyond that);
- ``delay_s`` (default 0) trades latency for smoothness (one packet period gives pure
  interpolation); ``predict_s`` (default 0) compensates latency by extrapolating;
  ``predict_s="auto"`` predicts by the median end-to-end latency of the last
  :data:`AUTO_WINDOW` packets (at most :data:`MAX_PREDICT_S`), so the applied pose stands for
  the present.

End-to-end latency is, per packet, ``applied - t``: the instant the first pose that used it
reached the physics (after the env's step) minus its sender timestamp (a stream that stops does
not count as ever older data). When the sender stamps
``t`` with Unix time (the included sender and the page do), this is the true latency on one
machine (or NTP-synchronised ones): ``clock == "unix"``. With another clock it is measured
against the fastest packet (``clock == "relative"``: transport jitter, sampling and processing
delay, but not the constant part of the transport). Without ``t`` the arrival time stands in
for it.
"""

from __future__ import annotations

import math
import time

import numpy as np

from handsim.envs.teleop.live import HANDS, LiveReceiver
from handsim.envs.teleop.streams import InvalidStream

__all__ = ["LiveSampler", "UNIX_CLOCK_TOLERANCE_S", "MAX_PREDICT_S", "AUTO_WINDOW"]

UNIX_CLOCK_TOLERANCE_S = 10.0
"""A sender time within this of the receiver's Unix time is taken as Unix time."""
MAX_PREDICT_S = 0.1
"""Largest prediction: constant-velocity extrapolation of hand tracking past ~100 ms
overshoots every stop and turn."""
AUTO_WINDOW = 50
"""Packets whose latency ``predict_s="auto"`` follows (about 0.5 s at 90 Hz)."""


class LiveSampler:
    """Samples one hand of a receiver at control steps (module docstring).

    Args:
        receiver: the live receiver (started).
        side: the hand to follow, ``"right"`` or ``"left"``; packets of the other hand are
            ignored (counted in :attr:`other_hand`).
        delay_s: how far behind the newest data to sample, seconds, in [0, 0.1].
        predict_s: prediction, seconds, in [0, :data:`MAX_PREDICT_S`], or ``"auto"`` (the
            measured latency).

    Attributes:
        latencies_s: per packet applied, ``applied - t``, seconds.
        residual_s: per packet applied, ``applied`` minus the sender instant that the
            applied pose stands for (after delay and prediction), seconds.
        clock: ``"unix"``, ``"relative"`` or ``"arrival"`` (see the module docstring).
        packets_used: how many packets were the newest one at some step (applied).
    """

    def __init__(
        self,
        receiver: LiveReceiver,
        side: str = "right",
        *,
        delay_s: float = 0.0,
        predict_s: float | str = 0.0,
    ) -> None:
        if side not in HANDS:
            raise InvalidStream(f"side={side!r} is not valid; one of right, left")
        self.auto = predict_s == "auto"
        if self.auto:
            predict_s = 0.0
        for name, value, top in (
            ("delay_s", delay_s, 0.1),
            ("predict_s", predict_s, MAX_PREDICT_S),
        ):
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not 0 <= value <= top
            ):
                raise InvalidStream(
                    f"{name} must be a number of seconds in [0, {top}]"
                    + (' or "auto"' if name == "predict_s" else "")
                    + f"; received {value!r}"
                )
        self.receiver, self.side = receiver, side
        self.delay_s, self.predict_s = float(delay_s), float(predict_s)
        self.latencies_s: list[float] = []
        self.residual_s: list[float] = []
        self.clock: str | None = None
        self.packets_used = 0
        self._offset = math.inf
        self._resets = 0
        self._newest: object = None
        self._pending: tuple[float, float] | None = None
        self._predicted: list[float] = []

    def _times(self, frames: list) -> np.ndarray:
        # The sender's instants (arrival time when a packet has no t).
        return np.array([f.t if math.isfinite(f.t) else f.received_s for f in frames])

    def __call__(self, step: int) -> np.ndarray | None:
        """The hand to apply at this step, (21, 3) world frame, metres (``None``: none yet)."""
        del step
        with self.receiver.lock:
            frames = list(self.receiver.history[self.side])
        self._pending = None
        if not frames:
            return None
        resets = self.receiver.counters["seq_reset"]
        if resets != self._resets:  # a new stream may have a new clock
            self._resets, self._offset, self.clock = resets, math.inf, None
        if self.clock is None:
            first = frames[-1]
            if not math.isfinite(first.t):
                self.clock = "arrival"
            elif abs(first.t - first.received_s) < UNIX_CLOCK_TOLERANCE_S:
                self.clock = "unix"
            else:
                self.clock = "relative"
        t = self._times(frames)
        received = np.array([f.received_s for f in frames])
        self._offset = min(self._offset, float(np.min(received - t)))
        # Sender instants -> receiver clock: as they are for Unix time, else by the offset.
        shift = 0.0 if self.clock == "unix" else self._offset
        now = time.time()
        if self.auto and self.latencies_s:
            recent = self.latencies_s[-AUTO_WINDOW:]
            self.predict_s = min(MAX_PREDICT_S, max(0.0, float(np.median(recent))))
            self._predicted.append(self.predict_s)
        want = now - shift - self.delay_s + self.predict_s
        # Never extrapolate further than the prediction asks.
        want = min(want, t[-1] + self.predict_s)
        kp = _sample(t, [f.keypoints_world for f in frames], want)
        if frames[-1] is not self._newest:
            # Latency is per packet: from its timestamp to its first application.
            self._newest = frames[-1]
            self.packets_used += 1
            self._pending = (t[-1] + shift, want + shift)
        return kp

    def applied(self) -> None:
        """Mark the last sample as applied now (call after the physics step)."""
        if self._pending is None:
            return
        sent, stands_for = self._pending
        now = time.time()
        self.latencies_s.append(now - sent)
        self.residual_s.append(now - stands_for)
        self._pending = None

    def summary(self) -> dict[str, float | str | int | None]:
        """Latency percentiles (ms), the clock, and how many packets were used."""
        lat = np.array(self.latencies_s) * 1e3
        res = np.array(self.residual_s) * 1e3

        def pct(a: np.ndarray, q: float) -> float:
            return float(np.percentile(a, q)) if a.size else math.nan

        return {
            "latency_p50_ms": pct(lat, 50),
            "latency_p95_ms": pct(lat, 95),
            "residual_latency_p50_ms": pct(res, 50),
            "residual_latency_p95_ms": pct(res, 95),
            "latency_clock": self.clock,
            "packets_used": self.packets_used,
            "predict_s": (
                float(np.mean(self._predicted)) if self.auto and self._predicted else self.predict_s
            ),
            "predict_auto": self.auto,
            "delay_s": self.delay_s,
        }


def _sample(t: np.ndarray, keypoints: list[np.ndarray], want: float) -> np.ndarray:
    """Keypoints at sender instant ``want``: interpolated, extrapolated past the end, held."""
    n = len(t)
    if n > 1 and np.any(np.diff(t) <= 0):  # a sender clock that stepped back: no interpolation
        return keypoints[-1].copy()
    if n == 1 or want <= t[0]:
        return keypoints[0 if want <= t[0] else -1].copy()
    k = int(np.searchsorted(t, want, side="right"))
    a, b = (k - 1, k) if k < n else (n - 2, n - 1)
    span = t[b] - t[a]
    if span <= 0:
        return keypoints[b].copy()
    w = (want - t[a]) / span
    # A point untracked at either end stays untracked (NaN propagates).
    return (1 - w) * keypoints[a] + w * keypoints[b]
