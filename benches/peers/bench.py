#!/usr/bin/env python3
"""Whole-process wall time and peak memory of `dmdsl slice` vs PrusaSlicer's SLA export.

Usage: bench.py [--replace] DMDSL_BIN OUTDIR RUNS MODEL.stl [MODEL.stl ...]

Runs are interleaved (for each run: each model: PrusaSlicer, then dmdsl) so machine noise
hits both tools alike. Every run writes a new output path and nothing is deleted until the
end: a run measures slicing a part into a fresh path, as a user does. (On this machine's
journal-less ext4, creating files within ~30 s of deleting many makes the kernel skip every
recently deleted inode: replacing a bundle right after deleting another costs dmdsl up to
0.5 s of kernel time, while PrusaSlicer writes one file. The `--replace` flag measures that
case: each run overwrites the previous run's output.) Reports per model the median wall time and peak RSS of each tool,
the speed ratio, and the geometric mean of the ratios. Needs prusa-slicer (apt).
"""
import json, math, os, statistics, subprocess, sys
from timing import timed

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    replace = "--replace" in sys.argv
    args = [a for a in sys.argv[1:] if a != "--replace"]
    dmdsl, out, runs = args[0], args[1], int(args[2])
    models = args[3:]
    subprocess.run(["rm", "-rf", out], check=True)
    os.makedirs(out, exist_ok=True)
    res = {m: {"prusa": [], "dmdsl": [], "prusa_kb": 0, "dmdsl_kb": 0} for m in models}
    for r in range(runs):
        for m in models:
            name = os.path.splitext(os.path.basename(m))[0]
            tag = "" if replace else f"-{r}"
            dt, ru = timed(["prusa-slicer", "--load", os.path.join(HERE, "prusa_sla.ini"), "--export-sla",
                            "--output", os.path.join(out, f"{name}{tag}.sl1"), m])
            res[m]["prusa"].append(dt)
            res[m]["prusa_kb"] = max(res[m]["prusa_kb"], ru.ru_maxrss)
            dt, ru = timed([dmdsl, "slice", m, "-q", "-o", os.path.join(out, f"{name}{tag}.dmdjob")])
            res[m]["dmdsl"].append(dt)
            res[m]["dmdsl_kb"] = max(res[m]["dmdsl_kb"], ru.ru_maxrss)
    ratios = []
    for m in models:
        r = res[m]
        p, d = statistics.median(r["prusa"]), statistics.median(r["dmdsl"])
        ratios.append(p / d)
        print(json.dumps({"model": os.path.basename(m), "prusa_s": round(p, 3), "dmdsl_s": round(d, 3),
                          "speedup": round(p / d, 2), "prusa_peak_mib": round(r["prusa_kb"] / 1024, 1),
                          "dmdsl_peak_mib": round(r["dmdsl_kb"] / 1024, 1)}))
    subprocess.run(["rm", "-rf", out], check=True)
    print(json.dumps({"geomean_speedup": round(math.exp(sum(map(math.log, ratios)) / len(ratios)), 2)}))


if __name__ == "__main__":
    main()
