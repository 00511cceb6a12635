#!/usr/bin/env python3
"""Compare dmdsl masks with PrusaSlicer 2.5's SLA export (BRIEF §7).

Usage: compare.py DMDSL_BIN OUTDIR MODEL.stl [MODEL.stl ...]

For each model: exports an .sl1 with prusa_sla.ini (next to this script), slices with
`dmdsl slice --binary` and with the default anti-aliased masks, and counts pixels whose
lit state (value >= 128) differs from PrusaSlicer's, over all layers, as a fraction of
PrusaSlicer's lit pixels. Needs prusa-slicer (apt) and Pillow + numpy (pip).
"""
import io, json, os, subprocess, sys, zipfile
import numpy as np
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))


def prusa_layers(sl1):
    z = zipfile.ZipFile(sl1)
    names = sorted(n for n in z.namelist() if n.endswith(".png") and not n.startswith("thumbnail"))
    for n in names:
        yield np.array(Image.open(io.BytesIO(z.read(n))).convert("L"))


def dmdsl_layers(bundle):
    job = json.load(open(os.path.join(bundle, "job.json")))
    for layer in job["layers"]:
        yield np.array(Image.open(os.path.join(bundle, layer["masks"][0]["file"])).convert("L"))


def main():
    dmdsl, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    rows = []
    for model in sys.argv[3:]:
        name = os.path.splitext(os.path.basename(model))[0]
        sl1 = os.path.join(out, name + ".sl1")
        subprocess.run(["prusa-slicer", "--load", os.path.join(HERE, "prusa_sla.ini"), "--export-sla",
                        "--output", sl1, model], check=True, capture_output=True)
        ref = list(prusa_layers(sl1))
        lit = sum(int((r >= 128).sum()) for r in ref)
        res = {"model": name, "prusa_layers": len(ref), "prusa_lit_px": lit}
        for mode, extra in (("binary", ["--binary"]), ("aa", [])):
            b = os.path.join(out, f"{name}-{mode}.dmdjob")
            subprocess.run([dmdsl, "slice", model, "-q", "-o", b] + extra, check=True)
            ours = list(dmdsl_layers(b))
            diff = 0
            for r, o in zip(ref, ours):
                diff += int(((r >= 128) != (o >= 128)).sum())
            for extra_layers in (ref[len(ours):], ours[len(ref):]):
                diff += sum(int((x >= 128).sum()) for x in extra_layers)
            res[f"{mode}_layers"] = len(ours)
            res[f"{mode}_diff_px"] = diff
            res[f"{mode}_diff_pct"] = round(100.0 * diff / max(lit, 1), 4)
        rows.append(res)
        print(json.dumps(res), flush=True)


if __name__ == "__main__":
    main()
