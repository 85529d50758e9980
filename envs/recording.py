"""Expert rollouts recorded as a Minari dataset (Gymnasium's offline-data standard).

:func:`record_minari` runs an env with its scripted expert through Minari's
``DataCollector(record_infos=True)``, so the dataset holds the observations, actions, rewards,
terminations and truncations, and every ``info`` entry — the frame labels under
``infos["labels"]`` (:data:`~handsim.data.arrays.LABEL_SCHEMA`, one row per step including the
reset). Minari (``pip install handsim[minari]``) is imported only here.

Minari keeps datasets under ``MINARI_DATASETS_PATH`` (default ``~/.minari/datasets``); the
dataset is written under ``out_dir`` when one is given, so it loads with
``minari.load_dataset("handsim/grasp-expert-v0")`` once ``MINARI_DATASETS_PATH=OUT`` is set.
"""

from __future__ import annotations

import contextlib
import os
import re
import warnings
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym

from handsim._validate import integer
from handsim.errors import HandSimError

__all__ = ["MinariUnavailable", "default_dataset_id", "record_minari"]


class MinariUnavailable(HandSimError, ImportError):
    """Minari (with its ``create`` extra) is not installed."""


_DATASET_ID = re.compile(r"(?:[A-Za-z0-9_][A-Za-z0-9_-]*/)*[A-Za-z0-9_][A-Za-z0-9_-]*-v[0-9]+")
"""A Minari dataset id: an optional namespace, a name and a version; no path parts."""


def default_dataset_id(env_id: str) -> str:
    """``handsim/Grasp-v0`` -> ``handsim/grasp-expert-v0`` (Minari's ``namespace/name-vN``)."""
    match = re.fullmatch(r"handsim/([A-Za-z]+)-v(\d+)", env_id)
    if match is None:
        raise HandSimError(
            f"env_id must be a registered handsim id such as 'handsim/Grasp-v0'; received "
            f"{env_id!r}"
        )
    name = re.sub(r"(?<!^)(?=[A-Z])", "-", match.group(1)).lower()
    return f"handsim/{name}-expert-v{match.group(2)}"


@contextlib.contextmanager
def _datasets_path(out_dir: Path | None) -> Iterator[None]:
    if out_dir is None:
        yield
        return
    old = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(out_dir)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = old


def record_minari(
    env_id: str,
    *,
    episodes: int,
    dataset_id: str | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    seed: int = 0,
    env_kwargs: Mapping[str, Any] | None = None,
    max_episode_steps: int | None = None,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Record ``episodes`` expert rollouts of ``env_id`` as a Minari dataset.

    Episode ``i`` is reset with seed ``seed + i``; the expert is planned from the truth at
    reset and acts every step (its pose targets, cast to the action space's float32 and
    clipped into it). Labels are on whatever ``env_kwargs`` say.

    Args:
        env_id: a registered handsim id with an expert (``handsim/Grasp-v0``,
            ``handsim/GraspClutter-v0``, ``handsim/HandPose-v0``).
        episodes: number of episodes (>= 1).
        dataset_id: Minari id ``namespace/name-vN`` (default :func:`default_dataset_id`).
        out_dir: folder that holds the dataset (Minari's ``MINARI_DATASETS_PATH``); default
            Minari's own.
        seed: seed of the first episode.
        env_kwargs: keyword arguments of ``gym.make``.
        max_episode_steps: episode length limit (default: the registered one).
        progress: called with the number of env steps after each step.

    Returns:
        ``dataset_id``, ``path`` (the dataset folder), ``episodes``, ``steps`` and
        ``successes`` (episodes whose last ``info["is_success"]`` is True).

    Raises:
        MinariUnavailable: without ``minari[create]``.
        HandSimError: for a bad ``env_id``, ``episodes`` or an existing dataset id.
    """
    if dataset_id is not None and (
        not isinstance(dataset_id, str) or not _DATASET_ID.fullmatch(dataset_id)
    ):
        raise HandSimError(
            "dataset_id must be a Minari id 'namespace/name-vN' (letters, digits, '_' and '-', "
            f"e.g. 'handsim/grasp-expert-v0'); received {dataset_id!r}"
        )
    try:
        import minari
        from minari import DataCollector
        from minari.storage import get_dataset_path
    except ImportError as err:  # minari, or jax for its DataCollector
        raise MinariUnavailable(
            f"Minari export needs minari with its create extra ({err}); "
            "pip install 'handsim[minari]'"
        ) from None
    episodes = integer("episodes", episodes, HandSimError, lo=1)
    dataset_id = dataset_id or default_dataset_id(env_id)
    kwargs = dict(env_kwargs or {})
    if max_episode_steps is not None:
        kwargs["max_episode_steps"] = int(max_episode_steps)
    # Absolute: Minari joins the datasets path with paths it has already joined with it.
    out = None if out_dir is None else Path(out_dir).resolve()
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    with _datasets_path(out):
        if dataset_id in minari.list_local_datasets():
            raise HandSimError(
                f"a Minari dataset {dataset_id!r} already exists in "
                f"{get_dataset_path(dataset_id)}; choose another dataset_id or "
                "out_dir, or delete it with minari.delete_dataset"
            )
        env = DataCollector(gym.make(env_id, **kwargs), record_infos=True)
        steps = successes = 0
        for i in range(episodes):
            env.reset(seed=seed + i)
            expert = env.get_wrapper_attr("make_expert")()
            expert_state = env.get_wrapper_attr("expert_state")
            done, info = False, {}
            while not done:
                action = expert.action(expert_state())
                _, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                steps += 1
                if progress is not None:
                    progress(steps)
            successes += bool(info.get("is_success", False))
        with warnings.catch_warnings():
            # Minari asks for an e-mail, a code link and an eval env: none apply here.
            warnings.filterwarnings("ignore", r"`(author_email|code_permalink|eval_env)`")
            dataset = env.create_dataset(
                dataset_id=dataset_id,
                algorithm_name=f"handsim scripted expert of {env_id}",
                author="handsim",
                description=(
                    f"{episodes} scripted-expert rollouts of {env_id} (seeds {seed}.."
                    f"{seed + episodes - 1}); frame labels in infos['labels'] "
                    "(handsim.data.arrays.LABEL_SCHEMA)"
                ),
            )
        env.close()
        path = Path(get_dataset_path(dataset_id))
    return {
        "dataset_id": dataset_id,
        "path": str(path),
        "episodes": int(dataset.total_episodes),
        "steps": int(dataset.total_steps),
        "successes": successes,
    }
