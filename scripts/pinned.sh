#!/usr/bin/env bash
# Run a `frontiernet` command on the code of one commit while the checkout is edited (a benchmark
# that spans hours and sessions, and base-against-fix comparisons: docs/benchmark.md).
#
#   scripts/pinned.sh COMMIT DIR [frontiernet arguments ...]
#
# DIR becomes a git worktree of COMMIT (made on the first call; a later call checks that DIR still
# holds COMMIT), with what an installed package has beside its code: the configs as the package
# `frontiernet.configs` and the entry points of COMMIT's pyproject.toml (the methods, runtimes and
# commands of datagen/, deploy/ and train/). The command runs with DIR first on the Python path,
# ahead of the current folder, so no edit of the checkout reaches it (nor its workers', which
# inherit the path), and relative paths in its arguments are read from the current folder as
# always. PYTHON (the checkout's .venv/bin/python) runs it, nice'd by NICE (5). With no arguments
# after DIR the worktree is only prepared.
set -euo pipefail
REPO=$(cd "$(dirname "$0")/.." && pwd)
COMMIT=${1:?usage: scripts/pinned.sh COMMIT DIR [frontiernet arguments ...]}
DIR=${2:?usage: scripts/pinned.sh COMMIT DIR [frontiernet arguments ...]}
shift 2
PYTHON=${PYTHON:-$REPO/.venv/bin/python}
SHA=$(git -C "$REPO" rev-parse --verify --quiet "$COMMIT^{commit}") || { echo "pinned.sh: $COMMIT is not a commit of $REPO" >&2; exit 2; }
# one preparation at a time: two commands started together on a new DIR would both make it
exec 9>"$DIR.lock"
flock 9
if [ ! -e "$DIR" ]; then
    git -C "$REPO" worktree add --detach --quiet "$DIR" "$SHA"
    cp -r "$DIR/configs" "$DIR/frontiernet/configs"
    # the entry points of that commit, as pip would install them (tomllib: Python 3.11+)
    "$PYTHON" - "$DIR" <<'EOF'
import sys, tomllib
from pathlib import Path

root = Path(sys.argv[1])
project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
info = root / f"{project['name']}-{project['version']}.dist-info"
info.mkdir()
(info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n")
groups = dict(project.get("entry-points", {}))
if project.get("scripts"):
    groups["console_scripts"] = project["scripts"]
(info / "entry_points.txt").write_text("".join(
    f"[{group}]\n" + "".join(f"{name} = {target}\n" for name, target in entries.items()) + "\n"
    for group, entries in groups.items()))
EOF
fi
flock -u 9
HELD=$(git -C "$DIR" rev-parse HEAD 2>/dev/null) || { echo "pinned.sh: $DIR is not a worktree (remove it or pick another DIR)" >&2; exit 2; }
if [ "$HELD" != "$SHA" ]; then
    echo "pinned.sh: $DIR holds ${HELD:0:7}, not ${SHA:0:7} (remove it with git worktree remove, or pick another DIR)" >&2
    exit 2
fi
[ $# -eq 0 ] && exit 0
# not `python -m`: that puts the current folder first on the path, and from a checkout it would
# import the checkout's code whatever PYTHONPATH says
exec nice -n "${NICE:-5}" "$PYTHON" -c 'import sys
sys.argv[0] = "frontiernet"
sys.path.insert(0, sys.argv.pop(1))
from frontiernet.cli.main import main
sys.exit(main())' "$DIR" "$@"
