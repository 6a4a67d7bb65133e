"""The on-disk dataset: what a shard stores comes back, byte-identical writes, clear errors."""

from __future__ import annotations

import json
import os
import pickle
import zipfile

import numpy as np
import pytest

from datagen.dataset import open_dataset
from datagen.labels import distance_field
from datagen.shards import (DatasetError, member_names, read_dataset_info,
                            remove_stale_temporaries, shard_complete, write_dataset_info,
                            write_shard)
from frontiernet.errors import InputError

H, W = 24, 32
PNG = {"rgb_format": "png", "jpg_quality": 95}


def make_sample(seed: int, scene: str = "test:a") -> dict:
    rng = np.random.default_rng(seed)
    depth = rng.uniform(0.2, 6.0, (H, W)).astype(np.float32)
    depth[:3, :5] = np.nan
    frontier = np.zeros((H, W), bool)
    frontier[5 + seed % 4, 3:20] = True
    gain = rng.uniform(0, 30, (H, W)).astype(np.float32)
    return {
        "rgb": rng.integers(0, 256, (H, W, 3), dtype=np.uint8),
        "depth": depth,
        "frontier_mask": frontier,
        "frontier_projected": rng.random((H, W)) < 0.2,
        "discontinuity": rng.random((H, W)) < 0.1,
        "gain": gain,
        "gain_class": rng.integers(0, 11, (H, W)),
        "record": {"scene": scene, "T_world_cam": np.eye(4) + seed, "K": [[300, 0, 16], [0, 300, 12],
                                                                          [0, 0, 1]],
                   "width": W, "height": H, "view": "uniform", "frontier_pixels": int(frontier.sum())},
    }


def make_dataset(root, shards=(("00000-a", "test:a", 3), ("00001-b", "test:b", 2)), conf=PNG,
                 truncation_px=7.0):
    write_dataset_info(root, {"generator_version": "1", "seed": 0, "scenes": [s[1] for s in shards],
                              "config": {"ground_truth": {"truncation_px": truncation_px}}})
    (root / "shards").mkdir(exist_ok=True)
    samples = {}
    for name, scene, count in shards:
        samples[name] = [make_sample(10 * len(samples) + j, scene) for j in range(count)]
        write_shard(root / "shards" / f"{name}.zip", samples[name], {"scene": scene}, conf)
    return samples


def test_round_trip_keeps_every_array_and_the_camera(tmp_path):
    samples = make_dataset(tmp_path)
    ds = open_dataset(tmp_path)
    assert len(ds) == 5 and ds.info["seed"] == 0 and ds.info["format"] == "frontiernet-dataset"
    expected = samples["00000-a"][1]
    got = ds[1]
    assert got["rgb"].dtype == np.uint8 and got["rgb"].shape == (H, W, 3)
    np.testing.assert_array_equal(got["rgb"], expected["rgb"])
    assert got["depth"].dtype == np.float32 and got["depth"].shape == (H, W)
    invalid = np.isnan(expected["depth"])
    np.testing.assert_array_equal(np.isnan(got["depth"]), invalid)
    assert np.abs(got["depth"][~invalid] - expected["depth"][~invalid]).max() <= 0.0005 + 1e-6
    for name in ("frontier_mask", "frontier_projected", "discontinuity"):
        assert got[name].dtype == bool and got[name].shape == (H, W)
        np.testing.assert_array_equal(got[name], expected[name])
    assert got["gain"].dtype == np.float32
    np.testing.assert_array_equal(got["gain"], expected["gain"])
    assert got["gain_class"].dtype == np.int64
    np.testing.assert_array_equal(got["gain_class"], expected["gain_class"])
    field = got["distance_field"]
    assert field.dtype == np.float32 and field.shape == (H, W)
    assert np.all(field[expected["frontier_mask"]] == 0) and field.max() == 7.0  # dataset.json's r
    np.testing.assert_array_equal(field, distance_field(expected["frontier_mask"], 7.0))
    assert got["K"].dtype == np.float64 and got["K"].shape == (3, 3) and got["K"][0, 0] == 300
    np.testing.assert_array_equal(got["T_world_cam"], np.eye(4) + 1)
    assert (got["scene"], got["index"], got["shard"], got["key"]) == ("test:a", 1, "00000-a.zip",
                                                                       "000001")
    assert got["record"]["view"] == "uniform" and got["record"]["frontier_pixels"] > 0


