#!/usr/bin/env bash
# From nothing to a trained FrontierNet on one GPU node: install, generate the data on the node's
# cores, build the training cache, train on the GPU, evaluate on the held-out scenes.
#
#   scripts/train_on_gpu.sh WORK [key=value ...]       (docs/model.md, "Training on a GPU node")
#
# WORK holds the dataset (WORK/data), the run (WORK/runs/<name>) and stages.tsv (seconds per
# stage). Every stage resumes: run the same command again after an interruption (a fresh node
# regenerates the same dataset bytes from the same seed). key=value pairs go to `frontiernet train`.
# RESULTS=DIR also packs the run's logs and metrics (NAME.run.tar.gz) and the float16 model, split into
# 15 MB parts (cat DIR/NAME.model_fp16.safetensors.part* > model.safetensors), into DIR. A second
# model on the same data: NAME=rgb scripts/train_on_gpu.sh WORK model.network.inputs=rgb (the
# dataset and its training cache are reused).
# BUDGET_S=SECONDS bounds the whole call: datagen stops at DATAGEN_SHARE % of it (training then uses
# the shards finished so far; stages.tsv says "datagen_cut"), training gets what is left but RESERVE_S
# (trainer.max_time), so a call always ends with a model and its metrics. DATAGEN_SHARE=0 trains on the
# dataset WORK has, as it is (a second model right after the first, on the same warm machine).
# Environment: SCENES (procedural:0-199: training scenes only, never the published or development
# ones), VIEWS (75 per scene: 15,000 views), NAME (rgbd), EPOCHS (20; 1000 under BUDGET_S, where the clock
# ends training: a call on the H200 stopped at 20 epochs of 4,522 views with two minutes unused), BATCH (64),
# EMULATED (0.5: augment.emulated_depth_fraction), PYTHON (python3),
# SITE (/tmp/site: where the package and the wheels in .whl/ are installed when missing).
set -euo pipefail
WORK=${1:?usage: scripts/train_on_gpu.sh WORK [key=value ...]}
shift
REPO=$(cd "$(dirname "$0")/.." && pwd)
PYTHON=${PYTHON:-python3}
SITE=${SITE:-/tmp/site}
SCENES=${SCENES:-procedural:0-199}
VIEWS=${VIEWS:-75}
NAME=${NAME:-rgbd}
BUDGET_S=${BUDGET_S:-}          # wall seconds this call may take in all (a lent machine's 10-minute command)
EPOCHS=${EPOCHS:-$([ -n "$BUDGET_S" ] && echo 1000 || echo 20)}  # under a budget the clock ends training
BATCH=${BATCH:-64}
# half the views get the emulated monocular depth prior: one file serves both regimes (a model the H200
# trained on rendered depth only scored DF error 0.577 px on emulated depth against 0.137 on rendered)
EMULATED=${EMULATED:-0.5}
DATAGEN_SHARE=${DATAGEN_SHARE:-45}  # ... of which data generation gets at most this percent
RESERVE_S=${RESERVE_S:-180}     # ... and this much is kept for the cache, evaluation, export and packing
CORES=$(nproc)
mkdir -p "$WORK"
STAGES="$WORK/stages.tsv"
stage() {  # stage NAME COMMAND...: run it, append "NAME<TAB>seconds" to stages.tsv; its exit status
    local name=$1 start=$SECONDS status=0
    shift
    echo "== $name: $*" >&2
    "$@" || status=$?
    printf '%s\t%d\n' "$name" $((SECONDS - start)) >> "$STAGES"
    return "$status"
}

