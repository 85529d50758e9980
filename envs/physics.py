"""The physical hand: the wrist-tracking driver, divergence checks, contact stiffness, friction."""

from __future__ import annotations

import mujoco
import numpy as np

from handsim.envs.config import InvalidEnvConfig
from handsim.errors import HandSimError
from handsim.hand.model import (
    HAND_CONTACT_SOLIMP,
    HAND_CONTACT_SOLMIX,
    HAND_CONTACT_SOLREF,
)
from handsim.hand.pose import HandPose
from handsim.world.scene import InvalidScene, Scene

__all__ = [
    "HandDriver",
    "PhysicsDiverged",
    "stiffen_hand_contacts",
    "SKIN_FRICTION",
    "OBJECT_MATERIALS",
    "skin_friction",
    "SKIN_PATCH_RADIUS_M",
    "SKIN_TORSION_FACTOR",
    "skin_torsional_friction",
    "set_skin_friction",
    "divergence_speed_bounds",
    "DIVERGENCE_SPEED_M_S",
    "DIVERGENCE_LEVER_RATIO",
    "DIVERGENCE_OBJECT_FACTOR",
    "FREE_FALL_FROM_M",
    "WRIST_TRACKING_SPEED",
    "WRIST_TRACKING_ANGULAR_SPEED",
]

WRIST_TRACKING_SPEED = 2.0
"""Fastest motion of the mocap body toward the wrist target, m/s (fast human reaching)."""
WRIST_TRACKING_ANGULAR_SPEED = 4 * np.pi
"""Fastest rotation of the mocap body toward the wrist target, rad/s."""
DIVERGENCE_SPEED_M_S = 5.0
"""Speed above which the physics counts as diverged, m/s: five times the fastest wrist tracking
and about twice the fastest human finger and hand motions (pitching, finger flicks)."""
DIVERGENCE_LEVER_RATIO = 0.1
"""Lever arm, as a fraction of the hand length (about a middle phalanx), that turns
:data:`DIVERGENCE_SPEED_M_S` into the angular-velocity bound of rotational DoFs."""
DIVERGENCE_OBJECT_FACTOR = 2.0
"""Objects' speed bounds are this many times the hand's: a light object struck by the hand
leaves at up to twice the hand's speed (an elastic collision with a heavier body)."""
FREE_FALL_FROM_M = 1.0
"""Height above the table top (``z = 0``) from which an object may be falling: its free-fall
speed at height ``z``, ``sqrt(2 g (1 m - z))``, is added to its linear bound, so an object
knocked off the table (there is no floor) is not read as diverged as it falls on."""
_DIVERGENCE_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQPOS,
)
_DIVERGENCE_WARNING_INDICES = [int(w) for w in _DIVERGENCE_WARNINGS]


class PhysicsDiverged(HandSimError, RuntimeError):
    """The physics diverged and the episode was truncated; it cannot be stepped further."""


