"""The dataset generator and ``frontiernet datagen``: same seed same bytes, resumable after a
kill, retries a dead worker, refuses bad input with one line and exit code 2, reports a
failing scene and writes the others."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from datagen.config import config_hash, load_datagen_config
from datagen.dataset import open_dataset
from datagen.generate import GENERATOR_VERSION, generate
from datagen.shards import shard_complete
from frontiernet.cli.main import main
from frontiernet.errors import InputError
from frontiernet.scenes.spec import expand_specs

# Tiny runs: 96 x 96 px views, 2 views per shard.
SMALL_SET = ["camera.width=96", "camera.height=96", "camera.focal_px=60", "writer.shard_size=2"]
SMALL_SCENES = ["procedural:5", "procedural:6"]
SMALL_VIEWS = 3  # shards of 2 and 1 views per scene
SMALL_SEED = 3

# A run that takes several seconds on two workers, so it can be interrupted mid-way.
BIG_SET = ["camera.width=160", "camera.height=160", "camera.focal_px=100", "writer.shard_size=2"]
BIG_SCENES = ["procedural:5", "procedural:6", "procedural:7"]
BIG_VIEWS = 8
BIG_SEED = 1
BIG_SHARDS = len(BIG_SCENES) * BIG_VIEWS // 2


def shard_bytes(out: Path) -> dict[str, bytes]:
    """{file name: bytes} of the shard .zip files of a dataset folder."""
    return {p.name: p.read_bytes() for p in sorted((Path(out) / "shards").glob("*.zip"))}


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    """{relative path: (bytes, mtime_ns)} of every file under `folder`."""
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def datagen_command(out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "frontiernet.cli.main", "datagen", "--scenes", *BIG_SCENES,
            "--views-per-scene", str(BIG_VIEWS), "--seed", str(BIG_SEED), "--out", str(out), "--no-progress",
            *extra, "--set", *BIG_SET]


def start_datagen(out: Path, *extra: str) -> subprocess.Popen:
    """The big run as a CLI subprocess, in its own session (so its process group can be killed)."""
    return subprocess.Popen(datagen_command(out, *extra), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def wait_for_first_shard(process: subprocess.Popen, out: Path, timeout_s: float = 180.0) -> int:
    """Poll until at least one shard (but not all) is on disk while `process` runs; the count.

    Fails the test when the run ends (or writes every shard) before that: it would then not
    test an interruption at all, and the sizes above need to grow.
    """
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        count = len(list((out / "shards").glob("*.zip"))) if (out / "shards").is_dir() else 0
        if process.poll() is not None or count >= BIG_SHARDS:
            process.kill()
            stdout, stderr = process.communicate()
            pytest.fail(f"the datagen run finished (rc {process.returncode}, {count} shards) before it could be "
                        f"interrupted; make BIG_VIEWS larger so it runs longer\n{stdout}\n{stderr}")
        if count:
            return count
        time.sleep(0.02)
    os.killpg(process.pid, signal.SIGKILL)
    process.communicate()
    pytest.fail(f"no shard appeared within {timeout_s} s")


def children(pid: int) -> list[tuple[int, int, str]]:
    """(start time in clock ticks, pid, command line) of the child processes of `pid`, oldest first."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:  # exited meanwhile
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) ": state, ppid, ...
        if int(fields[1]) == pid:
            found.append((int(fields[19]), int(entry.name), cmdline))
    return sorted(found)


def wait_until_group_is_gone(pgid: int, timeout_s: float = 10.0) -> None:
    """Wait until no process of process group `pgid` is left (zombies count as gone)."""
    deadline = time.monotonic() + timeout_s
    while True:
        alive = []
        for entry in Path("/proc").iterdir():
            try:
                stat = (entry / "stat").read_text() if entry.name.isdigit() else ""
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2:].split() if stat else []
            if fields and int(fields[2]) == pgid and fields[0] != "Z":
                alive.append(int(entry.name))
        if not alive:
            return
        assert time.monotonic() < deadline, f"processes {alive} of the killed run are still alive"
        time.sleep(0.05)


