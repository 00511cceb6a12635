//! Prusa SL1 / SL1S, the zip PrusaSlicer 2.5 writes (docs/FORMATS.md, "sl1, sl1s"):
//! `config.ini`, `prusaslicer.ini`, one 8-bit gray PNG a layer and the thumbnails.
//!
//! Both directions share PrusaSlicer 2.5's print-time estimate, the source of `printTime`
//! (docs/EXECUTOR.md, "Imported jobs", gives it in full): the exposure of `Scheme` and the
//! tilt, delay and tower of `Model`. Its fade counter steps in floating point, so it can
//! stop a hair above `expTime` and step once more: one layer less than `expTime`
//! (`fixtures/sl1/cube3mm.sl1`: 3.82 s instead of 6 s), or less than nothing
//! (`cylinder_hole.sl1s`: −1.83 s). The printer's firmware computes its own fade.
//!
//! [`mod@read`] imports a file as layers and steps that take what the estimate gives them;
//! `write.rs` writes a job as one, fitting the scheme to the job's exposures; what the
//! format cannot say is `cannot_carry`'s; `thumbnail.rs` draws the preview pictures.

pub mod read;
mod thumbnail;
mod write;

pub(crate) use read::import;
pub(crate) use thumbnail::preview_png;
pub(crate) use write::write;

use super::Format;
use crate::bundle::{Manifest, Mode};
use crate::error::{Error, Result};
use crate::text::plural;
use crate::warning::Warning;
use std::path::Path;

/// The printer's settings entry.
pub const CONFIG: &str = "config.ini";
/// PrusaSlicer's full configuration entry.
pub const PRUSASLICER: &str = "prusaslicer.ini";
/// Layers exposed for `expTimeFirst`.
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
/// The display of the printers the formats are named after: (pixels x, pixels y, width
/// mm, height mm), portrait.
const SL1_DISPLAY: (u32, u32, f64, f64) = (1440, 2560, 68.04, 120.96);
const SL1S_DISPLAY: (u32, u32, f64, f64) = (1620, 2560, 81.0, 128.0);

/// True when `archive` holds an SL1's two settings entries.
pub(crate) fn holds(archive: &super::archive::read::Archive) -> bool {
    archive.contains(CONFIG) && archive.contains(PRUSASLICER)
}

/// Refuses a job of several projectors for `format` (SL1/SL1S, NanoDLP): it shows one
/// image per layer.
pub(crate) fn check_projectors(format: Format, projectors: usize, out: &Path) -> Result<()> {
    if projectors > 1 {
        let name = if format == Format::Nanodlp {
            "NanoDLP plates"
        } else {
            "SL1/SL1S"
        };
        return Err(Error::Usage(format!(
            "{}: {name} carry one image per layer, but this job's machine has {projectors} projectors; export it as dmdjob-zip or sla-control instead",
            out.display()
        )));
    }
    Ok(())
}

/// The SL1 exposure scheme: `expTimeFirst`, `expTime`, `numFade`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Scheme {
    /// `expTimeFirst`, s.
    pub first_s: f64,
    /// `expTime`, s.
    pub exp_s: f64,
    /// `numFade`.
    pub fade: usize,
}

impl Scheme {
    /// The exposure the scheme gives layer `i`, exactly.
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

    /// The exposure of each of `n` layers as PrusaSlicer 2.5's estimate steps it, in
    /// floating point (module docs).
    fn estimate(&self, n: usize) -> Vec<f64> {
        let delta = (self.first_s - self.exp_s) / (self.fade as f64 + 1.0);
        let mut fade = self.first_s;
        (0..n)
            .map(|i| {
                if i < FIRST_LAYERS {
                    self.first_s
                } else if fade > self.exp_s {
                    fade -= delta;
                    fade
                } else {
                    self.exp_s
                }
            })
            .collect()
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
            let m = Scheme {
                first_s,
                exp_s,
                fade,
            }
            .misses(exps);
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

/// How the material prints (`material_print_speed`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PrintSpeed {
    /// `fast`: fast or slow tilt by the layer's area.
    Fast,
    /// `slow`: every layer tilts slowly.
    Slow,
    /// `high_viscosity`: every layer tilts with `high_viscosity_tilt_time`.
    HighViscosity,
}

/// The settings PrusaSlicer 2.5's print-time estimate uses (module docs): the importer
/// builds its steps from them, and the writer computes the `printTime` it writes with
/// them, so both agree with PrusaSlicer and with each other.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Model {
    /// The exposures.
    pub scheme: Scheme,
    /// `layerHeight`, mm.
    pub layer_mm: f64,
    /// `fast_tilt_time`, s.
    pub fast_tilt_s: f64,
    /// `slow_tilt_time`, s.
    pub slow_tilt_s: f64,
    /// `high_viscosity_tilt_time`, s.
    pub hv_tilt_s: f64,
    /// `area_fill` % × the display's area, mm².
    pub fast_max_mm2: f64,
    /// `material_print_speed`.
    pub speed: PrintSpeed,
}