def divergence_speed_bounds(
    model: mujoco.MjModel,
    hand_length_m: float,
    hand_root_body: int | tuple[int, ...] | None = None,
) -> np.ndarray:
    """Per-DoF speed bound above which a state counts as diverged.

    Linear DoFs (free-joint translations, slides) are bounded by :data:`DIVERGENCE_SPEED_M_S`;
    rotational DoFs (hinges, free and ball rotations) by that speed at a lever of
    :data:`DIVERGENCE_LEVER_RATIO` times the hand length (a phalanx), so a smaller hand, whose
    fingers legitimately turn faster, gets a higher angular bound. With ``hand_root_body``,
    the DoFs of every other body tree (the objects) get :data:`DIVERGENCE_OBJECT_FACTOR` times
    these bounds (:class:`HandDriver` also adds a falling object's free-fall speed).

    Args:
        model: the compiled model.
        hand_length_m: the hand's length, metres.
        hand_root_body: the body id of the hand's root (or of each hand's, two hands), to
            tell their DoFs from the objects'.

    Returns:
        (nv,) bound per DoF: m/s for linear DoFs, rad/s for rotational ones.
    """
    angular = DIVERGENCE_SPEED_M_S / (DIVERGENCE_LEVER_RATIO * hand_length_m)
    bounds = np.full(model.nv, angular)
    for j in range(model.njnt):
        adr = model.jnt_dofadr[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            bounds[adr : adr + 3] = DIVERGENCE_SPEED_M_S
        elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE:
            bounds[adr] = DIVERGENCE_SPEED_M_S
    if hand_root_body is not None:
        objects = ~np.isin(model.body_rootid[model.dof_bodyid], hand_root_body)
        bounds[objects] *= DIVERGENCE_OBJECT_FACTOR
    return bounds


def stiffen_hand_contacts(scene: Scene) -> None:
    """Give the scene's hand-object and hand-table contacts the hand's contact parameters.

    Writes :data:`~handsim.hand.model.HAND_CONTACT_SOLREF`, ``HAND_CONTACT_SOLIMP`` and
    ``HAND_CONTACT_SOLMIX`` onto every collision geom outside the hand (idempotent). MuJoCo
    mixes the two geoms' parameters by ``solmix``, so hand-object and hand-table contacts (and
    object-object and object-table ones) are stiff, and contacts between the hand's own
    segments keep MuJoCo's defaults (and so do the contacts between two hands).
    """
    model = scene.model
    roots = [model.body(h.root_body).id for h in scene.hands]
    other = ~np.isin(model.body_rootid[model.geom_bodyid], roots) & (
        (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    )
    model.geom_solref[other] = HAND_CONTACT_SOLREF
    model.geom_solimp[other] = HAND_CONTACT_SOLIMP
    model.geom_solmix[other] = HAND_CONTACT_SOLMIX


SKIN_FRICTION: dict[str, float] = {
    "paper": 0.42,
    "metal": 0.6,
    "plastic": 0.53,
    "other": 0.5,
}
"""Sliding friction of human skin on each object material (hand-object contacts).

Measured values: palmar skin on paper 0.27 dry and 0.42 moist, on smooth vinyl 0.53, on
textured vinyl 0.50, on aluminium 0.38 (Buchholz, Frederick & Armstrong 1988, Ergonomics
31(3):317-325); the finger pad sliding on aluminium 0.6 on average (Seo et al.
2009, Ergonomics 52(5):609-616; it falls as the normal force grows from 1 to 20 N). Cardboard
takes moist paper (finger pads are kept moist by their sweat glands), metal the finger pad on
aluminium (the digits, not the palm, carry the load), plastic smooth vinyl. Wood, foam and
fruit skin have no measured value in these sources; ``"other"`` takes textured vinyl's 0.50 as
a stand-in.
"""

OBJECT_MATERIALS: dict[str, str] = {
    "002_master_chef_can": "metal",
    "003_cracker_box": "paper",
    "004_sugar_box": "paper",
    "005_tomato_soup_can": "metal",
    "006_mustard_bottle": "plastic",
    "007_tuna_fish_can": "metal",
    "008_pudding_box": "paper",
    "009_gelatin_box": "paper",
    "010_potted_meat_can": "metal",
    "011_banana": "other",
    "019_pitcher_base": "plastic",
    "021_bleach_cleanser": "plastic",
    "024_bowl": "plastic",
    "025_mug": "plastic",
    "035_power_drill": "plastic",
    "036_wood_block": "other",
    "037_scissors": "plastic",
    "040_large_marker": "plastic",
    "051_large_clamp": "plastic",
    "052_extra_large_clamp": "plastic",
    "061_foam_brick": "other",
}
"""Surface material of each YCB-Video object (its outside, where the hand touches it);
imported objects are ``"other"``."""


SKIN_PATCH_RADIUS_M = 0.005
"""Radius of the skin's contact patch on a held object, metres: a finger pad pressed on a flat
surface with a few newtons touches about 1 cm^2 of it (an equivalent radius of 5-6 mm; the
smaller end taken)."""

SKIN_TORSION_FACTOR = 8.0 / 15.0
"""Torsional friction of a patch over its sliding friction and radius: a circular patch of
radius ``a`` under a paraboloid pressure (the finger pad's, Pawluk & Howe 1999, J. Biomech.
Eng. 121(6):605-611) resists turning about its normal up to ``mu * (8/15) * a`` times its
normal force (``2/3`` for a uniform pressure, ``3 pi/16`` for Hertz's)."""


def skin_torsional_friction(sliding: float) -> float:
    """Torsional friction of a skin contact, metres (MuJoCo's second friction coefficient).

    :data:`SKIN_TORSION_FACTOR` x ``sliding`` x :data:`SKIN_PATCH_RADIUS_M`: the most torque
    about the contact normal, per newton of normal force, that a finger pad's patch holds by
    friction.
    """
    return SKIN_TORSION_FACTOR * sliding * SKIN_PATCH_RADIUS_M


def skin_friction(name: str) -> float:
    """Hand-object sliding friction of an object, by name.

    :data:`SKIN_FRICTION` of its material (:data:`OBJECT_MATERIALS`; ``"other"`` for names
    not listed).
    """
    return SKIN_FRICTION[OBJECT_MATERIALS.get(name, "other")]


def set_skin_friction(scene: Scene, friction: float | None = None) -> None:
    """Give hand-object contacts the friction of skin on each object's material.

    Writes the sliding friction (:func:`skin_friction`, or ``friction`` for every object) onto
    the collision geoms of every object and raises their ``priority`` to 1, so that MuJoCo
    takes the object's friction for its contacts with the hand (and with the table and other
    objects) instead of the larger of the two geoms' values. The priority also gives those
    contacts the object's ``condim``: 4, with the torsional friction of the skin's contact
    patch (:func:`skin_torsional_friction`), so that every skin contact resists turning about
    its normal as a finger pad does. Every env calls it at reset (``object_friction="skin"``,
    the default); a bare :class:`~handsim.world.scene.Scene` keeps MuJoCo's friction of 1.0
    and ``condim`` 3 until it is called.

    Args:
        scene: the scene.
        friction: one sliding friction for every object (``None``: per material).

    Raises:
        InvalidEnvConfig: for a friction that is not a finite number > 0.
    """
    if friction is not None and not (
        isinstance(friction, (int, float, np.floating))
        and not isinstance(friction, bool)
        and np.isfinite(friction)
        and friction > 0
    ):
        raise InvalidEnvConfig(f"friction must be a finite number > 0; received {friction!r}")
    model = scene.model
    for body_name, obj in scene.objects:
        body = model.body(body_name).id
        geoms = (model.geom_bodyid == body) & (
            (model.geom_contype != 0) | (model.geom_conaffinity != 0)
        )
        sliding = skin_friction(obj.name) if friction is None else friction
        model.geom_friction[geoms, 0] = sliding
        # The object's condim governs too: 4 with the skin patch's torsional friction (a pinch
        # of two pads then resists the object's turning about the line through them).
        model.geom_friction[geoms, 1] = skin_torsional_friction(sliding)
        model.geom_condim[geoms] = 4
        model.geom_priority[geoms] = 1


class HandDriver:
    """Drives a scene's physical hand toward a target pose, one control step at a time.

    The finger targets go to the position actuators at once. The mocap body (the hand's wrist
    target, welded softly to the hand root) is moved once per :meth:`step` toward the wrist
    target, by at most :data:`WRIST_TRACKING_SPEED` m/s and
    :data:`WRIST_TRACKING_ANGULAR_SPEED` rad/s times the step's duration; the weld's own
    time constant (10 ms) smooths the motion in between. The physics sub-steps then run in one
    ``mj_step(..., nstep=n)`` call (no Python per sub-step), after the first, which reuses the
    ``mj_forward`` the previous step ended with (``mj_step2``), so a control step costs ``n``
    forward passes, as ``n`` bare ``mj_step`` calls do, and still ends forwarded for the
    observation. Whoever edits the data between steps should make a new driver (as
    ``set_state`` does) or call ``mj_forward``.

    Divergence is checked once per :meth:`step`, on the state it ends in: a MuJoCo
    instability warning raised during any of its sub-steps (MuJoCo then resets the state), a
    non-finite position or velocity, or a velocity above :meth:`speed_bounds` (a
    blow-up grows by orders of magnitude within a few sub-steps, long before MuJoCo warns about
    a huge acceleration). A diverged driver refuses to step again (:class:`PhysicsDiverged`).
    Envs and scripted-episode loops share it, so both run the same physics.

    A two-hand scene's driver drives both hands (one physics for both): each has its own
    target (:meth:`set_target` with ``side``; :attr:`target` is the first hand's,
    :meth:`target_of` any hand's), and the wrist tracking and speed limits apply to each.

    Args:
        scene: a scene with a hand (or two).
        forwarded: the data already holds ``mj_forward`` of its current state.
    """

    def __init__(self, scene: Scene, *, forwarded: bool = False) -> None:
        if scene.hand_rescaled:
            raise InvalidScene(
                "this scene's hand was rescaled in place (Scene.set_hand_length), which keeps "
                "the masses and actuator gains of the length it was built for: simulate a "
                "scene built for the hand, Scene(scene.spec)"
            )
        self.scene = scene
        self._bindings = scene.bindings
        self._sides = tuple(b.hand.params.side for b in self._bindings)
        self._targets = [b.pose(scene.data) for b in self._bindings]
        self._target_quats_wxyz = [t.quat_wxyz for t in self._targets]
        self._warnings = self._divergence_count()
        model = scene.model
        roots = tuple(model.body(h.root_body).id for h in scene.hands)
        self._static_bounds = divergence_speed_bounds(
            model, min(h.params.hand_length for h in scene.hands), roots
        )
        self._speed_bounds = self._static_bounds.copy()
        # The objects' free joints: linear DoFs and the qpos index of their height.
        free = [
            j
            for j in range(model.njnt)
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
            and model.body_rootid[model.jnt_bodyid[j]] not in roots
        ]
        self._fall_dofs = np.array([model.jnt_dofadr[j] + k for j in free for k in range(3)], int)
        self._fall_z = np.repeat(np.array([model.jnt_qposadr[j] + 2 for j in free], int), 3)
        self._gravity = float(np.linalg.norm(model.opt.gravity))
        stiffen_hand_contacts(scene)
        self.diverged = False
        """``True`` once a :meth:`step` diverged."""
        self._forwarded = bool(forwarded)
        # Per hand: the mocap body sits at the wrist target.
        self._arrived = [False] * len(self._bindings)

    @property
    def target(self) -> HandPose:
        """The (first) hand's 27-DoF target, world frame."""
        return self._targets[0]

    def _index(self, side: str | None) -> int:
        if side is None:
            return 0
        if side not in self._sides:
            raise InvalidEnvConfig(
                f"side={side!r} is not a hand of this scene; its hands: {', '.join(self._sides)}"
            )
        return self._sides.index(side)

    def target_of(self, side: str) -> HandPose:
        """The 27-DoF target of the hand of ``side`` (``"right"`` or ``"left"``), world frame.

        Raises:
            InvalidEnvConfig: for a side the scene has no hand of.
        """
        return self._targets[self._index(side)]

    def set_target(self, target: HandPose, side: str | None = None) -> None:
        """Set a 27-DoF target (world frame); angles are clipped to the joint limits.

        Args:
            target: the pose to drive the hand toward.
            side: which hand (``"right"`` or ``"left"``); ``None``: the (first) hand.

        Raises:
            InvalidEnvConfig: for a side the scene has no hand of.
        """
        i = self._index(side)
        target = target.clip()
        old = self._targets[i]
        if not (
            np.array_equal(target.wrist_pos, old.wrist_pos)
            and np.array_equal(target.wrist_rotvec, old.wrist_rotvec)
        ):
            self._arrived[i] = False
        self._targets[i] = target
        self._target_quats_wxyz[i] = target.quat_wxyz
        binding = self._bindings[i]
        self.scene.data.ctrl[binding.actuator_ids] = target.angles[binding.actuated]

    def speed_bounds(self) -> np.ndarray:
        """The (nv,) speed bounds of the current state, m/s or rad/s.

        :func:`divergence_speed_bounds` (objects at :data:`DIVERGENCE_OBJECT_FACTOR` times the
        hand's), plus, on an object's linear DoFs, the speed of a fall from
        :data:`FREE_FALL_FROM_M` to its height.
        """
        if len(self._fall_dofs):
            drop_m = np.maximum(FREE_FALL_FROM_M - self.scene.data.qpos[self._fall_z], 0.0)
            self._speed_bounds[self._fall_dofs] = self._static_bounds[self._fall_dofs] + np.sqrt(
                2.0 * self._gravity * drop_m
            )
        return self._speed_bounds

    def _within_bounds(self) -> bool:
        # NaN fails the comparison, so the bound also catches non-finite velocities; positions
        # integrate bounded velocities (MuJoCo itself warns on bad positions).
        return bool(np.all(np.abs(self.scene.data.qvel) <= self.speed_bounds()))

    def _divergence_count(self) -> int:
        data = self.scene.data
        return int(data.warning.number[_DIVERGENCE_WARNING_INDICES].sum())

    def _track(self, duration_s: float) -> None:
        """Move each mocap body toward its wrist target, rate-limited over ``duration_s``."""
        for i in range(len(self._bindings)):
            if not self._arrived[i]:
                self._track_hand(i, duration_s)

    def _track_hand(self, i: int, duration_s: float) -> None:
        data, mocap = self.scene.data, self._bindings[i].mocap_id
        target = self._targets[i]
        target_quat = self._target_quats_wxyz[i]
        pos = data.mocap_pos[mocap]
        offset = target.wrist_pos - pos
        distance = np.linalg.norm(offset)
        reach = WRIST_TRACKING_SPEED * duration_s
        if distance > reach:
            data.mocap_pos[mocap] = pos + offset * (reach / distance)
        else:
            data.mocap_pos[mocap] = target.wrist_pos
        quat = data.mocap_quat[mocap]
        # Rotation from the current to the target orientation (the short way), as axis * angle.
        inverse, relative, rotvec = np.empty(4), np.empty(4), np.empty(3)
        mujoco.mju_negQuat(inverse, quat)
        mujoco.mju_mulQuat(relative, target_quat, inverse)
        if relative[0] < 0:
            relative = -relative
        mujoco.mju_quat2Vel(rotvec, relative, 1.0)
        angle = np.linalg.norm(rotvec)
        turn = WRIST_TRACKING_ANGULAR_SPEED * duration_s
        if angle <= turn:
            data.mocap_quat[mocap] = target_quat
            self._arrived[i] = distance <= reach
            return
        step, new = np.empty(4), np.empty(4)
        mujoco.mju_axisAngle2Quat(step, rotvec / angle, turn)
        mujoco.mju_mulQuat(new, step, quat)
        mujoco.mju_normalize4(new)
        data.mocap_quat[mocap] = new

    def step(self, n: int) -> bool:
        """Run ``n`` physics steps toward the target, then ``mj_forward``.

        Returns:
            ``True`` if the physics diverged during these steps (see the class docstring); the
            data is then not forwarded and the driver refuses further steps.

        Raises:
            PhysicsDiverged: if an earlier step diverged.
        """
        if self.diverged:
            raise PhysicsDiverged(
                "the physics diverged in an earlier step and the episode was truncated; "
                "call reset() (or restore a state) before stepping again"
            )
        model, data = self.scene.model, self.scene.data
        self._track(n * model.opt.timestep)
        if self._forwarded:
            # The data holds the full forward pass of this state (the last step's mj_forward):
            # finish the first sub-step from it, so each sub-step costs one forward pass. The
            # new controls act at once (mj_step2 recomputes actuation); the mocap moved by
            # _track acts from the second sub-step on.
            mujoco.mj_step2(model, data)
            if n > 1:
                mujoco.mj_step(model, data, nstep=n - 1)
        else:
            mujoco.mj_step(model, data, nstep=n)
        self._forwarded = False
        warnings = self._divergence_count()
        if warnings != self._warnings or not self._within_bounds():
            self._warnings = warnings
            self.diverged = True
            return True
        # mj_step leaves positions, contacts and sites at the state before integration; the
        # observation and labels describe the state after it.
        mujoco.mj_forward(model, data)
        self._forwarded = True
        return False
