"""The reactive operator (§4) and the grip stabiliser (§3): behaviour, determinism, errors."""

import json
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

from handsim.envs.teleop import InvalidTeleopConfig, TeleopConfig, TeleopLoop
from handsim.envs.teleop.grip import DIGITS, GRIP_BAND_RAD, GripStabiliser
from handsim.envs.teleop.operator import ReactiveOperator

PRESS = {"task": "button"}
QUIET = {"motor_noise_mm": 0.0, "motor_noise_rad": 0.0}


def test_reactive_operator_presses_the_button_and_is_deterministic():
    """At 0 mm tracking noise the operator does the task; a seed repeats its hand exactly."""
    config = TeleopConfig(record=True, grip_hold=False)
    with TeleopLoop("handsim/Press-v0", config, env_kwargs=PRESS) as loop:
        runs = [loop.run(ReactiveOperator(loop.env, 0), 0) for _ in range(2)]
        other = loop.run(ReactiveOperator(loop.env, 1), 0)
    a, b = (r.arrays["operator_world"] for r in runs)
    assert runs[0].metrics["success"] and runs[0].metrics["unintended_presses"] == 0
    np.testing.assert_array_equal(a, b)
    n = min(len(a), len(other.arrays["operator_world"]))
    assert not np.allclose(a[:n], other.arrays["operator_world"][:n])  # motor noise differs


def test_reactive_operator_sees_the_display_late():
    """Its delay is display latency + a reaction drawn in 150-250 ms; it plans from that state."""
    delays = [ReactiveOperator(_env(), s).reaction_s for s in range(20)]
    assert 0.15 <= min(delays) and max(delays) <= 0.25 and np.std(delays) > 0.01
    env = _env()
    op = ReactiveOperator(env, 0, display_latency_s=0.1, reaction_s=(0.2, 0.2), **QUIET)
    assert op.delay_s == pytest.approx(0.3)
    env.reset(seed=0)
    seen = []
    base = env.unwrapped
    real = base.expert_state

    def spy():
        state = real()
        seen.append(state.time_s)
        return state

    base.expert_state = spy
    planned = []
    op(1)
    inner = op._expert.act
    op._expert.act = lambda state: planned.append(state.time_s) or inner(state)
    for i in range(2, 30):
        op(i)
        env.step(env.action_space.sample() * 0 + base.scene.binding.pose(base.scene.data).vector)
    # The clock it plans with is the present (the latest state's time).
    assert planned[-1] == pytest.approx(seen[-1])
    assert len(op._seen) == round(0.3 / base.control_dt) + 1
    assert op._seen[0].time_s == pytest.approx(seen[-1] - 0.3, abs=1e-9)
    env.close()


def test_reactive_operator_corrects_its_drift_as_it_sees_it():
    """The drift it sees (late) is integrated away.

    The wrist wanders less than the drift's own std, while without the correction it keeps
    the drift's std; the correction is deterministic per seed.
    """
    env = _env()
    env.reset(seed=0)

    def wrist_offsets(**kwargs):
        quiet = ReactiveOperator(env, 3, **QUIET)
        op = ReactiveOperator(env, 3, motor_noise_mm=2.0, motor_noise_rad=0.0, **kwargs)
        return np.array([op(i)[0] - quiet(i)[0] for i in range(1, 1501)])[250:] * 1e3

    corrected = wrist_offsets()
    free = wrist_offsets(correction_s=None)
    np.testing.assert_array_equal(corrected, wrist_offsets())
    assert 1.2 < np.std(free) < 2.8  # the drift's 2 mm per axis
    assert np.std(corrected) < 0.9 * np.std(free)
    env.close()


def _env():
    import handsim.envs  # noqa: F401

    return gym.make("handsim/Press-v0", obs_mode="state", control_mode="pose", **PRESS)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"reaction_s": (0.3, 0.1)}, r"reaction_s must be \(low, high\) seconds with low <= high"),
        ({"display_latency_s": -1.0}, r"display_latency_s must be a number in \[0, 2\]"),
        ({"motor_noise_mm": float("nan")}, r"motor_noise_mm must be a number in \[0, 100\]"),
        ({"motor_time_s": 0.0}, r"motor_time_s must be a number in \[0.001, 100\]"),
        ({"correction_s": -0.5}, r"correction_s must be a number in \[0.001, 100\]"),
    ],
)
def test_reactive_operator_refuses_bad_settings(kwargs, message):
    """Bad settings name what is valid."""
    with pytest.raises(InvalidTeleopConfig, match=message):
        ReactiveOperator(_env(), 0, **kwargs)


def test_reactive_operator_needs_a_task_with_an_expert():
    """An env without an expert is refused with the tasks that have one."""
    with pytest.raises(InvalidTeleopConfig, match="has no expert .* handsim/Grasp-v0"):
        ReactiveOperator(object())


class _Data:
    ncon = 0


class _Binding:
    """The physical hand's joint angles the stabiliser reads (set by the test)."""

    def __init__(self) -> None:
        self.angles = np.zeros(21)

    def pose(self, data):
        return type("Pose", (), {"angles": self.angles.copy()})()


def _stabiliser(touch):
    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    grip = GripStabiliser(env.unwrapped, 0.02, smooth_s=1e-6)  # no smoothing: exact values
    grip.touching = lambda data: np.array(touch[0])
    grip._binding = _Binding()
    return env, grip


INDEX = 6 + np.array([5, 6, 7, 8])  # mcp_flex, mcp_abd, pip_flex, dip_flex in the 27-vector
INDEX_FLEX = INDEX[[0, 2, 3]]