impl Model {
    /// The model of the files the writer makes: PrusaSlicer's default tilt and a fast
    /// material on a display of `display_mm2`.
    fn written(scheme: Scheme, layer_mm: f64, display_mm2: f64) -> Model {
        Model {
            scheme,
            layer_mm,
            fast_tilt_s: FAST_TILT_S,
            slow_tilt_s: SLOW_TILT_S,
            hv_tilt_s: HV_TILT_S,
            fast_max_mm2: display_mm2 * AREA_FILL_PCT / 100.0,
            speed: PrintSpeed::Fast,
        }
    }

    /// PrusaSlicer's `printTime` of layers of the given areas (mm²), s: every layer's
    /// exposure (negative ones included, as PrusaSlicer sums them) plus its tilt, delay
    /// and tower time.
    fn print_time_s(&self, areas_mm2: &[f64]) -> f64 {
        let exposures = self.scheme.estimate(areas_mm2.len());
        areas_mm2
            .iter()
            .zip(exposures)
            .map(|(&a, e)| e + self.overhead_s(a).0)
            .sum()
    }

    /// What a layer of `area_mm2` takes besides its exposure: tilt, delay, tower, s.
    fn overhead_s(&self, area_mm2: f64) -> (f64, bool) {
        let fast = area_mm2 <= self.fast_max_mm2;
        let tilt = match (self.speed, fast) {
            (PrintSpeed::Slow, _) | (PrintSpeed::Fast, false) => self.slow_tilt_s,
            (PrintSpeed::HighViscosity, _) => self.hv_tilt_s,
            (PrintSpeed::Fast, true) => self.fast_tilt_s,
        };
        let delay = match (self.speed, fast) {
            (PrintSpeed::Slow, _) => 3.0,
            (PrintSpeed::HighViscosity, _) => 3.5,
            (PrintSpeed::Fast, false) => 1.0,
            (PrintSpeed::Fast, true) => 0.0,
        };
        (tilt + delay + 5.0 * self.layer_mm, fast)
    }
}

/// A number as PrusaSlicer writes a setting: the shortest decimal that reads back.
fn num(v: f64) -> String {
    format!("{}", crate::round::derived(v))
}

/// A duration for a message, s, to the millisecond.
fn secs(v: f64) -> String {
    crate::text::number((v * 1000.0).round() / 1000.0)
}

/// What an SL1 (`format` Sl1) or SL1S cannot carry of `m` (a job of one projector and
/// at least one layer), in the order the exporter reports it: layers the exposure scheme
/// cannot give their exposure, other layer thicknesses, continuous layers, the stage
/// steps (always), a display other than the printer's.
pub(crate) fn cannot_carry(format: Format, m: &Manifest) -> Vec<Warning> {
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
                    "SL1 exposes layers 0-2 for expTimeFirst ({} s), fades over {} (numFade) to expTime ({} s); {n} {} a different exposure in the job (first layer {first}: {} s in the job, {} s in the SL1; largest difference {} s)",
                    secs(scheme.first_s),
                    crate::text::count(scheme.fade as u64, "layer", "layers"),
                    secs(scheme.exp_s),
                    plural(n, "layer has", "layers have"),
                    secs(job_s),
                    secs(sl1_s),
                    secs(worst)
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
    let count =
        |f: &dyn Fn(&crate::bundle::Layer) -> bool| m.layers.iter().filter(|l| f(l)).count() as u64;
    let uneven = count(&|l| (l.thickness_mm - h).abs() > 1e-9);
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
    let continuous = count(&|l| l.mode == Mode::Continuous);
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
    let steps: u64 = m.layers.iter().map(|l| l.steps.len() as u64).sum();
    warnings.push(
        Warning::new(
            "export.sl1-steps",
            format!(
                "SL1 carries no stage steps: the printer tilts its vat between layers instead of the job's {} process ({steps} planned steps, est. print time {} s in the job; the SL1's estimate with PrusaSlicer's tilt times)",
                serde_json::to_value(m.machine.process)
                    .ok()
                    .and_then(|v| v.as_str().map(String::from))
                    .unwrap_or_default(),
                secs(m.totals.print_time_s)
            ),
        )
        .with("steps", steps)
        .with("print_time_s", m.totals.print_time_s),
    );
    warnings.extend(other_display(format, m));
    warnings
}

