#!/usr/bin/env bash
# The paper's A3BoxNet ablations (Table 3 / Fig. 13) on this 2-core CPU: one model TRAINED at
# each number of input points (512, 1024, 2048, 3072, 4096) and one trained without the category
# vector, all with the same recipe and the same number of optimiser steps, then evaluated
# side by side on the oracle frustums of the test split.
#
#   bash export/scripts/ablation_boxnet.sh      # makes its data and caches first (resumable)
#
# A step at N = 4096 costs about 12x one at N = 512 here (10 s vs 0.8 s, one thread), so the
# shared budget is STEPS optimiser steps (default 400 of batch 32; a training takes 6 min at
# N = 512 and 70 min at 4096, about 100 min wall in all on two cores), far less than the
# shipped model's 2,626. The table compares the models with each other; the shipped model's
# row is what the full budget gives. Every training resumes after an
# interruption (run the script again). Logs: $OUT/<name>.log.
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=${PY:-.venv/bin/python}
BIN=$(dirname "$PY")
RUNS=${RUNS:-runs}
DATA=${DATA:-data/med}
OUT=${OUT:-$RUNS/boxnet/ablation}
STEPS=${STEPS:-400}
DIV_DATA=${DATA}_div
TRAIN_CACHE=$RUNS/boxnet/cache/train.npz
DIV_CACHE=$RUNS/boxnet/cache/div_train.npz
TEST_CACHE=$RUNS/boxnet/cache/test.npz
CACHES=("$TRAIN_CACHE" "$DIV_CACHE")
mkdir -p "$OUT" "$RUNS/boxnet/cache"

# the first release's data (data/med, as the `siamfc` recipe makes it, + 120 more train shapes)
# and its frustum caches; each command resumes or is skipped when its output exists
"$BIN/track3d-sim" generate --preset small --train 36 --test 18 --out "$DATA" --workers 2 --quiet
"$BIN/track3d-sim" generate --preset small --seed 1 --train 120 --test 0 --frames 25 --out "$DIV_DATA" --workers 2 --quiet
[ -f "$TRAIN_CACHE" ] || "$BIN/track3d-train" boxnet prepare --data "$DATA" --split train --jitters 5 --out "$TRAIN_CACHE" --quiet
[ -f "$DIV_CACHE" ] || "$BIN/track3d-train" boxnet prepare --data "$DIV_DATA" --split train --jitters 3 --out "$DIV_CACHE" --quiet
[ -f "$TEST_CACHE" ] || "$BIN/track3d-train" boxnet prepare --data "$DATA" --split test --jitters 0 --out "$TEST_CACHE" --quiet

train() {  # name, extra args...
    local name=$1; shift
    if [[ -f "$OUT/$name.onnx" ]]; then return; fi
    # four "epochs" of STEPS/4 steps: the cosine LR spans STEPS; validation and a checkpoint
    # after each quarter
    "$BIN/track3d-train" boxnet train --cache "${CACHES[@]}" --out "$OUT/$name" \
        --epochs 4 --epoch-samples $((STEPS * 8)) --max-steps "$STEPS" \
        --size-norm extent --flip-y --scale-aug 0.15 --threads 1 --seed 0 --quiet "$@" \
        > "$OUT/$name.log" 2>&1
    "$BIN/track3d-train" boxnet export --checkpoint "$OUT/$name/last.pt" --out "$OUT/$name.onnx" >> "$OUT/$name.log" 2>&1
}

# two chains of about equal cost, one per core; the N = 512 pair once more with another seed,
# so the table shows how far two trainings of one recipe differ
( train p4096 --num-points 4096; train p1024 --num-points 1024; train p512 --num-points 512
  train p512_s1 --num-points 512 --seed 1 ) &
( train p3072 --num-points 3072; train p2048 --num-points 2048; train p512_nocat --num-points 512 --no-category
  train p512_nocat_s1 --num-points 512 --no-category --seed 1 ) &
wait

"$PY" benchmarks/bench_boxnet.py --data "$DATA" --cache "$TEST_CACHE" \
    --ckpt "$RUNS/boxnet/v3/best.pt" --out "$OUT/results" --no-speed \
    --ablation p512="$OUT/p512.onnx" p1024="$OUT/p1024.onnx" p2048="$OUT/p2048.onnx" \
    p3072="$OUT/p3072.onnx" p4096="$OUT/p4096.onnx" nocat512="$OUT/p512_nocat.onnx" \
    p512_s1="$OUT/p512_s1.onnx" nocat512_s1="$OUT/p512_nocat_s1.onnx"
