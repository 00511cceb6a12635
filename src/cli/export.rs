//! `dmdsl export`: a job (any form `run` reads) into another form (one zip, Prusa SL1/SL1S, the SLA
//! control-file standard); also the `--format` values `slice` shares.

use crate::formats::control::hardware::Hardware;
use crate::formats::Format;
use clap::Args;
use std::path::{Path, PathBuf};

pub(crate) const EXPORT_HELP: &str = "Examples:
  dmdsl export part.dmdjob -o part.sl1                  # for PrusaSlicer / UVtools
  dmdsl export part.dmdjob -o part.dmdjob.zip           # the bundle as one file
  dmdsl export part.dmdjob -o print.zip --format sla-control
  dmdsl export part.dmdjob.zip -o part.dmdjob           # back to a directory

The job is verified and replayed first, as `dmdsl run` does: a job with violations is not
converted (--force converts it anyway, the violations printed). Every PNG is written up to
its IEND chunk; an output whose images add up to more than --max-size (1 GiB) is refused,
naming its size, unless --force.

Exit codes:
  0    the file was written (what the format cannot carry is reported as warnings)
  1    the job has violations (nothing was written; with --force the file was written),
       or the file was written but a warning was denied (--deny-warnings, -W CODE=error)
  2    unreadable bundle, a format that cannot hold the job (SL1 with several
       projectors), a name and --format that disagree, a plain .zip without --format,
       an output above --max-size without --force; nothing was written
  130  interrupted: nothing was written";

/// Parses `--max-size`: bytes, or a number with K, M, G or T (powers of 1024).
fn size(s: &str) -> Result<u64, String> {
    let (digits, unit) = match s.find(|c: char| !c.is_ascii_digit()) {
        Some(i) => s.split_at(i),
        None => (s, ""),
    };
    let shift = match unit.to_ascii_uppercase().as_str() {
        "" | "B" => 0,
        "K" => 10,
        "M" => 20,
        "G" => 30,
        "T" => 40,
        _ => {
            return Err(format!(
                "{s:?}: a size in bytes, or with K, M, G or T (e.g. 2G)"
            ))
        }
    };
    let n: u64 = digits
        .parse()
        .map_err(|_| format!("{s:?}: expected a whole number of bytes, e.g. 2G"))?;
    n.checked_mul(1 << shift)
        .ok_or_else(|| format!("{s:?}: too large"))
}

/// What `--machine ARG` names: a hardware description (a JSON file that reads as the
/// SLA control-file standard's printer configuration), or a profile (a built-in name or a
/// TOML file) as its machine record.
pub(crate) fn machine_arg(
    arg: Option<&str>,
) -> Result<(Option<crate::bundle::Machine>, Option<Hardware>), crate::Error> {
    let Some(arg) = arg else {
        return Ok((None, None));
    };
    let path = Path::new(arg);
    // A .json name is a hardware description, also when it cannot be read (the error
    // names the file, not a profile).
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        return Ok((None, Some(Hardware::read(path)?)));
    }
    let p = crate::profile::Profile::resolve(arg)?;
    Ok((Some(crate::bundle::Machine::of(&p)), None))
}

/// Fits `profile` to the printer `path` describes before a job is sliced for it: its
/// projectors take the light engines' names and wavelengths, its stage the build
/// platform's limits where they are tighter (checked as a profile is), and a profile
/// whose images the engines cannot show is refused, naming the keys.
pub(crate) fn fit_profile(
    profile: &mut crate::profile::Profile,
    path: &Path,
) -> Result<(), crate::Error> {
    let hw = Hardware::read(path)?;
    let ps = profile.projector.iter_mut();
    name_engines(&hw, ps.map(|p| (&mut p.name, &mut p.wavelength_nm)));
    let mine = crate::bundle::Machine::of(profile);
    let theirs = hw.machine(&mine)?;
    let (a, b) = (&mine.stage, &theirs.stage);
    let mut tighter = Vec::new();
    for (key, v, hw_v, lower) in [
        (
            "stage.max_speed_mm_s",
            a.max_speed_mm_s.get(),
            b.max_speed_mm_s.get(),
            true,
        ),
        (
            "stage.max_accel_mm_s2",
            a.max_accel_mm_s2.get(),
            b.max_accel_mm_s2.get(),
            true,
        ),
        (
            "stage.travel_max_mm",
            a.travel_max_mm,
            b.travel_max_mm,
            true,
        ),
        (
            "stage.travel_min_mm",
            a.travel_min_mm,
            b.travel_min_mm,
            false,
        ),
    ] {
        if (lower && hw_v < v) || (!lower && hw_v > v) {
            let label = format!("--machine {} ({})", path.display(), theirs.label(key));
            tighter.push(crate::profile::Override::new(
                label,
                key,
                toml::Value::Float(hw_v),
            ));
        }
    }
    *profile = profile.with_overrides(&tighter)?;
    refuse(
        &hw,
        path,
        hw.check_projectors(&crate::bundle::Machine::of(profile)),
    )
}

/// Gives the projectors (their names and wavelengths) the light engines of `hw` that show
/// them ([`Hardware::name_engines`]).
fn name_engines<'a>(
    hw: &Hardware,
    projectors: impl Iterator<Item = (&'a mut String, &'a mut Option<u32>)>,
) {
    let projectors: Vec<_> = projectors.collect();
    let named = hw.name_engines(projectors.iter().map(|(n, w)| (n.to_string(), **w)));
    for ((name, nm), engine) in projectors.into_iter().zip(named) {
        (*name, *nm) = engine;
    }
}

