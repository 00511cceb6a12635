#!/bin/bash
# Byte-for-byte check of the masks and optics/ files (and exit code and stderr) of a
# dmdsl binary against a reference binary, over 112 slicing combinations:
#   models (bunny00, logo_hires, mcad_gear from $MODELS, and a plate covering the field)
#   × calibration (built-in, or a `dmdsl calibrate` fit) × --compensation off|zone|pixel
#   × anti-aliased / --binary × --dither auto|on|off (off mode: auto and off only).
# A change that must not alter the output (a refactor, a faster encoder) passes with 0 differ.
#
# usage: REF=OLD_BIN MODELS=DIR CAL=cal.toml benches/check_masks.sh NEW_BIN OUTDIR
# env:
#   REF     reference binary (required), e.g. a release build of main
#   MODELS  directory with bunny00.stl, logo_hires.stl, mcad_gear.stl (required)
#   CAL     calibration TOML from `dmdsl calibrate` (required)
#   PLATE   STL of a plate covering the field (default: OUTDIR/plate.stl, a 64 x 48 x 1 mm
#           box written by this script)
# Prints one "DIFF <combo> rc <ref> <new>" line per differing combination, then
# "checked N combos, M differ"; exits 1 if any differ.
NEW=$1; OUT=$2
if [ -z "$NEW" ] || [ -z "$OUT" ] || [ -z "${REF:-}" ] || [ -z "${MODELS:-}" ] || [ -z "${CAL:-}" ]; then
  echo "usage: REF=OLD_BIN MODELS=DIR CAL=cal.toml $0 NEW_BIN OUTDIR" >&2; exit 2
fi
mkdir -p "$OUT"
if [ -z "${PLATE:-}" ]; then
  PLATE=$OUT/plate.stl
  python3 - "$PLATE" <<'PY'
import sys
x, y, z = 64.0, 48.0, 1.0
v = [(i * x, j * y, k * z) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
quads = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
c = (x / 2, y / 2, z / 2)
with open(sys.argv[1], "w") as f:
    f.write("solid plate\n")
    for q in quads:
        for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3])):
            a, b, d = (v[i] for i in t)
            u = [b[k] - a[k] for k in range(3)]
            w = [d[k] - a[k] for k in range(3)]
            n = (u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0])
            if sum(n[k] * (a[k] - c[k]) for k in range(3)) < 0:
                t = (t[0], t[2], t[1])
            f.write(" facet normal 0 0 0\n  outer loop\n")
            for i in t:
                f.write("   vertex %g %g %g\n" % v[i])
            f.write("  endloop\n endfacet\n")
    f.write("endsolid plate\n")
PY
fi
for f in "$REF" "$NEW" "$PLATE" "$CAL"; do
  [ -e "$f" ] || { echo "missing: $f" >&2; exit 2; }
done
fails=0; n=0
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
