"""Pictures of held grasps at maximum lift: ``docs/img/grasp_<object>.png`` (RGB, 480x480).

Run: ``python benchmarks/grasp_pictures.py [NAME ...]`` (default: the objects below). For each
object, a ``handsim/Grasp-v0`` episode (seed 0) with the grasp expert; the state of the highest
lift during the hold is restored with ``set_state`` and rendered from a free camera 0.4 m from
the object (azimuth 20 deg, elevation -15 deg). Prints the lift and the deepest hand-object
penetration of that state.
"""

from __future__ import annotations

import sys

import cv2
import gymnasium as gym
import mujoco

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.grasping import contact_metrics

OBJECTS = (
    "005_tomato_soup_can",
    "061_foam_brick",
    "003_cracker_box",
    "004_sugar_box",
    "025_mug",
    "011_banana",
    "035_power_drill",
    "037_scissors",
)


def main() -> None:
    """Render one picture per object (those named on the command line, else all of OBJECTS)."""
    for name in sys.argv[1:] or OBJECTS:
        env = gym.make("handsim/Grasp-v0", objects=name)
        env.reset(seed=0)
        base = env.unwrapped
        expert = base.make_expert()
        best = None
        while True:
            *_, terminated, truncated, info = env.step(expert.act(base.expert_state()).vector)
            if expert.phase == "hold" and (best is None or info["lift_m"] > best[0]):
                best = (info["lift_m"], base.get_state())
            if terminated or truncated:
                break
        base.set_state(best[1])
        model, data = base.scene.model, base.scene.data
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, 480)
        model.vis.global_.offheight = max(model.vis.global_.offheight, 480)
        renderer = mujoco.Renderer(model, 480, 480)
        camera = mujoco.MjvCamera()
        camera.lookat[:] = data.xpos[model.body(base.scene.objects[0][0]).id]
        camera.distance, camera.azimuth, camera.elevation = 0.4, 20.0, -15.0
        renderer.update_scene(data, camera=camera)
        image = renderer.render()
        renderer.close()
        depth_mm = 1000 * contact_metrics(base.scene, 0).object_depth_m
        cv2.imwrite(f"docs/img/grasp_{name}.png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        print(
            f"{name}: success {info['is_success']}, lift {1000 * best[0]:.0f} mm, "
            f"deepest penetration {depth_mm:.2f} mm"
        )
        env.close()


if __name__ == "__main__":
    main()
