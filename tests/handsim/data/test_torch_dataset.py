"""Tests of handsim.data.torch_dataset: random access, filters, splits, DataLoader workers."""

import numpy as np
import pytest

from handsim.data.generation import GenerationConfig, generate
from handsim.data.shards import ShardReader
from handsim.data.torch_dataset import HandSimDataset, InvalidDatasetQuery

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def dataset_folder(tmp_path_factory):
    """Six frames in three shards: a tomato soup can or a mug, one per episode."""
    folder = tmp_path_factory.mktemp("ds")
    config = GenerationConfig.from_mapping(
        {
            "frames": 6,
            "frames_per_shard": 2,
            "frames_per_episode": 1,
            "sensor": "none",
            "num_objects_range": (1, 1),
            "objects": ("005_tomato_soup_can", "025_mug"),
        }
    )
    generate(config, folder)
    return folder


def test_samples_are_the_shards_frames_as_tensors(dataset_folder):
    """Sample i is frame i in shard order, depth with a channel axis."""
    data = HandSimDataset(dataset_folder)
    assert len(data) == 6
    sample = data[3]
    frame = ShardReader(dataset_folder / "shard-00001.h5")[1]
    assert sample["depth"].shape == (1, 240, 320) and sample["depth"].dtype == torch.float32
    np.testing.assert_array_equal(sample["depth"][0].numpy(), frame["depth"])
    np.testing.assert_array_equal(sample["keypoints_cam"].numpy(), frame["keypoints_cam"])
    assert sample["segmentation"].dtype == torch.int64
    with pytest.raises(IndexError, match="out of range: the dataset has 6"):
        data[6]


def test_filters_and_splits_partition_the_frames(dataset_folder):
    """Splits partition the frames by episode; object and occlusion filters keep what they say."""
    sizes = [len(HandSimDataset(dataset_folder, split=s)) for s in ("train", "val", "test")]
    assert sizes == [4, 1, 1]  # six one-frame episodes: one each for val and test
    mugs = HandSimDataset(dataset_folder, objects=["mug"])
    cans = HandSimDataset(dataset_folder, objects=["tomato_soup_can"])
    assert len(mugs) + len(cans) == 6
    assert all(14 in mugs[i]["object_ycbv_id"].tolist() for i in range(len(mugs)))
    assert len(HandSimDataset(dataset_folder, sensors=["tof"])) == 0
    assert len(HandSimDataset(dataset_folder, occlusion_range=(0.0, 1.0))) == 6


def test_dataloader_with_two_workers_sees_every_sample_once(dataset_folder):
    """Each worker opens its own files; the batches hold every frame exactly once."""
    data = HandSimDataset(
        dataset_folder, transform=lambda s: {"step": s["step"], "ep": s["episode"]}
    )
    loader = torch.utils.data.DataLoader(data, batch_size=2, num_workers=2)
    seen = sorted(int(e) for batch in loader for e in batch["ep"])
    expected = sorted(int(data[i]["ep"]) for i in range(len(data)))
    assert seen == expected


def test_bad_queries_say_what_is_valid(dataset_folder, tmp_path):
    """Unknown splits, objects, ranges and non-dataset folders are named."""
    with pytest.raises(InvalidDatasetQuery, match="split must be one of train, val, test, all"):
        HandSimDataset(dataset_folder, split="dev")
    with pytest.raises(InvalidDatasetQuery, match="unknown object 'spoon'"):
        HandSimDataset(dataset_folder, objects=["spoon"])
    with pytest.raises(InvalidDatasetQuery, match=r"occlusion_range must be \(low, high\)"):
        HandSimDataset(dataset_folder, occlusion_range=(0.5, 0.1))
    with pytest.raises(InvalidDatasetQuery, match="has no manifest.json"):
        HandSimDataset(tmp_path)


def test_batched_reads_equal_single_reads_and_block_batches_cover_every_sample(dataset_folder):
    """__getitems__ (DataLoader's batch fetch) gives data[i] for each i, whatever the order."""
    data = HandSimDataset(dataset_folder)
    for indices in ([0, 1, 2, 3, 4, 5], [5, 0, 3], [4]):
        for batched, i in zip(data.__getitems__(indices), indices, strict=True):
            single = data[i]
            assert batched.keys() == single.keys()
            for key in single:
                np.testing.assert_array_equal(
                    batched[key].numpy(), single[key].numpy(), err_msg=key
                )
    sampler = data.batch_sampler(4, block_size=2, seed=1)
    epochs = [list(sampler), list(sampler)]
    assert len(sampler) == 2 and all(len(e) == 2 for e in epochs)
    for batches in epochs:
        assert sorted(i for b in batches for i in b) == list(range(6))
        assert all(b[k + 1] == b[k] + 1 for b in batches for k in range(0, len(b) - 1, 2))
    loader = torch.utils.data.DataLoader(
        HandSimDataset(dataset_folder, keys=("depth", "keypoints_px", "episode")),
        batch_sampler=data.batch_sampler(4),
        num_workers=2,
    )
    batches = list(loader)
    assert {k for b in batches for k in b} == {"depth", "keypoints_px", "episode"}
    assert sum(len(b["depth"]) for b in batches) == 6 and batches[0]["depth"].shape[1:] == (
        1,
        240,
        320,
    )
    with pytest.raises(InvalidDatasetQuery, match="keys must be a list drawn from"):
        HandSimDataset(dataset_folder, keys=("dpeth",))
    with pytest.raises(InvalidDatasetQuery, match="batch_size must be an integer >= 1"):
        data.batch_sampler(0)