def test_far_depth_round_trips_and_old_shards_read_without_it(tmp_path):
    """What a monocular network sees past the sensor's range (datagen's far_depth) is stored to the
    millimetre; shards written without it read as None, and a shard is all or nothing."""
    plain = make_sample(0)
    with_far = [dict(make_sample(j), far_depth=np.where(np.arange(W) < 10, np.float32(4.0 + j), np.nan)
                     * np.ones((H, 1), np.float32)) for j in range(2)]
    write_dataset_info(tmp_path, {"generator_version": "1", "seed": 0, "scenes": ["test:a"], "config": {}})
    write_shard(tmp_path / "shards" / "00000-a.zip", with_far, {"scene": "test:a"}, PNG)
    write_shard(tmp_path / "shards" / "00001-a.zip", [plain], {"scene": "test:a"}, PNG)
    ds = open_dataset(tmp_path)
    far = ds[1]["far_depth"]
    assert far.dtype == np.float32 and np.isnan(far[:, 10:]).all()
    assert np.abs(far[:, :10] - 5.0).max() <= 0.0005
    assert ds[2]["far_depth"] is None
    assert shard_complete(tmp_path / "shards" / "00000-a.zip")
    with zipfile.ZipFile(tmp_path / "shards" / "00000-a.zip") as archive:
        assert "000000/far_depth.png" in archive.namelist()
    with pytest.raises(ValueError, match="all or none"):
        write_shard(tmp_path / "mixed.zip", [with_far[0], plain], {"scene": "test:a"}, PNG)


def test_records_scenes_negative_index_and_scene_split(tmp_path):
    make_dataset(tmp_path)
    ds = open_dataset(tmp_path)
    assert ds.scenes == ["test:a", "test:b"]
    assert [(r["shard"], r["key"]) for r in ds.records][2:4] == [("00000-a.zip", "000002"),
                                                                  ("00001-b.zip", "000000")]
    assert ds[-1]["index"] == 4 and ds[-1]["key"] == "000001" and ds[-1]["scene"] == "test:b"
    with pytest.raises(IndexError):
        ds[5]
    with pytest.raises(IndexError):
        ds[-6]
    assert ds.indices_for_scenes(["test:b"]) == [3, 4]
    assert ds.indices_for_scenes("test:a") == [0, 1, 2]
    with pytest.raises(InputError, match="test:typo"):
        ds.indices_for_scenes(["test:typo"])
    val = ds.subset(ds.indices_for_scenes(["test:b"]))
    assert len(val) == 2 and val.scenes == ["test:b"] and val[0]["shard"] == "00001-b.zip"


def test_identical_inputs_give_byte_identical_shards(tmp_path):
    samples = [make_sample(j) for j in range(3)]
    first = write_shard(tmp_path / "first.zip", samples, {"scene": "test:a", "seed": 3}, PNG)
    second = write_shard(tmp_path / "second.zip", samples, {"seed": 3, "scene": "test:a"}, PNG)
    assert first.read_bytes() == second.read_bytes()
    with zipfile.ZipFile(first) as archive:
        names = archive.namelist()
    assert names == member_names("000000") + member_names("000001") + member_names("000002") + \
        ["meta.json"]


def test_single_shard_opens_alone_with_default_truncation(tmp_path):
    path = write_shard(tmp_path / "lone.zip", [make_sample(0)], {}, PNG)
    ds = open_dataset(path)
    assert len(ds) == 1 and ds.info == {} and ds.shards == [path]
    assert ds[0]["distance_field"].max() == 10.0


def test_jpg_option_is_lossy_but_close(tmp_path):
    sample = make_sample(0)
    sample["rgb"] = np.repeat(np.linspace(0, 255, W, dtype=np.uint8)[None, :, None], H, 0).repeat(3, 2)
    path = write_shard(tmp_path / "jpg.zip", [sample], {}, {"rgb_format": "jpg", "jpg_quality": 90})
    assert "000000/rgb.jpg" in zipfile.ZipFile(path).namelist() and shard_complete(path)
    rgb = open_dataset(path)[0]["rgb"]
    assert rgb.shape == (H, W, 3) and rgb.dtype == np.uint8
    assert np.abs(rgb.astype(int) - sample["rgb"]).mean() < 3


def test_bad_writer_input_is_refused(tmp_path):
    far = make_sample(0)
    far["depth"][0, 0] = 70.0
    with pytest.raises(ValueError, match="65.535"):
        write_shard(tmp_path / "far.zip", [far], {}, PNG)
    with pytest.raises(InputError, match="rgb_format"):
        write_shard(tmp_path / "bmp.zip", [make_sample(0)], {}, {"rgb_format": "bmp"})
    no_pose = make_sample(0)
    del no_pose["record"]["K"]
    with pytest.raises(ValueError, match="K"):
        write_shard(tmp_path / "nok.zip", [no_pose], {}, PNG)
    assert list(tmp_path.iterdir()) == []  # nothing half-written, no temporaries


