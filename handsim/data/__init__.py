"""Data out of handsim: labels as arrays, generation, crash-safe shards and their manifest.

=======================  ==========================================================================
module                   holds
=======================  ==========================================================================
:mod:`.arrays`           :func:`frame_to_arrays`: a Frame's labels as fixed-shape arrays and back
:mod:`.shards`           shards: :class:`ShardWriter`, :class:`ShardReader`, :func:`check_shard`
:mod:`.manifest`         :class:`Manifest` (``manifest.json``) and :func:`check_dataset`
:mod:`.config`           :class:`GenerationConfig`, :data:`PRESETS`, the frame sources by name
:mod:`.kinematic`        :class:`KinematicSource`: posed hands among objects, no physics
:mod:`.generation`       :func:`generate`: seeded, resumable shards in worker processes or Ray
:mod:`.views`            how a hand alone is turned toward the camera, per viewpoint
:mod:`.stats`            palm angles, pose/view mixes, the constant-mean-pose error of a dataset
:mod:`.splits`           train / val / test by episode (val, test: 10 % of the frames each)
:mod:`.torch_dataset`    :class:`HandSimDataset`: a map-style torch dataset (torch imported lazily)
:mod:`.export`           :func:`export_hand_labels` (JSON lines + depth PNG), :func:`export_bop`
=======================  ==========================================================================

Nothing here imports the envs or torch.
"""

from typing import Any

from handsim.data.arrays import LABEL_SCHEMA, arrays_to_frame, frame_to_arrays
from handsim.data.generation import PRESETS, GenerationConfig, generate
from handsim.data.manifest import Manifest, check_dataset
from handsim.data.shards import ShardReader, ShardWriter, check_shard
from handsim.data.torch_dataset import HandSimDataset

__all__ = [
    "LABEL_SCHEMA",
    "arrays_to_frame",
    "frame_to_arrays",
    "PRESETS",
    "GenerationConfig",
    "generate",
    "Manifest",
    "check_dataset",
    "ShardReader",
    "ShardWriter",
    "check_shard",
    "HandSimDataset",
    "export_bop",
    "export_hand_labels",
]


# The exports load OpenCV and SciPy's rotations: imported on first use, not by every user of
# handsim.data (a generation worker, `handsim generate`).
_LAZY = {"export_bop": "handsim.data.export", "export_hand_labels": "handsim.data.export"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'handsim.data' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
