#!/usr/bin/env python3
"""CPU and wall cost of the cure model in whole `dmdsl slice` runs.

Usage: cure_overhead.py DMDSL_BIN OUTDIR RUNS MODEL.stl [MODEL.stl ...]

`dmdsl slice MODEL` with `--cure-correction off` (the masks of the exact sections: the
code path of slice before the cure model), the default (`xy` correction) and
`--predict` (correction and prediction), interleaved round after round; medians of the
process CPU (user + sys, from wait4) and wall time, as ratios of `off`. Put OUTDIR on a
tmpfs (e.g. /dev/shm/cure); bundles are deleted after each round.
"""
import os, shutil, statistics, subprocess, sys, time


def run(cmd):
    t = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, ru = os.wait4(p.pid, 0)
    if status != 0:
        raise SystemExit(f"failed: {cmd}")
    return ru.ru_utime + ru.ru_stime, time.perf_counter() - t


def main():
    dmdsl, outdir, runs, models = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
    modes = {"off": ["--cure-correction", "off"], "xy": [], "predict": ["--predict"]}
    res = {}
    for r in range(runs):
        os.makedirs(outdir, exist_ok=True)
        for m in models:
            name = os.path.splitext(os.path.basename(m))[0]
            for mode, extra in modes.items():
                out = os.path.join(outdir, f"{name}-{mode}.dmdjob")
                res.setdefault((name, mode), []).append(run([dmdsl, "slice", m, "-q", "-o", out] + extra))
        shutil.rmtree(outdir)
    print("| model | off: CPU | off: wall | xy (default): CPU | xy: wall | --predict: CPU | --predict: wall |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for m in models:
        name = os.path.splitext(os.path.basename(m))[0]
        med = {k: [statistics.median(x[i] for x in res[(name, k)]) for i in (0, 1)] for k in modes}
        o = med["off"]
        print(f"| {name} | {o[0]:.3f} s | {o[1]:.3f} s | {med['xy'][0] / o[0]:.2f}× | {med['xy'][1] / o[1]:.2f}× "
              f"| {med['predict'][0] / o[0]:.2f}× | {med['predict'][1] / o[1]:.2f}× |")


if __name__ == "__main__":
    main()
