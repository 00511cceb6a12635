//! PrusaSlicer SL1 / SL1S files (as PrusaSlicer 2.5 writes them): a zip of `config.ini`
//! (what the printer reads: `expTime`, `expTimeFirst`, `numFade`, `layerHeight`,
//! `printTime`, `jobDir`, …), `prusaslicer.ini` (the full configuration: display size,
//! pixels and orientation, tilt times, `area_fill`, `material_print_speed`, …) and one
//! 8-bit gray PNG a layer, `<jobDir>NNNNN.png`.
//!
//! ## The machine and the steps
//! The projector is the display as the masks show it (portrait displays store the image
//! turned: `display_pixels_y` wide and `display_pixels_x` high), pixels
//! `display_width / display_pixels_x` mm, no mirroring (the masks are taken as they are
//! shown). Each layer becomes: a move of the tower to the layer's top (`(i + 1) ×
//! layerHeight`), a wait, and the exposure, so that the layer takes what PrusaSlicer 2.5's
//! estimate gives it (`SLAPrint::Steps::merge_slices_and_eval_stats`, the source of
//! `printTime`):
//! * exposure: `expTimeFirst` for the first 3 layers; then a counter starting at
//!   `expTimeFirst` steps down by `(expTimeFirst − expTime) / (numFade + 1)` for each
//!   later layer while it is above `expTime` and gives that layer the stepped value;
//!   `expTime` after that. This is PrusaSlicer's estimate, floating-point steps included:
//!   the counter can stop a hair above `expTime` and step once more, giving one layer
//!   less than `expTime` (`fixtures/sl1/cube3mm.sl1`: 3.82 s instead of 6 s), or less
//!   than nothing (`cylinder_hole.sl1s`: −1.83 s); such a layer is exposed for 0 s and
//!   its wait shortened by the rest, so the layer still takes what the estimate says.
//!   The printer's firmware computes its own fade.
//! * tilt: a layer is fast when its area is at most `area_fill` % of the display's
//!   (`display_width × display_height`); its tilt takes `fast_tilt_time` or
//!   `slow_tilt_time`, or `slow_tilt_time` / `high_viscosity_tilt_time` for every layer
//!   with `material_print_speed` `slow` / `high_viscosity`;
//! * a delay before the exposure: 3 s (slow material), 3.5 s (high viscosity), 1 s for a
//!   slow layer otherwise;
//! * the tower: 5 s per mm of layer height.
//!
//! The layer's area is the mask's lit area (pixel values / 255 × pixel area); PrusaSlicer
//! measures the polygons it rasterized, so a layer within a few pixels of the `area_fill`
//! threshold may count fast here and slow there. The job's estimate
//! (`totals.print_time_s`) is the file's `printTime`, so the executor's estimate check
//! compares the simulation with PrusaSlicer's own figure.
//!
//! A missing or unreadable key is an error naming the file and the key; a missing,
//! undecodable or wrongly sized mask is a violation of the layer in the report (a layer
//! whose mask is missing counts as fast).

use crate::bundle::{Layer, MaskRef, MemSource, Mode, Step};
use crate::error::Result;
use crate::formats::archive::read::Archive;
use crate::formats::{
    bbox_mm, manifest_of, mask_figures, ForeignEstimate, Format, Implied, Job, ManifestParts,
};
use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};

/// The printer's settings entry.
pub const CONFIG: &str = "config.ini";
/// PrusaSlicer's full configuration entry.
pub const PRUSASLICER: &str = "prusaslicer.ini";
/// Layers exposed for `expTimeFirst` in PrusaSlicer 2.5's estimate.
const FIRST_LAYERS: usize = 3;
/// Tower speed and acceleration of the imported machine (the tower move is part of the
/// per-layer time PrusaSlicer assumes; the wait makes up the rest).
const TOWER_SPEED_MM_S: f64 = 10.0;
const TOWER_ACCEL_MM_S2: f64 = 100.0;

/// `key = value` lines of an ini entry.
struct Ini<'a> {
    archive: &'a Archive,
    entry: &'static str,
    values: BTreeMap<String, String>,
}

