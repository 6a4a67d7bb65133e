"""Bad input of the eleventh probe of issue 55 (runs/probe11_report.md) in datasets, map datasets, training caches
and map-predictor checkpoints: Q3, Q4, Q7, Q8, Q12, Q13, Q15. Each refusal one line, exit code 2, nothing written
before lost; each test failed before its fix. A command that blocked on a pipe (or read /dev/zero) before runs in a
subprocess with a timeout, so that a regression fails instead of hanging."""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO_ROOT
from frontiernet.cli.main import main

DATAGEN_SET = ["camera.width=64", "camera.height=64", "camera.focal_px=40", "writer.shard_size=2"]
"""two_scenes' settings (conftest): its resume takes them."""
SMALL = "floors=1&footprint_min=8&footprint_max=10&rooms_min=3&rooms_max=4"
MAP_SCENE = f"procedural:5?{SMALL}"
MAPGEN_SET = ["sim.camera.width=64", "sim.camera.height=64", "sim.camera.focal_px=40", "mapgen.max_steps=8",
              "mapgen.snapshot_every_steps=4", "mapgen.first_snapshot_step=4",
              "mapgen.runs=[{method: classic, depth: gt}]"]
MIN_CELLS = "map_frontiers.min_cells_before_stop"


def datagen_resume(out) -> list[str]:
    return ["datagen", "--scenes", "procedural:3", "procedural:4", "--views-per-scene", "2", "--no-progress",
            "--out", str(out), "--resume", "--set", *DATAGEN_SET]


def mapgen_resume(out, *extra) -> list[str]:
    return ["mapgen", "--scenes", MAP_SCENE, "--no-progress", "--out", str(out), "--resume",
            "--set", *MAPGEN_SET, *extra]


def _at_most_8_gib() -> None:  # (a reader of /dev/zero ends in a MemoryError, not the OOM killer)
    resource.setrlimit(resource.RLIMIT_AS, (8 << 30, 8 << 30))


def cli_in_subprocess(args: list[str], timeout: float = 240) -> tuple[int, str]:
    """(exit code, stderr) of ``frontiernet ARGS`` in its own process; a run past `timeout` fails the test."""
    code = f"import sys; from frontiernet.cli.main import main; sys.argv = ['frontiernet', *{args!r}]; sys.exit(main())"
    try:
        result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout,
                                cwd=REPO_ROOT, preexec_fn=_at_most_8_gib)
    except subprocess.TimeoutExpired:
        pytest.fail(f"frontiernet {' '.join(args)}: still running after {timeout} s (blocked?)")
    return result.returncode, result.stderr.strip()


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(path.relative_to(folder)): path.read_bytes() for path in sorted(folder.rglob("*")) if path.is_file()}


@pytest.fixture(scope="module")
def map_data(tmp_path_factory) -> Path:
    """A tiny map dataset: one small procedural scene, one classic run of 8 steps."""
    out = tmp_path_factory.mktemp("maps") / "mg"
    assert main(["mapgen", "--scenes", MAP_SCENE, "--no-progress", "--out", str(out), "--set", *MAPGEN_SET]) == 0
    return out


def copy_of(folder: Path, tmp_path: Path, name: str = "copy") -> Path:
    shutil.copytree(folder, tmp_path / name)
    return tmp_path / name


def first_shard(folder: Path) -> Path:
    return sorted((folder / "shards").glob("*.zip"))[0]


# --------------------------------------------------------------------------- Q3: a map shard that is no file

def test_a_map_shard_that_is_a_pipe_is_refused_not_waited_on(map_data, tmp_path):
    data = copy_of(map_data, tmp_path)
    shard = first_shard(data)
    shard.unlink()
    os.mkfifo(shard)
    from frontiernet.mapprediction import shipped_predictor_path

    code, err = cli_in_subprocess(["mapeval", str(shipped_predictor_path("mapex")), "--data", str(data),
                                   "--max-snapshots", "1"])
    assert (code, err) == (2, f"frontiernet mapeval: error: {shard}: not a regular file, expected a file (map shard)")


