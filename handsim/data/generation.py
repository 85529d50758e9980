"""Dataset generation: seeded, sharded, resumable, in parallel worker processes.

:func:`generate` writes labelled depth frames into a dataset folder: ``shard-NNNNN.h5`` files
(:mod:`handsim.data.shards`) and ``manifest.json`` (:mod:`handsim.data.manifest`). Frames come
from a *source*; the built-in ``"kinematic"`` source poses the hand without physics
(:class:`~handsim.data.kinematic.KinematicSource`). The ``"rollout"`` source
(:mod:`handsim.envs.rollouts`, found by name in :data:`SOURCES`) labels env episodes driven by
their experts, with physical contact.

Reproducibility: shard ``i`` is made from ``numpy.random.default_rng([seed, i])`` alone, so a
shard is the same whichever worker makes it and whenever; a rerun of the same command skips
the complete shards listed in the manifest, deletes partial files and writes the missing
shards identically. A run killed at any moment (even SIGKILL) loses only shards in progress.
Shards are made in this process, in worker processes (``workers``: forked where that is safe,
else spawned) or as Ray tasks (``ray``), one shard per task, with the same result. The shard
size is the config's (by default sized to the job:
:func:`~handsim.data.config.auto_frames_per_shard`), never the worker count's, so any number
of workers makes the same dataset.

Occlusion control: ``occlusion_range`` keeps frames whose hand occlusion ratio lies in the
range; ``occlusion_buckets`` fills buckets of the ratio to fractions of every shard;
``max_fraction_below_min_visible`` caps the frames of every shard with fewer than
``min_visible_keypoints`` visible keypoints. All redraw a frame until it is accepted (at most
:data:`MAX_TRIES_PER_FRAME` draws).

Redraws: an episode whose draws cannot be satisfied (objects that do not fit on the table, a
grasp that cannot be made, views never accepted) raises
:class:`~handsim.data.config.CannotDraw` in its source; the shard keeps the frames it gave and
draws the next episode from the same generator, so a shard is still a function of
``(seed, index)`` and a resumed run is identical. Redraws are counted by cause per shard
(``ShardInfo.redraws``) and summed in the manifest. Only :data:`MAX_EMPTY_EPISODES` frameless
episodes in a row (:data:`MAX_EMPTY_EPISODES_STARTED` once the shard has frames) stop the run
with a :class:`GenerationError`: then the config cannot give a frame.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import json
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context
from pathlib import Path

import numpy as np

# The config names are imported from here too (the module held them before the split).
from handsim.data.config import (  # noqa: F401
    MAX_EMPTY_EPISODES,
    MAX_EMPTY_EPISODES_STARTED,
    MAX_PENETRATION_M,
    MAX_TRIES_PER_FRAME,
    MIN_KEYPOINTS_IN_FRAME,
    OCCLUDING_OBJECTS,
    POSE_SOURCES,
    PRESETS,
    REDRAW_REASONS,
    SENSORS,
    SOURCES,
    VIEWPOINTS,
    CannotDraw,
    FrameSource,
    GenerationConfig,
    GenerationError,
    InvalidGenerationConfig,
    _int,
    make_source,
    register_source,
)
from handsim.data.kinematic import KinematicSource  # noqa: F401
from handsim.data.manifest import InvalidManifest, Manifest
from handsim.data.shards import PARTIAL_SUFFIX, ShardInfo, ShardWriter, check_shard
from handsim.world.camera import camera_preset

__all__ = ["generate", "generate_shard", "close_kept_source", "RAY_MAX_RETRIES"]


class _Acceptor:
    """Acceptance of one shard's frames: occlusion range, bucket quotas, visible-keypoint cap."""

    def __init__(self, config: GenerationConfig, frames: int) -> None:
        self.lo, self.hi = config.occlusion_range
        self.edges = None
        if config.occlusion_buckets is not None:
            edges, fractions = config._buckets()
            quotas = np.floor(fractions * frames).astype(int)
            quotas[np.argsort(-(fractions * frames - quotas))[: frames - quotas.sum()]] += 1
            self.edges, self.left = edges, quotas
        self.min_visible = config.min_visible_keypoints
        # Frames below the minimum still allowed (the epsilon: 0.29 * 100 is 28.999...).
        self.below_left = int(np.floor(config.max_fraction_below_min_visible * frames + 1e-9))

    def describe_left(self) -> str:
        """``"; frames still wanted per bucket: [lo, hi) n, ..."``, or nothing without buckets."""
        if self.edges is None:
            return ""
        left = [
            f"[{lo:g}, {hi:g}) {n}"
            for lo, hi, n in zip(self.edges[:-1], self.edges[1:], self.left, strict=True)
            if n > 0
        ]
        return "; frames still wanted per bucket: " + ", ".join(left)

    def __call__(self, ratio: float, visible: int) -> bool:
        below = visible < self.min_visible
        if below and self.below_left <= 0:
            return False
        if not self.lo <= ratio <= self.hi:
            return False
        if self.edges is not None:
            k = int(np.searchsorted(self.edges, ratio, side="right")) - 1
            if ratio == self.edges[-1]:
                k = len(self.left) - 1
            if not 0 <= k < len(self.left) or self.left[k] <= 0:
                return False
            self.left[k] -= 1
        if below:
            self.below_left -= 1
        return True


