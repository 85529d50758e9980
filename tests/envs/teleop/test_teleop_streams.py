"""Operator streams: file schemas (NPZ, JSON, every format), resampling, malformed files."""

import json

import numpy as np
import pytest

from handsim.envs.teleop import (
    InvalidStream,
    OperatorStream,
    load_stream,
    save_stream,
    stream_from_motion,
    stream_from_poses,
)
from handsim.envs.teleop.streams import frame_to_world
from handsim.hand.keypoints import to_format
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import hand_params
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import GESTURES


def _keypoints(n=5):
    fk = ForwardKinematics(hand_params("medium"))
    wrist = np.array([[0.0, -0.1 + 0.01 * k, 0.15] for k in range(n)])
    poses = HandPose(
        wrist, np.tile([0.0, np.pi, 0.0], (n, 1)), np.tile(GESTURES["relaxed"].angles, (n, 1))
    )
    return fk.keypoints(poses), fk.points(poses)


Y_UP_FROM_WORLD = np.array(
    [[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]
)  # world (x, y, z) -> (x, z, -y)


def test_json_keypoints_round_trip(tmp_path):
    """Json keypoints round trip."""
    kp, _ = _keypoints()
    doc = {
        "format": "handsim21",
        "frames": [{"t": 0.01 * i, "keypoints": k.tolist()} for i, k in enumerate(kp)],
    }
    path = tmp_path / "s.json"
    path.write_text(json.dumps(doc))
    stream = load_stream(path)
    np.testing.assert_allclose(stream.keypoints_world, kp)
    np.testing.assert_allclose(stream.times_s, 0.01 * np.arange(5))


def test_openxr_y_up_in_mm_with_radii_becomes_world_metres(tmp_path):
    """Openxr y up in mm with radii becomes world metres."""
    kp, points = _keypoints()
    xr = to_format(points, "openxr26")  # (T, 26, 3) world metres
    xr_source = xr @ Y_UP_FROM_WORLD.T * 1000.0  # y-up frame, millimetres
    radii = np.full((len(kp), 26), 8.0)
    np.savez(
        tmp_path / "xr.npz",
        format="openxr26",
        units="mm",
        t=np.arange(5) / 90.0,
        keypoints=xr_source,
        radii=radii,
    )
    stream = load_stream(tmp_path / "xr.npz")
    np.testing.assert_allclose(stream.keypoints_world, kp, atol=1e-9)
    assert stream.radii_m.shape == (5, 21)
    np.testing.assert_allclose(stream.radii_m[:, 0], 0.008)


def test_webxr_25_joints_drop_the_palm():
    """Webxr 25 joints drop the palm."""
    kp, points = _keypoints(1)
    xr = to_format(points, "openxr26")[:, 1:]  # WebXR: no palm
    np.testing.assert_allclose(frame_to_world(xr, "webxr25", "z"), kp, atol=1e-12)


def test_mediapipe_world_landmarks_are_y_down():
    """Mediapipe world landmarks are y down."""
    kp, _ = _keypoints(1)
    y_down = kp @ np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]).T  # (x, -z, y)
    np.testing.assert_allclose(frame_to_world(y_down, "mediapipe_world", "-y"), kp, atol=1e-12)


def test_nyu14_keypoints_leave_the_missing_points_nan(tmp_path):
    """Nyu14 keypoints leave the missing points nan."""
    kp, points = _keypoints(2)
    nyu = to_format(points, "nyu14")
    path = tmp_path / "nyu.json"
    path.write_text(
        json.dumps(
            {"format": "nyu14", "fps": 30, "frames": [{"keypoints": f.tolist()} for f in nyu]}
        )
    )
    stream = load_stream(path)
    present = np.all(np.isfinite(stream.keypoints_world[0]), axis=1)
    assert 4 <= present.sum() < 21
    np.testing.assert_allclose(stream.times_s, [0.0, 1 / 30])


