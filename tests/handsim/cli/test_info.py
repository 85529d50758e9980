"""`handsim info` lists every name the program and the envs accept."""

import json

from handsim.cli import main
from handsim.envs import ENV_IDS
from handsim.envs.config import SENSORS, VIEWPOINTS
from handsim.hand.pose import JOINT_NAMES
from handsim.world.camera import CAMERA_PRESETS
from handsim.world.registry import OBJECT_NAMES, OBJECTS


def test_info_lists_envs_objects_cameras_sensors_estimators(capsys):
    """The text lists every registered id, object (with alias), preset, sensor and estimator."""
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    for name in (*ENV_IDS, *OBJECT_NAMES, *CAMERA_PRESETS, *JOINT_NAMES, *VIEWPOINTS):
        assert name in out, name
    assert "sensors: " + ", ".join(SENSORS) in out
    for name in OBJECT_NAMES:
        assert OBJECTS[name].alias in out
    assert "\n  oracle " in out and "\n  com " in out
    assert "module:Class[:kwargs-json]" in out


def test_info_json_is_strict_and_complete(capsys):
    """--json is strict JSON with the same lists."""
    assert main(["info", "--json"]) == 0

    def refuse(constant):
        raise AssertionError(f"non-strict JSON constant {constant}")

    info = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert [e["id"] for e in info["envs"]] == list(ENV_IDS)
    assert [o["name"] for o in info["objects"]] == list(OBJECT_NAMES)
    assert [c["name"] for c in info["cameras"]] == list(CAMERA_PRESETS)
    assert info["sensors"] == list(SENSORS)
    assert [e["name"] for e in info["estimators"]] == ["oracle", "com", "deepprior++", "deepprior"]
    assert list(info["hand"]["joint_limits_deg"]) == list(JOINT_NAMES)
    assert info["hand"]["nv"] == 27
    assert info["versions"]["blas"].startswith("openblas:")  # NumPy's wheels bundle OpenBLAS
