//! `dmdsl calibrate`: fit the light calibration E = P(x, y)·S(g) to measurements.

use crate::profile::{self, Profile};
use clap::Args;
use std::path::PathBuf;

pub(crate) const CALIBRATE_EXIT_HELP: &str = "Exit codes:
  0    the calibration (and its plots) were written
  1    written, but a warning was denied (--deny-warnings, -W CODE=error)
  2    usage or input error (unreadable or malformed measurements, a set-up the model
       cannot fit, bad profile); nothing was written";

#[derive(Args)]
pub(crate) struct CalibrateArgs {
    /// Measurements: CSV with header x_mm,y_mm,gray,irradiance_mw_cm2 (zone centre from the
    /// field's bottom-left corner, pixel value shown there (255 = fully on), irradiance).
    #[arg(required = true)]
    input: Option<PathBuf>,
    /// Calibration file to write (TOML); PNG plots are written next to it.
    #[arg(short, long, required = true)]
    output: Option<PathBuf>,
    #[command(subcommand)]
    kind: Option<Kind>,
    /// The irradiance column is in arbitrary units (exposure then comes from the profile).
    #[arg(long)]
    relative: bool,
    /// Compensation zone edge, mm.
    #[arg(long, value_name = "MM", default_value_t = 5.0)]
    zone_mm: f64,
    /// How far P is extrapolated beyond the measured area before it is held constant, mm.
    #[arg(long, value_name = "MM", default_value_t = 5.0)]
    extrapolate_mm: f64,
    /// Degree of the polynomial P(x, y), 3..6 [default: 3 (the paper's cubic) unless
    /// cross-validation on held-out zones shows a higher degree predicts better].
    #[arg(long, value_name = "N")]
    degree: Option<usize>,
    /// Machine profile whose field the predictions are made for.
    #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
    profile: String,
    /// Do not write PNG plots.
    #[arg(long)]
    no_plots: bool,
    /// Print a machine-readable report on stdout.
    #[arg(long)]
    pub(crate) json: bool,
    #[command(flatten)]
    warnings: super::WarningArgs,
}

