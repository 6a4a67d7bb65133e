"""The exploration benchmark (issue 6): shared starts, resumable parallel runs, the report they write
(the report's own tables and intervals: test_benchmark_report.py)."""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import check_sigterm_ends_workers, scenes_config
from frontiernet.cli.main import main
from frontiernet.config import load_config

OLD_ROBOT = ("sim.agent.radius_m=0.2", "sim.voxels.floor_clearance_m=0.2", "planner.clearance_m=0.3")
"""The robot every fixed-budget folder ran with (0.1 m, 0.1 m and 0.2 m since 2026-12-06):
docs/benchmark/published/resume.sh sets it back."""


def bench(*args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["bench", *[str(a) for a in args]])
    return code, out.getvalue(), err.getvalue()


def test_a_background_run_says_how_long_the_runs_left_take_at_its_rate_so_far():
    from frontiernet.benchmark.runner import time_left

    assert time_left(3600.0, 60, 338) == "about 4.6 h left"  # a minute a run, 278 to go
    assert time_left(600.0, 10, 15) == "about 5 min left"
    assert time_left(20.0, 2, 3) == "about 10 s left"
    assert time_left(0.0, 0, 5) == "" and time_left(100.0, 5, 5) == ""  # nothing to go on; nothing left


@pytest.mark.slow
def test_benchmark_runs_shares_starts_resumes_and_reports(plan_spec, tmp_path):
    out = tmp_path / "bench"
    args = ["--scenes", plan_spec, "--methods", "classic,random-frontier", "--starts", "2", "--repeats", "1",
            "--max-steps", "40", "--out", out]
    code, stdout, stderr = bench(*args)
    assert code == 0, stderr
    assert "Vox@25" in stdout and "4 runs (0 failed)" in stdout
    # not on a terminal (a background run's log): a line per finished run, with the time left but on the last
    lines = [line for line in stderr.splitlines() if line.startswith("bench ") and "/4: " in line]
    assert len(lines) == 4 and all(" left" in line for line in lines[:3]) and " left" not in lines[3]

    rows = list(csv.DictReader(open(out / "results.csv")))
    assert len(rows) == 4 and {r["status"] for r in rows} == {"done"}
    assert {(r["method"], r["start"]) for r in rows} == {(m, s) for m in ("classic", "random-frontier") for s in "01"}
    assert "depth" not in rows[0]  # one depth source: the columns, keys and plan of before several existed
    plan = json.loads((out / "plan.json").read_text())
    assert all("depth" not in run and "@" not in run["key"] for run in plan["runs"])
    poses = plan["start_poses"][plan_spec]
    assert len(poses) == 2 and poses[0] != poses[1]
    for row in rows:  # both methods started from the same pose
        run = next(r for r in plan["runs"] if r["method"] == row["method"] and str(r["start"]) == row["start"])
        metrics = json.loads((out / "runs" / run["key"] / "metrics.json").read_text())
        assert np.allclose(np.array(metrics["start"])[:2, 3], run["start_pose"][:2], atol=1e-3)
        assert metrics["collisions"] == 0 and float(row["vox25_shared"]) <= float(row["vox100"]) + 1e-9
    table = (out / "table.md").read_text()
    assert "| classic |" in table and "| random-frontier |" in table and "+-" in table
    assert list(out.glob("coverage_*.png"))

    # resumed: finished runs are not redone
    stamps = {p: p.stat().st_mtime_ns for p in (out / "runs").rglob("metrics.json")}
    code, stdout, stderr = bench(*args)
    assert code == 0, stderr
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    assert "bench 1/" not in stderr  # progress counts the runs to do, none here

    # --report rebuilds the report from the finished runs alone (here: one run not finished yet)
    unfinished = next(r for r in plan["runs"] if r["method"] == "classic" and r["start"] == 1)
    (out / "runs" / unfinished["key"]).rename(out / "elsewhere")
    code, stdout, stderr = bench("--report", "--out", out)
    assert code == 0, stderr
    assert "report of 3 finished runs (1 not yet)" in stdout
    assert (out / "table.md").read_text().startswith("Interim: 3 of 4 runs finished")
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert len(rows) == 3 and ("classic", "1") not in {(r["method"], r["start"]) for r in rows}
    code, stdout, stderr = bench(*args)  # resumed again: only that run is done, and progress says so
    assert code == 0 and f"bench 1/1: {unfinished['key']} classic done" in stderr and "4 runs (0 failed)" in stdout


