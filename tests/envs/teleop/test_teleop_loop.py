"""The teleop loop: direct-mode replays grasp and press; faults cost; camera mode; rollouts."""

import threading
import time

import numpy as np
import pytest

from handsim.envs.teleop import (
    FaultConfig,
    InvalidStream,
    InvalidTeleopConfig,
    TeleopConfig,
    TeleopLoop,
    UdpReceiver,
    read_rollout,
    stream_from_expert,
    write_rollout,
)
from handsim.envs.teleop.sender import send_stream


@pytest.fixture(scope="module")
def press_stream():
    """The press expert's stream of seed 0 (button task)."""
    return stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})


def test_direct_mode_replays_a_generated_stream_and_grasps():
    """Direct mode replays a generated stream and grasps."""
    stream = stream_from_expert("handsim/Grasp-v0", 0)
    with TeleopLoop("handsim/Grasp-v0") as loop:
        episode = loop.run(stream, 0)
    m = episode.metrics
    assert m["success"] and m["time_to_success_s"] > 2.0
    assert m["slip_max_mm"] < 10.0 and m["penetration_max_mm"] < 5.0
    assert m["dropped_frames"] == 0 and not m["physics_diverged"]
    assert m["tracking_error_mm"] < 5.0


def test_direct_press_replay_and_what_latency_does(press_stream):
    """Direct press replay and what latency does."""
    with TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop:
        clean = loop.run(press_stream, 0).metrics
        loop.config = TeleopConfig(faults=FaultConfig(latency_frames=5))
        late = loop.run(press_stream, 0).metrics
    assert clean["success"] and clean["unintended_presses"] == 0
    assert late["success"]
    # Lag is measured by cross-correlation: 5 frames later than the clean run.
    assert late["lag_s"] - clean["lag_s"] == pytest.approx(5 * clean["control_dt_s"], abs=0.021)
    assert late["time_to_success_s"] > clean["time_to_success_s"]


def test_noise_raises_jitter_and_the_one_euro_filter_lowers_it(press_stream):
    """Noise raises jitter and the one euro filter lowers it."""
    noisy = TeleopConfig(faults=FaultConfig(noise_mm=8.0))
    with TeleopLoop("handsim/Press-v0", noisy, env_kwargs={"task": "button"}) as loop:
        raw = loop.run(press_stream, 0, stop_at_success=False).metrics
        loop.config = TeleopConfig(faults=FaultConfig(noise_mm=8.0), filter="one_euro")
        filtered = loop.run(press_stream, 0, stop_at_success=False).metrics
        loop.config = TeleopConfig()
        clean = loop.run(press_stream, 0, stop_at_success=False).metrics
    assert raw["jitter_mm"] > 3 * clean["jitter_mm"]
    assert filtered["jitter_mm"] < 0.7 * raw["jitter_mm"]


def test_camera_mode_with_the_oracle_and_a_rollout(press_stream, tmp_path):
    """Camera mode with the oracle and a rollout."""
    from handsim.estimators import OracleEstimator  # the test glues the layers, as the CLI does

    config = TeleopConfig(mode="camera", record=True, sensor="structured_light")
    with TeleopLoop(
        "handsim/Press-v0", config, estimator=OracleEstimator(rng=0), env_kwargs={"task": "button"}
    ) as loop:
        episode = loop.run(press_stream, 0, max_steps=40)
        path = write_rollout(tmp_path / "r.npz", episode, loop)
    m = episode.metrics
    assert m["steps"] == 40 and m["stage_ms"]["capture"] > 0 and m["stage_ms"]["estimator"] > 0
    meta, arrays = read_rollout(path)
    assert meta["env_id"] == "handsim/Press-v0" and meta["seed"] == 0
    assert arrays["depth_mm"].shape == (40, 240, 320) and arrays["depth_mm"].dtype == np.uint16
    # The oracle without noise returns the rendered operator hand's truth.
    np.testing.assert_allclose(arrays["estimate_cam"], arrays["truth_cam"], atol=1e-9)
    assert (arrays["depth_mm"][-1] > 0).mean() > 0.5

    from handsim.envs.teleop.view import render_rollout

    video = render_rollout(path, tmp_path / "r.gif", every=10)
    assert video.stat().st_size > 1000

    from handsim.envs.teleop.view import log_rollout_rerun

    try:
        import rerun  # noqa: F401
    except ImportError:
        with pytest.raises(InvalidStream, match="needs the optional 'rerun-sdk'"):
            log_rollout_rerun(path, tmp_path / "r.rrd")
    else:
        assert log_rollout_rerun(path, tmp_path / "r.rrd").stat().st_size > 1000


