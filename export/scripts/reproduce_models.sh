#!/usr/bin/env bash
# Reproduces the models shipped in runtime/track3d/models/ on this 2-core CPU (no GPU needed):
# simulate the training data, cut the caches, train SiamFC (edge, faithful) and A3BoxNet, export.
# Every step resumes: run it again after an interruption. Logs go to $RUNS/*.log.
#
#   bash export/scripts/reproduce_models.sh            # DATA=data/med RUNS=runs by default
#
# Budgets (minutes of wall time per model) can be changed with BOXNET_MIN, EDGE_MIN, FAITHFUL_MIN.
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=${PY:-.venv/bin/python}
BIN=$(dirname "$PY")
DATA=${DATA:-data/med}
RUNS=${RUNS:-runs}
MODELS=runtime/track3d/models
BOXNET_MIN=${BOXNET_MIN:-30}
BOXNET_MIN2=${BOXNET_MIN2:-65}   # the shipped A3BoxNet: resumed to 65 min on 2 threads (a warm restart)
EDGE_MIN=${EDGE_MIN:-36}
FAITHFUL_MIN=${FAITHFUL_MIN:-40}
mkdir -p "$RUNS" "$MODELS"

# 1. data: 36 train / 18 test sequences x 100 frames, 640x480 (the `small` preset, doubled), and
#    for A3BoxNet 120 more train-only sequences x 25 frames (seed 1): more shapes beat more frames
DIV=${DIV:-${DATA}_div}
"$BIN/track3d-sim" generate --preset small --train 36 --test 18 --out "$DATA" --workers 2 --quiet
"$BIN/track3d-sim" generate --preset small --seed 1 --train 120 --test 0 --frames 25 --out "$DIV" --workers 2 --quiet

# 2. caches (the runtime's own frustum and crop code)
"$BIN/track3d-train" boxnet prepare --data "$DATA" --split train --jitters 5 --out "$RUNS/boxnet/cache/train.npz" --quiet
"$BIN/track3d-train" boxnet prepare --data "$DATA" --split test --jitters 0 --out "$RUNS/boxnet/cache/test.npz" --quiet
"$BIN/track3d-train" boxnet prepare --data "$DIV" --split train --jitters 3 --out "$RUNS/boxnet/cache/div_train.npz" --quiet
"$BIN/track3d-train" siamfc prepare --data "$DATA" --split train --max-frames 3600 --out "$RUNS/siamfc/cache" --quiet

# 3. training, one thread each, A3BoxNet and SiamFC-edge side by side, then SiamFC-faithful on both cores
"$BIN/track3d-train" boxnet train --cache "$RUNS/boxnet/cache/train.npz" "$RUNS/boxnet/cache/div_train.npz" \
    --out "$RUNS/boxnet/main" --num-points 512 --epochs 100 --time-budget-min "$BOXNET_MIN" --flip-y --scale-aug 0.15 \
    --size-norm extent --threads 1 --quiet > "$RUNS/boxnet_train.log" 2>&1 &
"$BIN/track3d-train" siamfc train --variant edge --cache "$RUNS/siamfc/cache" --out "$RUNS/siamfc_edge" \
    --max-steps "${EDGE_STEPS:-4800}" --batch 16 --time-budget-min "$EDGE_MIN" --threads 1 --quiet > "$RUNS/siamfc_edge_train.log" 2>&1 &
wait
"$BIN/track3d-train" siamfc train --variant faithful --cache "$RUNS/siamfc/cache" --out "$RUNS/siamfc_faithful" \
    --max-steps "${FAITHFUL_STEPS:-900}" --batch 8 --time-budget-min "$FAITHFUL_MIN" --threads 2 --quiet > "$RUNS/siamfc_faithful_train.log" 2>&1

"$BIN/track3d-train" boxnet train --cache "$RUNS/boxnet/cache/train.npz" "$RUNS/boxnet/cache/div_train.npz" \
    --out "$RUNS/boxnet/main" --num-points 512 --epochs 100 --time-budget-min "$BOXNET_MIN2" --flip-y --scale-aug 0.15 \
    --size-norm extent --threads 2 --quiet >> "$RUNS/boxnet_train.log" 2>&1

# 4. export with parity checks into the package
"$BIN/track3d-train" boxnet export --checkpoint "$RUNS/boxnet/main/best.pt" --out "$MODELS/a3boxnet.onnx" --force
"$BIN/track3d-train" siamfc export --checkpoint "$RUNS/siamfc_edge/ckpt.pt" --out "$MODELS/siamfc_edge" --force
"$BIN/track3d-train" siamfc export --checkpoint "$RUNS/siamfc_faithful/ckpt.pt" --out "$MODELS/siamfc_faithful" --force
