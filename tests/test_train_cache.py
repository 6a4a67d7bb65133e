"""The training cache: the same training items as decoding the dataset, resumable builds,
refusal of a cache that does not match its dataset or config, and the device-side batch."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf
from torch.utils.data import DataLoader

from datagen import open_dataset
from frontiernet.cli.main import main
from frontiernet.config import load_config
from frontiernet.errors import InputError
from frontiernet.model import normalise_batch
from train.cache import build_cache, default_cache_dir, ensure_cache, open_cache
from train.data import CachedSamples, TrainingSamples
from train.transforms import network_batch, training_sample

MODEL = OmegaConf.to_container(load_config("model"))
AUGMENT = OmegaConf.to_container(load_config("train").augment)
LABELS = MODEL["labels"]


@pytest.fixture()
def dataset_copy(tiny_dataset, tmp_path):
    """A private copy of the tiny dataset (tests here write caches into it and change it)."""
    copy = tmp_path / "data"
    shutil.copytree(tiny_dataset, copy, ignore=shutil.ignore_patterns("cache"))
    return copy


def test_cached_items_equal_decoded_ones_at_the_training_size(dataset_copy):
    cache = ensure_cache(dataset_copy, "auto", 64, LABELS)
    assert cache.path == default_cache_dir(dataset_copy, 64, LABELS) and cache.path.is_dir()
    dataset = open_dataset(dataset_copy)
    assert len(cache) == len(dataset) and cache.scenes == [r["scene"] for r in dataset.records]
    cached, decoded = CachedSamples(cache, range(len(cache))), TrainingSamples(dataset, MODEL, 64)
    for index in range(len(dataset)):
        a, b = cached[index], decoded[index]
        assert all(torch.equal(a[key], b[key]) for key in a), index
    # the batch the network sees: labels exactly those of training_sample, input = the library's normalisation
    batch = network_batch(next(iter(DataLoader(cached, batch_size=len(cached)))), MODEL)
    for index in (0, len(dataset) - 1):
        sample = training_sample(dataset[index], 64, LABELS)
        assert np.allclose(batch["distance"][index].numpy(), sample["distance"], atol=1e-5)
        assert np.array_equal(batch["gain_class"][index].numpy(), sample["gain_class"])
        assert np.array_equal(batch["frontier"][index].numpy(), sample["frontier"])
        assert np.array_equal(batch["discontinuity"][index].numpy(), sample["discontinuity"])
        expected = normalise_batch(sample["rgb"][None], sample["depth"][None], "rgbd", MODEL["input"])[0]
        assert np.allclose(batch["image"][index].numpy(), expected, atol=1e-3)


def test_augmentation_on_the_device_changes_the_input_not_the_labels(dataset_copy):
    cache = ensure_cache(dataset_copy, "auto", 64, LABELS)
    samples = CachedSamples(cache, range(len(cache)), {**AUGMENT, "crop_size": 48}, seed=3)
    torch.manual_seed(0)
    raw = next(iter(DataLoader(samples, batch_size=8)))
    assert raw["rgb"].shape == (8, 3, 48, 48) and (raw["jitter"] != 1).any()
    augmented = network_batch(raw, MODEL, AUGMENT)
    plain = network_batch(raw, MODEL)
    assert not torch.allclose(augmented["image"], plain["image"])
    for key in ("distance", "gain_class", "frontier", "discontinuity", "depth"):
        assert torch.equal(augmented[key], plain[key]), key
    valid = raw["depth"] > 0
    assert (augmented["image"][:, 3][~valid] == 0).all()  # invalid depth stays 0 under jitter


def test_views_without_depth_get_an_empty_prior_and_keep_their_rgb_and_labels(dataset_copy):
    cache = ensure_cache(dataset_copy, "auto", 64, LABELS)
    samples = CachedSamples(cache, range(len(cache)), {**AUGMENT, "crop_size": 48}, seed=3)
    raw = next(iter(DataLoader(samples, batch_size=8)))
    has_depth = (raw["depth"] > 0).flatten(1).any(1)
    assert has_depth.all()
    torch.manual_seed(0)
    kept = network_batch(raw, MODEL, {**AUGMENT, "no_depth_fraction": 0.0})
    torch.manual_seed(0)
    none = network_batch(raw, MODEL, {**AUGMENT, "no_depth_fraction": 1.0})
    assert (none["image"][:, 3] == 0).all() and (kept["image"][:, 3] != 0).flatten(1).any(1).all()
    assert torch.allclose(none["image"][:, :3], kept["image"][:, :3])
    for key in ("distance", "gain_class", "frontier", "discontinuity", "depth"):
        assert torch.equal(none[key], kept[key]), key
    torch.manual_seed(1)
    half = network_batch(raw, MODEL, {**AUGMENT, "no_depth_fraction": 0.5})
    empty = (half["image"][:, 3] == 0).flatten(1).all(1)
    assert 0 < empty.sum() < len(empty)  # some views without depth, the others with theirs


def test_interrupted_build_resumes_without_redoing_views(dataset_copy, monkeypatch):
    path = dataset_copy / "cache" / "mine"
    reference = build_cache(dataset_copy, dataset_copy / "cache" / "reference", 64, LABELS)
    calls = []

    def stop_after_ten(done, total):
        calls.append(done)
        if done >= 10:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        build_cache(dataset_copy, path, 64, LABELS, progress=stop_after_ten)
    assert not path.exists() and path.with_name("mine.partial").is_dir()
    decoded = []
    import train.cache as cache_module

    original = cache_module._PackedViews.__getitem__

    def counting(self, item):
        decoded.append(int(self.indices[item]))
        return original(self, item)

    monkeypatch.setattr(cache_module._PackedViews, "__getitem__", counting)
    resumed = build_cache(dataset_copy, path, 64, LABELS)
    assert len(decoded) == len(reference) - 10 and min(decoded) >= 10
    assert not path.with_name("mine.partial").exists()
    for name, array in reference.arrays.items():
        assert np.array_equal(array, resumed.arrays[name]), name


def test_a_cache_of_another_dataset_or_config_is_refused_and_kept(dataset_copy):
    cache = ensure_cache(dataset_copy, "auto", 64, LABELS)
    with pytest.raises(InputError, match="cache.json: built for size 64, the config asks for 48"):
        open_cache(cache.path, dataset_copy, 48, LABELS)
    with pytest.raises(InputError, match="cache.json: built for labels"):
        open_cache(cache.path, dataset_copy, 64, {**LABELS, "truncation_px": 8.0})
    info = dataset_copy / "dataset.json"
    info.write_text(json.dumps({**json.loads(info.read_text()), "seed": 12345}))  # "regenerated"
    with pytest.raises(InputError, match="another version of the dataset"):
        ensure_cache(dataset_copy, "auto", 64, LABELS)
    assert (cache.path / "rgb.npy").is_file()  # nothing rebuilt over it


def test_truncated_cache_is_one_line_exit_2_and_not_overwritten(dataset_copy, tmp_path, one_line_error):
    cache = ensure_cache(dataset_copy, "auto", 96, LABELS)
    array = cache.path / "gain_class.npy"
    size = array.stat().st_size
    with open(array, "r+b") as handle:
        handle.truncate(size // 2)
    args = ["train", "--config", "configs/train_tiny.yaml", "--no-progress", f"data.path={dataset_copy}",
            f"out={tmp_path / 'runs'}"]
    assert main(args) == 2
    message = one_line_error()
    assert "gain_class.npy: truncated or corrupt" in message
    assert array.stat().st_size == size // 2 and not (tmp_path / "runs").exists()


def test_lightning_config_errors_are_one_line(dataset_copy, tmp_path, one_line_error):
    args = ["train", "--config", "configs/train_tiny.yaml", "--no-progress", f"data.path={dataset_copy}",
            f"out={tmp_path / 'runs'}"]
    assert main(args + ["trainer.val_check_interval=60"]) == 2
    assert "trainer.val_check_interval: 60 steps, but an epoch has" in one_line_error()
    assert main(args + ["data.batch_size=0"]) == 2
    assert "data.batch_size" in one_line_error()
    assert main(args + ["optim.lr=-1"]) == 2
    assert "optim.lr" in one_line_error()
    assert main(args + ["trainer.accelerator=bogus"]) == 2  # (Lightning's own check; precision and strategy are
    message = one_line_error()  # ours: train.main)
    assert "trainer:" in message and "bogus" in message
    not_a_checkpoint = tmp_path / "notes.txt"
    not_a_checkpoint.write_text("hello")
    assert main(args + ["--resume", str(not_a_checkpoint)]) == 2
    assert "notes.txt: not a training checkpoint" in one_line_error()
    assert not (tmp_path / "runs").exists()


def test_bench_train_reports_loader_and_model_rates(dataset_copy, capsys):
    assert main(["bench", "train", f"data.path={dataset_copy}", "data.image_size=64", "augment.crop_size=48",
                 "data.batch_size=4", "--workers", "0", "--batches", "2", "--steps", "1", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    sources = [(row["source"], row["workers"]) for row in result["loader"]]
    assert sources == [("decode", 0), ("cache", 0)]
    assert all(row["samples_per_s"] > 0 for row in result["loader"])
    assert result["model"]["images_per_s"] > 0 and result["model"]["crop"] == 48 and result["model"]["batch"] == 4
    best = max(row["samples_per_s"] for row in result["loader"] if row["source"] == "cache")
    assert result["loader_to_model"] == pytest.approx(best / result["model"]["images_per_s"], rel=0.02)
    # both memory layouts timed in the same run, as ratios to NCHW; on a CPU `auto` trains in NCHW
    layouts = result["model_layouts"]
    assert [layout["channels_last"] for layout in layouts] == [False, True] and layouts[0]["ratio_to_nchw"] == 1.0
    assert result["model"] == layouts[0]


def _build_in_a_process(dataset, queue):
    cache = ensure_cache(dataset, "auto", 64, LABELS)
    queue.put((str(cache.path), int(len(cache))))


def test_two_processes_building_one_cache_at_once_both_get_it(dataset_copy):
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    processes = [context.Process(target=_build_in_a_process, args=(dataset_copy, queue)) for _ in range(2)]
    for process in processes:
        process.start()
    for process in processes:
        process.join(timeout=300)
    assert [process.exitcode for process in processes] == [0, 0]
    results = [queue.get(timeout=5) for _ in processes]
    assert results[0] == results[1] and results[0][1] == len(open_dataset(dataset_copy))
    cache = open_cache(default_cache_dir(dataset_copy, 64, LABELS), dataset_copy, 64, LABELS)
    reference = build_cache(dataset_copy, dataset_copy / "cache" / "reference", 64, LABELS)
    for name, array in reference.arrays.items():
        assert np.array_equal(array, cache.arrays[name]), name
    assert not any(path.name.endswith(".partial") for path in (dataset_copy / "cache").iterdir())


def test_bench_train_refuses_a_dataset_smaller_than_a_batch(dataset_copy, one_line_error):
    # issue 55's second probe: StopIteration, an internal error, after the cache was built
    assert main(["bench", "train", f"data.path={dataset_copy}", "data.batch_size=1000", "--workers", "0",
                 "--batches", "1", "--steps", "1"]) == 2
    assert "views, fewer than one batch (data.batch_size 1000)" in one_line_error()
    assert not (dataset_copy / "cache").exists()
