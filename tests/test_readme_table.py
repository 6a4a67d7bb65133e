"""The results table of README.md and docs/benchmark.md is the published data's (issue 58): the
block between the results-table markers is what frontiernet/benchmark/readme_table.py builds from
the folder that ``readme.source`` of configs/bench.yaml names, and ``bench --report`` writes it."""

from __future__ import annotations


import pytest

from conftest import REPO_ROOT, copy_tracked, needs_git
from frontiernet.benchmark.readme_table import (BEGIN, END, FILE, folder_rows, marked_block, published_folder,
                                                readme_markdown, with_block)
from frontiernet.cli.main import main
from frontiernet.config import load_config

PAGES = ("README.md", "docs/benchmark.md")
SMALL = "docs/benchmark/loop_fixes/base"
"""A small tracked benchmark folder with classic (2 methods, 2 depth sources, 40 packed runs)."""


@pytest.fixture(scope="module")
def published_table() -> str:
    folder = published_folder(REPO_ROOT)
    return readme_markdown(folder_rows(folder), folder, str(load_config("bench").readme.source))


@pytest.mark.parametrize("page", PAGES)
def test_the_pages_show_the_published_table(page, published_table):
    text = (REPO_ROOT / page).read_text()
    assert text.count(BEGIN) == 1 and text.count(END) == 1, f"{page}: one {BEGIN} ... {END} block"
    shown = marked_block(text)
    assert shown == published_table, (
        f"{page}'s results table differs from what {load_config('bench').readme.source} gives: run "
        f"`frontiernet bench --report --out {load_config('bench').readme.source}` and paste its {FILE} "
        f"between the markers")


def test_the_table_holds_the_reports_own_figures(published_table):
    """Each method's means and its Vox@50 ratio to classic (with the interval) are cells of the
    folder's table.md (the report's summary and its comparison with classic), and every method
    appears once per depth source."""
    report = (published_folder(REPO_ROOT) / "table.md").read_text()
    header, _, *rows = [line.strip("| ").split(" | ") for line in published_table.splitlines() if line.startswith("| ")]
    to_classic = header.index("to classic, Vox@25 / @50 / @100")
    methods = [row[0] for row in rows]
    assert "classic" in methods and "frontiernet" in methods
    assert len(methods) == len(set(methods)) * len({row[1] for row in rows})
    for row in rows:
        if row[0] != "classic":
            vox50 = row[to_classic].split(" / ")[1]
            assert "[" in vox50 and f"| {vox50} (" in report, row
        assert f"| {row[3]} +- " in report and f"| {row[4]} +- " in report, row  # the summary's means


def test_the_readmes_figures_with_an_interval_are_the_tables(published_table):
    """Every ratio with an interval that README.md's text around the table quotes (``1.25x [1.17, 1.35]``) is a
    cell of the published table: a re-published folder cannot leave the prose behind its table."""
    import re

    text = (REPO_ROOT / "README.md").read_text()
    prose = text.replace(marked_block(text), "")
    quoted = re.findall(r"\d+\.\d\dx \[\d+\.\d\d, \d+\.\d\d\]", prose)
    assert quoted, "the README quotes the table's headline ratios"
    missing = [figure for figure in quoted if figure not in published_table]
    assert not missing, f"README.md quotes {missing}, which the published table does not hold: update the text"


def test_the_block_is_replaced_whole():
    page = f"intro\n\n{BEGIN}\n\n| old |\n\n{END}\n\nafter\n"
    assert marked_block(page) == "| old |\n"
    updated = with_block(page, "| new |\n| --- |\n")
    assert marked_block(updated) == "| new |\n| --- |\n" and updated.endswith(f"{END}\n\nafter\n")
    assert marked_block("no markers") is None


@needs_git
def test_bench_report_writes_the_table(tmp_path, capsys):
    """``frontiernet bench --report`` on a copy of a small tracked folder writes table_readme.md,
    the same table the module builds from the folder."""
    folder = copy_tracked(SMALL, tmp_path / "bench")
    assert main(["bench", "--report", "--out", str(folder)]) == 0
    assert FILE in capsys.readouterr().out
    written = (folder / FILE).read_text()
    assert written == readme_markdown(folder_rows(folder), folder)
    assert written.count("| classic |") == 2 and "| random-frontier | emulated |" in written


