//! Writing a job as an SL1 or SL1S: the masks are the bundle's PNGs, byte for byte.
//! dmdsl draws them in PrusaSlicer's landscape orientation (column x/p, row H − 1 − y/p),
//! so `display_orientation = landscape`, the projector's size and mirror flags say exactly
//! how to read them. `expTimeFirst`, `expTime` and `numFade` are fitted to the job's
//! exposures ([`Scheme::fit`]); `printTime` is PrusaSlicer's estimate with its default tilt
//! ([`Model`]).

use super::{num, printer, Model, Scheme, CONFIG, PRUSASLICER};
use crate::bundle::{BundleSource, Manifest};
use crate::error::Result;
use crate::formats::archive::write::{Method, ZipOut};
use crate::formats::Format;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// The keys of `prusaslicer.ini` PrusaSlicer 2.5 writes for an SLA printer, with the
/// values it writes by default; the writer sets those the job decides (display, exposure,
/// layer height, names) and keeps PrusaSlicer's defaults for the rest (no supports, pad or
/// hollowing: dmdsl adds none).
const PRUSASLICER_DEFAULTS: &str = include_str!("prusaslicer.ini");

/// Writes the job `m` (one projector, at least one layer) as an SL1 (`format` Sl1) or SL1S
/// at `out`.
pub(crate) fn write(
    format: Format,
    m: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<()> {
    let job_dir = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "part".into());
    let scheme = Scheme::fit(&m.layers.iter().map(|l| l.exposure_s).collect::<Vec<_>>());
    let (config, slicer) = settings(format, m, scheme, &job_dir);
    let mut zip = ZipOut::create(out, cancel)?;
    zip.add(CONFIG, config.as_bytes(), Method::Deflated)?;
    zip.add(PRUSASLICER, slicer.as_bytes(), Method::Deflated)?;
    for (i, l) in m.layers.iter().enumerate() {
        let mask = &l.masks[0].file;
        zip.add(
            &format!("{job_dir}{i:05}.png"),
            &files.file(mask)?,
            Method::Stored,
        )?;
    }
    for (name, png) in super::thumbnail::thumbnails(m, files)? {
        zip.add(&name, &png, Method::Stored)?;
    }
    zip.finish()?;
    Ok(())
}

/// `config.ini` and `prusaslicer.ini` of the job `m` with exposures `scheme`, its images
/// named `<job_dir>NNNNN.png`.
fn settings(format: Format, m: &Manifest, scheme: Scheme, job_dir: &str) -> (String, String) {
    let machine = &m.machine;
    let p = &machine.projector[0];
    let h = m.settings.layer_height_mm;
    let (dw, dh) = (
        p.width_px as f64 * p.pixel_mm.get(),
        p.height_px as f64 * p.pixel_mm.get(),
    );
    // PrusaSlicer's model of the print: exposure and tilt per layer.
    let model = Model::written(scheme, h, dw * dh);
    let areas: Vec<f64> = m.layers.iter().map(|l| l.area_mm2).collect();
    let num_fast = areas.iter().filter(|&&a| model.overhead_s(a).1).count();
    let print_time = model.print_time_s(&areas);
    let (printer_model, _) = printer(format);
    let config = ini([
        ("action", "print".into()),
        ("expTime", num(scheme.exp_s)),
        ("expTimeFirst", num(scheme.first_s)),
        ("expUserProfile", "0".into()),
        ("fileCreationTimestamp", timestamp()),
        ("hollow", "0".into()),
        ("jobDir", job_dir.into()),
        ("layerHeight", num(h)),
        ("materialName", machine.resin.name.clone()),
        ("numFade", scheme.fade.to_string()),
        ("numFast", num_fast.to_string()),
        ("numSlow", (m.layers.len() - num_fast).to_string()),
        ("printProfile", String::new()),
        ("printTime", format!("{print_time:.6}")),
        ("printerModel", printer_model.into()),
        ("printerProfile", machine.name.clone()),
        ("printerVariant", String::new()),
        (
            "prusaSlicerVersion",
            format!("dmdsl-{}", env!("CARGO_PKG_VERSION")),
        ),
        ("usedMaterial", format!("{:.6}", m.totals.resin_volume_ml)),
    ]);
    let own: Vec<(&str, String)> = vec![
        (
            "bed_shape",
            format!("0x0,{w}x0,{w}x{d},0x{d}", w = num(dw), d = num(dh)),
        ),
        ("display_height", num(dh)),
        ("display_mirror_x", u8::from(p.mirror_x).to_string()),
        ("display_mirror_y", u8::from(p.mirror_y).to_string()),
        ("display_orientation", "landscape".into()),
        ("display_pixels_x", p.width_px.to_string()),
        ("display_pixels_y", p.height_px.to_string()),
        ("display_width", num(dw)),
        ("exposure_time", num(scheme.exp_s)),
        ("faded_layers", scheme.fade.to_string()),
        (
            "gamma_correction",
            if m.settings.binary { "0" } else { "1" }.into(),
        ),
        ("initial_exposure_time", num(scheme.first_s)),
        ("initial_layer_height", num(h)),
        ("layer_height", num(h)),
        ("max_print_height", num(max_print_height(machine))),
        (
            "output_filename_format",
            format!("[input_filename_base]{}", format.extension()),
        ),
        ("printer_settings_id", machine.name.clone()),
        ("sla_material_settings_id", machine.resin.name.clone()),
    ];
    let slicer = ini(PRUSASLICER_DEFAULTS
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split_once('='))
        .map(|(k, v)| {
            let (k, v) = (k.trim(), v.trim());
            let own = own.iter().find(|o| o.0 == k);
            (k, own.map_or_else(|| v.to_string(), |o| o.1.clone()))
        }));
    (config, slicer)
}

/// `fileCreationTimestamp`: now (or `SOURCE_DATE_EPOCH`, for reproducible files) as
/// PrusaSlicer writes it, `2026-11-27 at 21:02:20 UTC`.
fn timestamp() -> String {
    let secs = crate::formats::now_secs();
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} at {:02}:{:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// `key = value` lines, in the order given.
fn ini<'a>(pairs: impl IntoIterator<Item = (&'a str, String)>) -> String {
    pairs
        .into_iter()
        .map(|(k, v)| format!("{k} = {v}\n"))
        .collect()
}

/// The stage travel the file states: the machine's, or, when its record does not state one
/// (a job imported from a file without it), PrusaSlicer's default of 150 mm where that is
/// more than the stand-in.
fn max_print_height(machine: &crate::bundle::Machine) -> f64 {
    let travel = machine.stage.travel_max_mm;
    match machine.states("stage.travel_max_mm") {
        true => travel,
        false => travel.max(super::read::DEFAULT_MAX_PRINT_HEIGHT_MM),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_are_utc_dates() {
        std::env::set_var("SOURCE_DATE_EPOCH", "1795813340");
        assert_eq!(timestamp(), "2026-11-27 at 21:02:20 UTC");
        std::env::remove_var("SOURCE_DATE_EPOCH");
    }
}
