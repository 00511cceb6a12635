//! The command line: one file per command (its arguments and what it does); this file
//! holds the top-level parser and the dispatch.

mod calibrate;
mod completions;
mod distortion;
mod export;
mod help;
mod inspect;
mod interrupt;
mod man;
mod process;
mod profile;
mod psf;
mod run;
mod slice;
mod testjob;

pub use process::main;

use crate::warning::{Policy, Warning};
use clap::{Args, Parser, Subcommand};
use serde::Serialize;

/// Version of the `--json` outputs' schemas (`docs/JSON.md`); every `--json` object carries
/// it as `schema_version`.
pub(crate) const SCHEMA_VERSION: u32 = 1;

/// A `--json` object: `schema_version` first, then the command's fields.
#[derive(Serialize)]
struct Versioned<'a, T: Serialize> {
    schema_version: u32,
    #[serde(flatten)]
    body: &'a T,
}

/// Prints `body` as one pretty-printed JSON object on stdout, with `schema_version`.
pub(crate) fn print_json<T: Serialize>(body: &T) -> anyhow::Result<()> {
    let v = Versioned {
        schema_version: SCHEMA_VERSION,
        body,
    };
    println!("{}", serde_json::to_string_pretty(&v)?);
    Ok(())
}

/// What failed, in a `--json` object's `error`: the error's code, its file and message.
#[derive(Serialize)]
pub(crate) struct Failure<'a> {
    pub(crate) code: &'a str,
    pub(crate) file: Option<String>,
    pub(crate) message: &'a str,
}

/// The JSON object of a failure: `{schema_version, ok: false, error: {code, file,
/// message}}` (one line).
pub(crate) fn error_json(code: &str, file: Option<String>, message: &str) -> String {
    #[derive(Serialize)]
    struct Out<'a> {
        schema_version: u32,
        ok: bool,
        error: Failure<'a>,
    }
    let error = Failure {
        code,
        file,
        message,
    };
    let out = Out {
        schema_version: SCHEMA_VERSION,
        ok: false,
        error,
    };
    serde_json::to_string(&out).expect("serializes")
}

/// The format a picture path asks for (`.png`, `.jpg`, `.jpeg`); anything else is a usage
/// error naming the path and its extension.
pub(crate) fn picture_format(path: &std::path::Path) -> Result<crate::plot::Format, crate::Error> {
    crate::plot::Format::from_path(path).map_err(crate::Error::Usage)
}

/// The options that decide which warnings fail a command or are silenced.
#[derive(Args, Clone, Default)]
pub(crate) struct WarningArgs {
    /// Exit with code 1 when a warning (severity warning, not a note) is raised; the
    /// output is still written. Same as -W all=error.
    #[arg(long)]
    deny_warnings: bool,
    /// What to do with warnings of CODE (a code such as plan.unsupported-islands, an area
    /// such as mesh, or all): error (exit 1), warn, or allow (silence). Repeatable; a code
    /// beats an area beats all. Any unknown CODE lists the codes.
    #[arg(short = 'W', value_name = "CODE=error|warn|allow")]
    warn: Vec<String>,
}

impl WarningArgs {
    /// The policy these options give, after `extra` rules (e.g. `--strict`'s).
    pub(crate) fn policy(&self, extra: &[&str]) -> Result<Policy, crate::Error> {
        let mut p = Policy::default();
        if self.deny_warnings {
            p.deny_warnings();
        }
        for r in extra
            .iter()
            .copied()
            .chain(self.warn.iter().map(String::as_str))
        {
            p.add(r).map_err(crate::Error::Usage)?;
        }
        Ok(p)
    }
}

/// Build-job compiler for DMD mask-projection stereolithography.
#[derive(Parser)]
#[command(name = "dmdsl", version, about, after_help = help::join(help::TOP, help::TOP_EXIT))]
pub(crate) struct Cli {
    /// Print nothing but errors.
    #[arg(short, long, global = true)]
    pub(crate) quiet: bool,
    #[command(subcommand)]
    pub(crate) cmd: Cmd,
}

