//! Light-uniformity calibration and compensation (issue 3; method in docs/CALIBRATION.md).
//!
//! A DMD field is not evenly lit. Following seeds/000 the irradiance on the build plane is
//! modelled as E(x, y, g) = P(x, y)·S(g): a field factor P (a bivariate cubic,
//! [`field::FieldModel`]) times a gray response S (monotone on its valid gray range,
//! [`response::Response`]). The pieces:
//!
//! * [`calib`]: reads a measurement table (CSV) and fits P and S ([`calib::fit`]);
//!   `dmdsl calibrate` writes the result as a calibration file (TOML).
//! * [`Calibration`]: the stored model, attached to a projector in the profile
//!   (`[projector.calibration]`, so each projector of a tiled machine carries its own) or
//!   loaded from a file with `slice --calibration [PROJECTOR=]FILE`.
//! * [`compensate`]: per job, precomputes lookup tables once (one 256-entry table per zone,
//!   or a per-pixel gray map) and turns each layer's coverage mask into grays in place:
//!   a pixel of coverage c gets the level g with S(g)·P nearest to c·E*, where E* is the
//!   highest irradiance every point of the calibrated area can reach.
//! * [`exposure`]: the layer exposure rule (working curve for absolute calibrations).

pub mod calib;
pub mod compensate;
pub mod exposure;
pub mod field;
pub mod plots;
pub mod report;
pub mod response;
#[cfg(test)]
mod sweep;
#[cfg(test)]
mod synthetic;

pub use compensate::Compensator;
pub use field::{FieldModel, Poly};
pub use response::{GrayVariable, Interpolation, Response};

use crate::error::{Error, Result};
use crate::profile::Profile;
use crate::units::Positive;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Irradiance units of a calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Units {
    /// Relative units: only ratios are meaningful (the published seeds/000 fit). The
    /// profile's fixed exposure is the exposure at the target irradiance E*.
    #[serde(rename = "relative")]
    Relative,
    /// Absolute irradiance in mW/cm²: exposure follows the resin's working curve.
    #[serde(rename = "mW/cm2")]
    MwCm2,
}

impl Units {
    /// The unit as written in files and reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Units::Relative => "relative",
            Units::MwCm2 => "mW/cm2",
        }
    }
}

/// A projector's light calibration: E(x, y, g) = P(x, y)·S(g).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Where the calibration comes from (free text).
    pub source: String,
    /// Irradiance units of P·S.
    pub units: Units,
    /// Edge of a compensation zone (zone mode), mm; zones start at the field's bottom-left
    /// corner.
    pub zone_mm: Positive,
    /// The field factor P(x, y).
    pub field: FieldModel,
    /// The gray response S(g).
    pub response: Response,
    /// Fit statistics written by `dmdsl calibrate` (informational).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitSummary>,
}

/// Statistics of a fitted calibration, as written by `dmdsl calibrate`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitSummary {
    /// Measurement file name.
    pub measurements: String,
    /// Form of P (polynomial or exponential of a polynomial).
    pub form: field::Form,
    /// Degree of the polynomial in P.
    pub degree: u64,
    /// Cross-validated RMS relative error (held-out zones) of the polynomial candidates:
    /// [degree, %] pairs (empty when the degree was forced).
    pub cv_rms_pct: Vec<(u64, f64)>,
    /// The same for the exponential candidates.
    pub cv_exp_rms_pct: Vec<(u64, f64)>,
    /// The same for the inverse-square candidates (absent in files from before them).
    #[serde(default)]
    pub cv_inv_rms_pct: Vec<(u64, f64)>,
    /// Measured gray levels [lowest, highest] of the valid range. When every measured
    /// level is in it, S is also interpolated between the lowest and pixel value 0
    /// (mirror off, S = 0).
    pub measured_gray: [u8; 2],
    /// Readings used.
    pub readings: u64,
    /// Distinct zone positions.
    pub zones: u64,
    /// Distinct gray levels measured.
    pub gray_levels: u64,
    /// Gray levels measured but outside the valid range (S stops falling there).
    pub excluded_grays: Vec<u8>,
    /// RMS of the relative residuals (fit − measured)/measured over the valid range, %.
    pub residual_rms_pct: f64,
    /// Largest |relative residual|, %.
    pub residual_max_pct: f64,
    /// Line of the measurement file with the largest residual.
    pub residual_max_line: u64,
}

/// Compensation mode of a job.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// No compensation: a pixel's value is its coverage.
    Off,
    /// One gray per zone (seeds/000's method).
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
    /// Zone mode: a zone whose nearest gray misses the target by more than
    /// [`compensate::MIX_TOLERANCE`] mixes the two grays around its target (ordered 8×8
    /// pattern); every other zone keeps one gray. Pixel mode: no dithering.
    #[default]
    Auto,
    /// Zone mode: every zone mixes the two grays around its target. Pixel mode:
    /// Floyd–Steinberg error diffusion (serpentine, lit pixels only).
    On,
    /// One gray per zone / per pixel, nearest in irradiance (seeds/000's method).
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