_KEPT_SOURCE: dict[str, FrameSource] = {}
"""This process's kinematic source, by its config, kept from shard to shard (its scenes)."""
_kept_source_freed_at_exit = False


def close_kept_source() -> None:
    """Free the kinematic source (scenes, renderers) this process keeps between shards."""
    while _KEPT_SOURCE:
        _KEPT_SOURCE.popitem()[1].close()


_WARP_OPTIONS: dict[str, object] = {"device": None, "batch": None}
"""This process's warp backend options (device, batch): they change no frame."""


def _make_source(config: GenerationConfig) -> FrameSource:
    if config.backend == "warp":
        from handsim.data.warp_source import DEFAULT_BATCH, make_warp_source

        batch = _WARP_OPTIONS["batch"] or DEFAULT_BATCH
        return make_warp_source(config, device=_WARP_OPTIONS["device"], batch=batch)
    return make_source(config)


@contextlib.contextmanager
def _shard_source(config: GenerationConfig) -> Iterator[FrameSource]:
    """The source of one shard: a kinematic source is kept for the next shard of its config.

    A kept source changes no frame: it rescales a kept hand from the geometry it was built
    with (bitwise the same whatever the lengths before), and keeps a scene with objects only
    for the same objects at the same placements.
    """
    global _kept_source_freed_at_exit
    key = json.dumps([config.to_json(), sorted(_WARP_OPTIONS.items())], sort_keys=True)
    source = _KEPT_SOURCE.get(key)
    if source is None:
        source = _make_source(config)
        if isinstance(source, KinematicSource):
            close_kept_source()
            _KEPT_SOURCE[key] = source
    try:
        yield source
    except BaseException:
        if _KEPT_SOURCE.get(key) is source:
            del _KEPT_SOURCE[key]  # an error may leave a scene half-changed: not kept
        raise
    finally:
        if _KEPT_SOURCE.get(key) is not source:
            source.close()
    if key in _KEPT_SOURCE and not _kept_source_freed_at_exit:
        # Free the renderers before teardown (a pool worker keeps its source to the end).
        # Registered once a shard has made its OpenGL context: exit handlers run last
        # registered first, so this runs before MuJoCo's EGL display is terminated.
        atexit.register(close_kept_source)
        _kept_source_freed_at_exit = True


