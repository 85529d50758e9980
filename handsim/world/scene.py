"""Scenes: a table, lights, a hand, YCB-like objects and depth cameras, compiled with MjSpec.

World frame: ``z`` up, origin at the centre of the table top; the user sits on the ``-y`` side.

A :class:`SceneSpec` (frozen dataclasses) describes the scene; :class:`Scene` compiles it and
keeps the model, its data, the hand binding and the segmentation labels. Placements come from
:func:`sample_placements` (stable resting poses, random yaw, non-overlapping footprints);
cameras from :func:`third_person_camera`, :func:`egocentric_camera` or the seeded
:func:`sample_viewpoint`.

Segmentation labels (:data:`SEGMENT_LABELS`): 0 background (no surface), 1 table, 2 backdrop
(:attr:`SceneSpec.background`), 3 arm (the forearm beyond the palm's stub, and the upper
arm), 4 palm (with the forearm stub), 5 thumb,
6 index, 7 middle, 8 ring, 9 little, and ``10 + k`` (:data:`OBJECT_LABEL_OFFSET` ``+ k``) for
object instance ``k`` in the order of :attr:`SceneSpec.objects`. The hand's labels are
``palm`` up to the objects' (the forearm is not the hand).
"""

from __future__ import annotations

import dataclasses
import os
import pathlib

import mujoco
import numpy as np

from handsim._validate import boolean, integer, is_real, real_array, real_scalar, show
from handsim.errors import HandSimError
from handsim.hand.model import (
    FOREARM_GEOM,
    HAND_PHYSICS_OPTIONS,
    UPPER_ARM_GEOM,
    Hand,
    HandParams,
)
from handsim.hand.pose import DIGITS, HandPose
from handsim.world.camera import CameraIntrinsics, add_camera, camera_preset, look_at_quat_wxyz
from handsim.world.mjcf import save_spec, spec_to_xml
from handsim.world.objects import YCBObject, add_object
from handsim.world.registry import get_object

__all__ = [
    "SEGMENT_LABELS",
    "OBJECT_LABEL_OFFSET",
    "SKIN_LOD_GROUP",
    "BACKGROUNDS",
    "ObjectPlacement",
    "CameraSpec",
    "SceneSpec",
    "Scene",
    "InvalidScene",
    "third_person_camera",
    "egocentric_camera",
    "sample_viewpoint",
    "sample_placements",
]

SEGMENT_LABELS: tuple[str, ...] = ("background", "table", "backdrop", "arm", "palm", *DIGITS)
"""Names of the fixed segmentation labels; objects follow from :data:`OBJECT_LABEL_OFFSET`."""
OBJECT_LABEL_OFFSET = len(SEGMENT_LABELS)
SKIN_LOD_GROUP = 4
"""Geom group of the skin's coarse level of detail (:attr:`SceneSpec.skin_lod`); cameras draw
groups 0 to 2, so only a renderer that swaps it in for the skin shows it."""

BACKGROUNDS: tuple[str, ...] = ("none", "wall", "torso", "clutter")
"""What stands beyond the table (:attr:`SceneSpec.background`): nothing (no depth), a wall, the
person's torso and head in front of a wall, or furniture in front of a wall."""

_TABLE_HALF_SIZE_M = (0.6, 0.4, 0.02)
_BACKDROP_BODY = "backdrop"
_BACKDROP_PREFIX = "backdrop_"  # every backdrop geom's name starts so (label "backdrop")
# Backdrop geoms in the backdrop body's frame (+x toward the camera, +z up; the front plane is
# x = 0, the body origin at table-top height): (name, type, size, pos). A wall 6 m by 4 m; a
# seated adult's torso (chest 0.36 m broad, 0.22 m deep, 0.6 m from the table top up) and head
# (0.2 m) [estimate], with the wall 0.4 m behind the torso.
_BOX, _CYLINDER = mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_CYLINDER
_WALL = ("backdrop_wall", _BOX, (0.01, 3.0, 2.0), (-0.01, 0.0, 0.5))
_BACKDROPS = {
    "wall": (_WALL,),
    "torso": (
        ("backdrop_torso", mujoco.mjtGeom.mjGEOM_ELLIPSOID, (0.11, 0.18, 0.30), (-0.11, 0.0, 0.3)),
        ("backdrop_head", mujoco.mjtGeom.mjGEOM_ELLIPSOID, (0.09, 0.075, 0.11), (-0.1, 0.0, 0.73)),
        (_WALL[0], _WALL[1], _WALL[2], (-0.41, 0.0, 0.5)),
    ),
    # A room's furniture, all of it behind the front plane: a cabinet, a desk with a monitor
    # and a bottle, a floor lamp, the wall 0.65 m behind [estimate].
    "clutter": (
        ("backdrop_cabinet", _BOX, (0.2, 0.25, 0.45), (-0.2, -0.7, -0.3)),
        ("backdrop_desk", _BOX, (0.3, 0.6, 0.02), (-0.3, 0.35, 0.1)),
        ("backdrop_monitor", _BOX, (0.03, 0.27, 0.17), (-0.45, 0.35, 0.3)),
        ("backdrop_bottle", _CYLINDER, (0.04, 0.12, 0.0), (-0.12, 0.0, 0.24)),
        ("backdrop_lamp", _CYLINDER, (0.1, 0.6, 0.0), (-0.35, 0.95, -0.15)),
        (_WALL[0], _WALL[1], _WALL[2], (-0.66, 0.0, 0.5)),
    ),
}
# Beyond the table's far edge, the default backdrop leaves this much for a hand and forearm
# reaching past it, metres.
_BACKDROP_REACH_M = 0.3
_DEFAULT_HAND_TARGET = (0.0, 0.0, 0.12)
# OpenGL near clip plane, metres: well inside every sensor's minimum range.
_GL_NEAR_M = 0.01


