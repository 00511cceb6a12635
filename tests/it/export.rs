//! One-file outputs and `dmdsl export`: the native bundle as a zip, Prusa SL1/SL1S and the
//! SLA control-file standard, written by `slice -o` and by `export`; their files against
//! the directory bundle's, their entries and keys against a PrusaSlicer-made `.sl1`
//! (`fixtures/sl1/cube1.sl1`), bad names and formats, and failures that must leave
//! nothing.

use crate::common::*;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::{Command, Stdio};

/// Every file under `dir`, by relative path with `/`.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(base: &Path, d: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(base, &p, out);
            } else {
                let rel = p
                    .strip_prefix(base)
                    .unwrap()
                    .to_string_lossy()
                    .replace('\\', "/");
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// The keys of an ini text (`key = value` lines).
fn keys(text: &[u8]) -> BTreeSet<String> {
    String::from_utf8_lossy(text)
        .lines()
        .filter_map(|l| l.split_once(" = ").map(|(k, _)| k.to_string()))
        .collect()
}

/// Slices `fixture` in `dir` with `args` after it; panics unless it succeeds.
fn slice(dir: &Path, model: &str, args: &[&str]) {
    let m = fixture(model);
    let mut all = vec!["slice", m.to_str().unwrap(), "-q"];
    all.extend_from_slice(args);
    let o = run_in(dir, &all);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
}

#[test]
fn the_zip_bundle_holds_the_directory_bundles_files_byte_for_byte() {
    let d = tempdir("export-zip");
    slice(&d, "cylinder_hole.stl", &["-o", "a.dmdjob"]);
    slice(&d, "cylinder_hole.stl", &["-o", "a.dmdjob.zip"]);
    slice(
        &d,
        "cylinder_hole.stl",
        &["-o", "b.zip", "--format", "dmdjob-zip"],
    );
    let dir = files(&d.join("a.dmdjob"));
    let zip = zip_entries(&d.join("a.dmdjob.zip"));
    assert_eq!(zip[0].0, "job.json", "job.json comes first");
    let zipped: BTreeMap<String, Vec<u8>> = zip.into_iter().collect();
    assert_eq!(
        zipped.keys().collect::<Vec<_>>(),
        dir.keys().collect::<Vec<_>>()
    );
    assert!(zipped == dir, "a file differs");
    // Images are stored, not deflated again.
    let mut z = zip::ZipArchive::new(std::fs::File::open(d.join("a.dmdjob.zip")).unwrap()).unwrap();
    assert_eq!(
        z.by_name("masks/00000.png").unwrap().compression(),
        zip::CompressionMethod::Stored
    );
    // The same job gives the same bytes, through slice or export.
    let o = run_in(&d, &["export", "a.dmdjob", "-o", "c.dmdjob.zip", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let a = std::fs::read(d.join("a.dmdjob.zip")).unwrap();
    assert_eq!(a, std::fs::read(d.join("b.zip")).unwrap());
    assert_eq!(a, std::fs::read(d.join("c.dmdjob.zip")).unwrap());
    // And export back to a directory gives the directory again.
    let o = run_in(&d, &["export", "a.dmdjob", "-o", "copy.dmdjob", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(files(&d.join("copy.dmdjob")) == dir);
}

#[test]
fn sl1_has_prusaslicers_entries_and_keys_and_the_bundles_masks() {
    let d = tempdir("export-sl1");
    slice(&d, "island.stl", &["-o", "part.dmdjob"]);
    let o = run_in(&d, &["export", "part.dmdjob", "-o", "part.sl1", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["format"], "sl1");
    let codes: Vec<&str> = v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["code"].as_str().unwrap())
        .collect();
    // dmdsl's default: 2 bottom layers, which SL1's 3 first layers cannot say; its steps;
    // its 1024 x 768 display.
    for c in [
        "export.sl1-exposure",
        "export.sl1-steps",
        "export.sl1-display",
    ] {
        assert!(codes.contains(&c), "{codes:?}");
    }
    let ours = zip_entries(&d.join("part.sl1"));
    let theirs = zip_entries(&fixture("sl1/cube1.sl1"));
    let get = |e: &[(String, Vec<u8>)], n: &str| {
        e.iter()
            .find(|x| x.0 == n)
            .unwrap_or_else(|| panic!("no {n}"))
            .1
            .clone()
    };
    // The same first entries and the same keys.
    assert_eq!(ours[0].0, theirs[0].0);
    assert_eq!(ours[1].0, theirs[1].0);
    assert_eq!(
        keys(&get(&ours, "config.ini")),
        keys(&get(&theirs, "config.ini"))
    );
    assert_eq!(
        keys(&get(&ours, "prusaslicer.ini")),
        keys(&get(&theirs, "prusaslicer.ini"))
    );
    // Masks <jobDir>NNNNN.png, as PrusaSlicer names them, then the thumbnails.
    let config = String::from_utf8(get(&ours, "config.ini")).unwrap();
    assert!(config.contains("jobDir = part\n"), "{config}");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("part.dmdjob/job.json")).unwrap()).unwrap();
    let layers = manifest["layers"].as_array().unwrap();
    let masks: Vec<&(String, Vec<u8>)> = ours.iter().filter(|e| e.0.starts_with("part0")).collect();
    assert_eq!(masks.len(), layers.len());
    for (i, (name, bytes)) in masks.iter().enumerate() {
        assert_eq!(name, &format!("part{i:05}.png"));
        let file = layers[i]["masks"][0]["file"].as_str().unwrap();
        let (w, h, px) = read_gray(&d.join("part.dmdjob").join(file));
        let img = image::load_from_memory(bytes).unwrap();
        let g = img.as_luma8().expect("8-bit gray");
        assert_eq!((g.width(), g.height()), (w, h));
        assert!(g.as_raw() == &px, "layer {i}: decoded mask differs");
    }
    let their_mask = image::load_from_memory(&theirs[2].1).unwrap();
    assert_eq!(
        (their_mask.width(), their_mask.height()),
        (1024, 768),
        "the fixture's display is dmdsl's default projector's"
    );
    for (name, (w, h)) in [
        ("thumbnail/thumbnail400x400.png", (400, 400)),
        ("thumbnail/thumbnail800x480.png", (800, 480)),
    ] {
        let t = image::load_from_memory(&get(&ours, name)).unwrap();
        assert_eq!((t.width(), t.height()), (w, h));
        assert_eq!(t.color(), image::ColorType::Rgba8);
    }
    // The display keys describe the masks exactly.
    let ini = String::from_utf8(get(&ours, "prusaslicer.ini")).unwrap();
    for line in [
        "display_orientation = landscape",
        "display_pixels_x = 1024",
        "display_pixels_y = 768",
        "display_width = 65",
        "display_height = 48.75",
        "display_mirror_x = 0",
        "display_mirror_y = 0",
        "layer_height = 0.05",
    ] {
        assert!(ini.lines().any(|l| l == line), "{line}");
    }
    // An SL1S is the same layout for the other printer.
    let o = run_in(&d, &["export", "part.dmdjob", "-o", "part.sl1s", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let s = zip_entries(&d.join("part.sl1s"));
    assert!(String::from_utf8_lossy(&s[0].1).contains("printerModel = SL1S\n"));
}

#[test]
fn names_and_formats_that_disagree_are_one_line_and_exit_2() {
    let d = tempdir("export-usage");
    slice(&d, "island.stl", &["-o", "part.dmdjob"]);
    let m = fixture("island.stl");
    let m = m.to_str().unwrap();
    for args in [
        vec!["slice", m, "-o", "x.zip"],
        vec!["slice", m, "-o", "x.sl1", "--format", "dmdjob-zip"],
        vec!["slice", m, "-o", "x.zip", "--format", "sl1"],
        vec!["export", "part.dmdjob", "-o", "x.zip"],
        vec!["export", "part.dmdjob", "-o", "x.sl1s", "--format", "sl1"],
        vec![
            "export",
            "part.dmdjob",
            "-o",
            "x.dmdjob.zip",
            "--format",
            "sla-control",
        ],
    ] {
        let o = run_in(&d, &args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let e = stderr(&o);
        assert_eq!(e.lines().count(), 1, "{args:?}: {e}");
        assert!(e.contains("--format") || e.contains("name"), "{e}");
    }
    let o = run_in(&d, &["slice", m, "--format", "pdf"]);
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(names(&d), ["part.dmdjob"]);
}

#[test]
fn what_cannot_be_written_leaves_nothing() {
    let d = tempdir("export-fail");
    let m = fixture("island.stl");
    let m = m.to_str().unwrap();
    // SL1 shows one image per layer: a tiled job is refused before anything is sliced.
    let o = run_in(&d, &["slice", m, "-p", "tiled-2x1", "-o", "out/t.sl1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 projectors"), "{}", stderr(&o));
    assert!(names(&d).is_empty(), "{:?}", names(&d));
    // A directory in the way of the file: refused, nothing left beside it.
    std::fs::create_dir(d.join("busy.sl1")).unwrap();
    let o = run_in(&d, &["slice", m, "-o", "busy.sl1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(names(&d), ["busy.sl1"]);
    assert!(names(&d.join("busy.sl1")).is_empty());
    // An older file at the path stays as it was when the new one cannot be made.
    std::fs::write(d.join("old.dmdjob.zip"), b"old").unwrap();
    let o = run_in(&d, &["slice", "missing.stl", "-o", "old.dmdjob.zip"]);
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(std::fs::read(d.join("old.dmdjob.zip")).unwrap(), b"old");
    assert_eq!(names(&d), ["busy.sl1", "old.dmdjob.zip"]);
}

#[test]
fn an_interrupted_one_file_slice_leaves_nothing() {
    let d = tempdir("export-ctrlc");
    let bunny = fixture("bunny00.stl");
    let child = Command::new(bin())
        .args([
            "slice",
            bunny.to_str().unwrap(),
            "--layer-height",
            "0.004",
            "-o",
            "out/b.sl1",
        ])
        .current_dir(&d)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .stoppable()
        .spawn()
        .unwrap();
    // Wait until the job is under way (its output directory made), then interrupt it.
    let t = std::time::Instant::now();
    while !d.join("out").exists() {
        assert!(t.elapsed().as_secs() < 60, "the job did not start");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    std::thread::sleep(std::time::Duration::from_millis(100));
    signal(&child, "INT");
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(names(&d).is_empty(), "{:?}", names(&d));
}

#[test]
fn a_stale_temporary_file_of_a_killed_run_is_removed() {
    let d = tempdir("export-stale");
    let mut c = Command::new("true").spawn().unwrap();
    let dead = c.id();
    c.wait().unwrap();
    let stale = format!(".p.sl1.tmp-{dead}");
    std::fs::write(d.join(&stale), b"half").unwrap();
    std::fs::write(d.join(".p.sl1.tmp-x"), b"not ours").unwrap();
    slice(&d, "island.stl", &["-o", "p.sl1"]);
    assert_eq!(names(&d), [".p.sl1.tmp-x", "p.sl1"]);
}

#[test]
fn the_control_file_expands_to_the_bundles_masks_layer_by_layer() {
    let d = tempdir("export-control");
    for (profile, dir, out) in [
        ("xu2010-topdown", "one.dmdjob", "one.zip"),
        ("tiled-2x1", "two.dmdjob", "two.zip"),
    ] {
        slice(&d, "island.stl", &["-p", profile, "-o", dir]);
        let o = run_in(
            &d,
            &["export", dir, "-o", out, "--format", "sla-control", "-q"],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let zip: BTreeMap<String, Vec<u8>> = zip_entries(&d.join(out)).into_iter().collect();
        let v: serde_json::Value = serde_json::from_slice(&zip["print_settings.json"]).unwrap();
        let manifest: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join(dir).join("job.json")).unwrap()).unwrap();
        let layers = manifest["layers"].as_array().unwrap();
        let image = |name: &str| {
            let bytes = zip
                .get(&format!("slices/{name}"))
                .unwrap_or_else(|| panic!("{out}: no slices/{name}"));
            let img = image::load_from_memory(bytes).unwrap();
            assert_eq!(img.color(), image::ColorType::L8, "{name}");
            img.into_luma8().into_raw()
        };
        let default = &v["Default layer settings"];
        image(default["Image settings"]["Image file"].as_str().unwrap());
        // Expand "Number of duplications" and compare each layer with the bundle's.
        let mut i = 0;
        for e in v["Layers"].as_array().unwrap() {
            let n = e["Number of duplications"].as_u64().unwrap_or(1) as usize;
            let list = e["Image settings list"].as_array().unwrap();
            let thickness = e["Position settings"]["Layer thickness (um)"]
                .as_f64()
                .or(default["Position settings"]["Layer thickness (um)"].as_f64())
                .unwrap();
            for _ in 0..n {
                let l = &layers[i];
                let masks = l["masks"].as_array().unwrap();
                let per_mask = list.len() / masks.len();
                assert_eq!(per_mask * masks.len(), list.len());
                let mut light_ms = 0.0;
                for (k, m) in masks.iter().enumerate() {
                    let (_, _, px) = read_gray(&d.join(dir).join(m["file"].as_str().unwrap()));
                    for img in &list[k * per_mask..(k + 1) * per_mask] {
                        assert!(
                            image(img["Image file"].as_str().unwrap()) == px,
                            "{out}: layer {i}, mask {k} differs"
                        );
                        if k == 0 {
                            light_ms += img["Layer exposure time (ms)"].as_f64().unwrap();
                        }
                    }
                }
                assert_eq!(
                    light_ms,
                    (l["exposure_s"].as_f64().unwrap() * 1000.0).round()
                );
                assert_eq!(
                    thickness,
                    (l["thickness_mm"].as_f64().unwrap() * 1000.0).round()
                );
                i += 1;
            }
        }
        assert_eq!(i, layers.len(), "{out}: every layer once");
    }
}

#[test]
fn an_sl1_of_the_same_part_and_settings_says_what_prusaslicers_says() {
    // fixtures/sl1/cube1.sl1: cube10.stl scaled to 1 mm, 0.05 mm layers, 8 s each.
    let d = tempdir("export-sl1-same");
    slice(
        &d,
        "cube10.stl",
        &["--scale", "0.1", "--bottom-layers", "0", "-o", "cube1.sl1"],
    );
    let ini = |p: &Path| -> BTreeMap<String, String> {
        let e = zip_entries(p);
        String::from_utf8(e[0].1.clone())
            .unwrap()
            .lines()
            .filter_map(|l| l.split_once(" = "))
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    };
    let ours = ini(&d.join("cube1.sl1"));
    let theirs = ini(&fixture("sl1/cube1.sl1"));
    for key in [
        "action",
        "expTime",
        "expTimeFirst",
        "jobDir",
        "layerHeight",
        "numFade",
        "numFast",
        "numSlow",
        "printTime",
        "usedMaterial",
    ] {
        assert_eq!(ours[key], theirs[key], "{key}");
    }
    // And the same number of masks, of the same size.
    let count = |p: &Path| {
        zip_entries(p)
            .iter()
            .filter(|e| e.0.starts_with("cube1"))
            .count()
    };
    assert_eq!(
        count(&d.join("cube1.sl1")),
        count(&fixture("sl1/cube1.sl1"))
    );
}

/// A plate over half the display (PrusaSlicer's `area_fill`) prints with the slow tilt: the
/// SL1's `printTime` counts it so, and `run` on the file, which measures each layer's area
/// from its mask (light-compensated: its grays add up to a fifth less), agrees.
#[test]
fn an_sl1_of_a_plate_over_half_the_display_runs_clean() {
    let d = tempdir("export-sl1-slow");
    let model = d.join("plate.stl");
    write_stl(&model, &box_tris([5.0, 5.0, 0.0], [55.0, 40.0, 0.2]));
    let o = run_in(
        &d,
        &["slice", model.to_str().unwrap(), "-q", "-o", "plate.sl1"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let config = String::from_utf8(zip_entries(&d.join("plate.sl1"))[0].1.clone()).unwrap();
    assert!(config.contains("numFast = 0\n"), "{config}");
    let o = run_in(&d, &["run", "-q", "plate.sl1"]);
    assert!(o.status.success(), "{}{}", stdout(&o), stderr(&o));
}

#[test]
fn the_schemas_name_the_formats_the_code_has() {
    let names: Vec<&str> = dmdsl::formats::Format::ALL.map(|f| f.name()).to_vec();
    fn enums<'a>(v: &'a serde_json::Value, out: &mut Vec<&'a Vec<serde_json::Value>>) {
        match v {
            serde_json::Value::Object(m) => {
                if let Some(serde_json::Value::Array(e)) = m.get("enum") {
                    out.push(e);
                }
                m.values().for_each(|x| enums(x, out));
            }
            serde_json::Value::Array(a) => a.iter().for_each(|x| enums(x, out)),
            _ => {}
        }
    }
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/schemas");
    let mut schemas = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let path = e.unwrap().path();
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        let mut found = Vec::new();
        enums(&v, &mut found);
        for e in found
            .into_iter()
            .filter(|e| e.contains(&"dmdjob-zip".into()))
        {
            assert_eq!(e, &names, "{}", path.display());
            schemas += 1;
        }
    }
    assert_eq!(schemas, 5);
}

/// A job `run` fails is not converted (exit 1, nothing written, the violations printed):
/// `fixtures/verdict/shifted.dmdjob.zip` (layer 2's mask moved 12 px, its hash not
/// updated) into every form, and masks of another colour type or depth with their hashes
/// recorded; with `--force` it is, and the exit code stays 1.
#[test]
fn a_job_run_fails_is_not_converted_unless_forced() {
    let d = tempdir("export-verified");
    let shifted = fixture("verdict/shifted.dmdjob.zip");
    let job = shifted.to_str().unwrap();
    for (out, format) in [
        ("a.sl1", None),
        ("c.zip", Some("sla-control")),
        ("a.dmdjob", None),
    ] {
        let mut args = vec!["export", job, "-o", out];
        args.extend(format.map(|f| ["--format", f]).iter().flatten());
        let o = run_in(&d, &args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{out}: {e}");
        assert!(
            e.contains("not converted: violations: 1 (mask-checksum 1)"),
            "{e}"
        );
        assert!(
            e.ends_with(
                "the job has violations; nothing was written (--force converts it anyway)\n"
            ),
            "{e}"
        );
        assert!(names(&d).is_empty(), "{out}");
    }
    let o = run_in(&d, &["export", job, "-o", "a.sl1", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!((&v["ok"], &v["written"]), (&false.into(), &false.into()));
    assert_eq!(v["violations"][0]["kind"], "mask-checksum");
    let o = run_in(&d, &["export", job, "-o", "a.sl1", "--force"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("converted anyway (--force): violations: 1"),
        "{}",
        stderr(&o)
    );
    assert_eq!(names(&d), ["a.sl1"]);
    // RGB, 16-bit and palette masks, their hashes recorded.
    slice(
        &d,
        "cube10.stl",
        &["--scale", "0.3", "--layer-height", "1", "-o", "b.dmdjob"],
    );
    let b = d.join("b.dmdjob");
    for depth in ["rgb", "16-bit", "palette"] {
        let mask = b.join("masks/00001.png");
        let img = image::open(&mask).unwrap();
        match depth {
            "rgb" => img.to_rgb8().save(&mask).unwrap(),
            "16-bit" => img.to_luma16().save(&mask).unwrap(),
            _ => std::fs::write(&mask, palette_png(&img.to_luma8())).unwrap(),
        }
        let mut j: serde_json::Value =
            serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap();
        j["layers"][1]["masks"][0]["sha256"] =
            dmdsl::bundle::sha256_hex(&std::fs::read(&mask).unwrap()).into();
        std::fs::write(b.join("job.json"), serde_json::to_vec_pretty(&j).unwrap()).unwrap();
        let o = run_in(&d, &["export", "b.dmdjob", "-o", "b.sl1"]);
        assert_eq!(o.status.code(), Some(1), "{depth}");
        let e = stderr(&o);
        assert!(e.contains("expected 8-bit grayscale"), "{depth}: {e}");
        assert!(!d.join("b.sl1").exists());
    }
}

/// `img` as an 8-bit palette PNG (colour type 3) whose 256 entries are the grays, so it
/// shows the same picture: the gray PNG's chunks with its header's colour type changed
/// and a `PLTE` chunk before its data.
fn palette_png(img: &image::GrayImage) -> Vec<u8> {
    let gray = dmdsl::png::encode_gray8(img.width(), img.height(), img.as_raw());
    let chunk = |out: &mut Vec<u8>, kind: &[u8], body: &[u8]| {
        out.extend((body.len() as u32).to_be_bytes());
        let mut crc = crc32fast::Hasher::new();
        crc.update(kind);
        crc.update(body);
        out.extend(kind);
        out.extend(body);
        out.extend(crc.finalize().to_be_bytes());
    };
    let mut out = gray[..8].to_vec();
    let mut at = 8;
    while at + 8 <= gray.len() {
        let len = u32::from_be_bytes(gray[at..at + 4].try_into().unwrap()) as usize;
        let kind = &gray[at + 4..at + 8];
        let mut body = gray[at + 8..at + 8 + len].to_vec();
        if kind == b"IHDR" {
            assert_eq!((body[8], body[9]), (8, 0), "8-bit gray");
            body[9] = 3;
        }
        if kind == b"IDAT" && !out.windows(4).any(|w| w == b"PLTE") {
            let grays: Vec<u8> = (0..=255u8).flat_map(|g| [g, g, g]).collect();
            chunk(&mut out, b"PLTE", &grays);
        }
        chunk(&mut out, kind, &body);
        at += 12 + len;
    }
    let back = image::load_from_memory(&out).unwrap().to_luma8();
    assert!(back == *img, "the palette PNG shows the same picture");
    out
}

/// Masks are written up to their IEND chunk, and an output's size is known before it is
/// written: `fixtures/verdict/iend-junk.zip` (a control file whose base image carries
/// 1 MiB after IEND, its layer repeated 400 times) became a 420 MB `.sl1`; past
/// `--max-size` the export is refused, naming the size.
#[test]
fn masks_are_written_up_to_their_iend_chunk_and_outputs_are_bounded() {
    let d = tempdir("export-iend");
    let junk = fixture("verdict/iend-junk.zip");
    let o = run_in(&d, &["export", junk.to_str().unwrap(), "-o", "a.sl1", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let size = std::fs::metadata(d.join("a.sl1")).unwrap().len();
    assert!(size < 300_000, "{size}");
    let pngs = zip_entries(&d.join("a.sl1"));
    let pngs = pngs.iter().filter(|(n, _)| n.ends_with(".png"));
    assert!(pngs.clone().count() > 400);
    for (n, b) in pngs {
        assert!(b.ends_with(b"IEND\xae\x42\x60\x82"), "{n}");
    }
    let o = run_in(&d, &["run", "a.sl1", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let args = [
        "export",
        junk.to_str().unwrap(),
        "-o",
        "b.sl1",
        "--max-size",
        "20K",
    ];
    let o = run_in(&d, &args);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.starts_with("dmdsl: error: b.sl1: its images would add up to 57198 bytes (0.055 MiB), more than the 20480 (0.020 MiB) allowed (--max-size; --force writes it anyway)"), "{e}");
    assert_eq!(names(&d), ["a.sl1"]);
    let o = run_in(&d, &[&args[..], &["--force", "-q"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(names(&d), ["a.sl1", "b.sl1"]);
}

#[test]
fn a_control_file_for_a_described_printer_names_its_engine_and_is_refused_when_it_cannot_run() {
    let dir = tempdir("export-hardware");
    let hw = fixture("sla_control/hardware_config_example.json");
    let hw = hw.to_str().unwrap();
    let part = fixture("cube10.stl");
    let part = part.to_str().unwrap();
    // The default projector's 1024 × 768 images on visitech (2560 × 1600): refused, nothing
    // written.
    let o = run_in(
        &dir,
        &[
            "slice",
            part,
            "--scale",
            "0.3",
            "-o",
            "no.zip",
            "--format",
            "sla-control",
            "--machine",
            hw,
        ],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("visitech.resolution") && err.contains("cannot run this job"),
        "{err}"
    );
    assert!(!dir.join("no.zip").exists());
    // A 2560 × 1600 projector: the engine and its first LED named, the stage within the
    // build platform's limits, the file valid for that printer.
    let fits = [
        "--set",
        "projector.0.width_px=2560",
        "--set",
        "projector.0.height_px=1600",
        "--set",
        "projector.0.power_setting=250",
    ];
    let mut args = vec![
        "slice",
        part,
        "--scale",
        "0.3",
        "-p",
        "bottom-up",
        "-o",
        "hw.zip",
        "--format",
        "sla-control",
        "--machine",
        hw,
        "--json",
    ];
    args.extend(fits);
    let o = run_in(&dir, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(warnings_of(&v, "export.control-assumed").is_empty(), "{v}");
    let settings: serde_json::Value =
        serde_json::from_slice(&zip_entries(&dir.join("hw.zip"))[0].1).unwrap();
    let image = &settings["Default layer settings"]["Image settings"];
    assert_eq!(
        (
            &image["Light engine"],
            &image["Light engine wavelength (nm)"],
            &image["Light engine power setting"]
        ),
        (&"visitech".into(), &405.into(), &250.into())
    );
    let o = run_in(&dir, &["run", "hw.zip", "--machine", hw]);
    assert!(o.status.success(), "{}", stdout(&o));
    // A hardware description that is not there is named as a file, not as a profile.
    let o = run_in(&dir, &["run", "hw.zip", "--machine", "missing.json"]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.starts_with("dmdsl: error: missing.json: "), "{e}");
    assert!(!e.contains("profile"), "{e}");
    assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    // export --machine: the same names; a job the printer cannot run (the default
    // projector's size) refused.
    let o = run_in(
        &dir,
        &[
            "export",
            "hw.zip",
            "-o",
            "again.zip",
            "--format",
            "sla-control",
            "--machine",
            hw,
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    slice(
        &dir,
        "cube10.stl",
        &["--scale", "0.3", "-o", "small.dmdjob"],
    );
    let o = run_in(
        &dir,
        &[
            "export",
            "small.dmdjob",
            "-o",
            "small.zip",
            "--format",
            "sla-control",
            "--machine",
            hw,
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("visitech.resolution"), "{}", stderr(&o));
    assert!(!dir.join("small.zip").exists());
}
