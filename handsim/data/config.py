"""What a dataset is made of: the generation config, its presets and the frame sources by name.

:class:`GenerationConfig` validates every field on construction (errors name the field and what
is valid); :data:`PRESETS` are named configs; :data:`SOURCES` maps a source name to the class
that makes its frames (imported when used).
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from handsim.data.shards import DEFAULT_DEPTH_SCALE_MM, DEPTH_SCALE_RANGE_MM
from handsim.errors import HandSimError
from handsim.world.camera import CAMERA_PRESETS, CameraIntrinsics
from handsim.world.registry import OBJECT_NAMES, OBJECTS
from handsim.world.scene import BACKGROUNDS

SKIN_DETAILS: tuple[str, ...] = ("auto", "full")
"""Values of :attr:`GenerationConfig.skin_detail`."""

__all__ = [
    "POSE_SOURCES",
    "DEFAULT_POSE_SOURCES",
    "VIEWPOINTS",
    "DEFAULT_VIEWPOINTS",
    "MOTION_FRAME_PERIOD_S",
    "SENSORS",
    "BACKENDS",
    "BACKGROUNDS",
    "SKIN_DETAILS",
    "PRESETS",
    "OCCLUDING_OBJECTS",
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
    "CannotDraw",
    "REDRAW_REASONS",
    "GenerationConfig",
    "auto_frames_per_shard",
    "MAX_AUTO_SHARD_FRAMES",
    "MIN_AUTO_SHARDS",
]

POSE_SOURCES = ("gesture", "grasp", "synergy", "motion", "uniform")
"""Pose sources of the kinematic source (:mod:`handsim.hand.pose_sources`): named gestures,
the grasp taxonomy, postural synergies, smooth motions through gestures, grasps and synergy
postures, or uniform joint angles (for robustness studies)."""
DEFAULT_POSE_SOURCES = ("gesture", "grasp", "synergy", "motion")
"""The poses people make: every pose source but ``uniform``."""
VIEWPOINTS = ("third_person", "egocentric", "random", "through_object")
"""Camera placements: in front of the person (a hand alone: palm or back toward the camera,
:mod:`handsim.data.views`), head-mounted (from behind and above the hand), random (a hand
alone: a uniform rotation; among objects: a random direction above the hand), or behind an
object looking at the hand (the object is between camera and hand)."""
DEFAULT_VIEWPOINTS = ("third_person", "egocentric")
"""The views people and their sensors have: ``random`` and ``through_object`` on request."""
MOTION_FRAME_PERIOD_S = 0.1
"""Pose source ``motion``: the frames of an episode sample its motion every this many s."""
BACKENDS = ("opengl", "warp")
"""Renderers of :func:`~handsim.data.generation.generate`: MuJoCo's OpenGL (the reference) or
MuJoCo Warp's batched ray caster (``handsim[gpu]``)."""
SENSORS = ("none", "structured_light", "tof")
"""Depth sensor models."""
MAX_PENETRATION_M = 0.004
"""Deepest hand-object or hand-table overlap a kinematic frame may have, metres."""
MAX_TRIES_PER_FRAME = 200
"""Draws per frame before an episode ends early (its scene cannot give an accepted frame)."""
MIN_KEYPOINTS_IN_FRAME = 15
"""Fewest of the 21 keypoints inside the image for a frame to be kept."""
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


REDRAW_REASONS = ("placement", "grasp", "frame")
"""Causes of a redrawn episode that the built-in sources give (:class:`CannotDraw`):
``"placement"``: the episode's objects do not fit on the table; ``"grasp"``: no feasible grasp
of the episode's object; ``"frame"``: :data:`MAX_TRIES_PER_FRAME` draws of pose, wrist and view
gave no accepted frame (the episode's hand and objects cannot reach what is asked). A source
may give others (lowercase identifiers)."""
_REASON = re.compile(r"[a-z][a-z0-9_]{0,39}")


