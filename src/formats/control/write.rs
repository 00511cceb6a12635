//! Writing a job as a control-file zip (docs/FORMATS.md has the mapping in full): one
//! `Layers` entry per run of identical consecutive layers, holding only the images it
//! names; "Position settings" from the layer's planned steps ([`position`]); one image per
//! projector, an exposure over the schema's 10 000 ms split into equal exposures.

use super::WAVELENGTH_NM;
use super::{n, Position, EXPOSURE_MAX_MS, IMAGES, POWER_SETTING, SCHEMA_VERSION, SETTINGS};
use crate::bundle::{BundleSource, Layer, Manifest, Step};
use crate::error::Result;
use crate::formats::archive::write::{Method, ZipOut};
use serde_json::{json, Map, Value};
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// The "Position settings" of one layer whose steps start at `from_mm`, and whether its
/// steps fit the standard's sequence exactly (otherwise the nearest such sequence, moving
/// at most at the stage's `(speed, acceleration)` limits).
pub(crate) fn position(layer: &Layer, from_mm: f64, limits: (f64, f64)) -> (Position, bool) {
    let mut initial = 0.0;
    let mut up_wait = 0.0;
    let mut final_wait = 0.0;
    let mut up: Option<(f64, f64, f64)> = None;
    let mut down: Option<(f64, f64)> = None;
    let mut fits = true;
    let mut exposed = false;
    let mut at = from_mm;
    for s in &layer.steps {
        if exposed {
            fits = false;
        }
        match *s {
            Step::Wait { s } => match (up, down) {
                (None, _) => initial += s,
                (Some(_), None) => up_wait += s,
                (Some(_), Some(_)) => final_wait += s,
            },
            Step::Move {
                to_mm,
                speed_mm_s,
                accel_mm_s2,
            } => {
                match (up, down) {
                    (None, _) if to_mm > at => {
                        up = Some((to_mm - from_mm, speed_mm_s, accel_mm_s2))
                    }
                    (Some(_), None) if to_mm < at => down = Some((speed_mm_s, accel_mm_s2)),
                    _ => fits = false,
                }
                at = to_mm;
            }
            Step::Expose { .. } => exposed = true,
            Step::Sweep { to_mm, .. } => {
                fits = false;
                at = to_mm;
            }
        }
    }
    // The standard's printer comes back to the previous position plus the thickness.
    let thickness = layer.thickness_mm;
    if (at - (from_mm + thickness)).abs() > 1e-6 || up.is_none() || down.is_none() || !exposed {
        fits = false;
    }
    let (up_mm, up_speed, up_accel) = up.unwrap_or((thickness, limits.0, limits.1));
    let (down_speed, down_accel) = down.unwrap_or((up_speed, up_accel));
    let p = Position {
        thickness_mm: thickness,
        up_mm: up_mm.max(thickness),
        initial_s: initial,
        up_speed,
        up_accel,
        up_wait_s: up_wait,
        down_speed,
        down_accel,
        final_s: final_wait,
    };
    (p, fits)
}

/// The light time of a layer, ms: its exposure, or the time its sweeps show the mask.
pub(super) fn light_ms(layer: &Layer, from_mm: f64) -> i64 {
    let mut at = from_mm;
    let mut swept = 0.0;
    for s in &layer.steps {
        match *s {
            Step::Move { to_mm, .. } => at = to_mm,
            Step::Sweep { to_mm, speed_mm_s } => {
                swept += (to_mm - at).abs() / speed_mm_s;
                at = to_mm;
            }
            _ => {}
        }
    }
    let s = if swept > 0.0 { swept } else { layer.exposure_s };
    (s * 1000.0).round() as i64
}

/// `total` ms as the fewest equal exposures of at most [`EXPOSURE_MAX_MS`] (whole ms, the
/// remainder on the first ones).
pub(super) fn split(total: i64) -> Vec<i64> {
    let k = ((total + EXPOSURE_MAX_MS - 1) / EXPOSURE_MAX_MS).max(1);
    (0..k)
        .map(|i| total / k + i64::from(i < total % k))
        .collect()
}

