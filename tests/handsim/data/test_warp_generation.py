"""`handsim generate --backend warp`: batched MuJoCo Warp frames against the OpenGL path."""

import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from handsim.data.config import GenerationConfig, InvalidGenerationConfig
from handsim.data.generation import PRESETS, generate
from handsim.data.shards import ShardReader
from handsim.world.warp_render import warp_available

needs_warp = pytest.mark.skipif(
    not warp_available(), reason="mujoco-warp is not installed (pip install 'handsim[gpu]')"
)
# 8 frames of 320 x 240 (the smallest preset), 2 shards of 4, episodes of 3 (a batch of 4
# never spans two: the last one is cut short).
SMALL = dict(PRESETS["hand-only"], frames=8, frames_per_shard=4, frames_per_episode=3, seed=5)


# 3 grasp frames (1-3 objects on the table), shards of 2. Without sensor noise: its draws
# depend on the image (the pixels with depth), so with noise the two backends' draws part
# after an episode's first frame.
HAND_OBJECT = dict(
    PRESETS["hand-object"], frames=3, frames_per_shard=2, frames_per_episode=2, seed=5,
    sensor="none",
)  # fmt: skip
LABELS = (
    "hand_pose", "keypoints_px", "in_frame", "visible", "occluder", "hand_occlusion_ratio",
    "object_ycbv_id", "object_T_cam_from_obj", "object_px_count_all", "object_px_count_visib",
    "object_visib_fract",
)  # fmt: skip


@pytest.fixture(scope="module", autouse=True)
def _warp_cache(tmp_path_factory):
    os.environ.setdefault("WARP_CACHE_PATH", str(tmp_path_factory.mktemp("warp_cache")))


def _arrays(folder):
    out = {}
    for path in sorted(folder.glob("shard-*.h5")):
        reader = ShardReader(path)
        out[path.name] = {
            "depth": np.stack([reader[i]["depth"] for i in range(len(reader))]),
            "keypoints_px": reader.labels("keypoints_px"),
            "visible": reader.labels("visible"),
            "hand_pose": reader.labels("hand_pose"),
        }
        reader.close()
    return out


def _all_arrays(folder):
    """Every shard's images and labels, by shard name."""
    out = {}
    for path in sorted(folder.glob("shard-*.h5")):
        reader = ShardReader(path)
        out[path.name] = {name: reader.labels(name) for name in LABELS}
        for image in ("depth", "segmentation"):
            out[path.name][image] = np.stack([reader[i][image] for i in range(len(reader))])
        reader.close()
    return out


def _assert_same(a, b):
    assert a.keys() == b.keys()
    for name in a:
        for field in a[name]:
            np.testing.assert_array_equal(a[name][field], b[name][field], err_msg=field)


@needs_warp
def test_warp_dataset_checks_resumes_and_does_not_depend_on_batch(tmp_path):
    """A shard is a function of (seed, index): resumed, or made with another batch, the same."""
    config = GenerationConfig.from_mapping(SMALL)
    manifest = generate(config, tmp_path / "a", backend="warp", device="cpu", batch=4)
    assert manifest.frames == 8 and manifest.config["backend"] == "warp"
    first = _arrays(tmp_path / "a")
    # Deleted shards are made again identically.
    for path in (tmp_path / "a").glob("shard-*.h5"):
        path.unlink()
    generate(config, tmp_path / "a", backend="warp", device="cpu", batch=4)
    _assert_same(first, _arrays(tmp_path / "a"))
    # Another batch size draws the same frames (launches of 2 and 1 in place of 3).
    generate(config, tmp_path / "b", backend="warp", device="cpu", batch=2)
    _assert_same(first, _arrays(tmp_path / "b"))
    # A resume with the other backend is refused.
    with pytest.raises(InvalidGenerationConfig, match="fields differ: backend"):
        generate(config, tmp_path / "a")


@needs_warp
def test_a_launch_holds_no_more_worlds_than_the_episode_needs(monkeypatch):
    """A batch past frames_per_episode is capped; no candidate is drawn past the frames wanted."""
    from handsim.data.warp_source import WarpKinematicSource

    config = GenerationConfig.from_mapping(SMALL)  # episodes of 3 frames
    source = WarpKinematicSource(config, device="cpu", batch=16)
    drawn = []
    draw = source._candidate
    monkeypatch.setattr(source, "_candidate", lambda *args: drawn.append(draw(*args)) or drawn[-1])
    try:
        assert source.worlds == 3
        frames = list(source.episode(np.random.default_rng(0), lambda *args: True, 2))
        assert len(frames) == 2
        assert [kept[2].nworld for kept in source._warps.values()] == [3]
        # Every candidate of this episode is kept: two frames wanted, two drawn (not 16).
        assert len(drawn) == 2 and all(c is not None for c in drawn)
    finally:
        source.close()


