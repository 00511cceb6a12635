//! Prusa SL1 / SL1S: the zip PrusaSlicer 2.5 writes (`SL1Archive::export_print` in
//! PrusaSlicer's `src/libslic3r/Format/SL1.cpp`): `config.ini` (the printer's keys),
//! `prusaslicer.ini` (the slicer's configuration), the masks `<jobDir>NNNNN.png` and the
//! thumbnails `thumbnail/thumbnail400x400.png` and `thumbnail800x480.png`.
//!
//! The masks are the bundle's PNGs, byte for byte: dmdsl draws them in PrusaSlicer's
//! landscape orientation (column x/p, row H − 1 − y/p), so `display_orientation =
//! landscape`, the projector's size and mirror flags say exactly how to read them.
//!
//! SL1 exposes every layer alike but for the first ones: PrusaSlicer's model (its print
//! time estimate, `SLAPrint::Steps::merge_slices_and_eval_stats`) gives layers 0–2
//! `expTimeFirst`, then `numFade` layers stepping down by (`expTimeFirst` − `expTime`) /
//! (`numFade` + 1), then `expTime`; between layers the printer tilts its vat, a fast tilt
//! (`fast_tilt_time`) when the layer's area is at most `area_fill` % of the display, else
//! a slow one. The exporter fits `expTimeFirst`, `expTime` and `numFade` to the job's
//! exposures and warns about every layer the scheme cannot give its exposure; the job's
//! own stage steps, several projectors, the light-compensation records cannot be said at
//! all (warnings, or a refusal for several projectors).

use crate::bundle::BundleSource;
use crate::bundle::{Manifest, Mode};
use crate::error::{Error, Result};
use crate::formats::archive::write::{Method, ZipOut};
use crate::formats::Format;
use crate::warning::{plural, Warning};
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// Layers PrusaSlicer's model exposes for `expTimeFirst`.
const FIRST_LAYERS: usize = 3;
/// The `faded_layers` range PrusaSlicer accepts.
const FADE_RANGE: std::ops::RangeInclusive<usize> = 3..=20;
/// PrusaSlicer's default `faded_layers`.
const FADE_DEFAULT: usize = 10;
/// Two exposures closer than this are equal (manifest times are rounded to 1 ms), s.
const SAME_S: f64 = 0.0005;
/// PrusaSlicer's defaults for the tilt, written to `prusaslicer.ini` and used for the
/// `printTime` estimate: `area_fill` (%), `fast_tilt_time`, `slow_tilt_time` and
/// `high_viscosity_tilt_time` (s).
const AREA_FILL_PCT: f64 = 50.0;
const FAST_TILT_S: f64 = 5.0;
const SLOW_TILT_S: f64 = 8.0;
const HV_TILT_S: f64 = 10.0;

/// `printTime` of the job's layers with the scheme's exposures, as PrusaSlicer 2.5
/// estimates it (`sl1::read`'s model, the one `dmdsl run` replays an SL1 with).
fn print_time(scheme: &Scheme, layer_mm: f64, display_area_mm2: f64, areas_mm2: &[f64]) -> f64 {
    let model = super::read::Model {
        exp_s: scheme.exp_s,
        first_s: scheme.first_s,
        fade: scheme.fade,
        layer_mm,
        fast_tilt_s: FAST_TILT_S,
        slow_tilt_s: SLOW_TILT_S,
        hv_tilt_s: HV_TILT_S,
        fast_max_mm2: display_area_mm2 * AREA_FILL_PCT / 100.0,
        speed: super::read::PrintSpeed::Fast,
    };
    model.print_time_s(areas_mm2)
}
/// The display of the printers the formats are named after: (pixels x, pixels y, width
/// mm, height mm), portrait.
const SL1_DISPLAY: (u32, u32, f64, f64) = (1440, 2560, 68.04, 120.96);
const SL1S_DISPLAY: (u32, u32, f64, f64) = (1620, 2560, 81.0, 128.0);

/// Refuses a job of several projectors: an SL1 shows one image per layer.
pub(crate) fn check_projectors(projectors: usize, out: &Path) -> Result<()> {
    if projectors > 1 {
        return Err(Error::Usage(format!(
            "{}: SL1/SL1S carry one image per layer, but this job's machine has {projectors} projectors; export it as dmdjob-zip or sla-control instead",
            out.display()
        )));
    }
    Ok(())
}