@pytest.mark.slow
def test_a_benchmark_grows_by_a_command_that_names_only_what_it_adds(plan_spec, tmp_path):
    """More starts of one method (issue 54's second pass of two methods): the runs of the plan that
    the command does not name stay in the plan, the report and the table; only the new run is run."""
    out = tmp_path / "bench"
    common = ["--scenes", plan_spec, "--repeats", "1", "--max-steps", "30", "--out", out]
    code, stdout, stderr = bench("--methods", "classic,random-frontier", "--starts", "1", *common)
    assert code == 0, stderr
    first = json.loads((out / "plan.json").read_text())
    stamps = {p: p.stat().st_mtime_ns for p in (out / "runs").rglob("metrics.json")}

    code, stdout, stderr = bench("--methods", "classic", "--starts", "2", *common)
    assert code == 0, stderr
    assert "bench 1/1: " in stderr and "classic/start1_repeat0 classic done" in stderr  # only the added run
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    plan = json.loads((out / "plan.json").read_text())
    assert {(r["method"], r["start"]) for r in plan["runs"]} == \
        {("classic", 0), ("random-frontier", 0), ("classic", 1)}
    assert plan["start_poses"][plan_spec][0] == first["start_poses"][plan_spec][0]  # the same first start
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert {(r["method"], r["start"]) for r in rows} == {("classic", "0"), ("random-frontier", "0"), ("classic", "1")}
    assert "| random-frontier |" in (out / "table.md").read_text() and "3 runs (0 failed)" in stdout
    code, stdout, stderr = bench("--report", "--out", out)
    assert code == 0 and "report of 3 finished runs (0 not yet)" in stdout


@pytest.mark.slow
def test_model_goes_to_the_methods_that_run_it_and_every_other_runs_without(plan_spec, tmp_path):
    """`--model` beside methods that run none (the published protocol's command): each run of those
    gets no model, where the per-run check would refuse one (every classic run failed so)."""
    from conftest import REPO_ROOT

    model = REPO_ROOT / "frontiernet" / "weights" / "frontiernet_rgbd_resnet18.safetensors"
    code, stdout, stderr = bench("--scenes", plan_spec, "--methods", "classic,frontiernet", "--starts", "1",
                                 "--repeats", "1", "--max-steps", "12", "--model", model, "--out", tmp_path / "b")
    assert code == 0, stderr
    assert "2 runs (0 failed)" in stdout
    rows = {r["method"]: r for r in csv.DictReader(open(tmp_path / "b" / "results.csv"))}
    assert {r["status"] for r in rows.values()} == {"done"}
    # the benchmark grows by classic alone under its --model (a setting of its plan, whose frontiernet runs
    # read it); a new benchmark of classic alone has no use for one
    code, stdout, stderr = bench("--scenes", plan_spec, "--methods", "classic", "--starts", "2", "--repeats", "1",
                                 "--max-steps", "12", "--model", model, "--out", tmp_path / "b")
    assert code == 0 and "3 runs (0 failed)" in stdout, stderr
    code, stdout, stderr = bench("--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "1",
                                 "--max-steps", "12", "--model", model, "--out", tmp_path / "c")
    assert code == 2 and "none of the methods classic runs a FrontierNet model" in stderr