def generate_shard(
    config: GenerationConfig,
    index: int,
    folder: str | os.PathLike[str],
    on_frame: Callable[[], None] | None = None,
) -> ShardInfo:
    """Make shard ``index`` of a dataset (from ``default_rng([seed, index])`` alone).

    Args:
        config: what to generate.
        index: the shard's index.
        folder: the dataset folder.
        on_frame: called after every frame written (progress).

    Returns:
        The complete shard's record.
    """
    folder = Path(folder)
    frames = config.shard_frames(index)
    rng = np.random.default_rng([config.seed, index])
    accept = _Acceptor(config, frames)
    path = folder / Manifest.shard_name(index)
    with (
        _shard_source(config) as source,
        ShardWriter(
            path,
            image_shape=(source.intrinsics.height, source.intrinsics.width),
            depth_scale_mm=config.depth_scale_mm,
            paired_clean=config.paired_clean,
        ) as writer,
    ):
        done, episode, empty = 0, 0, 0
        redraws: dict[str, int] = {}
        while done < frames:
            n = min(config.frames_per_episode, frames - done)
            got, failed = 0, None
            try:
                for step, arrays in enumerate(source.episode(rng, accept, n)):
                    writer.append(arrays, episode=index * 1_000_000 + episode, step=step)
                    if on_frame is not None:
                        on_frame()
                    got += 1
            except CannotDraw as err:
                # Redrawn from the same generator: the shard stays a function of (seed, index).
                failed = err
                redraws[err.reason] = redraws.get(err.reason, 0) + 1
            done += got
            episode += 1
            empty = 0 if got else empty + 1
            limit = MAX_EMPTY_EPISODES_STARTED if done else MAX_EMPTY_EPISODES
            if empty < limit:
                continue
            if failed is not None and failed.reason != "frame":
                raise GenerationError(
                    f"{limit} episodes in a row could not be drawn ({done} of the shard's "
                    f"{frames} frames made); the last: {failed.reason}: {failed}"
                )
            raise GenerationError(
                f"{limit} episodes in a row gave no accepted frame in "
                f"{MAX_TRIES_PER_FRAME} draws each ({done} of the shard's {frames} frames "
                f"made{accept.describe_left()}): the occlusion range "
                f"{config.occlusion_range}, buckets {config.occlusion_buckets} or the cap of "
                f"{config.max_fraction_below_min_visible:g} of frames with fewer than "
                f"{config.min_visible_keypoints} visible keypoints are out of reach of this "
                "config (add objects, use the 'through_object' viewpoint, or widen the range)"
            )
    return dataclasses.replace(writer.info, redraws=dict(sorted(redraws.items())))


_FRAMES_WRITTEN = None
"""In a pool worker: the run's shared count of frames written (``multiprocessing.Value``)."""
_INHERITED: list[object] = []
"""Kept sources inherited through fork: referenced, never closed (their OpenGL objects are the
parent's)."""


def _count_frame() -> None:
    with _FRAMES_WRITTEN.get_lock():
        _FRAMES_WRITTEN.value += 1


def _worker(args: tuple[dict, int, str]) -> tuple[int, ShardInfo]:
    config_json, index, folder = args
    config = GenerationConfig.from_mapping(config_json)
    on_frame = _count_frame if _FRAMES_WRITTEN is not None else None
    return index, generate_shard(config, index, folder, on_frame)


def _start_worker(parent_pid: int, frames_written: object) -> None:
    """Pool worker initializer: die with the parent, count frames, drop inherited sources."""
    global _FRAMES_WRITTEN
    _die_with_parent(parent_pid)
    _FRAMES_WRITTEN = frames_written
    # A forked worker must not use (or free) its parent's scenes and OpenGL contexts.
    _INHERITED.extend(_KEPT_SOURCE.values())
    _KEPT_SOURCE.clear()


def _start_method() -> str:
    """``"fork"`` where a forked worker is safe and starts at once; else ``"spawn"``.

    A forked worker inherits this process's imports (about 1 s of a spawned worker's start)
    and numba's compiler set-up. Fork only on Linux, from a process with one thread (a fork
    copies locks other threads may hold) that has made no OpenGL display (MuJoCo's EGL or
    OSMesa backends; a GPU driver's EGL state does not survive a fork); else spawn, which
    starts fresh.
    """
    if not sys.platform.startswith("linux") or threading.active_count() != 1:
        return "spawn"
    backend = os.environ.get("MUJOCO_GL", "")
    if backend == "osmesa":
        return "fork"
    egl = sys.modules.get("mujoco.egl")
    if backend == "egl" and (egl is None or getattr(egl, "EGL_DISPLAY", None) is None):
        return "fork"
    return "spawn"


def _warm_up_for_fork() -> None:
    """What every forked worker would do again: numba's set-up and the frames' imports.

    Loading one compiled loop from numba's cache sets numba up (~0.3 s of CPU a process);
    forked workers inherit it and load the other loops in milliseconds. The hand's rotations
    (scipy.spatial, with scipy.sparse and scipy.special) and the sensor's image operations
    (OpenCV) load on a worker's first frame otherwise (~0.25 s of CPU in each worker).
    """
    import cv2  # noqa: F401
    import scipy.spatial.transform  # noqa: F401

    from handsim.data import _kernels

    _kernels.depth_units_into(np.zeros(1, dtype=np.float32), 1.0, np.zeros(1, dtype=np.uint16))