impl<'a> Ini<'a> {
    fn parse(archive: &'a Archive, entry: &'static str) -> Result<Ini<'a>> {
        let bytes = archive.get(entry).unwrap_or_default();
        let text = std::str::from_utf8(bytes)
            .map_err(|_| archive.error(Some(entry), "is not UTF-8 text"))?;
        let values = text
            .lines()
            .filter_map(|l| l.split_once('='))
            .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
            .collect();
        Ok(Ini {
            archive,
            entry,
            values,
        })
    }

    fn text(&self, key: &str) -> Result<&str> {
        self.values.get(key).map(String::as_str).ok_or_else(|| {
            self.archive
                .error(Some(self.entry), format!("missing key `{key}`"))
        })
    }

    fn opt_text(&self, key: &str) -> Option<&str> {
        self.values.get(key).map(String::as_str)
    }

    /// A finite number ≥ `min` (and > 0 when `positive`).
    fn num(&self, key: &str, positive: bool) -> Result<f64> {
        let t = self.text(key)?;
        match t.parse::<f64>() {
            Ok(v) if v.is_finite() && v >= 0.0 && (!positive || v > 0.0) => Ok(v),
            _ => Err(self.archive.error(
                Some(self.entry),
                format!(
                    "`{key} = {t}` is not a {} number",
                    if positive { "positive" } else { "non-negative" }
                ),
            )),
        }
    }

    fn opt_num(&self, key: &str, default: f64) -> Result<f64> {
        if self.values.contains_key(key) {
            self.num(key, false)
        } else {
            Ok(default)
        }
    }

    fn count(&self, key: &str) -> Result<usize> {
        let t = self.text(key)?;
        t.parse::<usize>().map_err(|_| {
            self.archive.error(
                Some(self.entry),
                format!("`{key} = {t}` is not a whole number ≥ 0"),
            )
        })
    }

    fn px(&self, key: &str) -> Result<u32> {
        let n = self.count(key)?;
        u32::try_from(n)
            .ok()
            .filter(|&n| (1..=16384).contains(&n))
            .ok_or_else(|| {
                self.archive.error(
                    Some(self.entry),
                    format!("`{key} = {n}` is not a display size in pixels (1 to 16384)"),
                )
            })
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
/// builds its steps from them, and the SL1 writer computes the `printTime` it writes with
/// them, so both agree with PrusaSlicer and with each other.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Model {
    /// `expTime`, s.
    pub(crate) exp_s: f64,
    /// `expTimeFirst`, s.
    pub(crate) first_s: f64,
    /// `numFade`.
    pub(crate) fade: usize,
    /// `layerHeight`, mm.
    pub(crate) layer_mm: f64,
    /// `fast_tilt_time`, s.
    pub(crate) fast_tilt_s: f64,
    /// `slow_tilt_time`, s.
    pub(crate) slow_tilt_s: f64,
    /// `high_viscosity_tilt_time`, s.
    pub(crate) hv_tilt_s: f64,
    /// `area_fill` % × the display's area, mm².
    pub(crate) fast_max_mm2: f64,
    /// `material_print_speed`.
    pub(crate) speed: PrintSpeed,
}

