"""Exports of handsim datasets to formats other tools read without handsim.

- :func:`export_hand_labels`: ``schema.json`` (every file and field: type, shape, unit, frame;
  the occluder codes) and per split ``labels.jsonl`` (one JSON object per frame: K, hand side,
  the 21 keypoints and every supported keypoint format in camera frame and pixels, visibility
  on the clean render and as the sensor returned it, occluder codes),
  ``depth/NNNNNN.png`` (uint16, ``depth_scale_mm`` per unit) and ``hand_mask/NNNNNN.png``.
- :func:`export_bop`: the BOP format (Hodan et al., "BOP: Benchmark for 6D Object Pose
  Estimation", ECCV 2018; the format of the BOP toolkit): ``models/obj_NNNNNN.ply`` in
  millimetres with ``models_info.json`` (diameter, extents, symmetries), and per scene (one
  shard) ``scene_camera.json``, ``scene_gt.json``, ``scene_gt_info.json``, ``depth/``, ``mask/``
  (the object's silhouette inside the image, rendered with the object alone as the Frame's
  ``visib_fract`` is) and ``mask_visib/`` (its visible pixels). ``scene_gt_info`` follows
  bop_toolkit's ``calc_gt_info``: ``px_count_all`` and ``bbox_obj`` from the whole silhouette
  on a canvas extending the image by its size on every side (a border-cut object counts its
  part outside the image), ``bbox_obj`` ``[-1, -1, -1, -1]`` unless some pixel is visible,
  boxes ``[x, y, w, h]`` with ``w = x_max - x_min`` and ``h = y_max - y_min``.

Both read a dataset folder (``manifest.json`` + shards) and write into a new folder.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import cv2
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from handsim.data.manifest import Manifest
from handsim.data.shards import ShardReader, depth_units
from handsim.data.splits import folder_splits
from handsim.errors import HandSimError
from handsim.hand.keypoints import FORMATS, KEYPOINT_NAMES, format_flags, to_format
from handsim.viz import project_points
from handsim.world.camera import CameraIntrinsics, camera_preset
from handsim.world.registry import OBJECTS, get_object
from handsim.world.render import DepthRenderer
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    CameraSpec,
    ObjectPlacement,
    Scene,
    SceneSpec,
)
from handsim.world.symmetry import SYMMETRY_MODALITIES, SymmetryModality

__all__ = [
    "InvalidExport",
    "export_hand_labels",
    "export_bop",
    "hand_labels_schema",
    "HAND_LABELS_FORMAT",
    "OCCLUDER_NAMES",
]

OCCLUDER_NAMES = {-1: "none", -2: "self", -3: "scene"}
"""Legend of the hand labels' negative occluder codes; an integer k >= 0 is object instance k."""
_PALM_LABEL = SEGMENT_LABELS.index("palm")  # the first hand label

_YCBV_NAMES = {spec.ycbv_id: name for name, spec in OBJECTS.items()}


class InvalidExport(HandSimError, ValueError):
    """An export cannot be made (the source is not a dataset, the target is not empty)."""


def _prepare(dataset: str | os.PathLike[str], out: str | os.PathLike[str]) -> tuple[Manifest, Path]:
    manifest = Manifest.read(dataset)
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise InvalidExport(f"{out} is not empty: export into a new or empty folder")
    out.mkdir(parents=True, exist_ok=True)
    return manifest, out


def _json_points(points: np.ndarray, digits: int) -> list:
    return [[None if not np.isfinite(v) else round(float(v), digits) for v in p] for p in points]


HAND_LABELS_FORMAT = "handsim-hand-labels-2"
"""Version of the hand-label export's layout (``schema.json``'s ``format``)."""