class InvalidScene(HandSimError, ValueError):
    """A scene description is inconsistent (names, placements, cameras)."""


@dataclasses.dataclass(frozen=True)
class ObjectPlacement:
    """One object instance on the table.

    Attributes:
        name: object name or alias (see :data:`handsim.world.OBJECTS`); for an imported
            mesh, its name.
        pos_m: (3,) object-frame origin in the world, metres.
        quat_wxyz: (4,) orientation ``world_from_obj``.
        mesh: an object from :func:`handsim.world.load_object`, used instead of the
            registry entry.
    """

    name: str
    pos_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    mesh: YCBObject | None = None

    def __post_init__(self) -> None:
        _check_name("name", self.name)
        object.__setattr__(self, "pos_m", _vec("pos_m", self.pos_m, 3))
        object.__setattr__(self, "quat_wxyz", _quat("quat_wxyz", self.quat_wxyz))
        if self.mesh is not None and not isinstance(self.mesh, YCBObject):
            raise InvalidScene(f"mesh must be a YCBObject or None; received {show(self.mesh)}")

    @property
    def object(self) -> YCBObject:
        """The object (imported mesh, or the registry entry by name)."""
        return self.mesh if self.mesh is not None else get_object(self.name)


@dataclasses.dataclass(frozen=True)
class CameraSpec:
    """A depth camera.

    Attributes:
        name: camera name in the model.
        intrinsics: pinhole intrinsics (image size included).
        pos_m: (3,) camera centre in the world, metres.
        quat_wxyz: (4,) orientation ``world_from_mjcam`` (MuJoCo camera frame).
    """

    name: str
    intrinsics: CameraIntrinsics
    pos_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]

    def __post_init__(self) -> None:
        _check_name("name", self.name)
        if not isinstance(self.intrinsics, CameraIntrinsics):
            raise InvalidScene(
                f"intrinsics must be a CameraIntrinsics (e.g. camera_preset('icvl')); received "
                f"{show(self.intrinsics)}"
            )
        object.__setattr__(self, "pos_m", _vec("pos_m", self.pos_m, 3))
        object.__setattr__(self, "quat_wxyz", _quat("quat_wxyz", self.quat_wxyz))

    @classmethod
    def look_at(
        cls,
        name: str,
        intrinsics: CameraIntrinsics,
        eye_m: tuple[float, float, float],
        target_m: tuple[float, float, float],
        up: tuple[float, float, float] = (0.0, 0.0, 1.0),
    ) -> CameraSpec:
        """A camera at ``eye_m`` looking at ``target_m`` (world frame, metres)."""
        eye_m, target_m = _vec("eye_m", eye_m, 3), _vec("target_m", target_m, 3)
        if np.linalg.norm(np.subtract(eye_m, target_m)) < 1e-6:
            raise InvalidScene(f"eye_m and target_m must differ; both are {eye_m}")
        quat = look_at_quat_wxyz(np.asarray(eye_m), np.asarray(target_m), up)
        return cls(name, intrinsics, tuple(map(float, eye_m)), tuple(map(float, quat)))


def _spherical_eye(target, distance_m, azimuth_deg, elevation_deg) -> np.ndarray:
    az, el = np.deg2rad(azimuth_deg), np.deg2rad(elevation_deg)
    offset = distance_m * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return np.asarray(target, dtype=np.float64) + offset


def third_person_camera(
    intrinsics: CameraIntrinsics | None = None,
    *,
    name: str = "third_person",
    target_m: tuple[float, float, float] = _DEFAULT_HAND_TARGET,
    distance_m: float = 0.6,
    azimuth_deg: float = 90.0,
    elevation_deg: float = 30.0,
) -> CameraSpec:
    """A sensor facing the user across the table (azimuth 90 deg = on the ``+y`` side).

    Args:
        intrinsics: default: the NYU Carmine preset.
        name: camera name.
        target_m: point looked at, world, metres.
        distance_m: distance from the target, metres.
        azimuth_deg: direction of the camera from the target in the table plane, from ``+x``.
        elevation_deg: angle above the table plane.
    """
    intrinsics = _intrinsics(intrinsics, "nyu_carmine")
    target_m = _vec("target_m", target_m, 3)
    distance_m = real_scalar(
        "distance_m", distance_m, InvalidScene, lo=0.0, hi=_MAX_DIST_M, lo_open=True, unit="m"
    )
    azimuth_deg = real_scalar("azimuth_deg", azimuth_deg, InvalidScene, lo=-720.0, hi=720.0)
    elevation_deg = real_scalar(
        "elevation_deg", elevation_deg, InvalidScene, lo=-90.0, hi=90.0, lo_open=True, hi_open=True
    )
    eye = _spherical_eye(target_m, distance_m, azimuth_deg, elevation_deg)
    return CameraSpec.look_at(name, intrinsics, tuple(eye), target_m)