@pytest.fixture(scope="module")
def small_conf():
    return load_datagen_config(overrides=SMALL_SET)


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory, small_conf):
    """2 procedural scenes x 3 views at 96 x 96 px, seed 3, made in this process (workers=1)."""
    out = tmp_path_factory.mktemp("small") / "ds"
    summary = generate(SMALL_SCENES, SMALL_VIEWS, out, small_conf, seed=SMALL_SEED, workers=1, progress=False)
    return out, summary


@pytest.fixture(scope="module")
def big_reference(tmp_path_factory) -> dict[str, bytes]:
    """Shard bytes of an uninterrupted run of the big dataset (in this process, workers=1)."""
    out = tmp_path_factory.mktemp("big") / "ref"
    summary = generate(BIG_SCENES, BIG_VIEWS, out, load_datagen_config(overrides=BIG_SET), seed=BIG_SEED,
                       workers=1, progress=False)
    assert summary["failed_scenes"] == [] and summary["shards"] == BIG_SHARDS
    return shard_bytes(out)


# --------------------------------------------------------------------------- determinism, format

def test_same_seed_gives_identical_shards_for_any_worker_count(small_dataset, small_conf, tmp_path):
    out, _ = small_dataset
    reference = shard_bytes(out)
    assert len(reference) == len(SMALL_SCENES) * 2  # 3 views in shards of 2 + 1
    generate(SMALL_SCENES, SMALL_VIEWS, tmp_path / "w2", small_conf, seed=SMALL_SEED, workers=2, progress=False)
    assert shard_bytes(tmp_path / "w2") == reference

    generate(SMALL_SCENES[:1], SMALL_VIEWS, tmp_path / "s4", small_conf, seed=SMALL_SEED + 1, progress=False)
    poses = [np.array(r["T_world_cam"]) for r in open_dataset(out).records if r["scene"] == SMALL_SCENES[0]]
    other = [np.array(r["T_world_cam"]) for r in open_dataset(tmp_path / "s4").records]
    assert len(poses) == len(other) == SMALL_VIEWS
    assert not any(np.allclose(a, b) for a in poses for b in other)


def test_dataset_reads_back_with_documented_arrays_and_metadata(small_dataset, small_conf):
    out, summary = small_dataset
    ds = open_dataset(out)
    assert len(ds) == len(SMALL_SCENES) * SMALL_VIEWS
    assert ds.scenes == SMALL_SCENES
    any_invalid_depth = False
    for i in range(len(ds)):
        s = ds[i]
        assert s["rgb"].shape == (96, 96, 3) and s["rgb"].dtype == np.uint8
        depth = s["depth"]
        assert depth.shape == (96, 96) and depth.dtype == np.float32
        assert np.all(np.isnan(depth) | ((depth > 0) & (depth <= small_conf.camera.max_depth + 1e-3)))
        any_invalid_depth |= bool(np.isnan(depth).any())
        mask = s["frontier_mask"]
        assert mask.shape == (96, 96) and mask.dtype == bool
        field = s["distance_field"]
        assert field.shape == (96, 96) and field.dtype == np.float32
        if mask.any():
            assert np.all(field[mask] == 0) and np.all(field[~mask] > 0)
        assert field.max() <= ds.truncation_px
        assert s["gain"].dtype == np.float32 and s["gain"].shape == (96, 96) and s["gain"].min() >= 0
        classes = s["gain_class"]
        assert classes.dtype == np.int64 and classes.shape == (96, 96)
        assert 0 <= classes.min() and classes.max() < len(small_conf.ground_truth.gain.bin_edges)
        assert s["K"].shape == (3, 3) and s["K"][0, 0] == pytest.approx(60.0)
        assert s["T_world_cam"].shape == (4, 4) and np.allclose(s["T_world_cam"][3], [0, 0, 0, 1])
        assert isinstance(s["scene"], str) and s["scene"] in SMALL_SCENES
    assert any_invalid_depth  # rooms larger than the sensor range: some pixels have no depth
    for record in ds.records:
        assert record["scene"] in SMALL_SCENES
        assert np.shape(record["T_world_cam"]) == (4, 4) and np.shape(record["K"]) == (3, 3)

    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk["views"] == summary["views"] == len(ds)
    assert on_disk["shards"] == on_disk["shards_planned"] == 4 and on_disk["failed_scenes"] == []
    info = json.loads((out / "dataset.json").read_text())
    assert info["config_hash"] == config_hash(small_conf)
    assert info["seed"] == SMALL_SEED and info["generator_version"] == GENERATOR_VERSION
    assert info["scenes"] == SMALL_SCENES and info["views_per_scene"] == SMALL_VIEWS


