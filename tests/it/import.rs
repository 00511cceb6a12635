//! `dmdsl run` and `dmdsl inspect` on jobs in one file: zipped bundles, PrusaSlicer SL1 /
//! SL1S files (`fixtures/sl1/`, made by PrusaSlicer 2.5), SLA control-file zips
//! (`fixtures/control/`), and hostile archives built here, each refused with one line
//! naming the archive and the entry, exit code 2, nothing extracted.

use crate::common::{fixture, run_in, stderr, stdout, tempdir, zip_entries};
use serde_json::Value;
use std::io::{Read, Write};
use std::path::Path;

/// `dmdsl ARGS --json` in `dir`: exit code and the JSON it printed.
fn json_run(dir: &Path, args: &[&str]) -> (i32, Value) {
    let mut a = args.to_vec();
    a.push("--json");
    let o = run_in(dir, &a);
    let v = serde_json::from_str(&stdout(&o)).unwrap_or_else(|e| {
        panic!("{args:?}: {e}: {}{}", stdout(&o), stderr(&o));
    });
    (o.status.code().unwrap(), v)
}

/// The value of `key` in the `key = value` lines of entry `entry` of zip `path` (read
/// with the zip crate: an oracle independent of dmdsl's reader).
fn ini_value(path: &Path, entry: &str, key: &str) -> String {
    let mut z = zip::ZipArchive::new(std::fs::File::open(path).unwrap()).unwrap();
    let mut text = String::new();
    z.by_name(entry).unwrap().read_to_string(&mut text).unwrap();
    text.lines()
        .filter_map(|l| l.split_once('='))
        .find(|(k, _)| k.trim() == key)
        .map(|(_, v)| v.trim().to_string())
        .unwrap()
}

#[test]
fn prusaslicer_files_run_at_prusaslicers_own_print_time() {
    let dir = tempdir("sl1-print-time");
    for (name, format, layers) in [
        ("sl1/cube3mm.sl1", "sl1", 30),
        ("sl1/cylinder_hole.sl1s", "sl1s", 25),
        ("sl1/cylinder_slow.sl1", "sl1", 20),
    ] {
        let path = fixture(name);
        let (code, r) = json_run(&dir, &["run", path.to_str().unwrap()]);
        assert_eq!(code, 0, "{name}: {r}");
        assert_eq!(r["ok"], true);
        assert_eq!(r["format"], format, "{name}");
        assert_eq!(r["layers"], layers, "{name}");
        assert_eq!(r["violations"].as_array().unwrap().len(), 0, "{name}: {r}");
        assert_eq!(r["estimate_source"], "PrusaSlicer printTime (config.ini)");
        let print_time: f64 = ini_value(&path, "config.ini", "printTime").parse().unwrap();
        assert_eq!(r["estimate_s"].as_f64().unwrap(), print_time, "{name}");
        let total = r["total_s"].as_f64().unwrap();
        let diff = (total - print_time) / print_time;
        assert!(
            diff.abs() < 0.01,
            "{name}: simulated {total} s, printTime {print_time} s"
        );
        // The model reproduces PrusaSlicer's estimate, not just within 1 %.
        assert!(
            diff.abs() < 1e-6,
            "{name}: simulated {total} s, printTime {print_time} s"
        );
        // The layer areas measured on the masks (which decide fast or slow tilt) add up to
        // the resin PrusaSlicer computed from its polygons (usedMaterial, ml).
        let (code, summary) = json_run(&dir, &["inspect", path.to_str().unwrap()]);
        assert_eq!(code, 0);
        let used: f64 = ini_value(&path, "config.ini", "usedMaterial")
            .parse()
            .unwrap();
        let ours = summary["resin_volume_ml"].as_f64().unwrap();
        assert!(
            (ours - used).abs() / used < 2e-3,
            "{name}: {ours} ml, usedMaterial {used} ml"
        );
    }
    // The content says what a file is, not its extension.
    std::fs::copy(fixture("sl1/cube3mm.sl1"), dir.join("renamed.zip")).unwrap();
    let (code, r) = json_run(&dir, &["run", "renamed.zip"]);
    assert_eq!((code, &r["format"]), (0, &Value::from("sl1")));
}

#[test]
fn slow_layers_count_by_area_as_prusaslicer_counts_them() {
    // PrusaSlicer counted every layer of this file slow (numSlow) and none fast.
    let path = fixture("sl1/cylinder_slow.sl1");
    assert_eq!(ini_value(&path, "config.ini", "numSlow"), "20");
    assert_eq!(ini_value(&path, "config.ini", "numFast"), "0");
    let dir = tempdir("sl1-slow");
    let (_, r) = json_run(&dir, &["run", path.to_str().unwrap()]);
    // A slow layer: 0.25 mm × 5 s/mm tower + 5 s slow tilt (SL1 default) + 1 s delay, plus
    // the exposure (8 s after the 3 faded layers).
    let last = &r["per_layer"].as_array().unwrap()[19];
    assert!(
        (last["time_s"].as_f64().unwrap() - (1.25 + 8.0 + 1.0 + 8.0)).abs() < 1e-6,
        "{last}"
    );
}

