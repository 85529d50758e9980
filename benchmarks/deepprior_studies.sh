#!/usr/bin/env bash
# The studies of docs/deepprior.md: (a) prior dimension and direct regression, (b) augmentation
# ablation, (e) hand-size generalization. Every run is DeepPrior++ cropped at the true middle
# MCP (isolating the pose network from the localizer), on frames of the `hand-only` preset of
# `handsim generate` (third-person camera, both sides, mirrored into the right-hand frame in
# training) with structured-light noise.
#
#   bash benchmarks/deepprior_studies.sh OUT_DIR
#
# Environment (defaults in brackets): HANDSIM [handsim], PYTHON [python3], FRAMES [3000],
# EPOCHS [3], WIDTH [0.25], WORKERS [2] (data generation), THREADS [1] (torch), DEVICE [cpu].
# Runs resume; OUT_DIR/summary.json collects the best validation error of every run.
set -euo pipefail
OUT=${1:?usage: deepprior_studies.sh OUT_DIR}
HANDSIM=${HANDSIM:-handsim}
PYTHON=${PYTHON:-python3}
FRAMES=${FRAMES:-3000}
EPOCHS=${EPOCHS:-3}
WIDTH=${WIDTH:-0.25}
WORKERS=${WORKERS:-2}
THREADS=${THREADS:-1}
DEVICE=${DEVICE:-cpu}
mkdir -p "$OUT"
gen() {  # name seed frames hand_length_lo hand_length_hi: the hand-only preset with these
  [[ -f "$OUT/data/$1/manifest.json" ]] && $HANDSIM dataset check "$OUT/data/$1" >/dev/null 2>&1 && return
  $PYTHON - "$OUT/$1.json" "$2" "$3" "$4" "$5" <<'PY'
import json, sys
from handsim.data.config import PRESETS, GenerationConfig
path, seed, frames, lo, hi = sys.argv[1:]
config = GenerationConfig.from_mapping(
    PRESETS["hand-only"], frames=int(frames), seed=int(seed), sensor="structured_light",
    hand_length_range_m=(float(lo), float(hi)))
with open(path, "w") as f:
    json.dump(config.to_json(), f, indent=1)
PY
  $HANDSIM generate --config "$OUT/$1.json" --workers "$WORKERS" --out "$OUT/data/$1" -q >/dev/null
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
evaluate() {  # network data: its error at the true centre on the test split of data
  [[ -f "$OUT/eval_${1}_on_$2/metrics.json" ]] && return
  $HANDSIM evaluate --estimator "$OUT/$1" --localizer none --data "$OUT/data/$2" --split test \
    --threads "$THREADS" --out "$OUT/eval_${1}_on_$2" -q >/dev/null
}
# The most telling runs first: a run cut short still answers part of each question.
run a_prior30 all --prior-dim 30
run b_none all --augment
run a_prior0 all --prior-dim 0
# (e): a network trained on small hands, and the all-sizes one, on large and small hands.
run e_small small
for n in e_small a_prior30; do evaluate "$n" large; evaluate "$n" small; done
for p in 8 16 45; do run "a_prior$p" all --prior-dim "$p"; done
for a in translation rotation scale; do run "b_$a" all --augment "$a"; done
$PYTHON - "$OUT" <<'PY'
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