/// The image name of a mask in `slices/` (its path under `masks/`).
fn image_name(mask: &str) -> &str {
    mask.strip_prefix("masks/").unwrap_or(mask)
}

/// A layer's entry before runs of equal layers are merged: the key they are compared by,
/// the entry and the images it needs.
type Entry<'a> = (String, Map<String, Value>, Vec<&'a str>);

/// One entry per layer of `m`.
fn entries(m: &Manifest) -> Vec<Entry<'_>> {
    let machine = &m.machine;
    let several = machine.projector.len() > 1;
    let stage = &machine.stage;
    let limits = (stage.max_speed_mm_s.get(), stage.max_accel_mm_s2.get());
    let mut at = stage.home_mm;
    let mut entries = Vec::with_capacity(m.layers.len());
    for l in &m.layers {
        let pos = position(l, at, limits).0.to_json();
        at = l.z_mm;
        let parts = split(light_ms(l, at));
        let mut images = Vec::new();
        let mut list = Vec::new();
        let mut key = format!("{pos}");
        for mask in &l.masks {
            let p = &machine.projector[mask.projector as usize];
            for &t in &parts {
                let mut img = json!({
                    "Image file": image_name(&mask.file),
                    "Layer exposure time (ms)": t,
                });
                let o = img.as_object_mut().expect("object");
                if several {
                    o.insert("Light engine".into(), json!(p.name));
                    o.insert(
                        "Light engine wavelength (nm)".into(),
                        json!(p.wavelength_nm.unwrap_or(WAVELENGTH_NM as u32)),
                    );
                    o.insert(
                        "Light engine power setting".into(),
                        json!(p.power_setting.unwrap_or(POWER_SETTING as u32)),
                    );
                    let px = p.pixel_mm.get() * 1000.0;
                    o.insert("Image x offset (um)".into(), n(p.offset_px[0] as f64 * px));
                    o.insert("Image y offset (um)".into(), n(p.offset_px[1] as f64 * px));
                }
                // The long axis is the image's longer side (the reader's rule).
                let (long, short) = match p.width_px >= p.height_px {
                    true => (p.mirror_x, p.mirror_y),
                    false => (p.mirror_y, p.mirror_x),
                };
                for (key, on) in [
                    ("Mirror image long axis", long),
                    ("Mirror image short axis", short),
                ] {
                    if on {
                        o.insert(key.into(), json!(true));
                    }
                }
                list.push(img);
            }
            key.push_str(&format!("|{}:{}:{parts:?}", mask.sha256, mask.projector));
            images.push(mask.file.as_str());
        }
        let mut e = Map::new();
        e.insert("Position settings".into(), pos);
        e.insert("Image settings list".into(), Value::Array(list));
        entries.push((key, e, images));
    }
    entries
}