@needs_warp
def test_episodes_of_both_sides_keep_one_device_model_per_side(monkeypatch):
    """Alternating left and right hands refit the skin; the device models are made once."""
    import handsim.world.warp_render as warp_render
    from handsim.data.warp_source import WarpKinematicSource

    made = []
    real = warp_render.WarpDepthRenderer
    monkeypatch.setattr(
        warp_render, "WarpDepthRenderer", lambda *a, **k: made.append(real(*a, **k)) or made[-1]
    )
    config = GenerationConfig.from_mapping(SMALL, left_fraction=0.5)
    source = WarpKinematicSource(config, device="cpu", batch=4)
    rng = np.random.default_rng(1)
    try:
        sides = []
        for _ in range(6):
            scene, _ = source._scene(rng)
            sides.append(scene.spec.hand.side)
            renderer = source._warp_renderer(scene)
            assert renderer is source._warps[id(scene)][2]
        assert set(sides) == {"left", "right"} and len(made) == 2
    finally:
        source.close()


@needs_warp
def test_labels_agree_with_the_opengl_path_on_the_same_draws():
    """Keypoints identical, visibility and segmentation >= 99 % as OpenGL's on the same states."""
    from handsim.data.warp_source import WarpKinematicSource, render_labels
    from handsim.frame import FrameRenderer

    config = GenerationConfig.from_mapping(SMALL, sensor="none")
    source = WarpKinematicSource(config, device="cpu", batch=4)
    try:
        rng = np.random.default_rng(0)
        kp_equal = visible_equal = total = 0
        for _ in range(2):  # two episodes: two hand lengths
            scene, renderer = source._scene(rng)
            # Candidate 2 is past the episode's postures: it draws its own motion.
            postures = source._postures(rng, "motion", 2)
            candidates = [
                source._candidate(scene, 7, k, postures, "motion") for k in range(source.worlds)
            ]
            candidates = [c for c in candidates if c is not None]
            assert candidates
            warp = source._warp_renderer(scene)
            worlds = candidates + [candidates[-1]] * (source.worlds - len(candidates))
            depth_m, labels = render_labels(scene, warp, worlds)
            saved = (scene.data, scene.model.geom_size.copy())
            # A new OpenGL renderer: the source's own one is never drawn with (nor rescaled).
            opengl = FrameRenderer(scene, "camera", skin_detail="full")
            for i, candidate in enumerate(candidates):
                ours = source.label(scene, renderer, candidate, (depth_m[i], labels[i]))
                # The OpenGL path on the same state: the data and the upper arm's length.
                scene.data, scene.model.geom_size[:] = candidate.data, candidate.geom_size
                try:
                    reference = opengl.render(np.random.default_rng(0))
                finally:
                    scene.data, scene.model.geom_size[:] = saved[0], saved[1]
                np.testing.assert_array_equal(ours.keypoints_px, reference.keypoints_px)
                np.testing.assert_array_equal(ours.in_frame, reference.in_frame)
                kp_equal += int(np.all(ours.keypoints_px == reference.keypoints_px))
                visible_equal += int(np.sum(ours.visible == reference.visible))
                total += len(ours.visible)
                seen = (ours.segmentation != 0) | (reference.segmentation != 0)
                seg_agree = np.mean(ours.segmentation[seen] == reference.segmentation[seen])
                assert seg_agree >= 0.99, seg_agree
            opengl.close()
        assert visible_equal / total >= 0.99, (visible_equal, total)
    finally:
        source.close()


