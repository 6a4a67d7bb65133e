"""The results table of README.md and docs/benchmark.md is the published data's (issue 58): the
block between the results-table markers is what frontiernet/benchmark/readme_table.py builds from
the folder that ``readme.source`` of configs/bench.yaml names, and ``bench --report`` writes it."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from conftest import REPO_ROOT, needs_git
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
    """Each method's means and ratios are cells of the folder's table.md (the report's summary
    and its comparison with classic), and every method appears once per depth source."""
    report = (published_folder(REPO_ROOT) / "table.md").read_text()
    rows = [line.split(" | ") for line in published_table.splitlines()[2:] if line.startswith("| ")]
    plan_methods = {row[0].strip("| ") for row in rows}
    assert "classic" in plan_methods and "frontiernet" in plan_methods
    for row in rows:
        vox25, vox50 = row[5], row[6]
        if row[0].strip("| ") != "classic":
            assert f"{vox25} (" in report and f"{vox50} (" in report, row
        assert f"| {row[2]} +- " in report, row  # the summary's mean


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
    listed = subprocess.run(["git", "ls-files", SMALL], cwd=REPO_ROOT, capture_output=True, text=True,
                            check=True).stdout.split()
    folder = tmp_path / "bench"
    for name in listed:
        target = folder / (REPO_ROOT / name).relative_to(REPO_ROOT / SMALL)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(REPO_ROOT / name, target)
    assert main(["bench", "--report", "--out", str(folder)]) == 0
    assert FILE in capsys.readouterr().out
    written = (folder / FILE).read_text()
    assert written == readme_markdown(folder_rows(folder), folder)
    assert written.count("| classic |") == 2 and "| random-frontier | emulated |" in written