def test_a_second_run_in_the_same_process_uses_its_own_config(small_dataset, tmp_path):
    # workers=1 runs in the caller's process, where the first run's scenes are still cached
    out = tmp_path / "ds"
    generate(SMALL_SCENES[:1], 2, out, load_datagen_config(overrides=["camera.width=64", "camera.height=48",
                                                                        "camera.focal_px=40"]), progress=False)
    sample = open_dataset(out)[0]
    assert sample["rgb"].shape == (48, 64, 3) and sample["K"][0, 0] == pytest.approx(40.0)


# --------------------------------------------------------------------------- kills

@pytest.mark.slow
def test_killed_run_leaves_only_complete_shards_and_resumes_to_the_same_bytes(big_reference, tmp_path):
    out = tmp_path / "ds"
    process = start_datagen(out, "--workers", "2")
    try:
        wait_for_first_shard(process, out)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)  # the CLI, its manager and its workers, mid-shard
        process.communicate()
    wait_until_group_is_gone(process.pid)  # no killed writer may still touch the folder
    shards = sorted((out / "shards").glob("*.zip"))
    assert 0 < len(shards) < BIG_SHARDS, "the kill came too late to interrupt the run"
    assert all(shard_complete(p) for p in shards), [p.name for p in shards if not shard_complete(p)]
    partial = open_dataset(out)
    assert len(partial) == sum(len(open_dataset(p)) for p in shards) > 0
    for name in (p.name for p in shards):
        assert (out / "shards" / name).read_bytes() == big_reference[name]

    # resume through the same command, in this process and on one worker (the worker count is no
    # part of a dataset: it may change between runs)
    assert main(datagen_command(out, "--resume")[3:]) == 0
    assert shard_bytes(out) == big_reference
    assert not list((out / "shards").glob("*.tmp-*"))  # the killed writers' temporaries are gone
    summary = json.loads((out / "summary.json").read_text())
    assert summary["views"] == len(BIG_SCENES) * BIG_VIEWS
    assert summary["shards_done_before"] == len(shards)


@pytest.mark.slow
def test_killed_worker_is_retried_and_the_run_completes(big_reference, tmp_path):
    out = tmp_path / "ds"
    process = start_datagen(out, "--workers", "2")
    try:
        wait_for_first_shard(process, out)
        spawned = [(start, pid) for start, pid, cmdline in children(process.pid) if "spawn_main" in cmdline]
        # the multiprocessing Manager starts first, then the pool's workers
        if len(spawned) < 3:
            pytest.skip(f"could not find the manager and two pool workers among the children of the datagen "
                        f"process ({len(spawned)} spawned processes)")
        victim = spawned[-1][1]
        os.kill(victim, signal.SIGKILL)
        stdout, stderr = process.communicate(timeout=300)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()
    assert process.returncode == 0, stderr
    assert "worker process died" in stderr  # the kill hit a pool worker, and its shards were redone
    assert shard_bytes(out) == big_reference
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed_shards"] == 0 and summary["views"] == len(BIG_SCENES) * BIG_VIEWS


# --------------------------------------------------------------------------- refusals

def small_args(out: Path, *extra: str) -> list[str]:
    return ["datagen", "--scenes", *SMALL_SCENES, "--views-per-scene", str(SMALL_VIEWS), "--seed",
            str(SMALL_SEED), "--out", str(out), "--no-progress", *extra, "--set", *SMALL_SET]


