"""Tests of handsim.data.export: hand labels (JSON lines + PNG) and BOP, against their specs."""

import json

import cv2
import numpy as np
import pytest
import trimesh

from handsim.data.export import InvalidExport, export_bop, export_hand_labels
from handsim.data.generation import GenerationConfig, generate
from handsim.data.shards import ShardReader
from handsim.errors import InvalidKeypoints
from handsim.hand.keypoints import FORMATS, KEYPOINT_NAMES, format_flags
from handsim.world.registry import get_object
from handsim.world.scene import OBJECT_LABEL_OFFSET, SEGMENT_LABELS


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Four frames with a continuous-symmetric can and a discrete-symmetric wood block."""
    folder = tmp_path_factory.mktemp("ds")
    config = GenerationConfig.from_mapping(
        {
            "frames": 4,
            "frames_per_shard": 2,
            "frames_per_episode": 2,
            "sensor": "structured_light",
            "num_objects_range": (2, 2),
            "objects": ("002_master_chef_can", "036_wood_block"),
            "viewpoints": ("third_person",),
        }
    )
    generate(config, folder)
    return folder


def _strict(text):
    return json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON {c}"))


def test_hand_labels_hold_every_frame_and_format(dataset, tmp_path):
    """One strict JSON line per frame, its depth PNG in depth_scale units, all formats."""
    counts = export_hand_labels(dataset, tmp_path / "out")
    assert sum(counts.values()) == 4
    lines = [
        _strict(line)
        for split in counts
        for line in (tmp_path / "out" / split / "labels.jsonl").read_text().splitlines()
    ]
    assert len(lines) == 4
    frames = {(r["source"]["shard"], r["source"]["frame"]): r for r in lines}
    frame = ShardReader(dataset / "shard-00001.h5")[0]
    line = frames[("shard-00001.h5", 0)]
    split = next(s for s in counts if (tmp_path / "out" / s / line["depth"]).exists())
    png = cv2.imread(str(tmp_path / "out" / split / line["depth"]), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint16
    np.testing.assert_allclose(png * line["depth_scale_mm"] / 1000.0, frame["depth"], atol=1e-6)
    np.testing.assert_allclose(line["keypoints_cam_m"], frame["keypoints_cam"], atol=1e-6)
    assert line["keypoint_names"] == list(KEYPOINT_NAMES)
    assert line["visible"] == frame["visible"].tolist()
    assert set(line["formats"]) == set(FORMATS)
    for fmt, names in FORMATS.items():
        assert len(line["formats"][fmt]["keypoints_cam_m"]) == len(names)
    assert {o["name"] for o in line["objects"]} == {"002_master_chef_can", "036_wood_block"}
    # One type for the occluder: the label's integer codes.
    assert line["occluder"] == frame["occluder"].tolist()
    assert line["visible_sensor"] == frame["visible_sensor"].tolist()
    mask = cv2.imread(str(tmp_path / "out" / split / line["hand_mask"]), cv2.IMREAD_UNCHANGED)
    assert mask.dtype == np.uint8 and set(np.unique(mask)) <= {0, 255}
    seg = frame["segmentation"]
    palm = SEGMENT_LABELS.index("palm")
    np.testing.assert_array_equal(mask == 255, (seg >= palm) & (seg < OBJECT_LABEL_OFFSET))
    assert mask.any()
    # Per format: the canonical flags, copied (mediapipe21 is the identity).
    mp = line["formats"]["mediapipe21"]
    assert mp["visible"] == line["visible"] and mp["in_frame"] == line["in_frame"]
    assert mp["visible_sensor"] == line["visible_sensor"]


def test_hand_label_schema_names_every_field_with_its_unit_and_frame(dataset, tmp_path):
    """schema.json lists exactly the fields of a line, each with type, shape, unit and frame."""
    counts = export_hand_labels(dataset, tmp_path / "out")
    schema = _strict((tmp_path / "out" / "schema.json").read_text())
    assert schema["format"] == "handsim-hand-labels-2"
    split = next(iter(counts))
    line = _strict((tmp_path / "out" / split / "labels.jsonl").read_text().splitlines()[0])
    assert set(schema["fields"]) == set(line)
    for name, field in schema["fields"].items():
        assert set(field) == {"type", "shape", "unit", "frame", "meaning"}, name
    assert schema["fields"]["keypoints_cam_m"]["unit"] == "m"
    assert schema["fields"]["keypoints_cam_m"]["frame"].startswith("OpenCV camera")
    assert schema["occluder_codes"] == {
        "-1": "none",
        "-2": "self",
        "-3": "scene",
        "k >= 0": "object instance k (objects[].instance)",
    }
    assert schema["depth_png"] == {"dtype": "uint16", "unit_mm": 0.1, "no_measurement": 0}
    assert schema["keypoint_formats"] == {k: list(v) for k, v in FORMATS.items()}


def test_format_flags_of_computed_points_need_every_source():
    """A copied point keeps its flag; the palm centre needs the wrist and the four MCPs."""
    flags = np.ones(21, dtype=bool)
    flags[KEYPOINT_NAMES.index("ring_mcp")] = False
    icvl = format_flags(flags, "icvl16")
    assert not icvl[FORMATS["icvl16"].index("palm")] and icvl[1:].all()
    np.testing.assert_array_equal(format_flags(flags, "mediapipe21"), flags)
    assert format_flags(np.ones((4, 21), bool), "nyu14").shape == (4, 14)
    with pytest.raises(InvalidKeypoints, match=r"flags of shape \(\.\.\., 21\)"):
        format_flags(np.ones(14, bool), "nyu14")


def test_bop_files_follow_the_format(dataset, tmp_path):
    """Field names, millimetres, row-major rotations, masks, PLY models and symmetries."""
    summary = export_bop(dataset, tmp_path / "bop")
    assert summary == {"scenes": 2, "images": 4, "objects": 2}
    scene = tmp_path / "bop" / "train_pbr" / "000001"
    cams = _strict((scene / "scene_camera.json").read_text())
    gts = _strict((scene / "scene_gt.json").read_text())
    infos = _strict((scene / "scene_gt_info.json").read_text())
    frame = ShardReader(dataset / "shard-00001.h5")[1]
    cam, gt, info = cams["1"], gts["1"], infos["1"]
    assert set(cam) == {"cam_K", "depth_scale", "cam_R_w2c", "cam_t_w2c"}
    np.testing.assert_allclose(np.reshape(cam["cam_K"], (3, 3)), frame["K"])
    np.testing.assert_allclose(cam["cam_t_w2c"], frame["T_cam_from_world"][:3, 3] * 1000.0)
    depth = cv2.imread(str(scene / "depth" / "000001.png"), cv2.IMREAD_UNCHANGED)
    np.testing.assert_allclose(depth * cam["depth_scale"], frame["depth"] * 1000.0, atol=1e-3)
    assert len(gt) == len(info) == 2
    for gt_id, (g, inf) in enumerate(zip(gt, info, strict=True)):
        assert set(g) == {"cam_R_m2c", "cam_t_m2c", "obj_id"}
        assert set(inf) == {
            "bbox_obj", "bbox_visib", "px_count_all", "px_count_valid", "px_count_visib",
            "visib_fract",
        }  # fmt: skip
        R = np.reshape(g["cam_R_m2c"], (3, 3))
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
        np.testing.assert_allclose(R, frame["object_T_cam_from_obj"][gt_id][:3, :3])
        np.testing.assert_allclose(
            g["cam_t_m2c"], frame["object_T_cam_from_obj"][gt_id][:3, 3] * 1e3
        )
        full = cv2.imread(str(scene / "mask" / f"000001_{gt_id:06d}.png"), 0) > 0
        visib = cv2.imread(str(scene / "mask_visib" / f"000001_{gt_id:06d}.png"), 0) > 0
        assert visib.sum() == inf["px_count_visib"]
        # px_count_all counts the whole silhouette (BOP's enlarged canvas); the mask is its
        # part inside the image.
        assert full.sum() <= inf["px_count_all"]
        # The silhouette is rendered as the Frame renders it: the same pixel count.
        rendered = frame["object_px_count_all"][gt_id]
        assert inf["px_count_all"] == rendered
        assert not (visib & ~full).any()
        # bop_toolkit's boxes: [x, y, w, h] with w = x_max - x_min (tight, inclusive ends).
        x, y, w, h = inf["bbox_visib"]
        if visib.any():
            ys, xs = np.nonzero(visib)
            assert [x, y, w, h] == [xs.min(), ys.min(), xs.max() - xs.min(), ys.max() - ys.min()]
            ox, oy, ow, oh = inf["bbox_obj"]
            assert ox <= x and oy <= y and ox + ow >= x + w and oy + oh >= y + h
    models = tmp_path / "bop" / "models"
    info = _strict((models / "models_info.json").read_text())
    can = info["1"]
    assert can["diameter"] == pytest.approx(get_object("002_master_chef_can").diameter_m * 1e3)
    assert can["symmetries_continuous"] == [{"axis": [0.0, 1.0, 0.0], "offset": [0.0, 0.0, 0.0]}]
    block = info["16"]
    assert len(block["symmetries_discrete"]) == 7  # 8 group elements without the identity
    for flat in block["symmetries_discrete"]:
        T = np.reshape(flat, (4, 4))
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
        np.testing.assert_allclose(T[3], [0, 0, 0, 1])
    mesh = trimesh.load(models / "obj_000016.ply")
    np.testing.assert_allclose(
        mesh.extents, get_object("036_wood_block").visual_mesh.extents * 1000.0, rtol=1e-5
    )
    assert block["size_y"] == pytest.approx(mesh.extents[1], rel=1e-5)


def test_bop_models_info_with_depth_symmetries(border_dataset, tmp_path):
    """symmetry="depth" writes the shape's symmetries; "texture" (default) BOP's; bad refused."""
    folder, _ = border_dataset  # a master chef can: continuous in both
    export_bop(folder, tmp_path / "depth", symmetry="depth")
    info = _strict((tmp_path / "depth" / "models" / "models_info.json").read_text())["1"]
    assert info["symmetries_continuous"] == [{"axis": [0.0, 1.0, 0.0], "offset": [0.0, 0.0, 0.0]}]
    with pytest.raises(InvalidExport, match=r"symmetry must be one of \('texture', 'depth'\)"):
        export_bop(folder, tmp_path / "bad", symmetry="rgb")
    from handsim.data.export import _models_info

    soup = get_object("005_tomato_soup_can")
    assert "symmetries_continuous" not in _models_info(soup.ycbv_id)
    assert _models_info(soup.ycbv_id, "depth")["symmetries_continuous"][0]["axis"] == [0, 1, 0]
    box = _models_info(get_object("003_cracker_box").ycbv_id, "depth")
    assert len(box["symmetries_discrete"]) == 3  # the three half turns


def test_exports_refuse_a_non_empty_target_and_a_non_dataset(dataset, tmp_path):
    """Nothing is overwritten; a folder without a manifest is named."""
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    with pytest.raises(InvalidExport, match="is not empty"):
        export_bop(dataset, tmp_path / "full")
    with pytest.raises(Exception, match="has no manifest.json"):
        export_hand_labels(tmp_path / "full", tmp_path / "out")


@pytest.fixture(scope="module")
def border_dataset(tmp_path_factory):
    """One frame: a can cut in half by the image's left border, a hand in view."""
    from handsim.data.manifest import Manifest
    from handsim.data.shards import ShardWriter
    from handsim.frame import FrameRenderer
    from handsim.hand.pose_sources import gesture
    from handsim.world.camera import camera_preset
    from handsim.world.scene import CameraSpec, ObjectPlacement, Scene, SceneSpec

    icvl = camera_preset("icvl")
    cam = CameraSpec.look_at("cam", icvl, (0.0, 0.0, 0.05), (0.0, 1.0, 0.05))
    d = 0.4
    standing = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0)  # the can's axis up
    can = ObjectPlacement("002_master_chef_can", (-icvl.cx / icvl.fx * d, d, 0.05), standing)
    scene = Scene(SceneSpec(cameras=(cam,), objects=(can,), table=False))
    scene.reset(gesture("open").replace(wrist_pos=np.array([0.05, 0.5, -0.05])))
    with FrameRenderer(scene, "cam") as renderer:
        frame = renderer.render(np.random.default_rng(0), hand_occlusion=True)
    folder = tmp_path_factory.mktemp("border")
    arrays = frame.to_arrays(images=True)
    with ShardWriter(folder / Manifest.shard_name(0), image_shape=arrays["depth"].shape) as w:
        w.append(arrays, episode=0, step=0)
    Manifest(
        config={"camera": "icvl", "seed": 0},
        seeds=[0],
        shards={0: w.info},
        depth_scale_mm=0.1,
        image_shape=arrays["depth"].shape,
    ).write(folder)
    return folder, frame


