#!/usr/bin/env python3
"""Compare dmdsl masks with PrusaSlicer 2.5's SLA export.

Usage: compare.py DMDSL_BIN OUTDIR MODEL.stl [MODEL.stl ...]

For each model: exports an .sl1 with prusa_sla.ini (next to this script), slices with
`dmdsl slice --binary` and with anti-aliased masks, both with `--compensation off
--cure-correction off` (the geometry is compared, not the light compensation, whose edge
pixel's gray is not proportional to its coverage, nor the cure correction, which moves
edges by what cures), and counts pixels whose lit state (value >= 128, i.e. at
least half the pixel inside the section) differs from PrusaSlicer's, over all layers, as a
fraction of PrusaSlicer's lit pixels. Needs prusa-slicer (apt) and Pillow.
"""
import io, json, os, subprocess, sys, zipfile
from PIL import Image, ImageChops

HERE = os.path.dirname(os.path.abspath(__file__))


def lit(image):
    """The image's lit state: 255 where the value is >= 128, else 0."""
    return image.convert("L").point(lambda v: 255 if v >= 128 else 0)


def count_lit(image):
    return image.histogram()[255]


def prusa_layers(sl1):
    z = zipfile.ZipFile(sl1)
    names = sorted(n for n in z.namelist() if n.endswith(".png") and not n.startswith("thumbnail"))
    for n in names:
        yield lit(Image.open(io.BytesIO(z.read(n))))


def dmdsl_layers(bundle):
    job = json.load(open(os.path.join(bundle, "job.json")))
    for layer in job["layers"]:
        yield lit(Image.open(os.path.join(bundle, layer["masks"][0]["file"])))


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
        lit_px = sum(count_lit(r) for r in ref)
        res = {"model": name, "prusa_layers": len(ref), "prusa_lit_px": lit_px}
        for mode, extra in (("binary", ["--binary"]), ("aa", [])):
            b = os.path.join(out, f"{name}-{mode}.dmdjob")
            subprocess.run([dmdsl, "slice", model, "-q", "--compensation", "off",
                            "--cure-correction", "off", "-o", b] + extra,
                           check=True)
            ours = list(dmdsl_layers(b))
            diff = 0
            for r, o in zip(ref, ours):
                diff += count_lit(ImageChops.difference(r, o))
            for extra_layers in (ref[len(ours):], ours[len(ref):]):
                diff += sum(count_lit(x) for x in extra_layers)
            res[f"{mode}_layers"] = len(ours)
            res[f"{mode}_diff_px"] = diff
            res[f"{mode}_diff_pct"] = round(100.0 * diff / max(lit_px, 1), 4)
        rows.append(res)
        print(json.dumps(res), flush=True)


if __name__ == "__main__":
    main()
