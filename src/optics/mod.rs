//! Light-uniformity calibration and compensation (docs/CALIBRATION.md): the irradiance is
//! modelled as E(x, y, g) = P(x, y)·S(g) ([`Calibration`], part of the machine description);
//! [`calib`] fits it (`dmdsl calibrate`, with [`report`] and [`plots`]), [`compensate`]
//! turns each layer's coverage into grays with it, [`exposure`] gives the layer exposure.
//! It returns values (the gray map, the manifest record); the job writes the bundle.
//!
//! Invariants: coverage 0 stays 0; a pixel gets the level nearest to coverage·E* in
//! irradiance; S is strictly increasing on its valid range (enforced when a calibration is
//! loaded); the output depends only on the input and the settings, never on the thread
//! count.

pub mod calib;
pub mod compensate;
pub mod exposure;
pub mod plots;
pub mod report;
#[cfg(test)]
pub(crate) mod synthetic;

/// The calibration model this stage fits and applies (defined with the profile that
/// carries it).
pub use crate::profile::calibration::{field, response, Calibration, FitSummary, Units};
pub use compensate::Compensator;

use crate::bundle::Optics;
use crate::error::{Error, Result};
use crate::profile::Profile;
use crate::text::{fixed, number, plural};
use crate::warning::Warning;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Compensation mode of a job.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// No compensation: a pixel's value is its coverage.
    Off,
    /// One gray per zone (the method of Xu et al. 2010).
    Zone,
    /// One gray per pixel from the smooth fit.
    Pixel,
}

impl Mode {
    /// The mode as written in the manifest.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Off => "off",
            Mode::Zone => "zone",
            Mode::Pixel => "pixel",
        }
    }
}

/// Dithering of compensated grays (to beat 8-bit gray steps).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dither {
    /// Zone mode: a zone whose nearest gray misses the target by more than 0.75 %
    /// (`MIX_TOLERANCE`) mixes the two grays around its target in whole rows; every other
    /// zone keeps one gray. Pixel mode: no dithering.
    #[default]
    Auto,
    /// Zone mode: every zone mixes the two grays around its target. Pixel mode:
    /// Floyd–Steinberg error diffusion (serpentine, lit pixels only).
    On,
    /// One gray per zone / per pixel, nearest in irradiance (the method of Xu et al. 2010).
    Off,
}

impl Dither {
    /// The setting as written in the manifest.
    pub fn as_str(self) -> &'static str {
        match self {
            Dither::Auto => "auto",
            Dither::On => "on",
            Dither::Off => "off",
        }
    }
}

/// Job options of the optics stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct OpticsOptions {
    /// Requested mode; `None`: zone if the projector has a calibration, else off.
    pub mode: Option<Mode>,
    /// Dithering.
    pub dither: Dither,
}

impl OpticsOptions {
    /// The mode to apply: the one asked for, else zone when a projector is `calibrated`,
    /// else off. `--dither on` without compensation is a usage error.
    pub fn resolve_mode(&self, calibrated: bool) -> Result<Mode> {
        let mode = (self.mode).unwrap_or(if calibrated { Mode::Zone } else { Mode::Off });
        if self.dither == Dither::On && mode == Mode::Off {
            let msg = "--dither on needs compensation (zone or pixel)";
            return Err(Error::Usage(msg.to_string()));
        }
        Ok(mode)
    }
}

/// Applies `--calibration [PROJECTOR=]FILE` arguments to a profile: each file replaces the
/// calibration of the named projector (without a name: the first projector, which must
/// then be the only one).
pub fn apply_calibration_args(profile: &mut Profile, args: &[String]) -> Result<()> {
    for a in args {
        let (name, file) = match a.split_once('=') {
            Some((n, f)) if !n.is_empty() && !n.contains('/') => (Some(n), f),
            _ => (None, a.as_str()),
        };
        let k = match name {
            Some(n) => profile
                .projector
                .iter()
                .position(|p| p.name == n)
                .ok_or_else(|| {
                    Error::Usage(format!(
                        "--calibration {a}: the profile has no projector named {n:?}"
                    ))
                })?,
            None if profile.projector.len() == 1 => 0,
            None => {
                return Err(Error::Usage(format!(
                    "--calibration {a}: the profile has {} projectors; write PROJECTOR=FILE",
                    profile.projector.len()
                )))
            }
        };
        let c = Calibration::read(Path::new(file))?;
        profile.projector[k]
            .check_calibration(&c)
            .map_err(|m| Error::input(Path::new(file), m))?;
        profile.projector[k].calibration = Some(c);
    }
    Ok(())
}

