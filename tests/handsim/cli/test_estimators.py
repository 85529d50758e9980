"""`--estimator module:Class[:kwargs-json]`: user estimators loaded, checked, named in errors."""

import pytest

from handsim.cli import main
from handsim.cli.estimators import InvalidEstimatorSpec, parse_estimator_spec

USER_ESTIMATORS = '''
import numpy as np

from handsim.estimator import Estimate


class FixedCentre:
    """A localizer that always answers the same point in front of the camera."""

    def __init__(self, z_m=0.5):
        if z_m <= 0:
            raise ValueError(f"z_m must be > 0; received {z_m}")
        self.z_m = z_m

    def predict(self, depth, K):
        return Estimate(center_cam=np.array([0.0, 0.0, self.z_m]))

    def predict_batch(self, depths, Ks):
        return [self.predict(d, k) for d, k in zip(depths, Ks)]

    def reset(self):
        pass

    def __repr__(self):
        return f"FixedCentre(z_m={self.z_m})"


class Plain(FixedCentre):
    """FixedCentre without a repr of its own."""

    __repr__ = object.__repr__


class Described(FixedCentre):
    def describe(self):
        return f"described, {self.z_m} m"


class NoBatch:
    def predict(self, depth, K):
        return Estimate(valid=False)

    def reset(self):
        pass


NOT_A_CLASS = 3
'''


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    """`user_est.py` in the current folder (as a user's project would have it)."""
    (tmp_path / "user_est.py").write_text(USER_ESTIMATORS)
    monkeypatch.chdir(tmp_path)
    yield tmp_path
    import sys

    sys.modules.pop("user_est", None)


def test_user_estimator_loaded_with_kwargs(user_module):
    """module:Class:kwargs builds fresh instances with the kwargs; a .py path works too."""
    spec = parse_estimator_spec('user_est:FixedCentre:{"z_m": 0.4}')
    first, second = spec.make(), spec.make()
    assert first is not second and first.z_m == 0.4 and spec.kwargs == {"z_m": 0.4}
    assert spec.name == "user_est:FixedCentre"
    by_path = parse_estimator_spec(f"{user_module / 'user_est.py'}:FixedCentre")
    assert by_path.make().z_m == 0.5


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("user_est:NoBatch", r"user_est:NoBatch is not an Estimator: it lacks predict_batch\(\)"),
        ("user_est:Missing", "module 'user_est' has no 'Missing'; it has: .*FixedCentre"),
        ("user_est:NOT_A_CLASS", "user_est:NOT_A_CLASS is a int, not a class"),
        ("no_such_module_xyz:Est", "cannot import module 'no_such_module_xyz'"),
        ("missing_file.py:Est", "file 'missing_file.py' does not exist"),
        ("user_est:FixedCentre:{z_m: 1}", "the kwargs '{z_m: 1}' are not valid JSON"),
        ("user_est:FixedCentre:[1, 2]", "the kwargs must be a JSON object; received"),
        (
            'user_est:FixedCentre:{"z_m": -1}',
            r"FixedCentre\(\*\*\{'z_m': -1\}\) failed: ValueError",
        ),
        ('user_est:FixedCentre:{"depth": 1}', "failed: TypeError: .*unexpected keyword"),
        (":Est", "is not valid; expected a built-in name"),
    ],
)
def test_bad_user_estimators_name_what_is_wrong(user_module, text, message):
    """Each failure is an InvalidEstimatorSpec that says what is missing or wrong."""
    with pytest.raises(InvalidEstimatorSpec, match=message):
        parse_estimator_spec(text)


def test_bad_user_estimator_on_the_command_line(user_module, capsys):
    """On the command line the same message is argparse's one-line usage error (exit 2)."""
    with pytest.raises(SystemExit) as exit_info:
        main(["closed-loop", "--estimator", "user_est:NoBatch"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert "error: argument --estimator: user_est:NoBatch is not an Estimator" in err
    assert "lacks predict_batch()" in err


def test_user_estimator_in_the_closed_loop(user_module, capsys):
    """A user estimator runs in the loop; the report names it with its kwargs (strict JSON)."""
    import json

    out = user_module / "out"
    argv = ["closed-loop", "--env", "handsim/HandPose-v0", "--episodes", "1", "--sensor"]
    argv += ["none", "-q", "--estimator", 'user_est:FixedCentre:{"z_m": 0.45}', "--out", str(out)]
    assert main(argv) == 0
    assert '"feedback_on"' in capsys.readouterr().out

    def refuse(constant):
        raise AssertionError(f"non-strict JSON constant {constant}")

    report = json.loads((out / "closed_loop.json").read_text(), parse_constant=refuse)
    assert report["estimator"]["name"] == "user_est:FixedCentre"
    assert report["estimator"]["kwargs"] == {"z_m": 0.45}
    assert report["estimator"]["repr"] == "FixedCentre(z_m=0.45)"
    off = report["modes"]["feedback_off"]
    # A localizer gives no keypoints: the keypoint figures are null, the centre error is not.
    assert off["kp_mean_mm"] is None and off["center_mm"] > 0
    # No keypoints, no F(tau) curve: null, not a flat 0 % and an AUC of 0.
    assert off["f_tau_auc"] is None and set(off["f_tau"]) == {None}
    assert off["n_frames"] == 151 and off["n_frames_with_keypoints"] == 0


def test_reports_name_estimators_without_object_addresses(user_module):
    """describe() first, then a class's own repr; a bare object repr gives the class name.

    Through the command line an estimator without a name of its own is titled by its spec
    (``module:Class:{kwargs}``), never ``<... object at 0x...>``.
    """
    from handsim.envs.closed_loop import estimator_label
    from handsim.estimator import describe_estimator

    spec = parse_estimator_spec('user_est:Plain:{"z_m": 0.4}')
    assert describe_estimator(spec.make()) == ("Plain", False)
    assert describe_estimator(parse_estimator_spec("user_est:FixedCentre").make()) == (
        "FixedCentre(z_m=0.5)",
        True,
    )
    described = parse_estimator_spec('user_est:Described:{"z_m": 0.3}').make()
    assert describe_estimator(described) == ("described, 0.3 m", True)
    report = {"estimator": {"repr": "Plain", "describes_itself": False, "spec": spec.text}}
    assert estimator_label(report) == 'user_est:Plain:{"z_m": 0.4}'
    report["estimator"]["describes_itself"] = True
    assert estimator_label(report) == "Plain"


def test_a_plain_user_estimator_is_titled_by_its_spec(user_module):
    """The closed-loop report of an estimator without a repr: its spec, in JSON and titles."""
    import json

    out = user_module / "out"
    argv = ["closed-loop", "--env", "handsim/HandPose-v0", "--episodes", "1", "--sensor"]
    argv += ["none", "-q", "--estimator", 'user_est:Plain:{"z_m": 0.45}', "--out", str(out)]
    assert main(argv) == 0
    report = json.loads((out / "closed_loop.json").read_text())
    assert report["estimator"]["repr"] == "Plain"
    assert report["estimator"]["describes_itself"] is False
    assert "object at" not in json.dumps(report)
