//! Writing a job as a NanoDLP plate: the plate's two sets of layer settings taken from the
//! job ([`plate`]), every layer it then gives back differently named by a warning
//! ([`cannot_carry`]), the masks as `1.png … N.png` (the same bytes), `info.json` measured
//! on them.

use super::{Group, Plate, INFO, META, OPTIONS, PLATE, PREVIEW, PROFILE, SLICER};
use crate::bundle::{BundleSource, Layer, Manifest, Step};
use crate::error::Result;
use crate::formats::archive::write::{Method, ZipOut};
use crate::formats::control::position;
use crate::text::plural;
use crate::warning::Warning;
use serde_json::{json, Map, Value};
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// Two exposures or positions closer than this are the same (the manifest writes whole
/// ms and µm).
const SAME: f64 = 1e-6;

/// The plate's settings for a group whose first layer is `f` (steps from `from_mm`): its
/// cure, thickness and the waits between its last move and the cure from layer `f`; the
/// lift after it (to the farthest point the next layer's steps reach, at their first
/// move's speed), the wait there, the waits before it and the move back from the steps
/// of layer `f + 1`.
fn group(layers: &[Layer], f: usize, from_mm: f64, limits: (f64, f64)) -> Group {
    let l = &layers[f];
    let mut before_s = 0.0;
    for s in l
        .steps
        .iter()
        .take_while(|s| !matches!(s, Step::Expose { .. }))
    {
        match *s {
            Step::Wait { s } => before_s += s,
            _ => before_s = 0.0,
        }
    }
    let approach = position(l, from_mm, limits).0;
    let mut g = Group {
        cure_s: l.exposure_s,
        thickness_mm: l.thickness_mm,
        before_s,
        down: [approach.down_speed, approach.down_accel],
        ..Group::default()
    };
    g.up = g.down;
    if let Some(next) = layers.get(f + 1) {
        let p = position(next, l.z_mm, limits).0;
        let far = next.steps.iter().fold(l.z_mm, |a, s| match *s {
            Step::Move { to_mm, .. } => a.max(to_mm),
            _ => a,
        });
        g.down = [p.down_speed, p.down_accel];
        if far > l.z_mm + SAME {
            (g.lift_mm, g.top_wait_s, g.after_s) = (far - l.z_mm, p.up_wait_s, p.initial_s);
            g.up = [p.up_speed, p.up_accel];
        }
    }
    g
}

/// The layer of `layers` (the ones after the support layers) whose settings the plate's
/// normal set takes: the first exposed as most of them are (a job's ramp from the bottom
/// exposure down to the normal one is thus counted as differing, not the rest of the job);
/// `None` for no layers.
fn normal_layer(layers: &[Layer]) -> Option<usize> {
    let mut exposures: Vec<f64> = layers.iter().map(|l| l.exposure_s).collect();
    exposures.sort_by(f64::total_cmp);
    let (mut best, mut most, mut run) = (*exposures.first()?, 0, 0);
    for (i, &e) in exposures.iter().enumerate() {
        run = match i > 0 && (e - exposures[i - 1]).abs() <= SAME {
            true => run + 1,
            false => 1,
        };
        if run > most {
            (best, most) = (e, run);
        }
    }
    layers
        .iter()
        .position(|l| (l.exposure_s - best).abs() <= SAME)
}

/// The plate of job `m` (at least one layer): its support layers are the first layers
/// exposed as layer 0 when the last layer is exposed otherwise.
fn plate(m: &Manifest) -> Plate {
    let layers = &m.layers;
    let stage = &m.machine.stage;
    let limits = (stage.max_speed_mm_s.get(), stage.max_accel_mm_s2.get());
    let first = layers[0].exposure_s;
    let same = |l: &Layer| (l.exposure_s - first).abs() <= SAME;
    let bottom = match same(&layers[layers.len() - 1]) {
        true => 0,
        false => layers.iter().take_while(|l| same(l)).count(),
    };
    let from = |f: usize| {
        if f == 0 {
            stage.home_mm
        } else {
            layers[f - 1].z_mm
        }
    };
    let support = group(layers, 0, from(0), limits);
    let other = match normal_layer(&layers[bottom..]) {
        Some(f) => group(layers, bottom + f, from(bottom + f), limits),
        None => support,
    };
    Plate {
        bottom,
        groups: [support, other],
    }
}

