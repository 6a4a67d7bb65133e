"""The exploration benchmark's report (issue 6; issue 27's monocular penalty): shared Vox@k
thresholds, Table I per scene and source, paired ratios to classic with their bootstrap interval,
the compute of the runs made, the coverage plots."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from frontiernet.benchmark.plan import scene_key
from frontiernet.benchmark.comparisons import ratio_interval
from frontiernet.benchmark.report import add_shared_vox, coverage_at, table_markdown, write_report
from frontiernet.config import load_config

INTERVAL = load_config("bench").report.interval  # the shipped report's bootstrap


def test_shared_vox_thresholds_are_the_mean_of_each_runs_quarter_and_half():
    long = np.linspace(0.0, 1.0, 101)  # 100 steps
    short = np.concatenate([np.linspace(0.0, 0.6, 51)])  # stopped after 50 steps (no frontiers left)
    rows = [{"scene": "s", "start": 0, "repeat": 0, "method": m} for m in ("a", "b")]
    add_shared_vox(rows, {0: long, 1: short})
    # k = 25: mean(25, 12.5) = 18.75 -> step 19; k = 50: mean(50, 25) = 37.5 -> step 38 (reached)
    assert rows[0]["vox25_shared"] == pytest.approx(long[19]) and rows[1]["vox25_shared"] == pytest.approx(short[19])
    assert rows[0]["vox50_shared"] == pytest.approx(long[38]) and rows[1]["vox50_shared"] == pytest.approx(short[38])
    # beyond its end a run holds its final coverage
    assert coverage_at(short, 80) == pytest.approx(0.6)


def test_runs_of_other_comparisons_do_not_share_thresholds():
    rows = [{"scene": "s", "start": start, "repeat": 0, "method": "a"} for start in (0, 1)]
    add_shared_vox(rows, {0: np.linspace(0, 1, 101), 1: np.linspace(0, 1, 11)})
    assert rows[0]["vox25_shared"] == pytest.approx(0.25) and rows[1]["vox25_shared"] == pytest.approx(0.3)


def test_a_method_still_running_moves_no_other_methods_vox():
    """The shared steps are those of the methods with every planned run finished: a method joining a
    folder (seer's first scenes) is read at them, and the others' Vox@k stay what they were until all
    its runs are in; with no finished method among a comparison's runs, all of them set the steps."""
    from frontiernet.benchmark.report import unfinished_methods

    runs = [{"scene": scene, "method": method, "start": 0, "repeat": 0}
            for scene in ("s", "t") for method in ("a", "b", "seer")]
    rows = [{"scene": scene, "start": 0, "repeat": 0, "method": method, "status": "done"}
            for scene, method in (("s", "a"), ("s", "b"), ("s", "seer"), ("t", "a"), ("t", "b"))]
    assert unfinished_methods(runs, rows) == {"seer": (1, 2)}
    slow, fast = np.linspace(0, 1, 101), np.concatenate([np.linspace(0, 1, 11), np.ones(90)])
    curves = {0: slow, 1: slow, 2: fast, 3: slow, 4: slow}
    add_shared_vox(rows, curves, "coverage", {"a", "b"})
    assert [row["vox25_shared"] for row in rows] == pytest.approx([0.25, 0.25, 1.0, 0.25, 0.25])
    add_shared_vox(rows, curves, "coverage")  # every run: seer's fast curve pulls the step on s forward
    assert rows[0]["vox25_shared"] == pytest.approx(0.18) and rows[3]["vox25_shared"] == pytest.approx(0.25)
    add_shared_vox(rows[2:3], {0: fast}, "coverage", {"a", "b"})  # none of them in the comparison
    assert rows[2]["vox25_shared"] == pytest.approx(0.3)


def test_the_summary_gives_table_one_per_scene_source_and_over_all_scenes():
    scenes = ["procedural:1", "procedural:2", "house.glb"]
    coverage = {"procedural:1": 0.3, "procedural:2": 0.5, "house.glb": 0.9}
    rows = [{"scene": scene, "method": method, "status": "done", "vox25_shared": value / 4,
             "vox50_shared": value / 2, "vox100": value, "success": value > 0.4}
            for scene, value in coverage.items() for method in ("ours", "theirs")]
    rows.append({"scene": "house.glb", "method": "theirs", "start": 1, "repeat": 0, "status": "failed",
                 "error": "boom"})  # not in the summary's runs
    table = table_markdown(rows, scenes, ["ours", "theirs"], interval=INTERVAL)
    blocks = table.split("### ")
    procedural = next(b for b in blocks if b.startswith("Summary: procedural (2 scenes)"))
    mesh = next(b for b in blocks if b.startswith("Summary: mesh (1 scene)"))
    overall = next(b for b in blocks if b.startswith("Summary: all scenes (3 scenes)"))
    # runs, Vox@25 / 50 / 100 mean +- std over the source's runs, success as a rate
    assert "| ours | 2 | 10.0 +- 2.5 | 20.0 +- 5.0 | 40.0 +- 10.0 | 50.0 |" in procedural
    assert "| ours | 1 | 22.5 | 45.0 | 90.0 | 100.0 |" in mesh
    assert "| theirs | 3 | 14.2 +- 6.2 | 28.3 +- 12.5 | 56.7 +- 24.9 | 66.7 |" in overall
    assert table.index("Summary: all scenes") < table.index("### Vox@25 (%)")  # the summary comes first


def test_each_method_is_compared_with_classic_over_paired_runs():
    # procedural:1 from starts 0 and 1, house from start 0; `ours` beats classic on two of three
    vox25 = {("ours", "procedural:1", 0): 0.30, ("ours", "procedural:1", 1): 0.10, ("ours", "house.glb", 0): 0.40,
             ("classic", "procedural:1", 0): 0.20, ("classic", "procedural:1", 1): 0.20,
             ("classic", "house.glb", 0): 0.20, ("ours", "house.glb", 1): 0.90}  # unpaired: left out
    rows = [{"method": method, "scene": scene, "start": start, "repeat": 0, "status": "done",
             "vox25_shared": value, "vox50_shared": value, "vox100": value, "success": True}
            for (method, scene, start), value in vox25.items()]
    table = table_markdown(rows, ["procedural:1", "house.glb"], ["ours", "classic"], interval=INTERVAL)
    versus = next(b for b in table.split("### ") if b.startswith("Against classic (paired runs)"))
    # procedural: 0.2 / 0.2 with one win and one loss; house: 0.4 / 0.2; all: 0.8 / 0.6 over 3 pairs.
    # Intervals resample (scene, start) clusters: procedural's ends are both draws of one start
    # (0.1 / 0.2 and 0.3 / 0.2), all scenes' the worst and best start thrice (each 1/27 > 2.5 %);
    # the house has one cluster, so no interval
    assert ("| ours | 1.00x [0.50, 1.50] (1-1) | 1.00x [0.50, 1.50] (1-1) | 2.00x (1-0) | 2.00x (1-0) | "
            "1.33x [0.50, 2.00] (2-1) | 1.33x [0.50, 2.00] (2-1) |") in versus
    assert "| classic |" not in versus
    # no reference, no section
    assert "Against classic" not in table_markdown(rows, ["procedural:1"], ["ours"], interval=INTERVAL)


def test_methods_that_ran_more_starts_are_compared_on_all_of_them_and_the_tables_on_the_common_ones():
    """A plan grown by more starts for classic and random-frontier (``common_starts``): the summary and the
    comparisons hold the start every method ran; a section more compares the two on all their starts."""
    from frontiernet.benchmark.report import common_starts

    planned = [{"method": method, "start": start, "repeat": 0}
               for method, starts in (("classic", 3), ("random-frontier", 3), ("ours", 1)) for start in range(starts)]
    assert common_starts(planned) == ({(0, 0)}, ["classic", "random-frontier"])
    value = {"classic": 0.4, "random-frontier": 0.4, "ours": 0.6}
    rows = [{**run, "scene": "procedural:1", "status": "done", "success": True,
             **{field: value[run["method"]] * (0.5 if run["method"] == "random-frontier" and run["start"] else 1)
                for field in ("vox25_shared", "vox50_shared", "vox100")}} for run in planned]
    table = table_markdown(rows, ["procedural:1"], ["classic", "random-frontier", "ours"], interval=INTERVAL,
                           starts=common_starts(planned))
    blocks = {block.split("\n")[0]: block for block in table.split("### ")}
    assert "| classic | 1 | 40.0 | 40.0 | 40.0 | 100.0 |" in blocks["Summary: procedural (1 scene)"]
    assert "| random-frontier | 1.00x (0-0) | 1.00x (0-0) |" in blocks["Against classic (paired runs)"]
    every = blocks["Against classic on every start"]
    assert "| random-frontier | 0.67x [0.50, 1.00] (0-2) |" in every and "| ours |" not in every
    assert "classic, random-frontier ran more" in table


def test_the_monocular_penalty_is_each_methods_ratio_to_ground_truth_over_paired_runs():
    """With several depth sources the summary and the comparison with classic come per source, and
    the penalty table gives each method's mean Vox@k on a source over its mean on ground truth,
    paired by (scene, start, repeat), with the interval of the comparison with classic."""
    gt = {("ours", 0): 0.40, ("ours", 1): 0.20, ("classic", 0): 0.30, ("classic", 1): 0.30}
    mono = {("ours", 0): 0.40, ("ours", 1): 0.10, ("classic", 0): 0.15, ("classic", 1): 0.15}
    rows = [{"method": method, "depth": depth, "scene": "procedural:1", "start": start, "repeat": 0,
             "status": "done", "vox25_shared": value, "vox50_shared": value / 2, "vox100": value, "success": True}
            for depth, values in (("ground_truth", gt), ("emulated", mono))
            for (method, start), value in values.items()]
    rows.append({**rows[-1], "start": 2, "vox25_shared": 0.9})  # classic on emulated from a start without a pair
    table = table_markdown(rows, ["procedural:1"], ["ours", "classic"], depths=["ground_truth", "emulated"],
                           interval=INTERVAL)
    assert re.findall(r"^## (.+)$", table, re.M) == ["ground_truth depth: summary", "emulated depth: summary",
                                                      "ground_truth depth: per scene", "emulated depth: per scene"]
    emulated = table[table.index("## emulated depth: summary"):table.index("### Monocular penalty")]
    assert "| ours | 2 | 25.0 +- 15.0 |" in emulated and "| classic | 3 |" in emulated
    assert "| ours | 1.67x [0.67, 2.67] (1-1) |" in emulated  # against classic on emulated depth alone
    penalty = next(b for b in table.split("### ") if b.startswith("Monocular penalty: emulated / ground_truth"))
    # ours: 0.5 / 0.6 with start 0 level and start 1 lower; classic halves from both starts.
    # Vox@50 is half of Vox@25 in every run: the same ratios
    assert "| ours | 0.83x [0.50, 1.00] (0-1) | 0.83x [0.50, 1.00] (0-1) | 0.83x [0.50, 1.00] (0-1) |" in penalty
    assert "| classic | 0.50x [0.50, 0.50] (0-2) |" in penalty  # the unpaired start 2 is left out
    assert table.index("Monocular penalty") < table.index("ground_truth depth: per scene")
    only_mono = [row for row in rows if row["depth"] == "emulated"]
    assert "Monocular penalty" not in table_markdown(only_mono, ["procedural:1"], ["ours"], depths=["emulated"],
                                                     interval=INTERVAL)


def test_runs_on_other_depth_sources_do_not_share_thresholds():
    rows = [{"scene": "s", "start": 0, "repeat": 0, "method": "a", "depth": depth} for depth in ("gt", "emulated")]
    add_shared_vox(rows, {0: np.linspace(0, 1, 101), 1: np.linspace(0, 1, 11)})
    assert rows[0]["vox25_shared"] == pytest.approx(0.25) and rows[1]["vox25_shared"] == pytest.approx(0.3)


def test_the_report_gives_the_compute_of_the_runs_made_and_not_of_their_copies():
    rows = [{"method": "ours", "scene": "house.glb", "start": 0, "repeat": 0, "status": "done", "wall_s": "100",
             "copy_of": ""},
            {"method": "ours", "scene": "house.glb", "start": 0, "repeat": 1, "status": "done", "wall_s": "200",
             "copy_of": ""},
            {"method": "classic", "scene": "house.glb", "start": 0, "repeat": 0, "status": "done", "wall_s": "36",
             "copy_of": ""},
            {"method": "classic", "scene": "house.glb", "start": 0, "repeat": 1, "status": "done", "wall_s": "36",
             "copy_of": "classic/start0_repeat0"},  # reported from repeat 0, never run
            {"method": "classic", "scene": "house.glb", "start": 1, "repeat": 0, "status": "failed", "error": "boom", "wall_s": "",
             "copy_of": ""}]
    for row in rows:
        row.update(vox25_shared=0.2, vox50_shared=0.4, vox100=0.6, success=True)
    table = table_markdown(rows, ["house.glb"], ["ours", "classic"], interval=INTERVAL)
    compute = next(b for b in table.split("### ") if b.startswith("Compute"))
    assert "| ours | 2 | 150 | 0.08 |" in compute and "| classic | 1 | 36 | 0.01 |" in compute
    assert "| all | 3 | 112 | 0.09 |" in compute  # 336 s


def test_the_ratio_interval_resamples_starts_and_narrows_with_more_of_them():
    conf = load_config("bench").report.interval
    rng = np.random.default_rng(0)
    theirs = rng.uniform(0.2, 0.4, 60)
    ours = 1.2 * theirs * rng.normal(1.0, 0.1, 60)
    starts = [index // 3 for index in range(60)]  # 20 starts x 3 repeats
    low, high = ratio_interval(ours, theirs, starts, conf)
    assert low < ours.sum() / theirs.sum() < high and 1.0 < low and high < 1.4
    few_low, few_high = ratio_interval(ours[:9], theirs[:9], starts[:9], conf)
    assert few_high - few_low > high - low  # 3 starts say less than 20
    assert ratio_interval(ours, theirs, starts, conf) == (low, high)  # seeded: a rebuilt report agrees
    assert ratio_interval(2 * theirs, theirs, starts, conf) == pytest.approx((2.0, 2.0))
    assert ratio_interval(ours[:3], theirs[:3], starts[:3], conf) is None  # one start: no interval


def test_the_report_plots_each_scene_and_the_mean_of_each_source_with_several(tmp_path):
    scenes = ["procedural:1", "procedural:2", "house.glb"]
    rows = []
    for index, scene in enumerate(scenes):
        key = f"scene{index}/classic/start0_repeat0"
        (tmp_path / "runs" / key).mkdir(parents=True)
        (tmp_path / "runs" / key / "metrics.json").write_text(json.dumps({"coverage_per_step": [0.0, 0.1, 0.2, 0.3]}))
        rows.append({"scene": scene, "method": "classic", "start": 0, "repeat": 0, "key": key, "status": "done",
                     "vox100": 0.3, "success": False})
    plots = write_report(tmp_path, rows, scenes, ["classic"], interval=INTERVAL)["plots"]
    expected = [f"coverage_{scene_key(scene)}.png" for scene in scenes]
    expected += ["coverage_summary_procedural.png", "coverage_summary_all_scenes.png"]  # no mean of the one mesh
    assert sorted(path.name for path in plots) == sorted(expected)
    assert all(path.stat().st_size > 1000 for path in plots)


def test_every_method_is_reported_as_a_share_of_the_bound_overall_and_per_scene():
    scenes = ["procedural:1", "procedural:2"]
    share = {"classic": 0.5, "frontiernet": 0.8}  # of the bound's coverage, at every k and start
    rows = [{"scene": scene, "method": method, "start": start, "repeat": 0, "status": "done",
             "vox25_shared": 0.2 * f, "vox50_shared": 0.4 * f, "vox100": 0.9 * f, "success": True}
            for scene in scenes for start in (0, 1)
            for method, f in (("omniscient", 1.0), *share.items())]
    table = table_markdown(rows, scenes, ["classic", "frontiernet", "omniscient"], interval=INTERVAL)
    bound = table.split("### Share of the bound (omniscient, paired runs)")[1].split("###")[0]
    assert "Vox@25, Vox@50 and Vox@100" in bound and "omniscient |" not in bound  # the bound is not its own row
    assert "| classic | 0.50x [0.50, 0.50] (0-4) | 0.50x [0.50, 0.50] (0-4) | 0.50x [0.50, 0.50] (0-4) |" in bound
    assert "| frontiernet | 0.80x" in bound
    for scene in scenes:
        assert f"### Share of the bound on {scene_key(scene)}" in table
    without = table_markdown([r for r in rows if r["method"] != "omniscient"], scenes, ["classic", "frontiernet"],
                             interval=INTERVAL)
    assert "Share of the bound" not in without
