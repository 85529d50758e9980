"""Where grasps fail under tracking noise: the reactive operator, with one part made clean.

Run: ``python benchmarks/teleop_stages.py [--noise-mm 10] [--latency 0] [--dropout 0]
[--filter none] [--beta 1] [--pose-filter on|off|wrist|auto] [--pose-filter-params JSON]
[--grasp-intent on|off]
[--closure-assist on|off] [--pose-prior on|off] [--keypoint-sigma-mm MM]
[--intent-params JSON] [--intent-oracle none|posture|flex|spread]
[--motor-noise on|off|wrist|joints] [--correction on|off] [--clean none|wrist|fingers]
[--clean-from PHASE] [--grip-steady on|off|hand] [--angle-error] [--episodes 20]
[--trace SEED] [--out FILE]``.

Runs ``handsim/Grasp-v0`` with :class:`~handsim.envs.teleop.operator.ReactiveOperator` for
seeds ``0 .. episodes - 1`` under the given faults. ``--clean wrist`` replaces the wrist of
every retargeted (and, with the pose filter, filtered) pose by the operator's own, so only
the fingers carry the tracking noise; ``--clean fingers`` the 21 joint angles, so only the
wrist does; ``--clean-from PHASE`` only from that phase of the operator's expert on (the
clean part replaces the pose filter's output: it has neither the noise nor the filter's
lag). ``--intent-oracle`` (with ``--grasp-intent on``) replaces, while the hand is in
grasp intent, the fingers' targets (``posture``), their flexion joints (``flex``) or their
spread joints (``spread``) by the operator's own: what a perfect intent posture would give.
Each failure is put in the stage it ended in: ``approach`` (the expert still
reaching or approaching), ``closure`` (the object never rose 2 cm), ``lift`` (it rose, but
not to 9.5 cm) or ``hold`` (lifted, then dropped, slipped or turned), and given a cause
from the episode's observations: ``pushed before closure`` (the object moved 15 mm on the
table before the expert closed), ``closed without a grasp`` (it hardly moved and never rose
2 cm), ``pushed during closure``, ``slipped during lift``, ``dropped in hold`` or
``slip/turn in hold`` (held, but it slipped 1 cm or turned 10 deg in the hand). Prints and
writes (``benchmarks/results/teleop_stages.json`` by default, one entry per configuration)
the success rate, the stage and cause counts, per seed the object, the first digits to touch
it (and in which phase), its slip and turn and the wrist's mean error per phase, and the wall
time. ``--trace SEED`` prints, every 4th control
step of that seed's episode, the expert's phase, whether the hand is in grasp intent, which
digits touch an object (thumb to little) and how far the target object has moved, mm.
``--angle-error`` adds, per phase of the operator's expert, the flexion targets' error against
the operator's own angles (after the retargeting and the pose filter, before the grip): each
joint's bias and standard deviation, averaged over the joints.
"""

from __future__ import annotations

import argparse
import collections
import json
import pathlib
import time
from typing import Any

import numpy as np

from handsim.envs.teleop import FaultConfig, TeleopConfig, TeleopLoop
from handsim.envs.teleop.operator import ReactiveOperator


class _Clean:
    """A pose filter stand-in that puts the operator's own wrist or joints into the pose."""

    def __init__(
        self, inner: Any, part: str, operator: dict[str, Any], phases: tuple[str, ...] = ()
    ) -> None:
        self.inner, self.part, self.operator, self.phases = inner, part, operator, phases

    def __call__(self, pose: np.ndarray) -> np.ndarray:
        out = np.array(self.inner(pose) if self.inner is not None else pose)
        if self.phases and self.operator.get("phase") not in self.phases:
            return out
        truth = self.operator["pose"]
        if self.part == "wrist":
            out[:6] = truth[:6]
        elif self.part == "fingers":
            out[6:] = truth[6:]
        return out


_PUSH_M = 0.015  # the object moved this far on the table: pushed, not grasped
_CLOSING = ("close", "squeeze", "settle")


