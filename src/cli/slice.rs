//! `dmdsl slice`: parts into job bundles, one after another.

use crate::geometry::distortion::DistortionChoice;
use crate::job::{self, PlacementMode, SliceOptions, SliceSummary, Transform};
use crate::profile::{self, Override, Profile};
use crate::text::hms;
use crate::text::{count, plural};
use crate::units::Positive;
use clap::Args;
use serde::Serialize;
use std::io::{IsTerminal, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

pub(crate) const SLICE_EXIT_HELP: &str =
    "Exit codes (with several parts, the worst of them: 2 > 1 > 0):
  0    the bundle was written (warnings and notes do not change this)
  1    the bundle was written, but a warning was denied (--strict, --deny-warnings,
       -W CODE=error)
  2    usage or input error (unreadable or malformed part, bad profile or --set, part does
       not fit the field or the stage travel, the output path holds anything but a dmdsl
       bundle's own files, or is a symbolic link); nothing was written for that part
  130  interrupted (Ctrl-C, SIGTERM or SIGHUP): the part being sliced was not written (an
       existing bundle at its path is left as it was) and the parts after it were not
       sliced";

/// The name standard input goes by in messages and in the manifest.
const STDIN_NAME: &str = "<stdin>";

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

/// Correction of the masks for the projector's blur (docs/CURE.md).
#[derive(Clone, Copy, clap::ValueEnum)]
enum CureCorrectionArg {
    /// Move the drawn edges so the predicted cured edge at mid-layer lands on the section.
    Xy,
    /// XY, and hold back downward-facing surfaces by the print-through (whole layers).
    Xyz,
    /// Draw the exact sections.
    Off,
}

/// The cure model's options and the calibration files (boxed: they would make every
/// command's arguments larger).
#[derive(clap::Args)]
struct CureArgs {
    /// Predict what cures: each layer's cured edge against its section (edge error,
    /// features that vanish or merge) in the summary, `--json` and job.json (docs/CURE.md).
    #[arg(long)]
    predict: bool,
    /// Correct the masks for the projector's blur (xy) and the light reaching through
    /// later layers (xyz) [default: xy when the profile has psf_sigma_px, else off].
    #[arg(long, value_enum)]
    cure_correction: Option<CureCorrectionArg>,
    /// With --predict: write the per-layer error chart and the worst layer's predicted
    /// outline over its section into DIR (PNG).
    #[arg(long, value_name = "DIR", requires = "predict")]
    cure_plots: Option<PathBuf>,
    /// Resin calibration file from `dmdsl calibrate resin`: its Dp (and Ec, when fitted to
    /// absolute doses) replace the profile's.
    #[arg(long, value_name = "FILE")]
    resin: Option<PathBuf>,
    /// Blur calibration file from `dmdsl calibrate psf`: its psf_sigma_px replace the
    /// named projectors'.
    #[arg(long, value_name = "FILE")]
    psf: Option<PathBuf>,
    /// Dimensional correction file from `dmdsl calibrate accuracy`: its scale and XY offset
    /// replace the profile's [accuracy].
    #[arg(long, value_name = "FILE")]
    accuracy: Option<PathBuf>,
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

/// Many parts on one plate (boxed: they would make every command's arguments larger).
#[derive(clap::Args)]
struct PlateArgs {
    /// Put all the parts, with their --copies, on one plate (several parts with -o go on one
    /// plate without it): one job, the parts laid out in
    /// rows on the field --spacing apart, inside the calibrated area when they fit there
    /// (with --keep-position: where their files put them, none overlapping). The bundle is
    /// -o's, or plate.dmdjob (or the --format's ending) in --output-dir or the current
    /// directory.
    #[arg(long)]
    plate: bool,
    /// Copies of each part on the plate (1 to 1000; more than 1 puts them on a plate).
    #[arg(long, value_name = "N")]
    copies: Option<usize>,
    /// Gap between the boxes of a plate's arranged parts, mm [default: 3].
    #[arg(long, value_name = "MM", allow_hyphen_values = true)]
    spacing: Option<f64>,
    /// Generate supports: a point under every island and every surface facing down too
    /// flat, heads, pillars and a pad, the part lifted by the elevation (the profile's
    /// [supports] section, changed with --set supports.KEY=VALUE; docs/SUPPORTS.md).
    #[arg(long)]
    supports: bool,
    /// With --supports: also write the support structure (pad and supports, closed
    /// shells, build-plane coordinates) as a binary STL.
    #[arg(long, value_name = "FILE.stl", requires = "supports")]
    supports_stl: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct SliceArgs {
    /// The parts: binary or ASCII STL, or OBJ; `-` reads an STL from stdin (then -o is
    /// required). Several parts are sliced one after another, a bundle each; with -o,
    /// --plate or --copies, onto one plate.
    #[arg(required = true, value_name = "PART")]
    inputs: Vec<PathBuf>,
    /// Bundle to write (default: <part stem>.dmdjob in the current directory, or the
    /// --format's ending); several parts go on one plate. Its name picks the format: NAME.dmdjob (a
    /// directory), NAME.dmdjob.zip, NAME.sl1, NAME.sl1s; a plain .zip needs --format.
    /// Missing parent directories are created.
    #[arg(short, long, conflicts_with = "output_dir")]
    output: Option<PathBuf>,
    /// Directory the bundles go in, <part stem>.dmdjob each (or the --format's ending;
    /// created if missing).
    #[arg(long, value_name = "DIR")]
    output_dir: Option<PathBuf>,
    /// Form of the output [default: what the -o name says; a directory bundle]:
    /// dmdjob (directory), dmdjob-zip (the same files in one zip), sl1 / sl1s (Prusa
    /// SL1/SL1S, opened by PrusaSlicer and UVtools), sla-control (the SLA control-file
    /// standard, schema v5). docs/FORMATS.md says what each carries.
    #[arg(long, value_name = "FORMAT", value_parser = super::export::formats())]
    format: Option<crate::formats::Format>,
    /// Machine profile: a built-in name or a TOML file.
    #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
    profile: String,
    /// The printer's hardware description (the SLA control-file standard's
    /// hardware_config.json): the projectors take its light engines' names and
    /// wavelengths, and a profile it cannot run is refused before anything is sliced.
    #[arg(long, value_name = "HARDWARE.json")]
    machine: Option<PathBuf>,
    /// Change one key of the profile, e.g. --set exposure.layer_s=6 (repeatable; the value
    /// read as TOML: a number, true/false, a string; a list entry by its index, as in
    /// projector.0.mirror_x). Checked like a profile file; the manifest's machine records
    /// the result.
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    set: Vec<String>,
    /// Layer exposure in s (the same as --set exposure.layer_s=S).
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    exposure: Option<String>,
    /// Number of bottom layers (the same as --set exposure.bottom_layers=N).
    #[arg(long, value_name = "N", allow_hyphen_values = true)]
    bottom_layers: Option<String>,
    /// Layer height in mm (default: the profile's).
    #[arg(long, value_name = "MM", allow_hyphen_values = true)]
    layer_height: Option<f64>,
    /// Binary coverage: a pixel is lit when at least half of it is inside the section (no
    /// anti-aliased edges). Light compensation still applies, so a lit pixel shows its
    /// zone's (or its own) gray; add --compensation off for masks of 0 and 255 only.
    #[arg(long)]
    binary: bool,
    /// Use the file's coordinates as build-plane coordinates instead of centring the part.
    #[arg(long)]
    keep_position: bool,
    /// Put the centre of the part's XY bounding box at X,Y mm (build-plane coordinates, from
    /// the field's bottom-left corner) instead of the field's centre; its lowest point
    /// still goes to z = 0.
    #[arg(
        long,
        value_name = "X,Y",
        allow_hyphen_values = true,
        conflicts_with = "keep_position"
    )]
    position: Option<String>,
    #[command(flatten)]
    plate: Box<PlateArgs>,
    /// Turn the part before placing it: DEG degrees about Z, or X,Y,Z degrees about the
    /// axes, applied in X, Y, Z order (counter-clockwise seen from the positive axis).
    #[arg(long, value_name = "DEG|X,Y,Z", allow_hyphen_values = true)]
    rotate: Option<String>,
    /// Scale the part before turning and placing it: one factor, or FX,FY,FZ per axis
    /// (each > 0).
    #[arg(long, value_name = "F|FX,FY,FZ", allow_hyphen_values = true)]
    scale: Option<String>,
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
    /// Print a machine-readable summary on stdout: one JSON object for one part; for
    /// several, one line per part (JSON Lines).
    #[arg(long)]
    pub(crate) json: bool,
    /// Lens distortion correction table (CSV x_mm,y_mm,seen_x_mm,seen_y_mm), or `off` to
    /// ignore the profile's [distortion] (default: the profile's, if any).
    #[arg(long, value_name = "TABLE.csv|off")]
    distortion: Option<PathBuf>,
    #[command(flatten)]
    cure: Box<CureArgs>,
    #[command(flatten)]
    warnings: super::WarningArgs,
}

/// A part to slice and where its bundle goes (`None`: the default, `<stem>.dmdjob` in the
/// current directory).
struct Part {
    input: PathBuf,
    output: Option<PathBuf>,
}

/// What every part of one call shares: the options of each part's job but for its input
/// and output, and whether to show a progress line.
struct Job<'a> {
    options: SliceOptions<'a>,
    show_progress: bool,
}

impl Job<'_> {
    /// Slices one part (`bytes`: its content when read from stdin); `label` names it on
    /// the progress line.
    fn slice(
        &self,
        part: &Part,
        bytes: Option<&[u8]>,
        label: &str,
    ) -> Result<SliceSummary, crate::Error> {
        let progress = |done: usize, total: usize| {
            if done == total || done.is_multiple_of(16) {
                let mut e = std::io::stderr().lock();
                let _ = write!(e, "\rslicing{label}: layer {done}/{total}");
                if done == total {
                    let _ = writeln!(e);
                }
            }
        };
        let opts = SliceOptions {
            input: part.input.clone(),
            input_bytes: bytes,
            output: part.output.clone(),
            progress: if self.show_progress {
                Some(&progress)
            } else {
                None
            },
            ..self.options.clone()
        };
        job::slice_to_bundle(&opts)
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
    let parts = parts(&a)?;
    let overrides = overrides(&a)?;
    let mut profile = Profile::resolve(&a.profile)?.with_overrides(&overrides)?;
    crate::optics::apply_calibration_args(&mut profile, &a.calibration)?;
    if let Some(r) = &a.cure.resin {
        crate::calib::ResinFit::apply_file(r, &mut profile)?;
    }
    if let Some(f) = &a.cure.psf {
        crate::calib::psf::PsfFit::apply_file(f, &mut profile)?;
    }
    if let Some(f) = &a.cure.accuracy {
        crate::calib::accuracy::AccuracyFit::apply_file(f, &mut profile)?;
    }
    if let Some(path) = &a.machine {
        super::export::fit_profile(&mut profile, path)?;
    }
    let optics = crate::optics::OpticsOptions {
        mode: a.compensation.map(|c| match c {
            CompensationArg::Zone => crate::optics::Mode::Zone,
            CompensationArg::Pixel => crate::optics::Mode::Pixel,
            CompensationArg::Off => crate::optics::Mode::Off,
        }),
        dither: match a.dither {
            DitherArg::Auto => crate::optics::Dither::Auto,
            DitherArg::On => crate::optics::Dither::On,
            DitherArg::Off => crate::optics::Dither::Off,
        },
    };
    let layer_height_mm = match a.layer_height {
        None => None,
        Some(v) => Some(Positive::new(v).ok_or_else(|| {
            crate::Error::Usage(format!("--layer-height must be a number > 0, got {v}"))
        })?),
    };
    let options = SliceOptions {
        profile,
        // Each part's own, set by `Job::slice`.
        input: PathBuf::new(),
        input_bytes: None,
        output: None,
        progress: None,
        dose: None,
        layer_height_mm,
        binary: a.binary.then_some(true),
        transform: transform(&a)?,
        placement: match (&a.position, a.keep_position) {
            (Some(p), _) => PlacementMode::At(position(p)?),
            (None, true) => PlacementMode::Keep,
            (None, false) => PlacementMode::Center,
        },
        optics,
        distortion: match &a.distortion {
            None => DistortionChoice::Profile,
            Some(p) if p.as_os_str() == "off" => DistortionChoice::Off,
            Some(p) => DistortionChoice::Table(p.clone()),
        },
        cure: crate::job::CureOptions {
            predict: a.cure.predict,
            correction: a.cure.cure_correction.map(|c| match c {
                CureCorrectionArg::Xy => crate::cure::Correction::Xy,
                CureCorrectionArg::Xyz => crate::cure::Correction::Xyz,
                CureCorrectionArg::Off => crate::cure::Correction::Off,
            }),
            plots: a.cure.cure_plots.clone(),
        },
        cancel: Some(&cancel),
        format: a.format,
        plate: plate(&a)?,
        supports_stl: a.plate.supports_stl.clone(),
    };
    let job = Job {
        options,
        show_progress: !quiet && !a.json && std::io::stderr().is_terminal(),
    };
    if let [part] = &parts[..] {
        let stdin = is_stdin(&a.inputs[0])
            .then(|| read_stdin(&cancel))
            .transpose()?;
        let mut summary = job.slice(part, stdin.as_deref(), "")?;
        summary.warnings = policy.apply(&summary.warnings);
        let failed = crate::warning::any_error(&summary.warnings);
        if a.json {
            let v = serde_json::json!({
                "ok": !failed,
                "bundle": summary.bundle,
                "format": summary.format.name(),
                "layers": summary.layers,
                "warnings": summary.warnings,
                "mesh": summary.mesh,
                "totals": summary.totals,
                "timings": summary.timings,
                "distortion": summary.distortion,
                "cure": summary.cure,
                "supports": summary.supports,
            });
            super::print_json(&v)?;
        } else if !quiet {
            print_summary(&summary, "");
        }
        if failed && !quiet && !a.json {
            eprintln!("dmdsl: warnings denied (see the error lines above); exit code 1");
        }
        return Ok(u8::from(failed));
    }
    slice_each(&job, &parts, &policy, a.json, quiet)
}

/// Slices several parts one after another (each uses every thread), a line of output per
/// part; a part that fails does not stop the others, an interrupt stops all. Returns the
/// worst exit code (2 > 1 > 0, or 130).
fn slice_each(
    job: &Job,
    parts: &[Part],
    policy: &crate::warning::Policy,
    json: bool,
    quiet: bool,
) -> anyhow::Result<u8> {
    let (mut failed, mut denied) = (0, 0);
    for (i, part) in parts.iter().enumerate() {
        let input = part.input.display().to_string();
        let result = if job
            .options
            .cancel
            .is_some_and(|c| c.load(Ordering::Relaxed))
        {
            Err(crate::Error::Interrupted)
        } else {
            job.slice(part, None, &format!(" {input}"))
        };
        match result {
            Ok(mut summary) => {
                summary.warnings = policy.apply(&summary.warnings);
                let ok = !crate::warning::any_error(&summary.warnings);
                denied += usize::from(!ok);
                if json {
                    print_line(&PartLine {
                        schema_version: super::SCHEMA_VERSION,
                        ok,
                        input,
                        summary: Some(&summary),
                        error: None,
                    })?;
                } else if !quiet {
                    print_summary(&summary, &format!("{input}: "));
                }
            }
            Err(e) => {
                failed += 1;
                let interrupted = matches!(e, crate::Error::Interrupted);
                // An error names its file; the few that do not (an interrupt) get the part's.
                let (file, message) = match e.file() {
                    Some(f) => (f, e.to_string()),
                    None => (input.clone(), format!("{input}: {e}")),
                };
                let message = super::process::printable(&message);
                eprintln!("dmdsl: error: {message}");
                if json {
                    print_line(&PartLine {
                        schema_version: super::SCHEMA_VERSION,
                        ok: false,
                        input,
                        summary: None,
                        error: Some(super::Failure {
                            code: e.code(),
                            file: Some(file),
                            message: &message,
                        }),
                    })?;
                }
                if interrupted {
                    let left = parts.len() - i - 1;
                    if left > 0 {
                        eprintln!(
                            "dmdsl: the {} after it {} not sliced",
                            count(left as u64, "part", "parts"),
                            plural(left as u64, "was", "were")
                        );
                    }
                    return Ok(130);
                }
            }
        }
    }
    let code = if failed > 0 {
        2
    } else if denied > 0 {
        1
    } else {
        0
    };
    if code != 0 && !quiet && !json {
        let mut what = Vec::new();
        if failed > 0 {
            what.push(format!("{failed} failed"));
        }
        if denied > 0 {
            what.push(format!(
                "{denied} {} denied warnings",
                if failed > 0 { "had" } else { "failed on" }
            ));
        }
        eprintln!(
            "dmdsl: of {} parts, {} (see the error lines above); exit code {code}",
            parts.len(),
            what.join(", ")
        );
    }
    Ok(code)
}

/// One part's line of `--json` output when several parts are sliced.
#[derive(Serialize)]
struct PartLine<'a> {
    schema_version: u32,
    ok: bool,
    /// The part as given on the command line.
    input: String,
    /// What a success reports (the fields of the one-part object but `ok`).
    #[serde(flatten)]
    summary: Option<&'a SliceSummary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<super::Failure<'a>>,
}

