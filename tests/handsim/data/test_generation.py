"""Tests of handsim.data.generation: configs, presets, determinism, resume after a kill, checks."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from handsim.data.generation import (
    PRESETS,
    CannotDraw,
    GenerationConfig,
    GenerationError,
    InvalidGenerationConfig,
    generate,
    generate_shard,
)
from handsim.data.manifest import InvalidManifest, Manifest, check_dataset
from handsim.data.shards import PARTIAL_SUFFIX, ShardReader, file_sha256
from handsim.world.scene import SEGMENT_LABELS

# Tiny and fast: 2 frames per shard and per episode, hand sizes fixed, noise-free depth.
TINY = {
    "frames": 4,
    "frames_per_shard": 2,
    "frames_per_episode": 2,
    "sensor": "none",
    "num_objects_range": (1, 1),
    "objects": ("005_tomato_soup_can",),
}


def test_every_preset_is_a_valid_config():
    """The presets build configs, and their JSON form round-trips."""
    for name, values in PRESETS.items():
        config = GenerationConfig.from_mapping(values)
        assert GenerationConfig.from_mapping(config.to_json()) == config, name


@pytest.mark.parametrize(
    ("values", "match"),
    [
        ({"frames": 0}, r"frames must be an integer in \[1, 1000000000\]; received 0"),
        ({"frames": 2.5}, r"frames must be an integer"),
        ({"camera": "kinect"}, r"camera must be one of .*icvl.*; received 'kinect'"),
        ({"viewpoints": ("top",)}, r"viewpoints must be one of third_person, egocentric"),
        ({"viewpoints": "random"}, r"viewpoints must be a non-empty list"),
        ({"sensor": "lidar"}, r"sensor must be one of none, structured_light, tof"),
        ({"hand_length_range_m": (0.1, 0.2)}, r"hand_length_range_m must be a pair of numbers"),
        ({"num_objects_range": (1.5, 2.5)}, r"num_objects_range must be a pair of integers"),
        ({"objects": ("spoon",)}, r"objects: unknown object 'spoon'; valid: 002_master_chef"),
        ({"occlusion_range": (0.5, 0.2)}, r"occlusion_range must be a pair of numbers"),
        ({"occlusion_buckets": ((0, 0.5), (0.5, 0.5))}, r"one more edge than fractions"),
        ({"occlusion_buckets": ((0, 0.5, 1), (0.5, 0.6))}, r"fractions must be >= 0 and sum"),
        ({"paired_clean": "yes"}, r"paired_clean must be true or false"),
        ({"min_visible_keypoints": 22}, r"min_visible_keypoints must be an integer in \[0, 21\]"),
        (
            {"max_fraction_below_min_visible": 1.5},
            r"max_fraction_below_min_visible must be a number in \[0, 1\]; received 1.5",
        ),
        (
            {"max_fraction_below_min_visible": "5 %"},
            r"max_fraction_below_min_visible must be a number in \[0, 1\]; received '5 %'",
        ),
        (
            {"viewpoints": ("through_object",), "num_objects_range": (0, 0)},
            r"'through_object' needs objects",
        ),
        (
            {"colour": "red"},
            r"unknown config field\(s\) colour; valid fields: approach_fraction, backend, "
            r"background",
        ),
        ({"background": "sky"}, r"background must be one of none, wall, torso, clutter; received"),
    ],
)
def test_config_errors_name_the_field_and_what_is_valid(values, match):
    """Every bad field raises InvalidGenerationConfig naming it."""
    with pytest.raises(InvalidGenerationConfig, match=match):
        GenerationConfig.from_mapping(values)


def test_config_files_json_and_bad_files(tmp_path):
    """JSON files load with overrides; missing and malformed files are named."""
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"frames": 7, "sensor": "tof"}))
    config = GenerationConfig.from_file(path, frames=9)
    assert config.frames == 9 and config.sensor == "tof"
    with pytest.raises(InvalidGenerationConfig, match="does not exist"):
        GenerationConfig.from_file(tmp_path / "none.json")
    path.write_text("{frames: 3")
    with pytest.raises(InvalidGenerationConfig, match="is not valid JSON"):
        GenerationConfig.from_file(path)


def test_a_shard_is_the_same_whoever_makes_it(tmp_path):
    """Shard i depends on (seed, i) only: made twice, the files are byte-identical."""
    config = GenerationConfig.from_mapping(TINY)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = generate_shard(config, 1, tmp_path / "a")
    b = generate_shard(config, 1, tmp_path / "b")
    assert a == b
    other = generate_shard(GenerationConfig.from_mapping(TINY, seed=1), 1, tmp_path / "a")
    assert other.sha256 != a.sha256


def test_generate_resumes_after_a_crash_and_check_finds_damage(tmp_path):
    """Missing, partial and damaged shards are (re)made identically; the manifest lists all."""
    config = GenerationConfig.from_mapping(TINY)
    full = generate(config, tmp_path / "full")
    assert full.frames == 4 and len(full.shards) == 2
    assert check_dataset(tmp_path / "full")["ok"]
    reader = ShardReader(tmp_path / "full" / "shard-00000.h5")
    assert len(reader) == 2 and reader[0]["valid"]
    assert reader[0]["object_valid"].sum() == 1

    # A crashed run: shard 1 never completed (a partial file), shard 0 damaged afterwards.
    run = tmp_path / "run"
    generate(GenerationConfig.from_mapping(TINY, frames=2), run)  # only shard 0
    manifest = json.loads((run / "manifest.json").read_text())
    manifest["config"]["frames"] = 4
    (run / "manifest.json").write_text(json.dumps(manifest))
    (run / f"shard-00001{PARTIAL_SUFFIX}").write_bytes(b"half a shard")
    data = bytearray((run / "shard-00000.h5").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (run / "shard-00000.h5").write_bytes(bytes(data))
    report = check_dataset(run)
    assert not report["ok"] and report["problems"][0].startswith("shard-00000.h5: ")
    assert report["partial"] == [f"shard-00001{PARTIAL_SUFFIX}"]

    resumed = generate(config, run)
    assert resumed.shards == full.shards  # names, counts, sizes and checksums
    assert check_dataset(run) == check_dataset(tmp_path / "full")
    assert not list(run.glob(f"*{PARTIAL_SUFFIX}"))


def test_generate_refuses_arguments_of_the_wrong_type(tmp_path):
    """Swapped arguments and a progress flag in place of a callback: clear errors, no folder."""
    config = GenerationConfig.from_mapping(PRESETS["hand-only"], frames=1)
    with pytest.raises(InvalidGenerationConfig, match="config must be a GenerationConfig"):
        generate(str(tmp_path / "d"), config)
    with pytest.raises(InvalidGenerationConfig, match="out must be a folder path"):
        generate(config, config)
    with pytest.raises(InvalidGenerationConfig, match="progress must be None or a callable"):
        generate(config, tmp_path / "d", progress=False)
    assert not (tmp_path / "d").exists()


def test_another_config_is_refused_in_an_existing_dataset(tmp_path):
    """Resuming with a different config would mix datasets: refused, naming the fields."""
    generate(GenerationConfig.from_mapping(TINY, frames=2), tmp_path)
    with pytest.raises(InvalidGenerationConfig, match=r"another config \(fields differ: seed\)"):
        generate(GenerationConfig.from_mapping(TINY, frames=2, seed=3), tmp_path)


def test_occlusion_control_keeps_the_range_and_fills_buckets(tmp_path):
    """Kept frames lie in the range; stratified shards fill each bucket to its quota."""
    ranged = GenerationConfig.from_mapping(
        PRESETS["occlusion-heavy"],
        frames=4,
        frames_per_shard=4,
        frames_per_episode=4,
        sensor="none",
        occlusion_buckets=None,
        occlusion_range=(0.2, 0.8),
    )
    manifest = generate(ranged, tmp_path / "ranged")
    ratios = ShardReader(tmp_path / "ranged" / "shard-00000.h5").labels("hand_occlusion_ratio")
    assert ((ratios >= 0.2) & (ratios <= 0.8)).all()
    assert sum(manifest.occlusion_histogram["counts"]) == 4

    buckets = GenerationConfig.from_mapping(
        PRESETS["occlusion-heavy"],
        frames=4,
        frames_per_shard=4,
        frames_per_episode=4,
        sensor="none",
        occlusion_buckets=((0.0, 0.3, 1.0), (0.5, 0.5)),
    )
    manifest = generate(buckets, tmp_path / "buckets")
    assert manifest.occlusion_histogram == {"edges": [0.0, 0.3, 1.0], "counts": [2, 2]}


def test_an_unreachable_occlusion_range_fails_clearly(tmp_path, monkeypatch):
    """A marker cannot hide 97 % of a hand: the error says what to change, nothing is left."""
    # The source draws (kinematic) and the error message (generation) read the limit.
    from handsim.data import generation as generate_module
    from handsim.data import kinematic

    monkeypatch.setattr(kinematic, "MAX_TRIES_PER_FRAME", 3)
    monkeypatch.setattr(generate_module, "MAX_TRIES_PER_FRAME", 3)
    config = GenerationConfig.from_mapping(
        TINY, frames=1, objects=("040_large_marker",), occlusion_range=(0.97, 1.0)
    )
    with pytest.raises(GenerationError, match="5 episodes in a row gave no accepted frame"):
        generate(config, tmp_path)
    assert not list(tmp_path.glob("*.h5*"))  # the failed shard left nothing behind
    with pytest.raises(InvalidGenerationConfig, match="frames without objects have a hand"):
        GenerationConfig.from_mapping(PRESETS["hand-only"], occlusion_range=(0.5, 1.0))


def test_the_occlusion_heavy_preset_fills_its_rare_bucket_in_a_small_shard(tmp_path):
    """150 frames in one shard: the last bucket to fill (least occluded) is rare, not unreachable.

    Five empty episodes in a row once stopped this run at frame 139.
    """
    config = GenerationConfig.from_mapping(
        PRESETS["occlusion-heavy"], frames=150, frames_per_shard=150
    )
    manifest = generate(config, tmp_path)
    assert manifest.occlusion_histogram["counts"] == [38, 38, 37, 37]


def _kill_after_the_first_shard(code, run):
    """Run ``code`` (a generation into ``run``) and SIGKILL it once a shard is complete."""
    proc = subprocess.Popen([sys.executable, "-c", code, str(run)])
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if (run / "manifest.json").exists() and Manifest.read(run).shards:
            break
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    return proc


def test_sigkill_loses_only_the_shard_in_progress(tmp_path):
    """A run killed with SIGKILL mid-way resumes to the same dataset as an uninterrupted run."""
    values = dict(TINY, frames=8)
    code = (
        "import sys; from handsim.data.generation import GenerationConfig, generate\n"
        f"generate(GenerationConfig.from_mapping({values!r}), sys.argv[1])\n"
    )
    run = tmp_path / "killed"
    proc = _kill_after_the_first_shard(code, run)
    before = Manifest.read(run)
    assert 1 <= len(before.shards) < 4 or proc.returncode != -signal.SIGKILL
    resumed = generate(GenerationConfig.from_mapping(values), run)
    clean = generate(GenerationConfig.from_mapping(values), tmp_path / "clean")
    assert resumed.shards == clean.shards
    for record in clean.shards.values():
        assert file_sha256(run / record.name) == record.sha256
    assert np.array_equal(
        ShardReader(run / "shard-00003.h5").labels("keypoints_cam"),
        ShardReader(tmp_path / "clean" / "shard-00003.h5").labels("keypoints_cam"),
    )


def test_ray_without_ray_installed_says_how_to_get_it(tmp_path, monkeypatch):
    """generate(ray=...) without Ray names the extra to install."""
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(GenerationError, match=r"pip install 'handsim\[ray\]'"):
        generate(GenerationConfig.from_mapping(TINY), tmp_path, ray="local")


def test_a_dataset_made_before_new_config_fields_resumes(tmp_path):
    """A manifest without later fields (e.g. source) resumes: missing fields take defaults."""
    config = GenerationConfig.from_mapping(TINY, frames=2)
    made = generate(config, tmp_path)
    doc = json.loads((tmp_path / "manifest.json").read_text())
    keys = ("source", "env_id", "frame_stride")
    for key in (*keys, "min_visible_keypoints", "max_fraction_below_min_visible"):
        del doc["config"][key]
    del doc["redraws"]
    for record in doc["shards"]:
        del record["redraws"]
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    assert generate(config, tmp_path).shards == made.shards
    assert Manifest.read(tmp_path).config == config.to_json()
    assert Manifest.read(tmp_path).redraws == {}


def test_a_dataset_made_before_the_skin_detail_field_resumes_with_the_full_skin(tmp_path):
    """Its shards were drawn with the full skin, the default; "auto" is refused on resume."""
    default = GenerationConfig.from_mapping(TINY, frames=2)
    assert default.skin_detail == "full"
    made = generate(default, tmp_path)
    doc = json.loads((tmp_path / "manifest.json").read_text())
    del doc["config"]["skin_detail"]
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    coarse = GenerationConfig.from_mapping(TINY, frames=2, skin_detail="auto")
    with pytest.raises(InvalidGenerationConfig, match=r"fields differ: skin_detail\)"):
        generate(coarse, tmp_path)
    assert generate(default, tmp_path).shards == made.shards


def test_scenes_kept_between_shards_change_no_frame(tmp_path):
    """A process keeps its hand scenes from shard to shard; a shard is the same without them."""
    from handsim.data import generation

    config = GenerationConfig.from_mapping(
        PRESETS["hand-only"], frames=6, frames_per_shard=3, frames_per_episode=1
    )
    generation.close_kept_source()
    for index in range(2):
        (tmp_path / f"kept{index}").mkdir()
        kept = generate_shard(config, index, tmp_path / f"kept{index}")
    (source,) = generation._KEPT_SOURCE.values()
    # Shard 1's episodes reused the scenes of shard 0 (one per side), rescaling their hands.
    assert 1 <= len(source._scenes) <= 2
    assert all(scene.hand_rescaled for scene, _ in source._scenes.values())
    generation.close_kept_source()
    (tmp_path / "fresh").mkdir()
    assert generate_shard(config, 1, tmp_path / "fresh") == kept
    lengths = ShardReader(tmp_path / "fresh" / "shard-00001.h5").labels("hand_length_m")
    assert len(set(lengths.tolist())) == 3  # one hand length per episode, off any grid
    generation.close_kept_source()
    assert not generation._KEPT_SOURCE


def test_a_failed_shard_keeps_no_scene(tmp_path, monkeypatch):
    """An error in the middle of a shard frees its source instead of keeping it."""
    from handsim.data import generation

    config = GenerationConfig.from_mapping(PRESETS["hand-only"], frames=2, frames_per_shard=2)
    closed = []
    close = generation.KinematicSource.close

    def recording_close(self):
        closed.append(self)
        close(self)  # the renderers are freed, not left to the garbage collector

    monkeypatch.setattr(generation.KinematicSource, "close", recording_close)

    def broken(self, rng, accept, frames):
        self._scene(rng)  # a scene is made and kept
        raise RuntimeError("broken episode")

    monkeypatch.setattr(generation.KinematicSource, "episode", broken)
    with pytest.raises(RuntimeError, match="broken episode"):
        generate_shard(config, 0, tmp_path)
    assert not generation._KEPT_SOURCE and len(closed) == 1
    assert not list(tmp_path.glob("*.h5*"))  # the partial shard is removed


def test_two_workers_make_the_shards_one_worker_makes(tmp_path):
    """From the CLI with 2 workers (forked): the same shards as in-process, a clean exit."""
    config = {**PRESETS["hand-only"], "frames": 8, "frames_per_shard": 2, "frames_per_episode": 2}
    (tmp_path / "c.json").write_text(json.dumps(config))
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    run = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "generate", "--config", str(tmp_path / "c.json")]
        + ["--workers", "2", "--out", str(tmp_path / "two")],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    # Workers keep their scenes to the end and free them at exit, before OpenGL goes.
    assert "Traceback" not in run.stderr and "Exception ignored" not in run.stderr, run.stderr
    one = generate(GenerationConfig.from_mapping(config), tmp_path / "one")
    assert Manifest.read(tmp_path / "two").shards == one.shards


@pytest.mark.parametrize("preset", ["hand-only", "occlusion-heavy"])
def test_the_hand_and_objects_lie_within_the_sensors_range(tmp_path, preset):
    """No hand or object pixel is nearer than the structured-light sensor's 0.35 m (a hole).

    The camera moves back along its line of sight from draws that would bring the hand or an
    occluder nearer (with the presets' distances, before: a quarter of the hand's pixels in
    ``hand-only`` and three quarters of the occluders' in ``occlusion-heavy`` had no depth).
    """
    config = GenerationConfig.from_mapping(
        PRESETS[preset],
        frames=16,
        frames_per_shard=16,
        frames_per_episode=4,
        occlusion_buckets=None,
        paired_clean=True,
        distance_range_m=(0.3, 0.45),  # the nearest draws, the ones that would reach too near
    )
    assert config.sensor == "structured_light"
    generate(config, tmp_path)
    reader = ShardReader(tmp_path / "shard-00000.h5")
    labelled = seen = 0
    for i in range(len(reader)):
        frame = reader[i]
        mask = frame["segmentation"] >= SEGMENT_LABELS.index("palm")  # the hand and objects
        labelled += np.count_nonzero(mask)
        assert not np.any(mask & (frame["depth_clean"] < 0.35)), i
        seen += np.count_nonzero(mask & (frame["depth"] > 0))
    assert seen > 0.8 * labelled  # the rest: projector shadows, grazing angles


# Every episode's objects fail to fit with probability 1/2, decided by the episode's own
# generator (so a shard is still a function of (seed, index)); the seed gives redraws.
FAILING_PLACEMENTS = """
from handsim.data import kinematic
from handsim.world.scene import InvalidScene

_place = kinematic.sample_placements


def _sometimes_no_fit(rng, names, **kwargs):
    if rng.random() < 0.5:
        raise InvalidScene(f"could not place {names[0]!r} without overlap (test)")
    return _place(rng, names, **kwargs)
"""


def _arrays(folder):
    """Every shard's images and labels, by shard name."""
    out = {}
    for path in sorted(folder.glob("shard-*.h5")):
        reader = ShardReader(path)
        f = reader._open()
        out[path.name] = {"depth": f["depth"][()], "episode": f["episode"][()]} | {
            key: f["labels"][key][()] for key in f["labels"]
        }
        reader.close()
    return out


def test_an_episode_that_cannot_be_placed_is_redrawn_and_counted(tmp_path, monkeypatch):
    """Objects that do not fit: the episode is redrawn from the same generator and counted."""
    from handsim.data import kinematic

    namespace = {}
    exec(FAILING_PLACEMENTS, namespace)
    monkeypatch.setattr(kinematic, "sample_placements", namespace["_sometimes_no_fit"])
    config = GenerationConfig.from_mapping(TINY, frames=6)
    full = generate(config, tmp_path / "full")
    assert full.frames == 6
    per_shard = [r.redraws.get("placement", 0) for r in full.shards.values()]
    assert sum(per_shard) >= 1 and full.redraws["placement"] == sum(per_shard)
    assert Manifest.read(tmp_path / "full").redraws == full.redraws
    doc = json.loads((tmp_path / "full" / "manifest.json").read_text())
    assert doc["redraws"] == full.redraws
    # A redrawn episode keeps its index: episode numbers skip the redrawn ones.
    redrawn = next(i for i, n in enumerate(per_shard) if n)
    episodes = ShardReader(tmp_path / "full" / Manifest.shard_name(redrawn))._open()["episode"]
    assert episodes[()].min() % 1_000_000 >= 1

    # The shard with a redraw, made again alone, is the same file with the same count.
    (tmp_path / "again").mkdir()
    again = generate_shard(config, redrawn, tmp_path / "again")
    assert again == full.shards[redrawn]


def test_a_run_with_redraws_resumes_identically_after_sigkill(tmp_path):
    """SIGKILL mid-run, with episodes redrawn: the resumed dataset equals an uninterrupted one."""
    values = dict(TINY, frames=8)
    code = (
        FAILING_PLACEMENTS
        + "kinematic.sample_placements = _sometimes_no_fit\n"
        + "import sys; from handsim.data.generation import GenerationConfig, generate\n"
        + f"generate(GenerationConfig.from_mapping({values!r}), sys.argv[1])\n"
    )
    run = tmp_path / "killed"
    proc = _kill_after_the_first_shard(code, run)
    assert 1 <= len(Manifest.read(run).shards) < 4 or proc.returncode != -signal.SIGKILL
    subprocess.run([sys.executable, "-c", code, str(run)], check=True)
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "clean")], check=True)
    resumed, clean = Manifest.read(run), Manifest.read(tmp_path / "clean")
    assert resumed.shards == clean.shards and clean.redraws["placement"] >= 1
    a, b = _arrays(run), _arrays(tmp_path / "clean")
    assert a.keys() == b.keys() and len(a) == 4
    for name in a:
        for key in a[name]:
            np.testing.assert_array_equal(a[name][key], b[name][key], err_msg=f"{name} {key}")


