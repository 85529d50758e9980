"""Property-based fuzzing of the public API: bad input is caught at the door.

Every public constructor and function is called with one argument replaced by a generated
value (wrong types, NaN/inf, complex, huge/negative numbers, wrong shapes, wrong strings). The
call must either raise a :class:`HandSimError` or succeed; when the replaced value was not
even of the argument's kind (a string for a number, a complex, NaN, ...) success is a failure
(silent acceptance), and a success must give finite outputs.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import handsim
from handsim import HandSimError
from handsim.estimators import CenterOfMassLocalizer, OracleEstimator

# Kinds of arguments: what a value must be to possibly be accepted.
REAL, INT, BOOL, STR, VEC, OBJ = "real", "int", "bool", "str", "vec", "obj"


@dataclasses.dataclass(frozen=True)
class Target:
    """One public callable, its valid base arguments and the kinds of the fuzzed ones."""

    name: str
    fn: Callable[..., Any]
    base: dict[str, Any]
    kinds: dict[str, str]
    finite_output: bool = True

    def __repr__(self) -> str:
        return self.name


def _rng() -> np.random.Generator:
    return np.random.default_rng(0)


def _pose_args() -> dict[str, Any]:
    return {"wrist_pos": np.zeros(3), "wrist_rotvec": np.zeros(3), "angles": np.zeros(21)}


def _keypoints(offset: float = 0.0) -> np.ndarray:
    return np.linspace(0.0, 0.2, 63).reshape(21, 3) + offset


_ICVL = handsim.camera_preset("icvl")
_MESH_DIR = tempfile.mkdtemp(prefix="handsim_fuzz_")
_BALL = os.path.join(_MESH_DIR, "ball.ply")
trimesh.creation.icosphere(subdivisions=1, radius=0.04).export(_BALL)

TARGETS = [
    Target(
        "HandParams",
        handsim.HandParams,
        {},
        {
            "hand_length": REAL,
            "side": STR,
            "palm_breadth": REAL + "|none",
            "thickness_scale": REAL,
            "forearm": BOOL,
            "couple_dip": BOOL,
        },
    ),
    Target("hand_params", handsim.hand_params, {}, {"size": REAL + "|" + STR, "side": STR}),
    Target("Hand", handsim.Hand, {}, {"params": OBJ}),
    Target("build_skeleton", handsim.build_skeleton, {}, {"params": OBJ}),
    Target("ForwardKinematics", handsim.ForwardKinematics, {}, {"hand": OBJ}),
    Target("Retargeter", handsim.Retargeter, {}, {"hand": OBJ}),
    Target("camera_preset", handsim.camera_preset, {}, {"name": STR}),
    Target(
        "CameraIntrinsics",
        handsim.CameraIntrinsics,
        {"width": 320, "height": 240, "fx": 241.42, "fy": 241.42, "cx": 160.0, "cy": 120.0},
        {"width": INT, "height": INT, "fx": REAL, "fy": REAL, "cx": REAL, "cy": REAL, "name": STR},
    ),
    Target(
        "third_person_camera",
        handsim.third_person_camera,
        {},
        {
            "intrinsics": OBJ,
            "name": STR,
            "target_m": VEC,
            "distance_m": REAL,
            "azimuth_deg": REAL,
            "elevation_deg": REAL,
        },
    ),
    Target(
        "egocentric_camera",
        handsim.egocentric_camera,
        {},
        {"intrinsics": OBJ, "name": STR, "target_m": VEC, "head_offset_m": VEC},
    ),
    Target(
        "sample_viewpoint",
        handsim.sample_viewpoint,
        {"rng": _rng()},
        {
            "rng": OBJ,
            "intrinsics": OBJ,
            "name": STR,
            "target_m": VEC,
            "distance_range_m": VEC,
            "azimuth_range_deg": VEC,
            "elevation_range_deg": VEC,
            "target_jitter_m": REAL,
        },
    ),
    Target(
        "CameraSpec",
        handsim.CameraSpec,
        {"name": "cam", "intrinsics": _ICVL, "pos_m": (0, 0, 1), "quat_wxyz": (1, 0, 0, 0)},
        {"name": STR, "intrinsics": OBJ, "pos_m": VEC, "quat_wxyz": VEC},
    ),
    Target(
        "ObjectPlacement",
        handsim.ObjectPlacement,
        {"name": "mug", "pos_m": (0, 0, 0.1)},
        {"name": STR, "pos_m": VEC, "quat_wxyz": VEC, "mesh": OBJ},
    ),
    Target(
        "SceneSpec",
        handsim.SceneSpec,
        {},
        {"hand": OBJ, "objects": OBJ, "cameras": OBJ, "table": BOOL},
    ),
    Target(
        "sample_placements",
        handsim.sample_placements,
        {"rng": _rng(), "names": ["mug"]},
        {"rng": OBJ, "names": OBJ, "region_m": VEC, "gap_m": REAL, "max_tries": INT},
    ),
    Target(
        "HandPose",
        handsim.HandPose,
        _pose_args(),
        {"wrist_pos": VEC, "wrist_rotvec": VEC, "angles": VEC},
    ),
    Target("gesture", handsim.gesture, {"name": "fist"}, {"name": STR, "noise_deg": REAL}),
    Target(
        "grasp_pose",
        handsim.grasp_pose,
        {"name": "power_sphere"},
        {"name": STR, "closure": VEC, "noise_deg": REAL},
    ),
    Target(
        "sample_uniform",
        handsim.sample_uniform,
        {"rng": _rng(), "n": 2},
        {"rng": OBJ, "n": INT, "coupled": BOOL},
    ),
    Target(
        "sample_synergy",
        handsim.sample_synergy,
        {"rng": _rng(), "n": 2},
        {"rng": OBJ, "n": INT, "num_synergies": INT, "scale": REAL},
    ),
    Target(
        "sample_grasp",
        handsim.sample_grasp,
        {"rng": _rng(), "n": 2},
        {"rng": OBJ, "n": INT, "names": OBJ, "closure_range": VEC, "noise_deg": REAL},
    ),
    Target(
        "random_motion",
        handsim.random_motion,
        {"rng": _rng(), "duration": 0.2, "dt": 0.05},
        # duration is not fuzzed: a valid 10^4 s motion is legitimately slow to draw.
        {
            "rng": OBJ,
            "dt": REAL,
            "sources": OBJ,
            "hold_range": VEC,
            "speed_range": VEC,
            "wrist_range_m": REAL,
            "wrist_rotation_rad": REAL,
            "noise_deg": REAL,
        },
    ),
    Target(
        "smooth_motion",
        handsim.smooth_motion,
        {"keyframes": [handsim.HandPose.neutral(), handsim.gesture("fist")], "dt": 0.05},
        {
            "keyframes": OBJ,
            "dt": REAL,
            "max_joint_speed": VEC,
            "max_wrist_speed": REAL,
            "max_wrist_angular_speed": REAL,
            "hold": VEC,
        },
    ),
    Target(
        "StructuredLight",
        handsim.StructuredLight,
        {},
        {
            "baseline_m": REAL,
            "disparity_step_px": REAL,
            "lateral_jitter_px": REAL,
            "max_incidence_deg": REAL,
            "min_range_m": REAL,
            "max_range_m": REAL,
            "shadow": BOOL,
        },
    ),
    Target(
        "TimeOfFlight",
        handsim.TimeOfFlight,
        {},
        {
            "sigma_m": REAL,
            "edge_threshold_m": REAL,
            "flying_pixel_prob": REAL,
            "dropout_prob": REAL,
            "min_range_m": REAL,
            "max_range_m": REAL,
        },
    ),
    Target("sensor_model", handsim.sensor_model, {"name": "tof"}, {"name": STR, "sigma_m": REAL}),
    Target(
        "evaluate_hand_poses",
        handsim.evaluate_hand_poses,
        {"pred_m": _keypoints(0.01)[None], "gt_m": _keypoints()[None]},
        {"pred_m": VEC, "gt_m": VEC, "visible": OBJ, "tau_max_mm": REAL, "step_mm": REAL},
        finite_output=False,
    ),
    Target(
        "evaluate_dexter_object",
        handsim.evaluate_dexter_object,
        {
            "pred_hand_m": _keypoints(0.01)[None, :5],
            "gt_hand_m": _keypoints()[None, :5],
            "pred_corners_m": np.ones((1, 8, 3)),
            "gt_corners_m": np.ones((1, 8, 3)),
        },
        {"tau_max_mm": REAL, "step_mm": REAL, "pred_hand_m": VEC, "gt_corners_m": VEC},
        finite_output=False,
    ),
    Target(
        "Symmetry",
        handsim.Symmetry,
        {"kind": "continuous", "axis": (0.0, 0.0, 1.0)},
        {"kind": STR, "axis": VEC, "offset_m": VEC},
    ),
    Target(
        "get_object",
        handsim.get_object,
        {"name": "mug"},
        {"name": STR, "n_model_points": INT, "seed": INT},
    ),
    Target(
        "OracleEstimator",
        OracleEstimator,
        {},
        {
            "noise_mm": REAL,
            "bias_mm": VEC,
            "dropout": REAL,
            "latency_steps": INT,
            "object_noise_mm": REAL,
            "object_noise_deg": REAL,
            "rng": OBJ,
        },
    ),
    Target(
        "CenterOfMassLocalizer",
        CenterOfMassLocalizer,
        {},
        {"cube_mm": REAL, "max_depth_m": REAL, "min_pixels": INT, "max_iterations": INT},
    ),
    Target(
        "Estimate",
        handsim.Estimate,
        {},
        {"keypoints_cam": VEC, "center_cam": VEC, "confidence": VEC, "valid": BOOL},
    ),
    Target(
        "load_object",
        handsim.load_object,
        {
            "path": _BALL,
            "name": "ball",
            "mass_kg": 0.1,
            "decomposition": "convex_hull",
            "n_model_points": 50,
        },
        {
            "path": OBJ,
            "name": STR,
            "mass_kg": REAL,
            "scale": REAL,
            "symmetry": OBJ,
            "decomposition": STR,
            "coacd_threshold": REAL,
            "recenter": BOOL,
            "rest_up": VEC,
            "rgba": VEC,
            "n_model_points": INT,
            "seed": INT,
            "max_faces": INT,
            "coacd_timeout_s": REAL,
        },
    ),
    Target("Scene", handsim.Scene, {}, {"spec": OBJ}),
    Target("FrameRenderer", handsim.FrameRenderer, {"camera": "cam"}, {"scene": OBJ}),
    Target("HandBinding", handsim.HandBinding, {"model": None}, {"hand": OBJ}),
    Target(
        "hand_center", handsim.hand_center, {"keypoints_cam": _keypoints()}, {"keypoints_cam": VEC}
    ),
]

_NAMES = ("medium", "left", "right", "icvl", "fist", "mug", "tof", "", "ICVL", "no", "none")

# Values that are never valid for a number (scalar or array entry).
_NOT_NUMBERS = st.sampled_from(
    [math.nan, math.inf, -math.inf, 1j, complex(1.0, 0.0), "0.18", "1", None, object(), b"1"]
)


def _values() -> st.SearchStrategy[Any]:
    floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
    huge = st.sampled_from([1e300, -1e300, 1e-300, 1e-9, -1e-9, 2**63, -(2**31), 20000, 0, -1])
    arrays = st.one_of(
        st.lists(floats, min_size=0, max_size=4),
        st.lists(st.one_of(huge, _NOT_NUMBERS), min_size=1, max_size=3),
        st.integers(0, 4).map(lambda n: np.full((n, 3), 1e300)),
        st.sampled_from(
            [
                np.full(3, np.nan),
                np.zeros((2, 2)),
                np.array(["a", "b", "c"]),
                np.ones(3, dtype=complex),
                (1.5, 2.5),
                ((0.1, 0.2), (0.3, 0.4)),
                [[1.0], [2.0, 3.0]],
                np.ones((1, 21, 3)),
                np.zeros((0, 21, 3)),
            ]
        ),
    )
    return st.one_of(
        floats,
        huge,
        _NOT_NUMBERS,
        st.integers(-(10**12), 10**12),
        st.booleans(),
        st.sampled_from(_NAMES),
        st.text(max_size=4),
        arrays,
        st.builds(dict),
    )


def _kind_ok(kind: str, value: Any) -> bool:
    """Whether ``value`` is of the argument's kind (then accepting it may be right)."""
    if "|" in kind:
        return any(_kind_ok(k, value) for k in kind.split("|"))
    if kind == "none":
        return value is None
    if kind == OBJ:
        return True
    if kind == STR:
        return isinstance(value, str)
    if kind == BOOL:
        return isinstance(value, (bool, np.bool_))
    if kind == INT:
        return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if kind == REAL:
        return (
            isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, (bool, np.bool_))
            and math.isfinite(float(value))
        )
    # VEC: a numeric, finite array-like.
    if isinstance(value, (str, bytes, bool, np.bool_)):
        return False
    try:
        arr = np.asarray(value)
    except Exception:  # noqa: BLE001 - ragged
        return False
    return arr.dtype.kind in "iuf" and bool(np.all(np.isfinite(arr)))