/// Prints `line` as one line of JSON on stdout.
fn print_line(line: &PartLine) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{}", serde_json::to_string(line)?)?;
    out.flush()?;
    Ok(())
}

/// Prints a slicing's warnings (on stderr, after `prefix`) and its summary line.
fn print_summary(summary: &SliceSummary, prefix: &str) {
    super::print_warnings(&summary.warnings, prefix);
    if let Some(d) = &summary.distortion {
        println!("{prefix}{}", d.summary());
    }
    println!(
        "{}: {}, {:.1} mm, est. print time {}, {:.2} ml resin ({:.2} s)",
        super::process::printable(&summary.bundle.display().to_string()),
        count(summary.layers as u64, "layer", "layers"),
        summary.totals.height_mm,
        hms(summary.totals.print_time_s),
        summary.totals.resin_volume_ml,
        summary.timings.total_s
    );
    if let Some(s) = &summary.supports {
        println!(
            "{prefix}supports: {} ({} under islands, {} standing on the part), {:.1} mm³ with the pad ({:.1} mm²); the part lifted {} mm",
            count(s.points as u64, "point", "points"),
            s.on_islands,
            s.on_part,
            s.volume_mm3,
            s.pad_area_mm2,
            crate::text::number(s.lift_mm)
        );
    }
    if let Some(p) = summary.cure.as_ref().and_then(|c| c.predicted.as_ref()) {
        let e = &p.edge_error_px;
        println!(
            "{prefix}cure ({} correction): edge error {:.2} px mean, {:.2} px p95, {:.2} px max ({:.3} mm mean); {} vanished, {} merged; print-through {:.3} mm",
            summary.cure.as_ref().map_or("off", |c| c.correction.as_str()),
            e.mean,
            e.p95,
            e.max,
            p.edge_error_mm.mean,
            p.vanished,
            p.merged,
            summary.cure.as_ref().map_or(0.0, |c| c.print_through_mm)
        );
    }
    if let (Some(all), Some(c)) = (
        summary.totals.all_layered_time_s,
        summary.totals.continuous_layers,
    ) {
        println!(
            "{prefix}hybrid: {c} of {} continuous; all layered would take {} ({:.0} % saved)",
            count(summary.layers as u64, "layer", "layers"),
            hms(all),
            100.0 * (1.0 - summary.totals.print_time_s / all)
        );
    }
}

