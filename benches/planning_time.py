#!/usr/bin/env python3
"""What the per-layer analysis adds to slicing time, process against process.

Usage: planning_time.py ROUNDS BIN BIN_NO_ANALYSIS MODEL.stl [MODEL.stl ...]

BIN_NO_ANALYSIS is the same source built with the benchmark-only Cargo feature that skips
the per-layer analysis (scans and max fill distance; the comparison with the layer below
that prisms' masks use stays):

    CARGO_TARGET_DIR=target-noan cargo build --release --features bench-no-analysis

Interleaved rounds of `dmdsl slice MODEL -q -o /dev/shm/planning_time.dmdjob` with both
binaries (default profile); process CPU (user + sys, from wait4) and wall time. Prints per
model the medians and the ratios BIN / BIN_NO_ANALYSIS: the wall ratio is what a user
waits for, the CPU ratio what the analysis costs on a busy machine. Then, per model, the
rounds' own ratios (each round runs both binaries back to back): their median and
quartiles, less sensitive to the load of a shared machine drifting over the run.
"""
import os, shutil, statistics, subprocess, sys, time


def run(binary, model, out):
    shutil.rmtree(out, ignore_errors=True)
    t = time.perf_counter()
    p = subprocess.Popen([binary, "slice", model, "-q", "--cure-correction", "off", "-o", out],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    if status != 0:
        raise SystemExit(f"failed: {binary} slice {model}")
    return ru.ru_utime + ru.ru_stime, wall


def main():
    rounds, full, bare, models = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4:]
    out = "/dev/shm/planning_time.dmdjob"
    res = {}
    for _ in range(rounds):
        for m in models:
            for b in (bare, full):
                res.setdefault((m, b), []).append(run(b, m, out))
    shutil.rmtree(out, ignore_errors=True)
    med = statistics.median
    print("model            wall: without → with analysis      CPU: without → with analysis")
    for m in models:
        c0, w0 = med(c for c, _ in res[(m, bare)]), med(w for _, w in res[(m, bare)])
        c1, w1 = med(c for c, _ in res[(m, full)]), med(w for _, w in res[(m, full)])
        name = os.path.splitext(os.path.basename(m))[0]
        print(f"{name:16s} {w0:.3f} → {w1:.3f} s ({100 * (w1 / w0 - 1):+.1f} %)"
              f"      {c0:.3f} → {c1:.3f} s ({100 * (c1 / c0 - 1):+.1f} %)")
    print("model            per-round ratios, median [quartiles]: wall / CPU")
    for m in models:
        name = os.path.splitext(os.path.basename(m))[0]
        cols = []
        for k in (1, 0):
            r = sorted(f[k] / b[k] - 1 for b, f in zip(res[(m, bare)], res[(m, full)]))
            q = statistics.quantiles(r, n=4) if len(r) > 1 else [r[0]] * 3
            cols.append(f"{100 * q[1]:+.1f} % [{100 * q[0]:+.1f}, {100 * q[2]:+.1f}]")
        print(f"{name:16s} {cols[0]}   /   {cols[1]}")


if __name__ == "__main__":
    main()
