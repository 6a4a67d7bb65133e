#!/usr/bin/env bash
# Resume the first two-regime run (docs/benchmark.md, "Both depth regimes"), kept as the record of
# gain exponent 1: the published run's script with `--depth gt,emulated` and
# `--set planner.gain_exponent=1` (its plan's exponent; 2 is the default since 2026-11-27) into this
# folder. It stopped at 81 of 270 pass-1 runs; docs/benchmark/regimes/resume.sh runs the protocol
# under today's defaults (the monocular map's keys null: the rule of its emulated-depth runs). Before
# committing while it runs:
# .venv/bin/frontiernet bench --pack --out docs/benchmark/regimes_exponent1
set -euo pipefail
cd "$(dirname "$0")"
OUT_DIR=${OUT_DIR:-docs/benchmark/regimes_exponent1} DEPTH=gt,emulated REPEATS=${REPEATS:-1} \
    SETTINGS="planner.gain_exponent=1 map.monocular_log_odds_miss=null map.monocular_max_incidence_deg=null planner.monocular_traversed_is_free=false" \
    exec ../published/resume.sh