_FIELDS: dict[str, tuple[str, str, str, str, str]] = {
    # name: (JSON type / dtype, shape, unit, frame, meaning)
    "depth": ("str", "()", "", "", "path of the depth PNG, relative to the split folder"),
    "hand_mask": ("str", "()", "", "", "path of the hand mask PNG, relative to the split folder"),
    "depth_scale_mm": ("float", "()", "mm", "", "millimetres per depth PNG unit"),
    "K": ("float", "(3, 3)", "px", "OpenCV camera", "intrinsic matrix"),
    "hand_side": ("str", "()", "", "", "'right' or 'left'"),
    "hand_length_m": ("float", "()", "m", "", "wrist crease to middle fingertip"),
    "keypoint_names": ("str", "(21,)", "", "", "names of the 21 keypoints, in order"),
    "keypoints_cam_m": (
        "float", "(21, 3)", "m", "OpenCV camera (x right, y down, z forward)", "keypoints",
    ),
    "keypoints_px": ("float | null", "(21, 2)", "px", "image (u right, v down)",
                     "keypoint pixels; null behind the camera"),
    "in_frame": ("bool", "(21,)", "", "", "in front of the camera and inside the image"),
    "visible": ("bool", "(21,)", "", "",
                "its own hand part is the surface seen at its pixel (clean render)"),
    "visible_sensor": ("bool", "(21,)", "", "",
                       "visible, and the sensor's depth there is valid and within 10 mm of the "
                       "clean depth"),
    "occluder": ("int", "(21,)", "", "", "what hides the keypoint: a code of occluder_codes"),
    "hand_occlusion_ratio": ("float | null", "()", "", "",
                             "1 - visible hand pixels / hand pixels without objects, forearm "
                             "left out; null when not computed"),
    "objects": ("object", "(n,)", "", "",
                "per object: instance (int), ycbv_id (int, -1 imported), name (str | null), "
                "visib_fract (float, BOP)"),
    "formats": ("object", "", "", "",
                "per keypoint format: names, keypoints_cam_m (m, OpenCV camera), keypoints_px "
                "(px), in_frame, visible, visible_sensor (a point computed from several "
                "keypoints is visible when all of them are)"),
    "episode": ("int", "()", "", "", "episode index in the dataset"),
    "step": ("int", "()", "", "", "frame index in its episode"),
    "source": ("object", "", "", "", "shard (file name) and frame (index) it came from"),
}  # fmt: skip


def hand_labels_schema(depth_scale_mm: float) -> dict[str, Any]:
    """The ``schema.json`` of a hand-label export: files, every field, the occluder codes.

    Args:
        depth_scale_mm: millimetres per unit of the depth PNGs.
    """
    return {
        "format": HAND_LABELS_FORMAT,
        "files": {
            "<split>/labels.jsonl": "one JSON object per frame (fields below)",
            "<split>/depth/NNNNNN.png": (
                f"depth along the optical axis, uint16, {depth_scale_mm} mm per unit "
                "(depth_mm = value * depth_scale_mm), 0 = no measurement"
            ),
            "<split>/hand_mask/NNNNNN.png": (
                "uint8, 255 where the rendered surface is the hand (palm, with the forearm's "
                "skin, and fingers), 0 elsewhere"
            ),
        },
        "depth_png": {"dtype": "uint16", "unit_mm": depth_scale_mm, "no_measurement": 0},
        "hand_mask_png": {"dtype": "uint8", "hand": 255, "other": 0},
        "fields": {
            name: {"type": t, "shape": shape, "unit": unit, "frame": frame, "meaning": meaning}
            for name, (t, shape, unit, frame, meaning) in _FIELDS.items()
        },
        "occluder_codes": {
            **{str(code): name for code, name in OCCLUDER_NAMES.items()},
            "k >= 0": "object instance k (objects[].instance)",
        },
        "keypoint_formats": {fmt: list(names) for fmt, names in FORMATS.items()},
    }