class CannotDraw(HandSimError, RuntimeError):
    """An episode's draws cannot be satisfied: the episode is redrawn, not the run failed.

    A source's :meth:`FrameSource.episode` raises it (before or after yielding frames) when
    what it drew from the episode's generator cannot give a frame: objects that do not fit on
    the table, a grasp that cannot be made, views that are never accepted. The shard keeps the
    frames already yielded, counts the redraw under ``reason`` (the manifest's ``redraws``)
    and draws the next episode from the same generator, so the shard stays a function of
    ``(seed, index)``. Only :data:`MAX_EMPTY_EPISODES` frameless episodes in a row stop the
    run (a :class:`GenerationError`: the config cannot give a frame).

    Args:
        reason: the cause, a lowercase identifier (:data:`REDRAW_REASONS` for the built-in
            sources).
        message: what could not be drawn, for the error raised if nothing can be.
    """

    def __init__(self, reason: str, message: str) -> None:
        if not isinstance(reason, str) or not _REASON.fullmatch(reason):
            raise GenerationError(
                "CannotDraw reason must be a lowercase identifier of at most 40 characters, "
                f"e.g. one of {', '.join(REDRAW_REASONS)}; received {reason!r}"
            )
        super().__init__(message)
        self.reason = reason


SOURCES: dict[str, str] = {
    "kinematic": "handsim.data.kinematic:KinematicSource",
    "rollout": "handsim.envs.rollouts:RolloutSource",
    "grasp": "handsim.envs.kinematic_grasps:GraspSource",
}
"""Frame sources by name -> ``"module:class"`` of a :class:`FrameSource`, imported when used
(so the core does not import the envs; spawned and Ray workers import the module by name).
Add one with :func:`register_source`."""


class FrameSource(Protocol):
    """What :func:`generate_shard` needs of a frame source.

    A source is made per shard from the config (``cls(config)``) and closed after it. Its
    :meth:`episode` draws everything from the generator it is given; when those draws cannot
    be satisfied it raises :class:`CannotDraw` and the shard draws the next episode from the
    same generator (counted by reason in the manifest), so no draw ever fails a run.
    """

    intrinsics: CameraIntrinsics

    @classmethod
    def check_config(cls, config: GenerationConfig) -> None:
        """Raise :class:`InvalidGenerationConfig` for a field this source cannot honour."""

    def episode(
        self, rng: np.random.Generator, accept: Callable[[float, int], bool], frames: int
    ) -> Iterator[dict[str, np.ndarray]]:
        """Yield the arrays (images included) of up to ``frames`` accepted frames.

        Args:
            rng: the episode's generator (every draw of the episode comes from it).
            accept: called with a candidate frame's hand occlusion ratio and its number of
                visible keypoints (``visible.sum()``); False refuses the frame (occlusion
                control and the visible-keypoint cap). True counts the frame as kept: yield it.
            frames: most frames to yield.

        Raises:
            CannotDraw: when the episode's draws cannot give (more) frames; frames already
                yielded are kept.
        """

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


def _fraction(name: str, value: object) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not 0.0 <= value <= 1.0
    ):
        raise InvalidGenerationConfig(f"{name} must be a number in [0, 1]; received {value!r}")
    return float(value)


def _choice(name: str, value: object, valid: Sequence[str]) -> str:
    if value not in valid:
        raise InvalidGenerationConfig(
            f"{name} must be one of {', '.join(valid)}; received {value!r}"
        )
    return str(value)


MAX_AUTO_SHARD_FRAMES = 250
"""Largest shard :func:`auto_frames_per_shard` makes (and the size of one-shard jobs)."""
MIN_AUTO_SHARDS = 4
"""Fewest shards :func:`auto_frames_per_shard` splits a job of more than 250 frames into."""


