//! `dmdsl testjob working-curve` and `dmdsl calibrate resin`: the working curve's test job
//! with its measurement sheet, and the fit of the filled-in sheet (docs/CALIBRATION.md).

use crate::error::Error;
use crate::profile::{self, Profile};
use clap::{Args, Subcommand};
use std::path::PathBuf;

/// After `dmdsl testjob --help`.
pub(crate) const TESTJOB_HELP: &str = "Examples:
  dmdsl testjob working-curve -o wc.dmdjob               # 12 windows; wc.csv beside the job
  dmdsl calibrate resin wc.csv -o resin.toml             # after filling in cured_mm
  dmdsl testjob accuracy -o acc.dmdjob -p bottom-up      # dimensions; acc.csv beside it
  dmdsl testjob psf -o psf.dmdjob                        # the blur; psf.csv beside it

Exit codes:
  0    the job and its sheet were written
  2    usage or input error (bad range, profile or output); nothing was written";

#[derive(Subcommand)]
pub(crate) enum TestjobCmd {
    /// Jacobs' windowpane: windows one layer thick, each at its own dose (a pixel value
    /// through the calibrated response S(g)), and the sheet <job stem>.csv to fill in.
    WorkingCurve(WorkingCurveArgs),
    /// A dimensional test part: pins, walls, holes and slots in X and Y, steps in Z, 0.2 to
    /// 5 mm, in both halves of the field, sliced with the profile's settings; the sheet
    /// <job stem>.csv lists each measurement to make.
    Accuracy {
        /// Job to write (its form from the name, as `slice -o`); the sheet goes beside it.
        #[arg(short, long)]
        output: PathBuf,
        /// Machine profile.
        #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
        profile: String,
        /// Correction file from `dmdsl calibrate accuracy`, replacing the profile's
        /// [accuracy] (to check it, or to refine it: give it to `calibrate accuracy` too).
        #[arg(long, value_name = "FILE")]
        accuracy: Option<PathBuf>,
    },
    /// The blur: lines and gaps 1 to 8 px wide, along x and along y, at the centre and
    /// the four corners of each projector's (calibrated) area, a few layers thick on base
    /// plates, drawn exactly (no cure correction); the sheet <job stem>.csv lists each
    /// width to measure.
    Psf {
        /// Job to write (its form from the name, as `slice -o`); the sheet goes beside it.
        #[arg(short, long)]
        output: PathBuf,
        /// Machine profile.
        #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
        profile: String,
    },
}

#[derive(Args)]
pub(crate) struct WorkingCurveArgs {
    /// Job to write (its form from the name, as `slice -o`); the sheet goes beside it.
    #[arg(short, long)]
    output: PathBuf,
    /// Machine profile.
    #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
    profile: String,
    /// Number of windows (2 to 64).
    #[arg(long, default_value_t = 12)]
    windows: usize,
    /// Exposures LO..HI in s at the brightest gray, a geometric series [default: half to
    /// 8 times the profile's layer exposure].
    #[arg(long, visible_alias = "dose", value_name = "LO..HI")]
    exposure: Option<String>,
    /// Light calibration file from `dmdsl calibrate`, replacing the profile's: its S(g)
    /// sets the gray levels and, when absolute, the doses in mJ/cm².
    #[arg(long, value_name = "FILE")]
    calibration: Option<String>,
}

/// Runs `dmdsl testjob ...`.
pub(crate) fn testjob(cmd: TestjobCmd, quiet: bool) -> anyhow::Result<u8> {
    let a = match cmd {
        TestjobCmd::WorkingCurve(a) => a,
        TestjobCmd::Accuracy {
            output,
            profile,
            accuracy,
        } => return accuracy_job(&output, (&profile, accuracy.as_deref()), quiet),
        TestjobCmd::Psf { output, profile } => {
            return super::psf::psf_job(&output, &profile, quiet)
        }
    };
    let mut p = Profile::resolve(&a.profile)?;
    crate::optics::apply_calibration_args(&mut p, a.calibration.as_slice())?;
    let t = p.exposure.layer_s.get();
    let range = match &a.exposure {
        None => [0.5 * t, 8.0 * t],
        Some(s) => match s.split_once("..").map(|(l, h)| (l.parse(), h.parse())) {
            Some((Ok(l), Ok(h))) => [l, h],
            _ => {
                return Err(
                    Error::Usage(format!("--exposure {s}: give LO..HI in s, e.g. 2..30")).into(),
                )
            }
        },
    };
    let wc = crate::calib::working_curve(&p, a.windows, range).map_err(Error::Usage)?;
    let layer_s = crate::units::Positive::new(wc.layer_s).expect("checked positive");
    (p.exposure.layer_s, p.exposure.bottom_s) = (layer_s, layer_s);
    let mut o = crate::job::SliceOptions::new("working-curve.stl", &a.output, p);
    o.input_bytes = Some(&wc.stl);
    o.placement = crate::job::PlacementMode::Keep;
    o.binary = Some(false);
    o.optics.mode = Some(crate::optics::Mode::Off);
    o.cure.correction = Some(crate::cure::Correction::Off);
    o.dose = Some(wc.dose.clone());
    let mut sheet = String::from("window,x_mm,y_mm,gray,exposure_s,dose_mj_cm2,cured_mm\n");
    for (i, w) in wc.windows.iter().enumerate() {
        let dose = w.dose_mj_cm2.map_or(String::new(), |d| format!("{d:.4}"));
        let [x, y] = w.centre_mm;
        sheet += &format!(
            "{},{x:.3},{y:.3},{},{:.4},{dose},\n",
            i + 1,
            w.gray,
            w.exposure_s
        );
    }
    let (s, sheet_path) = slice_with_sheet(&o, &sheet)?;
    if !quiet {
        super::print_warnings(&s.warnings, "");
        println!(
            "{}: {} windows, {:.3}..{:.3} s at the brightest gray, layer exposure {:.3} s",
            s.bundle.display(),
            wc.windows.len(),
            range[0],
            range[1],
            wc.layer_s
        );
        println!(
            "sheet: {} (fill in cured_mm, then `dmdsl calibrate resin`)",
            sheet_path.display()
        );
    }
    Ok(0)
}

