//! The `dmdsl calibrate` command: fit, predict, write the calibration file and its plots.

use super::calib::{self, FitOptions, FitResult};
use super::{Calibration, Compensator, Dither, Mode};
use crate::bundle::Spreads;
use crate::error::{Error, Result};
use crate::profile::Field;
use crate::text::fixed;
use crate::warning::Warning;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Options of [`calibrate`].
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// Measurement CSV.
    pub input: PathBuf,
    /// Calibration TOML to write; plots go next to it.
    pub output: PathBuf,
    /// The fit's options.
    pub fit: FitOptions,
    /// Field the predictions are made for (the fit's `field_mm`).
    pub field: Field,
    /// Write PNG plots.
    pub plots: bool,
}

/// What one compensation mode achieves under the fitted model.
#[derive(Debug, Clone, Serialize)]
pub struct ModeReport {
    /// Target irradiance E*.
    pub target_irradiance: f64,
    /// Mean irradiance of the calibrated area fully on.
    pub mean_irradiance: f64,
    /// E* / mean.
    pub throughput: f64,
    /// Predicted spreads, %.
    pub spreads: Spreads,
    /// Zones (zone mode) or pixels (pixel mode) that cannot reach E*.
    pub unreachable: u64,
}

/// Result of `dmdsl calibrate`.
#[derive(Debug, Clone, Serialize)]
pub struct CalibrateReport {
    /// The calibration file written.
    pub calibration: PathBuf,
    /// PNG plots written.
    pub plots: Vec<PathBuf>,
    /// Irradiance units.
    pub units: String,
    /// Readings in the file.
    pub readings: u64,
    /// Readings used (valid gray range).
    pub readings_used: u64,
    /// Distinct zone positions.
    pub zones: u64,
    /// Distinct gray levels.
    pub gray_levels: u64,
    /// Valid gray range [lo, hi].
    pub valid_gray: [u8; 2],
    /// Measured, monotone gray range [lo, hi] (below it S is interpolated to S(0) = 0 when
    /// `valid_gray` starts at 0).
    pub measured_gray: [u8; 2],
    /// Measured levels outside the valid range.
    pub excluded_grays: Vec<u8>,
    /// Relative residual RMS, %.
    pub residual_rms_pct: f64,
    /// Largest relative residual, %.
    pub residual_max_pct: f64,
    /// Its line in the measurement file.
    pub residual_max_line: u64,
    /// Condition number of the scaled design matrix of P.
    pub condition: f64,
    /// Calibrated area [x0, y0, x1, y1], mm.
    pub calibrated_area_mm: [f64; 4],
    /// Zones of the field outside the calibrated area.
    pub zones_outside: u64,
    /// Zone-mode prediction.
    pub zone: ModeReport,
    /// Pixel-mode prediction.
    pub pixel: ModeReport,
    /// Warnings.
    pub warnings: Vec<Warning>,
}

/// A mode's prediction, its figures to 6 significant digits (`crate::round::derived`).
fn mode_report(c: &Compensator) -> ModeReport {
    use crate::round::derived;
    let p = &c.prediction;
    let s = p.spreads;
    ModeReport {
        target_irradiance: derived(p.target),
        mean_irradiance: derived(p.mean),
        throughput: derived(p.target / p.mean),
        spreads: Spreads {
            before_zone_pct: derived(s.before_zone_pct),
            before_pixel_pct: derived(s.before_pixel_pct),
            after_zone_pct: derived(s.after_zone_pct),
            after_pixel_pct: derived(s.after_pixel_pct),
        },
        unreachable: p.unreachable,
    }
}

fn header(cal: &Calibration, input: &Path) -> String {
    let f = cal.fit.as_ref();
    let [lo, hi] = cal.response.valid_gray();
    let [mlo, mhi] = f.map_or([lo, hi], |f| f.measured_gray);
    let form = match cal.field.form {
        super::field::Form::Polynomial => "poly(u, v)",
        super::field::Form::Exponential => "exp(poly(u, v))",
        super::field::Form::InverseSquare => "1 / poly(u, v)²",
    };
    let below = if lo < mlo {
        format!(
            "\n#      Below {mlo} (the lowest measured gray) S is interpolated down to S(0) = 0\n#      (mirror off): an assumption, not a measurement."
        )
    } else {
        String::new()
    };
    format!(
        "# dmdsl light calibration, fitted by `dmdsl calibrate {}`.
# Use it with `dmdsl slice --calibration FILE`, or paste it into a profile as the
# [projector.calibration] section of the projector it was measured on (prefix the
# table names below with `projector.calibration.`).
#
# Model of Xu et al. 2010, \"Novel stereolithography system employing digital micro-mirror
# device\", Chinese J. Lasers 37(7): irradiance E(x, y, g) = P(x, y) * S(g), units: {}.
#  P = scale * {form}, u = (x_mm - origin_mm[0]) / length_unit_mm,
#      v = (y_mm - origin_mm[1]) / length_unit_mm; x, y in mm from the field's bottom-left
#      corner; coefficient xxy multiplies u^2 v. P is the irradiance with mirrors at the
#      brightest measured gray ({mhi}). area_mm is the measured area; outside
#      polynomial_area_mm (if given) the polynomial continues linearly; P is extrapolated
#      extrapolate_mm beyond area_mm and held constant further out.
#  S = relative response, S = 1 at {mhi}: cubic through response.points [pixel value, S]
#      (interpolation = spline or pchip); measured and monotone on {mlo}..{mhi}.{below}
# Fit: {} readings, residual RMS {:.2} %, max {:.2} % (line {}).
",
        input.display(),
        cal.units.as_str(),
        f.map_or(0, |f| f.readings),
        f.map_or(0.0, |f| f.residual_rms_pct),
        f.map_or(0.0, |f| f.residual_max_pct),
        f.map_or(0, |f| f.residual_max_line),
    )
}