/// An error naming the first of `problems` (and how many more) when there are any.
fn refuse(hw: &Hardware, path: &Path, problems: Vec<String>) -> Result<(), crate::Error> {
    let Some(first) = problems.first() else {
        return Ok(());
    };
    let more = match problems.len() - 1 {
        0 => String::new(),
        k => format!(" (and {k} more)"),
    };
    Err(crate::Error::Bundle {
        path: path.into(),
        msg: format!(
            "the printer {} cannot run this job: {first}{more}",
            hw.name()
        ),
    })
}

/// Fits the job to the printer `hw` describes before it is exported for it: its
/// projectors take the engines' names and wavelengths, and a job the printer cannot run
/// (a move beyond its build platform's limits, an image its engines cannot show) is
/// refused.
fn fit_job(job: &mut crate::formats::Job, hw: &Hardware, path: &Path) -> Result<(), crate::Error> {
    let ps = job.manifest.machine.projector.iter_mut();
    name_engines(hw, ps.map(|p| (&mut p.name, &mut p.wavelength_nm)));
    let mut on = job.manifest.clone();
    on.machine = hw.machine(&on.machine)?;
    let problems = crate::exec::hardware_check(job, hw)
        .into_iter()
        .chain(crate::exec::replay(&on))
        .map(|v| v.message)
        .collect();
    refuse(hw, path, problems)
}

/// The `--format` values: every [`Format`] by its name.
pub(crate) fn formats() -> impl clap::builder::TypedValueParser<Value = Format> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    let values = Format::ALL.map(|f| PossibleValue::new(f.name()).help(f.about()));
    PossibleValuesParser::new(values).map(|s| Format::parse(&s).expect("a possible value"))
}

#[derive(Args)]
pub(crate) struct ExportArgs {
    /// The job: a bundle directory, a zipped bundle, an SL1/SL1S file or a control-file
    /// zip (any form `dmdsl run` reads).
    bundle: PathBuf,
    /// The file to write; its name picks the format (NAME.dmdjob, NAME.dmdjob.zip,
    /// NAME.sl1, NAME.sl1s; a plain .zip needs --format). Replaced if it exists.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
    /// Form of the output [default: what the -o name says].
    #[arg(long, value_name = "FORMAT", value_parser = formats())]
    format: Option<Format>,
    /// Convert a job with violations (they are printed), and an output above --max-size.
    #[arg(long)]
    force: bool,
    /// The most bytes of images the output may hold without --force (K, M, G, T: powers
    /// of 1024).
    #[arg(long, value_name = "SIZE", default_value = "1G", value_parser = size)]
    max_size: u64,
    /// The printer's hardware description (the SLA control-file standard's
    /// hardware_config.json): the projectors take its light engines' names and wavelengths,
    /// and a job it cannot run (moves beyond its build platform's limits, images its
    /// engines cannot show) is refused, nothing written.
    #[arg(long, value_name = "HARDWARE.json")]
    machine: Option<PathBuf>,
    /// Print a machine-readable summary on stdout (one JSON object).
    #[arg(long)]
    pub(crate) json: bool,
    #[command(flatten)]
    warnings: super::WarningArgs,
}

/// Runs `dmdsl export`.
pub(crate) fn export(a: ExportArgs, quiet: bool) -> anyhow::Result<u8> {
    // First, so that an interrupt ends the command with its message and code 130 and
    // leaves nothing.
    let cancel = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    super::interrupt::on_interrupt(cancel.clone());
    let policy = a.warnings.policy(&[])?;
    let format = Format::for_output(a.format, &a.output)?;
    let mut job = crate::formats::open(&a.bundle)?;
    if let Some(path) = &a.machine {
        fit_job(&mut job, &Hardware::read(path)?, path)?;
    }
    crate::formats::check_fits(format, &job.manifest.machine, &a.output)?;
    // Verified as `run` verifies: a job `run` fails is not converted unless asked.
    let report = crate::exec::run_job(&mut job, &Default::default())?;
    let manifest = &job.manifest;
    let refused = !report.ok && !a.force;
    if !report.ok && !a.json && !quiet {
        let lines = crate::exec::report::render_violations(&report);
        let what = if refused {
            "not converted"
        } else {
            "converted anyway (--force)"
        };
        eprint!("dmdsl: {}: {what}: {lines}", printable(&a.bundle));
    }
    let warnings = if refused {
        Vec::new()
    } else {
        let max = (!a.force).then_some(a.max_size);
        let files = job.source.as_ref();
        let w =
            crate::formats::write_at_most(format, manifest, files, &a.output, Some(&cancel), max)?;
        policy.apply(&w)
    };
    let failed = !report.ok || crate::warning::any_error(&warnings);
    if a.json {
        super::print_json(&serde_json::json!({
            "ok": !failed,
            "written": !refused,
            "bundle": a.bundle,
            "output": a.output,
            "format": format.name(),
            "layers": manifest.layers.len(),
            "violations": report.violations,
            "warnings": warnings,
        }))?;
    } else if !quiet && !refused {
        super::print_warnings(&warnings, "");
        println!(
            "{}: {} of {} from {}",
            printable(&a.output),
            format.name(),
            crate::text::count(manifest.layers.len() as u64, "layer", "layers"),
            printable(&a.bundle)
        );
    }
    if refused {
        eprintln!("dmdsl: error: {}: the job has violations; nothing was written (--force converts it anyway)", printable(&a.bundle));
    }
    Ok(if failed { 1 } else { 0 })
}

/// A path as a summary line shows it: control characters as escapes, as in errors.
fn printable(p: &std::path::Path) -> String {
    super::process::printable(&p.display().to_string())
}
