"""Benchmark: env step rates, vector-env scaling, the closed loop, and memory over 10^4 steps.

Run: ``python benchmarks/bench_envs.py [--steps 300] [--memory-steps 10000] [--repeats 2]
[--only {all,vector,obs_modes,rgb_array,resolution,peer}] [--limit] [--out FILE.json]``.

``--limit`` runs only the ratios of "the step at the limit" (also printed at the end of a full
run), each measured interleaved step by step in this run and timed in process CPU time (on a
shared machine wall time mostly measures the other processes; MuJoCo and the software renderer
run in this thread since ``import handsim`` sets ``LP_NUM_THREADS=0``; wall rates are in the
JSON too):

1. physics of a held grasp's control step against bare ``mj_step`` calls (``bench_grasp.py``);
2. for each env, its labelled frame against MuJoCo's plain depth render (``mujoco.Renderer``)
   of the same state, the silhouettes kept as the env keeps them;
3. for each env, the step with its expert (the expert's decision + ``env.step``, and
   ``env.step`` alone) against bare physics (``mj_step`` x frame skip on a copy of the state) +
   the plain depth render; and, when ``gymnasium-robotics`` is installed, Grasp-v0 and
   GraspClutter-v0 (with the skin's level of detail chosen by projected size, as every env of
   the limit, and with ``skin_detail="full"``, the envs' default) against the peer
   ``HandManipulateBlock-v1`` stepping with a
   320 x 240 RGB render, Gymnasium's depth render (with a shadow pass) or a plain depth render
   (``mujoco.Renderer``) (MuJoCo 4's enums need a small shim in its helpers,
   :func:`_shim_gymnasium_robotics`); ``--only peer`` measures just these;
4. Grasp-v0 step + 320 x 240 ``rgb_array`` render (``render_quality="fast"`` and ``"high"``)
   against the depth step;
5. ``EstimatorLoop`` with the oracle, feedback on against off.

The JSON goes to ``benchmarks/results/bench_envs_limit.json`` (``bench_envs.json`` for a full
run).

Measured in one run (ICVL camera, 320x240 depth observation, default frame skip 10 = 50 Hz
control, no sensor noise unless stated):

- ``env_steps_per_s``: one env, for each id: HandPose-v0 driven by its gesture expert,
  Grasp-v0 by its grasp expert (tomato soup can), GraspClutter-v0 (4 objects) by random pose
  actions; plus Grasp-v0 with structured-light noise;
- ``async_2_vs_1``: steps/s of ``AsyncVectorEnv`` (spawned workers) with 2 HandPose-v0 envs
  against 1, and the ratio (this machine has 2 cores);
- ``make_vec_fork_2_vs_1``: the same through ``gym.make_vec(..., vectorization_mode="async")``
  with default arguments (forked workers, each pinned to one CPU: ``handsim.envs.workers``)
  after this process has rendered, and the same with the workers unpinned
  (``HANDSIM_PIN_WORKERS=0``); ``ratio`` divides by the faster of the pinned and unpinned single
  worker; best of ``--repeats`` interleaved runs each; and ``cpu_scaling_2_vs_1_processes``, the
  speed-up of two processes running a pure-Python loop over one, measured just after (on a
  shared machine it says how many cores were free);
- ``obs_modes``: Grasp-v0 steps/s with the same random pose actions in ``"state"`` (nothing
  rendered), ``"privileged_state"``, ``"depth"`` and ``"depth"`` with ``labels=False``, and
  the ratio state / depth (best of ``--repeats`` interleaved runs);
- ``rgb_array``: renders/s of ``render()`` alone at 320 x 240 (viewer camera, shadows on) and
  steps/s of step + render in ``rgb_array`` and ``depth_rgb_array`` modes, against the depth
  step rate;
- ``resolution`` (``--only resolution``): Grasp-v0 depth steps with labels, per process
  CPU-second, with the same random pose actions at 160 x 120, 320 x 240 and 640 x 480 (ICVL
  camera) and 160 x 120 and 640 x 480 (SR300), and MuJoCo's plain depth render of the same
  states at the same sizes: each one's cost relative to the same camera at its native size,
  and the step's cost over the plain render's (``--repeats`` interleaved rounds);
- ``closed_loop``: Grasp-v0 steps/s inside ``EstimatorLoop`` with the oracle (10 mm noise),
  feedback off (estimate measured only) and on (estimate retargeted and handed to the expert);
- ``memory``: resident memory after a warm-up of 1000 steps and after ``--memory-steps``
  more steps of HandPose-v0 with resets every 150 steps (growth in MiB).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import sys
import time
import types
from collections.abc import Iterator
from pathlib import Path
from unittest import mock

import gymnasium as gym
import mujoco
import numpy as np

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.workers import PIN_ENV_VAR
from handsim.envs.wrappers import EstimatorLoop
from handsim.estimators import OracleEstimator


def _expert_rate(env: gym.Env, steps: int, seed: int = 0) -> float:
    """Steps per second with the env's expert, resetting at episode ends."""
    # EstimatorLoop builds the expert's state (truth or estimate); a plain env gives the truth.
    source = env if isinstance(env, EstimatorLoop) else env.unwrapped
    env.reset(seed=seed)
    expert = source.make_expert(np.random.default_rng(seed))
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(expert.act(source.expert_state()).vector)
        if terminated or truncated:
            seed += 1
            env.reset(seed=seed)
            expert = source.make_expert(np.random.default_rng(seed))
    return steps / (time.perf_counter() - start)


