#!/usr/bin/env bash
# Resume the published benchmark run (docs/benchmark.md, "Published run") from the repository
# root: exports the shipped model to ONNX if runs/shipped.onnx is missing (plan.json pins that
# path), then runs the protocol's command; finished runs are kept, the rest are run. Pass 1 was
# `--repeats 1`; REPEATS=3 (the default) is pass 2 and the full protocol. Needs `make install`.
# Stop it with Ctrl-C (or kill it): runs in progress are lost, finished ones are not. When the
# benchmark ends, its new runs' metrics.json are packed into runs/<scene>/<method>.jsonl.gz, the
# form the repository keeps (docs/benchmark.md, "Packed runs"); before committing while it runs:
# .venv/bin/frontiernet bench --pack --out docs/benchmark/published
# The same protocol into another folder (docs/benchmark/regimes/resume.sh): OUT_DIR, DEPTH (a
# --depth list; unset: the published folder's run.depth), METHODS (some methods first: the plan
# pins the settings, not the method list), WORKERS, FRONTIERNET (the command; e.g.
# FRONTIERNET="scripts/pinned.sh COMMIT ../pinned" runs one commit's code while the checkout is edited),
# SETTINGS (`--set` KEY=VALUE pairs; unset: planner.gain_exponent=1, the exponent this folder's plan
# ran with before 2 became the default on 2026-11-27; a new folder sets it empty: today's defaults).
# Every folder of this fixed-budget protocol ran before planner.forgive_before_stop existed (on
# since 2026-12-05) and with planner.approach_radius_m 0 (1.5 since 2026-12-05): its runs go and
# stop as they did, so the command always sets both back; so it does the robot they ran with (a
# sphere of 0.2 m planned 0.3 m clear; 0.1 m and 0.2 m since 2026-12-06) and the planner's map alone
# on ground truth (planner.traversed_is_free off; on since 2026-12-07), bumps not in the map
# (planner.bumps_are_obstacles off; on since 2026-12-07), and a stop with no frontier left
# (map_frontiers.min_cells_before_stop null; 1 since 2026-12-07), and visited map frontiers proposed again
# (tracking.bury_visited off; on since 2026-12-08).
set -euo pipefail
SETTINGS=${SETTINGS-planner.gain_exponent=1}
cd "$(dirname "$0")/../../.."
FRONTIERNET=${FRONTIERNET:-.venv/bin/frontiernet}
OUT_DIR=${OUT_DIR:-docs/benchmark/published}
mkdir -p runs
[ -f runs/shipped.onnx ] || $FRONTIERNET export frontiernet/weights/frontiernet_rgbd_resnet18.safetensors \
    --format onnx --out runs/shipped.onnx
KTH=../shared/data/floorplans/kth
$FRONTIERNET bench --scenes ../shared/data/scenes/aws_small_house.glb procedural:1000-1009 \
    "$KTH/50010535_PLAN1" "$KTH/50015847" "$KTH/50037764_PLAN1" "$KTH/50052750" \
    --methods "${METHODS:-frontiernet,oracle,classic,gain-distance,df-uniform,discontinuity-gain,discontinuity-uniform,random-frontier,vacuum}" \
    --starts 3 --repeats "${REPEATS:-3}" --max-steps 500 --scene-starts --model runs/shipped.onnx \
    ${DEPTH:+--depth "$DEPTH"} --set planner.forgive_before_stop=false planner.approach_radius_m=0 \
    planner.traversed_is_free=false planner.bumps_are_obstacles=false \
    map_frontiers.min_cells_before_stop=null tracking.bury_visited=false sim.agent.radius_m=0.2 sim.voxels.floor_clearance_m=0.2 planner.clearance_m=0.3 $SETTINGS --workers "${WORKERS:-2}" --out "$OUT_DIR"
exec $FRONTIERNET bench --pack --out "$OUT_DIR"
