#!/bin/bash
# Slices every model of a directory with each of a set of option combinations and replays
# each job with `dmdsl run`: prints one line per job that `slice` refuses or that `run`
# fails (its violations), and one per job with layers drawn without the cure correction
# (`cure.layers-uncorrected`), then the counts. A job `slice` writes that `run` rejects
# is a defect; a refusal is one when its message is not what the user should be told.
#
# usage: benches/slice_run_matrix.sh BIN MODELS_DIR OUTDIR
# Exits 1 when some job was refused or failed. Every job takes a few seconds (the eight
# shared models, 19 combinations, two outputs each: about 6 minutes on 2 cores).
BIN=$1; MODELS=$2; OUT=$3
if [ -z "$BIN" ] || [ -z "$MODELS" ] || [ -z "$OUT" ]; then
  echo "usage: $0 BIN MODELS_DIR OUTDIR" >&2; exit 2
fi
mkdir -p "$OUT"
opts=(
  "--supports"
  "--supports --profile bottom-up"
  "--supports --profile hybrid-bottomup"
  "--supports --binary"
  "--supports --profile hybrid-bottomup --binary"
  "--supports --layer-height 0.025"
  "--supports --compensation pixel"
  "--supports --rotate 0,45,0"
  "--supports --rotate 90,0,0"
  "--supports --profile hybrid-bottomup --rotate 45,0,0"
  "--supports --set accuracy.xy_offset_mm=-0.05"
  "--supports --cure-correction xyz"
  "--cure-correction xyz"
  "--cure-correction xyz --profile bottom-up"
  "--cure-correction xyz --binary"
  "--profile tiled-2x1 --supports"
  "--cure-correction off --supports --binary"
  "--layer-height 0.1 --cure-correction xyz"
  "--set accuracy.xy_offset_mm=0.05"
)
jobs=0; bad=0; plain=0
for m in "$MODELS"/*.stl; do
  for a in "${opts[@]}"; do
    for ext in dmdjob.zip sl1; do
      f=$OUT/job.$ext
      rm -f "$f"
      jobs=$((jobs + 1))
      # shellcheck disable=SC2086
      if ! "$BIN" slice "$m" $a -o "$f" > "$OUT/slice.txt" 2>&1; then
        # A tiled job has no SL1 form: that refusal is the expected one.
        grep -q "carry one image per layer" "$OUT/slice.txt" && continue
        bad=$((bad + 1))
        echo "SLICE $(basename "$m") [$a] .$ext: $(head -c 300 "$OUT/slice.txt")"
        continue
      fi
      if grep -q "cure.layers-uncorrected" "$OUT/slice.txt"; then
        plain=$((plain + 1))
        echo "UNCORRECTED $(basename "$m") [$a] .$ext: $(grep -o 'cure: [0-9]* layers\? ([^)]*) drawn [^:]*' "$OUT/slice.txt")"
      fi
      if ! "$BIN" run -q "$f" > /dev/null 2>&1; then
        bad=$((bad + 1))
        echo "RUN $(basename "$m") [$a] .$ext: $("$BIN" run "$f" 2>&1 | grep -A1 '^violations' | tr '\n' ' ' | cut -c1-300)"
      fi
    done
  done
done
echo "$jobs jobs, $bad refused or failed, $plain with layers drawn without the cure correction"
[ "$bad" = 0 ]
