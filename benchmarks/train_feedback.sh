#!/usr/bin/env bash
# Data, training and evaluation of the feedback loop's updater behind the shipped DeepPrior++.
#
#   bash benchmarks/train_feedback.sh OUT_DIR
#
# Data: the realistic presets of DeepPrior++'s recipe (benchmarks/train_deepprior.sh), both
# sides, with seeds of their own: DeepPrior++ was trained on the recipe's seeds 0-5, and on its
# own training frames its error is smaller than the one the updater must correct.
#   third   hand-only (third person), structured light                THIRD_FRAMES  [2500]
#   object  hand-object (grasps in contact, 1-3 objects), structured light OBJECT_FRAMES [2500]
# Seeds 10 and 14 (handsim-bench-v1 uses 2601-2606).
#
# The updater: side-canonical (left frames mirrored into the right-hand frame, as DeepPrior++),
# crops where its predictor's training crops were centred (the predictor checkpoint's `crop`
# record; without one, the plane detector's centres refined three times by the shipped
# localizer), starting poses from the predictor there (PREDICTOR [deepprior++], the shipped one),
# the renderer synthesizer (every pool entry's crop is rendered once and cached in the run
# folder). Environment (defaults in brackets): HANDSIM [handsim], PYTHON [python3], THREADS [1],
# EPOCHS [8], FILTERS [16], FC [256], BATCH [64], SIGMA_MM [15] (perturbations of the starting
# poses, per coordinate), ITERATIONS [3] (most updates tried on validation), VAL_FRAMES [300],
# TRUTH_STARTS [0] (1: the truth itself is a starting pose, as in the paper; with it the updater
# learned to make no update here, docs/feedback.md),
# BENCH [OUT/bench], STAGES [data updater bench], UPDATER [OUT/updater] (the run folder; the
# bench stage writes UPDATER/bench_feedback and UPDATER/iterations.json).
#
# The learned synthesizer instead of the renderer (SYNTH [renderer] | learned): the stage
# `synthesizer` trains it on the hand-only set (the synthesizer, as the renderer, draws the hand
# alone: an object is nothing it can know from the pose) into SYNTH_CHECKPOINT
# [OUT/synthesizer] (SYNTH_EPOCHS [5], SYNTH_FRAMES [1500], SYNTH_FC [1024], filters FILTERS,
# batch 32); the updater, same options otherwise, goes to UPDATER [OUT/updater_learned] and
# is evaluated with that synthesizer. STAGES then defaults to [data synthesizer updater bench];
# leave out `synthesizer` to use another run (SYNTH_CHECKPOINT=runs/synth
# UPDATER=OUT/updater_synth STAGES="updater bench").
# Every stage resumes: run the same command again after an interruption (generate keeps
# complete shards, train restarts after its last finished epoch with its pool and its cached
# crops, benchmark make keeps complete sets).
set -euo pipefail
OUT=${1:?usage: train_feedback.sh OUT_DIR}
PYTHON=${PYTHON:-python3}
HANDSIM=${HANDSIM:-handsim}
THREADS=${THREADS:-1}
PREDICTOR=${PREDICTOR:-deepprior++}
THIRD_FRAMES=${THIRD_FRAMES:-2500}
OBJECT_FRAMES=${OBJECT_FRAMES:-2500}
EPOCHS=${EPOCHS:-8}
FILTERS=${FILTERS:-16}
FC=${FC:-256}
BATCH=${BATCH:-64}
SIGMA_MM=${SIGMA_MM:-15}
ITERATIONS=${ITERATIONS:-3}
VAL_FRAMES=${VAL_FRAMES:-300}
TRUTH_STARTS=${TRUTH_STARTS:-0}
BENCH=${BENCH:-$OUT/bench}
SYNTH=${SYNTH:-renderer}
SYNTH_CHECKPOINT=${SYNTH_CHECKPOINT:-$OUT/synthesizer}
SYNTH_EPOCHS=${SYNTH_EPOCHS:-5}
SYNTH_FRAMES=${SYNTH_FRAMES:-1500}
SYNTH_FC=${SYNTH_FC:-1024}
case $SYNTH in
  renderer)
    STAGES=${STAGES:-"data updater bench"}
    UPDATER=${UPDATER:-$OUT/updater}
    SYNTH_ARGS=()
    ;;
  learned)
    STAGES=${STAGES:-"data synthesizer updater bench"}
    UPDATER=${UPDATER:-$OUT/updater_learned}
    SYNTH_ARGS=(--synthesizer learned --synthesizer-checkpoint "$SYNTH_CHECKPOINT")
    ;;
  *) echo "SYNTH must be renderer or learned; received '$SYNTH'" >&2; exit 2 ;;
