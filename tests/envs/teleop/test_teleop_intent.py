"""The grasp intent (§3): the closure measure, the trigger's hysteresis, the averaged fingers."""

import gymnasium as gym
import numpy as np
import pytest

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.teleop import TeleopConfig, TeleopLoop, stream_from_expert
from handsim.envs.teleop.filters import InvalidFilter
from handsim.envs.teleop.intent import (
    INTENT_DEFAULTS,
    GraspIntent,
    hand_closure,
    make_grasp_intent,
    palm_size,
)
from handsim.envs.teleop.loop import InvalidTeleopConfig
from handsim.envs.teleop.pose_filter import make_pose_filter
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_LIMITS, JOINT_NAMES, HandPose

_FLEX = np.array(["flex" in n for n in JOINT_NAMES])


def _keypoints(flex_fraction: float) -> np.ndarray:
    """The default hand's keypoints with every flexion joint at a fraction of its range."""
    angles = np.zeros(21)
    angles[_FLEX] = flex_fraction * JOINT_LIMITS[_FLEX, 1]
    fk = ForwardKinematics(HandParams())
    return fk.keypoints(HandPose(np.zeros(3), np.zeros(3), angles))


def test_closure_falls_as_the_hand_closes_and_ignores_place_turn_and_size():
    """Closure is smaller for a closed hand; a moved, turned, scaled hand has the same."""
    from scipy.spatial.transform import Rotation

    values = [hand_closure(_keypoints(f)) for f in (0.0, 0.3, 0.6, 0.9)]
    assert all(a > b for a, b in zip(values, values[1:], strict=False)), values
    assert 0.9 < values[0] < 1.4 and values[-1] < 0.75
    kp = _keypoints(0.4)
    moved = 1.3 * Rotation.from_rotvec([0.3, -1.0, 2.0]).apply(kp) + [0.2, -0.5, 1.0]
    assert hand_closure(moved) == pytest.approx(hand_closure(kp), abs=1e-12)
    # A given palm size divides instead of the frame's own.
    assert hand_closure(kp, 2 * palm_size(kp)) == pytest.approx(hand_closure(kp) / 2)
    no_wrist = kp.copy()
    no_wrist[0] = np.nan
    assert np.isnan(hand_closure(no_wrist))
    few = kp.copy()
    few[[3, 4, 7, 8, 11, 12]] = np.nan  # 4 distal points left of 10
    assert np.isnan(hand_closure(few))


class _Binding:
    """The physical hand the intent reads: keypoints and joint angles set by the test."""

    def __init__(self, keypoints: np.ndarray) -> None:
        self.kp = keypoints
        self.angles = np.zeros(21)

    def keypoints(self, data):
        return self.kp

    def pose(self, data):
        return type("Pose", (), {"angles": self.angles.copy()})()


def _intent(touch, physical_kp, **params):
    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    intent = GraspIntent(env.unwrapped.scene, 0.02, **params)
    intent._contacts.touching = lambda data: np.array(touch[0])
    intent._binding = _Binding(physical_kp)
    env.close()
    return intent


def test_intent_passes_tracking_until_an_opposition_grasp_and_averages_the_fingers_in_it():
    """No opposition: the target passes exactly. In a grasp the fingers' noise averages out.

    The onset needs the thumb and another digit on an object and the tracked hand at least as
    closed as the physical one; in the grasp, 0.3 rad of noise per joint comes out about
    0.05 rad (the running mean over ``hold_s`` = 0.4 s) and the wrist passes unchanged
    (``press_rad=0``: the touching digits too follow the averaged posture).
    """
    rng = np.random.default_rng(0)
    touch = [[False, True, False, False, False]]  # the index alone: no opposition
    closed = _keypoints(0.6)
    intent = _intent(touch, _keypoints(0.5), press_rad=0.0)
    held = 0.6 * np.where(_FLEX, JOINT_LIMITS[:, 1], 0.0)
    for _ in range(20):
        target = np.r_[rng.normal(size=6), held + rng.normal(0, 0.3, 21)]
        np.testing.assert_array_equal(intent(target, closed, None), target)
    assert not intent.grasping and intent.onsets == 0
    touch[0] = [True, True, False, False, False]  # thumb and index: an opposition
    outs = []
    for _ in range(200):
        target = np.r_[rng.normal(size=6), held + rng.normal(0, 0.3, 21)]
        out = intent(target, closed, None)
        np.testing.assert_array_equal(out[:6], target[:6])
        outs.append(out[6:])
    assert intent.grasping and intent.onsets == 1 and intent.grasp_steps == 200
    late = np.array(outs[50:])
    assert 0.02 < late.std(axis=0).mean() < 0.08
    assert np.abs(late.mean(axis=0) - held).max() < 0.05