def _all_finite(result: Any, depth: int = 0) -> bool:
    if depth > 3:
        return True
    if isinstance(result, np.ndarray):
        return result.dtype.kind not in "fc" or bool(np.all(np.isfinite(result)))
    if isinstance(result, float):
        return math.isfinite(result)
    if isinstance(result, (list, tuple)):
        return all(_all_finite(r, depth + 1) for r in result)
    if dataclasses.is_dataclass(result) and not isinstance(result, type):
        return all(
            _all_finite(getattr(result, f.name), depth + 1) for f in dataclasses.fields(result)
        )
    return True


_CALLS: list[str] = []


@settings(
    max_examples=600,
    deadline=None,
    derandomize=True,
    suppress_health_check=list(HealthCheck),
    database=None,
)
@given(data=st.data())
def test_public_api_catches_bad_input_at_the_door(data):
    """Every call raises a HandSimError or succeeds on values of the right kind, finitely."""
    target = data.draw(st.sampled_from(TARGETS))
    arg = data.draw(st.sampled_from(sorted(target.kinds)))
    value = data.draw(_values())
    kwargs = {**target.base, arg: value}
    _CALLS.append(target.name)
    try:
        result = target.fn(**kwargs)
    except HandSimError:
        return
    except Exception as err:  # noqa: BLE001 - the point of the test
        pytest.fail(f"{target.name}({arg}={value!r}) raised {type(err).__name__}: {err}")
    kind = target.kinds[arg]
    assert _kind_ok(kind, value), (
        f"{target.name}({arg}={value!r}) silently accepted a value that is not {kind}"
    )
    if target.finite_output:
        assert _all_finite(result), f"{target.name}({arg}={value!r}) gave non-finite output"