esac
mkdir -p "$OUT"
has() { [[ " $STAGES " == *" $1 "* ]]; }
stamp() { echo "[$(date -u +%H:%M:%S)] $*" >&2; }

# add_set name preset frames seed sensor (benchmarks/preset_sets.sh)
source "$(dirname "${BASH_SOURCE[0]}")/preset_sets.sh"
add_set third hand-only "$THIRD_FRAMES" 10 structured_light
add_set object hand-object "$OBJECT_FRAMES" 14 structured_light
DATA=()
for s in "${SETS[@]}"; do DATA+=("$OUT/data/$s"); done

if has data; then
  for s in "${SETS[@]}"; do
    stamp "generate $s ($OUT/$s.json)"
    $HANDSIM generate --config "$OUT/$s.json" --workers 1 --out "$OUT/data/$s" -q >/dev/null
  done
fi
if has synthesizer && [[ $SYNTH == learned ]]; then
  stamp "train the learned synthesizer on $OUT/data/third"
  $HANDSIM train synthesizer --data "$OUT/data/third" --out "$SYNTH_CHECKPOINT" \
    --epochs "$SYNTH_EPOCHS" --filters "$FILTERS" --fc "$SYNTH_FC" --max-frames "$SYNTH_FRAMES" \
    --batch-size 32 --threads "$THREADS" -q
fi
if has updater; then
  stamp "train the updater ($SYNTH synthesizer): $UPDATER"
  $HANDSIM train updater --data "${DATA[@]}" --out "$UPDATER" --epochs "$EPOCHS" \
    --filters "$FILTERS" --fc "$FC" --batch-size "$BATCH" --perturb-sigma-mm "$SIGMA_MM" \
    --iterations "$ITERATIONS" --max-val-frames "$VAL_FRAMES" --threads "$THREADS" -q \
    --predictor "$PREDICTOR" \
    "${SYNTH_ARGS[@]}" $([[ $TRUTH_STARTS == 1 ]] || echo --no-truth-starts)
fi
if has bench; then
  stamp "handsim-bench: make $BENCH"
  $HANDSIM benchmark make --out "$BENCH" -q >/dev/null
  stamp "handsim-bench: the feedback estimator, offline"
  ARGS="\"updater\": \"$UPDATER/best.pt\", \"predictor\": \"$PREDICTOR\""
  [[ $SYNTH == learned ]] && ARGS+=", \"synthesizer\": \"learned\", \"synthesizer_checkpoint\": \"$SYNTH_CHECKPOINT\""
  $HANDSIM benchmark run --estimator "handsim.estimators:FeedbackEstimator:{$ARGS}" \
    --bench "$BENCH" --episodes 0 --out "$UPDATER/bench_feedback" -q
  stamp "error after each update, per set and occlusion bucket"
  $PYTHON -m handsim.estimators.feedback.evaluate --updater "$UPDATER/best.pt" \
    --predictor "$PREDICTOR" \
    --bench "$BENCH" "${SYNTH_ARGS[@]}" --out "$UPDATER/iterations.json"
fi
stamp done
