"""The handsim.estimators package: lazy exports, and no torch for the torch-free estimators."""

import subprocess
import sys

import pytest


def test_torch_free_estimators_do_not_import_torch():
    """Importing the package, the oracle and the CoM localizer leaves torch unimported."""
    code = (
        "import sys, handsim.estimators as e; e.OracleEstimator; e.CenterOfMassLocalizer; "
        "import handsim.estimators.oracle, handsim.estimators.com; print('torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_every_name_in_all_resolves():
    """Every name of handsim.estimators.__all__ resolves; unknown names raise AttributeError."""
    import handsim.estimators as estimators

    for name in estimators.__all__:
        assert getattr(estimators, name).__name__ == name
        assert name in dir(estimators)
    with pytest.raises(AttributeError, match="has no attribute 'Nope'"):
        estimators.Nope  # noqa: B018
