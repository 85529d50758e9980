"""The env keyword arguments: their valid values, checked once into an :class:`EnvConfig`."""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from handsim.errors import HandSimError
from handsim.hand.model import (
    HAND_SIZES,
    hand_params,
)
from handsim.world.camera import CAMERA_PRESETS
from handsim.world.registry import OBJECTS

__all__ = [
    "EnvConfig",
    "InvalidEnvConfig",
    "OBS_MODES",
    "CONTROL_MODES",
    "REWARD_TYPES",
    "VIEWPOINTS",
    "HANDEDNESS",
    "OBJECT_SETS",
    "WORKSPACE_M",
    "SENSORS",
    "DEPTH_FORMATS",
    "IMAGE_SIZE_RANGE",
    "RENDER_SIZE_RANGE",
    "RENDER_QUALITIES",
    "RENDER_MODES",
    "OBJECT_FRICTIONS",
]

OBS_MODES: tuple[str, ...] = (
    "depth",
    "depth+segmentation",
    "state",
    "depth+state",
    "privileged_state",
)
"""Observation modes: which keys the observation ``Dict`` has (see
:class:`~handsim.envs.base.HandSimEnv`)."""
DEPTH_FORMATS: tuple[str, ...] = ("float32_m", "uint16_mm")
"""Depth observation encodings: float32 metres, or uint16 millimetres (rounded)."""
IMAGE_SIZE_RANGE: tuple[int, int] = (8, 2048)
"""Valid observation image ``width`` / ``height``, pixels (inclusive)."""
RENDER_SIZE_RANGE: tuple[int, int] = (16, 4096)
"""Valid ``render_width`` / ``render_height``, pixels (inclusive)."""
RENDER_QUALITIES: tuple[str, ...] = ("fast", "high")
"""``render_quality`` values: ``"fast"`` draws no shadows (a shadow pass more than doubles the
cost of a software-rendered colour image); ``"high"`` lets one light cast shadows, with a shadow
map about half the image size."""
SKIN_DETAILS: tuple[str, ...] = ("auto", "full")
"""``skin_detail`` values (:class:`~handsim.frame.renderer.FrameRenderer`)."""
_HAS_DISPLAY = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
RENDER_MODES: tuple[str, ...] = ("rgb_array", "depth_array", "depth_rgb_array") + (
    ("human",) if _HAS_DISPLAY else ()
)
"""``render_mode`` values: ``"depth_array"`` is the (H, W) float32 depth in metres (Gymnasium's
convention), ``"depth_rgb_array"`` that depth colour-mapped as an (H, W, 3) uint8 picture (what
``RecordVideo`` encodes); ``"human"`` only where a display is present."""
CONTROL_MODES: tuple[str, ...] = ("pose", "delta")
"""Absolute 27-DoF pose targets, or normalized deltas of the current target."""
REWARD_TYPES: tuple[str, ...] = ("dense", "sparse")
VIEWPOINTS: tuple[str, ...] = ("third_person", "egocentric", "random")
"""Camera placements: across the table, head-mounted, or a seeded random view per episode."""
HANDEDNESS: tuple[str, ...] = ("right", "left", "random")
OBJECT_SETS: dict[str, tuple[str, ...]] = {"ycbv": tuple(OBJECTS)}
"""Named object sets accepted for ``objects``."""
WORKSPACE_M: tuple[tuple[float, float], ...] = ((-0.5, 0.5), (-0.5, 0.5), (0.0, 0.6))
"""Bounds of the wrist target (x, y, z), world frame, metres (table top at z = 0)."""
SENSORS: tuple[str, ...] = ("none", "structured_light", "tof")
"""Sensor model names (:func:`handsim.world.sensors.sensor_model`)."""
OBJECT_FRICTIONS: tuple[str, ...] = ("mujoco", "skin")
"""Named ``object_friction`` values (a number is valid too): measured skin friction on each
object's material (the default; :func:`~handsim.envs.physics.set_skin_friction`), or MuJoCo's
1.0 for every contact."""


class InvalidEnvConfig(HandSimError, ValueError):
    """An env keyword argument is invalid."""


