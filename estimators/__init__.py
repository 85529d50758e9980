"""Pose estimators of handsim (imported as ``handsim.estimators``); torch is imported lazily."""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "CenterOfMassLocalizer",
    "DeepPriorEstimator",
    "FeedbackEstimator",
    "LearnedDetector",
    "OracleEstimator",
    "PlaneRemovedLocalizer",
    "RefinedLocalizer",
]

# Public name -> submodule; a name is imported on first access, so this package stays free of
# torch until a torch estimator is asked for (`import handsim.estimators` never imports torch).
_LAZY_NAMES = {
    "CenterOfMassLocalizer": "handsim.estimators.com",
    "OracleEstimator": "handsim.estimators.oracle",
    "DeepPriorEstimator": "handsim.estimators.deepprior.estimator",
    "FeedbackEstimator": "handsim.estimators.feedback.estimator",
    "LearnedDetector": "handsim.estimators.deepprior.detector",
    "PlaneRemovedLocalizer": "handsim.estimators.deepprior.preprocess",
    "RefinedLocalizer": "handsim.estimators.deepprior.estimator",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY_NAMES:
        return getattr(importlib.import_module(_LAZY_NAMES[name]), name)
    raise AttributeError(f"module 'handsim.estimators' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
