"""Checkpoints: a torch state dict (``.pt``) next to a small JSON config (``.json``).

A checkpoint ``NAME.pt`` holds ``{"model": state_dict, ...}`` (training adds the optimizer,
the epoch and the best validation error) and is read with ``torch.load(weights_only=True)``:
only tensors and plain containers, never pickled code. ``NAME.json`` holds the network config
(:func:`~handsim.estimators.deepprior.models.build_model`) and the preprocessing (cube, crop
size). Shipped weights live in ``weights/`` of this package and are named by
:data:`SHIPPED` (``deepprior``, ``deepprior++``, ``localizer``).
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path
from typing import Any

from handsim.errors import HandSimError

__all__ = [
    "WEIGHTS_DIR",
    "SHIPPED",
    "InvalidCheckpoint",
    "resolve_checkpoint",
    "save_checkpoint",
    "load_checkpoint",
    "load_resume_state",
    "save_resume_state",
    "load_model",
    "built_from",
    "ship_weights",
]

WEIGHTS_DIR = Path(__file__).parent / "weights"
"""Folder of the shipped weights."""

SHIPPED = {
    "deepprior": "deepprior",
    "deepprior++": "deepprior_pp",
    "localizer": "localizer",
    "detector": "detector",
}
"""Shipped weights by name -> file stem in :data:`WEIGHTS_DIR`."""


class InvalidCheckpoint(HandSimError, ValueError):
    """A checkpoint name or path cannot be loaded; the message says what is valid."""


def resolve_checkpoint(name_or_path: str | os.PathLike[str]) -> Path:
    """The ``.pt`` path of a shipped name or of a checkpoint path (``.pt`` optional).

    Raises:
        InvalidCheckpoint: if neither a shipped name nor an existing ``.pt`` + ``.json`` pair.
    """
    text = str(name_or_path)
    if text in SHIPPED:
        path = WEIGHTS_DIR / f"{SHIPPED[text]}.pt"
        if not path.is_file():
            raise InvalidCheckpoint(
                f"no shipped weights {text!r} in this installation ({path.name} is missing); "
                f"train them with `handsim train {text} --data DIR --out RUN` and give RUN"
            )
        return path
    path = Path(text)
    if path.is_dir():
        path = path / "best.pt"
    if path.suffix != ".pt":
        path = path.with_suffix(".pt")
    if not path.is_file() or not path.with_suffix(".json").is_file():
        raise InvalidCheckpoint(
            f"checkpoint {text!r} not found: give a shipped name ({', '.join(SHIPPED)}), a "
            "training folder (its best.pt is used) or a NAME.pt with its NAME.json beside it"
        )
    return path


def save_checkpoint(path: str | os.PathLike[str], state: dict[str, Any], config: dict) -> None:
    """Write ``state`` to ``path`` (atomically) and ``config`` to the ``.json`` beside it."""
    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".pt.tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)
    tmp_json = path.with_suffix(".json.tmp")
    tmp_json.write_text(json.dumps(config, indent=2, sort_keys=True) + "\n")
    os.replace(tmp_json, path.with_suffix(".json"))


def load_checkpoint(name_or_path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict]:
    """``(state, config)`` of a checkpoint, read with ``weights_only=True``.

    Raises:
        InvalidCheckpoint: for a missing or unreadable checkpoint.
    """
    import torch

    path = resolve_checkpoint(name_or_path)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
        config = json.loads(path.with_suffix(".json").read_text())
    except Exception as err:  # torch and json raise many types; name the file
        raise InvalidCheckpoint(
            f"cannot read checkpoint {path}: {type(err).__name__}: {err}"
        ) from None
    if not isinstance(state, dict) or "model" not in state:
        raise InvalidCheckpoint(f"checkpoint {path} has no 'model' state dict")
    model = state["model"]
    if not isinstance(model, dict) or not all(
        isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in model.items()
    ):
        raise InvalidCheckpoint(
            f"checkpoint {path}: 'model' must map parameter names to tensors; received "
            f"{type(model).__name__}"
        )
    for key, value in model.items():
        if value.is_floating_point() and not bool(torch.isfinite(value).all()):
            raise InvalidCheckpoint(
                f"checkpoint {path} has non-finite weights (NaN or inf) in {key!r}: the run that "
                "wrote it diverged; use an earlier checkpoint or train again"
            )
    if not isinstance(config, dict) or not isinstance(config.get("model"), dict):
        raise InvalidCheckpoint(
            f"{path.with_suffix('.json')} must be a JSON object with a 'model' mapping (the "
            f"network's configuration); received {type(config).__name__}"
        )
    return state, config


_RESUME_KEYS = ("model", "optimizer", "epoch", "best_val_mm", "history", "elapsed_s", "torch_rng")


def save_resume_state(
    path: str | os.PathLike[str],
    model: Any,
    optimizer: Any,
    *,
    epoch: int,
    best_val_mm: float,
    history: list,
    elapsed_s: float,
    config: dict,
    extra: dict[str, Any] | None = None,
) -> None:
    """Write a run's ``last.pt``: what :func:`load_resume_state` reads (``extra``: more tensors)."""
    import torch

    state = {
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "epoch": epoch,
        "best_val_mm": best_val_mm,
        "history": json.dumps(history),
        "elapsed_s": elapsed_s,
        "torch_rng": torch.get_rng_state(),
        **(extra or {}),
    }
    save_checkpoint(path, state, config)