@pytest.mark.slow
def test_repeats_of_a_method_that_draws_nothing_are_reported_from_its_first_run(plan_spec, tmp_path):
    """classic on ground-truth depth repeats its run exactly (test_methods), so its repeat 1 is not
    run but reported from repeat 0; random-frontier draws, so both repeats run."""
    out = tmp_path / "bench"
    code, stdout, stderr = bench("--scenes", plan_spec, "--methods", "classic,random-frontier", "--starts", "1",
                                 "--repeats", "2", "--max-steps", "30", "--out", out)
    assert code == 0, stderr
    assert "4 runs (0 failed, 1 identical repeats taken from repeat 0)" in stdout
    rows = {(r["method"], r["repeat"]): r for r in csv.DictReader(open(out / "results.csv"))}
    copy, first = rows[("classic", "1")], rows[("classic", "0")]
    assert copy["status"] == "done" and copy["seed"] == "1" and copy["copy_of"].endswith("classic/start0_repeat0")
    assert {k: v for k, v in copy.items() if k not in ("repeat", "seed", "copy_of")} == \
        {k: v for k, v in first.items() if k not in ("repeat", "seed", "copy_of")}
    assert not rows[("random-frontier", "1")]["copy_of"]
    runs = {p.parent.relative_to(out / "runs").as_posix().split("/", 1)[1] for p in (out / "runs").rglob("metrics.json")}
    assert runs == {"classic/start0_repeat0", "random-frontier/start0_repeat0", "random-frontier/start0_repeat1"}
    final = (out / "results.csv").read_text()
    assert bench("--report", "--out", out)[0] == 0 and (out / "results.csv").read_text() == final  # copies too


@pytest.mark.slow
def test_several_depth_sources_run_every_run_once_per_source_from_the_same_starts_and_seeds(plan_spec, tmp_path):
    """--depth gt,emulated: each (start, repeat, method) once per source, the same pose and seed;
    classic's repeat 1 is a copy on ground truth (it draws nothing) and a run of its own on the
    seeded emulated depth; results.csv has a depth column, table.md a part per source and the
    penalty; --report and a resumed benchmark rebuild the same report, packed or not."""
    from frontiernet.benchmark.store import read_pack

    out = tmp_path / "bench"
    args = ["--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "2", "--max-steps", "4",
            "--depth", "gt,emulated", "--out", out]
    code, stdout, stderr = bench(*args)
    assert code == 0 and "4 runs (0 failed, 1 identical repeats taken from repeat 0)" in stdout, stderr
    plan = json.loads((out / "plan.json").read_text())
    assert plan["settings"]["depth"] == "gt,emulated"
    runs = {(run["depth"], run["repeat"]): run for run in plan["runs"]}
    assert sorted(runs) == [("emulated", 0), ("emulated", 1), ("ground_truth", 0), ("ground_truth", 1)]
    assert {tuple(run["start_pose"]) for run in runs.values()} == {tuple(plan["start_poses"][plan_spec][0])}
    assert runs[("ground_truth", 1)]["seed"] == runs[("emulated", 1)]["seed"] == 1
    assert runs[("ground_truth", 1)]["copy_of"] == runs[("ground_truth", 0)]["key"]
    assert runs[("emulated", 1)]["copy_of"] is None and runs[("emulated", 0)]["key"].split("/")[1] == "classic@emulated"
    for (depth, repeat), run in runs.items():  # each run used its own source
        if not run["copy_of"]:
            assert json.loads((out / "runs" / run["key"] / "metrics.json").read_text())["depth"] == depth
    header = (out / "results.csv").read_text().splitlines()[0]
    assert header.startswith("scene,method,depth,start,repeat,")
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert [(r["depth"], r["repeat"]) for r in rows] == [("ground_truth", "0"), ("emulated", "0"),
                                                          ("ground_truth", "1"), ("emulated", "1")]
    table = (out / "table.md").read_text()
    assert "## ground_truth depth: summary" in table and "## emulated depth: summary" in table
    assert "### Monocular penalty: emulated / ground_truth depth" in table and "| classic | " in table
    written = {name: (out / name).read_bytes() for name in ("results.csv", "table.md")}
    code, _, stderr = bench(*args)  # resumed: nothing to run, the same report
    assert code == 0 and "bench 1/" not in stderr
    assert {name: (out / name).read_bytes() for name in written} == written
    code, stdout, _ = bench("--pack", "--report", "--out", out)
    assert code == 0 and "report of 4 finished runs (0 not yet)" in stdout
    assert {name: (out / name).read_bytes() for name in written} == written
    assert set(read_pack(out / "runs" / (runs[("emulated", 0)]["key"].rsplit("/", 1)[0] + ".jsonl.gz"))) == \
        {runs[("emulated", 0)]["key"], runs[("emulated", 1)]["key"]}
    code, _, stderr = bench(*args[:-3], "emulated,gt", "--out", out)  # another order is another benchmark
    assert code == 2 and "other settings" in stderr


