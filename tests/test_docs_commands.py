"""Every command of README.md, docs/*.md and the results log (docs/results/*.md) works as written:
each ``frontiernet ...`` line of a command block parses through the real command line
(``frontiernet.cli.main.build_parser``), and the cheap ones run (scene info / topdown, render,
predict; shared data where they name it). The results log's long benchmark commands are parsed
only, as every page's are."""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from conftest import REPO_ROOT
from frontiernet.cli.main import build_parser, main

PAGES = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md")),
         *sorted((REPO_ROOT / "docs" / "results").glob("*.md"))]
RUN = {("scene", "info"), ("scene", "topdown"), ("render",), ("predict",)}
"""Commands cheap enough to run here (seconds); the others are parsed only."""
SHARED = "../shared/data/"


def documented_commands() -> list[tuple[str, list[str]]]:
    """(``page:line``, argv after ``frontiernet``) of every command line in the pages' fenced
    blocks (``python`` blocks aside): backslash continuations joined, ``# comments`` and ``cmd &&``
    prefixes dropped. Synopsis lines (``[--option X]``, ``a|b`` alternatives) are left out."""
    commands = []
    for page in PAGES:
        text = page.read_text()
        for block in re.finditer(r"^[ \t]*```([^\n]*)\n(.*?)^[ \t]*```", text, re.S | re.M):
            if block.group(1).strip() not in ("", "sh", "bash", "console", "shell"):
                continue
            first_line = text.count("\n", 0, block.start(2)) + 1
            lines = block.group(2).split("\n")
            number = 0
            while number < len(lines):
                line, where = lines[number], number
                while line.rstrip().endswith("\\") and number + 1 < len(lines):
                    number += 1
                    line = line.rstrip()[:-1] + " " + lines[number]
                number += 1
                for part in line.split("&&"):
                    words = shlex.split(part.strip().removeprefix("$ "), comments=True)
                    if len(words) < 2 or words[0] != "frontiernet":
                        continue
                    if any(word.startswith("[") or ("|" in word and not word.startswith("--")) or
                           re.fullmatch(r"[\w-]+(\|[\w-]+)+", word) for word in words):
                        continue  # a synopsis, not a command
                    commands.append((f"{page.relative_to(REPO_ROOT)}:{first_line + where}", words[1:]))
    return commands


COMMANDS = documented_commands()


def test_the_pages_hold_the_commands_users_copy():
    pages = {where.split(":")[0] for where, _ in COMMANDS}
    assert {"README.md", "docs/benchmark.md", "docs/datagen.md", "docs/sequences.md", "docs/usage.md"} <= pages
    render = [argv for _, argv in COMMANDS if argv[0] == "render"]
    assert ["--pose", "-4.5,-0.5,1.2,0"] == render[0][2:4]  # the README's view of the house, negative x first


@pytest.mark.parametrize("argv", [argv for _, argv in COMMANDS], ids=[where for where, _ in COMMANDS])
def test_every_documented_command_parses(argv):
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            args = build_parser().parse_args(argv)
        except SystemExit as stop:
            pytest.fail(f"frontiernet {shlex.join(argv)}: {err.getvalue().strip() or stop}")
    assert getattr(args, "func", None) is not None


def _cheap(argv: list[str]) -> bool:
    return tuple(argv[:2]) in RUN or tuple(argv[:1]) in RUN


def _here(argv: list[str], shared: Path, out: Path) -> list[str] | None:
    """`argv` with the shared data's real path and ``--out`` under `out`; None when it names an
    input that is not here (a placeholder such as ``rgb.png`` or ``.../NYU_color.ppm``)."""
    argv = [str(shared / word[len(SHARED):]) if word.startswith(SHARED) else word for word in argv]
    args = build_parser().parse_args(argv)
    for name in ("spec", "image", "depth", "model"):
        value = getattr(args, name, None)
        if value and not value.startswith(("procedural:", "default")) and \
                not Path(re.sub(r"^\w+:", "", value).split("?")[0]).exists():
            return None
    if "--out" in argv:
        at = argv.index("--out") + 1
        argv[at] = str(out / argv[at])
    return argv


@pytest.mark.parametrize("argv", [argv for _, argv in COMMANDS if _cheap(argv)],
                         ids=[where for where, argv in COMMANDS if _cheap(argv)])
def test_cheap_documented_commands_run_as_written(argv, shared_data, tmp_path, capsys):
    here = _here(argv, shared_data, tmp_path)
    if here is None:
        pytest.skip("names an input that is a placeholder here")
    assert main(here) == 0, capsys.readouterr().err
