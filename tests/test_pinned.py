"""scripts/pinned.sh runs a command on one commit's code while the checkout is edited: the worktree's
code is what the command imports (not the checkout's, though it runs from the checkout), and a
wrong commit or a worktree of another commit is one line, exit 2."""

from __future__ import annotations

import subprocess
import sys

import pytest

from conftest import REPO_ROOT, needs_git

SCRIPT = REPO_ROOT / "scripts" / "pinned.sh"

pytestmark = needs_git


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(REPO_ROOT), *args], check=True, capture_output=True, text=True).stdout.strip()


def _pinned(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(SCRIPT), *args], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300,
                          env={"PATH": "/usr/bin:/bin", "PYTHON": sys.executable, "NICE": "0"})


@pytest.fixture
def worktree(tmp_path):
    path = tmp_path / "pinned"
    yield path
    if path.exists():
        _git("worktree", "remove", "--force", str(path))


def test_the_command_imports_the_pinned_code(worktree, tmp_path):
    head = _git("rev-parse", "HEAD")
    prepared = _pinned(head, str(worktree))
    assert prepared.returncode == 0, prepared.stderr
    assert (worktree / "frontiernet" / "configs" / "explore.yaml").is_file()
    entry_points = next(worktree.glob("frontiernet-*.dist-info")) / "entry_points.txt"
    assert "oracle = datagen.oracle:oracle" in entry_points.read_text()
    marker = tmp_path / "marker"
    with open(worktree / "frontiernet" / "cli" / "main.py", "a") as handle:  # only the worktree has it
        handle.write(f"\nopen({str(marker)!r}, 'w').write(__file__)\n")
    run = _pinned(head, str(worktree), "--version")
    assert run.returncode == 0, run.stderr
    assert marker.read_text() == str(worktree / "frontiernet" / "cli" / "main.py")


def test_bad_commit_or_worktree_is_one_line_exit_2(worktree):
    bad = _pinned("no-such-commit", str(worktree))
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "no-such-commit" in bad.stderr
    assert not worktree.exists()
    assert _pinned("HEAD", str(worktree)).returncode == 0
    other = _pinned(_git("rev-parse", "HEAD~1"), str(worktree))
    assert other.returncode == 2 and other.stderr.count("\n") == 1 and str(worktree) in other.stderr


def test_two_commands_started_together_on_a_new_worktree_both_run(worktree):
    """Two benchmarks started at once on the same new DIR: one prepares it, the other waits for it."""
    head = _git("rev-parse", "HEAD")
    env = {"PATH": "/usr/bin:/bin", "PYTHON": sys.executable, "NICE": "0"}
    both = [subprocess.Popen([str(SCRIPT), head, str(worktree)], cwd=REPO_ROOT, env=env, stderr=subprocess.PIPE,
                             text=True) for _ in range(2)]
    results = [(process.wait(timeout=300), process.stderr.read()) for process in both]
    assert [code for code, _ in results] == [0, 0], results
    assert (worktree / "frontiernet" / "configs" / "explore.yaml").is_file()
