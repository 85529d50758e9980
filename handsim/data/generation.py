"""Dataset generation: seeded, sharded, resumable, in parallel worker processes.

:func:`generate` writes labelled depth frames into a dataset folder: ``shard-NNNNN.h5`` files
(:mod:`handsim.data.shards`) and ``manifest.json`` (:mod:`handsim.data.manifest`). Frames come
from a *source*; the built-in ``"kinematic"`` source poses the hand without physics
(:class:`KinematicSource`): every episode draws a hand (size, side), objects on the table and a
pose source, and every frame of the episode a pose, a wrist placement near an object and a
camera viewpoint around the hand. Frames where the hand enters an object or the table by more
than :data:`MAX_PENETRATION_M` are redrawn. The ``"rollout"`` source
(:mod:`handsim.envs.rollouts`, found by name in :data:`SOURCES`) labels env episodes driven by
their experts, with physical contact.

Reproducibility: shard ``i`` is made from ``numpy.random.default_rng([seed, i])`` alone, so a
shard is the same whichever worker makes it and whenever; a rerun of the same command skips
the complete shards listed in the manifest, deletes partial files and writes the missing
shards identically. A run killed at any moment (even SIGKILL) loses only shards in progress.
Shards are made in this process, in spawned worker processes (``workers``) or as Ray tasks
(``ray``), one shard per task, with the same result.

Occlusion control: ``occlusion_range`` keeps frames whose hand occlusion ratio lies in the
range; ``occlusion_buckets`` fills buckets of the ratio to fractions of every shard. Both
redraw a frame until it is accepted (at most :data:`MAX_TRIES_PER_FRAME` draws).
"""

from __future__ import annotations

import atexit
import collections
import contextlib
import dataclasses
import importlib
import json
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Protocol

import mujoco
import numpy as np

from handsim.data import _kernels
from handsim.data.arrays import frame_to_arrays
from handsim.data.manifest import InvalidManifest, Manifest
from handsim.data.shards import (
    DEFAULT_DEPTH_SCALE_MM,
    PARTIAL_SUFFIX,
    ShardInfo,
    ShardWriter,
    check_shard,
)
from handsim.errors import HandSimError
from handsim.frame import FrameRenderer
from handsim.hand.model import hand_params
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import (
    GESTURES,
    gesture,
    sample_grasp,
    sample_synergy,
    sample_uniform,
)
from handsim.world.camera import (
    CAMERA_PRESETS,
    CameraIntrinsics,
    camera_preset,
    look_at_quat_wxyz,
)
from handsim.world.registry import OBJECT_NAMES, OBJECTS
from handsim.world.render import shared_render_context
from handsim.world.scene import (
    CameraSpec,
    Scene,
    SceneSpec,
    sample_placements,
)
from handsim.world.sensors import sensor_model

__all__ = [
    "POSE_SOURCES",
    "VIEWPOINTS",
    "SENSORS",
    "PRESETS",
    "MAX_PENETRATION_M",
    "MAX_TRIES_PER_FRAME",
    "MAX_EMPTY_EPISODES",
    "MAX_EMPTY_EPISODES_STARTED",
    "MIN_KEYPOINTS_IN_FRAME",
    "SOURCES",
    "FrameSource",
    "register_source",
    "make_source",
    "InvalidGenerationConfig",
    "GenerationError",
    "GenerationConfig",
    "KinematicSource",
    "generate",
    "generate_shard",
    "RAY_MAX_RETRIES",
]

POSE_SOURCES = ("gesture", "grasp", "synergy", "uniform")
"""Pose sources of the kinematic source (:mod:`handsim.hand.pose_sources`)."""
VIEWPOINTS = ("third_person", "egocentric", "random", "through_object")
"""Camera placements: across the table, head-mounted, a random sphere around the hand, or
behind an object looking at the hand (the object is between camera and hand)."""
SENSORS = ("none", "structured_light", "tof")
"""Depth sensor models."""
MAX_PENETRATION_M = 0.004
"""Deepest hand-object or hand-table overlap a kinematic frame may have, metres."""
MAX_TRIES_PER_FRAME = 200
"""Draws per frame before an episode ends early (its scene cannot give an accepted frame)."""
KEPT_SCENES = 2
"""Scenes a kinematic source keeps between episodes (a right and a left hand alone)."""
MIN_KEYPOINTS_IN_FRAME = 15
"""Fewest of the 21 keypoints inside the image for a frame to be kept."""
_PALM_OFFSET_M = 0.07
"""The palm centre lies about this far along the hand's +y (distal) from the wrist."""
_MIN_EYE_HEIGHT_M = 0.03
"""Cameras stay this far above the table top (world z = 0), metres."""
MAX_EMPTY_EPISODES = 5
"""Episodes in a row without an accepted frame, before a shard's first frame, after which
generation stops with a clear error (the config cannot give a frame)."""
MAX_EMPTY_EPISODES_STARTED = 50
"""The same once the shard has frames: the occlusion buckets left may only be rare (3 % of the
``occlusion-heavy`` draws fall in its least occluded bucket), not out of reach."""


class InvalidGenerationConfig(HandSimError, ValueError):
    """A generation config field is invalid; the message names the field and what is valid."""


class GenerationError(HandSimError, RuntimeError):
    """Generation cannot go on (e.g. an occlusion range no frame reaches)."""


