"""The glb export of a model's visible geoms: sizes, frames, what is drawn, errors."""

import io
import json
import struct

import mujoco
import numpy as np
import pytest
import trimesh

from handsim.world.gltf import InvalidExport, body_poses, export_glb

XML = """
<mujoco>
  <worldbody>
    <geom name="slab" type="box" size="0.1 0.2 0.3" pos="1 2 3" rgba="0.2 0.4 0.6 1"/>
    <body name="ball" pos="0.5 0 1" quat="0.7071068 0 0 0.7071068">
      <freejoint/>
      <geom name="ball_visual" type="sphere" size="0.05" group="2" rgba="1 0 0 1"/>
      <geom name="ball_collision" type="capsule" size="0.05 0.5" group="3"/>
      <geom name="ball_ghost" type="box" size="1 1 1" group="2" rgba="1 1 1 0"/>
    </body>
    <body name="pieces" pos="0 0 2">
      <geom name="piece" type="cylinder" size="0.02 0.1" group="3"/>
    </body>
  </worldbody>
</mujoco>
"""


def _gltf_json(glb: bytes) -> dict:
    length = struct.unpack("<I", glb[12:16])[0]
    return json.loads(glb[20 : 20 + length])


@pytest.fixture
def model_data():
    """The small model above, after mj_forward."""
    model = mujoco.MjModel.from_xml_string(XML)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def test_the_visible_geoms_are_exported_at_their_size_in_the_y_up_frame(model_data):
    """The slab keeps its size and place (MuJoCo z up -> glTF y up); hidden geoms are not drawn."""
    model, data = model_data
    export = export_glb(model, data)
    assert export.glb[:4] == b"glTF"
    assert export.body_names == ("world", "ball", "pieces")
    scene = trimesh.load(io.BytesIO(export.glb), file_type="glb")
    # slab, ball sphere, the collision-only body's cylinder: not the capsule, not alpha 0.
    assert len(scene.geometry) == 3
    slab = scene.graph.geometry_nodes
    node = next(n for names in slab.values() for n in names if n.endswith("slab"))
    transform, geometry = scene.graph[node]
    mesh = scene.geometry[geometry].copy()
    mesh.apply_transform(transform)
    # MuJoCo: centre (1, 2, 3), half sizes (0.1, 0.2, 0.3) -> glTF (x, z, -y).
    np.testing.assert_allclose(mesh.bounds, [[0.9, 2.7, -2.2], [1.1, 3.3, -1.8]], atol=1e-6)
    doc = _gltf_json(export.glb)
    colours = [m["pbrMetallicRoughness"]["baseColorFactor"] for m in doc["materials"]]
    assert any(np.allclose(c, [0.2, 0.4, 0.6, 1.0], atol=0.01) for c in colours)


def test_body_nodes_start_at_the_data_and_poses_stream_in_their_order(model_data):
    """A body node's pose is the body's world pose, the same as a body_poses row."""
    model, data = model_data
    export = export_glb(model, data)
    scene = trimesh.load(io.BytesIO(export.glb), file_type="glb")
    poses = body_poses(data, export.body_ids)
    assert poses.shape == (3, 7)
    ball = export.body_names.index("ball")
    np.testing.assert_allclose(poses[ball, :3], [0.5, 0.0, 1.0])
    np.testing.assert_allclose(np.abs(poses[ball, 3:]), [0.7071068, 0, 0, 0.7071068], atol=1e-6)
    # The node, seen from the glb's root, is the y-up turn of that pose.
    world_from_node, _ = scene.graph.get("ball")
    y_up = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]])
    np.testing.assert_allclose(world_from_node[:3, 3], y_up @ [0.5, 0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(
        world_from_node[:3, :3], y_up @ data.xmat[model.body("ball").id].reshape(3, 3), atol=1e-6
    )


def test_an_export_is_deterministic(model_data):
    """The same model gives the same bytes (pages may cache by content)."""
    model, _ = model_data
    assert export_glb(model).glb == export_glb(model).glb


@pytest.mark.parametrize(
    ("model", "kwargs", "match"),
    [
        ("scene.xml", {}, "model must be a mujoco.MjModel; received str"),
        (None, {"groups": ()}, "groups must be a non-empty tuple of geom groups 0-5"),
        (None, {"groups": [0, 1]}, "non-empty tuple.*received \\[0, 1\\]"),
        (None, {"groups": (7,)}, "geom groups 0-5; received \\(7,\\)"),
    ],
)
def test_bad_input_is_refused(model_data, model, kwargs, match):
    """Wrong model types and groups are refused with what is valid."""
    with pytest.raises(InvalidExport, match=match):
        export_glb(model if model is not None else model_data[0], **kwargs)


def test_unnamed_bodies_and_reserved_names_go_by_their_id():
    """A body without a name, or named like the glb's root nodes, is the node ``body<id>``."""
    model = mujoco.MjModel.from_xml_string(
        """<mujoco><worldbody>
        <body pos="0 0 1"><geom type="sphere" size="0.1"/></body>
        <body name="y_up"><geom type="sphere" size="0.1"/></body>
        </worldbody></mujoco>"""
    )
    export = export_glb(model)
    assert export.body_names == ("body1", "body2")
    scene = trimesh.load(io.BytesIO(export.glb), file_type="glb")
    assert {"body1", "body2", "y_up"} <= set(scene.graph.nodes)
