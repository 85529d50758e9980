"""``handsim benchmark make`` / ``run``: handsim-bench, one fixed table for every estimator.

``make`` builds the versioned test sets (:data:`~handsim.cli.benchmark_sets.SETS`, each a
dataset folder of ``handsim generate`` made from a fixed seed) and ``benchmark.json`` naming the
version (:data:`~handsim.cli.benchmark_sets.VERSION`) and every set's content digest. A folder
that holds another version is refused, and so is a set whose digest is not the one its version
records (:func:`~handsim.cli.benchmark_sets.make_benchmark`): a versioned set never changes, a
new one gets a new name. Rerunning ``make`` into its own folder resumes it (complete shards are
kept) and checks nothing changed.

``run`` runs one estimator on every frame of every set, each frame on its own (``reset()``
before it; the side of the hand, ``is_left``, goes to an estimator's optional ``set_side``;
oracles get the truth through ``observe_truth``) and
then, unless ``--episodes 0``, ``handsim/Grasp-v0`` with the estimator in the loop, feedback
off and on (:func:`~handsim.envs.closed_loop.evaluate_closed_loop`). It writes
``benchmark.json`` (strict JSON: ``null`` for a figure that does not exist, e.g. keypoint
errors of a localizer; the digests of the sets it ran on, ``set_digests``, and whether they
are the version's, ``set_digests_match``), ``table.md``, ``f_tau.png``, ``error_by_set.png``
and the closed-loop report under ``closed_loop/``.

Offline figures per set: mean and median keypoint error (mm, over the frames with keypoints),
the area under F(tau) (fraction of frames whose largest joint error is within tau, tau in
0-80 mm; a frame without keypoints fails every tau), the hand-centre error (mm), and the frames
without an estimate; pooled, per side, per occlusion bucket and per joint.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from handsim.cli._args import (
    add_quiet,
    integer,
    number,
    probability,
    progress_bar,
    strict_json,
)
from handsim.cli.benchmark_sets import (
    BLAS_KERNEL,
    DIGESTS,
    SETS,
    VERSION,
    BenchmarkError,
    make_benchmark,
    read_benchmark,
    recorded_blas_environment,
    set_digest,
    valid_frames,
)

__all__ = [
    "VERSION",
    "SETS",
    "BenchmarkError",
    "make_benchmark",
    "run_benchmark",
    "compare_runs",
    "add_parser",
]

# The name the feedback evaluation (estimators/feedback/evaluate.py) imports.
_read_benchmark = read_benchmark

OCCLUSION_EDGES = (0.0, 0.1, 0.3, 0.5, 0.7, 1.0)
"""Occlusion buckets of the report (hand occlusion ratio)."""

CLOSED_LOOP_ENV = "handsim/Grasp-v0"
"""The env of the closed-loop part."""
CLOSED_LOOP_SEED = 0
"""First seed of the closed-loop episodes."""


def _frames(folder: Path) -> Any:
    """Every valid frame of a dataset folder: (arrays, Frame) in shard order."""
    from handsim.data.arrays import arrays_to_frame

    for arrays in valid_frames(folder):
        yield arrays, arrays_to_frame(arrays)


def _run_set(folder: Path, estimator: Any) -> dict[str, np.ndarray]:
    """Per-frame errors of one set: joint errors (mm), centre error, occlusion, side, time."""
    from handsim.estimator import PrivilegedEstimator, hand_center

    privileged = isinstance(estimator, PrivilegedEstimator)
    set_side = getattr(estimator, "set_side", None)
    rows: dict[str, list[Any]] = {k: [] for k in ("joint", "center", "occ", "left", "time")}
    for arrays, frame in _frames(folder):
        # Frames are independent draws: none may carry a tracker's state into the next.
        estimator.reset()
        if privileged:
            estimator.observe_truth(frame)
        left = bool(arrays["is_left"])
        if callable(set_side):
            set_side(left)
        start = time.perf_counter()
        estimate = estimator.predict(arrays["depth"], np.asarray(arrays["K"], np.float64))
        rows["time"].append(time.perf_counter() - start)
        gt = np.asarray(arrays["keypoints_cam"], np.float64)
        joint = np.full(21, np.nan)
        center = math.nan
        if estimate.valid and estimate.keypoints_cam is not None:
            joint = np.linalg.norm(estimate.keypoints_cam - gt, axis=1) * 1000.0
        if estimate.valid and estimate.center_cam is not None:
            center = float(np.linalg.norm(estimate.center_cam - hand_center(gt)) * 1000.0)
        rows["joint"].append(joint)
        rows["center"].append(center)
        occ = float(arrays["hand_occlusion_ratio"])
        rows["occ"].append(occ)
        rows["left"].append(left)
    return {
        "joint": np.asarray(rows["joint"]).reshape(-1, 21),
        "center": np.asarray(rows["center"], np.float64),
        "occ": np.asarray(rows["occ"], np.float64),
        "left": np.asarray(rows["left"], bool),
        "time": np.asarray(rows["time"], np.float64),
    }


def _stats(joint: np.ndarray, center: np.ndarray, time_s: np.ndarray | None = None) -> dict:
    """Figures of a group of frames; ``None`` for what does not exist (no keypoints)."""
    from handsim import metrics

    has = np.all(np.isfinite(joint), axis=1)
    taus = metrics.threshold_grid_mm()
    frame_max = np.where(has, np.nanmax(np.where(has[:, None], joint, 0.0), axis=1), np.inf)
    f_tau = metrics.fraction_of_frames_within(frame_max, taus) if len(joint) else None
    found = np.isfinite(center)
    out = {
        "n_frames": int(len(joint)),
        "n_with_keypoints": int(has.sum()),
        "n_without_estimate": int((~has & ~found).sum()),
        "mean_mm": float(joint[has].mean()) if has.any() else None,
        "median_mm": float(np.median(joint[has])) if has.any() else None,
        "auc_f_tau": metrics.curve_auc(taus, f_tau) if has.any() else None,
        "f_tau": [float(v) for v in f_tau] if has.any() else None,
        "center_mm": float(center[found].mean()) if found.any() else None,
    }
    if time_s is not None and len(time_s):
        out["time_ms_mean"] = float(time_s.mean() * 1000.0)
    return out


def _offline(bench: Path, sets: dict[str, Any], make_estimator: Any, quiet: bool) -> dict:
    from handsim.hand.keypoints import KEYPOINT_NAMES

    estimator = make_estimator()
    per_set, pooled = {}, []
    total = sum(int(v["frames"]) for v in sets.values())
    with progress_bar(total, "benchmark offline", "frame", enabled=not quiet) as bar:
        for name, info in sets.items():
            folder = bench / str(info["folder"])
            if not (folder / "manifest.json").is_file():
                raise BenchmarkError(
                    f"--bench {bench}: set {name!r} is missing ({folder}); finish it with "
                    f"`handsim benchmark make --out {bench}`"
                )
            rows = _run_set(folder, estimator)
            per_set[name] = {"what": info.get("what", ""), **_stats(**_pick(rows))}
            pooled.append(rows)
            bar.update(int(info["frames"]))
    rows = {k: np.concatenate([r[k] for r in pooled]) for k in pooled[0]}
    by_side = {
        side: _stats(rows["joint"][rows["left"] == left], rows["center"][rows["left"] == left])
        for side, left in (("right", False), ("left", True))
    }
    by_occ = []
    for lo, hi in zip(OCCLUSION_EDGES[:-1], OCCLUSION_EDGES[1:], strict=True):
        last = hi == OCCLUSION_EDGES[-1]
        m = (rows["occ"] >= lo) & ((rows["occ"] <= hi) if last else (rows["occ"] < hi))
        by_occ.append({"occlusion": [lo, hi], **_stats(rows["joint"][m], rows["center"][m])})
    has = np.all(np.isfinite(rows["joint"]), axis=1)
    per_joint = {
        n: (float(rows["joint"][has, j].mean()) if has.any() else None)
        for j, n in enumerate(KEYPOINT_NAMES)
    }
    return {
        "sets": per_set,
        "all": _stats(rows["joint"], rows["center"], rows["time"]),
        "by_side": by_side,
        "by_occlusion": by_occ,
        "per_joint_mean_mm": per_joint,
    }


def _pick(rows: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {"joint": rows["joint"], "center": rows["center"], "time_s": rows["time"]}


def _closed_loop(make_estimator: Any, episodes: int, out: Path, quiet: bool) -> dict:
    import gymnasium as gym

    import handsim.envs  # noqa: F401 (registers the ids)
    from handsim.envs.closed_loop import evaluate_closed_loop, write_report

    env_kwargs = {"obs_mode": "depth", "sensor": "structured_light", "camera": "icvl"}
    total = 2 * episodes * (gym.spec(CLOSED_LOOP_ENV).max_episode_steps or 0)
    with progress_bar(total, "benchmark closed loop", "step", enabled=not quiet) as bar:
        report = evaluate_closed_loop(
            CLOSED_LOOP_ENV,
            make_estimator,
            episodes=episodes,
            seed=CLOSED_LOOP_SEED,
            env_kwargs=env_kwargs,
            progress=bar.update,
            media_dir=out / "closed_loop",
        )
    write_report(report, out / "closed_loop")
    on, off = report["modes"]["feedback_on"], report["modes"]["feedback_off"]
    return {
        "env_id": CLOSED_LOOP_ENV,
        "episodes": episodes,
        "seeds": [CLOSED_LOOP_SEED, CLOSED_LOOP_SEED + episodes - 1],
        "env_kwargs": env_kwargs,
        "success_rate_feedback_on": on["success_rate"],
        "success_rate_feedback_off": off["success_rate"],
        "kp_mean_mm_feedback_on": on["kp_mean_mm"],
        "center_mm_feedback_on": on["center_mm"],
        "estimator_time_mean_s": on["estimator_time_mean_s"],
        "report": "closed_loop/closed_loop.json",
    }


def _fmt(value: Any, digits: int = 1) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def _table(result: dict[str, Any]) -> str:
    off = result["offline"]
    lines = [
        f"{result['benchmark']} · {result['estimator'].get('spec', result['estimator']['name'])}",
        _digest_line(result),
        "",
        "| set | frames | mean mm | median mm | AUC F(τ) 0-80 mm | centre mm | no estimate |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, s in [*off["sets"].items(), ("**all**", off["all"])]:
        lines.append(
            f"| {name} | {s['n_frames']} | {_fmt(s['mean_mm'])} | {_fmt(s['median_mm'])} | "
            f"{_fmt(s['auc_f_tau'], 3)} | {_fmt(s['center_mm'])} | {s['n_without_estimate']} |"
        )
    groups = [(f"side: {side}", s) for side, s in off["by_side"].items()]
    groups += [
        (f"occlusion {b['occlusion'][0]:.1f}-{b['occlusion'][1]:.1f}", b)
        for b in off["by_occlusion"]
    ]
    for name, s in groups:
        lines.append(
            f"| {name} | {s['n_frames']} | {_fmt(s['mean_mm'])} | {_fmt(s['median_mm'])} "
            f"| {_fmt(s['auc_f_tau'], 3)} | {_fmt(s['center_mm'])} | {s['n_without_estimate']} |"
        )
    loop = result["closed_loop"]
    if loop is not None:
        lines += [
            "",
            f"Closed loop, {loop['env_id']}, {loop['episodes']} seeds: success "
            f"{100 * loop['success_rate_feedback_on']:.0f} % with feedback on "
            f"({100 * loop['success_rate_feedback_off']:.0f} % acting on the truth); "
            f"in-loop keypoint error {_mm(_finite(loop['kp_mean_mm_feedback_on']))}.",
        ]
    return "\n".join(lines) + "\n"


def _digest_line(result: dict[str, Any]) -> str:
    match = result.get("set_digests_match")
    if match is None:
        return "Sets: no recorded digests to check them against (a folder made before them)."
    if match:
        return f"Sets: the content digests {result['benchmark']} records."
    return (
        f"Sets: NOT those of {result['benchmark']} (their content digests differ): these "
        "figures compare only with runs on the same sets (benchmark.json, set_digests)."
    )


def _mm(value: Any) -> str:
    return "n/a (no keypoints)" if value is None else f"{value:.1f} mm"


def _finite(x: Any) -> Any:
    return None if x is None or not math.isfinite(x) else x


def _plots(result: dict[str, Any], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from handsim import metrics

    title = f"{result['benchmark']}\n{result['estimator']['describe']}"
    sets = result["offline"]["sets"]
    taus = metrics.threshold_grid_mm()
    fig, ax = plt.subplots(figsize=(6, 4))
    drawn = False
    for name, s in sets.items():
        if s["f_tau"] is not None:
            ax.plot(taus, 100 * np.asarray(s["f_tau"]), label=name)
            drawn = True
    if not drawn:
        ax.text(0.5, 0.5, "no keypoints: F(τ) does not exist", ha="center", transform=ax.transAxes)
    else:
        ax.legend(fontsize=7)
    ax.set(xlabel="τ / mm", ylabel="frames with max joint error ≤ τ / %", ylim=(0, 100))
    ax.set_title(title, fontsize=8)
    fig.tight_layout()
    paths = [out / "f_tau.png", out / "error_by_set.png"]
    fig.savefig(paths[0], dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    keypoints = any(s["mean_mm"] is not None for s in sets.values())
    key = "mean_mm" if keypoints else "center_mm"
    ax.bar(range(len(sets)), [s[key] or 0.0 for s in sets.values()], color="tab:blue")
    ax.set_xticks(range(len(sets)), list(sets), rotation=20, fontsize=7)
    ax.set_ylabel("mean keypoint error / mm" if keypoints else "hand-centre error / mm")
    ax.set_title(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(paths[1], dpi=100)
    plt.close(fig)
    return paths


def _digests(bench: Path, record: dict[str, Any]) -> tuple[dict[str, str], bool | None]:
    """The sets' digests as found now, and whether they are those the version names.

    Compared with :data:`~handsim.cli.benchmark_sets.DIGESTS` for a recorded version, else with
    the digests ``make`` wrote into the folder; ``None`` where neither has them (a folder made
    before digests were recorded).
    """
    found = {name: set_digest(bench / str(info["folder"])) for name, info in record["sets"].items()}
    expected = DIGESTS.get(record["version"]) or {
        name: info.get("digest") for name, info in record["sets"].items()
    }
    if any(expected.get(name) is None for name in found):
        return found, None
    return found, all(found[name] == expected[name] for name in found)


def run_benchmark(
    bench: str | Path,
    make_estimator: Any,
    naming: dict[str, Any],
    out: str | Path,
    *,
    episodes: int = 20,
    quiet: bool = True,
) -> dict[str, Any]:
    """Run one estimator on the benchmark; write the JSON, the table and the plots.

    Args:
        bench: a folder of ``handsim benchmark make``.
        make_estimator: builds a fresh estimator (offline part, and each closed-loop mode).
        naming: how the report names the estimator (``name`` at least).
        out: output folder.
        episodes: closed-loop seeds (0: offline part only).
        quiet: no progress bars.

    Returns:
        The result (also ``out/benchmark.json``).

    Raises:
        BenchmarkError: for a folder that is not a benchmark or misses a set.
    """
    from handsim.envs.closed_loop import to_strict_json
    from handsim.estimator import describe_estimator

    bench, out = Path(bench), Path(out)
    record = read_benchmark(bench)
    out.mkdir(parents=True, exist_ok=True)
    offline = _offline(bench, record["sets"], make_estimator, quiet)
    digests, match = _digests(bench, record)
    loop = _closed_loop(make_estimator, episodes, out, quiet) if episodes else None
    result = {
        "benchmark": record["version"],
        "bench_folder": str(bench),
        "set_digests": digests,
        "set_digests_match": match,
        "estimator": {**naming, "describe": describe_estimator(make_estimator())[0]},
        "offline": offline,
        "closed_loop": loop,
    }
    result = to_strict_json(result)
    (out / "benchmark.json").write_text(json.dumps(result, indent=2, allow_nan=False) + "\n")
    (out / "table.md").write_text(_table(result))
    _plots(result, out)
    return result


def compare_runs(runs: list[str | Path], out: str | Path) -> str:
    """One table of several ``run`` results, and closed-loop success against offline error.

    Args:
        runs: ``run`` output folders (or their ``benchmark.json``), all of one version.
        out: output folder for ``compare.md`` and ``success_vs_error.png``.

    Returns:
        The table (Markdown).

    Raises:
        BenchmarkError: for a folder without a result, or results of different versions.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = []
    for run in runs:
        path = Path(run)
        path = path / "benchmark.json" if path.is_dir() else path
        try:
            result = json.loads(path.read_text())
            result["offline"]["sets"]
        except (OSError, json.JSONDecodeError, KeyError, TypeError):
            raise BenchmarkError(
                f"{run} holds no result of `handsim benchmark run` (benchmark.json)"
            ) from None
        results.append(result)
    versions = sorted({r["benchmark"] for r in results})
    if len(versions) != 1:
        raise BenchmarkError(
            f"results of one benchmark version compare; received {', '.join(versions)}"
        )
    _check_same_sets(runs, results)
    sets = list(results[0]["offline"]["sets"])
    head = ["estimator", *sets, "all", "AUC", "centre mm", "loop success (on/off)"]
    lines = [
        f"{versions[0]}: mean keypoint error, mm (centre error where there are no keypoints)",
        "",
        "| " + " | ".join(head) + " |",
        "|---|" + "---:|" * (len(head) - 1),
    ]
    points = []
    for r in results:
        name = _name(r["estimator"])
        off = r["offline"]
        cells = [_cell(off["sets"][k]) for k in sets] + [_cell(off["all"])]
        loop = r.get("closed_loop")
        success = "n/a"
        if loop is not None:
            on, no = loop["success_rate_feedback_on"], loop["success_rate_feedback_off"]
            success = f"{100 * on:.0f} / {100 * no:.0f} % ({loop['episodes']})"
            error = off["all"]["mean_mm"] or off["all"]["center_mm"]
            if error is not None:
                points.append((name, error, 100 * on, off["all"]["mean_mm"] is None))
        lines.append(
            f"| {name} | "
            + " | ".join(cells)
            + f" | {_fmt(off['all']['auc_f_tau'], 3)} | {_fmt(off['all']['center_mm'])} | "
            + f"{success} |"
        )
    table = "\n".join(lines) + "\n"
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "compare.md").write_text(table)
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, error, success, centre_only in points:
        ax.scatter(error, success, marker="s" if centre_only else "o")
        ax.annotate(name, (error, success), fontsize=7, xytext=(4, 4), textcoords="offset points")
    ax.set(
        xlabel="offline mean keypoint error / mm (squares: centre error, no keypoints)",
        ylabel=f"{CLOSED_LOOP_ENV} success, feedback on / %",
        ylim=(-5, 105),
    )
    ax.set_title(versions[0], fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "success_vs_error.png", dpi=100)
    plt.close(fig)
    return table