def egocentric_camera(
    intrinsics: CameraIntrinsics | None = None,
    *,
    name: str = "egocentric",
    target_m: tuple[float, float, float] = _DEFAULT_HAND_TARGET,
    head_offset_m: tuple[float, float, float] = (0.0, -0.35, 0.45),
) -> CameraSpec:
    """A head-mounted sensor: above and behind the hands (user side), looking down at them.

    Args:
        intrinsics: default: the SR300 preset (as in egocentric datasets like FPHA).
        name: camera name.
        target_m: point looked at (the hands), world, metres.
        head_offset_m: head position relative to the target, metres.
    """
    intrinsics = _intrinsics(intrinsics, "sr300")
    target_m = _vec("target_m", target_m, 3)
    head_offset_m = _vec("head_offset_m", head_offset_m, 3)
    eye = np.asarray(target_m) + np.asarray(head_offset_m)
    return CameraSpec.look_at(name, intrinsics, tuple(eye), target_m, up=(0.0, 1.0, 0.0))


def sample_viewpoint(
    rng: np.random.Generator,
    intrinsics: CameraIntrinsics | None = None,
    *,
    name: str = "random_view",
    target_m: tuple[float, float, float] = _DEFAULT_HAND_TARGET,
    distance_range_m: tuple[float, float] = (0.4, 0.8),
    azimuth_range_deg: tuple[float, float] = (0.0, 360.0),
    elevation_range_deg: tuple[float, float] = (15.0, 75.0),
    target_jitter_m: float = 0.02,
) -> CameraSpec:
    """A seeded random viewpoint on a spherical shell around the hand.

    Args:
        rng: random generator.
        intrinsics: default: the NYU Carmine preset.
        name: camera name.
        target_m: centre of the shell, world, metres.
        distance_range_m: camera distance range, metres.
        azimuth_range_deg: azimuth range, degrees from ``+x``.
        elevation_range_deg: elevation range above the table plane, degrees (< 90).
        target_jitter_m: the look-at point is jittered uniformly by up to this, metres.

    Raises:
        InvalidScene: for empty or out-of-range intervals.
    """
    if not isinstance(rng, np.random.Generator):
        raise InvalidScene(f"rng must be a numpy.random.Generator; received {show(rng)}")
    intrinsics = _intrinsics(intrinsics, "nyu_carmine")
    target_m = _vec("target_m", target_m, 3)
    distance_range_m = _pair("distance_range_m", distance_range_m, _MAX_DIST_M)
    azimuth_range_deg = _pair("azimuth_range_deg", azimuth_range_deg, 720.0)
    elevation_range_deg = _pair("elevation_range_deg", elevation_range_deg, 90.0)
    target_jitter_m = real_scalar(
        "target_jitter_m", target_jitter_m, InvalidScene, lo=0.0, hi=_MAX_DIST_M, unit="m"
    )
    for label, (lo, hi) in (
        ("distance_range_m", distance_range_m),
        ("azimuth_range_deg", azimuth_range_deg),
        ("elevation_range_deg", elevation_range_deg),
    ):
        if not lo <= hi:
            raise InvalidScene(f"{label} must be (low, high) with low <= high; received {(lo, hi)}")
    if distance_range_m[0] <= 0 or not -90 < elevation_range_deg[0] <= elevation_range_deg[1] < 90:
        raise InvalidScene(
            "distances must be > 0 m and elevations inside (-90, 90) deg; received "
            f"{distance_range_m}, {elevation_range_deg}"
        )
    intrinsics = intrinsics or camera_preset("nyu_carmine")
    target = np.asarray(target_m) + rng.uniform(-target_jitter_m, target_jitter_m, 3)
    eye = _spherical_eye(
        target,
        rng.uniform(*distance_range_m),
        rng.uniform(*azimuth_range_deg),
        rng.uniform(*elevation_range_deg),
    )
    return CameraSpec.look_at(name, intrinsics, tuple(eye), tuple(target))


def _footprint_radius(obj: YCBObject) -> float:
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, np.asarray(obj.rest_quat_wxyz, dtype=np.float64))
    rested = obj.visual_mesh.vertices @ rot.reshape(3, 3).T
    return float(np.linalg.norm(rested[:, :2], axis=1).max())


