"""docs/design.md, "Walk (a)" and "Walk (b)": no call chain of an exploration returns to a library file.

A profiler (``sys.setprofile``) follows ``frontiernet explore`` from the command line through the
setup (scene spec -> world -> method -> model) and a few steps (render -> ray cast, frame ->
prediction -> anchoring, map, planning, motion, outputs). At each call into a function of the
library, the chain of library files on the call stack (the frames of one file in a row counted
once; frames outside the library, Python's, NumPy's or a plugin package's such as ``datagen``,
passed through) must not hold a file twice. A file that calls another which calls back into it
(a callback, a stopwatch that runs the timed function, a property that a borrowed method reads,
a parser class that argparse builds for another module) is the back and forth issue 29 took out.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import sys
from pathlib import Path

import pytest

from conftest import REPO_ROOT

LIBRARY = REPO_ROOT / "frontiernet"


def _chain(frame, root: str) -> list[str]:
    """The files under `root` on the stack of `frame`, innermost first, consecutive repeats merged."""
    files: list[str] = []
    while frame is not None:
        name = frame.f_code.co_filename
        if name.startswith(root) and (not files or files[-1] != name):
            files.append(name)
        frame = frame.f_back
    return files


def returns_during(function, library: Path = LIBRARY) -> dict[str, str]:
    """Run `function()` under a profiler; each function of `library` that was entered while its file
    already waited lower on the stack, below another file of `library`: ``file:function`` -> the
    chain of files (innermost first), relative to `library`."""
    root = str(library) + "/"
    found: dict[str, str] = {}

    def profile(frame, event, arg) -> None:
        if event != "call" or not frame.f_code.co_filename.startswith(root):
            return
        chain = _chain(frame, root)
        if len(set(chain)) < len(chain):
            names = [name[len(root):] for name in chain]
            found.setdefault(f"{names[0]}:{frame.f_code.co_name}", " <- ".join(names))

    sys.setprofile(profile)
    try:
        function()
    finally:
        sys.setprofile(None)
    return found


def test_the_check_finds_a_file_that_calls_back_into_its_caller(tmp_path, monkeypatch):
    # two modules of a stand-in library: caller.py hands its own function to helper.py, which calls it
    (tmp_path / "helper.py").write_text("def apply(callback):\n    return callback() + 1\n")
    (tmp_path / "caller.py").write_text("import helper\n\n\ndef inner():\n    return 1\n\n\n"
                                        "def direct():\n    return inner() + helper.apply(int)\n\n\n"
                                        "def back_and_forth():\n    return helper.apply(inner)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    caller = importlib.import_module("caller")
    assert returns_during(caller.direct, tmp_path) == {}  # into helper.py and back out: no return
    assert returns_during(caller.back_and_forth, tmp_path) == {"caller.py:inner": "caller.py <- helper.py <- caller.py"}


@pytest.mark.parametrize("method, options", [
    ("classic", ()),
    ("frontiernet", ("--depth", "emulated")),  # the shipped model; monocular depth emulation
    ("oracle", ()),  # a method of a package built on the library (datagen), through the method table
    ("vacuum", ()),
])
def test_an_exploration_never_calls_back_into_a_library_file_it_came_from(plan_spec, tmp_path, method, options):
    from frontiernet.cli.main import main

    def explore() -> None:
        stream = io.StringIO()
        with contextlib.redirect_stdout(stream), contextlib.redirect_stderr(stream):
            code = main(["explore", "--scene", plan_spec, "--method", method, "--max-steps", "4", "--no-video",
                         "--out", str(tmp_path / "run"), *options])
        assert code == 0, stream.getvalue()

    returns = returns_during(explore)
    assert (tmp_path / "run" / "metrics.json").is_file()
    assert returns == {}, "\n".join(f"{where}: {chain}" for where, chain in returns.items())
