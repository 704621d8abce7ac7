#!/usr/bin/env bash
# The EdgeTrack recipe: simulate the training data, cut the caches, train (about 3 h on one
# thread, resumable), export with a parity check, and evaluate one pass against SiamFC-edge.
# Every step resumes: run the script again after an interruption (kill it at any time; the
# training checkpoints atomically every 3 minutes and continues from there).
#
#   nice -n 10 bash export/scripts/train_edgetrack.sh   # DATA=data/engine-train RUNS=runs by default
#
# Knobs: THREADS (torch threads, 1), MINUTES (training budget, 175), STEPS (a step cap, 30000;
# the cosine LR ends at the cap or at the time budget, whichever comes first),
# BATCH (32). The model lands in $RUNS/edgetrack/model/edgetrack_{template,search}.onnx; copy it
# to runtime/track3d/models/ only if it beats the shipped EdgeTrack and SiamFC-edge on both
# evaluation splits: eval_<split>.json compares them on the same frames.
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=${PY:-.venv/bin/python}
BIN=$(dirname "$PY")
DATA=${DATA:-data/engine-train}
EVAL=${EVAL:-data/engine-ideal}
DIV=${DIV:-${DATA}_div}
RUNS=${RUNS:-runs}
THREADS=${THREADS:-1}
MINUTES=${MINUTES:-175}
STEPS=${STEPS:-30000}
BATCH=${BATCH:-32}
OUT=$RUNS/edgetrack
mkdir -p "$OUT"

# 1. data (the data engine): 36 train sequences x 100 frames, plus 120 more train shapes x 25
#    frames (seed 1) with low-light auto exposure and motion blur for variety; --test-unseen 1
#    holds the unseen generators out of train (its one sequence is not used). The evaluation
#    sets are the README's engine sets (9 test + 9 test_unseen x 60 frames, seed 0): train
#    and test share no fine category whatever the seeds.
"$BIN/track3d-sim" generate --preset small --train 36 --test 0 --test-unseen 1 --out "$DATA" --workers 2 --quiet
"$BIN/track3d-sim" generate --preset small --seed 1 --train 120 --test 0 --test-unseen 1 --frames 25 \
    --auto-exposure --motion-blur --out "$DIV" --workers 2 --quiet

# 2. one cache of both train splits: target crops (442 kB each, ~1.6 GB in all) and background
#    crops (absent frames, empty sky); the last 2 sequences (of $DIV) are the validation set
[ -f "$OUT/cache/background/bg.json" ] || "$BIN/track3d-train" edgetrack prepare --data "$DATA" "$DIV" \
    --max-frames 3600 --max-background 1500 --out "$OUT/cache" --quiet

# 3. training, one thread, ~3 h
"$BIN/track3d-train" edgetrack train --cache "$OUT/cache" --out "$OUT/run" --max-steps "$STEPS" \
    --batch "$BATCH" --time-budget-min "$MINUTES" --threads "$THREADS" --quiet >> "$OUT/train.log" 2>&1

# 4. export (parity check printed) and one-pass evaluation against SiamFC-edge and the shipped EdgeTrack
"$BIN/track3d-train" edgetrack export --checkpoint "$OUT/run/ckpt.pt" --out "$OUT/model/edgetrack"
"$BIN/track3d-sim" generate --preset small --train 0 --test 9 --test-unseen 9 --frames 60 --sensors ideal \
    --seed 0 --out "$EVAL" --quiet
for split in test test_unseen; do
  "$BIN/track3d-train" edgetrack eval --model "$OUT/model/edgetrack" --data "$EVAL" --split $split \
      --compare siamfc-edge edgetrack --out "$OUT/eval_$split.json" --quiet
done
