#!/usr/bin/env bash
# Resume the published protocol in both depth regimes under today's defaults (docs/benchmark.md,
# "Both depth regimes"; issue 27, steps 2 and 7): the published run's script with
# `--depth gt,emulated` into this folder and no `--set` (the published folder's script adds
# planner.gain_exponent=1 for its own plan). REPEATS=1 (the default here) is pass 1, REPEATS=3
# pass 2 and the full protocol; METHODS=frontiernet,oracle,classic runs those first (the full list
# afterwards adds the other methods' runs to the same folder). Before committing while it runs, pack
# with the code that runs it: scripts/pinned.sh 7ef1fb1 ../pinned bench --pack --out docs/benchmark/regimes
# (packs written since 2026-11-28 store the per-step curves as integer steps, which 7ef1fb1's report,
# run at the end of each invocation, cannot read; today's code reads both forms)
set -euo pipefail
cd "$(dirname "$0")"
# Since 2026-12-06 (the explorable space of one storey, issue 55) today's defaults change its
# procedural_1005 runs, and (the monocular map's symmetric miss and oblique pixels, issue 54) its
# emulated-depth runs, as (the way back kept open behind the robot on monocular maps) its emulated-depth
# runs again: it resumes as a record, with the rules it was made under (the keys null or off).
OUT_DIR=${OUT_DIR:-docs/benchmark/regimes} DEPTH=gt,emulated REPEATS=${REPEATS:-1} \
    SETTINGS="sim.voxels.storey_floor_share=null sim.voxels.storey_slab_share=null map.monocular_log_odds_miss=null map.monocular_max_incidence_deg=null planner.monocular_traversed_is_free=false" \
    exec ../published/resume.sh
