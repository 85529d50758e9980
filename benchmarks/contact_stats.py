"""Hand-object contact and penetration of a generated dataset, from its labels alone.

Contact: the fraction of frames with at least one hand-object contact (``contact_count > 0``).
Penetration: every frame's scene is set up again from its labels (the objects at their poses,
the hand's side, length and 27-DoF pose, the table) and the deepest overlap of a hand
collision geom with an object or the table is measured with MuJoCo's collision detection
(objects with an imported mesh are not replayed).

Usage: ``python benchmarks/contact_stats.py DATASET [DATASET ...]``; prints one line per
dataset (frames, contact rate, penetration max / p95 / median in mm).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import mujoco
import numpy as np

from handsim.data.manifest import Manifest
from handsim.data.shards import ShardReader
from handsim.hand.model import hand_params
from handsim.hand.pose import HandPose
from handsim.world.registry import OBJECTS
from handsim.world.scene import OBJECT_LABEL_OFFSET, ObjectPlacement, Scene, SceneSpec


def _names_by_ycbv_id() -> dict[int, str]:
    return {obj.ycbv_id: name for name, obj in OBJECTS.items() if obj.ycbv_id is not None}


def _penetration_m(scene: Scene) -> float:
    """Deepest overlap of a hand geom with anything not the hand (objects, table), metres."""
    labels, data = scene.geom_labels, scene.data
    deepest = 0.0
    for i in range(data.ncon):
        con = data.contact[i]
        hand = [2 <= labels[g] < OBJECT_LABEL_OFFSET for g in (con.geom1, con.geom2)]
        if hand[0] != hand[1]:
            deepest = max(deepest, -float(con.dist))
    return deepest


def dataset_stats(folder: Path) -> dict[str, float]:
    """Contact rate and penetration (m) of every frame of a dataset."""
    names = _names_by_ycbv_id()
    manifest = Manifest.read(folder)
    contact, depth = [], []
    for record in manifest.shards.values():
        reader = ShardReader(folder / record.name)
        for i in range(len(reader)):
            a = reader[i]
            contact.append(int(a["contact_count"]) > 0)
            T_world_from_cam = np.linalg.inv(a["T_cam_from_world"])
            placements = []
            for k in np.flatnonzero(a["object_valid"]):
                T = T_world_from_cam @ a["object_T_cam_from_obj"][k]
                quat = np.empty(4)
                mujoco.mju_mat2Quat(quat, np.ascontiguousarray(T[:3, :3]).ravel())
                name = names[int(a["object_ycbv_id"][k])]
                placements.append(ObjectPlacement(name, tuple(T[:3, 3]), tuple(quat)))
            side = "left" if bool(a["is_left"]) else "right"
            scene = Scene(
                SceneSpec(
                    hand=hand_params("medium", side),
                    objects=tuple(placements),
                    table=bool(placements),
                )
            )
            scene.set_hand_length(float(a["hand_length_m"]))
            pose = a["hand_pose"]
            scene.binding.set_pose(scene.data, HandPose(pose[:3], pose[3:6], pose[6:]))
            depth.append(_penetration_m(scene))
        reader.close()
    depth_m = np.asarray(depth)
    return {
        "frames": len(contact),
        "contact_rate": float(np.mean(contact)),
        "penetration_max_mm": 1000 * float(depth_m.max()),
        "penetration_p95_mm": 1000 * float(np.percentile(depth_m, 95)),
        "penetration_median_mm": 1000 * float(np.median(depth_m)),
    }


def main() -> None:
    """Print the stats of every dataset named on the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("datasets", nargs="+", type=Path)
    for folder in parser.parse_args().datasets:
        s = dataset_stats(folder)
        print(
            f"{folder}: {s['frames']} frames, contact in {100 * s['contact_rate']:.1f} %, "
            f"penetration max {s['penetration_max_mm']:.2f} mm, p95 "
            f"{s['penetration_p95_mm']:.2f} mm, median {s['penetration_median_mm']:.2f} mm"
        )


if __name__ == "__main__":
    main()