PUBLISHED_RESULTS_SHA256 = "fd0ee640f8a0709943332df28f5ece252b80e0fbf7b4615521dae094628262c0"
"""docs/benchmark/published/results.csv as tracked until 2026-12-07 (git show 0f6c59a:docs/benchmark/published/
results.csv); untracked since to keep the tree under 10 MB (its .gitignore), its bytes still checked."""


@pytest.mark.slow
def test_the_published_benchmarks_report_is_rebuilt_byte_for_byte(tmp_path, request):
    """docs/benchmark/published (one depth source, packed) reports as it did before several sources."""
    import shutil

    from conftest import REPO_ROOT

    published = REPO_ROOT / "docs" / "benchmark" / "published"
    shutil.copytree(published, tmp_path / "published", ignore=shutil.ignore_patterns("*.png"))
    assert bench("--report", "--out", tmp_path / "published")[0] == 0
    rebuilt = (tmp_path / "published" / "results.csv").read_bytes()
    assert hashlib.sha256(rebuilt).hexdigest() == PUBLISHED_RESULTS_SHA256  # the file as it was tracked
    # table.md groups scenes by source, read from the scene files the plan names (../shared/data/...): a
    # checkout without them reports the KTH plans as "other", so that half needs the shared data
    request.getfixturevalue("shared_data")
    assert (tmp_path / "published" / "table.md").read_bytes() == (published / "table.md").read_bytes()


@pytest.mark.slow
def test_the_ray_backend_gives_the_rows_of_local_processes(plan_spec, tmp_path):
    pytest.importorskip("ray")
    common = ["--scenes", plan_spec, "--methods", "classic", "--starts", "2", "--repeats", "1", "--max-steps", "20",
              "--workers", "2"]
    results = {}
    for backend in ("local", "ray"):
        code, stdout, stderr = bench(*common, "--backend", backend, "--out", tmp_path / backend)
        assert code == 0, stderr
        results[backend] = [{k: v for k, v in row.items() if k not in ("wall_s", "step_ms")}
                            for row in csv.DictReader(open(tmp_path / backend / "results.csv"))]
    assert len(results["ray"]) == 2 and results["ray"] == results["local"]


@pytest.mark.slow
def test_a_failing_run_is_recorded_with_its_error_and_the_rest_go_on(plan_spec, tmp_path):
    out = tmp_path / "bench"
    code, stdout, stderr = bench("--scenes", plan_spec, "--methods", "vacuum", "--starts", "1", "--repeats", "1",
                                 "--max-steps", "8", "--out", out, "--set", "planner.clearance_m=0.05")
    assert code == 1 and "1 of 1 runs failed; their errors are in" in stderr, stderr  # (a bad --depth is
    # refused up front: tests/test_bad_input.py)
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert rows[0]["status"] == "failed" and "planner.clearance_m" in rows[0]["error"]
    assert "1 run(s) failed" in (out / "table.md").read_text()
    assert list((out / "failed").glob("*.json"))
    assert bench("--report", "--out", out)[0] == 0 and "1 run(s) failed" in (out / "table.md").read_text()


