#!/usr/bin/env python3
"""Wall and CPU time of dmdsl against mslicer's command-line slicer (`slicer`, a `.goo`).

Usage: mslicer.py MSLICER_BIN DMDSL_BIN OUTDIR RUNS MODEL.stl [MODEL.stl ...]

mslicer is built outside this repository (docs/BENCHMARKS.md, "Against mslicer" says
how and at which commit). For each of RUNS rounds after one warm-up round and each model,
in turn: mslicer on the default profile's display (1024 x 768 px, 65 x 48.75 mm, 0.05 mm
layers, 2 bottom layers at 16 s, 8 s layers; it centres the part itself), then `dmdsl
slice MODEL --binary --compensation off --cure-correction off -q -o x.dmdjob.zip` (binary
masks, one file, like the `.goo`), then the default `dmdsl slice MODEL -q -o
y.dmdjob.zip`. Prints per model the median wall and CPU (user + system) time of each and
their ratios to mslicer's.
"""
import json, os, statistics, subprocess, sys
from timing import timed

DISPLAY = ["--platform-resolution", "1024,768", "--platform-size", "65,48.75,260",
           "--layer-height", "0.05", "--first-layers", "2", "--transition-layers", "0",
           "--exposure-time", "8", "--first-exposure-time", "16"]


def main():
    mslicer, dmdsl, out, runs, models = *sys.argv[1:4], int(sys.argv[4]), sys.argv[5:]
    os.makedirs(out, exist_ok=True)
    tools = {
        "mslicer": lambda m, o: [mslicer, *DISPLAY, "--mesh", m, o + ".goo"],
        "binary": lambda m, o: [dmdsl, "slice", m, "--binary", "--compensation", "off",
                                "--cure-correction", "off", "-q", "-o", o + "-b.dmdjob.zip"],
        "default": lambda m, o: [dmdsl, "slice", m, "-q", "-o", o + "-d.dmdjob.zip"],
    }
    t = {m: {k: [] for k in tools} for m in models}
    for r in range(runs + 1):
        for m in models:
            o = os.path.join(out, os.path.splitext(os.path.basename(m))[0])
            for k, cmd in tools.items():
                wall, ru = timed(cmd(m, o))
                cpu = ru.ru_utime + ru.ru_stime
                if r > 0:
                    t[m][k].append((wall, cpu))
    for m in models:
        med = {k: [statistics.median(x[i] for x in v) for i in (0, 1)] for k, v in t[m].items()}
        row = {"model": os.path.basename(m)}
        for k, (wall, cpu) in med.items():
            row[f"{k}_wall_s"], row[f"{k}_cpu_s"] = round(wall, 3), round(cpu, 3)
            row[f"{k}/mslicer cpu"] = round(cpu / med["mslicer"][1], 2)
        print(json.dumps(row))
    subprocess.run(["rm", "-rf", out], check=True)


if __name__ == "__main__":
    main()