def test_leftover_temporary_is_ignored_then_removed(tmp_path):
    make_dataset(tmp_path)
    shard_dir = tmp_path / "shards"
    (shard_dir / "00002-c.zip.tmp-12345").write_bytes(b"PK\x03\x04 half a shard")
    assert len(open_dataset(tmp_path)) == 5
    assert remove_stale_temporaries(shard_dir) == 1
    assert sorted(p.name for p in shard_dir.iterdir()) == ["00000-a.zip", "00001-b.zip"]
    assert remove_stale_temporaries(shard_dir) == 0


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_corrupt_shard_is_named_at_open(tmp_path, damage):
    make_dataset(tmp_path)
    shard = tmp_path / "shards" / "00001-b.zip"
    data = shard.read_bytes()
    shard.write_bytes({"truncate": data[: len(data) // 2], "garbage": b"not a zip" * 100,
                       "empty": b""}[damage])
    assert not shard_complete(shard) and shard_complete(tmp_path / "shards" / "00000-a.zip")
    with pytest.raises(DatasetError, match=r"shards/00001-b\.zip: corrupt shard .*--resume"):
        open_dataset(tmp_path)


def test_shard_without_meta_is_named_at_open(tmp_path):
    make_dataset(tmp_path)
    shard = tmp_path / "shards" / "00001-b.zip"
    with zipfile.ZipFile(shard, "w") as archive:
        archive.writestr("000000/rgb.png", b"")
    with pytest.raises(DatasetError, match=r"00001-b\.zip: corrupt shard \(no meta.json\)"):
        open_dataset(tmp_path)


def test_missing_or_damaged_member_is_named_on_read(tmp_path):
    make_dataset(tmp_path)
    shard = tmp_path / "shards" / "00001-b.zip"
    with zipfile.ZipFile(shard) as source:
        members = {info.filename: source.read(info) for info in source.infolist()}
    members.pop("000001/gain.npy")
    members["000000/depth.png"] = b"\x89PNG garbage"
    with zipfile.ZipFile(shard, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    assert not shard_complete(shard)
    ds = open_dataset(tmp_path)
    assert ds[0]["key"] == "000000"  # other shards still read
    with pytest.raises(DatasetError, match=r"00001-b\.zip: corrupt shard \(member 000001/gain.npy "
                                           r"is missing\)"):
        ds[4]
    with pytest.raises(DatasetError, match=r"00001-b\.zip: .*000000/depth.png"):
        ds[3]


def test_pickled_dataset_reads_the_same(tmp_path):
    make_dataset(tmp_path)
    ds = open_dataset(tmp_path)
    before = ds[2]  # opens a handle, which pickling must drop
    clone = pickle.loads(pickle.dumps(ds))
    after = clone[2]
    np.testing.assert_array_equal(after["rgb"], before["rgb"])
    np.testing.assert_array_equal(after["distance_field"], before["distance_field"])
    assert clone.records == ds.records and clone.truncation_px == 7.0
    ds.close()
    clone.close()
    assert ds[0]["index"] == 0  # reopens after close


def test_dataset_description_is_checked(tmp_path):
    with pytest.raises(DatasetError, match="no dataset.json and no shards"):
        open_dataset(tmp_path)
    with pytest.raises(DatasetError, match="no such dataset"):
        open_dataset(tmp_path / "missing")
    write_dataset_info(tmp_path, {"seed": 1})
    assert read_dataset_info(tmp_path)["format_version"] == 1
    assert len(open_dataset(tmp_path)) == 0  # described, nothing generated yet
    (tmp_path / "dataset.json").write_text(json.dumps({"format": "something-else",
                                                       "format_version": 1}))
    with pytest.raises(DatasetError, match=r"dataset\.json: not a FrontierNet dataset"):
        open_dataset(tmp_path)
    (tmp_path / "dataset.json").write_text(json.dumps({"format": "frontiernet-dataset",
                                                       "format_version": 99}))
    with pytest.raises(DatasetError, match=r"dataset\.json: .*version 99"):
        read_dataset_info(tmp_path)
    (tmp_path / "dataset.json").write_text("{not json")
    with pytest.raises(DatasetError, match=r"dataset\.json: not a readable JSON"):
        open_dataset(tmp_path)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_forked_worker_reopens_its_own_handles(tmp_path):
    """DataLoader workers fork with the parent's open zips; both sides must still read right."""
    make_dataset(tmp_path)
    ds = open_dataset(tmp_path)
    expected = [ds[i]["gain"].sum() for i in range(len(ds))]  # parent handles are open now
    pid = os.fork()
    if pid == 0:  # child: read in reverse order, report success through the exit status
        ok = False
        try:
            ok = all(ds[i]["gain"].sum() == expected[i] for i in reversed(range(len(ds))))
            ok = ok and ds._pid == os.getpid()
        finally:
            os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    assert [ds[i]["gain"].sum() for i in range(len(ds))] == expected
