"""The MJCF hand: :class:`Hand` builds a hand's ``mujoco.MjSpec``, :class:`HandBinding` drives it.

The hand is made from the kinematic skeleton of :mod:`handsim.hand.skeleton`
(:class:`~handsim.hand.skeleton.HandParams`: size, handedness, palm breadth, thickness, forearm
stub, DIP coupling; :func:`~handsim.hand.skeleton.build_skeleton`), from which the NumPy forward
kinematics (:mod:`handsim.hand.kinematics`) is made too, so the two cannot drift apart. The
skeleton's names are importable from here as well.

Naming scheme (``<side>`` is ``rh`` or ``lh``; ``<digit>`` is thumb, index, middle, ring, little):

==================  ===========================================  ==========================
element             name                                         example
==================  ===========================================  ==========================
root body           ``<side>_palm``                              ``rh_palm``
free joint          ``<side>_root``                              ``rh_root``
mocap body          ``<side>_mocap``                             ``rh_mocap``
wrist weld          ``<side>_root_weld``                         ``rh_root_weld``
digit bodies        ``<side>_<digit>_<segment>``                 ``rh_index_proximal``
hinge joints        ``<side>_<joint>`` (:data:`JOINT_NAMES`)     ``rh_index_mcp_flex``
actuators           ``<side>_<joint>_act``                       ``rh_index_mcp_flex_act``
keypoint sites      ``<side>_kp_<keypoint>``                     ``rh_kp_index_tip``
collision geoms     ``<side>_<part>_collision_<n>``              ``rh_index_distal_collision_0``
visual geoms        ``<side>_<part>_visual_<n>``                 ``rh_palm_visual_0``
forearm (drawn)     ``<side>_forearm_visual_0`` (palm body)      ``rh_forearm_visual_0``
upper arm (drawn)   ``<side>_upper_arm_visual_0`` (palm body)    ``rh_upper_arm_visual_0``
default classes     ``<side>_hand``, ``<side>_collision``, ...   ``rh_visual``
==================  ===========================================  ==========================

Visual geoms: with ``HandParams.surface == "skin"`` (default) one mesh per body,
``<side>_<body>_visual_0`` (mesh of the same name, :mod:`handsim.hand.skin`); with
``"capsules"`` a copy of each collision primitive.

Geom groups: visual geoms are group 2 (``contype = conaffinity = 0``; what cameras render);
collision geoms are group 3 (hidden from cameras by default; they carry the mass). Fingertip
(distal) collision geoms use ``condim = 4`` for torsional friction.

Control: the free root follows the mocap body through a soft weld (a physics hand that cannot
pass through objects); the 21 articulations have position actuators (``ctrl`` in radians).
Gains are set per joint so that a step reaches 95 % within 60 ms without overshoot: each joint
gets a stiffness ``kp`` (N m/rad, :data:`ACTUATOR_GAINS`), and an armature that brings its
effective inertia to ``kp / omega**2`` with ``omega`` = :data:`FINGER_OMEGA` rad/s, and critical
damping ``kv = 2 sqrt(kp I)``. Torques are limited to human ranges (``forcerange``).
"""

from __future__ import annotations

import copy
import dataclasses
import os
import pathlib

import mujoco
import numpy as np

from handsim._validate import show
from handsim.errors import InvalidHandParams, UnknownName
from handsim.hand.keypoints import EXTRA_POINT_NAMES, KEYPOINT_NAMES
from handsim.hand.pose import FINGERS, JOINT_LIMITS, JOINT_NAMES, HandPose, InvalidPose
from handsim.hand.skeleton import (
    HAND_LENGTH_RANGE_M as HAND_LENGTH_RANGE_M,
)
from handsim.hand.skeleton import (
    HAND_SIZES,
    Box,
    Capsule,
    HandParams,
    Skeleton,
    SkeletonBody,
    build_skeleton,
    extra_point_positions,
    hand_params,
)
from handsim.hand.skin import (
    ELBOW_RATIO,
    UPPER_ARM_RATIOS,
    build_skin,
    forearm_extension,
)

__all__ = [
    "HandParams",
    "HAND_SIZES",
    "Skeleton",
    "SkeletonBody",
    "Capsule",
    "Box",
    "build_skeleton",
    "Hand",
    "HandBinding",
    "ACTUATOR_GAINS",
    "FINGER_OMEGA",
    "HAND_PHYSICS_OPTIONS",
    "hand_params",
    "FOREARM_GEOM",
    "UPPER_ARM_GEOM",
]

