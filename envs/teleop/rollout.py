"""Teleop rollouts on disk: a recorded episode for ``handsim view`` (compressed NPZ).

:func:`write_rollout` saves what :meth:`~handsim.envs.teleop.loop.TeleopLoop.run` recorded
(``TeleopConfig(record=True)``); :func:`read_rollout` reads it back. Both are also importable
from :mod:`handsim.envs.teleop.loop`.
"""

from __future__ import annotations

import json
import pathlib
from typing import TYPE_CHECKING, Any

import numpy as np

from handsim.envs.teleop.streams import InvalidStream

if TYPE_CHECKING:
    from handsim.envs.teleop.loop import TeleopEpisode, TeleopLoop

__all__ = ["ROLLOUT_VERSION", "write_rollout", "read_rollout"]

ROLLOUT_VERSION = 1


def write_rollout(
    path: str | pathlib.Path, episode: TeleopEpisode, loop: TeleopLoop
) -> pathlib.Path:
    """Save a recorded episode for ``handsim view`` (compressed NPZ).

    Keys: ``meta`` (JSON: version, env id, env kwargs, seed, control period, metrics, and
    ``events``: the interaction events as dicts of
    :class:`~handsim.envs.teleop.events.InteractionEvent`);
    ``qpos`` (T, nq), ``mocap_pos`` (T, nmocap, 3), ``mocap_quat`` (T, nmocap, 4): the task's
    state after each step; ``operator_world``, ``tracked_world``, ``physical_world`` (T, 21,
    3) metres, world frame; ``dropped``, ``success``, ``intent`` (grasp intent) (T,) bool;
    ``penetration_m`` (T,); and in
    camera mode ``depth_mm`` (T, H, W) uint16 capture depth in mm, ``truth_cam`` and
    ``estimate_cam`` (T, 21, 3) metres in the capture camera frame, ``K`` (3, 3) and
    ``T_cam_from_world`` (4, 4).

    Raises:
        InvalidTeleopConfig: if the episode was not recorded (``TeleopConfig(record=True)``).
    """
    from handsim.envs.teleop.loop import InvalidTeleopConfig

    if not episode.arrays:
        raise InvalidTeleopConfig(
            "the episode has no arrays: run it with TeleopConfig(record=True)"
        )
    from handsim.envs.closed_loop import to_strict_json

    p = pathlib.Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "version": ROLLOUT_VERSION,
        "env_id": loop.env_id,
        "env_kwargs": loop.env_kwargs,
        "seed": episode.metrics["seed"],
        "control_dt_s": episode.metrics["control_dt_s"],
        "metrics": episode.metrics,
        "events": [e.to_dict() for e in episode.events],
    }
    np.savez_compressed(p, meta=np.array(json.dumps(to_strict_json(meta))), **episode.arrays)
    return p


def read_rollout(path: str | pathlib.Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read a rollout of :func:`write_rollout`: ``(meta, arrays)``.

    Raises:
        InvalidStream: for a missing file or one that is not a handsim rollout.
    """
    p = pathlib.Path(path)
    if not p.is_file():
        raise InvalidStream(f"rollout {str(p)!r} does not exist")
    try:
        with np.load(p, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError) as err:
        raise InvalidStream(
            f"{p} is not a handsim rollout (written by 'handsim teleop replay --rollout'): {err}"
        ) from None
    if meta.get("version") != ROLLOUT_VERSION or "qpos" not in arrays:
        raise InvalidStream(
            f"{p}: rollout version {meta.get('version')!r} is not "
            f"{ROLLOUT_VERSION}, or it has no 'qpos'"
        )
    return meta, arrays
