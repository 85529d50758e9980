"""Curves of hand pose metrics as PNG files (matplotlib, Agg backend)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from handsim.metrics._common import TAU_MAX_MM, TAU_STEP_MM, InvalidMetricInput, _array
from handsim.metrics.hand import (
    HandPoseReport,
    _frame_reduce,
    curve_auc,
    fraction_of_frames_within,
    pck,
    threshold_grid_mm,
)

# Plots -----------------------------------------------------------------------------------------


def _png_path(path: str | os.PathLike[str]) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidMetricInput(
            f"path must be a str or os.PathLike ending in .png; received {path!r}"
        )
    p = Path(path)
    if p.suffix.lower() != ".png":
        raise InvalidMetricInput(f"path must end in .png; received {str(p)!r}")
    p.parent.mkdir(parents=True, exist_ok=True)
    return p


def _check_methods(methods: Mapping[str, Any]) -> None:
    if not isinstance(methods, Mapping) or len(methods) == 0:
        raise InvalidMetricInput(
            "methods must be a non-empty mapping of method name -> errors or report; received "
            f"{methods!r}"
        )


def _save_curves(
    curves: list[tuple[str, np.ndarray, np.ndarray]],
    path: Path,
    *,
    xlabel: str,
    ylabel: str,
    title: str | None,
) -> Path:
    # The object-oriented API with an Agg canvas: no pyplot state, no GUI backend.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.0, 4.5), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for label, x, y in curves:
        ax.plot(x, 100.0 * y, linewidth=2.0, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_xlim(curves[0][1][0], curves[0][1][-1])
    ax.set_ylim(0.0, 100.0)
    ax.grid(True)
    ax.legend(loc="lower right")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, format="png")
    return path


def plot_f_tau(
    methods: Mapping[str, HandPoseReport | Any],
    path: str | os.PathLike[str],
    *,
    tau_max_mm: float = TAU_MAX_MM,
    step_mm: float = TAU_STEP_MM,
    title: str | None = None,
) -> Path:
    """Plot F(tau) (fraction of frames with max joint error <= tau) of one or more methods.

    Args:
        methods: method name -> a :class:`HandPoseReport` (its own grid is used), (N,) per-frame
            max errors in mm, or (N, J) per-joint errors in mm (NaN = not evaluated). All on
            one axes, with a legend giving each AUC.
        path: output PNG file (parent folders are created).
        tau_max_mm: last threshold for array inputs, mm.
        step_mm: threshold spacing for array inputs, mm.
        title: optional axes title.

    Returns:
        The path of the written PNG.

    Raises:
        InvalidMetricInput: on no method, a path not ending in ``.png`` or bad errors.
    """
    _check_methods(methods)
    threshold_grid_mm(tau_max_mm, step_mm)  # checked even when only reports are given
    if title is not None and not isinstance(title, str):
        raise InvalidMetricInput(f"title must be a str or None; received {title!r}")
    out = _png_path(path)
    curves = []
    for name, value in methods.items():
        if isinstance(value, HandPoseReport):
            taus, f = np.asarray(value.thresholds_mm), np.asarray(value.f_tau)
        else:
            e = _array(f"methods[{name!r}]", value)
            if e.ndim == 2:
                e = _frame_reduce(e, "max")
            taus = threshold_grid_mm(tau_max_mm, step_mm)
            f = fraction_of_frames_within(e, taus)
        curves.append((f"{name} (AUC {curve_auc(taus, f):.3f})", taus, f))
    return _save_curves(
        curves,
        out,
        xlabel="Distance threshold tau / mm",
        ylabel="Frames with max joint error <= tau / %",
        title=title,
    )


def plot_pck(
    methods: Mapping[str, HandPoseReport | Any],
    path: str | os.PathLike[str],
    *,
    tau_max_mm: float = TAU_MAX_MM,
    step_mm: float = TAU_STEP_MM,
    title: str | None = None,
) -> Path:
    """Plot PCK(tau) (fraction of joints with error <= tau) of one or more methods.

    Args:
        methods: method name -> a :class:`HandPoseReport` (its own grid is used) or per-joint
            errors in mm of any shape (NaN = not evaluated). All on one axes, with a legend
            giving each AUC.
        path: output PNG file (parent folders are created).
        tau_max_mm: last threshold for array inputs, mm.
        step_mm: threshold spacing for array inputs, mm.
        title: optional axes title.

    Returns:
        The path of the written PNG.

    Raises:
        InvalidMetricInput: on no method, a path not ending in ``.png`` or bad errors.
    """
    _check_methods(methods)
    threshold_grid_mm(tau_max_mm, step_mm)  # checked even when only reports are given
    if title is not None and not isinstance(title, str):
        raise InvalidMetricInput(f"title must be a str or None; received {title!r}")
    out = _png_path(path)
    curves = []
    for name, value in methods.items():
        if isinstance(value, HandPoseReport):
            taus, p = np.asarray(value.thresholds_mm), np.asarray(value.pck)
        else:
            taus = threshold_grid_mm(tau_max_mm, step_mm)
            p = pck(value, taus)
        curves.append((f"{name} (AUC {curve_auc(taus, p):.3f})", taus, p))
    return _save_curves(
        curves,
        out,
        xlabel="Distance threshold tau / mm",
        ylabel="Joints with error <= tau / %",
        title=title,
    )
