"""Degradation sweeps: the task under a grid of tracking faults and filters.

:func:`run_sweep` runs :class:`~handsim.envs.teleop.loop.TeleopLoop` for every combination
of noise level, latency, dropout rate and filter, one episode per seed, and returns one row
per grid point with the mean metrics over the episodes. The operator is, by default, the
:class:`~handsim.envs.teleop.operator.ReactiveOperator` (the task's expert planning from the
displayed state, seeing it as late as the grid point's latency plus its reaction delay), so
latency and filtering act on what it does; ``operator="replay"`` replays the expert's
recorded streams (:func:`~handsim.envs.teleop.streams.stream_from_expert`) instead, which
cannot react. :func:`write_sweep` saves the table as CSV and JSON and plots success and
fingertip jitter against each degradation.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import math
import pathlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from handsim.envs.teleop.faults import FaultConfig
from handsim.envs.teleop.loop import InvalidTeleopConfig, TeleopConfig, TeleopLoop
from handsim.envs.teleop.operator import OPERATORS, ReactiveOperator
from handsim.envs.teleop.streams import OperatorStream, stream_from_expert
from handsim.estimator import Estimator

__all__ = ["run_sweep", "write_sweep", "SWEEP_COLUMNS"]

SWEEP_COLUMNS: tuple[str, ...] = (
    "noise_mm",
    "latency_frames",
    "dropout",
    "filter",
    "episodes",
    "success_rate",
    "time_to_success_s",
    "penetration_max_mm",
    "penetration_mean_mm",
    "slip_max_mm",
    "jitter_mm",
    "lag_s",
    "unintended_presses",
    "tracking_error_mm",
    "grip_hold_s",
    "intent_grasp_s",
    "intent_onsets",
    "closure_assist_s",
    "assisted_success_rate",
    "keypoint_sigma_mm",
    "steps_per_s",
)
"""Columns of the sweep table (means over the episodes of a grid point; NaN-aware)."""

_MEANS = tuple(c for c in SWEEP_COLUMNS[6:] if c != "assisted_success_rate")


def run_sweep(
    env_id: str = "handsim/Grasp-v0",
    *,
    noise_mm: Sequence[float] = (0.0, 5.0, 10.0),
    latency_frames: Sequence[int] = (0, 3),
    dropout: Sequence[float] = (0.0, 0.1),
    filters: Sequence[str] = ("none", "one_euro"),
    episodes: int = 2,
    seed: int = 0,
    mode: str = "direct",
    estimator_factory: Callable[[], Estimator] | None = None,
    base_faults: FaultConfig | None = None,
    env_kwargs: dict[str, Any] | None = None,
    streams: Sequence[OperatorStream] | None = None,
    operator: str | None = None,
    grip_hold: bool = True,
    grip_steady: bool | str = False,
    pose_filter: bool | str = False,
    grasp_intent: bool = False,
    closure_assist: bool = False,
    pose_prior: bool = False,
    keypoint_sigma_mm: float | str | None = None,
    filter_params: dict[str, dict[str, float]] | None = None,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Run the grid and return the table.

    Args:
        env_id: the task (``handsim/Grasp-v0``, ``handsim/Press-v0``, ...).
        noise_mm: keypoint noise levels, mm.
        latency_frames: latencies, frames.
        dropout: dropout rates, in [0, 1].
        filters: filter names.
        episodes: episodes per grid point (seeds ``seed ... seed + episodes - 1``).
        seed: first seed.
        mode: ``direct`` or ``camera``.
        estimator_factory: builds the estimator of ``camera`` mode.
        base_faults: the other fault settings (bias, jitter, occlusion, dropout mode).
        env_kwargs: keyword arguments of ``gym.make``.
        streams: one recorded operator stream per episode (``operator="replay"``; default:
            the expert's, per seed).
        operator: one of :data:`~handsim.envs.teleop.operator.OPERATORS` (default:
            ``replay`` with ``streams``, else ``reactive``).
        grip_hold: the loop's grip stabiliser (:attr:`TeleopConfig.grip_hold`).
        grip_steady: its steady hold (:attr:`TeleopConfig.grip_steady`).
        pose_filter: the loop's joint-space pose filter (:attr:`TeleopConfig.pose_filter`:
            ``False``, ``True`` or ``"wrist"``).
        grasp_intent: the loop's grasp intent (:attr:`TeleopConfig.grasp_intent`).
        closure_assist: its closure assist (:attr:`TeleopConfig.closure_assist`).
        pose_prior: retarget with the pose prior (:attr:`TeleopConfig.pose_prior`).
        keypoint_sigma_mm: its keypoint noise (:attr:`TeleopConfig.keypoint_sigma_mm`;
            ``None``: each cell's ``noise_mm``; ``"auto"``: estimated from the stream).
        filter_params: parameters per filter name (e.g. ``{"one_euro": {"beta": 1.0}}``).
        progress: called with 1 after every episode.

    Returns:
        ``{"env_id", "mode", "episodes", "seed", "grid", "rows"}``; each row has the
        :data:`SWEEP_COLUMNS` and ``episodes_detail`` (per-episode metrics).
    """
    if not isinstance(episodes, int) or episodes < 1:
        raise InvalidTeleopConfig(f"episodes must be an int >= 1; received {episodes!r}")
    if streams is not None and len(streams) != episodes:
        raise InvalidTeleopConfig(
            f"streams must hold one stream per episode ({episodes}); received {len(streams)}"
        )
    if operator is None:
        operator = "replay" if streams is not None else "reactive"
    if operator not in OPERATORS:
        raise InvalidTeleopConfig(
            f"operator={operator!r} is not valid; choose one of {', '.join(OPERATORS)}"
        )
    if streams is not None and operator != "replay":
        raise InvalidTeleopConfig("streams are replayed: pass operator='replay' with them")
    base = base_faults or FaultConfig()
    seeds = [seed + k for k in range(episodes)]
    if streams is None and operator == "replay":
        streams = [stream_from_expert(env_id, s, env_kwargs=env_kwargs) for s in seeds]
    rows = []
    loops: dict[str, TeleopLoop] = {}
    try:
        for n, lat, p, filt in itertools.product(noise_mm, latency_frames, dropout, filters):
            faults = dataclasses.replace(base, noise_mm=n, latency_frames=lat, dropout=p)
            config = TeleopConfig(
                mode=mode,
                faults=faults,
                filter=filt,
                filter_params=dict((filter_params or {}).get(filt, {})),
                grip_hold=grip_hold,
                grip_steady=grip_steady,
                pose_filter=pose_filter,
                grasp_intent=grasp_intent,
                closure_assist=closure_assist,
                pose_prior=pose_prior,
                keypoint_sigma_mm=keypoint_sigma_mm,
                seed=seed,
            )
            if filt not in loops:
                loops[filt] = TeleopLoop(
                    env_id,
                    config,
                    estimator=estimator_factory() if estimator_factory else None,
                    env_kwargs=env_kwargs,
                )
            loop = loops[filt]
            loop.config = config
            details = []
            for k, s in enumerate(seeds):
                if streams is not None:
                    details.append(loop.run(streams[k], s).metrics)
                    continue
                # The display is as late as the tracking (a symmetric round trip).
                op = ReactiveOperator(loop.env, s, display_latency_s=lat * loop.control_dt)
                details.append({**loop.run(op, s).metrics, "reaction_s": op.reaction_s})
                if progress is not None:
                    progress(1)
            row: dict[str, Any] = {
                "noise_mm": float(n),
                "latency_frames": int(lat),
                "dropout": float(p),
                "filter": filt,
                "episodes": len(details),
                "success_rate": float(np.mean([d["success"] for d in details])),
                # Successes while the closure assist drove a digit (physical grasps still).
                "assisted_success_rate": float(
                    np.mean([d.get("success_assisted", False) for d in details])
                ),
            }
            for key in _MEANS:
                values = np.array([d[key] for d in details], dtype=np.float64)
                row[key] = float(np.nanmean(values)) if np.isfinite(values).any() else math.nan
            row["episodes_detail"] = details
            rows.append(row)
    finally:
        for loop in loops.values():
            loop.close()
    return {
        "env_id": env_id,
        "mode": mode,
        "operator": operator,
        "grip_hold": bool(grip_hold),
        "grip_steady": grip_steady if isinstance(grip_steady, str) else bool(grip_steady),
        "pose_filter": pose_filter if isinstance(pose_filter, str) else bool(pose_filter),
        "grasp_intent": bool(grasp_intent),
        "closure_assist": bool(closure_assist),
        "pose_prior": bool(pose_prior),
        "keypoint_sigma_mm": keypoint_sigma_mm,
        "filter_params": filter_params or {},
        "episodes": episodes,
        "seed": seed,
        "grid": {
            "noise_mm": list(map(float, noise_mm)),
            "latency_frames": list(map(int, latency_frames)),
            "dropout": list(map(float, dropout)),
            "filters": list(filters),
        },
        "base_faults": base.to_dict(),
        "rows": rows,
    }


