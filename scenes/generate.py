"""Generate the MJCF assets in ``scenes/`` (Menagerie layout) from handsim's models.

Run ``python -m handsim.scenes`` (writes into this package's folder, i.e. ``scenes/`` of a
checkout) or ``python -m handsim.scenes --out DIR``. Output is deterministic: the committed
files are checked by ``tests/scenes/test_generate.py`` (regenerate -> byte-identical).

What is written (``<side>`` is ``right``/``left``, ``<name>`` an object name such as
``005_tomato_soup_can``):

- ``hand/<side>_hand.xml``: :meth:`handsim.hand.model.Hand.to_xml` of the default hand of that
  side; ``hand/keyframes_<side>.xml``: one keyframe per named gesture;
  ``hand/scene_<side>.xml``: includes both and adds a floor, lights and a camera.
- ``objects/<name>/<name>.xml``: the object resting on ``z = 0`` (free joint, meshes in
  ``objects/<name>/assets/``); ``objects/<name>/scene.xml``: includes it on a floor.
- ``grasp/scene.xml``: a :class:`handsim.world.scene.Scene` (table, right hand, a mustard
  bottle, a depth camera) with a floor; the hand starts above the table, palm down.
- ``README.md`` in every folder.
"""

from __future__ import annotations

import argparse
import pathlib
import xml.etree.ElementTree as ET
from collections.abc import Sequence

import mujoco
import numpy as np

from handsim.hand.model import Hand, HandParams
from handsim.hand.pose import HandPose
from handsim.hand.pose_sources import GESTURES, gesture
from handsim.world.mjcf import save_spec, spec_to_xml
from handsim.world.objects import add_object
from handsim.world.registry import OBJECT_NAMES, get_object
from handsim.world.scene import ObjectPlacement, Scene, SceneSpec, third_person_camera

__all__ = ["PARTS", "GRASP_OBJECT", "generate", "main"]

PARTS: tuple[str, ...] = ("hand", "objects", "grasp")
"""Folders :func:`generate` can write."""
GRASP_OBJECT = "006_mustard_bottle"
"""The object of ``grasp/scene.xml``."""
_GRASP_OBJECT_XY_M = (0.0, 0.18)
_SIDES = ("right", "left")
_REGENERATE = "python -m handsim.scenes"


def _scene_dressing(
    spec: mujoco.MjSpec, *, floor_z_m: float, center_m, extent_m: float, sun: bool = True
) -> None:
    """Add a sky, a checker floor at ``floor_z_m``, a light (``sun``) and the viewer's framing."""
    spec.stat.center = center_m
    spec.stat.extent = extent_m
    spec.visual.headlight.diffuse = [0.6, 0.6, 0.6]
    spec.visual.headlight.ambient = [0.3, 0.3, 0.3]
    spec.visual.headlight.specular = [0.0, 0.0, 0.0]
    spec.visual.global_.azimuth = 120.0
    spec.visual.global_.elevation = -20.0
    spec.add_texture(
        name="skybox",
        type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        rgb1=[0.3, 0.5, 0.7],
        rgb2=[0.0, 0.0, 0.0],
        width=512,
        height=3072,
    )
    spec.add_texture(
        name="groundplane",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        mark=mujoco.mjtMark.mjMARK_EDGE,
        rgb1=[0.2, 0.3, 0.4],
        rgb2=[0.1, 0.2, 0.3],
        markrgb=[0.8, 0.8, 0.8],
        width=300,
        height=300,
    )
    material = spec.add_material(name="groundplane", texuniform=True, texrepeat=[5, 5])
    material.reflectance = 0.2
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "groundplane"
    if sun:
        spec.worldbody.add_light(
            name="sun",
            pos=[0.0, 0.0, floor_z_m + 1.5],
            dir=[0.0, 0.0, -1.0],
            type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
        )
    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0.0, 0.0, 0.05],
        pos=[0.0, 0.0, floor_z_m],
        material="groundplane",
    )


def _with_include(xml: str, *files: str) -> str:
    # MjSpec has no <include>: put the elements before <compiler>, after the header comment.
    head, rest = xml.split("\n  <compiler", 1)
    includes = "".join(f'\n  <include file="{f}"/>' for f in files)
    return f"{head}{includes}\n  <compiler{rest}"


def _write(path: pathlib.Path, text: str) -> pathlib.Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(text.encode("utf-8"))
    return path


def _numbers(values: np.ndarray) -> str:
    return " ".join(repr(float(v)).removesuffix(".0") for v in np.asarray(values).ravel())


