//! The light calibration a projector carries: E(x, y, g) = P(x, y)·S(g) (Xu et al. 2010,
//! eq. 1–3; docs/CALIBRATION.md).
//!
//! * [`field::FieldModel`]: the field factor P, a bivariate polynomial (or its exponential,
//!   or its inverse square) over the build plane;
//! * [`response::Response`]: the gray response S, monotone on its valid gray range;
//! * [`Calibration`]: both, with their units and zone size, as stored in a profile's
//!   `[projector.calibration]` or a file written by `dmdsl calibrate`.
//!
//! The optics stage fits (`optics::calib`) and applies (`optics::compensate`) them.

pub mod field;
pub mod response;

use crate::error::{Error, Result};
use crate::units::Positive;
use field::FieldModel;
use response::Response;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Irradiance units of a calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Units {
    /// Relative units: only ratios are meaningful (the published fit of Xu et al. 2010). The
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

impl Calibration {
    /// Checks the model (P positive on the calibrated area, S positive and strictly
    /// increasing on its valid gray range).
    pub fn validate(&self) -> std::result::Result<(), String> {
        self.field.validate()?;
        self.response.validate()
    }

    /// Parses and validates calibration TOML; `path` names the file in errors.
    pub fn from_toml(src: &str, path: &Path) -> Result<Calibration> {
        let c: Calibration =
            toml::from_str(src).map_err(|e| Error::input(path, super::one_line(&e.to_string())))?;
        c.validate().map_err(|m| Error::input(path, m))?;
        Ok(c)
    }

    /// Reads a calibration file (as written by `dmdsl calibrate`).
    pub fn read(path: &Path) -> Result<Calibration> {
        let src = crate::input::read_text(path, "calibration file")?;
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