/// True for the part `-`: standard input.
fn is_stdin(p: &Path) -> bool {
    p.as_os_str() == "-"
}

/// The parts and their bundles' paths; refuses what cannot work before anything is read.
fn parts(a: &SliceArgs) -> Result<Vec<Part>, crate::Error> {
    let usage = |m: String| Err(crate::Error::Usage(m));
    if a.output.as_deref().is_some_and(is_stdin) {
        return usage(
            "-o -: writing a bundle to stdout is not supported; give a directory path".into(),
        );
    }
    if a.output_dir.as_deref().is_some_and(is_stdin) {
        return usage(
            "--output-dir -: writing bundles to stdout is not supported; give a directory path"
                .into(),
        );
    }
    let n = a.inputs.len();
    if a.inputs.iter().any(|p| is_stdin(p)) && (n > 1 || a.output.is_none()) {
        return usage(format!(
            "reading a part from stdin (-) needs -o PATH for its bundle{}",
            if n > 1 {
                ", and a plate's parts are read from files: slice the others in another call"
            } else {
                ""
            }
        ));
    }
    if a.plate.plate || a.plate.copies.is_some_and(|c| c > 1) || (n > 1 && a.output.is_some()) {
        if a.inputs.iter().any(|p| is_stdin(p)) {
            return usage("a plate's parts are read from files: - (stdin) cannot be one".into());
        }
        let format = a.format.unwrap_or(crate::formats::Format::Dmdjob);
        let name = job::default_output_as(Path::new("plate"), format);
        return Ok(vec![Part {
            input: a.inputs[0].clone(),
            output: Some(a.output.clone().unwrap_or_else(|| match &a.output_dir {
                Some(d) => d.join(name),
                None => name,
            })),
        }]);
    }
    let parts: Vec<Part> = a
        .inputs
        .iter()
        .map(|input| Part {
            input: if is_stdin(input) {
                PathBuf::from(STDIN_NAME)
            } else {
                input.clone()
            },
            output: a.output.clone().or_else(|| {
                a.output_dir
                    .as_ref()
                    .map(|d| d.join(default_output(input, a)))
            }),
        })
        .collect();
    for (i, p) in parts.iter().enumerate() {
        let out = bundle_path(p, a);
        if let Some(q) = parts[..i].iter().find(|q| bundle_path(q, a) == out) {
            return usage(format!(
                "{} and {} would both write {}; slice them in separate calls with -o",
                q.input.display(),
                p.input.display(),
                out.display()
            ));
        }
    }
    if parts.len() > 1 && a.plate.supports_stl.is_some() {
        return usage(
            "--supports-stl names one file, but the parts are sliced one by one: add --plate, or slice one part".into(),
        );
    }
    Ok(parts)
}