def test_grip_stops_a_touching_digit_at_its_surface_and_releases_on_opening():
    """A digit closing onto an object stops at the contact posture.

    Each flexion joint presses past it as tracked; opening within the band keeps the press
    (the spread follows tracking); opening beyond the band releases the digit.
    """
    touch = [[False, True, False, False, False]]  # the index only
    env, grip = _stabiliser(touch)
    surface = np.array([0.5, 0.1, 0.7, 0.4])  # the physical index, stopped by the object
    grip._binding.angles[INDEX - 6] = surface
    target = np.zeros(27)
    target[INDEX] = [0.6, -0.1, 0.65, 0.5]  # tracked: inside the object on average
    out = grip(target, _Data())
    np.testing.assert_allclose(out[INDEX], [0.6, -0.1, 0.7, 0.5])  # never below the surface
    assert grip.latched().tolist() == [False, True, False, False, False]
    # Opening within the band keeps the press it had; the thumb follows tracking.
    opened = target.copy()
    opened[INDEX] = surface + [-0.1, 0.2, -0.15, -0.05]
    opened[6] = 0.3
    out = grip(opened, _Data())
    np.testing.assert_allclose(out[INDEX], [0.6, 0.3, 0.7, 0.5])
    assert out[6] == 0.3 and grip.held_steps == 2
    # Opening by more than the band releases: the tracked target comes through.
    opened[INDEX_FLEX] = surface[[0, 2, 3]] - GRIP_BAND_RAD - 0.05
    np.testing.assert_allclose(grip(opened, _Data())[INDEX], opened[INDEX])
    assert not grip.latched().any()
    env.close()


def test_grip_does_not_latch_a_digit_that_opens_away_from_the_object():
    """A touching digit whose tracked target is outside the object (opening) is not held."""
    touch = [[False, True, False, False, False]]
    env, grip = _stabiliser(touch)
    grip._binding.angles[INDEX - 6] = [0.5, 0.0, 0.7, 0.4]
    target = np.zeros(27)
    target[INDEX] = [0.3, 0.0, 0.5, 0.3]
    np.testing.assert_allclose(grip(target, _Data())[INDEX], target[INDEX])
    assert not grip.latched().any() and grip.held_steps == 0
    env.close()


def test_grip_releases_a_digit_off_every_object():
    """A latched digit that stops touching for release_s releases although it stays closed."""
    touch = [[False, True, False, False, False]]
    env, grip = _stabiliser(touch)
    grip._binding.angles[INDEX[0] - 6] = 0.5
    target = np.zeros(27)
    target[INDEX[0]] = 0.5
    grip(target, _Data())
    touch[0] = [False] * len(DIGITS)
    moved = target.copy()
    moved[INDEX[0]] = 0.4  # opened within the band
    outs = [grip(moved, _Data())[INDEX[0]] for _ in range(16)]
    assert outs[0] == 0.5 and outs[-1] == 0.4  # 0.3 s = 15 steps of 20 ms
    env.close()


def test_grip_hold_time_is_in_the_metrics_and_off_reports_zero():
    """The loop reports the seconds the grip stabiliser held a digit; off, it is 0."""
    from handsim.envs.teleop import stream_from_expert

    stream = stream_from_expert("handsim/Grasp-v0", 0)
    with TeleopLoop("handsim/Grasp-v0") as loop:
        on = loop.run(stream, 0).metrics
        loop.config = TeleopConfig(grip_hold=False)
        off = loop.run(stream, 0).metrics
    assert on["success"] and off["success"]
    assert on["grip_hold_s"] > 1.0 and off["grip_hold_s"] == 0.0


def test_sweep_with_the_reactive_operator_and_its_errors(tmp_path):
    """The sweep runs the reactive operator by default and says so; bad operators are refused."""
    from handsim.envs.teleop.sweep import run_sweep

    report = run_sweep(
        "handsim/Press-v0",
        noise_mm=(0.0,),
        latency_frames=(2,),
        dropout=(0.0,),
        filters=("none",),
        episodes=1,
        env_kwargs=PRESS,
    )
    assert report["operator"] == "reactive" and report["grip_hold"]
    detail = report["rows"][0]["episodes_detail"][0]
    assert 0.15 <= detail["reaction_s"] <= 0.25 and "grip_hold_s" in report["rows"][0]
    with pytest.raises(InvalidTeleopConfig, match="operator='human' is not valid; choose one of"):
        run_sweep("handsim/Press-v0", operator="human")
    with pytest.raises(InvalidTeleopConfig, match="pass operator='replay'"):
        run_sweep("handsim/Press-v0", operator="reactive", episodes=1, streams=[None])


def test_cli_sweep_reactive_operator(tmp_path):
    """`handsim teleop sweep --operator reactive --grip-hold off` runs as a subprocess."""
    out = tmp_path / "sweep"
    argv = ["teleop", "sweep", "--task", "press", "--noise-mm", "0", "--latency", "0"]
    argv += ["--dropout", "0", "--filters", "none", "--episodes", "1", "--operator", "reactive"]
    argv += ["--grip-hold", "off", "--pose-filter", "on", "--out", str(out), "-q"]
    done = subprocess.run(
        [sys.executable, "-m", "handsim.cli", *argv], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert "grip_hold_s" in done.stdout
    report = json.loads((out / "sweep.json").read_text())
    assert report["operator"] == "reactive" and report["grip_hold"] is False
    assert report["pose_filter"] is True
    bad = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "teleop", "sweep", "--operator", "human"],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and "invalid choice: 'human'" in bad.stderr
