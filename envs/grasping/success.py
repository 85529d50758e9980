"""The success definition of a pick-and-lift episode: :class:`LiftTracker` and its outcome.

See :mod:`handsim.envs.grasping` for the definition.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import numpy as np

from handsim.envs.grasping.planning import (
    HOLD_DURATION_S,
    LIFT_HEIGHT_M,
    MAX_SLIP_M,
    MAX_TURN_RAD,
    InvalidGraspState,
    _check_transform,
    _object_body_id,
)
from handsim.world.scene import Scene

__all__ = ["FailureReason", "GraspOutcome", "LiftTracker", "evaluate_lift"]

FailureReason = Literal["not_lifted", "dropped", "slipped", "turned", "hold_incomplete", "diverged"]


@dataclasses.dataclass(frozen=True)
class GraspOutcome:
    """The result of a pick-and-lift episode.

    Attributes:
        success: lifted by :data:`LIFT_HEIGHT_M` and held :data:`HOLD_DURATION_S` with less
            than :data:`MAX_SLIP_M` slip and :data:`MAX_TURN_RAD` turn in the palm frame.
        failure: why it failed (``None`` on success): ``"not_lifted"`` (never reached the lift
            height), ``"dropped"`` (lifted, but below the lift height at the end),
            ``"slipped"`` / ``"turned"`` (still lifted at the end, but its hold window ended
            when the object had moved :data:`MAX_SLIP_M` or turned :data:`MAX_TURN_RAD` or
            more in the palm frame; slip is checked first), ``"hold_incomplete"`` (still lifted
            and within both limits, held for less than the hold duration), ``"diverged"``
            (physics).
        max_lift_m: highest rise of the object origin above its rest height, metres.
        slip_m: on success the largest slip of the successful window; otherwise the largest
            slip of any window, metres.
        turn_rad: the same for the turn (rotation angle of the object in the palm frame),
            radians.
        hold_s: duration of the last hold window, seconds.
        success_time_s: episode time at which the hold completed (``None`` on failure).
        steps: control steps run.
    """

    success: bool
    failure: FailureReason | None
    max_lift_m: float
    slip_m: float
    turn_rad: float
    hold_s: float
    success_time_s: float | None
    steps: int

    def to_dict(self) -> dict[str, object]:
        """A JSON-serializable dict of the fields."""
        return dataclasses.asdict(self)


def _rotation_angle_rad(R: np.ndarray) -> float:  # noqa: N803
    """The angle of a rotation matrix, radians in [0, pi].

    ``atan2(sin, cos)`` from the skew part and the trace: accurate at small angles, where
    ``arccos((trace - 1) / 2)`` loses half the digits.

    Args:
        R: (3, 3) rotation matrix.
    """
    sin = 0.5 * math.sqrt(
        (R[2, 1] - R[1, 2]) ** 2 + (R[0, 2] - R[2, 0]) ** 2 + (R[1, 0] - R[0, 1]) ** 2
    )
    cos = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    return math.atan2(sin, cos)


class LiftTracker:
    """Per-step evaluation of the lift success definition (module docstring).

    Feed every control step with :meth:`update`; :attr:`success` turns true once an object has
    been held lifted for :data:`HOLD_DURATION_S` with slip below :data:`MAX_SLIP_M` and turn
    below :data:`MAX_TURN_RAD`, and stays true. :meth:`outcome` summarizes the episode so far.

    The hold window opens at the first step at which the object is lifted; the object's pose
    in the palm frame at that step is the reference of the whole window. A window that reaches
    either limit ends the hold: no new window opens until the object has been below the lift
    height again (a reference taken while the object still slides would hide the slip).

    Args:
        rest_height_m: height of the object origin at rest (episode start), metres.
        lift_height_m: the lift threshold (default :data:`LIFT_HEIGHT_M`).
        hold_s: the hold duration (default :data:`HOLD_DURATION_S`).
        max_slip_m: the slip threshold (default :data:`MAX_SLIP_M`).
        max_turn_rad: the turn threshold (default :data:`MAX_TURN_RAD`).
    """

    def __init__(
        self,
        rest_height_m: float,
        *,
        lift_height_m: float = LIFT_HEIGHT_M,
        hold_s: float = HOLD_DURATION_S,
        max_slip_m: float = MAX_SLIP_M,
        max_turn_rad: float = MAX_TURN_RAD,
    ) -> None:
        for name, value in (
            ("rest_height_m", rest_height_m),
            ("lift_height_m", lift_height_m),
            ("hold_s", hold_s),
            ("max_slip_m", max_slip_m),
            ("max_turn_rad", max_turn_rad),
        ):
            if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value)):
                raise InvalidGraspState(f"{name} must be a finite number; received {value!r}")
        if lift_height_m <= 0 or hold_s <= 0 or max_slip_m <= 0 or max_turn_rad <= 0:
            raise InvalidGraspState(
                "lift_height_m, hold_s, max_slip_m and max_turn_rad must be > 0; received "
                f"{lift_height_m}, {hold_s}, {max_slip_m}, {max_turn_rad}"
            )
        self.rest_height_m = float(rest_height_m)
        self.lift_height_m = float(lift_height_m)
        self.hold_s = float(hold_s)
        self.max_slip_m = float(max_slip_m)
        self.max_turn_rad = float(max_turn_rad)
        self.success = False
        self.success_time_s: float | None = None
        self.max_lift_m = -math.inf
        self.steps = 0
        self._window_start_s: float | None = None
        self._window_pos_palm: np.ndarray | None = None
        self._window_R_palm: np.ndarray | None = None
        self._window_slip_m = 0.0
        self._window_turn_rad = 0.0
        self._last_time_s = -math.inf
        self._ever_lifted = False
        self._broken: FailureReason | None = None
        # Set when a window reached a limit; cleared once the object is below the lift height.
        self._hold_ended = False
        self._break_slip_m = 0.0
        self._break_turn_rad = 0.0
        self._window_duration_s = 0.0

    def update(
        self, time_s: float, T_world_from_obj: np.ndarray, T_world_from_palm: np.ndarray
    ) -> bool:
        """Add one step.

        Args:
            time_s: episode time, seconds (increasing).
            T_world_from_obj: (4, 4) pose of the object body (its origin), world frame.
            T_world_from_palm: (4, 4) pose of the palm (hand root) body, world frame.

        Returns:
            :attr:`success` after this step.

        Raises:
            InvalidGraspState: for non-increasing time or malformed arrays.
        """
        self._check_time(time_s)
        obj = _check_transform(T_world_from_obj, "T_world_from_obj")
        palm = _check_transform(T_world_from_palm, "T_world_from_palm")
        return self._update(time_s, obj[:3, :3], obj[:3, 3], palm[:3, :3], palm[:3, 3])

    def _check_time(self, time_s: float) -> None:
        if not time_s > self._last_time_s:
            raise InvalidGraspState(
                f"time_s must increase from step to step; received {time_s} after "
                f"{self._last_time_s}"
            )

    def _update(
        self,
        time_s: float,
        R_world_from_obj: np.ndarray,  # noqa: N803
        pos: np.ndarray,
        R_world_from_palm: np.ndarray,  # noqa: N803
        palm_pos: np.ndarray,
    ) -> bool:
        """:meth:`update` on checked arrays."""
        self._last_time_s = float(time_s)
        self.steps += 1
        if self.success:
            return True
        lift = float(pos[2] - self.rest_height_m)
        self.max_lift_m = max(self.max_lift_m, lift)
        if lift < self.lift_height_m:
            if self._window_start_s is not None:
                self._broken = "dropped"
            self._close_window()
            self._hold_ended = False
            return False
        self._ever_lifted = True
        if self._hold_ended:
            return False
        pos_palm = R_world_from_palm.T @ (pos - palm_pos)
        R_palm_from_obj = R_world_from_palm.T @ R_world_from_obj  # noqa: N806
        if self._window_start_s is None:
            self._open_window(time_s, pos_palm, R_palm_from_obj)
            return False
        slip = float(np.linalg.norm(pos_palm - self._window_pos_palm))
        turn = _rotation_angle_rad(self._window_R_palm.T @ R_palm_from_obj)
        self._window_slip_m = max(self._window_slip_m, slip)
        self._window_turn_rad = max(self._window_turn_rad, turn)
        if slip >= self.max_slip_m or turn >= self.max_turn_rad:
            self._broken = "slipped" if slip >= self.max_slip_m else "turned"
            self._break_slip_m = max(self._break_slip_m, self._window_slip_m)
            self._break_turn_rad = max(self._break_turn_rad, self._window_turn_rad)
            self._window_duration_s = time_s - self._window_start_s
            self._close_window()
            self._hold_ended = True
            return False
        self._window_duration_s = time_s - self._window_start_s
        # A small tolerance absorbs float round-off in time stamps (k * dt).
        if self._window_duration_s >= self.hold_s - 1e-9:
            self.success = True
            self.success_time_s = float(time_s)
        return self.success

    def _open_window(self, time_s: float, pos_palm: np.ndarray, R_palm: np.ndarray) -> None:  # noqa: N803
        self._window_start_s = float(time_s)
        self._window_pos_palm = pos_palm
        self._window_R_palm = R_palm
        self._window_slip_m = 0.0
        self._window_turn_rad = 0.0
        self._window_duration_s = 0.0

    def _close_window(self) -> None:
        self._window_start_s = None
        self._window_pos_palm = None
        self._window_R_palm = None

    def update_from_sim(self, scene: Scene, instance: int, time_s: float) -> bool:
        """:meth:`update` with the ground truth of ``scene`` (object ``instance``)."""
        body_id = _object_body_id(scene, instance)
        palm_id = int(scene.model.body(scene.hand.root_body).id)
        data = scene.data
        self._check_time(time_s)
        pos, palm_pos = data.xpos[body_id], data.xpos[palm_id]
        R_obj = data.xmat[body_id].reshape(3, 3)  # noqa: N806
        R = data.xmat[palm_id].reshape(3, 3)  # noqa: N806
        # MuJoCo's xmat is a rotation; only a diverged state could be non-finite.
        finite = np.isfinite(pos).all() and np.isfinite(palm_pos).all()
        if not (finite and np.isfinite(R).all() and np.isfinite(R_obj).all()):
            raise InvalidGraspState(
                f"the scene's object or palm pose is not finite (object at {pos}); the physics "
                "diverged"
            )
        return self._update(time_s, R_obj.copy(), pos.copy(), R.copy(), palm_pos.copy())

    def outcome(self, diverged: bool = False) -> GraspOutcome:
        """The outcome of the episode so far (call at its end).

        Args:
            diverged: the physics diverged (the episode was cut short).
        """
        failure: FailureReason | None
        if self.success:
            failure = None
        elif diverged:
            failure = "diverged"
        elif not self._ever_lifted:
            failure = "not_lifted"
        elif self._hold_ended:
            failure = self._broken  # still lifted after the window reached a limit
        elif self._window_start_s is None:
            failure = "dropped"
        else:
            failure = "hold_incomplete"
        return GraspOutcome(
            success=self.success,
            failure=failure,
            max_lift_m=float(self.max_lift_m) if self.steps else 0.0,
            slip_m=float(
                self._window_slip_m
                if self.success
                else max(self._window_slip_m, self._break_slip_m)
            ),
            turn_rad=float(
                self._window_turn_rad
                if self.success
                else max(self._window_turn_rad, self._break_turn_rad)
            ),
            hold_s=float(self._window_duration_s),
            success_time_s=self.success_time_s,
            steps=self.steps,
        )


def evaluate_lift(
    times_s: np.ndarray,
    T_world_from_obj: np.ndarray,
    T_world_from_palm: np.ndarray,
    rest_height_m: float,
) -> GraspOutcome:
    """Evaluate a recorded trajectory against the success definition.

    Args:
        times_s: (T,) increasing episode times, seconds.
        T_world_from_obj: (T, 4, 4) object poses (the body origin), world frame.
        T_world_from_palm: (T, 4, 4) palm poses, world frame.
        rest_height_m: height of the object origin at rest, metres.

    Returns:
        The outcome, as :class:`LiftTracker` would give after the last step.

    Raises:
        InvalidGraspState: for mismatched shapes or non-increasing times.
    """
    times = np.asarray(times_s, dtype=np.float64)
    obj = np.asarray(T_world_from_obj, dtype=np.float64)
    palm = np.asarray(T_world_from_palm, dtype=np.float64)
    if times.ndim != 1 or obj.shape != (len(times), 4, 4) or palm.shape != (len(times), 4, 4):
        raise InvalidGraspState(
            "expected times_s (T,), T_world_from_obj (T, 4, 4) and T_world_from_palm "
            f"(T, 4, 4); received {times.shape}, {obj.shape}, {palm.shape}"
        )
    tracker = LiftTracker(rest_height_m)
    for t, T_obj, T_palm in zip(times, obj, palm, strict=True):
        tracker.update(float(t), T_obj, T_palm)
    return tracker.outcome()
