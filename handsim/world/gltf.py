"""A MuJoCo model's visible geoms as a binary glTF (``.glb``), one node per body.

What a viewer outside MuJoCo needs to draw a scene (the teleop page draws it with three.js): the
meshes of every body, in the body's frame, under a node named after the body, so that a stream
of body poses (:func:`body_poses`) moves them. The geoms drawn are those MuJoCo's viewer shows by
default (groups 0-2: the table, the hand's skin pieces, objects' visual meshes, buttons); a body
with no such geom is drawn from its other geoms (e.g. an imported object with collision pieces
only). Primitives are tessellated by trimesh, meshes keep MuJoCo's vertices.

Frames: the glb's node ``y_up`` (under the root ``scene``) turns MuJoCo's +z-up world into
glTF's +y-up, (x, y, z) -> (x, z, -y); body nodes are children of ``y_up`` with MuJoCo-frame
poses, so a pose from :func:`body_poses` is applied to a node as it is.
"""

from __future__ import annotations

import dataclasses
import io

import mujoco
import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from handsim.errors import HandSimError

__all__ = ["InvalidExport", "SceneGlb", "export_glb", "body_poses", "DEFAULT_GROUPS"]

DEFAULT_GROUPS: tuple[int, ...] = (0, 1, 2)
"""Geom groups drawn (MuJoCo's viewer shows 0-2 by default; handsim's collision geoms are 3)."""
_PLANE_HALF_M = 5.0  # an infinite plane (size 0) is drawn as a 10 m square
_SPHERE_SUBDIVISIONS = 2
_SECTIONS = 16  # segments around capsules and cylinders


class InvalidExport(HandSimError, ValueError):
    """A glTF export was asked for something it cannot do (no model, bad groups)."""


@dataclasses.dataclass(frozen=True)
class SceneGlb:
    """An exported scene.

    Attributes:
        glb: the binary glTF 2.0 file.
        body_ids: MuJoCo ids of the exported bodies, in the order of :func:`body_poses` rows.
        body_names: their names (the glTF node names; ``body<id>`` for unnamed bodies and
            for bodies named ``scene`` or ``y_up``, the glb's own nodes).
    """

    glb: bytes
    body_ids: tuple[int, ...]
    body_names: tuple[str, ...]


def _geom_mesh(model: mujoco.MjModel, g: int) -> trimesh.Trimesh | None:
    kind = int(model.geom_type[g])
    size = model.geom_size[g].astype(np.float64)
    gt = mujoco.mjtGeom
    if kind == gt.mjGEOM_SPHERE:
        return trimesh.creation.icosphere(_SPHERE_SUBDIVISIONS, radius=size[0])
    if kind == gt.mjGEOM_ELLIPSOID:
        mesh = trimesh.creation.icosphere(_SPHERE_SUBDIVISIONS, radius=1.0)
        mesh.apply_scale(size)
        return mesh
    if kind == gt.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(
            height=2 * size[1], radius=size[0], count=[_SECTIONS, _SECTIONS // 2]
        )
    if kind == gt.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=_SECTIONS)
    if kind == gt.mjGEOM_BOX:
        return trimesh.creation.box(extents=2 * size)
    if kind == gt.mjGEOM_PLANE:
        half = [s if s > 0 else _PLANE_HALF_M for s in size[:2]]
        # A thin slab just below the plane, so its top face is the plane.
        mesh = trimesh.creation.box(extents=[2 * half[0], 2 * half[1], 1e-3])
        mesh.apply_translation([0.0, 0.0, -5e-4])
        return mesh
    if kind == gt.mjGEOM_MESH:
        m = int(model.geom_dataid[g])
        v0, nv = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
        f0, nf = int(model.mesh_faceadr[m]), int(model.mesh_facenum[m])
        return trimesh.Trimesh(
            model.mesh_vert[v0 : v0 + nv].astype(np.float64),
            model.mesh_face[f0 : f0 + nf].astype(np.int64),
            process=False,
        )
    return None  # height fields, SDFs, lines: not drawn


def _rgba(model: mujoco.MjModel, g: int) -> np.ndarray:
    mat = int(model.geom_matid[g])
    return (model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[g]).astype(np.float64)


