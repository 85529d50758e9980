#!/usr/bin/env bash
# Data, training and evaluation of the shipped DeepPrior++ and localizer weights.
#
#   bash benchmarks/train_deepprior.sh OUT_DIR
#
# Environment (defaults in brackets): HANDSIM [handsim], PYTHON [python3], DEVICE [cuda if torch sees one, else cpu], WORKERS
# [nproc], HAND_FRAMES [60000], GRASP_FRAMES [15000], LOC_EPOCHS [15], DPP_EPOCHS [40],
# WIDTH [1], BATCH [128] (on CUDA with bfloat16 mixed precision), EVAL_FRAMES [3000]; STAGES [data localizer dpp evaluate] picks the
# stages. Every stage resumes: run the same command again after an interruption. The
# figures of docs/deepprior.md name the settings they were made with.
set -euo pipefail
OUT=${1:?usage: train_deepprior.sh OUT_DIR}
PYTHON=${PYTHON:-python3}
HANDSIM=${HANDSIM:-handsim}
DEVICE=${DEVICE:-$($PYTHON -c "import torch; print('cuda' if torch.cuda.is_available() else 'cpu')")}
WORKERS=${WORKERS:-$(nproc)}
HAND_FRAMES=${HAND_FRAMES:-60000}
GRASP_FRAMES=${GRASP_FRAMES:-15000}
LOC_EPOCHS=${LOC_EPOCHS:-15}
DPP_EPOCHS=${DPP_EPOCHS:-40}
WIDTH=${WIDTH:-1}
BATCH=${BATCH:-128}
EVAL_FRAMES=${EVAL_FRAMES:-3000}
STAGES=${STAGES:-"data localizer dpp evaluate"}
mkdir -p "$OUT"
has() { [[ " $STAGES " == *" $1 "* ]]; }
stamp() { echo "[$(date -u +%H:%M:%S)] $*" >&2; }

# Hand alone before the third-person camera, structured-light noise (the test distribution),
# and Grasp-v0 rollouts of the scripted expert from the same camera (hand-object frames).
cat > "$OUT/handonly.json" <<JSON
{"frames": $HAND_FRAMES, "seed": 0, "viewpoints": ["third_person"], "num_objects_range": [0, 0],
 "sensor": "structured_light"}
JSON
cat > "$OUT/grasp.json" <<JSON
{"frames": $GRASP_FRAMES, "seed": 1, "source": "rollout", "env_id": "handsim/Grasp-v0",
 "num_objects_range": [1, 1], "viewpoints": ["third_person"], "sensor": "structured_light",
 "frames_per_episode": 60, "frame_stride": 5}
JSON
DATA=("$OUT/data/handonly")
[[ $GRASP_FRAMES -gt 0 ]] && DATA+=("$OUT/data/grasp")
COMMON=(--device "$DEVICE" --loader-workers "$WORKERS" --batch-size "$BATCH" -q)
[[ $DEVICE == cuda ]] && COMMON+=(--amp)

if has data; then
  stamp "generate $HAND_FRAMES hand-only frames"
  $HANDSIM generate --config "$OUT/handonly.json" --workers "$WORKERS" --out "$OUT/data/handonly" >/dev/null
  if [[ $GRASP_FRAMES -gt 0 ]]; then
    stamp "generate $GRASP_FRAMES Grasp-v0 rollout frames"
    $HANDSIM generate --config "$OUT/grasp.json" --workers "$WORKERS" --out "$OUT/data/grasp" >/dev/null
  fi
fi
if has localizer; then
  stamp "train the localizer"
  $HANDSIM train localizer --data "${DATA[@]}" --out "$OUT/localizer" --epochs "$LOC_EPOCHS" \
    "${COMMON[@]}"
fi
if has dpp; then
  stamp "train DeepPrior++"
  $HANDSIM train deepprior++ --data "${DATA[@]}" --out "$OUT/dpp" --epochs "$DPP_EPOCHS" \
    --width "$WIDTH" --localizer "$OUT/localizer/best.pt" "${COMMON[@]}"
fi
if has evaluate; then
  stamp "evaluate on the hand-only test split"
  $HANDSIM evaluate --estimator "$OUT/dpp" --localizer "$OUT/localizer/best.pt" \
    --data "$OUT/data/handonly" --split test --max-frames "$EVAL_FRAMES" --device "$DEVICE" \
    --out "$OUT/eval_handonly" -q
  if [[ $GRASP_FRAMES -gt 0 ]]; then
    stamp "evaluate on the Grasp-v0 test split"
    $HANDSIM evaluate --estimator "$OUT/dpp" --localizer "$OUT/localizer/best.pt" \
      --data "$OUT/data/grasp" --split test --max-frames "$EVAL_FRAMES" --device "$DEVICE" \
      --out "$OUT/eval_grasp" -q
  fi
fi
stamp done
