//! `dmdsl run --cure`: the cure predicted from a bundle's masks alone, against the model's
//! closed forms (print-through, docs/CURE.md) and the slicer's own prediction
//! (`slice --predict`, which works against the exact sections).

use crate::common::*;
use serde_json::Value;
use std::path::Path;

/// The default profile's layer, mm, and bottom layers.
const H: f64 = 0.05;
const BOTTOM: usize = 2;

/// Slices `part` in `dir` with `args`, into `out` (at its file position unless the part is
/// the bunny, which sits around the origin).
fn slice(dir: &Path, part: &str, out: &str, args: &[&str]) {
    let f = fixture(part);
    let mut a = vec!["slice", f.to_str().unwrap(), "-q"];
    if part != "bunny00.stl" {
        a.push("--keep-position");
    }
    a.extend_from_slice(args);
    a.extend_from_slice(&["-o", out]);
    let o = run_in(dir, &a);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `dmdsl run --cure --json` of `bundle`: the report's `cure`.
fn cure(dir: &Path, bundle: &str) -> Value {
    let o = run_in(dir, &["run", "--cure", "--json", bundle]);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", stderr(&o));
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    report["cure"].clone()
}

#[test]
fn print_through_and_the_z_correction_from_the_masks() {
    let dir = tempdir("run-cure-island");
    // island.stl's upper block hangs over nothing: its first layer's pixels are
    // downward-facing, with 40 lit layers above them.
    slice(
        &dir,
        "island.stl",
        "xy.dmdjob",
        &["--cure-correction", "xy"],
    );
    let c = cure(&dir, "xy.dmdjob");
    let closed = 0.219; // CureModel::print_through_mm(None) with the defaults
    let pt = c["print_through_mm"].as_f64().unwrap();
    assert!((pt - closed).abs() <= 0.05 * closed, "print-through {pt}");
    assert_eq!(c["correction"], "xy");
    assert!(c.get("z_error_mm").is_none());
    assert_eq!(c["vanished"], 0);
    assert_eq!(c["merged"], 0);
    // Held back by M layers: the cured bottom lies within a layer of the CAD.
    slice(
        &dir,
        "island.stl",
        "xyz.dmdjob",
        &["--cure-correction", "xyz"],
    );
    let c = cure(&dir, "xyz.dmdjob");
    // The held-back layers light less than their sections by design: the plain run
    // verifies them clean.
    for b in ["xy.dmdjob", "xyz.dmdjob"] {
        let o = run_in(&dir, &["run", b]);
        assert!(o.status.success(), "{b}: {}{}", stdout(&o), stderr(&o));
    }
    let held = c["held_back_layers"].as_u64().unwrap();
    assert!(held >= 2, "{held}");
    let z = c["z_error_mm"].as_f64().unwrap();
    assert!(z.abs() <= H, "Z error {z} mm");
    let pt = c["print_through_mm"].as_f64().unwrap();
    assert!((pt - held as f64 * H - z).abs() < 1e-6);
    // The human summary's line.
    let o = run_in(&dir, &["run", "--cure", "xy.dmdjob"]);
    let text = stdout(&o);
    let line = text.lines().find(|l| l.starts_with("cure: ")).unwrap();
    assert!(
        line.contains("edge offset") && line.contains("print-through 0.2"),
        "{line}"
    );
}

#[test]
fn the_slicers_prediction_is_the_runs_and_the_correction_holds_on_every_layer() {
    let dir = tempdir("run-cure-features");
    // The feature part made 0.9 mm tall (18 layers), compensation off as in cure.rs:
    // 2 bottom layers at twice the exposure, fewer layers above the top ones.
    for name in ["off", "xy"] {
        let out = format!("{name}.dmdjob");
        slice(
            &dir,
            "features.stl",
            &out,
            &[
                "--scale",
                "1,1,3",
                "--compensation",
                "off",
                "--predict",
                "--cure-correction",
                name,
            ],
        );
        let c = cure(&dir, &out);
        let layers = c["per_layer"].as_array().unwrap();
        let n = layers.len();
        assert_eq!(n, 18);
        for l in layers {
            let i = l["index"].as_u64().unwrap() as usize;
            // The slicer's prediction is the same engine on the same masks.
            let diff = l["slicer_diff_px"].as_f64().unwrap();
            assert!(diff.abs() <= 0.05, "{name} layer {i}: {diff}");
            let off = l["offset_px"].as_f64().unwrap();
            if name == "xy" {
                // Corrected: every layer, the bottom and the top ones included.
                assert!(off.abs() < 0.1, "{name} layer {i}: offset {off}");
            } else if i >= BOTTOM && n - 1 - i >= 10 {
                // Uncorrected, a wall of many layers grows by the blur.
                assert!(off > 0.4 && off < 0.65, "{name} layer {i}: offset {off}");
            }
        }
        if name == "off" {
            // The bottom layers' longer exposure grows them more; the top layer, with no
            // layer above it, less.
            let at = |i: usize| layers[i]["offset_px"].as_f64().unwrap();
            assert!(at(0) > at(8) + 0.05, "{} vs {}", at(0), at(8));
            assert!(at(n - 1) < at(8) - 0.3, "{} vs {}", at(n - 1), at(8));
        }
        assert_eq!(c["vanished"], 0);
        assert_eq!(c["merged"], 0);
        assert_eq!(c["slicer"]["vanish_disagreements"], Value::Array(vec![]));
    }
}

#[test]
fn a_sloped_part_cures_on_its_sections_layer_by_layer() {
    let dir = tempdir("run-cure-bunny");
    // The bunny at 0.3 scale (236 layers of sloped walls; a debug build's time), the
    // default job but for --predict: the run's edge offsets over every layer, bottom
    // ones included, the docs/CURE.md acceptance figures.
    slice(
        &dir,
        "bunny00.stl",
        "b.dmdjob",
        &["--scale", "0.3", "--predict"],
    );
    let c = cure(&dir, "b.dmdjob");
    let e = &c["edge_offset_px"];
    let (mean, p95) = (e["mean"].as_f64().unwrap(), e["p95"].as_f64().unwrap());
    let signed = c["signed_mean_px"].as_f64().unwrap();
    assert!(
        mean <= 0.25 && p95 <= 0.5 && signed.abs() <= 0.05,
        "{mean} {p95} {signed}"
    );
    // The slicer's records agree layer by layer.
    let s = &c["slicer"];
    assert_eq!(s["layers"], c["layers_checked"]);
    assert!(s["max_diff_px"].as_f64().unwrap() <= 0.05, "{s}");
    // And its samples along the exact sections' normals, another measure of the same
    // light, agree with the offsets on average.
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("b.dmdjob/job.json")).unwrap()).unwrap();
    let p = &job["cure"]["predicted"];
    let sampled = p["signed_mean_px"].as_f64().unwrap();
    assert!((sampled - signed).abs() <= 0.05, "{sampled} vs {signed}");
    assert!(p["edge_error_px"]["mean"].as_f64().unwrap() <= 0.25, "{p}");
}

#[test]
fn jobs_without_a_cure_model_are_refused_in_one_line() {
    let dir = tempdir("run-cure-refused");
    // An SL1 file carries no cure record.
    let sl1 = fixture("sl1/cube1.sl1");
    let o = run_in(&dir, &["run", "--cure", sl1.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(
        e.contains("cube1.sl1") && e.contains("`cure` record"),
        "{e}"
    );
    // A job sliced with a profile without psf_sigma_px.
    let o = run_in(&dir, &["profile", "show", "xu2010-topdown"]);
    let toml: String = stdout(&o)
        .lines()
        .filter(|l| !l.starts_with("psf_sigma_px"))
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(dir.join("old.toml"), toml).unwrap();
    let f = fixture("cube10.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            f.to_str().unwrap(),
            "-q",
            "--layer-height",
            "1",
            "-p",
            "old.toml",
            "-o",
            "old.dmdjob",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run_in(&dir, &["run", "--cure", "old.dmdjob"]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(
        e.contains("old.dmdjob") && e.contains("psf_sigma_px"),
        "{e}"
    );
    // Without --cure the same job runs and reports no cure.
    let o = run_in(&dir, &["run", "--json", "old.dmdjob"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(r.get("cure").is_none());
}