@pytest.mark.parametrize("args, message", [
    (["--methods", "classic,no-such-method"], "unknown method 'no-such-method'; valid: classic"),
    (["--max-steps", "3"], "at least 4 steps"),
    (["--starts", "0"], "--starts must be an integer in [1, 1000], got 0"),
    (["--backend", "slurm"], "--backend must be one of local, ray"),
    (["--scenes", "procedural:9-2"], "seed range must satisfy 0 <= FIRST <= LAST"),
    (["--model", "no/such/model.onnx"], "no/such/model.onnx: model file not found"),  # not a failed run each
    (["--set", "depth.emulated.fill_dept=20"], "unknown config key 'depth.emulated.fill_dept'"),
    (["--set", "sim.camera.max_dept=5"], "unknown config key 'sim.camera.max_dept'"),
    (["--depth", "gt,sonar"], "depth source 'sonar' (--depth, run.depth) is unknown; valid: gt, ground_truth"),
    (["--depth", "gt,emulated,ground_truth"], "source 'ground_truth' is given twice in 'gt,emulated,ground_truth'"),
    (["--depth", "gt,,emulated"], "depth sources 'gt,,emulated' (--depth, run.depth) have an empty item"),
    (["--depth", "emulated,"], "have an empty item"),
])
def test_bad_benchmark_input_exits_2_with_one_line(plan_spec, tmp_path, args, message):
    steps = [] if "--max-steps" in args else ["--max-steps", "20"]  # (an option given twice is refused)
    code, _, stderr = bench("--scenes", plan_spec, *steps, "--out", tmp_path / "b", *args)
    assert code == 2 and message in stderr and stderr.count("\n") == 1
    assert not (tmp_path / "b").exists()  # refused before anything is written


def test_set_reaches_sim_and_depth_keys_of_every_run(plan_spec, tmp_path):
    """`--set` (and --config) set sim.yaml and depth.yaml keys for the whole benchmark: the plan
    records them (a resumed benchmark with other values is refused) and every run uses them."""
    import yaml

    out = tmp_path / "bench"
    args = ["--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "1", "--max-steps", "4",
            "--depth", "emulated", "--out", out, "--set", "map.max_range_m=3.0", "depth.emulated.scale_per_frame=false",
            "sim.camera.max_depth=3.0"]  # (the map's rays reach no farther than the camera: configs/ranges/explore.yaml)
    code, stdout, stderr = bench(*args)
    assert code == 0 and "1 runs (0 failed)" in stdout, stderr
    conf = json.loads((out / "plan.json").read_text())["settings"]["conf"]
    assert conf["depth"]["emulated"]["scale_per_frame"] is False and conf["sim"]["camera"]["max_depth"] == 3.0
    used = yaml.safe_load(next((out / "runs").rglob("config.yaml")).read_text())
    assert used["depth"]["emulated"]["scale_per_frame"] is False and used["sim"]["camera"]["max_depth"] == 3.0
    code, _, stderr = bench(*args[:-1], "sim.camera.max_depth=3.2")
    assert code == 2 and "other settings" in stderr and stderr.count("\n") == 1
    # a plan made before runs had sim, depth and scenes sections used the shipped files: it resumes without --set
    plan = json.loads((out / "plan.json").read_text())
    for section in ("sim", "depth", "scenes"):
        del plan["settings"]["conf"][section]
    plan["settings"]["conf"]["planner"]["clearance_m"] = 0.3  # as such plans had it: the robot of then ...
    (out / "plan.json").write_text(json.dumps(plan))
    assert bench(*args)[0] == 2
    code, stdout, stderr = bench(*args[:-4], "--set", "map.max_range_m=3.0", *OLD_ROBOT)  # ... whose sim section was shipped then
    assert code == 0 and "1 runs (0 failed)" in stdout, stderr