def test_objects_that_never_fit_fail_clearly(tmp_path):
    """Six cracker boxes never fit on the table: after five tries, the error says why."""
    config = GenerationConfig.from_mapping(
        TINY, frames=1, objects=("003_cracker_box",), num_objects_range=(6, 6)
    )
    with pytest.raises(
        GenerationError,
        match=r"5 episodes in a row could not be drawn \(0 of the shard's 1 frames made\); "
        r"the last: placement: could not place '003_cracker_box'",
    ):
        generate(config, tmp_path)
    assert not list(tmp_path.glob("*.h5*"))


def test_cannot_draw_needs_a_reason_that_can_be_counted():
    """A redraw's cause is a short lowercase identifier (a manifest key)."""
    assert CannotDraw("grasp", "no grasp").reason == "grasp"
    with pytest.raises(GenerationError, match=r"lowercase identifier .*received 'No Fit'"):
        CannotDraw("No Fit", "objects overlap")


def test_a_manifest_with_malformed_redraws_is_refused(tmp_path):
    """Redraw counts are checked on reading: a negative count names the shard record."""
    generate(GenerationConfig.from_mapping(TINY, frames=2), tmp_path)
    doc = json.loads((tmp_path / "manifest.json").read_text())
    doc["shards"][0]["redraws"] = {"placement": -1}
    (tmp_path / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(InvalidManifest, match=r"a shard record is malformed .*redraws must map"):
        Manifest.read(tmp_path)


def test_the_visible_keypoint_cap_counts_only_accepted_frames():
    """floor(fraction * frames) frames below the minimum; a refused frame takes no bucket."""
    from handsim.data.generation import _Acceptor

    config = GenerationConfig.from_mapping(
        PRESETS["occlusion-heavy"], occlusion_buckets=((0.0, 0.5, 1.0), (0.5, 0.5))
    )
    accept = _Acceptor(config, 40)  # 5 % of 40: 2 frames without a visible keypoint
    assert accept.below_left == 2 and list(accept.left) == [20, 20]
    assert accept(0.9, 0) and accept(0.9, 0)
    assert not accept(0.9, 0)  # the cap is full: refused, the bucket keeps its place
    assert list(accept.left) == [20, 18]
    assert accept(0.9, 1) and list(accept.left) == [20, 17]
    assert _Acceptor(GenerationConfig.from_mapping(TINY), 40).below_left == 40  # no cap
    # 0.29 * 100 is 28.999... in floating point: still 29 frames.
    capped = GenerationConfig.from_mapping(TINY, max_fraction_below_min_visible=0.29)
    assert _Acceptor(capped, 100).below_left == 29


def test_a_shard_keeps_the_visible_keypoint_cap(tmp_path):
    """No frame with fewer than 12 visible keypoints when the cap allows none."""
    config = GenerationConfig.from_mapping(
        TINY,
        frames=4,
        frames_per_shard=4,
        min_visible_keypoints=12,
        max_fraction_below_min_visible=0.0,
    )
    generate(config, tmp_path)
    visible = ShardReader(tmp_path / "shard-00000.h5").labels("visible")
    assert visible.shape == (4, 21) and (visible.sum(axis=1) >= 12).all()


def _kinematic_frames(config, n):
    """(arrays, scene, renderer) of the first ``n`` frames of shard 0's first episode."""
    from handsim.data.kinematic import KinematicSource

    source = KinematicSource(config)
    try:
        for arrays in source.episode(
            np.random.default_rng([config.seed, 0]), lambda ratio, visible: True, n
        ):
            scene, renderer = next(reversed(source._scenes.values()))
            yield arrays, scene, renderer
    finally:
        source.close()


def test_the_backdrop_never_hides_the_hand_arm_or_objects():
    """Per frame the backdrop stands behind the hand, arm and objects.

    Rendered without it, every hand, arm and object pixel of a frame is the same; it covers
    only empty pixels or the table (a wall may cut the table), and carries the label
    ``backdrop``.
    """
    config = GenerationConfig.from_mapping(
        TINY, camera="nyu_carmine", background="torso", viewpoints=("third_person", "random")
    )
    person_or_object = SEGMENT_LABELS.index("arm")
    backdrop = SEGMENT_LABELS.index("backdrop")
    seen = 0
    for arrays, scene, renderer in _kinematic_frames(config, 6):
        labels = arrays["segmentation"]
        names = [scene.model.geom(g).name for g in range(scene.model.ngeom)]
        others = np.array([not n.startswith("backdrop") for n in names])
        alone = scene.segment(renderer._render_only(scene.data, np.flatnonzero(others)))
        mine = (alone >= person_or_object) & (labels > 0)  # labels 0: beyond the range
        np.testing.assert_array_equal(labels[mine], alone[mine])
        assert set(np.unique(alone[labels == backdrop]).tolist()) <= {0, 1}
        seen += np.count_nonzero(labels == backdrop)
    assert seen > 0


def test_the_arm_leaves_the_image():
    """In the hand-object preset's frames the arm runs out of the image.

    The arm (forearm, then the upper arm to the shoulder) reaches the image border in most
    frames (86 % of 250 frames of ``handsim generate --preset hand-object --frames 250``).
    """
    config = GenerationConfig.from_mapping(
        PRESETS["hand-object"], frames=24, frames_per_shard=24, frames_per_episode=6
    )
    arm = SEGMENT_LABELS.index("arm")
    touches = []
    for arrays, _, _ in _kinematic_frames(config, 24):
        mask = arrays["segmentation"] == arm
        touches.append(mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())
    assert np.mean(touches) >= 0.7, touches


def test_a_forearm_in_the_table_is_measured():
    """The kinematic source measures how far the (drawn only) forearm enters the table.

    Frames deeper than MAX_PENETRATION_M are redrawn. An upright hand's forearm points down
    its full length from the wrist.
    """
    from handsim.data.kinematic import KinematicSource, forearm_geom
    from handsim.hand.model import hand_params
    from handsim.hand.pose import HandPose
    from handsim.hand.skin import FOREARM_LENGTH_RATIO
    from handsim.world.scene import Scene, SceneSpec

    for side in ("right", "left"):
        scene = Scene(SceneSpec(hand=hand_params("medium", side)))
        forearm = forearm_geom(scene)
        upright = HandPose.neutral(wrist_pos=(0.0, 0.0, 0.1), wrist_rotvec=(np.pi / 2, 0, 0))
        scene.binding.set_pose(scene.data, upright)
        depth = KinematicSource._forearm_below_table_m(scene, forearm)
        # MuJoCo keeps mesh vertices in float32: 0.3 m to about 1e-8 m.
        assert depth == pytest.approx(FOREARM_LENGTH_RATIO * 0.189 - 0.1, abs=1e-7)
        scene.reset()  # palm down 0.12 m above the table: the forearm lies above it
        assert KinematicSource._forearm_below_table_m(scene, forearm) == 0.0


def test_a_second_run_into_a_folder_being_written_is_refused(tmp_path):
    """The folder is held (flock) by its run: another run into it stops with a clear error."""
    import fcntl

    from handsim.data.generation import LOCK_NAME

    tmp_path.mkdir(exist_ok=True)
    with open(tmp_path / LOCK_NAME, "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(GenerationError, match=r"another `handsim generate` is writing into"):
            generate(GenerationConfig.from_mapping(TINY, frames=1), tmp_path)
    # Released with its holder (a killed run leaves no stale lock): the folder is usable.
    assert generate(GenerationConfig.from_mapping(TINY, frames=1), tmp_path).frames == 1


def _children(pid):
    """Every descendant pid of ``pid`` (Linux /proc)."""
    found, todo = set(), [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").glob("*"):
            try:
                kids = (task / "children").read_text().split()
            except OSError:
                continue
            for kid in map(int, kids):
                if kid not in found:
                    found.add(kid)
                    todo.append(kid)
    return found


def _alive(pid):
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal is Linux's")
def test_killing_the_generating_process_ends_its_workers(tmp_path):
    """SIGKILL of `generate` alone (not its group): its workers end with it."""
    values = dict(TINY, frames=40, frames_per_shard=10)
    code = (
        "import sys; from handsim.data.generation import GenerationConfig, generate\n"
        f"generate(GenerationConfig.from_mapping({values!r}), sys.argv[1], workers=2)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code, str(tmp_path / "d")])
    deadline = time.monotonic() + 120
    workers = set()
    while time.monotonic() < deadline and proc.poll() is None:
        workers = {p for p in _children(proc.pid) if _alive(p)}
        if len(workers) >= 2 and list((tmp_path / "d").glob("*.partial")):
            break
        time.sleep(0.05)
    assert proc.poll() is None and len(workers) >= 2
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(p) for p in workers):
        time.sleep(0.05)
    assert not [p for p in workers if _alive(p)]  # the shard workers and the resource tracker


# Shards sized to the job, workers that pay off ----------------------------------------------


@pytest.mark.parametrize(
    ("frames", "size", "shards"),
    [
        (1, 1, 1),
        (250, 250, 1),
        (251, 63, 4),
        (600, 150, 4),
        (999, 250, 4),
        (1000, 250, 4),
        (10**6, 250, 4000),
    ],  # fmt: skip
)
def test_the_default_shard_size_is_sized_to_the_job(frames, size, shards):
    """One shard up to 250 frames, else at least 4 of at most 250: the frames alone decide."""
    from handsim.data.config import auto_frames_per_shard

    config = GenerationConfig(frames=frames)
    assert config.frames_per_shard is None and auto_frames_per_shard(frames) == size
    assert config.shard_size == size and config.num_shards == shards
    assert sum(config.shard_frames(i) for i in range(shards)) == frames
    assert GenerationConfig(frames=frames, frames_per_shard=7).shard_size == 7


def test_the_manifest_records_the_shard_size_and_a_resumed_run_keeps_it(tmp_path):
    """A run records its shard size; rerun without one, it keeps the recorded size.

    Another explicit size would make other shards (another dataset): refused.
    """
    values = dict(TINY, frames=5, frames_per_shard=2)
    made = generate(GenerationConfig.from_mapping(values), tmp_path / "d")
    assert made.config["frames_per_shard"] == 2 and len(made.shards) == 3
    auto = dict(values, frames_per_shard=None)
    assert GenerationConfig.from_mapping(auto).shard_size == 5  # the job's size: one shard
    again = generate(GenerationConfig.from_mapping(auto), tmp_path / "d")
    assert again.shards == made.shards and again.config["frames_per_shard"] == 2
    fresh = generate(GenerationConfig.from_mapping(auto), tmp_path / "fresh")
    assert fresh.config["frames_per_shard"] == 5 and len(fresh.shards) == 1
    with pytest.raises(InvalidGenerationConfig, match=r"fields differ: frames_per_shard"):
        generate(GenerationConfig.from_mapping(dict(values, frames_per_shard=3)), tmp_path / "d")


def test_two_workers_report_progress_per_frame(tmp_path):
    """With workers, progress counts frames as they are written, not whole shards."""
    values = dict(TINY, frames=80, frames_per_shard=40, frames_per_episode=10)
    seen = []
    made = generate(
        GenerationConfig.from_mapping(values),
        tmp_path / "d",
        workers=2,
        progress=lambda done, total: seen.append((done, total)),
    )
    assert made.frames == 80
    done = [d for d, _ in seen]
    assert {t for _, t in seen} == {80} and done == sorted(done) and done[-1] == 80
    # Values between the shards' boundaries: frames of shards still in progress.
    assert set(done) - {0, 40, 80}, done


def test_workers_fork_only_when_it_is_safe():
    """Forked workers (imports inherited) from a one-thread process without OpenGL; else spawn.

    Checked in a fresh process: before anything renders; with a second thread running; after
    MuJoCo's EGL display exists (a GPU driver's EGL state does not survive a fork).
    """
    code = (
        "import os, threading, time\n"
        "import handsim.data.generation as g\n"
        "print(g._start_method())\n"
        "t = threading.Thread(target=time.sleep, args=(0.5,)); t.start()\n"
        "print(g._start_method()); t.join()\n"
        "import mujoco.egl\n"
        "mujoco.egl.EGL_DISPLAY = object()  # as after a first render\n"
        "print(g._start_method())\n"
    )
    env = {**os.environ, "MUJOCO_GL": "egl"}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    )
    assert out.stdout.split() == ["fork", "spawn", "spawn"]


def test_the_parent_loads_before_forking_what_every_worker_needs():
    """Before forking, the parent sets numba up and imports the hand's and sensor's modules.

    Forked workers inherit them instead of each importing them on its first frame; the
    warm-up makes no OpenGL display, so forking stays safe after it.
    """
    code = (
        "import sys\n"
        "import handsim.data.generation as g\n"
        "names = ('cv2', 'scipy.spatial.transform', 'numba')\n"
        "print([n in sys.modules for n in names])\n"
        "g._warm_up_for_fork()\n"
        "print([n in sys.modules for n in names])\n"
        "print(g._start_method())\n"
    )
    env = {**os.environ, "MUJOCO_GL": "egl"}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    )
    assert out.stdout.splitlines() == [
        "[False, False, True]",
        "[True, True, True]",
        "fork",
    ]
