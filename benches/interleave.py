#!/usr/bin/env python3
"""Whole-job time of several dmdsl builds, interleaved.

Usage: interleave.py ROUNDS MODEL.stl [SLICE_ARG ...] -- BIN [BIN ...]

Runs `BIN slice MODEL -q -o /dev/shm/interleaveK.dmdjob.zip SLICE_ARG...` with every binary
in turn, one warm-up round and ROUNDS counted ones, so a change of load hits all alike.
Prints per binary the median wall and CPU (user + system) time, their ratios to the first
binary's, and the least CPU time. Set RAYON_NUM_THREADS=1 for the steadiest figures.
"""
import os, statistics, sys
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "peers"))
from timing import timed


def main():
    rounds, model = int(sys.argv[1]), sys.argv[2]
    split = sys.argv.index("--")
    args, bins = sys.argv[3:split], sys.argv[split + 1:]
    res = {k: ([], []) for k in range(len(bins))}
    for r in range(rounds + 1):
        for k, b in enumerate(bins):
            out = f"/dev/shm/interleave{k}.dmdjob.zip"
            wall, ru = timed([b, "slice", model, "-q", "-o", out, *args])
            if r > 0:
                res[k][0].append(wall)
                res[k][1].append(ru.ru_utime + ru.ru_stime)
    base = None
    for k, b in enumerate(bins):
        w, c = statistics.median(res[k][0]), statistics.median(res[k][1])
        base = base or (w, c)
        print(f"{b}: wall {w * 1e3:.1f} ms, cpu {c * 1e3:.1f} ms, ratio wall {w / base[0]:.3f}"
              f" cpu {c / base[1]:.3f}, least cpu {min(res[k][1]) * 1e3:.1f} ms")
        os.remove(f"/dev/shm/interleave{k}.dmdjob.zip")


if __name__ == "__main__":
    main()
