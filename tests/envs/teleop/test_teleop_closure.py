"""The grasp intent's closure assist (§3): digits close toward the object, then press."""

import gymnasium as gym
import numpy as np
import pytest

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.teleop import TeleopConfig, TeleopLoop, stream_from_expert
from handsim.envs.teleop.filters import InvalidFilter
from handsim.envs.teleop.grip import _DIGIT_FLEX
from handsim.envs.teleop.intent import CLOSE_S, GraspIntent
from handsim.envs.teleop.loop import InvalidTeleopConfig
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_LIMITS, JOINT_NAMES, HandPose
from handsim.hand.pose_library import GRASP_TYPES

_FLEX = np.array(["flex" in n for n in JOINT_NAMES])
THUMB, INDEX, MIDDLE, RING = (_DIGIT_FLEX[d] for d in range(4))


def _keypoints(flex_fraction: float) -> np.ndarray:
    angles = np.zeros(21)
    angles[_FLEX] = flex_fraction * JOINT_LIMITS[_FLEX, 1]
    return ForwardKinematics(HandParams()).keypoints(HandPose(np.zeros(3), np.zeros(3), angles))


class _Binding:
    def __init__(self, keypoints: np.ndarray, angles: np.ndarray) -> None:
        self.kp, self.angles = keypoints, angles

    def keypoints(self, data):
        return self.kp

    def pose(self, data):
        return type("Pose", (), {"angles": self.angles.copy()})()


def _intent(touch, angles, **params):
    """Grasp-v0 seed 0's scene (its target, the large marker: a tripod), contacts scripted."""
    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    scene = env.unwrapped.scene
    assert scene.objects[env.unwrapped.target_instance][1].name == "040_large_marker"
    intent = GraspIntent(scene, 0.02, **params)
    intent._contacts.touching = lambda data: np.array(touch[0])
    intent._contacts.touched_object = lambda data: env.unwrapped.target_instance
    intent._binding = _Binding(_keypoints(0.5), angles)
    env.close()
    return intent


def test_digits_of_the_grasp_close_at_its_pace_until_they_touch_then_press():
    """Thumb and index touch (the onset); the middle finger, the tripod's third digit, closes.

    It closes from its physical angles along the tripod's path (preshape to closed in
    ``close_s``), whatever the tracked angles do; when it touches it holds its contact flexion
    + ``press_rad``. The ring finger, not a digit of a tripod, follows the averaged posture.
    """
    rng = np.random.default_rng(0)
    touch = [[True, True, False, False, False]]
    start = np.full(21, 0.1)
    intent = _intent(touch, start, close_s=0.5, press_rad=0.2)
    tripod = GRASP_TYPES["tripod"]
    rate = np.maximum(tripod.small - tripod.preshape, 0.0)[MIDDLE] / (0.5 / 0.02)
    assert rate.max() > 0.01
    held = 0.3 * np.where(_FLEX, JOINT_LIMITS[:, 1], 0.0)
    outs = []
    for _ in range(10):
        target = np.r_[np.zeros(6), held + rng.normal(0, 0.3, 21)]
        outs.append(intent(target, _keypoints(0.6), None)[6:])
    assert intent.grasping and intent.assisted()
    for k, out in enumerate(outs, start=1):
        np.testing.assert_allclose(out[MIDDLE], np.minimum(0.1 + k * rate, JOINT_LIMITS[MIDDLE, 1]))
        np.testing.assert_allclose(out[THUMB], 0.1 + 0.2)  # touching from the onset: pressing
        np.testing.assert_allclose(out[INDEX], 0.1 + 0.2)
    assert np.abs(outs[-1][RING] - held[RING]).max() < 0.35  # the averaged posture, noisy
    # The middle finger touches at its present physical angles: it presses from there.
    contact = start.copy()
    contact[MIDDLE] = 0.7
    intent._binding.angles = contact
    touch[0] = [True, True, True, False, False]
    out = intent(np.r_[np.zeros(6), held], _keypoints(0.6), None)[6:]
    np.testing.assert_allclose(out[MIDDLE], 0.7 + 0.2)
    np.testing.assert_array_equal(intent.assist_steps, [11, 11, 11, 0, 0])
    assert intent.any_assist_steps == 11


def test_without_close_s_the_intent_does_not_close_untouched_digits():
    """``close_s`` 0 (the default): the middle finger follows the averaged tracked posture."""
    touch = [[True, True, False, False, False]]
    intent = _intent(touch, np.full(21, 0.1))
    held = 0.3 * np.where(_FLEX, JOINT_LIMITS[:, 1], 0.0)
    for _ in range(30):
        out = intent(np.r_[np.zeros(6), held], _keypoints(0.6), None)[6:]
    np.testing.assert_allclose(out[MIDDLE], held[MIDDLE], atol=1e-9)
    assert not intent.assisted() and intent.any_assist_steps == 0


