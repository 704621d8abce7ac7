#!/usr/bin/env bash
# The EdgeTrack recipe: simulate the training data, cut the caches, train (about 3 h on one
# thread, resumable), export with a parity check, and evaluate one pass against SiamFC-edge.
# Every step resumes: run the script again after an interruption (kill it at any time; the
# training checkpoints atomically every 3 minutes and continues from there).
#
#   nice -n 10 bash export/scripts/train_edgetrack.sh        # DATA=data/engine-med RUNS=runs by default
#
# Knobs: THREADS (torch threads, 1), MINUTES (training budget, 175), STEPS (a step cap, 30000;
# the cosine LR ends at the cap or at the time budget, whichever comes first),
# BATCH (32). The model lands in $RUNS/edgetrack/model/edgetrack_{template,search}.onnx; copy it
# to runtime/track3d/models/ only if it beats the shipped short-run EdgeTrack (AO_2d 0.713) and
# SiamFC-edge (0.627) on the 18-sequence test split: eval.json compares it with SiamFC-edge.
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=${PY:-.venv/bin/python}
BIN=$(dirname "$PY")
DATA=${DATA:-data/engine-med}
DIV=${DIV:-${DATA}_div}
RUNS=${RUNS:-runs}
THREADS=${THREADS:-1}
MINUTES=${MINUTES:-175}
STEPS=${STEPS:-30000}
BATCH=${BATCH:-32}
OUT=$RUNS/edgetrack
mkdir -p "$OUT"

# 1. data (the data engine): 36 train / 18 test / 18 test_unseen x 100 frames, plus 120 more
#    train-only shapes x 25 frames (seed 1) with low-light auto exposure and motion blur for
#    variety; --test-unseen holds the unseen generators out of both train splits
"$BIN/track3d-sim" generate --preset small --train 36 --test 18 --test-unseen 18 --out "$DATA" --workers 2 --no-progress
"$BIN/track3d-sim" generate --preset small --seed 1 --train 120 --test 0 --test-unseen 1 --frames 25 \
    --auto-exposure --motion-blur --out "$DIV" --workers 2 --no-progress

# 2. one cache of both train splits: target crops (442 kB each, ~1.6 GB in all) and background
#    crops (absent frames, empty sky); the last 2 sequences (of $DIV) are the validation set
[ -f "$OUT/cache/background/bg.json" ] || "$BIN/track3d-train" edgetrack prepare --data "$DATA" "$DIV" \
    --max-frames 3600 --max-background 1500 --out "$OUT/cache" --quiet

# 3. training, one thread, ~3 h
"$BIN/track3d-train" edgetrack train --cache "$OUT/cache" --out "$OUT/run" --steps "$STEPS" \
    --batch "$BATCH" --time-budget-min "$MINUTES" --threads "$THREADS" --quiet >> "$OUT/train.log" 2>&1

# 4. export (parity check printed) and one-pass evaluation against SiamFC-edge and the shipped EdgeTrack
"$BIN/track3d-train" edgetrack export --checkpoint "$OUT/run/ckpt.pt" --out "$OUT/model/edgetrack"
for split in test test_unseen; do
  "$BIN/track3d-train" edgetrack eval --model "$OUT/model/edgetrack" --data "$DATA" --split $split \
      --compare siamfc-edge edgetrack --out "$OUT/eval_$split.json" --quiet
done