/// The optics stage of one job: the compensator of the calibrated projector and how the
/// exposure was resolved. Built once per job by [`prepare`].
#[derive(Debug)]
pub struct JobOptics {
    /// The precomputed tables.
    pub compensator: Compensator,
    /// Index of the projector whose calibration is applied.
    pub projector: usize,
    /// The calibration applied.
    pub calibration: Calibration,
    /// How the exposure was derived.
    pub exposure: exposure::ExposureDerivation,
}

/// Prepares the optics stage of a job: picks the mode (default: zone when the projector has
/// a calibration, else off), builds the compensator and resolves the exposure in `profile`
/// (see [`exposure::resolve`]). `Ok(None)`: compensation is off.
pub fn prepare(
    profile: &mut Profile,
    opts: &OpticsOptions,
    thickness_mm: f64,
) -> Result<Option<JobOptics>> {
    let cal = profile
        .projector
        .iter()
        .position(|p| p.calibration.is_some());
    let mode = opts.resolve_mode(cal.is_some())?;
    if mode == Mode::Off {
        return Ok(None);
    }
    let Some(k) = cal else {
        return Err(Error::Usage(format!(
            "--compensation {}: profile {:?} has no light calibration; give --calibration FILE (from `dmdsl calibrate`) or use --compensation off",
            mode.as_str(),
            profile.name
        )));
    };
    if profile.projector.len() > 1 {
        return Err(Error::Usage(format!(
            "--compensation {}: compensating a tiled machine ({} projectors) is not supported yet; use --compensation off",
            mode.as_str(),
            profile.projector.len()
        )));
    }
    let calibration = profile.projector[k]
        .calibration
        .clone()
        .expect("position found it");
    let field = profile.field();
    let compensator =
        Compensator::new(&calibration, &field, mode, opts.dither).map_err(|m| Error::Profile {
            origin: profile.name.clone(),
            msg: format!("projector {} calibration: {m}", profile.projector[k].name),
        })?;
    let exposure = exposure::resolve(
        profile,
        calibration.units,
        compensator.prediction.target,
        thickness_mm,
    );
    Ok(Some(JobOptics {
        compensator,
        projector: k,
        calibration,
        exposure,
    }))
}

/// A gray map for the bundle: the full-coverage gray of every pixel as the projector shows
/// it (8-bit PNG), and its path inside the bundle.
#[derive(Debug, Clone, PartialEq)]
pub struct GrayMap {
    /// Path inside the bundle, `optics/<projector>-gray-map.png`.
    pub file: String,
    /// The PNG bytes.
    pub png: Vec<u8>,
}

impl JobOptics {
    /// The gray map of the calibrated projector, as a PNG (the masks' encoding). It depends
    /// on the set-up only, so the job can write it while the masks are made.
    pub fn gray_map(&self, profile: &Profile) -> GrayMap {
        let p = &profile.projector[self.projector];
        GrayMap {
            file: format!("optics/{}-gray-map.png", p.name),
            png: self.compensator.gray_map_png(p),
        }
    }