#[test]
fn control_file_zip_runs_with_the_steps_its_settings_give() {
    let dir = tempdir("control");
    let path = fixture("control/channel.zip");
    let (code, r) = json_run(&dir, &["run", path.to_str().unwrap()]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(r["format"], "sla-control");
    assert_eq!(r["estimate_source"], "import steps");
    // burn-in, 2 × base, 2 × (walls + edge), roof: 8 exposures.
    assert_eq!(r["layers"], 8);
    let per: Vec<f64> = r["per_layer"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["time_s"].as_f64().unwrap())
        .collect();
    // Layer 0 by hand: initial wait 0.1; 0.3 mm up at 2 mm/s, 20 mm/s² (0.2 s ramping,
    // 0.1 mm cruising: 0.25 s); up wait 0.2; 0.28 mm down at 1 mm/s, 10 mm/s² (0.2 s +
    // 0.18 s); wait 0.02, expose 2.0, wait 0.01; final wait 0.05.
    assert!((per[0] - 3.01).abs() < 1e-6, "{per:?}");
    // The edge image of a channel layer: no move, its own exposure 0.15 s between its
    // waits, then the layer's final wait.
    assert!(
        (per[4] - (0.02 + 0.15 + 0.01 + 0.05)).abs() < 1e-6,
        "{per:?}"
    );
    let exp: Vec<f64> = r["per_layer"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["exposure_s"].as_f64().unwrap())
        .collect();
    assert_eq!(exp, [2.0, 0.4, 0.4, 0.4, 0.15, 0.4, 0.15, 0.6]);
}

/// A zip of `entries` written by the zip crate (each stored or deflated).
fn zip_of(entries: &[(&str, &[u8], bool)]) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, data, stored) in entries {
        let method = if *stored {
            zip::CompressionMethod::Stored
        } else {
            zip::CompressionMethod::Deflated
        };
        let o = zip::write::SimpleFileOptions::default().compression_method(method);
        w.start_file(*name, o).unwrap();
        w.write_all(data).unwrap();
    }
    w.finish().unwrap().into_inner()
}

/// The files of bundle directory `dir`, `job.json` first, as `(name, bytes)`.
fn bundle_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = vec![(
        "job.json".to_string(),
        std::fs::read(dir.join("job.json")).unwrap(),
    )];
    let mut stack = vec![dir.to_path_buf()];
    let mut rest = Vec::new();
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p
                    .strip_prefix(dir)
                    .unwrap()
                    .to_str()
                    .unwrap()
                    .replace('\\', "/");
                if rel != "job.json" {
                    rest.push((rel, std::fs::read(&p).unwrap()));
                }
            }
        }
    }
    rest.sort();
    out.extend(rest);
    out
}

#[test]
fn a_zipped_bundle_runs_and_inspects_as_its_directory() {
    let dir = tempdir("dmdjob-zip");
    let cube = fixture("cube10.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            cube.to_str().unwrap(),
            "-o",
            "cube.dmdjob",
            "--layer-height",
            "0.5",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let files = bundle_files(&dir.join("cube.dmdjob"));
    let entries: Vec<(&str, &[u8], bool)> = files
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice(), n.ends_with(".png")))
        .collect();
    std::fs::write(dir.join("cube.dmdjob.zip"), zip_of(&entries)).unwrap();
    let (c1, mut a) = json_run(&dir, &["run", "cube.dmdjob"]);
    let (c2, mut b) = json_run(&dir, &["run", "cube.dmdjob.zip"]);
    assert_eq!((c1, c2), (0, 0), "{b}");
    assert_eq!(
        (&a["format"], &b["format"]),
        (&Value::from("dmdjob"), &Value::from("dmdjob-zip"))
    );
    for r in [&mut a, &mut b] {
        let o = r.as_object_mut().unwrap();
        for k in ["bundle", "format", "timings"] {
            o.remove(k);
        }
    }
    assert_eq!(a, b);
    let (code, s) = json_run(
        &dir,
        &["inspect", "cube.dmdjob.zip", "--contact-sheet", "s.png"],
    );
    assert_eq!(code, 0, "{s}");
    assert_eq!(s["format"], "dmdjob-zip");
    assert!(dir.join("s.png").is_file());
    // A mask changed inside the zip is found as in a directory.
    let mut bad = files.clone();
    let k = bad
        .iter()
        .position(|(n, _)| n.ends_with("00003.png"))
        .unwrap();
    bad[k].1 = b"not a png".to_vec();
    let entries: Vec<(&str, &[u8], bool)> = bad
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice(), true))
        .collect();
    std::fs::write(dir.join("bad.dmdjob.zip"), zip_of(&entries)).unwrap();
    let (code, r) = json_run(&dir, &["run", "bad.dmdjob.zip"]);
    assert_eq!(code, 1);
    let kinds: Vec<&str> = r["violations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["kind"].as_str().unwrap())
        .collect();
    assert!(
        kinds.contains(&"mask-checksum") && kinds.contains(&"mask-decode"),
        "{kinds:?}"
    );
}