def _observe(base: Any, phase: str, diag: dict[str, Any], state: dict[str, Any]) -> None:
    """Per step: where the target is, which digits touch it, the wrist's error, by phase."""
    from handsim.envs.teleop.grip import DigitContacts

    if "contacts" not in diag:
        diag["contacts"] = DigitContacts(base.scene)
        diag["name"] = base.scene.objects[base.target_instance][1].name
    pos = base._object_pose(base.target_instance)[:3, 3].copy()
    diag.setdefault("start", pos)
    moved = float(np.linalg.norm((pos - diag["start"])[:2]))
    if phase in _CLOSING and "moved_at_close_m" not in diag:
        diag["moved_at_close_m"] = moved
    if phase == "lift" and "moved_at_lift_m" not in diag:
        diag["moved_at_lift_m"] = moved
    touch = diag["contacts"].touching(base.scene.data)
    if touch.any() and "first_touch" not in diag:
        diag["first_touch"] = (phase, [int(d) for d in np.flatnonzero(touch)])
    physical = base.scene.binding.keypoints(base.scene.data)[0]
    operator = state.get("operator_world")
    if operator is not None and np.all(np.isfinite(operator[0])):
        key = "approach" if phase in ("wait", "reach", "approach") else phase
        diag.setdefault("wrist_err", {}).setdefault(key, []).append(
            float(np.linalg.norm(physical - operator[0]))
        )
    info = base._task_info()
    diag["slip_m"], diag["turn_rad"] = info["slip_m"], info["turn_rad"]
    diag["moved_m"] = moved


def _cause(stage: str, diag: dict[str, Any], lifts: list[float]) -> dict[str, Any]:
    """The failure's cause from the episode's observations (``ok`` for a success)."""
    at_close = diag.get("moved_at_close_m", diag.get("moved_m", 0.0))
    at_lift = diag.get("moved_at_lift_m", diag.get("moved_m", 0.0))
    if stage == "success":
        cause = "ok"
    elif at_close > _PUSH_M:
        cause = "pushed before closure"
    elif stage in ("approach", "closure"):
        cause = "pushed during closure" if at_lift > _PUSH_M else "closed without a grasp"
    elif stage == "lift":
        cause = "slipped during lift"
    elif lifts[-1] < 0.02:
        cause = "dropped in hold"
    else:
        cause = "slip/turn in hold"
    first = diag.get("first_touch")
    wrist = {k: round(1e3 * float(np.mean(v)), 1) for k, v in diag.get("wrist_err", {}).items()}
    return {
        "cause": cause,
        "object": diag.get("name"),
        "moved_at_close_mm": round(1e3 * at_close, 1),
        "moved_at_lift_mm": round(1e3 * at_lift, 1),
        "first_touch": None if first is None else f"{first[0]}:{first[1]}",
        "slip_mm": round(1e3 * float(diag.get("slip_m", np.nan)), 1),
        "turn_deg": round(float(np.degrees(diag.get("turn_rad", np.nan))), 1),
        "wrist_err_mm": wrist,
    }


def _angle_error(errors: dict[str, list[np.ndarray]]) -> dict[str, dict[str, float]]:
    """Per expert phase: the flexion targets' error against the operator's, rad.

    ``bias``: the mean over joints of each joint's mean error's magnitude; ``std``: the mean
    over joints of each joint's error's standard deviation (noise and lag).
    """
    from handsim.hand.pose import JOINT_NAMES

    flex = np.array(["flex" in n for n in JOINT_NAMES])
    out = {}
    for phase, rows in errors.items():
        e = np.array(rows)[:, flex]
        out[phase] = {
            "bias_rad": round(float(np.mean(np.abs(e.mean(axis=0)))), 3),
            "std_rad": round(float(np.mean(e.std(axis=0))), 3),
            "steps": len(rows),
        }
    return out