/// The plate of `--plate`/`--copies`: the parts after the first and how they are laid out.
fn plate(a: &SliceArgs) -> Result<Option<job::Plate>, crate::Error> {
    let usage = |m: &str| Err(crate::Error::Usage(m.into()));
    let copies = a.plate.copies.unwrap_or(1);
    if !(1..=job::MAX_COPIES).contains(&copies) {
        return usage(&format!(
            "--copies must be a whole number from 1 to {}, got {copies}",
            job::MAX_COPIES
        ));
    }
    let spacing_mm = a.plate.spacing.unwrap_or(job::SPACING_MM);
    if !(spacing_mm.is_finite() && spacing_mm >= 0.0) {
        return usage(&format!(
            "--spacing must be a number of mm ≥ 0, got {spacing_mm}"
        ));
    }
    if !(a.plate.plate || copies > 1 || (a.inputs.len() > 1 && a.output.is_some())) {
        return match a.plate.spacing {
            Some(_) => usage("--spacing lays out the parts of a plate: add --plate or --copies N"),
            None => Ok(None),
        };
    }
    if a.position.is_some() {
        return usage("--position places a single part; a plate's parts are arranged on the field (or kept where their files put them with --keep-position)");
    }
    Ok(Some(job::Plate {
        more: a.inputs[1..].to_vec(),
        copies,
        spacing_mm,
    }))
}

