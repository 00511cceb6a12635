#!/usr/bin/env python3
"""CPU and wall cost of light compensation and of the planner's per-layer analysis.

Usage: overhead.py DMDSL_BIN OUTDIR RUNS MODEL.stl [MODEL.stl ...]

* Compensation: `dmdsl slice --cure-correction off` with `--compensation off`, the default
  (zone) and `pixel`, interleaved (the path where the rasterizer applies the compensation); medians of process CPU (user + sys, from wait4) and wall time, as ratios
  of `off`.
* Analysis: the `analysis_cpu_s` of `--json` (time spent in the per-layer analysis,
  summed over the workers) against the rest of the process CPU, default settings.

Put OUTDIR on a tmpfs (e.g. /dev/shm/ov) to leave out the filesystem: on this machine's
journal-less ext4, creating files shortly after many were deleted costs a varying amount of
kernel time. Bundles are deleted after each round.
"""
import json, os, shutil, statistics, subprocess, sys, time


def run(cmd):
    t = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    out = p.stdout.read()
    _, status, ru = os.wait4(p.pid, 0)
    if status != 0:
        raise SystemExit(f"failed: {cmd}")
    return ru.ru_utime + ru.ru_stime, time.perf_counter() - t, out


def main():
    dmdsl, outdir, runs, models = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
    modes = {"off": ["--compensation", "off"], "zone": [], "pixel": ["--compensation", "pixel"]}
    comp, share = {}, {}
    for r in range(runs):
        os.makedirs(outdir, exist_ok=True)
        for m in models:
            name = os.path.splitext(os.path.basename(m))[0]
            for mode, extra in modes.items():
                out = os.path.join(outdir, f"{name}-{mode}-{r}.dmdjob")
                cpu, wall, js = run([dmdsl, "slice", m, "-q", "--json", "--cure-correction", "off", "-o", out] + extra)
                comp.setdefault((name, mode), []).append((cpu, wall))
                if mode == "zone":
                    a = json.loads(js)["timings"]["analysis_cpu_s"]
                    share.setdefault(name, []).append(a / (cpu - a))
        shutil.rmtree(outdir)
    med = statistics.median
    print("compensation (ratios of --compensation off, medians):")
    for m in models:
        name = os.path.splitext(os.path.basename(m))[0]
        c0 = med(c for c, _ in comp[(name, "off")])
        w0 = med(w for _, w in comp[(name, "off")])
        for mode in modes:
            c = med(x for x, _ in comp[(name, mode)])
            w = med(y for _, y in comp[(name, mode)])
            print(f"  {name:14s} {mode:5s} CPU {c:.3f} s ({c / c0:.3f}x)  wall {w:.3f} s ({w / w0:.3f}x)")
    print("analysis CPU / rest of the process CPU (default settings):")
    for m in models:
        name = os.path.splitext(os.path.basename(m))[0]
        v = share[name]
        print(f"  {name:14s} median {100 * med(v):.1f} % (min {100 * min(v):.1f} %, max {100 * max(v):.1f} %)")


if __name__ == "__main__":
    main()
