#!/usr/bin/env bash
# Resume the published protocol in both depth regimes (docs/benchmark.md, "Both depth regimes";
# issue 27, steps 2 and 7) from the repository root: exports the shipped model to ONNX if
# runs/shipped.onnx is missing (plan.json pins that path), then runs the protocol's command with
# `--depth gt,emulated`; finished runs are kept, the rest are run. REPEATS=1 (the default) is
# pass 1, REPEATS=3 pass 2 and the full protocol. Needs `make install`. Stop it with Ctrl-C (or
# kill it): runs in progress are lost, finished ones are not. When the benchmark ends, its new
# runs are packed into runs/<scene>/<method>@<source>.jsonl.gz; before committing while it runs:
# .venv/bin/frontiernet bench --pack --out docs/benchmark/regimes
# METHODS=frontiernet,oracle,classic runs those first (the plan keeps the settings, not the method
# list: the full list afterwards adds the other methods' runs to the same folder).
set -euo pipefail
cd "$(dirname "$0")/../../.."
BIN=${BIN:-.venv/bin}
mkdir -p runs
[ -f runs/shipped.onnx ] || "$BIN/frontiernet" export frontiernet/weights/frontiernet_rgbd_resnet18.safetensors \
    --format onnx --out runs/shipped.onnx
KTH=../shared/data/floorplans/kth
"$BIN/frontiernet" bench --scenes ../shared/data/scenes/aws_small_house.glb procedural:1000-1009 \
    "$KTH/50010535_PLAN1" "$KTH/50015847" "$KTH/50037764_PLAN1" "$KTH/50052750" \
    --methods "${METHODS:-frontiernet,oracle,classic,gain-distance,df-uniform,discontinuity-gain,discontinuity-uniform,random-frontier,vacuum}" \
    --starts 3 --repeats "${REPEATS:-1}" --max-steps 500 --scene-starts --model runs/shipped.onnx \
    --depth gt,emulated --workers "${WORKERS:-2}" --out "${OUT_DIR:-docs/benchmark/regimes}"
exec "$BIN/frontiernet" bench --pack --out "${OUT_DIR:-docs/benchmark/regimes}"