/// Where `part`'s bundle goes.
fn bundle_path(part: &Part, a: &SliceArgs) -> PathBuf {
    part.output
        .clone()
        .unwrap_or_else(|| default_output(&part.input, a))
}

/// The default output of part `input`: `<stem>` and the ending of `--format` (`.dmdjob`
/// without it), in the current directory.
fn default_output(input: &Path, a: &SliceArgs) -> PathBuf {
    let format = a.format.unwrap_or(crate::formats::Format::Dmdjob);
    job::default_output_as(input, format)
}

/// The profile changes asked for: every `--set` in order, then `--exposure` and
/// `--bottom-layers`.
fn overrides(a: &SliceArgs) -> Result<Vec<Override>, crate::Error> {
    let mut o = a
        .set
        .iter()
        .map(|s| Override::parse_set(s))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(t) = &a.exposure {
        let v = t
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
            .ok_or_else(|| {
                crate::Error::Usage(format!(
                    "--exposure must be a number of seconds > 0, got {t}"
                ))
            })?;
        o.push(Override::new(
            format!("--exposure {t}"),
            "exposure.layer_s",
            toml::Value::Float(v),
        ));
    }
    if a.plate.supports {
        o.push(Override::new(
            "--supports",
            "supports.enabled",
            toml::Value::Boolean(true),
        ));
    }
    if let Some(t) = &a.bottom_layers {
        let n = t.trim().parse::<u32>().map_err(|_| {
            crate::Error::Usage(format!(
                "--bottom-layers must be a whole number >= 0, got {t}"
            ))
        })?;
        o.push(Override::new(
            format!("--bottom-layers {t}"),
            "exposure.bottom_layers",
            toml::Value::Integer(n.into()),
        ));
    }
    Ok(o)
}

