"""The FrameRenderer: it renders a scene's camera into labelled Frames, by the rules below.

:class:`FrameRenderer` is bound to one :class:`~handsim.world.Scene` and one of its cameras; it
keeps one :class:`~handsim.world.render.DepthRenderer` and renders
:class:`~handsim.frame.record.Frame` records.

Depth range: the camera's working range ``intrinsics.range_m = (near, far)`` bounds what is
seen. The render's far clip plane is ``far``; surfaces nearer than ``near`` are dropped from the
clean render (depth 0, segmentation background), as a real sensor returns nothing there.

Keypoint visibility rule (tolerance :data:`VISIBILITY_TOLERANCE_M`): a keypoint is a point
*inside* the hand (a joint centre, or the end of a fingertip's skin), so the surface the camera
sees at its pixel is normally its own skin, up to one skin radius ``r`` in front of it (``r``:
the largest collision radius of the segments meeting at the keypoint; the palm's half thickness
at the wrist and MCPs). A keypoint is **visible** only when the rendered surface confirms it: it
is in front of the camera and inside the image, and the *clean* render shows one of its own hand
parts (the part of the segment it belongs to, or of the segment it joins, e.g. palm or finger at
an MCP) at a depth within ``r + tolerance`` of the keypoint's depth ``z``, at its rounded pixel,
or, when that pixel has no nearer surface (the keypoint on its silhouette's edge), at one of the
8 pixels around it. A pixel without depth (outside the camera's range, background) is never
evidence of visibility. Visibility is decided on the clean render, so sensor dropouts and noise
do not change it. A keypoint that is not visible has as occluder what the camera sees at its
pixel when that surface is nearer than ``z - (r + tolerance)``: a hand part (its own digit
folded in front included, or the person's other hand) ->
:data:`~handsim.frame.record.OCCLUDER_SELF`; an object instance ``k`` -> ``k``; the table ->
:data:`~handsim.frame.record.OCCLUDER_SCENE`. With nothing in front (out of range, or its surface
not rendered) the occluder is :data:`~handsim.frame.record.OCCLUDER_NONE`.

What the sensor returned: ``visible_sensor`` is ``visible`` judged on the noisy image too. A
visible keypoint is seen by the sensor when, at a pixel that makes it visible (its own pixel,
or else a confirming neighbour), the sensor returned a depth (not a dropout, shadow or
out-of-range pixel) within :data:`SENSOR_AGREEMENT_M` of the clean depth. Without a noise model
it equals ``visible``.

Keypoints behind the camera (``z <= 0``) have NaN pixels (``keypoints_px``) and are neither in
frame nor visible.

Objects: ``T_cam_from_obj`` (4 x 4, OpenCV camera frame), box corners in the camera frame, and
``visib_fract`` as BOP defines it (bop_toolkit's ``calc_gt_info``): ``px_count_visib /
px_count_all``, where ``px_count_all`` counts the object's whole silhouette, rendered with
nothing else in the scene on a canvas that extends the image by its own size on every side (so
an object cut by the image's border counts its part outside the image too), and
``px_count_visib`` the pixels where the full render sees the object. An object whose projected
box misses the image gets 0 for both. Unoccluded objects inside the image need no extra render
(see ``FrameRenderer._silhouettes``); the others share one silhouette render when their
projected boxes do not overlap. A silhouette
is reused while the object has moved by at most ``silhouette_tolerance_px`` in the image
(:data:`SILHOUETTE_TOLERANCE_PX`, 0.1 pixel) since it was made: objects resting in clutter, which
jitter by tens of micrometres a step, then cost no render, and the counts differ from a fresh
render at most by the mask's boundary pixels whose centres the edge crossed (exact counts:
``silhouette_tolerance_px=0``).

Hand occlusion ratio: ``1 - visible hand pixels / hand pixels with every object hidden``
(and, in a two-hand scene, the other hand), counting the hand proper, from the wrist crease
to the fingertips: the forearm's pixels (the palm's skin proximal of the wrist crease plane,
the palm frame's ``y = 0``) are left out, so a hidden hand scores 1 however much of its
forearm is in view. It needs one more render and is computed on request.

Contacts: every MuJoCo contact between a hand geom and an object geom, as (hand part label,
object instance, position in the camera frame, normal force in newtons).

Skin level of detail (``skin_detail``): a scene built with :attr:`SceneSpec.skin_lod
<handsim.world.scene.SceneSpec.skin_lod>` holds the skin twice, in full and at
a quarter of the triangles (:data:`handsim.hand.skin.SKIN_DETAILS`), on the same bodies, so
both pose alike. With ``"auto"`` (the renderer's default; a scene without the coarse skin
always draws the full one) a frame draws the coarse skin when its largest
deviation from the skin's surface (:func:`~handsim.hand.skin.skin_deviation_m`, 1.2 mm on a
medium hand) projects to less than :data:`LOD_TOLERANCE_PX` (one pixel) at the hand's nearest
point, i.e. for small projected hands, where the full skin's triangles are smaller than a
pixel and its vertex work buys no detail; ``"full"`` always draws the full skin. Keypoints
come from the kinematics, so their positions and pixels do not depend on the level; depth,
segmentation and what is decided on them (visibility, pixel counts) do, by at most the
deviation.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import mujoco
import numpy as np

from handsim.errors import UnknownName
from handsim.frame.record import (
    OCCLUDER_NONE,
    OCCLUDER_SCENE,
    OCCLUDER_SELF,
    Contact,
    Frame,
    ObjectLabel,
    _owned_read_only,
    _read_only,
)

# The object silhouettes' machinery (BOP visib_fract); its names stay importable from here.
from handsim.frame.silhouettes import (  # noqa: F401
    _HIDDEN_GROUP,
    _KERNEL_3X3,
    _OCCLUSION_MARGIN_M,
    _PALM_LABEL,
    _Mask,
    _ObjectSilhouettes,
    _pixel_box,
)
from handsim.world.camera import T_cam_from_world
from handsim.world.render import DepthRenderer
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    SKIN_LOD_GROUP,
    InvalidScene,
    Scene,
)
from handsim.world.sensors import InvalidSensor, NoNoise, SensorModel

__all__ = [
    "FrameRenderer",
    "VISIBILITY_TOLERANCE_M",
    "SENSOR_AGREEMENT_M",
    "SILHOUETTE_TOLERANCE_PX",
    "SKIN_DETAIL_CHOICES",
    "LOD_TOLERANCE_PX",
]

VISIBILITY_TOLERANCE_M = 0.005
"""Allowance beyond the skin radius for a surface in front of a keypoint, metres."""
SENSOR_AGREEMENT_M = 0.01
"""Largest difference between the sensor's and the clean depth at a keypoint's pixel for the
sensor to have seen the keypoint, metres: about 3 sigma of the built-in sensors' axial noise at
1.5 m (time of flight 3 mm; structured light 3.5 mm, Nguyen 2012), and less than a finger's
thickness, so a pixel that took the background's or a blended depth does not count."""