def _random_rate(env: gym.Env, steps: int) -> float:
    env.reset(seed=0)
    env.action_space.seed(0)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def _vector_rate(n: int, steps: int) -> float:
    fns = [lambda: gym.make("handsim.envs:handsim/HandPose-v0") for _ in range(n)]
    envs = gym.vector.AsyncVectorEnv(fns, context="spawn")
    envs.reset(seed=list(range(n)))
    envs.action_space.seed(0)
    envs.step(envs.action_space.sample())  # warm-up (first render)
    start = time.perf_counter()
    for _ in range(steps):
        envs.step(envs.action_space.sample())
    elapsed = time.perf_counter() - start
    envs.close()
    return n * steps / elapsed


def _make_vec_rate(n: int, steps: int, vector_kwargs: dict | None = None) -> float:
    """Steps/s of ``gym.make_vec`` (default arguments unless given: fork on Linux)."""
    envs = gym.make_vec(
        "handsim/HandPose-v0",
        num_envs=n,
        vectorization_mode="async",
        vector_kwargs=vector_kwargs,
    )
    envs.reset(seed=list(range(n)))
    envs.action_space.seed(0)
    envs.step(envs.action_space.sample())
    start = time.perf_counter()
    for _ in range(steps):
        envs.step(envs.action_space.sample())
    elapsed = time.perf_counter() - start
    envs.close()
    return n * steps / elapsed


def _fixed_actions_rate(
    env: gym.Env, steps: int, render: bool = False, clock=time.perf_counter
) -> float:
    """Steps/s (with ``render()`` after each step when asked) on seeded random actions.

    ``clock``: ``time.perf_counter`` (wall) or ``time.process_time`` (this process's CPU time).
    """
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    env.step(actions[0])
    if render:
        env.render()
    start = clock()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if render:
            env.render()
        if terminated or truncated:
            env.reset()
    return steps / (clock() - start)


def _best_of(repeats: int, runs: dict) -> dict:
    """Best rate of each run over ``repeats`` interleaved rounds (less sensitive to load)."""
    best = {name: 0.0 for name in runs}
    for _ in range(repeats):
        for name, run in runs.items():
            best[name] = max(best[name], run())
    return best


def _obs_modes(steps: int, repeats: int) -> dict:
    grasp = {"objects": "005_tomato_soup_can"}
    envs = {
        "state": gym.make("handsim/Grasp-v0", obs_mode="state", **grasp),
        "privileged_state": gym.make("handsim/Grasp-v0", obs_mode="privileged_state", **grasp),
        "depth": gym.make("handsim/Grasp-v0", **grasp),
        "depth (labels=False)": gym.make("handsim/Grasp-v0", labels=False, **grasp),
    }
    rates = _best_of(
        repeats, {name: (lambda e=env: _fixed_actions_rate(e, steps)) for name, env in envs.items()}
    )
    for env in envs.values():
        env.close()
    rates["ratio_state_vs_depth"] = rates["state"] / rates["depth"]
    return rates


_RESOLUTIONS = {
    "icvl 160x120": ("icvl", 160, 120),
    "icvl 320x240 (native)": ("icvl", 320, 240),
    "icvl 640x480": ("icvl", 640, 480),
    "sr300 160x120": ("sr300", 160, 120),
    "sr300 640x480 (native)": ("sr300", 640, 480),
}