def sample_placements(
    rng: np.random.Generator,
    names: list[str] | tuple[str, ...],
    *,
    region_m: tuple[tuple[float, float], tuple[float, float]] = ((-0.25, 0.25), (-0.1, 0.25)),
    gap_m: float = 0.01,
    max_tries: int = 2000,
) -> tuple[ObjectPlacement, ...]:
    """Stable, non-overlapping placements of objects on the table top.

    Each object rests in its stable orientation (``YCBObject.rest_quat_wxyz``), turned by a
    uniform yaw, at a uniform position in ``region_m``; footprints (circles around the object
    origin that enclose its rested outline) keep ``gap_m`` apart.

    Args:
        rng: random generator.
        names: object names (repeats make several instances).
        region_m: ((x_min, x_max), (y_min, y_max)) area for object origins, metres.
        gap_m: minimum clearance between footprints, metres.
        max_tries: attempts per object before giving up.

    Returns:
        One placement per name, in order.

    Raises:
        UnknownName: for an unknown object name.
        InvalidScene: if the objects do not fit in the region.
    """
    if not isinstance(rng, np.random.Generator):
        raise InvalidScene(f"rng must be a numpy.random.Generator; received {show(rng)}")
    if isinstance(names, str) or not isinstance(names, (list, tuple)):
        raise InvalidScene(f"names must be a list or tuple of object names; received {show(names)}")
    for name in names:
        _check_name("names[i]", name)
    region = real_array("region_m", region_m, InvalidScene, shape=(2, 2), max_abs=_MAX_DIST_M)
    if not np.all(region[:, 0] <= region[:, 1]):
        raise InvalidScene(
            f"region_m must be ((x_min, x_max), (y_min, y_max)) with min <= max; received "
            f"{show(region_m)}"
        )
    gap_m = real_scalar("gap_m", gap_m, InvalidScene, lo=0.0, hi=_MAX_DIST_M, unit="m")
    max_tries = integer("max_tries", max_tries, InvalidScene, lo=1, hi=1_000_000)
    placed: list[tuple[np.ndarray, float]] = []
    placements = []
    (x0, x1), (y0, y1) = region.tolist()
    for name in names:
        obj = get_object(name)
        radius = _footprint_radius(obj)
        for _ in range(max_tries):
            xy = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
            if all(np.linalg.norm(xy - c) >= radius + r + gap_m for c, r in placed):
                break
        else:
            raise InvalidScene(
                f"could not place {name!r} (footprint radius {radius:.3f} m) without overlap in "
                f"region x {region_m[0]}, y {region_m[1]} m after {max_tries} tries; use fewer "
                "objects or a larger region"
            )
        placed.append((xy, radius))
        yaw = rng.uniform(-np.pi, np.pi)
        yaw_quat = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, yaw_quat, np.asarray(obj.rest_quat_wxyz, dtype=np.float64))
        # Lift by 0.5 mm so the first contact is not a penetration.
        pos = (float(xy[0]), float(xy[1]), float(obj.rest_height_m + 5e-4))
        placements.append(ObjectPlacement(obj.name, pos, tuple(map(float, quat))))
    return tuple(placements)


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """Everything a scene contains.

    Attributes:
        hand: the hand (``None`` for an object-only scene).
        objects: object instances on the table.
        cameras: depth cameras (at least one); names must be unique.
        table: add the table (top at ``z = 0``).
        background: what stands beyond the table (:data:`BACKGROUNDS`): ``"none"`` (no depth
            there), ``"wall"``, ``"torso"`` (the person's torso and head, a wall behind) or
            ``"clutter"`` (a cabinet, a desk with a monitor, a lamp; a wall behind).
            Its geoms are drawn only (no contact, no mass) and labelled ``"backdrop"``; it
            stands upright, facing the first camera beyond the table (and beyond anything a
            hand reaches over it), and :meth:`Scene.place_backdrop` moves it per frame.
        skin_lod: also build the skin's coarse level of detail (a hand with
            ``surface="skin"``): one more mesh geom per hand body, ``<side>_<body>_visual_1``
            in geom group :data:`SKIN_LOD_GROUP` (no camera draws it by default), which a
            :class:`~handsim.frame.FrameRenderer` draws instead of the skin for small projected
            hands. Drawn only (no contact, no mass): physics is the same without it.
    """

    hand: HandParams | None = dataclasses.field(default_factory=HandParams)
    objects: tuple[ObjectPlacement, ...] = ()
    cameras: tuple[CameraSpec, ...] = dataclasses.field(
        default_factory=lambda: (third_person_camera(),)
    )
    table: bool = True
    background: str = "none"
    skin_lod: bool = True

    def __post_init__(self) -> None:
        if self.hand is not None and not isinstance(self.hand, HandParams):
            raise InvalidScene(
                f"hand must be a HandParams or None (e.g. hand_params('medium')); received "
                f"{show(self.hand)}"
            )
        for field, kind in (("objects", ObjectPlacement), ("cameras", CameraSpec)):
            items = getattr(self, field)
            if isinstance(items, (str, bytes)) or not isinstance(items, (list, tuple)):
                raise InvalidScene(
                    f"{field} must be a tuple of {kind.__name__}; received {show(items)}"
                )
            if not all(isinstance(x, kind) for x in items):
                raise InvalidScene(
                    f"{field} must hold only {kind.__name__} instances; received {show(items)}"
                )
            object.__setattr__(self, field, tuple(items))
        boolean("table", self.table, InvalidScene)
        boolean("skin_lod", self.skin_lod, InvalidScene)
        if not isinstance(self.background, str) or self.background not in BACKGROUNDS:
            raise InvalidScene(
                f"background must be one of {', '.join(map(repr, BACKGROUNDS))}; received "
                f"{show(self.background)}"
            )
        if not self.cameras:
            raise InvalidScene("a scene needs at least one camera; received none")
        names = [c.name for c in self.cameras]
        if len(set(names)) != len(names):
            raise InvalidScene(f"camera names must be unique; received {names}")
        for placement in self.objects:
            placement.object  # noqa: B018 (raises UnknownName listing the valid names)