#[derive(Subcommand)]
pub(crate) enum Cmd {
    /// Slice parts (STL or OBJ) into job bundles of mask PNGs and a manifest, one each.
    #[command(after_help = help::join(help::SLICE, slice::SLICE_EXIT_HELP))]
    Slice(Box<slice::SliceArgs>),
    /// Show or list machine profiles.
    #[command(subcommand, after_help = help::PROFILE)]
    Profile(profile::ProfileCmd),
    /// Dry-run a job bundle: verify its masks, replay its steps on a simulated stage,
    /// shutter and DMD, and report the time and every violation.
    #[command(after_help = help::join(help::RUN, run::RUN_EXIT_HELP))]
    Run(run::RunArgs),
    /// Fit a light-uniformity calibration (E = P(x,y)·S(g)) to irradiance measurements.
    #[command(after_help = help::join(help::CALIBRATE, calibrate::CALIBRATE_EXIT_HELP))]
    #[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
    Calibrate(calibrate::CalibrateArgs),
    /// Fit a distortion correction table and report its quality (and optionally plot it).
    #[command(after_help = help::join(help::DISTORTION, distortion::DISTORTION_EXIT_HELP))]
    Distortion(distortion::DistortionArgs),
    /// Make a calibration test job and the measurement sheet beside it (docs/CALIBRATION.md).
    #[command(subcommand, after_help = testjob::TESTJOB_HELP)]
    Testjob(testjob::TestjobCmd),
    /// Write a job bundle in another form: one zip, Prusa SL1/SL1S, or the SLA
    /// control-file standard.
    #[command(after_help = export::EXPORT_HELP)]
    Export(export::ExportArgs),
    /// Summarize a job bundle (layers, time, resin, warnings, per-layer extremes) and draw
    /// it: a contact sheet of layer masks, a per-layer chart, a shaded preview of the part.
    #[command(after_help = inspect::INSPECT_EXIT_HELP)]
    Inspect(inspect::InspectArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    #[command(after_help = help::COMPLETIONS)]
    Completions(completions::CompletionsArgs),
    /// Print a man page (roff): dmdsl(1), or dmdsl-COMMAND(1) for one command.
    #[command(after_help = help::MAN)]
    Man(man::ManArgs),
}

/// Prints warnings on stderr, one line each: `dmdsl: warning: MESSAGE [CODE]` (or `note:`,
/// `error:`), after `prefix` (e.g. the part's name when several are sliced).
pub(crate) fn print_warnings(warnings: &[Warning], prefix: &str) {
    use crate::warning::Severity;
    for w in warnings {
        let label = match w.severity {
            Severity::Note => "note",
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        eprintln!("dmdsl: {label}: {prefix}{w}");
    }
}

impl Cli {
    /// True when the command was asked for `--json` output.
    pub(crate) fn json(&self) -> bool {
        match &self.cmd {
            Cmd::Slice(a) => a.json,
            Cmd::Run(a) => a.json,
            Cmd::Calibrate(a) => a.json,
            Cmd::Distortion(a) => a.json,
            Cmd::Inspect(a) => a.json,
            Cmd::Export(a) => a.json,
            Cmd::Profile(_) | Cmd::Completions(_) | Cmd::Man(_) | Cmd::Testjob(_) => false,
        }
    }
}

/// Runs the command `cli` names; returns its exit code.
pub(crate) fn run(cli: Cli) -> anyhow::Result<u8> {
    match cli.cmd {
        Cmd::Slice(a) => slice::slice(*a, cli.quiet),
        Cmd::Distortion(a) => distortion::distortion(a, cli.quiet),
        Cmd::Run(a) => run::run_bundle(a, cli.quiet),
        Cmd::Calibrate(a) => calibrate::calibrate(a, cli.quiet),
        Cmd::Testjob(c) => testjob::testjob(c, cli.quiet),
        Cmd::Inspect(a) => inspect::inspect(a, cli.quiet),
        Cmd::Export(a) => export::export(a, cli.quiet),
        Cmd::Profile(c) => profile::profile(c),
        Cmd::Completions(a) => completions::completions(a),
        Cmd::Man(a) => man::man(a),
    }
}
