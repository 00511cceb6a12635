"""What the peer benchmarks share: one timed run of a command."""
import os, subprocess, time


def timed(cmd):
    """Runs `cmd` (output discarded) and returns its wall time, s, and its resource use
    (`ru_utime`, `ru_stime`, `ru_maxrss` in KiB on Linux); a failing run stops the script."""
    t = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, ru = os.wait4(p.pid, 0)
    dt = time.perf_counter() - t
    if status != 0:
        raise SystemExit(f"failed: {cmd}")
    return dt, ru
