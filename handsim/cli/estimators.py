"""Estimators named on the command line: the built-in ones and ``module:Class[:kwargs-json]``.

``--estimator`` takes a built-in name (:data:`BUILTIN_ESTIMATORS`) or a user estimator:

- ``my_package.my_module:MyEstimator``: a class importable as a module path (the current
  folder is searched first, as with ``python -m``);
- ``path/to/file.py:MyEstimator``: a class in a Python file;
- either followed by ``:{"json": "kwargs"}``: keyword arguments of the constructor, a JSON object.

The class is instantiated once while the command line is parsed and checked against the
:class:`~handsim.estimator.Estimator` protocol (``predict(depth, K)``, ``predict_batch(depths,
Ks)``, ``reset()``); a failure at any step is an :class:`InvalidEstimatorSpec` naming what is
wrong or missing.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from handsim.errors import HandSimError

__all__ = [
    "BUILTIN_ESTIMATORS",
    "PROTOCOL_METHODS",
    "EstimatorSpec",
    "InvalidEstimatorSpec",
    "parse_estimator_spec",
    "check_estimator",
]

BUILTIN_ESTIMATORS: dict[str, str] = {
    "oracle": "handsim.estimators:OracleEstimator (ground truth + noise, dropout, latency)",
    "com": "handsim.estimators:CenterOfMassLocalizer (hand centre from the depth image)",
    "deepprior++": "handsim.estimators:DeepPriorEstimator (shipped DeepPrior++ weights, torch)",
    "deepprior": "handsim.estimators:DeepPriorEstimator (shipped DeepPrior `deep` weights, torch)",
}
"""Built-in estimator names of ``--estimator`` and what they are."""

PROTOCOL_METHODS: tuple[str, ...] = ("predict", "predict_batch", "reset")
"""Methods of the :class:`~handsim.estimator.Estimator` protocol."""

_FORMAT = "a built-in name ({names}) or module:Class[:kwargs-json] (e.g. my_pkg.est:MyNet or my_est.py:MyNet:'{{\"cube_mm\": 250}}')"  # noqa: E501


class InvalidEstimatorSpec(HandSimError, ValueError):
    """An ``--estimator`` value cannot be loaded as an estimator."""


@dataclasses.dataclass(frozen=True)
class EstimatorSpec:
    """A user estimator named on the command line.

    Attributes:
        text: the value as given.
        cls: the estimator class (or any callable that returns an estimator).
        kwargs: keyword arguments of ``cls``.
    """

    text: str
    cls: Callable[..., Any]
    kwargs: dict[str, Any]

    def make(self) -> Any:
        """A fresh estimator."""
        return self.cls(**self.kwargs)

    @property
    def name(self) -> str:
        """``module:Class``."""
        return f"{getattr(self.cls, '__module__', '?')}:{getattr(self.cls, '__qualname__', '?')}"


def _import(module: str) -> Any:
    if module.endswith(".py") or os.sep in module or "/" in module:
        path = Path(module)
        if not path.is_file():
            raise InvalidEstimatorSpec(f"--estimator: file {module!r} does not exist")
        name = f"_handsim_user_estimator_{path.stem}"
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise InvalidEstimatorSpec(f"--estimator: cannot import {module!r} as a Python file")
        loaded = importlib.util.module_from_spec(spec)
        sys.modules[name] = loaded
        try:
            spec.loader.exec_module(loaded)
        except Exception as err:  # the user's file: say which one failed and how
            del sys.modules[name]
            raise InvalidEstimatorSpec(
                f"--estimator: importing {module!r} failed: {type(err).__name__}: {err}"
            ) from None
        return loaded
    cwd = os.getcwd()
    if cwd not in sys.path:
        sys.path.insert(0, cwd)  # as `python -m` does: modules in the current folder
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as err:
        raise InvalidEstimatorSpec(
            f"--estimator: cannot import module {module!r} ({err}); give an importable module "
            "path or a .py file"
        ) from None
    except Exception as err:  # the user's module: say which one failed and how
        raise InvalidEstimatorSpec(
            f"--estimator: importing {module!r} failed: {type(err).__name__}: {err}"
        ) from None


def check_estimator(estimator: Any, name: str) -> None:
    """Check that ``estimator`` has the methods of the Estimator protocol.

    Raises:
        InvalidEstimatorSpec: naming the missing methods.
    """
    missing = [m for m in PROTOCOL_METHODS if not callable(getattr(estimator, m, None))]
    if missing:
        raise InvalidEstimatorSpec(
            f"--estimator: {name} is not an Estimator: it lacks "
            f"{', '.join(m + '()' for m in missing)}; the protocol (handsim.estimator.Estimator) "
            "needs predict(depth, K) -> Estimate, predict_batch(depths, Ks) and reset()"
        )


def parse_estimator_spec(text: str) -> EstimatorSpec:
    """Load ``module:Class[:kwargs-json]``, instantiate it once and check the protocol.

    Raises:
        InvalidEstimatorSpec: for a malformed value, a module or class that cannot be found, a
            kwargs value that is not a JSON object, a constructor that fails, or an object
            without the protocol's methods.
    """
    parts = text.split(":", 2)
    if len(parts) < 2 or not parts[0] or not parts[1]:
        raise InvalidEstimatorSpec(
            f"--estimator {text!r} is not valid; expected "
            + _FORMAT.format(names=", ".join(BUILTIN_ESTIMATORS))
        )
    module_name, class_name = parts[0], parts[1]
    kwargs: dict[str, Any] = {}
    if len(parts) == 3:
        try:
            kwargs = json.loads(parts[2])
        except json.JSONDecodeError as err:
            raise InvalidEstimatorSpec(
                f"--estimator: the kwargs {parts[2]!r} are not valid JSON ({err.msg}); give a "
                'JSON object such as {"noise_mm": 5}'
            ) from None
        if not isinstance(kwargs, dict):
            raise InvalidEstimatorSpec(
                f"--estimator: the kwargs must be a JSON object; received {parts[2]!r}"
            )
    module = _import(module_name)
    target: Any = module
    for attribute in class_name.split("."):
        target = getattr(target, attribute, None)
        if target is None:
            public = sorted(n for n in vars(module) if not n.startswith("_"))
            raise InvalidEstimatorSpec(
                f"--estimator: module {module_name!r} has no {class_name!r}; it has: "
                f"{', '.join(public) or 'nothing public'}"
            )
    if not callable(target):
        raise InvalidEstimatorSpec(
            f"--estimator: {module_name}:{class_name} is a {type(target).__name__}, not a class"
        )
    spec = EstimatorSpec(text=text, cls=target, kwargs=kwargs)
    try:
        estimator = spec.make()
    except Exception as err:  # a user's constructor: say which one failed and how
        raise InvalidEstimatorSpec(
            f"--estimator: {module_name}:{class_name}(**{kwargs}) failed: "
            f"{type(err).__name__}: {err}"
        ) from None
    check_estimator(estimator, f"{module_name}:{class_name}")
    return spec
