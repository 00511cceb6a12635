//! Round trips through every form: a part sliced to a bundle directory, written as a
//! zipped bundle, an SL1 and an SLA control file (by `slice -o` and by `export`), read back
//! by `dmdsl run`: every mask decodes to the bundle's pixels, the run is clean, and the
//! timeline agrees with the bundle's as far as the form carries it.

use crate::common::*;
use serde_json::Value;
use std::path::Path;

/// `dmdsl run FILE --json` in `dir`: the report, asserting exit 0.
fn run_report(dir: &Path, file: &str) -> Value {
    let o = run_in(dir, &["run", file, "--json"]);
    assert!(o.status.success(), "run {file}: {}", stderr(&o));
    serde_json::from_str(&stdout(&o)).unwrap_or_else(|e| panic!("{file}: {e}"))
}

/// The decoded first mask of every layer with a thickness (a control file's extra
/// exposures of a layer are layers of thickness 0), in order.
fn layer_pixels(path: &Path) -> Vec<Vec<u8>> {
    let job = dmdsl::formats::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    job.manifest
        .layers
        .iter()
        .filter(|l| l.thickness_mm > 0.0)
        .map(|l| {
            let rel = &l.masks[0].file;
            let bytes = job.source.read(rel).unwrap();
            image::load_from_memory(&bytes)
                .unwrap_or_else(|e| panic!("{}: {rel}: {e}", path.display()))
                .into_luma8()
                .into_raw()
        })
        .collect()
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} in {v:.200}"))
}

#[test]
fn every_form_runs_clean_with_the_bundles_masks_and_timeline() {
    let d = tempdir("roundtrip");
    let part = fixture("cylinder_hole.stl");
    let part = part.to_str().unwrap();
    let sliced = |args: &[&str]| {
        let mut all = vec!["slice", part, "-q"];
        all.extend_from_slice(args);
        let o = run_in(&d, &all);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    };
    sliced(&["-o", "a.dmdjob"]);
    sliced(&["-o", "s.sl1"]);
    sliced(&["-o", "s.zip", "--format", "sla-control"]);
    sliced(&["-o", "s.dmdjob.zip"]);
    for (out, format) in [
        ("e.dmdjob.zip", None),
        ("e.sl1", None),
        ("e.zip", Some("sla-control")),
        ("e.dmdjob", None),
    ] {
        let mut args = vec!["export", "a.dmdjob", "-o", out, "-q"];
        if let Some(f) = format {
            args.extend_from_slice(&["--format", f]);
        }
        let o = run_in(&d, &args);
        assert!(o.status.success(), "export {out}: {}", stderr(&o));
    }
    // A one-file form exports again (zip bundle → SL1).
    let o = run_in(&d, &["export", "s.dmdjob.zip", "-o", "z.sl1", "-q"]);
    assert!(o.status.success(), "export zip → sl1: {}", stderr(&o));

    let native = run_report(&d, "a.dmdjob");
    assert_eq!(native["violations"].as_array().unwrap().len(), 0);
    let pixels = layer_pixels(&d.join("a.dmdjob"));
    assert!(pixels.len() > 10);
    let job: Value =
        serde_json::from_slice(&std::fs::read(d.join("a.dmdjob/job.json")).unwrap()).unwrap();
    let shutter =
        num(&job["machine"]["shutter"], "open_s") + num(&job["machine"]["shutter"], "close_s");

    for (file, format) in [
        ("s.sl1", "sl1"),
        ("e.sl1", "sl1"),
        ("z.sl1", "sl1"),
        ("s.zip", "sla-control"),
        ("e.zip", "sla-control"),
        ("s.dmdjob.zip", "dmdjob-zip"),
        ("e.dmdjob.zip", "dmdjob-zip"),
        ("e.dmdjob", "dmdjob"),
    ] {
        let r = run_report(&d, file);
        assert_eq!(r["format"], format, "{file}");
        assert_eq!(
            r["violations"].as_array().unwrap().len(),
            0,
            "{file}: {}",
            r["violations"]
        );
        assert!(
            layer_pixels(&d.join(file)) == pixels,
            "{file}: a mask differs from the bundle's"
        );
        match format {
            // The same job: the same simulation to the millisecond.
            "dmdjob" | "dmdjob-zip" => {
                for k in ["total_s", "light_on_s", "stage_travel_mm", "wait_s"] {
                    assert_eq!(r[k], native[k], "{file}: {k}");
                }
            }
            // The same light, moves and waits; the standard has no shutter delays, so each
            // image's exposure lacks the shutter's opening and closing.
            "sla-control" => {
                for k in ["light_on_s", "stage_travel_mm", "wait_s"] {
                    assert_eq!(r[k], native[k], "{file}: {k}");
                }
                let missing = num(&native, "total_s") - num(&r, "total_s");
                let layers = pixels.len() as f64;
                assert!(
                    (missing - layers * shutter).abs() < 1e-6,
                    "{file}: {missing} s shorter, expected {} s",
                    layers * shutter
                );
            }
            // PrusaSlicer's own model of the print: the run replays the file's printTime.
            _ => {
                assert!(
                    num(&r, "estimate_diff_pct").abs() < 1e-6,
                    "{file}: {r:.300}"
                );
            }
        }
    }
}