_SKIN_RGBA = (0.87, 0.72, 0.63, 1.0)
FOREARM_GEOM = "forearm_visual_0"
"""Name (after the side prefix: ``rh_forearm_visual_0``) of the forearm's visual mesh geom, on
the palm body; segmentation gives it the label ``"arm"``, apart from the hand's."""
UPPER_ARM_GEOM = "upper_arm_visual_0"
"""Name (after the side prefix) of the upper arm's visual capsule, on the palm body (label
``"arm"``)."""
_DENSITY_KG_M3 = 1060.0  # soft tissue

ACTUATOR_GAINS: dict[str, tuple[float, float]] = {
    # joint kind: (minimum kp in N m/rad, torque limit in N m)
    "thumb_cmc_flex": (3.0, 3.0),
    "thumb_cmc_abd": (3.0, 3.0),
    "thumb_mcp_flex": (2.0, 1.5),
    "thumb_mcp_abd": (0.5, 0.8),
    "thumb_ip_flex": (1.0, 0.8),
    "mcp_flex": (3.0, 2.5),
    "mcp_abd": (0.5, 0.8),
    "pip_flex": (2.0, 1.5),
    "dip_flex": (0.8, 0.6),
}
"""Position-actuator stiffness (raised where a joint's inertia needs more for the bandwidth) and
torque limit per joint kind. The limits give fingertip
forces of a few tens of newtons (e.g. 2.5 N m at the index MCP over ~90 mm is ~28 N) and a
power grip of a few hundred newtons over all contacts. The flexion stiffnesses are high enough
that a grasp squeezing 45 deg past first contact (``handsim.envs.grasping``) presses with most
of that torque (a 0.9 kg drill held in a pinch needs it); the armature grows with them, so
the natural frequency and the 60 ms step response stay the same."""

FINGER_OMEGA = 120.0
"""Natural frequency (rad/s) of every finger joint: critically damped, 95 % of a step takes
4.74 / omega = 40 ms."""

HAND_PHYSICS_OPTIONS: dict[str, object] = {
    "timestep": 0.002,
    "cone": mujoco.mjtCone.mjCONE_ELLIPTIC,
    "impratio": 100.0,
    "integrator": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
}
"""MuJoCo options a scene with a hand should use: elliptic cones and impratio 100 (the LEAP
hand's value in MuJoCo Menagerie) keep grasped objects from slipping. Soft friction lets a held
object creep at a speed proportional to the friction regularization, which impratio divides:
a 0.41 kg can held in a power grasp creeps 3.3 mm/s at impratio 10 and 0.4 mm/s at 100."""

HAND_CONTACT_SOLREF: tuple[float, float] = (0.004, 1.0)
"""Contact ``solref`` of the hand's collision geoms: time constant 4 ms (twice the timestep,
the stiffest MuJoCo integrates stably), critically damped. With MuJoCo's default 20 ms a
fingertip pressing with a few newtons sinks 7-11 mm into a held object."""
HAND_CONTACT_SOLIMP: tuple[float, ...] = (0.95, 0.99, 0.001, 0.5, 2.0)
"""Contact ``solimp`` (dmin, dmax, width m, midpoint, power) of the hand's collision geoms: an
impedance near 1 leaves little of the contact force to the soft-constraint regularization
(steady penetration scales with ``(1 - d) / d`` times the time constant squared)."""
HAND_FRICTION = 1.0
"""Sliding friction coefficient of the hand's collision geoms (MuJoCo uses the larger of the
two geoms' coefficients)."""
HAND_CONTACT_SOLMIX = 100.0
"""Weight of these ``solref``/``solimp`` against the hand geom's MuJoCo defaults (MuJoCo mixes
the two geoms' parameters weighted by ``solmix``; the default is 1).

The three ``HAND_CONTACT_*`` values are the contact parameters of hand-object and hand-table
contacts. They are written onto the geoms the hand touches (every geom outside the hand) of a
compiled scene by ``handsim.envs.physics.HandDriver``, so contacts between the hand's own
segments keep MuJoCo's defaults (a fist's fingers press into each other softly, as gesture
targets assume)."""