def test_pose27_streams_keep_poses_and_resample_at_the_sim_rate(tmp_path):
    """Pose27 streams keep poses and resample at the sim rate."""
    poses = np.zeros((3, 27))
    poses[:, 0] = [0.0, 0.1, 0.2]
    poses[:, 2] = 0.15
    poses[:, 4] = np.pi / 2
    stream = stream_from_poses(poses, 0.1)
    path = save_stream(stream, tmp_path / "p.npz")
    back = load_stream(path, rate_hz=50.0)
    assert len(back) == 11
    np.testing.assert_allclose(back.poses[5, 0], 0.1)  # linear in position
    np.testing.assert_allclose(back.times_s, np.arange(11) * 0.02, atol=1e-12)
    fk = ForwardKinematics(hand_params("medium"))
    np.testing.assert_allclose(back.keypoints_world, fk.keypoints(HandPose.from_vector(back.poses)))


def test_resampling_keypoints_is_linear_and_keeps_absent_points_absent():
    """Resampling keypoints is linear and keeps absent points absent."""
    kp = np.zeros((2, 21, 3))
    kp[1] += 1.0
    kp[:, 3] = np.nan
    stream = OperatorStream(np.array([0.0, 1.0]), kp)
    half = stream.resample(2.0)
    np.testing.assert_allclose(half.keypoints_world[1, 0], 0.5)
    assert np.isnan(half.keypoints_world[:, 3]).all()


def test_json_save_load_round_trip(tmp_path):
    """Json save load round trip."""
    stream = stream_from_motion(np.random.default_rng(0), 0.3, 0.02)
    back = load_stream(save_stream(stream, tmp_path / "m.json"))
    np.testing.assert_allclose(back.poses, stream.poses)
    np.testing.assert_allclose(back.keypoints_world, stream.keypoints_world, atol=1e-12)


def _write(tmp_path, doc, name="bad.json"):
    path = tmp_path / name
    path.write_text(json.dumps(doc) if not isinstance(doc, str) else doc)
    return path


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ("{not json", "not valid JSON"),
        ([1, 2], "top level must be an object"),
        ({"format": "bvh", "frames": [{}]}, r"format='bvh' is not valid; choose one of .*openxr26"),
        ({"frames": []}, "frames must be a non-empty list"),
        (
            {"fps": 30, "frames": [{"keypoints": [[0, 0, 0]] * 21}, {"kp": 1}]},
            r"frames\[1\] must be an object with 'keypoints'",
        ),
        (
            {"fps": 30, "frames": [{"keypoints": [[0, 0, 0]] * 20}]},
            r"frames\[0\]\.keypoints has shape \(20, 3\); format 'handsim21' needs \(21, 3\)",
        ),
        (
            {"format": "openxr26", "fps": 30, "frames": [{"keypoints": [[0, 0, 0]] * 21}]},
            r"needs \(26, 3\)",
        ),
        (
            {
                "frames": [
                    {"t": 0, "keypoints": [[0, 0, 0]] * 21},
                    {"t": 0, "keypoints": [[0, 0, 0]] * 21},
                ]
            },
            r"frame 1: t = 0\.0 must be finite and greater",
        ),
        (
            {
                "frames": [
                    {"t": 0, "keypoints": [[0, 0, 0]] * 21},
                    {"t": "x", "keypoints": [[0, 0, 0]] * 21},
                ]
            },
            r"frames\[1\]\.t must be",
        ),
        ({"frames": [{"keypoints": [[0, 0, 0]] * 21}]}, "no timestamps"),
        (
            {"fps": 30, "frames": [{"keypoints": [[0, 0, None]] + [[0, 0, 0]] * 20}]},
            r"frame 0: keypoints\[0\] .* some but not all coordinates",
        ),
        (
            {"fps": 30, "frames": [{"keypoints": [["a", 0, 0]] + [[0, 0, 0]] * 20}]},
            r"frames\[0\]\.keypoints must be numbers",
        ),
        ({"fps": 30, "frames": [{"keypoints": [[0, 0, 500]] * 21}]}, r"beyond 100.0 m"),
        (
            {"fps": 30, "units": "cm", "frames": [{"keypoints": [[0, 0, 0]] * 21}]},
            r"units='cm' is not valid",
        ),
        (
            {"fps": 30, "up_axis": "x", "frames": [{"keypoints": [[0, 0, 0]] * 21}]},
            r"up_axis='x' is not valid; choose one of z, y, -y",
        ),
        (
            {"format": "pose27", "fps": 30, "frames": [{"pose": [0.0] * 26}]},
            r"frames\[0\]\.pose has shape \(26,\); format 'pose27' needs \(27,\)",
        ),
        (
            {"format": "pose27", "fps": 30, "frames": [{"pose": [0.0] * 26 + [None]}]},
            r"frame 0: pose\[26\] is not finite",
        ),
        (
            {
                "format": "openxr26",
                "fps": 30,
                "frames": [{"keypoints": [[0, 0, 0]] * 26, "radii": [-1.0] * 26}],
            },
            r"frame 0: radii\[0\] = -1.0 must be >= 0",
        ),
        ({"fps": -1, "frames": [{"keypoints": [[0, 0, 0]] * 21}]}, "fps must be a number > 0"),
    ],
)
def test_malformed_files_name_the_field_and_frame(tmp_path, doc, message):
    """Malformed files name the field and frame."""
    with pytest.raises(InvalidStream, match=message):
        load_stream(_write(tmp_path, doc))


