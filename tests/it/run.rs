//! `dmdsl run` (the dry-run executor) as a user runs it: on fresh bundles from
//! `dmdsl slice`, and on bundles broken on purpose.

use crate::common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Slices a 10 × 10 × 2 mm box at 0.5 mm layers (4 layers) into `<dir>/box.dmdjob`.
fn sliced(name: &str) -> (TempDir, PathBuf) {
    let dir = tempdir(&format!("run-{name}"));
    write_stl(&dir.join("box.stl"), &box_tris([0.0; 3], [10.0, 10.0, 2.0]));
    let o = run_in(&dir, &["slice", "box.stl", "--layer-height", "0.5", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let b = dir.join("box.dmdjob");
    assert!(b.join("job.json").is_file());
    (dir, b)
}

fn job(b: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap()
}

fn set_job(b: &Path, v: &Value) {
    std::fs::write(b.join("job.json"), serde_json::to_vec_pretty(v).unwrap()).unwrap();
}

fn run_json(dir: &Path, args: &[&str]) -> (i32, Value) {
    let mut a = vec!["run", "box.dmdjob", "--json"];
    a.extend_from_slice(args);
    let o = run_in(dir, &a);
    let code = o.status.code().unwrap();
    let v = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {} / {}", stdout(&o), stderr(&o)));
    (code, v)
}

fn kinds(r: &Value) -> Vec<String> {
    r["violations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["kind"].as_str().unwrap().to_string())
        .collect()
}

/// The violation kinds (`dmdsl::exec::Kind`) are exactly the enums of the report's schema
/// (faults: the injected ones) and the table of `docs/EXECUTOR.md`, in their order and
/// with their meanings.
#[test]
fn violation_kinds_are_the_schemas_and_the_docs() {
    use dmdsl::exec::{sim::FaultKind, Kind};
    let names = |ks: &[Kind]| Value::from(ks.iter().map(|k| k.name()).collect::<Vec<_>>());
    let text = |f: &str| std::fs::read_to_string(root().join(f)).unwrap();
    let schema: Value = serde_json::from_str(&text("docs/schemas/run-report.schema.json")).unwrap();
    let p = &schema["properties"];
    assert_eq!(
        p["violations"]["items"]["properties"]["kind"]["enum"],
        names(Kind::ALL)
    );
    let faults = FaultKind::ALL.map(Kind::from);
    assert_eq!(
        p["fault"]["oneOf"][1]["properties"]["kind"]["enum"],
        names(&faults)
    );
    let doc = text("docs/EXECUTOR.md");
    let section = doc
        .split("\n## Invariants and violation kinds\n")
        .nth(1)
        .unwrap();
    let section = section.split("\n## ").next().unwrap();
    let rows: Vec<&str> = section.lines().filter(|l| l.starts_with("| `")).collect();
    let want: Vec<String> = Kind::ALL
        .iter()
        .map(|k| format!("| `{}` | {} |", k.name(), k.meaning()))
        .collect();
    assert_eq!(
        rows,
        want,
        "docs/EXECUTOR.md's table must be:\n{}",
        want.join("\n")
    );
}

#[test]
fn fresh_bundle_replays_cleanly() {
    let (dir, b) = sliced("clean");
    let o = run_in(
        &dir,
        &["run", "box.dmdjob", "--trace", "t.csv", "--plot", "p.png"],
    );
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{out}{}", stderr(&o));
    assert!(
        out.contains("box.dmdjob: 4 layers, 4 masks checked"),
        "{out}"
    );
    assert!(
        out.contains("violations: none") && out.trim_end().ends_with("OK"),
        "{out}"
    );

    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 0);
    assert_eq!(r["layers"], 4);
    assert_eq!(r["violations"].as_array().unwrap().len(), 0);
    let j = job(&b);
    let mut exposures = 0.0;
    let mut waits = 0.0;
    for l in j["layers"].as_array().unwrap() {
        for s in l["steps"].as_array().unwrap() {
            match s["kind"].as_str().unwrap() {
                "expose" => exposures += s["s"].as_f64().unwrap(),
                "wait" => waits += s["s"].as_f64().unwrap(),
                _ => {}
            }
        }
    }
    let total = r["total_s"].as_f64().unwrap();
    assert!(exposures > 0.0 && waits > 0.0);
    assert!(
        total >= exposures + waits,
        "{total} < {exposures} + {waits}"
    );
    assert!((r["light_on_s"].as_f64().unwrap() - exposures).abs() < 1e-9);
    // The simulation agrees with the planner's estimate within 1 %.
    let est = j["totals"]["print_time_s"].as_f64().unwrap();
    assert_eq!(r["estimate_s"].as_f64().unwrap(), est);
    assert!(
        ((total - est) / est).abs() < 0.01,
        "simulated {total} s, estimated {est} s"
    );
    for (p, l) in r["per_layer"]
        .as_array()
        .unwrap()
        .iter()
        .zip(j["layers"].as_array().unwrap())
    {
        let (t, e) = (p["time_s"].as_f64().unwrap(), l["time_s"].as_f64().unwrap());
        assert!(
            ((t - e) / e).abs() < 0.01,
            "layer {}: {t} vs {e}",
            p["index"]
        );
    }

    // The trace covers the job and ends at total_s; the plot is a PNG.
    let csv = std::fs::read_to_string(dir.join("t.csv")).unwrap();
    let last: Vec<&str> = csv.lines().last().unwrap().split(',').collect();
    assert!((last[0].parse::<f64>().unwrap() - total).abs() < 1e-5);
    assert_eq!(last[7], "end");
    let z_max = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse::<f64>().unwrap())
        .fold(0.0, f64::max);
    assert!(
        (z_max - (2.0 + 5.0)).abs() < 1e-9,
        "dip above the last layer: {z_max}"
    );
    let img = image::open(dir.join("p.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1400, 600));
    let title = img
        .enumerate_pixels()
        .filter(|(_, y, p)| *y < 40 && p.0.iter().all(|&c| c < 110))
        .count();
    assert!(title > 100, "no title text");
    // The stage line (blue), the exposure dots (red) and the light-on shading (orange).
    let count = |f: &dyn Fn([u8; 3]) -> bool| img.pixels().filter(|p| f(p.0)).count();
    assert!(count(&|p| p[2] > 150 && p[0] < 80) > 1000);
    assert!(count(&|p| p[0] > 170 && p[1] < 90 && p[2] < 60) > 40);
    assert!(count(&|p| p[0] > 240 && p[1] > 200 && p[2] < 200) > 1000);
    // As JPEG.
    let o = run_in(&dir, &["run", "box.dmdjob", "-q", "--plot", "p.jpg"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let jpg = image::open(dir.join("p.jpg")).unwrap();
    assert_eq!((jpg.width(), jpg.height()), (1400, 600));

    // --layers limits trace and plot.
    let o = run_in(
        &dir,
        &[
            "run",
            "box.dmdjob",
            "-q",
            "--trace",
            "t2.csv",
            "--layers",
            "1..2",
        ],
    );
    assert_eq!(o.status.code(), Some(0));
    let csv = std::fs::read_to_string(dir.join("t2.csv")).unwrap();
    let layers: std::collections::BTreeSet<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(6).unwrap())
        .collect();
    assert_eq!(layers.into_iter().collect::<Vec<_>>(), vec!["1", "2"]);
}

#[test]
fn corrupted_mask_is_named() {
    let (dir, b) = sliced("corrupt");
    let p = b.join("masks/00001.png");
    let mut bytes = std::fs::read(&p).unwrap();
    let n = bytes.len();
    for x in &mut bytes[n / 2..n / 2 + 16] {
        *x ^= 0x5a;
    }
    std::fs::write(&p, bytes).unwrap();
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("box.dmdjob/masks/00001.png: layer 1: SHA-256 mismatch"),
        "{out}"
    );
    assert!(out.contains("FAILED"));
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1);
    let v = &r["violations"][0];
    assert_eq!(v["kind"], "mask-checksum");
    assert_eq!(v["file"], "masks/00001.png");
    assert_eq!(v["layer"], 1);
    assert!(v["time_s"].as_f64().unwrap() > 0.0);
}

#[test]
fn missing_mask_is_named() {
    let (dir, b) = sliced("missing");
    std::fs::remove_file(b.join("masks/00002.png")).unwrap();
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("masks/00002.png: layer 2: mask file is missing"),
        "{out}"
    );
    let (_, r) = run_json(&dir, &[]);
    assert_eq!(kinds(&r), vec!["mask-missing"]);
}

#[test]
fn move_beyond_travel_is_a_violation() {
    let (dir, b) = sliced("travel");
    let mut j = job(&b);
    // The profile's travel is 0..120 mm; dip layer 2 to 500 mm.
    j["layers"][2]["steps"][0]["to_mm"] = 500.0.into();
    set_job(&b, &j);
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1);
    let v: Vec<&Value> = r["violations"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|v| v["kind"] == "travel")
        .collect();
    assert!(!v.is_empty(), "{r}");
    assert_eq!(v[0]["layer"], 2);
    assert!(v[0]["message"]
        .as_str()
        .unwrap()
        .contains("to 500.0000 mm leaves the stage travel [0, 120] mm"));
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    assert!(stdout(&o).contains("travel"), "{}", stdout(&o));
}