def test_touching_digits_press_past_their_contact_posture_whatever_the_tracking():
    """In a grasp a digit on the object holds its contact flexion + press_rad.

    Its flexion targets no longer carry the tracked noise; a digit off the object and every
    spread joint follow the averaged posture.
    """
    rng = np.random.default_rng(2)
    touch = [[True, True, False, False, False]]  # thumb and index on the object
    intent = _intent(touch, _keypoints(0.5), press_rad=0.25)
    contact = rng.uniform(0.2, 0.8, 21)
    intent._binding.angles = contact
    held = 0.6 * np.where(_FLEX, JOINT_LIMITS[:, 1], 0.0)
    for _ in range(100):
        out = intent(np.r_[np.zeros(6), held + rng.normal(0, 0.3, 21)], _keypoints(0.6), None)
    thumb_flex = [0, 2, 4]  # cmc, mcp, ip flexion
    index_flex = [5, 7, 8]  # mcp, pip, dip
    np.testing.assert_allclose(
        out[6:][thumb_flex + index_flex], contact[thumb_flex + index_flex] + 0.25
    )
    middle_flex = [9, 11, 12]
    assert np.abs(out[6:][middle_flex] - held[middle_flex]).max() < 0.2
    assert np.abs(out[6:][[1, 3, 6]]).max() < 0.2  # spread: averaged around 0


def test_intent_does_not_start_while_the_tracked_hand_is_more_open_than_the_physical():
    """Touching with an opposition while the tracked hand opens away is no grasp."""
    touch = [[True, True, False, False, False]]
    intent = _intent(touch, _keypoints(0.6))
    target = np.zeros(27)
    for _ in range(20):
        np.testing.assert_array_equal(intent(target, _keypoints(0.1), None), target)
    assert not intent.grasping


def test_intent_releases_on_opening_beyond_the_band_and_blends_back():
    """Opening within the band keeps the grasp; beyond it, the tracked angles return linearly.

    The release blend lasts ``blend_s`` (0.2 s = 10 steps of 20 ms).
    """
    touch = [[True, True, False, False, False]]
    intent = _intent(touch, _keypoints(0.5), press_rad=0.0)
    grasp = np.r_[np.zeros(6), 0.6 * np.where(_FLEX, JOINT_LIMITS[:, 1], 0.0)]
    for _ in range(100):
        intent(grasp, _keypoints(0.6), None)
    assert intent.grasping
    # A little opening (within the band) keeps the grasp and its posture.
    for _ in range(50):
        out = intent(grasp * 0.95, _keypoints(0.55), None)
    assert intent.grasping
    posture = out[6:].copy()
    # The user opens the hand: the closure rises far above its mean in the grasp.
    opened = np.zeros(27)
    steps = []
    for _ in range(30):
        steps.append(intent(opened, _keypoints(0.0), None)[6:])
        if not intent.grasping and len(steps) < 30:
            continue
    assert not intent.grasping and intent.onsets == 1 and intent.releases == 1
    first = next(k for k, s in enumerate(steps) if np.abs(s).max() < np.abs(posture).max())
    blend = [np.abs(s).max() for s in steps[first : first + 11]]
    assert all(a > b for a, b in zip(blend, blend[1:], strict=False))  # falls step by step
    np.testing.assert_array_equal(steps[-1], 0.0)  # then the tracked angles exactly