def _check_same_sets(runs: list[str | Path], results: list[dict[str, Any]]) -> None:
    """Refuse results measured on different sets (results from before digests pass)."""
    with_digests = [
        (run, r["set_digests"])
        for run, r in zip(runs, results, strict=True)
        if r.get("set_digests")
    ]
    if not with_digests:
        return
    first_run, first = with_digests[0]
    for run, digests in with_digests[1:]:
        differ = sorted(k for k in set(first) | set(digests) if first.get(k) != digests.get(k))
        if differ:
            raise BenchmarkError(
                f"{first_run} and {run} were measured on different sets (content digests "
                f"differ for {', '.join(differ)}): their figures do not compare; run both "
                "estimators on one made benchmark"
            )


def _name(estimator: dict[str, Any]) -> str:
    name = str(estimator.get("spec", estimator.get("name", "?")))
    if "noise_mm" in estimator:
        name += f" {estimator['noise_mm']:g} mm"
    return name


def _cell(stats: dict[str, Any]) -> str:
    if stats["mean_mm"] is not None:
        return _fmt(stats["mean_mm"])
    return "n/a" if stats["center_mm"] is None else f"({_fmt(stats['center_mm'])})"


# Command line ----------------------------------------------------------------------------------


def _make(args: argparse.Namespace) -> int:
    env = recorded_blas_environment()
    if env is not None:  # the kernels are chosen when NumPy loads: generate in a new process
        import subprocess
        import sys

        again = ["--out", str(args.out), *(["-q"] if args.quiet else [])]
        if args.frames_per_set is not None:
            again += ["--frames-per-set", str(args.frames_per_set)]
        command = [sys.executable, "-m", "handsim.cli", "benchmark", "make", *again]
        return subprocess.run(command, env=env, check=False).returncode
    start = time.perf_counter()
    n = args.frames_per_set
    total = sum(s.frames for s in SETS) if n is None else n * len(SETS)
    with progress_bar(total, "benchmark make", "frame", enabled=not args.quiet) as bar:
        record = make_benchmark(args.out, frames_per_set=args.frames_per_set, progress=bar.update)
    frames = sum(s["frames"] for s in record["sets"].values())
    print(
        strict_json(
            {
                "version": record["version"],
                "out": str(args.out),
                "frames": frames,
                "sets": {k: v["frames"] for k, v in record["sets"].items()},
                "digests": {k: v["digest"] for k, v in record["sets"].items()},
                "seconds": round(time.perf_counter() - start, 1),
            }
        )
    )
    return 0