def export_hand_labels(
    dataset: str | os.PathLike[str], out: str | os.PathLike[str]
) -> dict[str, int]:
    """Write a dataset's hand labels as JSON lines with depth and hand-mask PNGs, per split.

    ``out/schema.json`` (:func:`hand_labels_schema`) names every file and field with its type,
    shape, unit and frame, and the occluder codes. Per frame (one line of
    ``<split>/labels.jsonl``): ``depth`` and ``hand_mask`` (PNG paths relative to the split
    folder), ``depth_scale_mm``, ``K`` (3 x 3), ``hand_side``, ``hand_length_m``,
    ``keypoint_names``, ``keypoints_cam_m`` (21 x 3, OpenCV camera frame), ``keypoints_px``
    (21 x 2, ``null`` behind the camera), ``in_frame``, ``visible``, ``visible_sensor``,
    ``occluder`` (integer codes: -1 none, -2 self, -3 scene, ``k >= 0`` object instance ``k``),
    ``hand_occlusion_ratio``, ``objects`` (instance, YCB-Video id, name, visible fraction),
    ``formats`` (every supported keypoint format: names, camera-frame points, pixels and
    per-point ``in_frame``, ``visible``, ``visible_sensor``), ``episode``, ``step`` and
    ``source`` (shard and frame).

    Returns:
        Frames written per split.

    Raises:
        InvalidManifest: if ``dataset`` is not a dataset folder.
        InvalidExport: if ``out`` is not empty.
    """
    manifest, out = _prepare(dataset, out)
    (out / "schema.json").write_text(
        json.dumps(hand_labels_schema(manifest.depth_scale_mm), indent=1, allow_nan=False) + "\n"
    )
    splits = folder_splits(dataset, manifest)
    counts: dict[str, int] = {}
    files: dict[str, Any] = {}
    h, w = manifest.image_shape
    try:
        for record in sorted(manifest.shards.values(), key=lambda s: s.name):
            reader = ShardReader(Path(dataset) / record.name)
            for i in range(len(reader)):
                a = reader[i]
                split = splits[int(a["episode"])]
                folder = out / split
                if split not in files:
                    (folder / "depth").mkdir(parents=True)
                    (folder / "hand_mask").mkdir()
                    files[split] = open(folder / "labels.jsonl", "w")  # noqa: SIM115
                k = counts.get(split, 0)
                counts[split] = k + 1
                png = f"depth/{k:06d}.png"
                cv2.imwrite(str(folder / png), depth_units(a["depth"], manifest.depth_scale_mm))
                mask_png = f"hand_mask/{k:06d}.png"
                seg = a["segmentation"]
                hand = (seg >= _PALM_LABEL) & (seg < OBJECT_LABEL_OFFSET)
                cv2.imwrite(str(folder / mask_png), hand.astype(np.uint8) * 255)
                K = a["K"]
                kp = a["keypoints_cam"]
                formats = {}
                for fmt, point_names in FORMATS.items():
                    pts = to_format(kp, fmt)
                    px = project_points(K, pts)
                    with np.errstate(invalid="ignore"):
                        inside = (
                            (pts[:, 2] > 0)
                            & (np.rint(px[:, 0]) >= 0)
                            & (np.rint(px[:, 0]) < w)
                            & (np.rint(px[:, 1]) >= 0)
                            & (np.rint(px[:, 1]) < h)
                        )
                    formats[fmt] = {
                        "names": list(point_names),
                        "keypoints_cam_m": _json_points(pts, 6),
                        "keypoints_px": _json_points(px, 3),
                        "in_frame": [bool(v) for v in inside],
                        "visible": [bool(v) for v in format_flags(a["visible"], fmt)],
                        "visible_sensor": [bool(v) for v in format_flags(a["visible_sensor"], fmt)],
                    }
                objects = [
                    {
                        "instance": int(j),
                        "ycbv_id": int(a["object_ycbv_id"][j]),
                        "name": _YCBV_NAMES.get(int(a["object_ycbv_id"][j])),
                        "visib_fract": round(float(a["object_visib_fract"][j]), 6),
                    }
                    for j in np.flatnonzero(a["object_valid"])
                ]
                ratio = float(a["hand_occlusion_ratio"])
                line = {
                    "depth": png,
                    "hand_mask": mask_png,
                    "depth_scale_mm": manifest.depth_scale_mm,
                    "K": K.tolist(),
                    "hand_side": "left" if bool(a["is_left"]) else "right",
                    "hand_length_m": float(a["hand_length_m"]),
                    "keypoint_names": list(KEYPOINT_NAMES),
                    "keypoints_cam_m": _json_points(kp, 6),
                    "keypoints_px": _json_points(a["keypoints_px"], 3),
                    "in_frame": [bool(v) for v in a["in_frame"]],
                    "visible": [bool(v) for v in a["visible"]],
                    "visible_sensor": [bool(v) for v in a["visible_sensor"]],
                    "occluder": [int(o) for o in a["occluder"]],
                    "hand_occlusion_ratio": round(ratio, 6) if ratio >= 0 else None,
                    "objects": objects,
                    "formats": formats,
                    "episode": int(a["episode"]),
                    "step": int(a["step"]),
                    "source": {"shard": record.name, "frame": i},
                }
                files[split].write(json.dumps(line, allow_nan=False) + "\n")
            reader.close()
    finally:
        for f in files.values():
            f.close()
    return counts


def _ply_mm(path: Path, vertices_m: np.ndarray, faces: np.ndarray) -> None:
    """A binary little-endian PLY mesh with vertices in millimetres."""
    v = (np.asarray(vertices_m, dtype=np.float64) * 1000.0).astype("<f4")
    f = np.asarray(faces, dtype="<i4")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    rows = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    rows["n"], rows["i"] = 3, f
    path.write_bytes(header.encode() + v.tobytes() + rows.tobytes())


