//! `dmdsl slice`: a part into a job bundle.

use clap::Args;
use dmdsl::exec::report::hms;
use dmdsl::geometry::distortion::DistortionChoice;
use dmdsl::job::{self, PlacementMode, SliceOptions};
use dmdsl::profile::{self, Profile};
use dmdsl::units::Positive;
use dmdsl::warning::count;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

pub(crate) const SLICE_EXIT_HELP: &str = "Exit codes:
  0    the bundle was written (warnings and notes do not change this)
  1    the bundle was written, but a warning was denied (--strict, --deny-warnings,
       -W CODE=error)
  2    usage or input error (unreadable or malformed part, bad profile, part does not fit
       the field or the stage travel, the output path holds anything but a dmdsl bundle's
       own files, or is a symbolic link); nothing was written
  130  interrupted (Ctrl-C, SIGTERM or SIGHUP); nothing was written: an existing bundle at
       the path is left as it was";

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
    /// One gray per zone (Xu et al. 2010, "Novel stereolithography system employing digital
    /// micro-mirror device").
    Zone,
    /// One gray per pixel from the smooth fit.
    Pixel,
    /// No compensation: pixel value = coverage.
    Off,
}

#[derive(Args)]
pub(crate) struct SliceArgs {
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
    /// Binary coverage: a pixel is lit when at least half of it is inside the section (no
    /// anti-aliased edges). Light compensation still applies, so a lit pixel shows its
    /// zone's (or its own) gray; add --compensation off for masks of 0 and 255 only.
    #[arg(long)]
    binary: bool,
    /// Use the file's coordinates as build-plane coordinates instead of centring the part.
    #[arg(long)]
    keep_position: bool,
    /// Exit with code 1 if the mesh has defects (the bundle is still written). Same as
    /// -W mesh=error: open, non-manifold or backwards edges (notes such as degenerate
    /// facets do not count).
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
    #[command(flatten)]
    warnings: super::WarningArgs,
}

impl SliceArgs {
    /// True when `--json` was given.
    pub(crate) fn json(&self) -> bool {
        self.json
    }
}

/// Runs `dmdsl slice`.
pub(crate) fn slice(a: SliceArgs, quiet: bool) -> anyhow::Result<u8> {
    // First, so that an interrupt at any point (even while the profile and the part load)
    // ends the command with its message and code 130.
    let cancel = Arc::new(AtomicBool::new(false));
    super::interrupt::on_interrupt(cancel.clone());
    let policy = a
        .warnings
        .policy(if a.strict { &["mesh=error"] } else { &[] })?;
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
    let mut summary = job::slice_to_bundle(&opts)?;
    summary.warnings = policy.apply(&summary.warnings);
    let failed = dmdsl::warning::any_error(&summary.warnings);
    if a.json {
        let v = serde_json::json!({
            "ok": !failed,
            "bundle": summary.bundle,
            "layers": summary.layers,
            "warnings": summary.warnings,
            "mesh": summary.mesh,
            "totals": summary.totals,
            "timings": summary.timings,
            "distortion": summary.distortion,
        });
        super::print_json(&v)?;
    } else if !quiet {
        super::print_warnings(&summary.warnings, "");
        if let Some(d) = &summary.distortion {
            println!("{}", d.summary());
        }
        println!(
            "{}: {}, {:.1} mm, est. print time {}, {:.2} ml resin ({:.2} s)",
            summary.bundle.display(),
            count(summary.layers as u64, "layer", "layers"),
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
                "hybrid: {c} of {} continuous; all layered would take {} ({:.0} % saved)",
                count(summary.layers as u64, "layer", "layers"),
                hms(all),
                100.0 * (1.0 - summary.totals.print_time_s / all)
            );
        }
    }
    if failed {
        if !quiet && !a.json {
            eprintln!("dmdsl: warnings denied (see the error lines above); exit code 1");
        }
        return Ok(1);
    }
    Ok(0)
}