/// True when two step lists are the same within [`SAME`].
fn same_steps(a: &[Step], b: &[Step]) -> bool {
    let near = |x: f64, y: f64| (x - y).abs() <= SAME * x.abs().max(1.0);
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| match (*x, *y) {
            (Step::Wait { s }, Step::Wait { s: t })
            | (Step::Expose { s }, Step::Expose { s: t }) => near(s, t),
            (
                Step::Move {
                    to_mm: a,
                    speed_mm_s: b,
                    accel_mm_s2: c,
                },
                Step::Move {
                    to_mm: d,
                    speed_mm_s: e,
                    accel_mm_s2: f,
                },
            ) => near(a, d) && near(b, e) && near(c, f),
            _ => false,
        })
}

/// A warning of `code` for the layers `bad` (their indices), `what` saying what they
/// have.
fn layers_warning(code: &str, bad: &[u64], what: &str) -> Option<Warning> {
    let (&first, k) = (bad.first()?, bad.len() as u64);
    let msg = format!(
        "{k} {} {what} (first: layer {first}); {} the plate's",
        plural(k, "layer has", "layers have"),
        plural(k, "it gets", "they get")
    );
    Some(
        Warning::new(code, msg)
            .with("layers", k)
            .with("first_layer", first),
    )
}

/// What a plate cannot carry of `m` (one projector, at least one layer): the layers it
/// gives another exposure, thickness or steps than the job's, a top-bottom mirroring.
pub(crate) fn cannot_carry(m: &Manifest) -> Vec<Warning> {
    let p = plate(m);
    let given = p.layers(m.layers.len());
    let (mut exposure, mut thick, mut steps, mut worst) = (vec![], vec![], vec![], 0.0f64);
    for (l, (top, t, s, _)) in m.layers.iter().zip(&given) {
        let cure = p.group(l.index as usize).cure_s;
        if (cure - l.exposure_s).abs() > SAME {
            exposure.push(l.index);
            worst = worst.max((cure - l.exposure_s).abs());
        }
        if (t - l.thickness_mm).abs() > SAME || (top - l.z_mm).abs() > SAME {
            thick.push(l.index);
        }
        if !same_steps(s, &l.steps) {
            steps.push(l.index);
        }
    }
    let mut out: Vec<Warning> = [
        layers_warning("export.nanodlp-exposure", &exposure, "another exposure than the bottom and normal cure times")
            .map(|w| w.with("max_difference_s", crate::round::derived(worst))),
        layers_warning("export.nanodlp-layer-thickness", &thick, "another thickness than the plate's two"),
        layers_warning("export.nanodlp-steps", &steps, "steps the plate's lift, wait, return and cure waits cannot say (sweeps, several moves, other speeds or waits)"),
    ]
    .into_iter()
    .flatten()
    .collect();
    if m.machine.projector.iter().any(|p| p.mirror_y) {
        let msg = "the projector mirrors top-bottom: a NanoDLP plate mirrors left-right only (ImageMirror), so the plate does not say it";
        out.push(Warning::new("export.nanodlp-mirror", msg));
    }
    out
}

/// The areas (px) of the 8-connected regions of pixels lit at least half in the gray
/// image `px` of width `w`, by runs joined with union-find.
fn regions(px: &[u8], w: usize) -> Vec<u64> {
    let mut parent: Vec<usize> = Vec::new();
    let mut size: Vec<u64> = Vec::new();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    let mut prev: Vec<(usize, usize, usize)> = Vec::new();
    for row in px.chunks_exact(w.max(1)) {
        let mut cur = Vec::new();
        let mut x = 0;
        while x < row.len() {
            if row[x] < 128 {
                x += 1;
                continue;
            }
            let start = x;
            while x < row.len() && row[x] >= 128 {
                x += 1;
            }
            let id = parent.len();
            parent.push(id);
            size.push((x - start) as u64);
            // Runs of the row above touching [start − 1, x] (diagonals count).
            for &(_, _, j) in prev.iter().filter(|r| r.0 <= x && start <= r.1) {
                let (ra, rb) = (root(&mut parent, id), root(&mut parent, j));
                if ra != rb {
                    parent[rb] = ra;
                    size[ra] += size[rb];
                }
            }
            cur.push((start, x, id));
        }
        prev = cur;
    }
    (0..parent.len())
        .filter(|&i| root(&mut parent, i) == i)
        .map(|i| size[i])
        .collect()
}