SOURCES: dict[str, str] = {
    "kinematic": "handsim.data.generation:KinematicSource",
    "rollout": "handsim.envs.rollouts:RolloutSource",
}
"""Frame sources by name -> ``"module:class"`` of a :class:`FrameSource`, imported when used
(so the core does not import the envs; spawned and Ray workers import the module by name).
Add one with :func:`register_source`."""


class FrameSource(Protocol):
    """What :func:`generate_shard` needs of a frame source.

    A source is made per shard from the config (``cls(config)``) and closed after it.
    """

    intrinsics: CameraIntrinsics

    @classmethod
    def check_config(cls, config: GenerationConfig) -> None:
        """Raise :class:`InvalidGenerationConfig` for a field this source cannot honour."""

    def episode(
        self, rng: np.random.Generator, accept: Callable[[float], bool], frames: int
    ) -> Iterator[dict[str, np.ndarray]]:
        """Yield the arrays (images included) of up to ``frames`` accepted frames."""

    def close(self) -> None:
        """Free what the source holds (renderers, envs)."""


def register_source(name: str, spec: str) -> None:
    """Register a frame source under ``name`` as ``"module:class"`` (imported when used).

    Register it in every process that generates (e.g. at import of the module that defines
    it); the built-in ones need no registration.

    Raises:
        InvalidGenerationConfig: for a spec not of the form ``"module:class"``.
    """
    if not isinstance(name, str) or not name or not isinstance(spec, str) or spec.count(":") != 1:
        raise InvalidGenerationConfig(
            f"register_source needs a name and a 'module:class' spec; received {name!r}, {spec!r}"
        )
    SOURCES[name] = spec


def _source_class(name: str) -> type:
    module, _, attr = SOURCES[name].partition(":")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as err:
        raise InvalidGenerationConfig(
            f"source {name!r} ({SOURCES[name]}) cannot be imported: {err}"
        ) from err


def make_source(config: GenerationConfig) -> FrameSource:
    """The frame source of a config (``config.source``), made for one shard."""
    return _source_class(config.source)(config)


def _pair(name: str, value: object, lo: float, hi: float, integer: bool = False) -> tuple:
    kind = "integers" if integer else "numbers"
    ok = (
        isinstance(value, (tuple, list))
        and len(value) == 2
        and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
            for v in value
        )
        and (not integer or all(float(v).is_integer() for v in value))
        and lo <= value[0] <= value[1] <= hi
    )
    if not ok:
        raise InvalidGenerationConfig(
            f"{name} must be a pair of {kind} (low, high) with {lo} <= low <= high <= {hi}; "
            f"received {value!r}"
        )
    return (int(value[0]), int(value[1])) if integer else (float(value[0]), float(value[1]))