#[test]
fn the_zipped_bundle_fixture_runs_clean() {
    let dir = tempdir("zip-fixture");
    let p = fixture("zip/cube5.dmdjob.zip");
    let (code, r) = json_run(&dir, &["run", p.to_str().unwrap()]);
    assert_eq!(code, 0, "{r}");
    assert_eq!(
        (&r["format"], &r["layers"]),
        (&Value::from("dmdjob-zip"), &Value::from(5))
    );
    assert_eq!(r["estimate_source"], "planner");
}

#[test]
fn inspect_reads_imported_jobs() {
    let dir = tempdir("inspect-imported");
    for (name, format) in [
        ("sl1/cylinder_hole.sl1s", "sl1s"),
        ("control/channel.zip", "sla-control"),
    ] {
        let p = fixture(name);
        let (code, s) = json_run(
            &dir,
            &["inspect", p.to_str().unwrap(), "--contact-sheet", "s.png"],
        );
        assert_eq!(code, 0, "{s}");
        assert_eq!(s["format"], format);
    }
    // What the reader could not take as stated is in the summary, as `run` says it.
    let p = fixture("sla_control/example.zip");
    let (code, s) = json_run(&dir, &["inspect", p.to_str().unwrap()]);
    assert_eq!(code, 0, "{s}");
    let notes = s["notes"].to_string();
    assert!(
        notes.contains("Print on film") && notes.contains("no pixel size stated"),
        "{s}"
    );
    let o = run_in(&dir, &["inspect", p.to_str().unwrap()]);
    let out = stdout(&o);
    assert!(
        out.contains("note: not simulated: Squeeze out resin"),
        "{out}"
    );
    // Without a pixel size the areas and the resin are counts of a stand-in pixel: not
    // shown as measurements.
    assert!(out.contains("resin not measured (no pixel size)"), "{out}");
    assert!(
        out.lines()
            .any(|l| l.contains("largest area") && l.contains("not measured")),
        "{out}"
    );
    let o = run_in(
        &dir,
        &["inspect", fixture("control/channel.zip").to_str().unwrap()],
    );
    assert!(stdout(&o).contains("resin not measured"), "{}", stdout(&o));
    let o = run_in(
        &dir,
        &["inspect", fixture("sl1/cube3mm.sl1").to_str().unwrap()],
    );
    assert!(
        !stdout(&o).contains("not measured") && stdout(&o).contains(" ml"),
        "{}",
        stdout(&o)
    );
}

#[test]
fn an_imported_job_states_no_section_figures() {
    // A file's images are not sections: it has no fill distances or islands to report,
    // and neither has a bundle exported from it.
    let dir = tempdir("import-sections");
    let sl1 = fixture("sl1/cube3mm.sl1");
    let o = run_in(
        &dir,
        &["export", sl1.to_str().unwrap(), "-o", "cube.dmdjob", "-q"],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("cube.dmdjob/job.json")).unwrap()).unwrap();
    let schemas = crate::schema::Schemas::load();
    schemas.assert_valid("job.schema.json", &job);
    for l in job["layers"].as_array().unwrap() {
        assert!(l.get("max_fill_distance_mm").is_none() && l.get("islands").is_none());
    }
    for job in [sl1.to_str().unwrap(), "cube.dmdjob"] {
        let _ = std::fs::remove_file(dir.join("c.png"));
        let (code, s) = json_run(&dir, &["inspect", job]);
        assert_eq!(code, 0, "{s}");
        schemas.assert_valid("inspect-summary.schema.json", &s);
        let e = &s["extremes"];
        assert!(
            e["max_fill_distance_mm"].is_null() && e["islands"].is_null(),
            "{e}"
        );
        assert!(e["area_mm2"]["value"].as_f64().unwrap() > 0.0, "{e}");
        let out = stdout(&run_in(&dir, &["inspect", job, "--chart", "c.png"]));
        assert!(out.contains("imported from cube3mm.sl1"), "{out}");
        // In the value column, where the known figures end (before their layer).
        let area = out.lines().find(|l| l.contains("largest area")).unwrap();
        let column = area.find("  layer").unwrap();
        for what in ["largest fill distance", "most islands on nothing"] {
            let line = out.lines().find(|l| l.contains(what)).unwrap_or_default();
            assert!(line.ends_with(" not in the file"), "{out}");
            assert_eq!(
                line.chars().count(),
                area[..column].chars().count(),
                "{out}"
            );
        }
        assert!(dir.join("c.png").is_file());
    }
}