RAY_MAX_RETRIES = 3
"""Times Ray reruns a shard task whose worker died (the rerun writes the same shard)."""


def _ray_results(
    jobs: list[tuple[dict, int, str]], address: str
) -> Iterator[tuple[int, ShardInfo]]:
    """Run one Ray task per shard; yield ``(index, record)`` as tasks complete."""
    try:
        import ray
    except ImportError as err:
        raise GenerationError(
            "--ray needs Ray: pip install 'handsim[ray]' (or pip install ray)"
        ) from err
    if not isinstance(address, str) or not address:
        raise InvalidGenerationConfig(
            f"ray must be 'local' or a cluster address such as 'auto' or 'ray://host:10001'; "
            f"received {address!r}"
        )
    if not ray.is_initialized():
        env = {k: os.environ[k] for k in ("MUJOCO_GL", "PYOPENGL_PLATFORM") if k in os.environ}
        ray.init(
            address=None if address == "local" else address,
            include_dashboard=False,
            runtime_env={"env_vars": env} if env else None,
            log_to_driver=False,
        )
    # Retries cover dead workers (SIGKILL, lost node), not errors of the config: those stop.
    task = ray.remote(num_cpus=1, max_retries=RAY_MAX_RETRIES)(_worker)
    pending = [task.remote(job) for job in jobs]
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            try:
                yield ray.get(done[0])
            except ray.exceptions.RayTaskError as err:
                raise err.as_instanceof_cause() from None
            except ray.exceptions.RayError as err:
                raise GenerationError(
                    f"a Ray shard task failed {RAY_MAX_RETRIES + 1} times ({err}); the complete "
                    "shards are kept, rerun the same command to resume"
                ) from err
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


def _as_completed(
    futures: list[Future], tick: Callable[[], None] | None, period_s: float = 0.1
) -> Iterator[tuple[int, ShardInfo]]:
    """Results of ``futures`` as they complete; ``tick()`` every ``period_s`` meanwhile."""
    pending = set(futures)
    while pending:
        done, pending = wait(pending, timeout=period_s, return_when=FIRST_COMPLETED)
        if tick is not None:
            tick()
        for future in done:
            yield future.result()


def _histogram(folder: Path, manifest: Manifest, edges: Sequence[float]) -> dict[str, list]:
    from handsim.data.shards import ShardReader

    counts = np.zeros(len(edges) - 1, dtype=int)
    for record in manifest.shards.values():
        reader = ShardReader(folder / record.name)
        ratio = reader.labels("hand_occlusion_ratio")
        counts += np.histogram(np.nan_to_num(ratio), bins=edges)[0]
        reader.close()
    return {"edges": [round(float(e), 6) for e in edges], "counts": counts.tolist()}


