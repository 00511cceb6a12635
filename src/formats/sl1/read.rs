//! Reading a PrusaSlicer SL1 / SL1S file (as PrusaSlicer 2.5 writes it) as a job
//! (docs/EXECUTOR.md, "Imported jobs").
//!
//! Each layer is a move of the tower to the layer's top, a wait and the exposure, timed
//! so that the layer takes what PrusaSlicer 2.5's estimate gives it (the model of
//! [`super`]); a negative estimated exposure is 0 s of light with the wait shortened by
//! the rest. The tilt counts a layer's area, as the layer record does, as the pixels lit at
//! least half (PrusaSlicer measures its polygons: a layer within a few pixels of
//! `area_fill` may count otherwise; the sum of a compensated mask's grays would count a
//! fifth less). The job's estimate is the file's
//! `printTime`, so the executor compares the simulation with PrusaSlicer's own figure.
//!
//! A missing or unreadable key is an error naming the file and the key; a missing,
//! undecodable or wrongly sized mask is a violation of the layer in the report (a layer
//! whose mask is missing counts as fast).

use super::{Model, PrintSpeed, Scheme, CONFIG, PRUSASLICER};
use crate::bundle::{Layer, Machine, Step};
use crate::error::Result;
use crate::formats::archive::read::Archive;
use crate::formats::imported::{self, Imported};
use crate::formats::{ForeignEstimate, Format, Job};
use std::collections::BTreeMap;