@needs_warp
def test_hand_object_frames_follow_the_opengl_path_and_resume(tmp_path):
    """Grasp frames on Warp: the OpenGL path's draws and labels, and a shard of (seed, index)."""
    config = GenerationConfig.from_mapping(HAND_OBJECT)
    manifest = generate(config, tmp_path / "w", backend="warp", device="cpu")
    assert manifest.frames == 3 and manifest.config["backend"] == "warp"
    warp = _all_arrays(tmp_path / "w")
    generate(config, tmp_path / "g")
    opengl = _all_arrays(tmp_path / "g")
    assert warp.keys() == opengl.keys()
    for name, ours in warp.items():
        ref = opengl[name]
        # The same draws: grasps, hands, objects and views.
        for field in ("hand_pose", "keypoints_px", "in_frame", "object_ycbv_id"):
            np.testing.assert_array_equal(ours[field], ref[field], err_msg=field)
        np.testing.assert_allclose(ours["object_T_cam_from_obj"], ref["object_T_cam_from_obj"])
        # The labels: as the images (test_warp_render.py checks them where the images agree).
        seen = (ours["segmentation"] != 0) | (ref["segmentation"] != 0)
        assert (ours["segmentation"] == ref["segmentation"])[seen].mean() >= 0.99
        assert (ours["visible"] == ref["visible"]).mean() >= 0.95
        np.testing.assert_allclose(ours["object_visib_fract"], ref["object_visib_fract"], atol=0.05)
        np.testing.assert_allclose(
            ours["hand_occlusion_ratio"], ref["hand_occlusion_ratio"], atol=0.02
        )
        assert (ours["object_px_count_all"] > 0).any()
    # A deleted shard is made again identically; a resume with the other backend is refused.
    (tmp_path / "w" / "shard-00000.h5").unlink()
    generate(config, tmp_path / "w", backend="warp", device="cpu")
    _assert_same(warp, _all_arrays(tmp_path / "w"))
    with pytest.raises(InvalidGenerationConfig, match="fields differ: backend"):
        generate(config, tmp_path / "w")
    with pytest.raises(InvalidGenerationConfig, match="fields differ: backend"):
        generate(dataclasses.replace(config, backend="warp"), tmp_path / "g", device="cpu")


def test_options_the_warp_backend_cannot_do_are_refused(tmp_path):
    """The rollout source, workers, stray options: refused, the option named."""
    config = GenerationConfig.from_mapping(SMALL)
    with pytest.raises(InvalidGenerationConfig, match="cannot do: source 'rollout'"):
        generate(GenerationConfig.from_mapping(PRESETS["grasp-rollouts"]), tmp_path / "g",
                 backend="warp")  # fmt: skip
    from handsim.data.warp_source import WarpKinematicSource

    with pytest.raises(InvalidGenerationConfig, match="renders a hand alone.*source 'grasp'"):
        WarpKinematicSource(GenerationConfig.from_mapping(PRESETS["hand-object"]), device="cpu")
    with pytest.raises(InvalidGenerationConfig, match="workers must be 1 and ray None"):
        generate(config, tmp_path / "w", backend="warp", workers=2)
    with pytest.raises(InvalidGenerationConfig, match="options of the warp backend"):
        generate(config, tmp_path / "d", device="cpu")
    with pytest.raises(InvalidGenerationConfig, match="backend must be one of"):
        generate(config, tmp_path / "x", backend="vulkan")
    with pytest.raises(InvalidGenerationConfig, match="batch must be an integer"):
        generate(config, tmp_path / "b", backend="warp", batch=0)


def test_import_handsim_does_not_import_warp():
    """Warp loads only when a warp renderer is made."""
    code = (
        "import sys, handsim, handsim.data.generation, handsim.data.warp_source; "
        "print(sorted(m for m in ('warp', 'mujoco_warp') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@needs_warp
def test_cli_generates_with_warp_and_the_dataset_checks(tmp_path):
    """`handsim generate --backend warp` writes a dataset that `handsim dataset check` passes."""
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    out = tmp_path / "cli"
    cli = [sys.executable, "-m", "handsim.cli"]
    args = ["generate", "--preset", "hand-only", "--frames", "4", "--seed", "2", "--quiet"]
    done = subprocess.run(
        [*cli, *args, "--backend", "warp", "--device", "cpu", "--batch", "4", "--out", str(out)],
        capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout)["frames"] == 4
    check = subprocess.run(
        [*cli, "dataset", "check", str(out)], capture_output=True, text=True, env=env
    )
    assert check.returncode == 0, check.stdout + check.stderr
    # Objects hiding the hand: the occlusion-heavy preset's grasps.
    occluded = tmp_path / "occluded"
    done = subprocess.run(
        [*cli, "generate", "--preset", "occlusion-heavy", "--frames", "2", "--seed", "2",
         "--quiet", "--backend", "warp", "--device", "cpu", "--out", str(occluded)],
        capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    check = subprocess.run(
        [*cli, "dataset", "check", str(occluded)], capture_output=True, text=True, env=env
    )
    assert check.returncode == 0, check.stdout + check.stderr
    ratio = ShardReader(next(occluded.glob("shard-*.h5"))).labels("hand_occlusion_ratio")
    assert (ratio >= 0.1).all()  # the preset's lowest bucket
    refused = subprocess.run(
        [*cli, *args, "--batch", "4", "--out", str(tmp_path / "r")],
        capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert refused.returncode != 0
    assert "options of the warp backend" in refused.stderr