def _resolution(steps: int, repeats: int) -> dict:
    """Grasp-v0 depth steps (labels on) per image size, against MuJoCo's plain depth render.

    For each size, the same seeded random pose actions; after each step, MuJoCo's plain depth
    render (``mujoco.Renderer``) of the same state at the same size, timed apart. Process CPU
    time, summed over ``repeats`` interleaved rounds. Costs are relative to the same camera at
    its native size.
    """
    envs = {
        name: gym.make(
            "handsim/Grasp-v0", objects="005_tomato_soup_can", camera=cam, width=w, height=h
        )
        for name, (cam, w, h) in _RESOLUTIONS.items()
    }
    clocks = {name: (_Clock(), _Clock()) for name in envs}
    raws = {name: _Raw() for name in envs}
    for _ in range(repeats):
        for name, env in envs.items():
            env.reset(seed=0)
            env.action_space.seed(0)
            raws[name].bind(env)
            step_clock, render_clock = clocks[name]
            for _ in range(steps):
                action = env.action_space.sample()
                with step_clock.time():
                    _, _, terminated, truncated, _ = env.step(action)
                raws[name].render(render_clock)
                if terminated or truncated:
                    env.reset()
                    raws[name].bind(env)
    for name, env in envs.items():
        raws[name].close()
        env.close()
    out: dict = {}
    for name, (cam, _, _) in _RESOLUTIONS.items():
        native = next(n for n, v in _RESOLUTIONS.items() if v[0] == cam and "native" in n)
        step, render = clocks[name]
        out[name] = {
            "steps_per_cpu_s": step.rates()["per_cpu_s"],
            "plain_depth_renders_per_cpu_s": render.rates()["per_cpu_s"],
            "step_cost_vs_native": _ratio(clocks[native][0], step),
            "plain_render_cost_vs_native": _ratio(clocks[native][1], render),
            "step_over_plain_render": _ratio(render, step),
        }
        row = out[name]
        print(
            f"{name:<24} step cost {row['step_cost_vs_native']:.2f} x native, plain render "
            f"{row['plain_render_cost_vs_native']:.2f} x native; step / plain render "
            f"{row['step_over_plain_render']:.2f}"
        )
    return out


def _rgb_array(steps: int, repeats: int) -> dict:
    grasp = {"objects": "005_tomato_soup_can", "render_width": 320, "render_height": 240}
    rgb = gym.make("handsim/Grasp-v0", render_mode="rgb_array", **grasp)
    depth_view = gym.make("handsim/Grasp-v0", render_mode="depth_rgb_array", **grasp)
    depth = gym.make("handsim/Grasp-v0", **grasp)
    rgb.reset(seed=0)
    rgb.render()

    def renders() -> float:
        start = time.perf_counter()
        for _ in range(steps):
            rgb.render()
        return steps / (time.perf_counter() - start)

    rates = _best_of(
        repeats,
        {
            "render_only_per_s": renders,
            "rgb_array_steps_per_s": lambda: _fixed_actions_rate(rgb, steps, render=True),
            "depth_rgb_array_steps_per_s": lambda: _fixed_actions_rate(depth_view, steps, True),
            "depth_obs_steps_per_s": lambda: _fixed_actions_rate(depth, steps),
        },
    )
    for env in (rgb, depth_view, depth):
        env.close()
    rates["ratio_rgb_array_vs_depth"] = (
        rates["rgb_array_steps_per_s"] / rates["depth_obs_steps_per_s"]
    )
    return rates


def _rss_mib() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _memory(steps: int) -> dict:
    env = gym.make("handsim/HandPose-v0")
    env.reset(seed=0)
    env.action_space.seed(0)

    def run(n: int) -> None:
        for _ in range(n):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()

    run(1000)
    before = _rss_mib()
    run(steps)
    after = _rss_mib()
    env.close()
    return {"steps": steps, "rss_after_warmup_mib": before, "rss_after_mib": after,
            "growth_mib": after - before}  # fmt: skip


# --- The step at the limit (issue 11): every ratio from one run -------------------------------

# The limit's envs draw the skin's level of detail chosen by projected size (the envs' default
# is the full skin; the peer comparison measures both).
_ENVS = {
    "HandPose-v0": {"skin_detail": "auto"},
    "Grasp-v0": {"objects": "005_tomato_soup_can", "skin_detail": "auto"},
    "GraspClutter-v0": {"num_objects": 4, "skin_detail": "auto"},
}


