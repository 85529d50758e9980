#!/usr/bin/env bash
# The studies of docs/deepprior.md: (a) prior dimension and direct regression, (b) augmentation
# ablation, (e) hand-size generalization. Every run is DeepPrior++ cropped at the true middle
# MCP (isolating the pose network from the localizer), on hand-only frames of the
# third-person camera with structured-light noise.
#
#   bash benchmarks/deepprior_studies.sh OUT_DIR
#
# Environment (defaults in brackets): HANDSIM [handsim], FRAMES [3000], EPOCHS [6], WIDTH [0.25],
# WORKERS [2] (data generation), THREADS [1] (torch), DEVICE [cpu]. Runs resume; OUT_DIR/summary.json
# collects the best validation error of every run.
set -euo pipefail
OUT=${1:?usage: deepprior_studies.sh OUT_DIR}
HANDSIM=${HANDSIM:-handsim}
FRAMES=${FRAMES:-3000}
EPOCHS=${EPOCHS:-6}
WIDTH=${WIDTH:-0.25}
WORKERS=${WORKERS:-2}
THREADS=${THREADS:-1}
DEVICE=${DEVICE:-cpu}
mkdir -p "$OUT"
gen() {  # name seed frames hand_length_lo hand_length_hi
  [[ -f "$OUT/data/$1/manifest.json" ]] && $HANDSIM dataset check "$OUT/data/$1" >/dev/null 2>&1 && return
  echo "{\"frames\": $3, \"seed\": $2, \"viewpoints\": [\"third_person\"], \"num_objects_range\": [0, 0],
  \"sensor\": \"structured_light\", \"hand_length_range_m\": [$4, $5]}" > "$OUT/$1.json"
  $HANDSIM generate --config "$OUT/$1.json" --workers "$WORKERS" --out "$OUT/data/$1" >/dev/null
}
gen all 5 "$FRAMES" 0.15 0.22
gen small 6 "$FRAMES" 0.15 0.18
gen large 7 $((FRAMES / 4)) 0.19 0.22
COMMON=(--width "$WIDTH" --epochs "$EPOCHS" --device "$DEVICE" --threads "$THREADS" -q)
run() {  # name data args...
  local name=$1 data=$2; shift 2
  [[ -f "$OUT/$name/metrics.json" ]] && return
  echo "[$(date -u +%H:%M:%S)] $name" >&2
  $HANDSIM train deepprior++ --data "$OUT/data/$data" --out "$OUT/$name" "${COMMON[@]}" "$@" >/dev/null
}
for p in 30 0 8 16 45; do run "a_prior$p" all --prior-dim "$p"; done
run b_none all --augment
for a in translation rotation scale; do run "b_$a" all --augment "$a"; done
run e_small small
# (e): the small-hand network and the all-sizes network on large hands, at the true centre.
for n in e_small a_prior30; do
  for d in large small; do
    [[ -f "$OUT/eval_${n}_on_$d/metrics.json" ]] && continue
    $HANDSIM evaluate --estimator "$OUT/$n" --localizer none --data "$OUT/data/$d" --split test \
      --threads "$THREADS" --out "$OUT/eval_${n}_on_$d" -q >/dev/null
  done
done
python3 - "$OUT" <<'PY'
import json, sys
from pathlib import Path
out = Path(sys.argv[1])
summary = {}
for m in sorted(out.glob("*/metrics.json")):
    d = json.loads(m.read_text())
    if "best_val_mean_error_mm" in d:
        summary[m.parent.name] = {"best_val_mean_error_mm": d["best_val_mean_error_mm"],
                                  "train_frames": d["train_frames"], "epochs": d["epochs_done"]}
    else:
        summary[m.parent.name] = {"mean_error_mm_at_true_centre":
                                  d["mean_error_mm_by_crop_centre"]["ground_truth"],
                                  "frames": d["n_frames"]}
(out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
print(json.dumps(summary, indent=2))
PY
