# Sourced by the training recipes (train_deepprior.sh, train_feedback.sh); needs PYTHON and OUT.
#
# add_set NAME PRESET FRAMES SEED SENSOR: writes OUT/NAME.json, the preset's generation config
# with these frames, seed and sensor (`handsim generate` overrides frames and seed, not the
# sensor), and appends NAME to SETS; a set of 0 frames is left out.
SETS=()
add_set() {
  [[ $3 -gt 0 ]] || return 0
  $PYTHON - "$2" "$3" "$4" "$5" "$OUT/$1.json" <<'PY'
import json, sys
from handsim.data.config import PRESETS, GenerationConfig
preset, frames, seed, sensor, path = sys.argv[1:]
config = GenerationConfig.from_mapping(PRESETS[preset], frames=int(frames), seed=int(seed),
                                       sensor=sensor)
with open(path, "w") as f:
    json.dump(config.to_json(), f, indent=1)
PY
  SETS+=("$1")
}
