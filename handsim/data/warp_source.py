"""The kinematic source rendered N frames at a time on MuJoCo Warp (``backend="warp"``).

:class:`WarpKinematicSource` makes the frames of :class:`~handsim.data.kinematic.KinematicSource`
for a hand alone (the ``hand-only`` presets: no objects, no table, no backdrop), but renders
them in batches of ``batch`` worlds with :class:`~handsim.world.warp_render.WarpDepthRenderer`
instead of one at a time with OpenGL.

Draws. A frame's draws cannot wait for the previous frame's render (which decides whether it is
kept) when frames are rendered together, so every *candidate* frame ``k`` of an episode draws
its view, hand rotation, camera distance and sensor noise from its own generator,
``default_rng([episode seed, k])``; the episode's scene (hand length, side), pose source, its
postures (candidate ``k`` takes posture ``k``; the ones past the first ``frames + 8`` draw their
own) and the episode seed are drawn from the shard's generator as the OpenGL path draws them.
Candidates are accepted in order, so a shard is a function of ``(seed, index)`` alone and the
same whatever the batch size or device; it is not the OpenGL backend's shard.

Labels. On the device, batched over the launch's worlds: each pixel's geom id, the camera's
working range and the segmentation label (:func:`render_labels`). Each image then goes
through the OpenGL path's own labelling
(:meth:`~handsim.frame.renderer.FrameRenderer.render` with the image handed in instead of
drawn), on the host: keypoint projection, visibility and occluder, sensor noise. A hand alone
has no objects, so no object silhouettes and no hand occlusion ratio (0) are needed: the
second render without occluders the OpenGL path makes for them does
not arise here. What would move to the device next: the noise models and the keypoint
visibility kernel (per-pixel, per-world).

Geometry per world. The upper arm is turned per frame toward a shoulder placed from the eye
(:func:`~handsim.data.kinematic.alone_shoulder_m`): the host computes every geom's pose and the
arm's length, and the renderer takes them per world. The hand's length changes per episode
(its skin's vertices): the device model is made once per scene and the skin's vertices are
copied to it and their BVH refitted per episode, so a batch never spans two episodes: a launch
holds at most ``frames_per_episode`` worlds (a larger ``batch`` is capped there) and draws no
more candidates than the episode still needs.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Iterator

import mujoco
import numpy as np

from handsim.data.config import (
    MAX_TRIES_PER_FRAME,
    CannotDraw,
    GenerationConfig,
    InvalidGenerationConfig,
    make_source,
)
from handsim.data.kinematic import (
    KinematicSource,
    accepted_arrays,
    alone_shoulder_m,
    beyond_near,
    near_geoms,
)
from handsim.frame import FrameRenderer
from handsim.hand.pose import HandPose
from handsim.world.sensors import NoNoise

__all__ = [
    "WarpKinematicSource",
    "check_warp_config",
    "batched",
    "make_warp_source",
    "DEFAULT_BATCH",
    "WARP_SOURCES",
    "render_labels",
]

DEFAULT_BATCH = 16
"""Candidate frames rendered per launch by default."""


WARP_SOURCES = ("kinematic", "grasp")
"""Frame sources the warp backend renders (the posed hands of the kinematic source and the
grasp source's grasps); the rollout source renders inside its env."""


def check_warp_config(config: GenerationConfig) -> None:
    """Refuse what the warp backend cannot make, naming the options.

    Raises:
        InvalidGenerationConfig: for a source not in :data:`WARP_SOURCES`.
    """
    if config.source not in WARP_SOURCES:
        raise InvalidGenerationConfig(
            f"the warp backend renders the sources {', '.join(map(repr, WARP_SOURCES))}; it "
            f"cannot do: source {config.source!r}. Use backend 'opengl' for it"
        )


def batched(config: GenerationConfig) -> bool:
    """Whether the warp backend renders the config's frames in batches.

    A hand alone (the kinematic source without objects or backdrop, the ``hand-only``
    presets) is rendered ``batch`` candidate frames per launch (:class:`WarpKinematicSource`);
    everything else (objects, a backdrop, the grasp source) one frame at a time, by the
    OpenGL path's own source and labels with the depth renderer on Warp
    (:class:`~handsim.world.warp_render.WarpSceneRenderer`).
    """
    return (
        config.source == "kinematic"
        and tuple(config.num_objects_range) == (0, 0)
        and config.background == "none"
    )


def make_warp_source(
    config: GenerationConfig, device: str | None = None, batch: int = DEFAULT_BATCH
) -> object:
    """The frame source of one shard on the warp backend (:func:`batched`).

    Args:
        config: the generation config (``backend="warp"``).
        device: Warp device (``"cpu"``, ``"cuda"``, ``"cuda:N"``; default: Warp's).
        batch: candidate frames per launch of a hand alone; the other configs render one
            frame per launch.
    """
    check_warp_config(config)
    if batched(config):
        return WarpKinematicSource(config, device=device, batch=batch)
    source = make_source(config)
    source.warp_device = device
    return source


class _Prerendered:
    """Stands in for a :class:`DepthRenderer` and hands out an image rendered elsewhere.

    ``image`` is ``(depth_m, labels)``: the segmentation labels already mapped on the device
    (:func:`render_labels`), which are the values the frame renderer asks for.
    """

    def __init__(self, renderer: object) -> None:
        self.real = renderer
        self.camera_id = renderer.camera_id
        self.image: tuple[np.ndarray, np.ndarray] | None = None

    def scale_geoms(self, *args: object) -> None:
        """The device model follows the rescaled hand (its skin refitted per episode)."""

    def render(
        self,
        data: mujoco.MjData,
        *,
        out: tuple[np.ndarray, np.ndarray],
        geom_values: np.ndarray,
        fill: int,
        depth_range_m: tuple[float, float],
    ) -> tuple[np.ndarray, np.ndarray]:
        depth_m, labels = self.image
        out[0][...] = depth_m
        out[1][...] = labels
        return out

    def close(self) -> None:
        self.real.close()


def render_labels(
    scene: object,
    warp: object,
    candidates: list[_Candidate],
    timings_s: dict[str, float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Render candidates' states in one launch: depth and segmentation labels.

    The segmentation labels (:data:`~handsim.world.scene.SEGMENT_LABELS`, 0 on background and
    outside the camera's working range) are mapped from geom ids on the device, as the frame
    renderer asks the OpenGL renderer for them.

    Returns:
        ``(depth_m, labels)``: (N, H, W) float32 metres and (N, H, W) int16 labels.
    """
    return warp.render(
        [c.data for c in candidates],
        depth_range_m=warp.intrinsics.range_m,
        host_geom_poses=True,
        geom_size=np.stack([c.geom_size for c in candidates]),
        timings_s=timings_s,
        geom_values=scene.geom_labels.astype(np.int16),
        fill=0,
    )


class _TimedSensor:
    """A sensor model whose ``apply`` adds its seconds to ``noise`` (and ``_noise``)."""

    def __init__(self, sensor: object, timings: dict[str, float]) -> None:
        self.sensor, self.timings = sensor, timings

    def apply(self, depth_m: np.ndarray, intrinsics: object, rng: np.random.Generator):  # noqa: ANN201
        start = time.perf_counter()
        out = self.sensor.apply(depth_m, intrinsics, rng)
        spent = time.perf_counter() - start
        for key in ("noise", "_noise"):
            self.timings[key] = self.timings.get(key, 0.0) + spent
        return out


class _Candidate:
    """One drawn frame: its generator, view, and the scene's state (data, geom sizes)."""

    def __init__(self, rng, view, data, geom_size):  # noqa: ANN001
        self.rng, self.view, self.data, self.geom_size = rng, view, data, geom_size


class WarpKinematicSource(KinematicSource):
    """The kinematic source for a hand alone, rendered ``batch`` frames per Warp launch.

    Args:
        config: the generation config, a hand alone (:func:`batched`).
        device: Warp device (``"cpu"``, ``"cuda"``, ``"cuda:N"``; default: Warp's).
        batch: candidate frames rendered per launch, >= 1; capped at the config's
            ``frames_per_episode`` (:attr:`worlds`), since a launch never spans two episodes.

    Raises:
        InvalidGenerationConfig: for a config that is not a hand alone, or a bad ``batch``.
    """

    def __init__(
        self, config: GenerationConfig, device: str | None = None, batch: int = DEFAULT_BATCH
    ) -> None:
        if not batched(config):
            raise InvalidGenerationConfig(
                "WarpKinematicSource renders a hand alone: source 'kinematic', "
                "num_objects_range (0, 0), background 'none'; received source "
                f"{config.source!r}, num_objects_range {tuple(config.num_objects_range)}, "
                f"background {config.background!r} (make_warp_source renders these one "
                "frame at a time)"
            )
        if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or batch < 1:
            raise InvalidGenerationConfig(f"batch must be an integer >= 1; received {batch!r}")
        super().__init__(config)
        self.device, self.batch = device, int(batch)
        # A launch never spans two episodes (each has its own hand length, so its own skin
        # on the device): worlds past an episode's frames would be drawn and never used.
        self.worlds = min(self.batch, config.frames_per_episode)
        # A device model per kept scene (a hand alone: one per side), so that episodes that
        # alternate sides do not rebuild it: id(scene) -> [scene, hand geometry version, renderer].
        self._warps: dict[int, list] = {}

    timings_s: dict[str, float] | None = None
    """Set to a dict (on the class, for benchmarks) to add each stage's seconds to it.

    ``device_model`` (a new one per scene, the skin refitted per episode), ``draws`` (pose,
    view, camera and host kinematics), the renderer's stages, ``labels``, ``noise``. The
    device is synchronized between stages then.
    """

    def _frame_renderer(self, scene: object) -> object:
        """The OpenGL path's frame renderer: its labels, with the images rendered here."""
        return FrameRenderer(scene, "camera", self.sensor)

    def _warp_renderer(self, scene: object) -> object:
        """The scene's device model: made once per scene, its skin refitted per hand length."""
        from handsim.world.warp_render import WarpDepthRenderer

        start = time.perf_counter()
        version = scene.hand_geometry_version
        kept = self._warps.get(id(scene))
        if kept is None or kept[0] is not scene:
            # Only the kept scenes' models stay (an id can be reused by a later scene).
            scenes = {id(s) for s, _ in self._scenes.values()}
            self._warps = {k: v for k, v in self._warps.items() if k in scenes}
            renderer = WarpDepthRenderer(
                scene.model, "camera", self.intrinsics, self.worlds, device=self.device
            )
            kept = self._warps[id(scene)] = [scene, version, renderer]
        elif kept[1] != version:
            # A new hand length (Scene.set_hand_length): its skin's vertices on the device.
            kept[2].refresh_meshes(scene.hand_mesh_ids)
            kept[1] = version
        if self.timings_s is not None:
            spent = time.perf_counter() - start
            self.timings_s["device_model"] = self.timings_s.get("device_model", 0.0) + spent
        return kept[2]

    def close(self) -> None:
        """Free the device models and the kept scenes."""
        self._warps = {}
        super().close()

    def _candidate(
        self, scene, seed: int, k: int, postures: np.ndarray, source: str
    ) -> _Candidate | None:  # noqa: ANN001
        """Draw candidate ``k`` and pose the scene for it; None when the camera cannot see."""
        rng = np.random.default_rng([seed, k])
        viewpoints = self.config.viewpoints
        view = viewpoints[int(rng.integers(len(viewpoints)))]
        is_left = scene.spec.hand.side == "left"
        wrist, rotvec, palm, eye, quat = self._hand_alone(rng, view, is_left)
        # Past the episode's postures, a candidate draws its own (two: a motion needs length).
        posture = postures[k] if k < len(postures) else self._postures(rng, source, 2)[0]
        scene.binding.set_pose(scene.data, HandPose(wrist, rotvec, posture), kinematics_only=True)
        eye = beyond_near(scene, near_geoms(scene), eye, palm, self._near_m)
        if eye is None:
            return None
        scene.binding.point_upper_arm(scene.data, alone_shoulder_m(view, is_left, eye))
        cam = scene.model.camera("camera").id
        scene.model.cam_pos[cam], scene.model.cam_quat[cam] = eye, quat
        mujoco.mj_camlight(scene.model, scene.data)
        return _Candidate(rng, view, copy.copy(scene.data), scene.model.geom_size.copy())

    def label(
        self, scene, renderer, candidate: _Candidate, image: tuple[np.ndarray, np.ndarray]
    ) -> object:  # noqa: ANN001
        """The :class:`~handsim.frame.record.Frame` of a candidate from its image.

        ``image``: ``(depth_m, labels)`` of :func:`render_labels`.
        """
        real, sensor = renderer.renderer, renderer.sensor
        stand_in = _Prerendered(real)
        stand_in.image = image
        saved = scene.data
        renderer.renderer, scene.data = stand_in, candidate.data
        timings = self.timings_s
        if timings is not None and type(sensor) is not NoNoise:
            renderer.sensor = _TimedSensor(sensor, timings)
        start = time.perf_counter()
        try:
            return renderer.render(candidate.rng, keep_clean=self.config.paired_clean)
        finally:
            renderer.renderer, renderer.sensor, scene.data = real, sensor, saved
            if timings is not None:
                spent = time.perf_counter() - start - timings.pop("_noise", 0.0)
                timings["labels"] = timings.get("labels", 0.0) + spent

    def episode(
        self, rng: np.random.Generator, accept: Callable[[float, int], bool], frames: int
    ) -> Iterator[dict[str, np.ndarray]]:
        """Yield the arrays of ``frames`` accepted frames of one episode (module docstring).

        Raises:
            CannotDraw: ``"frame"`` when :data:`MAX_TRIES_PER_FRAME` candidates in a row give
                no accepted frame.
        """
        scene, renderer = self._scene(rng)
        source = str(rng.choice(self.config.pose_sources))
        postures = self._postures(rng, source, frames + 8)
        seed = int(rng.integers(2**63))
        warp = self._warp_renderer(scene)
        k, done, tries = 0, 0, 0
        while True:
            start = time.perf_counter()
            # No more candidates than the frames still wanted: each is drawn from its own
            # generator and kept in order, so the frames do not depend on how many are drawn.
            candidates = []
            for _ in range(min(self.worlds, frames - done)):
                candidates.append(self._candidate(scene, seed, k, postures, source))
                k += 1
            if self.timings_s is not None:
                self.timings_s["draws"] = (
                    self.timings_s.get("draws", 0.0) + time.perf_counter() - start
                )
            drawn = [c for c in candidates if c is not None]
            if drawn:
                # Worlds past the drawn ones repeat the last (their images are not used).
                worlds = drawn + [drawn[-1]] * (self.worlds - len(drawn))
                depth_m, labels = render_labels(scene, warp, worlds, self.timings_s)
            i = 0
            for candidate in candidates:
                arrays = None
                if candidate is not None:
                    frame = self.label(scene, renderer, candidate, (depth_m[i], labels[i]))
                    i += 1
                    arrays = accepted_arrays(frame, accept, source, candidate.view)
                if arrays is None:
                    tries += 1
                    if tries >= MAX_TRIES_PER_FRAME:
                        raise CannotDraw(
                            "frame",
                            f"{MAX_TRIES_PER_FRAME} draws of pose and view gave no accepted frame",
                        )
                    continue
                yield arrays
                done, tries = done + 1, 0
                if done == frames:
                    return
