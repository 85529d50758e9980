"""The closed-loop report: strict JSON, every plot, titles that name the estimator."""

import json
import math

import cv2
import numpy as np
import pytest

from handsim.envs.closed_loop import OCCLUSION_EDGES, estimator_label, to_strict_json, write_report


def _mode(feedback, rng):
    taus = np.linspace(0, 80, 81)
    episodes = [
        {
            "seed": s,
            "object": obj,
            "success": bool(s % 2),
            "steps": 5,
            "kp_mean_mm": [10.0 + rng.normal(), math.nan, 12.0, 11.0, 9.0, 10.0],
        }
        for s, obj in enumerate(["025_mug", "011_banana", "025_mug"])
    ]
    episodes.append({"seed": 3, "object": None, "success": False, "steps": 0, "no_plan": "x"})
    return {
        "feedback": feedback,
        "estimator": "Fake(noise_mm=3.0)",
        "control_dt_s": 0.02,
        "episodes": episodes,
        "success_rate": 0.5,
        "success_by_object": {
            "025_mug": {"episodes": 2, "success_rate": 0.5},
            "011_banana": {"episodes": 1, "success_rate": 1.0},
            "(none)": {"episodes": 1, "success_rate": 0.0},
        },
        "n_frames": 18,
        "kp_mean_mm": 10.5,
        "center_mm": math.nan,
        "f_tau_thresholds_mm": taus.tolist(),
        "f_tau": np.clip(taus / 40, 0, 1).tolist(),
        "f_tau_auc": 0.75,
        "by_occlusion": [
            {"occlusion": [lo, hi], "n_frames": n, "kp_mean_mm": m}
            for lo, hi, n, m in zip(
                OCCLUSION_EDGES[:-1],
                OCCLUSION_EDGES[1:],
                (9, 6, 3, 0),
                (9.0, 11.0, 14.0, math.nan),
                strict=True,
            )
        ],
        "estimator_time_mean_s": math.inf,
    }


@pytest.fixture
def report():
    """A hand-made report with NaN and Inf figures, two modes, three objects."""
    rng = np.random.default_rng(0)
    return {
        "env_id": "handsim/Grasp-v0",
        "env_kwargs": {"objects": ["025_mug", "011_banana"]},
        "episodes": 4,
        "seed": 0,
        "estimator": {"name": "fake", "repr": "Fake(noise_mm=3.0, latency_steps=2)"},
        "modes": {"feedback_off": _mode(False, rng), "feedback_on": _mode(True, rng)},
    }


def test_to_strict_json_replaces_non_finite():
    """NaN/Inf -> None at any depth; numpy scalars and arrays -> Python; the rest kept."""
    value = {"a": [1.0, math.nan, (np.float32(np.inf), np.int64(3))], "b": np.array([1.5, -np.inf])}
    assert to_strict_json(value) == {"a": [1.0, None, [None, 3]], "b": [1.5, None]}
    assert json.dumps(to_strict_json({"x": np.bool_(True)}), allow_nan=False) == '{"x": true}'


def test_write_report_strict_json_and_plots(report, tmp_path, monkeypatch):
    """JSON without NaN; five non-blank plots; each title names the env and the estimator."""
    from matplotlib.axes import Axes

    titles = []
    original = Axes.set_title
    monkeypatch.setattr(
        Axes, "set_title", lambda self, t, *a, **k: titles.append(t) or original(self, t, *a, **k)
    )
    paths = write_report(report, tmp_path)
    text = paths["json"].read_text()
    assert "NaN" not in text and "Infinity" not in text
    loaded = json.loads(text)
    assert loaded["modes"]["feedback_on"]["center_mm"] is None
    assert loaded["modes"]["feedback_off"]["episodes"][0]["kp_mean_mm"][1] is None
    kinds = {"f_tau", "success", "error_over_time", "error_by_occlusion", "success_by_object"}
    assert set(paths) == kinds | {"json"}
    for kind in kinds:
        image = cv2.imread(str(paths[kind]))
        assert image is not None and image.ndim == 3 and image.std() > 5, kind
    assert len(titles) == len(kinds)
    for title in titles:
        assert "handsim/Grasp-v0" in title
        assert "Fake(noise_mm=3.0, latency_steps=2)" in title.replace("\n", " ")
    assert estimator_label(report) == "Fake(noise_mm=3.0, latency_steps=2)"
    assert estimator_label({"estimator": "Oracle(noise_mm=10)"}) == "Oracle(noise_mm=10)"


def test_evaluate_closed_loop_says_what_it_takes():
    """An estimator instance where a factory belongs, or feedback modes that are not booleans."""
    from handsim.envs.closed_loop import evaluate_closed_loop
    from handsim.errors import HandSimError
    from handsim.estimators import OracleEstimator

    with pytest.raises(HandSimError, match=r"must build a fresh estimator .*an estimator instance"):
        evaluate_closed_loop("handsim/HandPose-v0", OracleEstimator())
    with pytest.raises(HandSimError, match=r"must build a fresh estimator .*received int"):
        evaluate_closed_loop("handsim/HandPose-v0", 3)
    with pytest.raises(HandSimError, match=r"feedback_modes must be a non-empty tuple of booleans"):
        evaluate_closed_loop("handsim/HandPose-v0", OracleEstimator, feedback_modes=("yes",))