def _keyframes_xml(hand: Hand, model: mujoco.MjModel) -> str:
    """One ``<key>`` per gesture of :data:`GESTURES`: joints, ctrl and mocap target agree."""
    binding = hand.bind(model)
    data = mujoco.MjData(model)
    root = ET.Element("mujoco", model=f"{hand.prefix}keyframes")
    root.append(ET.Comment(" One key per gesture of handsim.hand.pose_sources.GESTURES. "))
    keyframe = ET.SubElement(root, "keyframe")
    for name in GESTURES:
        pose = gesture(name)
        binding.set_pose(data, HandPose(pose.wrist_pos, pose.wrist_rotvec, pose.angles))
        ET.SubElement(
            keyframe,
            "key",
            name=name,
            qpos=_numbers(data.qpos),
            ctrl=_numbers(data.ctrl),
            mpos=_numbers(data.mocap_pos),
            mquat=_numbers(data.mocap_quat),
        )
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def _hand_files(out: pathlib.Path) -> list[pathlib.Path]:
    written = []
    for side in _SIDES:
        hand = Hand(HandParams(side=side))
        path = hand.save(out / "hand" / f"{side}_hand.xml")
        written.append(path)
        written += sorted((out / "hand" / "assets").glob(f"{hand.prefix}*.obj"))
        keys = _keyframes_xml(hand, hand.compile())
        written.append(_write(out / "hand" / f"keyframes_{side}.xml", keys))
        spec = mujoco.MjSpec()
        spec.modelname = f"{side}_hand scene"
        spec.comment = (
            f" The default {side} hand ({side}_hand.xml) held palm up 10 cm above a floor, "
            f"with its gestures as keyframes (keyframes_{side}.xml). Generated by "
            f"{_REGENERATE}. "
        )
        _scene_dressing(spec, floor_z_m=-0.1, center_m=[0.0, 0.05, 0.0], extent_m=0.3)
        spec.worldbody.add_camera(
            name="closeup",
            pos=[0.0, -0.25, 0.3],
            xyaxes=[1.0, 0.0, 0.0, 0.0, 0.77, 0.64],
        )
        xml = _with_include(spec_to_xml(spec), f"{side}_hand.xml", f"keyframes_{side}.xml")
        written.append(_write(out / "hand" / f"scene_{side}.xml", xml))
    written.append(_write(out / "hand" / "README.md", _HAND_README))
    return written


def _object_files(out: pathlib.Path, names: Sequence[str]) -> list[pathlib.Path]:
    written = []
    for name in names:
        obj = get_object(name)
        folder = out / "objects" / obj.name
        spec = mujoco.MjSpec()
        spec.modelname = obj.name
        spec.comment = (
            f" {obj.name}: {obj.shape}. Mass {obj.mass_kg} kg. Resting on z = 0 in its stable "
            f"pose. Generated by {_REGENERATE}. "
        )
        spec.compiler.degree = False
        add_object(
            spec, obj, pos=(0.0, 0.0, obj.rest_height_m), quat_wxyz=tuple(obj.rest_quat_wxyz)
        )
        written.append(save_spec(spec, folder / f"{obj.name}.xml"))
        written.extend(sorted((folder / "assets").glob("*.obj")))
        scene = mujoco.MjSpec()
        scene.modelname = f"{obj.name} scene"
        scene.comment = f" {obj.name}.xml on a floor. Generated by {_REGENERATE}. "
        extent = float(max(obj.extents_m))
        _scene_dressing(
            scene, floor_z_m=0.0, center_m=[0.0, 0.0, obj.rest_height_m], extent_m=2 * extent
        )
        xml = _with_include(spec_to_xml(scene), f"{obj.name}.xml")
        written.append(_write(folder / "scene.xml", xml))
    written.append(_write(out / "objects" / "README.md", _OBJECTS_README))
    return written


