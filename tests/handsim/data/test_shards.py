"""Tests of handsim.data.shards: crash-safe writing, exact read-back, corruption found and named."""

import numpy as np
import pytest

from handsim.data.arrays import DRAW_LABEL_SCHEMA, LABEL_SCHEMA
from handsim.data.shards import (
    PARTIAL_SUFFIX,
    InvalidShard,
    ShardReader,
    ShardWriter,
    check_shard,
    file_sha256,
)
from handsim.frame import FrameRenderer
from handsim.hand.pose_sources import gesture
from handsim.world.scene import ObjectPlacement, Scene, SceneSpec
from handsim.world.sensors import StructuredLight


@pytest.fixture(scope="module")
def frame_arrays():
    """Arrays (images included, clean depth kept) of three noisy frames of a hand over a can."""
    scene = Scene(SceneSpec(objects=(ObjectPlacement("005_tomato_soup_can", (0.0, 0.0, 0.051)),)))
    rng = np.random.default_rng(0)
    out = []
    with FrameRenderer(scene, "third_person", StructuredLight()) as renderer:
        for z in (0.3, 0.2, 0.12):
            pose = gesture("open").replace(
                wrist_pos=np.array([0.0, -0.07, z]), wrist_rotvec=np.array([0.0, np.pi, 0.0])
            )
            scene.reset(pose)
            out.append(renderer.render(rng, keep_clean=True).to_arrays(images=True))
    return out


def _write(path, frames, **kwargs):
    shape = frames[0]["depth"].shape
    with ShardWriter(path, image_shape=shape, **kwargs) as writer:
        for step, arrays in enumerate(frames):
            writer.append(arrays, episode=7, step=step)
    return writer.info


def test_round_trip_labels_exact_depth_within_half_a_unit(tmp_path, frame_arrays):
    """Labels come back bit-exact; depth within depth_scale / 2; zeros stay zeros."""
    info = _write(tmp_path / "s.h5", frame_arrays, paired_clean=True)
    assert info.frames == 3 and info.name == "s.h5"
    assert info.sha256 == file_sha256(tmp_path / "s.h5")
    reader = ShardReader(tmp_path / "s.h5")
    assert len(reader) == 3 and reader.has_clean
    for i, arrays in enumerate(frame_arrays):
        back = reader[i]
        for key in LABEL_SCHEMA:
            np.testing.assert_array_equal(back[key], arrays[key], err_msg=key)
            assert back[key].dtype == arrays[key].dtype
        for key in ("depth", "depth_clean"):
            d = arrays[key]
            assert back[key].dtype == np.float32
            assert np.abs(back[key] - d).max() <= 0.5 * 0.1e-3 + 1e-7
            np.testing.assert_array_equal(back[key] == 0, d == 0)
        np.testing.assert_array_equal(back["segmentation"], arrays["segmentation"])
        assert back["episode"] == 7 and back["step"] == i
    np.testing.assert_array_equal(reader.labels("step"), [0, 1, 2])
    assert reader[-1]["step"] == 2


def test_image_chunks_are_zlib_streams_hdf5s_gzip_filter_declares(tmp_path, frame_arrays):
    """Each image is one chunk, a zlib stream (what any HDF5 reader's gzip filter inflates)."""
    import zlib

    import h5py

    _write(tmp_path / "s.h5", frame_arrays, paired_clean=True)
    with h5py.File(tmp_path / "s.h5") as f:
        for key in ("depth", "depth_clean", "segmentation"):
            dataset = f[key]
            assert dataset.compression == "gzip" and not dataset.shuffle
            assert dataset.chunks == (1, *dataset.shape[1:])
            for i in range(len(frame_arrays)):
                mask, chunk = dataset.id.read_direct_chunk((i, 0, 0))
                assert mask == 0  # the filter applied
                image = np.frombuffer(zlib.decompress(chunk), dtype=dataset.dtype)
                np.testing.assert_array_equal(image.reshape(dataset.shape[1:]), dataset[i])


