#!/usr/bin/env python3
"""Zone compensation's cost over `--compensation off`, by `perf stat` task-clock.

Usage: overhead_taskclock.py ROUNDS BIN[,BIN...] MODEL.stl [MODEL.stl ...]

Like compare_overhead.py, but the CPU time of each run is perf's task-clock (the time the
process's threads were scheduled, measured at every context switch) instead of
getrusage's user + sys, which the kernel may account in whole scheduler ticks (4 ms on
this machine: too coarse for 20 ms jobs). Interleaved rounds of `dmdsl slice MODEL -q
-o /dev/shm/overhead_tc/N.dmdjob [--compensation off]`, each run to a fresh path (removed
after the run: removing a bundle is not timed). Prints per model and binary the zone/off
ratio of the minimum, the lower quartile and the median of the task-clock, and of the
median wall time.
"""
import os, shutil, statistics, subprocess, sys, time


def main():
    rounds, bins, models = int(sys.argv[1]), sys.argv[2].split(","), sys.argv[3:]
    base = "/dev/shm/overhead_tc"
    shutil.rmtree(base, ignore_errors=True)
    os.makedirs(base)
    res = {}
    k = 0
    for _ in range(rounds):
        for m in models:
            for b in bins:
                for mode in ["off", "zone"]:
                    k += 1
                    out = f"{base}/{k}.dmdjob"
                    csv = f"{base}/stat.csv"
                    cmd = ["perf", "stat", "-x,", "-o", csv, "-e", "task-clock", "--",
                           b, "slice", m, "-q", "-o", out]
                    if mode == "off":
                        cmd += ["--compensation", "off"]
                    t = time.perf_counter()
                    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
                    wall = time.perf_counter() - t
                    ms = None
                    for line in open(csv):
                        f = line.split(",")
                        if len(f) > 2 and f[2].startswith("task-clock"):
                            ms = float(f[0])
                    res.setdefault((m, b, mode), []).append((ms / 1e3, wall))
                    shutil.rmtree(out, ignore_errors=True)
    shutil.rmtree(base, ignore_errors=True)
    med = statistics.median
    q1 = lambda v: statistics.quantiles(v, n=4)[0]
    pct = lambda z, o: f"{100 * (z / o - 1):+6.1f} %"
    for m in models:
        for b in bins:
            oc, ow = zip(*res[(m, b, "off")])
            zc, zw = zip(*res[(m, b, "zone")])
            print(
                f"{os.path.basename(m):14} {b}: task-clock off {min(oc)*1e3:.2f}/{med(oc)*1e3:.2f} ms"
                f" zone {min(zc)*1e3:.2f}/{med(zc)*1e3:.2f} ms  zone/off min {pct(min(zc), min(oc))}"
                f" q1 {pct(q1(zc), q1(oc))} median {pct(med(zc), med(oc))}"
                f"  wall median {pct(med(zw), med(ow))}"
            )


if __name__ == "__main__":
    main()