def _grasp_files(out: pathlib.Path) -> list[pathlib.Path]:
    obj = get_object(GRASP_OBJECT)
    placement = ObjectPlacement(
        obj.name,
        (*_GRASP_OBJECT_XY_M, float(obj.rest_height_m + 5e-4)),
        tuple(map(float, obj.rest_quat_wxyz)),
    )
    # No coarse skin (a handsim renderer's level of detail): the asset is the hand as drawn.
    spec = SceneSpec(objects=(placement,), cameras=(third_person_camera(),), skin_lod=False)
    scene = Scene(spec)
    spec = scene.mjspec.copy()
    spec.modelname = "grasp scene"
    spec.comment = (
        " A handsim Scene (handsim.world.scene): table top at z = 0, the default right hand, "
        f"{obj.name}, the third-person depth camera; plus a floor. The hand's free joint and "
        "its mocap target start at Scene.reset()'s pose (palm down above the table). "
        f"Generated by {_REGENERATE}. "
    )
    # qpos0 of a free joint is its body's pose: start the hand where Scene.reset puts it.
    hand, binding = scene.hand, scene.binding
    wrist = scene.data.qpos[binding.root_qpos : binding.root_qpos + 7]
    for body in (hand.root_body, hand.mocap_body):
        spec.body(body).pos = wrist[:3]
        spec.body(body).quat = wrist[3:]
    # The scene has its own lights over the table.
    _scene_dressing(spec, floor_z_m=-0.75, center_m=[0.0, 0.0, 0.1], extent_m=0.6, sun=False)
    written = [save_spec(spec, out / "grasp" / "scene.xml")]
    written.extend(sorted((out / "grasp" / "assets").glob("*.obj")))
    written.append(_write(out / "grasp" / "README.md", _GRASP_README))
    return written


def generate(
    out: str | pathlib.Path,
    *,
    parts: Sequence[str] = PARTS,
    objects: Sequence[str] | None = None,
) -> list[pathlib.Path]:
    """Write the scene assets into ``out``.

    Args:
        out: destination folder (``scenes/`` for the committed files).
        parts: which of :data:`PARTS` to write.
        objects: object names for ``objects/`` (default: all 21, in YCB-Video id order).

    Returns:
        The files written, in a deterministic order.

    Raises:
        ValueError: for an unknown part.
        UnknownName: for an unknown object name.
    """
    unknown = [p for p in parts if p not in PARTS]
    if unknown:
        raise ValueError(f"unknown parts {unknown}; valid parts: {', '.join(PARTS)}")
    out = pathlib.Path(out)
    written = [_write(out / "README.md", _TOP_README)]
    if "hand" in parts:
        written += _hand_files(out)
    if "objects" in parts:
        written += _object_files(out, OBJECT_NAMES if objects is None else objects)
    if "grasp" in parts:
        written += _grasp_files(out)
    return written


def main(argv: Sequence[str] | None = None) -> None:
    """Command line: ``python -m handsim.scenes [--out DIR] [--parts hand objects grasp]``."""
    parser = argparse.ArgumentParser(
        prog="python -m handsim.scenes", description="Generate handsim's MJCF assets."
    )
    parser.add_argument(
        "--out",
        type=pathlib.Path,
        default=pathlib.Path(__file__).resolve().parent,
        help="destination folder (default: the handsim.scenes package folder, i.e. scenes/)",
    )
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    args = parser.parse_args(argv)
    files = generate(args.out, parts=args.parts)
    size = sum(f.stat().st_size for f in files)
    print(f"wrote {len(files)} files ({size / 1e6:.2f} MB) to {args.out}")


_VERSIONS = f"MuJoCo {mujoco.__version__}, NumPy {np.__version__.split('.')[0]}"

_TOP_README = f"""# handsim MJCF assets

MJCF models of the handsim hand, the 21 YCB-Video-like objects and a grasp scene, laid out
like MuJoCo Menagerie: one folder per asset kind; a model file holds only the hand or object,
and a `scene*.xml` includes it and adds a floor, lights and a camera.

- `hand/`: `right_hand.xml`, `left_hand.xml` (the hands alone), `keyframes_<side>.xml`,
  `scene_right.xml`, `scene_left.xml`;
- `objects/<name>/`: `<name>.xml` (the object, meshes in `assets/`) and `scene.xml`;
- `grasp/`: `scene.xml`, a table, the right hand, a mustard bottle and a depth camera
  (meshes in `assets/`).

Open one in MuJoCo's viewer:

```bash
python -m mujoco.viewer --mjcf scenes/hand/scene_right.xml
```

## How these files are made

1. Every file here is written by `{_REGENERATE}` (`scenes/generate.py`) from the models in
   `handsim` (`Hand.to_xml()`, `handsim.world.mjcf.save_spec`, `Scene`); do not edit them by hand.
2. Numbers are printed at full precision, so each XML compiles to the same model as the
   in-memory one (`tests/handsim/world/test_mjcf.py`).
3. Meshes are Wavefront OBJ with the shortest float32 decimals (exactly MuJoCo's float32
   vertices).
4. `tests/scenes/test_generate.py` regenerates into a temporary folder and checks the files
   are byte-identical to these. Generated with {_VERSIONS}; after upgrading MuJoCo, run
   `{_REGENERATE}` again.

Names follow handsim's scheme (`docs/mjcf.md`): `rh_`/`lh_` + digit + joint
(`rh_index_mcp_flex`), actuators `..._act`, keypoint sites `rh_kp_<keypoint>`, objects
`obj_<name>...`. Geom group 2 is visual (what cameras see), group 3 collision.
"""

