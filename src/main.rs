//! The `dmdsl` command line: parses arguments, calls the library, maps errors to exit codes.
//!
//! Exit codes: 0 success; 1 finished, but checks failed (e.g. `slice --strict` on a
//! defective mesh); 2 usage or input error; 130 interrupted.

use clap::{Args, Parser, Subcommand};
use dmdsl::exec::report::hms;
use dmdsl::geometry::distortion::DistortionChoice;
use dmdsl::job::{self, PlacementMode, SliceOptions};
use dmdsl::profile::{self, Profile};
use dmdsl::units::Positive;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

const EXIT_HELP: &str = "Exit codes:
  0    success
  1    finished, but checks failed (slice --strict with mesh defects)
  2    usage or input error (bad file, bad profile, part does not fit)
  130  interrupted (Ctrl-C); nothing was written";

/// Build-job compiler for DMD mask-projection stereolithography.
#[derive(Parser)]
#[command(name = "dmdsl", version, about, after_help = EXIT_HELP)]
struct Cli {
    /// Print nothing but errors.
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Slice a part (STL or OBJ) into a job bundle of mask PNGs and a manifest.
    #[command(after_help = EXIT_HELP)]
    Slice(SliceArgs),
    /// Show or list machine profiles.
    #[command(subcommand)]
    Profile(ProfileCmd),
    /// Dry-run a job bundle: verify its masks, replay its steps on a simulated stage,
    /// shutter and DMD, and report the time and every violation.
    #[command(after_help = RUN_EXIT_HELP)]
    Run(RunArgs),
    /// Fit a light-uniformity calibration (E = P(x,y)·S(g)) to irradiance measurements.
    #[command(after_help = EXIT_HELP)]
    Calibrate(CalibrateArgs),
    /// Fit a distortion correction table and report its quality (and optionally plot it).
    #[command(after_help = EXIT_HELP)]
    Distortion(DistortionArgs),
}