class _Clock:
    """Process CPU time and wall time of timed blocks.

    CPU time is what a task costs on a shared machine: MuJoCo and software GL run in this
    thread (``LP_NUM_THREADS=0``).
    """

    def __init__(self) -> None:
        self.cpu_s = 0.0
        self.wall_s = 0.0
        self.n = 0

    @contextlib.contextmanager
    def time(self) -> Iterator[None]:
        cpu, wall = time.process_time(), time.perf_counter()
        yield
        self.cpu_s += time.process_time() - cpu
        self.wall_s += time.perf_counter() - wall
        self.n += 1

    def rates(self) -> dict:
        return {
            "per_cpu_s": self.n / max(self.cpu_s, 1e-12),
            "per_wall_s": self.n / max(self.wall_s, 1e-12),
        }


def _ratio(a: _Clock, b: _Clock) -> float:
    """Rate of ``a`` over rate of ``b``, in CPU time."""
    return a.rates()["per_cpu_s"] / b.rates()["per_cpu_s"]


class _Raw:
    """The cost an env step cannot go below.

    MuJoCo's plain depth render (``mujoco.Renderer``) of the env's camera, and bare physics
    (``mj_step`` x frame skip) on a scratch copy of the env's state. The render draws the
    skin's level of detail the env draws for the state (``FrameRenderer.skin_as_drawn``).
    """

    def __init__(self) -> None:
        self.model = None

    def bind(self, env: gym.Env) -> None:
        u = env.unwrapped
        if self.model is u.scene.model:
            return
        self.close()
        self.model, self.data = u.scene.model, u.scene.data
        self.frame_renderer = u.frame_renderer
        self.scratch = mujoco.MjData(self.model)
        intr = u.frame_renderer.intrinsics
        self.renderer = mujoco.Renderer(self.model, intr.height, intr.width)
        self.renderer.enable_depth_rendering()
        self.frame_skip = u.config.frame_skip
        self.renderer.update_scene(self.data, camera="camera")
        self.renderer.render()  # the first draw uploads the meshes

    def physics_and_render(self, clock: _Clock) -> None:
        mujoco.mj_copyData(self.scratch, self.model, self.data)
        # The skin's level of detail the env draws for this state (the same scene's limit).
        with self.frame_renderer.skin_as_drawn(), clock.time():
            mujoco.mj_step(self.model, self.scratch, nstep=self.frame_skip)
            self.renderer.update_scene(self.scratch, camera="camera")
            self.renderer.render()

    def render(self, clock: _Clock) -> None:
        with self.frame_renderer.skin_as_drawn(), clock.time():
            self.renderer.update_scene(self.data, camera="camera")
            self.renderer.render()

    def close(self) -> None:
        if self.model is not None:
            self.renderer.close()
            self.model = None


def _env_vs_limit(name: str, steps: int) -> dict:
    """Env step with its expert against bare physics + raw depth render of the same state.

    Also the labelled frame against the raw render of the same state; interleaved step by step.
    """
    env = gym.make(f"handsim/{name}", **_ENVS[name])
    u = env.unwrapped
    seed = 0
    env.reset(seed=seed)
    expert = u.make_expert(np.random.default_rng(seed))
    raw = _Raw()
    keys = ("env_step", "env_step_only", "limit", "labelled_frame", "raw_render")
    rng = np.random.default_rng(0)
    for i in range(steps + 1):
        if i <= 1:  # round 0 warms up every renderer
            clocks = {k: _Clock() for k in keys}
        raw.bind(env)
        raw.physics_and_render(clocks["limit"])
        # env_step: the expert's decision and env.step; env_step_only: env.step alone.
        with clocks["env_step"].time():
            action = expert.act(u.expert_state()).vector
            with clocks["env_step_only"].time():
                _, _, terminated, truncated, _ = env.step(action)
        # The labelled frame of the state just reached (silhouettes kept as the env keeps them)
        # against MuJoCo's plain depth render of it.
        raw.render(clocks["raw_render"])
        with clocks["labelled_frame"].time():
            u.frame_renderer.render(rng)
        if terminated or truncated:
            seed += 1
            env.reset(seed=seed)
            expert = u.make_expert(np.random.default_rng(seed))
    raw.close()
    env.close()
    row = {k: c.rates() for k, c in clocks.items()}
    row["ratio_env_step_vs_limit"] = _ratio(clocks["env_step"], clocks["limit"])
    row["ratio_env_step_only_vs_limit"] = _ratio(clocks["env_step_only"], clocks["limit"])
    row["ratio_labelled_vs_raw_render"] = _ratio(clocks["labelled_frame"], clocks["raw_render"])
    return row


