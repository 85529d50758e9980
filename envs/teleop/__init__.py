"""Teleoperation: drive the physical hand from tracked operator streams, with tracking faults.

For VR/AR interaction prototyping: replay a recorded OpenXR / WebXR / MediaPipe / keypoint
file or a live UDP / WebSocket stream through a tracker model (direct, or capture camera +
estimator), inject noise, bias, latency, jitter, dropout and occlusion, smooth with the One
Euro filter, retarget onto the physical hand and measure what the user would feel (success,
interpenetration, slip, jitter, lag, unintended presses).

- :mod:`~handsim.envs.teleop.streams`: operator streams (files, generated).
- :mod:`~handsim.envs.teleop.live`: live packets over UDP and WebSocket.
- :mod:`~handsim.envs.teleop.sampling`: timestamp-aware sampling, prediction, latency.
- :mod:`~handsim.envs.teleop.handedness`: the side check of streams.
- :mod:`~handsim.envs.teleop.capture`: camera mode's capture scene.
- :mod:`~handsim.envs.teleop.events`: interaction events (pinch, grab, buttons, slider).
- :mod:`~handsim.envs.teleop.faults`, :mod:`~handsim.envs.teleop.filters`: faults, smoothing.
- :mod:`~handsim.envs.teleop.loop`: :class:`TeleopLoop`, rollouts.
- :mod:`~handsim.envs.teleop.metrics`: the metrics.
- :mod:`~handsim.envs.teleop.sweep`: degradation sweeps (table and plots).
"""

from handsim.envs.teleop.events import EVENT_KINDS, InteractionEvent
from handsim.envs.teleop.faults import FaultConfig, FaultInjector, InvalidFaults
from handsim.envs.teleop.filters import (
    FILTERS,
    ExponentialFilter,
    InvalidFilter,
    NoFilter,
    OneEuroFilter,
    make_filter,
)
from handsim.envs.teleop.live import (
    InvalidPacket,
    LiveReceiver,
    UdpReceiver,
    WebSocketReceiver,
    parse_packet,
)
from handsim.envs.teleop.loop import (
    BehindRealTime,
    InvalidTeleopConfig,
    TeleopConfig,
    TeleopEpisode,
    TeleopLoop,
    read_rollout,
    write_rollout,
)
from handsim.envs.teleop.sampling import LiveSampler
from handsim.envs.teleop.streams import (
    STREAM_FORMATS,
    InvalidStream,
    OperatorStream,
    load_stream,
    save_stream,
    stream_from_expert,
    stream_from_motion,
    stream_from_poses,
)
from handsim.envs.teleop.two_hands import (
    TwoHandTeleopLoop,
    load_streams,
    save_streams,
    streams_from_expert,
)

__all__ = [
    "OperatorStream",
    "STREAM_FORMATS",
    "InvalidStream",
    "load_stream",
    "save_stream",
    "stream_from_poses",
    "stream_from_motion",
    "stream_from_expert",
    "InvalidPacket",
    "parse_packet",
    "LiveReceiver",
    "UdpReceiver",
    "WebSocketReceiver",
    "LiveSampler",
    "FaultConfig",
    "FaultInjector",
    "InvalidFaults",
    "FILTERS",
    "OneEuroFilter",
    "ExponentialFilter",
    "NoFilter",
    "InvalidFilter",
    "make_filter",
    "TeleopConfig",
    "TeleopLoop",
    "TeleopEpisode",
    "InvalidTeleopConfig",
    "BehindRealTime",
    "write_rollout",
    "read_rollout",
    "InteractionEvent",
    "EVENT_KINDS",
    "TwoHandTeleopLoop",
    "load_streams",
    "save_streams",
    "streams_from_expert",
]
