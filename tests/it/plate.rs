//! `slice --plate` / `--copies`: many parts on one build plate, checked from what the job
//! writes: each copy's box on the plate, the lit regions of the masks, `dmdsl run`.

use crate::common::*;
use crate::schema::Schemas;
use serde_json::Value;
use std::path::Path;

/// The default profile's field, mm.
const FIELD: [f64; 2] = [65.0, 48.75];

/// Slices `args` in `dir` (exit 0 expected) and returns `out`'s manifest, checked
/// against its schema, after `dmdsl run` on it passed.
fn plate(dir: &Path, args: &[&str], out: &str) -> Value {
    let mut a = vec!["slice"];
    a.extend_from_slice(args);
    a.extend_from_slice(&["-o", out]);
    let o = run_in(dir, &a);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join(out).join("job.json")).unwrap()).unwrap();
    Schemas::load().assert_valid("job.schema.json", &job);
    let r = run_in(dir, &["run", out]);
    assert!(
        r.status.success(),
        "run {out}: {}{}",
        stdout(&r),
        stderr(&r)
    );
    job
}

/// The copies' boxes on the build plane, XY: [x0, y0, x1, y1].
fn boxes(job: &Value) -> Vec<[f64; 4]> {
    job["source"]["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let b = &p["placed_bbox_mm"];
            let v = |i: usize, k: usize| b[i][k].as_f64().unwrap();
            [v(0, 0), v(0, 1), v(1, 0), v(1, 1)]
        })
        .collect()
}

/// Asserts the boxes lie inside the field and at least `gap` apart.
fn laid_out(b: &[[f64; 4]], gap: f64) {
    for (i, p) in b.iter().enumerate() {
        assert!(
            p[0] >= 0.0 && p[1] >= 0.0 && p[2] <= FIELD[0] && p[3] <= FIELD[1],
            "{p:?}"
        );
        for q in &b[..i] {
            let apart = p[0] >= q[2] + gap - 1e-3
                || q[0] >= p[2] + gap - 1e-3
                || p[1] >= q[3] + gap - 1e-3
                || q[1] >= p[3] + gap - 1e-3;
            assert!(apart, "{p:?} and {q:?} are closer than {gap} mm");
        }
    }
}

/// Connected lit regions (8-neighbours) of a mask: their pixel boxes [x0, y0, x1, y1].
fn regions(path: &Path) -> Vec<[usize; 4]> {
    let (w, h, px) = read_gray(path);
    let (w, h) = (w as usize, h as usize);
    let mut seen = vec![false; px.len()];
    let mut out = Vec::new();
    for start in 0..px.len() {
        if px[start] == 0 || seen[start] {
            continue;
        }
        let mut b = [usize::MAX, usize::MAX, 0, 0];
        let mut stack = vec![start];
        seen[start] = true;
        while let Some(k) = stack.pop() {
            let (x, y) = (k % w, k / w);
            b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                    if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                        continue;
                    }
                    let n = yy as usize * w + xx as usize;
                    if px[n] > 0 && !seen[n] {
                        seen[n] = true;
                        stack.push(n);
                    }
                }
            }
        }
        out.push(b);
    }
    out
}