/// Runs `dmdsl calibrate resin SHEET -o FILE`.
pub(crate) fn calibrate_resin(input: PathBuf, output: PathBuf, quiet: bool) -> anyhow::Result<u8> {
    let sheet =
        crate::calib::Sheet::read(&input, &["window", "exposure_s", "dose_mj_cm2", "cured_mm"])?;
    let f = crate::calib::fit_resin(&sheet)?;
    let (crit, unit) = match f.ec_mj_cm2 {
        Some(ec) => (
            format!("Ec = {ec:.4} ± {:.4} mJ/cm²", f.critical_se),
            "mJ/cm²",
        ),
        None => (
            format!(
                "critical exposure {:.4} ± {:.4} s at the brightest gray",
                f.critical_exposure_s.unwrap_or(0.0),
                f.critical_se
            ),
            "s",
        ),
    };
    let head = format!("# dmdsl resin calibration, fitted by `dmdsl calibrate resin {}`: Jacobs' working\n# curve Cd = Dp*ln(E/Ec), least squares in ln E. Use it with `dmdsl slice --resin FILE`.\n", input.display());
    let png = write_fit(
        &output,
        head + &toml::to_string(&f).expect("fit serializes"),
        &f.chart(),
    )?;
    if !quiet {
        println!(
            "{}: {} cured windows; Dp = {:.4} ± {:.4} mm, {crit}",
            output.display(),
            f.residuals.len(),
            f.dp_mm,
            f.dp_se_mm
        );
        for r in &f.residuals {
            println!(
                "  line {}: E {:.4} {unit}, cured {:.4} mm, residual {} mm",
                r[0],
                r[1],
                r[2],
                crate::text::signed(r[3], 4)
            );
        }
        println!(
            "residual RMS {:.4} mm\nplot: {}",
            f.residual_rms_mm,
            png.display()
        );
    }
    Ok(0)
}

/// Writes the accuracy part's job and its sheet.
fn accuracy_job(
    output: &std::path::Path,
    (profile, accuracy): (&str, Option<&std::path::Path>),
    quiet: bool,
) -> anyhow::Result<u8> {
    let mut p = Profile::resolve(profile)?;
    if let Some(f) = accuracy {
        crate::calib::accuracy::AccuracyFit::apply_file(f, &mut p)?;
    }
    // The part is drawn scaled by the correction about the field's origin: so are the
    // features' centres in the sheet.
    let [fx, fy, _] = p.accuracy.scale;
    let (feats, stl) = crate::calib::accuracy_part(&p).map_err(Error::Usage)?;
    let mut o = crate::job::SliceOptions::new("accuracy.stl", output, p);
    o.input_bytes = Some(&stl);
    o.placement = crate::job::PlacementMode::Keep;
    let mut sheet = String::from("feature,axis,nominal_mm,measured_mm,x_mm,y_mm\n");
    for f in &feats {
        let [x, y] = [f.centre_mm[0] * fx, f.centre_mm[1] * fy];
        sheet += &format!("{},{},{},,{x:.3},{y:.3}\n", f.kind, f.axis, f.nominal_mm);
    }
    let (s, sheet_path) = slice_with_sheet(&o, &sheet)?;
    if !quiet {
        super::print_warnings(&s.warnings, "");
        println!(
            "{}: {} layers; sheet {} ({} measurements)",
            s.bundle.display(),
            s.layers,
            sheet_path.display(),
            feats.len()
        );
    }
    Ok(0)
}

/// `dmdsl calibrate accuracy`'s options.
#[derive(Args)]
pub(crate) struct AccuracyArgs {
    /// The sheet (feature, axis, nominal_mm, measured_mm; empty where not measured).
    input: PathBuf,
    /// Correction file to write (TOML); the plot goes beside it as .png.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Tolerance, mm.
    #[arg(long, value_name = "MM", default_value_t = 0.1)]
    tolerance: f64,
    /// The profile the part was printed with (its [accuracy] correction is composed
    /// with the fit).
    #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
    profile: String,
    /// The correction file the part was printed with (`testjob accuracy --accuracy`),
    /// replacing the profile's.
    #[arg(long, value_name = "FILE")]
    accuracy: Option<PathBuf>,
}