_MAX_DIST_M = 1000.0  # positions and distances beyond a kilometre are a mistake


def _check_name(label: str, name: object) -> None:
    if not isinstance(name, str) or not name:
        raise InvalidScene(f"{label} must be a non-empty str; received {show(name)}")


def _vec(label: str, value: object, n: int) -> tuple[float, ...]:
    arr = real_array(label, value, InvalidScene, shape=(n,), max_abs=_MAX_DIST_M, unit="m")
    return tuple(float(x) for x in arr)


def _quat(label: str, value: object) -> tuple[float, float, float, float]:
    arr = real_array(label, value, InvalidScene, shape=(4,), max_abs=1e6)
    if np.linalg.norm(arr) < 1e-9:
        raise InvalidScene(f"{label} must be a non-zero quaternion (w, x, y, z); got {value!r}")
    return tuple(float(x) for x in arr)  # type: ignore[return-value]


def _pair(label: str, value: object, bound: float) -> tuple[float, float]:
    arr = real_array(label, value, InvalidScene, shape=(2,), max_abs=bound)
    return float(arr[0]), float(arr[1])


def _intrinsics(value: object, default: str) -> CameraIntrinsics:
    if value is None:
        return camera_preset(default)
    if not isinstance(value, CameraIntrinsics):
        raise InvalidScene(
            f"intrinsics must be a CameraIntrinsics or None (e.g. camera_preset('icvl')); "
            f"received {show(value)}"
        )
    return value


def _add_coarse_skin(mj: mujoco.MjSpec, hand: Hand) -> None:
    """Add the skin's coarse level of detail to the hand attached to ``mj`` (drawn only)."""
    from handsim.hand.skin import build_skin

    full_rgba = mj.geom(f"{hand.prefix}palm_visual_0").rgba
    for part in build_skin(hand.params, "coarse"):
        name = f"{hand.prefix}{hand.skeleton.bodies[part.body].name}_visual_1"
        mj.add_mesh(name=name, uservert=part.vertices.ravel(), userface=part.faces.ravel())
        mj.body(f"{hand.prefix}{hand.skeleton.bodies[part.body].name}").add_geom(
            name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, group=SKIN_LOD_GROUP,
            contype=0, conaffinity=0, density=0.0, rgba=full_rgba,
        )  # fmt: skip


