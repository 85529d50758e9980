"""Kinematic hand-object frames taken from real grasps: the ``"grasp"`` frame source.

:class:`GraspSource` is the kinematic source (:class:`~handsim.data.kinematic.KinematicSource`:
the same episodes of a hand and objects resting on the table, the same viewpoints, renders and
labels) with the hand taken from the grasp planner instead of a posture source: per episode
one object is the target, :func:`~handsim.envs.grasping.plan_grasp` plans the grasp that
:class:`~handsim.envs.grasping.GraspExpert` executes for it (the object at its sampled pose,
the episode's hand length and side, the other objects as obstacles), and every frame of the
episode shows the hand at that grasp, each digit closed from the open preshape along the
planned closing path until it touches the object (:func:`close_onto`). The wrist is not moved
by the closing, so a frame is the grasp as the expert's fingers leave it at contact; distractor
objects are obstacles, not targets.

A ``through_object`` camera looks at the hand through one of the episode's objects, drawn per
view (the grasped one or another), from beyond it and above the table: through the grasped
object alone, a hand that grasps a low object from above could only be seen from under the
table, and a small object hides too little of it for the occlusion buckets.

With ``approach_fraction`` above 0 that fraction of the frames is drawn along the approach
instead, as the expert moves: the open hand from the pre-grasp pose (8 cm before the hover
point above the grasp) to the hover point, then down to the grasp while the digits close
(mostly not yet in contact). A kinematic release is the same path backwards, so it needs no
field of its own.

Frames whose hand enters an object or the table by more than :data:`MAX_GRASP_PENETRATION_M`
are never made. An episode whose object has no grasp (no collision-free candidate, or one
whose closed hand would enter something too deep, or whose forearm would enter the table)
raises :class:`~handsim.data.config.CannotDraw` ``"grasp"``: the shard redraws the episode
from its own generator and the manifest counts it (``redraws``); a hand never hovers beside an
object instead.

The core reaches this module by name (``GenerationConfig(source="grasp")``; the
``hand-object`` and ``occlusion-heavy`` presets) and never imports it itself.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator

import mujoco
import numpy as np

from handsim.data.config import (
    MAX_TRIES_PER_FRAME,
    CannotDraw,
    GenerationConfig,
    InvalidGenerationConfig,
)
from handsim.data.kinematic import (
    _PALM_OFFSET_M,
    SHOULDER_M,
    KinematicSource,
    _distal_axis,
    forearm_geom,
    near_geoms,
)
from handsim.envs.grasping import GraspPlanningError, plan_grasp
from handsim.envs.grasping.planning import _PREGRASP_DIST_M, GraspPlan
from handsim.hand.pose import JOINT_NAMES, HandPose
from handsim.world.scene import SEGMENT_LABELS, Scene

__all__ = ["GraspSource", "MAX_GRASP_PENETRATION_M", "TOUCH_DEPTH_M", "close_onto"]

MAX_GRASP_PENETRATION_M = 0.003
"""Deepest hand-object or hand-table overlap of a grasp frame, metres."""
TOUCH_DEPTH_M = 0.0005
"""A closing digit stops once it overlaps what it touches by about this much, metres (a
contact needs an overlap: MuJoCo reports none between surfaces that only meet)."""

_DIGITS = ("thumb", "index", "middle", "ring", "little")
_DIGIT_JOINTS = [np.array([j.startswith(d) for j in JOINT_NAMES]) for d in _DIGITS]
_DIGIT_LABELS = np.array([SEGMENT_LABELS.index(d) for d in _DIGITS])
_PALM_LABEL = SEGMENT_LABELS.index("palm")
_SCAN_STEPS = 24
"""Steps of the coarse scan along a digit's closing path (preshape -> contact -> closed)."""
_BISECTIONS = 10
"""Halvings of the scan step that place a digit at its touch (1/1024 of a step)."""
_ABOVE_M = 0.03
"""A palm centre within this horizontal distance of an object's origin is above it, metres."""
_MIN_AIM_HEIGHT_M = 0.08
"""A ``through_object`` camera at the farthest distance stays this high above the table, m."""
_APPROACH_TRIES = 8
"""Draws of a point of the approach before a frame shows the grasp instead."""


