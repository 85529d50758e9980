"""Interaction events: pinch, grab/release, button press/release and slider, with timestamps."""

import numpy as np
import pytest

from handsim.envs.teleop import TeleopConfig, TeleopLoop, read_rollout, stream_from_expert
from handsim.envs.teleop.events import EVENT_KINDS, PINCH_END_M, PINCH_START_M
from handsim.envs.teleop.loop import write_rollout


def _kinds(events):
    return [e.kind for e in events]


def test_a_pinch_starts_and_ends_once_with_hysteresis():
    """Thumb-index gap 5 -> 1 cm -> 2.5 cm (between thresholds) -> 5 cm: one start, one end."""
    stream = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
    base = stream.keypoints_world[0]
    gaps = np.r_[np.full(10, 0.05), np.full(10, 0.01), np.full(10, 0.025), np.full(10, 0.05)]

    def operator(i):
        kp = base.copy()
        kp[8] = kp[4] + [gaps[min(i, len(gaps) - 1)], 0.0, 0.0]
        return kp

    with TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop:
        episode = loop.run(operator, 0, max_steps=40)
    pinches = [e for e in episode.events if e.kind.startswith("pinch")]
    assert _kinds(pinches) == ["pinch_start", "pinch_end"]
    start, end = pinches
    assert (
        start.step == 10 and end.step == 30
    )  # operator(i) at step i; 2.5 cm is neither under 2 nor over 3 cm
    assert start.value < PINCH_START_M and end.value > PINCH_END_M
    assert start.t_s == pytest.approx(10 * loop.control_dt) and start.hand == "right"
    assert episode.metrics["events"]["pinch_start"] == 1


def test_the_press_expert_presses_and_releases_its_target_and_events_reach_the_rollout(tmp_path):
    """The target button's press comes when the task succeeds; the rollout keeps the events."""
    stream = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
    with TeleopLoop(
        "handsim/Press-v0", TeleopConfig(record=True), env_kwargs={"task": "button"}
    ) as loop:
        episode = loop.run(stream, 0, stop_at_success=False)
        path = write_rollout(tmp_path / "r.npz", episode, loop)
        target = loop.env.unwrapped._target_index()
    presses = [e for e in episode.events if e.kind == "button_press"]
    assert presses and presses[0].target == f"button_{target}"
    assert presses[0].t_s == pytest.approx(episode.metrics["time_to_success_s"], abs=0.05)
    meta, _ = read_rollout(path)
    assert [e["kind"] for e in meta["events"]] == _kinds(episode.events)
    assert set(meta["metrics"]["events"]) == set(EVENT_KINDS)


def test_the_grasp_expert_grabs_its_object_and_the_slider_reports_its_value():
    """A grasp replay grabs the object; a slider replay reports the knob's positions."""
    stream = stream_from_expert("handsim/Grasp-v0", 0)
    with TeleopLoop("handsim/Grasp-v0") as loop:
        episode = loop.run(stream, 0)
        name = loop.env.unwrapped.scene.objects[0][0]
    grabs = [e for e in episode.events if e.kind == "grab"]
    assert grabs and grabs[0].target == name and grabs[0].t_s > 0.5
    kwargs = {"task": "slider"}
    stream = stream_from_expert("handsim/Press-v0", 1, env_kwargs=kwargs)
    with TeleopLoop("handsim/Press-v0", env_kwargs=kwargs) as loop:
        episode = loop.run(stream, 1)
        goal = loop.env.unwrapped.slider_goal_m
    slides = [e.value for e in episode.events if e.kind == "slider"]
    assert len(slides) >= 3 and abs(slides[-1] - goal) < abs(slides[0] - goal)
