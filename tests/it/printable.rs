//! `dmdsl run` finds the regions of the masks that rest on nothing below: a warning for a
//! job without supports (native or imported), a violation for one compiled with supports,
//! and `inspect --preview` rings them and draws the supports. The regions are checked
//! against a flood fill of the decoded mask PNGs written here.

use crate::common::*;
use serde_json::Value;
use std::path::Path;

fn job(b: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap()
}

/// `dmdsl run JOB --json` in `dir`: exit code and report.
fn run(dir: &Path, job: &str) -> (i32, Value) {
    let o = run_in(dir, &["run", job, "--json"]);
    let v = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {} / {}", stdout(&o), stderr(&o)));
    (o.status.code().unwrap(), v)
}

/// Slices bunny00.stl on the default profile in `dir` to `out` with `more` arguments;
/// the `--json` summary.
fn slice_bunny(dir: &Path, out: &str, more: &[&str]) -> Value {
    let f = fixture("bunny00.stl");
    let mut a = vec!["slice", f.to_str().unwrap(), "-o", out, "--json"];
    a.extend(more);
    let o = run_in(dir, &a);
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The field of the job `b`: its lit pixels per layer (gray ≥ 128 after placing its one
/// projector's mask), width and height, and pixel size.
struct Field {
    w: usize,
    h: usize,
    pixel_mm: f64,
    layers: Vec<Vec<bool>>,
}

fn field_of(b: &Path, j: &Value) -> Field {
    let p = &j["machine"]["projector"][0];
    assert_eq!(j["machine"]["projector"].as_array().unwrap().len(), 1);
    let (w, h) = (
        p["width_px"].as_u64().unwrap() as usize,
        p["height_px"].as_u64().unwrap() as usize,
    );
    let (ox, oy) = (
        p["offset_px"][0].as_u64().unwrap() as usize,
        p["offset_px"][1].as_u64().unwrap() as usize,
    );
    let (mx, my) = (p["mirror_x"] == true, p["mirror_y"] == true);
    let (fw, fh) = (ox + w, oy + h);
    let layers = j["layers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| {
            let (mw, mh, px) = read_gray(&b.join(l["masks"][0]["file"].as_str().unwrap()));
            assert_eq!((mw as usize, mh as usize), (w, h));
            let mut lit = vec![false; fw * fh];
            for r in 0..h {
                for c in 0..w {
                    let (fc, fr) = (
                        ox + if mx { w - 1 - c } else { c },
                        oy + if my { h - 1 - r } else { r },
                    );
                    lit[fr * fw + fc] = px[r * w + c] >= 128;
                }
            }
            lit
        })
        .collect();
    Field {
        w: fw,
        h: fh,
        pixel_mm: p["pixel_mm"].as_f64().unwrap(),
        layers,
    }
}

/// The regions of every layer resting on nothing below, by a flood fill of the field's
/// pixels: (layer, x mm, y mm, area mm²).
fn flood_regions(f: &Field) -> Vec<(usize, f64, f64, f64)> {
    let (w, h, p) = (f.w, f.h, f.pixel_mm);
    let mut out = Vec::new();
    for i in 1..f.layers.len() {
        let found = regions_on_nothing(&f.layers[i], &f.layers[i - 1], w, h);
        for (n, c, r) in found {
            out.push((i, c * p, (h as f64 - r) * p, n as f64 * p * p));
        }
    }
    out
}

/// The report's regions as (layer, x, y, area), sorted.
fn reported(r: &Value) -> Vec<(usize, f64, f64, f64)> {
    let mut v: Vec<_> = r["unsupported_regions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| {
            let f = |k: &str| g[k].as_f64().unwrap();
            (
                g["layer"].as_u64().unwrap() as usize,
                f("x_mm"),
                f("y_mm"),
                f("area_mm2"),
            )
        })
        .collect();
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v
}