def test_camera_mode_with_a_keypoint_stream_poses_the_operator_hand_by_retargeting(press_stream):
    """Without poses, the operator hand is retargeted to the keypoints, then captured."""
    from handsim.envs.teleop import OperatorStream
    from handsim.estimators import OracleEstimator

    keypoints = press_stream.keypoints_world.copy()
    keypoints[10:15, 2:5] = np.nan  # the thumb untracked for a while
    keypoints[20] = np.nan  # nothing tracked in one frame
    stream = OperatorStream(press_stream.times_s, keypoints)
    config = TeleopConfig(mode="camera", record=True)
    with TeleopLoop(
        "handsim/Press-v0", config, estimator=OracleEstimator(rng=0), env_kwargs={"task": "button"}
    ) as loop:
        episode = loop.run(stream, 0, max_steps=30)
    truth = episode.arrays["truth_cam"]
    T = episode.arrays["T_cam_from_world"]  # noqa: N806
    operator_cam = press_stream.keypoints_world[1:31] @ T[:3, :3].T + T[:3, 3]
    error_mm = 1e3 * np.linalg.norm(truth - operator_cam, axis=-1).mean()
    assert error_mm < 5.0  # the rendered operator hand is where the stream says
    assert episode.metrics["dropped_frames"] == 0  # the camera sees the held operator hand


def test_live_udp_stream_drives_the_hand(press_stream):
    """Live udp stream drives the hand."""
    with (
        UdpReceiver(0) as rx,
        TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop,
    ):
        loop.env.reset(seed=0)
        sender = threading.Thread(target=send_stream, args=(press_stream, rx.port))
        sender.start()
        assert rx.wait_for(1, 5.0)

        def newest(_):
            frame = rx.latest()
            return None if frame is None else frame.keypoints_world

        t0 = time.perf_counter()
        m = loop.run(newest, 0, max_steps=len(press_stream) + 20, realtime=True).metrics
        sender.join()
    assert rx.counters["accepted"] == len(press_stream)
    assert m["steps"] > 20 and time.perf_counter() - t0 >= 0.9 * m["steps"] * m["control_dt_s"]
    assert m["tracking_error_mm"] < 30.0


def test_bad_loop_settings():
    """Bad loop settings."""
    with pytest.raises(InvalidTeleopConfig, match="mode='camera' needs an estimator"):
        TeleopLoop("handsim/Press-v0", TeleopConfig(mode="camera"))
    with pytest.raises(InvalidTeleopConfig, match="estimator must satisfy"):
        TeleopLoop("handsim/Press-v0", TeleopConfig(mode="camera"), estimator=object())
    with pytest.raises(InvalidTeleopConfig, match="mode='vr' is not valid; choose one of direct"):
        TeleopConfig(mode="vr")
    with pytest.raises(InvalidTeleopConfig, match="anchor='x' is not valid"):
        TeleopConfig(anchor="x")


def test_sweep_writes_table_and_plots(press_stream, tmp_path):
    """Sweep writes table and plots."""
    from handsim.envs.teleop.sweep import SWEEP_COLUMNS, run_sweep, write_sweep

    report = run_sweep(
        "handsim/Press-v0",
        noise_mm=(0.0, 10.0),
        latency_frames=(0, 3),
        dropout=(0.0,),
        filters=("none",),
        episodes=1,
        env_kwargs={"task": "button"},
        streams=[press_stream],
    )
    assert len(report["rows"]) == 4
    first = report["rows"][0]
    assert (first["noise_mm"], first["latency_frames"]) == (0.0, 0) and first["success_rate"] == 1
    paths = write_sweep(report, tmp_path)
    header = paths["csv"].read_text().splitlines()[0].split(",")
    assert tuple(header) == SWEEP_COLUMNS
    for kind in ("success_vs_noise", "jitter_vs_noise", "success_vs_latency", "json"):
        assert paths[kind].stat().st_size > 0
