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
    sliced(&["-o", "s.nanodlp"]);
    for (out, format) in [
        ("e.nanodlp", None),
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
        ("s.nanodlp", "nanodlp"),
        ("e.nanodlp", "nanodlp"),
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
            // The same light and waits; every layer after the first as the bundle's but the
            // shutter's delays (a plate starts with a move to the first layer: no dip).
            "nanodlp" => {
                for k in ["light_on_s", "wait_s", "exposure_s"] {
                    assert_eq!(r[k], native[k], "{file}: {k}");
                }
                let per = |v: &Value| v["per_layer"].as_array().unwrap().clone();
                for (a, b) in per(&native).iter().zip(per(&r)).skip(1) {
                    let missing = num(a, "time_s") - num(&b, "time_s");
                    assert!((missing - shutter).abs() < 1e-6, "{file}: {a} {b}");
                }
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

#[test]
fn a_nanodlp_plate_carries_the_documented_files_and_keys() {
    let d = tempdir("nanodlp-keys");
    let part = fixture("cube10.stl");
    let o = run_in(
        &d,
        &[
            "slice",
            part.to_str().unwrap(),
            "--scale",
            "0.2",
            "-p",
            "bottom-up",
            "--cure-correction",
            "off",
            "-o",
            "b.nanodlp",
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    // The bottom-up peel's two speeds are one lift on a plate: said, never silent.
    assert!(!warnings_of(&v, "export.nanodlp-steps").is_empty(), "{v}");
    let files = zip_entries(&d.join("b.nanodlp"));
    let get = |n: &str| -> Value {
        let b = &files
            .iter()
            .find(|(k, _)| k == n)
            .unwrap_or_else(|| panic!("{n}"))
            .1;
        serde_json::from_slice(b).unwrap()
    };
    // NanoDLP's format documentation: meta.json's keys, info.json's per layer.
    let meta = get("meta.json");
    for k in [
        "FormatVersion",
        "Distro",
        "Program",
        "Version",
        "OS",
        "Arch",
        "Profile",
    ] {
        assert!(meta.get(k).is_some(), "meta.json lacks {k}");
    }
    let info = get("info.json");
    let layers = info.as_array().unwrap();
    let n = get("plate.json")["LayersCount"].as_u64().unwrap() as usize;
    assert_eq!(layers.len(), n);
    for l in layers {
        for k in [
            "TotalSolidArea",
            "LargestArea",
            "SmallestArea",
            "MinX",
            "MinY",
            "MaxX",
            "MaxY",
            "AreaCount",
        ] {
            assert!(l.get(k).is_some(), "info.json lacks {k}");
        }
        assert_eq!(l["AreaCount"], 1);
        assert!(
            // The cube: 10.15625 mm × 0.2 square.
            (l["TotalSolidArea"].as_f64().unwrap() - 2.03125f64.powi(2)).abs() < 1e-3,
            "{l}"
        );
    }
    for k in [
        "PWidth",
        "PHeight",
        "XPixelSize",
        "YPixelSize",
        "ImageMirror",
    ] {
        assert!(
            get("options.json").get(k).is_some(),
            "options.json lacks {k}"
        );
    }
    assert_eq!(get("options.json"), get("slicer.json"));
    for k in [
        "CureTime",
        "SupportCureTime",
        "SupportLayerNumber",
        "Depth",
        "WaitHeight",
    ] {
        assert!(
            get("profile.json").get(k).is_some(),
            "profile.json lacks {k}"
        );
    }
    // The layers 1.png … N.png, the 200 × 100 preview.
    for i in 1..=n {
        assert!(
            files.iter().any(|(k, _)| *k == format!("{i}.png")),
            "{i}.png"
        );
    }
    let preview = &files.iter().find(|(k, _)| k == "3d.png").unwrap().1;
    let img = image::load_from_memory(preview).unwrap();
    assert_eq!((img.width(), img.height()), (200, 100));
    // Read back: the plate's exposures; every layer the plate gives another is counted by
    // the warning.
    let r = run_report(&d, "b.nanodlp");
    assert_eq!(r["violations"].as_array().unwrap().len(), 0, "{r:.400}");
    let o = run_in(
        &d,
        &[
            "slice",
            part.to_str().unwrap(),
            "--scale",
            "0.2",
            "-p",
            "bottom-up",
            "-q",
            "-o",
            "b.dmdjob",
        ],
    );
    assert!(o.status.success());
    let job: Value =
        serde_json::from_slice(&std::fs::read(d.join("b.dmdjob/job.json")).unwrap()).unwrap();
    let exposures = |v: &Value, k: &str| -> Vec<f64> {
        v[k].as_array()
            .unwrap()
            .iter()
            .map(|l| l["exposure_s"].as_f64().unwrap())
            .collect()
    };
    let (a, b) = (exposures(&r, "per_layer"), exposures(&job, "layers"));
    let differ = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| (*x - *y).abs() > 1e-6)
        .count() as u64;
    let said = warnings_of(&v, "export.nanodlp-exposure");
    let said = said
        .first()
        .map_or(0, |w| w["fields"]["layers"].as_u64().unwrap());
    assert_eq!(differ, said, "{a:?} {b:?}");
    // The normal cure time is the one most layers have: only the ramp from the bottom
    // exposure down to it differs.
    let ramp = b
        .iter()
        .filter(|&&e| e < b[0] && e > b[b.len() - 1])
        .count() as u64;
    assert!(
        ramp > 0 && differ <= ramp,
        "{differ} differ, ramp {ramp}: {b:?}"
    );
}

#[test]
fn control_files_round_trip_their_projectors_and_into_bundles() {
    let d = tempdir("control-roundtrip");
    let part = fixture("island.stl");
    let o = run_in(
        &d,
        &[
            "slice",
            part.to_str().unwrap(),
            "-p",
            "tiled-2x1",
            "-o",
            "t.dmdjob",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run_in(
        &d,
        &[
            "export",
            "t.dmdjob",
            "-o",
            "t.zip",
            "--format",
            "sla-control",
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    // A tiled job's images are exposed in turn on a control-file printer: said.
    assert!(
        !warnings_of(&v, "export.control-sequential").is_empty(),
        "{v}"
    );
    // Read back: both projectors at their offsets, the pixel size stated.
    let native = dmdsl::formats::open(&d.join("t.dmdjob")).unwrap();
    let back = dmdsl::formats::open(&d.join("t.zip")).unwrap();
    let place = |j: &dmdsl::formats::Job| -> Vec<(String, [u32; 2], f64)> {
        j.manifest
            .machine
            .projector
            .iter()
            .map(|p| (p.name.clone(), p.offset_px, p.pixel_mm.get()))
            .collect()
    };
    assert_eq!(place(&back), place(&native));
    assert!(back.manifest.machine.states("projector[].pixel_mm"));
    // Every record one projector's image; the light per layer as the bundle's, in turn.
    let light: f64 = back.manifest.layers.iter().map(|l| l.exposure_s).sum();
    let light0: f64 = native.manifest.layers.iter().map(|l| l.exposure_s).sum();
    assert!((light - 2.0 * light0).abs() < 1e-6, "{light} {light0}");
    let r = run_report(&d, "t.zip");
    assert_eq!(r["violations"].as_array().unwrap().len(), 0, "{r:.400}");
    // Into a bundle directory and a zipped bundle: every layer its own files, runs clean.
    for out in ["back.dmdjob", "back.dmdjob.zip"] {
        let o = run_in(&d, &["export", "t.zip", "-o", out, "-q"]);
        assert!(o.status.success(), "{out}: {}", stderr(&o));
        let r = run_report(&d, out);
        assert_eq!(
            r["violations"].as_array().unwrap().len(),
            0,
            "{out}: {r:.400}"
        );
    }
    // One projector: the same through a control file and back into a bundle.
    let o = run_in(
        &d,
        &[
            "slice",
            part.to_str().unwrap(),
            "-o",
            "one.zip",
            "--format",
            "sla-control",
            "-q",
        ],
    );
    assert!(o.status.success());
    let o = run_in(&d, &["export", "one.zip", "-o", "one.dmdjob", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = run_report(&d, "one.dmdjob");
    assert_eq!(r["violations"].as_array().unwrap().len(), 0, "{r:.400}");
}
