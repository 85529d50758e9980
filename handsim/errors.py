"""Exceptions raised by handsim.

Every public entry point validates its input once and raises a subclass of
:class:`HandSimError`. Messages say what was expected, what was received and
what is valid (or how to fix it).
"""

from __future__ import annotations

__all__ = [
    "HandSimError",
    "InvalidHandParams",
    "InvalidPose",
    "InvalidKeypoints",
    "UnknownName",
    "InvalidEstimate",
    "InvalidEstimatorInput",
    "InvalidEstimatorParams",
    "EstimatorStateError",
    "InvalidObjectParams",
]


class HandSimError(Exception):
    """Base class of every error raised by handsim."""


class InvalidHandParams(HandSimError, ValueError):
    """A hand parameter is outside its valid range."""


class InvalidPose(HandSimError, ValueError):
    """A hand pose has the wrong shape, a non-finite value or an angle outside its limits."""


class InvalidKeypoints(HandSimError, ValueError):
    """Keypoints have the wrong shape, order or non-finite values."""


class UnknownName(HandSimError, KeyError):
    """A name (gesture, grasp, keypoint format, ...) is not registered."""

    def __str__(self) -> str:
        # KeyError quotes its argument; show the message as written.
        return str(self.args[0]) if self.args else ""


class InvalidEstimate(HandSimError, ValueError):
    """An estimate has a wrong shape, a non-finite value or fields that contradict ``valid``."""


class InvalidEstimatorInput(HandSimError, ValueError):
    """An estimator received a depth image, intrinsics or ground-truth frame it cannot use."""


class InvalidEstimatorParams(HandSimError, ValueError):
    """An estimator's constructor argument is outside its valid range."""


class EstimatorStateError(HandSimError, RuntimeError):
    """An estimator was called out of order (an oracle's ``predict`` before ``observe_truth``)."""


class InvalidObjectParams(HandSimError, ValueError):
    """An object parameter (mass, scale, name, option) is invalid."""