def test_a_map_shard_that_is_a_folder_or_a_dangling_link_is_named_as_such(map_data, tmp_path):
    from datagen.mapshards import DatasetError, open_map_dataset

    data = copy_of(map_data, tmp_path)
    shard = first_shard(data)
    shard.unlink()
    shard.mkdir()  # (was "corrupt map shard (unreadable: IsADirectoryError)")
    with pytest.raises(DatasetError, match="is a folder, expected a file \\(map shard\\)$"):
        open_map_dataset(data)
    shard.rmdir()
    shard.symlink_to(tmp_path / "gone.zip")
    with pytest.raises(DatasetError, match="map shard not found: a symbolic link to .*gone.zip, which does not exist"):
        open_map_dataset(data)


# --------------------------------------------------------------------------- Q4: dataset.json no regular file

@pytest.mark.parametrize("kind", ["fifo", "dev-zero"])
def test_datagen_resume_with_a_dataset_json_that_is_no_file_is_refused_unread(two_scenes, tmp_path, kind):
    data = copy_of(two_scenes, tmp_path)
    info = data / "dataset.json"
    info.unlink()
    os.mkfifo(info) if kind == "fifo" else info.symlink_to("/dev/zero")
    before = snapshot(data)
    code, err = cli_in_subprocess(datagen_resume(data))
    assert (code, err) == (2, f"frontiernet datagen: error: {info}: not a regular file, expected a file (dataset "
                              "description)")
    assert snapshot(data) == before


def test_mapgen_resume_with_a_dataset_json_that_is_a_pipe_is_refused(map_data, tmp_path):
    data = copy_of(map_data, tmp_path)
    info = data / "dataset.json"
    info.unlink()
    os.mkfifo(info)
    code, err = cli_in_subprocess(mapgen_resume(data))
    assert (code, err) == (2, f"frontiernet mapgen: error: {info}: not a regular file, expected a file (dataset "
                              "description)")


# --------------------------------------------------------------------------- Q7, Q12: the paths a resume writes

def test_datagen_resume_with_shards_a_file_is_refused_before_any_work_and_keeps_the_caches(two_scenes, tmp_path,
                                                                                            one_line_error):
    data = copy_of(two_scenes, tmp_path)
    shutil.rmtree(data / "shards")
    (data / "shards").write_text("not a folder")
    cache = data / "cache" / "64px-0123abcd"
    cache.mkdir(parents=True)
    (cache / "cache.json").write_text("{}")
    before = snapshot(data)
    assert main(datagen_resume(data)) == 2
    assert f"{data / 'shards'}: is a file, expected a folder (dataset shards)" in one_line_error()
    assert snapshot(data) == before  # the training caches and summary.json as they were


def test_a_resume_with_summary_json_a_folder_is_refused_before_the_work(two_scenes, tmp_path, one_line_error):
    data = copy_of(two_scenes, tmp_path)
    first_shard(data).unlink()  # work to do: it was done, then the summary refused
    (data / "summary.json").unlink()
    (data / "summary.json").mkdir()
    before = snapshot(data)
    assert main(datagen_resume(data)) == 2
    assert f"{data / 'summary.json'}: a folder is where the run writes its summary.json" in one_line_error()
    assert snapshot(data) == before


def test_the_training_caches_go_only_when_a_shard_was_added(tmp_path):
    from datagen.generate import drop_stale_caches

    shard, cache = tmp_path / "shards" / "a.zip", tmp_path / "cache"
    (cache / "64px-x").mkdir(parents=True)
    with drop_stale_caches(tmp_path, [shard]):
        pass  # (a run whose every scene failed: nothing added)
    assert (cache / "64px-x").is_dir()
    with pytest.raises(KeyboardInterrupt), drop_stale_caches(tmp_path, [shard]):
        shard.parent.mkdir()
        shard.write_bytes(b"made")  # then interrupted: the shard is there, the caches no longer match
        raise KeyboardInterrupt
    assert not cache.exists()


@pytest.mark.parametrize("command", ["datagen", "mapgen"])
def test_a_folder_named_zip_among_the_shards_is_refused_at_resume(command, two_scenes, map_data, tmp_path,
                                                                   one_line_error):
    data = copy_of(two_scenes if command == "datagen" else map_data, tmp_path)
    (data / "shards" / "zz-extra.zip").mkdir()  # (datagen declared the dataset complete; train then refused it)
    args = datagen_resume(data) if command == "datagen" else mapgen_resume(data)
    assert main(args) == 2
    kind = "dataset shard" if command == "datagen" else "map shard"
    assert f"{data / 'shards' / 'zz-extra.zip'}: is a folder, expected a file ({kind})" in one_line_error()