def test_bop_gt_info_of_a_border_cut_object_is_bop_toolkits(border_dataset, tmp_path):
    """px_count_all and bbox_obj count the part outside the image; visib_fract about 1/2."""
    folder, frame = border_dataset
    export_bop(folder, tmp_path / "bop")
    scene = tmp_path / "bop" / "train_pbr" / "000000"
    info = _strict((scene / "scene_gt_info.json").read_text())["0"][0]
    label = frame.objects[0]
    assert info["px_count_all"] == label.px_count_all
    assert info["px_count_visib"] == label.px_count_visib
    assert info["visib_fract"] == pytest.approx(label.visib_fract)
    assert 0.4 < info["visib_fract"] < 0.6  # half the can is outside the image
    mask = cv2.imread(str(scene / "mask" / "000000_000000.png"), 0) > 0
    assert mask.sum() < 0.6 * info["px_count_all"]
    # The whole silhouette's box starts left of the image; it ends where the visible one does.
    x, y, w, h = info["bbox_obj"]
    vx, vy, vw, vh = info["bbox_visib"]
    assert x < 0 and vx == 0
    assert x + w == vx + vw and y <= vy and y + h >= vy + vh
    # Its width: the can's round section (radius r, centre at x_c, z_c in the camera frame)
    # spans the rays at angles phi +- asin(r / rho) from the optical axis.
    x_c, _, z_c = label.T_cam_from_obj[:3, 3]
    r = get_object("002_master_chef_can").visual_mesh.extents[0] / 2
    phi, half = np.arctan2(x_c, z_c), np.arcsin(r / np.hypot(x_c, z_c))
    width_px = 241.42 * (np.tan(phi + half) - np.tan(phi - half))
    assert w == pytest.approx(width_px, abs=1.5)