/// The numbers of a comma-separated option value, if there are `counts` of them (one of)
/// and each passes `ok`.
fn numbers(text: &str, counts: &[usize], ok: impl Fn(f64) -> bool) -> Option<Vec<f64>> {
    let v = text
        .split(',')
        .map(|s| s.trim().parse::<f64>().ok().filter(|&x| ok(x)))
        .collect::<Option<Vec<f64>>>()?;
    counts.contains(&v.len()).then_some(v)
}

/// The scale and rotation of `--scale` and `--rotate`.
fn transform(a: &SliceArgs) -> Result<Transform, crate::Error> {
    let mut t = Transform::IDENTITY;
    if let Some(s) = &a.scale {
        let v = numbers(s, &[1, 3], |x| x.is_finite() && x > 0.0).ok_or_else(|| {
            crate::Error::Usage(format!(
                "--scale must be a factor > 0 or three, FX,FY,FZ, got {s}"
            ))
        })?;
        t.scale = if v.len() == 1 {
            [v[0]; 3]
        } else {
            [v[0], v[1], v[2]]
        };
    }
    if let Some(r) = &a.rotate {
        let v = numbers(r, &[1, 3], f64::is_finite).ok_or_else(|| {
            crate::Error::Usage(format!(
                "--rotate must be degrees about Z (DEG) or about X, Y and Z (X,Y,Z), got {r}"
            ))
        })?;
        t.rotate_deg = if v.len() == 1 {
            [0.0, 0.0, v[0]]
        } else {
            [v[0], v[1], v[2]]
        };
    }
    Ok(t)
}

