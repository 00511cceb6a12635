#!/usr/bin/env python3
"""Compares what two dmdsl binaries write, pixel for pixel: for a change of the PNG
encoding (different bytes, same images).

Usage: compare_pixels.py REF_BIN NEW_BIN OUTDIR CASE...
  CASE = MODEL.stl[,ARG,ARG...]   (extra `dmdsl slice` arguments, comma-separated)

For each case: every PNG under masks/ and optics/ decoded (Pillow) and compared, and
job.json compared with the SHA-256 fields left out. Prints the total PNG bytes of both.
Exit status 1 if anything differs.
"""
import json, os, shutil, subprocess, sys

from PIL import Image


def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if not k.endswith("sha256")}
    if isinstance(v, list):
        return [strip(x) for x in v]
    return v


def pngs(d):
    out = {}
    for sub in ("masks", "optics"):
        for root, _, names in os.walk(os.path.join(d, sub)):
            for n in names:
                if n.endswith(".png"):
                    p = os.path.join(root, n)
                    out[os.path.relpath(p, d)] = p
    return out


def main():
    ref, new, outdir, cases = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
    bad = 0
    for case in cases:
        model, *extra = case.split(",")
        dirs = []
        for tag, b in (("ref", ref), ("new", new)):
            d = os.path.join(outdir, tag + ".dmdjob")
            shutil.rmtree(d, ignore_errors=True)
            subprocess.run([b, "slice", model, "-q", "-o", d] + extra, check=True)
            dirs.append(d)
        a, b = pngs(dirs[0]), pngs(dirs[1])
        diffs = []
        if sorted(a) != sorted(b):
            diffs.append("file lists differ")
        size = [0, 0]
        for k in sorted(set(a) & set(b)):
            size[0] += os.path.getsize(a[k])
            size[1] += os.path.getsize(b[k])
            ia, ib = Image.open(a[k]), Image.open(b[k])
            if ia.mode != ib.mode or ia.size != ib.size or ia.tobytes() != ib.tobytes():
                diffs.append(k)
        ja = strip(json.load(open(os.path.join(dirs[0], "job.json"))))
        jb = strip(json.load(open(os.path.join(dirs[1], "job.json"))))
        if ja != jb:
            diffs.append("job.json (without sha256 fields)")
        name = os.path.basename(model) + " " + " ".join(extra)
        print(f"{'same' if not diffs else 'DIFF'} {name}: PNG bytes {size[0]} -> {size[1]}"
              f" ({100 * (size[1] / max(size[0], 1) - 1):+.1f} %) {diffs[:5]}")
        bad += bool(diffs)
        for d in dirs:
            shutil.rmtree(d, ignore_errors=True)
    print(f"{len(cases)} cases, {bad} differ")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