/// The printer model `format` names and its display.
fn printer(format: Format) -> (&'static str, (u32, u32, f64, f64)) {
    match format {
        Format::Sl1s => ("SL1S", SL1S_DISPLAY),
        _ => ("SL1", SL1_DISPLAY),
    }
}

/// `export.sl1-display` when the job's projector is not the display of the printer the
/// format names.
fn other_display(format: Format, m: &Manifest) -> Option<Warning> {
    let p = &m.machine.projector[0];
    let (model, real) = printer(format);
    let size = (p.width_px, p.height_px);
    if size == (real.0, real.1) || size == (real.1, real.0) {
        return None;
    }
    let px = p.pixel_mm.get();
    Some(
        Warning::new(
            "export.sl1-display",
            format!(
                "the masks are {}x{} px ({} x {} mm), a Prusa {model} shows {}x{} px: PrusaSlicer and UVtools open the file, the printer itself refuses it",
                p.width_px,
                p.height_px,
                num(p.width_px as f64 * px),
                num(p.height_px as f64 * px),
                real.1,
                real.0
            ),
        )
        .with("width_px", p.width_px as u64)
        .with("height_px", p.height_px as u64)
        .with("printer", model),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> Model {
        Model {
            scheme: Scheme {
                exp_s: 6.0,
                first_s: 30.0,
                fade: 10,
            },
            layer_mm: 0.1,
            fast_tilt_s: 5.0,
            slow_tilt_s: 8.0,
            hv_tilt_s: 10.0,
            fast_max_mm2: 100.0,
            speed: PrintSpeed::Fast,
        }
    }

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
    fn estimated_exposures_step_in_floating_point_as_prusaslicers() {
        let e = model().scheme.estimate(30);
        assert_eq!(&e[..3], &[30.0; 3]);
        let delta = 24.0 / 11.0;
        assert!((e[3] - (30.0 - delta)).abs() < 1e-12);
        // 30 − 11·(24/11) ends a hair above 6 in floating point: one more step follows.
        assert!((e[13] - 6.0).abs() < 1e-9);
        assert!((e[14] - (6.0 - delta)).abs() < 1e-9, "{}", e[14]);
        assert_eq!(e[15], 6.0);
        // PrusaSlicer 2.5 wrote printTime = 534.818182 for such a 30-layer 3 mm cube
        // (fixtures/sl1/cube3mm.sl1): exposures + 30 × (5 s tilt + 0.5 s tower).
        let total: f64 = e.iter().sum::<f64>() + 30.0 * 5.5;
        assert!((total - 534.818182).abs() < 1e-5, "{total}");
        // A huge numFade steps down from expTimeFirst by a vanishing amount.
        let huge = Scheme {
            fade: usize::MAX,
            ..model().scheme
        };
        assert_eq!(huge.estimate(5)[3], 30.0);
    }

    #[test]
    fn tilt_and_delay_by_area_and_material() {
        let mut m = model();
        assert_eq!(m.overhead_s(100.0), (5.0 + 0.5, true));
        assert_eq!(m.overhead_s(100.5), (8.0 + 1.0 + 0.5, false));
        m.speed = PrintSpeed::Slow;
        assert_eq!(m.overhead_s(1.0).0, 8.0 + 3.0 + 0.5);
        m.speed = PrintSpeed::HighViscosity;
        assert_eq!(m.overhead_s(1e6).0, 10.0 + 3.5 + 0.5);
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
        let time = |s: Scheme, area: f64, n: usize| {
            Model::written(s, 0.05, display).print_time_s(&vec![area; n])
        };
        assert!((time(s, 1.0, 20) - 265.0).abs() < 1e-9);
        // A 45.7 mm cube, 900 slow layers: printTime 15525.000003.
        assert!((time(s, 8000.0, 900) - 15525.0).abs() < 1e-6);
        // First 20 s, fade 4 (the scheme test above): 325.
        let f = Scheme {
            first_s: 20.0,
            exp_s: 8.0,
            fade: 4,
        };
        assert!((time(f, 1.0, 20) - 325.0).abs() < 1e-9);
    }
}
