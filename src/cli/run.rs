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
    pub(crate) json: bool,
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
    /// built-in profile name, a TOML profile, or the SLA control-file standard's hardware
    /// description (hardware_config.json: its build platform is the stage, and every
    /// image's light engine, wavelength, size and offset are checked). The report names
    /// the keys in which it differs from the job's machine.
    #[arg(long, value_name = "PROFILE|HARDWARE.json")]
    machine: Option<String>,
    /// Change one key of the machine the job runs on, as slice's --set names it (e.g.
    /// --set projector.0.pixel_mm=0.05, --set stage.max_speed_mm_s=30; repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    set: Vec<String>,
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

/// Runs `dmdsl run`.
pub(crate) fn run_bundle(a: RunArgs, quiet: bool) -> anyhow::Result<u8> {
    let faults = a
        .fault
        .iter()
        .map(|f| f.parse().map_err(crate::Error::Usage))
        .collect::<Result<Vec<_>, _>>()?;
    let (machine, hardware) = super::export::machine_arg(a.machine.as_deref())?;
    let set = a
        .set
        .iter()
        .map(|s| crate::profile::Override::parse_set(s))
        .collect::<Result<Vec<_>, _>>()?;
    let opts = crate::exec::RunOptions {
        faults,
        trace: a.trace,
        plot: a.plot,
        layers: a.layers,
        machine,
        cure: a.cure,
        hardware,
        set,
    };
    let report = crate::exec::run(&a.bundle, &opts)?;
    if a.json {
        super::print_json(&report)?;
    } else if !quiet {
        print!("{}", crate::exec::report::render_human(&report));
    }
    Ok(if report.ok { 0 } else { 1 })
}