def generate(
    config: GenerationConfig,
    out: str | os.PathLike[str],
    *,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    ray: str | None = None,
    backend: str | None = None,
    device: str | None = None,
    batch: int | None = None,
) -> Manifest:
    """Generate (or resume) a dataset in ``out``.

    Args:
        config: what to generate.
        out: the dataset folder (created; an existing one must hold the same config).
        workers: worker processes, each making whole shards (forked from this process where
            that is safe, else spawned: :func:`_start_method`). Ignored with ``ray``. The
            shards are the same whatever the number of workers.
        progress: called with (frames done, frames total) as frames are written (at most
            every 0.1 s with workers; per shard with ``ray``).
        ray: run one Ray task per shard instead (needs ``pip install handsim[ray]``):
            ``"local"`` starts a local Ray instance (or uses the one this process already
            joined), any other value is the address of a running cluster (``"auto"``,
            ``"ray://host:10001"``, ...). ``out`` must be a folder every node sees. A task
            that dies is retried (:data:`RAY_MAX_RETRIES` times) and writes the same shard.
        backend: the renderer, ``"opengl"`` or ``"warp"`` (default: the config's
            ``backend``); the warp backend (:mod:`handsim.data.warp_source`) renders the
            ``kinematic`` and ``grasp`` sources in this process (``workers`` 1, no ``ray``).
        device: the warp backend's device (``"cpu"``, ``"cuda"``, ``"cuda:N"``; default:
            Warp's default device). The shards are the same on any device, up to the ray
            caster's floating point.
        batch: the warp backend's frames per launch of a hand alone (default
            :data:`~handsim.data.warp_source.DEFAULT_BATCH`; other configs render a frame per
            launch). The shards are the same whatever the batch.

    Returns:
        The final manifest (also written to ``out/manifest.json``).

    Raises:
        InvalidGenerationConfig: if ``out`` holds a dataset made with another config, or for
            arguments of the wrong type.
        GenerationError: if a shard cannot be made.
    """
    if not isinstance(config, GenerationConfig):
        raise InvalidGenerationConfig(
            "config must be a GenerationConfig (e.g. GenerationConfig.from_mapping("
            f"PRESETS['hand-only'])); received {type(config).__name__}"
        )
    if not isinstance(out, (str, os.PathLike)):
        raise InvalidGenerationConfig(
            f"out must be a folder path (str or os.PathLike); received {type(out).__name__}"
        )
    if progress is not None and not callable(progress):
        raise InvalidGenerationConfig(
            "progress must be None or a callable taking (frames done, frames total); "
            f"received {progress!r}"
        )
    folder = Path(out)
    _int("workers", workers, 1, 256)
    if backend is not None:
        config = dataclasses.replace(config, backend=backend)  # validated by the config
    _check_backend(config, workers, ray, device, batch)
    folder.mkdir(parents=True, exist_ok=True)
    with _folder_lock(folder):
        return _generate_in(folder, config, workers, progress, ray)


def _check_backend(
    config: GenerationConfig, workers: int, ray: str | None, device: object, batch: object
) -> None:
    """Refuse options the config's backend cannot do; set this process's warp options."""
    if config.backend != "warp":
        given = [name for name, value in (("device", device), ("batch", batch)) if value]
        if given:
            raise InvalidGenerationConfig(
                f"{' and '.join(given)} are options of the warp backend; add backend='warp' "
                f"(--backend warp) or leave them out (backend {config.backend!r})"
            )
        _WARP_OPTIONS.update(device=None, batch=None)
        return
    from handsim.data.warp_source import check_warp_config

    check_warp_config(config)
    if workers != 1 or ray is not None:
        raise InvalidGenerationConfig(
            "the warp backend renders in this process (one device, many worlds per launch): "
            f"workers must be 1 and ray None; received workers={workers}, ray={ray!r}"
        )
    if batch is not None:
        _int("batch", batch, 1, 65_536)
    if device is not None and not isinstance(device, str):
        raise InvalidGenerationConfig(
            f"device must be a Warp device name ('cpu', 'cuda', 'cuda:0'); received {device!r}"
        )
    _WARP_OPTIONS.update(device=device, batch=batch)


LOCK_NAME = ".handsim-generate.lock"
"""File in a dataset folder that a running :func:`generate` holds locked (``flock``)."""


@contextlib.contextmanager
def _folder_lock(folder: Path) -> Iterator[None]:
    """Hold the dataset folder for this run: a second run into it is refused.

    The lock is the kernel's (``flock``): it goes with the process, so a killed run never
    leaves a stale lock behind.
    """
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock, as before
        yield
        return
    with open(folder / LOCK_NAME, "w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise GenerationError(
                f"another `handsim generate` is writing into {folder} (it holds "
                f"{folder / LOCK_NAME}); wait for it to end, or use another folder"
            ) from None
        yield


