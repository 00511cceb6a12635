#!/usr/bin/env python3
"""Wall time of dmdsl's output forms against PrusaSlicer's anti-aliased SL1 export.

Usage: formats.py [--age N] [--off] DMDSL_BIN OUTDIR RUNS MODEL.stl [MODEL.stl ...]

For each of RUNS rounds and each model, in turn: PrusaSlicer's SLA export with
anti-aliasing (`benches/peers/prusa_sla.ini` plus `--gamma-correction 1`), then
`dmdsl slice MODEL -q -o` a bundle directory, a `.dmdjob.zip` and a `.sl1` (the default
profile: zone light compensation and the full planning). Every run writes a fresh path under
OUTDIR. With `--age N`, before each round N files are created in OUTDIR, synced and deleted
(the state a CI loop that slices many parts leaves the filesystem in; on this machine's ext4
creating files right after that costs extra kernel time). Prints per model the median wall
time of each, the ratios, and the geometric means. With `--off`, each form is also run
with `--cure-correction off` (the uncorrected masks; columns `dir-off`, `zip-off`,
`sl1-off`), interleaved with the rest.
"""
import json, math, os, statistics, subprocess, sys
from timing import timed

HERE = os.path.dirname(os.path.abspath(__file__))
FORMS = [("dir", ".dmdjob"), ("zip", ".dmdjob.zip"), ("sl1", ".sl1")]


def age(out, n):
    d = os.path.join(out, "age")
    os.makedirs(d, exist_ok=True)
    for i in range(n):
        with open(os.path.join(d, f"{i}.png"), "wb") as f:
            f.write(b"x" * 3000)
    os.sync()
    subprocess.run(["rm", "-rf", d], check=True)


def gmean(xs):
    return math.exp(sum(map(math.log, xs)) / len(xs))


def main():
    args = sys.argv[1:]
    aging, off = 0, False
    while args[0] in ("--age", "--off"):
        if args[0] == "--age":
            aging, args = int(args[1]), args[2:]
        else:
            off, args = True, args[1:]
    forms = [(f, e, []) for f, e in FORMS]
    if off:
        forms += [(f + "-off", e, ["--cure-correction", "off"]) for f, e in FORMS]
    dmdsl, out, runs, models = args[0], args[1], int(args[2]), args[3:]
    subprocess.run(["rm", "-rf", out], check=True)
    os.makedirs(out, exist_ok=True)
    t = {m: {k: [] for k in ["prusa"] + [f for f, _, _ in forms]} for m in models}
    sys_t = {m: {f: [] for f, _, _ in forms} for m in models}
    for r in range(runs):
        for m in models:
            name = os.path.splitext(os.path.basename(m))[0]
            if aging:
                age(out, aging)
            dt, _ = timed(["prusa-slicer", "--load", os.path.join(HERE, "prusa_sla.ini"),
                           "--gamma-correction", "1", "--export-sla",
                           "--output", os.path.join(out, f"{name}-{r}-prusa.sl1"), m])
            t[m]["prusa"].append(dt)
            for form, ext, extra in forms:
                if aging:
                    age(out, aging)
                dt, ru = timed([dmdsl, "slice", m, "-q", "-o", os.path.join(out, f"{name}-{r}-{form}{ext}")] + extra)
                t[m][form].append(dt)
                sys_t[m][form].append(ru.ru_stime)
    ratios = {f: [] for f, _, _ in forms}
    for m in models:
        med = {k: statistics.median(v) for k, v in t[m].items()}
        row = {"model": os.path.basename(m), "prusa_s": round(med["prusa"], 3)}
        for f, _, _ in forms:
            row[f"{f}_s"] = round(med[f], 3)
            row[f"{f}_sys_s"] = round(statistics.median(sys_t[m][f]), 3)
            ratios[f].append(med["prusa"] / med[f])
            row[f"prusa/{f}"] = round(med["prusa"] / med[f], 1)
        print(json.dumps(row))
    print(json.dumps({f"geomean prusa/{f}": round(gmean(v), 1) for f, v in ratios.items()}))
    subprocess.run(["rm", "-rf", out], check=True)


if __name__ == "__main__":
    main()
