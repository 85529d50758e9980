"""Ground-truth pick-and-lift episodes: :func:`run_episode` and :func:`contact_metrics`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import mujoco
import numpy as np

from handsim.envs.grasping.execution import FALL_HEIGHT_M, GraspExpert
from handsim.envs.grasping.planning import (
    CONTROL_DT_S,
    FRAME_SKIP,
    GraspState,
    InvalidGraspState,
    _object_body_id,
    start_pose,
)
from handsim.envs.grasping.success import GraspOutcome, LiftTracker
from handsim.envs.physics import HandDriver
from handsim.world.scene import Scene

__all__ = ["ContactMetrics", "contact_metrics", "run_episode"]


@dataclasses.dataclass(frozen=True)
class ContactMetrics:
    """How the hand touches the target object and the table at one instant.

    Attributes:
        object_depth_m: deepest hand-object penetration (MuJoCo contact ``dist < 0``), metres;
            0 without penetration.
        table_depth_m: deepest hand-table penetration, metres.
        normal_force_n: total normal force of the hand-object contacts, newtons.
        deepest_geom: name of the hand geom of the deepest hand-object contact ("" if none).
    """

    object_depth_m: float
    table_depth_m: float
    normal_force_n: float
    deepest_geom: str


def contact_metrics(scene: Scene, instance: int) -> ContactMetrics:
    """Penetration and grip force of the hand on object ``instance`` (after ``mj_forward``).

    Raises:
        InvalidGraspState: for a scene without a hand or a bad instance.
    """
    body_id = _object_body_id(scene, instance)
    model, data = scene.model, scene.data
    n = data.ncon
    if n == 0:
        return ContactMetrics(0.0, 0.0, 0.0, "")
    root = model.body(scene.hand.root_body).id
    hand = model.body_rootid == root
    contact = data.contact
    g1, g2 = contact.geom1[:n], contact.geom2[:n]
    b1, b2 = model.geom_bodyid[g1], model.geom_bodyid[g2]
    h1, h2 = hand[b1], hand[b2]
    on_object = (h1 & (b2 == body_id)) | (h2 & (b1 == body_id))
    table = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "table")  # -1 without a table
    on_table = (h1 & (g2 == table)) | (h2 & (g1 == table))
    dist = contact.dist[:n]
    object_depth = float(max(0.0, -dist[on_object].min())) if on_object.any() else 0.0
    table_depth = float(max(0.0, -dist[on_table].min())) if on_table.any() else 0.0
    force, wrench = 0.0, np.zeros(6)
    for i in np.nonzero(on_object)[0]:
        mujoco.mj_contactForce(model, data, int(i), wrench)
        force += float(wrench[0])
    deepest = ""
    if on_object.any():
        i = np.nonzero(on_object)[0][np.argmin(dist[on_object])]
        deepest = model.geom(int(g1[i] if h1[i] else g2[i])).name
    return ContactMetrics(object_depth, table_depth, force, deepest)


def run_episode(
    scene: Scene,
    instance: int,
    expert: GraspExpert,
    rng: np.random.Generator,
    max_steps: int = 400,
    *,
    stop_on_success: bool = True,
    on_step: Callable[[int, GraspExpert], None] | None = None,
    perceive: Callable[[GraspState], GraspState] | None = None,
) -> GraspOutcome:
    """Run one ground-truth pick-and-lift episode.

    Resets ``scene`` (objects at their placements, the hand at :func:`start_pose`), then per
    control step: state -> ``expert.act`` -> ``set_target`` -> :data:`FRAME_SKIP` physics steps
    -> success tracking. As in ``handsim/Grasp-v0``, the episode ends when the object has
    fallen off the table (its origin below :data:`FALL_HEIGHT_M`).

    Args:
        scene: a scene with a hand and the target object.
        instance: index of the target in ``scene.objects``.
        expert: a :class:`GraspExpert` for that object.
        rng: random generator of the start pose.
        max_steps: control steps at most (400 = 8 s).
        stop_on_success: end the episode as soon as the hold succeeds.
        on_step: called after every control step with its index and the expert (whose
            ``phase`` says where the episode is); for measurements such as
            :func:`contact_metrics`.
        perceive: turns each ground-truth state into the one the expert acts on (e.g. a
            noisy object pose, as an estimator would give); ``None``: the truth.

    Returns:
        The outcome.

    Raises:
        InvalidGraspState: for a bad instance, expert or ``max_steps``.
        GraspPlanningError: if the expert finds no grasp at the start and does not re-plan.
    """
    body_id = _object_body_id(scene, instance)
    if not isinstance(expert, GraspExpert):
        raise InvalidGraspState(f"expert must be a GraspExpert; received {type(expert).__name__}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise InvalidGraspState(f"max_steps must be an int >= 1; received {max_steps!r}")
    obj = scene.objects[instance][1]
    if expert.obj.name != obj.name:
        raise InvalidGraspState(
            f"the expert grasps {expert.obj.name!r} but scene object {instance} is {obj.name!r}"
        )
    data = scene.data
    scene.reset()
    T0 = GraspState.from_sim(scene, instance, 0.0).T_world_from_obj
    scene.reset(start_pose(rng, T0, scene.hand.params, obj=obj))
    tracker = LiftTracker(float(data.xpos[body_id][2]))
    perceived = perceive if perceive is not None else (lambda state: state)
    state = perceived(GraspState.from_sim(scene, instance, 0.0))
    expert.reset(state)
    diverged = False
    # The env's driver: same mocap tracking and stepping as handsim/Grasp-v0.
    driver = HandDriver(scene)
    for step in range(int(max_steps)):
        driver.set_target(expert.act(state))
        if driver.step(FRAME_SKIP):
            diverged = True
            break
        time_s = (step + 1) * CONTROL_DT_S
        success = tracker.update_from_sim(scene, instance, time_s)
        if on_step is not None:
            on_step(step, expert)
        if success and stop_on_success:
            break
        if data.xpos[body_id][2] < FALL_HEIGHT_M:
            break  # fallen off the table (falling on, it would pass the divergence speed)
        state = perceived(GraspState.from_sim(scene, instance, time_s))
    return tracker.outcome(diverged=diverged)