_WELD_SOLREF = (0.01, 1.0)
# Negative solref = (-stiffness, -damping) in rad/s^2 per rad and per rad/s: critically damped
# at 500 rad/s.
_LIMIT_SOLREF = (-2.5e5, -1000.0)
_LIMIT_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)


# MuJoCo model --------------------------------------------------------------------------------


def _joint_kind(joint: str) -> str:
    return joint if joint.startswith("thumb") else joint.split("_", 1)[1]


def _joint_class(joint: str) -> str:
    """Default class of a joint: one per kind, unless the fingers' ranges differ (abduction)."""
    kind = _joint_kind(joint)
    ranges = {tuple(JOINT_LIMITS[i]) for i, n in enumerate(JOINT_NAMES) if _joint_kind(n) == kind}
    return kind if len(ranges) == 1 else joint


_TUNED_GAINS: dict[HandParams, tuple[tuple[float, float, float], ...]] = {}
"""Actuator gains per hand parameters (:meth:`Hand._tune_actuators`), a few kB each."""


class Hand:
    """A hand model: owns its ``MjSpec`` and knows the names of everything in it.

    Build once, then compile it alone (:meth:`compile`) or attach it to a scene
    (:meth:`attach_to`). Per compiled model, :meth:`bind` resolves names to indices once and
    returns a :class:`HandBinding` that reads and writes poses in ``MjData``.

    Args:
        params: hand parameters (default: a medium right hand).
    """

    def __init__(self, params: HandParams | None = None) -> None:
        if params is not None and not isinstance(params, HandParams):
            raise InvalidHandParams(
                f"params must be a HandParams (e.g. hand_params({params!r}) for a preset size) "
                f"or None; received {show(params)} ({type(params).__name__})"
            )
        self.params = params if params is not None else HandParams()
        self.skeleton = build_skeleton(self.params)
        p = self.params.prefix
        self.prefix = p
        self.joint_names: tuple[str, ...] = tuple(p + n for n in JOINT_NAMES)
        """The 21 hinge names in pose-vector order."""
        self.actuated: tuple[int, ...] = tuple(
            i
            for i, n in enumerate(JOINT_NAMES)
            if not (self.params.couple_dip and n.endswith("dip_flex"))
        )
        """Angle indices that have an actuator (all 21 unless the DIPs are coupled)."""
        self.actuator_names: tuple[str, ...] = tuple(
            f"{p}{JOINT_NAMES[i]}_act" for i in self.actuated
        )
        self.keypoint_site_names: tuple[str, ...] = tuple(f"{p}kp_{k}" for k in KEYPOINT_NAMES)
        self.point_site_names: tuple[str, ...] = self.keypoint_site_names + tuple(
            f"{p}kp_{k}" for k in EXTRA_POINT_NAMES
        )
        """Sites of every hand point (:data:`~handsim.hand.keypoints.HAND_POINT_NAMES`)."""
        self.root_body = f"{p}palm"
        self.root_joint = f"{p}root"
        self.mocap_body = f"{p}mocap"
        self.weld = f"{p}root_weld"
        self.spec = self._build_spec()
        self._spec_length = self.params.hand_length  # the length the spec was built for
        self._tune_actuators()

    # Building -------------------------------------------------------------------------------

    def _build_spec(self) -> mujoco.MjSpec:
        # Names are unprefixed here; attach_to adds the side prefix to every element.
        spec = mujoco.MjSpec()
        spec.modelname = "hand"
        spec.compiler.degree = False

        hand_cls = spec.add_default("hand", spec.default)
        hand_cls.joint.type = mujoco.mjtJoint.mjJNT_HINGE
        # Joint limits use direct (mass-independent) stiffness: with MuJoCo's default
        # time-constant form the limits of the light distal segments are too soft to hold
        # against the inertial loads of a fast thumb or finger motion.
        hand_cls.joint.solref_limit = _LIMIT_SOLREF
        hand_cls.joint.solimp_limit = _LIMIT_SOLIMP
        visual = spec.add_default("visual", hand_cls)
        visual.geom.contype = 0
        visual.geom.conaffinity = 0
        visual.geom.group = 2
        visual.geom.density = 0.0
        visual.geom.rgba = _SKIN_RGBA
        collision = spec.add_default("collision", hand_cls)
        collision.geom.group = 3
        collision.geom.density = _DENSITY_KG_M3
        collision.geom.friction = (HAND_FRICTION, 0.005, 0.0001)
        pad = spec.add_default("pad", collision)
        pad.geom.condim = 4
        pad.geom.friction = (HAND_FRICTION, 0.01, 0.0001)
        joint_classes = {}
        for kind in sorted({_joint_class(n) for n in JOINT_NAMES}):
            cls = spec.add_default(f"{kind}", hand_cls)
            joint_classes[kind] = cls

        for i, name in enumerate(JOINT_NAMES):
            cls = joint_classes[_joint_class(name)]
            cls.joint.range = JOINT_LIMITS[i]
            cls.joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
            kp, torque = ACTUATOR_GAINS[_joint_kind(name)]
            cls.actuator.ctrlrange = JOINT_LIMITS[i]
            cls.actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            cls.actuator.forcerange = (-torque, torque)
            cls.actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE

        mocap = spec.worldbody.add_body(name="mocap", mocap=True)
        mocap.add_site(name="mocap_site", size=(0.005, 0, 0), group=5)

        body_specs: list[mujoco.MjsBody] = []
        for b in self.skeleton.bodies:
            parent = spec.worldbody if b.parent < 0 else body_specs[b.parent]
            body = parent.add_body(name=b.name, pos=b.pos, quat=b.quat_wxyz)
            if b.parent < 0:
                body.add_freejoint(name="root")
            for angle_index, axis in b.joints:
                name = JOINT_NAMES[angle_index]
                body.add_joint(
                    name=name,
                    default=joint_classes[_joint_class(name)],
                    axis=axis,
                )
            distal = b.name.endswith("distal") and b.part != "palm"
            roles = [("collision", pad if distal else collision)]
            if self.params.surface == "capsules":
                roles.append(("visual", visual))
            for n, g in enumerate(b.geoms):
                for role, cls in roles:
                    kw = dict(name=f"{b.name}_{role}_{n}", default=cls)
                    if isinstance(g, Capsule):
                        body.add_geom(
                            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                            fromto=np.concatenate([g.start, g.end]),
                            size=(g.radius, 0, 0),
                            **kw,
                        )
                    else:
                        body.add_geom(
                            type=mujoco.mjtGeom.mjGEOM_BOX, pos=g.pos, size=g.half_size, **kw
                        )
            body_specs.append(body)
        meshes: list[tuple[int, str, np.ndarray, np.ndarray]] = []
        if self.params.surface == "skin":
            meshes = [
                (p.body, f"{self.skeleton.bodies[p.body].name}_visual_0", p.vertices, p.faces)
                for p in build_skin(self.params)
            ]
        if self.params.forearm:
            # The forearm beyond the palm's stub, its own mesh (and segmentation label).
            meshes.append((0, FOREARM_GEOM, *forearm_extension(self.params)))
        # Visual only (the `visual` class: no contact, no mass), so physics is the same with
        # and without the forearm beyond its collision stub.
        for body_index, name, vertices, faces in meshes:
            spec.add_mesh(name=name, uservert=vertices.ravel(), userface=faces.ravel())
            body_specs[body_index].add_geom(
                name=name, default=visual, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name
            )
        if self.params.forearm:
            # The upper arm, from the elbow on in line with the forearm (an arm held straight);
            # frame sources may turn it toward the shoulder (HandBinding.point_upper_arm).
            hl = self.params.hand_length
            length, radius = (r * hl for r in UPPER_ARM_RATIOS)
            elbow = np.array([0.0, -ELBOW_RATIO * hl, 0.0])
            body_specs[0].add_geom(
                name=UPPER_ARM_GEOM,
                default=visual,
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                fromto=np.concatenate([elbow, elbow - [0.0, length, 0.0]]),
                size=(radius, 0, 0),
            )

        for k, (body_index, pos) in enumerate(self.skeleton.keypoints):
            body_specs[body_index].add_site(
                name=f"kp_{KEYPOINT_NAMES[k]}", pos=pos, size=(0.003, 0, 0), group=4
            )
        # The other formats' points (palm centre, NYU wrist points, metacarpal bases, ...).
        for name, pos in extra_point_positions(self.skeleton).items():
            body_specs[0].add_site(name=f"kp_{name}", pos=pos, size=(0.003, 0, 0), group=4)

        spec.add_equality(
            type=mujoco.mjtEq.mjEQ_WELD,
            name="root_weld",
            name1="mocap",
            name2="palm",
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            data=[0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0],
            solref=_WELD_SOLREF,
        )
        if self.params.couple_dip:
            for f in FINGERS:
                spec.add_equality(
                    type=mujoco.mjtEq.mjEQ_JOINT,
                    name=f"{f}_dip_coupling",
                    name1=f"{f}_dip_flex",
                    name2=f"{f}_pip_flex",
                    objtype=mujoco.mjtObj.mjOBJ_JOINT,
                    data=[0, 2.0 / 3.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
                )
        for i in self.actuated:
            name = JOINT_NAMES[i]
            spec.add_actuator(
                name=f"{name}_act",
                default=joint_classes[_joint_class(name)],
                target=name,
                trntype=mujoco.mjtTrn.mjTRN_JOINT,
            )
        # Neighbouring proximal phalanges touch when adducted against each other; skin slides
        # there, so their contacts are excluded (as MyoHand does).
        for a, b in zip(FINGERS[:-1], FINGERS[1:], strict=True):
            spec.add_exclude(
                name=f"{a}_{b}_exclude", bodyname1=f"{a}_proximal", bodyname2=f"{b}_proximal"
            )
        return spec

    def _tune_actuators(self) -> None:
        """Set armature, kp and kv of every hinge for the step response in the module doc.

        A joint's inertia ``I`` varies with the pose (MCP abduction of a flexed finger turns
        the finger about its own axis, with ~1 % of the flat-hand inertia), and ``kp`` is
        integrated explicitly, so every joint gets an armature of at least ``kp (2 dt)^2``
        (stable at ``omega dt <= 0.5`` even if the link inertia vanished). At the flat pose:
        ``kp = max(kp_kind, I omega^2 / (1 - (2 dt omega)^2))``, armature
        ``max(kp (2 dt)^2, kp / omega^2 - I)`` and critical damping ``kv = 2 sqrt(kp (I + arm))``.
        """
        joints = {self.prefix + j.name: j for j in self.spec.joints}
        actuators = {self.prefix + a.name: a for a in self.spec.actuators}
        # The gains depend on the parameters only: compiled once per parameters (~20 ms,
        # paid again by every scene and dataset episode of the same hand otherwise).
        gains = _TUNED_GAINS.get(self.params)
        if gains is None:
            gains = self._compute_gains()
            if len(_TUNED_GAINS) >= 1024:
                _TUNED_GAINS.clear()
            _TUNED_GAINS[self.params] = gains
        for i, name in enumerate(JOINT_NAMES):
            full_name = self.prefix + name
            armature, kp, kv = gains[i]
            joints[full_name].armature = armature
            if i in self.actuated:
                actuators[f"{full_name}_act"].set_to_position(kp=kp, kv=kv)

    def _compute_gains(self) -> tuple[tuple[float, float, float], ...]:
        """``(armature, kp, kv)`` of every hinge in :data:`JOINT_NAMES` order."""
        model = self.compile()
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        inertia = np.empty((model.nv, model.nv))
        mujoco.mj_fullM(model, data, inertia)
        stable = (2.0 * HAND_PHYSICS_OPTIONS["timestep"]) ** 2
        gains = []
        for name in JOINT_NAMES:
            dof = model.jnt_dofadr[model.joint(self.prefix + name).id]
            link_inertia = inertia[dof, dof]
            kp = max(
                ACTUATOR_GAINS[_joint_kind(name)][0],
                link_inertia * FINGER_OMEGA**2 / (1.0 - stable * FINGER_OMEGA**2),
            )
            armature = max(kp * stable, kp / FINGER_OMEGA**2 - link_inertia)
            kv = 2.0 * np.sqrt(kp * (link_inertia + armature))
            gains.append((armature, kp, kv))
        return tuple(gains)

    # Using ----------------------------------------------------------------------------------

    def compile(self) -> mujoco.MjModel:
        """Compile the hand alone in an empty world (gravity on, no floor)."""
        scene = mujoco.MjSpec()
        scene.modelname = f"{self.prefix}hand"
        self.attach_to(scene)
        return scene.compile()

    def attach_to(self, scene: mujoco.MjSpec) -> None:
        """Attach a copy of this hand to ``scene``'s world body.

        Every element name gets the side prefix (``rh_``/``lh_``), so a right and a left hand
        can share a scene. Sets the scene's options to :data:`HAND_PHYSICS_OPTIONS`.
        """
        self._check_spec("attach_to")
        for key, value in HAND_PHYSICS_OPTIONS.items():
            setattr(scene.option, key, value)
        scene.attach(self.spec.copy(), prefix=self.prefix, frame=scene.worldbody.add_frame())

    def to_xml(self) -> str:
        """The MJCF text of the hand alone, as :meth:`compile` builds it.

        The skin's meshes are inline (vertex data), so the text is complete:
        ``mujoco.MjModel.from_xml_string`` compiles it to a model equal to :meth:`compile`'s
        (numbers at full precision, see :func:`handsim.world.mjcf.spec_to_xml`). A comment at
        the top lists the naming scheme.
        """
        # handsim.world imports this module; import its writer here to avoid a cycle.
        from handsim.world.mjcf import spec_to_xml

        return spec_to_xml(self._xml_spec())

    def _xml_spec(self) -> mujoco.MjSpec:
        scene = mujoco.MjSpec()
        scene.modelname = f"{self.prefix}hand"
        scene.comment = _xml_naming_comment(self)
        self.attach_to(scene)
        return scene

    def save(self, path: str | os.PathLike[str], *, assets_dir: str = "assets") -> pathlib.Path:
        """Write the hand as ``path`` plus its skin meshes as OBJ files in ``<assets_dir>/``.

        The layout of MuJoCo Menagerie: the XML references ``<assets_dir>/<mesh>.obj`` beside
        it and compiles to the same model as :meth:`to_xml` (which inlines the meshes). Open
        it with ``python -m mujoco.viewer --mjcf <path>`` (no floor: include it from a scene,
        as ``scenes/hand/scene_right.xml`` does). Parent folders are created.

        Args:
            path: the XML file to write.
            assets_dir: mesh folder, relative to the XML file's folder (shared by both sides:
                mesh names carry the side's prefix).

        Returns:
            The path of the XML file.
        """
        from handsim.world.mjcf import save_spec

        return save_spec(self._xml_spec(), path, assets_dir=assets_dir)

    def rescaled(self, params: HandParams) -> Hand:
        """This hand's record for ``params``, a uniform rescale of its own (no spec is built).

        What :meth:`handsim.world.scene.Scene.set_hand_length` keeps for a hand it scaled in a
        compiled model: the parameters and the skeleton of the new length, the same names.
        Its :attr:`spec` is this hand's (the built length), so it cannot be compiled or
        attached.
        """
        hand = copy.copy(self)
        hand.params = params
        hand.skeleton = build_skeleton(params)
        hand._spec_length = self._spec_length
        return hand

    def _check_spec(self, what: str) -> None:
        if self._spec_length != self.params.hand_length:
            raise InvalidHandParams(
                f"{what}: this hand was rescaled from {self._spec_length} m in a compiled model "
                f"(Scene.set_hand_length) and has no spec of its own; build "
                f"Hand(hand.params) for a {self.params.hand_length} m hand"
            )

    def bind(self, model: mujoco.MjModel) -> HandBinding:
        """Resolve this hand's names in a compiled model.

        Raises:
            UnknownName: if the model does not contain this hand.
        """
        return HandBinding(self, model)


def _xml_naming_comment(hand: Hand) -> str:
    """The comment at the top of :meth:`Hand.to_xml`: what the file is and its naming scheme."""
    p = hand.prefix
    rows = [
        ("root body", f"{p}palm", f"{p}palm"),
        ("free joint", f"{p}root", f"{p}root"),
        ("mocap body (target)", f"{p}mocap", f"{p}mocap"),
        ("wrist weld", f"{p}root_weld", f"{p}root_weld"),
        ("digit bodies", f"{p}<digit>_<segment>", f"{p}index_proximal"),
        ("hinge joints", f"{p}<digit>_<joint>", f"{p}index_mcp_flex"),
        ("actuators", f"{p}<digit>_<joint>_act", f"{p}index_mcp_flex_act"),
        ("keypoint sites", f"{p}kp_<keypoint>", f"{p}kp_index_tip"),
        ("collision geoms", f"{p}<body>_collision_<n>", f"{p}index_distal_collision_0"),
        ("visual geoms", f"{p}<body>_visual_<n>", f"{p}palm_visual_0"),
        ("default classes", f"{p}hand, {p}visual, {p}collision, {p}pad, {p}<joint kind>", ""),
    ]
    table = "\n".join(f"  {a:<20} {b:<40} {c}".rstrip() for a, b, c in rows)
    params = ", ".join(
        f"{f.name}={getattr(hand.params, f.name)!r}" for f in dataclasses.fields(hand.params)
    )
    return f"""
  {hand.params.side.capitalize()} hand of handsim, written by Hand.to_xml() from
  HandParams({params}).
  Generated; do not edit by hand (regenerate: python -m handsim.scenes).
  Units: metres, radians, kilograms. Hand frame: +x {"radial" if p == "rh_" else "ulnar"},
  +y distal, +z palmar, origin at the wrist crease centre.

  Names (<digit>: thumb, index, middle, ring, little; <joint>: cmc_flex, cmc_abd, mcp_flex,
  mcp_abd, ip_flex for the thumb, mcp_flex, mcp_abd, pip_flex, dip_flex for the fingers):
  element              name                                     example
{table}

  Geom groups: 2 visual (contype=conaffinity=0, what cameras see), 3 collision (capsules and
  boxes; they carry the mass). Site groups: 4 keypoints, 5 mocap target.
  Control: the free root follows the mocap body through the soft weld; the finger actuators
  are position servos with ctrl in radians (ctrlrange = joint range).
"""


def _one_pose(method: str, pose: object) -> None:
    """Refuse anything but one pose (a name, None, a vector or a batch), saying what to pass."""
    if not isinstance(pose, HandPose):
        raise InvalidPose(
            f"{method} takes a HandPose (e.g. gesture('open') or HandPose.from_vector(v)); "
            f"received {type(pose).__name__}"
        )
    if pose.batch_shape:
        raise InvalidPose(
            f"{method} takes one pose; received a batch of shape {pose.batch_shape} (index it, "
            "e.g. pose[0])"
        )


class HandBinding:
    """Index look-ups of one :class:`Hand` inside one compiled model.

    Reads and writes :class:`~handsim.hand.pose.HandPose` in ``MjData``: kinematically
    (:meth:`set_pose`) or as physics targets (:meth:`set_target`).
    """

    def __init__(self, hand: Hand, model: mujoco.MjModel) -> None:
        if not isinstance(hand, Hand) or not isinstance(model, mujoco.MjModel):
            raise InvalidHandParams(
                f"HandBinding needs a Hand and a compiled mujoco.MjModel; received "
                f"{type(hand).__name__}, {type(model).__name__}"
            )
        self.hand = hand
        self.model = model
        try:
            root = model.joint(hand.root_joint)
            self.root_qpos = int(root.qposadr[0])
            self.root_dof = int(root.dofadr[0])
            self.joint_qpos = np.array(
                [model.joint(n).qposadr[0] for n in hand.joint_names], dtype=np.intp
            )
            self.joint_dof = np.array(
                [model.joint(n).dofadr[0] for n in hand.joint_names], dtype=np.intp
            )
            self.actuator_ids = np.array(
                [model.actuator(n).id for n in hand.actuator_names], dtype=np.intp
            )
            self.site_ids = np.array(
                [model.site(n).id for n in hand.keypoint_site_names], dtype=np.intp
            )
            self.point_site_ids = np.array(
                [model.site(n).id for n in hand.point_site_names], dtype=np.intp
            )
            self.mocap_id = int(model.body(hand.mocap_body).mocapid[0])
            self.palm_id = model.body(hand.root_body).id
            self.upper_arm_id = (
                model.geom(hand.prefix + UPPER_ARM_GEOM).id if hand.params.forearm else -1
            )
        except KeyError as err:
            raise UnknownName(
                f"the model does not contain the {hand.params.side} hand "
                f"(prefix {hand.prefix!r}): {err}. Attach it with Hand.attach_to(scene_spec)."
            ) from None
        self.actuated = np.array(hand.actuated, dtype=np.intp)

    def set_pose(
        self, data: mujoco.MjData, pose: HandPose, *, kinematics_only: bool = False
    ) -> None:
        """Kinematic mode: write the pose into qpos (and mocap, ctrl), zero velocities, forward.

        Angles are clamped to the joint limits.

        Args:
            data: the simulation data.
            pose: the hand pose.
            kinematics_only: compute only the positions and orientations of bodies, geoms and
                sites (``mj_kinematics``), not contacts and forces (``mj_forward``): what
                keypoints and rendering need, at a fraction of the cost.

        Raises:
            InvalidPose: for anything but one :class:`~handsim.hand.pose.HandPose`.
        """
        _one_pose("set_pose", pose)
        pose = pose.clip()
        q = self.root_qpos
        data.qpos[q : q + 3] = pose.wrist_pos
        data.qpos[q + 3 : q + 7] = pose.quat_wxyz
        data.qpos[self.joint_qpos] = pose.angles
        data.qvel[self.root_dof : self.root_dof + 6] = 0.0
        data.qvel[self.joint_dof] = 0.0
        self.set_target(data, pose)
        if kinematics_only:
            mujoco.mj_kinematics(self.model, data)
        else:
            mujoco.mj_forward(self.model, data)

    def point_upper_arm(self, data: mujoco.MjData, shoulder_m: np.ndarray) -> None:
        """Turn the upper arm from the elbow to a shoulder, reaching it (drawn only).

        Call it after the pose is set (:meth:`set_pose`): it writes the upper arm's capsule
        into the model (geom position, orientation, half length and bounds, in the palm frame)
        and into ``data``'s geom poses, so the next render draws it and a later forward keeps
        it. Its length is the elbow-shoulder distance, at most 0.8 m. No effect on a hand
        without a forearm.

        Args:
            data: the simulation data, forwarded at the pose.
            shoulder_m: (3,) the shoulder, world, metres.
        """
        g = self.upper_arm_id
        if g < 0:
            return
        model = self.model
        rot = data.xmat[self.palm_id].reshape(3, 3)
        hl = self.hand.params.hand_length
        elbow = np.array([0.0, -ELBOW_RATIO * hl, 0.0])
        reach = rot.T @ (np.asarray(shoulder_m, dtype=np.float64) - data.xpos[self.palm_id])
        reach -= elbow
        length = float(np.linalg.norm(reach))
        # In line with the forearm when the shoulder is at the elbow.
        axis = reach / length if length > 1e-6 else np.array([0.0, -1.0, 0.0])
        length = min(length, 0.8)
        half = 0.5 * length
        radius = float(model.geom_size[g, 0])
        quat = np.empty(4)
        mujoco.mju_quatZ2Vec(quat, axis)  # the capsule's axis is its local z
        model.geom_pos[g] = elbow + axis * half
        model.geom_quat[g] = quat
        model.geom_size[g, 1] = half
        model.geom_rbound[g] = half + radius
        model.geom_aabb[g] = (0.0, 0.0, 0.0, radius, radius, half + radius)
        local = np.empty(9)
        mujoco.mju_quat2Mat(local, quat)
        data.geom_xpos[g] = data.xpos[self.palm_id] + rot @ model.geom_pos[g]
        data.geom_xmat[g] = (rot @ local.reshape(3, 3)).ravel()

    def set_target(self, data: mujoco.MjData, pose: HandPose) -> None:
        """Physics mode: move the mocap target to the wrist pose and set the finger targets.

        Angles are clamped to the joint limits (the actuators' ctrlrange).

        Raises:
            InvalidPose: for anything but one :class:`~handsim.hand.pose.HandPose`.
        """
        _one_pose("set_target", pose)
        pose = pose.clip()
        data.mocap_pos[self.mocap_id] = pose.wrist_pos
        data.mocap_quat[self.mocap_id] = pose.quat_wxyz
        data.ctrl[self.actuator_ids] = pose.angles[self.actuated]

    def pose(self, data: mujoco.MjData) -> HandPose:
        """The current pose read from qpos."""
        q = self.root_qpos
        # MuJoCo's conversion: scipy's rotation vector (angle in [0, pi]) at 1/20 of the cost.
        rotvec = np.empty(3)
        mujoco.mju_quat2Vel(rotvec, data.qpos[q + 3 : q + 7], 1.0)
        return HandPose(data.qpos[q : q + 3].copy(), rotvec, data.qpos[self.joint_qpos].copy())

    def keypoints(self, data: mujoco.MjData) -> np.ndarray:
        """(21, 3) keypoint positions in the world frame from the sites, metres."""
        return data.site_xpos[self.site_ids].copy()

    def points(self, data: mujoco.MjData) -> np.ndarray:
        """(29, 3) positions of every hand point (``HAND_POINT_NAMES``) from the sites, metres.

        :func:`~handsim.hand.keypoints.to_format` turns them into any format's points.
        """
        return data.site_xpos[self.point_site_ids].copy()