def test_fuzz_ran_enough_cases():
    """The property test above ran at least 400 generated calls (over every target)."""
    if not _CALLS:  # run alone (-k): run the property test here
        test_public_api_catches_bad_input_at_the_door()
    assert len(_CALLS) >= 400
    assert set(_CALLS) == {t.name for t in TARGETS}


# Regression tests: the cases measured on main, each caught at the door ---------------------


def test_hand_params_rejects_a_string_length():
    """A hand length given as text is refused by name, not by a numpy ufunc error."""
    with pytest.raises(handsim.InvalidHandParams, match=r"hand_length must be a real number.*str"):
        handsim.HandParams(hand_length="0.18")


def test_hand_rejects_a_size_name_for_its_params():
    """Hand("medium") says to pass HandParams (e.g. hand_params("medium"))."""
    with pytest.raises(
        handsim.InvalidHandParams, match=r"params must be a HandParams.*hand_params"
    ):
        handsim.Hand("medium")


def test_camera_preset_rejects_a_list():
    """An unhashable preset name gives UnknownName listing the presets."""
    with pytest.raises(handsim.UnknownName, match=r"unknown camera preset \['icvl'\]; valid"):
        handsim.camera_preset(["icvl"])


def test_metrics_refuse_a_threshold_grid_that_cannot_be_allocated():
    """A 1e-9 mm step would need 8e10 thresholds (596 GiB): refused with the limit."""
    gt = _keypoints()[None]
    with pytest.raises(handsim.HandSimError, match=r"at most 100000 thresholds.*step_mm=1e-09"):
        handsim.evaluate_hand_poses(gt, gt, step_mm=1e-9)
    with pytest.raises(handsim.HandSimError, match=r"tau_max_mm must be <= 10000 mm"):
        handsim.evaluate_hand_poses(gt, gt, tau_max_mm=1e300)


