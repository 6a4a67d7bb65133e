"""The clone stays small (issue 29): the tracked files, the shipped weights aside, stay under 10 MB.

The benchmark folders grow with every committed run (docs/benchmark/regimes/sessions.md keeps the
margin); this catches a commit that would pass the bound before it lands. Sizes are those of the
files git tracks as they are on disk (the index's list, so an untracked or ignored file never
counts), in bytes.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_TRACKED_BYTES = 10_000_000
"""Issue 29, "Done when": the tracked tree, shipped weights aside, is under 10 MB."""
WEIGHTS = "frontiernet/weights/"


def tracked_files() -> list[str]:
    """Paths (relative to the checkout, '/'-separated) of the files git tracks; skips without git."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return [name for name in listed.decode().split("\0") if name]


def test_the_tracked_tree_without_the_shipped_weights_stays_under_10_MB():
    tracked = tracked_files()
    assert any(name.startswith(WEIGHTS) for name in tracked)  # the weights are what is set aside
    files = [name for name in tracked if not name.startswith(WEIGHTS)]
    sizes = {name: (ROOT / name).stat().st_size for name in files if (ROOT / name).is_file()}
    total = sum(sizes.values())
    largest = sorted(sizes, key=sizes.get, reverse=True)[:5]
    assert total < MAX_TRACKED_BYTES, f"{total / 1e6:.2f} MB tracked; largest: " + ", ".join(
        f"{name} ({sizes[name] / 1e6:.2f} MB)" for name in largest)
