//! Jobs changed after slicing with their SHA-256 hashes recorded again ("re-signed"):
//! `dmdsl run` fails every one. Seventeen edits of one mask, and four settings changed on
//! their own (docs/EXECUTOR.md, "Mask records and settings").

use crate::common::*;
use serde_json::Value;
use std::path::Path;

/// A mask as its pixels, 1024 × 768.
type Pixels = Vec<u8>;
const W: usize = 1024;
const H: usize = 768;

fn job(b: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap()
}

fn set_job(b: &Path, v: &Value) {
    std::fs::write(b.join("job.json"), serde_json::to_vec_pretty(v).unwrap()).unwrap();
}

/// Moves every pixel by (dx, dy), filling with 0.
fn shifted(p: &[u8], dx: i64, dy: i64) -> Pixels {
    let mut out = vec![0; p.len()];
    for r in 0..H as i64 {
        for c in 0..W as i64 {
            let (sr, sc) = (r - dy, c - dx);
            if (0..H as i64).contains(&sr) && (0..W as i64).contains(&sc) {
                out[(r * W as i64 + c) as usize] = p[(sr * W as i64 + sc) as usize];
            }
        }
    }
    out
}

/// Each pixel the minimum (`grow` false) or maximum of its square neighbourhood of radius
/// `k`: erosion and dilation.
fn morph(p: &[u8], k: i64, grow: bool) -> Pixels {
    let at = |r: i64, c: i64| {
        let ok = (0..H as i64).contains(&r) && (0..W as i64).contains(&c);
        if ok {
            p[(r * W as i64 + c) as usize]
        } else {
            0
        }
    };
    let mut out = vec![0; p.len()];
    for r in 0..H as i64 {
        for c in 0..W as i64 {
            let around = (-k..=k).flat_map(|i| (-k..=k).map(move |j| (i, j)));
            let vals = around.map(|(i, j)| at(r + i, c + j));
            out[(r * W as i64 + c) as usize] = if grow {
                vals.max().unwrap()
            } else {
                vals.min().unwrap()
            };
        }
    }
    out
}

/// The 17 edits: name and the edited pixels of `p` (`other`: another layer's mask).
fn edits(p: &[u8], other: &[u8]) -> Vec<(&'static str, Pixels)> {
    let map = |f: &dyn Fn(u8) -> u8| p.iter().map(|&v| f(v)).collect::<Pixels>();
    let lit: Vec<usize> = (0..p.len()).filter(|&i| p[i] > 0).collect();
    let c0 = lit[0] % W;
    let mid = lit[lit.len() / 2];
    // An 80 × 80 hole where the mask is lit throughout.
    let hole_at = (0..p.len())
        .find(|&i| {
            let (c, r) = (i % W, i / W);
            c + 80 < W
                && r + 80 < H
                && (r..r + 80).all(|y| p[y * W + c..y * W + c + 80].iter().all(|&v| v > 0))
        })
        .expect("an 80 x 80 lit square");
    let mut hole = p.to_vec();
    for y in 0..80 {
        let start = (hole_at / W + y) * W + hole_at % W;
        hole[start..start + 80].fill(0);
    }
    let mut one = p.to_vec();
    one[mid] ^= 1;
    let mut stray = p.to_vec();
    stray[(H - 1) * W + (W - 1 - c0)] = 255;
    let mirrored: Pixels = p
        .chunks(W)
        .flat_map(|row| row.iter().rev().copied())
        .collect();
    vec![
        ("blank", vec![0; p.len()]),
        ("all lit", vec![255; p.len()]),
        ("inverted", map(&|v| 255 - v)),
        ("another layer's mask", other.to_vec()),
        ("shifted 12 px", shifted(p, 12, 0)),
        ("shifted 1 px right", shifted(p, 1, 0)),
        ("shifted 1 px down", shifted(p, 0, 1)),
        ("shifted 2 px diagonally", shifted(p, 2, 2)),
        ("mirrored", mirrored),
        ("grays x 0.02", map(&|v| (v as f64 * 0.02).round() as u8)),
        ("grays x 0.5", map(&|v| v / 2)),
        ("binarized", map(&|v| if v >= 128 { 255 } else { 0 })),
        ("80 x 80 px hole", hole),
        ("eroded 5 px", morph(p, 5, false)),
        ("dilated 5 px", morph(p, 5, true)),
        ("one pixel's gray", one),
        ("one stray pixel", stray),
    ]
}

/// `dmdsl run` of `b` as JSON: exit code and report.
fn run(dir: &Path) -> (i32, Value) {
    let o = run_in(dir, &["run", "part.dmdjob", "--json"]);
    let v = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {} / {}", stdout(&o), stderr(&o)));
    (o.status.code().unwrap(), v)
}

/// The kinds of the violations on `layer`, and of the job's.
fn kinds_on(r: &Value, layer: u64) -> Vec<String> {
    let v = r["violations"].as_array().unwrap();
    let on = v
        .iter()
        .filter(|v| v["layer"] == layer || v["layer"].is_null());
    on.map(|v| v["kind"].as_str().unwrap().to_string())
        .collect()
}

