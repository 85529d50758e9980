"""Checkpoints of the feedback networks: DeepPrior's format (``NAME.pt`` + ``NAME.json``).

The JSON's ``kind`` (``synthesizer`` or ``updater``) says which network it holds; weights are
read with ``torch.load(weights_only=True)``
(:func:`~handsim.estimators.deepprior.checkpoint.load_checkpoint`).
"""

from __future__ import annotations

import os
from typing import Any

from ..deepprior.checkpoint import InvalidCheckpoint, built_from, load_checkpoint

__all__ = ["load_feedback_model"]


def load_feedback_model(
    name_or_path: str | os.PathLike[str], kind: str, device: str = "cpu"
) -> tuple[Any, dict]:
    """The ``kind`` network of a checkpoint in eval mode (float32), and its config.

    Raises:
        InvalidCheckpoint: for an unreadable checkpoint, another kind of network, or weights
            that do not fit the network.
    """
    from .models import build_feedback_model

    state, config = load_checkpoint(name_or_path)
    if config.get("kind") != kind:
        raise InvalidCheckpoint(
            f"checkpoint {name_or_path} holds a {config.get('kind')!r} network; expected a "
            f"{kind} (train one with `handsim train {kind} --data DIR --out RUN`)"
        )
    model = built_from(build_feedback_model, state, config, name_or_path)
    return model.to(device).eval(), config