def _shim_gymnasium_robotics() -> None:
    """Give gymnasium-robotics' helpers plain-int joint types (benchmark only).

    gymnasium-robotics 1.4 tests ``joint_type in (mjtJoint..., ...)``, which MuJoCo 4's enums
    fail (``==`` holds, ``in`` does not).
    """
    from gymnasium_robotics.utils import mujoco_utils

    shim = types.ModuleType("mujoco_int_joint_types")
    shim.__dict__.update(mujoco.__dict__)
    shim.mjtJoint = types.SimpleNamespace(  # type: ignore[attr-defined]
        **{
            k: int(getattr(mujoco.mjtJoint, k))
            for k in dir(mujoco.mjtJoint)
            if k.startswith("mjJNT")
        }
    )
    mujoco_utils.mujoco = shim


class _PeerPlainDepth:
    """The peer stepping and rendering a plain 320 x 240 depth image (``mujoco.Renderer``).

    The same camera as its own renders (Gymnasium's viewer camera), without the shadow pass
    that Gymnasium's ``depth_array`` draws.
    """

    def __init__(self, peer: gym.Env) -> None:
        self.peer = peer
        u = peer.unwrapped
        self.camera = u.mujoco_renderer._get_viewer("rgb_array").cam
        self.renderer = mujoco.Renderer(u.model, 240, 320)
        self.renderer.enable_depth_rendering()

    def step(self) -> tuple[bool, bool]:
        _, _, terminated, truncated, _ = self.peer.step(self.peer.action_space.sample())
        self.renderer.update_scene(self.peer.unwrapped.data, camera=self.camera)
        self.renderer.render()
        return terminated, truncated

    def close(self) -> None:
        self.renderer.close()


_PEER_ENVS = ("Grasp-v0", "GraspClutter-v0")
"""handsim envs compared with the peer, each with ``skin_detail`` "auto" and "full" (default)."""


def _peer(steps: int) -> dict:
    """Grasp-v0 and GraspClutter-v0 (expert) against Gymnasium-Robotics' HandManipulateBlock-v1.

    The peer steps (random actions) and renders 320 x 240 RGB, Gymnasium's depth (with its
    shadow pass) or a plain depth image (``mujoco.Renderer``, no shadows); each handsim env
    steps with its default skin level of detail ("auto") and with the full skin. All of them
    interleaved step by step.
    """
    try:
        import gymnasium_robotics
    except ImportError:
        return {"installed": False, "note": "pip install gymnasium-robotics to compare"}
    _shim_gymnasium_robotics()
    gym.register_envs(gymnasium_robotics)
    peers = {
        mode: gym.make(
            "HandManipulateBlock-v1", render_mode=mode, width=320, height=240,
            disable_env_checker=True,  # it declares no depth_array, but renders it
        )
        for mode in ("rgb_array", "depth_array", "plain")
    }  # fmt: skip
    for peer in peers.values():
        peer.reset(seed=0)
        peer.action_space.seed(0)
    plain = _PeerPlainDepth(peers["plain"])
    ours = {}
    for name in _PEER_ENVS:
        for detail in ("auto", "full"):
            env = gym.make(f"handsim/{name}", skin_detail=detail, **_ENVS[name])
            env.reset(seed=0)
            ours[f"{name}_{detail}"] = [env, 0, env.unwrapped.make_expert(np.random.default_rng(0))]
    keys = (*ours, "peer_rgb", "peer_depth", "peer_plain_depth")
    clocks = {k: _Clock() for k in keys}
    coarse = dict.fromkeys(ours, 0)
    for i in range(steps + 1):
        if i == 1:
            clocks = {k: _Clock() for k in keys}
            coarse = dict.fromkeys(ours, 0)
        for key, run in ours.items():
            env, seed, expert = run
            u = env.unwrapped
            with clocks[key].time():
                _, _, terminated, truncated, _ = env.step(expert.act(u.expert_state()).vector)
            coarse[key] += u.frame_renderer.last_skin_detail == "coarse"
            if terminated or truncated:
                run[1] = seed = seed + 1
                env.reset(seed=seed)
                run[2] = u.make_expert(np.random.default_rng(seed))
        for mode, key in (("rgb_array", "peer_rgb"), ("depth_array", "peer_depth")):
            peer = peers[mode]
            with clocks[key].time():
                _, _, terminated, truncated, _ = peer.step(peer.action_space.sample())
                # Gymnasium's renderer makes its OpenGL context current only when made: with
                # other contexts in the process it would draw into theirs (and cost nothing).
                peer.unwrapped.mujoco_renderer._get_viewer(mode).make_context_current()
                peer.render()
            if terminated or truncated:
                peer.reset()
        with clocks["peer_plain_depth"].time():
            terminated, truncated = plain.step()
        if terminated or truncated:
            peers["plain"].reset()
    plain.close()
    for env in (*(run[0] for run in ours.values()), *peers.values()):
        env.close()
    out = {
        "installed": True,
        "gymnasium_robotics": getattr(gymnasium_robotics, "__version__", "?"),
        "mujoco": mujoco.__version__,
        **{k: c.rates() for k, c in clocks.items()},
        **{f"{k}_coarse_fraction": v / max(steps, 1) for k, v in coarse.items()},
    }
    for key in ours:
        for peer in ("peer_rgb", "peer_depth", "peer_plain_depth"):
            out[f"ratio_{key}_vs_{peer}"] = _ratio(clocks[key], clocks[peer])
    # The names of the earlier single-env runs: Grasp-v0 as made by default.
    out["ratio_grasp_vs_peer_rgb"] = out["ratio_Grasp-v0_auto_vs_peer_rgb"]
    out["ratio_grasp_vs_peer_depth"] = out["ratio_Grasp-v0_auto_vs_peer_depth"]
    return out


