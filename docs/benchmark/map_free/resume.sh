#!/usr/bin/env bash
# Map-free mode on the published protocol (the paper's Table III; docs/benchmark.md, "Map-free mode";
# issue 27, step 6): the published run's script with `--set planner.mode=map_free`, frontiernet in
# both depth regimes, into this folder. Its plan's starts are those of docs/benchmark/regimes (the
# same scenes, seed and --scene-starts), so `tests/bench/paired.py` pairs its runs with the map-mode
# ones there run by run; run it on the code that folder ran (FRONTIERNET="scripts/pinned.sh 7ef1fb1
# ../pinned"), so that the mode is the only difference. REPEATS=1 (the default here) is pass 1,
# REPEATS=3 pass 2. Before committing while it runs: scripts/pinned.sh 7ef1fb1 ../pinned bench
# --pack --out docs/benchmark/map_free
set -euo pipefail
cd "$(dirname "$0")"
OUT_DIR=${OUT_DIR:-docs/benchmark/map_free} METHODS=${METHODS:-frontiernet} DEPTH=gt,emulated \
    REPEATS=${REPEATS:-1} SETTINGS=planner.mode=map_free exec ../published/resume.sh