install() {
    # carried wheels (embreex, omegaconf, ...: what a torch-only GPU image lacks, and setuptools to build
    # this package offline; see docs/model.md), each unless that very version is importable already
    local wheel name version missing=()
    for wheel in "$REPO"/.whl/*.whl; do
        [ -e "$wheel" ] || continue
        name=$(basename "$wheel"); version=${name#*-}; version=${version%%-*}; name=${name%%-*}
        PYTHONPATH="$SITE" "$PYTHON" -c "import importlib.metadata as m, sys; assert m.version(sys.argv[1]) == sys.argv[2]" \
            "$name" "$version" 2> /dev/null || missing+=("$wheel")
    done
    if [ ${#missing[@]} -gt 0 ]; then
        "$PYTHON" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" "${missing[@]}"
    fi
    PYTHONPATH="$SITE" "$PYTHON" -m pip install -q --no-index --no-deps --no-build-isolation --no-cache-dir --upgrade \
        --target "$SITE" "$REPO"
}
export PYTHONPATH="$SITE${PYTHONPATH:+:$PYTHONPATH}"
FRONTIERNET=("$PYTHON" "$SITE/bin/frontiernet")
stage install install  # every time: the checkout may have changed since the last run
"$PYTHON" -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())" >&2

# the node's per-core datagen figures, once (~10 s): datagen ran at 1.6 views/s a core on the first node against
# 4-5 here, and this tells the ground-truth pipeline from the rest (pose sampling, encoding, writing)
if [ ! -f "$WORK/datagen_bench.txt" ]; then
    { lscpu | grep -i "model name" || true; "${FRONTIERNET[@]}" datagen bench --scene procedural:5 --views 8; } \
        > "$WORK/datagen_bench.txt" 2>&1 || echo "datagen bench failed (see $WORK/datagen_bench.txt)" >&2
fi

DATA="$WORK/data"
DATAGEN=(datagen --scenes "$SCENES" --views-per-scene "$VIEWS" --seed 0 --out "$DATA" --workers "$CORES" --no-progress)
if [ "$DATAGEN_SHARE" -eq 0 ] && [ -f "$DATA/dataset.json" ]; then
    echo "DATAGEN_SHARE=0: training on the $(ls "$DATA/shards" | wc -l) shards there are" >&2
elif [ ! -f "$DATA/summary.json" ]; then  # datagen writes summary.json last
    [ -f "$DATA/dataset.json" ] && DATAGEN+=(--resume)
    if [ -n "$BUDGET_S" ]; then  # timeout signals datagen's whole process group: its workers stop too
        status=0
        stage datagen timeout $((BUDGET_S * DATAGEN_SHARE / 100 - SECONDS)) "${FRONTIERNET[@]}" "${DATAGEN[@]}" || status=$?
        [ "$status" -eq 124 ] && printf 'datagen_cut\t%d\n' "$SECONDS" >> "$STAGES"
        [ "$status" -eq 0 ] || [ "$status" -eq 124 ] || exit "$status"
    else
        stage datagen "${FRONTIERNET[@]}" "${DATAGEN[@]}"
    fi
fi

RUN="$WORK/runs/$NAME"
TRAIN=(train data.path="$DATA" out="$WORK/runs" name="$NAME" trainer.accelerator=gpu trainer.devices=1
       trainer.precision=bf16-mixed data.batch_size="$BATCH" data.num_workers=auto trainer.max_epochs="$EPOCHS"
       optim.warmup_steps=500 data.max_val_samples=1024 augment.emulated_depth_fraction="$EMULATED" "$@")
if [ -n "$BUDGET_S" ]; then
    left=$((BUDGET_S - SECONDS - RESERVE_S))
    [ "$left" -gt 60 ] || { echo "BUDGET_S=$BUDGET_S leaves ${left} s to train" >&2; exit 2; }
    TRAIN+=(trainer.max_time="$(printf '00:%02d:%02d:%02d' $((left / 3600)) $((left % 3600 / 60)) $((left % 60)))"
            optim.horizon=time)  # the cosine ends at max_time: the budget ends with a decayed rate
fi
if [ -f "$RUN/summary.json" ]; then
    :  # trained
elif [ -f "$RUN/checkpoints/last.ckpt" ]; then
    stage train "${FRONTIERNET[@]}" "${TRAIN[@]}" --no-progress --resume
else
    stage train "${FRONTIERNET[@]}" "${TRAIN[@]}" --no-progress
fi

stage evaluate "${FRONTIERNET[@]}" evaluate "$RUN/model.safetensors" --data "$DATA" --max-samples 512 --workers "$CORES" \
    --json "$RUN/evaluate.json" --force  # (a rerun evaluates again: its own earlier file, replaced)
# the shippable file: float16 weights, the frontier threshold l = the held-out best-F1 one
THRESHOLD=$("$PYTHON" -c "import json, sys; print(json.load(open(sys.argv[1]))['best_f1_threshold_px'])" "$RUN/evaluate.json")
rm -f "$RUN/model_fp16.safetensors"
stage export "${FRONTIERNET[@]}" export "$RUN/model.safetensors" --format safetensors --half \
    --frontier-threshold "$THRESHOLD" --out "$RUN/model_fp16.safetensors"
cat "$STAGES" >&2
if [ -n "${RESULTS:-}" ]; then  # e.g. a lent machine's $OUT: at most 8 files of 16 MiB come back
    mkdir -p "$RESULTS"
    tar -C "$WORK" -czf "$RESULTS/$NAME.run.tar.gz" stages.tsv "runs/$NAME/metrics.csv" "runs/$NAME/summary.json" \
        "runs/$NAME/evaluate.json" "runs/$NAME/config.yaml" $(cd "$WORK" && ls data/summary.json datagen_bench.txt 2> /dev/null)
    split -b 15M -d "$RUN/model_fp16.safetensors" "$RESULTS/$NAME.model_fp16.safetensors.part"  # cat *.part* > file
fi