/// The SL1 exposure scheme: first exposure, normal exposure, faded layers.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Scheme {
    first_s: f64,
    exp_s: f64,
    fade: usize,
}

impl Scheme {
    /// The exposure PrusaSlicer's model gives layer `i`.
    fn exposure(&self, i: usize) -> f64 {
        if i < FIRST_LAYERS {
            return self.first_s;
        }
        let k = i - FIRST_LAYERS + 1;
        if self.first_s > self.exp_s && k <= self.fade {
            let delta = (self.first_s - self.exp_s) / (self.fade + 1) as f64;
            self.first_s - k as f64 * delta
        } else {
            self.exp_s
        }
    }

    /// The layers whose exposure in `exps` the scheme does not give: (layer, job's, SL1's).
    fn misses(&self, exps: &[f64]) -> Vec<(usize, f64, f64)> {
        exps.iter()
            .enumerate()
            .filter_map(|(i, &e)| {
                let s = self.exposure(i);
                ((e - s).abs() > SAME_S).then_some((i, e, s))
            })
            .collect()
    }

    /// The scheme closest to the exposures `exps` (at least one): `expTimeFirst` is layer
    /// 0's, `expTime` the exposure most layers from layer 3 on have (the last layer's when
    /// there are none), `numFade` the one of PrusaSlicer's range that misses fewest layers
    /// (then the smallest total difference; PrusaSlicer's default when the fade does not
    /// matter).
    fn fit(exps: &[f64]) -> Scheme {
        let first_s = exps[0];
        let mut counts: Vec<(i64, usize)> = Vec::new();
        for &e in exps.iter().skip(FIRST_LAYERS) {
            let key = (e * 1000.0).round() as i64;
            match counts.iter_mut().find(|c| c.0 == key) {
                Some(c) => c.1 += 1,
                None => counts.push((key, 1)),
            }
        }
        let exp_s = match counts.iter().max_by_key(|c| c.1) {
            Some(&(key, _)) => exps
                .iter()
                .skip(FIRST_LAYERS)
                .copied()
                .find(|e| (e * 1000.0).round() as i64 == key)
                .unwrap_or(first_s),
            None => *exps.last().expect("one layer or more"),
        };
        let cost = |fade: usize| {
            let s = Scheme {
                first_s,
                exp_s,
                fade,
            };
            let m = s.misses(exps);
            (m.len(), m.iter().map(|x| (x.1 - x.2).abs()).sum::<f64>())
        };
        let mut best = (FADE_DEFAULT, cost(FADE_DEFAULT));
        for fade in FADE_RANGE {
            let c = cost(fade);
            if c.0 < best.1 .0 || (c.0 == best.1 .0 && c.1 < best.1 .1 - 1e-9) {
                best = (fade, c);
            }
        }
        Scheme {
            first_s,
            exp_s,
            fade: best.0,
        }
    }
}

/// A number as PrusaSlicer writes a setting: the shortest decimal that reads back.
fn num(v: f64) -> String {
    format!("{}", crate::round::derived(v))
}

/// `fileCreationTimestamp`: now (or `SOURCE_DATE_EPOCH`, for reproducible files) as
/// PrusaSlicer writes it, `2026-11-27 at 21:02:20 UTC`.
fn timestamp() -> String {
    let secs = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|s| s.trim().parse::<i64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs() as i64)
        });
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
fn ini(pairs: &[(&str, String)]) -> String {
    pairs.iter().map(|(k, v)| format!("{k} = {v}\n")).collect()
}