def test_depth_scale_sets_the_unit_and_the_range(tmp_path, frame_arrays):
    """With 1 mm units the error is <= 0.5 mm; depth past 65535 units is stored as none."""
    arrays = dict(frame_arrays[0])
    depth = arrays["depth"].copy()
    depth[0, :4] = (70.0, np.inf, np.nan, -1.0)
    arrays["depth"] = depth
    _write(tmp_path / "s.h5", [arrays], depth_scale_mm=1.0)
    back = ShardReader(tmp_path / "s.h5")[0]["depth"]
    np.testing.assert_array_equal(back[0, :4], 0.0)
    ok = np.isfinite(depth) & (depth >= 0) & (depth < 65.0)
    assert np.abs(back[ok] - depth[ok]).max() <= 0.5e-3 + 1e-6


def test_an_interrupted_shard_never_gets_its_final_name(tmp_path, frame_arrays):
    """While writing only the partial file exists; an exception deletes it."""
    path = tmp_path / "s.h5"
    with pytest.raises(RuntimeError, match="killed"):
        with ShardWriter(path, image_shape=frame_arrays[0]["depth"].shape) as writer:
            writer.append(frame_arrays[0], episode=0, step=0)
            assert (tmp_path / ("s" + PARTIAL_SUFFIX)).exists() and not path.exists()
            raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []


