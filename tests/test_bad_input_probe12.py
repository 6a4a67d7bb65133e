"""Bad input of the twelfth probe of issue 55 (runs/probe12_report.md): things of the wrong kind where a run's lock,
a training cache's files, a benchmark's packs and a sequence's MCAP go, and a camera range of 3e38 m. Each refusal
one line naming the path or value, exit code 2, nothing written before lost. What blocked on a pipe before runs in a
subprocess with a timeout, so that a regression fails instead of hanging."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from conftest import copy_tracked, folder_files, python_in_subprocess
from frontiernet.cli.main import main
from frontiernet.errors import InputError

SMALL = "docs/benchmark/loop_fixes/base"
"""A small tracked benchmark folder (packed runs), copied, never written to."""


@pytest.fixture
def small(tmp_path) -> Path:
    return copy_tracked(SMALL, tmp_path / "bench")


def a_pack(folder: Path) -> Path:
    return sorted((folder / "runs").glob("*/*.jsonl.gz"))[0]


@pytest.mark.parametrize("action", ["--report", "--pack"])
def test_a_pack_that_is_a_folder_is_named_not_an_internal_error(action, small, one_line_error):
    # --pack: internal error (IsADirectoryError reading it)
    pack = a_pack(small)
    pack.unlink()
    pack.mkdir()
    before = folder_files(small)
    assert main(["bench", action, "--out", str(small)]) == 2
    assert one_line_error().endswith(f"{pack}: is a folder, expected a file (packed benchmark file)")
    assert folder_files(small) == before


def test_a_pack_that_is_a_pipe_is_refused_not_waited_on(small):
    # --report blocked on the pipe until killed
    pack = a_pack(small)
    pack.unlink()
    os.mkfifo(pack)
    result = python_in_subprocess("import sys; from frontiernet.cli.main import main; "
                           f"sys.argv = ['frontiernet', 'bench', '--report', '--out', {str(small)!r}]; sys.exit(main())")
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().endswith(f"{pack}: not a regular file, expected a file (packed benchmark file)")
    assert not (small / "results.csv").exists()


def test_a_lock_that_is_a_folder_is_named(two_scenes, tmp_path, one_line_error):
    # datagen --resume: internal error (IsADirectoryError opening .frontiernet.lock)
    data = tmp_path / "data"
    shutil.copytree(two_scenes, data)
    (data / ".frontiernet.lock").mkdir()
    before = folder_files(data)
    assert main(["datagen", "--scenes", "procedural:3", "procedural:4", "--views-per-scene", "2", "--no-progress",
                 "--out", str(data), "--resume", "--set", "camera.width=64", "camera.height=64", "camera.focal_px=40",
                 "writer.shard_size=2"]) == 2
    assert one_line_error().endswith(f"{data / '.frontiernet.lock'}: is a folder, expected the lock file frontiernet "
                                     "keeps while a run writes there; remove it")
    assert folder_files(data) == before


def test_a_lock_that_is_a_pipe_is_refused_not_opened(tmp_path):
    from frontiernet.io import LOCK_NAME

    os.mkfifo(tmp_path / LOCK_NAME)
    result = python_in_subprocess("from frontiernet.io import check_not_locked, claim_output_folder\n"
                           "from frontiernet.errors import InputError\n"
                           "for call in (lambda: check_not_locked(%r), lambda: claim_output_folder(%r, True).__enter__()):\n"
                           "    try:\n        call()\n    except InputError as error:\n        print(error)\n"
                           % (str(tmp_path), str(tmp_path)))
    lines = result.stdout.strip().splitlines()
    assert lines == [f"{tmp_path / LOCK_NAME}: not a regular file, expected the lock file frontiernet keeps while a "
                     "run writes there; remove it"] * 2, result.stderr


@pytest.mark.parametrize("name", ["cache.json", "rgb.npy"])
def test_a_training_cache_file_that_is_a_pipe_is_refused_not_waited_on(name, tmp_path):
    # train blocked reading a cache.json that is a pipe
    cache = tmp_path / "cache" / "64px-0123abcd"
    cache.mkdir(parents=True)
    os.mkfifo(cache / name)
    reader = "_read_info(path)" if name == "cache.json" else "_map_arrays(path, 64, 2)"
    result = python_in_subprocess("from pathlib import Path\nfrom train.cache import _read_info, _map_arrays\n"
                           "from frontiernet.errors import InputError\n"
                           f"path = Path({str(cache)!r})\ntry:\n    {reader}\nexcept InputError as error:\n"
                           "    print(error)\n")
    assert result.stdout.strip() == (f"{cache / name}: not a regular file, expected a file of the training cache; "
                                     f"delete {cache} to rebuild it"), result.stderr


def test_a_folder_where_the_mcap_goes_is_refused_before_the_frames(tmp_path):
    # sequence --mcap: internal error (IsADirectoryError) when the file was put in place, after the work
    from frontiernet.sequences.ros_out import RosWriter

    (tmp_path / "frontiers.mcap").mkdir()
    with pytest.raises(InputError, match="frontiers.mcap: a folder is where the run writes its frontiers.mcap"):
        RosWriter(tmp_path)
    (tmp_path / "frontiers.mcap").rmdir()
    os.mkfifo(tmp_path / ".frontiers.mcap.partial")  # its scratch: open(..., "wb") would wait for a reader
    with pytest.raises(InputError, match=r"\.frontiers\.mcap\.partial: not a regular file"):
        RosWriter(tmp_path)


def test_a_camera_range_past_100_m_is_refused_before_the_scene(tmp_path, one_line_error):
    # numpy's invalid-cast warnings from the map, the labels and seer's boxes at 3e38 m
    out = tmp_path / "run"
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "4", "--no-video", "--method", "classic",
                 "--out", str(out), "sim.camera.max_depth=3e38"]) == 2
    assert "camera.max_depth" in one_line_error() and not out.exists()


def test_a_lock_that_is_a_link_is_refused_and_the_file_it_names_kept(tmp_path, one_line_error):
    # probe 13 T6: a lock that is a link to a file was followed: the file written over with a pid, the link removed
    from frontiernet.io import LOCK_NAME

    out, precious = tmp_path / "run", tmp_path / "notes.txt"
    out.mkdir()
    precious.write_text("mine\n")
    (out / LOCK_NAME).symlink_to(precious)
    assert main(["explore", "--scene", "procedural:3", "--max-steps", "2", "--no-video", "--out", str(out),
                 "--force", "sim.camera.width=64", "sim.camera.height=64", "sim.camera.focal_px=40"]) == 2
    assert one_line_error().endswith(f"{out / LOCK_NAME}: a symbolic link, expected the lock file frontiernet keeps "
                                     "while a run writes there; remove it")
    assert precious.read_text() == "mine\n" and (out / LOCK_NAME).is_symlink()
