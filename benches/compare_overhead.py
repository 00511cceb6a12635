#!/usr/bin/env python3
"""Zone compensation's cost over `--compensation off`, for several dmdsl binaries at once.

Usage: compare_overhead.py ROUNDS BIN[,BIN...] MODEL.stl [MODEL.stl ...]

Interleaved rounds (each round runs every model with every binary, off then zone) of
`dmdsl slice MODEL -q -o /dev/shm/compare_overhead.dmdjob [--compensation off]`; process
CPU (user + sys, from wait4) and wall time. Prints, per model and binary, the zone/off
ratio of the minimum and of the median over the rounds: on a busy machine the minimum is
the steadier of the two. Compare a change against main's binary in the same run.
"""
import os, shutil, statistics, subprocess, sys, time


def main():
    rounds, bins, models = int(sys.argv[1]), sys.argv[2].split(","), sys.argv[3:]
    out = "/dev/shm/compare_overhead.dmdjob"
    res = {}
    for _ in range(rounds):
        for m in models:
            for b in bins:
                for mode in ["off", "zone"]:
                    shutil.rmtree(out, ignore_errors=True)
                    cmd = [b, "slice", m, "-q", "-o", out]
                    if mode == "off":
                        cmd += ["--compensation", "off"]
                    t = time.perf_counter()
                    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                    _, status, ru = os.wait4(p.pid, 0)
                    if status != 0:
                        raise SystemExit(f"failed: {cmd}")
                    res.setdefault((m, b, mode), []).append(
                        (ru.ru_utime + ru.ru_stime, time.perf_counter() - t)
                    )
    shutil.rmtree(out, ignore_errors=True)
    med = statistics.median
    pct = lambda z, o: f"{100 * (z / o - 1):+6.1f} %"
    for m in models:
        for b in bins:
            oc, ow = zip(*res[(m, b, "off")])
            zc, zw = zip(*res[(m, b, "zone")])
            name = os.path.splitext(os.path.basename(m))[0]
            print(
                f"{name:14s} {b}: CPU off {min(oc):.3f}/{med(oc):.3f} s zone {min(zc):.3f}/{med(zc):.3f} s"
                f"  zone/off min {pct(min(zc), min(oc))} median {pct(med(zc), med(oc))}"
                f"  wall min {pct(min(zw), min(ow))} median {pct(med(zw), med(ow))}"
            )


if __name__ == "__main__":
    main()