def run(args: argparse.Namespace) -> dict[str, Any]:
    """The episodes of one configuration: success rate, stage counts, wall time."""
    import handsim.envs.teleop.channel as channel_module
    from handsim.envs.teleop.pose_filter import make_pose_filter
    from handsim.hand.kinematics import ForwardKinematics

    operator_pose: dict[str, Any] = {}
    if args.clean != "none" or args.intent_oracle != "none" or args.angle_error:
        # The operator's pose of this step: the one its keypoints are made from.
        keypoints = ForwardKinematics.keypoints

        def spy(self: Any, pose: Any) -> np.ndarray:
            operator_pose["pose"] = pose.vector.copy()
            return keypoints(self, pose)

        ForwardKinematics.keypoints = spy  # type: ignore[method-assign]
    if args.intent_oracle != "none":
        from handsim.envs.teleop.intent import GraspIntent
        from handsim.hand.pose import JOINT_NAMES

        flex = np.array(["flex" in n for n in JOINT_NAMES])
        part = {"posture": np.ones(21, bool), "flex": flex, "spread": ~flex}[args.intent_oracle]
        intent_call = GraspIntent.__call__

        def oracle(self: Any, target: np.ndarray, tracked: Any, data: Any) -> np.ndarray:
            out = intent_call(self, target, tracked, data)
            if self.grasping:
                out[6:][part] = operator_pose["pose"][6:][part]
            return out

        GraspIntent.__call__ = oracle  # type: ignore[method-assign]
    if args.clean != "none":
        use_filter = args.pose_filter != "off"

        def clean_filter(rate_hz: float, **params: Any) -> Any:
            params["wrist_only"] = args.pose_filter == "wrist"
            inner = make_pose_filter(rate_hz, **params) if use_filter else None
            order = ("wait", "reach", "approach", "close", "squeeze", "settle", "lift", "hold")
            phases = order[order.index(args.clean_from) :] if args.clean_from else ()
            return _Clean(inner, args.clean, operator_pose, phases)

        channel_module.make_pose_filter = clean_filter  # type: ignore[assignment]
    config = TeleopConfig(
        faults=FaultConfig(
            noise_mm=args.noise_mm, latency_frames=args.latency, dropout=args.dropout
        ),
        filter=args.filter,
        filter_params={"beta": args.beta} if args.filter == "one_euro" else {},
        # The clean part goes in where the pose filter sits.
        pose_filter=(
            True
            if args.pose_filter == "on" or (args.clean != "none" and args.pose_filter == "off")
            else (args.pose_filter if args.pose_filter in ("wrist", "auto") else False)
        ),
        pose_filter_params=json.loads(args.pose_filter_params),
        grip_steady={"on": True, "off": False, "hand": "hand"}[args.grip_steady],
        grasp_intent=args.grasp_intent == "on",
        intent_params=json.loads(args.intent_params),
        closure_assist=args.closure_assist == "on",
        pose_prior=args.pose_prior == "on",
        keypoint_sigma_mm=args.keypoint_sigma_mm,
    )
    quiet: dict[str, Any] = {
        "on": {},
        "off": {"motor_noise_mm": 0.0, "motor_noise_rad": 0.0},
        "wrist": {"motor_noise_rad": 0.0},
        "joints": {"motor_noise_mm": 0.0},
    }[args.motor_noise]
    if args.correction == "off":
        quiet["correction_s"] = None
    stages = []
    intent_s: list[float] = []
    assist_s: list[float] = []
    assisted: list[bool] = []
    details: list[dict[str, Any]] = []
    start = time.perf_counter()
    errors: dict[str, list[np.ndarray]] = collections.defaultdict(list)
    if args.angle_error:
        action = channel_module.HandChannel.action

        def measured(self: Any, tracked: Any, data: Any) -> np.ndarray:
            # The channel's target (retargeted and filtered) against the operator's angles.
            if "pose" in operator_pose and "phase" in operator_pose:
                errors[operator_pose["phase"]].append(self.target[6:] - operator_pose["pose"][6:])
            return action(self, tracked, data)

        channel_module.HandChannel.action = measured  # type: ignore[method-assign]
    with TeleopLoop("handsim/Grasp-v0", config) as loop:
        base = loop.env.unwrapped
        intent_flag: list[bool] = [False]
        if args.trace is not None:
            from handsim.envs.teleop.intent import GraspIntent

            traced_call = GraspIntent.__call__

            def flagged(self: Any, target: np.ndarray, tracked: Any, data: Any) -> np.ndarray:
                out = traced_call(self, target, tracked, data)
                intent_flag[0] = self.grasping
                return out

            GraspIntent.__call__ = flagged  # type: ignore[method-assign]
        for seed in range(args.episodes):
            op = ReactiveOperator(
                loop.env, seed, display_latency_s=args.latency * loop.control_dt, **quiet
            )
            lifts: list[float] = []
            phase: list[str] = []
            diag: dict[str, Any] = {}
            start_pos = np.zeros(3)
            if seed == args.trace:
                loop.env.reset(seed=seed)  # the object's start
                start_pos = base._object_pose(base.target_instance)[:3, 3].copy()

            def on_step(
                i: int,
                state: dict[str, Any],
                op: Any = op,
                lifts: list = lifts,
                phase: list = phase,
                seed: int = seed,
                start_pos: np.ndarray = start_pos,
                diag: dict[str, Any] = diag,
            ) -> None:
                lifts.append(float(base._task_info()["lift_m"]))
                phase[:] = [op._expert.phase]
                operator_pose["phase"] = phase[0]
                _observe(base, phase[0], diag, state)
                if seed == args.trace and i % 4 == 0:
                    from handsim.envs.teleop.grip import DigitContacts

                    moved = base._object_pose(base.target_instance)[:3, 3] - start_pos
                    touch = DigitContacts(base.scene).touching(base.scene.data).astype(int)
                    print(
                        f"trace step {i:4d} {phase[0]:8s} intent {int(intent_flag[0])} "
                        f"touching {''.join(map(str, touch))} object moved "
                        f"{np.round(moved * 1e3, 1).tolist()} mm"
                    )

            metrics = loop.run(op, seed, on_step=on_step).metrics
            intent_s.append(metrics["intent_grasp_s"])
            assist_s.append(metrics["closure_assist_s"])
            assisted.append(metrics["success_assisted"])
            lift = max(lifts)
            if metrics["success"]:
                stage = "success"
            elif phase[0] in ("wait", "reach", "approach"):
                stage = "approach"
            elif lift < 0.02:
                stage = "closure"
            elif lift < 0.095:
                stage = "lift"
            else:
                stage = "hold"
            stages.append(stage)
            detail = _cause(stage, diag, lifts)
            details.append({"seed": seed, "stage": stage, **detail})
    counts = collections.Counter(stages)
    return {
        "config": {k: v for k, v in vars(args).items() if k != "out"},
        "success_rate": counts["success"] / len(stages),
        "stages": dict(counts),
        "per_seed": stages,
        "causes": dict(collections.Counter(d["cause"] for d in details if d["stage"] != "success")),
        "details": details,
        "intent_grasp_s": round(float(np.mean(intent_s)), 2),
        "closure_assist_s": round(float(np.mean(assist_s)), 2),
        "assisted_successes": int(np.sum(assisted)),
        "angle_error": _angle_error(errors),
        "wall_s": round(time.perf_counter() - start, 1),
    }