/// Writes `files` (path, bytes) all-or-nothing: each goes to a temporary sibling first and
/// is renamed into place only when every file was written. A symbolic link at a path is
/// refused ([`crate::output::refuse_special`]); an error names the file, not its temporary
/// sibling.
pub(crate) fn write_all(files: &[(PathBuf, Vec<u8>)]) -> Result<()> {
    let tmp: Vec<PathBuf> = files
        .iter()
        .map(|(p, _)| {
            crate::output::refuse_special(p)?;
            crate::output::temp_sibling(p)
                .ok_or_else(|| Error::Usage(format!("{}: not a file name", p.display())))
        })
        .collect::<Result<_>>()?;
    // Removes the temporary files left (those not written yet or renamed already are gone).
    let fail = |path: &Path, e| {
        tmp.iter().for_each(|t| drop(std::fs::remove_file(t)));
        Error::io(path, e)
    };
    for ((p, bytes), t) in files.iter().zip(&tmp) {
        std::fs::write(t, bytes).map_err(|e| fail(p, e))?;
    }
    for ((p, _), t) in files.iter().zip(&tmp) {
        std::fs::rename(t, p).map_err(|e| fail(p, e))?;
    }
    Ok(())
}

/// Runs the fit and writes the calibration (and plots). See the module docs.
pub fn calibrate(opts: &CalibrateOptions) -> Result<CalibrateReport> {
    let out = &opts.output;
    if out.is_dir() {
        return Err(Error::input(
            out,
            "is a directory; give the calibration file to write",
        ));
    }
    if let Some(msg) = crate::output::parent_problem(out) {
        return Err(Error::input(out, msg));
    }
    let readings = calib::read_csv(&opts.input)?;
    let fit: FitResult = calib::fit(&readings, &opts.input, &opts.fit)?;
    let cal = &fit.calibration;
    let wrap = |m: String| Error::input(&opts.input, m);
    let zone = Compensator::new(cal, &opts.field, Mode::Zone, Dither::Auto).map_err(wrap)?;
    let pixel = Compensator::new(cal, &opts.field, Mode::Pixel, Dither::Auto).map_err(wrap)?;
    let mut warnings = fit.warnings.clone();
    let f = cal.fit.clone().expect("fit writes a summary");
    let zp = &zone.prediction;
    let lowest = (0..zp.zone_gray.len())
        .filter(|&z| zp.zone_inside[z])
        .map(|z| zp.zone_gray[z])
        .min()
        .unwrap_or(255);
    if lowest < f.measured_gray[0] {
        warnings.push(
            Warning::new(
                "calibrate.low-grays-unmeasured",
                format!(
                    "zone compensation needs grays down to {lowest}, below the lowest measured gray {}: S there is interpolated towards S(0) = 0",
                    f.measured_gray[0]
                ),
            )
            .with("lowest_gray", lowest)
            .with("lowest_measured_gray", f.measured_gray[0]),
        );
    }
    for (name, c) in [("zone", &zone), ("pixel", &pixel)] {
        let p = &c.prediction;
        if p.spreads.after_zone_pct > 2.0 || p.spreads.after_pixel_pct > 5.0 && name == "pixel" {
            warnings.push(
                Warning::new(
                    "calibrate.spread-remains",
                    format!(
                        "{name} mode leaves a predicted spread of {} % (zone means) / {} % (pixels): the gray range cannot flatten this field",
                        fixed(p.spreads.after_zone_pct, 2), fixed(p.spreads.after_pixel_pct, 2)
                    ),
                )
                .with("mode", name)
                .with("after_zone_pct", p.spreads.after_zone_pct)
                .with("after_pixel_pct", p.spreads.after_pixel_pct),
            );
        }
    }

    let mut files = vec![(
        out.clone(),
        format!("{}\n{}", header(cal, &opts.input), cal.to_toml()).into_bytes(),
    )];
    if opts.plots {
        files.extend(super::plots::calibration_plots(out, &fit, &zone, &pixel));
    }
    write_all(&files)?;
    Ok(CalibrateReport {
        calibration: out.clone(),
        plots: files[1..].iter().map(|(p, _)| p.clone()).collect(),
        units: cal.units.as_str().into(),
        readings: readings.len() as u64,
        readings_used: f.readings,
        zones: f.zones,
        gray_levels: f.gray_levels,
        valid_gray: cal.response.valid_gray(),
        excluded_grays: f.excluded_grays,
        residual_rms_pct: crate::round::derived(f.residual_rms_pct),
        residual_max_pct: crate::round::derived(f.residual_max_pct),
        residual_max_line: f.residual_max_line,
        condition: crate::round::derived(fit.condition),
        calibrated_area_mm: cal.field.area_mm.map(crate::round::plane_mm),
        zones_outside: zone.prediction.zones_outside,
        zone: mode_report(&zone),
        pixel: mode_report(&pixel),
        measured_gray: f.measured_gray,
        warnings,
    })
}
