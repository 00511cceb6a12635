#!/usr/bin/env python3
"""Compares the job.json (and the masks/ and optics/ files) that two dmdsl binaries write.

Usage: compare_jobs.py [--pixels] REF_BIN NEW_BIN OUTDIR CASE...
  CASE = MODEL.stl[,ARG,ARG...]   (extra `dmdsl slice` arguments, comma-separated; a
                                   comma inside an argument written as ';', e.g.
                                   'bunny00.stl,--rotate=60;0;20')

For each case: every value of job.json that differs (path, ref, new; for numbers the
relative difference), and whether the masks/ and optics/ files are byte-identical.
With --pixels (for a change of the PNG encoding: other bytes, the same images) PNG files
are compared decoded (Pillow), the SHA-256 fields of job.json are left out, and the PNG
bytes of both are totalled. Exit status 1 if anything differs or a binary refuses a case.
"""
import hashlib, json, os, shutil, subprocess, sys


def files(d, pixels):
    """Each masks/ and optics/ file's SHA-256: of its bytes, or with `pixels` of a PNG's
    decoded mode, size and pixels (and its size in bytes)."""
    out = {}
    for sub in ("masks", "optics"):
        for root, _, names in os.walk(os.path.join(d, sub)):
            for n in names:
                p = os.path.join(root, n)
                data = open(p, "rb").read()
                if pixels and n.endswith(".png"):
                    from PIL import Image

                    im = Image.open(p)
                    data = f"{im.mode} {im.size}".encode() + im.tobytes()
                out[os.path.relpath(p, d)] = (hashlib.sha256(data).hexdigest(), os.path.getsize(p))
    return out


def strip_sha(v):
    if isinstance(v, dict):
        return {k: strip_sha(x) for k, x in v.items() if not k.endswith("sha256")}
    if isinstance(v, list):
        return [strip_sha(x) for x in v]
    return v


def diff(a, b, path, out):
    if type(a) != type(b):
        out.append((path, a, b))
    elif isinstance(a, dict):
        for k in sorted(set(a) | set(b)):
            diff(a.get(k), b.get(k), f"{path}.{k}", out)
    elif isinstance(a, list):
        if len(a) != len(b):
            out.append((path + ".len", len(a), len(b)))
        for i, (x, y) in enumerate(zip(a, b)):
            diff(x, y, f"{path}[{i}]", out)
    elif a != b:
        out.append((path, a, b))


def main():
    argv = sys.argv[1:]
    pixels = argv[:1] == ["--pixels"]
    if pixels:
        argv = argv[1:]
    ref, new, outdir, cases = argv[0], argv[1], argv[2], argv[3:]
    os.makedirs(outdir, exist_ok=True)
    bad = 0
    for case in cases:
        model, *args = (a.replace(";", ",") for a in case.split(","))
        res = []
        for tag, b in (("ref", ref), ("new", new)):
            d = os.path.join(outdir, tag + ".dmdjob")
            shutil.rmtree(d, ignore_errors=True)
            p = subprocess.run([b, "slice", model, "-q", "-o", d] + args, capture_output=True)
            j = json.load(open(os.path.join(d, "job.json"))) if p.returncode in (0, 1) else None
            if j is not None and pixels:
                j = strip_sha(j)
            res.append((p.returncode, p.stderr, j, files(d, pixels) if j else {}))
        (ra, ea, ja, fa), (rb, eb, jb, fb) = res
        d = []
        if ja is not None and jb is not None:
            diff(ja, jb, "", d)
        if pixels:
            same_files = {k: v[0] for k, v in fa.items()} == {k: v[0] for k, v in fb.items()}
        else:
            same_files = fa == fb
        name = os.path.basename(model) + " " + " ".join(args)
        if ra not in (0, 1) or rb not in (0, 1):
            # A case both binaries refuse compares nothing: never "same".
            bad += 1
            first = (ea or eb).decode(errors="replace").splitlines()[:1]
            print(f"FAIL {name}: rc {ra}/{rb}: {first[0] if first else ''}")
            continue
        if pixels:
            sa, sb = (sum(v[1] for k, v in f.items() if k.endswith(".png")) for f in (fa, fb))
            name += f" (PNG bytes {sa} -> {sb}, {100 * (sb / max(sa, 1) - 1):+.1f} %)"
        if ra != rb or ea != eb or d or not same_files:
            bad += 1
            print(f"DIFF {name}: rc {ra}/{rb} stderr {'same' if ea == eb else 'differs'} files {'same' if same_files else 'DIFFER'}")
            for p, x, y in d:
                rel = ""
                if isinstance(x, float) and isinstance(y, float) and x != 0:
                    rel = f" (relative {abs(y - x) / abs(x):.1e})"
                print(f"    {p}: {x} -> {y}{rel}")
        else:
            print(f"same {name}")
    print(f"{len(cases)} cases, {bad} differ")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