#[test]
fn move_faster_than_the_stage_is_a_violation() {
    let (dir, b) = sliced("speed");
    let mut j = job(&b);
    // Max speed is 10 mm/s.
    j["layers"][1]["steps"][1]["speed_mm_s"] = 25.0.into();
    set_job(&b, &j);
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1);
    let k = kinds(&r);
    assert!(k.contains(&"speed".to_string()), "{k:?}");
    let v = r["violations"]
        .as_array()
        .unwrap()
        .iter()
        .find(|v| v["kind"] == "speed")
        .unwrap();
    assert_eq!(v["layer"], 1);
    assert!(v["message"]
        .as_str()
        .unwrap()
        .contains("25 mm/s exceeds the stage's max_speed_mm_s 10"));
}

#[test]
fn each_fault_stops_the_job_with_layer_and_time() {
    let (dir, _) = sliced("faults");
    for kind in ["stall", "limit", "shutter-stuck", "mask-load"] {
        let spec = format!("{kind}@2");
        let o = run_in(&dir, &["run", "box.dmdjob", "--fault", &spec]);
        let out = stdout(&o);
        assert_eq!(o.status.code(), Some(1), "{kind}: {out}");
        assert!(
            out.contains(&format!("FAULT {kind} in layer 2 at ")),
            "{out}"
        );
        let (code, r) = run_json(&dir, &["--fault", &spec]);
        assert_eq!(code, 1);
        let f = &r["fault"];
        assert_eq!(f["kind"], kind);
        assert_eq!(f["layer"], 2);
        let t = f["time_s"].as_f64().unwrap();
        let l2 = &r["per_layer"][2];
        let start = l2["start_s"].as_f64().unwrap();
        let end = start + l2["time_s"].as_f64().unwrap();
        assert!(t >= start && t <= end + 1e-9, "{r}");
        assert_eq!(r["layers_completed"], 2);
        assert_eq!(r["per_layer"].as_array().unwrap().len(), 3);
        assert!(kinds(&r).contains(&kind.to_string()));
        assert_eq!(r["ok"], false);
    }
    // A shutter stuck in layer 2 is found when it should close after the exposure
    // (close_s 0.05 s), then the DMD is blanked (load_s 0.02 s): 0.07 s of extra light.
    let (_, r) = run_json(&dir, &["--fault", "shutter-stuck@2"]);
    let l = &r["per_layer"][2];
    assert!(
        (l["light_s"].as_f64().unwrap() - l["exposure_s"].as_f64().unwrap() - 0.07).abs() < 1e-6
    );
    assert!(
        r["fault"]["message"]
            .as_str()
            .unwrap()
            .contains("layer 2 got 0.070 s of extra light"),
        "{r}"
    );
}