def _int(name: str, value: object, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise InvalidGenerationConfig(
            f"{name} must be an integer in [{lo}, {hi}]; received {value!r}"
        )
    return int(value)


def _choice(name: str, value: object, valid: Sequence[str]) -> str:
    if value not in valid:
        raise InvalidGenerationConfig(
            f"{name} must be one of {', '.join(valid)}; received {value!r}"
        )
    return str(value)


@dataclasses.dataclass(frozen=True)
class GenerationConfig:
    """What to generate. Every field is validated on construction (errors name the field).

    Attributes:
        frames: total frames of the dataset.
        frames_per_shard: frames per shard (the unit of work, resume and checksums).
        frames_per_episode: frames drawn per episode (one hand and one object set).
        seed: base seed; shard ``i`` uses ``default_rng([seed, i])``.
        camera: camera preset (intrinsics), e.g. ``"icvl"`` (320 x 240).
        viewpoints: camera placements drawn per frame (:data:`VIEWPOINTS`).
        distance_range_m: camera distance from the hand, metres (random and through-object);
            the camera moves back along its line of sight when the hand or an object would be
            nearer than the camera's or the sensor's working range (a hole in the depth).
        sensor: depth sensor model (:data:`SENSORS`).
        paired_clean: also store the noise-free depth of every frame.
        hand_length_range_m: hand length drawn per episode, metres (0.140 to 0.235).
        left_fraction: fraction of left hands.
        objects: object names drawn from (canonical or short names).
        num_objects_range: objects per episode (0 for hand-only data).
        pose_sources: pose sources drawn per episode (:data:`POSE_SOURCES`).
        occlusion_range: keep frames whose hand occlusion ratio lies in this range.
        occlusion_buckets: ``(edges, fractions)``: bucket edges of the occlusion ratio and the
            fraction of every shard each bucket must fill (``None``: no stratification).
        depth_scale_mm: stored depth unit, millimetres.
        source: where frames come from (:data:`SOURCES`): ``"kinematic"`` (posed hands, no
            physics) or ``"rollout"`` (an env driven by its expert, with physical contact).
        env_id: the env of the rollout source (``handsim/Grasp-v0``,
            ``handsim/GraspClutter-v0`` or ``handsim/HandPose-v0``); ``None`` otherwise.
        frame_stride: rollout source: env steps between kept frames (1 = every step).
    """

    frames: int = 1000
    frames_per_shard: int = 250
    frames_per_episode: int = 25
    seed: int = 0
    camera: str = "icvl"
    viewpoints: tuple[str, ...] = ("third_person", "egocentric", "random")
    distance_range_m: tuple[float, float] = (0.35, 0.7)
    sensor: str = "structured_light"
    paired_clean: bool = False
    hand_length_range_m: tuple[float, float] = (0.150, 0.220)
    left_fraction: float = 0.5
    objects: tuple[str, ...] = OBJECT_NAMES
    num_objects_range: tuple[int, int] = (1, 3)
    pose_sources: tuple[str, ...] = POSE_SOURCES
    occlusion_range: tuple[float, float] = (0.0, 1.0)
    occlusion_buckets: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    depth_scale_mm: float = DEFAULT_DEPTH_SCALE_MM
    source: str = "kinematic"
    env_id: str | None = None
    frame_stride: int = 1

    def __post_init__(self) -> None:
        _choice("source", self.source, tuple(SOURCES))
        _int("frame_stride", self.frame_stride, 1, 10_000)
        if (
            isinstance(self.depth_scale_mm, bool)
            or not isinstance(self.depth_scale_mm, (int, float))
            or not 0.001 <= self.depth_scale_mm <= 10.0
        ):
            raise InvalidGenerationConfig(
                f"depth_scale_mm must be a number in [0.001, 10]; received {self.depth_scale_mm!r}"
            )
        if self.env_id is not None and not isinstance(self.env_id, str):
            raise InvalidGenerationConfig(
                f"env_id must be an env id such as 'handsim/Grasp-v0'; received {self.env_id!r}"
            )
        _int("frames", self.frames, 1, 10**9)
        _int("frames_per_shard", self.frames_per_shard, 1, 100_000)
        _int("frames_per_episode", self.frames_per_episode, 1, 10_000)
        _int("seed", self.seed, 0, 2**63 - 1)
        _choice("camera", self.camera, tuple(CAMERA_PRESETS))
        self._tuple_of("viewpoints", VIEWPOINTS)
        _pair("distance_range_m", self.distance_range_m, 0.15, 3.0)
        _choice("sensor", self.sensor, SENSORS)
        if not isinstance(self.paired_clean, bool):
            raise InvalidGenerationConfig(
                f"paired_clean must be true or false; received {self.paired_clean!r}"
            )
        _pair("hand_length_range_m", self.hand_length_range_m, 0.140, 0.235)
        _pair("left_fraction", (self.left_fraction, self.left_fraction), 0.0, 1.0)
        if isinstance(self.objects, str) or not isinstance(self.objects, (tuple, list)):
            raise InvalidGenerationConfig(
                f"objects must be a list of object names; received {self.objects!r}"
            )
        for name in self.objects:
            if name not in OBJECTS:
                raise InvalidGenerationConfig(
                    f"objects: unknown object {name!r}; valid: {', '.join(OBJECT_NAMES)}"
                )
        lo, hi = _pair("num_objects_range", self.num_objects_range, 0, 6, integer=True)
        if hi > 0 and not self.objects:
            raise InvalidGenerationConfig("objects is empty but num_objects_range asks for some")
        self._tuple_of("pose_sources", POSE_SOURCES)
        _pair("occlusion_range", self.occlusion_range, 0.0, 1.0)
        if self.occlusion_buckets is not None:
            edges, fractions = self._buckets()
            if len(edges) != len(fractions) + 1 or len(fractions) < 1:
                raise InvalidGenerationConfig(
                    "occlusion_buckets must be (edges, fractions) with one more edge than "
                    f"fractions; received {self.occlusion_buckets!r}"
                )
            if not (np.all(np.diff(edges) > 0) and edges[0] >= 0 and edges[-1] <= 1):
                raise InvalidGenerationConfig(
                    f"occlusion_buckets edges must increase within [0, 1]; received {edges}"
                )
            if np.any(fractions < 0) or not np.isclose(fractions.sum(), 1.0):
                raise InvalidGenerationConfig(
                    f"occlusion_buckets fractions must be >= 0 and sum to 1; received {fractions}"
                )
        if self.source != "kinematic":
            # The source checks its own fields (e.g. the env id and the viewpoints it has).
            _source_class(self.source).check_config(self)
            return
        if self.env_id is not None or self.frame_stride != 1:
            raise InvalidGenerationConfig(
                "env_id and frame_stride are fields of the 'rollout' source; set source: rollout "
                f"or remove them (received env_id={self.env_id!r}, "
                f"frame_stride={self.frame_stride!r})"
            )
        if hi == 0 and (self.occlusion_range[0] > 0 or self.occlusion_buckets is not None):
            raise InvalidGenerationConfig(
                "frames without objects have a hand occlusion ratio of 0: occlusion_range and "
                "occlusion_buckets need num_objects_range above 0"
            )
        if "through_object" in self.viewpoints and hi == 0:
            raise InvalidGenerationConfig(
                "viewpoint 'through_object' needs objects: raise num_objects_range above 0"
            )

    def _tuple_of(self, name: str, valid: Sequence[str]) -> None:
        values = getattr(self, name)
        if isinstance(values, str) or not isinstance(values, (tuple, list)) or not values:
            raise InvalidGenerationConfig(
                f"{name} must be a non-empty list drawn from {', '.join(valid)}; "
                f"received {values!r}"
            )
        for v in values:
            _choice(name, v, valid)

    def _buckets(self) -> tuple[np.ndarray, np.ndarray]:
        try:
            edges, fractions = self.occlusion_buckets  # type: ignore[misc]
            return np.asarray(edges, dtype=float), np.asarray(fractions, dtype=float)
        except (TypeError, ValueError) as err:
            raise InvalidGenerationConfig(
                f"occlusion_buckets must be (edges, fractions); received {self.occlusion_buckets!r}"
            ) from err

    @property
    def num_shards(self) -> int:
        """Number of shards (the last one may be shorter)."""
        return -(-self.frames // self.frames_per_shard)

    def shard_frames(self, index: int) -> int:
        """Frames of shard ``index``."""
        return min(self.frames_per_shard, self.frames - index * self.frames_per_shard)

    def to_json(self) -> dict[str, Any]:
        """The config as JSON (lists for tuples)."""
        return json.loads(json.dumps(dataclasses.asdict(self)))

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], **overrides: Any) -> GenerationConfig:
        """A config from a mapping (a parsed JSON/YAML file), with keyword overrides.

        Raises:
            InvalidGenerationConfig: for an unknown field (the valid ones are listed) or a
                bad value.
        """
        if not isinstance(values, Mapping):
            raise InvalidGenerationConfig(
                f"a config must be a mapping of field -> value; received {type(values).__name__}"
            )
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - fields)
        if unknown:
            raise InvalidGenerationConfig(
                f"unknown config field(s) {', '.join(unknown)}; valid fields: "
                f"{', '.join(sorted(fields))}"
            )
        merged = {**values, **{k: v for k, v in overrides.items() if v is not None}}
        for key, value in merged.items():
            if isinstance(value, list):
                merged[key] = tuple(tuple(v) if isinstance(v, list) else v for v in value)
        return cls(**merged)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str], **overrides: Any) -> GenerationConfig:
        """A config from a JSON or YAML file (YAML needs PyYAML), with keyword overrides."""
        path = Path(path)
        if not path.is_file():
            raise InvalidGenerationConfig(f"config file {path} does not exist")
        text = path.read_text()
        if path.suffix in (".yaml", ".yml"):
            try:
                import yaml
            except ImportError as err:
                raise InvalidGenerationConfig(
                    "YAML configs need PyYAML (pip install pyyaml); or write the config as JSON"
                ) from err
            try:
                values = yaml.safe_load(text)
            except yaml.YAMLError as err:
                raise InvalidGenerationConfig(f"{path} is not valid YAML ({err})") from err
        else:
            try:
                values = json.loads(text)
            except json.JSONDecodeError as err:
                raise InvalidGenerationConfig(f"{path} is not valid JSON ({err})") from err
        return cls.from_mapping(values, **overrides)


