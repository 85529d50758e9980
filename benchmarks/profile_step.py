"""Where an env step's time goes: process CPU time per part, and cProfile's top functions.

Run: ``python benchmarks/profile_step.py [--env Grasp-v0] [--steps 300] [--cprofile]
[--draw-by-part]``.

The env steps with its expert (as in ``bench_envs.py --limit``). Each part is timed by wrapping
the function that does it (process CPU time, nested parts subtracted):

- ``GL draw + read``: the depth/segmentation draw and ``mjr_readPixels`` (``DepthRenderer``'s
  draw and read, silhouette renders included);
- ``depth + label images``: the rest of ``DepthRenderer.render`` (depth from the z-buffer,
  segmentation labels from the colour index);
- ``labels (keypoints, objects, contacts)``: the rest of ``FrameRenderer.render``;
- ``physics``: ``HandDriver.step`` (``mj_step`` x frame skip, ``mj_forward``, checks);
- ``expert``: the expert's state and decision;
- ``env (other)``: the rest of ``env.step`` (action, reward, observation, info).

``--cprofile`` also prints cProfile's top functions by own time (CPU clock).
``--draw-by-part`` then times the depth draw + read-back of the last state with parts of the
scene hidden (everything, everything with the skin's coarse level of detail, without the palm's
mesh, without the hand, without the table, nothing), with the triangles each part adds.
"""

from __future__ import annotations

import argparse
import cProfile
import functools
import pstats
import time

import gymnasium as gym
import mujoco
import numpy as np

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.physics import HandDriver
from handsim.frame.renderer import _HIDDEN_GROUP, FrameRenderer
from handsim.world.render import RENDERED_GEOM_GROUPS, DepthRenderer

_ENVS = {
    "HandPose-v0": {},
    "Grasp-v0": {"objects": "005_tomato_soup_can"},
    "GraspClutter-v0": {"num_objects": 4},
}


class _Timers:
    """Process CPU time per part, exclusive of the parts nested in it."""

    def __init__(self) -> None:
        self.total: dict[str, float] = {}
        self._stack: list[list] = []

    def wrap(self, owner: object, name: str, part: str) -> None:
        original = getattr(owner, name)

        @functools.wraps(original)
        def timed(*args: object, **kwargs: object) -> object:
            self._stack.append([part, time.process_time(), 0.0])
            try:
                return original(*args, **kwargs)
            finally:
                _, start, nested = self._stack.pop()
                spent = time.process_time() - start
                self.total[part] = self.total.get(part, 0.0) + spent - nested
                if self._stack:
                    self._stack[-1][2] += spent

        setattr(owner, name, timed)


def main() -> None:
    """Step the env with its expert, print the parts' shares and (optionally) cProfile's."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--env", default="Grasp-v0", choices=tuple(_ENVS))
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--cprofile", action="store_true")
    parser.add_argument("--draw-by-part", action="store_true")
    args = parser.parse_args()
    timers = _Timers()
    for owner, name in ((DepthRenderer, "_draw"), (mujoco, "mjr_readPixels")):
        timers.wrap(owner, name, "GL draw + read")
    timers.wrap(DepthRenderer, "render", "depth + label images")
    timers.wrap(FrameRenderer, "render", "labels (keypoints, objects, contacts)")
    timers.wrap(HandDriver, "step", "physics")
    env = gym.make(f"handsim/{args.env}", **_ENVS[args.env])
    u = env.unwrapped
    seed = 0
    env.reset(seed=seed)
    expert = u.make_expert(np.random.default_rng(seed))
    env.step(expert.act(u.expert_state()).vector)  # warm-up
    timers.total.clear()
    expert_s = step_s = 0.0
    profile = cProfile.Profile(time.process_time) if args.cprofile else None
    if profile is not None:
        profile.enable()
    for _ in range(args.steps):
        start = time.process_time()
        action = expert.act(u.expert_state()).vector
        middle = time.process_time()
        _, _, terminated, truncated, _ = env.step(action)
        end = time.process_time()
        expert_s += middle - start
        step_s += end - middle
        if terminated or truncated:
            seed += 1
            env.reset(seed=seed)
            expert = u.make_expert(np.random.default_rng(seed))
    if profile is not None:
        profile.disable()
    parts = dict(timers.total)
    parts["expert"] = expert_s
    parts["env (other)"] = step_s - sum(timers.total.values())
    total = expert_s + step_s
    print(f"{args.env}: {1e3 * total / args.steps:.2f} ms CPU per step with the expert")
    print(f"{'part':<40} {'ms/step':>8} {'share':>6}")
    for part, spent in sorted(parts.items(), key=lambda kv: -kv[1]):
        print(f"{part:<40} {1e3 * spent / args.steps:8.2f} {100 * spent / total:5.0f}%")
    if profile is not None:
        pstats.Stats(profile).sort_stats("tottime").print_stats(20)
    if args.draw_by_part:
        _draw_by_part(u)
    env.close()


def _draw_by_part(u: gym.Env, draws: int = 300) -> None:
    """CPU time of one depth draw + read-back with parts of the scene hidden."""
    model, data = u.scene.model, u.scene.data
    renderer = u.frame_renderer.renderer
    rgb = np.empty((*renderer._zbuffer.shape, 3), dtype=np.uint8)
    depth = np.empty_like(renderer._zbuffer)
    drawn = np.isin(model.geom_group, RENDERED_GEOM_GROUPS)
    hand = drawn & u.frame_renderer._is_hand_geom
    names = [model.geom(i).name for i in range(model.ngeom)]
    palm = hand & np.array(["palm" in name for name in names])
    table = drawn & np.array([name == "table" for name in names])
    is_mesh = model.geom_type == mujoco.mjtGeom.mjGEOM_MESH
    faces = np.where(is_mesh, model.mesh_facenum[np.maximum(model.geom_dataid, 0)], 0)
    saved = model.geom_group.copy()
    print(f"{'drawn':<28} {'ms/draw':>8} {'mesh triangles hidden':>22}")
    lod = u.scene.skin_lod_geom_ids
    for label, hide in (
        ("everything", np.zeros_like(drawn)),
        *((("everything, coarse skin", None),) if lod is not None else ()),
        ("without the palm", palm),
        ("without the hand", hand),
        ("without the table", table),
        ("nothing", drawn),
    ):
        if hide is None:  # the coarse skin drawn instead of the full one
            model.geom_group[lod[0]] = _HIDDEN_GROUP
            model.geom_group[lod[1]] = 2
            hide = np.zeros_like(drawn)
        else:
            model.geom_group[hide] = _HIDDEN_GROUP  # the group the frame hides geoms in
        try:
            renderer._draw(data)
            mujoco.mjr_readPixels(rgb, depth, renderer._rect, renderer._context)
            start = time.process_time()
            for _ in range(draws):
                renderer._draw(data)
                mujoco.mjr_readPixels(rgb, depth, renderer._rect, renderer._context)
            ms = 1e3 * (time.process_time() - start) / draws
        finally:
            model.geom_group[:] = saved
        print(f"{label:<28} {ms:8.2f} {int(faces[hide].sum()):>22}")


if __name__ == "__main__":
    main()