/// What else is calibrated (instead of the light).
#[derive(clap::Subcommand)]
enum Kind {
    /// Fit Jacobs' working curve Cd = Dp·ln(E/Ec) to the filled-in sheet of `dmdsl testjob
    /// working-curve`; writes Dp and Ec (TOML, for `slice --resin`) and the curve's plot.
    Resin {
        /// The sheet (window, exposure_s, dose_mj_cm2, cured_mm: 0 or empty where nothing cured).
        input: PathBuf,
        /// Resin calibration file to write (TOML); the plot goes beside it as .png.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Report the accuracy of the filled-in sheet of `dmdsl testjob accuracy` (error mean
    /// and deviation, share within ±0.06 mm and the tolerance, per axis and feature kind)
    /// and fit measured = scale·nominal ± offset per axis; with -o, write the correction
    /// that undoes the fits (TOML, for `slice --accuracy`) and the plot of the errors.
    Accuracy(super::testjob::AccuracyArgs),
    /// Fit the point-spread function's σ (psf_sigma_px, per projector) to the filled-in
    /// sheet of `dmdsl testjob psf` under the cure model; writes σ (TOML, for `slice
    /// --psf`) and the plot of printed against drawn width.
    Psf {
        /// The sheet (feature, kind, projector, drawn_px, layers, printed_mm; empty where
        /// not measured).
        input: PathBuf,
        /// Blur calibration file to write (TOML); the plot goes beside it as .png.
        #[arg(short, long)]
        output: PathBuf,
        /// The profile the job was printed with (its resin, layer and exposure make the
        /// cure model).
        #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
        profile: String,
        /// Resin calibration file from `dmdsl calibrate resin`, replacing the profile's Dp
        /// (and Ec).
        #[arg(long, value_name = "FILE")]
        resin: Option<PathBuf>,
    },
}

/// Runs `dmdsl calibrate`.
pub(crate) fn calibrate(a: CalibrateArgs, quiet: bool) -> anyhow::Result<u8> {
    match a.kind {
        Some(Kind::Resin { input, output }) => {
            return super::testjob::calibrate_resin(input, output, quiet)
        }
        Some(Kind::Accuracy(a)) => return super::testjob::calibrate_accuracy(a, quiet),
        Some(Kind::Psf {
            input,
            output,
            profile,
            resin,
        }) => return super::psf::calibrate_psf(&input, &output, &profile, resin.as_deref(), quiet),
        None => {}
    }
    let (input, output) = (a.input.expect("required"), a.output.expect("required"));
    use crate::optics::report::{self, CalibrateOptions};
    use crate::optics::{calib::FitOptions, Units};
    let policy = a.warnings.policy(&[])?;
    let field = Profile::resolve(&a.profile)?.field();
    // A size that slice would refuse in the calibration file is refused before the fit.
    for (flag, key, v) in [
        ("--zone-mm", "zone_mm", a.zone_mm),
        ("--extrapolate-mm", "extrapolate_mm", a.extrapolate_mm),
    ] {
        profile::check_unit(flag, key, v).map_err(crate::error::Error::Usage)?;
    }
    let fit = FitOptions {
        units: if a.relative {
            Units::Relative
        } else {
            Units::MwCm2
        },
        zone_mm: a.zone_mm,
        extrapolate_mm: a.extrapolate_mm,
        field_mm: (field.width_mm(), field.height_mm()),
        degree: a.degree,
    };
    let mut r = report::calibrate(&CalibrateOptions {
        input,
        output,
        fit,
        field,
        plots: !a.no_plots,
    })?;
    r.warnings = policy.apply(&r.warnings);
    let exit = u8::from(crate::warning::any_error(&r.warnings));
    if a.json {
        #[derive(serde::Serialize)]
        struct Out<'a> {
            ok: bool,
            #[serde(flatten)]
            report: &'a crate::optics::report::CalibrateReport,
        }
        super::print_json(&Out {
            ok: exit == 0,
            report: &r,
        })?;
        return Ok(exit);
    }
    if quiet {
        return Ok(exit);
    }
    super::print_warnings(&r.warnings, "");
    let u = if a.relative { "" } else { " mW/cm²" };
    println!(
        "{}: {} zones x {} gray levels ({} readings); residual RMS {:.2} %, max {:.2} % (line {})",
        r.calibration.display(),
        r.zones,
        r.gray_levels,
        r.readings,
        r.residual_rms_pct,
        r.residual_max_pct,
        r.residual_max_line
    );
    let excluded = if r.excluded_grays.is_empty() {
        String::new()
    } else {
        format!(
            "; S stops falling below it, excluded levels {:?}",
            r.excluded_grays
        )
    };
    let interp = if r.valid_gray[0] < r.measured_gray[0] {
        format!(
            ", measured {}..{} (below: interpolated to S(0) = 0)",
            r.measured_gray[0], r.measured_gray[1]
        )
    } else {
        String::new()
    };
    println!(
        "valid gray {}..{}{interp}{excluded}",
        r.valid_gray[0], r.valid_gray[1]
    );
    for (name, m) in [("zone", &r.zone), ("pixel", &r.pixel)] {
        println!(
            "{name} mode: target {:.4}{u} = {:.1} % of the mean; spread zone means {:.1} % -> {:.2} %, pixels {:.1} % -> {:.2} %",
            m.target_irradiance,
            m.throughput * 100.0,
            m.spreads.before_zone_pct,
            m.spreads.after_zone_pct,
            m.spreads.before_pixel_pct,
            m.spreads.after_pixel_pct
        );
    }
    for p in &r.plots {
        println!("plot: {}", p.display());
    }
    Ok(exit)
}