def test_camera_resolution_is_capped():
    """A 20000 x 20000 camera (a MuJoCo FatalError on main) is refused with the cap."""
    with pytest.raises(handsim.HandSimError, match=r"width and height must be in \[1, 8192\]"):
        handsim.CameraIntrinsics(20000, 20000, 20000.0, 20000.0, 10000.0, 10000.0)
    with pytest.raises(handsim.HandSimError, match=r"width and height must be integers"):
        handsim.CameraIntrinsics(320.0, 240, 241.0, 241.0, 160.0, 120.0)
    with pytest.raises(handsim.HandSimError, match=r"fx must be a finite real number.*complex"):
        handsim.CameraIntrinsics(320, 240, 241j, 241.0, 160.0, 120.0)
    with pytest.raises(handsim.HandSimError, match=r"fx must be in \[0.32, 3.2e\+06\] pixels"):
        handsim.CameraIntrinsics(320, 240, 1e300, 241.0, 160.0, 120.0)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -0.1, 0.0, "0.6", 0.6j, True])
def test_third_person_camera_rejects_a_bad_distance(bad):
    """NaN distance gave NaN extrinsics on main; now every bad distance names the argument."""
    with pytest.raises(handsim.HandSimError, match=r"distance_m must be in \(0, 1000\]"):
        handsim.third_person_camera(distance_m=bad)


