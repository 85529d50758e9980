"""``handsim info``: versions, the hand, and every name the program and the envs accept.

Lists the registered env ids, the objects, the camera presets, the sensor models, the
viewpoints and the built-in estimators, then the hand (size presets and joint limits).
``--json`` prints the same as strict JSON.
"""

from __future__ import annotations

import argparse
from typing import Any

from handsim.cli._args import add_quiet

__all__ = ["add_parser", "collect_info"]


def collect_info() -> dict[str, Any]:
    """Everything ``handsim info`` prints, as a JSON-ready dict."""
    import gymnasium
    import mujoco
    import numpy as np

    import handsim
    from handsim.cli.estimators import BUILTIN_ESTIMATORS
    from handsim.envs import ENV_IDS
    from handsim.envs.config import OBS_MODES, SENSORS, VIEWPOINTS
    from handsim.hand.blas import blas_kernels
    from handsim.hand.model import HAND_SIZES, Hand
    from handsim.hand.pose import JOINT_LIMITS_DEG, JOINT_NAMES
    from handsim.world.camera import CAMERA_PRESETS
    from handsim.world.registry import OBJECTS

    model = Hand().compile()
    return {
        "versions": {
            "handsim": handsim.__version__,
            "mujoco": mujoco.__version__,
            "gymnasium": gymnasium.__version__,
            "numpy": np.__version__,
            # The kernels NumPy's BLAS picked: results (and datasets) differ between kernels.
            "blas": blas_kernels(),
        },
        "envs": [
            {"id": env_id, "max_episode_steps": gymnasium.spec(env_id).max_episode_steps}
            for env_id in ENV_IDS
        ],
        "objects": [
            {
                "name": name,
                "alias": spec.alias,
                "ycbv_id": spec.ycbv_id,
                "extents_mm": [round(1000 * e, 1) for e in spec.extents_m],
                "mass_kg": spec.mass_kg,
            }
            for name, spec in OBJECTS.items()
        ],
        "cameras": [
            {"name": name, "width": c.width, "height": c.height, "fx": c.fx, "fy": c.fy}
            for name, c in CAMERA_PRESETS.items()
        ],
        "sensors": list(SENSORS),
        "viewpoints": list(VIEWPOINTS),
        "obs_modes": list(OBS_MODES),
        "estimators": [{"name": name, "is": what} for name, what in BUILTIN_ESTIMATORS.items()],
        "hand": {
            "nq": model.nq,
            "nv": model.nv,
            "nu": model.nu,
            "bodies": model.nbody - 1,
            "size_presets_m": dict(HAND_SIZES),
            "joint_limits_deg": {
                name: [float(lo), float(hi)]
                for name, (lo, hi) in zip(JOINT_NAMES, JOINT_LIMITS_DEG, strict=True)
            },
        },
    }


def _run(args: argparse.Namespace) -> int:
    info = collect_info()
    if args.json:
        from handsim.cli._args import strict_json

        print(strict_json(info))
        return 0
    v = info["versions"]
    print(
        f"handsim {v['handsim']}, MuJoCo {v['mujoco']}, Gymnasium {v['gymnasium']}, "
        f"NumPy {v['numpy']} (BLAS {v['blas']})"
    )
    print("envs (gymnasium.make ids; import handsim.envs first):")
    for env in info["envs"]:
        print(f"  {env['id']:<26} {env['max_episode_steps']} steps")
    print(f"objects ({len(info['objects'])}; also by alias):")
    for obj in info["objects"]:
        extents = " x ".join(f"{e:.0f}" for e in obj["extents_mm"])
        print(f"  {obj['name']:<26} {obj['alias']:<22} {extents} mm, {obj['mass_kg']:.3f} kg")
    print("cameras (presets):")
    for cam in info["cameras"]:
        print(f"  {cam['name']:<12} {cam['width']}x{cam['height']}, fx {cam['fx']:.2f}")
    print("sensors: " + ", ".join(info["sensors"]))
    print("viewpoints: " + ", ".join(info["viewpoints"]))
    print("obs modes: " + ", ".join(info["obs_modes"]))
    print("estimators (also module:Class[:kwargs-json] for your own):")
    for est in info["estimators"]:
        print(f"  {est['name']:<8} {est['is']}")
    hand = info["hand"]
    print(f"hand: nq={hand['nq']} nv={hand['nv']} nu={hand['nu']} bodies={hand['bodies']}")
    print(
        "size presets: "
        + ", ".join(f"{k}={v * 1000:.0f} mm" for k, v in hand["size_presets_m"].items())
    )
    print("joints (deg):")
    for name, (lo, hi) in hand["joint_limits_deg"].items():
        print(f"  {name:<16} {lo:7.1f} .. {hi:6.1f}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``handsim info`` to the program's subcommands."""
    info = sub.add_parser(
        "info",
        help="print versions, envs, objects, cameras, sensors, estimators and the hand",
        description="Print versions and every name handsim accepts: env ids, objects, camera "
        "presets, sensor models, viewpoints, observation modes, built-in estimators; then the "
        "hand's size presets and joint limits.",
    )
    info.add_argument("--json", action="store_true", help="print strict JSON instead of text")
    add_quiet(info, "accepted by every command; info shows no progress bars")
    info.set_defaults(func=_run)