fn same_regions(got: &[(usize, f64, f64, f64)], mut want: Vec<(usize, f64, f64, f64)>) {
    want.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert_eq!(got.len(), want.len(), "{got:?}\n{want:?}");
    for (g, w) in got.iter().zip(&want) {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-5 * (1.0 + b.abs());
        assert!(
            g.0 == w.0 && close(g.1, w.1) && close(g.2, w.2) && close(g.3, w.3),
            "{g:?} != {w:?}"
        );
    }
}

/// The slicer's islands of the job in `dir`/`b` (its summary `s`): the count its
/// `plan.unsupported-islands` warning gives, and per layer (`layers[].islands`).
fn slicer_islands(s: &Value, j: &Value) -> (u64, Vec<(usize, u64)>) {
    let w = warnings_of(s, "plan.unsupported-islands");
    assert_eq!(w.len(), 1, "{}", s["warnings"]);
    let per_layer = (j["layers"].as_array().unwrap().iter().enumerate())
        .filter(|(_, l)| l["islands"] != 0)
        .map(|(i, l)| (i, l["islands"].as_u64().unwrap()))
        .collect();
    (w[0]["fields"]["islands"].as_u64().unwrap(), per_layer)
}

/// The regions' count per layer.
fn per_layer(g: &[(usize, f64, f64, f64)]) -> Vec<(usize, u64)> {
    let mut out: Vec<(usize, u64)> = Vec::new();
    for &(l, ..) in g {
        match out.last_mut() {
            Some((k, n)) if *k == l => *n += 1,
            _ => out.push((l, 1)),
        }
    }
    out
}

/// The report's warning `run.unsupported-regions`, checked against its regions.
fn warned(r: &Value) -> &Value {
    let w = warnings_of(r, "run.unsupported-regions");
    assert_eq!(w.len(), 1, "{}", r["warnings"]);
    let n = r["unsupported_regions"].as_array().unwrap().len();
    assert_eq!(w[0]["fields"]["regions"], n as u64);
    assert_eq!(w[0]["severity"], "warning");
    let msg = w[0]["message"].as_str().unwrap();
    assert!(msg.contains("largest per layer: layer "), "{msg}");
    w[0]
}