def test_existing_dataset_is_refused_without_resume_and_on_a_mismatched_resume(small_dataset, tmp_path, capsys, one_line_error):
    out = tmp_path / "ds"
    shutil.copytree(small_dataset[0], out)
    before = snapshot(out)

    assert main(small_args(out)) == 2
    err = one_line_error()
    assert str(out) in err and "--resume" in err

    args = small_args(out, "--resume")
    args[args.index("--seed") + 1] = str(SMALL_SEED + 1)
    assert main(args) == 2
    err = one_line_error()
    assert str(out) in err and "seed" in err

    args = small_args(out, "--resume")
    args[args.index("--views-per-scene") + 1] = str(SMALL_VIEWS + 1)
    assert main(args) == 2
    err = one_line_error()
    assert str(out) in err and "views_per_scene" in err

    args = small_args(out, "--resume")  # seventh probe (D22): "a different config_hash ('4781...', now 'a144...')"
    args[args.index("camera.focal_px=60")] = "camera.focal_px=50"
    assert main(args) == 2
    assert one_line_error() == (f"frontiernet datagen: error: {out}: cannot resume, the dataset was made with other "
                                "settings (camera.focal_px: 60 in the dataset, 50 now); use another --out")

    assert snapshot(out) == before  # nothing in the dataset was touched


def test_resume_of_a_finished_dataset_changes_no_shard(small_dataset, tmp_path, capsys):
    out = tmp_path / "ds"
    shutil.copytree(small_dataset[0], out)
    before = {name: data for name, data in snapshot(out).items() if name.startswith("shards")}
    assert main(small_args(out, "--resume")) == 0
    assert {name: data for name, data in snapshot(out).items() if name.startswith("shards")} == before
    assert json.loads((out / "summary.json").read_text())["shards_done_before"] == 4


def test_a_run_that_adds_shards_removes_the_training_caches_of_the_dataset_before(small_dataset, tmp_path):
    # a budget-cut run resumed later (scripts/train_on_gpu.sh): the training cache built in between
    # no longer matches the dataset, and training refuses a mismatched cache (train/cache.py)
    out = tmp_path / "ds"
    shutil.copytree(small_dataset[0], out)
    cache = out / "cache" / "64px-0123abcd"
    cache.mkdir(parents=True)
    (cache / "cache.json").write_text("{}")
    assert main(small_args(out, "--resume")) == 0  # nothing to add: the cache stays
    assert (cache / "cache.json").is_file()
    shard = sorted((out / "shards").glob("*.zip"))[-1]
    shard.unlink()
    assert main(small_args(out, "--resume")) == 0
    assert shard.is_file() and not (out / "cache").exists()


@pytest.mark.parametrize("change, message", [
    (("--scenes", "nosuch.glb"), "nosuch.glb"),
    (("--views-per-scene", "0"), "--views-per-scene"),
    (("--workers", "0"), "--workers"),
    (("--scenes", "procedural:5-2"), "procedural:5-2"),
])
def test_bad_arguments_are_one_line_exit_2_before_any_output(tmp_path, capsys, change, message, one_line_error):
    out = tmp_path / "ds"
    args = small_args(out)
    flag, value = change
    if flag in args:
        at = args.index(flag) + 1
        args[at:at + (len(SMALL_SCENES) if flag == "--scenes" else 1)] = [value]
    else:
        args[1:1] = [flag, value]
    assert main(args) == 2
    assert message in one_line_error()
    assert not out.exists()


def test_unknown_backend_and_missing_out_exit_2(tmp_path, capsys, one_line_error):
    assert main(small_args(tmp_path / "ds", "--backend", "nosuch")) == 2  # as bench's: checked with --workers
    assert "--backend must be one of local, ray, got 'nosuch'" in one_line_error()
    assert not (tmp_path / "ds").exists()

    args = small_args(tmp_path / "ds")
    del args[args.index("--out"):args.index("--out") + 2]
    assert main(args) == 2
    assert "--out" in one_line_error()
    assert not (tmp_path / "ds").exists()


def test_output_under_a_file_is_refused_naming_the_path(tmp_path, capsys, one_line_error):
    (tmp_path / "file.txt").write_text("not a folder")
    out = tmp_path / "file.txt" / "ds"
    assert main(small_args(out)) == 2
    assert str(out) in one_line_error()


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root ignores file permissions")
def test_unwritable_output_is_refused_naming_the_path(tmp_path, capsys, one_line_error):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        out = locked / "ds"
        assert main(small_args(out)) == 2
        assert str(out) in one_line_error()
        assert not out.exists()
    finally:
        locked.chmod(0o700)