SILHOUETTE_TOLERANCE_PX = 0.1
"""Default image motion, pixels, below which an object's silhouette is reused (see
:class:`FrameRenderer`): it bounds the reused mask's difference from a fresh render to pixels whose
centres lie within 0.1 pixel of the silhouette's edge."""

SKIN_DETAIL_CHOICES: tuple[str, ...] = ("auto", "full", "coarse")
"""Values of ``FrameRenderer(skin_detail=...)``: the level of detail chosen per frame by the
hand's projected size, or always the full or the coarse skin."""
LOD_TOLERANCE_PX = 1.0
"""With ``skin_detail="auto"``, the coarse skin is drawn while its largest deviation from the
skin's surface projects to less than this, pixels, at the hand's nearest point."""

_VISUAL_GROUP = 2  # the hand's visual geoms (cameras draw it; not SKIN_LOD_GROUP)
# The person's own arm hiding a keypoint is self-occlusion, as the palm's forearm stub is.
_SELF_LABEL = SEGMENT_LABELS.index("arm")


def _keypoint_radii(scene: Scene) -> np.ndarray:
    """Largest collision radius of the segments that meet at each keypoint, metres."""
    skeleton = scene.hand.skeleton
    radius_of_body = []
    for body in skeleton.bodies:
        radii = [g.radius for g in body.geoms if hasattr(g, "radius")]
        if body.part == "palm":
            # Half the palm thickness (the box's z half size).
            radii = [g.half_size[2] for g in body.geoms if hasattr(g, "half_size")]
        radius_of_body.append(max(radii))
    parents = [b.parent for b in skeleton.bodies]
    radii = []
    for body_index, _ in skeleton.keypoints:
        r = radius_of_body[body_index]
        if parents[body_index] >= 0:
            r = max(r, radius_of_body[parents[body_index]])
        radii.append(r)
    return np.array(radii)


