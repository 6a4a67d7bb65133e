"""Finished benchmark runs packed per (scene, method): the report and a resumed benchmark read
them as they read per-run files (frontiernet/benchmark/store.py, docs/benchmark.md)."""

from __future__ import annotations

import csv
import gzip
import json
import shutil

import numpy as np
import pytest

from frontiernet.benchmark.plan import RunSpec
from frontiernet.benchmark.store import pack_path, read_pack, read_plan, write_pack
from frontiernet.cli.main import main
from test_benchmark import bench

SCENES, METHODS = ("procedural:1", "procedural:2"), ("classic", "ours")
REPORT = ("results.csv", "table.md")


def metrics_record(rng: np.random.Generator, steps: int) -> dict:
    """A run's metrics.json record with the fields the report reads: full-precision floats, the
    coverage curve rounded to 5 decimals as a run writes it, the surface curve not (a pack stores
    the first as integer steps and keeps the second a list)."""
    curve = np.round(np.maximum.accumulate(rng.uniform(0.0, 1.0, steps + 1)), 5).tolist()
    return {"steps": steps, "max_steps": 40, "coverage": curve[-1], "success": curve[-1] > 0.4,
            "vox_at": {"25": curve[steps // 4], "50": curve[steps // 2], "100": curve[-1]},
            "surface_coverage": rng.uniform(), "surface_auc": rng.uniform(), "chamfer_m": float("nan"),
            "completeness": rng.uniform(), "path_length_m": rng.uniform(0, 20), "collisions": 0,
            "timing": {"step_ms_without_motion": rng.uniform(10, 100)}, "wall_s": rng.uniform(10, 100),
            "stop_reason": "step budget spent", "coverage_per_step": curve,
            "surface_coverage_per_step": np.maximum.accumulate(rng.uniform(0.0, 1.0, steps + 1)).tolist()}


def fake_benchmark(out) -> list[dict]:
    """A benchmark folder as `frontiernet bench` leaves it: plan.json (2 scenes x 2 methods x 2 starts
    x 2 repeats; classic's repeat 1 a copy of repeat 0) and each run's metrics.json. Returns the runs."""
    rng = np.random.default_rng(0)
    runs = []
    for scene in SCENES:
        for start in range(2):
            for repeat in range(2):
                for method in METHODS:
                    copy_of = RunSpec(scene, method, start, 0, (0, 0, 1.2, 0), 0).key \
                        if method == "classic" and repeat else None
                    spec = RunSpec(scene, method, start, repeat, (0, 0, 1.2, 0), repeat, copy_of)
                    runs.append({**spec.as_dict(), "key": spec.key})
    for run in runs:
        if not run["copy_of"]:
            (out / "runs" / run["key"]).mkdir(parents=True)
            record = metrics_record(rng, int(rng.integers(20, 41)))
            (out / "runs" / run["key"] / "metrics.json").write_text(json.dumps(record, indent=2))
    (out / "plan.json").write_text(json.dumps({"settings": {}, "start_poses": {s: [[0, 0, 1.2, 0]] * 2 for s in SCENES},
                                               "runs": runs}))
    return runs


def report_files(out) -> dict:
    return {path.name: path.read_bytes() for path in sorted(out.iterdir()) if path.name in REPORT or
            path.suffix == ".png"}


def test_packing_leaves_the_report_byte_identical_and_one_file_per_scene_and_method(tmp_path):
    per_run, packed = tmp_path / "per_run", tmp_path / "packed"
    per_run.mkdir()
    runs = fake_benchmark(per_run)
    assert bench("--report", "--out", per_run)[0] == 0
    expected = report_files(per_run)
    assert len(expected) == 2 + 3  # results.csv, table.md, a plot per scene and their mean
    shutil.copytree(per_run, packed)
    late = [run for run in runs if run["start"] == 1 and run["repeat"] == 0]  # (classic's repeat 1 copies it)
    for run in late:  # finished after the pack: read from their own files beside the packs
        shutil.move(packed / "runs" / run["key"], tmp_path / run["key"].replace("/", "_"))

    code, stdout, _ = bench("--pack", "--out", packed)
    assert code == 0 and "packed 8 run(s) into 4 file(s)" in stdout
    assert sorted(p.relative_to(packed / "runs").as_posix() for p in (packed / "runs").rglob("*") if p.is_file()) \
        == sorted(f"{run['key'].rsplit('/', 1)[0]}.jsonl.gz" for run in runs if run["start"] == 0 and run["repeat"] == 0)
    for run in late:
        shutil.move(tmp_path / run["key"].replace("/", "_"), packed / "runs" / run["key"])
    code, stdout, _ = bench("--report", "--out", packed)
    assert code == 0 and "report of 16 finished runs (0 not yet)" in stdout
    assert report_files(packed) == expected

    plan = (per_run / "plan.json").read_bytes()
    assert not (packed / "plan.json").exists() and gzip.decompress((packed / "plan.json.gz").read_bytes()) == plan
    packs = {path: path.read_bytes() for path in (packed / "runs").rglob("*.jsonl.gz")}
    code, stdout, _ = bench("--pack", "--report", "--out", packed)  # the late runs join their packs
    assert code == 0 and "packed 4 run(s) into 4 file(s); 12 runs packed" in stdout
    assert not list(packed.rglob("metrics.json")) and report_files(packed) == expected
    assert all(path.read_bytes() != data for path, data in packs.items())
    again = {path: path.read_bytes() for path in packs}
    packed_plan = (packed / "plan.json.gz").read_bytes()
    assert bench("--pack", "--out", packed)[1].startswith("bench: packed 0 run(s)")
    assert {path: path.read_bytes() for path in packs} == again  # nothing to pack: nothing rewritten
    assert (packed / "plan.json.gz").read_bytes() == packed_plan
    # the records are the per-run files' values, NaN included
    pack = read_pack(packed / "runs" / (runs[1]["key"].rsplit("/", 1)[0] + ".jsonl.gz"))
    original = json.loads((per_run / "runs" / runs[1]["key"] / "metrics.json").read_text())
    assert json.dumps(pack[runs[1]["key"]]) == json.dumps(original)


def test_a_folder_whose_runs_left_the_tree_keeps_its_report(tmp_path):
    """A record folder keeps its plan and report when its runs leave the tree (docs/benchmark/regimes,
    its sessions.md): `bench --report` there refuses rather than write an empty report over the figures."""
    fake_benchmark(tmp_path)
    assert bench("--pack", "--report", "--out", tmp_path)[0] == 0
    report = report_files(tmp_path)
    shutil.rmtree(tmp_path / "runs")
    code, _, err = bench("--report", "--out", tmp_path)
    assert code == 2 and err.count("\n") == 1 and "none of its 16 planned runs is finished here" in err
    assert report_files(tmp_path) == report
    for name in REPORT:  # with no report there, nothing is lost: an empty interim report is written
        (tmp_path / name).unlink(missing_ok=True)
    code, stdout, _ = bench("--report", "--out", tmp_path)
    assert code == 0 and "report of 0 finished runs (16 not yet)" in stdout


@pytest.mark.slow
def test_a_resumed_benchmark_skips_packed_runs_and_runs_the_rest(plan_spec, tmp_path, one_line_error):
    out = tmp_path / "bench"
    args = ["--scenes", plan_spec, "--methods", "vacuum", "--starts", "2", "--repeats", "1", "--max-steps", "8",
            "--out", out]
    code, _, stderr = bench(*args)
    assert code == 0, stderr
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert bench("--pack", "--out", out)[0] == 0 and not list(out.rglob("metrics.json"))
    (pack_file,) = (out / "runs").rglob("*.jsonl.gz")
    records = read_pack(pack_file)
    unfinished = next(key for key in records if key.endswith("start1_repeat0"))
    write_pack(pack_file, {key: value for key, value in records.items() if key != unfinished})

    assert not (out / "plan.json").exists()  # the plan is packed too, and read from there on resuming
    code, stdout, stderr = bench(*args)  # the packed run is kept, the other is run
    assert code == 0 and "2 runs (0 failed)" in stdout, stderr
    assert not (out / "plan.json").exists() and read_plan(out)["settings"]["budget"] == 8  # kept packed
    assert [line.split(":")[0] for line in stderr.splitlines() if line.startswith("bench ")] == ["bench 1/1"]
    assert f"{unfinished} vacuum done" in stderr and (out / "runs" / unfinished / "metrics.json").is_file()
    assert list(csv.DictReader(open(out / "results.csv")))[0] == rows[0]  # read from the pack

    pack_file.write_bytes(pack_file.read_bytes()[:-20])  # truncated (a copy cut off)
    assert main(["bench", *map(str, args)]) == 2
    assert str(pack_file) in (error := one_line_error()) and "not a packed benchmark file" in error
    assert (out / "runs" / unfinished / "metrics.json").is_file()  # nothing written is lost


def test_packs_store_rounded_curves_as_integer_steps_and_read_every_form_back(tmp_path):
    runs = fake_benchmark(tmp_path)
    records = {run["key"]: json.loads((tmp_path / "runs" / run["key"] / "metrics.json").read_text())
               for run in runs if not run["copy_of"]}
    assert bench("--pack", "--out", tmp_path)[0] == 0
    lines = [json.loads(line) for path in sorted((tmp_path / "runs").rglob("*.jsonl.gz"))
             for line in gzip.decompress(path.read_bytes()).decode().splitlines()]
    assert all(set(line["metrics"]["coverage_per_step"]) == {"steps_1e5"} for line in lines)
    assert all(isinstance(line["metrics"]["surface_coverage_per_step"], list) for line in lines)  # not 5 decimals
    first = lines[0]
    steps = first["metrics"]["coverage_per_step"]["steps_1e5"]
    assert all(isinstance(k, int) for k in steps) and np.cumsum(steps)[-1] == round(records[first["key"]]["coverage"] * 1e5)
    packed = {key: record for path in (tmp_path / "runs").rglob("*.jsonl.gz") for key, record in read_pack(path).items()}
    for key, record in records.items():  # the very floats of the run's file, NaN aside
        assert packed[key]["coverage_per_step"] == record["coverage_per_step"]
        assert packed[key]["surface_coverage_per_step"] == record["surface_coverage_per_step"]
    old = tmp_path / "old" / "procedural_1-x"  # a pack written before: curves as lists
    old.mkdir(parents=True)
    (old / "ours.jsonl.gz").write_bytes(gzip_lines(json.dumps({"key": "procedural_1-x/ours/start0_repeat0",
                                                               "metrics": records[first["key"]]})))
    assert read_pack(old / "ours.jsonl.gz")["procedural_1-x/ours/start0_repeat0"]["coverage_per_step"] == \
        records[first["key"]]["coverage_per_step"]


def test_packing_rewrites_older_list_form_packs_with_the_same_records_and_report(tmp_path):
    runs = fake_benchmark(tmp_path)
    assert bench("--pack", "--report", "--out", tmp_path)[0] == 0
    expected = report_files(tmp_path)
    packs = sorted((tmp_path / "runs").rglob("*.jsonl.gz"))
    today = {path: path.read_bytes() for path in packs}
    old = packs[0]  # as packs were written before 2026-11-28: the curves as lists of floats
    lines = gzip.decompress(today[old]).decode().splitlines()
    old.write_bytes(gzip_lines(*(json.dumps({"key": entry["key"], "metrics": read_pack(old)[entry["key"]]})
                                 for entry in map(json.loads, lines))))
    assert isinstance(next(iter(read_pack(old).values()))["coverage_per_step"], list)
    assert "steps_1e5" not in gzip.decompress(old.read_bytes()).decode()
    late = next(run for run in runs if not run["copy_of"] and pack_path(tmp_path, run["key"]) != old)  # another pack's new run
    records = read_pack(pack_path(tmp_path, late["key"]))
    record = records.pop(late["key"])
    write_pack(pack_path(tmp_path, late["key"]), records)
    (tmp_path / "runs" / late["key"]).mkdir(parents=True)
    (tmp_path / "runs" / late["key"] / "metrics.json").write_text(json.dumps(record))

    code, stdout, _ = bench("--pack", "--report", "--out", tmp_path)
    assert code == 0 and "packed 1 run(s) into 1 file(s), 1 older pack(s) rewritten in today's form" in stdout
    assert {path: path.read_bytes() for path in packs} == today  # both packs as today's code writes them
    assert report_files(tmp_path) == expected
    code, stdout, _ = bench("--pack", "--out", tmp_path)
    assert code == 0 and "rewritten" not in stdout and {path: path.read_bytes() for path in packs} == today


def gzip_lines(*lines: str) -> bytes:
    return gzip.compress("\n".join(lines).encode())


@pytest.mark.parametrize("content, reason", [
    (b"not gzip at all", "Not a gzipped file"),
    (gzip_lines('{"key": "x"'), "line 1: Expecting"),
    (gzip_lines('["a list"]'), 'line 1 is not {"key": ..., "metrics": {...}}'),
    (gzip_lines('{"key": "procedural_2-d8e8f4/ours/start0_repeat0", "metrics": {}}'), "of another method or scene"),
], ids=["not-gzip", "bad-json", "not-an-entry", "other-group"])
def test_a_corrupt_pack_is_one_line_naming_it_and_exit_2(tmp_path, one_line_error, content, reason):
    fake_benchmark(tmp_path)
    assert bench("--pack", "--out", tmp_path)[0] == 0
    pack_file = sorted((tmp_path / "runs").rglob("*.jsonl.gz"))[0]
    pack_file.write_bytes(content)
    for command in ("--report", "--pack"):
        assert main(["bench", command, "--out", str(tmp_path)]) == 2
        error = one_line_error()
        assert error.startswith(f"frontiernet bench: error: {pack_file}: not a packed benchmark file") and reason in error


def test_a_pack_with_a_curve_that_is_not_integer_steps_is_one_line_naming_it(tmp_path, one_line_error):
    fake_benchmark(tmp_path)
    assert bench("--pack", "--out", tmp_path)[0] == 0
    pack_file = sorted((tmp_path / "runs").rglob("*.jsonl.gz"))[0]
    key = f"{pack_file.parent.name}/{pack_file.name[:-len('.jsonl.gz')]}/start0_repeat0"
    pack_file.write_bytes(gzip_lines(json.dumps({"key": key, "metrics": {"coverage_per_step": {"steps_1e5": [0.5]}}})))
    assert main(["bench", "--report", "--out", str(tmp_path)]) == 2
    assert one_line_error() == (f"frontiernet bench: error: {pack_file}: not a packed benchmark file (line 1: "
                                'coverage_per_step is neither a list nor {"steps_1e5": [integers]}); restore it '
                                "(git checkout, a copy) or remove it to run its runs again")


def test_a_corrupt_metrics_file_is_one_line_and_nothing_is_packed(tmp_path, one_line_error):
    runs = fake_benchmark(tmp_path)
    (tmp_path / "runs" / runs[-1]["key"] / "metrics.json").write_text('{"steps": 4, ')  # cut off mid-write
    assert main(["bench", "--pack", "--out", str(tmp_path)]) == 2
    assert f"{runs[-1]['key']}/metrics.json: not a run's metrics" in one_line_error()
    assert len(list(tmp_path.rglob("metrics.json"))) == 12 and not list(tmp_path.rglob("*.jsonl.gz"))
    assert main(["bench", "--pack", "--out", str(tmp_path / "elsewhere")]) == 2
    assert "no benchmark here" in one_line_error()


def test_a_corrupt_packed_plan_is_one_line_naming_it(tmp_path, one_line_error):
    fake_benchmark(tmp_path)
    (tmp_path / "plan.json").unlink()
    (tmp_path / "plan.json.gz").write_bytes(b"not gzip")
    assert main(["bench", "--report", "--out", str(tmp_path)]) == 2
    assert f"{tmp_path / 'plan.json.gz'}: not a benchmark plan" in one_line_error()