def test_release_blends_from_the_applied_target_without_a_jump():
    """On release a pressing digit's target moves linearly from its press, not from the posture.

    The blend's first step is one ``blend_s`` step (1/11 of the way for 0.2 s at 20 ms) from
    the last applied target toward the tracked angles.
    """
    touch = [[True, True, False, False, False]]
    intent = _intent(touch, np.full(21, 0.1), close_s=0.5, press_rad=0.3)
    held = 0.6 * np.where(_FLEX, JOINT_LIMITS[:, 1], 0.0)
    for _ in range(30):
        last = intent(np.r_[np.zeros(6), held], _keypoints(0.6), None)[6:]
    np.testing.assert_allclose(last[INDEX], 0.4)  # pressing, far from the posture (held)
    assert np.abs(held[INDEX] - 0.4).max() > 0.5
    opened = np.zeros(21)
    steps = []
    for _ in range(40):
        steps.append(intent(np.r_[np.zeros(6), opened], _keypoints(0.0), None)[6:])
    assert intent.releases == 1
    first = next(k for k, s in enumerate(steps) if not np.allclose(s[INDEX], 0.4))
    path = [last] + steps[first : first + 11]
    jumps = [np.abs(b[INDEX] - a[INDEX]).max() for a, b in zip(path, path[1:], strict=False)]
    assert max(jumps) <= 0.4 / 11 + 1e-9, jumps
    np.testing.assert_array_equal(steps[-1], opened)


def test_loop_reports_assisted_closure_and_press_is_unchanged():
    """The loop reports the assist per digit and whether a success was assisted.

    The replayed grasp expert (Grasp-v0, seed 8: the wood block, four fingers and thumb) grasps
    with the assist; Press-v0 (no objects) runs step for step as without it.
    """
    stream = stream_from_expert("handsim/Grasp-v0", 8)
    # Replayed without noise: the gate (no grasp with clean tracking) is opened for the test.
    config = TeleopConfig(
        grasp_intent=True, closure_assist=True, intent_params={"noise_gate_rad": 0.0}
    )
    with TeleopLoop("handsim/Grasp-v0", config) as loop:
        m = loop.run(stream, 8).metrics
    assert m["config"]["closure_assist"] is True
    assert m["closure_assist_s"] > 0.5
    assert set(m["closure_assist_digit_s"]) == {"thumb", "index", "middle", "ring", "little"}
    assert max(m["closure_assist_digit_s"].values()) == pytest.approx(m["closure_assist_s"])
    assert m["success"] and m["success_assisted"]
    press = stream_from_expert("handsim/Press-v0", 0)
    runs = []
    for assist in (False, True):
        cfg = TeleopConfig(grasp_intent=assist, closure_assist=assist, record=True)
        with TeleopLoop("handsim/Press-v0", cfg) as loop:
            runs.append(loop.run(press, 0))
    assert runs[1].metrics["closure_assist_s"] == 0.0
    assert runs[1].metrics["success_assisted"] is False
    np.testing.assert_array_equal(runs[0].arrays["qpos"], runs[1].arrays["qpos"])


def test_closure_assist_needs_the_grasp_intent_and_a_valid_close_s():
    """The assist acts within the intent; ``close_s`` is a time >= 0."""
    with pytest.raises(InvalidTeleopConfig, match="closure_assist acts while the grasp intent"):
        TeleopConfig(closure_assist=True)
    assert TeleopConfig(grasp_intent=True, closure_assist=True).closure_assist
    assert CLOSE_S > 0
    with pytest.raises(InvalidFilter, match="close_s must be a finite number >= 0"):
        _intent([[False] * 5], np.zeros(21), close_s=-1.0)


def test_noise_gate_keeps_the_intent_off_with_clean_tracking():
    """``noise_gate_rad``: with smooth tracked angles no grasp starts; with noisy ones it does.

    The noise estimate is the RMS second difference over sqrt(6): white noise of 0.3 rad per
    joint reads about 0.3 rad; a closure of 1 rad in 0.4 s, under 0.02 rad.
    """
    touch = [[True, True, False, False, False]]
    smooth = _intent(touch, np.full(21, 0.1), close_s=0.5, noise_gate_rad=0.05)
    closing = np.where(_FLEX, 1.0, 0.0)
    for k in range(40):
        target = np.r_[np.zeros(6), min(k / 20, 1.0) * closing]
        np.testing.assert_array_equal(smooth(target, _keypoints(0.6), None), target)
    assert not smooth.grasping and smooth.onsets == 0 and smooth.noise_rad < 0.02
    rng = np.random.default_rng(3)
    noisy = _intent(touch, np.full(21, 0.1), close_s=0.5, noise_gate_rad=0.05)
    for _ in range(100):
        noisy(np.r_[np.zeros(6), 0.5 * closing + rng.normal(0, 0.3, 21)], _keypoints(0.6), None)
    assert noisy.grasping and noisy.onsets == 1
    assert noisy.noise_rad == pytest.approx(0.3, rel=0.25)


def test_closure_assist_config_sets_the_pace_and_the_gate():
    """``closure_assist=True`` gives the intent CLOSE_S and NOISE_GATE_RAD unless given."""
    from handsim.envs.teleop.channel import HandChannel
    from handsim.envs.teleop.intent import NOISE_GATE_RAD

    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    scene = env.unwrapped.scene
    rng = np.random.default_rng(0)
    cfg = TeleopConfig(grasp_intent=True, closure_assist=True)
    channel = HandChannel(cfg, scene, 0.02, rng)
    assert channel.intent.close_s == CLOSE_S and channel.intent.noise_gate_rad == NOISE_GATE_RAD
    cfg = TeleopConfig(grasp_intent=True, closure_assist=True, intent_params={"close_s": 0.3})
    assert HandChannel(cfg, scene, 0.02, rng).intent.close_s == 0.3
    plain = HandChannel(TeleopConfig(grasp_intent=True), scene, 0.02, rng).intent
    assert plain.close_s == 0.0 and plain.noise_gate_rad == 0.0
    env.close()