def test_malformed_npz_and_paths(tmp_path):
    """Malformed npz and paths."""
    np.savez(tmp_path / "a.npz", t=np.arange(3.0), keypoints=np.zeros((3, 20, 3)))
    with pytest.raises(InvalidStream, match=r"keypoints has shape \(3, 20, 3\)"):
        load_stream(tmp_path / "a.npz")
    np.savez(tmp_path / "b.npz", t=np.arange(3.0))
    with pytest.raises(InvalidStream, match="missing the array 'keypoints'"):
        load_stream(tmp_path / "b.npz")
    with pytest.raises(InvalidStream, match="does not exist"):
        load_stream(tmp_path / "missing.json")
    (tmp_path / "x.csv").write_text("1")
    with pytest.raises(InvalidStream, match=r"must end in \.json or \.npz"):
        load_stream(tmp_path / "x.csv")
    (tmp_path / "c.npz").write_bytes(b"garbage")
    with pytest.raises(InvalidStream, match="not a readable NPZ"):
        load_stream(tmp_path / "c.npz")


def test_stream_arrays_are_checked():
    """Stream arrays are checked."""
    with pytest.raises(InvalidStream, match=r"keypoints_world must have shape \(T, 21, 3\)"):
        OperatorStream(np.arange(2.0), np.zeros((2, 20, 3)))
    with pytest.raises(InvalidStream, match="strictly increasing; frame 1"):
        OperatorStream(np.array([0.0, 0.0]), np.zeros((2, 21, 3)))
    with pytest.raises(InvalidStream, match="rate_hz must be a finite number > 0"):
        OperatorStream(np.arange(2.0), np.zeros((2, 21, 3))).resample(0)


def test_a_stream_too_long_to_resample_is_refused_before_it_is_allocated(tmp_path):
    """Timestamps 1e6 s apart at 500 Hz: a message, not 108 GiB asked for; fps 1e-300 is no rate."""
    kp, _ = _keypoints(3)
    spread = {
        "format": "handsim21",
        "frames": [{"t": 1e6 * i, "keypoints": k.tolist()} for i, k in enumerate(kp)],
    }
    slow = {"format": "handsim21", "fps": 1e-300, "frames": [{"keypoints": k.tolist()} for k in kp]}
    path = tmp_path / "long.json"
    path.write_text(json.dumps(spread))
    with pytest.raises(InvalidStream, match=r"the stream spans 2e\+06 s .*more than 2000000"):
        load_stream(path, rate_hz=500.0)
    path.write_text(json.dumps(slow))
    with pytest.raises(InvalidStream, match=r"fps must be in \[0\.01, 10000\].*received 1e-300"):
        load_stream(path, rate_hz=500.0)


