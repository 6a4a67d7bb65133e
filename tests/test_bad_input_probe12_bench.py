"""Bad input of the twelfth probe of issue 55 (runs/probe12_report.md) in benchmark folders and output files, its
S11, S12, S13 and S16: `bench --pack` on a run whose metrics.json is a folder or a pipe, or whose method folder is a
file; report files, a pack and a preview folder that are symbolic links to nothing; `--redo-changed` with a setting
no planned run reads. Each refusal one line naming the path, exit code 2, nothing written before lost. What could
block on a pipe runs in a subprocess with a timeout, so that a regression fails instead of hanging."""

from __future__ import annotations

import gzip
import json
import os
import shutil
from pathlib import Path

import pytest

from conftest import folder_files, python_in_subprocess
from frontiernet.benchmark.store import read_pack
from frontiernet.cli.main import main
from frontiernet.errors import InputError
from test_bad_input_probe12 import a_pack, small  # noqa: F401 (a fixture)
from test_benchmark import bench

SMALL = "docs/benchmark/loop_fixes/base"
"""A small tracked benchmark folder (40 packed runs, its table.md), copied, never written to."""


def links(folder: Path) -> dict:
    return {path.relative_to(folder): os.readlink(path) for path in sorted(folder.rglob("*")) if path.is_symlink()}


DANGLING = "which does not exist; make its target first, or remove the link, or choose another output"
"""The end of :func:`frontiernet.io.check_not_dangling`'s refusal of an output that is a link to nothing."""


@pytest.fixture
def unpacked(small) -> tuple[Path, list[str]]:
    """:data:`SMALL` with its plan as plan.json and its first pack's runs as per-run metrics.json (as a benchmark
    leaves them before a pack), that pack removed; (the folder, those runs' keys)."""
    (small / "plan.json").write_bytes(gzip.decompress((small / "plan.json.gz").read_bytes()))
    (small / "plan.json.gz").unlink()
    pack = a_pack(small)
    records = read_pack(pack)
    for key, record in records.items():
        path = small / "runs" / key / "metrics.json"
        path.parent.mkdir(parents=True)
        path.write_text(json.dumps(record, indent=2) + "\n")
    pack.unlink()
    return small, list(records)


@pytest.mark.parametrize("action", ["--pack", "--report"])
def test_a_metrics_file_that_is_a_folder_is_refused_by_pack_as_by_report(action, unpacked, one_line_error):
    # S11: --pack "packed 3 run(s) ...", exit 0, the run left out without a word and the plan packed
    folder, keys = unpacked
    metrics = folder / "runs" / keys[-1] / "metrics.json"
    metrics.unlink()
    metrics.mkdir()
    before = folder_files(folder)
    assert main(["bench", action, "--out", str(folder)]) == 2
    assert one_line_error().endswith(f"{metrics}: not a run's metrics (a folder); remove the run's folder to run it "
                                     "again")
    assert folder_files(folder) == before and (folder / "plan.json").is_file() and metrics.is_dir()


def test_a_method_folder_that_is_a_file_is_refused_by_pack(unpacked, one_line_error):
    # S11 (c19): the method's runs skipped, the plan packed
    folder, keys = unpacked
    method = folder / "runs" / keys[0].rsplit("/", 1)[0]
    shutil.rmtree(method)
    method.write_text("")
    before = folder_files(folder)
    assert main(["bench", "--pack", "--out", str(folder)]) == 2
    error = one_line_error()
    assert f"{method}/" in error and "metrics.json: not a run's metrics (Not a directory)" in error
    assert folder_files(folder) == before and not (folder / "plan.json.gz").exists()


def test_a_metrics_file_that_is_a_pipe_is_refused_by_pack_not_waited_on(unpacked):
    # S11 (c16): the same for a FIFO
    folder, keys = unpacked
    metrics = folder / "runs" / keys[0] / "metrics.json"
    metrics.unlink()
    os.mkfifo(metrics)
    before = folder_files(folder)
    result = python_in_subprocess("import sys; from frontiernet.cli.main import main; "
                           f"sys.argv = ['frontiernet', 'bench', '--pack', '--out', {str(folder)!r}]; sys.exit(main())")
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [f"frontiernet bench: error: {metrics}: not a run's metrics (not a "
                                                  "regular file); remove the run's folder to run it again"]
    assert folder_files(folder) == before and not (folder / "plan.json.gz").exists()


def test_pack_still_packs_the_finished_runs_and_leaves_those_not_run(unpacked, capsys):
    # (a planned run with no metrics.json is not finished: no refusal)
    folder, keys = unpacked
    shutil.rmtree(folder / "runs" / keys[-1])
    assert main(["bench", "--pack", "--out", str(folder)]) == 0, capsys.readouterr().err
    assert set(read_pack(a_pack(folder))) == set(keys[:-1]) and (folder / "plan.json.gz").is_file()
    assert not any((folder / "runs").rglob("metrics.json"))