/// Runs `dmdsl calibrate accuracy SHEET`.
pub(crate) fn calibrate_accuracy(a: AccuracyArgs, quiet: bool) -> anyhow::Result<u8> {
    use crate::calib::accuracy::AccuracyFit;
    let tolerance = a.tolerance;
    if !(tolerance > 0.0 && tolerance.is_finite()) {
        return Err(Error::Usage(format!("--tolerance {tolerance}: give a size in mm > 0")).into());
    }
    let mut printed = Profile::resolve(&a.profile)?;
    if let Some(f) = &a.accuracy {
        AccuracyFit::apply_file(f, &mut printed)?;
    }
    let sheet =
        crate::calib::Sheet::read(&a.input, &["feature", "axis", "nominal_mm", "measured_mm"])?;
    let report = crate::calib::accuracy(&sheet, tolerance)?;
    let fit = AccuracyFit::new(&sheet, report.fits.clone(), &printed.accuracy);
    let correction = fit.correction();
    if let Some(out) = &a.output {
        correction
            .validate()
            .map_err(|m| Error::input(&a.input, format!("the fitted correction: {m}")))?;
        let toml = format!(
            "# dmdsl calibrate accuracy: the correction of the dimensions fitted to {}\n# (slice --accuracy {}); scale and xy_offset_mm are the profile's [accuracy] keys.\n{}",
            fit.sheet,
            out.display(),
            toml::to_string(&fit).expect("a correction serializes")
        );
        write_fit(out, toml, &fit.chart(&report.rows))?;
    }
    if quiet {
        return Ok(0);
    }
    println!(
        "{:<8} {:>4} {:>10} {:>9} {:>10} {:>10}",
        "group",
        "n",
        "mean (mm)",
        "sd (mm)",
        "±0.06 mm",
        format!("±{tolerance} mm")
    );
    for g in &report.stats {
        println!(
            "{:<8} {:>4} {:>+10.4} {:>9.4} {:>9.1}% {:>9.1}%",
            g.group,
            g.n,
            g.mean_mm,
            g.sd_mm,
            100.0 * g.within_006,
            100.0 * g.within_tolerance
        );
    }
    for f in &report.fits {
        println!("{}", fit_line(f));
    }
    let [sx, sy, sz] = correction.scale;
    println!(
        "correction: scale {sx:.5}, {sy:.5}, {sz:.5}; xy offset {:+.4} mm{}",
        correction.xy_offset_mm,
        match fit.z_offset_mm {
            Some(z) => format!(" (Z offset {z:+.4} mm: not corrected, see docs/CALIBRATION.md)"),
            None => String::new(),
        }
    );
    match &a.output {
        Some(out) => println!(
            "{}: dmdsl slice --accuracy {} applies it\nplot: {}",
            out.display(),
            out.display(),
            out.with_extension("png").display()
        ),
        None => println!("(-o FILE writes it for dmdsl slice --accuracy FILE)"),
    }
    Ok(0)
}

/// An axis's fit as `calibrate accuracy` prints it: outer sizes grow by the offset, holes
/// and slots (X and Y only) shrink by it.
fn fit_line(f: &crate::calib::accuracy::AxisFit) -> String {
    let sign = |o: f64| if o < 0.0 { '−' } else { '+' };
    let (o, mag) = (f.offset_mm, f.offset_mm.abs());
    let holes = match f.axis {
        'Z' => String::new(),
        _ => format!(" (holes and slots: {} {mag:.4} mm)", sign(-o)),
    };
    format!(
        "{}: measured = {:.5}·nominal {} {mag:.4} mm{holes}, residual RMS {:.4} mm",
        f.axis,
        f.scale,
        sign(o),
        f.residual_rms_mm
    )
}

/// Slices the test job `o` and writes its measurement sheet beside it (`.csv`; a symbolic
/// link there is refused before anything is written); returns the sheet's path.
pub(super) fn slice_with_sheet(
    o: &crate::job::SliceOptions,
    sheet: &str,
) -> anyhow::Result<(crate::job::SliceSummary, PathBuf)> {
    let output = o.output.as_ref().expect("a test job names its output");
    let sheet_path = output.with_extension("csv");
    crate::output::refuse_special(&sheet_path)?;
    let s = crate::job::slice_to_bundle(o)?;
    crate::output::write_atomic(&sheet_path, sheet.as_bytes())?;
    Ok((s, sheet_path))
}

/// Writes a fit file `output` (`toml`) and its chart beside it (`.png`), both or neither;
/// returns the chart's path.
pub(super) fn write_fit(
    output: &std::path::Path,
    toml: String,
    chart: &crate::plot::Chart,
) -> anyhow::Result<PathBuf> {
    let png = output.with_extension("png");
    let bytes = chart.render().encode(crate::plot::Format::Png);
    crate::optics::report::write_all(&[
        (output.to_path_buf(), toml.into_bytes()),
        (png.clone(), bytes),
    ])?;
    Ok(png)
}