def test_a_map_shard_that_is_a_pipe_is_refused_at_resume(map_data, tmp_path):
    data = copy_of(map_data, tmp_path)
    shard = first_shard(data)
    shard.unlink()
    os.mkfifo(shard)
    code, err = cli_in_subprocess(mapgen_resume(data))
    assert (code, err) == (2, f"frontiernet mapgen: error: {shard}: not a regular file, expected a file (map shard)")


# --------------------------------------------------------------------------- Q8: the default cache location

def test_train_with_the_datasets_cache_a_file_is_refused_before_the_trainer(two_scenes, tmp_path, capfd):
    data = copy_of(two_scenes, tmp_path)
    (data / "cache").write_text("not a folder")
    runs = tmp_path / "runs"
    assert main(["train", "--no-progress", "--config", str(REPO_ROOT / "configs/train_tiny.yaml"), "data.batch_size=1",
                 "trainer.max_epochs=1", "model.network.pretrained=false", f"data.path={data}", f"out={runs}"]) == 2
    err = capfd.readouterr().err.strip()  # (the descriptor's: Lightning's lines went there, 10 before the refusal)
    assert err == (f"frontiernet train: error: {data / 'cache'}: is a file, expected the folder of the dataset's "
                   "training caches (data.cache=auto); remove it, or set data.cache=FOLDER to put the cache elsewhere")
    assert not runs.exists() and (data / "cache").read_text() == "not a folder"


# --------------------------------------------------------------------------- Q13: a key added after the dataset

def test_a_map_dataset_made_before_a_key_resumes_with_its_old_value(map_data, tmp_path, capsys, one_line_error):
    data = copy_of(map_data, tmp_path)
    info = json.loads((data / "dataset.json").read_text())
    del info["config"]["map_frontiers"]["min_cells_before_stop"]  # as mapgen wrote it before the key
    (data / "dataset.json").write_text(json.dumps(info))
    shards = {name: content for name, content in snapshot(data).items() if name.startswith("shards")}
    assert main(mapgen_resume(data)) == 2  # the default (1) changes what the runs do
    assert (f"{data}: cannot resume, the dataset was made with other settings ({MIN_CELLS}: null in the dataset, 1 "
            "now); use another --out") in one_line_error()
    assert main(mapgen_resume(data, f"{MIN_CELLS}=null")) == 0  # the behaviour it was made with
    capsys.readouterr()
    assert {name: content for name, content in snapshot(data).items() if name.startswith("shards")} == shards


# --------------------------------------------------------------------------- Q15: map-predictor checkpoints

def test_an_empty_truncated_or_foreign_map_predictor_checkpoint_says_which(map_data, tmp_path, one_line_error):
    import torch

    (tmp_path / "empty.ckpt").write_bytes(b"")
    torch.save({"state_dict": {"net.w": torch.zeros(1000)}, "hyper_parameters": {"predictor": {"kind": "mapex"}}},
               tmp_path / "full.ckpt")
    data = (tmp_path / "full.ckpt").read_bytes()
    (tmp_path / "cut.ckpt").write_bytes(data[: len(data) // 2])
    shutil.copy(first_shard(map_data), tmp_path / "shard.ckpt")  # a zip archive, not PyTorch's
    for name, reason in (("empty.ckpt", "empty file (0 bytes), expected a predictor file"),
                         ("cut.ckpt", "not a predictor file or training checkpoint (not a PyTorch zip archive, the "
                                      "format frontiernet train writes: truncated, or another kind of file)"),
                         ("shard.ckpt", "not a predictor file or training checkpoint (a zip archive, but not "
                                        "PyTorch's; a dataset shard?)")):
        assert main(["mapeval", str(tmp_path / name), "--data", str(map_data), "--max-snapshots", "1"]) == 2
        assert one_line_error() == f"frontiernet mapeval: error: {tmp_path / name}: {reason}"


def test_a_foreign_zip_to_resume_a_training_from_says_so(map_data, tmp_path):
    from frontiernet.errors import InputError
    from train.resume import check_checkpoint

    shutil.copy(first_shard(map_data), tmp_path / "shard.ckpt")  # (was "not a training checkpoint (RuntimeError)")
    with pytest.raises(InputError, match=r"shard.ckpt: not a training checkpoint \(a zip archive, but not PyTorch's"):
        check_checkpoint(str(tmp_path / "shard.ckpt"))