    /// After all layers, with the gray map ([`gray_map`](Self::gray_map)) written as `file`
    /// with SHA-256 `gray_map_sha256`: the manifest record and the warnings for the job.
    pub fn finish_with(&self, (file, gray_map_sha256): (String, String)) -> (Optics, Vec<Warning>) {
        let c = &self.compensator;
        let pr = &c.prediction;
        let zone_grays = match c.mode() {
            Mode::Zone => pr
                .zone_gray
                .chunks(pr.zone_grid.0)
                .map(<[u8]>::to_vec)
                .collect(),
            _ => Vec::new(),
        };
        let mut warnings = self.exposure.warnings.clone();
        let [x0, y0, x1, y1] = self.calibration.field.area_mm;
        let layers_outside = c.layers_outside();
        if layers_outside > 0 {
            let (beyond, margin) = (c.beyond_mm(), self.calibration.field.extrapolate_mm.get());
            let area = format!(
                "x {}..{}, y {}..{} mm",
                number(x0),
                number(x1),
                number(y0),
                number(y1)
            );
            let reach = format!(
                "{layers_outside} {} up to {} mm beyond the calibrated area ({area})",
                plural(layers_outside, "layer reaches", "layers reach"),
                fixed(beyond, 2),
            );
            let (code, rest) = match beyond > margin + 1e-9 {
                true => ("optics.beyond-extrapolation", "farther than the calibration's extrapolate_mm = {m} mm: beyond that margin the light is unknown and compensated as if it were the light at the margin"),
                false => ("optics.outside-calibrated-area", "within the calibration's extrapolate_mm = {m} mm: the compensation there extrapolates the measured light"),
            };
            let w = Warning::new(
                code,
                format!("{reach}, {}", rest.replace("{m}", &number(margin))),
            );
            warnings.push(
                w.with("layers", layers_outside)
                    .with("area_mm", vec![x0, y0, x1, y1])
                    .with("beyond_mm", beyond)
                    .with("extrapolate_mm", margin),
            );
        }
        if pr.unreachable > 0 && layers_outside > 0 {
            let (unit, units) = match c.mode() {
                Mode::Zone => ("zone", "zones"),
                _ => ("pixel", "pixels"),
            };
            warnings.push(
                Warning::new(
                    "optics.unreachable",
                    format!(
                        "{} {} outside the calibrated area cannot reach the target irradiance even fully on: the part's exposure there falls short",
                        pr.unreachable,
                        plural(pr.unreachable, unit, units)
                    ),
                )
                .with("count", pr.unreachable)
                .with("unit", unit),
            );
        }
        let record = Optics {
            mode: c.mode().as_str().into(),
            dither: c.dither().as_str().into(),
            mixed_zones: pr.mixed_zones,
            projector: self.projector as u32,
            calibration: self.calibration.source.clone(),
            units: self.calibration.units.as_str().into(),
            target_irradiance: pr.target,
            mean_irradiance: pr.mean,
            throughput: pr.target / pr.mean,
            calibrated_area_mm: self.calibration.field.area_mm,
            valid_gray: self.calibration.response.valid_gray(),
            zone_mm: self.calibration.zone_mm.get(),
            zone_grays,
            gray_map: file,
            gray_map_sha256,
            predicted: pr.spreads,
            zones_outside: pr.zones_outside,
            pixels_outside: pr.pixels_outside,
            unreachable: pr.unreachable,
            layers_outside,
            exposure_rule: self.exposure.rule.clone(),
            dose_mj_cm2: self.exposure.dose_mj_cm2,
        };
        (record, warnings)
    }
}

#[cfg(test)]
mod tests {
    use super::synthetic::{p_published, s_published};
    use crate::profile::Profile;

    /// The default profile carries the published fit of Xu et al. 2010 (x, y in cm,
    /// z = 255 − pixel value) as its calibration data; the synthetic calibration sets write
    /// the same P and S out as formulas, once.
    #[test]
    fn the_default_profile_carries_the_published_fit() {
        let cal = Profile::default_profile().projector[0]
            .calibration
            .clone()
            .expect("the default profile is calibrated");
        for (x, y) in [
            (2.5, 2.5),
            (32.5, 22.5),
            (62.5, 42.5),
            (10.0, 40.0),
            (65.0, 0.0),
        ] {
            let (got, want) = (cal.field.eval(x, y), 1e-8 * p_published(x, y));
            assert!(
                (got / want - 1.0).abs() < 1e-12,
                "P({x}, {y}) = {got}, want {want}"
            );
        }
        let [lo, hi] = cal.response.valid_gray();
        for g in lo..=hi {
            let (got, want) = (cal.response.eval(g as f64), s_published(g as f64));
            assert!(
                (got / want - 1.0).abs() < 1e-12,
                "S({g}) = {got}, want {want}"
            );
        }
    }
}
