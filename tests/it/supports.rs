//! `slice --supports`: parts that start in mid-air or overhang, made printable. Checked
//! from what the job writes, independently of the slicer: every lit region of every mask
//! rests on a lit pixel of the layer below, down to the platform; the support structure
//! (`--supports-stl`, sliced alone) lies inside the part's sections only where a head or
//! a foot reaches into it; the structure is closed; `dmdsl run` passes.

use crate::common::*;
use crate::schema::Schemas;
use serde_json::Value;
use std::path::Path;

type Tris = Vec<[[f32; 3]; 3]>;

/// A cup upside down: open at the bottom, a wall from radius `ri` to `ro`, `h` tall, its
/// ceiling `t` thick.
fn cup(c: [f32; 2], ro: f32, ri: f32, h: f32, t: f32, n: usize) -> Tris {
    let p = |r: f32, i: usize, z: f32| {
        let a = std::f32::consts::TAU * (i % n) as f32 / n as f32;
        [c[0] + r * a.cos(), c[1] + r * a.sin(), z]
    };
    let mut v = Vec::new();
    for i in 0..n {
        let j = i + 1;
        // Outer wall, top, inner wall (facing the axis), ceiling (facing down), rim.
        v.push([p(ro, i, 0.0), p(ro, j, 0.0), p(ro, j, h)]);
        v.push([p(ro, i, 0.0), p(ro, j, h), p(ro, i, h)]);
        v.push([[c[0], c[1], h], p(ro, i, h), p(ro, j, h)]);
        v.push([p(ri, i, 0.0), p(ri, j, h - t), p(ri, j, 0.0)]);
        v.push([p(ri, i, 0.0), p(ri, i, h - t), p(ri, j, h - t)]);
        v.push([[c[0], c[1], h - t], p(ri, j, h - t), p(ri, i, h - t)]);
        v.push([p(ri, i, 0.0), p(ri, j, 0.0), p(ro, j, 0.0)]);
        v.push([p(ri, i, 0.0), p(ro, j, 0.0), p(ro, i, 0.0)]);
    }
    v
}

/// A UV sphere of `n` segments about `c`.
fn sphere(c: [f32; 3], r: f32, n: usize) -> Tris {
    let p = |i: usize, j: usize| {
        let (a, b) = (
            std::f32::consts::TAU * (i % (2 * n)) as f32 / (2 * n) as f32,
            std::f32::consts::PI * j as f32 / n as f32,
        );
        [
            c[0] + r * b.sin() * a.cos(),
            c[1] + r * b.sin() * a.sin(),
            c[2] - r * b.cos(),
        ]
    };
    let mut t = Vec::new();
    for i in 0..2 * n {
        for j in 0..n {
            let (a, b, cc, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
            if j > 0 {
                t.push([a, b, cc]);
            }
            if j + 1 < n {
                t.push([a, cc, d]);
            }
        }
    }
    t
}

/// The test parts: an arch, a T, a sphere floating over a base, a cup upside down.
fn test_parts(dir: &Path) -> Vec<(&'static str, std::path::PathBuf)> {
    let mut arch = box_tris([0.0, 0.0, 0.0], [2.0, 3.0, 4.0]);
    arch.extend(box_tris([8.0, 0.0, 0.0], [10.0, 3.0, 4.0]));
    arch.extend(box_tris([0.0, 0.0, 4.0], [10.0, 3.0, 5.5]));
    let mut tee = box_tris([4.0, 0.0, 0.0], [6.0, 3.0, 4.0]);
    tee.extend(box_tris([0.0, 0.0, 4.0], [10.0, 3.0, 5.5]));
    let mut floating = box_tris([0.0, 0.0, 0.0], [10.0, 10.0, 1.5]);
    floating.extend(sphere([5.0, 5.0, 5.0], 2.5, 16));
    let parts = [
        ("arch", arch),
        ("tee", tee),
        ("floating", floating),
        ("cup", cup([5.0, 5.0], 4.0, 3.0, 5.0, 1.0, 32)),
    ];
    parts
        .into_iter()
        .map(|(name, tris)| {
            let p = dir.join(format!("{name}.stl"));
            write_stl(&p, &tris);
            (name, p)
        })
        .collect()
}

/// The lit pixels (value ≥ 128) of each layer of the one-projector bundle `job`.
fn lit_layers(job: &Path) -> Vec<(u32, Vec<bool>)> {
    let m: Value = serde_json::from_slice(&std::fs::read(job.join("job.json")).unwrap()).unwrap();
    m["layers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| {
            let (w, _, px) = read_gray(&job.join(l["masks"][0]["file"].as_str().unwrap()));
            (w, px.iter().map(|&v| v >= 128).collect())
        })
        .collect()
}