#[test]
fn a_fault_after_the_one_that_ends_the_run_is_reported_as_never_triggered() {
    let (dir, _) = sliced("untriggered");
    let o = run_in(
        &dir,
        &[
            "run",
            "box.dmdjob",
            "--fault",
            "stall@3",
            "--fault",
            "limit@1",
        ],
    );
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("FAULT limit in layer 1"), "{out}");
    assert!(
        out.contains(
            "note: fault stall@3 never triggered (the run ended at the limit fault in layer 1)"
        ),
        "{out}"
    );
    let (_, r) = run_json(&dir, &["--fault", "stall@3", "--fault", "limit@1"]);
    assert_eq!(r["untriggered_faults"], serde_json::json!(["stall@3"]));
}

#[test]
fn a_stuck_shutter_on_a_machine_without_close_latency_reports_the_extra_light() {
    // The built-in bottom-up profile's shutter closes at once (close_s 0): the light
    // stays on until the DMD is blanked, one mask load (load_s 0.02 s).
    let (dir, _) = sliced("stuck-bottom-up");
    let o = run_in(
        &dir,
        &[
            "slice",
            "box.stl",
            "-p",
            "bottom-up",
            "-o",
            "bu.dmdjob",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run_in(&dir, &["run", "bu.dmdjob", "--fault", "shutter-stuck@2"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("layer 2 got 0.020 s of extra light"), "{out}");
    assert!(!out.contains("got 0.000 s"), "{out}");
}

#[test]
fn a_job_of_one_layer_is_counted_in_the_singular() {
    let dir = tempdir("run-one-layer");
    write_stl(
        &dir.join("tile.stl"),
        &box_tris([0.0; 3], [10.0, 10.0, 0.5]),
    );
    let o = run_in(&dir, &["slice", "tile.stl", "--layer-height", "0.5"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("tile.dmdjob: 1 layer, 0.5 mm"),
        "{}",
        stdout(&o)
    );
    let o = run_in(&dir, &["run", "tile.dmdjob"]);
    assert!(
        stdout(&o).contains("tile.dmdjob: 1 layer, 1 mask checked"),
        "{}",
        stdout(&o)
    );
    let o = run_in(&dir, &["run", "tile.dmdjob", "--fault", "stall@1"]);
    assert!(
        stderr(&o).contains("the job has 1 layer (0..0)"),
        "{}",
        stderr(&o)
    );
    // An STL whose header declares one triangle it does not hold.
    let mut stl = vec![0u8; 80];
    stl.extend(1u32.to_le_bytes());
    std::fs::write(dir.join("short.stl"), &stl).unwrap();
    let o = run_in(&dir, &["slice", "short.stl"]);
    assert!(
        stderr(&o).contains("declares 1 triangle (134 bytes) but the file has 84 bytes"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn unreadable_bundles_and_bad_options_exit_2() {
    let (dir, b) = sliced("unreadable");
    for (args, needle) in [
        (vec!["run", "nope.dmdjob"], "nope.dmdjob: does not exist"),
        (
            vec!["run", "box.dmdjob", "--fault", "jam@1"],
            "dmdsl: error: --fault jam@1: unknown kind \"jam\"",
        ),
        (
            vec!["run", "box.dmdjob", "--fault", "stall@9"],
            "the job has 4 layers",
        ),
        (
            vec!["run", "box.dmdjob", "--plot", "p.png", "--layers", "3..7"],
            "--layers \"3..7\": the job has layers 0..3",
        ),
        (
            vec!["run", "box.dmdjob", "--layers", "1..2"],
            "--layers applies to --trace and --plot",
        ),
        (
            vec!["run", "box.dmdjob", "--plot", "p.gif"],
            "p.gif: cannot write pictures as .gif; use .png, .jpg or .jpeg",
        ),
        (
            vec!["run", "box.dmdjob", "--trace", "no/such/dir/t.csv"],
            "t.csv",
        ),
        // What the job was made for is the job's: the run would ignore it.
        (
            vec!["run", "box.dmdjob", "--set", "exposure.layer_s=3"],
            "dmdsl: error: --set exposure.layer_s=3: exposure is the job's, not the machine's: the run takes it from the job (slice again to change it)",
        ),
        (
            vec!["run", "box.dmdjob", "--set", "projector.0.calibration.zone_mm=3"],
            "--set projector.0.calibration.zone_mm=3: projector[].calibration is the job's",
        ),
    ] {
        let o = run_in(&dir, &args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(needle), "{args:?}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    }
    let mut j = job(&b);
    j["version"] = 99.into();
    set_job(&b, &j);
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("box.dmdjob/job.json: unsupported version"),
        "{}",
        stderr(&o)
    );
    std::fs::write(b.join("job.json"), b"{ not json").unwrap();
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("job.json: invalid JSON"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("no").exists());
}

#[test]
fn older_bundles_still_run_and_export_as_version_4() {
    // Versions 1 and 2 embedded the whole resolved profile as `machine`; the reader takes
    // the machine record's keys from it. Version 1 stored warnings as text (read as code
    // `bundle.uncoded`).
    let (dir, b) = sliced("v1");
    let mut j = job(&b);
    assert_eq!(j["version"], 4);
    let record = j["machine"].clone();
    // Versions 1 to 3 have no pixels records.
    for l in j["layers"].as_array_mut().unwrap() {
        l["masks"][0].as_object_mut().unwrap().remove("pixels");
    }
    assert!(record.get("recoat").is_none() && record.get("slicing").is_none());
    j["machine"] = serde_json::to_value(dmdsl::Profile::default_profile()).unwrap();
    for version in [2, 1] {
        j["version"] = version.into();
        if version == 1 {
            j["warnings"] = serde_json::json!(["mesh has 3 open edges (holes)"]);
        }
        set_job(&b, &j);
        let (code, r) = run_json(&dir, &[]);
        assert_eq!(code, 0, "{r}");
        assert_eq!(r["violations"].as_array().unwrap().len(), 0);
    }
    // What is read is held, and written, as the current version.
    let o = run_in(&dir, &["export", "box.dmdjob", "-o", "new.dmdjob", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let new = job(&dir.join("new.dmdjob"));
    assert_eq!((&new["version"], &new["machine"]), (&4.into(), &record));
    assert_eq!(new["warnings"][0]["code"], "bundle.uncoded");
    // The export counted the masks' pixels again: the new bundle has every record.
    assert!(new["layers"]
        .as_array()
        .unwrap()
        .iter()
        .all(|l| l["masks"][0]["pixels"]["lit_px"].as_u64() > Some(0)));
    let o = run_in(&dir, &["run", "new.dmdjob", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Version 4 without the records is refused; so is a version from the future.
    j["version"] = 4.into();
    set_job(&b, &j);
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.contains("job.json: layers[0].masks[0] has no `pixels` record (every mask has one from version 4 on)"), "{e}");
    j["version"] = 5.into();
    set_job(&b, &j);
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("unsupported version Some(5); this dmdsl reads versions 1 to 4"),
        "{}",
        stderr(&o)
    );
}

/// Slices `tris` (written as `part.stl`) at 0.5 mm layers with `args` into
/// `<dir>/box.dmdjob` (the name `run_json` runs).
fn sliced_part(name: &str, tris: &[[[f32; 3]; 3]], args: &[&str]) -> (TempDir, PathBuf) {
    let dir = tempdir(&format!("run-{name}"));
    write_stl(&dir.join("part.stl"), tris);
    let mut a = vec![
        "slice",
        "part.stl",
        "-o",
        "box.dmdjob",
        "--layer-height",
        "0.5",
        "-q",
    ];
    a.extend_from_slice(args);
    let o = run_in(&dir, &a);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    let b = dir.join("box.dmdjob");
    (dir, b)
}

/// A 10 × 10 × 1 mm slab under a 6 × 6 × 1 mm block: layers 0 and 1 are 10 mm squares,
/// layers 2 and 3 6 mm squares.
fn stepped() -> Vec<[[f32; 3]; 3]> {
    let mut t = box_tris([0.0; 3], [10.0, 10.0, 1.0]);
    t.extend(box_tris([2.0, 2.0, 1.0], [8.0, 8.0, 2.0]));
    t
}

/// Replaces the file of layer `layer`'s first mask with a gray PNG of value `v` (the
/// projector's size) and records its SHA-256 in the manifest.
fn uniform_mask(b: &Path, layer: usize, v: u8) {
    let mut j = job(b);
    let file = j["layers"][layer]["masks"][0]["file"]
        .as_str()
        .unwrap()
        .to_string();
    image::GrayImage::from_pixel(1024, 768, image::Luma([v]))
        .save(b.join(&file))
        .unwrap();
    let bytes = std::fs::read(b.join(&file)).unwrap();
    j["layers"][layer]["masks"][0]["sha256"] = dmdsl::bundle::sha256_hex(&bytes).into();
    set_job(b, &j);
}

/// The violations of kind `kind` as (layer, file).
fn of_kind(r: &Value, kind: &str) -> Vec<(Value, Value)> {
    r["violations"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|v| v["kind"] == kind)
        .map(|v| (v["layer"].clone(), v["file"].clone()))
        .collect()
}

#[test]
fn masks_that_do_not_show_their_layer_are_named() {
    for (name, args) in [
        ("content-zone", vec![]),
        ("content-binary", vec!["--binary"]),
        ("content-off", vec!["--compensation", "off"]),
    ] {
        let (dir, b) = sliced_part(name, &stepped(), &args);
        let (code, r) = run_json(&dir, &[]);
        assert_eq!(code, 0, "{args:?}: {r}");
        let clean = job(&b);
        let saved: Vec<Vec<u8>> = (0..4)
            .map(|i| std::fs::read(b.join(format!("masks/{i:05}.png"))).unwrap())
            .collect();
        let restore = || {
            set_job(&b, &clean);
            for (i, bytes) in saved.iter().enumerate() {
                std::fs::write(b.join(format!("masks/{i:05}.png")), bytes).unwrap();
            }
        };

        // Layers 1 and 2 swapped, checksums and all: each shows the other's section, and
        // other pixels than its record.
        let mut j = job(&b);
        let (s1, s2) = (
            j["layers"][1]["masks"][0]["sha256"].clone(),
            j["layers"][2]["masks"][0]["sha256"].clone(),
        );
        j["layers"][1]["masks"][0]["sha256"] = s2;
        j["layers"][2]["masks"][0]["sha256"] = s1;
        set_job(&b, &j);
        std::fs::write(b.join("masks/00001.png"), &saved[2]).unwrap();
        std::fs::write(b.join("masks/00002.png"), &saved[1]).unwrap();
        let (code, r) = run_json(&dir, &[]);
        assert_eq!(code, 1, "{args:?}: {r}");
        assert_eq!(
            of_kind(&r, "mask-content"),
            vec![
                (1.into(), "masks/00001.png".into()),
                (2.into(), "masks/00002.png".into())
            ],
            "{args:?}: {r}"
        );
        let kinds = kinds(&r);
        assert_eq!(kinds, ["mask-content", "mask-pixels"].repeat(2), "{r}");
        let o = run_in(&dir, &["run", "box.dmdjob"]);
        let out = stdout(&o);
        assert!(
            out.contains("box.dmdjob/masks/00002.png: layer 2: its masks light columns")
                && out.contains("outside the section"),
            "{out}"
        );
        restore();

        // An all-white mask: light outside the section.
        uniform_mask(&b, 0, 255);
        let (code, r) = run_json(&dir, &[]);
        assert_eq!(code, 1);
        assert_eq!(
            of_kind(&r, "mask-content"),
            vec![(0.into(), "masks/00000.png".into())],
            "{args:?}: {r}"
        );
        assert!(r["violations"][0]["message"]
            .as_str()
            .unwrap()
            .contains("layer 0: its masks light columns 0..1023, rows 0..767 of the field"));
        restore();

        // An all-black mask: a section that gets no light.
        uniform_mask(&b, 3, 0);
        let (code, r) = run_json(&dir, &[]);
        assert_eq!(code, 1);
        assert_eq!(
            of_kind(&r, "mask-content"),
            vec![(3.into(), "masks/00003.png".into())],
            "{args:?}: {r}"
        );
        let msg = r["violations"][0]["message"].as_str().unwrap();
        assert!(
            msg.contains("layer 3: the section's area is 3")
                && msg.ends_with(" mm² but its masks light no pixel"),
            "{msg}"
        );
        restore();

        // A layer with no section whose mask lights pixels.
        let mut j = job(&b);
        j["layers"][3]["bbox_mm"] = Value::Null;
        j["layers"][3]["area_mm2"] = 0.0.into();
        set_job(&b, &j);
        let (code, r) = run_json(&dir, &[]);
        assert_eq!(code, 1);
        assert_eq!(
            of_kind(&r, "mask-content"),
            vec![(3.into(), "masks/00003.png".into())]
        );
        assert!(r["violations"][0]["message"]
            .as_str()
            .unwrap()
            .contains("layer 3: the layer has no section (bbox_mm null) but its masks light"));
        restore();
        let (code, r) = run_json(&dir, &[]);
        assert_eq!(code, 0, "{r}");
    }
}

#[test]
fn fresh_bundles_of_every_profile_and_mode_show_their_layers() {
    let dir = tempdir("run-fresh-modes");
    // A profile whose projector shows the field mirrored both ways.
    let o = run_in(&dir, &["profile", "show", "xu2010-topdown"]);
    assert!(o.status.success());
    let mirrored = stdout(&o)
        .replace("mirror_x = false", "mirror_x = true")
        .replace("mirror_y = false", "mirror_y = true");
    std::fs::write(dir.join("mirrored.toml"), mirrored).unwrap();
    let part = fixture("cylinder_hole.stl");
    let lens = fixture("lens_table.csv");
    let (part, lens) = (part.to_str().unwrap(), lens.to_str().unwrap());
    for args in [
        vec!["-p", "xu2010-topdown"],
        vec!["-p", "bottom-up"],
        vec!["-p", "hybrid-bottomup"],
        vec!["-p", "tiled-2x1"],
        vec!["-p", "tiled-2x1", "--binary"],
        vec!["--binary"],
        vec!["--compensation", "off"],
        vec!["--compensation", "pixel"],
        vec!["--distortion", lens],
        vec!["--distortion", lens, "--binary", "--compensation", "off"],
        vec!["-p", "mirrored.toml"],
    ] {
        let mut a = vec![
            "slice",
            part,
            "-o",
            "part.dmdjob",
            "--layer-height",
            "0.5",
            "-q",
        ];
        a.extend_from_slice(&args);
        let o = run_in(&dir, &a);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        let o = run_in(&dir, &["run", "part.dmdjob", "--json"]);
        let r: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(o.status.code(), Some(0), "{args:?}: {r}");
        assert!(r["masks_verified"].as_u64().unwrap() >= 10, "{r}");
    }
}

#[test]
fn a_layer_naming_another_layers_mask_is_named() {
    // Every layer of the box has the same mask bytes, so a layer pointing at another
    // layer's file passes its checksum and shows the right section.
    let (dir, b) = sliced("shared");
    let mut j = job(&b);
    j["layers"][2]["masks"][0] = j["layers"][1]["masks"][0].clone();
    set_job(&b, &j);
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1, "{r}");
    assert_eq!(kinds(&r), vec!["mask-shared"]);
    let v = &r["violations"][0];
    assert_eq!(v["layer"], 2);
    assert_eq!(v["file"], "masks/00001.png");
    assert!(
        v["message"].as_str().unwrap().contains(
            "box.dmdjob/masks/00001.png: layer 2: the mask of projector 0 is the same file as layer 1's mask"
        ),
        "{v}"
    );
}

#[test]
fn corrupted_gray_map_is_named() {
    let (dir, b) = sliced("gray-map");
    let j = job(&b);
    let file = j["optics"]["gray_map"].as_str().unwrap().to_string();
    assert_eq!(file, "optics/p0-gray-map.png");
    let path = b.join(&file);
    let good = std::fs::read(&path).unwrap();

    let mut bytes = good.clone();
    let n = bytes.len();
    for x in &mut bytes[n / 2..n / 2 + 16] {
        *x ^= 0x5a;
    }
    std::fs::write(&path, &bytes).unwrap();
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1, "{r}");
    let v = &r["violations"][0];
    assert_eq!(v["kind"], "optics-file");
    assert_eq!(v["file"], file);
    assert_eq!(v["layer"], Value::Null);
    assert!(
        v["message"].as_str().unwrap().contains(
            "box.dmdjob/optics/p0-gray-map.png: gray map of projector 0: SHA-256 mismatch"
        ),
        "{v}"
    );
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stdout(&o).contains("job: optics-file: "), "{}", stdout(&o));

    // A gray map of the wrong size, its checksum updated.
    image::GrayImage::from_pixel(512, 384, image::Luma([200]))
        .save(&path)
        .unwrap();
    let mut j2 = j.clone();
    j2["optics"]["gray_map_sha256"] =
        dmdsl::bundle::sha256_hex(&std::fs::read(&path).unwrap()).into();
    set_job(&b, &j2);
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1);
    assert_eq!(kinds(&r), vec!["optics-file"]);
    assert!(r["violations"][0]["message"]
        .as_str()
        .unwrap()
        .contains("PNG is 512x384, projector p0 is 1024x768"));

    set_job(&b, &j);
    std::fs::remove_file(&path).unwrap();
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1);
    assert_eq!(kinds(&r), vec!["optics-file"]);
    assert!(r["violations"][0]["message"]
        .as_str()
        .unwrap()
        .ends_with("gray map of projector 0: gray map file is missing"));
    std::fs::write(&path, &good).unwrap();
    let (code, _) = run_json(&dir, &[]);
    assert_eq!(code, 0);
}

#[test]
fn a_job_without_layers_fails() {
    let (dir, b) = sliced("no-layers");
    let mut j = job(&b);
    j["layers"] = serde_json::json!([]);
    j["totals"]["layers"] = 0.into();
    j["totals"]["print_time_s"] = 0.0.into();
    set_job(&b, &j);
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1, "{r}");
    assert_eq!(kinds(&r), vec!["manifest"]);
    assert_eq!(r["violations"][0]["layer"], Value::Null);
    assert!(r["violations"][0]["message"]
        .as_str()
        .unwrap()
        .ends_with("box.dmdjob/job.json: the job has no layers"));
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stdout(&o).trim_end().ends_with("FAILED"), "{}", stdout(&o));
}

#[test]
fn machine_option_checks_the_job_on_the_real_machine() {
    let (dir, b) = sliced("machine");
    let clean = job(&b);
    let (code, r) = run_json(&dir, &["--machine", "xu2010-topdown"]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["machine"]["profile"], "xu2010-topdown");
    assert_eq!(r["machine"]["differences"], serde_json::json!([]));
    let o = run_in(&dir, &["run", "box.dmdjob", "--machine", "xu2010-topdown"]);
    assert!(
        stdout(&o).contains(
            "machine xu2010-topdown (--machine): the same stage, shutter, DMD and projectors as the job's"
        ),
        "{}",
        stdout(&o)
    );
    let (_, r) = run_json(&dir, &[]);
    assert_eq!(r["machine"], Value::Null);

    // The bundle's own machine raised to 50 mm/s, and layer 1's return move (5 mm at
    // 1 mm/s, 50 mm/s²) at 25 mm/s with the estimates to match: clean on the embedded
    // machine, a violation on the real one.
    let mut j = job(&b);
    j["machine"]["stage"]["max_speed_mm_s"] = 50.0.into();
    let step = &mut j["layers"][1]["steps"][1];
    assert_eq!(
        (step["kind"].as_str(), step["speed_mm_s"].as_f64()),
        (Some("move"), Some(1.0))
    );
    step["speed_mm_s"] = 25.0.into();
    let saved =
        dmdsl::motion::move_time(5.0, 1.0, 50.0) - dmdsl::motion::move_time(5.0, 25.0, 50.0);
    for key in ["/layers/1/time_s", "/totals/print_time_s"] {
        let t = j.pointer_mut(key).unwrap();
        *t = (t.as_f64().unwrap() - saved).into();
    }
    set_job(&b, &j);
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 0, "{r}");
    let (code, r) = run_json(&dir, &["--machine", "xu2010-topdown"]);
    assert_eq!(code, 1, "{r}");
    assert_eq!(
        r["machine"]["differences"],
        serde_json::json!([{"key": "stage.max_speed_mm_s", "job": "50", "machine": "10"}])
    );
    let v = &r["violations"][0];
    assert_eq!(
        (v["kind"].as_str(), v["layer"].as_u64()),
        (Some("speed"), Some(1))
    );
    assert!(v["message"]
        .as_str()
        .unwrap()
        .contains("25 mm/s exceeds the stage's max_speed_mm_s 10"));
    let o = run_in(&dir, &["run", "box.dmdjob", "--machine", "xu2010-topdown"]);
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        out.contains(
            "machine xu2010-topdown (--machine) differs from the job's: stage.max_speed_mm_s: job 50, machine 10\n"
        ),
        "{out}"
    );
    set_job(&b, &clean);

    // A machine file whose projector is narrower: the masks do not fit it.
    let o = run_in(&dir, &["profile", "show", "xu2010-topdown"]);
    let toml = stdout(&o).replace("width_px = 1024", "width_px = 1000");
    std::fs::write(dir.join("narrow.toml"), toml).unwrap();
    let (code, r) = run_json(&dir, &["--machine", "narrow.toml"]);
    assert_eq!(code, 1, "{r}");
    assert_eq!(
        r["machine"]["differences"],
        serde_json::json!([{"key": "projector[0].width_px", "job": "1024", "machine": "1000"}])
    );
    // The gray map is checked against the machine's projector too.
    assert_eq!(
        kinds(&r),
        vec![
            "optics-file",
            "mask-format",
            "mask-format",
            "mask-format",
            "mask-format"
        ],
        "{r}"
    );
    assert!(r["violations"][1]["message"]
        .as_str()
        .unwrap()
        .contains("PNG is 1024x768, projector p0 is 1000x768"));

    // More differences than the summary lists: the first four, then a count.
    let o = run_in(&dir, &["profile", "show", "bottom-up"]);
    let toml = stdout(&o).replace("load_s = 0.02", "load_s = 0.5");
    std::fs::write(dir.join("other.toml"), toml).unwrap();
    let o = run_in(&dir, &["run", "box.dmdjob", "--machine", "other.toml"]);
    let out = stdout(&o);
    assert!(
        out.contains(
            "machine bottom-up (--machine) differs from the job's: stage.travel_max_mm: job 120, machine 150; stage.max_accel_mm_s2: job 50, machine 20; shutter.open_s: job 0.05, machine 0; shutter.close_s: job 0.05, machine 0 (and 1 more, --json lists all)\n"
        ),
        "{out}"
    );

    // Two projectors: every layer lacks the second one's mask.
    let (code, r) = run_json(&dir, &["--machine", "tiled-2x1"]);
    assert_eq!(code, 1);
    assert!(of_kind(&r, "manifest").len() == 4, "{r}");
    assert!(r["violations"][0]["message"]
        .as_str()
        .unwrap()
        .contains("layer 0 has masks for 1 of the machine's 2 projectors"));

    // An unknown machine is a usage error.
    let o = run_in(&dir, &["run", "box.dmdjob", "--machine", "nope"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("nope"), "{}", stderr(&o));
}

/// Numbers no job can hold are refused as the manifest is read, naming the key (exit 2):
/// `fixtures/verdict/never-finishes.dmdjob.zip` (a move at 1e-308 mm/s, which ran "inf s"
/// and passed), `negative-area.dmdjob.zip`, and more set here. Numbers a job can hold
/// but that no estimate allows still give finite figures and violations.
#[test]
fn numbers_out_of_range_are_refused_and_every_figure_is_finite() {
    let (dir, b) = sliced("ranges");
    for (job, key) in [
        ("verdict/never-finishes.dmdjob.zip", "job.json: layers[2].steps[1].speed_mm_s = 1e-308 is not a speed a machine has (1e-6 to 10000.0; check its unit)"),
        ("verdict/negative-area.dmdjob.zip", "job.json: layers[1].area_mm2 = -1.0 is not an area of the 30.72 mm² field"),
    ] {
        let o = run_in(&dir, &["run", fixture(job).to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{job}");
        assert!(stderr(&o).ends_with(&format!("{key}\n")), "{job}: {}", stderr(&o));
    }
    let clean = job(&b);
    type Edit = fn(&mut Value);
    let cases: [(Edit, &str); 6] = [
        (
            |j| j["layers"][2]["steps"][1]["accel_mm_s2"] = 1e-308.into(),
            "layers[2].steps[1].accel_mm_s2 = 1e-308 is not an acceleration a machine has",
        ),
        (
            |j| j["layers"][1]["area_mm2"] = 1e308.into(),
            "layers[1].area_mm2 = 1e308 is not an area of the 3168.75 mm² field",
        ),
        (
            |j| j["layers"][1]["exposure_s"] = 1e308.into(),
            "layers[1].exposure_s = 1e308 is not a duration a machine has",
        ),
        (
            |j| j["layers"][2]["steps"][2]["s"] = (-1e300).into(),
            "layers[2].steps[2].s = -1e300 is not a duration",
        ),
        (
            |j| j["layers"][0]["bbox_mm"][0][0] = 99.0.into(),
            "layers[0].bbox_mm: the corners are not in order",
        ),
        (
            |j| j["totals"]["print_time_s"] = (-5.0).into(),
            "totals.print_time_s = -5.0 is negative",
        ),
    ];
    for (edit, says) in cases {
        let mut j = clean.clone();
        edit(&mut j);
        set_job(&b, &j);
        let o = run_in(&dir, &["run", "box.dmdjob"]);
        assert_eq!(o.status.code(), Some(2), "{says}");
        assert!(
            stderr(&o).contains(&format!("box.dmdjob/job.json: {says}")),
            "{}",
            stderr(&o)
        );
    }
    // Waits as long as a machine allows, in every layer: finite, and off the estimate.
    let mut j = clean.clone();
    for l in j["layers"].as_array_mut().unwrap() {
        l["steps"][2]["s"] = 999_999.0.into();
    }
    set_job(&b, &j);
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 1);
    for key in [
        "total_s",
        "estimate_diff_pct",
        "light_on_s",
        "wait_s",
        "shutter_open_s",
    ] {
        assert!(r[key].as_f64().is_some_and(f64::is_finite), "{key}: {r}");
    }
    assert!(kinds(&r).iter().all(|k| k == "estimate"), "{r}");
}

/// Peak memory of `run` on an archive follows the entries the job uses: an SL1 of
/// `fixtures/sl1/cube1.sl1` with 15 entries it does not use, each 250 MiB of zeros
/// deflated (3.66 GiB declared, 4 MB of file), used to be inflated whole (3.76 GB); it
/// runs in an address space of 1 GiB now.
#[cfg(target_os = "linux")]
#[test]
fn unused_large_entries_are_never_inflated() {
    use std::io::Write;
    use zip::write::SimpleFileOptions;
    let dir = tempdir("run-unused-entries");
    let cube = std::fs::read(fixture("sl1/cube1.sl1")).unwrap();
    let mut src = zip::ZipArchive::new(std::io::Cursor::new(cube)).unwrap();
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for i in 0..src.len() {
        w.raw_copy_file(src.by_index_raw(i).unwrap()).unwrap();
    }
    let deflated = SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .compression_level(Some(9));
    w.start_file("unused/00.bin", deflated).unwrap();
    let zeros = vec![0u8; 1 << 20];
    for _ in 0..250 {
        w.write_all(&zeros).unwrap();
    }
    let one = w.finish().unwrap().into_inner();
    let mut src = zip::ZipArchive::new(std::io::Cursor::new(one.clone())).unwrap();
    let mut w = zip::ZipWriter::new_append(std::io::Cursor::new(one)).unwrap();
    let big = src.index_for_name("unused/00.bin").unwrap();
    for k in 1..15 {
        let f = src.by_index_raw(big).unwrap();
        w.raw_copy_file_rename(f, format!("unused/{k:02}.bin"))
            .unwrap();
    }
    let bytes = w.finish().unwrap().into_inner();
    assert!(bytes.len() < 8 << 20, "{}", bytes.len());
    std::fs::write(dir.join("big.sl1"), &bytes).unwrap();
    let (o, code, peak) = run_limited(&dir, &["run", "big.sl1", "-q"], Some(1 << 30), None);
    assert_eq!(code, Some(0), "{}", stderr(&o));
    assert!(
        peak > 1 << 20,
        "the program's memory was read: {peak} bytes"
    );
    assert!(peak < 200 << 20, "peak {peak} bytes");
}