def _transform(pos: np.ndarray, quat_wxyz: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    w, x, y, z = np.asarray(quat_wxyz, dtype=np.float64)
    T[:3, :3] = Rotation.from_quat([x, y, z, w]).as_matrix()
    T[:3, 3] = pos
    return T


_RESERVED_NODES = ("scene", "y_up")


def _body_name(model: mujoco.MjModel, b: int) -> str:
    name = model.body(b).name
    # Unnamed bodies, and bodies named like the glb's own root nodes, go by their id.
    return f"body{b}" if not name or name in _RESERVED_NODES else name


def export_glb(
    model: mujoco.MjModel,
    data: mujoco.MjData | None = None,
    *,
    groups: tuple[int, ...] = DEFAULT_GROUPS,
) -> SceneGlb:
    """Export the visible geoms of ``model`` as a binary glTF, one node per body.

    Args:
        model: the compiled model.
        data: if given, the body nodes start at its poses (``xpos``, ``xquat``); else at the
            identity (a viewer then waits for the first :func:`body_poses`).
        groups: geom groups drawn; a body without a geom in them is drawn from its other
            geoms. Geoms with alpha 0 are never drawn.

    Returns:
        The glb bytes and the exported bodies (those with at least one drawn geom).

    Raises:
        InvalidExport: ``model`` is not an ``MjModel``, or ``groups`` is not a tuple of
            ints in 0-5.
    """
    if not isinstance(model, mujoco.MjModel):
        raise InvalidExport(f"model must be a mujoco.MjModel; received {type(model).__name__}")
    if (
        not isinstance(groups, tuple)
        or not groups
        or not all(isinstance(k, int) and not isinstance(k, bool) and 0 <= k <= 5 for k in groups)
    ):
        raise InvalidExport(
            f"groups must be a non-empty tuple of geom groups 0-5; received {groups!r}"
        )
    scene = trimesh.Scene(base_frame="scene")
    # glTF is +y up: the root turns MuJoCo's +z up into it.
    y_up = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=np.float64)
    scene.graph.update(frame_from="scene", frame_to="y_up", matrix=y_up)
    body_ids: list[int] = []
    visible = model.geom_rgba[:, 3] > 0
    for b in range(model.nbody):
        geoms = np.flatnonzero((model.geom_bodyid == b) & visible)
        drawn = [g for g in geoms if int(model.geom_group[g]) in groups]
        if not drawn:
            drawn = list(geoms) if b != 0 else []
        meshes = []
        for g in drawn:
            mesh = _geom_mesh(model, int(g))
            if mesh is None or len(mesh.faces) == 0:
                continue
            rgba = _rgba(model, int(g))
            mesh.visual = trimesh.visual.TextureVisuals(
                material=trimesh.visual.material.PBRMaterial(
                    baseColorFactor=rgba,
                    metallicFactor=0.0,
                    roughnessFactor=0.8,
                    alphaMode="BLEND" if rgba[3] < 1 else "OPAQUE",
                    doubleSided=False,
                )
            )
            meshes.append((int(g), mesh))
        if not meshes:
            continue
        name = _body_name(model, b)
        body_ids.append(b)
        pose = (
            _transform(data.xpos[b], data.xquat[b])
            if data is not None
            else _transform(np.zeros(3), np.array([1.0, 0, 0, 0]))
        )
        scene.graph.update(frame_from="y_up", frame_to=name, matrix=pose)
        for g, mesh in meshes:
            gname = model.geom(g).name or f"geom{g}"
            scene.add_geometry(
                mesh,
                node_name=f"{name}/{gname}",
                geom_name=gname,
                parent_node_name=name,
                transform=_transform(model.geom_pos[g], model.geom_quat[g]),
            )
    buffer = io.BytesIO()
    buffer.write(scene.export(file_type="glb", include_normals=True))
    return SceneGlb(
        buffer.getvalue(),
        tuple(body_ids),
        tuple(_body_name(model, b) for b in body_ids),
    )


def body_poses(data: mujoco.MjData, body_ids: tuple[int, ...] | np.ndarray) -> np.ndarray:
    """World poses of bodies, for the nodes of :func:`export_glb`.

    Args:
        data: the simulation state (after ``mj_forward`` or a step).
        body_ids: (N,) body ids (e.g. :attr:`SceneGlb.body_ids`).

    Returns:
        (N, 7) float64: ``[x, y, z, qw, qx, qy, qz]`` per body, MuJoCo world frame, metres.
    """
    ids = np.asarray(body_ids, dtype=np.int64)
    return np.concatenate([data.xpos[ids], data.xquat[ids]], axis=1)