/// The regions (4-connected lit pixels) of each layer that share no pixel with the layer
/// below's lit pixels (layer 0 rests on the platform): (layer, pixels), by the flood fill
/// [`regions_on_nothing`], apart from the slicer's run-based counter.
fn resting_on_nothing(layers: &[(u32, Vec<bool>)]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for i in 1..layers.len() {
        let (w, cur) = (layers[i].0 as usize, &layers[i].1);
        let found = regions_on_nothing(cur, &layers[i - 1].1, w, cur.len() / w);
        out.extend(found.into_iter().map(|(n, _, _)| (i, n as usize)));
    }
    out
}

/// The pixels of each layer of the one-projector bundle `job` (made without light
/// compensation) that cure by the model of its `cure` record, from the masks alone and
/// apart from the executor's judgment: each pixel's light g/255, blurred by the PSF (a
/// Gaussian of σ pixels integrated over each lit pixel by a midpoint sum, summed along
/// rows, then columns, over the lit box), times the layer's exposure against the normal layer's, at least the
/// record's edge threshold.
fn cured_layers(job: &Path) -> Vec<(u32, Vec<bool>)> {
    let m: Value = serde_json::from_slice(&std::fs::read(job.join("job.json")).unwrap()).unwrap();
    let cure = &m["cure"];
    let (sigma, t) = (
        cure["psf_sigma_px"].as_f64().unwrap(),
        cure["edge_threshold"].as_f64().unwrap(),
    );
    let normal = m["machine"]["exposure"]["layer_s"].as_f64().unwrap();
    let reach = (5.0 * sigma).ceil() as i64 + 1;
    // The share of a pixel's light that falls on the pixel `d` away, along one axis.
    let share = |d: i64| {
        let n = 400;
        (0..n)
            .map(|k| {
                let x = d as f64 - 0.5 + (k as f64 + 0.5) / n as f64;
                (-x * x / (2.0 * sigma * sigma)).exp() / (sigma * (std::f64::consts::TAU).sqrt())
            })
            .sum::<f64>()
            / n as f64
    };
    let weights: Vec<f64> = (-reach..=reach).map(share).collect();
    m["layers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| {
            let (w, h, g) = read_gray(&job.join(l["masks"][0]["file"].as_str().unwrap()));
            let (w, h) = (w as i64, h as i64);
            let ratio = l["exposure_s"].as_f64().unwrap() / normal;
            let mut cured = vec![false; (w * h) as usize];
            let lit: Vec<i64> = (0..w * h).filter(|&k| g[k as usize] > 0).collect();
            let Some(r0) = lit.first().map(|k| k / w) else {
                return (w as u32, cured);
            };
            let r1 = lit.last().unwrap() / w;
            let c0 = lit.iter().map(|k| k % w).min().unwrap();
            let c1 = lit.iter().map(|k| k % w).max().unwrap();
            let rows = (r0 - reach).max(0)..=(r1 + reach).min(h - 1);
            let cols = (c0 - reach).max(0)..=(c1 + reach).min(w - 1);
            // Across (over every row the blur down reads), then down.
            let mut across = vec![0.0; (w * h) as usize];
            for r in (r0 - 2 * reach).max(0)..=(r1 + 2 * reach).min(h - 1) {
                for c in cols.clone() {
                    across[(r * w + c) as usize] = (-reach..=reach)
                        .filter(|d| (0..w).contains(&(c + d)))
                        .map(|d| {
                            g[(r * w + c + d) as usize] as f64 / 255.0
                                * weights[(d + reach) as usize]
                        })
                        .sum();
                }
            }
            for r in rows {
                for c in cols.clone() {
                    let b: f64 = (-reach..=reach)
                        .filter(|d| (0..h).contains(&(r + d)))
                        .map(|d| across[((r + d) * w + c) as usize] * weights[(d + reach) as usize])
                        .sum();
                    cured[(r * w + c) as usize] = ratio * b >= t;
                }
            }
            (w as u32, cured)
        })
        .collect()
}