def test_a_second_benchmark_on_a_folder_in_use_is_refused_at_once(plan_spec, tmp_path):
    """Two `bench` commands on one --out would run the same runs twice and write one plan over the
    other: the second is refused while the first holds the folder (issue 55's bad-input probe);
    --report and --pack still read a folder in use."""
    from frontiernet.io import claim_output_folder

    out = tmp_path / "bench"
    with claim_output_folder(out, force=True):  # a benchmark running there
        code, _, stderr = bench("--scenes", plan_spec, "--methods", "classic", "--starts", "1", "--repeats", "1",
                                "--max-steps", "40", "--out", out)
    assert code == 2 and "another run" in stderr and "is writing there" in stderr
    assert not (out / "plan.json").exists()


def test_report_of_a_folder_without_a_benchmark_says_so(tmp_path, one_line_error):
    assert main(["bench", "--report", "--out", str(tmp_path)]) == 2
    assert "no benchmark here" in one_line_error()
    assert main(["bench", "--report"]) == 2
    assert "--report needs --out" in one_line_error()


def test_bench_without_a_benchmark_or_scenes_says_what_to_give():
    code, _, stderr = bench()
    assert code == 2 and "--scenes" in stderr


def kth_folder(folder, starts, wall=48, door=(20, 40)) -> str:
    """A two-room plan in KTH/MapEx's layout (0.05 m/px) with a start_poses.json of `starts` (raw row,
    col): rooms left and right of a 4 px wall from column `wall`, joined by a door over rows `door`."""
    occ = np.full((60, 100), 254, np.uint8)
    occ[10:50, 10:13] = occ[10:50, 87:90] = occ[10:13, 10:90] = occ[47:50, 10:90] = 0
    occ[10:50, wall:wall + 4] = 0
    occ[door[0]:door[1], wall:wall + 4] = 254  # default: a 1 m door
    valid = np.zeros_like(occ)
    valid[13:47, 13:wall], valid[13:47, wall + 4:87] = 1, 2
    np.save(folder / "occ_map.npy", occ)
    np.save(folder / "valid_space.npy", valid)
    (folder / "start_poses.json").write_text(json.dumps({"start_poses": [{"raw_pixel_row_col": s} for s in starts]}))
    return f"floorplan:{folder}"


def test_a_folder_of_floor_plans_is_benchmarked_plan_by_plan(tmp_path):
    plans = tmp_path / "kth"
    for name, wall in (("plan_a", 48), ("plan_b", 40)):
        (plans / name).mkdir(parents=True)
        kth_folder(plans / name, [[30, 30]], wall=wall)
    out = tmp_path / "bench"
    code, _, stderr = bench("--scenes", plans, "--methods", "vacuum", "--starts", "1", "--repeats", "1",
                            "--max-steps", "8", "--out", out)
    assert code == 0, stderr
    plan = json.loads((out / "plan.json").read_text())
    assert list(plan["start_poses"]) == [str(plans / "plan_a"), str(plans / "plan_b")]
    assert {row["status"] for row in csv.DictReader(open(out / "results.csv"))} == {"done"}


def test_scene_starts_come_first_from_a_plan_folders_start_poses(tmp_path):
    from frontiernet.benchmark.plan import start_poses

    spec = kth_folder(tmp_path, [[30, 30], [30, 70]])
    conf = load_config("explore")
    poses = start_poses(spec, 3, 0, conf, scene_starts=True)
    H, s = 60, 0.05
    expected = [((30 + 0.5) * s, (H - 30 - 0.5) * s), ((70 + 0.5) * s, (H - 30 - 0.5) * s)]
    np.testing.assert_allclose([p[:2] for p in poses[:2]], expected, atol=1e-4)
    assert poses[0][2] == pytest.approx(conf.motion.camera_height_m) and len(poses) == 3  # the third is sampled
    assert start_poses(spec, 3, 0, conf, scene_starts=True) == poses  # seeded headings
    assert [p[:2] for p in start_poses(spec, 2, 0, conf)] != [p[:2] for p in poses[:2]]  # without: sampled