/// PrusaSlicer's `max_print_height` when a file does not give one, mm.
pub(super) const DEFAULT_MAX_PRINT_HEIGHT_MM: f64 = 150.0;

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
        let bytes = archive.get(entry)?.unwrap_or_default();
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

    /// `0`/`1` (absent: 0).
    fn flag(&self, key: &str) -> Result<bool> {
        match self.opt_text(key).unwrap_or("0") {
            "0" => Ok(false),
            "1" => Ok(true),
            t => Err(self.archive.error(
                Some(self.entry),
                format!("`{key} = {t}` is neither 0 nor 1"),
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

/// What an SL1's settings say of its job.
struct Settings {
    /// `jobDir`: the images' name before their number.
    job_dir: String,
    /// `printTime`, s.
    print_time_s: f64,
    /// PrusaSlicer's estimate.
    model: Model,
    /// The images: their size, the edge and area of a pixel (mm, mm²), mirroring.
    size_px: (u32, u32),
    pixel_mm: f64,
    pixel_area_mm2: f64,
    mirror: (bool, bool),
    /// `max_print_height`, mm.
    max_height_mm: f64,
    /// `printerModel` (empty when absent).
    printer_model: String,
}

/// Reads `config.ini` and `prusaslicer.ini` of `archive`.
fn settings(archive: &Archive, cfg: &Ini, ps: &Ini) -> Result<Settings> {
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
        scheme: Scheme {
            exp_s: cfg.num("expTime", true)?,
            first_s: cfg.num("expTimeFirst", true)?,
            fade: cfg.count("numFade")?,
        },
        layer_mm,
        fast_tilt_s: ps.num("fast_tilt_time", false)?,
        slow_tilt_s: ps.num("slow_tilt_time", false)?,
        hv_tilt_s: ps.opt_num("high_viscosity_tilt_time", 10.0)?,
        fast_max_mm2: ps.num("area_fill", false)? / 100.0 * width_mm * height_mm,
        speed,
    };
    let size_px = if portrait { (px_y, px_x) } else { (px_x, px_y) };
    Ok(Settings {
        job_dir,
        print_time_s,
        model,
        size_px,
        pixel_mm: width_mm / px_x as f64,
        pixel_area_mm2: (width_mm / px_x as f64) * (height_mm / px_y as f64),
        mirror: (ps.flag("display_mirror_x")?, ps.flag("display_mirror_y")?),
        max_height_mm: ps.opt_num("max_print_height", DEFAULT_MAX_PRINT_HEIGHT_MM)?,
        printer_model: cfg.opt_text("printerModel").unwrap_or_default().to_string(),
    })
}

/// The layer images `<jobDir>NNNNN.png` at the top of `archive`, one name a layer up to
/// the last one found (a missing one named all the same).
fn image_names(archive: &Archive, job_dir: &str) -> Result<Vec<String>> {
    let mut masks: BTreeMap<usize, String> = BTreeMap::new();
    for name in archive.names() {
        let Some(num) = name
            .strip_prefix(job_dir)
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
    Ok((0..=last)
        .map(|i| {
            masks
                .remove(&i)
                .unwrap_or_else(|| format!("{job_dir}{i:05}.png"))
        })
        .collect())
}

/// The layers of the images `names`: each a move of the tower, a wait and the exposure
/// that take what PrusaSlicer's estimate gives the layer.
fn layers(s: &Settings, archive: &Archive, names: &[String], machine: &Machine) -> Vec<Layer> {
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let images = imported::images(archive, &refs);
    let layer_mm = s.model.layer_mm;
    let exposures = s.model.scheme.estimate(names.len());
    let mut layers = Vec::with_capacity(names.len());
    for (i, ((name, image), exp)) in refs.iter().zip(&images).zip(exposures).enumerate() {
        let area_mm2 = image
            .1
            .map_or(0.0, |(_, _, f)| f.half_px as f64 * s.pixel_area_mm2);
        let (overhead, _fast) = s.model.overhead_s(area_mm2);
        let z = (i + 1) as f64 * layer_mm;
        let prev = i as f64 * layer_mm;
        let move_s = crate::motion::move_time(z - prev, TOWER_SPEED_MM_S, TOWER_ACCEL_MM_S2);
        let exposure_s = exp.max(0.0);
        let wait_s = (overhead + exp.min(0.0) - move_s).max(0.0);
        let steps = vec![
            Step::Move {
                to_mm: z,
                speed_mm_s: TOWER_SPEED_MM_S,
                accel_mm_s2: TOWER_ACCEL_MM_S2,
            },
            Step::Wait { s: wait_s },
            Step::Expose { s: exposure_s },
        ];
        let time_s = move_s + wait_s + exposure_s;
        let place = (i, (z, (i as f64 + 0.5) * layer_mm, layer_mm));
        let on = (machine, 0, s.pixel_area_mm2, None);
        layers.push(imported::layer(place, (name, image), on, steps, time_s));
    }
    layers
}

/// Imports the SL1/SL1S archive `archive` (SHA-256 `sha256`).
pub(crate) fn import(archive: Archive, sha256: &str) -> Result<Job> {
    let cfg = Ini::parse(&archive, CONFIG)?;
    let ps = Ini::parse(&archive, PRUSASLICER)?;
    let s = settings(&archive, &cfg, &ps)?;
    let layer_mm = s.model.layer_mm;
    let mut display = imported::projector("display", s.size_px, s.pixel_mm);
    (display.mirror_x, display.mirror_y) = s.mirror;
    let name = match s.printer_model.as_str() {
        "" => "sl1-import".into(),
        m => format!("sl1-import-{}", m.to_lowercase()),
    };
    let resin = cfg.opt_text("materialName").unwrap_or_default().into();
    let tower = (
        s.max_height_mm.max(layer_mm),
        TOWER_SPEED_MM_S,
        TOWER_ACCEL_MM_S2,
        // 1 µm steps, or finer for layers thinner than that.
        1000f64.max(1.0 / layer_mm),
    );
    let unstated = [
        "stage.max_speed_mm_s",
        "stage.max_accel_mm_s2",
        "stage.steps_per_mm",
    ];
    let machine = imported::machine((name, resin), tower, vec![display], &unstated);
    let layers = layers(&s, &archive, &image_names(&archive, &s.job_dir)?, &machine);
    let sl1s = archive
        .path()
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("sl1s"));
    let resin_ml = cfg
        .opt_text("usedMaterial")
        .and_then(|t| t.parse::<f64>().ok());
    let imported = Imported {
        format: match s.printer_model == "SL1S" || sl1s {
            true => Format::Sl1s,
            false => Format::Sl1,
        },
        generator: cfg
            .opt_text("prusaSlicerVersion")
            .unwrap_or("PrusaSlicer")
            .to_string(),
        sha256: sha256.into(),
        machine,
        layer_height_mm: layer_mm,
        layers,
        estimate: Some(ForeignEstimate {
            source: "PrusaSlicer printTime (config.ini)".into(),
            print_time_s: s.print_time_s,
        }),
        resin_ml: resin_ml.filter(|v| v.is_finite() && *v >= 0.0),
        stated_areas: false,
        requests: Vec::new(),
        vacuum: false,
        notes: Vec::new(),
    };
    imported.job(archive, (PRUSASLICER, "the display and tower it describes"))
}
