#!/bin/bash
# Byte-for-byte check of the masks and optics/ files (and exit code and stderr) of a
# dmdsl binary against a reference binary, over 112 slicing combinations:
#   models (bunny00, logo_hires, mcad_gear from $MODELS, and a plate covering the field)
#   × calibration (built-in, or a `dmdsl calibrate` fit) × --compensation off|zone|pixel
#   × anti-aliased / --binary × --dither auto|on|off (off mode: auto and off only).
#
# usage: benches/check_masks.sh NEWBIN OUTDIR
# env:
#   REF     reference binary (default /work/target-comp/dmdsl-base)
#   MODELS  directory with bunny00.stl, logo_hires.stl, mcad_gear.stl
#           (default /work/shared/models)
#   PLATE   STL of a plate covering the field (default /dev/shm/eqc/plate.stl)
#   CAL     calibration TOML from `dmdsl calibrate` (default /dev/shm/eqc/cal.toml)
# Prints one "DIFF <combo> rc <ref> <new>" line per differing combination, then
# "checked N combos, M differ"; exits 1 if any differ.
NEW=$1; OUT=$2
if [ -z "$NEW" ] || [ -z "$OUT" ]; then
  echo "usage: $0 NEWBIN OUTDIR" >&2; exit 2
fi
REF=${REF:-/work/target-comp/dmdsl-base}
MODELS=${MODELS:-/work/shared/models}
PLATE=${PLATE:-/dev/shm/eqc/plate.stl}
CAL=${CAL:-/dev/shm/eqc/cal.toml}
for f in "$REF" "$NEW" "$PLATE" "$CAL"; do
  [ -e "$f" ] || { echo "missing: $f" >&2; exit 2; }
done
mkdir -p "$OUT"; fails=0; n=0
for m in bunny00 logo_hires mcad_gear plate; do
 for cal in builtin fit; do
  for comp in off zone pixel; do
   [ $cal = fit ] && [ $comp = off ] && continue
   for bin in aa bin; do
    for d in auto on off; do
     [ $comp = off ] && [ $d = on ] && continue
     mp=$MODELS/$m.stl; [ $m = plate ] && mp=$PLATE
     args=(slice "$mp" -q --compensation $comp --dither $d)
     [ $bin = bin ] && args+=(--binary)
     [ $cal = fit ] && args+=(--calibration "$CAL")
     tag=$m-$cal-$comp-$bin-$d
     rm -rf "$OUT/a.dmdjob" "$OUT/b.dmdjob"
     "$REF" "${args[@]}" -o "$OUT/a.dmdjob" 2>"$OUT/a.err"; ra=$?
     "$NEW" "${args[@]}" -o "$OUT/b.dmdjob" 2>"$OUT/b.err"; rb=$?
     ha=$(cd "$OUT/a.dmdjob" && find masks optics -type f 2>/dev/null | sort | xargs sha256sum | sha256sum)
     hb=$(cd "$OUT/b.dmdjob" && find masks optics -type f 2>/dev/null | sort | xargs sha256sum | sha256sum)
     n=$((n+1))
     if [ "$ha" != "$hb" ] || [ $ra != $rb ] || ! cmp -s "$OUT/a.err" "$OUT/b.err"; then
       echo "DIFF $tag rc $ra $rb"; fails=$((fails+1))
     fi
    done
   done
  done
 done
done
echo "checked $n combos, $fails differ"
[ $fails = 0 ]