/// Writes the job as an SL1 (`format` Sl1) or SL1S at `out`; returns what it lost.
pub(crate) fn write(
    format: Format,
    m: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<Vec<Warning>> {
    let machine = &m.machine;
    check_projectors(machine.projector.len(), out)?;
    let p = &machine.projector[0];
    if m.layers.is_empty() {
        return Err(Error::Bundle {
            path: out.into(),
            msg: "the job has no layers".into(),
        });
    }
    let mut warnings = Vec::new();
    let exps: Vec<f64> = m.layers.iter().map(|l| l.exposure_s).collect();
    let scheme = Scheme::fit(&exps);
    let misses = scheme.misses(&exps);
    if let Some(&(first, job_s, sl1_s)) = misses.first() {
        let n = misses.len() as u64;
        let worst = misses.iter().map(|x| (x.1 - x.2).abs()).fold(0.0, f64::max);
        warnings.push(
            Warning::new(
                "export.sl1-exposure",
                format!(
                    "SL1 exposes layers 0-2 for expTimeFirst ({} s), fades over numFade ({}) layers to expTime ({} s); {n} {} a different exposure in the job (first layer {first}: {} s in the job, {} s in the SL1; largest difference {} s)",
                    num(scheme.first_s),
                    scheme.fade,
                    num(scheme.exp_s),
                    plural(n, "layer has", "layers have"),
                    num(job_s),
                    num(sl1_s),
                    num(worst)
                ),
            )
            .with("layers", n)
            .with("first_layer", first as u64)
            .with("job_s", crate::round::derived(job_s))
            .with("sl1_s", crate::round::derived(sl1_s))
            .with("max_difference_s", crate::round::derived(worst)),
        );
    }
    let h = m.settings.layer_height_mm;
    let uneven = m
        .layers
        .iter()
        .filter(|l| (l.thickness_mm - h).abs() > 1e-9)
        .count() as u64;
    if uneven > 0 {
        warnings.push(
            Warning::new(
                "export.sl1-layer-thickness",
                format!(
                    "SL1 has one layer height ({} mm); {uneven} {} another thickness in the job",
                    num(h),
                    plural(uneven, "layer has", "layers have")
                ),
            )
            .with("layers", uneven)
            .with("layer_height_mm", h),
        );
    }
    let continuous = m
        .layers
        .iter()
        .filter(|l| l.mode == Mode::Continuous)
        .count() as u64;
    if continuous > 0 {
        warnings.push(
            Warning::new(
                "export.sl1-continuous",
                format!(
                    "SL1 prints every layer stopped and tilted; {continuous} continuous (swept) {} of the job become layered exposures of the same length",
                    plural(continuous, "layer", "layers")
                ),
            )
            .with("layers", continuous),
        );
    }
    warnings.push(
        Warning::new(
            "export.sl1-steps",
            format!(
                "SL1 carries no stage steps: the printer tilts its vat between layers instead of the job's {} process ({} planned steps, est. print time {} s in the job; the SL1's estimate with PrusaSlicer's tilt times)",
                serde_json::to_value(machine.process)
                    .ok()
                    .and_then(|v| v.as_str().map(String::from))
                    .unwrap_or_default(),
                m.layers.iter().map(|l| l.steps.len()).sum::<usize>(),
                num(m.totals.print_time_s)
            ),
        )
        .with("steps", m.layers.iter().map(|l| l.steps.len() as u64).sum::<u64>())
        .with("print_time_s", m.totals.print_time_s),
    );
    let (dw, dh) = (
        p.width_px as f64 * p.pixel_mm.get(),
        p.height_px as f64 * p.pixel_mm.get(),
    );
    let (model, real) = match format {
        Format::Sl1s => ("SL1S", SL1S_DISPLAY),
        _ => ("SL1", SL1_DISPLAY),
    };
    let matches_printer = (p.width_px, p.height_px) == (real.0, real.1)
        || (p.width_px, p.height_px) == (real.1, real.0);
    if !matches_printer {
        warnings.push(
            Warning::new(
                "export.sl1-display",
                format!(
                    "the masks are {}x{} px ({} x {} mm), a Prusa {model} shows {}x{} px: PrusaSlicer and UVtools open the file, the printer itself refuses it",
                    p.width_px,
                    p.height_px,
                    num(dw),
                    num(dh),
                    real.1,
                    real.0
                ),
            )
            .with("width_px", p.width_px as u64)
            .with("height_px", p.height_px as u64)
            .with("printer", model),
        );
    }

    // PrusaSlicer's model of the print: exposure and tilt per layer.
    let display_area = dw * dh;
    let fast = |l: &crate::bundle::Layer| l.area_mm2 <= display_area * AREA_FILL_PCT / 100.0;
    let num_fast = m.layers.iter().filter(|l| fast(l)).count();
    let areas: Vec<f64> = m.layers.iter().map(|l| l.area_mm2).collect();
    let print_time = print_time(&scheme, h, display_area, &areas);
    let job_dir = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "part".into());
    let config = ini(&[
        ("action", "print".into()),
        ("expTime", num(scheme.exp_s)),
        ("expTimeFirst", num(scheme.first_s)),
        ("expUserProfile", "0".into()),
        ("fileCreationTimestamp", timestamp()),
        ("hollow", "0".into()),
        ("jobDir", job_dir.clone()),
        ("layerHeight", num(h)),
        ("materialName", machine.resin.name.clone()),
        ("numFade", scheme.fade.to_string()),
        ("numFast", num_fast.to_string()),
        ("numSlow", (m.layers.len() - num_fast).to_string()),
        ("printProfile", String::new()),
        ("printTime", format!("{print_time:.6}")),
        ("printerModel", model.into()),
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
        ("max_print_height", num(machine.stage.travel_max_mm)),
        (
            "output_filename_format",
            format!("[input_filename_base]{}", format.extension()),
        ),
        ("printer_settings_id", machine.name.clone()),
        ("sla_material_settings_id", machine.resin.name.clone()),
    ];
    let slicer: Vec<(&str, String)> = PRUSASLICER_KEYS
        .iter()
        .map(|&(k, v)| {
            let v = own
                .iter()
                .find(|o| o.0 == k)
                .map_or_else(|| v.to_string(), |o| o.1.clone());
            (k, v)
        })
        .collect();

    let mut zip = ZipOut::create(out, cancel)?;
    zip.add("config.ini", config.as_bytes(), Method::Deflated)?;
    zip.add("prusaslicer.ini", ini(&slicer).as_bytes(), Method::Deflated)?;
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
    Ok(warnings)
}

/// The keys of `prusaslicer.ini` PrusaSlicer 2.5 writes for an SLA printer, with the
/// values it writes by default; the exporter sets those the job decides (display,
/// exposure, layer height, names) and keeps PrusaSlicer's defaults for the rest (no
/// supports, pad or hollowing: dmdsl adds none).
const PRUSASLICER_KEYS: &[(&str, &str)] = &[
    ("absolute_correction", "0"),
    ("area_fill", "50"),
    ("bed_shape", "0x0,65x0,65x48.75,0x48.75"),
    ("bottle_cost", "0"),
    ("bottle_volume", "1000"),
    ("bottle_weight", "1"),
    ("display_height", "48.75"),
    ("display_mirror_x", "0"),
    ("display_mirror_y", "0"),
    ("display_orientation", "landscape"),
    ("display_pixels_x", "1024"),
    ("display_pixels_y", "768"),
    ("display_width", "65"),
    ("elefant_foot_compensation", "0"),
    ("elefant_foot_min_width", "0.2"),
    ("exposure_time", "8"),
    ("faded_layers", "10"),
    ("fast_tilt_time", "5"),
    ("gamma_correction", "0"),
    ("high_viscosity_tilt_time", "10"),
    ("hollowing_closing_distance", "2"),
    ("hollowing_enable", "0"),
    ("hollowing_min_thickness", "3"),
    ("hollowing_quality", "0.5"),
    ("initial_exposure_time", "8"),
    ("initial_layer_height", "0.05"),
    ("layer_height", "0.05"),
    ("material_correction", "1,1,1"),
    ("material_correction_x", "1"),
    ("material_correction_y", "1"),
    ("material_correction_z", "1"),
    ("material_density", "1"),
    ("material_print_speed", "fast"),
    ("max_exposure_time", "100"),
    ("max_initial_exposure_time", "150"),
    ("max_print_height", "200"),
    ("min_exposure_time", "0"),
    ("min_initial_exposure_time", "0"),
    ("output_filename_format", "[input_filename_base].sl1"),
    ("pad_around_object", "0"),
    ("pad_around_object_everywhere", "0"),
    ("pad_brim_size", "1.6"),
    ("pad_enable", "0"),
    ("pad_max_merge_distance", "50"),
    ("pad_object_connector_penetration", "0.3"),
    ("pad_object_connector_stride", "10"),
    ("pad_object_connector_width", "0.5"),
    ("pad_object_gap", "1"),
    ("pad_wall_height", "0"),
    ("pad_wall_slope", "90"),
    ("pad_wall_thickness", "2"),
    ("physical_printer_settings_id", ""),
    ("printer_settings_id", ""),
    ("printer_technology", "SLA"),
    ("relative_correction", "1,1"),
    ("relative_correction_x", "1"),
    ("relative_correction_y", "1"),
    ("relative_correction_z", "1"),
    ("sla_material_settings_id", ""),
    ("sla_print_settings_id", ""),
    ("slice_closing_radius", "0.049"),
    ("slicing_mode", "regular"),
    ("slow_tilt_time", "8"),
    ("support_base_diameter", "4"),
    ("support_base_height", "1"),
    ("support_base_safety_distance", "1"),
    ("support_buildplate_only", "0"),
    ("support_critical_angle", "45"),
    ("support_head_front_diameter", "0.4"),
    ("support_head_penetration", "0.2"),
    ("support_head_width", "1"),
    ("support_max_bridge_length", "15"),
    ("support_max_bridges_on_pillar", "3"),
    ("support_max_pillar_link_distance", "10"),
    ("support_object_elevation", "5"),
    ("support_pillar_connection_mode", "dynamic"),
    ("support_pillar_diameter", "1"),
    ("support_pillar_widening_factor", "0"),
    ("support_points_density_relative", "100"),
    ("support_points_minimal_distance", "1"),
    ("support_small_pillar_diameter_percent", "50%"),
    ("supports_enable", "0"),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scheme_is_prusaslicers_model() {
        // PrusaSlicer 2.5, --initial-exposure-time 20 --faded-layers 4 --exposure-time 8:
        // layers 0-2 at 20 s, then 17.6, 15.2, 12.8, 10.4, then 8 s.
        let s = Scheme {
            first_s: 20.0,
            exp_s: 8.0,
            fade: 4,
        };
        let e: Vec<f64> = (0..9).map(|i| s.exposure(i)).collect();
        let want = [20.0, 20.0, 20.0, 17.6, 15.2, 12.8, 10.4, 8.0, 8.0];
        for (a, b) in e.iter().zip(want) {
            assert!((a - b).abs() < 1e-9, "{e:?}");
        }
        assert_eq!(Scheme::fit(&e), s);
        assert!(s.misses(&e).is_empty());
    }

    #[test]
    fn a_job_the_scheme_cannot_say_is_fitted_as_closely_as_it_can() {
        // dmdsl's default: 2 bottom layers of 16 s, then 8 s.
        let mut e = vec![16.0, 16.0];
        e.extend([8.0; 20]);
        let s = Scheme::fit(&e);
        assert_eq!((s.first_s, s.exp_s), (16.0, 8.0));
        // Layer 2 gets 16 s in the SL1 and at least one fade layer differs.
        let m = s.misses(&e);
        assert_eq!(m[0], (2, 8.0, 16.0));
        assert_eq!(m.len(), 1 + s.fade);
        assert_eq!(s.fade, 3);
    }

    #[test]
    fn print_time_is_what_prusaslicer_writes() {
        // fixtures/sl1/cube1.sl1: 20 fast layers at 8 s, printTime 265.
        let s = Scheme {
            first_s: 8.0,
            exp_s: 8.0,
            fade: 10,
        };
        // Layers of 0.05 mm on the SL1's display (8230 mm²): 1 mm² is fast, 8000 mm² slow.
        let display = 68.04 * 120.96;
        let time = |s: &Scheme, area: f64, n: usize| print_time(s, 0.05, display, &vec![area; n]);
        assert!((time(&s, 1.0, 20) - 265.0).abs() < 1e-9);
        // A 45.7 mm cube, 900 slow layers: printTime 15525.000003.
        assert!((time(&s, 8000.0, 900) - 15525.0).abs() < 1e-6);
        // First 20 s, fade 4 (the scheme test above): 325.
        let f = Scheme {
            first_s: 20.0,
            exp_s: 8.0,
            fade: 4,
        };
        assert!((time(&f, 1.0, 20) - 325.0).abs() < 1e-9);
    }

    #[test]
    fn timestamps_are_utc_dates() {
        std::env::set_var("SOURCE_DATE_EPOCH", "1795813340");
        assert_eq!(timestamp(), "2026-11-27 at 21:02:20 UTC");
        std::env::remove_var("SOURCE_DATE_EPOCH");
    }
}