def write_sweep(report: dict[str, Any], out_dir: str | pathlib.Path) -> dict[str, pathlib.Path]:
    """Write ``sweep.csv``, ``sweep.json`` and the plots into ``out_dir``.

    Plots (PNG): ``success_vs_noise.png`` and ``jitter_vs_noise.png`` (one line per latency,
    dropout and filter), ``success_vs_latency.png`` and ``success_vs_dropout.png`` (one line
    per filter, at the lowest other degradations).

    Returns:
        The written paths by kind.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from handsim.envs.closed_loop import to_strict_json

    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / "sweep.csv", "json": out / "sweep.json"}
    with paths["csv"].open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(SWEEP_COLUMNS))
        writer.writeheader()
        for row in report["rows"]:
            writer.writerow({k: row[k] for k in SWEEP_COLUMNS})
    paths["json"].write_text(json.dumps(to_strict_json(report), indent=2, allow_nan=False))
    rows = report["rows"]
    title = (
        f"{report['env_id']}, {report['mode']} mode, {report.get('operator', 'replay')} "
        f"operator, {report['episodes']} episode(s) per point"
    )

    def lines(
        ax: Any, x_key: str, y_key: str, group: tuple[str, ...], scale: float = 1.0, data=None
    ) -> None:
        data = rows if data is None else data
        keys = sorted({tuple(r[g] for g in group) for r in data}, key=str)
        for key in keys:
            pts = sorted((r[x_key], r[y_key]) for r in data if tuple(r[g] for g in group) == key)
            if not pts:
                continue
            x, y = zip(*pts, strict=True)
            label = ", ".join(
                f"{g.replace('_frames', '')} {v}" for g, v in zip(group, key, strict=True)
            )
            ax.plot(x, np.array(y, dtype=float) * scale, marker="o", label=label)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
        ax.set_title(title, fontsize=8)

    def save(fig: Any, kind: str) -> None:
        paths[kind] = out / f"{kind}.png"
        fig.tight_layout()
        fig.savefig(paths[kind], dpi=100)
        plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    lines(ax, "noise_mm", "success_rate", ("latency_frames", "dropout", "filter"), 100.0)
    ax.set_xlabel("Keypoint noise / mm (std per axis)")
    ax.set_ylabel("Task success / %")
    ax.set_ylim(-5, 105)
    save(fig, "success_vs_noise")
    fig, ax = plt.subplots(figsize=(6, 4))
    lines(ax, "noise_mm", "jitter_mm", ("latency_frames", "dropout", "filter"))
    ax.set_xlabel("Keypoint noise / mm (std per axis)")
    ax.set_ylabel("Fingertip jitter / mm (RMS above 5 Hz)")
    ax.set_ylim(bottom=0)
    save(fig, "jitter_vs_noise")
    low_n = min(r["noise_mm"] for r in rows)
    low_p = min(r["dropout"] for r in rows)
    low_l = min(r["latency_frames"] for r in rows)
    for x_key, fixed, kind, label in (
        (
            "latency_frames",
            {"noise_mm": low_n, "dropout": low_p},
            "success_vs_latency",
            "Latency / frames",
        ),
        (
            "dropout",
            {"noise_mm": low_n, "latency_frames": low_l},
            "success_vs_dropout",
            "Dropped frames / fraction",
        ),
    ):
        fig, ax = plt.subplots(figsize=(6, 4))
        subset = [r for r in rows if all(r[k] == v for k, v in fixed.items())]
        lines(ax, x_key, "success_rate", ("filter",), 100.0, data=subset)
        ax.set_xlabel(label)
        ax.set_ylabel("Task success / %")
        ax.set_ylim(-5, 105)
        save(fig, kind)
    return paths