def _depths(scene: Scene, pose: HandPose) -> tuple[np.ndarray, float, bool]:
    """Pose the hand (positions and contacts only) and measure its overlaps.

    Returns:
        Per hand part label (index 0..7) the deepest overlap with anything not the hand
        (metres, 0 without contact), the deepest overlap overall, and whether the hand
        touches an object.
    """
    scene.binding.set_pose(scene.data, pose, kinematics_only=True)
    mujoco.mj_collision(scene.model, scene.data)
    data, labels = scene.data, scene.geom_labels
    depth = np.zeros(len(SEGMENT_LABELS))
    touches = False
    for i in range(data.ncon):
        con = data.contact[i]
        a, b = int(labels[con.geom1]), int(labels[con.geom2])
        hand_a = _PALM_LABEL <= a < len(SEGMENT_LABELS)
        hand_b = _PALM_LABEL <= b < len(SEGMENT_LABELS)
        if hand_a == hand_b:
            continue
        part, other = (a, b) if hand_a else (b, a)
        depth[part] = max(depth[part], -float(con.dist))
        touches |= other >= len(SEGMENT_LABELS)
    return depth, float(depth.max()), touches


def _path(plan: GraspPlan, s: np.ndarray) -> np.ndarray:
    """(21,) angles with each digit at its own point ``s[d]`` of the closing path.

    ``s`` in [0, 2]: 0 the preshape, 1 the planned contact closure, 2 the squeeze targets.
    """
    angles = np.empty(len(JOINT_NAMES))
    for d, joints in enumerate(_DIGIT_JOINTS):
        t = float(s[d])
        if t <= 1.0:
            a = plan.preshape + t * (plan.contact - plan.preshape)
        else:
            a = plan.contact + (t - 1.0) * (plan.closed - plan.contact)
        angles[joints] = a[joints]
    return angles


def close_onto(scene: Scene, plan: GraspPlan) -> HandPose | None:
    """The hand at the grasp wrist pose of ``plan``, each digit closed until it touches.

    Every digit moves along the planned closing path (preshape -> contact closure -> squeeze
    targets) and stops where it first overlaps something (the object, another object or the
    table) by :data:`TOUCH_DEPTH_M` (a scan, then bisection; kinematic, on the scene's own
    model). A digit that touches nothing on the way ends at the squeeze targets.

    Args:
        scene: the scene, objects at their poses (the hand is posed in it; restore it after).
        plan: the grasp.

    Returns:
        The closed pose, or None if it overlaps anything by more than
        :data:`MAX_GRASP_PENETRATION_M` or does not touch an object.
    """
    n = len(_DIGITS)
    lo = np.zeros(n)  # the last scanned point without a touch, per digit
    hi = np.full(n, np.nan)  # the first point past the touch
    step = 2.0 / _SCAN_STEPS
    for k in range(1, _SCAN_STEPS + 1):
        moving = np.isnan(hi)
        if not moving.any():
            break
        s = np.where(moving, k * step, lo)
        depth = _depths(scene, plan.pose(_path(plan, s)))[0][_DIGIT_LABELS]
        hit = moving & (depth > TOUCH_DEPTH_M)
        hi[hit] = s[hit]
        lo[moving & ~hit] = s[moving & ~hit]
    touched = ~np.isnan(hi)
    for _ in range(_BISECTIONS):
        if not touched.any():
            break
        s = np.where(touched, 0.5 * (lo + np.nan_to_num(hi)), lo)
        depth = _depths(scene, plan.pose(_path(plan, s)))[0][_DIGIT_LABELS]
        deep = touched & (depth > TOUCH_DEPTH_M)
        hi[deep] = s[deep]
        lo[touched & ~deep] = s[touched & ~deep]
    # Touching digits end just past their touch (hi), free ones at the squeeze targets (lo = 2).
    pose = plan.pose(_path(plan, np.where(touched, hi, lo)))
    _, deepest, touches = _depths(scene, pose)
    if deepest > MAX_GRASP_PENETRATION_M or not touches:
        return None
    return pose