def test_a_shipped_start_shut_in_by_a_narrow_door_is_left_out_and_sampled_starts_avoid_it(tmp_path, caplog):
    """Room 2's door is 0.25 m wide, narrower than the robot's 2 x 0.2 m clearance: its shipped start
    is left out (logged) and every start lies in room 1, the region the robot can travel."""
    from frontiernet.benchmark.plan import start_poses
    from frontiernet.config import load_config

    spec = kth_folder(tmp_path, [[30, 75], [30, 30]], wall=60, door=(28, 33))  # a 0.25 m door
    with caplog.at_level("WARNING"):
        poses = start_poses(spec, 4, 0, load_config("explore"), scene_starts=True)
    assert "shipped start 0" in caplog.text and "too narrow" in caplog.text
    assert poses[0][:2] == pytest.approx(((30 + 0.5) * 0.05, (60 - 30 - 0.5) * 0.05), abs=1e-4)  # start 1
    assert len(poses) == 4 and all(x < 60 * 0.05 for x, *_ in poses)  # the rest sampled in room 1


def test_a_shipped_start_on_a_wall_is_an_input_error(tmp_path):
    from frontiernet.errors import InputError
    from frontiernet.scenes import load_scene

    with pytest.raises(InputError, match="start_poses.json: start pose"):
        load_scene(kth_folder(tmp_path, [[11, 30]]), scenes_config())


def test_hot_path_benchmarks_keep_their_scene_option_beside_the_exploration_benchmark():
    # `--scene` of `bench map` must not be taken for an abbreviation of the benchmark's `--scenes`
    code, stdout, stderr = bench("map", "--scene", "procedural:0", "--frames", "2", "--views", "2", "--json")
    assert code == 0, stderr
    assert json.loads(stdout)["scene"] == "procedural:0"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads worker processes from Linux's /proc")
def test_stopping_the_benchmark_with_sigterm_ends_its_workers(plan_spec, tmp_path):
    """`kill PID` of a running benchmark (SIGTERM to the main process alone) must not leave its
    workers running their explorations unseen beside the resumed benchmark."""
    check_sigterm_ends_workers(["bench", "--scenes", plan_spec, "--methods", "classic", "--starts", "2", "--repeats",
                                "1", "--max-steps", "2000", "--workers", "2", "--out", str(tmp_path / "bench")])


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads worker processes from Linux's /proc")
def test_a_run_whose_worker_is_killed_is_run_again_and_the_benchmark_completes(plan_spec, tmp_path):
    """A worker killed mid-run (out of memory, `kill -9`) costs its runs one more try, not a failed row."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from conftest import _alive, _spawned_children

    out = tmp_path / "bench"
    process = subprocess.Popen([sys.executable, "-m", "frontiernet.cli.main", "bench", "--scenes", plan_spec,
                                "--methods", "classic", "--starts", "2", "--repeats", "1", "--max-steps", "20",
                                "--workers", "2", "--out", str(out)], stderr=subprocess.PIPE, text=True)
    found = []
    try:
        deadline = time.monotonic() + 120
        while len(found := _spawned_children(process.pid)) < 2 and time.monotonic() < deadline:
            assert process.poll() is None, process.communicate()[1][-2000:]
            time.sleep(0.1)
        assert len(found) >= 2, "the benchmark started no workers"
        os.kill(found[-1], signal.SIGKILL)  # (its runs have not ended yet: a worker's imports alone take seconds)
        _, stderr = process.communicate(timeout=300)
    finally:  # a failed check leaves nothing running
        if process.poll() is None:
            process.kill()
        for pid in _alive(found):
            os.kill(pid, signal.SIGKILL)
    assert process.returncode == 0, stderr[-2000:]
    assert "a worker process died; retrying" in stderr
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert [row["status"] for row in rows] == ["done", "done"], rows