/// `info.json`'s record of a mask (`bytes`), pixels `pixel_mm2` in area: its solid area,
/// largest and smallest region (mm²), their count, and its lit box in pixels.
fn info(bytes: &[u8], pixel_mm2: f64, buf: &mut Vec<u8>) -> Value {
    let area = |px: u64| crate::round::derived(px as f64 * pixel_mm2);
    let Some((w, _, fig)) = crate::formats::imported::mask_figures(bytes, buf) else {
        return json!({"TotalSolidArea": 0, "LargestArea": 0, "SmallestArea": 0,
            "MinX": 0, "MinY": 0, "MaxX": 0, "MaxY": 0, "AreaCount": 0});
    };
    let r = regions(buf, w as usize);
    let b = fig.lit_box.unwrap_or_default();
    json!({
        "TotalSolidArea": area(r.iter().sum()),
        "LargestArea": area(r.iter().copied().max().unwrap_or(0)),
        "SmallestArea": area(r.iter().copied().min().unwrap_or(0)),
        "MinX": b[0], "MinY": b[1], "MaxX": b[2], "MaxY": b[3],
        "AreaCount": r.len(),
    })
}

/// The plate's bounds (mm, centred on the display, as UVtools writes them) and its
/// other `plate.json` keys.
fn plate_json(m: &Manifest, name: &str, time_s: f64, now: i64) -> Value {
    let f = m.machine.field();
    let (w, h) = (f.width_mm() / 2.0, f.height_mm() / 2.0);
    let [lo, hi] = m.source.bbox_mm;
    let r = |v: f64| crate::round::derived(v);
    let um = r(f.pixel_mm * 1000.0);
    json!({
        "PlateID": 0, "ProfileID": 0, "CreatedDate": now, "Updated": now, "Path": name,
        "StopLayers": "", "LowQualityLayerNumber": 0, "AutoCenter": 0, "LastPrint": 0,
        "PrintTime": time_s.round(), "PrintEst": time_s.round(), "ImageRotate": 0,
        "MaskEffect": 0, "XRes": um, "YRes": um,
        "ZRes": r(m.settings.layer_height_mm * 1000.0), "MultiCure": "",
        "MultiThickness": "", "CureTimes": [], "DynamicThickness": [], "Offset": 0,
        "OverHangs": [], "Risky": false, "IsFaulty": false, "Repaired": false,
        "FaultyLayers": [], "Corrupted": false,
        "TotalSolidArea": r(m.totals.resin_volume_ml), "BlackoutData": "",
        "LayersCount": m.layers.len(), "Processed": true, "Feedback": false,
        "ReSliceNeeded": false, "MultiMaterial": false, "PrintID": 0,
        "XMin": r(lo[0] - w), "XMax": r(hi[0] - w), "YMin": r(lo[1] - h), "YMax": r(hi[1] - h),
        "ZMin": 0, "ZMax": r(m.totals.height_mm),
    })
}

/// `options.json`: the display's pixels and pixel size, mirroring, the layers.
fn options(m: &Manifest, p: &Plate) -> Value {
    let d = &m.machine.projector[0];
    let mm = d.pixel_mm.get();
    let r = |v: f64| crate::round::derived(v);
    let um = r(mm * 1000.0);
    json!({
        "Type": "dmdsl", "PWidth": d.width_px, "PHeight": d.height_px,
        "XPixelSize": mm, "YPixelSize": mm, "XRes": um, "YRes": um, "XYRes": um,
        "Thickness": r(p.groups[1].thickness_mm * 1000.0),
        "SupportDepth": r(p.groups[0].thickness_mm * 1000.0),
        "SupportLayerNumber": p.bottom, "XOffset": 0, "YOffset": 0, "ZOffset": 0,
        "ImageMirror": u8::from(d.mirror_x), "ImageRotate": 0, "DisplayController": 1,
        "LayerCount": m.layers.len(), "PreviewWidth": 200, "PreviewHeight": 100,
        "AntiAlias": 0, "IgnoreMask": 1, "FillColor": "#ffffff", "BlankColor": "#000000",
        "FillColorRGB": {"R": 255, "G": 255, "B": 255, "A": 255},
        "BlankColorRGB": {"R": 0, "G": 0, "B": 0, "A": 255}, "ExportType": 1,
    })
}