#[test]
fn twelve_copies_lie_apart_inside_the_field_and_each_is_lit_where_its_record_says() {
    let dir = tempdir("plate-twelve");
    let cube = fixture("cube10.stl");
    let job = plate(
        &dir,
        &[
            cube.to_str().unwrap(),
            "--copies",
            "12",
            "--layer-height",
            "1",
        ],
        "twelve.dmdjob",
    );
    let parts = job["source"]["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 12);
    assert_eq!(job["source"]["placement"]["mode"], "plate");
    assert_eq!(job["source"]["file"], "cube10.stl");
    let copies: Vec<u64> = parts.iter().map(|p| p["copy"].as_u64().unwrap()).collect();
    assert_eq!(copies, (1..=12).collect::<Vec<u64>>());
    let b = boxes(&job);
    laid_out(&b, 3.0);
    // The masks, read independently: twelve separate lit regions, each within a pixel of
    // a copy's box (row 0 is the field's top edge).
    let px = 65.0 / 1024.0;
    let mut found = regions(&dir.join("twelve.dmdjob/masks/00005.png"));
    assert_eq!(found.len(), 12, "{found:?}");
    for p in &b {
        let want = [
            p[0] / px,
            (FIELD[1] - p[3]) / px,
            p[2] / px - 1.0,
            (FIELD[1] - p[1]) / px - 1.0,
        ];
        let at = found
            .iter()
            .position(|r| (0..4).all(|k| (r[k] as f64 - want[k]).abs() <= 1.5));
        let at = at.unwrap_or_else(|| panic!("no lit region at {want:?}: {found:?}"));
        found.remove(at);
    }
    // The layer's area is twelve cubes'.
    let area = job["layers"][5]["area_mm2"].as_f64().unwrap();
    let one = {
        let p = &parts[0]["bbox_mm"];
        let d = |k: usize| p[1][k].as_f64().unwrap() - p[0][k].as_f64().unwrap();
        d(0) * d(1)
    };
    assert!(
        (area / (12.0 * one) - 1.0).abs() < 0.01,
        "{area} vs 12 x {one}"
    );
}

#[test]
fn different_parts_share_a_plate_and_each_keeps_its_own_record() {
    let dir = tempdir("plate-mixed");
    write_stl(
        &dir.join("tall.stl"),
        &box_tris([0.0, 0.0, 0.0], [4.0, 20.0, 3.0]),
    );
    write_stl(
        &dir.join("flat.stl"),
        &box_tris([5.0, 5.0, 1.0], [25.0, 9.0, 2.0]),
    );
    let cyl = fixture("cylinder_hole.stl");
    let job = plate(
        &dir,
        &[
            "tall.stl",
            "flat.stl",
            cyl.to_str().unwrap(),
            "--layer-height",
            "0.5",
        ],
        "mixed.dmdjob",
    );
    let parts = job["source"]["parts"].as_array().unwrap();
    let files: Vec<&str> = parts.iter().map(|p| p["file"].as_str().unwrap()).collect();
    assert_eq!(files, ["tall.stl", "flat.stl", "cylinder_hole.stl"]);
    assert_eq!(
        job["source"]["file"],
        "tall.stl + flat.stl + cylinder_hole.stl"
    );
    laid_out(&boxes(&job), 3.0);
    // Every part stands on the platform: the flat one's file starts at z = 1 mm.
    for p in parts {
        assert_eq!(p["placed_bbox_mm"][0][2], 0.0, "{p}");
    }
    let tris: u64 = parts.iter().map(|p| p["triangles"].as_u64().unwrap()).sum();
    assert_eq!(job["source"]["triangles"].as_u64().unwrap(), tris);
    // --plate with --spacing: farther apart.
    let job = plate(
        &dir,
        &[
            "tall.stl",
            "flat.stl",
            "--plate",
            "--spacing",
            "10",
            "--layer-height",
            "0.5",
        ],
        "wide.dmdjob",
    );
    laid_out(&boxes(&job), 10.0);
}

#[test]
fn keep_position_puts_each_part_where_its_file_says() {
    let dir = tempdir("plate-keep");
    write_stl(
        &dir.join("a.stl"),
        &box_tris([5.0, 5.0, 0.0], [10.0, 10.0, 1.0]),
    );
    write_stl(
        &dir.join("b.stl"),
        &box_tris([30.0, 20.0, 0.0], [40.0, 30.0, 1.0]),
    );
    write_stl(
        &dir.join("c.stl"),
        &box_tris([8.0, 8.0, 0.0], [12.0, 12.0, 1.0]),
    );
    let job = plate(
        &dir,
        &[
            "a.stl",
            "b.stl",
            "--plate",
            "--keep-position",
            "--layer-height",
            "0.5",
        ],
        "keep.dmdjob",
    );
    for p in job["source"]["parts"].as_array().unwrap() {
        assert_eq!(p["translate_mm"], serde_json::json!([0.0, 0.0, 0.0]));
        assert_eq!(p["placed_bbox_mm"], p["bbox_mm"]);
    }
    // Overlapping boxes are refused, naming both.
    let o = run_in(
        &dir,
        &[
            "slice",
            "a.stl",
            "c.stl",
            "--plate",
            "--keep-position",
            "-o",
            "x.dmdjob",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("c.stl") && e.contains("overlaps that of a.stl"),
        "{e}"
    );
    assert!(!dir.join("x.dmdjob").exists());
}

#[test]
fn a_plate_that_cannot_be_made_is_one_line_naming_the_part_and_nothing_is_written() {
    let dir = tempdir("plate-bad");
    let cube = fixture("cube10.stl");
    let cube = cube.to_str().unwrap();
    let cases: [(&[&str], &str); 6] = [
        (
            &[cube, "--copies", "40"],
            "cube10.stl: the plate has no room for this part (copy ",
        ),
        (
            &[cube, "--copies", "0"],
            "--copies must be a whole number from 1 to 1000, got 0",
        ),
        (
            &[cube, "--spacing", "2"],
            "--spacing lays out the parts of a plate: add --plate",
        ),
        (
            &[cube, "--copies", "2", "--spacing", "-1"],
            "--spacing must be a number of mm ≥ 0",
        ),
        (
            &[cube, "--copies", "2", "--position", "20,20"],
            "--position places a single part",
        ),
        (
            &[cube, "--copies", "2", "--keep-position"],
            "--copies needs room to arrange the copies",
        ),
    ];
    for (args, want) in cases {
        let mut a = vec!["slice"];
        a.extend_from_slice(args);
        a.extend_from_slice(&["-o", "bad.dmdjob"]);
        let o = run_in(&dir, &a);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let e = stderr(&o);
        assert!(e.contains(want), "{args:?}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{args:?}: {e}");
        assert!(!dir.join("bad.dmdjob").exists(), "{args:?}");
    }
    // Several parts that cannot be read: the first of them named, whichever thread read
    // which first.
    std::fs::write(dir.join("cut.stl"), "solid x\n").unwrap();
    std::fs::write(dir.join("junk.stl"), "junk").unwrap();
    let args = [
        "slice", cube, "cut.stl", "junk.stl", "cut.stl", "junk.stl", "--plate",
    ];
    let args = [&args[..], &["-o", "bad.dmdjob"]].concat();
    for _ in 0..4 {
        let o = run_threads(&dir, &args, "4");
        assert_eq!(o.status.code(), Some(2));
        let e = stderr(&o);
        assert!(e.starts_with("dmdsl: error: cut.stl: "), "{e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        assert!(!dir.join("bad.dmdjob").exists());
    }
    // How much room is missing, in mm: 40 cubes of 10.156 mm in rows of five, 3 mm apart.
    let o = run_in(&dir, &["slice", cube, "--copies", "40", "-o", "bad.dmdjob"]);
    assert!(
        stderr(&o).contains("mm more in Y than the 65 x 48.75 mm field"),
        "{}",
        stderr(&o)
    );
}
