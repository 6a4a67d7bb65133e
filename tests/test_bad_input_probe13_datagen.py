"""Bad input of the thirteenth probe of issue 55 (docs/bad_input.md, "Probe 13") for the commands that read a
FrontierNet dataset: a dataset path that is a symbolic link to nothing (or a loop) was "no such dataset folder or
shard" (``datagen preview``) or "dataset folder not found" (``evaluate``), which sent one looking for a missing
folder. Each refusal is one line naming the link and what it is, exit code 2, no output folder made."""

from __future__ import annotations

from pathlib import Path

import pytest

from frontiernet.cli.main import main
from frontiernet.model import default_model_path

EXPECTED = "expected a dataset folder (made by frontiernet datagen) or one of its shards (.zip)"


def dangling(tmp_path: Path) -> tuple[Path, str]:
    """(a link to nothing, what it is)."""
    link = tmp_path / "data"
    link.symlink_to(tmp_path / "gone")
    return link, f"a symbolic link to {tmp_path / 'gone'}, which does not exist"


def loop(tmp_path: Path) -> tuple[Path, str]:
    """(a link that leads back to itself, what it is)."""
    link = tmp_path / "data"
    link.symlink_to("data")
    return link, f"a symbolic link loop ({link} -> data), which leads back to itself"


@pytest.mark.parametrize("link_of", [dangling, loop])
def test_datagen_preview_of_a_link_to_nothing_names_the_link(link_of, tmp_path, one_line_error):
    # was "data: no such dataset folder or shard"
    link, what = link_of(tmp_path)
    assert main(["datagen", "preview", str(link)]) == 2
    assert one_line_error() == f"frontiernet datagen: error: {link}: {what}; {EXPECTED}"
    assert sorted(tmp_path.iterdir()) == [link]  # no preview/ folder beside it


@pytest.mark.parametrize("link_of", [dangling, loop])
def test_evaluate_on_a_link_to_nothing_names_the_link(link_of, tmp_path, one_line_error):
    # was "data: dataset folder not found (make one with `frontiernet datagen`)"
    link, what = link_of(tmp_path)
    json_out = tmp_path / "metrics.json"
    assert main(["evaluate", str(default_model_path()), "--data", str(link), "--all", "--json", str(json_out)]) == 2
    assert one_line_error() == f"frontiernet evaluate: error: {link}: {what}; {EXPECTED}"
    assert sorted(tmp_path.iterdir()) == [link]


def test_a_dataset_that_is_not_there_at_all_is_still_not_found(tmp_path, one_line_error):
    # (no link: the earlier words stand)
    assert main(["datagen", "preview", str(tmp_path / "none")]) == 2
    assert one_line_error() == f"frontiernet datagen: error: {tmp_path / 'none'}: no such dataset folder or shard"
    assert main(["evaluate", str(default_model_path()), "--data", str(tmp_path / "none"), "--all"]) == 2
    assert one_line_error() == (f"frontiernet evaluate: error: {tmp_path / 'none'}: dataset folder not found (make "
                                "one with `frontiernet datagen`)")
    assert not any(tmp_path.iterdir())