class Scene:
    """A compiled scene with its data.

    Args:
        spec: the scene description.

    Attributes:
        spec: the description.
        model: compiled MuJoCo model.
        data: its data (reset to the spec's placements and a flat hand at the default target).
        mjspec: the ``mujoco.MjSpec`` the model was compiled from (see :meth:`to_xml`).
        hand: the hand entity (``None`` without a hand).
        binding: the hand's look-ups in ``model`` (``None`` without a hand).
        objects: one ``(body name, YCBObject)`` per instance, in spec order.
        geom_labels: (ngeom,) int16 segmentation label of each geom (see module docstring).
    """

    def __init__(self, spec: SceneSpec) -> None:
        if not isinstance(spec, SceneSpec):
            raise InvalidScene(f"spec must be a SceneSpec; received {show(spec)}")
        self.spec = spec
        mj = mujoco.MjSpec()
        mj.modelname = "handsim_scene"
        mj.visual.global_.offwidth = max(c.intrinsics.width for c in spec.cameras)
        mj.visual.global_.offheight = max(c.intrinsics.height for c in spec.cameras)
        # Depth sensors do not antialias, and resolving a multisampled buffer costs a blit.
        mj.visual.quality.offsamples = 0
        mj.worldbody.add_light(name="key", pos=[0.3, -0.5, 1.2], dir=[-0.2, 0.4, -1.0])
        mj.worldbody.add_light(name="fill", pos=[-0.4, 0.3, 1.0], dir=[0.3, -0.2, -1.0])
        if spec.table:
            mj.worldbody.add_geom(
                name="table",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=_TABLE_HALF_SIZE_M,
                pos=[0.0, 0.0, -_TABLE_HALF_SIZE_M[2]],
                rgba=[0.55, 0.45, 0.35, 1.0],
                group=0,
            )
        if spec.background != "none":
            # Drawn only: no contact, no mass; moved with the body (place_backdrop).
            backdrop = mj.worldbody.add_body(name=_BACKDROP_BODY)
            for name, kind, size, pos in _BACKDROPS[spec.background]:
                backdrop.add_geom(
                    name=name, type=kind, size=size, pos=pos, contype=0, conaffinity=0,
                    density=0.0, group=0, rgba=[0.8, 0.8, 0.75, 1.0],
                )  # fmt: skip
        self.hand = Hand(spec.hand) if spec.hand is not None else None
        if self.hand is not None:
            self.hand.attach_to(mj)
            if spec.skin_lod and spec.hand.surface == "skin":
                _add_coarse_skin(mj, self.hand)
        else:
            for key, value in HAND_PHYSICS_OPTIONS.items():
                setattr(mj.option, key, value)
        self.objects: list[tuple[str, YCBObject]] = []
        counts: dict[str, int] = {}
        for placement in spec.objects:
            obj = placement.object
            k = counts.get(obj.name, 0)
            counts[obj.name] = k + 1
            body = obj.body_name if k == 0 else f"{obj.body_name}_{k}"
            add_object(mj, obj, pos=placement.pos_m, quat_wxyz=placement.quat_wxyz, body_name=body)
            self.objects.append((body, obj))
        for cam in spec.cameras:
            add_camera(mj.worldbody, cam.name, cam.intrinsics, cam.pos_m, cam.quat_wxyz)
        self.model = mj.compile()
        self.mjspec = mj
        self._set_clip_planes()
        self.data = mujoco.MjData(self.model)
        self.binding = self.hand.bind(self.model) if self.hand is not None else None
        self.geom_labels = self._label_geoms()
        self._hand_body_ids = np.array(
            []
            if self.hand is None
            else [self.model.body(self.hand.prefix + b.name).id for b in self.hand.skeleton.bodies],
            dtype=np.intp,
        )
        hand_geoms = np.isin(self.model.geom_bodyid, self._hand_body_ids)
        mesh_geoms = hand_geoms & (self.model.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
        self.hand_mesh_ids: tuple[int, ...] = tuple(
            int(m) for m in np.unique(self.model.geom_dataid[mesh_geoms])
        )
        """Meshes of the hand (its skin), for renderers to upload again after a rescale."""
        self.hand_skin_geom_ids: np.ndarray = np.flatnonzero(mesh_geoms)
        """The geoms that draw the hand's skin (those meshes), read-only."""
        self.hand_skin_geom_ids.setflags(write=False)
        self.skin_lod_geom_ids: tuple[np.ndarray, np.ndarray] | None = None
        """``(full, coarse)``: (n,) ids of the skin's geoms and of their coarse twins in the
        same order (the same bodies), or ``None`` without :attr:`SceneSpec.skin_lod`."""
        if self.hand is not None and spec.skin_lod and spec.hand.surface == "skin":
            full, coarse = [], []
            for b in self.hand.skeleton.bodies:
                name = self.hand.prefix + b.name
                full.append(self.model.geom(f"{name}_visual_0").id)
                coarse.append(self.model.geom(f"{name}_visual_1").id)
            self.skin_lod_geom_ids = (np.array(full), np.array(coarse))
            for ids in self.skin_lod_geom_ids:
                ids.setflags(write=False)
        self._built_hand_params = None if self.hand is None else self.hand.params
        self._built_hand_geometry: list | None = None
        self.hand_geometry_version = 0
        """Counts :meth:`set_hand_length` calls (renderers compare it to upload the skin)."""
        self.reset()

    def to_xml(self) -> str:
        """The MJCF text of the scene's model; object meshes are inline (vertex/face data).

        ``mujoco.MjModel.from_xml_string`` compiles it to a model equal to :attr:`model`
        (numbers at full precision, see :func:`handsim.world.mjcf.spec_to_xml`). The state is not
        part of it: objects start at their placements, the hand at the world origin (its
        ``qpos0``), not where :meth:`reset` puts it.

        Raises:
            InvalidScene: after :meth:`set_hand_length`.
        """
        self._check_not_rescaled("to_xml")
        return spec_to_xml(self.mjspec)

    def save(self, path: str | os.PathLike[str], *, assets_dir: str = "assets") -> pathlib.Path:
        """Write the scene as ``path`` plus its meshes as OBJ files in ``<assets_dir>/`` beside it.

        The XML compiles with ``mujoco.MjModel.from_xml_path(path)`` to a model equal to
        :attr:`model` and opens in ``python -m mujoco.viewer --mjcf <path>``.

        Args:
            path: the XML file to write (parent folders are created).
            assets_dir: mesh folder, relative to the XML file's folder.

        Returns:
            The path of the XML file.

        Raises:
            InvalidScene: after :meth:`set_hand_length`.
        """
        self._check_not_rescaled("save")
        return save_spec(self.mjspec, path, assets_dir=assets_dir)

    @property
    def built_hand_params(self) -> HandParams | None:
        """The hand parameters the model's hand (its meshes) was built with (``None``: none).

        :meth:`set_hand_length` scales that hand in place; :attr:`hand` then has the new
        parameters.
        """
        return self._built_hand_params

    @property
    def hand_rescaled(self) -> bool:
        """:meth:`set_hand_length` changed the hand from the one built: kinematic use only."""
        return self.hand is not None and self.hand.params != self._built_hand_params

    def _check_not_rescaled(self, what: str) -> None:
        if self.hand_rescaled:
            raise InvalidScene(
                f"{what}: the hand was rescaled in place with set_hand_length (kinematic use "
                f"only); build Scene(scene.spec) for a model of the hand at "
                f"{self.hand.params.hand_length} m"
            )

    def _set_clip_planes(self) -> None:
        # OpenGL clip planes from the cameras' working ranges, not from the model's extent
        # (MuJoCo's znear/zfar are fractions of it): the far plane is the farthest camera
        # range, so a far object is simply not seen. The near plane stays close to the lens
        # (clipping a too-near surface would reveal what is behind it); FrameRenderer drops
        # surfaces nearer than each camera's range instead.
        if not self.spec.cameras:
            return
        extent = self.model.stat.extent
        far_m = max(c.intrinsics.range_m[1] for c in self.spec.cameras)
        near_m = min(_GL_NEAR_M, *(c.intrinsics.range_m[0] for c in self.spec.cameras))
        self.model.vis.map.znear = near_m / extent
        self.model.vis.map.zfar = far_m / extent
        # The spec says the same, so its MJCF (to_xml, save) gives this model.
        self.mjspec.visual.map.znear = self.model.vis.map.znear
        self.mjspec.visual.map.zfar = self.model.vis.map.zfar

    def set_hand_length(self, hand_length_m: float) -> None:
        """Scale the hand in place to ``hand_length_m``: for kinematic use (posing, rendering).

        A hand of another length is the same hand scaled uniformly about its wrist (the palm
        breadth and every radius follow the length), so this rescales the compiled model's
        hand geometry: body and site positions, geom sizes and bounds, and the skin's mesh
        vertices. Keypoints, collision geoms and depth images are then those of a scene built
        for that length, up to the skin's triangulation (built on a fixed grid in metres, so a
        rescaled skin's triangles are scaled too). It costs about a millisecond, against tens
        of milliseconds for a new scene (and about 0.15 s for a new length's skin).

        Renderers made before the call draw the rescaled skin from their next frame on
        (:class:`~handsim.frame.FrameRenderer` does it itself, scaling the skin it uploaded
        as it draws; a bare :class:`~handsim.world.render.DepthRenderer` needs
        :meth:`~handsim.world.render.DepthRenderer.upload_meshes` with :attr:`hand_mesh_ids`,
        or :meth:`~handsim.world.render.DepthRenderer.scale_geoms`). Masses, inertias and
        actuator gains are not rescaled, so a rescaled scene cannot be simulated:
        :class:`~handsim.envs.physics.HandDriver` refuses it, and :meth:`to_xml` and
        :meth:`save` too (the ``MjSpec`` still holds the built length).

        Args:
            hand_length_m: the new hand length, metres (the range of
                :class:`~handsim.hand.model.HandParams`).

        Raises:
            InvalidScene: if the scene has no hand.
            InvalidHandParams: for a length outside the valid range.
        """
        if self.hand is None:
            raise InvalidScene("set_hand_length needs a scene with a hand; SceneSpec(hand=None)")
        built_params = self._built_hand_params  # every value from the built ones: no drift
        factor = float(hand_length_m) / built_params.hand_length if is_real(hand_length_m) else 1
        params = dataclasses.replace(
            built_params,
            hand_length=hand_length_m,  # validated here
            palm_breadth=None
            if built_params.palm_breadth is None
            else built_params.palm_breadth * factor,
        )
        if params == self.hand.params:
            return
        if self._built_hand_geometry is None:
            self._built_hand_geometry = self._hand_geometry()
        for name, rows, values in self._built_hand_geometry:
            np.multiply(values, factor, out=getattr(self.model, name)[rows])
        self.hand = self.hand.rescaled(params)
        self.binding.hand = self.hand
        self.spec = dataclasses.replace(self.spec, hand=params)
        self.hand_geometry_version += 1
        mujoco.mj_forward(self.model, self.data)

    def _hand_geometry(self) -> list[tuple[str, slice, np.ndarray]]:
        """``(model field, rows, built values)`` of what scales with the hand length."""
        model = self.model
        hand_bodies = np.zeros(model.nbody, dtype=bool)
        hand_bodies[self._hand_body_ids] = True
        geoms = np.flatnonzero(hand_bodies[model.geom_bodyid])
        bvh = [
            np.arange(adr, adr + num)
            for adr, num in [
                *((model.body_bvhadr[b], model.body_bvhnum[b]) for b in self._hand_body_ids),
                *((model.mesh_bvhadr[m], model.mesh_bvhnum[m]) for m in self.hand_mesh_ids),
            ]
            if adr >= 0
        ]
        verts = [
            np.arange(model.mesh_vertadr[m], model.mesh_vertadr[m] + model.mesh_vertnum[m])
            for m in self.hand_mesh_ids
        ]
        rows = {
            "body_pos": self._hand_body_ids[1:],  # the root's position is the wrist pose (qpos)
            "geom_pos": geoms,
            "geom_size": geoms,
            "geom_rbound": geoms,
            "geom_aabb": geoms,
            "site_pos": np.flatnonzero(hand_bodies[model.site_bodyid]),
            "bvh_aabb": np.concatenate(bvh) if bvh else np.zeros(0, dtype=np.intp),
            "mesh_vert": np.concatenate(verts) if verts else np.zeros(0, dtype=np.intp),
        }
        # Contiguous runs of rows as slices: views to scale into in place (the skin's meshes
        # and their bounding-volume hierarchies are long runs; fancy indexing cost ~1.8 ms).
        out = []
        for name, index in rows.items():
            index = np.sort(index)
            breaks = np.flatnonzero(np.diff(index) != 1) + 1
            for run in np.split(index, breaks) if index.size else []:
                rows_run = slice(int(run[0]), int(run[-1]) + 1)
                out.append((name, rows_run, getattr(model, name)[rows_run].copy()))
        return out

    def _label_geoms(self) -> np.ndarray:
        labels = np.zeros(self.model.ngeom, dtype=np.int16)
        body_label = {}
        if self.hand is not None:
            for b in self.hand.skeleton.bodies:
                body_id = self.model.body(self.hand.prefix + b.name).id
                body_label[body_id] = SEGMENT_LABELS.index(b.part)
        for k, (body, _) in enumerate(self.objects):
            body_label[self.model.body(body).id] = OBJECT_LABEL_OFFSET + k
        p = "" if self.hand is None else self.hand.prefix
        arm = () if self.hand is None else (p + FOREARM_GEOM, p + UPPER_ARM_GEOM)
        for g in range(self.model.ngeom):
            name = self.model.geom(g).name
            if name == "table":
                labels[g] = SEGMENT_LABELS.index("table")
            elif name in arm:
                labels[g] = SEGMENT_LABELS.index("arm")
            elif name.startswith(_BACKDROP_PREFIX):
                labels[g] = SEGMENT_LABELS.index("backdrop")
            else:
                labels[g] = body_label.get(int(self.model.geom_bodyid[g]), 0)
        return labels

    def place_backdrop(
        self, eye_m: np.ndarray, target_m: np.ndarray, distance_m: float, *, forward: bool = True
    ) -> None:
        """Stand the backdrop upright, facing a camera, ``distance_m`` beyond it.

        Its front is the vertical plane at horizontal distance ``distance_m`` from ``eye_m``
        along the horizontal direction to ``target_m``, and all of it lies behind that plane:
        a surface nearer than ``distance_m`` along that direction is never hidden by it (along
        any ray of the camera the horizontal distance grows). Centred on the line of sight. No
        effect without a background.

        Args:
            eye_m: (3,) camera position, world, metres.
            target_m: (3,) a point the camera looks at, world, metres.
            distance_m: horizontal distance of the front plane from the eye, metres.
            forward: also update the data's geom poses (``mj_kinematics``); False leaves that
                to the caller's next forward.
        """
        if self.spec.background == "none":
            return
        eye = np.asarray(eye_m, dtype=np.float64)
        ahead = np.asarray(target_m, dtype=np.float64) - eye
        ahead[2] = 0.0
        norm = float(np.linalg.norm(ahead))
        # A camera looking straight down: any horizontal direction (the wall is out of view).
        ahead = ahead / norm if norm > 1e-9 else np.array([0.0, 1.0, 0.0])
        body = self.model.body(_BACKDROP_BODY).id
        front = eye + ahead * float(distance_m)
        self.model.body_pos[body] = (front[0], front[1], 0.0)
        yaw = np.arctan2(-ahead[1], -ahead[0])  # body +x toward the camera
        self.model.body_quat[body] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
        if forward:
            mujoco.mj_kinematics(self.model, self.data)

    def _place_default_backdrop(self) -> None:
        # Facing the first camera, beyond the table's farthest corner (or the hand's default
        # target) by what a hand and forearm reach past it.
        cam = self.spec.cameras[0]
        eye = np.asarray(cam.pos_m)
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, np.asarray(cam.quat_wxyz))
        ahead = -rot.reshape(3, 3)[:, 2]  # a MuJoCo camera looks along its -z
        ahead[2] = 0.0
        ahead = ahead / max(float(np.linalg.norm(ahead)), 1e-9)
        hx, hy, _ = _TABLE_HALF_SIZE_M
        corners = np.array([(x, y, 0.0) for x in (-hx, hx) for y in (-hy, hy)])
        points = np.vstack([corners, _DEFAULT_HAND_TARGET])
        far = float(((points - eye) @ ahead).max())
        self.place_backdrop(eye, eye + ahead, far + _BACKDROP_REACH_M, forward=False)

    def reset(self, hand_pose: HandPose | None = None) -> None:
        """Reset the data: objects at their placements, hand at ``hand_pose``.

        Args:
            hand_pose: default: a flat hand, palm down, above the table centre.
        """
        mujoco.mj_resetData(self.model, self.data)
        self._place_default_backdrop()
        if self.binding is not None:
            if hand_pose is None:
                # Palm down (hand z = palmar -> world -z), fingers toward +y.
                hand_pose = HandPose.neutral(
                    wrist_pos=(0.0, -0.1, 0.12), wrist_rotvec=(0.0, np.pi, 0.0)
                )
            self.binding.set_pose(self.data, hand_pose)
        mujoco.mj_forward(self.model, self.data)

    def segment(self, geom_id: np.ndarray) -> np.ndarray:
        """Map a geom-id image (from :class:`~handsim.world.render.DepthRenderer`) to labels.

        Args:
            geom_id: (H, W) int geom ids, -1 = background.

        Returns:
            (H, W) int16 segmentation labels (module docstring).
        """
        lut = np.concatenate([[0], self.geom_labels]).astype(np.int16)
        return lut[np.asarray(geom_id) + 1]

    def camera(self, name: str) -> CameraSpec:
        """The spec of a camera by name.

        Raises:
            InvalidScene: listing the scene's cameras.
        """
        for cam in self.spec.cameras:
            if cam.name == name:
                return cam
        raise InvalidScene(
            f"no camera {name!r} in this scene; cameras: "
            f"{', '.join(c.name for c in self.spec.cameras)}"
        )
