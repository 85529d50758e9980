"""The hand side: a stream's `hand` is honoured, and one whose geometry disagrees is refused."""

import numpy as np
import pytest

from handsim.envs.teleop import (
    InvalidStream,
    InvalidTeleopConfig,
    OperatorStream,
    TeleopLoop,
    UdpReceiver,
    load_stream,
    save_stream,
    stream_from_expert,
)
from handsim.envs.teleop.handedness import check_side
from handsim.envs.teleop.sampling import LiveSampler
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import hand_params
from handsim.hand.pose import HandPose


@pytest.fixture(scope="module")
def left_keypoints():
    """The press expert's motion done by a left hand: (T, 21, 3) keypoints and times."""
    stream = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
    fk = ForwardKinematics(hand_params("medium", "left"))
    return stream.times_s, fk.keypoints(HandPose.from_vector(stream.poses))


def test_the_side_check_votes_on_geometry(left_keypoints):
    """Left keypoints pass as left and are refused as right, naming the fix."""
    _, kp = left_keypoints
    assert check_side(kp, "left") == 5
    with pytest.raises(
        InvalidStream, match=r"says hand='right', but its keypoints are a left hand"
    ):
        check_side(kp, "right", "hand.json")
    assert check_side(np.full((3, 21, 3), np.nan), "right") == 0  # nothing tracked: no verdict


def test_a_left_file_drives_a_left_hand_and_a_mislabelled_one_is_refused(left_keypoints, tmp_path):
    """`hand: left` replays on a left hand; the same keypoints labelled right are refused."""
    t, kp = left_keypoints
    left = save_stream(OperatorStream(t, kp, side="left"), tmp_path / "left.json")
    stream = load_stream(left)
    assert stream.side == "left"
    kwargs = {"task": "button", "handedness": "left"}
    with TeleopLoop("handsim/Press-v0", env_kwargs=kwargs) as loop:
        m = loop.run(stream, 0, max_steps=30).metrics
    assert m["tracking_error_mm"] < 15.0
    wrong = OperatorStream(t, kp, side="right", source="wrong.json")
    with TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop:
        with pytest.raises(InvalidStream, match="wrong.json says hand='right'.*left hand"):
            loop.run(wrong, 0, max_steps=5)
        with pytest.raises(InvalidStream, match="is a left hand, but the task's hand is right"):
            loop.run(stream, 0, max_steps=5)


def test_live_streams_of_the_other_side_are_refused(left_keypoints):
    """A live left hand on a right task is refused after its first 5 tracked frames."""
    _, kp = left_keypoints
    with TeleopLoop("handsim/Press-v0", env_kwargs={"task": "button"}) as loop:
        with pytest.raises(InvalidStream, match="the live stream says hand='right'"):
            loop.run(lambda i: kp[min(i, len(kp) - 1)], 0, max_steps=20)
        with pytest.raises(InvalidTeleopConfig, match="follows the left hand, but the task's"):
            loop.run(LiveSampler(UdpReceiver(0), "left"), 0, max_steps=5)