def test_camera_specs_reject_non_finite_placements():
    """CameraSpec / ObjectPlacement check their vectors (no NaN pose reaches MuJoCo)."""
    icvl = handsim.camera_preset("icvl")
    with pytest.raises(handsim.HandSimError, match=r"pos_m must be finite numbers of shape \(3,\)"):
        handsim.CameraSpec("cam", icvl, (0.0, math.nan, 1.0), (1.0, 0.0, 0.0, 0.0))
    with pytest.raises(handsim.HandSimError, match=r"quat_wxyz must be a non-zero quaternion"):
        handsim.ObjectPlacement("mug", (0.0, 0.0, 0.1), (0.0, 0.0, 0.0, 0.0))
    with pytest.raises(handsim.HandSimError, match=r"intrinsics must be a CameraIntrinsics"):
        handsim.CameraSpec("cam", "icvl", (0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0))


def test_hand_pose_rejects_a_huge_rotation_vector():
    """A 1e300 rad rotation vector (a NaN quaternion in qpos on main) is refused."""
    with pytest.raises(
        handsim.InvalidPose, match=r"wrist_rotvec must have entries with \|x\| <= 100"
    ):
        handsim.HandPose(np.zeros(3), np.array([1e300, 0.0, 0.0]), np.zeros(21))
    with pytest.raises(handsim.InvalidPose, match=r"angles must be real numbers.*complex"):
        handsim.HandPose(np.zeros(3), np.zeros(3), np.zeros(21, dtype=complex))
    with pytest.raises(handsim.InvalidPose, match=r"wrist_pos must be real numbers.*<U"):
        handsim.HandPose(["0", "0", "0"], np.zeros(3), np.zeros(21))


@pytest.mark.parametrize("bad", [math.nan, math.inf, "0.003", None, True])
def test_time_of_flight_rejects_a_bad_sigma(bad):
    """ToF sigma_m=nan silently switched the noise off on main."""
    with pytest.raises(handsim.HandSimError, match=r"sigma_m must be"):
        handsim.TimeOfFlight(sigma_m=bad)
    with pytest.raises(handsim.HandSimError, match=r"sigma_m must be"):
        handsim.sensor_model("tof", sigma_m=bad)


def test_sensor_model_rejects_unknown_parameters_and_names():
    """Unknown keyword arguments and unhashable names are HandSimErrors, not TypeErrors."""
    with pytest.raises(handsim.HandSimError, match=r"unknown parameter\(s\) sigma for sensor"):
        handsim.sensor_model("tof", sigma=0.01)
    with pytest.raises(handsim.UnknownName, match=r"unknown sensor model \['tof'\]"):
        handsim.sensor_model(["tof"])
    with pytest.raises(handsim.HandSimError, match=r"shadow must be True or False"):
        handsim.StructuredLight(shadow="no")


def test_pose_sources_reject_text_numbers_and_bad_flags():
    """Numbers given as text and non-bool flags are refused (accepted silently on main)."""
    rng = np.random.default_rng(0)
    with pytest.raises(handsim.InvalidPose, match=r"closure must be"):
        handsim.grasp_pose("power_sphere", closure="0.5")
    with pytest.raises(handsim.InvalidPose, match=r"coupled must be True or False"):
        handsim.sample_uniform(rng, 2, coupled="no")
    with pytest.raises(handsim.InvalidPose, match=r"noise_deg must be a finite number >= 0"):
        handsim.gesture("fist", noise_deg="3")
    with pytest.raises(handsim.InvalidPose, match=r"n must be at most 1000000 \(number of poses\)"):
        handsim.sample_uniform(rng, 2**63)
    with pytest.raises(handsim.InvalidPose, match=r"duration / dt must be at most 1000000"):
        handsim.random_motion(rng, 10.0, 1e-9)
    with pytest.raises(handsim.InvalidPose, match=r"dt must be at most 3600 seconds"):
        handsim.random_motion(rng, 0.2, 1e300)


