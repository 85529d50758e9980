#!/usr/bin/env bash
# Data, training and evaluation of the shipped DeepPrior++, localizer and hand detector weights.
#
#   bash benchmarks/train_deepprior.sh OUT_DIR
#
# Data: the realistic presets of `handsim generate`, a mix of sensors, both sides (training is
# side-canonical: left frames are mirrored into the right-hand frame, the checkpoints carry
# canonical_side):
#   third   hand-only (third person, NYU-fitted views), structured light   THIRD_FRAMES  [6000]
#   tof     hand-only, time of flight                                      TOF_FRAMES    [2000]
#   clean   hand-only, noise-free depth                                    CLEAN_FRAMES  [1000]
#   ego     hand-only-egocentric, structured light                        EGO_FRAMES    [2500]
#   object  hand-object (grasps in contact, 1-3 objects), structured light OBJECT_FRAMES [3500]
#   rollout Grasp-v0 rollouts of the expert (grasp-rollouts), structured light ROLLOUT_FRAMES [0]
# A set with 0 frames is left out. Seeds 0-5 (handsim-bench-v1 uses 2601-2606).
#
# Environment (defaults in brackets): HANDSIM [handsim], PYTHON [python3], DEVICE [cuda if
# torch sees one, else cpu], WORKERS [1] (generate workers; on CUDA also loader workers),
# THREADS [1] (torch CPU threads: on a shared CPU one thread is fastest), DET_EPOCHS [20]
# (the whole-image hand detector, `detector.pt`), LOC_EPOCHS [24],
# DPP_EPOCHS [30], DEEP_EPOCHS [15], WIDTH [0.25] (DeepPrior++ conv filter factor; 1 = the
# paper's), DPP_AUGMENT [scale translation] (DeepPrior++'s online augmentations; `rotation`
# adds the in-plane rotation, which cost 8 mm of validation error in the recipe's control),
# BONE_LOSS [0] (weight of the pose networks' bone-length term from the first epoch, `handsim
# train --bone-loss`), BONE_FT_LOSS [0.01], BONE_FT_EPOCHS [5], BONE_FT_LR [1e-4] (the `bone`
# stage: DeepPrior++ of the `dpp` stage fine-tuned with the bone-length term into OUT/dpp_bone,
# as the shipped network was made; the bench stage then runs it),
# DEEP_FC [512] (units of the `deep` network's two fully connected layers; the paper's 1024
# makes 6.4 MB of float16 weights, 512 makes 2.8 MB), BATCH [64], BENCH
# [OUT/bench], EPISODES [5], LOCALIZER [OUT/localizer/best.pt] (the crop centres of the pose
# networks, e.g. `localizer` for the shipped one); DETECTOR [the run's detector,
# OUT/detector/best.pt, once trained, else `learned`, the shipped one] (the first centre of
# the pose networks' training crops, and of the bench stage's pipeline; `plane` or `com` also);
# REFINE [0] (the localizer's steps from that centre; 0: the detector's centre as it is, as
# the shipped networks were trained; the checkpoints record it and the estimator crops alike);
# STAGES [data detector localizer dpp bone bench] picks the stages (also: deep, DeepPrior's `deep`
# network). The defaults fit a 2-core CPU in about an
# hour (DeepPrior++ alone: 32 min); on a GPU (`--amp`, bfloat16) raise the frames, epochs and
# WIDTH. Every stage resumes: run the same command again after an interruption
# (generate keeps complete shards, train restarts after its last finished epoch, benchmark
# make keeps complete sets). The figures of docs/deepprior.md name the settings they were
# made with.
set -euo pipefail
OUT=${1:?usage: train_deepprior.sh OUT_DIR}
PYTHON=${PYTHON:-python3}
HANDSIM=${HANDSIM:-handsim}
DEVICE=${DEVICE:-$($PYTHON -c "import torch; print('cuda' if torch.cuda.is_available() else 'cpu')")}
WORKERS=${WORKERS:-1}
THREADS=${THREADS:-1}
THIRD_FRAMES=${THIRD_FRAMES:-6000}
TOF_FRAMES=${TOF_FRAMES:-2000}
CLEAN_FRAMES=${CLEAN_FRAMES:-1000}
EGO_FRAMES=${EGO_FRAMES:-2500}
OBJECT_FRAMES=${OBJECT_FRAMES:-3500}
ROLLOUT_FRAMES=${ROLLOUT_FRAMES:-0}
DET_EPOCHS=${DET_EPOCHS:-20}
LOC_EPOCHS=${LOC_EPOCHS:-24}
DPP_EPOCHS=${DPP_EPOCHS:-30}
DPP_AUGMENT=${DPP_AUGMENT:-scale translation}
DEEP_EPOCHS=${DEEP_EPOCHS:-15}
DEEP_FC=${DEEP_FC:-512}
BONE_LOSS=${BONE_LOSS:-0}
BONE_FT_LOSS=${BONE_FT_LOSS:-0.01}
BONE_FT_EPOCHS=${BONE_FT_EPOCHS:-5}
BONE_FT_LR=${BONE_FT_LR:-1e-4}
WIDTH=${WIDTH:-0.25}
BATCH=${BATCH:-64}
BENCH=${BENCH:-$OUT/bench}
EPISODES=${EPISODES:-5}
STAGES=${STAGES:-"data detector localizer dpp bone bench"}
LOCALIZER=${LOCALIZER:-$OUT/localizer/best.pt}
REFINE=${REFINE:-0}
# The first centre of the pose networks' crops: DETECTOR, else the run's detector once trained.
detector() {
  if [[ -n ${DETECTOR:-} ]]; then echo "$DETECTOR"
  elif [[ -f $OUT/detector/best.pt ]]; then echo "$OUT/detector/best.pt"
  else echo learned; fi
}
mkdir -p "$OUT"
has() { [[ " $STAGES " == *" $1 "* ]]; }
stamp() { echo "[$(date -u +%H:%M:%S)] $*" >&2; }

