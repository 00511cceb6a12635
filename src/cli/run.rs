//! `dmdsl run`: the dry-run executor.

use clap::Args;
use std::path::PathBuf;

pub(crate) const RUN_EXIT_HELP: &str = "Exit codes:
  0    the bundle verified and replayed without violations
  1    violations, bad masks or an injected fault
  2    unreadable bundle or archive (an unsafe zip entry included), a setting missing from
       an imported file, unknown or invalid --machine profile, or usage error

Fault kinds: stall, limit (limit switch hit), shutter-stuck (stuck open), mask-load.";

#[derive(Args)]
pub(crate) struct RunArgs {
    /// The job: a bundle directory (job.json and masks/), a zipped bundle (.dmdjob.zip), a
    /// PrusaSlicer .sl1/.sl1s file or an SLA control-file zip (found from the content).
    bundle: PathBuf,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Write the simulated timeline as CSV (time, stage, velocity, shutter, mask).
    #[arg(long, value_name = "FILE.csv")]
    trace: Option<PathBuf>,
    /// Write a picture of stage position and light over time: PNG or JPEG by the
    /// extension (.png, .jpg, .jpeg).
    #[arg(long, value_name = "FILE.png|FILE.jpg")]
    plot: Option<PathBuf>,
    /// Restrict --trace and --plot to layers A..B (inclusive, 0-based); needs one of them.
    #[arg(long, value_name = "A..B")]
    layers: Option<String>,
    /// Check the job against this machine instead of the one the bundle embeds: a
    /// built-in profile name or a TOML file. Its stage, shutter and DMD are simulated and
    /// its projectors' sizes and placement checked; the report names the keys in which it
    /// differs from the job's machine.
    #[arg(long, value_name = "PROFILE")]
    machine: Option<String>,
    /// Inject a fault: KIND@LAYER, KIND one of stall, limit, shutter-stuck, mask-load
    /// (repeatable).
    #[arg(long, value_name = "KIND@LAYER")]
    fault: Vec<String>,
    /// Predict what cures from the masks alone (the job's cure model: PSF, dose, depth)
    /// and report the edge offset, vanishing and merging islands and the print-through.
    /// Needs a job sliced with a profile that has psf_sigma_px, one projector. Findings
    /// do not change the exit code.
    #[arg(long)]
    cure: bool,
}

impl RunArgs {
    /// True when `--json` was given.
    pub(crate) fn json(&self) -> bool {
        self.json
    }
}

/// Runs `dmdsl run`.
pub(crate) fn run_bundle(a: RunArgs, quiet: bool) -> anyhow::Result<u8> {
    let faults = a
        .fault
        .iter()
        .map(|f| f.parse().map_err(crate::Error::Usage))
        .collect::<Result<Vec<_>, _>>()?;
    let machine = a
        .machine
        .as_deref()
        .map(crate::profile::Profile::resolve)
        .transpose()?
        .map(|p| crate::bundle::Machine::of(&p));
    let opts = crate::exec::RunOptions {
        faults,
        trace: a.trace,
        plot: a.plot,
        layers: a.layers,
        machine,
        cure: a.cure,
    };
    let report = crate::exec::run(&a.bundle, &opts)?;
    if a.json {
        super::print_json(&report)?;
    } else if !quiet {
        print!("{}", crate::exec::report::render_human(&report));
    }
    Ok(if report.ok { 0 } else { 1 })
}
