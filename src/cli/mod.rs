//! The command line: one file per command (its arguments and what it does); this file
//! holds the top-level parser and the dispatch.

mod calibrate;
mod distortion;
mod profile;
mod run;
mod slice;

use clap::{Parser, Subcommand};

pub(crate) const EXIT_HELP: &str = "Exit codes:
  0    success
  1    finished, but checks failed (slice --strict with mesh defects)
  2    usage or input error (bad file, bad profile, part does not fit)
  130  interrupted (Ctrl-C); nothing was written";

/// Build-job compiler for DMD mask-projection stereolithography.
#[derive(Parser)]
#[command(name = "dmdsl", version, about, after_help = EXIT_HELP)]
pub(crate) struct Cli {
    /// Print nothing but errors.
    #[arg(short, long, global = true)]
    pub(crate) quiet: bool,
    #[command(subcommand)]
    pub(crate) cmd: Cmd,
}

#[derive(Subcommand)]
pub(crate) enum Cmd {
    /// Slice a part (STL or OBJ) into a job bundle of mask PNGs and a manifest.
    #[command(after_help = EXIT_HELP)]
    Slice(slice::SliceArgs),
    /// Show or list machine profiles.
    #[command(subcommand)]
    Profile(profile::ProfileCmd),
    /// Dry-run a job bundle: verify its masks, replay its steps on a simulated stage,
    /// shutter and DMD, and report the time and every violation.
    #[command(after_help = run::RUN_EXIT_HELP)]
    Run(run::RunArgs),
    /// Fit a light-uniformity calibration (E = P(x,y)·S(g)) to irradiance measurements.
    #[command(after_help = EXIT_HELP)]
    Calibrate(calibrate::CalibrateArgs),
    /// Fit a distortion correction table and report its quality (and optionally plot it).
    #[command(after_help = EXIT_HELP)]
    Distortion(distortion::DistortionArgs),
}

/// Prints warnings on stderr, one line each: `dmdsl: warning: MESSAGE [CODE]` (or `note:`).
pub(crate) fn print_warnings(warnings: &[dmdsl::warning::Warning]) {
    use dmdsl::warning::Severity;
    for w in warnings {
        let label = match w.severity {
            Severity::Note => "note",
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        eprintln!("dmdsl: {label}: {w}");
    }
}

/// Runs the command `cli` names; returns its exit code.
pub(crate) fn run(cli: Cli) -> anyhow::Result<u8> {
    match cli.cmd {
        Cmd::Slice(a) => slice::slice(a, cli.quiet),
        Cmd::Distortion(a) => distortion::distortion(a, cli.quiet),
        Cmd::Run(a) => run::run_bundle(a, cli.quiet),
        Cmd::Calibrate(a) => calibrate::calibrate(a, cli.quiet),
        Cmd::Profile(c) => profile::profile(c),
    }
}