/// `run --json` reports nothing resting on nothing: the cure correction leaves out the
/// pieces of a supported job's layers that would cure loose.
fn assert_no_regions(report: &Value, what: &str) {
    assert_eq!(
        report["unsupported_regions"],
        serde_json::json!([]),
        "{what}"
    );
}

/// Every support point of `job` (the bundle at `path`) is held: the pixel under it is lit
/// in the layer below its own, whatever the support stands on (also a point right above
/// the part's layer, whose support has no height of its own).
fn assert_points_held(path: &Path, job: &Value) {
    let h = job["settings"]["layer_height_mm"].as_f64().unwrap();
    let p = &job["machine"]["projector"][0];
    let (px, rows) = (
        p["pixel_mm"].as_f64().unwrap(),
        p["height_px"].as_u64().unwrap() as usize,
    );
    let layers = job["layers"].as_array().unwrap();
    let mut masks = std::collections::HashMap::new();
    for pt in job["supports"]["points"].as_array().unwrap() {
        let at: Vec<f64> = pt["at_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let below = (at[2] / h).round() as usize - 1;
        let (w, gray) = masks.entry(below).or_insert_with(|| {
            let file = layers[below]["masks"][0]["file"].as_str().unwrap();
            let (w, _, g) = read_gray(&path.join(file));
            (w as usize, g)
        });
        let (col, row) = ((at[0] / px) as usize, rows - 1 - (at[1] / px) as usize);
        assert!(
            gray[row * *w + col] > 0,
            "support point {pt} is not lit in layer {below}"
        );
    }
}

/// Slices `args` to `out` in `dir` (exit 0 expected); the manifest.
fn slice(dir: &Path, args: &[&str], out: &str) -> Value {
    let mut a = vec!["slice"];
    a.extend_from_slice(args);
    a.extend_from_slice(&["-o", out]);
    let o = run_in(dir, &a);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    serde_json::from_slice(&std::fs::read(dir.join(out).join("job.json")).unwrap()).unwrap()
}

#[test]
fn test_parts_print_from_the_platform_up_on_every_process() {
    let dir = tempdir("supports-parts");
    let schemas = Schemas::load();
    // Coverage masks, 0.1 mm layers (short jobs).
    let exact = [
        "--compensation",
        "off",
        "--cure-correction",
        "off",
        "--layer-height",
        "0.1",
    ];
    for (name, stl) in test_parts(&dir) {
        let stl = stl.to_str().unwrap();
        let mut bare = vec![stl];
        bare.extend(exact);
        slice(&dir, &bare, "bare.dmdjob");
        // The sphere starts in mid-air; the arch's, the T's and the cup's overhangs hang
        // from what holds them.
        let bare_free = resting_on_nothing(&lit_layers(&dir.join("bare.dmdjob")));
        assert_eq!(
            !bare_free.is_empty(),
            name == "floating",
            "{name}: {bare_free:?}"
        );
        std::fs::remove_dir_all(dir.join("bare.dmdjob")).unwrap();
        for profile in ["xu2010-topdown", "bottom-up", "hybrid-bottomup"] {
            let out = format!("{name}-{profile}.dmdjob");
            let mut args = vec![stl, "--supports", "-p", profile];
            args.extend(exact);
            let job = slice(&dir, &args, &out);
            schemas.assert_valid("job.schema.json", &job);
            let points = job["supports"]["points"].as_array().unwrap();
            assert!(!points.is_empty(), "{name} {profile}");
            let free = resting_on_nothing(&lit_layers(&dir.join(&out)));
            assert!(
                free.is_empty(),
                "{name} on {profile}: regions on nothing {free:?}"
            );
            let w = serde_json::json!({"warnings": job["warnings"]});
            assert!(
                warnings_of(&w, "plan.unsupported-islands").is_empty(),
                "{name} {profile}"
            );
            let r = run_in(&dir, &["run", &out]);
            assert!(
                r.status.success(),
                "run {out}: {}{}",
                stdout(&r),
                stderr(&r)
            );
            std::fs::remove_dir_all(dir.join(&out)).unwrap();
        }
        // Corrected (without the light compensation, whose grays the independent cure
        // above does not model): what cures rests on what cured below, and `run` finds
        // nothing on nothing.
        for profile in ["xu2010-topdown", "bottom-up", "hybrid-bottomup"] {
            let out = format!("{name}-{profile}-corrected.dmdjob");
            let args = [
                stl,
                "--supports",
                "-p",
                profile,
                "--compensation",
                "off",
                "--layer-height",
                "0.1",
            ];
            slice(&dir, &args, &out);
            let free = resting_on_nothing(&cured_layers(&dir.join(&out)));
            assert!(
                free.is_empty(),
                "{name} on {profile}: cured on nothing {free:?}"
            );
            let r = run_in(&dir, &["run", &out, "--json"]);
            assert!(r.status.success(), "run {out}: {}", stderr(&r));
            let report: Value = serde_json::from_slice(&r.stdout).unwrap();
            assert_eq!(
                report["unsupported_regions"],
                serde_json::json!([]),
                "{out}"
            );
            std::fs::remove_dir_all(dir.join(&out)).unwrap();
        }
        // The job as users make it (compensation, cure correction) runs clean too.
        slice(&dir, &[stl, "--supports"], "default.dmdjob");
        let r = run_in(&dir, &["run", "default.dmdjob", "--json"]);
        assert!(
            r.status.success(),
            "run {name}: {}{}",
            stdout(&r),
            stderr(&r)
        );
        assert_no_regions(&serde_json::from_slice(&r.stdout).unwrap(), name);
        std::fs::remove_dir_all(dir.join("default.dmdjob")).unwrap();
    }
}

/// Whether pixel (`col`, `row`) at height `z` lies where a support of `job` reaches into
/// the part: within a head (the cone below its point and the penetration above it) or a
/// foot standing on the part, with a pixel and a layer of slack.
fn in_head_or_foot(job: &Value, col: usize, row: usize, z: f64, px: f64, field_h: f64) -> bool {
    let s = &job["supports"];
    let (hl, pen) = (
        s["head_length_mm"].as_f64().unwrap(),
        s["head_penetration_mm"].as_f64().unwrap(),
    );
    let (x, y) = ((col as f64 + 0.5) * px, field_h - (row as f64 + 0.5) * px);
    s["points"].as_array().unwrap().iter().any(|p| {
        let at: Vec<f64> = p["at_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let r = p["pillar_diameter_mm"].as_f64().unwrap() / 2.0 + 3.0 * px;
        let near = (x - at[0]).hypot(y - at[1]) <= r;
        let head = z >= at[2] - hl - 0.1 && z <= at[2] + pen + 0.1;
        let foot_z = p["foot_z_mm"].as_f64().unwrap();
        let foot = p["foot"] == "part" && z >= foot_z - 0.1 && z <= foot_z + hl + 0.1;
        near && (head || foot)
    })
}

#[test]
fn supports_reach_into_the_part_only_at_heads_and_feet_and_form_closed_shells() {
    let dir = tempdir("supports-inside");
    let parts = test_parts(&dir);
    let exact = ["--compensation", "off", "--cure-correction", "off"];
    for (name, stl) in parts
        .iter()
        .filter(|(n, _)| *n == "floating" || *n == "cup")
    {
        let stl = stl.to_str().unwrap();
        let mut args = vec![stl, "--supports", "--supports-stl", "s.stl"];
        args.extend(exact);
        let job = slice(&dir, &args, "with.dmdjob");
        let mut bare = vec![stl];
        bare.extend(exact);
        slice(&dir, &bare, "bare.dmdjob");
        let mesh = dmdsl::mesh::load(&dir.join("s.stl")).unwrap();
        let points = job["supports"]["points"].as_array().unwrap().len();
        assert!(mesh.report.closed_manifold, "{name}: {:?}", mesh.report);
        assert_eq!(
            mesh.report.shells as usize,
            points + 1,
            "{name}: a shell per support and the pad"
        );
        let vol = job["supports"]["volume_mm3"].as_f64().unwrap();
        assert!((mesh.report.volume_mm3 - vol).abs() < 1e-3 * vol, "{name}");
        // The structure alone, where the job put it.
        let mut alone = vec!["s.stl", "--keep-position"];
        alone.extend(exact);
        slice(&dir, &alone, "alone.dmdjob");
        let (with, part, sup) = (
            lit_layers(&dir.join("with.dmdjob")),
            lit_layers(&dir.join("bare.dmdjob")),
            lit_layers(&dir.join("alone.dmdjob")),
        );
        let h = job["settings"]["layer_height_mm"].as_f64().unwrap();
        let lift = (job["supports"]["lift_mm"].as_f64().unwrap() / h).round() as usize;
        assert_eq!(with.len(), part.len() + lift, "{name}");
        let (px, field_h) = (65.0 / 1024.0, 48.75);
        let mut inside = 0;
        for (i, (w, lit)) in with.iter().enumerate() {
            let part_lit = i.checked_sub(lift).map(|k| &part[k].1);
            let sup_lit = sup.get(i).map(|s| &s.1);
            for k in 0..lit.len() {
                let p = part_lit.is_some_and(|p| p[k]);
                let s = sup_lit.is_some_and(|s| s[k]);
                // The job lights the part and the supports (and, where their edges meet
                // in a pixel, what their coverages light together).
                let (w, col) = (*w as usize, k % *w as usize);
                let near = |m: Option<&Vec<bool>>| {
                    m.is_some_and(|m| {
                        (col > 0 && m[k - 1])
                            || (col + 1 < w && m[k + 1])
                            || (k >= w && m[k - w])
                            || (k + w < m.len() && m[k + w])
                    })
                };
                assert!(!(p || s) || lit[k], "{name} layer {i} pixel {k}");
                let edge = near(part_lit) || near(sup_lit);
                assert!(!lit[k] || p || s || edge, "{name} layer {i} pixel {k}");
                if p && s {
                    let row = k / w;
                    if !in_head_or_foot(&job, col, row, (i as f64 + 0.5) * h, px, field_h) {
                        inside += 1;
                    }
                }
            }
        }
        assert_eq!(
            inside, 0,
            "{name}: support pixels inside the part away from heads and feet"
        );
        for d in ["with.dmdjob", "bare.dmdjob", "alone.dmdjob"] {
            std::fs::remove_dir_all(dir.join(d)).unwrap();
        }
    }
}

#[test]
fn bunny_and_a_plate_of_copies_with_supports_run_clean() {
    let dir = tempdir("supports-bunny");
    let bunny = fixture("bunny00.stl");
    let o = run_in(
        &dir,
        &["slice", bunny.to_str().unwrap(), "--json", "-o", "b.dmdjob"],
    );
    let bare: Value = serde_json::from_slice(&o.stdout).unwrap();
    let w = &warnings_of(&bare, "plan.unsupported-islands")[0];
    assert!(w["message"].as_str().unwrap().contains("--supports"), "{w}");
    // Bottom-up: the first layers' long exposure moves corrected edges furthest.
    let o = run_in(
        &dir,
        &[
            "slice",
            bunny.to_str().unwrap(),
            "--supports",
            "--profile",
            "bottom-up",
            "--json",
            "-o",
            "s.dmdjob",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    Schemas::load().assert_valid("slice-summary.schema.json", &v);
    assert!(
        warnings_of(&v, "plan.unsupported-islands").is_empty(),
        "{v}"
    );
    let s = &v["supports"];
    assert!(
        s["points"].as_u64().unwrap() > 20 && s["volume_mm3"].as_f64().unwrap() > 0.0,
        "{s}"
    );
    let r = run_in(&dir, &["run", "s.dmdjob", "--json"]);
    assert!(r.status.success(), "{}{}", stdout(&r), stderr(&r));
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("s.dmdjob/job.json")).unwrap()).unwrap();
    assert_no_regions(&serde_json::from_slice(&r.stdout).unwrap(), "bunny00");
    // Each layer records its supports' area apart from the part's.
    let layers = job["layers"].as_array().unwrap();
    assert!(layers[0]["support_area_mm2"].as_f64().unwrap() > 0.0);
    assert!(layers
        .iter()
        .all(|l| l["support_area_mm2"].as_f64().unwrap() <= l["area_mm2"].as_f64().unwrap()));
    assert_points_held(&dir.join("s.dmdjob"), &job);
    // A plate of copies: one pad, supports for each copy.
    let parts = test_parts(&dir);
    let floating = parts[2].1.to_str().unwrap();
    let o = run_in(
        &dir,
        &[
            "slice",
            floating,
            "--copies",
            "4",
            "--supports",
            "-o",
            "p.dmdjob",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("p.dmdjob/job.json")).unwrap()).unwrap();
    let points = job["supports"]["points"].as_array().unwrap();
    assert!(points.iter().filter(|p| p["island"] == true).count() >= 4);
    // Each point names the copy it holds: the one whose box (lifted with the part) holds it.
    let parts = job["source"]["parts"].as_array().unwrap();
    let lift = job["supports"]["lift_mm"].as_f64().unwrap();
    for (k, part) in parts.iter().enumerate() {
        let b = &part["placed_bbox_mm"];
        assert!((b[0][2].as_f64().unwrap() - lift).abs() < 1e-6, "{part}");
        let inside = |p: &&Value| {
            let at = &p["at_mm"];
            (0..2).all(|a| {
                let v = at[a].as_f64().unwrap();
                b[0][a].as_f64().unwrap() <= v && v <= b[1][a].as_f64().unwrap()
            })
        };
        let held: Vec<&Value> = points.iter().filter(|p| p["part"] == k).collect();
        assert!(
            !held.is_empty() && held.iter().all(inside),
            "copy {k}: {held:?}"
        );
    }
    // Without supports, the islands warning names the copy an island is in.
    let o = run_in(
        &dir,
        &[
            "slice", floating, "--copies", "2", "--json", "-o", "q.dmdjob",
        ],
    );
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let w = &warnings_of(&v, "plan.unsupported-islands")[0];
    let m = w["message"].as_str().unwrap();
    assert!(m.contains("mm²), in floating.stl (copy "), "{m}");
    let r = run_in(&dir, &["run", "p.dmdjob"]);
    assert!(r.status.success(), "{}{}", stdout(&r), stderr(&r));
}

/// At 0.025 mm layers the cure correction cuts the neck that joins a 55-pixel piece of the
/// bunny's overhang (layer 247) to the region over a support's head: the slicer draws the
/// neck back, and `run` finds nothing resting on nothing.
#[test]
fn a_neck_the_correction_cuts_is_drawn_back_and_the_fine_bunny_runs_clean() {
    let dir = tempdir("supports-neck");
    let bunny = fixture("bunny00.stl");
    let args = [
        bunny.to_str().unwrap(),
        "--supports",
        "--layer-height",
        "0.025",
        "-q",
    ];
    slice(&dir, &args, "f.dmdjob");
    let r = run_in(&dir, &["run", "f.dmdjob", "--json"]);
    assert!(r.status.success(), "{}{}", stdout(&r), stderr(&r));
    assert_no_regions(
        &serde_json::from_slice(&r.stdout).unwrap(),
        "bunny00, 0.025 mm",
    );
}

/// bunny00 turned 60° about x and 20° about z, with binary masks: the correction breaks
/// up the first layer of a thin feature over a support (layer 160), and `run` finds a
/// region on nothing above layer 159. The slicer finds it before it writes the job, draws
/// layer 159 in a window around the region without the correction (as `--cure-correction
/// off` draws it there, corrected elsewhere) and says so; `run` passes.
#[test]
fn layers_the_correction_leaves_unheld_are_drawn_uncorrected_and_the_job_runs_clean() {
    let dir = tempdir("supports-plain");
    let bunny = fixture("bunny00.stl");
    let bunny = bunny.to_str().unwrap();
    let args = [
        "slice",
        bunny,
        "--supports",
        "--rotate",
        "60,0,20",
        "--binary",
    ];
    let o = run_in(&dir, &[&args[..], &["--json", "-o", "b.dmdjob"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let w = &warnings_of(&v, "cure.layers-uncorrected")[0];
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("b.dmdjob/job.json")).unwrap()).unwrap();
    let schemas = Schemas::load();
    schemas.assert_valid("job.schema.json", &job);
    schemas.assert_valid("slice-summary.schema.json", &v);
    // One window, no whole layer.
    assert!(
        job["cure"].get("uncorrected_layers").is_none(),
        "{}",
        job["cure"]
    );
    let windows = job["cure"]["uncorrected_windows"].as_array().unwrap();
    assert_eq!(windows.len(), 1, "{windows:?}");
    let layer = windows[0]["layer"].as_u64().unwrap();
    assert_eq!(
        w["fields"]["uncorrected"],
        serde_json::json!([layer]),
        "{w}"
    );
    assert_eq!(
        (&w["fields"]["windows"], &w["fields"]["first_layer"]),
        (&1.into(), &layer.into()),
        "{w}"
    );
    let r = run_in(&dir, &["run", "b.dmdjob", "--json"]);
    assert!(r.status.success(), "{}{}", stdout(&r), stderr(&r));
    assert_no_regions(
        &serde_json::from_slice(&r.stdout).unwrap(),
        "bunny00 turned, binary",
    );
    // In the window the layer is as without the correction; outside it, corrected.
    let o = run_in(
        &dir,
        &[
            &args[..],
            &["--cure-correction", "off", "-q", "-o", "off.dmdjob"],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let mask = |job: &str| read_gray(&dir.join(format!("{job}/masks/{layer:05}.png")));
    let ((w_px, _, on), (_, _, off)) = (mask("b.dmdjob"), mask("off.dmdjob"));
    let b: Vec<usize> = windows[0]["box_px"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let (mut inside, mut outside) = (0, 0);
    for (k, (a, o)) in on.iter().zip(&off).enumerate() {
        let (r, c) = (k / w_px as usize, k % w_px as usize);
        if (b[1]..b[3]).contains(&r) && (b[0]..b[2]).contains(&c) {
            assert_eq!(a, o, "row {r}, column {c}, in the window");
            inside += usize::from(*a > 0);
        } else {
            outside += usize::from(a != o);
        }
    }
    assert!(
        inside > 0 && outside > 0,
        "{inside} lit in the window, {outside} moved outside it"
    );
}

#[test]
fn a_head_too_thin_to_cure_is_named_as_a_support_head() {
    let dir = tempdir("supports-thin-head");
    let cube = fixture("cube10.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            cube.to_str().unwrap(),
            "--supports",
            "--set",
            "supports.head_front_diameter_mm=0.06",
            "--json",
            "-o",
            "c.dmdjob",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let w = &warnings_of(&v, "cure.features-widened")[0];
    let m = w["message"].as_str().unwrap();
    assert!(
        m.contains("in the head of the support of the point at x ")
            && m.contains("supports.head_front_diameter_mm"),
        "{m}"
    );
}

#[test]
fn bad_support_settings_and_a_pad_off_the_field_are_one_line_errors() {
    let dir = tempdir("supports-errors");
    let cube = fixture("cube10.stl");
    let cube = cube.to_str().unwrap();
    let o = run_in(
        &dir,
        &[
            "slice",
            cube,
            "--supports",
            "--set",
            "supports.spacing_mm=0",
            "-o",
            "x.dmdjob",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(
        e.contains("supports.spacing_mm = 0.0 is outside 0.2..100"),
        "{e}"
    );
    // --supports-stl without --supports.
    let o = run_in(
        &dir,
        &["slice", cube, "--supports-stl", "s.stl", "-o", "x.dmdjob"],
    );
    assert_eq!(o.status.code(), Some(2));
    // A T in the field's corner: the pillars under its bar would stand off the field.
    let tee = test_parts(&dir)[1].1.clone();
    let tee = tee.to_str().unwrap();
    let o = run_in(
        &dir,
        &[
            "slice",
            tee,
            "--supports",
            "--keep-position",
            "--supports-stl",
            "s.stl",
            "-o",
            "x.dmdjob",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("beyond the build field"), "{e}");
    assert!(!dir.join("x.dmdjob").exists() && !dir.join("s.stl").exists());
    // One support mesh for parts sliced one by one (no -o): a usage error, nothing written.
    std::fs::copy(cube, dir.join("cube10.stl")).unwrap();
    let o = run_in(
        &dir,
        &[
            "slice",
            "cube10.stl",
            tee,
            "--supports",
            "--supports-stl",
            "s.stl",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(
        e.contains("--supports-stl names one file") && e.contains("--plate"),
        "{e}"
    );
    for left in ["cube10.dmdjob", "tee.dmdjob", "s.stl"] {
        assert!(!dir.join(left).exists(), "{left}");
    }
}