/// The point of `--position X,Y`.
fn position(text: &str) -> Result<[f64; 2], crate::Error> {
    let v = numbers(text, &[2], f64::is_finite).ok_or_else(|| {
        crate::Error::Usage(format!(
            "--position must be X,Y in mm (where the part's centre goes on the build field), got {text}"
        ))
    })?;
    Ok([v[0], v[1]])
}

/// Reads an STL from standard input (at most [`crate::mesh::MESH_MAX_BYTES`]). A reader
/// thread reads it, so that an interrupt stops the command even while no data comes.
fn read_stdin(cancel: &AtomicBool) -> Result<Vec<u8>, crate::Error> {
    use std::sync::mpsc::{channel, RecvTimeoutError};
    let max = crate::mesh::MESH_MAX_BYTES;
    if std::io::stdin().is_terminal() {
        return Err(crate::Error::Usage(
            "part - reads an STL from stdin, but stdin is a terminal: pipe or redirect a file into it (dmdsl slice - -o part.dmdjob < part.stl)".into(),
        ));
    }
    let (tx, rx) = channel();
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let r = std::io::stdin()
            .lock()
            .take(max + 1)
            .read_to_end(&mut bytes);
        let _ = tx.send(r.map(|_| bytes));
    });
    loop {
        match rx.recv_timeout(std::time::Duration::from_millis(50)) {
            Ok(Ok(bytes)) if bytes.len() as u64 > max => {
                return Err(crate::Error::input(
                    STDIN_NAME,
                    format!("is more than the {max} bytes a mesh file may have"),
                ))
            }
            Ok(Ok(bytes)) => return Ok(bytes),
            Ok(Err(e)) => return Err(crate::Error::io(STDIN_NAME, e)),
            Err(RecvTimeoutError::Timeout) if cancel.load(Ordering::Relaxed) => {
                return Err(crate::Error::Interrupted)
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                return Err(crate::Error::io(
                    STDIN_NAME,
                    std::io::Error::other("the reader stopped"),
                ))
            }
        }
    }
}