def test_a_deeply_nested_json_stream_or_config_is_refused(tmp_path):
    """100 000 nested lists: a clear error for a stream file and for a generation config."""
    from handsim.data.config import GenerationConfig, InvalidGenerationConfig

    deep = "[" * 100_000 + "]" * 100_000
    (tmp_path / "deep.json").write_text(deep)
    with pytest.raises(InvalidStream, match="JSON nested too deeply to be a stream"):
        load_stream(tmp_path / "deep.json")
    with pytest.raises(InvalidGenerationConfig, match="JSON nested too deeply to be a config"):
        GenerationConfig.from_file(tmp_path / "deep.json")


def test_a_null_joint_row_is_an_untracked_joint_in_files_as_in_packets(tmp_path):
    """`null` for a whole joint (what live packets and the page send) is a NaN row."""
    from handsim.envs.teleop import parse_packet
    from handsim.envs.teleop.sender import packet

    kp = np.random.default_rng(0).normal(0.0, 0.05, (2, 21, 3))
    rows = [[None if j == 4 else p.tolist() for j, p in enumerate(frame)] for frame in kp]
    path = tmp_path / "nulls.json"
    path.write_text(
        json.dumps({"frames": [{"t": i / 90, "keypoints": r} for i, r in enumerate(rows)]})
    )
    stream = load_stream(path)
    assert np.isnan(stream.keypoints_world[:, 4]).all()
    np.testing.assert_allclose(stream.keypoints_world[:, 5:], kp[:, 5:])
    # The same frame as a packet gives the same keypoints.
    live = kp[0].copy()
    live[4] = np.nan
    frame = parse_packet(packet(0, 0.0, live))
    np.testing.assert_allclose(frame.keypoints_world, stream.keypoints_world[0], atol=1e-6)
    assert stream.rate_hz() == pytest.approx(90.0)


@pytest.mark.parametrize(
    ("factor", "units", "match"),
    [
        # Metre values labelled millimetres: a 0.19 mm hand.
        (1.0, "mm", r"a hand 0\.\d+ mm long .*'units': 'mm'.*the values look like metres: set "),
        # Millimetre values of a child's 95 mm hand labelled metres (a 95 m hand, within the
        # 100 m position bound).
        (5e2, "m", r"a hand 9\.\d+e\+04 mm long.*look like millimetres: set 'units': 'mm'"),
        # Neither: a hand 10x too big.
        (1e1, "m", r"a hand 189\d mm long.*check the keypoint format and the units"),
    ],
)
def test_a_hand_of_no_human_size_names_the_likely_unit(tmp_path, factor, units, match):
    """Keypoints read at the wrong unit are refused (a 0.2 mm operator hand was driven)."""
    kp, _ = _keypoints()
    kp = kp - kp.mean(axis=1, keepdims=True)  # hands at the origin: 500x stays < 100 m
    doc = {
        "units": units,
        "fps": 30,
        "frames": [{"keypoints": (k * factor).tolist()} for k in kp],
    }
    with pytest.raises(InvalidStream, match=match):
        load_stream(_write(tmp_path, doc))
    if factor == 1.0:  # the same values with the right unit are accepted
        doc["units"] = "m"
        assert load_stream(_write(tmp_path, doc)).keypoints_world.shape == (5, 21, 3)


def test_the_hand_size_check_skips_frames_without_the_middle_finger(tmp_path):
    """A stream that never tracks the whole middle finger is not measured (nothing to tell)."""
    kp, _ = _keypoints()
    kp[:, 12] = np.nan
    doc = {
        "fps": 30,
        "frames": [{"keypoints": np.where(np.isnan(k), None, k).tolist()} for k in kp],
    }
    assert load_stream(_write(tmp_path, doc)).keypoints_world.shape == (5, 21, 3)