/// Runs `dmdsl run FILE` on archive bytes `bytes` in a fresh directory and checks the
/// refusal: exit code 2, one line naming the archive and each of `words`, nothing else
/// written there.
fn refused(name: &str, bytes: &[u8], words: &[&str]) {
    let dir = tempdir(&format!("hostile-{name}"));
    let file = format!("{name}.zip");
    std::fs::write(dir.join(&file), bytes).unwrap();
    let o = run_in(&dir, &["run", &file]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{name}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
    assert!(err.contains(&file), "{name}: {err}");
    for w in words {
        assert!(err.contains(w), "{name}: {err:?} lacks {w:?}");
    }
    let left: Vec<_> = std::fs::read_dir(&*dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        left,
        [std::ffi::OsString::from(&file)],
        "{name}: something was written"
    );
}

/// Offsets of the central directory headers (`PK\x01\x02`) and local headers
/// (`PK\x03\x04`) of `zip`.
fn headers(zip: &[u8], sig: &[u8; 4]) -> Vec<usize> {
    zip.windows(4)
        .enumerate()
        .filter(|(_, w)| w == sig)
        .map(|(i, _)| i)
        .collect()
}

fn put_u16(b: &mut [u8], at: usize, v: u16) {
    b[at..at + 2].copy_from_slice(&v.to_le_bytes());
}

fn put_u32(b: &mut [u8], at: usize, v: u32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

const CENTRAL: &[u8; 4] = b"PK\x01\x02";
const LOCAL: &[u8; 4] = b"PK\x03\x04";

#[test]
fn hostile_not_a_zip() {
    refused("notzip", b"this is not an archive at all", &["not a job"]);
}

#[test]
fn a_directory_that_is_not_a_bundle_is_named_as_such() {
    let dir = tempdir("not-a-bundle");
    std::fs::create_dir(dir.join("parts")).unwrap();
    for cmd in ["run", "inspect"] {
        let o = run_in(&dir, &[cmd, "parts"]);
        assert_eq!(o.status.code(), Some(2), "{cmd}");
        let e = stderr(&o);
        assert!(
            e.starts_with("dmdsl: error: parts: not a job: a directory without `job.json`"),
            "{cmd}: {e}"
        );
        assert_eq!(e.trim_end().lines().count(), 1, "{cmd}: {e}");
    }
}

#[test]
fn hostile_truncated_archive() {
    let b = std::fs::read(fixture("sl1/cube3mm.sl1")).unwrap();
    refused(
        "truncated",
        &b[..b.len() / 2],
        &["not a readable zip archive"],
    );
}

#[test]
fn hostile_parent_directory_entry() {
    refused(
        "dotdot",
        &zip_of(&[("../job.json", b"{}", true)]),
        &["../job.json", "`..`"],
    );
}

#[test]
fn hostile_absolute_entry() {
    refused(
        "absolute",
        &zip_of(&[("/etc/job.json", b"{}", true)]),
        &["/etc/job.json", "absolute"],
    );
}

#[test]
fn hostile_backslash_entry() {
    refused(
        "backslash",
        &zip_of(&[("masks\\a.png", b"x", true)]),
        &["backslash"],
    );
}

#[test]
fn hostile_duplicate_names() {
    // Two entries whose names differ in one byte, then made equal in place.
    let mut z = zip_of(&[
        ("config.ini", b"a = 1", true),
        ("config.inj", b"b = 2", true),
    ]);
    let at: Vec<usize> = z
        .windows(10)
        .enumerate()
        .filter(|(_, w)| w == b"config.inj")
        .map(|(i, _)| i)
        .collect();
    assert_eq!(at.len(), 2);
    for i in at {
        z[i + 9] = b'i';
    }
    refused("duplicate", &z, &["config.ini", "appears twice"]);
}

#[test]
fn hostile_declared_size_too_large() {
    // A bomb announces itself: an entry declaring 4 GB is refused before inflating.
    let mut z = zip_of(&[("job.json", b"{}", false)]);
    for c in headers(&z, CENTRAL) {
        put_u32(&mut z, c + 24, 0xFFFF_FFF0);
    }
    for l in headers(&z, LOCAL) {
        put_u32(&mut z, l + 22, 0xFFFF_FFF0);
    }
    refused(
        "bomb-declared",
        &z,
        &["job.json", "declared size 4294967280"],
    );
}

#[test]
fn hostile_entry_larger_than_declared() {
    // A bomb that lies: 1 MB of zeros declared as 100 bytes stops at 101.
    let zeros = vec![0u8; 1 << 20];
    let mut z = zip_of(&[("job.json", &zeros, false)]);
    for c in headers(&z, CENTRAL) {
        put_u32(&mut z, c + 24, 100);
    }
    for l in headers(&z, LOCAL) {
        put_u32(&mut z, l + 22, 100);
    }
    refused("bomb-lie", &z, &["job.json", "larger than its declared"]);
}

#[test]
fn hostile_encrypted_entry() {
    let mut z = zip_of(&[("job.json", b"{}", true)]);
    for c in headers(&z, CENTRAL) {
        z[c + 8] |= 1;
    }
    for l in headers(&z, LOCAL) {
        z[l + 6] |= 1;
    }
    refused("encrypted", &z, &["job.json", "encrypted"]);
}

#[test]
fn hostile_unsupported_method() {
    let mut z = zip_of(&[("job.json", b"{}", true)]);
    for c in headers(&z, CENTRAL) {
        put_u16(&mut z, c + 10, 12); // bzip2
    }
    for l in headers(&z, LOCAL) {
        put_u16(&mut z, l + 8, 12);
    }
    refused("method", &z, &["job.json", "not supported"]);
}

#[test]
fn hostile_symbolic_link() {
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    w.add_symlink(
        "job.json",
        "/etc/passwd",
        zip::write::SimpleFileOptions::default(),
    )
    .unwrap();
    let z = w.finish().unwrap().into_inner();
    refused("symlink", &z, &["job.json", "symbolic link"]);
}

#[test]
fn hostile_sl1_without_a_key() {
    let mut files = zip_entries(&fixture("sl1/cube3mm.sl1"));
    for (name, b) in &mut files {
        if name == "config.ini" {
            let t = String::from_utf8(std::mem::take(b)).unwrap();
            *b = t
                .lines()
                .filter(|l| !l.starts_with("expTime "))
                .collect::<Vec<_>>()
                .join("\n")
                .into_bytes();
        }
    }
    let entries: Vec<(&str, &[u8], bool)> = files
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice(), true))
        .collect();
    refused(
        "sl1-key",
        &zip_of(&entries),
        &["config.ini", "missing key `expTime`"],
    );
}