# add_set name preset frames seed sensor (benchmarks/preset_sets.sh)
source "$(dirname "${BASH_SOURCE[0]}")/preset_sets.sh"
add_set third hand-only "$THIRD_FRAMES" 0 structured_light
add_set tof hand-only "$TOF_FRAMES" 1 tof
add_set clean hand-only "$CLEAN_FRAMES" 2 none
add_set ego hand-only-egocentric "$EGO_FRAMES" 3 structured_light
add_set object hand-object "$OBJECT_FRAMES" 4 structured_light
add_set rollout grasp-rollouts "$ROLLOUT_FRAMES" 5 structured_light
DATA=()
for s in "${SETS[@]}"; do DATA+=("$OUT/data/$s"); done

COMMON=(--device "$DEVICE" --batch-size "$BATCH" --threads "$THREADS" -q)
[[ $DEVICE == cuda ]] && COMMON+=(--amp --loader-workers "$WORKERS")

if has data; then
  for s in "${SETS[@]}"; do
    stamp "generate $s ($OUT/$s.json)"
    $HANDSIM generate --config "$OUT/$s.json" --workers "$WORKERS" --out "$OUT/data/$s" -q \
      >/dev/null
  done
fi
if has detector; then
  stamp "train the hand detector"
  $HANDSIM train detector --data "${DATA[@]}" --out "$OUT/detector" --epochs "$DET_EPOCHS" \
    --device "$DEVICE" --batch-size "$BATCH" --threads "$THREADS" -q >/dev/null
fi
if has localizer; then
  stamp "train the localizer"
  $HANDSIM train localizer --data "${DATA[@]}" --out "$OUT/localizer" --epochs "$LOC_EPOCHS" \
    "${COMMON[@]}" >/dev/null
fi
if has dpp; then
  stamp "train DeepPrior++ (width $WIDTH)"
  $HANDSIM train deepprior++ --data "${DATA[@]}" --out "$OUT/dpp" --epochs "$DPP_EPOCHS" \
    --width "$WIDTH" --augment $DPP_AUGMENT --localizer "$LOCALIZER" --detector "$(detector)" \
    --refine-iterations "$REFINE" --bone-loss "$BONE_LOSS" "${COMMON[@]}" >/dev/null
fi
if has bone; then
  stamp "fine-tune DeepPrior++ with the bone-length term ($BONE_FT_LOSS)"
  $HANDSIM train deepprior++ --data "${DATA[@]}" --out "$OUT/dpp_bone" --init "$OUT/dpp/best.pt" \
    --epochs "$BONE_FT_EPOCHS" --lr "$BONE_FT_LR" --bone-loss "$BONE_FT_LOSS" --width "$WIDTH" \
    --augment $DPP_AUGMENT --localizer "$LOCALIZER" --detector "$(detector)" \
    --refine-iterations "$REFINE" "${COMMON[@]}" >/dev/null
fi
if has deep; then
  stamp "train DeepPrior (deep, FC $DEEP_FC)"
  $HANDSIM train deepprior --arch deep --data "${DATA[@]}" --out "$OUT/deep" \
    --epochs "$DEEP_EPOCHS" --fc "$DEEP_FC" --localizer "$LOCALIZER" --detector "$(detector)" \
    --refine-iterations "$REFINE" --bone-loss "$BONE_LOSS" "${COMMON[@]}" >/dev/null
fi
if has bench; then
  stamp "handsim-bench: make $BENCH"
  $HANDSIM benchmark make --out "$BENCH" -q >/dev/null
  # spec CHECKPOINT [EXTRA_KWARGS]: the run's network behind the shipped pipeline class.
  RUN_DETECTOR=$(detector)  # as the networks were trained
  spec() {
    echo "handsim.estimators:DeepPriorEstimator:{\"checkpoint\": \"$1\", \"localizer\": \"$LOCALIZER\", \"detector\": \"$RUN_DETECTOR\", \"threads\": $THREADS${2:-}}"
  }
  DPP=$OUT/dpp/best.pt  # the fine-tuned network where the bone stage ran
  [[ -f $OUT/dpp_bone/best.pt ]] && DPP=$OUT/dpp_bone/best.pt
  stamp "handsim-bench: run DeepPrior++ ($DPP), $EPISODES closed-loop episodes"
  $HANDSIM benchmark run --estimator "$(spec "$DPP")" --bench "$BENCH" \
    --episodes "$EPISODES" --out "$OUT/bench_dpp" -q
  stamp "handsim-bench: the same network without canonicalization (offline)"
  $HANDSIM benchmark run --estimator "$(spec "$DPP" ', "canonical_side": false')" \
    --bench "$BENCH" --episodes 0 --out "$OUT/bench_dpp_unmirrored" -q
  if [[ -f $OUT/deep/best.pt ]]; then
    stamp "handsim-bench: DeepPrior (deep), offline"
    $HANDSIM benchmark run --estimator "$(spec "$OUT/deep/best.pt")" --bench "$BENCH" \
      --episodes 0 --out "$OUT/bench_deep" -q
  fi
fi
stamp done