def auto_frames_per_shard(frames: int) -> int:
    """The shard size of a job of ``frames`` frames when none is given.

    Up to :data:`MAX_AUTO_SHARD_FRAMES` (250) frames a job is one shard; a larger one is split
    into at least :data:`MIN_AUTO_SHARDS` (4) shards of at most 250 frames
    (``min(250, ceil(frames / 4))``), so that two or four workers share even a small job
    (600 frames: 4 shards of 150). From 1000 frames on, shards have 250 frames. The size
    depends on the job alone, never on the worker count: the same config gives the same
    dataset with any number of workers.
    """
    if frames <= MAX_AUTO_SHARD_FRAMES:
        return max(int(frames), 1)
    return min(MAX_AUTO_SHARD_FRAMES, -(-int(frames) // MIN_AUTO_SHARDS))


@dataclasses.dataclass(frozen=True)
class GenerationConfig:
    """What to generate. Every field is validated on construction (errors name the field).

    Attributes:
        frames: total frames of the dataset.
        frames_per_shard: frames per shard (the unit of work, resume and checksums);
            ``None`` (default): sized to the job, :func:`auto_frames_per_shard` (one shard up
            to 250 frames, else at least 4 shards of at most 250). A resumed run keeps the
            size recorded in the dataset's manifest.
        frames_per_episode: frames drawn per episode (one hand and one object set).
        seed: base seed; shard ``i`` uses ``default_rng([seed, i])``.
        camera: camera preset (intrinsics), e.g. ``"icvl"`` (320 x 240).
        viewpoints: camera placements drawn per frame (:data:`VIEWPOINTS`); ``random`` gives
            a hand alone a uniform rotation (robustness studies).
        distance_range_m: camera distance from the hand, metres;
            the camera moves back along its line of sight when the hand or an object would be
            nearer than the camera's or the sensor's working range (a hole in the depth).
        sensor: depth sensor model (:data:`SENSORS`).
        paired_clean: also store the noise-free depth of every frame.
        hand_length_range_m: hand length drawn per episode, metres (0.140 to 0.235).
        left_fraction: fraction of left hands.
        objects: object names drawn from (canonical or short names).
        num_objects_range: objects per episode (0 for hand-only data).
        pose_sources: pose sources drawn per episode (:data:`POSE_SOURCES`); ``uniform``
            (uniform joint angles) only on request.
        occlusion_range: keep frames whose hand occlusion ratio lies in this range.
        occlusion_buckets: ``(edges, fractions)``: bucket edges of the occlusion ratio and the
            fraction of every shard each bucket must fill (``None``: no stratification).
        min_visible_keypoints: a frame with fewer visible keypoints (of 21, ``visible`` of the
            clean render) is *below the minimum*; see the next field.
        max_fraction_below_min_visible: most frames of every shard below the minimum
            (``floor(fraction * shard frames)``); others are redrawn. 1 keeps every frame.
        depth_scale_mm: stored depth unit, millimetres.
        source: where frames come from (:data:`SOURCES`): ``"kinematic"`` (posed hands, no
            physics), ``"grasp"`` (posed hands closed onto an object by the grasp planner's
            grasp, no physics) or ``"rollout"`` (an env driven by its expert, with physical
            contact).
        env_id: the env of the rollout source (``handsim/Grasp-v0``,
            ``handsim/GraspClutter-v0`` or ``handsim/HandPose-v0``); ``None`` otherwise.
        frame_stride: rollout source: env steps between kept frames (1 = every step).
        background: kinematic source: what stands beyond the hand and the table
            (:data:`BACKGROUNDS`): ``"none"`` (default: no depth there), ``"wall"``,
            ``"torso"`` (the person's torso and head, a wall behind) or ``"clutter"``
            (furniture, a wall behind). Placed per frame behind
            everything the camera sees of the hand (forearm included) and the objects; its
            pixels carry the segmentation label ``"backdrop"``. The rollout source renders its
            env's scene, which has none.
        approach_fraction: grasp source: fraction of frames drawn along the approach to the
            grasp (the open hand, not yet in contact) instead of at the grasp.
        backend: the renderer (:data:`BACKENDS`): ``"opengl"`` (default, the reference) or
            ``"warp"`` (MuJoCo Warp: :mod:`handsim.data.warp_source`; the ``kinematic`` and
            ``grasp`` sources, a hand alone N frames per launch). Recorded with the dataset: a
            resume with the other backend is refused (their shards differ).
        skin_detail: the skin's level of detail in the OpenGL renders of every source
            (:data:`SKIN_DETAILS`; the warp backend draws the full skin): ``"full"`` (default)
            always the full skin; ``"auto"`` the coarse skin (a quarter of the triangles) when
            its deviation from the skin's surface projects to under a pixel, i.e. for small
            projected hands (:class:`~handsim.frame.renderer.FrameRenderer`), for cheaper frames.
            Recorded with the dataset.
    """

    frames: int = 1000
    frames_per_shard: int | None = None
    frames_per_episode: int = 25
    seed: int = 0
    camera: str = "icvl"
    viewpoints: tuple[str, ...] = DEFAULT_VIEWPOINTS
    distance_range_m: tuple[float, float] = (0.35, 0.7)
    sensor: str = "structured_light"
    paired_clean: bool = False
    hand_length_range_m: tuple[float, float] = (0.150, 0.220)
    left_fraction: float = 0.5
    objects: tuple[str, ...] = OBJECT_NAMES
    num_objects_range: tuple[int, int] = (1, 3)
    pose_sources: tuple[str, ...] = DEFAULT_POSE_SOURCES
    occlusion_range: tuple[float, float] = (0.0, 1.0)
    occlusion_buckets: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    min_visible_keypoints: int = 1
    max_fraction_below_min_visible: float = 1.0
    depth_scale_mm: float = DEFAULT_DEPTH_SCALE_MM
    source: str = "kinematic"
    env_id: str | None = None
    frame_stride: int = 1
    background: str = "none"
    approach_fraction: float = 0.0
    backend: str = "opengl"
    skin_detail: str = "full"

    def __post_init__(self) -> None:
        _choice("source", self.source, tuple(SOURCES))
        _int("frame_stride", self.frame_stride, 1, 10_000)
        if (
            isinstance(self.approach_fraction, bool)
            or not isinstance(self.approach_fraction, (int, float))
            or not 0.0 <= self.approach_fraction <= 1.0
        ):
            raise InvalidGenerationConfig(
                f"approach_fraction must be a number in [0, 1]; received {self.approach_fraction!r}"
            )
        if self.approach_fraction and self.source != "grasp":
            raise InvalidGenerationConfig(
                "approach_fraction is a field of the 'grasp' source; set source: grasp or "
                f"remove it (received {self.approach_fraction!r} with source {self.source!r})"
            )
        if (
            isinstance(self.depth_scale_mm, bool)
            or not isinstance(self.depth_scale_mm, (int, float))
            or not DEPTH_SCALE_RANGE_MM[0] <= self.depth_scale_mm <= DEPTH_SCALE_RANGE_MM[1]
        ):
            lo, hi = DEPTH_SCALE_RANGE_MM
            raise InvalidGenerationConfig(
                f"depth_scale_mm must be a number in [{lo:g}, {hi:g}]; received "
                f"{self.depth_scale_mm!r}"
            )
        if self.env_id is not None and not isinstance(self.env_id, str):
            raise InvalidGenerationConfig(
                f"env_id must be an env id such as 'handsim/Grasp-v0'; received {self.env_id!r}"
            )
        _int("frames", self.frames, 1, 10**9)
        if self.frames_per_shard is not None:
            _int("frames_per_shard", self.frames_per_shard, 1, 100_000)
        _int("frames_per_episode", self.frames_per_episode, 1, 10_000)
        _int("seed", self.seed, 0, 2**63 - 1)
        _choice("camera", self.camera, tuple(CAMERA_PRESETS))
        self._tuple_of("viewpoints", VIEWPOINTS)
        _pair("distance_range_m", self.distance_range_m, 0.15, 3.0)
        _choice("sensor", self.sensor, SENSORS)
        _choice("background", self.background, BACKGROUNDS)
        _choice("backend", self.backend, BACKENDS)
        _choice("skin_detail", self.skin_detail, SKIN_DETAILS)
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
        _int("min_visible_keypoints", self.min_visible_keypoints, 0, 21)
        _fraction("max_fraction_below_min_visible", self.max_fraction_below_min_visible)
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
    def shard_size(self) -> int:
        """Frames per shard: ``frames_per_shard``, or the job's size when that is ``None``."""
        if self.frames_per_shard is not None:
            return self.frames_per_shard
        return auto_frames_per_shard(self.frames)

    @property
    def num_shards(self) -> int:
        """Number of shards (the last one may be shorter)."""
        return -(-self.frames // self.shard_size)

    def shard_frames(self, index: int) -> int:
        """Frames of shard ``index``."""
        return min(self.shard_size, self.frames - index * self.shard_size)

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
        kind = "YAML" if path.suffix in (".yaml", ".yml") else "JSON"
        try:
            if kind == "YAML":
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
        except RecursionError:
            raise InvalidGenerationConfig(
                f"{path}: {kind} nested too deeply to be a config (fields are one level)"
            ) from None
        return cls.from_mapping(values, **overrides)


OCCLUDING_OBJECTS: tuple[str, ...] = (
    "002_master_chef_can",
    "003_cracker_box",
    "004_sugar_box",
    "005_tomato_soup_can",
    "006_mustard_bottle",
    "010_potted_meat_can",
    "019_pitcher_base",
    "021_bleach_cleanser",
    "024_bowl",
    "025_mug",
    "035_power_drill",
    "036_wood_block",
    "061_foam_brick",
)
"""The YCB-Video objects that can hide a hand from any side: every extent at least 5 cm, the
extra-large clamp excepted (an open frame). Scissors, clamps, the marker, the banana and the
flat boxes and can seen edge-on hide little."""

PRESETS: dict[str, dict[str, Any]] = {
    "hand-only": {"num_objects_range": (0, 0), "viewpoints": ("third_person",)},
    "hand-only-egocentric": {"num_objects_range": (0, 0), "viewpoints": ("egocentric",)},
    "hand-object": {"source": "grasp", "num_objects_range": (1, 3)},
    "occlusion-heavy": {
        "source": "grasp",
        "num_objects_range": (2, 4),
        "viewpoints": ("through_object",),
        "distance_range_m": (0.4, 0.7),
        "occlusion_buckets": ((0.1, 0.3, 0.5, 0.7, 0.95), (0.25, 0.25, 0.25, 0.25)),
        "min_visible_keypoints": 1,
        "max_fraction_below_min_visible": 0.05,
    },
    "grasp-rollouts": {
        "source": "rollout",
        "env_id": "handsim/Grasp-v0",
        "num_objects_range": (1, 1),
        "viewpoints": ("third_person", "egocentric", "random"),
        "frames_per_episode": 60,
        "frame_stride": 5,
    },
    "grasp-rollouts-occluded": {
        "source": "rollout",
        "env_id": "handsim/Grasp-v0",
        "num_objects_range": (1, 1),
        "objects": OCCLUDING_OBJECTS,
        "viewpoints": ("through_object",),
        "distance_range_m": (0.4, 0.7),
        "frames_per_episode": 60,
        "frame_stride": 5,
        "occlusion_buckets": ((0.1, 0.3, 0.5, 0.7, 0.95), (0.25, 0.25, 0.25, 0.25)),
    },
}
"""Named configs: hand alone seen by a sensor in front of the person (third person, views as in
NYU's test set) or by a head-mounted camera (egocentric; kinematic), hand grasping one
of the objects on the table, objects between camera and hand with the occlusion ratio
stratified in four buckets from 0.1 to 0.95 and at most 5 % of frames without a visible
keypoint (both from the grasp planner's grasps, posed without physics: the ``"grasp"``
source), Grasp-v0 rollouts of the grasp expert, every fifth step (10 Hz) of the approach,
grasp and lift (physical contact), and the same rollouts of :data:`OCCLUDING_OBJECTS` seen
through the object (a view drawn per kept step) with the occlusion buckets of
``occlusion-heavy``."""