def _estimator_arg(text: str) -> Any:
    from handsim.cli.closed_loop import estimator_arg

    if text == "feedback":
        return _feedback_spec()
    return estimator_arg(text)


def _feedback_spec() -> Any:
    """The feedback estimator with its shipped updater, built once now to fail early."""
    from handsim.cli.estimators import EstimatorSpec
    from handsim.errors import HandSimError
    from handsim.estimators import FeedbackEstimator

    try:
        FeedbackEstimator().close()
    except HandSimError as err:
        raise argparse.ArgumentTypeError(f"feedback: {err}") from None
    return EstimatorSpec("feedback", FeedbackEstimator, {})


def _run(args: argparse.Namespace) -> int:
    from handsim.cli.closed_loop import _factory

    # The oracle's options as closed-loop has them (its factory is shared).
    args.object_noise_mm, args.object_noise_deg, args.seed = None, 0.0, 0
    make_estimator, naming = _factory(args)
    if args.estimator == "oracle":
        naming = {**naming, "noise_mm": args.noise_mm}
    elif isinstance(args.estimator, str) and args.estimator not in ("com",):
        naming = {**naming, "name": args.estimator}
    result = run_benchmark(
        args.bench, make_estimator, naming, args.out, episodes=args.episodes, quiet=args.quiet
    )
    print(_table(result), end="")
    print(f"written: {Path(args.out) / 'benchmark.json'}, table.md, f_tau.png, error_by_set.png")
    return 0