impl Model {
    /// Exposure of each of `n` layers, in PrusaSlicer 2.5's estimate (module docs).
    fn exposures(&self, n: usize) -> Vec<f64> {
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

    /// PrusaSlicer's `printTime` of layers of the given areas (mm²), s: every layer's
    /// exposure (negative ones included, as PrusaSlicer sums them) plus its tilt, delay
    /// and tower time.
    pub(crate) fn print_time_s(&self, areas_mm2: &[f64]) -> f64 {
        let exposures = self.exposures(areas_mm2.len());
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

/// Imports the SL1/SL1S archive `archive` (SHA-256 `sha256`).
pub(crate) fn import(archive: Archive, sha256: &str) -> Result<Job> {
    let path = archive.path().to_path_buf();
    let cfg = Ini::parse(&archive, CONFIG)?;
    let ps = Ini::parse(&archive, PRUSASLICER)?;
    let job_dir = cfg.text("jobDir")?.to_string();
    let print_time_s = cfg.num("printTime", false)?;
    let layer_mm = cfg.num("layerHeight", true)?;
    let px_x = ps.px("display_pixels_x")?;
    let px_y = ps.px("display_pixels_y")?;
    let width_mm = ps.num("display_width", true)?;
    let height_mm = ps.num("display_height", true)?;
    let portrait = match ps.text("display_orientation")? {
        "portrait" => true,
        "landscape" => false,
        other => {
            return Err(archive.error(
                Some(PRUSASLICER),
                format!("`display_orientation = {other}` is neither portrait nor landscape"),
            ))
        }
    };
    let speed = match ps.opt_text("material_print_speed").unwrap_or("fast") {
        "fast" => PrintSpeed::Fast,
        "slow" => PrintSpeed::Slow,
        "high_viscosity" => PrintSpeed::HighViscosity,
        other => {
            return Err(archive.error(
                Some(PRUSASLICER),
                format!("`material_print_speed = {other}` is not fast, slow or high_viscosity"),
            ))
        }
    };
    let model = Model {
        exp_s: cfg.num("expTime", true)?,
        first_s: cfg.num("expTimeFirst", true)?,
        fade: cfg.count("numFade")?,
        layer_mm,
        fast_tilt_s: ps.num("fast_tilt_time", false)?,
        slow_tilt_s: ps.num("slow_tilt_time", false)?,
        hv_tilt_s: ps.opt_num("high_viscosity_tilt_time", 10.0)?,
        fast_max_mm2: ps.num("area_fill", false)? / 100.0 * width_mm * height_mm,
        speed,
    };
    let max_height_mm = ps.opt_num("max_print_height", 150.0)?;
    let model_name = cfg.opt_text("printerModel").unwrap_or_default().to_string();
    let generator = cfg
        .opt_text("prusaSlicerVersion")
        .unwrap_or("PrusaSlicer")
        .to_string();
    let format = if model_name == "SL1S"
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("sl1s"))
    {
        Format::Sl1s
    } else {
        Format::Sl1
    };

    // The layer images: `<jobDir>NNNNN.png` at the top of the archive.
    let mut masks: BTreeMap<usize, String> = BTreeMap::new();
    for name in archive.names() {
        let Some(num) = name
            .strip_prefix(job_dir.as_str())
            .and_then(|r| r.strip_suffix(".png"))
        else {
            continue;
        };
        if num.len() == 5 && num.bytes().all(|b| b.is_ascii_digit()) {
            masks.insert(num.parse().unwrap_or_default(), name.clone());
        }
    }
    let Some(&last) = masks.keys().next_back() else {
        return Err(archive.error(
            None,
            format!("no layer images `{job_dir}NNNNN.png` (jobDir in {CONFIG})"),
        ));
    };
    let n = last + 1;
    let (w_px, h_px) = if portrait { (px_y, px_x) } else { (px_x, px_y) };
    let pixel_mm = width_mm / px_x as f64;
    let pixel_area_mm2 = (width_mm / px_x as f64) * (height_mm / px_y as f64);

    // Decode every mask (in parallel) for its area and lit box.
    let names: Vec<String> = (0..n)
        .map(|i| {
            masks
                .get(&i)
                .cloned()
                .unwrap_or_else(|| format!("{job_dir}{i:05}.png"))
        })
        .collect();
    let figures: Vec<(String, Option<crate::formats::MaskFigures>)> = names
        .par_iter()
        .map_init(Vec::new, |buf, name| match archive.get(name) {
            Some(b) => (
                crate::digest::sha256_hex(b),
                mask_figures(b, buf).map(|(_, _, f)| f),
            ),
            None => (String::new(), None),
        })
        .collect();

    // PrusaSlicer's estimate may give a layer a negative exposure (module docs): the layer
    // is exposed for 0 s and its wait is shortened by the rest, so that the layer still
    // takes what the estimate gives it.
    let exposures = model.exposures(n);
    let mut layers = Vec::with_capacity(n);
    for (i, ((name, (sha, fig)), exp)) in names.iter().zip(figures).zip(exposures).enumerate() {
        let area_mm2 = fig.map_or(0.0, |f| f.coverage_px * pixel_area_mm2);
        let (overhead, _fast) = model.overhead_s(area_mm2);
        let z = (i + 1) as f64 * layer_mm;
        let prev = i as f64 * layer_mm;
        let move_s = crate::motion::move_time(z - prev, TOWER_SPEED_MM_S, TOWER_ACCEL_MM_S2);
        let exposure_s = exp.max(0.0);
        let wait_s = (overhead + exp.min(0.0) - move_s).max(0.0);
        layers.push(Layer {
            cure: None,
            index: i as u64,
            z_mm: z,
            slice_z_mm: (i as f64 + 0.5) * layer_mm,
            thickness_mm: layer_mm,
            mode: Mode::Layered,
            exposure_s,
            area_mm2,
            max_fill_distance_mm: 0.0,
            islands: 0,
            bbox_mm: fig
                .and_then(|f| f.lit_box)
                .map(|b| bbox_mm(b, h_px, pixel_mm)),
            masks: vec![MaskRef {
                file: name.clone(),
                sha256: sha,
                projector: 0,
            }],
            steps: vec![
                Step::Move {
                    to_mm: z,
                    speed_mm_s: TOWER_SPEED_MM_S,
                    accel_mm_s2: TOWER_ACCEL_MM_S2,
                },
                Step::Wait { s: wait_s },
                Step::Expose { s: exposure_s },
            ],
            time_s: move_s + wait_s + exposure_s,
        });
    }

    let machine = Implied {
        name: match model_name.as_str() {
            "" => "sl1-import".into(),
            m => format!("sl1-import-{}", m.to_lowercase()),
        },
        resin: cfg.opt_text("materialName").unwrap_or_default().into(),
        projector: "display",
        size_px: (w_px, h_px),
        pixel_mm,
        travel_max_mm: max_height_mm.max(layer_mm),
        max_speed_mm_s: TOWER_SPEED_MM_S,
        max_accel_mm_s2: TOWER_ACCEL_MM_S2,
        // 1 µm steps, or finer for layers thinner than that.
        steps_per_mm: 1000f64.max(1.0 / layer_mm),
    }
    .machine(&layers)
    .map_err(|m| {
        archive.error(
            Some(PRUSASLICER),
            format!("the display and tower it describes: {m}"),
        )
    })?;
    let manifest = manifest_of(
        &path,
        ManifestParts {
            generator,
            sha256: sha256.into(),
            machine,
            layer_height_mm: layer_mm,
            binary: false,
            layers,
            print_time_s: Some(print_time_s),
        },
    );
    let files: HashMap<String, Vec<u8>> = archive.into_files();
    Ok(Job {
        source: Box::new(MemSource::new(&path, files)),
        path,
        format,
        manifest,
        estimate: Some(ForeignEstimate {
            source: "PrusaSlicer printTime (config.ini)".into(),
            print_time_s,
        }),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> Model {
        Model {
            exp_s: 6.0,
            first_s: 30.0,
            fade: 10,
            layer_mm: 0.1,
            fast_tilt_s: 5.0,
            slow_tilt_s: 8.0,
            hv_tilt_s: 10.0,
            fast_max_mm2: 100.0,
            speed: PrintSpeed::Fast,
        }
    }

    #[test]
    fn exposures_follow_prusaslicers_estimate_floating_point_steps_included() {
        let e = model().exposures(30);
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
    }

    #[test]
    fn a_huge_num_fade_steps_down_by_a_vanishing_amount() {
        // The steps follow the file's fade: after the bottom layers the exposure steps
        // down from expTimeFirst by a vanishing amount.
        let e = Model {
            fade: usize::MAX,
            ..model()
        }
        .exposures(5);
        assert_eq!(e[3], 30.0);
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
}