def test_the_bound_and_nbvp_columns_are_ratios_of_paired_means(tmp_path):
    """A folder with the bound and nbvp gets their columns: each method's mean Vox@k over the
    bound's (its share) and over nbvp's, on the runs both finished, the interval at Vox@50."""
    import json

    import numpy as np

    methods = ["classic", "nbvp", "omniscient", "frontiernet"]
    scale = {"classic": 0.5, "nbvp": 0.6, "omniscient": 1.0, "frontiernet": 0.8}
    runs, rows = [], []
    for scene in ("procedural:1", "procedural:2"):
        for start in range(3):
            for method in methods:
                runs.append({"scene": scene, "method": method, "start": start, "repeat": 0,
                             "key": f"{scene}/{method}/start{start}_repeat0"})
                if method == "nbvp" and start == 2 and scene == "procedural:2":
                    continue  # not finished: its pair is left out of the ratios to nbvp, its row out of the table
                base = 0.2 + 0.1 * start
                rows.append({"scene": scene, "method": method, "start": start, "repeat": 0, "depth": None,
                             "status": "done", "vox25_shared": scale[method] * base,
                             "vox50_shared": scale[method] * base * 1.5, "vox100": scale[method] * base * 2})
    plan = {"settings": {"budget": {"steps_per_m2": 6.5}, "vox_steps": "coverage"},
            "start_poses": {"procedural:1": [], "procedural:2": []}, "runs": runs}
    (tmp_path / "plan.json").write_text(json.dumps(plan))
    table = readme_markdown(rows, tmp_path)
    header, _, *lines = [line.strip("| ").split(" | ") for line in table.splitlines() if line.startswith("| ")]
    assert header[6:] == ["share of the bound, Vox@25 / @50 / @100", "to classic, Vox@25 / @50 / @100",
                          "to nbvp, Vox@25 / @50 / @100"]
    row = {line[0]: line for line in lines}
    assert row["frontiernet"][2] == "6" and row["omniscient"][6] == row["classic"][7] == "1.00x"
    assert "nbvp" not in row  # 5 of its 6 runs finished: named under the table, not a row
    share, to_classic, to_nbvp = (cell.split(" / ") for cell in row["frontiernet"][6:9])
    assert [part[:5] for part in share] == ["0.80x"] * 3  # 0.8 of the bound at every start
    assert [part[:5] for part in to_classic] == ["1.60x"] * 3 and [part[:5] for part in to_nbvp] == ["1.33x"] * 3
    assert share[1].startswith("0.80x [0.80, 0.80]")  # a constant ratio: a point interval
    assert row["classic"][6].split(" / ")[0] == "0.50x" and np.isclose(float(row["classic"][3]), 15.0)
    assert "scene-sized step budgets" in table and "Not yet in the table, their runs not all finished: nbvp (5 of 6 runs)" in table


def test_a_method_with_runs_left_is_named_under_the_table_not_shown(tmp_path):
    """A method joining a published folder (seer's first scenes) gets no row until all its planned runs are
    finished: its means would rest on the scenes it reached first. The caption names it with its counts, and
    the finished methods' rows are as they were."""
    import json

    runs, rows = [], []
    for scene in ("procedural:1", "procedural:2", "procedural:3"):
        for method in ("classic", "frontiernet", "seer"):
            runs.append({"scene": scene, "method": method, "start": 0, "repeat": 0, "key": f"{scene}/{method}"})
            if method == "seer" and scene != "procedural:1":
                continue
            value = {"classic": 0.4, "frontiernet": 0.5, "seer": 0.9}[method] + 0.01 * len(scene)
            rows.append({"scene": scene, "method": method, "start": 0, "repeat": 0, "depth": None,
                         "status": "done", "vox25_shared": value, "vox50_shared": value, "vox100": value})
    plan = {"settings": {"budget": 500, "vox_steps": "budget"},
            "start_poses": {"procedural:1": [], "procedural:2": [], "procedural:3": []}, "runs": runs}
    (tmp_path / "plan.json").write_text(json.dumps(plan))
    with_seer = readme_markdown(rows, tmp_path)
    without_seer = readme_markdown([row for row in rows if row["method"] != "seer"], tmp_path)
    shown = [line.split(" | ")[0].strip("| ") for line in with_seer.splitlines() if line.startswith("| ")][2:]
    assert shown == ["classic", "frontiernet"]
    assert "Not yet in the table, their runs not all finished: seer (1 of 3 runs)." in with_seer
    assert with_seer.replace("seer (1 of 3", "seer (0 of 3") == without_seer


def test_the_table_compares_the_methods_on_the_starts_every_method_has(tmp_path):
    """A benchmark grown by more starts for two methods (pass 2 of classic and random-frontier) keeps its
    table on the starts every method ran: the same runs behind every row, the others named in the caption."""
    import json

    runs, rows = [], []
    for scene in ("procedural:1", "procedural:2"):
        for method, starts in (("classic", 3), ("random-frontier", 3), ("frontiernet", 1)):
            for start in range(starts):
                runs.append({"scene": scene, "method": method, "start": start, "repeat": 0,
                             "key": f"{scene}/{method}/start{start}_repeat0"})
                value = {"classic": 0.4, "random-frontier": 0.2 if start else 0.4, "frontiernet": 0.6}[method]
                rows.append({"scene": scene, "method": method, "start": start, "repeat": 0, "depth": None,
                             "status": "done", "vox25_shared": value, "vox50_shared": value, "vox100": value})
    plan = {"settings": {"budget": {"steps_per_m2": 6.5}, "vox_steps": "coverage"},
            "start_poses": {"procedural:1": [], "procedural:2": []}, "runs": runs}
    (tmp_path / "plan.json").write_text(json.dumps(plan))
    table = readme_markdown(rows, tmp_path)
    row = {line.strip("| ").split(" | ")[0]: line.strip("| ").split(" | ")
           for line in table.splitlines() if line.startswith("| ") and not line.startswith("| method")}
    assert row["classic"][2] == row["random-frontier"][2] == row["frontiernet"][2] == "2"
    assert row["random-frontier"][3] == "40.0" and row["random-frontier"][6].startswith("1.00x")  # start 0 alone
    assert "Interim" not in table and "Each scene from its first start (classic and random-frontier ran more" in table