def _compare(args: argparse.Namespace) -> int:
    print(compare_runs(args.runs, args.out), end="")
    print(f"written: {Path(args.out) / 'compare.md'}, success_vs_error.png")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``handsim benchmark make``, ``run`` and ``compare``."""
    from handsim.cli.closed_loop import ESTIMATORS

    bench = sub.add_parser(
        "benchmark",
        help=f"{VERSION}: make the fixed test sets, run an estimator on them",
        description=f"handsim-bench: fixed, versioned test sets ({VERSION}) and one table for "
        "any estimator, offline and in the loop.",
    )
    actions = bench.add_subparsers(dest="action", metavar="ACTION", required=True)
    make = actions.add_parser(
        "make",
        help="build the test sets (a few minutes on one core)",
        description=f"Build the {VERSION} test sets from fixed seeds: "
        + "; ".join(f"{s.name} ({s.frames} frames: {s.what})" for s in SETS)
        + ". Both sides in every set. The same command gives bit-identical sets; rerunning it "
        "resumes a killed make; a folder holding another version is refused, and so is a set "
        "whose content digest differs from the one the version records (a generator change "
        f"needs a new version). It generates with OpenBLAS's {BLAS_KERNEL} kernels "
        "(OPENBLAS_CORETYPE, unless set), as the digests were recorded: the simulated grasps "
        "carry the last bits of NumPy's matrix products.",
    )
    make.add_argument("--out", required=True, type=Path, metavar="DIR", help="benchmark folder")
    # Tests build a tiny benchmark (its version name carries its size): not for users.
    make.add_argument(
        "--frames-per-set", type=integer(1, 100_000), default=None, help=argparse.SUPPRESS
    )
    add_quiet(make)
    make.set_defaults(func=_make)

    names = (*ESTIMATORS, "feedback")
    run = actions.add_parser(
        "run",
        help="run an estimator on the benchmark: table, JSON, plots, closed loop",
        description="Run an estimator on every frame of every set (mean and median keypoint "
        "error, AUC of F(tau), hand-centre error, per set, side, occlusion bucket and joint), "
        f"then {CLOSED_LOOP_ENV} with the estimator in the loop over --episodes seeds, "
        "feedback off and on. Writes OUT/benchmark.json (strict JSON, null where a figure "
        "does not exist), table.md, f_tau.png, error_by_set.png and closed_loop/.",
    )
    run.add_argument(
        "--estimator",
        required=True,
        type=_estimator_arg,
        metavar="NAME|CKPT|FILE.py:CLASS[:KWARGS]",
        help=f"one of {', '.join(names)}; a learned estimator's checkpoint (NAME.pt or a "
        "handsim train run folder); or a user estimator module:Class[:kwargs-json] (a module "
        "path or a .py file)",
    )
    run.add_argument("--bench", required=True, type=Path, metavar="DIR", help="benchmark folder")
    run.add_argument(
        "--out", default="handsim-benchmark", help="output folder (default: %(default)s)"
    )
    run.add_argument(
        "--episodes",
        type=integer(0, 10_000),
        default=20,
        help=f"closed-loop seeds of {CLOSED_LOOP_ENV} (0: offline only; default: %(default)s)",
    )
    run.add_argument(
        "--noise-mm",
        type=number(0, 1000),
        default=10.0,
        help="oracle noise per axis, mm (default: %(default)s)",
    )
    run.add_argument(
        "--dropout",
        type=probability,
        default=0.0,
        help="oracle dropout probability in [0, 1] (default: %(default)s)",
    )
    run.add_argument(
        "--latency-steps", type=integer(0, 1000), default=0, help="oracle latency (default: 0)"
    )
    add_quiet(run)
    run.set_defaults(func=_run)

    compare = actions.add_parser(
        "compare",
        help="one table of several runs, and closed-loop success against offline error",
        description="Read the benchmark.json of several `handsim benchmark run` folders (one "
        "benchmark version) and write OUT/compare.md (mean error per set, AUC, centre error, "
        "closed-loop success) and OUT/success_vs_error.png.",
    )
    compare.add_argument("runs", nargs="+", metavar="RUN", help="run output folders")
    compare.add_argument(
        "--out", default="handsim-benchmark-compare", help="output folder (default: %(default)s)"
    )
    add_quiet(compare, "accepted by every command; compare shows no progress bars")
    compare.set_defaults(func=_compare)