#[test]
fn every_resigned_mask_edit_fails_run() {
    let dir = tempdir("tamper-masks");
    // A 12 mm block under a 6 mm one, default profile (zone compensation, the XY cure
    // correction), 0.5 mm layers: 8 layers.
    let mut part = box_tris([0.0; 3], [12.0, 12.0, 2.0]);
    part.extend(box_tris([3.0, 3.0, 2.0], [9.0, 9.0, 4.0]));
    write_stl(&dir.join("part.stl"), &part);
    let args = ["slice", "part.stl", "--layer-height", "0.5", "-q"];
    let o = run_in(&dir, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let b = dir.join("part.dmdjob");
    let clean = job(&b);
    let (layer, other) = (1u64, 6u64);
    let file = |l: u64| {
        clean["layers"][l as usize]["masks"][0]["file"]
            .as_str()
            .unwrap()
            .to_string()
    };
    let original = std::fs::read(b.join(file(layer))).unwrap();
    let (_, _, pixels) = read_gray(&b.join(file(layer)));
    let (_, _, below) = read_gray(&b.join(file(other)));
    assert_eq!(run(&dir).0, 0);
    let mut failed = Vec::new();
    for (name, edited) in edits(&pixels, &below) {
        let path = b.join(file(layer));
        image::GrayImage::from_raw(W as u32, H as u32, edited)
            .unwrap()
            .save(&path)
            .unwrap();
        let mut j = clean.clone();
        let sha = dmdsl::bundle::sha256_hex(&std::fs::read(&path).unwrap());
        j["layers"][layer as usize]["masks"][0]["sha256"] = sha.into();
        set_job(&b, &j);
        let (code, r) = run(&dir);
        let kinds = kinds_on(&r, layer);
        assert!(
            code == 1 && kinds.contains(&"mask-pixels".to_string()),
            "{name}: exit {code}, {kinds:?}"
        );
        failed.push((name, kinds));
    }
    assert_eq!(failed.len(), 17, "{failed:?}");
    std::fs::write(b.join(file(layer)), original).unwrap();
    set_job(&b, &clean);
    assert_eq!(run(&dir).0, 0);
}

#[test]
fn settings_changed_on_their_own_fail_run() {
    let dir = tempdir("tamper-settings");
    let model = fixture("cube10.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            model.to_str().unwrap(),
            "-o",
            "part.dmdjob",
            "--layer-height",
            "0.5",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let b = dir.join("part.dmdjob");
    let clean = job(&b);
    type Edit = fn(&mut Value);
    let cases: [(&str, Edit, &str); 4] = [
        (
            "layer height",
            |j| j["settings"]["layer_height_mm"] = 0.25.into(),
            "settings",
        ),
        (
            "normal exposure",
            |j| j["machine"]["exposure"]["layer_s"] = 2.0.into(),
            "settings",
        ),
        (
            "compensation off",
            |j| j["settings"]["compensation"] = "off".into(),
            "settings",
        ),
        (
            "offset",
            |j| j["machine"]["projector"][0]["offset_px"] = serde_json::json!([1, 0]),
            "mask-pixels",
        ),
    ];
    for (name, edit, kind) in cases {
        let mut j = clean.clone();
        edit(&mut j);
        set_job(&b, &j);
        let (code, r) = run(&dir);
        let kinds: Vec<&str> = r["violations"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v["kind"].as_str().unwrap())
            .collect();
        assert!(
            code == 1 && kinds.contains(&kind),
            "{name}: exit {code}, {kinds:?}"
        );
    }
}

/// What `run` cannot see (docs/EXECUTOR.md, "Mask records and settings"): the records are
/// checks, not signatures, so a mask with an 80 × 80 px hole, its SHA-256 and its pixel
/// record both written again, passes: it stays within what its layer's section allows.
#[test]
fn an_edit_with_its_records_rewritten_is_checked_against_the_section_only() {
    let dir = tempdir("tamper-records");
    let mut part = box_tris([0.0; 3], [12.0, 12.0, 2.0]);
    part.extend(box_tris([3.0, 3.0, 2.0], [9.0, 9.0, 4.0]));
    write_stl(&dir.join("part.stl"), &part);
    let o = run_in(&dir, &["slice", "part.stl", "--layer-height", "0.5", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let b = dir.join("part.dmdjob");
    let mut j = job(&b);
    let rec = &j["layers"][1]["masks"][0];
    let path = b.join(rec["file"].as_str().unwrap());
    let (_, _, pixels) = read_gray(&path);
    let hole = edits(&pixels, &pixels)
        .into_iter()
        .find(|(n, _)| *n == "80 x 80 px hole");
    let hole = hole.unwrap().1;
    image::GrayImage::from_raw(W as u32, H as u32, hole.clone())
        .unwrap()
        .save(&path)
        .unwrap();
    // The hash alone: the pixel record tells.
    let sha = dmdsl::bundle::sha256_hex(&std::fs::read(&path).unwrap());
    j["layers"][1]["masks"][0]["sha256"] = sha.into();
    set_job(&b, &j);
    let (code, r) = run(&dir);
    let kinds = kinds_on(&r, 1);
    assert_eq!(
        (code, &kinds[..]),
        (1, &["mask-pixels".to_string()][..]),
        "{}",
        r["violations"]
    );
    // The pixel record too, placed as the projector shows it.
    let p = &j["machine"]["projector"][0];
    let n = |v: &Value| v.as_u64().unwrap() as u32;
    let px = dmdsl::bundle::MaskPixels::of_gray8(W as u32, &hole).placed(
        [n(&p["width_px"]), n(&p["height_px"])],
        [n(&p["offset_px"][0]), n(&p["offset_px"][1])],
        [p["mirror_x"] == true, p["mirror_y"] == true],
    );
    j["layers"][1]["masks"][0]["pixels"] = serde_json::to_value(px).unwrap();
    set_job(&b, &j);
    let (code, r) = run(&dir);
    assert_eq!(code, 0, "{}", r["violations"]);
}
