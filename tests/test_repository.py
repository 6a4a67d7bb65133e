"""The clone stays small (issue 29): the tracked files, the shipped weights aside, stay under 10 MB.

The benchmark folders grow with every committed run (docs/benchmark/regimes/sessions.md keeps the
margin: the runs of a replaced protocol leave the tree, kept in git); this catches a commit that would
pass the bound before it lands. Sizes are those of the
files git tracks as they are on disk (the index's list, so an untracked or ignored file never
counts), in bytes.
"""

from __future__ import annotations

import subprocess

from conftest import REPO_ROOT, needs_git

MAX_TRACKED_BYTES = 10_000_000
"""Issue 29, "Done when": the tracked tree, shipped weights aside, is under 10 MB."""
WEIGHTS = "frontiernet/weights/"


@needs_git
def test_the_tracked_tree_without_the_shipped_weights_stays_under_10_MB():
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=REPO_ROOT, capture_output=True, check=True).stdout
    tracked = [name for name in listed.decode().split("\0") if name]  # '/'-separated, relative to the checkout
    assert any(name.startswith(WEIGHTS) for name in tracked)  # the weights are what is set aside
    files = [name for name in tracked if not name.startswith(WEIGHTS)]
    sizes = {name: (REPO_ROOT / name).stat().st_size for name in files if (REPO_ROOT / name).is_file()}
    total = sum(sizes.values())
    largest = sorted(sizes, key=sizes.get, reverse=True)[:5]
    assert total < MAX_TRACKED_BYTES, f"{total / 1e6:.2f} MB tracked; largest: " + ", ".join(
        f"{name} ({sizes[name] / 1e6:.2f} MB)" for name in largest)