/// Writes the job `m` (at least one layer) as a control-file zip at `out`.
pub(crate) fn write(
    m: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<()> {
    let entries = entries(m);
    // The defaults: the last run of layers' settings (its image is one the zip holds).
    let last_run = entries
        .iter()
        .rposition(|e| e.0 != entries.last().expect("a job has layers").0)
        .map_or(0, |i| i + 1);
    let last = &entries[last_run].1;
    let default_pos = last["Position settings"].clone();
    let first_image = &last["Image settings list"][0];
    let p0 = &m.machine.projector[0];
    let default_image = json!({
        "Image file": first_image["Image file"],
        "Layer exposure time (ms)": first_image["Layer exposure time (ms)"],
        "Light engine": p0.name,
        "Light engine power setting": p0.power_setting.unwrap_or(POWER_SETTING as u32),
        "Light engine wavelength (nm)": p0.wavelength_nm.unwrap_or(WAVELENGTH_NM as u32),
        "Relative focus position (um)": 0,
        "Wait before exposure (ms)": 0,
        "Wait after exposure (ms)": 0,
    });
    // Runs of identical layers become one entry.
    let mut layers: Vec<Value> = Vec::new();
    let mut needed: Vec<&str> = Vec::new();
    for run in entries.chunk_by(|a, b| a.0 == b.0) {
        let (_, e, images) = &run[0];
        let mut e = e.clone();
        if e["Position settings"] == default_pos {
            e.remove("Position settings");
        }
        if run.len() > 1 {
            e.insert("Number of duplications".into(), json!(run.len()));
        }
        layers.push(Value::Object(e));
        needed.extend(images.iter().copied());
    }
    let settings = json!({
        "Header": {
            "Schema version": SCHEMA_VERSION,
            "Image directory": IMAGES,
            "Comment": format!(
                "Written by dmdsl {} from the job's manifest (job.json); pixel_mm {}",
                env!("CARGO_PKG_VERSION"),
                p0.pixel_mm.get()
            ),
        },
        "Design": {
            "STL file": m.source.file,
            "Resin": m.machine.resin.name,
            "3D printer": m.machine.name,
            "Slicer": format!("dmdsl {}", env!("CARGO_PKG_VERSION")),
        },
        "Default layer settings": {
            "Number of duplications": 1,
            "Position settings": default_pos,
            "Image settings": default_image,
        },
        "Layers": layers,
    });
    let mut text = serde_json::to_vec_pretty(&settings).expect("settings serialize");
    text.push(b'\n');
    let mut zip = ZipOut::create(out, cancel)?;
    zip.add(SETTINGS, &text, Method::Deflated)?;
    let mut seen = std::collections::HashSet::new();
    for rel in needed {
        if seen.insert(rel) {
            let name = format!("{IMAGES}/{}", image_name(rel));
            zip.add(&name, &files.file(rel)?, Method::Stored)?;
        }
    }
    zip.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_exposures_split_into_equal_whole_ms() {
        assert_eq!(split(8000), [8000]);
        assert_eq!(split(10000), [10000]);
        assert_eq!(split(16000), [8000, 8000]);
        assert_eq!(split(20001), [6667, 6667, 6667]);
        assert_eq!(split(0), [0]);
        for t in [1, 9999, 10001, 123_457] {
            let s = split(t);
            assert_eq!(s.iter().sum::<i64>(), t);
            assert!(s.iter().all(|&x| x <= EXPOSURE_MAX_MS));
        }
    }

    #[test]
    fn a_dip_and_return_is_a_move_away_and_back() {
        // From 0.5 mm: dip to 6 mm at 2 mm/s, back to 1 mm at 1 mm/s, wait 10 s, expose.
        let mut l = crate::exec::testutil::two_layer_topdown().layers[1].clone();
        let (pos, fits) = position(&l, 0.5, (10.0, 50.0));
        assert!(fits, "{l:?}");
        let want = json!({
            "Layer thickness (um)": 500, "Distance up (mm)": 5.5, "Initial wait (ms)": 0,
            "BP up speed (mm/sec)": 2, "BP up acceleration (mm/sec^2)": 50, "Up wait (ms)": 0,
            "BP down speed (mm/sec)": 1, "BP down acceleration (mm/sec^2)": 50,
            "Final wait (ms)": 10000
        });
        assert_eq!(pos.to_json(), want);
        // A layer that does not come back onto its thickness, or sweeps, does not fit.
        assert!(!position(&l, 0.4, (10.0, 50.0)).1);
        l.steps = vec![Step::Sweep {
            to_mm: 1.0,
            speed_mm_s: 0.1,
        }];
        let (pos, fits) = position(&l, 0.5, (10.0, 50.0));
        assert!(!fits);
        assert!(pos.up_mm > 0.0);
        assert_eq!(light_ms(&l, 0.5), 5000);
    }
}