def test_intent_releases_when_no_digit_touches_for_release_s():
    """The object gone (no contact for release_s = 0.3 s), the grasp ends though closed."""
    touch = [[True, True, False, False, False]]
    intent = _intent(touch, _keypoints(0.5))
    target = np.zeros(27)
    intent(target, _keypoints(0.6), None)
    assert intent.grasping
    touch[0] = [False] * 5
    states = []
    for _ in range(16):
        intent(target, _keypoints(0.6), None)
        states.append(intent.grasping)
    assert states[13] and not states[15]


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"hold_s": 0.0}, "hold_s must be a finite number > 0"),
        ({"band": -0.1}, "band must be a finite number >= 0"),
        ({"threshold": 0.5}, r"grasp intent parameters \['threshold'\] are not valid"),
    ],
)
def test_bad_intent_parameters_name_what_is_valid(params, message):
    """Out-of-range or unknown parameters are refused with what is valid."""
    env = gym.make("handsim/Grasp-v0", obs_mode="state", control_mode="pose")
    env.reset(seed=0)
    with pytest.raises(InvalidFilter, match=message):
        make_grasp_intent(env.unwrapped.scene, 0.02, **params)
    env.close()


def test_bad_config_values_are_refused():
    """TeleopConfig refuses an unknown intent parameter and an unknown pose filter part."""
    with pytest.raises(InvalidTeleopConfig, match="intent_params .*'grip'.* choose from"):
        TeleopConfig(intent_params={"grip": 1.0})
    with pytest.raises(InvalidTeleopConfig, match="pose_filter='fingers' is not valid"):
        TeleopConfig(pose_filter="fingers")
    assert set(INTENT_DEFAULTS) >= {"hold_s", "band", "release_s", "blend_s"}


def test_wrist_only_pose_filter_smooths_the_wrist_and_passes_the_angles():
    """``wrist_only``: the joint angles come out as they went in, the wrist smoothed."""
    pose_filter = make_pose_filter(50.0, wrist_only=True)
    rng = np.random.default_rng(1)
    outs, ins = [], []
    for _ in range(100):
        pose = np.r_[rng.normal(0, 0.01, 3), rng.normal(0, 0.05, 3), rng.normal(0, 0.3, 21)]
        out = pose_filter(pose)
        np.testing.assert_array_equal(out[6:], pose[6:])
        outs.append(out[:3])
        ins.append(pose[:3])
    assert np.std(outs) < 0.5 * np.std(ins)


def test_loop_reports_intent_time_and_press_without_objects_is_unchanged(tmp_path):
    """The loop reports the intent; Press-v0 (no objects) is the same with it as without.

    Grasp-v0's replayed expert grasps in intent (seconds, onsets, a rollout array); Press-v0's
    episode with the intent is the one without, step for step.
    """
    from handsim.envs.teleop import read_rollout, write_rollout

    stream = stream_from_expert("handsim/Grasp-v0", 0)
    with TeleopLoop("handsim/Grasp-v0", TeleopConfig(grasp_intent=True, record=True)) as loop:
        episode = loop.run(stream, 0)
        path = write_rollout(tmp_path / "r.npz", episode, loop)
    m = episode.metrics
    assert m["intent_onsets"] >= 1 and m["intent_grasp_s"] > 0.5
    assert m["intent_onsets"] - m["intent_releases"] in (0, 1)
    _, arrays = read_rollout(path)
    assert arrays["intent"].sum() * m["control_dt_s"] == pytest.approx(m["intent_grasp_s"])
    press = stream_from_expert("handsim/Press-v0", 0)
    runs = []
    for on in (False, True):
        with TeleopLoop("handsim/Press-v0", TeleopConfig(grasp_intent=on, record=True)) as loop:
            runs.append(loop.run(press, 0))
    assert runs[1].metrics["intent_grasp_s"] == 0.0 and runs[1].metrics["intent_onsets"] == 0
    np.testing.assert_array_equal(runs[0].arrays["qpos"], runs[1].arrays["qpos"])