#[test]
fn hostile_control_file_failing_the_schema() {
    let files = zip_entries(&fixture("control/channel.zip"));
    let json = |f: &dyn Fn(&mut Value)| {
        let mut out = files.clone();
        let mut v: Value = serde_json::from_slice(&out[0].1).unwrap();
        f(&mut v);
        out[0].1 = serde_json::to_vec(&v).unwrap();
        let e: Vec<(&str, &[u8], bool)> = out
            .iter()
            .map(|(n, b)| (n.as_str(), b.as_slice(), true))
            .collect();
        zip_of(&e)
    };
    assert_eq!(files[0].0, "print_settings.json");
    refused(
        "control-version",
        &json(&|v| v["Header"]["Schema version"] = "4.0.0".into()),
        &["print_settings.json", "Schema version"],
    );
    refused(
        "control-type",
        &json(&|v| {
            v["Default layer settings"]["Position settings"]["Distance up (mm)"] = "far".into()
        }),
        &[
            "print_settings.json",
            "Distance up (mm)",
            "\"far\" is not of type \"number\"",
        ],
    );
    refused(
        "control-exposure",
        &json(&|v| {
            v["Layers"][0]["Image settings list"][0]["Layer exposure time (ms)"] = 20000.into()
        }),
        &["print_settings.json", "Layers[0]", "10000"],
    );
    refused(
        "control-circle",
        &json(&|v| {
            v["Named image settings"]["short"]["Using named image settings"] = "edge".into();
        }),
        &["print_settings.json", "circle", "edge -> short -> edge"],
    );
    refused(
        "control-variable",
        &json(&|v| v["Variables"]["base_ms"] = "${nowhere * 2}".into()),
        &["print_settings.json", "`nowhere` is not a variable"],
    );
    refused(
        "control-missing",
        &json(&|v| {
            v["Default layer settings"]["Image settings"]
                .as_object_mut()
                .unwrap()
                .remove("Image file");
        }),
        &["print_settings.json", "Image file"],
    );
}

#[test]
fn problems_of_an_imported_job_are_violations() {
    // An SL1 whose layer 4 mask is missing and layer 7 mask is the wrong size.
    let mut files = zip_entries(&fixture("sl1/cube3mm.sl1"));
    let small = {
        let mut out = Vec::new();
        image::GrayImage::new(16, 8)
            .write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .unwrap();
        out
    };
    files.retain(|(n, _)| n != "cube3mm00004.png");
    for (n, b) in &mut files {
        if n == "cube3mm00007.png" {
            *b = small.clone();
        }
    }
    let entries: Vec<(&str, &[u8], bool)> = files
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice(), true))
        .collect();
    let dir = tempdir("imported-violations");
    std::fs::write(dir.join("x.sl1"), zip_of(&entries)).unwrap();
    let (code, r) = json_run(&dir, &["run", "x.sl1"]);
    assert_eq!(code, 1);
    let found: Vec<(u64, &str)> = r["violations"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|v| v["kind"] != "estimate")
        .map(|v| (v["layer"].as_u64().unwrap(), v["kind"].as_str().unwrap()))
        .collect();
    assert_eq!(found, [(4, "mask-missing"), (7, "mask-format")], "{r}");
}

