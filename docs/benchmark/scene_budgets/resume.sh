#!/usr/bin/env bash
# Resume the published benchmark under the paper's protocol (issue 54, "Know the limit"): scene-sized
# step budgets (configs/bench.yaml `budget`), Vox@25/@50 at the step where the methods on average
# first reach 25 / 50 % coverage, both depth regimes, the all-knowing bound (omniscient) and NBVP
# beside classic, random-frontier, frontiernet and oracle, and the map-predicting seer, mapex and
# frontiernet-mapex. Run from anywhere; finished runs are kept.
#   STARTS=1 (the default) is pass 1: every scene from its first start, one repeat (15 scenes x
#   9 methods x 2 regimes = 270 runs, 24,600 steps a method and regime; the first six methods' 180 took
#   about 15 worker-hours on 2 cores, the other three planned at about 11 more).
#   STARTS=3 is pass 2 (the same first poses, two more each); REPEATS=3 pass 3, the full protocol
#   (runs that would repeat exactly are copied, not run). METHODS=classic,random-frontier STARTS=3
#   runs pass 2 of those two methods alone (a benchmark grows by a command that names only what it adds:
#   the other methods' runs stay in the plan and the report).
# seer, mapex and frontiernet-mapex (issue 56) joined on 0f6c59a, which changes no run of the others (the seer
# section and the shipped predictors; sessions.md).
# FRONTIERNET: the command (default: the code this folder's runs were made with, pinned with
# scripts/pinned.sh in a folder beside the checkout, so the checkout can be edited meanwhile;
# sessions.md logs the code of each invocation: later commits that change no run, checked to the step).
# --redo-changed: where the pinned code changes settings that only some runs read (the monocular keys:
# the emulated-depth runs; a method's own section: its runs), those runs are redone, the others kept.
# The folder was made anew on ddf24ef (the 0.1 m robot, sessions.md); 671581e's NBVP edges keep the
# move check's body clear (nbvp.edge_check), so its nbvp runs were redone, the others kept; a0ae25f keeps
# the way back open on ground truth too (planner.traversed_is_free), so its ground-truth runs are redone;
# 9711f05 marks bumps in the map (planner.bumps_are_obstacles), which acts only on a collision: it redoes
# the runs that collided (two when it was made) and keeps the others (the same to the step otherwise).
# tracking.bury_visited (2026-12-08) is read by the map-frontier-region methods alone (classic, random-frontier,
# mapex): --redo-changed redoes their runs and keeps the others (sessions.md).
# Pack before committing while it runs: $FRONTIERNET bench --pack --out docs/benchmark/scene_budgets
set -euo pipefail
cd "$(dirname "$0")/../../.."
FRONTIERNET=${FRONTIERNET:-scripts/pinned.sh 0f6c59a ../pinned_scene_budgets_0f6c59a}
OUT_DIR=docs/benchmark/scene_budgets
mkdir -p runs
[ -f runs/shipped.onnx ] || $FRONTIERNET export frontiernet/weights/frontiernet_rgbd_resnet18.safetensors \
    --format onnx --out runs/shipped.onnx
KTH=../shared/data/floorplans/kth
$FRONTIERNET bench --scenes ../shared/data/scenes/aws_small_house.glb procedural:1000-1009 \
    "$KTH/50010535_PLAN1" "$KTH/50015847" "$KTH/50037764_PLAN1" "$KTH/50052750" \
    --methods "${METHODS:-classic,random-frontier,nbvp,omniscient,frontiernet,oracle,seer,mapex,frontiernet-mapex}" \
    --starts "${STARTS:-1}" --repeats "${REPEATS:-1}" --scene-starts --model runs/shipped.onnx \
    --depth gt,emulated --workers "${WORKERS:-2}" --redo-changed --out "$OUT_DIR" || status=$?  # 1: a run failed
$FRONTIERNET bench --pack --out "$OUT_DIR"
exit "${status:-0}"
