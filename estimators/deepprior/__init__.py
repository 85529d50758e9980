"""DeepPrior and DeepPrior++ (Oberweger et al.) trained on handsim data.

Modules: :mod:`.preprocess` (localization, crop, augmentation, PCA; NumPy only),
:mod:`.models`, :mod:`.data`, :mod:`.train`, :mod:`.evaluate`, :mod:`.checkpoint`,
:mod:`.detector` (the whole-image hand detector) and :mod:`.estimator` (torch). Importing this
package does not import torch; the names below are loaded on first access.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["DeepPriorEstimator", "RefinedLocalizer", "PlaneRemovedLocalizer", "LearnedDetector"]

_LAZY_NAMES = {
    "DeepPriorEstimator": "handsim.estimators.deepprior.estimator",
    "RefinedLocalizer": "handsim.estimators.deepprior.estimator",
    "PlaneRemovedLocalizer": "handsim.estimators.deepprior.preprocess",
    "LearnedDetector": "handsim.estimators.deepprior.detector",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY_NAMES:
        return getattr(importlib.import_module(_LAZY_NAMES[name]), name)
    raise AttributeError(f"module 'handsim.estimators.deepprior' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
