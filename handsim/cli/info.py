"""``handsim info``: versions, hand presets and joint limits."""

from __future__ import annotations

import argparse

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    import mujoco

    import handsim
    from handsim.hand.model import HAND_SIZES, Hand
    from handsim.hand.pose import JOINT_LIMITS_DEG, JOINT_NAMES

    model = Hand().compile()
    print(f"handsim {handsim.__version__}, MuJoCo {mujoco.__version__}")
    print(f"hand: nq={model.nq} nv={model.nv} nu={model.nu} bodies={model.nbody - 1}")
    print("size presets: " + ", ".join(f"{k}={v * 1000:.0f} mm" for k, v in HAND_SIZES.items()))
    print("joints (deg):")
    for name, (lo, hi) in zip(JOINT_NAMES, JOINT_LIMITS_DEG, strict=True):
        print(f"  {name:<16} {lo:7.1f} .. {hi:6.1f}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``handsim info`` to the program's subcommands."""
    info = sub.add_parser("info", help="print versions, hand presets and joint limits")
    info.set_defaults(func=_run)