@pytest.mark.parametrize("name", ["results.csv", "table.md", "coverage_summary_procedural.png"])
def test_a_report_file_that_is_a_dangling_link_is_refused_not_replaced(name, small, tmp_path, one_line_error):
    # S12: exit 0, the link replaced by a file
    link, target = small / name, tmp_path / "gone" / name
    link.unlink(missing_ok=True)
    link.symlink_to(target)
    before = folder_files(small)
    assert main(["bench", "--report", "--out", str(small)]) == 2
    assert one_line_error().endswith(f"{link}: a symbolic link to {target}, {DANGLING}")
    assert folder_files(small) == before and links(small) == {Path(name): str(target)}


def test_check_output_files_refuses_a_dangling_link_and_takes_files_and_nothing(tmp_path):
    from frontiernet.io import check_output_files

    (tmp_path / "a.json").write_text("{}\n")
    check_output_files(tmp_path, ["a.json", "b.json"])  # a file written before, nothing yet: both fine
    (tmp_path / "c.json").symlink_to(tmp_path / "a.json")  # a link to a file: written through, as before
    check_output_files(tmp_path, ["c.json"])
    (tmp_path / "d.json").symlink_to("nowhere.json")
    with pytest.raises(InputError, match=r"d\.json: a symbolic link to nowhere\.json, which does not exist"):
        check_output_files(tmp_path, ["a.json", "d.json"])


def test_a_preview_folder_that_is_a_dangling_link_is_named_not_file_exists(tmp_path):
    # S12 (o19): "dangle_dir: cannot create output folder (File exists)"
    from datagen.preview import write_previews
    from frontiernet.io import ensure_dir

    link = tmp_path / "dangle_dir"
    link.symlink_to(tmp_path / "gone")
    words = f"{link}: a symbolic link to {tmp_path / 'gone'}, which does not exist"
    with pytest.raises(InputError, match=words):
        write_previews([{"never": "read"}], link)  # before a sample is read
    for out in (link, link / "sub"):  # ensure_dir, for the other writers: the link itself or on the way
        with pytest.raises(InputError, match=words):
            ensure_dir(out)
    assert not (tmp_path / "gone").exists() and link.is_symlink()


@pytest.mark.parametrize("action", ["--report", "--pack"])
def test_a_pack_that_is_a_dangling_link_is_named_not_read_as_not_run(action, small, tmp_path, one_line_error):
    # S13: --report "Interim: 38 of 40 runs finished", without a word
    pack, target = a_pack(small), tmp_path / "gone.jsonl.gz"
    pack.unlink()
    pack.symlink_to(target)
    before = folder_files(small)
    assert main(["bench", action, "--out", str(small)]) == 2
    assert one_line_error().endswith(f"{pack}: packed benchmark file not found: a symbolic link to {target}, which "
                                     "does not exist")
    assert folder_files(small) == before and pack.is_symlink()


def test_a_pack_truly_absent_is_runs_not_finished(small):
    from frontiernet.benchmark.main import report

    pack = a_pack(small)
    count = len(read_pack(pack))
    pack.unlink()
    assert report(small)["pending"] == count


def test_a_dangling_metrics_file_is_named(unpacked, tmp_path, one_line_error):
    # (S13 for a per-run metrics.json: read as a run not finished)
    folder, keys = unpacked
    metrics, target = folder / "runs" / keys[0] / "metrics.json", tmp_path / "gone.json"
    metrics.unlink()
    metrics.symlink_to(target)
    before = folder_files(folder)
    for action in ("--report", "--pack"):
        assert main(["bench", action, "--out", str(folder)]) == 2
        assert one_line_error().endswith(f"{metrics}: run's metrics not found: a symbolic link to {target}, which "
                                         "does not exist")
    assert folder_files(folder) == before


@pytest.mark.parametrize("setting", ["omniscient.yaw_count=4", "nbvp.yaw_samples=4"])
def test_redo_changed_with_a_setting_no_planned_run_reads_warns_nothing(setting, plan_spec, tmp_path, caplog):
    # S16: "WARNING: ...: the settings of its  changed; 0 finished runs of them discarded, to run again"
    out = tmp_path / "bench"
    args = ["--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "1", "--max-steps", "4",
            "--out", out]
    code, _, stderr = bench(*args)
    assert code == 0, stderr
    metrics = {path: path.read_bytes() for path in (out / "runs").rglob("metrics.json")}
    caplog.clear()
    code, _, stderr = bench(*args, "--redo-changed", "--set", setting)
    assert code == 0, stderr
    assert "changed" not in caplog.text and "discarded" not in caplog.text, caplog.text
    assert metrics and {path: path.read_bytes() for path in metrics} == metrics  # the finished run kept
    section, _, rest = setting.partition(".")
    key, _, value = rest.partition("=")
    plan = json.loads((out / "plan.json").read_text())
    assert plan["settings"]["conf"][section][key] == int(value)  # the plan takes the new settings, as before