class GraspSource(KinematicSource):
    """Frames of a hand grasping an object, posed without physics (see the module docstring).

    Frames are labelled with pose source ``"grasp"``; ``pose_sources`` is not used.

    Args:
        config: the generation config (``source="grasp"``).
    """

    def __init__(self, config: GenerationConfig) -> None:
        self.check_config(config)
        super().__init__(config)

    @classmethod
    def check_config(cls, config: GenerationConfig) -> None:
        """Raise an :class:`~handsim.data.config.InvalidGenerationConfig` (fields it lacks)."""
        if config.num_objects_range[0] < 1:
            raise InvalidGenerationConfig(
                "source 'grasp' grasps an object in every frame: num_objects_range must start "
                f"at 1 or more; received {tuple(config.num_objects_range)}"
            )
        if config.env_id is not None or config.frame_stride != 1:
            raise InvalidGenerationConfig(
                "env_id and frame_stride are fields of the 'rollout' source; remove them for "
                f"source 'grasp' (received env_id={config.env_id!r}, "
                f"frame_stride={config.frame_stride!r})"
            )

    def _grasp(self, scene: Scene, k: int) -> tuple[GraspPlan, HandPose] | str:
        """The plan and the closed pose of a grasp of object ``k``, or why it has none."""
        model, data = scene.model, scene.data
        T = []  # T_world_from_obj of every object
        for body_name, _ in scene.objects:
            body = model.body(body_name).id
            pose = np.eye(4)
            pose[:3, :3] = data.xmat[body].reshape(3, 3)
            pose[:3, 3] = data.xpos[body]
            T.append(pose)
        obstacles = [(o, T[i]) for i, (_, o) in enumerate(scene.objects) if i != k]
        # The planner collides the hand's capsules only: without the skin meshes (which only
        # cameras see) its private model of a new hand length is made in 20-30 ms, not 250-420.
        params = dataclasses.replace(scene.hand.params, surface="capsules")
        try:
            plan = plan_grasp(scene.objects[k][1], T[k], params, obstacles)
        except GraspPlanningError:
            return "no grasp"
        closed = close_onto(scene, plan)
        return "closed grasp overlaps" if closed is None else (plan, closed)

    def _approach(
        self, rng: np.random.Generator, scene: Scene, plan: GraspPlan, closed: HandPose
    ) -> HandPose:
        """A pose along the approach, as the expert moves.

        The open hand from the pre-grasp pose to the hover point, then down to the grasp
        while the digits close. Positions are redrawn (up to :data:`_APPROACH_TRIES` times)
        where the hand would enter something by more than :data:`MAX_GRASP_PENETRATION_M`;
        then the grasp itself.
        """
        hover = plan.approach_end - plan.wrist_pos
        pre = hover - _PREGRASP_DIST_M * plan.approach_dir
        for _ in range(_APPROACH_TRIES):
            u = float(rng.uniform(0.0, 2.0))
            if u <= 1.0:
                pose = plan.pose(plan.preshape, pre + u * (hover - pre))
            else:
                angles = plan.preshape + (u - 1.0) * (closed.angles - plan.preshape)
                pose = plan.pose(angles, (2.0 - u) * hover)
            if _depths(scene, pose)[1] <= MAX_GRASP_PENETRATION_M:
                return pose
        return closed

    def _through_object_aim(
        self, rng: np.random.Generator, palm: np.ndarray, obj: np.ndarray
    ) -> np.ndarray:
        """A point beyond which a ``through_object`` camera looks through an object at the hand.

        The camera sits beyond the object as seen from the palm centre, but above the table:
        a hand above the object is seen from low on the far side of the object, looking up
        through it, never from under the table. Where the palm is right above the object the
        side is drawn at random.

        Args:
            rng: the episode's generator.
            palm: (3,) palm centre, world, m.
            obj: (3,) the occluding object's origin, world, m.

        Returns:
            (3,) a point at 1 m from ``palm`` in the camera's direction, world, m.
        """
        v = obj - palm
        across = float(np.hypot(v[0], v[1]))
        if across < _ABOVE_M:
            turn = rng.uniform(0.0, 2.0 * np.pi)
            side = np.array([np.cos(turn), np.sin(turn)])
        else:
            side = v[:2] / across
        farthest = self.config.distance_range_m[1]
        lowest = np.arcsin(np.clip((_MIN_AIM_HEIGHT_M - palm[2]) / farthest, -1.0, 0.0))
        elevation = max(float(np.arctan2(v[2], across)), float(lowest))
        return palm + np.array([*(side * np.cos(elevation)), np.sin(elevation)])

    def episode(
        self, rng: np.random.Generator, accept: Callable[[float, int], bool], frames: int
    ) -> Iterator[dict[str, np.ndarray]]:
        """Yield the arrays (images included) of ``frames`` grasp frames of one episode.

        Args:
            rng: the episode's generator.
            accept: called with the hand occlusion ratio and the number of visible keypoints;
                False redraws the frame's view.
            frames: frames to yield.

        Raises:
            CannotDraw: ``"placement"`` when the episode's objects do not fit on the table;
                ``"grasp"`` when the episode's object has no grasp (none planned, or its
                closed hand would enter something too deep); ``"frame"`` when
                :data:`MAX_TRIES_PER_FRAME` views give no accepted frame.
        """
        scene, renderer = self._scene(rng)
        k = int(rng.integers(len(scene.objects)))
        grasp = self._grasp(scene, k)
        if isinstance(grasp, str):
            name = scene.objects[k][1].name
            raise CannotDraw("grasp", f"{grasp}: {name} at its sampled pose")
        plan, closed = grasp
        obj_pos = scene.data.xpos[scene.model.body(scene.objects[k][0]).id].copy()
        centres = [scene.data.xpos[scene.model.body(b).id].copy() for b, _ in scene.objects]
        viewpoints = list(self.config.viewpoints)
        geoms, forearm = near_geoms(scene), forearm_geom(scene)
        # Everything the backdrop stands behind: what is kept in range, and the arm.
        arm = () if forearm is None else (forearm, scene.binding.upper_arm_id)
        behind = np.append(geoms, arm).astype(np.intp)
        shoulder = SHOULDER_M * ((-1.0, 1.0, 1.0) if scene.hand.params.side == "left" else 1.0)
        for _ in range(frames):
            pose = closed
            if rng.random() < self.config.approach_fraction:
                pose = self._approach(rng, scene, plan, closed)
            # Forward: the hand placed and its contacts found (with forces) for the labels.
            scene.binding.set_pose(scene.data, pose)
            # The forearm is drawn only (no contact): a real one cannot enter the table.
            if self._forearm_below_table_m(scene, forearm) > MAX_GRASP_PENETRATION_M:
                name = scene.objects[k][1].name
                raise CannotDraw("grasp", f"the forearm of the grasp of {name} enters the table")
            scene.binding.point_upper_arm(scene.data, shoulder)
            palm = pose.wrist_pos + _distal_axis(pose.wrist_rotvec) * _PALM_OFFSET_M
            for _ in range(MAX_TRIES_PER_FRAME):
                view = viewpoints[int(rng.integers(len(viewpoints)))]
                aim = obj_pos
                if view == "through_object":
                    occluder = centres[int(rng.integers(len(centres)))]
                    aim = self._through_object_aim(rng, palm, occluder)
                camera = self._camera(rng, view, palm, aim, pose.wrist_rotvec)
                arrays = self._view(
                    rng, scene, renderer, camera, palm, geoms, behind, accept, "grasp", view
                )
                if arrays is not None:
                    yield arrays
                    break
            else:
                raise CannotDraw(
                    "frame", f"{MAX_TRIES_PER_FRAME} views of a grasp gave no accepted frame"
                )