def _bool(value: object, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidEnvConfig(f"{name} must be True or False; received {value!r}")
    return bool(value)


def _size(value: object, name: str, valid: tuple[int, int], note: str = "") -> int:
    lo, hi = valid
    if (
        not isinstance(value, (int, np.integer))
        or isinstance(value, (bool, np.bool_))
        or not lo <= value <= hi
    ):
        raise InvalidEnvConfig(
            f"{name} must be an integer number of pixels in [{lo}, {hi}]{note}; received {value!r}"
        )
    return int(value)


def _choice(value: object, name: str, valid: tuple[str, ...]) -> str:
    if value not in valid:
        raise InvalidEnvConfig(f"{name}={value!r} is not valid; choose one of {', '.join(valid)}")
    return str(value)


def _object_friction(value: object) -> str | float:
    if isinstance(value, str) and value in OBJECT_FRICTIONS:
        return value
    if (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and np.isfinite(value)
        and 0 < value <= 10
    ):
        return float(value)
    raise InvalidEnvConfig(
        f"object_friction={value!r} is not valid; choose one of {', '.join(OBJECT_FRICTIONS)} "
        "or a sliding friction in (0, 10]"
    )


def _hand_size(value: object) -> tuple[float, float]:
    """(low, high) hand length in metres from a preset name, a length or a range."""
    if isinstance(value, str):
        if value not in HAND_SIZES:
            raise InvalidEnvConfig(
                f"hand_size={value!r} is not a size; use one of {', '.join(HAND_SIZES)}, "
                "a hand length in metres, or a (low, high) range in metres"
            )
        length = HAND_SIZES[value]
        return (length, length)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = (float(value), float(value))
    try:
        lo, hi = (float(v) for v in value)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise InvalidEnvConfig(
            f"hand_size={value!r} is not valid; use one of {', '.join(HAND_SIZES)}, a hand "
            "length in metres, or a (low, high) range in metres"
        ) from None
    if not lo <= hi:
        raise InvalidEnvConfig(f"hand_size range ({lo}, {hi}) has low > high")
    for length in (lo, hi):
        hand_params(length)  # raises InvalidHandParams with the valid range
    return (lo, hi)


def _object_names(value: object, min_count: int) -> tuple[str, ...]:
    if isinstance(value, str):
        value = OBJECT_SETS[value] if value in OBJECT_SETS else (value,)
    try:
        names = tuple(OBJECTS.canonical(n) for n in value)  # type: ignore[union-attr]
    except TypeError:
        raise InvalidEnvConfig(
            f"objects={value!r} is not valid; give an object name, a list of names or a set "
            f"({', '.join(OBJECT_SETS)})"
        ) from None
    if len(names) < min_count:
        raise InvalidEnvConfig(
            f"objects needs at least {min_count} name(s); received {len(names)}: {names}"
        )
    return names


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Validated keyword arguments shared by every handsim env.

    Attributes:
        objects: canonical object names the episode draws from.
        hand_size_m: (low, high) hand length, metres; drawn uniformly per episode.
        handedness: ``"right"``, ``"left"`` or ``"random"`` (per episode).
        camera: camera preset (:data:`~handsim.world.camera.CAMERA_PRESETS`).
        viewpoint: one of :data:`VIEWPOINTS`.
        sensor: sensor model name (:data:`SENSORS`).
        obs_mode: one of :data:`OBS_MODES`.
        control_mode: one of :data:`CONTROL_MODES`.
        reward_type: one of :data:`REWARD_TYPES`.
        frame_skip: physics steps per action (control period = ``frame_skip * 0.002`` s).
        render_mode: ``None``, ``"rgb_array"``, ``"depth_array"``, ``"depth_rgb_array"`` or
            (only with a display) ``"human"``.
        labels: render and label a :class:`~handsim.frame.record.Frame` every step
            (``info["labels"]``);
            default ``True`` for modes with images, ``False`` for ``"state"`` and
            ``"privileged_state"`` (nothing is rendered then).
        width: observation image width, pixels (default: the camera preset's); the camera
            renders at this size with its ``K`` scaled (the same field of view; no resize).
        height: observation image height, pixels (default: the preset's, or ``width`` times the
            preset's aspect ratio when only ``width`` is given).
        depth_format: ``"float32_m"`` (metres) or ``"uint16_mm"`` (millimetres, rounded).
        channel_axis: give images a leading channel axis: depth and segmentation ``(1, H, W)``
            (what Stable-Baselines3's CNN policies take) instead of ``(H, W)``.
        render_width: width of ``render()`` images, pixels.
        render_height: height of ``render()`` images, pixels.
        render_quality: ``"fast"`` (default: no shadow pass, the cheapest colour image) or
            ``"high"`` (one light casts shadows, for pictures); see :data:`RENDER_QUALITIES`.
        object_friction: hand-object sliding friction: ``"skin"`` (default: measured skin
            friction on each object's material, 0.42 to 0.6), ``"mujoco"`` (MuJoCo's 1.0) or a
            number > 0 for every object (:func:`~handsim.envs.physics.set_skin_friction`).
        skin_detail: the hand skin's level of detail in depth frames (``"full"``, default:
            always the full skin, as the ``-v0`` envs have drawn it; ``"auto"``: the coarse
            skin for small projected hands, 1.2-1.4x faster steps; see
            :class:`~handsim.frame.renderer.FrameRenderer`).

    The episode length is Gymnasium's: ``gym.make(id, max_episode_steps=N)`` (defaults in
    :mod:`handsim.envs`).
    """

    objects: tuple[str, ...] = ()
    hand_size_m: tuple[float, float] = (HAND_SIZES["medium"], HAND_SIZES["medium"])
    handedness: str = "right"
    camera: str = "icvl"
    viewpoint: str = "third_person"
    sensor: str = "none"
    obs_mode: str = "depth"
    control_mode: str = "pose"
    reward_type: str = "dense"
    frame_skip: int = 10
    render_mode: str | None = None
    labels: bool = True
    width: int = 320
    height: int = 240
    depth_format: str = "float32_m"
    channel_axis: bool = False
    render_width: int = 480
    render_height: int = 360
    render_quality: str = "fast"
    object_friction: str | float = "skin"
    skin_detail: str = "full"

    @classmethod
    def from_kwargs(
        cls,
        *,
        objects: object = (),
        min_objects: int = 0,
        hand_size: object = "medium",
        handedness: object = "right",
        camera: object = "icvl",
        viewpoint: object = "third_person",
        sensor: object = "none",
        obs_mode: object = "depth",
        control_mode: object = "pose",
        reward_type: object = "dense",
        frame_skip: object = 10,
        render_mode: object = None,
        labels: object = None,
        width: object = None,
        height: object = None,
        depth_format: object = "float32_m",
        channel_axis: object = False,
        render_width: object = 480,
        render_height: object = 360,
        render_quality: object = "fast",
        object_friction: object = "skin",
        skin_detail: object = "full",
    ) -> EnvConfig:
        """Validate the keyword arguments of an env (each error lists the valid values)."""
        if not isinstance(frame_skip, (int, np.integer)) or isinstance(frame_skip, bool):
            raise InvalidEnvConfig(
                f"frame_skip must be a positive integer; received {frame_skip!r}"
            )
        if frame_skip < 1:
            raise InvalidEnvConfig(f"frame_skip must be a positive integer; received {frame_skip}")
        if render_mode == "human" and not _HAS_DISPLAY:
            raise InvalidEnvConfig(
                "render_mode='human' needs a display (DISPLAY is not set); use 'rgb_array' or "
                "'depth_array' headless"
            )
        if render_mode is not None:
            _choice(render_mode, "render_mode", RENDER_MODES)
        camera = _choice(camera, "camera", tuple(CAMERA_PRESETS))
        obs_mode = _choice(obs_mode, "obs_mode", OBS_MODES)
        preset = CAMERA_PRESETS[camera]
        note = f" (the {camera!r} sensor is {preset.width} x {preset.height})"
        if width is not None:
            width = _size(width, "width", IMAGE_SIZE_RANGE, note)
        if height is not None:
            height = _size(height, "height", IMAGE_SIZE_RANGE, note)
        if width is None:
            width = (
                preset.width
                if height is None
                else max(IMAGE_SIZE_RANGE[0], round(height * preset.width / preset.height))
            )
        if height is None:
            height = max(IMAGE_SIZE_RANGE[0], round(width * preset.height / preset.width))
        labels = "depth" in obs_mode if labels is None else _bool(labels, "labels")
        return cls(
            objects=_object_names(objects, min_objects) if min_objects or objects else (),
            hand_size_m=_hand_size(hand_size),
            handedness=_choice(handedness, "handedness", HANDEDNESS),
            camera=camera,
            viewpoint=_choice(viewpoint, "viewpoint", VIEWPOINTS),
            sensor=_choice(sensor, "sensor", SENSORS),
            obs_mode=obs_mode,
            control_mode=_choice(control_mode, "control_mode", CONTROL_MODES),
            reward_type=_choice(reward_type, "reward_type", REWARD_TYPES),
            frame_skip=int(frame_skip),
            render_mode=render_mode,  # type: ignore[arg-type]
            labels=labels,
            width=int(width),
            height=int(height),
            depth_format=_choice(depth_format, "depth_format", DEPTH_FORMATS),
            channel_axis=_bool(channel_axis, "channel_axis"),
            render_width=_size(render_width, "render_width", RENDER_SIZE_RANGE),
            render_height=_size(render_height, "render_height", RENDER_SIZE_RANGE),
            render_quality=_choice(render_quality, "render_quality", RENDER_QUALITIES),
            object_friction=_object_friction(object_friction),
            skin_detail=_choice(skin_detail, "skin_detail", SKIN_DETAILS),
        )