def load_resume_state(
    path: str | os.PathLike[str], model: Any, optimizer: Any, device: str = "cpu"
) -> dict[str, Any]:
    """Load a run folder's ``last.pt`` into ``model``, ``optimizer`` and torch's generator.

    Returns:
        The rest of the state, checked: ``epoch`` (epochs done), ``best_val_mm``, ``history``
        (a list) and ``elapsed_s``.

    Raises:
        InvalidCheckpoint: naming the file and what to do, for a file that is not a whole
            training state of this network (garbage, truncated, another run's, non-finite).
    """
    import torch

    path = Path(path)
    fix = f"delete {path} to train this run from its start (best.pt is kept), or give another --out"
    # torch.save writes a zip archive; torch's own error on other bytes suggests loading
    # without weights_only, which must not be followed for a file of unknown origin.
    if not zipfile.is_zipfile(path):
        raise InvalidCheckpoint(
            f"cannot resume from {path}: it is not a readable checkpoint (not the zip archive "
            f"torch.save writes: garbage or truncated); {fix}"
        )
    try:
        state = torch.load(path, map_location=device, weights_only=True)
    except Exception as err:  # torch raises many types on a damaged file; name the file
        raise InvalidCheckpoint(
            f"cannot resume from {path}: it is not a readable checkpoint "
            f"({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}); {fix}"
        ) from None
    missing = [k for k in _RESUME_KEYS if not isinstance(state, dict) or k not in state]
    if missing:
        raise InvalidCheckpoint(
            f"cannot resume from {path}: it lacks {', '.join(missing)} (a training state holds "
            f"{', '.join(_RESUME_KEYS)}); {fix}"
        )
    weights = state["model"]
    if isinstance(weights, dict) and any(
        isinstance(v, torch.Tensor) and v.is_floating_point() and not bool(v.isfinite().all())
        for v in weights.values()
    ):
        raise InvalidCheckpoint(
            f"cannot resume from {path}: its weights are not finite (NaN or inf; the run "
            f"diverged); {fix}"
        )
    try:
        model.load_state_dict(weights)
        optimizer.load_state_dict(state["optimizer"])
        rest = {
            "epoch": int(state["epoch"]),
            "best_val_mm": float(state["best_val_mm"]),
            "history": json.loads(str(state["history"])),
            "elapsed_s": float(state["elapsed_s"]),
        }
        if rest["epoch"] < 0 or not isinstance(rest["history"], list):
            raise ValueError("epoch must be >= 0 and history a JSON list")
        torch.set_rng_state(state["torch_rng"])
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        raise InvalidCheckpoint(
            f"cannot resume from {path}: it does not fit this run's network and optimizer "
            f"({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}); {fix}"
        ) from None
    return rest


def built_from(build: Any, state: dict, config: dict, name_or_path: str | os.PathLike[str]) -> Any:
    """``build(config["model"])`` with the checkpoint's float32 weights loaded.

    Raises:
        InvalidCheckpoint: if the network cannot be built or the weights do not fit it.
    """
    try:
        model = build(config["model"])
        model.load_state_dict(
            {k: v.float() if v.is_floating_point() else v for k, v in state["model"].items()}
        )
    except (HandSimError, KeyError, TypeError, ValueError, RuntimeError) as err:
        # Wrong keys or shapes (RuntimeError from torch), or a model config it cannot build.
        raise InvalidCheckpoint(
            f"checkpoint {name_or_path} does not fit its network: {type(err).__name__}: "
            f"{str(err).splitlines()[0]}"
        ) from None
    return model


def load_model(name_or_path: str | os.PathLike[str], device: str = "cpu") -> tuple[Any, dict]:
    """The network of a checkpoint in eval mode (float32, channels-last), and its config."""
    import torch

    from .models import build_model

    state, config = load_checkpoint(name_or_path)
    model = built_from(build_model, state, config, name_or_path)
    # Channels-last convolutions are ~1.5x faster at batch 1 on a CPU core (oneDNN).
    return model.to(device=device, memory_format=torch.channels_last).eval(), config


def ship_weights(checkpoint: str | os.PathLike[str], name: str, *, half: bool = False) -> Path:
    """Copy a checkpoint's model (only) into :data:`WEIGHTS_DIR` under a shipped name.

    Args:
        checkpoint: a checkpoint path or run folder (its ``best.pt``).
        name: one of :data:`SHIPPED`.
        half: store floating-point tensors as float16 (half the size; loaded as float32).

    Returns:
        The written ``.pt`` path (its ``.json`` is beside it).

    Raises:
        InvalidCheckpoint: for an unknown name or an unreadable checkpoint.
    """
    if name not in SHIPPED:
        raise InvalidCheckpoint(f"name must be one of {', '.join(SHIPPED)}; received {name!r}")
    state, config = load_checkpoint(checkpoint)
    model = {
        k: (v.half() if half and v.is_floating_point() else v).contiguous()
        for k, v in state["model"].items()
    }
    path = WEIGHTS_DIR / f"{SHIPPED[name]}.pt"
    save_checkpoint(path, {"model": model}, {**config, "source": Path(str(checkpoint)).name})
    return path