/// The archive `base` with its print settings edited by `edit` (entry order kept).
fn control_edited(base: &Path, edit: &dyn Fn(&mut Value)) -> Vec<u8> {
    let mut files = zip_entries(base);
    let i = files
        .iter()
        .position(|(n, _)| n.ends_with(".json"))
        .unwrap();
    let mut v: Value = serde_json::from_slice(&files[i].1).unwrap();
    edit(&mut v);
    files[i].1 = serde_json::to_vec(&v).unwrap();
    let e: Vec<(&str, &[u8], bool)> = files
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice(), true))
        .collect();
    zip_of(&e)
}

#[test]
fn control_files_breaking_the_schema_are_refused() {
    // The reproducers: edits of channel.zip that the standard's schema (or its rules)
    // refuse, each refused with one line naming the place.
    let cases: Value =
        serde_json::from_slice(&std::fs::read(fixture("control/schema_breaking.json")).unwrap())
            .unwrap();
    let cases = cases["cases"].as_array().unwrap();
    assert!(cases.len() >= 16);
    for c in cases {
        let name = format!("schema-{}", c["name"].as_str().unwrap());
        let path = c["path"].as_str().unwrap();
        let bytes = control_edited(&fixture("control/channel.zip"), &|v| {
            // A JSON pointer: `~1` is a `/` in a key, `~0` a `~`.
            let (parent, key) = path.rsplit_once('/').unwrap();
            let key = &key.replace("~1", "/").replace("~0", "~");
            let parent = v.pointer_mut(parent).unwrap();
            match parent {
                Value::Array(a) => a[key.parse::<usize>().unwrap()] = c["value"].clone(),
                p => p[key] = c["value"].clone(),
            }
        });
        let says: Vec<&str> = c["says"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s.as_str().unwrap())
            .collect();
        let mut words = vec!["print_settings.json"];
        words.extend(says);
        refused(&name, &bytes, &words);
    }
}

/// The standard's example and its printer (fixtures/sla_control, CC BY 4.0).
fn example() -> (std::path::PathBuf, std::path::PathBuf) {
    (
        fixture("sla_control/example.zip"),
        fixture("sla_control/hardware_config_example.json"),
    )
}

/// Kinds and messages of a report's violations.
fn found(r: &Value) -> Vec<(String, String)> {
    r["violations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| {
            (
                v["kind"].as_str().unwrap().into(),
                v["message"].as_str().unwrap().into(),
            )
        })
        .collect()
}

#[test]
fn the_standards_example_runs_clean_on_what_it_states() {
    let dir = tempdir("example");
    let (zip, _) = example();
    let (code, r) = json_run(&dir, &["run", zip.to_str().unwrap()]);
    assert_eq!((code, found(&r)), (0, vec![]), "{r:.800}");
    // What the file does not state is not checked, and the report says so.
    let unchecked = r["unchecked"].to_string();
    for k in [
        "stage.max_speed_mm_s",
        "stage.max_accel_mm_s2",
        "stage.travel_max_mm",
        "projector[].pixel_mm",
    ] {
        assert!(unchecked.contains(k), "{unchecked}");
    }
    let notes = r["notes"].to_string();
    for w in [
        "Print on film",
        "Squeeze out resin",
        "0 um layer",
        "not measured",
    ] {
        assert!(notes.contains(w), "{notes}");
    }
    // Each image its own record: 1 + 2 (burn-in layer) + 3 × 2 (duplicated) + 2 (group) + 2.
    assert_eq!(r["layers"], 12);
    // The imported machine: an engine per light engine, offset and mirroring.
    let job = dmdsl::formats::open(&zip).unwrap();
    let names: Vec<&str> = job
        .manifest
        .machine
        .projector
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    assert_eq!(
        names,
        [
            "visitech",
            "visitech at (0, 0) um, mirrored along its long axis",
            "visitech at (2500, 0) um",
            "wintech"
        ]
    );
    let p = &job.manifest.machine.projector;
    assert!(p[1].mirror_x && !p[1].mirror_y);
    assert_eq!((p[2].offset_px, p[3].wavelength_nm), ([2500, 0], Some(365)));
    // Given a pixel size, the same pixels measure: areas and offsets in mm.
    let (code, r) = json_run(
        &dir,
        &[
            "run",
            zip.to_str().unwrap(),
            "--set",
            "projector.0.pixel_mm=0.0076",
            "--set",
            "projector.1.pixel_mm=0.0076",
            "--set",
            "projector.2.pixel_mm=0.0076",
            "--set",
            "projector.3.pixel_mm=0.0076",
        ],
    );
    assert_eq!(code, 0, "{r:.600}");
    assert!(
        !r["unchecked"].to_string().contains("pixel_mm"),
        "{}",
        r["unchecked"]
    );
    // A limit given with --set is checked: the fast peel's 50 mm/s.
    let (code, r) = json_run(
        &dir,
        &[
            "run",
            zip.to_str().unwrap(),
            "--set",
            "stage.max_speed_mm_s=30",
        ],
    );
    assert_eq!(code, 1);
    let f = found(&r);
    assert!(
        f.iter()
            .all(|(k, m)| k == "speed" && m.contains("50 mm/s") && m.contains("30")),
        "{f:?}"
    );
    // A DMD load time the file does not have is not held against its own timing.
    let (code, r) = json_run(
        &dir,
        &["run", zip.to_str().unwrap(), "--set", "dmd.load_s=0.5"],
    );
    assert_eq!((code, found(&r)), (0, vec![]), "{r:.600}");
    assert!(r["notes"].to_string().contains("estimate: not checked"));
    assert!(r["total_s"].as_f64().unwrap() > r["estimate_s"].as_f64().unwrap() + 0.1);
}