def _models_info(ycbv_id: int, symmetry: SymmetryModality = "texture") -> dict[str, Any]:
    """BOP ``models_info`` of one object (millimetres), symmetries in BOP's encoding."""
    obj = get_object(_YCBV_NAMES[ycbv_id])
    lo = obj.visual_mesh.vertices.min(axis=0) * 1000.0
    size = obj.visual_mesh.vertices.max(axis=0) * 1000.0 - lo
    info: dict[str, Any] = {
        "diameter": round(obj.diameter_m * 1000.0, 6),
        "min_x": round(float(lo[0]), 6),
        "min_y": round(float(lo[1]), 6),
        "min_z": round(float(lo[2]), 6),
        "size_x": round(float(size[0]), 6),
        "size_y": round(float(size[1]), 6),
        "size_z": round(float(size[2]), 6),
    }
    info.update(obj.symmetry_of(symmetry).to_bop())
    return info


def _bbox(mask: np.ndarray, offset: tuple[int, int] = (0, 0)) -> list[int]:
    """BOP's ``[x, y, w, h]`` of a mask, bop_toolkit's convention: ``w = x_max - x_min``.

    ``offset``: image coordinates ``(u, v)`` of the mask's pixel ``(0, 0)``.
    """
    ys, xs = np.nonzero(mask)
    if not len(xs):
        return [-1, -1, -1, -1]
    return [
        int(xs.min() + offset[0]),
        int(ys.min() + offset[1]),
        int(xs.max() - xs.min()),
        int(ys.max() - ys.min()),
    ]


class _Silhouettes:
    """Whole silhouettes of objects rendered alone by MuJoCo, on BOP's canvas.

    The canvas is the image and one image size beyond it on every side (3 W x 3 H; image pixel
    ``(u, v)`` is canvas pixel ``(u + W, v + H)``), as bop_toolkit's ``calc_gt_info`` renders
    it, and as the Frame counts ``px_count_all``.
    """

    def __init__(self, intrinsics: CameraIntrinsics) -> None:
        # A camera at the world origin whose OpenCV frame is the world frame, so an object's
        # world pose is its camera-frame pose.
        self.camera = CameraSpec.look_at("cam", intrinsics, (0, 0, 0), (0, 0, 1), up=(0, -1, 0))
        self._scenes: dict[str, tuple[Scene, DepthRenderer]] = {}

    def __call__(self, name: str, T_cam_from_obj: np.ndarray) -> np.ndarray:
        if name not in self._scenes:
            spec = SceneSpec(
                hand=None,
                objects=(ObjectPlacement(name, (0.0, 0.0, 1.0)),),
                cameras=(self.camera,),
                table=False,
            )
            scene = Scene(spec)
            self._scenes[name] = (scene, DepthRenderer(scene.model, "cam", self.camera.intrinsics))
        scene, renderer = self._scenes[name]
        R = T_cam_from_obj[:3, :3]
        qpos = np.concatenate(
            [T_cam_from_obj[:3, 3], np.roll(Rotation.from_matrix(R).as_quat(), 1)]
        )
        scene.data.qpos[:7] = qpos
        mujoco.mj_forward(scene.model, scene.data)
        w, h = self.camera.intrinsics.width, self.camera.intrinsics.height
        return renderer.render_segmentation_canvas(scene.data, (-w, -h, 2 * w, 2 * h)) >= 0

    def close(self) -> None:
        for _, renderer in self._scenes.values():
            renderer.close()