#[test]
fn unsupported_regions_are_found_in_the_masks_and_warned() {
    let dir = tempdir("printable-bunny");
    // Coverage masks (no light compensation, no cure correction) show the pixels the
    // slicer analysed: the same regions, layer by layer.
    let cov = ["--compensation", "off", "--cure-correction", "off"];
    let summary = slice_bunny(
        &dir,
        "c.dmdjob",
        &[&["--layer-height", "0.1"][..], &cov].concat(),
    );
    let b = dir.join("c.dmdjob");
    let j = job(&b);
    let (count, layers) = slicer_islands(&summary, &j);
    let (code, r) = run(&dir, "c.dmdjob");
    assert_eq!(code, 0, "{}", r["violations"]);
    let found = reported(&r);
    same_regions(&found, flood_regions(&field_of(&b, &j)));
    assert_eq!(found.len() as u64, count);
    assert_eq!(per_layer(&found), layers);
    assert_eq!(warned(&r)["fields"]["first_layer"], layers[0].0 as u64);

    // The default profile's masks (zone compensation, the XY cure correction): of the
    // regions a flood fill of the masks finds by gray, those that rest on nothing by what
    // cures (the lone pixels at edges that cure with their neighbours, or not at all,
    // are not), at least the slicer's islands.
    let summary = slice_bunny(&dir, "b.dmdjob", &["--layer-height", "0.1"]);
    let b = dir.join("b.dmdjob");
    let j = job(&b);
    let (count, _) = slicer_islands(&summary, &j);
    let (code, r) = run(&dir, "b.dmdjob");
    assert_eq!(code, 0, "{}", r["violations"]);
    let found = reported(&r);
    let by_gray = flood_regions(&field_of(&b, &j));
    let kept: Vec<_> = by_gray
        .iter()
        .filter(|g| {
            let near = |a: f64, b: f64| (a - b).abs() <= 1e-5 * (1.0 + b.abs());
            found
                .iter()
                .any(|f| f.0 == g.0 && near(f.1, g.1) && near(f.2, g.2))
        })
        .copied()
        .collect();
    same_regions(&found, kept);
    assert!(found.len() < by_gray.len(), "{found:?}");
    assert!(found.len() as u64 >= count, "{} {count}", found.len());
    warned(&r);
    // The human summary says it too.
    let o = run_in(&dir, &["run", "b.dmdjob"]);
    let text = stdout(&o);
    assert!(
        text.contains("warning: ") && text.contains("[run.unsupported-regions]"),
        "{text}"
    );

    // Exported to an SL1, the job is imported: no supports, the same masks, no cure model
    // to judge them by, so the regions by gray, and the warning.
    let o = run_in(&dir, &["export", "b.dmdjob", "-o", "b.sl1", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (code, s) = run(&dir, "b.sl1");
    assert_eq!(code, 0, "{}", s["violations"]);
    assert_eq!(s["format"], "sl1");
    warned(&s);
    same_regions(&reported(&s), by_gray);
}

/// The field pixels of a disc on the build plane: (column, row).
fn disc(centre: [f64; 2], radius: f64, pixel_mm: f64, field_h: usize) -> Vec<(usize, usize)> {
    let r = (radius / pixel_mm).ceil() as i64 + 1;
    let (c0, r0) = (
        (centre[0] / pixel_mm).floor() as i64,
        field_h as i64 - 1 - (centre[1] / pixel_mm).floor() as i64,
    );
    let mut out = Vec::new();
    for dr in -r..=r {
        for dc in -r..=r {
            if ((dr * dr + dc * dc) as f64).sqrt() <= r as f64 {
                out.push(((c0 + dc) as usize, (r0 + dr) as usize));
            }
        }
    }
    out
}

#[test]
fn a_supported_job_runs_clean_and_a_cut_support_is_a_violation() {
    let dir = tempdir("printable-supports");
    // Without the cure correction's moved edges (see docs/EXECUTOR.md "Printability")
    // the masks rest layer on layer everywhere.
    let args = [
        "--layer-height",
        "0.1",
        "--supports",
        "--cure-correction",
        "off",
    ];
    slice_bunny(&dir, "s.dmdjob", &args);
    let (code, r) = run(&dir, "s.dmdjob");
    assert_eq!(code, 0, "{}", r["violations"]);
    assert!(warnings_of(&r, "run.unsupported-regions").is_empty());
    assert_eq!(r["unsupported_regions"], Value::Array(vec![]));

    // The longest pillar standing on the pad, cut over three layers halfway up.
    let b = dir.join("s.dmdjob");
    let mut j = job(&b);
    let points = j["supports"]["points"].as_array().unwrap().clone();
    let head = j["supports"]["head_length_mm"].as_f64().unwrap();
    let pillar =
        |p: &Value| p["at_mm"][2].as_f64().unwrap() - head - p["foot_z_mm"].as_f64().unwrap();
    let p = points
        .iter()
        .filter(|p| p["foot"] == "pad")
        .max_by(|a, b| pillar(a).total_cmp(&pillar(b)))
        .expect("a support on the pad");
    let (foot, top) = (
        p["foot_z_mm"].as_f64().unwrap(),
        p["at_mm"][2].as_f64().unwrap() - head,
    );
    assert!(top - foot > 1.0, "{p}");
    let mid = (foot + top) / 2.0;
    let layers = j["layers"].as_array().unwrap().clone();
    let k = layers
        .iter()
        .position(|l| l["z_mm"].as_f64().unwrap() >= mid)
        .unwrap();
    let proj = j["machine"]["projector"][0].clone();
    let (w, h) = (
        proj["width_px"].as_u64().unwrap() as usize,
        proj["height_px"].as_u64().unwrap() as usize,
    );
    let (ox, oy) = (
        proj["offset_px"][0].as_u64().unwrap() as usize,
        proj["offset_px"][1].as_u64().unwrap() as usize,
    );
    let (mx, my) = (proj["mirror_x"] == true, proj["mirror_y"] == true);
    let pixel_mm = proj["pixel_mm"].as_f64().unwrap();
    let radius = p["pillar_diameter_mm"].as_f64().unwrap() / 2.0 + 2.0 * pixel_mm;
    let xy = [
        p["at_mm"][0].as_f64().unwrap(),
        p["at_mm"][1].as_f64().unwrap(),
    ];
    for layer in k..k + 3 {
        let file = layers[layer]["masks"][0]["file"]
            .as_str()
            .unwrap()
            .to_string();
        let path = b.join(&file);
        let (_, _, mut px) = read_gray(&path);
        let mut blanked = 0;
        for (fc, fr) in disc(xy, radius, pixel_mm, oy + h) {
            let (c, r) = (fc - ox, fr - oy);
            let (c, r) = (
                if mx { w - 1 - c } else { c },
                if my { h - 1 - r } else { r },
            );
            blanked += usize::from(px[r * w + c] != 0);
            px[r * w + c] = 0;
        }
        assert!(
            blanked > 0,
            "layer {layer}: the pillar lights no pixel at {xy:?}"
        );
        image::GrayImage::from_raw(w as u32, h as u32, px.clone())
            .unwrap()
            .save(&path)
            .unwrap();
        // Signed again: the hash and the pixels' record.
        let m = &mut j["layers"][layer]["masks"][0];
        m["sha256"] = dmdsl::bundle::sha256_hex(&std::fs::read(&path).unwrap()).into();
        let rec = dmdsl::bundle::MaskPixels::of_gray8(w as u32, &px).placed(
            [w as u32, h as u32],
            [ox as u32, oy as u32],
            [mx, my],
        );
        m["pixels"] = serde_json::to_value(rec).unwrap();
    }
    std::fs::write(b.join("job.json"), serde_json::to_vec_pretty(&j).unwrap()).unwrap();
    let (code, r) = run(&dir, "s.dmdjob");
    assert_eq!(code, 1, "{}", r["violations"]);
    let v = r["violations"].as_array().unwrap();
    let cut: Vec<&Value> = v
        .iter()
        .filter(|v| v["kind"] == "unsupported-region")
        .collect();
    assert!(
        cut.iter().any(|v| v["layer"] == (k + 3) as u64),
        "{}",
        r["violations"]
    );
    let at = cut.iter().find(|v| v["layer"] == (k + 3) as u64).unwrap();
    assert!(
        at["message"]
            .as_str()
            .unwrap()
            .contains("though the job was compiled with supports"),
        "{at}"
    );
    assert!(
        v.iter().all(|v| v["kind"] == "unsupported-region"),
        "only the cut pillar is wrong: {}",
        r["violations"]
    );
    let g = reported(&r);
    let near = |(l, x, y, _): &(usize, f64, f64, f64)| {
        *l == k + 3 && (x - xy[0]).hypot(y - xy[1]) < radius
    };
    assert!(g.iter().any(near), "{g:?} at {xy:?}");
    assert!(warnings_of(&r, "run.unsupported-regions").is_empty());

    // The preview rings the cut pillar's top and draws the supports; without supports
    // it is another picture.
    slice_bunny(
        &dir,
        "u.dmdjob",
        &["--layer-height", "0.1", "--cure-correction", "off"],
    );
    for (job, png) in [("s.dmdjob", "s.png"), ("u.dmdjob", "u.png")] {
        let o = run_in(&dir, &["inspect", job, "--preview", png, "-q"]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let (s, u) = (
        image::open(dir.join("s.png")).unwrap().into_rgb8(),
        image::open(dir.join("u.png")).unwrap().into_rgb8(),
    );
    assert_ne!(s.as_raw(), u.as_raw());
    let has = |img: &image::RgbImage, c: [u8; 3]| img.pixels().any(|p| p.0 == c);
    use dmdsl::inspect::marks::{REGION, SUPPORT};
    assert!(has(&s, SUPPORT) && has(&s, REGION));
    assert!(has(&u, REGION) && !has(&u, SUPPORT));
}
