#!/bin/bash
# Instruction counts of the default zone compensation over `--compensation off`
# (repeatable, unlike process CPU on a shared machine; docs/BENCHMARKS.md, "Light
# compensation overhead").
#
# usage: benches/callgrind_overhead.sh BIN OUTDIR MODEL.stl...
# For each model: one single-threaded callgrind run per mode, then
#   MODEL off X M zone Y M extra E % | sha off S0 zone S1 | without software SHA E' % (D M)
# valgrind hides SHA-NI, so SHA-256 runs in software there (about 10x its native cost);
# E' takes 90 % of the `sha2::sha256::compress256` instructions out of both counts.
BIN=$1; OUT=$2; shift 2
if [ -z "$BIN" ] || [ -z "$OUT" ] || [ $# = 0 ]; then
  echo "usage: $0 BIN OUTDIR MODEL.stl..." >&2; exit 2
fi
mkdir -p "$OUT"
for model in "$@"; do
  m=$(basename "$model" .stl)
  declare -A T S
  for c in off zone; do
    cg="$OUT/$m-$c.callgrind"
    rm -rf "$OUT/$m-$c.dmdjob"
    RAYON_NUM_THREADS=1 valgrind --tool=callgrind --dump-instr=no --callgrind-out-file="$cg" \
      "$BIN" slice "$model" -q -o "$OUT/$m-$c.dmdjob" --compensation $c --cure-correction off >/dev/null 2>&1 \
      || { echo "$m $c: slice failed" >&2; exit 1; }
    T[$c]=$(grep -m1 '^totals:' "$cg" | awk '{print $2}')
    S[$c]=$(callgrind_annotate --inclusive=yes "$cg" 2>/dev/null \
      | grep -m1 'sha2::sha256::compress256' | awk '{gsub(",", "", $1); print $1}')
    rm -rf "$OUT/$m-$c.dmdjob"
  done
  python3 -c "
o, z, so, sz = ${T[off]}, ${T[zone]}, ${S[off]:-0}, ${S[zone]:-0}
ao, az = o - 0.9 * so, z - 0.9 * sz
print(f'$m off {o/1e6:.0f} M zone {z/1e6:.0f} M extra {100*(z/o-1):.1f} % | sha off {so/1e6:.0f} zone {sz/1e6:.0f} | without software SHA {100*(az/ao-1):.2f} % ({(az-ao)/1e6:.1f} M)')"
done