#[test]
fn the_standards_example_on_its_printer_reports_what_the_printer_cannot_do() {
    let dir = tempdir("example-printer");
    let (zip, hw) = example();
    let run = |hw: &Path| {
        json_run(
            &dir,
            &[
                "run",
                zip.to_str().unwrap(),
                "--machine",
                hw.to_str().unwrap(),
            ],
        )
    };
    let (code, r) = run(&hw);
    assert_eq!(code, 1);
    let f = found(&r);
    let kinds: Vec<&str> = f.iter().map(|(k, _)| k.as_str()).collect();
    // The fast peel (50 mm/s, 500 mm/s²) up and down, and wintech's image size.
    assert_eq!(
        kinds,
        ["hardware", "speed", "accel", "speed", "accel"],
        "{f:?}"
    );
    let size = &f[0].1;
    for w in [
        "layer 11",
        "Layers[4].Image settings list[1]",
        "slices/0005.png",
        "2560 × 1600",
        "wintech.resolution",
    ] {
        assert!(size.contains(w), "{size}");
    }
    assert!(
        f[1].1.contains("galil.axes_speed.D") && f[2].1.contains("galil.axes_acceleration.D"),
        "{f:?}"
    );
    assert_eq!(r["machine"]["profile"], "hardware_config_example.json");
    // Edited printers: what each lacks is named with its key, layer and image.
    let config: Value = serde_json::from_slice(&std::fs::read(&hw).unwrap()).unwrap();
    // (name, the edit of the description, words the finding holds)
    type Case<'a> = (&'a str, &'a dyn Fn(&mut Value), &'a [&'a str]);
    let cases: [Case; 4] = [
        (
            "no-wintech",
            &|c| c["light_engines"] = serde_json::json!(["visitech"]),
            &[
                "light engine 'wintech' is not on this printer",
                "light_engines",
                "slices/0005.png",
            ],
        ),
        (
            "no-405",
            &|c| c["visitech"]["leds_nm"] = serde_json::json!([365]),
            &[
                "no 405 nm LED",
                "visitech.leds_nm",
                "slices/0004.png",
                "layer 10",
            ],
        ),
        (
            "no-xy",
            &|c| c["stages"]["xy_stage"] = "".into(),
            &["needs an XY stage", "stages.xy_stage", "slices/0003a.png"],
        ),
        (
            "no-gray",
            &|c| c["visitech"]["grayscale_correction_image"] = serde_json::json!([]),
            &[
                "grayscale correction",
                "visitech.grayscale_correction_image",
                "slices/0002.png",
            ],
        ),
    ];
    for (name, edit, words) in cases {
        let mut c = config.clone();
        edit(&mut c);
        let path = dir.join(format!("{name}.json"));
        std::fs::write(&path, serde_json::to_vec(&c).unwrap()).unwrap();
        let (code, r) = run(&path);
        assert_eq!(code, 1, "{name}");
        let hw: Vec<String> = found(&r)
            .into_iter()
            .filter(|(k, _)| k == "hardware")
            .map(|(_, m)| m)
            .collect();
        assert!(
            hw.iter().any(|m| words.iter().all(|w| m.contains(w))),
            "{name}: {hw:?}"
        );
    }
    // The printer the example fits: no finding, only the fast peel.
    let mut c = config.clone();
    c["wintech"]["resolution"] = serde_json::json!([2560, 1600]);
    std::fs::write(dir.join("fits.json"), serde_json::to_vec(&c).unwrap()).unwrap();
    let (_, r) = run(&dir.join("fits.json"));
    assert!(found(&r).iter().all(|(k, _)| k != "hardware"), "{r:.600}");
    // A malformed description: one line naming file and key, exit 2.
    for (name, text, key) in [
        (
            "bad-axis",
            r#"{"stages": {"bp_stage": "galil"}, "galil": {"default_axis": "D", "axes_travel": {"D": "far"}}}"#,
            "galil.axes_travel.D",
        ),
        (
            "bad-engine",
            r#"{"stages": {"bp_stage": "g"}, "g": {"axes": ["Z"], "axes_travel": {"Z": 100}, "axes_ctspmm": {"Z": 1000}, "axes_speed": {"Z": 5}, "axes_acceleration": {"Z": 5}}, "light_engines": ["e"], "e": {"resolution": [1920]}}"#,
            "e.resolution",
        ),
        ("not-json", "{", "not JSON"),
    ] {
        let path = dir.join(format!("{name}.json"));
        std::fs::write(&path, text).unwrap();
        let o = run_in(
            &dir,
            &[
                "run",
                zip.to_str().unwrap(),
                "--machine",
                path.to_str().unwrap(),
            ],
        );
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(
            err.contains(&format!("{name}.json")) && err.contains(key),
            "{name}: {err}"
        );
    }
}

#[test]
fn sl1_files_keep_their_mirroring_and_state_their_resin() {
    let dir = tempdir("sl1-mirror");
    let part = fixture("cube10.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            part.to_str().unwrap(),
            "--scale",
            "0.2",
            "-q",
            "-o",
            "m.sl1",
            "--set",
            "projector.0.mirror_x=true",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let job = dmdsl::formats::open(&dir.join("m.sl1")).unwrap();
    assert!(job.manifest.machine.projector[0].mirror_x);
    let used: f64 = ini_value(&dir.join("m.sl1"), "config.ini", "usedMaterial")
        .parse()
        .unwrap();
    assert_eq!(job.manifest.totals.resin_volume_ml, used);
    let (code, r) = json_run(&dir, &["run", "m.sl1"]);
    assert_eq!((code, found(&r)), (0, vec![]), "{r:.600}");
    let o = run_in(&dir, &["export", "m.sl1", "-o", "again.sl1", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        ini_value(
            &dir.join("again.sl1"),
            "prusaslicer.ini",
            "display_mirror_x"
        ),
        "1"
    );
    // PrusaSlicer's own file: the area from the masks' half-lit pixels, the resin stated.
    let path = fixture("sl1/cube3mm.sl1");
    let job = dmdsl::formats::open(&path).unwrap();
    let used: f64 = ini_value(&path, "config.ini", "usedMaterial")
        .parse()
        .unwrap();
    assert_eq!(job.manifest.totals.resin_volume_ml, used);
    assert!(job
        .notes
        .iter()
        .any(|n| n.contains("layer areas are estimates")));
}

#[test]
fn hostile_nanodlp_plates_are_one_line_and_exit_2() {
    let dir = tempdir("hostile-nanodlp");
    let part = fixture("cube10.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            part.to_str().unwrap(),
            "--scale",
            "0.1",
            "-q",
            "-o",
            "p.nanodlp",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let files = zip_entries(&dir.join("p.nanodlp"));
    // An edit of one JSON entry's value (a JSON pointer), or an entry dropped.
    let edited = |entry: &str, pointer: &str, value: Value| -> Vec<u8> {
        let mut files = files.clone();
        let f = files.iter_mut().find(|(n, _)| n == entry).unwrap();
        let mut v: Value = serde_json::from_slice(&f.1).unwrap();
        *v.pointer_mut(pointer).unwrap() = value;
        f.1 = serde_json::to_vec(&v).unwrap();
        let e: Vec<(&str, &[u8], bool)> = files
            .iter()
            .map(|(n, b)| (n.as_str(), b.as_slice(), true))
            .collect();
        zip_of(&e)
    };
    let cases: [(&str, &str, &str, Value, &[&str]); 8] = [
        (
            "cure-text",
            "profile.json",
            "/CureTime",
            "abc".into(),
            &["profile.json", "`CureTime`"],
        ),
        (
            "cure-negative",
            "profile.json",
            "/CureTime",
            (-5).into(),
            &["`CureTime` is -5"],
        ),
        (
            "cure-huge",
            "profile.json",
            "/CureTime",
            1e308.into(),
            &["`CureTime` is 1e308"],
        ),
        (
            "depth-negative",
            "profile.json",
            "/Depth",
            (-50).into(),
            &["`Depth` is -50"],
        ),
        (
            "speed-tiny",
            "profile.json",
            "/CustomValues/DmdslUpSpeed",
            "1e-308".into(),
            &["CustomValues.DmdslUpSpeed"],
        ),
        (
            "layers-huge",
            "plate.json",
            "/LayersCount",
            1e12.into(),
            &["plate.json", "LayersCount"],
        ),
        (
            "display-empty",
            "options.json",
            "/PWidth",
            0.into(),
            &["options.json", "PWidth"],
        ),
        (
            "area-negative",
            "info.json",
            "/0/TotalSolidArea",
            (-1).into(),
            &["info.json", "layer 0", "TotalSolidArea"],
        ),
    ];
    for (name, entry, pointer, value, words) in cases {
        refused(
            &format!("nanodlp-{name}"),
            &edited(entry, pointer, value),
            words,
        );
    }
    // What NanoDLP's fields ask and dmdsl does not evaluate is said, not silent.
    let plate = edited("profile.json", "/TransitionalLayer", 3.into());
    std::fs::write(dir.join("fade.nanodlp"), plate).unwrap();
    let (code, r) = json_run(&dir, &["run", "fade.nanodlp"]);
    assert_eq!(code, 0, "{r:.400}");
    assert!(
        r["notes"].to_string().contains("TransitionalLayer 3"),
        "{}",
        r["notes"]
    );
}