PRESETS: dict[str, dict[str, Any]] = {
    "hand-only": {"num_objects_range": (0, 0), "viewpoints": ("third_person", "random")},
    "hand-object": {"num_objects_range": (1, 3)},
    "occlusion-heavy": {
        "num_objects_range": (2, 4),
        "viewpoints": ("through_object",),
        "distance_range_m": (0.4, 0.7),
        "occlusion_buckets": ((0.1, 0.3, 0.5, 0.7, 0.95), (0.25, 0.25, 0.25, 0.25)),
    },
    "grasp-rollouts": {
        "source": "rollout",
        "env_id": "handsim/Grasp-v0",
        "num_objects_range": (1, 1),
        "viewpoints": ("third_person", "egocentric", "random"),
        "frames_per_episode": 60,
        "frame_stride": 5,
    },
}
"""Named configs: hand alone, hand among objects, objects between camera and hand with the
occlusion ratio stratified in four buckets from 0.1 to 0.95 (kinematic), and Grasp-v0 rollouts
of the grasp expert, every fifth step (10 Hz) of the approach, grasp and lift (physical
contact)."""


class KinematicSource:
    """Frames of a kinematically posed hand among objects (no physics).

    Args:
        config: the generation config.
    """

    def __init__(self, config: GenerationConfig) -> None:
        self.config = config
        self.intrinsics = camera_preset(config.camera)
        self.sensor = sensor_model(config.sensor)
        # The nearest distance that gets depth: the camera's and the sensor's working range.
        self._near_m = max(
            self.intrinsics.range_m[0], float(getattr(self.sensor, "min_range_m", 0.0))
        )
        # A new scene's renderer takes over the OpenGL context of the one it replaces (its
        # meshes uploaded again): ~10 ms less than a new context.
        self._render_context = contextlib.ExitStack()
        self._render_context.enter_context(shared_render_context())
        # Scenes kept between episodes with their renderers, least recently used first: an
        # episode with the same side, objects and placements rescales the hand of a kept one
        # (about 1 ms) instead of building a scene (~50 ms, plus ~0.15 s for each new hand
        # length's skin).
        self._scenes: collections.OrderedDict[tuple, tuple[Scene, FrameRenderer]] = (
            collections.OrderedDict()
        )

    @classmethod
    def check_config(cls, config: GenerationConfig) -> None:
        """Every field is checked by :class:`GenerationConfig` itself."""

    def close(self) -> None:
        """Free the scenes, renderers and OpenGL context kept between episodes."""
        while self._scenes:
            self._scenes.popitem()[1][1].close()
        self._render_context.close()

    def _scene(self, rng: np.random.Generator) -> tuple[Scene, FrameRenderer]:
        """The episode's scene and renderer: a kept one when it has the same side and objects."""
        c = self.config
        length = float(rng.uniform(*c.hand_length_range_m))
        side = "left" if rng.random() < c.left_fraction else "right"
        n = int(rng.integers(c.num_objects_range[0], c.num_objects_range[1] + 1))
        names = [c.objects[i] for i in rng.choice(len(c.objects), size=n)] if n else []
        placements = sample_placements(rng, names) if names else ()
        key = (side, placements)
        kept = self._scenes.pop(key, None)
        if kept is None:
            while len(self._scenes) >= KEPT_SCENES:
                self._scenes.popitem(last=False)[1][1].close()
            camera = CameraSpec.look_at(
                "camera", self.intrinsics, (0.0, -0.6, 0.4), (0.0, 0.0, 0.1)
            )
            spec = SceneSpec(
                # Every hand is the medium one rescaled: its skin is built once per process.
                hand=hand_params("medium", side),
                objects=placements,
                cameras=(camera,),
                table=n > 0,
            )
            scene = Scene(spec)
            kept = (scene, FrameRenderer(scene, "camera", self.sensor))
        self._scenes[key] = kept
        kept[0].set_hand_length(length)
        return kept

    def _postures(self, rng: np.random.Generator, source: str, n: int) -> np.ndarray:
        """(n, 21) finger angles from the pose source ``source``, radians."""
        if source == "gesture":
            names = list(GESTURES)
            return np.stack(
                [gesture(str(rng.choice(names)), rng=rng, noise_deg=5.0).angles for _ in range(n)]
            )
        if source == "grasp":
            return sample_grasp(rng, n)[0].angles
        if source == "synergy":
            return sample_synergy(rng, n, num_synergies=3).angles
        return sample_uniform(rng, n).angles

    def _wrist(
        self, rng: np.random.Generator, scene: Scene, beside: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Wrist position, rotation vector, palm centre and the object it is near (world, m)."""
        if not scene.objects:
            # A uniform rotation: a normalized 4-D Gaussian quaternion.
            quat = rng.normal(size=4)
            quat /= np.linalg.norm(quat)
            R = np.empty(9)  # noqa: N806
            mujoco.mju_quat2Mat(R, quat)
            rotvec = np.empty(3)
            mujoco.mju_quat2Vel(rotvec, quat, 1.0)
            wrist = np.array([0.0, 0.0, 0.3])
            return wrist, rotvec, wrist + R.reshape(3, 3)[:, 1] * _PALM_OFFSET_M, None
        k = int(rng.integers(len(scene.objects)))
        body_name, obj = scene.objects[k]
        body = scene.model.body(body_name).id
        obj_pos = scene.data.xpos[body].copy()
        # The palm faces the object from a random side above the table.
        direction = rng.normal(size=3)
        # Beside the object (for a camera behind it) or from a random side above it.
        direction[2] = rng.uniform(0.0, 0.15) if beside else abs(direction[2]) + 0.3
        direction /= np.linalg.norm(direction)
        palm = obj_pos + direction * (0.5 * obj.diameter_m + rng.uniform(0.02, 0.07))
        palm[2] = max(palm[2], 0.05)
        # Hand +z (palmar) toward the object, random roll about it.
        z = obj_pos - palm
        z /= np.linalg.norm(z)
        x, y = np.empty(3), np.empty(3)
        mujoco.mju_cross(x, rng.normal(size=3), z)
        x /= np.linalg.norm(x)
        mujoco.mju_cross(y, z, x)
        R = np.column_stack([x, y, z])  # noqa: N806
        wrist = palm - R[:, 1] * _PALM_OFFSET_M
        rotvec = np.empty(3)
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, R.reshape(-1))
        mujoco.mju_quat2Vel(rotvec, quat, 1.0)
        return wrist, rotvec, palm, obj_pos

    def _camera(
        self, rng: np.random.Generator, view: str, target: np.ndarray, obj: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        c = self.config
        distance = rng.uniform(*c.distance_range_m)
        up = (0.0, 0.0, 1.0)
        if view == "third_person":
            direction = np.array([0.0, 1.0, 0.6])
        elif view == "egocentric":
            direction = np.array([0.0, -0.35, 0.45])
            up = (0.0, 1.0, 0.0)
        elif view == "through_object" and obj is not None:
            # Beyond the object as seen from the hand, turned a little so that the object hides
            # anything from a sliver to all of the hand; never below the table top.
            direction = (obj - target) / np.linalg.norm(obj - target)
            direction[:2] += rng.normal(scale=0.08, size=2)
            direction[2] += rng.uniform(0.0, 0.12)
        else:
            direction = rng.normal(size=3)
            direction[2] = abs(direction[2]) + 0.2
        direction /= np.linalg.norm(direction)
        eye = target + distance * direction
        eye[2] = max(eye[2], _MIN_EYE_HEIGHT_M)
        # What CameraSpec.look_at computes, without building (and validating) a spec per frame.
        return eye, look_at_quat_wxyz(eye, target, up)

    def _beyond_near(
        self, scene: Scene, geoms: np.ndarray, eye: np.ndarray, target: np.ndarray
    ) -> np.ndarray | None:
        """The eye moved back along its line of sight until the hand and objects are in range.

        Nothing nearer than the camera's or the sensor's working range gets depth (a
        structured-light sensor measures from 0.35 m): a hand or an occluder there would be a
        hole in the depth image. The bounding boxes of ``geoms`` (the hand's skin meshes and
        every geom of the objects) are kept beyond that range. None when the moved eye would
        be below the table top.
        """
        forward = target - eye
        forward /= np.linalg.norm(forward)
        model, data = scene.model, scene.data
        # The nearest corner of the geoms' bounding boxes (in their geom frames).
        nearest = _kernels.nearest_box_depth(
            model.geom_aabb[geoms], data.geom_xmat[geoms], data.geom_xpos[geoms], eye, forward
        )
        if nearest >= self._near_m:
            return eye
        eye = eye - forward * (self._near_m - nearest)
        return eye if eye[2] >= _MIN_EYE_HEIGHT_M else None

    @staticmethod
    def _near_geoms(scene: Scene) -> np.ndarray:
        """The geoms kept beyond the near range: the hand's skin and every object geom.

        (An object's half diameter around its body origin does not bound every object: the
        extra-large clamp reached 1.4 mm nearer than that.)
        """
        bodies = [scene.model.body(name).id for name, _ in scene.objects]
        objects = np.flatnonzero(np.isin(scene.model.geom_bodyid, bodies))
        return np.concatenate([scene.hand_skin_geom_ids, objects]).astype(np.intp)

    @staticmethod
    def _penetration_m(scene: Scene) -> float:
        """Deepest overlap of a hand geom with an object or the table, metres."""
        data, labels = scene.data, scene.geom_labels
        deepest = 0.0
        for i in range(data.ncon):
            con = data.contact[i]
            hand = [2 <= labels[g] < 8 for g in (con.geom1, con.geom2)]
            if hand[0] != hand[1]:
                deepest = max(deepest, -float(con.dist))
        return deepest

    def episode(
        self, rng: np.random.Generator, accept: Callable[[float], bool], frames: int
    ) -> Iterator[dict[str, np.ndarray]]:
        """Yield the arrays (images included) of ``frames`` accepted frames of one episode.

        Args:
            rng: the episode's generator.
            accept: called with the hand occlusion ratio; False redraws the frame.
            frames: frames to yield.

        Stops early when :data:`MAX_TRIES_PER_FRAME` draws give no accepted frame (the
        episode's hand and objects may not reach the occlusion asked for).
        """
        scene, renderer = self._scene(rng)
        source = str(rng.choice(self.config.pose_sources))
        cam = scene.model.camera("camera").id
        viewpoints = list(self.config.viewpoints)
        alone = not scene.objects and not scene.spec.table
        near_geoms = self._near_geoms(scene)
        # Postures are drawn a batch at a time (a sampler's cost is mostly per call), a few
        # more than the frames for the draws that are refused.
        batch = frames + 8
        postures, used = self._postures(rng, source, batch), 0
        for _ in range(frames):
            for _ in range(MAX_TRIES_PER_FRAME):
                if used == batch:
                    postures, used = self._postures(rng, source, batch), 0
                view = viewpoints[int(rng.integers(len(viewpoints)))]
                wrist, rotvec, palm, obj = self._wrist(rng, scene, view == "through_object")
                pose = HandPose(wrist, rotvec, postures[used])
                used += 1
                if alone:  # nothing to touch: no contacts to find or label
                    scene.binding.set_pose(scene.data, pose, kinematics_only=True)
                else:  # forwards: the hand placed, its contacts found
                    scene.binding.set_pose(scene.data, pose)
                    if self._penetration_m(scene) > MAX_PENETRATION_M:
                        continue
                eye, quat = self._camera(rng, view, palm, obj)
                eye = self._beyond_near(scene, near_geoms, eye, palm)
                if eye is None:
                    continue
                scene.model.cam_pos[cam], scene.model.cam_quat[cam] = eye, quat
                mujoco.mj_camlight(scene.model, scene.data)
                frame = renderer.render(
                    rng, keep_clean=self.config.paired_clean, hand_occlusion=bool(scene.objects)
                )
                ratio = frame.hand_occlusion_ratio or 0.0
                if frame.in_frame.sum() >= MIN_KEYPOINTS_IN_FRAME and accept(ratio):
                    arrays = frame_to_arrays(frame)
                    arrays["hand_occlusion_ratio"][()] = ratio
                    # The frame's own images, not copies: the writer only reads them, and
                    # before the next frame is rendered.
                    arrays["depth"], arrays["segmentation"] = frame.depth, frame.segmentation
                    if frame.depth_clean is not None:
                        arrays["depth_clean"] = frame.depth_clean
                    yield arrays
                    break
            else:
                return  # this scene cannot give an accepted frame: a new episode may


class _Acceptor:
    """Occlusion control of one shard: the range, and bucket quotas when stratified."""

    def __init__(self, config: GenerationConfig, frames: int) -> None:
        self.lo, self.hi = config.occlusion_range
        self.edges = None
        if config.occlusion_buckets is not None:
            edges, fractions = config._buckets()
            quotas = np.floor(fractions * frames).astype(int)
            quotas[np.argsort(-(fractions * frames - quotas))[: frames - quotas.sum()]] += 1
            self.edges, self.left = edges, quotas

    def describe_left(self) -> str:
        """``"; frames still wanted per bucket: [lo, hi) n, ..."``, or nothing without buckets."""
        if self.edges is None:
            return ""
        left = [
            f"[{lo:g}, {hi:g}) {n}"
            for lo, hi, n in zip(self.edges[:-1], self.edges[1:], self.left, strict=True)
            if n > 0
        ]
        return "; frames still wanted per bucket: " + ", ".join(left)

    def __call__(self, ratio: float) -> bool:
        if not self.lo <= ratio <= self.hi:
            return False
        if self.edges is None:
            return True
        k = int(np.searchsorted(self.edges, ratio, side="right")) - 1
        if ratio == self.edges[-1]:
            k = len(self.left) - 1
        if not 0 <= k < len(self.left) or self.left[k] <= 0:
            return False
        self.left[k] -= 1
        return True


_KEPT_SOURCE: dict[str, FrameSource] = {}
"""This process's kinematic source, by its config, kept from shard to shard (its scenes)."""
_kept_source_freed_at_exit = False


def close_kept_source() -> None:
    """Free the kinematic source (scenes, renderers) this process keeps between shards."""
    while _KEPT_SOURCE:
        _KEPT_SOURCE.popitem()[1].close()


@contextlib.contextmanager
def _shard_source(config: GenerationConfig) -> Iterator[FrameSource]:
    """The source of one shard: a kinematic source is kept for the next shard of its config.

    A kept source changes no frame: it rescales a kept hand from the geometry it was built
    with (bitwise the same whatever the lengths before), and keeps a scene with objects only
    for the same objects at the same placements.
    """
    global _kept_source_freed_at_exit
    key = json.dumps(config.to_json(), sort_keys=True)
    source = _KEPT_SOURCE.get(key)
    if source is None:
        source = make_source(config)
        if isinstance(source, KinematicSource):
            close_kept_source()
            _KEPT_SOURCE[key] = source
    try:
        yield source
    except BaseException:
        if _KEPT_SOURCE.get(key) is source:
            del _KEPT_SOURCE[key]  # an error may leave a scene half-changed: not kept
        raise
    finally:
        if _KEPT_SOURCE.get(key) is not source:
            source.close()
    if key in _KEPT_SOURCE and not _kept_source_freed_at_exit:
        # Free the renderers before teardown (a pool worker keeps its source to the end).
        # Registered once a shard has made its OpenGL context: exit handlers run last
        # registered first, so this runs before MuJoCo's EGL display is terminated.
        atexit.register(close_kept_source)
        _kept_source_freed_at_exit = True


def generate_shard(
    config: GenerationConfig,
    index: int,
    folder: str | os.PathLike[str],
    on_frame: Callable[[], None] | None = None,
) -> ShardInfo:
    """Make shard ``index`` of a dataset (from ``default_rng([seed, index])`` alone).

    Args:
        config: what to generate.
        index: the shard's index.
        folder: the dataset folder.
        on_frame: called after every frame written (progress).

    Returns:
        The complete shard's record.
    """
    folder = Path(folder)
    frames = config.shard_frames(index)
    rng = np.random.default_rng([config.seed, index])
    accept = _Acceptor(config, frames)
    path = folder / Manifest.shard_name(index)
    with (
        _shard_source(config) as source,
        ShardWriter(
            path,
            image_shape=(source.intrinsics.height, source.intrinsics.width),
            depth_scale_mm=config.depth_scale_mm,
            paired_clean=config.paired_clean,
        ) as writer,
    ):
        done, episode, empty = 0, 0, 0
        while done < frames:
            n = min(config.frames_per_episode, frames - done)
            got = 0
            for step, arrays in enumerate(source.episode(rng, accept, n)):
                writer.append(arrays, episode=index * 1_000_000 + episode, step=step)
                if on_frame is not None:
                    on_frame()
                got += 1
            done += got
            episode += 1
            empty = 0 if got else empty + 1
            limit = MAX_EMPTY_EPISODES_STARTED if done else MAX_EMPTY_EPISODES
            if empty == limit:
                raise GenerationError(
                    f"{limit} episodes in a row gave no accepted frame in "
                    f"{MAX_TRIES_PER_FRAME} draws each ({done} of the shard's {frames} frames "
                    f"made{accept.describe_left()}): the occlusion range "
                    f"{config.occlusion_range} or buckets {config.occlusion_buckets} are out of "
                    "reach of this config (add objects, use the 'through_object' viewpoint, or "
                    "widen the range)"
                )
    return writer.info


def _worker(args: tuple[dict, int, str]) -> tuple[int, ShardInfo]:
    config_json, index, folder = args
    config = GenerationConfig.from_mapping(config_json)
    return index, generate_shard(config, index, folder)


RAY_MAX_RETRIES = 3
"""Times Ray reruns a shard task whose worker died (the rerun writes the same shard)."""


def _ray_results(
    jobs: list[tuple[dict, int, str]], address: str
) -> Iterator[tuple[int, ShardInfo]]:
    """Run one Ray task per shard; yield ``(index, record)`` as tasks complete."""
    try:
        import ray
    except ImportError as err:
        raise GenerationError(
            "--ray needs Ray: pip install 'handsim[ray]' (or pip install ray)"
        ) from err
    if not isinstance(address, str) or not address:
        raise InvalidGenerationConfig(
            f"ray must be 'local' or a cluster address such as 'auto' or 'ray://host:10001'; "
            f"received {address!r}"
        )
    if not ray.is_initialized():
        env = {k: os.environ[k] for k in ("MUJOCO_GL", "PYOPENGL_PLATFORM") if k in os.environ}
        ray.init(
            address=None if address == "local" else address,
            include_dashboard=False,
            runtime_env={"env_vars": env} if env else None,
            log_to_driver=False,
        )
    # Retries cover dead workers (SIGKILL, lost node), not errors of the config: those stop.
    task = ray.remote(num_cpus=1, max_retries=RAY_MAX_RETRIES)(_worker)
    pending = [task.remote(job) for job in jobs]
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            try:
                yield ray.get(done[0])
            except ray.exceptions.RayTaskError as err:
                raise err.as_instanceof_cause() from None
            except ray.exceptions.RayError as err:
                raise GenerationError(
                    f"a Ray shard task failed {RAY_MAX_RETRIES + 1} times ({err}); the complete "
                    "shards are kept, rerun the same command to resume"
                ) from err
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


def _histogram(folder: Path, manifest: Manifest, edges: Sequence[float]) -> dict[str, list]:
    from handsim.data.shards import ShardReader

    counts = np.zeros(len(edges) - 1, dtype=int)
    for record in manifest.shards.values():
        reader = ShardReader(folder / record.name)
        ratio = reader.labels("hand_occlusion_ratio")
        counts += np.histogram(np.nan_to_num(ratio), bins=edges)[0]
        reader.close()
    return {"edges": [float(e) for e in edges], "counts": counts.tolist()}


def generate(
    config: GenerationConfig,
    out: str | os.PathLike[str],
    *,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    ray: str | None = None,
) -> Manifest:
    """Generate (or resume) a dataset in ``out``.

    Args:
        config: what to generate.
        out: the dataset folder (created; an existing one must hold the same config).
        workers: worker processes (spawned; each makes whole shards). Ignored with ``ray``.
        progress: called with (frames done, frames total) after every completed shard.
        ray: run one Ray task per shard instead (needs ``pip install handsim[ray]``):
            ``"local"`` starts a local Ray instance (or uses the one this process already
            joined), any other value is the address of a running cluster (``"auto"``,
            ``"ray://host:10001"``, ...). ``out`` must be a folder every node sees. A task
            that dies is retried (:data:`RAY_MAX_RETRIES` times) and writes the same shard.

    Returns:
        The final manifest (also written to ``out/manifest.json``).

    Raises:
        InvalidGenerationConfig: if ``out`` holds a dataset made with another config.
        GenerationError: if a shard cannot be made.
    """
    folder = Path(out)
    _int("workers", workers, 1, 256)
    folder.mkdir(parents=True, exist_ok=True)
    for partial in folder.glob(f"*{PARTIAL_SUFFIX}"):
        partial.unlink()  # a shard in progress when a run was killed
    shape = (camera_preset(config.camera).height, camera_preset(config.camera).width)
    try:
        manifest = Manifest.read(folder)
    except InvalidManifest:
        if any(folder.glob("shard-*.h5")):
            raise InvalidGenerationConfig(
                f"{folder} holds shards but no readable manifest.json; use an empty folder"
            ) from None
        manifest = Manifest(
            config=config.to_json(),
            seeds=[],
            shards={},
            depth_scale_mm=float(config.depth_scale_mm),
            image_shape=shape,
        )
    stored = manifest.config
    try:
        # Fields added since the dataset was made take their defaults.
        stored = GenerationConfig.from_mapping(manifest.config).to_json()
    except (InvalidGenerationConfig, TypeError):
        pass
    if stored != config.to_json():
        changed = sorted(k for k in config.to_json() if stored.get(k) != config.to_json()[k])
        raise InvalidGenerationConfig(
            f"{folder} holds a dataset made with another config (fields differ: "
            f"{', '.join(changed)}); resume with the same config or use another folder"
        )
    manifest.config = config.to_json()
    manifest.seeds = [config.seed] * config.num_shards
    for index, record in list(manifest.shards.items()):
        if check_shard(folder / record.name, record):
            del manifest.shards[index]  # damaged since: make it again
    todo = [i for i in range(config.num_shards) if i not in manifest.shards]
    manifest.write(folder)
    done = manifest.frames
    if progress is not None:
        progress(done, config.frames)
    jobs = [(config.to_json(), i, str(folder)) for i in todo]
    pool = None
    if ray is not None:
        results: Iterator = _ray_results(jobs, ray)
    elif workers == 1 or len(jobs) <= 1:
        # In this process: progress frame by frame (workers report whole shards).
        counted = [done]

        def on_frame() -> None:
            counted[0] += 1
            if progress is not None:
                progress(counted[0], config.frames)

        results = ((i, generate_shard(config, i, folder, on_frame)) for _, i, folder in jobs)
    else:
        # Spawned workers get fresh GL contexts; a worker that dies breaks the pool (an
        # error), where multiprocessing.Pool would replace it and wait forever.
        pool = ProcessPoolExecutor(min(workers, len(jobs)), mp_context=get_context("spawn"))
        results = (f.result() for f in as_completed([pool.submit(_worker, j) for j in jobs]))
    try:
        for index, info in results:
            manifest.shards[index] = info
            manifest.write(folder)
            done += info.frames
            if progress is not None:
                progress(done, config.frames)
    except BrokenProcessPool as err:
        raise GenerationError(
            f"a generation worker died ({err}); the complete shards are kept, rerun the same "
            "command to resume (with workers=1 to see the worker's error)"
        ) from err
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        close_kept_source()  # shards made in this process
    edges = config._buckets()[0] if config.occlusion_buckets is not None else np.linspace(0, 1, 11)
    manifest.occlusion_histogram = _histogram(folder, manifest, edges)
    manifest.write(folder)
    return manifest
