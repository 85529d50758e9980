"""The feedback loop (Oberweger, Wohlhart and Lepetit, ICCV 2015) trained on handsim data.

Modules: :mod:`.synth` (handsim's renderer as the synthesizer; the learned one behind the same
call), :mod:`.models` (the learned synthesizer and the Siamese updater), :mod:`.train`
(``handsim train synthesizer|updater``), :mod:`.checkpoint` and :mod:`.estimator`
(:class:`FeedbackEstimator`). Importing this package does not import torch.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["FeedbackEstimator", "RendererSynthesizer"]

_LAZY_NAMES = {
    "FeedbackEstimator": "handsim.estimators.feedback.estimator",
    "RendererSynthesizer": "handsim.estimators.feedback.synth",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY_NAMES:
        return getattr(importlib.import_module(_LAZY_NAMES[name]), name)
    raise AttributeError(f"module 'handsim.estimators.feedback' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
