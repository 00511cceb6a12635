#!/usr/bin/env python3
"""Whole-job cost of `dmdsl slice` settings, as ratios of the first setting.

Usage: slice_settings.py ROUNDS DMDSL_BIN MODEL.stl SETTING [SETTING ...]
  SETTING = extra `dmdsl slice` arguments in one string ("" for the defaults), e.g.
  slice_settings.py 11 target/release/dmdsl bunny00.stl "--compensation off" \\
      "--compensation off --distortion fixtures/lens_table.csv" "--profile tiled-2x1"

Interleaved rounds (each round runs every setting once, in order) of
`dmdsl slice MODEL -q -o /dev/shm/slice_settings.dmdjob SETTING`; the bundle is removed
before each run and the removal is not timed. Process CPU (user + sys, from wait4) and wall
time. Prints per setting the medians and their ratios to the first setting's medians, and
the median of the rounds' own wall ratios (each round runs all settings back to back, so
that ratio is less sensitive to the load of a shared machine drifting over the run).
"""
import os, shlex, shutil, statistics, subprocess, sys, time


def run(cmd, out):
    shutil.rmtree(out, ignore_errors=True)
    t = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    if status != 0:
        raise SystemExit(f"failed: {shlex.join(cmd)}")
    return ru.ru_utime + ru.ru_stime, wall


def main():
    if len(sys.argv) < 5:
        raise SystemExit(__doc__)
    rounds, dmdsl, model, settings = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4:]
    out = "/dev/shm/slice_settings.dmdjob"
    res = [[] for _ in settings]
    for _ in range(rounds):
        for i, s in enumerate(settings):
            cmd = [dmdsl, "slice", model, "-q", "-o", out] + shlex.split(s)
            res[i].append(run(cmd, out))
    shutil.rmtree(out, ignore_errors=True)
    med = statistics.median
    c0 = med(c for c, _ in res[0])
    w0 = med(w for _, w in res[0])
    print(f"{os.path.basename(model)}, {rounds} rounds; ratios to the first setting")
    for i, s in enumerate(settings):
        c = med(x for x, _ in res[i])
        w = med(y for _, y in res[i])
        per_round = med(res[i][r][1] / res[0][r][1] for r in range(rounds))
        print(f"  {s or '(defaults)':60s} CPU {c:.3f} s ({c / c0:.2f}x)  wall {w:.3f} s "
              f"({w / w0:.2f}x; per round {per_round:.2f}x)")


if __name__ == "__main__":
    main()
