"""The world around the hand: objects, scenes, cameras, rendering and depth-sensor models.

=======================  ==========================================================================
module                   holds
=======================  ==========================================================================
:mod:`.objects`          the object type (:class:`YCBObject`), :func:`add_object`
:mod:`.symmetry`         :class:`Symmetry`: an object's symmetries (BOP style)
:mod:`.ycbv`             the recipes of the 21 YCB-Video objects (facts, colours, symmetries)
:mod:`.ycbv_shapes`      the shapes of the 21 YCB-Video objects (meshes, collision pieces)
:mod:`.ycbv_vessels`     the open vessels among them: bowl, mug, pitcher base
:mod:`.meshing`          lofts, revolutions, signed distances, marching tetrahedra, decimation
:mod:`.registry`         :data:`OBJECTS` and :func:`get_object`
:mod:`.mesh_import`      :func:`load_object`: user meshes (OBJ/PLY/STL/GLB)
:mod:`.scene`            :class:`SceneSpec` (table, lights, hand, objects, cameras), :class:`Scene`
:mod:`.camera`           exact intrinsics of real sensors (OpenCV convention), camera placement
:mod:`.render`           the one-pass depth + segmentation renderer
:mod:`.sensors`          seeded depth noise: structured light, time of flight
:mod:`.mjcf`             MJCF out: full-precision XML of any ``MjSpec``, meshes as OBJ files
:mod:`.gltf`             glTF out: a model's visible geoms as a ``.glb``, one node per body
=======================  ==========================================================================
"""

from handsim.world.camera import CAMERA_PRESETS, CameraIntrinsics, camera_preset
from handsim.world.mesh_import import load_object
from handsim.world.objects import ObjectSpec, YCBObject, add_object
from handsim.world.registry import OBJECT_NAMES, OBJECTS, get_object
from handsim.world.render import DepthRenderer
from handsim.world.scene import (
    SEGMENT_LABELS,
    CameraSpec,
    ObjectPlacement,
    Scene,
    SceneSpec,
    egocentric_camera,
    sample_placements,
    sample_viewpoint,
    third_person_camera,
)
from handsim.world.sensors import StructuredLight, TimeOfFlight, sensor_model
from handsim.world.symmetry import NO_SYMMETRY, Symmetry

__all__ = [
    "CAMERA_PRESETS",
    "CameraIntrinsics",
    "camera_preset",
    "load_object",
    "NO_SYMMETRY",
    "ObjectSpec",
    "Symmetry",
    "YCBObject",
    "add_object",
    "OBJECT_NAMES",
    "OBJECTS",
    "get_object",
    "DepthRenderer",
    "SEGMENT_LABELS",
    "CameraSpec",
    "ObjectPlacement",
    "Scene",
    "SceneSpec",
    "egocentric_camera",
    "sample_placements",
    "sample_viewpoint",
    "third_person_camera",
    "StructuredLight",
    "TimeOfFlight",
    "sensor_model",
]