def _die_with_parent(parent_pid: int) -> None:
    """Pool worker initializer: end when the generating process ends (Linux).

    A worker whose parent was killed would otherwise finish its shard unseen and could race a
    resumed run for the same file.
    """
    if sys.platform.startswith("linux"):
        import ctypes

        pr_set_pdeathsig = 1
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, signal.SIGKILL)
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def _generate_in(
    folder: Path,
    config: GenerationConfig,
    workers: int,
    progress: Callable[[int, int], None] | None,
    ray: str | None,
) -> Manifest:
    """:func:`generate` in a folder this run holds."""
    for partial in folder.glob(f"*{PARTIAL_SUFFIX}"):
        partial.unlink()  # a shard in progress when a run was killed
    shape = (camera_preset(config.camera).height, camera_preset(config.camera).width)
    try:
        manifest = Manifest.read(folder)
    except InvalidManifest:
        if any(folder.glob("shard-*.h5")):
            raise InvalidGenerationConfig(
                f"{folder} holds shards but no readable manifest.json; use an empty folder"
            ) from None
        manifest = None
    if config.frames_per_shard is None:
        # The manifest records the size (the shards depend on it): a resumed run keeps the
        # recorded one, a new run takes the job's.
        recorded = None if manifest is None else manifest.config.get("frames_per_shard")
        size = recorded if _is_int(recorded) else config.shard_size
        config = dataclasses.replace(config, frames_per_shard=int(size))
    if manifest is None:
        manifest = Manifest(
            config=config.to_json(),
            seeds=[],
            shards={},
            depth_scale_mm=float(config.depth_scale_mm),
            image_shape=shape,
        )
    stored = manifest.config
    try:
        # Fields added since the dataset was made take their defaults.
        stored = GenerationConfig.from_mapping(manifest.config).to_json()
    except (InvalidGenerationConfig, TypeError):
        pass
    if stored != config.to_json():
        changed = sorted(k for k in config.to_json() if stored.get(k) != config.to_json()[k])
        raise InvalidGenerationConfig(
            f"{folder} holds a dataset made with another config (fields differ: "
            f"{', '.join(changed)}); resume with the same config or use another folder"
        )
    manifest.config = config.to_json()
    manifest.seeds = [config.seed] * config.num_shards
    for index, record in list(manifest.shards.items()):
        if check_shard(folder / record.name, record):
            del manifest.shards[index]  # damaged since: make it again
    todo = [i for i in range(config.num_shards) if i not in manifest.shards]
    manifest.write(folder)
    done = manifest.frames
    if progress is not None:
        progress(done, config.frames)
    jobs = [(config.to_json(), i, str(folder)) for i in todo]
    pool = None
    if ray is not None:
        results: Iterator = _ray_results(jobs, ray)
    elif workers == 1 or len(jobs) <= 1:
        # In this process: progress frame by frame (workers report whole shards).
        counted = [done]

        def on_frame() -> None:
            counted[0] += 1
            if progress is not None:
                progress(counted[0], config.frames)

        results = ((i, generate_shard(config, i, folder, on_frame)) for _, i, folder in jobs)
    else:
        # Workers make their own GL contexts; a worker that dies breaks the pool (an error),
        # where multiprocessing.Pool would replace it and wait forever.
        method = _start_method()
        if method == "fork":
            _warm_up_for_fork()
        context = get_context(method)
        # Frames written by the workers, shards in progress included (progress per frame).
        written = context.Value("q", 0)
        pool = ProcessPoolExecutor(
            min(workers, len(jobs)),
            mp_context=context,
            initializer=_start_worker,
            initargs=(os.getpid(), written),
        )
        futures = [pool.submit(_worker, j) for j in jobs]
        tick = None
        if progress is not None:
            start = done

            def tick() -> None:
                progress(start + written.value, config.frames)

        results = _as_completed(futures, tick)
    complete = False
    try:
        for index, info in results:
            manifest.shards[index] = info
            manifest.write(folder)
            done += info.frames
            if progress is not None and pool is None:
                progress(done, config.frames)
        complete = True
    except BrokenProcessPool as err:
        raise GenerationError(
            f"a generation worker died ({err}); the complete shards are kept, rerun the same "
            "command to resume (with workers=1 to see the worker's error)"
        ) from err
    finally:
        if pool is not None:
            # Every shard is written: the workers free their contexts and exit while this
            # process sums the dataset up. After an error they are awaited first (a worker
            # still writing could race a resumed run).
            pool.shutdown(wait=not complete, cancel_futures=True)
        close_kept_source()  # shards made in this process
    try:
        buckets = config.occlusion_buckets is not None
        edges = config._buckets()[0] if buckets else np.linspace(0, 1, 11)
        manifest.occlusion_histogram = _histogram(folder, manifest, edges)
        manifest.write(folder)
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
    return manifest