def main() -> None:
    """Parse the options, run, print and append the result to ``--out``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--noise-mm", type=float, default=10.0)
    p.add_argument("--latency", type=int, default=0)
    p.add_argument("--dropout", type=float, default=0.0)
    p.add_argument("--filter", choices=("none", "one_euro"), default="none")
    p.add_argument("--beta", type=float, default=1.0)
    p.add_argument("--pose-filter", choices=("on", "off", "wrist", "auto"), default="off")
    p.add_argument("--pose-filter-params", default="{}", help="e.g. '{\"beta_joint\": 1}'")
    p.add_argument("--grasp-intent", choices=("on", "off"), default="off")
    p.add_argument("--closure-assist", choices=("on", "off"), default="off")
    p.add_argument("--pose-prior", choices=("on", "off"), default="off")
    p.add_argument(
        "--keypoint-sigma-mm",
        type=lambda v: v if v == "auto" else float(v),
        default=None,
        help="a number or 'auto' (default: --noise-mm)",
    )
    p.add_argument("--intent-params", default="{}", help="e.g. '{\"press_rad\": 0.2}'")
    p.add_argument("--intent-oracle", choices=("none", "posture", "flex", "spread"), default="none")
    p.add_argument("--motor-noise", choices=("on", "off", "wrist", "joints"), default="off")
    p.add_argument("--correction", choices=("on", "off"), default="on")
    p.add_argument("--clean", choices=("none", "wrist", "fingers"), default="none")
    p.add_argument(
        "--clean-from",
        choices=("close", "squeeze", "settle", "lift", "hold"),
        default=None,
        help="make --clean's part clean only from this phase of the operator's expert on",
    )
    p.add_argument("--grip-steady", choices=("on", "off", "hand"), default="off")
    p.add_argument(
        "--angle-error",
        action="store_true",
        help="report per phase the flexion targets' error against the operator's angles",
    )
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--trace", type=int, default=None, help="print this seed's steps")
    p.add_argument("--out", default="benchmarks/results/teleop_stages.json")
    args = p.parse_args()
    result = run(args)
    print(json.dumps(result))
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    runs = json.loads(out.read_text()) if out.is_file() else []
    runs.append(result)
    out.write_text(json.dumps(runs, indent=1))


if __name__ == "__main__":
    main()