def export_bop(
    dataset: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    symmetry: SymmetryModality = "texture",
) -> dict[str, int]:
    """Write a dataset in the BOP format (one BOP scene per shard, split by shard).

    Units and conventions are BOP's: millimetres, ``cam_R_*`` row-major 3 x 3, ``cam_K``
    row-major 3 x 3, depth PNG in units of ``depth_scale`` mm, masks named
    ``{im_id:06d}_{gt_id:06d}.png`` with ``gt_id`` the object's index in ``scene_gt``.

    Args:
        dataset: the dataset folder.
        out: a new or empty folder.
        symmetry: the symmetries in ``models_info.json`` (``symmetries_continuous``,
            ``symmetries_discrete``): ``"texture"`` (default; what looks the same in colour, as
            BOP's ycbv models_info) or ``"depth"`` (the shape alone, for depth-only methods:
            the tomato soup and tuna cans are then continuous, the plain boxes discrete;
            :meth:`~handsim.world.YCBObject.symmetry_of`).

    Returns:
        ``{"scenes": n, "images": n, "objects": n}``.

    Raises:
        InvalidManifest: if ``dataset`` is not a dataset folder.
        InvalidExport: if ``out`` is not empty.
    """
    if symmetry not in SYMMETRY_MODALITIES:
        raise InvalidExport(f"symmetry must be one of {SYMMETRY_MODALITIES}; received {symmetry!r}")
    manifest, out = _prepare(dataset, out)
    silhouettes = _Silhouettes(camera_preset(manifest.config.get("camera", "icvl")))
    used: set[int] = set()
    images = 0
    for scene_id, record in enumerate(sorted(manifest.shards.values(), key=lambda s: s.name)):
        folder = out / "train_pbr" / f"{scene_id:06d}"
        for sub in ("depth", "mask", "mask_visib"):
            (folder / sub).mkdir(parents=True)
        reader = ShardReader(Path(dataset) / record.name)
        cams, gts, infos = {}, {}, {}
        for im_id in range(len(reader)):
            a = reader[im_id]
            K, T = a["K"], a["T_cam_from_world"]
            cv2.imwrite(
                str(folder / "depth" / f"{im_id:06d}.png"),
                depth_units(a["depth"], manifest.depth_scale_mm),
            )
            cams[str(im_id)] = {
                "cam_K": [float(x) for x in K.ravel()],
                "depth_scale": manifest.depth_scale_mm,
                "cam_R_w2c": [float(x) for x in T[:3, :3].ravel()],
                "cam_t_w2c": [float(x) * 1000.0 for x in T[:3, 3]],
            }
            gt, info = [], []
            depth_valid = a["depth"] > 0
            for gt_id, k in enumerate(np.flatnonzero(a["object_valid"])):
                ycbv_id = int(a["object_ycbv_id"][k])
                if ycbv_id < 0:
                    continue  # imported meshes have no BOP model
                used.add(ycbv_id)
                T_obj = a["object_T_cam_from_obj"][k]
                gt.append(
                    {
                        "cam_R_m2c": [float(x) for x in T_obj[:3, :3].ravel()],
                        "cam_t_m2c": [float(x) * 1000.0 for x in T_obj[:3, 3]],
                        "obj_id": ycbv_id,
                    }
                )
                name = _YCBV_NAMES[ycbv_id]
                canvas = silhouettes(name, T_obj)
                h, w = depth_valid.shape
                full = canvas[h : 2 * h, w : 2 * w]  # the part inside the image: BOP's mask
                visib = a["segmentation"] == OBJECT_LABEL_OFFSET + k
                n_all = int(canvas.sum())
                n_visib = int(visib.sum())
                info.append(
                    {
                        # As bop_toolkit: the whole silhouette's box, given only when visible.
                        "bbox_obj": _bbox(canvas, (-w, -h)) if n_visib else [-1, -1, -1, -1],
                        "bbox_visib": _bbox(visib),
                        "px_count_all": n_all,
                        "px_count_valid": int((full & depth_valid).sum()),
                        "px_count_visib": n_visib,
                        "visib_fract": n_visib / n_all if n_all else 0.0,
                    }
                )
                png = f"{im_id:06d}_{gt_id:06d}.png"
                cv2.imwrite(str(folder / "mask" / png), full.astype(np.uint8) * 255)
                cv2.imwrite(str(folder / "mask_visib" / png), visib.astype(np.uint8) * 255)
            gts[str(im_id)], infos[str(im_id)] = gt, info
            images += 1
        reader.close()
        for name, doc in (
            ("scene_camera.json", cams),
            ("scene_gt.json", gts),
            ("scene_gt_info.json", infos),
        ):
            (folder / name).write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    silhouettes.close()
    models = out / "models"
    models.mkdir()
    info_all = {}
    for ycbv_id in sorted(used):
        obj = get_object(_YCBV_NAMES[ycbv_id])
        _ply_mm(models / f"obj_{ycbv_id:06d}.ply", obj.visual_mesh.vertices, obj.visual_mesh.faces)
        info_all[str(ycbv_id)] = _models_info(ycbv_id, symmetry)
    (models / "models_info.json").write_text(json.dumps(info_all, indent=1) + "\n")
    return {"scenes": len(manifest.shards), "images": images, "objects": len(used)}
