//! Features the cure model leaves out, named by position: flat features over nothing that
//! the Z correction (`--cure-correction xyz`) drops (`cure.features-dropped`), and features
//! too thin to cure (`cure.features-vanish`). Fixtures from `fixtures/make_fixtures.py`.

use crate::common::*;
use serde_json::Value;
use std::path::Path;

/// Pixel edge of the default profile, mm.
const P: f64 = 0.0634765625;

/// The tab of `tab2.stl` and `tab5.stl` on the build plane: x and y ranges, mm.
const TAB_X: [f64; 2] = [300.0 * P, 360.0 * P];
const TAB_Y: [f64; 2] = [230.0 * P, 270.0 * P];

/// Slices `model` in `dir` at its file position with `args` added; the `--json` summary
/// and the bundle's `job.json`.
fn slice(dir: &Path, model: &Path, out: &str, args: &[&str]) -> (Value, Value) {
    let mut a = vec![
        "slice",
        model.to_str().unwrap(),
        "--keep-position",
        "-q",
        "--json",
        "-o",
        out,
    ];
    a.extend_from_slice(args);
    let o = run_in(dir, &a);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: Value = serde_json::from_slice(&o.stdout).unwrap();
    let job = std::fs::read(dir.join(out).join("job.json")).unwrap();
    (summary, serde_json::from_slice(&job).unwrap())
}

/// Whether the warning's position lies in the box `[x, y]` (mm), its figures and its
/// message alike.
fn names_a_point_in(w: &Value, x: [f64; 2], y: [f64; 2]) {
    let f = &w["fields"];
    let (wx, wy) = (f["x_mm"].as_f64().unwrap(), f["y_mm"].as_f64().unwrap());
    assert!(x[0] < wx && wx < x[1], "{w}");
    assert!(y[0] < wy && wy < y[1], "{w}");
    let msg = w["message"].as_str().unwrap();
    assert!(msg.contains(&format!("at x {wx} mm, y {wy} mm, ")), "{msg}");
}

#[test]
fn xyz_names_a_flat_tab_it_drops_and_xy_does_not() {
    let dir = tempdir("cure-dropped-tab");
    let tab = fixture("tab2.stl");
    let (v, job) = slice(&dir, &tab, "xyz.dmdjob", &["--cure-correction", "xyz"]);
    let held = v["cure"]["held_back_layers"].as_u64().unwrap();
    assert_eq!(
        held, 4,
        "the fixtures are made for the default profile's 4 layers"
    );
    let w = warnings_of(&v, "cure.features-dropped");
    assert_eq!(w.len(), 1, "{}", v["warnings"]);
    let w = w[0];
    assert_eq!(w["severity"], "warning");
    names_a_point_in(w, TAB_X, TAB_Y);
    let f = &w["fields"];
    // The tab is layers 20 and 21 (z 1.0 to 1.1 mm), 60 × 40 px: one feature, ending in 21.
    assert_eq!(f["features"], 1, "{w}");
    assert_eq!(f["pixels"], 60 * 40, "{w}");
    assert_eq!(f["first_layer"], 21, "{w}");
    assert_eq!(f["held_back_layers"], 4, "{w}");
    assert!(
        (f["width_mm"].as_f64().unwrap() - 60.0 * P).abs() < 1e-3,
        "{w}"
    );
    assert!(
        (f["height_mm"].as_f64().unwrap() - 40.0 * P).abs() < 1e-3,
        "{w}"
    );
    let msg = w["message"].as_str().unwrap();
    assert!(msg.contains("layer 21"), "{msg}");
    assert!(msg.contains("--cure-correction xy"), "{msg}");
    assert!(msg.contains("5 layers (0.25 mm)"), "{msg}");
    // The bundle records it, and its masks have indeed no tab.
    let d = &job["cure"]["dropped"];
    assert_eq!(d["features"], 1, "{d}");
    assert_eq!(d["pixels"], 2400, "{d}");
    assert_eq!(d["first_layer"], 21, "{d}");
    assert_eq!(job["warnings"], v["warnings"]);
    let tab_pixel = |bundle: &str, layer: usize| {
        let (w, h, px) = read_gray(&dir.join(bundle).join(format!("masks/{layer:05}.png")));
        // Column 330, the row of y = 250 px from the bottom.
        px[(h as usize - 1 - 250) * w as usize + 330]
    };
    for layer in [20, 21] {
        assert_eq!(tab_pixel("xyz.dmdjob", layer), 0, "layer {layer}");
    }

    // With `xy` the tab is drawn and nothing is dropped: no warning, no record.
    let (v, job) = slice(&dir, &tab, "xy.dmdjob", &["--cure-correction", "xy"]);
    assert!(
        warnings_of(&v, "cure.features-dropped").is_empty(),
        "{}",
        v["warnings"]
    );
    assert!(job["cure"].get("dropped").is_none(), "{}", job["cure"]);
    assert!(tab_pixel("xy.dmdjob", 21) > 0);
}

