"""Checkpoints of the feedback networks: DeepPrior's format (``NAME.pt`` + ``NAME.json``).

The JSON's ``kind`` (``synthesizer`` or ``updater``) says which network it holds; weights are
read with ``torch.load(weights_only=True)``
(:func:`~handsim.estimators.deepprior.checkpoint.load_checkpoint`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..deepprior.checkpoint import InvalidCheckpoint, built_from, load_checkpoint, save_checkpoint

__all__ = ["SHIPPED_UPDATER", "load_feedback_model", "ship_updater"]

SHIPPED_UPDATER = Path(__file__).resolve().parent / "weights" / "updater.pt"
"""The shipped updater (float16), loaded by the name ``"feedback"``."""


def _resolve(name_or_path: str | os.PathLike[str]) -> str | os.PathLike[str]:
    if str(name_or_path) != "feedback":
        return name_or_path
    if not SHIPPED_UPDATER.is_file():
        raise InvalidCheckpoint(
            f"no shipped updater in this installation ({SHIPPED_UPDATER.name} is missing); "
            "train one with `handsim train updater --data DIR --out RUN` and give RUN"
        )
    return SHIPPED_UPDATER


def ship_updater(checkpoint: str | os.PathLike[str]) -> Path:
    """Copy an updater checkpoint's model, as float16, to :data:`SHIPPED_UPDATER`.

    Raises:
        InvalidCheckpoint: for an unreadable checkpoint or one that holds no updater.
    """
    state, config = load_checkpoint(checkpoint)
    if config.get("kind") != "updater":
        raise InvalidCheckpoint(f"checkpoint {checkpoint} holds no updater")
    model = {
        k: (v.half() if v.is_floating_point() else v).contiguous()
        for k, v in state["model"].items()
    }
    source = Path(str(checkpoint)).name
    save_checkpoint(SHIPPED_UPDATER, {"model": model}, {**config, "source": source})
    return SHIPPED_UPDATER


def load_feedback_model(
    name_or_path: str | os.PathLike[str], kind: str, device: str = "cpu"
) -> tuple[Any, dict]:
    """The ``kind`` network of a checkpoint in eval mode (float32), and its config.

    Raises:
        InvalidCheckpoint: for an unreadable checkpoint, another kind of network, or weights
            that do not fit the network.
    """
    from .models import build_feedback_model

    state, config = load_checkpoint(_resolve(name_or_path) if kind == "updater" else name_or_path)
    if config.get("kind") != kind:
        raise InvalidCheckpoint(
            f"checkpoint {name_or_path} holds a {config.get('kind')!r} network; expected a "
            f"{kind} (train one with `handsim train {kind} --data DIR --out RUN`)"
        )
    model = built_from(build_feedback_model, state, config, name_or_path)
    return model.to(device).eval(), config
