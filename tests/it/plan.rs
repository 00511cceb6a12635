//! Process planning as a user sees it: `dmdsl slice --profile …` on generated parts, checked
//! layer by layer from the written `job.json` (for the hybrid profile: the cases Li, Wu, Cui,
//! Yang and Zhao printed in their model-guided hybrid layered/continuous DLP printing paper).

use crate::common::*;
use serde_json::Value;
use std::f64::consts::PI;
use std::path::Path;

type Tri = [[f32; 3]; 3];

/// Regular n-gon, counter-clockwise, first vertex at angle 0.
fn ngon(r: f64, n: usize) -> Vec<[f64; 2]> {
    (0..n)
        .map(|i| {
            let a = 2.0 * PI * i as f64 / n as f64;
            [r * a.cos(), r * a.sin()]
        })
        .collect()
}

fn square(s: f64) -> Vec<[f64; 2]> {
    let h = s / 2.0;
    vec![[-h, -h], [h, -h], [h, h], [-h, h]]
}

fn p3(p: [f64; 2], z: f64) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, z as f32]
}

/// Closed prism over a convex counter-clockwise polygon, z0..z1, outward facing.
fn prism(poly: &[[f64; 2]], z0: f64, z1: f64) -> Vec<Tri> {
    let n = poly.len();
    let c = [
        poly.iter().map(|p| p[0]).sum::<f64>() / n as f64,
        poly.iter().map(|p| p[1]).sum::<f64>() / n as f64,
    ];
    let mut t = Vec::new();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        t.push([p3(a, z0), p3(b, z0), p3(b, z1)]);
        t.push([p3(a, z0), p3(b, z1), p3(a, z1)]);
        t.push([p3(c, z1), p3(a, z1), p3(b, z1)]);
        t.push([p3(c, z0), p3(b, z0), p3(a, z0)]);
    }
    t
}

/// Closed tube between two counter-clockwise loops with corresponding vertices (the inner
/// loop strictly inside the outer), z0..z1, outward facing.
fn tube(outer: &[[f64; 2]], inner: &[[f64; 2]], z0: f64, z1: f64) -> Vec<Tri> {
    assert_eq!(outer.len(), inner.len());
    let n = outer.len();
    let mut t = Vec::new();
    for i in 0..n {
        let j = (i + 1) % n;
        let (a, b) = (outer[i], outer[j]);
        t.push([p3(a, z0), p3(b, z0), p3(b, z1)]);
        t.push([p3(a, z0), p3(b, z1), p3(a, z1)]);
        // Inner wall faces the hole: reversed.
        let (a, b) = (inner[i], inner[j]);
        t.push([p3(b, z0), p3(a, z0), p3(a, z1)]);
        t.push([p3(b, z0), p3(a, z1), p3(b, z1)]);
        // Annular caps.
        let (oa, ob, ia, ib) = (outer[i], outer[j], inner[i], inner[j]);
        t.push([p3(oa, z1), p3(ob, z1), p3(ib, z1)]);
        t.push([p3(oa, z1), p3(ib, z1), p3(ia, z1)]);
        t.push([p3(oa, z0), p3(ib, z0), p3(ob, z0)]);
        t.push([p3(oa, z0), p3(ia, z0), p3(ib, z0)]);
    }
    t
}