def _keypoint_parts(scene: Scene) -> np.ndarray:
    """(21, 2) segmentation labels a keypoint's own surface may carry (its body's, its parent's)."""
    skeleton = scene.hand.skeleton
    label = [SEGMENT_LABELS.index(b.part) for b in skeleton.bodies]
    parts = []
    for body_index, _ in skeleton.keypoints:
        parent = skeleton.bodies[body_index].parent
        parts.append((label[body_index], label[parent] if parent >= 0 else label[body_index]))
    return np.array(parts, dtype=np.int16)


# Offsets of a pixel and its 8 neighbours (the centre first).
_NEIGHBOURS = np.array([(0, 0)] + [(dv, du) for dv in (-1, 0, 1) for du in (-1, 0, 1) if dv or du])


class FrameRenderer(_ObjectSilhouettes):
    """Renders labelled frames of one scene from one camera.

    Args:
        scene: a scene with a hand.
        camera: name of one of the scene's cameras.
        sensor: depth noise model (default: none).
        silhouette_tolerance_px: image motion, pixels in [0, 0.5), up to which an object's
            silhouette is reused (module docstring); 0 re-renders whenever the object's pose
            relative to the camera changed at all.
        skin_detail: the skin's level of detail (:data:`SKIN_DETAIL_CHOICES`; module
            docstring): ``"auto"`` by the hand's projected size, ``"full"`` always the full
            skin, ``"coarse"`` always the coarse one. A scene without the coarse skin
            (``SceneSpec(skin_lod=False)`` or a capsule hand) always draws the full one.
        renderer: the depth and geom-id renderer to draw with, made for ``camera``'s
            intrinsics with :class:`~handsim.world.render.DepthRenderer`'s interface (e.g. a
            :class:`~handsim.world.warp_render.WarpSceneRenderer`); ``None``: an OpenGL
            :class:`~handsim.world.render.DepthRenderer`. The frame renderer closes it.

    Raises:
        InvalidScene: for an unknown camera or a bad ``silhouette_tolerance_px``.
        UnknownName: if the scene has no hand.
    """

    def __init__(
        self,
        scene: Scene,
        camera: str,
        sensor: SensorModel | None = None,
        *,
        silhouette_tolerance_px: float = SILHOUETTE_TOLERANCE_PX,
        skin_detail: str = "auto",
        renderer: DepthRenderer | None = None,
    ) -> None:
        if not isinstance(scene, Scene):
            raise InvalidScene(f"scene must be a Scene; received {type(scene).__name__}")
        if not isinstance(camera, str):
            raise UnknownName(f"camera must be a camera name (str); received {camera!r}")
        if sensor is not None and not callable(getattr(sensor, "apply", None)):
            raise InvalidSensor(
                f"sensor must be a sensor model with apply(depth_m, intrinsics, rng) (e.g. "
                f"sensor_model('tof')) or None; received {type(sensor).__name__}"
            )
        if scene.hand is None:
            raise UnknownName("a FrameRenderer needs a scene with a hand; SceneSpec(hand=None)")
        tolerance = silhouette_tolerance_px
        if (
            isinstance(tolerance, bool)
            or not isinstance(tolerance, (int, float, np.integer, np.floating))
            or not 0.0 <= tolerance < 0.5
        ):
            raise InvalidScene(
                f"silhouette_tolerance_px must be a number in [0, 0.5) pixels; received "
                f"{tolerance!r}"
            )
        self.silhouette_tolerance_px = float(tolerance)
        self.skin_detail = skin_detail
        self.last_skin_detail = "full"
        """The level of detail the last :meth:`render` drew (``"full"`` or ``"coarse"``)."""
        self.scene = scene
        self.camera_spec = scene.camera(camera)
        self.intrinsics = self.camera_spec.intrinsics
        self.sensor = sensor if sensor is not None else NoNoise()
        self.renderer = (
            renderer
            if renderer is not None
            else DepthRenderer(scene.model, camera, self.intrinsics)
        )
        self._hand_version = scene.hand_geometry_version
        self._uploaded_hand_length_m = scene.hand.params.hand_length
        self._kp_radius = _keypoint_radii(scene)
        self._kp_parts = _keypoint_parts(scene)
        self._near_m = np.float32(self.intrinsics.range_m[0])
        self._far_m = np.float32(self.intrinsics.range_m[1])
        model = scene.model
        self._object_geoms = [
            np.nonzero(scene.geom_labels == OBJECT_LABEL_OFFSET + k)[0]
            for k in range(len(scene.objects))
        ]
        self._object_bodies = np.array(
            [model.body(body).id for body, _ in scene.objects], dtype=np.intp
        )
        # (n, 8, 3) box corners of each object in its body frame, metres.
        self._object_corners = np.array([obj.corners_m for _, obj in scene.objects]).reshape(
            -1, 8, 3
        )
        labels = scene.geom_labels
        self._is_hand_geom = (labels >= _PALM_LABEL) & (labels < OBJECT_LABEL_OFFSET)
        # geom id -> object instance (-1: not an object); geom id -1 (background) -> the last.
        # Labels past the objects' are a second hand's (Scene module docstring): no instance.
        self._object_end = OBJECT_LABEL_OFFSET + len(scene.objects)
        is_object = (labels >= OBJECT_LABEL_OFFSET) & (labels < self._object_end)
        self._other_hand_geoms = np.flatnonzero(labels >= self._object_end)
        instance = np.where(is_object, labels - OBJECT_LABEL_OFFSET, -1)
        self._geom_instance = np.append(instance, -1).astype(np.intp)
        self._geom_labels = labels.astype(np.int16)
        # Buffers reused by every frame (no image-sized allocation per frame but the Frame's).
        h, w = self.intrinsics.height, self.intrinsics.width
        self._depth_buffer = np.empty((h, w), dtype=np.float32)
        # Each object's silhouette and its box corners in the camera frame when it was made
        # (NaN: none yet); see _silhouettes.
        self._silhouette_masks: list[_Mask | None] = [None] * len(scene.objects)
        self._silhouette_corners = np.full((len(scene.objects), 8, 3), np.nan)
        self._K = _read_only(self.intrinsics.K)
        self._palm_body = int(model.body(scene.hand.root_body).id)
        self._hand_only_buffers: tuple[np.ndarray, np.ndarray] | None = None
        self._camera_key: bytes | None = None
        self._T_cam_from_world: np.ndarray | None = None
        self._lod = scene.skin_lod_geom_ids
        if self._lod is not None:
            from handsim.hand.skin import skin_deviation_m

            # That of the meshes built, per metre of hand length: a rescaled hand scales them.
            built = scene.built_hand_params
            self._lod_deviation_per_m = skin_deviation_m(built, "coarse") / built.hand_length
            full = self._lod[0]
            # (n, 8, 3) corners of the skin geoms' boxes in their geom frames.
            aabb = model.geom_aabb[full]
            signs = np.array([(i & 1, i >> 1 & 1, i >> 2 & 1) for i in range(8)]) * 2.0 - 1.0
            self._skin_box_corners = aabb[:, None, :3] + signs[None] * aabb[:, None, 3:]
            self._skin_box_scale_m = scene.hand.params.hand_length

    def close(self) -> None:
        """Free the renderer."""
        self.renderer.close()

    def __enter__(self) -> FrameRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _camera_pose(self, data: mujoco.MjData) -> np.ndarray:
        """``T_cam_from_world`` (read-only), recomputed only when the camera moved."""
        cam = self.renderer.camera_id
        key = data.cam_xpos[cam].tobytes() + data.cam_xmat[cam].tobytes()
        if key != self._camera_key:
            self._camera_key = key
            self._T_cam_from_world = _read_only(T_cam_from_world(data, cam))
        return self._T_cam_from_world

    def _visibility(
        self,
        depth_m: np.ndarray,
        labels: np.ndarray,
        z: np.ndarray,
        row: np.ndarray,
        col: np.ndarray,
        in_frame: np.ndarray,
        sensor_depth_m: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-keypoint ``visible``, ``occluder`` and ``visible_sensor`` (module docstring)."""
        # numba loads on the first frame, not on `import handsim`.
        from handsim.world import _kernels

        visible = np.zeros(21, dtype=bool)
        occluder = np.full(21, OCCLUDER_NONE, dtype=np.int32)
        visible_sensor = np.zeros(21, dtype=bool)
        _kernels.keypoint_visibility(
            depth_m, labels, z, row, col, in_frame, self._kp_radius + VISIBILITY_TOLERANCE_M,
            self._kp_parts, _NEIGHBOURS, OBJECT_LABEL_OFFSET, self._object_end, _SELF_LABEL,
            OCCLUDER_SELF,
            OCCLUDER_SCENE, sensor_depth_m, SENSOR_AGREEMENT_M, visible, occluder,
            visible_sensor,
        )  # fmt: skip
        return visible, occluder, visible_sensor

    def _hand_pixels(
        self,
        data: mujoco.MjData,
        labels: np.ndarray,
        depth_m: np.ndarray,
        R: np.ndarray,
        t: np.ndarray,
    ) -> int:  # noqa: N803
        """Pixels of the hand proper (wrist to fingertips) in a render: the forearm left out.

        The palm and the forearm are one skin mesh (one label), so a palm-labelled pixel is
        told apart by where its surface point lies: proximal of the wrist crease plane (the
        palm frame's ``y = 0``: +y is distal, the origin the wrist crease centre) it is
        forearm. Exact per pixel, and no change to the hand's geoms.
        """
        hand = (labels >= _PALM_LABEL) & (labels < OBJECT_LABEL_OFFSET)
        rows, cols = np.nonzero(labels == _PALM_LABEL)
        if not len(rows):
            return int(np.count_nonzero(hand))
        z = depth_m[rows, cols].astype(np.float64)
        intr = self.intrinsics
        points = np.stack(
            [(cols - intr.cx) / intr.fx * z, (rows - intr.cy) / intr.fy * z, z], axis=-1
        )
        palm = self._palm_body
        origin_cam = R @ data.xpos[palm] + t
        distal_cam = R @ data.xmat[palm].reshape(3, 3)[:, 1]
        forearm = (points - origin_cam) @ distal_cam < 0.0
        return int(np.count_nonzero(hand)) - int(np.count_nonzero(forearm))

    def _hand_occlusion_ratio(
        self,
        data: mujoco.MjData,
        labels: np.ndarray,
        depth_m: np.ndarray,
        R: np.ndarray,  # noqa: N803
        t: np.ndarray,
    ) -> float:
        """``1 - visible hand pixels / hand pixels with objects and other hand hidden``."""
        groups = self.scene.model.geom_group
        saved = groups.copy()
        for geoms in (*self._object_geoms, self._other_hand_geoms):
            groups[geoms] = _HIDDEN_GROUP
        if self._hand_only_buffers is None:
            self._hand_only_buffers = (np.empty_like(depth_m), np.empty_like(labels))
        try:
            # The same working range as the full render: a pixel out of range is in neither.
            depth_hand, labels_hand = self.renderer.render(
                data,
                out=self._hand_only_buffers,
                geom_values=self._geom_labels,
                fill=0,
                depth_range_m=(self._near_m, self._far_m),
            )
        finally:
            groups[:] = saved
        hand_px = self._hand_pixels(data, labels_hand, depth_hand, R, t)
        visible_px = self._hand_pixels(data, labels, depth_m, R, t)
        return 1.0 - visible_px / hand_px if hand_px else 0.0

    @property
    def skin_detail(self) -> str:
        """The skin's level of detail (:data:`SKIN_DETAIL_CHOICES`); may be set between frames.

        Raises:
            InvalidScene: when set to another value.
        """
        return self._skin_detail

    @skin_detail.setter
    def skin_detail(self, value: str) -> None:
        if not isinstance(value, str) or value not in SKIN_DETAIL_CHOICES:
            raise InvalidScene(
                f"skin_detail must be one of {', '.join(map(repr, SKIN_DETAIL_CHOICES))}; "
                f"received {value!r}"
            )
        self._skin_detail = value

    def _coarse_wanted(self, data: mujoco.MjData, R: np.ndarray, t: np.ndarray) -> bool:  # noqa: N803
        """Whether this frame draws the coarse skin (``skin_detail``, module docstring)."""
        if self._lod is None or self._skin_detail == "full":
            return False
        if self._skin_detail == "coarse":
            return True
        full = self._lod[0]
        hand_length_m = self.scene.hand.params.hand_length
        # The skin boxes' corners (rescaled with the hand) in the camera frame: the nearest.
        corners = self._skin_box_corners * (hand_length_m / self._skin_box_scale_m)
        rot = data.geom_xmat[full].reshape(-1, 3, 3)
        world = np.einsum("nij,nkj->nki", rot, corners) + data.geom_xpos[full][:, None]
        z_near_m = float(np.min(world.reshape(-1, 3) @ R[2] + t[2]))
        if z_near_m <= 0.0:
            return False  # part of the hand behind the camera: its size is unbounded
        focal_px = max(self.intrinsics.fx, self.intrinsics.fy)
        deviation_px = self._lod_deviation_per_m * hand_length_m * focal_px / z_near_m
        return deviation_px < LOD_TOLERANCE_PX

    def _swap_skin(self, coarse: bool) -> None:
        """Draw the coarse skin instead of the full one (``coarse``), or back."""
        full, lod = self._lod
        groups = self.scene.model.geom_group
        groups[full] = _HIDDEN_GROUP if coarse else _VISUAL_GROUP
        groups[lod] = _VISUAL_GROUP if coarse else SKIN_LOD_GROUP

    def _follow_hand_geometry(self) -> None:
        scene = self.scene
        if scene.hand_geometry_version != self._hand_version:  # Scene.set_hand_length
            # The skin is drawn scaled from the vertices uploaded: no upload per new length.
            self.renderer.scale_geoms(
                scene.hand_skin_geom_ids,
                scene.hand.params.hand_length / self._uploaded_hand_length_m,
            )
            self._kp_radius = _keypoint_radii(scene)
            self._hand_version = scene.hand_geometry_version

    @contextlib.contextmanager
    def skin_as_drawn(self) -> Iterator[str]:
        """Within the block, the model shows the skin's level of detail :meth:`render` draws.

        For the scene's current state (:attr:`skin_detail`): the coarse skin's geoms take the
        full skin's geom group (which is hidden), so any renderer of the same model, e.g.
        ``mujoco.Renderer`` for a reference render, draws what this one draws. The groups are
        restored when the block ends.

        Yields:
            The level drawn, ``"full"`` or ``"coarse"`` (also :attr:`last_skin_detail`).
        """
        self._follow_hand_geometry()
        data = self.scene.data
        T = self._camera_pose(data)  # noqa: N806
        coarse = self._coarse_wanted(data, T[:3, :3], T[:3, 3])
        self.last_skin_detail = "coarse" if coarse else "full"
        if coarse:
            self._swap_skin(True)
        try:
            yield self.last_skin_detail
        finally:
            if coarse:
                self._swap_skin(False)

    def render_images(self) -> tuple[np.ndarray, np.ndarray]:
        """The scene's current state drawn as :meth:`render` draws it, without any label work.

        The same level of detail (:attr:`skin_detail`) as :meth:`render`; no working range is
        applied (what :meth:`render` gives on every pixel within it).

        Returns:
            ``(depth_m, geom_id)``: (H, W) float32 clean depth along the optical axis, metres
            (0 where no geom is seen), and (H, W) int32 geom ids (-1 for background).
        """
        with self.skin_as_drawn():
            return self.renderer.render(self.scene.data)

    def render(
        self,
        rng: np.random.Generator,
        *,
        keep_clean: bool = False,
        hand_occlusion: bool = False,
    ) -> Frame:
        """Render the scene's current state and label it.

        Args:
            rng: random generator of the sensor noise.
            keep_clean: also return the noise-free depth.
            hand_occlusion: compute the hand occlusion ratio (one more render).

        Returns:
            The labelled frame.
        """
        scene, model, data = self.scene, self.scene.model, self.scene.data
        intr = self.intrinsics
        # The skin's level of detail for both draws of the hand (the frame and the hand alone).
        with self.skin_as_drawn():
            T = self._camera_pose(data)  # noqa: N806
            R, t = T[:3, :3], T[:3, 3]  # noqa: N806
            labels = np.empty(self._depth_buffer.shape, dtype=np.int16)  # the Frame's own array
            # The camera's working range: nothing is measured outside it (the far clip plane
            # of the scene may serve a camera with a longer range); those pixels get label 0.
            depth_clean, labels = self.renderer.render(
                data,
                out=(self._depth_buffer, labels),
                geom_values=self._geom_labels,
                fill=0,
                depth_range_m=(self._near_m, self._far_m),
            )
            occlusion_ratio = None
            if hand_occlusion:
                occlusion_ratio = self._hand_occlusion_ratio(data, labels, depth_clean, R, t)
        if type(self.sensor) is NoNoise:
            depth = depth_clean.copy()  # its apply() would also check the depth: two more passes
        else:
            depth = self.sensor.apply(depth_clean, intr, rng)
            if np.may_share_memory(depth, depth_clean):
                depth = depth.copy()  # a sensor model that returned its input

        # Keypoints.
        kp_world = scene.binding.keypoints(data)
        kp_cam = kp_world @ R.T + t
        z = kp_cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            kp_px = intr.project(np.where(z[:, None] > 0, kp_cam, np.nan))
        col = np.rint(kp_px[:, 0])
        row = np.rint(kp_px[:, 1])
        in_frame = (z > 0) & (col >= 0) & (col < intr.width) & (row >= 0) & (row < intr.height)
        visible, occluder, visible_sensor = self._visibility(
            depth_clean, labels, z, row, col, in_frame, depth
        )
        # Objects, all at once: (n, 4, 4) poses and (n, 8, 3) box corners in the camera frame.
        n = len(scene.objects)
        objects = []
        if n:  # a scene without objects skips the object work (its arrays would be empty)
            bodies = self._object_bodies
            T_cam_obj = np.zeros((n, 4, 4))  # noqa: N806
            T_cam_obj[:, :3, :3] = R @ data.xmat[bodies].reshape(n, 3, 3)
            T_cam_obj[:, :3, 3] = data.xpos[bodies] @ R.T + t
            T_cam_obj[:, 3, 3] = 1.0
            corners_cam = (
                np.einsum("nij,nkj->nki", T_cam_obj[:, :3, :3], self._object_corners)
                + T_cam_obj[:, None, :3, 3]
            )
            boxes = []
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = intr.project(corners_cam)  # (n, 8, 2)
            for k in range(n):
                if np.all(corners_cam[k, :, 2] > 1e-3):
                    boxes.append((uv[k].min(axis=0), uv[k].max(axis=0)))
                else:  # partly behind the camera: its image extent is unbounded
                    boxes.append((np.full(2, -np.inf), np.full(2, np.inf)))
            silhouettes = self._silhouettes(data, labels, depth_clean, corners_cam, boxes)
            for k, (_, obj) in enumerate(scene.objects):
                px_all = silhouettes[k].count()
                px_visib = silhouettes[k].count_where(labels, OBJECT_LABEL_OFFSET + k)
                objects.append(
                    ObjectLabel(
                        instance=k,
                        name=obj.name,
                        ycbv_id=obj.ycbv_id,
                        T_cam_from_obj=_owned_read_only(T_cam_obj[k].copy()),
                        corners_cam=_owned_read_only(corners_cam[k].copy()),
                        visib_fract=px_visib / px_all if px_all else 0.0,
                        px_count_all=px_all,
                        px_count_visib=px_visib,
                    )
                )

        contacts = []
        ncon = data.ncon
        if ncon and n:
            contact = data.contact
            pairs = contact.geom[:ncon]  # (ncon, 2) geom ids
            contact_pos = contact.pos
            hand_first = self._is_hand_geom[pairs[:, 0]] & (self._geom_instance[pairs[:, 1]] >= 0)
            hand_second = self._is_hand_geom[pairs[:, 1]] & (self._geom_instance[pairs[:, 0]] >= 0)
            force = np.zeros(6)
            for i in np.flatnonzero(hand_first | hand_second):
                pos_cam = R @ contact_pos[i] + t
                for hand_geom, other, hit in (
                    (pairs[i, 0], pairs[i, 1], hand_first[i]),
                    (pairs[i, 1], pairs[i, 0], hand_second[i]),
                ):
                    if hit:
                        mujoco.mj_contactForce(model, data, int(i), force)
                        contacts.append(
                            Contact(
                                hand_part=int(scene.geom_labels[hand_geom]),
                                instance=int(self._geom_instance[other]),
                                pos_cam=_owned_read_only(pos_cam.copy()),
                                normal_force_n=float(force[0]),
                            )
                        )

        hand = scene.hand.params
        return Frame(
            camera=self.camera_spec.name,
            K=self._K,
            T_cam_from_world=T,
            depth=_owned_read_only(depth),
            depth_clean=_read_only(depth_clean) if keep_clean else None,
            segmentation=_owned_read_only(labels),
            keypoints_cam=_read_only(kp_cam),
            keypoints_px=_read_only(kp_px),
            in_frame=_read_only(in_frame),
            visible=_read_only(visible),
            visible_sensor=_read_only(visible_sensor),
            occluder=_read_only(occluder),
            hand_pose=scene.binding.pose(data),
            hand_length_m=hand.hand_length,
            handedness=hand.side,
            objects=tuple(objects),
            hand_occlusion_ratio=occlusion_ratio,
            contacts=tuple(contacts),
        )
