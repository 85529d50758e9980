"""Scenes compiled with MjSpec: a table, lights, one or two hands, YCB-like objects, cameras.

World frame: ``z`` up, origin at the centre of the table top; the user sits on the ``-y`` side.

A :class:`~handsim.world.scene_spec.SceneSpec` (frozen dataclasses, with the seeded layouts
:func:`sample_placements` and :func:`sample_viewpoint`; re-exported here) describes the scene;
:class:`Scene` compiles it and keeps the model, its data, the hand bindings and the
segmentation labels.

Segmentation labels (:data:`SEGMENT_LABELS`): 0 background (no surface), 1 table, 2 backdrop
(:attr:`SceneSpec.background`), 3 arm (the forearm beyond the palm's stub, and the upper
arm), 4 palm (with the forearm stub), 5 thumb,
6 index, 7 middle, 8 ring, 9 little, and ``10 + k`` (:data:`OBJECT_LABEL_OFFSET` ``+ k``) for
object instance ``k`` in the order of :attr:`SceneSpec.objects`. The hand's labels are
``palm`` up to the objects' (the forearm is not the hand). These are the first hand's
(:attr:`Scene.hand`); in a two-hand scene the second hand's parts follow the objects, in the
same order (``arm``, ``palm``, ``thumb`` ... ``little``), named ``<side>_<part>`` (e.g.
``left_palm``) in :attr:`Scene.label_names`: so a frame of the first hand keeps every label
it has in a one-hand scene, and the other hand is never mistaken for it. Read them by name
with :meth:`Scene.label`.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib

import mujoco
import numpy as np

from handsim._validate import is_real, show
from handsim.hand.model import (
    FOREARM_GEOM,
    HAND_PHYSICS_OPTIONS,
    UPPER_ARM_GEOM,
    Hand,
    HandBinding,
    HandParams,
)
from handsim.hand.pose import DIGITS, HandPose
from handsim.world.camera import add_camera
from handsim.world.mjcf import save_spec, spec_to_xml
from handsim.world.objects import YCBObject, add_object

# The description's names are re-exported (``from handsim.world.scene import SceneSpec``) and
# documented where they are defined, in scene_spec.
from handsim.world.scene_spec import (
    BACKGROUNDS,  # noqa: F401
    DEFAULT_HAND_TARGET_M,
    CameraSpec,
    InvalidScene,
    ObjectPlacement,  # noqa: F401
    SceneSpec,
    egocentric_camera,  # noqa: F401
    sample_placements,  # noqa: F401
    sample_viewpoint,  # noqa: F401
    third_person_camera,  # noqa: F401
)

__all__ = [
    "SEGMENT_LABELS",
    "OBJECT_LABEL_OFFSET",
    "HAND_PART_LABELS",
    "SKIN_LOD_GROUP",
    "Scene",
]

SEGMENT_LABELS: tuple[str, ...] = ("background", "table", "backdrop", "arm", "palm", *DIGITS)
"""Names of the fixed segmentation labels; objects follow from :data:`OBJECT_LABEL_OFFSET`."""
OBJECT_LABEL_OFFSET = len(SEGMENT_LABELS)
HAND_PART_LABELS: tuple[str, ...] = ("arm", "palm", *DIGITS)
"""The labels a hand's geoms carry (each hand after the first gets its own copy of them)."""
SKIN_LOD_GROUP = 4
"""Geom group of the skin's coarse level of detail (:attr:`SceneSpec.skin_lod`); cameras draw
groups 0 to 2, so only a renderer that swaps it in for the skin shows it."""

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
_DEFAULT_HAND_TARGET = DEFAULT_HAND_TARGET_M
# OpenGL near clip plane, metres: well inside every sensor's minimum range.
_GL_NEAR_M = 0.01


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
        hand: the hand entity (``None`` without a hand); in a two-hand scene the first of
            :attr:`hands`.
        binding: the hand's look-ups in ``model`` (``None`` without a hand).
        hands: every hand entity, in :attr:`SceneSpec.all_hands` order (empty without one).
        bindings: their look-ups in ``model``, in the same order.
        objects: one ``(body name, YCBObject)`` per instance, in spec order.
        geom_labels: (ngeom,) int16 segmentation label of each geom (see module docstring).
        label_names: the name of every label in use, indexed by label: :data:`SEGMENT_LABELS`,
            the objects' body names, then ``<side>_<part>`` for a second hand's parts.
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
        self.hands: tuple[Hand, ...] = tuple(Hand(p) for p in spec.all_hands)
        self.hand = self.hands[0] if self.hands else None
        for hand in self.hands:
            hand.attach_to(mj)
            if spec.skin_lod and hand.params.surface == "skin":
                _add_coarse_skin(mj, hand)
        if not self.hands:
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
        self._bind_hands()
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
        same order (the same bodies; every hand's), or ``None`` without
        :attr:`SceneSpec.skin_lod`."""
        lod_hands = [h for h in self.hands if spec.skin_lod and h.params.surface == "skin"]
        if lod_hands:
            full, coarse = [], []
            for hand in lod_hands:
                for b in hand.skeleton.bodies:
                    name = hand.prefix + b.name
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
        (:class:`~handsim.frame.renderer.FrameRenderer` does it itself, scaling the skin it uploaded
        as it draws; a bare :class:`~handsim.world.render.DepthRenderer` needs
        :meth:`~handsim.world.render.DepthRenderer.upload_meshes` with :attr:`hand_mesh_ids`,
        or :meth:`~handsim.world.render.DepthRenderer.scale_geoms`). Masses, inertias and
        actuator gains are not rescaled, so a rescaled scene cannot be simulated:
        :class:`~handsim.envs.physics.HandDriver` refuses it, and :meth:`to_xml` and
        :meth:`save` too (the ``MjSpec`` still holds the built length).

        Args:
            hand_length_m: the new hand length, metres (the range of
                :class:`~handsim.hand.skeleton.HandParams`).

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
        self.hands = (self.hand, *self.hands[1:])
        hands = None if self.spec.hands is None else (params, *self.spec.hands[1:])
        self.spec = dataclasses.replace(self.spec, hand=params, hands=hands)
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

    def _bind_hands(self) -> None:
        """Look the hands up in :attr:`model` and label its geoms (after every compile)."""
        self.bindings: tuple[HandBinding, ...] = tuple(h.bind(self.model) for h in self.hands)
        self.binding = self.bindings[0] if self.bindings else None
        self.geom_labels = self._label_geoms()

    def recompile(self) -> None:
        """Compile :attr:`mjspec` again after adding to it (a task's fixtures), with new data.

        The cameras keep the model's current placement; the hands are bound and the geoms
        labelled again (a geom added after the objects is labelled 0 unless its task labels it).
        """
        cam = (self.model.cam_pos.copy(), self.model.cam_quat.copy())
        self.model = self.mjspec.compile()
        self._set_clip_planes()
        self.model.cam_pos[:], self.model.cam_quat[:] = cam
        self.data = mujoco.MjData(self.model)
        self._bind_hands()

    def _label_geoms(self) -> np.ndarray:
        labels = np.zeros(self.model.ngeom, dtype=np.int16)
        body_label = {}
        arm: dict[str, int] = {}
        names = list(SEGMENT_LABELS) + [body for body, _ in self.objects]
        for i, hand in enumerate(self.hands):
            if i == 0:
                part_label = {p: SEGMENT_LABELS.index(p) for p in HAND_PART_LABELS}
            else:
                # A second hand's parts follow the objects: the first hand's labels (and a
                # frame's) stay those of a one-hand scene.
                part_label = {p: len(names) + k for k, p in enumerate(HAND_PART_LABELS)}
                names += [f"{hand.params.side}_{p}" for p in HAND_PART_LABELS]
            for b in hand.skeleton.bodies:
                body_label[self.model.body(hand.prefix + b.name).id] = part_label[b.part]
            for geom in (FOREARM_GEOM, UPPER_ARM_GEOM):
                arm[hand.prefix + geom] = part_label["arm"]
        for k, (body, _) in enumerate(self.objects):
            body_label[self.model.body(body).id] = OBJECT_LABEL_OFFSET + k
        self.label_names: tuple[str, ...] = tuple(names)
        for g in range(self.model.ngeom):
            name = self.model.geom(g).name
            if name == "table":
                labels[g] = SEGMENT_LABELS.index("table")
            elif name in arm:
                labels[g] = arm[name]
            elif name.startswith(_BACKDROP_PREFIX):
                labels[g] = SEGMENT_LABELS.index("backdrop")
            else:
                labels[g] = body_label.get(int(self.model.geom_bodyid[g]), 0)
        return labels

    def label(self, name: str) -> int:
        """The segmentation label called ``name`` in :attr:`label_names` (e.g. ``"left_palm"``).

        Raises:
            InvalidScene: for a name not in this scene, listing the names.
        """
        if name not in self.label_names:
            raise InvalidScene(
                f"no segmentation label {name!r} in this scene; labels: "
                f"{', '.join(self.label_names)}"
            )
        return self.label_names.index(name)

    def hand_binding(self, side: str) -> HandBinding:
        """The binding of the scene's hand of ``side`` (``"right"`` or ``"left"``).

        Raises:
            InvalidScene: if the scene has no hand of that side, listing its hands.
        """
        for binding in self.bindings:
            if binding.hand.params.side == side:
                return binding
        have = ", ".join(b.hand.params.side for b in self.bindings) or "none"
        raise InvalidScene(
            f"this scene has no {side!r} hand; its hands: {have} (two hands: "
            "SceneSpec(hands=(hand_params('medium', 'right'), hand_params('medium', 'left'))))"
        )

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

    def reset(
        self, hand_pose: HandPose | None = None, *, other_pose: HandPose | None = None
    ) -> None:
        """Reset the data: objects at their placements, hand at ``hand_pose``.

        Args:
            hand_pose: the (first) hand's pose; default: a flat hand, palm down, above the
                table centre (two hands: each 12 cm to its own side of it).
            other_pose: a second hand's pose (same default).
        """
        mujoco.mj_resetData(self.model, self.data)
        self._place_default_backdrop()
        two = len(self.bindings) == 2
        for binding, pose in zip(self.bindings, (hand_pose, other_pose), strict=False):
            if pose is None:
                # Palm down (hand z = palmar -> world -z), fingers toward +y; two hands apart.
                x = (0.12 if binding.hand.params.side == "right" else -0.12) if two else 0.0
                pose = HandPose.neutral(wrist_pos=(x, -0.1, 0.12), wrist_rotvec=(0.0, np.pi, 0.0))
            binding.set_pose(self.data, pose)
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
