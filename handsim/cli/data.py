"""``handsim generate``, ``handsim dataset check|info`` and ``handsim export``: datasets.

- ``handsim generate --preset NAME | --config FILE [--frames N] [--workers N | --ray ADDRESS]
  [--seed S] [--backend opengl|warp [--device cpu|cuda] [--batch N]] --out DIR``: make (or
  resume) a dataset; the same command again resumes a killed run.
- ``handsim dataset check DIR``: name every truncated, corrupt or missing shard (exit 1 if any).
- ``handsim dataset info DIR [--plot]``: frames, shards, sizes, episodes redrawn by cause,
  occlusion histogram, and the distribution of hands and views
  (:func:`handsim.data.stats.dataset_stats`: palm angle to the camera, pose-source, viewpoint
  and side mix, contact rate, the constant-mean-pose error on ``nyu14``); with ``--plot`` a
  contact sheet of random frames and histogram PNGs.
- ``handsim export hand-labels|bop DIR OUT``: the formats other tools read.
- ``handsim export minari ENV_ID OUT [--episodes N]``: expert rollouts of an env recorded with
  Minari (observations, actions, rewards, labels in ``infos``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from handsim.cli._args import (
    add_quiet,
    choice_help,
    integer,
    output_folder,
    positive_int,
    progress_bar,
    seed,
    strict_json,
)

__all__ = ["add_parser", "EXPORTS"]

EXPORTS = ("hand-labels", "bop", "minari")
"""Export formats of ``handsim export``."""
# handsim.world.symmetry.SYMMETRY_MODALITIES, spelled out so that parsing imports no mesh code.
_SYMMETRIES = ("texture", "depth")


def _config(args: argparse.Namespace):
    from handsim.data.generation import PRESETS, GenerationConfig

    overrides = {"frames": args.frames, "seed": args.seed}
    if args.skin_detail is not None:
        overrides["skin_detail"] = args.skin_detail
    if args.config is not None:
        return GenerationConfig.from_file(args.config, **overrides)
    return GenerationConfig.from_mapping(PRESETS[args.preset], **overrides)


def _generate(args: argparse.Namespace) -> int:
    from handsim.data.generation import generate

    config = _config(args)
    bar = progress_bar(
        config.frames, f"generate {Path(args.out).name}", "frame", enabled=not args.quiet
    )
    last = [0]

    def progress(done: int, total: int) -> None:
        bar.update(done - last[0])
        last[0] = done

    try:
        manifest = generate(
            config,
            args.out,
            workers=args.workers,
            progress=progress,
            ray=args.ray,
            backend=args.backend,
            device=args.device,
            batch=args.batch,
        )
    finally:
        bar.close()
    hist = manifest.occlusion_histogram or {}
    print(
        strict_json(
            {
                "out": str(args.out),
                "frames": manifest.frames,
                "shards": len(manifest.shards),
                "redraws": manifest.redraws,
                "occlusion_histogram": hist,
            }
        )
    )
    return 0


def _check(args: argparse.Namespace) -> int:
    from handsim.data.manifest import check_dataset

    report = check_dataset(args.dir)
    print(strict_json(report))
    return 0 if report["ok"] else 1


def _info(args: argparse.Namespace) -> int:
    from handsim.data.manifest import Manifest
    from handsim.data.stats import dataset_stats

    manifest = Manifest.read(args.dir)
    folder = Path(args.dir)
    size = sum(s.bytes for s in manifest.shards.values())
    info = {
        "frames": manifest.frames,
        "shards": len(manifest.shards),
        "bytes": size,
        "bytes_per_frame": size / manifest.frames if manifest.frames else None,
        "image_shape": list(manifest.image_shape),
        "depth_scale_mm": manifest.depth_scale_mm,
        "config": manifest.config,
        "versions": manifest.versions,
        "git_commit": manifest.git_commit,
        "redraws": manifest.redraws,
        "occlusion_histogram": manifest.occlusion_histogram,
        # Hands and views: palm angles, mixes, contact rate, the constant-mean-pose error.
        "distribution": dataset_stats(folder),
    }
    if args.plot:
        info["plots"] = [str(p) for p in _plots(folder, manifest, args.seed)]
    print(strict_json(info))
    return 0


def _plots(folder: Path, manifest, seed: int) -> list[Path]:
    import cv2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from handsim.data.arrays import arrays_to_frame
    from handsim.data.shards import ShardReader
    from handsim.viz import draw_frame, frame_legend

    rng = np.random.default_rng(seed)
    records = sorted(manifest.shards.values(), key=lambda s: s.name)
    readers = [ShardReader(folder / r.name) for r in records]
    tiles = []
    for _ in range(12):
        reader = readers[int(rng.integers(len(readers)))]
        frame = arrays_to_frame(reader[int(rng.integers(len(reader)))])
        tiles.append(draw_frame(frame))
    rows = [np.hstack(tiles[i : i + 4]) for i in range(0, len(tiles), 4)]
    sheet = folder / "contact_sheet.png"
    cv2.imwrite(str(sheet), np.vstack([*rows, frame_legend(rows[0].shape[1])]))
    ratio = np.concatenate([np.nan_to_num(r.labels("hand_occlusion_ratio")) for r in readers])
    visible = np.concatenate([r.labels("visible").sum(axis=1) for r in readers])
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    axes[0].hist(ratio, bins=np.linspace(0, 1, 21), color="tab:red")
    axes[0].set(xlabel="hand occlusion ratio", ylabel="frames", title="occlusion")
    axes[1].hist(visible, bins=np.arange(23) - 0.5, color="tab:blue")
    axes[1].set(xlabel="visible keypoints (of 21)", ylabel="frames", title="visibility")
    fig.tight_layout()
    hist = folder / "histograms.png"
    fig.savefig(hist, dpi=100)
    plt.close(fig)
    for r in readers:
        r.close()
    return [sheet, hist]


def _export(args: argparse.Namespace) -> int:
    from handsim.data.export import export_bop, export_hand_labels

    if args.format == "minari":
        return _export_minari(args)
    if args.format == "hand-labels":
        summary = export_hand_labels(args.dir, args.out)
    else:
        summary = {
            "symmetry": args.symmetry,
            **export_bop(args.dir, args.out, symmetry=args.symmetry),
        }
    print(strict_json({"format": args.format, "out": str(args.out), **summary}))
    return 0


def _export_minari(args: argparse.Namespace) -> int:
    import gymnasium as gym

    import handsim.envs  # noqa: F401  (registers the ids)
    from handsim.envs.recording import record_minari

    env_id = str(args.dir)
    if env_id not in gym.registry or not env_id.startswith("handsim/"):
        ids = sorted(k for k in gym.registry if k.startswith("handsim/"))
        args.parser.error(
            f"export minari records expert rollouts of an env: SOURCE must be one of "
            f"{', '.join(ids)}; received {env_id!r}"
        )
    max_steps = gym.spec(env_id).max_episode_steps or 0
    bar = progress_bar(
        args.episodes * max_steps, f"minari {env_id}", "step", enabled=not args.quiet
    )
    last = [0]

    def progress(steps: int) -> None:
        bar.update(steps - last[0])
        last[0] = steps

    try:
        result = record_minari(
            env_id,
            episodes=args.episodes,
            dataset_id=args.dataset_id,
            out_dir=args.out,
            seed=args.seed,
            progress=progress,
        )
    finally:
        bar.close()
    print(strict_json({"format": "minari", "out": str(args.out), **result}))
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``handsim generate``, ``handsim dataset`` and ``handsim export``."""
    from handsim.data.config import BACKENDS, SKIN_DETAILS
    from handsim.data.generation import PRESETS

    presets = tuple(PRESETS)
    gen = sub.add_parser(
        "generate",
        help="generate (or resume) a dataset of labelled depth frames",
        description="Generate labelled depth frames into a dataset folder (HDF5 shards and "
        "manifest.json) with spawned worker processes. Rerunning the same command resumes a "
        "killed run: complete shards are kept and the missing ones are made identically.",
    )
    source = gen.add_mutually_exclusive_group(required=True)
    source.add_argument(
        "--preset", choices=presets, metavar="NAME", help=choice_help("a preset", presets)
    )
    source.add_argument("--config", type=Path, metavar="FILE", help="a JSON or YAML config file")
    gen.add_argument(
        "--frames", type=integer(1, 10**9), help="frames, up to 10**9 (overrides the config)"
    )
    gen.add_argument("--seed", type=seed, help="base seed (overrides the config)")
    gen.add_argument(
        "--workers", type=integer(1, 1024), default=1, help="worker processes (default: 1)"
    )
    gen.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run one Ray task per shard: 'local' (a local Ray instance) or the address of a "
        "running cluster ('auto', 'ray://HOST:10001'), instead of --workers; needs pip install "
        "'handsim[ray]'",
    )
    gen.add_argument(
        "--backend",
        choices=BACKENDS,
        help="renderer (overrides the config; default: opengl): 'warp' renders on MuJoCo Warp, "
        "--batch frames per launch for a hand alone (the kinematic and grasp sources; needs "
        "pip install 'handsim[gpu]')",
    )
    gen.add_argument(
        "--device", metavar="DEV", help="warp backend: 'cpu', 'cuda' or 'cuda:N' (default: Warp's)"
    )
    gen.add_argument(
        "--batch",
        type=integer(1, 65536),
        help="warp backend: frames per launch of a hand alone (default: 16)",
    )
    gen.add_argument(
        "--skin-detail",
        choices=SKIN_DETAILS,
        help="the hand skin's level of detail (overrides the config; default: auto, the coarse "
        "skin for small projected hands; full: always the full skin)",
    )
    gen.add_argument(
        "--out", type=output_folder, required=True, metavar="DIR", help="dataset folder"
    )
    add_quiet(gen)
    gen.set_defaults(func=_generate)

    data = sub.add_parser("dataset", help="check or summarize a dataset folder")
    data_sub = data.add_subparsers(dest="dataset_command", metavar="ACTION", required=True)
    check = data_sub.add_parser(
        "check", help="name truncated, corrupt or missing shards (exit 1 if any)"
    )
    check.add_argument("dir", type=Path, help="dataset folder")
    add_quiet(check, "accepted by every command; check shows no progress bars")
    check.set_defaults(func=_check)
    info = data_sub.add_parser(
        "info",
        help="frames, shards, sizes, occlusion histogram and the distribution of hands and views",
        description="Print a dataset's summary as JSON: frames, shards, sizes, config, the "
        "occlusion histogram, and under 'distribution' the palm angle to the camera, the "
        "pose-source, viewpoint and side mix, the contact rate and the constant-mean-pose error "
        "on the nyu14 joints (mm; NYU's test labels: 51.3, ICVL's: 22.5).",
    )
    info.add_argument("dir", type=Path, help="dataset folder")
    info.add_argument(
        "--plot",
        action="store_true",
        help="write contact_sheet.png (12 random frames) and histograms.png into the folder",
    )
    info.add_argument("--seed", type=seed, default=0, help="seed of the frame picks")
    add_quiet(info, "accepted by every command; info shows no progress bars")
    info.set_defaults(func=_info)

    export = sub.add_parser(
        "export",
        help="export a dataset to hand labels (JSON lines + PNG) or BOP, or record Minari",
        description="Export a dataset folder into a new folder in a format other tools read "
        "(hand-labels, bop), or record expert rollouts of an env as a Minari dataset (minari: "
        "SOURCE is an env id such as handsim/Grasp-v0; load it with "
        "MINARI_DATASETS_PATH=OUT and minari.load_dataset(ID)).",
    )
    export.add_argument(
        "format", choices=EXPORTS, metavar="FORMAT", help=choice_help("format", EXPORTS)
    )
    export.add_argument(
        "dir", metavar="SOURCE", help="dataset folder (hand-labels, bop) or env id (minari)"
    )
    export.add_argument("out", type=output_folder, help="output folder (new or empty)")
    export.add_argument(
        "--episodes", type=positive_int, default=10, help="minari: episodes to record (10)"
    )
    export.add_argument(
        "--dataset-id", default=None, help="minari: dataset id (default handsim/<env>-expert-v0)"
    )
    export.add_argument("--seed", type=seed, default=0, help="minari: seed of the first episode")
    add_quiet(export)
    export.add_argument(
        "--symmetry",
        choices=_SYMMETRIES,
        default="texture",
        help="bop: symmetries written to models_info.json: texture (what looks the same in "
        "colour, BOP's; default) or depth (the shape alone: also plain cans and boxes)",
    )
    export.set_defaults(func=_export, parser=export)