fn slice_json(dir: &Path, stl: &str, tris: &[Tri], extra: &[&str]) -> (Value, Value) {
    write_stl(&dir.join(stl), tris);
    let mut args = vec!["slice", stl, "--json"];
    args.extend_from_slice(extra);
    let o = run_in(dir, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let bundle = dir.join(summary["bundle"].as_str().unwrap());
    let job: Value =
        serde_json::from_slice(&std::fs::read(bundle.join("job.json")).unwrap()).unwrap();
    (summary, job)
}

/// `dmdsl slice STL -q --layer-height 0.1 -o t<threads>.dmdjob` in `dir` on `threads`
/// worker threads; the bundle's path.
fn slice_with_threads(dir: &Path, stl: &str, threads: &str, extra: &[&str]) -> std::path::PathBuf {
    let out = format!("t{threads}.dmdjob");
    let mut args = vec!["slice", stl, "-q", "--layer-height", "0.1", "-o", &out];
    args.extend_from_slice(extra);
    let o = run_threads(dir, &args, threads);
    assert!(o.status.success(), "{}", stderr(&o));
    dir.join(out)
}

fn layers(job: &Value) -> &Vec<Value> {
    job["layers"].as_array().unwrap()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

/// Highest `to_mm` of a layer's steps minus its exposure position.
fn lift(layer: &Value) -> f64 {
    let top = layer["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s.get("to_mm").map(f))
        .fold(f64::NEG_INFINITY, f64::max);
    top - f(&layer["z_mm"])
}

/// The built-in profile `job` was sliced on.
fn profile_of(job: &Value) -> dmdsl::Profile {
    dmdsl::Profile::resolve(job["machine"]["name"].as_str().unwrap()).unwrap()
}

/// The hybrid profile's bottom + transition layers (always layered) and bottom layers.
fn hybrid_ramp(job: &Value) -> (usize, usize) {
    let e = profile_of(job).exposure;
    let b = e.bottom_layers as usize;
    (b + e.transition_layers as usize, b)
}

/// What a layered slice after the ramp must lift, by the hybrid printing paper's table.
fn olh(fill: f64) -> f64 {
    if fill <= 5.02 {
        2.0
    } else if fill <= 7.52 {
        4.0
    } else {
        8.0
    }
}

/// Checks every layer of a hybrid job whose sections all have max fill distance `fill`.
fn check_uniform_hybrid(job: &Value, fill: f64, continuous: bool) {
    let (ramp, bottom) = hybrid_ramp(job);
    let ls = layers(job);
    assert!(ls.len() > ramp + 2, "part too short for the check");
    for (i, l) in ls.iter().enumerate() {
        let mfd = f(&l["max_fill_distance_mm"]);
        assert!((mfd - fill).abs() <= 0.02, "layer {i}: {mfd} vs {fill}");
        let mode = l["mode"].as_str().unwrap();
        if i < ramp || !continuous {
            assert_eq!(mode, "layered", "layer {i}");
            if i > 0 {
                let want = if i - 1 < bottom {
                    olh(fill).max(8.0)
                } else {
                    olh(fill)
                };
                assert!((lift(l) - want).abs() < 1e-9, "layer {i}: lift {}", lift(l));
            }
            let last = l["steps"].as_array().unwrap().last().unwrap();
            assert_eq!(last["kind"], "expose");
        } else {
            assert_eq!(mode, "continuous", "layer {i}");
            let steps = l["steps"].as_array().unwrap();
            let last = steps.last().unwrap();
            assert_eq!(last["kind"], "sweep");
            assert_eq!(f(&last["to_mm"]), f(&l["z_mm"]));
            assert_eq!(f(&last["speed_mm_s"]), 0.06);
            // The sweep's light time, to 7 significant digits.
            assert!((f(&l["exposure_s"]) - 0.1 / 0.06).abs() < 1e-6);
            // No lift: the stage never goes above the layer it prints.
            assert!(lift(l) <= 1e-12);
            if i > ramp {
                assert_eq!(steps.len(), 1, "layer {i}: one sweep inside a run");
            }
        }
    }
}

#[test]
fn li_hybrid_square_prism_5mm_prints_continuously() {
    let dir = tempdir("plan-prism5");
    let (summary, job) = slice_json(
        &dir,
        "prism5.stl",
        &prism(&square(5.0), 0.0, 1.2),
        &["--profile", "hybrid-bottomup"],
    );
    check_uniform_hybrid(&job, 2.5, true);
    let (ramp, _) = hybrid_ramp(&job);
    let t = &summary["totals"];
    assert_eq!(t["continuous_layers"].as_u64().unwrap() as usize, 12 - ramp);
    let all = f(&t["all_layered_time_s"]);
    assert!(all > f(&t["print_time_s"]), "{t}");
    assert_eq!(&job["totals"], t);
}

#[test]
fn li_hybrid_cube_10mm_layered_lift_2mm() {
    let dir = tempdir("plan-cube10");
    let (_, job) = slice_json(
        &dir,
        "cube10.stl",
        &box_tris([0.0, 0.0, 0.0], [10.0, 10.0, 1.0]),
        &["--profile", "hybrid-bottomup"],
    );
    check_uniform_hybrid(&job, 5.0, false);
    // All layered: the comparison plan is the plan itself.
    let t = &job["totals"];
    assert_eq!(t["continuous_layers"], 0);
    assert!((f(&t["all_layered_time_s"]) - f(&t["print_time_s"])).abs() < 1e-9);
}

#[test]
fn li_hybrid_cube_and_cylinder_15mm_lift_4mm() {
    let dir = tempdir("plan-15");
    let (_, job) = slice_json(
        &dir,
        "cube15.stl",
        &box_tris([0.0, 0.0, 0.0], [15.0, 15.0, 1.0]),
        &["--profile", "hybrid-bottomup"],
    );
    check_uniform_hybrid(&job, 7.5, false);
    // A 128-gon of circumradius 7.5 mm: inradius 7.5·cos(π/128).
    let (_, job) = slice_json(
        &dir,
        "cyl15.stl",
        &prism(&ngon(7.5, 128), 0.0, 1.0),
        &["--profile", "hybrid-bottomup"],
    );
    check_uniform_hybrid(&job, 7.5 * (PI / 128.0).cos(), false);
}

#[test]
fn li_hybrid_cylinder_20mm_and_square_30mm_lift_8mm() {
    let dir = tempdir("plan-20-30");
    let (_, job) = slice_json(
        &dir,
        "cyl20.stl",
        &prism(&ngon(10.0, 128), 0.0, 1.0),
        &["--profile", "hybrid-bottomup"],
    );
    check_uniform_hybrid(&job, 10.0 * (PI / 128.0).cos(), false);
    let (_, job) = slice_json(
        &dir,
        "sq30.stl",
        &box_tris([0.0, 0.0, 0.0], [30.0, 30.0, 1.0]),
        &["--profile", "hybrid-bottomup"],
    );
    check_uniform_hybrid(&job, 15.0, false);
}

#[test]
fn li_hybrid_tower_alternates_layered_solids_and_continuous_hollows() {
    // Sections, bottom up; each rests on the one below. The first is tall enough to hold
    // the bottom and transition layers.
    let cos96 = (PI / 96.0).cos();
    // (expected max fill distance, continuous?, section height)
    let plan: Vec<(f64, bool, f64)> = vec![
        (4.5, false, 1.0), // solid 9 mm square: (2.5, 5] → 2 mm
        // 9/7 mm square tube, 1 mm wall: the largest circle sits in a corner, touching
        // the two outer sides and the inner corner: 2 − √2.
        (2.0 - std::f64::consts::SQRT_2, true, 0.5),
        (10.0 * cos96, false, 0.5),           // solid 20 mm cylinder: 8 mm
        (0.75, true, 0.5),                    // 20/17 mm ring, 1.5 mm wall
        (7.0, false, 0.5),                    // solid 14 mm square: 4 mm
        (2.5 * (PI / 64.0).cos(), true, 0.5), // solid 5 mm cylinder: continuous
    ];
    let mut zs = Vec::new();
    let mut z = 0.0;
    for p in &plan {
        zs.push((z, z + p.2));
        z += p.2;
    }
    let (c20, c17) = (ngon(10.0, 96), ngon(8.5, 96));
    let shapes = [
        prism(&square(9.0), zs[0].0, zs[0].1),
        tube(&square(9.0), &square(7.0), zs[1].0, zs[1].1),
        prism(&c20, zs[2].0, zs[2].1),
        tube(&c20, &c17, zs[3].0, zs[3].1),
        prism(&square(14.0), zs[4].0, zs[4].1),
        prism(&ngon(2.5, 64), zs[5].0, zs[5].1),
    ];
    let tris: Vec<Tri> = shapes.concat();
    let dir = tempdir("plan-tower");
    let (summary, job) = slice_json(&dir, "tower.stl", &tris, &["--profile", "hybrid-bottomup"]);
    let (ramp, bottom) = hybrid_ramp(&job);
    let ls = layers(&job);
    assert_eq!(ls.len(), 35);
    let mut section_of = Vec::new();
    for (k, p) in plan.iter().enumerate() {
        section_of.extend(std::iter::repeat_n(k, (p.2 / 0.1).round() as usize));
    }
    let mut prev_mode = "";
    for (i, l) in ls.iter().enumerate() {
        let (fill, cont, _) = plan[section_of[i]];
        let mfd = f(&l["max_fill_distance_mm"]);
        assert!((mfd - fill).abs() <= 0.02, "layer {i}: {mfd} vs {fill}");
        let mode = l["mode"].as_str().unwrap();
        let steps = l["steps"].as_array().unwrap();
        if cont && i >= ramp {
            assert_eq!(mode, "continuous", "layer {i}");
            assert_eq!(steps.last().unwrap()["kind"], "sweep");
            if prev_mode == "layered" {
                // Explicit switch: settle, then start the run from the last exposure.
                assert_eq!(steps[0]["kind"], "wait", "layer {i}");
            } else {
                assert_eq!(steps.len(), 1, "layer {i}");
            }
        } else {
            assert_eq!(mode, "layered", "layer {i}");
            if i > 0 {
                let want = if i - 1 < bottom {
                    olh(fill).max(8.0)
                } else {
                    olh(fill)
                };
                assert!((lift(l) - want).abs() < 1e-9, "layer {i}: lift {}", lift(l));
            }
        }
        assert_eq!(l["islands"], 0, "layer {i}");
        prev_mode = mode;
    }
    let t = &summary["totals"];
    assert_eq!(t["continuous_layers"], 15);
    let (print, all) = (f(&t["print_time_s"]), f(&t["all_layered_time_s"]));
    assert!(all > print, "{all} vs {print}");
    // Each layer's time and the total are rounded to 1 ms.
    let sum: f64 = ls.iter().map(|l| f(&l["time_s"])).sum();
    assert!((sum - print).abs() <= 0.0005 * (ls.len() + 1) as f64);
}

#[test]
fn top_down_default_dips_and_waits_longer_over_wider_tops() {
    // A step pyramid: 2 mm then 1 mm then 0.6 mm wide squares.
    let mut tris = prism(&square(2.0), 0.0, 0.2);
    tris.extend(prism(&square(1.0), 0.2, 0.4));
    tris.extend(prism(&square(0.6), 0.4, 0.6));
    let dir = tempdir("plan-topdown");
    let (summary, job) = slice_json(&dir, "steps.stl", &tris, &[]);
    let r = &serde_json::to_value(profile_of(&job).recoat).unwrap();
    assert_eq!(r["wait_model"], "leveling");
    let ls = layers(&job);
    assert_eq!(ls.len(), 12);
    let wait = |l: &Value| -> f64 {
        l["steps"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["kind"] == "wait")
            .map(|s| f(&s["s"]))
            .sum()
    };
    for l in ls {
        let steps = l["steps"].as_array().unwrap();
        assert_eq!(steps[0]["kind"], "move");
        assert!((lift(l) - f(&r["dip_mm"])).abs() < 1e-9);
        assert_eq!(steps.last().unwrap()["kind"], "expose");
        let w = wait(l);
        assert!(w >= f(&r["wait_s"]) && w <= f(&r["wait_max_s"]));
    }
    // Wider flat tops wait longer (or hit the cap).
    let (w0, w1, w2) = (wait(&ls[0]), wait(&ls[5]), wait(&ls[10]));
    assert!(w0 >= w1 && w1 >= w2 && w0 > w2, "{w0} {w1} {w2}");
    assert!((f(&ls[0]["max_fill_distance_mm"]) - 1.0).abs() <= 0.02);
    assert!(summary["totals"].get("all_layered_time_s").is_none());
}

#[test]
fn bottom_up_lifts_higher_and_peels_slower_for_larger_layers() {
    // 30 mm square base, then a 5 mm square column.
    let mut tris = prism(&square(30.0), 0.0, 0.5);
    tris.extend(prism(&square(5.0), 0.5, 1.0));
    let dir = tempdir("plan-bottomup");
    let (_, job) = slice_json(&dir, "peel.stl", &tris, &["--profile", "bottom-up"]);
    let ls = layers(&job);
    assert_eq!(ls.len(), 20);
    let slow = |l: &Value| f(&l["steps"].as_array().unwrap()[1]["speed_mm_s"]);
    // Layer 9 peels a base layer, layer 11 a column layer (both after the ramp).
    assert!(
        lift(&ls[9]) > lift(&ls[11]),
        "{} {}",
        lift(&ls[9]),
        lift(&ls[11])
    );
    assert!(slow(&ls[9]) < slow(&ls[11]));
    for l in &ls[1..] {
        let kinds: Vec<&str> = l["steps"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["kind"].as_str().unwrap())
            .collect();
        assert_eq!(kinds, ["wait", "move", "move", "move", "wait", "expose"]);
    }
}

#[test]
fn islands_are_counted_where_a_region_starts_in_mid_air() {
    // Box A from the plate; box B beside it starting at z = 0.5 (floating), and box C on
    // top of A wider than A (overhang, but resting on A).
    let mut tris = box_tris([0.0, 0.0, 0.0], [5.0, 5.0, 1.0]);
    tris.extend(box_tris([10.0, 0.0, 0.5], [14.0, 4.0, 1.0]));
    tris.extend(box_tris([-1.0, -1.0, 1.0], [6.0, 6.0, 1.5]));
    let dir = tempdir("plan-islands");
    let (summary, job) = slice_json(&dir, "isl.stl", &tris, &["--layer-height", "0.1"]);
    let isl: Vec<u64> = layers(&job)
        .iter()
        .map(|l| l["islands"].as_u64().unwrap())
        .collect();
    let mut want = vec![0u64; 15];
    want[5] = 1;
    assert_eq!(isl, want);
    let b = layers(&job)[12]["bbox_mm"].as_array().unwrap().clone();
    let w = f(&b[1][0]) - f(&b[0][0]);
    assert!((w - 7.0).abs() < 1e-6, "{b:?}");
    let islands = summary["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|w| w["code"] == "plan.unsupported-islands")
        .expect("islands warned");
    assert_eq!(islands["severity"], "warning");
    assert_eq!(
        islands["fields"],
        serde_json::json!({"islands": 1, "layers": 1, "first_layer": 5,
            "largest_mm": [[5, 37.991, 23.899, 15.992]]})
    );
    // B, centred with the part on the field, has its centre at (38, 23.875) mm and 16 mm²;
    // its pixels put it within a pixel (0.063 mm) of that.
    assert_eq!(
        islands["message"],
        "1 unsupported island on 1 layer (first at layer 5); largest per layer: layer 5 at x 37.99, y 23.90 mm (15.992 mm²): regions that do not rest on the layer below need supports; slice with --supports to hold them, or orient the part so that they rest on the layer below"
    );
}

#[test]
fn islands_over_masks_shared_across_blocks_whatever_the_threads() {
    // A pillar (a prism: its masks are reused within and across blocks of 8 layers) and
    // two boxes beside it that start in mid-air, one on a block's first layer (16) and one
    // inside a block (27): each counts its islands over the lit pixels of a layer below
    // whose mask another block drew.
    let mut tris = box_tris([0.0, 0.0, 0.0], [5.0, 5.0, 4.0]);
    tris.extend(box_tris([10.0, 0.0, 1.6], [14.0, 4.0, 4.0]));
    tris.extend(box_tris([0.0, 10.0, 2.7], [4.0, 14.0, 4.0]));
    let dir = tempdir("plan-islands-shared");
    write_stl(&dir.join("isl.stl"), &tris);
    let mut want = vec![0u64; 40];
    want[16] = 1;
    want[27] = 1;
    let mut bundles = Vec::new();
    for threads in ["1", "2"] {
        let out = slice_with_threads(&dir, "isl.stl", threads, &[]);
        let job: Value =
            serde_json::from_slice(&std::fs::read(out.join("job.json")).unwrap()).unwrap();
        let isl: Vec<u64> = layers(&job)
            .iter()
            .map(|l| l["islands"].as_u64().unwrap())
            .collect();
        assert_eq!(isl, want, "{threads} threads");
        bundles.push(tree(&out));
    }
    assert!(
        bundles[0] == bundles[1],
        "bundles differ with the thread count"
    );
}

#[test]
fn part_taller_than_the_stage_travel_is_a_one_line_error() {
    let dir = tempdir("plan-travel");
    let src = crate::common::stdout(&run_in(&dir, &["profile", "show", "hybrid-bottomup"]));
    let short = src.replace("travel_max_mm = 150.0", "travel_max_mm = 5.0");
    assert_ne!(short, src);
    std::fs::write(dir.join("short.toml"), short).unwrap();
    write_stl(
        &dir.join("tall.stl"),
        &box_tris([0.0, 0.0, 0.0], [5.0, 5.0, 10.0]),
    );
    let o = run_in(
        &dir,
        &[
            "slice",
            "tall.stl",
            "-p",
            "short.toml",
            "--layer-height",
            "1",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    assert!(
        e.contains("tall.stl: part is 10 mm tall")
            && e.contains("the stage travels only to stage.travel_max_mm = 5 mm"),
        "{e}"
    );
    assert!(!dir.join("tall.dmdjob").exists());
}

#[test]
fn prism_layers_share_masks_and_analysis_whatever_the_threads() {
    // A tower of prisms: a 96-gon cylinder, a square tube, a square block. Every side
    // quad is two triangles, so each layer's contours hold points sliding along the walls
    // (never equal point lists): layers equal to the layer below once those are left out
    // reuse its analysis and mask bytes. Bundles must not depend on the thread count, and
    // every layer after the first two of a section must repeat the layer below.
    let tris: Vec<Tri> = [
        prism(&ngon(10.0, 96), 0.0, 2.0),
        tube(&square(9.0), &square(7.0), 2.0, 4.0),
        prism(&square(14.0), 4.0, 5.0),
    ]
    .concat();
    let dir = tempdir("plan-prism-reuse");
    write_stl(&dir.join("tower.stl"), &tris);
    let mut bundles = Vec::new();
    // Without the cure correction: with it, a layer's masks also follow its dose and the
    // layers above, so the bottom layers and those below a change differ from their
    // neighbours (its thread independence is checked with the islands above).
    for threads in ["1", "3"] {
        let off = ["--cure-correction", "off"];
        bundles.push(tree(&slice_with_threads(&dir, "tower.stl", threads, &off)));
    }
    assert!(
        bundles[0] == bundles[1],
        "bundles differ with the thread count"
    );
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("t1.dmdjob/job.json")).unwrap()).unwrap();
    let ls = layers(&job);
    assert_eq!(ls.len(), 50);
    // (first layer, fill distance, area) of each section.
    let a96 = 0.5 * 96.0 * 100.0 * (2.0 * PI / 96.0).sin();
    let sections = [
        (0, 10.0 * (PI / 96.0).cos(), a96),
        // A 1 mm wall; its corners hold the largest circle: w·(2 − √2).
        (20, 2.0 - 2f64.sqrt(), 81.0 - 49.0),
        (40, 7.0, 196.0),
    ];
    for (i, l) in ls.iter().enumerate() {
        let &(first, fill, area) = sections.iter().rev().find(|s| s.0 <= i).unwrap();
        let mfd = f(&l["max_fill_distance_mm"]);
        assert!(
            fill - 0.02 <= mfd && mfd <= fill + 1e-6,
            "layer {i}: {mfd} vs {fill}"
        );
        let a = f(&l["area_mm2"]);
        assert!(
            (a - area).abs() <= 0.005 * area,
            "layer {i}: area {a} vs {area}"
        );
        assert_eq!(l["islands"], 0, "layer {i}");
        if i >= first + 2 {
            let below = &ls[i - 1];
            assert_eq!(
                l["masks"][0]["sha256"], below["masks"][0]["sha256"],
                "layer {i}"
            );
            assert_eq!(l["max_fill_distance_mm"], below["max_fill_distance_mm"]);
            assert_eq!(l["area_mm2"], below["area_mm2"]);
        }
    }
    // The masks differ between sections, and the files really are there.
    assert_ne!(ls[10]["masks"][0]["sha256"], ls[30]["masks"][0]["sha256"]);
    let (w, h, px) = read_gray(&dir.join("t1.dmdjob/masks/00045.png"));
    assert_eq!((w, h), (1024, 768));
    assert!(px.iter().any(|&v| v > 0));
}

#[test]
fn prism_reaching_outside_the_calibrated_area_counts_every_layer() {
    // The built-in calibration covers y 0..45 mm of the 48.77 mm field: a prism from
    // y 42 to 47 reaches outside on every layer, and every layer must be counted even
    // though its section repeats the layer below's.
    let mut poly = ngon(2.5, 48);
    for p in &mut poly {
        p[0] += 30.0;
        p[1] += 44.5;
    }
    let tris = prism(&poly, 0.0, 2.0);
    let dir = tempdir("plan-prism-outside");
    let (summary, _) = slice_json(
        &dir,
        "p.stl",
        &tris,
        &["--keep-position", "--layer-height", "0.1"],
    );
    let warnings = summary["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w["code"] == "optics.outside-calibrated-area"
                && w["fields"]["layers"] == 20
                && w["message"]
                    .as_str()
                    .unwrap()
                    .starts_with("20 layers reach up to ")),
        "{warnings:?}"
    );
}