def test_estimators_reject_classes_text_and_bools():
    """Estimator constructors take real numbers only (text and bools were accepted on main)."""
    with pytest.raises(handsim.InvalidEstimatorParams, match=r"noise_mm must be a number >= 0"):
        OracleEstimator(noise_mm="5")
    with pytest.raises(handsim.InvalidEstimatorParams, match=r"dropout must be a number >= 0"):
        OracleEstimator(dropout=True)
    with pytest.raises(
        handsim.InvalidEstimatorParams, match=r"latency_steps must be at most 10000 steps"
    ):
        OracleEstimator(latency_steps=2**63)
    with pytest.raises(handsim.InvalidEstimatorParams, match=r"rng must be a seed >= 0"):
        OracleEstimator(rng=-1)
    with pytest.raises(handsim.InvalidEstimatorParams, match=r"cube_mm must be a number > 0"):
        CenterOfMassLocalizer(cube_mm="250")


def test_load_object_rejects_a_non_bool_recenter(tmp_path):
    """recenter="no" recentred on main (a truthy string); now it must be a bool."""
    import trimesh

    path = tmp_path / "box.stl"
    trimesh.creation.box((0.05, 0.08, 0.03)).export(path)
    with pytest.raises(handsim.HandSimError, match=r"recenter must be True or False.*'no'"):
        handsim.load_object(path, name="box", mass_kg=0.1, recenter="no")
    with pytest.raises(handsim.HandSimError, match=r"mass_kg must be a finite number > 0.*complex"):
        handsim.load_object(path, name="box", mass_kg=0.1j)


def test_scene_spec_checks_its_parts():
    """SceneSpec refuses wrong part types before anything is compiled."""
    with pytest.raises(handsim.HandSimError, match=r"hand must be a HandParams or None"):
        handsim.SceneSpec(hand="medium")
    with pytest.raises(handsim.HandSimError, match=r"cameras must hold only CameraSpec"):
        handsim.SceneSpec(cameras=("icvl",))
    with pytest.raises(handsim.HandSimError, match=r"table must be True or False"):
        handsim.SceneSpec(table="yes")
    with pytest.raises(handsim.HandSimError, match=r"spec must be a SceneSpec"):
        handsim.Scene("scene")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pos": "abc"}, r"pos must be 3 finite numbers \(m\), got 'abc'"),
        ({"quat_wxyz": [1j, 0, 0, 0]}, r"quat_wxyz must be 4 finite numbers"),
        ({"friction": ["a", "b", "c"]}, r"friction must be 3 non-negative numbers"),
        ({"rgba": "red"}, r"rgba must be 4 numbers in \[0, 1\], got 'red'"),
    ],
)
def test_add_object_rejects_text_and_complex(kwargs, match):
    """add_object's vectors refuse strings and complex numbers (converted or cut on main)."""
    import mujoco

    with pytest.raises(handsim.HandSimError, match=match):
        handsim.add_object(mujoco.MjSpec(), handsim.get_object("mug"), **kwargs)


def test_metric_options_are_checked_even_when_unused(tmp_path):
    """Plot options and the symmetric flag are checked (a text tau or a non-bool flag)."""
    gt = _keypoints()[None]
    report = handsim.evaluate_hand_poses(gt, gt)
    png = tmp_path / "pck.png"
    with pytest.raises(handsim.HandSimError, match=r"tau_max_mm must be a positive number"):
        handsim.plot_pck({"a": report}, png, tau_max_mm="80")
    with pytest.raises(handsim.HandSimError, match=r"title must be a str or None"):
        handsim.plot_f_tau({"a": report}, png, title=5)
    with pytest.raises(handsim.HandSimError, match=r"path must be a str or os.PathLike"):
        handsim.plot_pck({"a": report}, 5)
    pose = np.eye(4)[None]
    with pytest.raises(handsim.HandSimError, match=r"symmetric must be True, False or None"):
        handsim.evaluate_object_poses(pose, pose, handsim.get_object("mug"), symmetric="no")
