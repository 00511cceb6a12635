#!/usr/bin/env python3
"""Supports side by side: `dmdsl slice --supports` against PrusaSlicer's SLA supports.

Usage: supports.py DMDSL_BIN OUTDIR RUNS MODEL.stl [MODEL.stl ...]

For each model both tools write an .sl1 on the same 1024 x 768, 65 x 48.75 mm, 0.05 mm
printer (prusa_sla.ini; PrusaSlicer with --supports-enable --pad-enable and its default
support settings, dmdsl with its profile's [supports] defaults), with and without supports.
Runs are interleaved. Reports per model: the median wall time of each tool with supports
and the ratio; layers; resin (ml, as each job states it) with and without supports, so the
difference is the supports' and the pad's; and the pillars: the lit regions of the layer
2 mm below the part's lowest point (what stands on the pad there), counted the same way in
both tools' masks. PrusaSlicer's command line does not report its support points, so the
pillar count stands in for them. Needs prusa-slicer (apt) and Pillow.
"""
import configparser, io, json, os, statistics, subprocess, sys, time, zipfile

from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))


def timed(cmd):
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t


def sl1_facts(path):
    """Layers, resin (ml) and the layer PNG names of an .sl1."""
    z = zipfile.ZipFile(path)
    ini = "[c]\n" + z.read("config.ini").decode()
    c = configparser.ConfigParser()
    c.read_string(ini)
    pngs = sorted(n for n in z.namelist() if n.endswith(".png") and "thumbnail" not in n)
    return z, float(c["c"]["usedMaterial"]), pngs


def regions(z, name):
    """4-connected lit regions (value >= 128) of one layer PNG."""
    im = Image.open(io.BytesIO(z.read(name))).convert("L")
    w, h = im.size
    px = im.load()
    seen, n = set(), 0
    for y in range(h):
        for x in range(w):
            if px[x, y] >= 128 and (x, y) not in seen:
                n += 1
                stack = [(x, y)]
                seen.add((x, y))
                while stack:
                    a, b = stack.pop()
                    for q in ((a + 1, b), (a - 1, b), (a, b + 1), (a, b - 1)):
                        if 0 <= q[0] < w and 0 <= q[1] < h and q not in seen and px[q] >= 128:
                            seen.add(q)
                            stack.append(q)
    return n


def main():
    dmdsl, out, runs = sys.argv[1], sys.argv[2], int(sys.argv[3])
    models = sys.argv[4:]
    os.makedirs(out, exist_ok=True)
    ini = os.path.join(HERE, "prusa_sla.ini")
    t = {m: {"prusa": [], "dmdsl": []} for m in models}
    for r in range(runs):
        for m in models:
            n = os.path.splitext(os.path.basename(m))[0]
            t[m]["prusa"].append(timed(["prusa-slicer", "--load", ini, "--supports-enable",
                                        "--pad-enable", "--export-sla", "--output",
                                        os.path.join(out, f"{n}-{r}-prusa.sl1"), m]))
            t[m]["dmdsl"].append(timed([dmdsl, "slice", m, "--supports", "-o",
                                        os.path.join(out, f"{n}-{r}-dmdsl.sl1")]))
    for m in models:
        n = os.path.splitext(os.path.basename(m))[0]
        subprocess.run(["prusa-slicer", "--load", ini, "--export-sla", "--output",
                        os.path.join(out, f"{n}-bare-prusa.sl1"), m], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        subprocess.run([dmdsl, "slice", m, "-o", os.path.join(out, f"{n}-bare-dmdsl.sl1")],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        row = {"model": os.path.basename(m)}
        for tool in ["prusa", "dmdsl"]:
            z, ml, pngs = sl1_facts(os.path.join(out, f"{n}-0-{tool}.sl1"))
            _, bare_ml, bare = sl1_facts(os.path.join(out, f"{n}-bare-{tool}.sl1"))
            lift = len(pngs) - len(bare)
            below = max(lift - 40, 0)  # 2 mm (40 layers of 0.05 mm) below the part
            row[tool] = {"s": round(statistics.median(t[m][tool]), 3), "layers": len(pngs),
                         "resin_ml": ml, "supports_ml": round(ml - bare_ml, 3),
                         "lift_layers": lift, "pillars_2mm_below": regions(z, pngs[below])}
        row["speedup"] = round(row["prusa"]["s"] / row["dmdsl"]["s"], 2)
        print(json.dumps(row))


if __name__ == "__main__":
    main()
