"""Scene descriptions: what a scene holds (frozen dataclasses), and seeded layouts of it.

World frame: ``z`` up, origin at the centre of the table top; the user sits on the ``-y`` side.

A :class:`SceneSpec` describes a scene (its hands, objects, cameras, table and background);
:class:`~handsim.world.scene.Scene` compiles it. Placements come from :func:`sample_placements`
(stable resting poses, random yaw, non-overlapping footprints); cameras from
:func:`third_person_camera`, :func:`egocentric_camera` or the seeded :func:`sample_viewpoint`.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from handsim._validate import boolean, integer, real_array, real_scalar, show
from handsim.errors import HandSimError
from handsim.hand.skeleton import HandParams
from handsim.world.camera import CameraIntrinsics, camera_preset, look_at_quat_wxyz
from handsim.world.objects import YCBObject
from handsim.world.registry import get_object

__all__ = [
    "BACKGROUNDS",
    "DEFAULT_HAND_TARGET_M",
    "ObjectPlacement",
    "CameraSpec",
    "SceneSpec",
    "InvalidScene",
    "third_person_camera",
    "egocentric_camera",
    "sample_viewpoint",
    "sample_placements",
]

BACKGROUNDS: tuple[str, ...] = ("none", "wall", "torso", "clutter")
"""What stands beyond the table (:attr:`SceneSpec.background`): nothing (no depth), a wall, the
person's torso and head in front of a wall, or furniture in front of a wall."""

DEFAULT_HAND_TARGET_M = (0.0, 0.0, 0.12)
"""Where the cameras look by default and the hand starts: above the table centre, metres."""
_DEFAULT_HAND_TARGET = DEFAULT_HAND_TARGET_M


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
        hand: the hand (``None`` for an object-only scene); with :attr:`hands`, the first of
            them (set from it).
        objects: object instances on the table.
        cameras: depth cameras (at least one); names must be unique.
        table: add the table (top at ``z = 0``).
        background: what stands beyond the table (:data:`BACKGROUNDS`): ``"none"`` (no depth
            there), ``"wall"``, ``"torso"`` (the person's torso and head, a wall behind) or
            ``"clutter"`` (a cabinet, a desk with a monitor, a lamp; a wall behind).
            Its geoms are drawn only (no contact, no mass) and labelled ``"backdrop"``; it
            stands upright, facing the first camera beyond the table (and beyond anything a
            hand reaches over it), and :meth:`Scene.place_backdrop` moves it per frame.
        hands: two hands at once (or one), e.g. ``(hand_params("medium", "right"),
            hand_params("medium", "left"))``: one of each side at most (every MJCF name of a
            hand carries its side's prefix, ``rh_`` or ``lh_``, so they stay unique). The
            first is :attr:`hand`, the hand a :class:`~handsim.frame.record.Frame` labels. ``None``
            (default): the one hand of :attr:`hand`.
        skin_lod: also build the skin's coarse level of detail (default: no; each hand with
            ``surface="skin"``): one more mesh geom per hand body, ``<side>_<body>_visual_1``
            in geom group :data:`~handsim.world.scene.SKIN_LOD_GROUP` (no camera draws it by
            default), which a :class:`~handsim.frame.renderer.FrameRenderer` draws instead of the
            skin for small projected hands. Drawn only (no contact, no mass): physics is the same
            without it.
    """

    hand: HandParams | None = dataclasses.field(default_factory=HandParams)
    objects: tuple[ObjectPlacement, ...] = ()
    cameras: tuple[CameraSpec, ...] = dataclasses.field(
        default_factory=lambda: (third_person_camera(),)
    )
    table: bool = True
    background: str = "none"
    hands: tuple[HandParams, ...] | None = None
    skin_lod: bool = False

    def __post_init__(self) -> None:
        if self.hand is not None and not isinstance(self.hand, HandParams):
            raise InvalidScene(
                f"hand must be a HandParams or None (e.g. hand_params('medium')); received "
                f"{show(self.hand)}"
            )
        if self.hands is not None:
            self._set_hands()
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

    def _set_hands(self) -> None:
        hands = self.hands
        example = "e.g. (hand_params('medium', 'right'), hand_params('medium', 'left'))"
        if (
            isinstance(hands, (str, bytes))
            or not isinstance(hands, (list, tuple))
            or not 1 <= len(hands) <= 2
            or not all(isinstance(h, HandParams) for h in hands)
        ):
            raise InvalidScene(
                f"hands must be a tuple of one or two HandParams ({example}) or None; received "
                f"{show(hands)}"
            )
        sides = [h.side for h in hands]
        if len(set(sides)) != len(sides):
            raise InvalidScene(
                f"hands must be of different sides (one right, one left: each hand's MJCF "
                f"names carry its side's prefix); received sides {sides}"
            )
        # hand= is the first of hands=: left at its default (or None) it is set from them.
        if self.hand not in (None, HandParams(), hands[0]):
            raise InvalidScene(
                f"hand={show(self.hand)} disagrees with hands[0]={show(hands[0])}: give the "
                "hands with hands= alone (hand is set to hands[0])"
            )
        object.__setattr__(self, "hands", tuple(hands))
        object.__setattr__(self, "hand", hands[0])

    @property
    def all_hands(self) -> tuple[HandParams, ...]:
        """Every hand of the scene, first :attr:`hand` (empty without a hand)."""
        if self.hands is not None:
            return self.hands
        return () if self.hand is None else (self.hand,)


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
