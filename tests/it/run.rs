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
    let img = image::open(dir.join("p.png")).unwrap();
    assert!(img.width() > 500 && img.height() > 300);

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
            "unknown kind",
        ),
        (
            vec!["run", "box.dmdjob", "--fault", "stall@9"],
            "the job has 4 layers",
        ),
        (vec!["run", "box.dmdjob", "--layers", "3..7"], "--layers"),
        (
            vec!["run", "box.dmdjob", "--trace", "no/such/dir/t.csv"],
            "t.csv",
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
fn version_1_bundle_with_text_warnings_still_runs() {
    // Version 1 manifests stored warnings as text; `run` reads them (as code
    // `bundle.uncoded`) and replays the job as before.
    let (dir, b) = sliced("v1");
    let mut j = job(&b);
    assert_eq!(j["version"], 2);
    j["version"] = 1.into();
    j["warnings"] = serde_json::json!(["mesh has 3 open edges (holes)"]);
    set_job(&b, &j);
    let (code, r) = run_json(&dir, &[]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["violations"].as_array().unwrap().len(), 0);
    j["version"] = 3.into();
    set_job(&b, &j);
    let o = run_in(&dir, &["run", "box.dmdjob"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("unsupported version Some(3); this dmdsl reads versions 1 to 2"),
        "{}",
        stderr(&o)
    );
}