def _rgb_vs_depth(steps: int) -> dict:
    """Grasp-v0 step + 320 x 240 ``rgb_array`` render against the depth step.

    Both render qualities; the same random actions; interleaved step by step.
    """
    grasp = {"objects": "005_tomato_soup_can", "render_width": 320, "render_height": 240}
    grasp["skin_detail"] = "auto"  # as the limit's other envs
    envs = {
        "depth_step": gym.make("handsim/Grasp-v0", **grasp),
        "rgb_array_step": gym.make("handsim/Grasp-v0", render_mode="rgb_array", **grasp),
        "rgb_array_step_high": gym.make(
            "handsim/Grasp-v0", render_mode="rgb_array", render_quality="high", **grasp
        ),
    }
    for env in envs.values():
        env.reset(seed=0)
    space = envs["depth_step"].action_space
    space.seed(0)
    clocks = {k: _Clock() for k in envs}
    for i in range(steps + 1):
        if i == 1:
            clocks = {k: _Clock() for k in clocks}
        action = space.sample()
        for key, env in envs.items():
            with clocks[key].time():
                _, _, terminated, truncated, _ = env.step(action)
                env.render()
            if terminated or truncated:
                env.reset()
    for env in envs.values():
        env.close()
    return {
        **{k: c.rates() for k, c in clocks.items()},
        "ratio_rgb_array_vs_depth": _ratio(clocks["rgb_array_step"], clocks["depth_step"]),
        "ratio_rgb_array_high_vs_depth": _ratio(
            clocks["rgb_array_step_high"], clocks["depth_step"]
        ),
    }


def _closed_loop(steps: int) -> dict:
    """Grasp-v0 in ``EstimatorLoop`` with the oracle, feedback on against off, interleaved."""
    loops = {
        key: EstimatorLoop(
            gym.make("handsim/Grasp-v0", objects="005_tomato_soup_can"),
            OracleEstimator(noise_mm=10.0, object_noise_mm=10.0, rng=0),
            feedback=feedback,
        )
        for key, feedback in (("feedback_off", False), ("feedback_on", True))
    }
    experts, seeds = {}, {}
    for key, loop in loops.items():
        seeds[key] = 0
        loop.reset(seed=0)
        experts[key] = loop.make_expert(np.random.default_rng(0))
    clocks = {k: _Clock() for k in loops}
    for i in range(steps + 1):
        if i == 1:
            clocks = {k: _Clock() for k in clocks}
        for key, loop in loops.items():
            with clocks[key].time():
                action = experts[key].act(loop.expert_state()).vector
                _, _, terminated, truncated, _ = loop.step(action)
            if terminated or truncated:
                seeds[key] += 1
                loop.reset(seed=seeds[key])
                experts[key] = loop.make_expert(np.random.default_rng(seeds[key]))
    for loop in loops.values():
        loop.close()
    return {
        **{k: c.rates() for k, c in clocks.items()},
        "ratio_feedback_on_vs_off": _ratio(clocks["feedback_on"], clocks["feedback_off"]),
    }


def _physics(control_steps: int) -> dict:
    """Physics of a held grasp's control step against bare ``mj_step`` (bench_grasp.py)."""
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_grasp import bench_physics

    out = bench_physics(["005_tomato_soup_can"], control_steps=control_steps, repeats=3)
    return {"ratio_driver_vs_bare_mj_step": out["median_ratio"], **out}