#[test]
fn a_tab_one_layer_thicker_than_the_held_back_layers_is_drawn_without_a_warning() {
    let dir = tempdir("cure-dropped-tab5");
    let (v, job) = slice(
        &dir,
        &fixture("tab5.stl"),
        "xyz.dmdjob",
        &["--cure-correction", "xyz"],
    );
    assert!(
        warnings_of(&v, "cure.features-dropped").is_empty(),
        "{}",
        v["warnings"]
    );
    let d = &job["cure"]["dropped"];
    assert_eq!(
        (&d["features"], &d["pixels"]),
        (&0.into(), &0.into()),
        "{d}"
    );
    // The tab's top layer (24, z 1.2 to 1.25 mm) is its one drawn layer (a compensated
    // gray), the one below it is held back.
    let tab_pixel = |layer: usize| {
        let (w, h, px) = read_gray(&dir.join(format!("xyz.dmdjob/masks/{layer:05}.png")));
        px[(h as usize - 1 - 250) * w as usize + 330]
    };
    assert!(tab_pixel(24) > 0);
    assert_eq!(tab_pixel(23), 0);
}

#[test]
fn a_tab_at_the_top_of_the_job_is_named_and_one_on_the_platform_is_not() {
    let dir = tempdir("cure-dropped-top");
    // A 1.1 mm block (22 layers) whose top two layers have a tab over nothing, and beside it
    // a 2-layer plate on the platform (layers below the platform count as lit).
    let p = P as f32;
    let mut tris = box_tris([200.0 * p, 200.0 * p, 0.0], [300.0 * p, 300.0 * p, 1.1]);
    tris.extend(box_tris(
        [300.0 * p, 230.0 * p, 1.0],
        [360.0 * p, 270.0 * p, 1.1],
    ));
    tris.extend(box_tris(
        [500.0 * p, 200.0 * p, 0.0],
        [600.0 * p, 300.0 * p, 0.1],
    ));
    let model = dir.join("top.stl");
    write_stl(&model, &tris);
    let (v, job) = slice(&dir, &model, "top.dmdjob", &["--cure-correction", "xyz"]);
    assert_eq!(v["layers"], 22);
    let w = warnings_of(&v, "cure.features-dropped");
    assert_eq!(w.len(), 1, "{}", v["warnings"]);
    names_a_point_in(w[0], TAB_X, TAB_Y);
    assert_eq!(w[0]["fields"]["first_layer"], 21, "{}", w[0]);
    assert_eq!(w[0]["fields"]["features"], 1, "{}", w[0]);
    assert_eq!(job["cure"]["dropped"]["layers"], 1);
}

#[test]
fn a_pin_too_thin_to_cure_is_named_by_its_position() {
    let dir = tempdir("cure-vanish-pin");
    // A 0.02 mm pin, uncorrected, as the xy correction would widen it (`cure_widen.rs`).
    let (model, [x0, y0]) = tiny_pin_part(&dir);
    let (v, _) = slice(
        &dir,
        &model,
        "pin.dmdjob",
        &["--predict", "--cure-correction", "off"],
    );
    let w = warnings_of(&v, "cure.features-vanish");
    assert_eq!(w.len(), 1, "{}", v["warnings"]);
    let w = w[0];
    names_a_point_in(w, [x0, x0 + 0.02], [y0, y0 + 0.02]);
    let f = &w["fields"];
    assert_eq!(f["features"], 6, "{w}");
    assert_eq!(f["first_layer"], 0, "{w}");
    assert_eq!(f["width_mm"], 0.02, "{w}");
    assert_eq!(f["height_mm"], 0.02, "{w}");
    let msg = w["message"].as_str().unwrap();
    assert!(msg.contains("(first: layer 0, at x "), "{msg}");
    assert!(msg.contains(", 0.02 × 0.02 mm)"), "{msg}");
}

#[test]
fn a_tab_exactly_as_thick_as_the_held_back_layers_across_two_windows_is_named() {
    let dir = tempdir("cure-dropped-tab4");
    // Layers 30 to 33 (z 1.5 to 1.7 mm): 4 layers, the default held-back count, across the
    // pipeline's 32-layer windows. Finding it needs the 5 layers below layer 34.
    let p = P as f32;
    let mut tris = box_tris([200.0 * p, 200.0 * p, 0.0], [300.0 * p, 300.0 * p, 2.0]);
    tris.extend(box_tris(
        [300.0 * p, 230.0 * p, 1.5],
        [360.0 * p, 270.0 * p, 1.7],
    ));
    let model = dir.join("tab4.stl");
    write_stl(&model, &tris);
    for threads in ["1", "3"] {
        let out = format!("t{threads}.dmdjob");
        let o = run_threads(
            &dir,
            &[
                "slice",
                model.to_str().unwrap(),
                "--keep-position",
                "-q",
                "--json",
                "--cure-correction",
                "xyz",
                "-o",
                &out,
            ],
            threads,
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        let w = warnings_of(&v, "cure.features-dropped");
        assert_eq!(w.len(), 1, "{}", v["warnings"]);
        names_a_point_in(w[0], TAB_X, TAB_Y);
        let f = &w[0]["fields"];
        assert_eq!(
            (&f["first_layer"], &f["pixels"]),
            (&33.into(), &2400.into())
        );
    }
}