/// Writes the job `m` (one projector, at least one layer) as a NanoDLP plate at `out`.
pub(crate) fn write(
    m: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<()> {
    let name = out
        .file_stem()
        .map_or_else(|| "part".into(), |s| s.to_string_lossy().into_owned());
    let p = plate(m);
    let time_s: f64 = p.layers(m.layers.len()).iter().map(|l| l.3).sum();
    let now = crate::formats::now_secs();
    let mut profile: Map<String, Value> = p.to_profile();
    for (k, v) in [
        ("Title", json!(m.machine.resin.name)),
        (
            "Desc",
            json!(format!(
                "{} (dmdsl {})",
                m.machine.name,
                env!("CARGO_PKG_VERSION")
            )),
        ),
        ("Updated", json!(now)),
        ("ProfileID", json!(0)),
        ("ResinID", json!(0)),
        ("Type", json!(0)),
        ("DynamicCureTime", json!("")),
        ("DynamicSpeed", json!("")),
        ("DynamicLift", json!("")),
        ("DynamicWait", json!("")),
        ("FillColor", json!("#ffffff")),
        ("BlankColor", json!("#000000")),
        ("IgnoreMask", json!(1)),
        ("AntiAlias", json!(0)),
    ] {
        profile.insert(k.into(), v);
    }
    let meta = json!({
        "FormatVersion": 1, "Distro": "generic", "Program": "dmdsl",
        "Version": env!("CARGO_PKG_VERSION"), "OS": std::env::consts::OS,
        "Arch": std::env::consts::ARCH, "Profile": true,
    });
    let pixel = m.machine.projector[0].pixel_mm.get();
    let mut buf = Vec::new();
    let mut infos = Vec::with_capacity(m.layers.len());
    let mut masks = Vec::with_capacity(m.layers.len());
    for l in &m.layers {
        let bytes = files.file(&l.masks[0].file)?;
        infos.push(info(&bytes, pixel * pixel, &mut buf));
        masks.push(bytes);
    }
    let text = |v: &Value| serde_json::to_vec_pretty(v).expect("JSON serializes");
    let options = text(&options(m, &p));
    let mut zip = ZipOut::create(out, cancel)?;
    for (entry, bytes) in [
        (META, text(&meta)),
        (PLATE, text(&plate_json(m, &name, time_s, now))),
        (PROFILE, text(&Value::Object(profile))),
        (OPTIONS, options.clone()),
        (SLICER, options),
        (INFO, text(&Value::Array(infos))),
    ] {
        zip.add(entry, &bytes, Method::Deflated)?;
    }
    let preview = crate::formats::sl1::preview_png(m, files, (200, 100))?;
    zip.add(PREVIEW, &preview, Method::Stored)?;
    for (i, bytes) in masks.iter().enumerate() {
        zip.add(&format!("{}.png", i + 1), bytes, Method::Stored)?;
    }
    zip.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_join_diagonal_neighbours_and_count_half_lit_pixels() {
        // Two blocks touching at a corner, one apart, a dim pixel that is not lit.
        let w = 6;
        let mut px = vec![0u8; w * 4];
        for (x, y) in [(0, 0), (1, 0), (0, 1), (1, 1), (2, 2), (5, 0), (5, 1)] {
            px[y * w + x] = 255;
        }
        px[3 * w + 4] = 100;
        let mut r = regions(&px, w);
        r.sort_unstable();
        assert_eq!(r, [2, 5]);
        assert!(regions(&[0; 12], 4).is_empty());
    }

    #[test]
    fn the_normal_set_takes_the_exposure_most_layers_have() {
        use crate::bundle::Mode;
        use crate::exec::testutil::layer;
        // A ramp 20.5 … 7 s down to 2.5 s: the normal layers' first at 2.5 s.
        let layers: Vec<Layer> = [20.5, 16.0, 11.5, 7.0, 2.5, 2.5, 2.5, 3.0, 2.5]
            .iter()
            .enumerate()
            .map(|(i, &e)| layer(i, 0.05 * (i + 1) as f64, 0.05, Mode::Layered, e, vec![], e))
            .collect();
        assert_eq!(normal_layer(&layers), Some(4));
        assert_eq!(normal_layer(&layers[..1]), Some(0));
        assert_eq!(normal_layer(&[]), None);
    }
}
