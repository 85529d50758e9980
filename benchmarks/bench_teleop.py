"""Benchmark: the teleop loop's steps per second on one core, per mode, with the time per stage.

Run: ``python benchmarks/bench_teleop.py [--steps 300] [--repeats 2] [--live-s 5] [--only live|loop]
[--out FILE]``.

After the live runs the process is pinned to one CPU core (``os.sched_setaffinity``; Mesa's
software rasterizer runs without worker threads, ``LP_NUM_THREADS=0``). For each task
(Grasp-v0 and Press-v0, their scripted experts' streams of seed 0, replayed with the operator
holding still after the stream ends) it measures, best of ``--repeats`` interleaved runs of
``--steps`` steps:

- ``physics_only``: ``env.step`` with the stream's poses as actions (no tracking): the limit;
- ``direct``: the loop in direct mode with 5 mm noise and the One Euro filter (faults, filter,
  retargeting, physics);
- ``camera_oracle``: camera mode, 320 x 240 ICVL capture of the operator hand, no sensor noise,
  the oracle estimator;
- ``camera_oracle_structured_light``: the same with the structured-light sensor model.

Each entry has ``steps_per_s``, ``ratio_to_physics`` and ``stage_ms`` (mean per step: capture,
estimator, faults, filter, retarget, physics). The goal is >= 90 steps/s (a headset's rate)
with the oracle and in direct mode.

``live`` (skip with ``--live-s 0``): a sender process streams the press expert's motion,
resampled to 90 and 120 Hz, over local UDP (each packet stamped with Unix time) into the live
loop (direct mode, real time, :class:`~handsim.envs.teleop.sampling.LiveSampler`) for
``--live-s`` seconds, at the control rate sized to the stream and, as the control, at the
envs' fixed 50 Hz, and at 90 Hz with 10 ms and with automatic prediction; per run: the
control rate, the real-time factor, the fraction of packets ever applied, the end-to-end
latency (sender timestamp -> after the physics step) p50 / p95 in ms and what is left of it
after the prediction, and the kernel's UDP drops. Results go to
``benchmarks/results/bench_teleop.json``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import platform
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.teleop import (
    FaultConfig,
    LiveSampler,
    TeleopConfig,
    TeleopLoop,
    UdpReceiver,
    stream_from_expert,
)
from handsim.envs.teleop.sender import send_stream
from handsim.estimators import OracleEstimator

TASKS = {"handsim/Grasp-v0": {}, "handsim/Press-v0": {"task": "button"}}
MODES = {
    "direct": (TeleopConfig(faults=FaultConfig(noise_mm=5.0), filter="one_euro"), False),
    "camera_oracle": (TeleopConfig(mode="camera"), True),
    "camera_oracle_structured_light": (
        TeleopConfig(mode="camera", sensor="structured_light"),
        True,
    ),
}


def _physics_rate(env_id: str, kwargs: dict, actions: np.ndarray, steps: int) -> float:
    env = gym.make(env_id, obs_mode="state", **kwargs)
    env.reset(seed=0)
    start = time.perf_counter()
    for i in range(steps):
        _, _, terminated, truncated, _ = env.step(actions[min(i + 1, len(actions) - 1)])
        if truncated:
            env.reset(seed=0)
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def _send_forever(stream, port: int) -> None:
    while True:
        send_stream(stream, port)


def _live(
    stream, rate_hz: float, control_hz: float, seconds: float, predict_s: float | str = 0.0
) -> dict:
    """One live session: a sender process at ``rate_hz``, the loop at ``control_hz``."""
    with UdpReceiver(0) as rx:
        sender = multiprocessing.get_context("fork").Process(
            target=_send_forever, args=(stream.resample(rate_hz), rx.port), daemon=True
        )
        sender.start()
        try:
            rx.wait_for(1, 30.0)
            env_kwargs = {"task": "button"}
            with TeleopLoop(
                "handsim/Press-v0",
                env_kwargs=env_kwargs,
                control_rate_hz=control_hz,
                episode_s=seconds,
            ) as loop:
                sampler = LiveSampler(rx, predict_s=predict_s)
                steps = int(round(seconds / loop.control_dt))
                start = dict(rx.counters)
                m = loop.run(sampler, 0, max_steps=steps, realtime=True, stop_at_success=False)
                m = m.metrics
                accepted = rx.counters["accepted"] - start["accepted"]
        finally:
            sender.kill()
            sender.join()
    return {
        "stream_hz": rate_hz,
        "control_hz": 1.0 / m["control_dt_s"],
        "realtime_factor": m["realtime_factor"],
        "packets_used_fraction": min(1.0, sampler.packets_used / max(accepted, 1)),
        "latency_p50_ms": m["latency_p50_ms"],
        "latency_p95_ms": m["latency_p95_ms"],
        "latency_clock": m["latency_clock"],
        "predict_ms": 1e3 * m["predict_s"],
        "predict_auto": m["predict_auto"],
        "residual_latency_p50_ms": m["residual_latency_p50_ms"],
        "residual_latency_p95_ms": m["residual_latency_p95_ms"],
        "kernel_dropped": rx.counters["kernel_dropped"],
        "stage_ms": m["stage_ms"],
    }


def main() -> None:
    """Run the benchmark and write its JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", default="benchmarks/results/bench_teleop.json")
    parser.add_argument("--live-s", type=float, default=5.0)
    parser.add_argument("--only", choices=("live", "loop"), default=None)
    args = parser.parse_args()
    if args.only == "loop":
        args.live_s = 0.0
    cores = sorted(os.sched_getaffinity(0))
    results_live = []
    if args.live_s > 0:
        # Before pinning: the sender process gets the other cores.
        press = stream_from_expert("handsim/Press-v0", 0, env_kwargs={"task": "button"})
        print(f"live, direct mode, {args.live_s:g} s each (sender in its own process):")
        runs = [(90.0, 90.0, 0.0), (90.0, 50.0, 0.0), (120.0, 120.0, 0.0), (120.0, 50.0, 0.0)]
        runs.append((90.0, 90.0, 0.01))  # prediction: the residual latency drops by 10 ms
        runs.append((90.0, 90.0, "auto"))  # by the measured latency: residual about 0
        for rate, control, predict_s in runs:
            run = _live(press, rate, control, args.live_s, predict_s)
            results_live.append(run)
            auto = " (auto)" if run["predict_auto"] else ""
            print(
                f"  stream {rate:3.0f} Hz, control {run['control_hz']:5.1f} Hz, predict "
                f"{run['predict_ms']:4.1f} ms{auto}: real time x{run['realtime_factor']:.2f}, "
                f"packets applied {100 * run['packets_used_fraction']:3.0f} %, latency p50 "
                f"{run['latency_p50_ms']:.1f} ms, p95 {run['latency_p95_ms']:.1f} ms "
                f"({run['latency_clock']} clock), after prediction p50 "
                f"{run['residual_latency_p50_ms']:.1f} ms, kernel drops {run['kernel_dropped']}"
            )
    core = cores[0]
    os.sched_setaffinity(0, {core})
    results: dict = {
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "pinned_core": core,
            "load_average": os.getloadavg(),
        },
        "steps": args.steps,
        "tasks": {},
        "live": results_live,
    }
    for env_id, kwargs in TASKS.items() if args.only != "live" else ():
        stream = stream_from_expert(env_id, 0, env_kwargs=kwargs)
        entry: dict = {"stream_frames": len(stream)}
        best: dict = {}
        for _ in range(args.repeats):
            rate = _physics_rate(env_id, kwargs, stream.poses, args.steps)
            best["physics_only"] = max(
                best.get("physics_only", {"steps_per_s": 0}),
                {"steps_per_s": rate},
                key=lambda d: d["steps_per_s"],
            )
            for name, (config, camera) in MODES.items():
                estimator = OracleEstimator(rng=0) if camera else None
                with TeleopLoop(env_id, config, estimator=estimator, env_kwargs=kwargs) as loop:
                    loop.run(stream, 0, max_steps=5)  # warm-up: scene, renderer, GL context
                    m = loop.run(stream, 0, max_steps=args.steps, stop_at_success=False).metrics
                run = {
                    "steps_per_s": m["steps_per_s"],
                    "stage_ms": m["stage_ms"],
                    "success": m["success"],
                }
                if run["steps_per_s"] > best.get(name, {"steps_per_s": 0})["steps_per_s"]:
                    best[name] = run
        physics = best["physics_only"]["steps_per_s"]
        for run in best.values():
            run["ratio_to_physics"] = run["steps_per_s"] / physics
        entry.update(best)
        results["tasks"][env_id] = entry
        print(f"{env_id} ({args.steps} steps, one core {core}, best of {args.repeats}):")
        for name, run in best.items():
            stages = ", ".join(f"{k} {v:.2f}" for k, v in run.get("stage_ms", {}).items())
            goal = (
                ""
                if name == "physics_only"
                else ("  >= 90 Hz" if run["steps_per_s"] >= 90 else "  < 90 Hz goal")
            )
            print(
                f"  {name:32s} {run['steps_per_s']:7.1f} steps/s  "
                f"x{run['ratio_to_physics']:.2f} of physics{goal}"
            )
            if stages:
                print(f"  {'':32s} ms/step: {stages}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(f"results: {out}")


if __name__ == "__main__":
    main()