impl Calibration {
    /// Checks the model (P positive on the calibrated area, S positive and strictly
    /// increasing on its valid gray range).
    pub fn validate(&self) -> std::result::Result<(), String> {
        self.field.validate()?;
        self.response.validate()
    }

    /// Parses and validates calibration TOML; `path` names the file in errors.
    pub fn from_toml(src: &str, path: &Path) -> Result<Calibration> {
        let c: Calibration = toml::from_str(src).map_err(|e| {
            Error::input(
                path,
                e.to_string()
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" "),
            )
        })?;
        c.validate().map_err(|m| Error::input(path, m))?;
        Ok(c)
    }

    /// Reads a calibration file (as written by `dmdsl calibrate`).
    pub fn read(path: &Path) -> Result<Calibration> {
        let src = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Calibration::from_toml(&src, path)
    }

    /// The calibration as TOML (response points one per line).
    pub fn to_toml(&self) -> String {
        let t = toml::to_string(self).expect("calibration serializes");
        let mut out = String::with_capacity(t.len() + 256);
        for line in t.lines() {
            match line
                .strip_prefix("points = [[")
                .and_then(|l| l.strip_suffix("]]"))
            {
                Some(inner) => {
                    out.push_str("points = [\n");
                    for p in inner.split("], [") {
                        out.push_str(&format!("    [{p}],\n"));
                    }
                    out.push_str("]\n");
                }
                None => {
                    out.push_str(line);
                    out.push('\n');
                }
            }
        }
        out
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
        profile.projector[k].calibration = Some(Calibration::read(Path::new(file))?);
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
    pub exposure: exposure::Resolved,
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
    let mode = match (opts.mode, cal) {
        (Some(m), _) => m,
        (None, Some(_)) => Mode::Zone,
        (None, None) => Mode::Off,
    };
    if opts.dither == Dither::On && mode == Mode::Off {
        return Err(Error::Usage(
            "--dither on needs compensation (zone or pixel)".to_string(),
        ));
    }
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

impl JobOptics {
    /// After all layers: writes the gray map into the bundle and returns the manifest
    /// record and the warnings for the job.
    pub fn finish(
        &self,
        writer: &crate::bundle::BundleWriter,
        profile: &Profile,
        png: impl Fn(&crate::raster::Mask) -> Vec<u8>,
    ) -> Result<(crate::bundle::Optics, Vec<String>)> {
        let gray_map = self.write_gray_map(writer, profile, png)?;
        self.finish_with(gray_map)
    }

    /// Writes the gray map into the bundle (it does not depend on the layers: the slicer
    /// writes it while the masks are made) and returns its file and SHA-256.
    pub fn write_gray_map(
        &self,
        writer: &crate::bundle::BundleWriter,
        profile: &Profile,
        png: impl Fn(&crate::raster::Mask) -> Vec<u8>,
    ) -> Result<(String, String)> {
        let p = &profile.projector[self.projector];
        writer.create_dir("optics")?;
        let bytes = self.compensator.gray_map_png(p, png);
        let file = format!("optics/{}-gray-map.png", p.name);
        writer.write_file(&file, &bytes)?;
        Ok((file, crate::bundle::sha256_hex(&bytes)))
    }

    /// After all layers, with the gray map written ([`write_gray_map`](Self::write_gray_map)):
    /// the manifest record and the warnings for the job.
    pub fn finish_with(
        &self,
        (file, gray_map_sha256): (String, String),
    ) -> Result<(crate::bundle::Optics, Vec<String>)> {
        let c = &self.compensator;
        let pr = &c.prediction;
        let (zc, zr) = pr.zone_grid;
        let zone_grays = if c.mode() == Mode::Zone {
            (0..zr)
                .map(|r| pr.zone_gray[r * zc..(r + 1) * zc].to_vec())
                .collect()
        } else {
            Vec::new()
        };
        let mut warnings = self.exposure.warnings.clone();
        let [x0, y0, x1, y1] = self.calibration.field.area_mm;
        let layers_outside = c.layers_outside();
        if layers_outside > 0 {
            warnings.push(format!(
                "{layers_outside} layers reach outside the calibrated area x {x0}..{x1}, y {y0}..{y1} mm: compensation there extrapolates the calibration (docs/CALIBRATION.md)"
            ));
        }
        if pr.unreachable > 0 && layers_outside > 0 {
            warnings.push(format!(
                "{} {} outside the calibrated area cannot reach the target irradiance even fully on",
                pr.unreachable,
                if c.mode() == Mode::Zone { "zones" } else { "pixels" }
            ));
        }
        let record = crate::bundle::Optics {
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
        Ok((record, warnings))
    }
}