def test_check_finds_and_names_bad_shards(tmp_path, frame_arrays):
    """Truncated, overwritten, foreign and missing files are named; a sound shard passes."""
    info = _write(tmp_path / "good.h5", frame_arrays)
    assert check_shard(tmp_path / "good.h5", info) == []
    data = (tmp_path / "good.h5").read_bytes()
    (tmp_path / "cut.h5").write_bytes(data[: len(data) // 2])
    (problem,) = check_shard(tmp_path / "cut.h5")
    assert problem.startswith("cut.h5: ")
    flipped = bytearray(data)
    flipped[len(data) // 2 : len(data) // 2 + 64] = bytes(64)
    (tmp_path / "flip.h5").write_bytes(bytes(flipped))
    problems = check_shard(tmp_path / "flip.h5", info)
    assert problems and problems[0] == "flip.h5: checksum differs from the manifest (corrupt)"
    (tmp_path / "junk.h5").write_bytes(np.random.default_rng(0).bytes(4096))
    assert "not a readable HDF5 file" in check_shard(tmp_path / "junk.h5")[0]
    assert check_shard(tmp_path / "none.h5") == ["none.h5: missing"]


def test_writer_and_reader_errors_say_what_is_valid(tmp_path, frame_arrays):
    """Bad paths, shapes, scales, frames and indices raise InvalidShard naming the problem."""
    shape = frame_arrays[0]["depth"].shape
    with pytest.raises(InvalidShard, match=r"must end in '\.h5'"):
        ShardWriter(tmp_path / "s.hdf5", image_shape=shape)
    with pytest.raises(InvalidShard, match=r"image_shape must be \(H, W\)"):
        ShardWriter(tmp_path / "s.h5", image_shape=(0, 10))
    with pytest.raises(InvalidShard, match=r"depth_scale_mm must be a number in \[0.001, 10\]"):
        ShardWriter(tmp_path / "s.h5", image_shape=shape, depth_scale_mm=float("nan"))
    with ShardWriter(tmp_path / "s.h5", image_shape=shape, paired_clean=True) as writer:
        labels_only = {k: v for k, v in frame_arrays[0].items() if k in LABEL_SCHEMA}
        with pytest.raises(InvalidShard, match=r"lack depth, segmentation, depth_clean"):
            writer.append(labels_only, episode=0, step=0)
        small = dict(frame_arrays[0], depth=np.zeros((4, 4), np.float32))
        with pytest.raises(InvalidShard, match="depth must be a float array of shape"):
            writer.append(small, episode=0, step=0)
        writer.append(frame_arrays[0], episode=0, step=0)
    with pytest.raises(InvalidShard, match="already closed"):
        writer.close()
    reader = ShardReader(tmp_path / "s.h5")
    with pytest.raises(InvalidShard, match="frame 5 is out of range: s.h5 has 1 frames"):
        reader[5]
    with pytest.raises(InvalidShard, match="unknown label 'pose'"):
        reader.labels("pose")
    (tmp_path / "x.h5").write_bytes(b"")
    with pytest.raises(InvalidShard, match="not a readable HDF5 file"):
        ShardReader(tmp_path / "x.h5")


def test_read_block_can_give_the_images_as_stored(tmp_path):
    """stored=True: depth in uint16 units and uint8 labels, which convert to the default block."""
    from handsim.data.generation import GenerationConfig, generate

    config = GenerationConfig.from_mapping(
        {"frames": 3, "sensor": "none", "num_objects_range": (1, 1), "paired_clean": True}
    )
    generate(config, tmp_path)
    reader = ShardReader(tmp_path / "shard-00000.h5")
    stored, block = reader.read_block(0, 3, stored=True), reader.read_block(0, 3)
    assert stored["depth"].dtype == stored["depth_clean"].dtype == np.uint16
    assert stored["segmentation"].dtype == np.uint8
    scale = np.float32(reader.depth_scale_mm / 1000.0)
    for key in ("depth", "depth_clean"):
        np.testing.assert_array_equal(stored[key] * scale, block[key])
    np.testing.assert_array_equal(stored["segmentation"], block["segmentation"])
    np.testing.assert_array_equal(stored["keypoints_cam"], block["keypoints_cam"])


def test_draw_labels_are_stored_and_old_shards_read_minus_one(tmp_path, frame_arrays):
    """pose_source and viewpoint are stored when given, -1 when not.

    A shard written before them reads -1 for every frame.
    """
    import h5py

    given = [{**a, "pose_source": np.int8(4), "viewpoint": np.int8(1)} for a in frame_arrays]
    _write(tmp_path / "given.h5", given[:2] + frame_arrays[2:])
    reader = ShardReader(tmp_path / "given.h5")
    np.testing.assert_array_equal(reader.labels("pose_source"), [4, 4, -1])
    np.testing.assert_array_equal(reader.labels("viewpoint"), [1, 1, -1])
    assert reader[0]["pose_source"] == 4 and reader[0]["pose_source"].dtype == np.int8
    reader.close()
    _write(tmp_path / "old.h5", frame_arrays)
    with h5py.File(tmp_path / "old.h5", "a") as f:
        for key in DRAW_LABEL_SCHEMA:
            del f["labels"][key]
    assert check_shard(tmp_path / "old.h5") == []
    reader = ShardReader(tmp_path / "old.h5")
    for key, (_, dtype, _) in DRAW_LABEL_SCHEMA.items():
        labels = reader.labels(key)
        assert labels.dtype == dtype
        np.testing.assert_array_equal(labels, [-1, -1, -1])
        assert reader[1][key] == -1


def test_a_shard_written_before_visible_sensor_reads_with_it_filled(tmp_path, frame_arrays):
    """An older shard (no labels/visible_sensor) is sound and reads visible_sensor = visible."""
    import h5py

    from handsim.frame import Frame

    _write(tmp_path / "old.h5", frame_arrays)
    with h5py.File(tmp_path / "old.h5", "r+") as f:
        del f["labels/visible_sensor"]
    assert check_shard(tmp_path / "old.h5") == []
    reader = ShardReader(tmp_path / "old.h5")
    for i, arrays in enumerate(frame_arrays):
        back = reader[i]
        np.testing.assert_array_equal(back["visible_sensor"], arrays["visible"])
        assert back["visible_sensor"].dtype == np.bool_
        Frame.from_arrays(back)  # the Frame of older data reads too
    np.testing.assert_array_equal(
        reader.labels("visible_sensor"), np.stack([a["visible"] for a in frame_arrays])
    )


def test_a_damaged_chunk_is_named_when_read(tmp_path, frame_arrays):
    """Flipped bytes in the depth's compressed chunk: reading names the shard and the check.

    h5py's own error ("filter returned failure") names no file; the reader's does, for a
    frame, a block of frames and the labels alike.
    """
    import h5py

    path = tmp_path / "damaged.h5"
    _write(path, frame_arrays)
    with h5py.File(path, "r") as f:
        chunk = f["depth"].id.get_chunk_info(0)
        labels = f["labels"]["keypoints_cam"].id.get_chunk_info(0)
    data = bytearray(path.read_bytes())
    for where in (chunk, labels):
        middle = where.byte_offset + where.size // 2
        data[middle : middle + 32] = bytes(32)
    path.write_bytes(bytes(data))
    reader = ShardReader(path)
    message = r"damaged.h5 cannot be read .*the shard is damaged; run `handsim dataset check`"
    with pytest.raises(InvalidShard, match=message):
        reader[0]
    with pytest.raises(InvalidShard, match=message):
        reader.read_block(0, 2)
    with pytest.raises(InvalidShard, match=message):
        reader.labels("keypoints_cam")
    reader.close()
