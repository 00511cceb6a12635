//! Narrow features the XY correction would starve are drawn back and wider so they cure
//! (`cure.features-widened`, docs/CURE.md): `fixtures/thin_pin.stl`'s 0.05 mm pin and a
//! 0.04 mm wall written here, checked by the brute-force evaluation of `cure.rs` on the
//! written masks (compensation off: the mask's values are the relative irradiance).

use crate::common::*;
use crate::cure::{mid_threshold as threshold, Oracle, P, ROWS};
use serde_json::Value;
use std::path::Path;

/// Slices `model` at its file position with the compensation off, `--predict` and
/// `--cure-correction correction`; the `--json` summary.
fn slice(dir: &Path, model: &Path, out: &str, correction: &str) -> Value {
    let o = run_in(
        dir,
        &[
            "slice",
            model.to_str().unwrap(),
            "--keep-position",
            "--compensation",
            "off",
            "--predict",
            "--cure-correction",
            correction,
            "-q",
            "--json",
            "-o",
            out,
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The oracle's largest light (of the layer and the layers above, at the layer's top) on
/// a 0.05 px grid over the field pixel box [u0, u1] × [v0, v1] of layer `layer`.
fn peak(b: &Path, layer: usize, u: [f64; 2], v: [f64; 2]) -> f64 {
    let job: Value = serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap();
    let oracle = Oracle::of_layer(b, &job, layer);
    let n = |a: [f64; 2]| ((a[1] - a[0]) / 0.05).round() as usize;
    let mut best = 0.0f64;
    for i in 0..=n(u) {
        for j in 0..=n(v) {
            best = best.max(oracle.light(u[0] + 0.05 * i as f64, v[0] + 0.05 * j as f64));
        }
    }
    best
}

/// The one `cure.features-widened` warning of the slice summary `v`, which names no
/// feature that vanishes.
fn widened_only(v: &Value) -> &Value {
    assert!(
        warnings_of(v, "cure.features-vanish").is_empty(),
        "{}",
        v["warnings"]
    );
    let w = warnings_of(v, "cure.features-widened");
    assert_eq!(w.len(), 1, "{}", v["warnings"]);
    w[0]
}

#[test]
fn a_pin_under_a_pixel_is_widened_with_xy_and_cures() {
    let dir = tempdir("cure-widen-pin");
    let pin = fixture("thin_pin.stl");
    // The pin: x 400 px to 400 px + 0.05 mm, y 300 px to 300 px + 0.05 mm, 6 layers.
    let (u, v) = (400.0 + 0.025 / P, ROWS - 300.0 - 0.025 / P);
    let around = ([u - 1.5, u + 1.5], [v - 1.5, v + 1.5]);
    let t = threshold();

    let xy = slice(&dir, &pin, "xy.dmdjob", "xy");
    // The top layer has no layer above it: its own light alone does not cure the pin
    // within the 1 px the widening may reach; every layer below cures.
    let v = warnings_of(&xy, "cure.features-vanish");
    assert_eq!(v.len(), 1, "{}", xy["warnings"]);
    assert_eq!(v[0]["fields"]["first_layer"], 5, "{}", v[0]);
    assert_eq!(v[0]["fields"]["layers"], 1, "{}", v[0]);
    let w = warnings_of(&xy, "cure.features-widened");
    assert_eq!(w.len(), 1, "{}", xy["warnings"]);
    let f = &w[0]["fields"];
    assert_eq!(f["features"], 6, "{}", w[0]);
    assert_eq!(f["layers"], 6, "{}", w[0]);
    assert_eq!(f["first_layer"], 0, "{}", w[0]);
    assert_eq!(f["width_mm"], 0.05, "{}", w[0]);
    let (x, y) = (f["x_mm"].as_f64().unwrap(), f["y_mm"].as_f64().unwrap());
    assert!((x - (400.0 * P + 0.025)).abs() < 1e-3, "{}", w[0]);
    assert!((y - (300.0 * P + 0.025)).abs() < 1e-3, "{}", w[0]);
    let msg = w[0]["message"].as_str().unwrap();
    assert!(
        msg.starts_with("cure: 6 features too thin to cure were drawn wider so that they cure"),
        "{msg}"
    );
    assert!(msg.contains(&format!(
        "(first: layer 0, at x {x} mm, y {y} mm, 0.05 × 0.05 mm)"
    )));
    assert_eq!(xy["cure"]["predicted"]["vanished"], 1, "{}", xy["cure"]);
    // The executor finds the widened masks within the layers' boxes.
    let o = run_in(&dir, &["run", "xy.dmdjob"]);
    assert!(o.status.success(), "{}{}", stdout(&o), stderr(&o));
    for layer in [0, 3, 4] {
        let l = peak(&dir.join("xy.dmdjob"), layer, around.0, around.1);
        assert!(l >= t, "layer {layer}: the widened pin peaks at {l}, T {t}");
    }

    // Uncorrected, nothing is widened: the pin's own 0.62 coverage cures in its bottom
    // layers (twice the exposure), not in the four above, with fewer layers above them.
    let off = slice(&dir, &pin, "off.dmdjob", "off");
    assert!(warnings_of(&off, "cure.features-widened").is_empty());
    let v = warnings_of(&off, "cure.features-vanish");
    assert_eq!(v.len(), 1, "{}", off["warnings"]);
    assert_eq!(v[0]["fields"]["first_layer"], 2, "{}", v[0]);
    assert_eq!(v[0]["fields"]["layers"], 4, "{}", v[0]);
    let l = peak(&dir.join("off.dmdjob"), 0, around.0, around.1);
    assert!(l >= t, "uncorrected: {l}, T {t}");
}

#[test]
fn a_pin_that_would_not_cure_uncorrected_is_drawn_wider_and_cures() {
    let dir = tempdir("cure-widen-tiny-pin");
    // A 0.02 mm pin at pixel (400, 300): uncorrected it cures nowhere (`cure_dropped.rs`).
    let (model, _) = tiny_pin_part(&dir);
    let xy = slice(&dir, &model, "xy.dmdjob", "xy");
    let w = widened_only(&xy);
    assert_eq!(w["fields"]["features"], 6, "{}", w);
    assert_eq!(w["fields"]["width_mm"], 0.02, "{}", w);
    let (u, v) = (400.0 + 0.01 / P, ROWS - 300.0 - 0.01 / P);
    let l = peak(
        &dir.join("xy.dmdjob"),
        2,
        [u - 1.5, u + 1.5],
        [v - 1.5, v + 1.5],
    );
    let t = threshold();
    assert!(l >= t, "{l}, T {t}");
    // At the layer's top right corner it grows only down and left, within the box.
    let o = run_in(&dir, &["run", "xy.dmdjob"]);
    assert!(o.status.success(), "{}{}", stdout(&o), stderr(&o));
    let off = slice(&dir, &model, "off.dmdjob", "off");
    let l = peak(
        &dir.join("off.dmdjob"),
        2,
        [u - 1.5, u + 1.5],
        [v - 1.5, v + 1.5],
    );
    assert!(l < 0.5 * t, "uncorrected: {l}, T {t}");
    assert_eq!(warnings_of(&off, "cure.features-vanish").len(), 1);
}

#[test]
fn a_pin_whose_facets_face_inwards_is_drawn_wider_as_well() {
    // The pin above with its facets turned inwards (a shell that runs backwards; the block
    // keeps the mesh's volume positive): filled all the same, and found as narrow.
    let dir = tempdir("cure-widen-backwards-pin");
    let (mut tris, _) = tiny_pin_tris();
    let pin = tris.len() - 12;
    tris[pin..].iter_mut().for_each(|t| t.swap(1, 2));
    let model = dir.join("back.stl");
    write_stl(&model, &tris);
    let xy = slice(&dir, &model, "xy.dmdjob", "xy");
    let w = widened_only(&xy);
    assert_eq!(w["fields"]["features"], 6, "{}", w);
    // Uncorrected, the prediction finds it vanish as it does the forward pin.
    let (forward, _) = tiny_pin_part(&dir);
    let [back, fwd] = [&model, &forward].map(|m| {
        let off = slice(&dir, m, "off.dmdjob", "off");
        let v = warnings_of(&off, "cure.features-vanish");
        assert_eq!(v.len(), 1, "{}", off["warnings"]);
        v[0]["fields"].clone()
    });
    assert_eq!(back, fwd);
}

#[test]
fn a_thin_wall_is_widened_with_xy_and_cures_and_the_block_beside_it_is_not_changed() {
    let dir = tempdir("cure-widen-wall");
    let p = P as f32;
    // A block, and a wall 0.04 mm (0.63 px) wide and 40 px long at a fraction of a pixel,
    // 0.2 mm tall (4 layers).
    let block = || box_tris([200.0 * p, 200.0 * p, 0.0], [300.0 * p, 300.0 * p, 0.2]);
    let mut tris = block();
    let x0 = 400.3 * p;
    tris.extend(box_tris([x0, 250.0 * p, 0.0], [x0 + 0.04, 290.0 * p, 0.2]));
    let model = dir.join("wall.stl");
    write_stl(&model, &tris);
    let xy = slice(&dir, &model, "xy.dmdjob", "xy");
    // The two bottom layers, at twice the exposure, cure it as drawn; the two above are
    // widened.
    let w = widened_only(&xy);
    assert_eq!(w["fields"]["features"], 2, "{}", w);
    assert_eq!(w["fields"]["first_layer"], 2, "{}", w);
    assert_eq!(w["fields"]["width_mm"], 0.04, "{}", w);
    // Along the wall, away from its ends, the light peaks above T.
    let t = threshold();
    let u = 400.3 + 0.02 / P;
    for row in [255.0, 270.0, 285.0] {
        let v = ROWS - row;
        let l = peak(&dir.join("xy.dmdjob"), 1, [u - 1.5, u + 1.5], [v, v]);
        assert!(l >= t, "row {row}: {l}, T {t}");
    }
    let o = run_in(&dir, &["run", "xy.dmdjob"]);
    assert!(o.status.success(), "{}{}", stdout(&o), stderr(&o));
    // The block alone has the same masks: the wall's widening stays near the wall.
    let alone = dir.join("block.stl");
    write_stl(&alone, &block());
    let b = slice(&dir, &alone, "block.dmdjob", "xy");
    assert!(warnings_of(&b, "cure.features-widened").is_empty());
    let (wd, _, with) = read_gray(&dir.join("xy.dmdjob/masks/00001.png"));
    let (_, _, without) = read_gray(&dir.join("block.dmdjob/masks/00001.png"));
    let w = wd as usize;
    for r in 0..ROWS as usize {
        for c in 0..380 {
            assert_eq!(with[r * w + c], without[r * w + c], "({c}, {r})");
        }
    }
}

#[test]
fn with_xyz_a_narrow_bar_is_widened_only_above_its_held_back_layers() {
    let dir = tempdir("cure-widen-xyz");
    // A block on the platform and a 0.04 mm bar over nothing, z 1.0 to 1.5 mm (layers 20
    // to 29): xyz holds its first 4 layers back (the default profile's print-through).
    let p = P as f32;
    let mut tris = box_tris([200.0 * p, 200.0 * p, 0.0], [300.0 * p, 300.0 * p, 1.5]);
    let x0 = 400.3 * p;
    tris.extend(box_tris([x0, 250.0 * p, 1.0], [x0 + 0.04, 290.0 * p, 1.5]));
    let model = dir.join("bar.stl");
    write_stl(&model, &tris);
    let v = slice(&dir, &model, "xyz.dmdjob", "xyz");
    // Below its top layers the bar cures from the light of the layers above it too: only
    // the last two, with little light above, are widened.
    let w = widened_only(&v);
    let f = &w["fields"];
    assert_eq!(f["first_layer"], 28, "{}", w);
    assert_eq!(f["features"], 2, "{}", w);
    let o = run_in(&dir, &["run", "xyz.dmdjob"]);
    assert!(o.status.success(), "{}{}", stdout(&o), stderr(&o));
    // A held-back layer stays dark there.
    let (wd, _, m) = read_gray(&dir.join("xyz.dmdjob/masks/00021.png"));
    let r0 = (ROWS - 290.0) as usize;
    for r in r0 - 2..r0 + 42 {
        for c in 398..404 {
            assert_eq!(m[r * wd as usize + c], 0, "({c}, {r})");
        }
    }
}
