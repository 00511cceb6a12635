//! `dmdsl export`: a job (any form `run` reads) into another form (one zip, Prusa SL1/SL1S, the SLA
//! control-file standard); also the `--format` values `slice` shares.

use crate::formats::Format;
use clap::Args;
use std::path::PathBuf;

pub(crate) const EXPORT_HELP: &str = "Examples:
  dmdsl export part.dmdjob -o part.sl1                  # for PrusaSlicer / UVtools
  dmdsl export part.dmdjob -o part.dmdjob.zip           # the bundle as one file
  dmdsl export part.dmdjob -o print.zip --format sla-control
  dmdsl export part.dmdjob.zip -o part.dmdjob           # back to a directory

Exit codes:
  0    the file was written (what the format cannot carry is reported as warnings)
  1    the file was written, but a warning was denied (--deny-warnings, -W CODE=error)
  2    unreadable bundle, a format that cannot hold the job (SL1 with several
       projectors), a name and --format that disagree, a plain .zip without --format;
       nothing was written
  130  interrupted: nothing was written";

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
    /// Print a machine-readable summary on stdout (one JSON object).
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    warnings: super::WarningArgs,
}

impl ExportArgs {
    /// True when `--json` was given.
    pub(crate) fn json(&self) -> bool {
        self.json
    }
}

/// Runs `dmdsl export`.
pub(crate) fn export(a: ExportArgs, quiet: bool) -> anyhow::Result<u8> {
    // First, so that an interrupt ends the command with its message and code 130 and
    // leaves nothing.
    let cancel = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    super::interrupt::on_interrupt(cancel.clone());
    let policy = a.warnings.policy(&[])?;
    let format = Format::for_output(a.format, &a.output)?;
    let job = crate::formats::open(&a.bundle)?;
    let manifest = &job.manifest;
    crate::formats::check_fits(format, &manifest.machine, &a.output)?;
    let warnings = crate::formats::write(
        format,
        manifest,
        job.source.as_ref(),
        &a.output,
        Some(&cancel),
    )?;
    let warnings = policy.apply(&warnings);
    let failed = crate::warning::any_error(&warnings);
    if a.json {
        super::print_json(&serde_json::json!({
            "ok": !failed,
            "bundle": a.bundle,
            "output": a.output,
            "format": format.name(),
            "layers": manifest.layers.len(),
            "warnings": warnings,
        }))?;
    } else if !quiet {
        super::print_warnings(&warnings, "");
        println!(
            "{}: {} of {} layers from {}",
            a.output.display(),
            format.name(),
            manifest.layers.len(),
            a.bundle.display()
        );
    }
    Ok(if failed { 1 } else { 0 })
}