#[derive(Args)]
struct DistortionArgs {
    /// The table: CSV x_mm,y_mm,seen_x_mm,seen_y_mm (docs/GEOMETRY.md).
    table: PathBuf,
    /// Machine profile whose projector field the table describes.
    #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
    profile: String,
    /// Write a heatmap of the correction over the field (gray: unreachable) to this PNG.
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Print the fit report as JSON on stdout.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct CalibrateArgs {
    /// Measurements: CSV with header x_mm,y_mm,gray,irradiance_mw_cm2 (zone centre from the
    /// field's bottom-left corner, pixel value shown there (255 = fully on), irradiance).
    input: PathBuf,
    /// Calibration file to write (TOML); PNG plots are written next to it.
    #[arg(short, long)]
    output: PathBuf,
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
    json: bool,
}

/// Dithering of compensated grays.
#[derive(Clone, Copy, clap::ValueEnum)]
enum DitherArg {
    /// Zone mode mixes two grays only where one gray misses the target by > 0.75 %.
    Auto,
    /// Every zone mixes two grays; pixel mode diffuses the error.
    On,
    /// One gray per zone or pixel.
    Off,
}

/// Light compensation mode.
#[derive(Clone, Copy, clap::ValueEnum)]
enum CompensationArg {
    /// One gray per zone (Xu et al. 2010, Chinese J. Lasers 37(7)).
    Zone,
    /// One gray per pixel from the smooth fit.
    Pixel,
    /// No compensation: pixel value = coverage.
    Off,
}

const RUN_EXIT_HELP: &str = "Exit codes:
  0    the bundle verified and replayed without violations
  1    violations, bad masks or an injected fault
  2    unreadable bundle or usage error

Fault kinds: stall, limit (limit switch hit), shutter-stuck (stuck open), mask-load.";

#[derive(Args)]
struct RunArgs {
    /// The job bundle (directory with job.json and masks/).
    bundle: PathBuf,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Write the simulated timeline as CSV (time, stage, velocity, shutter, mask).
    #[arg(long, value_name = "FILE.csv")]
    trace: Option<PathBuf>,
    /// Write a PNG of stage position and light over time.
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Restrict --trace and --plot to layers A..B (inclusive, 0-based).
    #[arg(long, value_name = "A..B")]
    layers: Option<String>,
    /// Inject a fault: KIND@LAYER, KIND one of stall, limit, shutter-stuck, mask-load
    /// (repeatable).
    #[arg(long, value_name = "KIND@LAYER")]
    fault: Vec<String>,
}

#[derive(Args)]
struct SliceArgs {
    /// The part: binary or ASCII STL, or OBJ.
    input: PathBuf,
    /// Bundle to write (default: <input stem>.dmdjob in the current directory).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Machine profile: a built-in name or a TOML file.
    #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
    profile: String,
    /// Layer height in mm (default: the profile's).
    #[arg(long, value_name = "MM")]
    layer_height: Option<f64>,
    /// Binary masks: a pixel is lit when at least half of it is inside the section.
    #[arg(long)]
    binary: bool,
    /// Use the file's coordinates as build-plane coordinates instead of centring the part.
    #[arg(long)]
    keep_position: bool,
    /// Exit with code 1 if the mesh has defects (the bundle is still written).
    #[arg(long)]
    strict: bool,
    /// Light calibration file from `dmdsl calibrate`, replacing the profile's (repeatable:
    /// PROJECTOR=FILE for a named projector).
    #[arg(long, value_name = "[PROJECTOR=]FILE")]
    calibration: Vec<String>,
    /// Light compensation [default: zone when the profile or --calibration has a
    /// calibration, else off].
    #[arg(long, value_enum)]
    compensation: Option<CompensationArg>,
    /// Dithering of compensated grays, to beat 8-bit gray steps. auto: a zone whose
    /// nearest gray misses the target by > 0.75 % mixes the two grays around it (ordered
    /// pattern), pixel mode does not dither; on: every zone mixes, pixel mode diffuses
    /// the error (Floyd-Steinberg); off: one gray per zone/pixel.
    #[arg(long, value_enum, default_value = "auto")]
    dither: DitherArg,
    /// Print a machine-readable summary on stdout.
    #[arg(long)]
    json: bool,
    /// Lens distortion correction table (CSV x_mm,y_mm,seen_x_mm,seen_y_mm), or `off` to
    /// ignore the profile's [distortion] (default: the profile's, if any).
    #[arg(long, value_name = "TABLE.csv|off")]
    distortion: Option<PathBuf>,
}

#[derive(Subcommand)]
enum ProfileCmd {
    /// Print a profile as TOML (built-in: with its comments), ready to copy and edit.
    Show {
        /// Built-in name or TOML file.
        name: String,
    },
    /// List the built-in profiles.
    List,
}

/// Restores the default SIGPIPE action, which Rust's runtime sets to "ignore": then
/// `dmdsl ... --json | head` ends quietly when the reader goes away, as other command-line
/// tools do, instead of panicking on a failed print. Output is only printed after a bundle
/// is complete, so this never leaves anything half-written.
#[cfg(unix)]
fn default_sigpipe() {
    unsafe extern "C" {
        fn signal(signum: i32, handler: usize) -> usize;
    }
    const SIGPIPE: i32 = 13;
    const SIG_DFL: usize = 0;
    // SAFETY: called once at start-up, before any other thread exists; SIG_DFL is a valid
    // disposition for SIGPIPE.
    unsafe {
        signal(SIGPIPE, SIG_DFL);
    }
}

fn main() -> ExitCode {
    #[cfg(unix)]
    default_sigpipe();
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            match e.downcast_ref::<dmdsl::Error>() {
                // The library's errors are complete one-line messages (their sources are
                // already in the text), so print them without the cause chain.
                Some(d) => {
                    eprintln!("dmdsl: error: {d}");
                    ExitCode::from(d.exit_code() as u8)
                }
                None => {
                    eprintln!("dmdsl: error: {e:#}");
                    ExitCode::from(2)
                }
            }
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<u8> {
    match cli.cmd {
        Cmd::Slice(a) => slice(a, cli.quiet),
        Cmd::Distortion(a) => distortion(a, cli.quiet),
        Cmd::Run(a) => run_bundle(a, cli.quiet),
        Cmd::Calibrate(a) => calibrate(a, cli.quiet),
        Cmd::Profile(ProfileCmd::List) => {
            for (name, src) in profile::BUILTIN {
                let p = Profile::from_toml(src, name)?;
                println!("{name}\t{}", p.description);
            }
            Ok(0)
        }
        Cmd::Profile(ProfileCmd::Show { name }) => {
            match profile::builtin_source(&name) {
                Some(src) => print!("{src}"),
                None => print!("{}", Profile::resolve(&name)?.to_toml()),
            }
            Ok(0)
        }
    }
}

fn slice(a: SliceArgs, quiet: bool) -> anyhow::Result<u8> {
    let mut profile = Profile::resolve(&a.profile)?;
    dmdsl::optics::apply_calibration_args(&mut profile, &a.calibration)?;
    let optics = dmdsl::optics::OpticsOptions {
        mode: a.compensation.map(|c| match c {
            CompensationArg::Zone => dmdsl::optics::Mode::Zone,
            CompensationArg::Pixel => dmdsl::optics::Mode::Pixel,
            CompensationArg::Off => dmdsl::optics::Mode::Off,
        }),
        dither: match a.dither {
            DitherArg::Auto => dmdsl::optics::Dither::Auto,
            DitherArg::On => dmdsl::optics::Dither::On,
            DitherArg::Off => dmdsl::optics::Dither::Off,
        },
    };
    let layer_height_mm = match a.layer_height {
        None => None,
        Some(v) => Some(Positive::new(v).ok_or_else(|| {
            dmdsl::Error::Usage(format!("--layer-height must be a number > 0, got {v}"))
        })?),
    };
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        // A second handler registration fails only if one exists; ignore that.
        let _ = ctrlc::set_handler(move || c.store(true, Ordering::Relaxed));
    }
    let show_progress = !quiet && !a.json && std::io::stderr().is_terminal();
    let progress = |done: usize, total: usize| {
        if done == total || done % 16 == 0 {
            let mut e = std::io::stderr().lock();
            let _ = write!(e, "\rslicing: layer {done}/{total}");
            if done == total {
                let _ = writeln!(e);
            }
        }
    };
    let opts = SliceOptions {
        input: a.input.clone(),
        output: a.output.clone(),
        profile,
        layer_height_mm,
        binary: a.binary.then_some(true),
        placement: if a.keep_position {
            PlacementMode::Keep
        } else {
            PlacementMode::Center
        },
        optics,
        progress: if show_progress { Some(&progress) } else { None },
        cancel: Some(&cancel),
        distortion: match &a.distortion {
            None => DistortionChoice::Profile,
            Some(p) if p.as_os_str() == "off" => DistortionChoice::Off,
            Some(p) => DistortionChoice::Table(p.clone()),
        },
    };
    let summary = job::slice_to_bundle(&opts)?;
    let defects = !summary.mesh.closed_manifold;
    let failed = a.strict && defects;
    if a.json {
        let v = serde_json::json!({
            "bundle": summary.bundle,
            "layers": summary.layers,
            "warnings": summary.warnings,
            "mesh": summary.mesh,
            "totals": summary.totals,
            "timings": summary.timings,
            "distortion": summary.distortion,
            "checks_failed": failed,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else if !quiet {
        for w in &summary.warnings {
            eprintln!("dmdsl: warning: {w}");
        }
        if let Some(d) = &summary.distortion {
            println!("{}", d.summary());
        }
        println!(
            "{}: {} layers, {:.1} mm, est. print time {}, {:.2} ml resin ({:.2} s)",
            summary.bundle.display(),
            summary.layers,
            summary.totals.height_mm,
            hms(summary.totals.print_time_s),
            summary.totals.resin_volume_ml,
            summary.timings.total_s
        );
        if let (Some(all), Some(c)) = (
            summary.totals.all_layered_time_s,
            summary.totals.continuous_layers,
        ) {
            println!(
                "hybrid: {c} of {} layers continuous; all layered would take {} ({:.0} % saved)",
                summary.layers,
                hms(all),
                100.0 * (1.0 - summary.totals.print_time_s / all)
            );
        }
    }
    if failed {
        if !quiet {
            eprintln!("dmdsl: --strict: mesh has defects (see warnings); exit code 1");
        }
        return Ok(1);
    }
    Ok(0)
}

fn distortion(a: DistortionArgs, quiet: bool) -> anyhow::Result<u8> {
    let mut profile = Profile::resolve(&a.profile)?;
    let c = dmdsl::geometry::distortion::for_job(&DistortionChoice::Table(a.table), &mut profile)?
        .expect("a table was given");
    let report = c.report();
    let (_, _, map) = c.field_map(1.0);
    let reachable = map.iter().filter(|v| v.is_finite()).count() as f64 / map.len() as f64;
    if let Some(p) = &a.plot {
        std::fs::write(p, c.plot_png()).map_err(|e| dmdsl::Error::io(p, e))?;
    }
    if a.json {
        let v = serde_json::json!({ "report": report, "reachable_fraction": reachable });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else if !quiet {
        println!("{}", report.summary());
        println!(
            "reachable: {:.1} % of the {:.2} x {:.2} mm field (1 mm cells)",
            reachable * 100.0,
            profile.field().width_mm(),
            profile.field().height_mm()
        );
    }
    Ok(0)
}

fn calibrate(a: CalibrateArgs, quiet: bool) -> anyhow::Result<u8> {
    use dmdsl::optics::report::{self, CalibrateOptions};
    let field = Profile::resolve(&a.profile)?.field();
    let r = report::calibrate(&CalibrateOptions {
        input: a.input,
        output: a.output,
        units: if a.relative {
            dmdsl::optics::Units::Relative
        } else {
            dmdsl::optics::Units::MwCm2
        },
        zone_mm: a.zone_mm,
        extrapolate_mm: a.extrapolate_mm,
        field,
        degree: a.degree,
        plots: !a.no_plots,
    })?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(0);
    }
    if quiet {
        return Ok(0);
    }
    for w in &r.warnings {
        eprintln!("dmdsl: warning: {w}");
    }
    let u = if r.units == "relative" {
        ""
    } else {
        " mW/cm²"
    };
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
    Ok(0)
}

fn run_bundle(a: RunArgs, quiet: bool) -> anyhow::Result<u8> {
    let faults = a
        .fault
        .iter()
        .map(|f| f.parse().map_err(dmdsl::Error::Usage))
        .collect::<Result<Vec<_>, _>>()?;
    let opts = dmdsl::exec::RunOptions {
        faults,
        trace: a.trace,
        plot: a.plot,
        layers: a.layers,
    };
    let report = dmdsl::exec::run(&a.bundle, &opts)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else if !quiet {
        print!("{}", dmdsl::exec::report::render_human(&report));
    }
    Ok(if report.ok { 0 } else { 1 })
}