def _limit_ratios(steps: int) -> dict:
    """Every ratio of issue 11 (items 1-5), measured in this run."""
    results: dict = {}
    print("item 1: physics of a control step vs bare mj_step ...", flush=True)
    results["physics"] = _physics(max(steps // 2, 20))
    results["envs"] = {}
    for name in _ENVS:
        print(f"items 2-3: {name} step vs raw depth render + physics ...", flush=True)
        results["envs"][name] = _env_vs_limit(name, steps)
    print("item 3: Grasp-v0 vs HandManipulateBlock-v1 ...", flush=True)
    results["peer"] = _peer(steps)
    print("item 4: rgb_array step vs depth step ...", flush=True)
    results["rgb_array_vs_depth"] = _rgb_vs_depth(steps)
    print("item 5: closed loop, feedback on vs off ...", flush=True)
    results["closed_loop_ratio"] = _closed_loop(steps)
    envs = results["envs"]
    results["summary"] = {
        "1 physics / bare mj_step (target >= 0.85)": results["physics"][
            "ratio_driver_vs_bare_mj_step"
        ],
        **{
            f"2 {n} labelled frame / raw depth render (target >= 0.8)": envs[n][
                "ratio_labelled_vs_raw_render"
            ]
            for n in envs
        },
        **{
            f"3 {n} expert + step / (raw depth render + physics) (target >= 0.7)": envs[n][
                "ratio_env_step_vs_limit"
            ]
            for n in envs
        },
        **{
            f"3 {n} env.step alone / (raw depth render + physics)": envs[n][
                "ratio_env_step_only_vs_limit"
            ]
            for n in envs
        },
        **(
            {
                "3 Grasp-v0 / peer step + RGB (target >= 4)": results["peer"][
                    "ratio_grasp_vs_peer_rgb"
                ],
                "3 Grasp-v0 / peer step + depth (target >= 1.5)": results["peer"][
                    "ratio_grasp_vs_peer_depth"
                ],
                "3 Grasp-v0 / peer step + plain depth (target >= 1.5)": results["peer"][
                    "ratio_Grasp-v0_auto_vs_peer_plain_depth"
                ],
                "3 GraspClutter-v0 / peer step + plain depth (target >= 1.0)": results["peer"][
                    "ratio_GraspClutter-v0_auto_vs_peer_plain_depth"
                ],
                "3 Grasp-v0 skin_detail='full' / peer step + plain depth": results["peer"][
                    "ratio_Grasp-v0_full_vs_peer_plain_depth"
                ],
                "3 GraspClutter-v0 skin_detail='full' / peer step + plain depth": results["peer"][
                    "ratio_GraspClutter-v0_full_vs_peer_plain_depth"
                ],
            }
            if results["peer"]["installed"]
            else {}
        ),
        "4 rgb_array step / depth step (target >= 0.5)": results["rgb_array_vs_depth"][
            "ratio_rgb_array_vs_depth"
        ],
        "5 closed loop feedback on / off (target >= 0.8)": results["closed_loop_ratio"][
            "ratio_feedback_on_vs_off"
        ],
    }
    return results


def _print_summary(summary: dict) -> None:
    print("\nratios (rates in process CPU time, measured interleaved in this run):")
    for key, value in summary.items():
        print(f"  {key:<70} {value:6.2f}")


def main() -> None:
    """Run every measurement, print it, write JSON."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--memory-steps", type=int, default=10_000)
    parser.add_argument(
        "--out", default=None, help="default: benchmarks/results/bench_envs[_ONLY].json"
    )
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument(
        "--limit",
        action="store_true",
        help="only the ratios of issue 11 (step at the limit, labels, peer, RGB, closed loop)",
    )
    parser.add_argument(
        "--only",
        choices=["all", "vector", "obs_modes", "rgb_array", "resolution", "peer"],
        default="all",
        help="run one group of measurements",
    )
    args = parser.parse_args()
    if args.out is None:
        suffix = "_limit" if args.limit else "" if args.only == "all" else f"_{args.only}"
        args.out = f"benchmarks/results/bench_envs{suffix}.json"
    results: dict = {"cpu_count": os.cpu_count(), "load_avg_1min_start": os.getloadavg()[0]}
    if args.limit:
        results["limit"] = _limit_ratios(args.steps)
        _write(results, args.out)
        _print_summary(results["limit"]["summary"])
        return
    if args.only != "all":
        runs = {
            "vector": lambda: {"make_vec_fork_2_vs_1": _make_vec_2_vs_1(args)},
            "obs_modes": lambda: {"obs_modes": _obs_modes(args.steps, args.repeats)},
            "rgb_array": lambda: {"rgb_array": _rgb_array(args.steps, args.repeats)},
            "resolution": lambda: {"resolution": _resolution(args.steps, args.repeats)},
            "peer": lambda: {"peer": _peer(args.steps)},
        }
        results.update(runs[args.only]())
        if args.only == "peer" and results["peer"]["installed"]:
            _print_summary(
                {k: v for k, v in results["peer"].items() if k.startswith("ratio_")}
                | {k: v for k, v in results["peer"].items() if k.endswith("_fraction")}
            )
        _write(results, args.out)
        return
    results["env_steps_per_s"] = {}
    rates = results["env_steps_per_s"]
    rates["HandPose-v0 (gesture expert)"] = _expert_rate(
        gym.make("handsim/HandPose-v0"), args.steps
    )
    grasp = {"objects": "005_tomato_soup_can"}
    rates["Grasp-v0 (grasp expert)"] = _expert_rate(
        gym.make("handsim/Grasp-v0", **grasp), args.steps
    )
    rates["Grasp-v0 (grasp expert, structured light)"] = _expert_rate(
        gym.make("handsim/Grasp-v0", sensor="structured_light", **grasp), args.steps
    )
    rates["GraspClutter-v0 (4 objects, random actions)"] = _random_rate(
        gym.make("handsim/GraspClutter-v0", num_objects=4), args.steps
    )
    one, two = _vector_rate(1, args.steps), _vector_rate(2, args.steps)
    results["async_2_vs_1"] = {"1_worker": one, "2_workers": two, "ratio": two / one}
    results["closed_loop"] = {}
    for feedback in (False, True):
        env = EstimatorLoop(
            gym.make("handsim/Grasp-v0", **grasp),
            OracleEstimator(noise_mm=10.0, object_noise_mm=10.0, rng=0),
            feedback=feedback,
        )
        key = "feedback_on" if feedback else "feedback_off"
        results["closed_loop"][key] = _expert_rate(env, args.steps)
    results["make_vec_fork_2_vs_1"] = _make_vec_2_vs_1(args)
    results["obs_modes"] = _obs_modes(args.steps, args.repeats)
    results["rgb_array"] = _rgb_array(args.steps, args.repeats)
    results["memory"] = _memory(args.memory_steps)
    results["limit"] = _limit_ratios(args.steps)
    _write(results, args.out)
    _print_summary(results["limit"]["summary"])


def _spin(n: int) -> int:
    total = 0
    for i in range(n):
        total += i * i
    return total


def _cpu_scaling(n: int = 8_000_000) -> float:
    """Speed-up of two processes running a pure-Python loop over one: the cores free now.

    On a machine that other jobs share this is what bounds any 2-worker ratio measured beside it.
    """
    import multiprocessing

    start = time.perf_counter()
    _spin(n)
    one = time.perf_counter() - start
    with multiprocessing.get_context("fork").Pool(2) as pool:
        start = time.perf_counter()
        pool.map(_spin, [n, n])
        two = time.perf_counter() - start
    return 2 * one / two


def _unpinned(run):
    """``run`` with Gymnasium's vector workers left unpinned (``HANDSIM_PIN_WORKERS=0``)."""

    def unpinned() -> float:
        # Read by the workers, which inherit the environment.
        with mock.patch.dict(os.environ, {PIN_ENV_VAR: "0"}):
            return run()

    return unpinned


def _make_vec_2_vs_1(args: argparse.Namespace) -> dict:
    # Render in this process first: forked workers must not inherit a hanging GL state.
    parent = gym.make("handsim/HandPose-v0")
    parent.reset(seed=0)
    parent.step(parent.action_space.sample())
    best = _best_of(
        args.repeats,
        {
            "1_worker": lambda: _make_vec_rate(1, args.steps),
            "2_workers": lambda: _make_vec_rate(2, args.steps),
            "1_worker_unpinned": _unpinned(lambda: _make_vec_rate(1, args.steps)),
            "2_workers_unpinned": _unpinned(lambda: _make_vec_rate(2, args.steps)),
        },
    )
    parent.close()
    return {
        **best,
        # Against the faster single worker: a pinned one pays cross-CPU wake-ups.
        "ratio": best["2_workers"] / max(best["1_worker"], best["1_worker_unpinned"]),
        "ratio_unpinned": best["2_workers_unpinned"] / best["1_worker_unpinned"],
        # The cores free at the time, measured just after the runs.
        "cpu_scaling_2_vs_1_processes": _cpu_scaling(),
    }


def _write(results: dict, path: str) -> None:
    results["load_avg_1min_end"] = os.getloadavg()[0]
    print(json.dumps(results, indent=2))
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(f"written: {out}")


if __name__ == "__main__":
    main()