_HAND_README = f"""# hand

The default (medium, 189 mm) handsim hand, both sides.

- `right_hand.xml`, `left_hand.xml`: the hand alone, `Hand(HandParams(side=...)).save(...)`,
  its skin meshes in `assets/` (OBJ, one per hand segment and side, and the forearm's), and
  the arm, drawn only: `<side>_forearm_visual_0` (mesh) and `<side>_upper_arm_visual_0`
  (capsule), no contact and no mass (`docs/hand.md`, "The arm");
- `keyframes_right.xml`, `keyframes_left.xml`: one keyframe per gesture of
  `handsim.hand.pose_sources.GESTURES` (load one in the viewer's Simulation panel);
- `scene_right.xml`, `scene_left.xml`: the hand and its keyframes, palm up 10 cm above a
  floor, with lights and a camera `closeup`.

The hand is a free body (`<side>_root`) held by a soft weld (`<side>_root_weld`) to the mocap
body `<side>_mocap`: move the mocap body to move the hand. The 21 finger actuators are
position servos (`ctrl` in radians). The naming scheme is a comment at the top of each hand
file.

Derivation:

1. `Hand(HandParams(side=side))` builds the parametric hand with `mujoco.MjSpec`
   (segment lengths from Buchholz et al. 1992 in `handsim/hand/skeleton.py`, joint limits and
   gains in `handsim/hand/model.py`).
2. `Hand.save()` attaches it to an empty spec with the `rh_`/`lh_` prefix and writes it at
   full precision, the skin meshes as OBJ under `assets/` (`handsim.world.mjcf.save_spec`).
3. Keyframes: `HandBinding.set_pose` of each gesture; `qpos`, `ctrl` and the mocap pose are
   copied from the resulting `MjData`.
4. Regenerate with `{_REGENERATE} --parts hand`.
"""

_OBJECTS_README = f"""# objects

The 21 YCB-Video objects as handsim approximates them (shapes made from primitives at the
real extents and masses; `handsim/world/ycbv.py`, `ycbv_shapes.py`), one folder each:
`<name>/<name>.xml`, `<name>/scene.xml`, `<name>/assets/*.obj`.

Names (`<name>` e.g. `005_tomato_soup_can`): body `obj_<name>`, free joint `obj_<name>_root`,
visual geom and mesh `obj_<name>_visual` (group 2, no contacts), collision geoms and meshes
`obj_<name>_collision_<k>` (group 3, convex pieces). The body's mass, centre of mass and
inertia are explicit (Calli et al. 2015 masses).

Each object rests on the plane `z = 0` in its stable pose (`YCBObject.rest_quat_wxyz`,
`rest_height_m`); its body frame is the YCB-Video model frame.

Derivation:

1. `handsim.world.registry.get_object(name)` builds the object (visual mesh, convex collision
   pieces, mass properties).
2. `handsim.world.objects.add_object` adds it to an empty `MjSpec` at its rest pose.
3. `handsim.world.mjcf.save_spec` writes the XML and its meshes as OBJ under `assets/`.
4. Regenerate with `{_REGENERATE} --parts objects`.
"""

_GRASP_README = f"""# grasp

`scene.xml`: a handsim `Scene` (`handsim.world.scene`) with the table (top at `z = 0`), the
default right hand, `{GRASP_OBJECT}` and the third-person depth camera, plus a floor.
Meshes are in `assets/`. The hand starts palm down above the table (where `Scene.reset()`
puts it).

Derivation:

1. `Scene(SceneSpec(objects=(ObjectPlacement("{GRASP_OBJECT}", ...),),
   cameras=(third_person_camera(),)))`.
2. A copy of `Scene.mjspec` with the hand's root and mocap bodies moved to the reset pose, and
   a floor 0.75 m below the table top.
3. `handsim.world.mjcf.save_spec` writes the XML and its meshes as OBJ under `assets/`.
4. Regenerate with `{_REGENERATE} --parts grasp`.
"""


if __name__ == "__main__":
    main()