def test_the_loader_batches_equal_collated_samples(dataset_folder):
    """dataset.loader(): collate-free batches equal default_collate of the samples."""
    data = HandSimDataset(dataset_folder, keys=("depth", "segmentation", "keypoints_px", "step"))
    batches = list(data.loader(4, block_size=2, seed=3, num_workers=2))
    order = list(data.batch_sampler(4, block_size=2, seed=3))
    assert len(batches) == len(order) == 2
    for batch, indices in zip(batches, order, strict=True):
        expected = torch.utils.data.default_collate([data[i] for i in indices])
        assert batch.keys() == expected.keys()
        for key in expected:
            assert batch[key].dtype == expected[key].dtype
            np.testing.assert_array_equal(batch[key].numpy(), expected[key].numpy(), err_msg=key)
    with_transform = HandSimDataset(dataset_folder, transform=lambda s: {"ep": s["episode"]})
    assert with_transform.batch([0, 5])["ep"].shape == (2, 1)


def test_a_batch_is_one_buffer_equal_to_the_collated_samples(dataset_folder):
    """batch(): every key as default_collate would give it, all views of one storage."""
    data = HandSimDataset(dataset_folder)
    indices = [4, 5, 0, 2]  # a run of two frames, a frame, a frame of another shard
    batch = data.batch(indices)
    expected = torch.utils.data.default_collate([data[i] for i in indices])
    assert batch.keys() == expected.keys()
    for key in expected:
        assert batch[key].dtype == expected[key].dtype, key
        np.testing.assert_array_equal(batch[key].numpy(), expected[key].numpy(), err_msg=key)
    # One storage: a worker sends the batch as one shared-memory segment.
    assert len({t.untyped_storage().data_ptr() for t in batch.values()}) == 1


def test_a_batch_across_folders_with_and_without_an_image_is_an_error(dataset_folder, tmp_path):
    """A key some shards lack (paired clean depth) cannot be stacked: the error names it."""
    config = GenerationConfig.from_mapping(
        {"frames": 1, "sensor": "none", "num_objects_range": (0, 0), "paired_clean": True}
    )
    generate(config, tmp_path / "clean")
    data = HandSimDataset([tmp_path / "clean", dataset_folder])
    assert data.batch([0])["depth_clean"].shape == (1, 1, 240, 320)
    with pytest.raises(InvalidDatasetQuery, match="mixes shards with and without 'depth_clean'"):
        data.batch([0, 1])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"depth_scale_mm": -1}, r"depth_scale_mm must be a number in \[0.001, 10\].*-1"),
        ({"depth_scale_mm": "abc"}, r"depth_scale_mm must be a number .*'abc'"),
        ({"image_shape": [240]}, r"image_shape must be \[height, width\]"),
        ({"config": [1, 2]}, r"config must be a mapping"),
        ({"frames": "2"}, r"a shard record is malformed .*frames must be an integer >= 1"),
        ({"frames": 0}, r"frames must be an integer >= 1; received 0"),
    ],
)
def test_a_tampered_manifest_is_refused_with_the_field(dataset_folder, tmp_path, change, message):
    """Every manifest field is checked on reading: no silent wrong depth scale or shape."""
    import json
    import shutil

    from handsim.data.manifest import InvalidManifest, Manifest

    folder = tmp_path / "ds"
    shutil.copytree(dataset_folder, folder)
    doc = json.loads((folder / "manifest.json").read_text())
    if "frames" in change:
        doc["shards"][0]["frames"] = change["frames"]
    else:
        doc.update(change)
    (folder / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(InvalidManifest, match=message):
        Manifest.read(folder)
    with pytest.raises(InvalidDatasetQuery, match=message):
        HandSimDataset(folder)


def test_a_manifest_that_miscounts_a_shard_is_refused(dataset_folder, tmp_path):
    """A record that says 1 frame for a shard of 2: the Dataset names the shard, never serves 2."""
    import json
    import shutil

    folder = tmp_path / "ds"
    shutil.copytree(dataset_folder, folder)
    doc = json.loads((folder / "manifest.json").read_text())
    doc["shards"][0]["frames"] = 1
    (folder / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(
        InvalidDatasetQuery,
        match=r"shard-00000.h5 holds 2 frames but the manifest says 1: .*handsim dataset check",
    ):
        HandSimDataset(folder)
