#!/usr/bin/env python3
"""`dmdsl run --cure` on the default jobs of a set of models: the figures of docs/CURE.md.

Usage: cure_figures.py DMDSL_BIN OUTDIR MODEL.stl [MODEL.stl ...] [-- SLICE ARGS]

Each model is sliced with `dmdsl slice MODEL --predict` (plus the slice arguments after
`--`), then `dmdsl run JOB --cure --json` replays it. Printed per model: the run's mean,
95th percentile and largest absolute per-layer edge offset (weighted by the drawn
perimeter, every layer), its signed mean, and the largest per-layer difference from the
slicer's own prediction (`layers[].cure.offset_px`); then the same over all models.
Bundles are deleted as they are done.
"""
import json, os, shutil, subprocess, sys


def main():
    args = sys.argv[1:]
    extra = []
    if "--" in args:
        k = args.index("--")
        args, extra = args[:k], args[k + 1:]
    dmdsl, outdir, models = args[0], args[1], args[2:]
    os.makedirs(outdir, exist_ok=True)
    print("| model | layers | mean px | p95 px | max px | signed mean px | largest difference from the slicer px |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    every = []
    for m in models:
        name = os.path.splitext(os.path.basename(m))[0]
        job = os.path.join(outdir, f"{name}.dmdjob")
        subprocess.run([dmdsl, "slice", m, "-q", "--predict", "-o", job] + extra, check=True)
        out = subprocess.run([dmdsl, "run", job, "--cure", "--json"], check=True, capture_output=True)
        c = json.loads(out.stdout)["cure"]
        layers = [(l["perimeter_mm"], l["offset_px"]) for l in c["per_layer"] if l["perimeter_mm"] > 0]
        every += layers
        diff = c.get("slicer") or {}
        e = c["edge_offset_px"]
        print(f"| {name} | {len(layers)} | {e['mean']:.3f} | {e['p95']:.3f} | {e['max']:.3f} "
              f"| {c['signed_mean_px']:+.3f} | {diff.get('max_diff_px', float('nan')):.3f} |")
        shutil.rmtree(job)
    total = sum(w for w, _ in every)
    mean = sum(w * abs(o) for w, o in every) / total
    signed = sum(w * o for w, o in every) / total
    cum, p95 = 0.0, 0.0
    for o, w in sorted((abs(o), w) for w, o in every):
        cum += w
        if cum >= 0.95 * total:
            p95 = o
            break
    print(f"| all | {len(every)} | {mean:.3f} | {p95:.3f} | {max(abs(o) for _, o in every):.3f} | {signed:+.3f} | |")


if __name__ == "__main__":
    main()