def test_failing_scene_is_reported_and_the_others_are_written(tmp_path, capsys):
    bad = tmp_path / "broken.glb"
    bad.write_bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    out = tmp_path / "ds"
    args = ["datagen", "--scenes", str(bad), "procedural:5", "--views-per-scene", "2", "--out", str(out),
            "--no-progress", "--set", *SMALL_SET]
    assert main(args) == 2  # bad input (a corrupt scene file): exit 2, one error line on stderr
    printed = capsys.readouterr()
    [line] = printed.err.strip().splitlines()
    assert line.startswith(f"frontiernet datagen: error: {bad}: ") and "rerun with --resume" in line
    assert f"failed: {bad}" in printed.out
    shards = sorted(p.name for p in (out / "shards").glob("*.zip"))
    assert shards == ["00001-procedural-5-0000.zip"]
    assert shard_complete(out / "shards" / shards[0])
    ds = open_dataset(out)
    assert len(ds) == 2 and ds.scenes == ["procedural:5"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["views"] == 2 and summary["failed_shards"] == 1
    [failure] = summary["failed_scenes"]
    assert failure["scene"] == str(bad) and failure["error"] and "\n" not in failure["error"]


# --------------------------------------------------------------------------- Ray

@pytest.mark.slow
def test_ray_backend_writes_the_same_bytes_as_local(small_dataset, small_conf, tmp_path):
    pytest.importorskip("ray")
    out = tmp_path / "ray"
    summary = generate(SMALL_SCENES, SMALL_VIEWS, out, small_conf, seed=SMALL_SEED, workers=2, backend="ray",
                       progress=False)
    assert summary["failed_scenes"] == []
    assert shard_bytes(out) == shard_bytes(small_dataset[0])


# --------------------------------------------------------------------------- scene specs

def test_expand_specs_ranges_globs_and_folders_of_floor_plans(tmp_path):
    assert expand_specs(["procedural:0-3?floors=2"]) == [f"procedural:{i}?floors=2" for i in range(4)]
    assert expand_specs(["procedural:2", "procedural:1-2"]) == ["procedural:2", "procedural:1"]

    meshes = tmp_path / "meshes"
    meshes.mkdir()
    for name in ("b.glb", "a.glb", "notes.txt"):
        (meshes / name).write_bytes(b"")
    assert expand_specs([str(meshes / "*.glb")]) == [str(meshes / "a.glb"), str(meshes / "b.glb")]
    assert expand_specs([f"mesh:{meshes}/*.glb?up=y"]) == [f"mesh:{meshes / 'a.glb'}?up=y",
                                                            f"mesh:{meshes / 'b.glb'}?up=y"]

    kth = tmp_path / "kth"
    for plan in ("50052751", "50052750"):
        (kth / plan).mkdir(parents=True)
        np.save(kth / plan / "occ_map.npy", np.zeros((8, 8), np.uint8))
    (kth / "empty").mkdir()
    (kth / "README").write_text("not a scene")
    assert expand_specs([str(kth)]) == [str(kth / "50052750"), str(kth / "50052751")]

    for bad in ("procedural:5-2", "procedural:a-b", str(meshes / "*.obj")):
        with pytest.raises(InputError):
            expand_specs([bad])


# --------------------------------------------------------------------------- preview, bench

def test_preview_writes_contact_sheets_into_the_dataset(small_dataset, tmp_path, capsys):
    out = tmp_path / "ds"
    shutil.copytree(small_dataset[0], out)
    assert main(["datagen", "preview", str(out), "--n", "2"]) == 0
    sheets = sorted((out / "preview").glob("*.png"))
    assert len(sheets) == 2
    for sheet in sheets:
        image = np.asarray(Image.open(sheet))
        assert image.ndim == 3 and min(image.shape[:2]) >= 96


def test_bench_prints_json_figures(capsys):
    assert main(["datagen", "bench", "--scene", "procedural:5", "--views", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["scene"] == "procedural:5" and result["views"] == 2
    assert result["view_in_renders"] > 0 and result["render_ms"] > 0
    assert result["views_per_second_per_core"] > 0
