//! The dry-run executor behind `dmdsl run`: replays a job bundle against a simulated
//! lift stage, shutter and DMD.
//!
//! The executor reads only the bundle (`job.json` through [`crate::bundle::Manifest`] and
//! the mask files); the machine comes from the manifest's machine record
//! ([`crate::bundle::Machine`]), or from the record given as [`RunOptions::machine`]
//! (`--machine`, made from a profile) to check the job against the machine it will run on.
//! It shares nothing with the slicer and the planner except the bundle format, the cure
//! model's math of [`crate::cure`] and the pure trapezoid math of [`crate::motion`].
//! Stages:
//!
//! 1. [`verify`]: manifest structure and every mask (present, SHA-256, decodable PNG of
//!    the projector's size and bit depth, its own file, lit where the layer's section is
//!    and enough for its area) and gray map, all problems collected, in parallel; each
//!    layer's lit pixels on the field kept as runs.
//! 2. [`printable`]: the regions of each layer resting on nothing below, from those runs
//!    in one pass over consecutive layers: a warning, or a violation for a job compiled
//!    with supports.
//! 3. [`sim`]: event-based simulation of the steps under the bundle's timing contract,
//!    with optional fault injection, streaming [`sim::Segment`]s to sinks.
//! 4. Sinks: [`check::Checker`] (invariants → violations), [`report::Stats`],
//!    [`trace::TraceWriter`] (`--trace`), [`report::PlotCollector`] (`--plot`).
//! 5. With `--cure`, [`cure`]: what cures, predicted from the masks alone (the model of
//!    [`crate::cure`]), once the masks verified; information, never a violation.
//! 6. [`report::Report`]: the summary, `--json`, exit status.
//!
//! [`testutil`] builds manifests by hand for the executor's tests and benchmarks.
//!
//! See `docs/EXECUTOR.md` for the model and every check.

pub mod check;
pub mod cure;
pub mod printable;
pub mod report;
pub mod sim;
pub mod trace;
pub mod verify;
mod violation;

#[cfg(any(test, feature = "internals"))]
pub mod testutil;

use crate::bundle::regions::Run;
use crate::bundle::Machine as MachineRecord;
use crate::bundle::{BundleSource, Manifest, MANIFEST};
use crate::error::{Error, Result};
use crate::formats::control::hardware::Hardware;
use crate::output::write_atomic;
use crate::plot::Format;
pub use printable::UnsupportedRegion;
use report::{LayerTiming, MachineCheck, PlotCollector, Report, Stats, Timings};
use sim::{FaultSpec, Machine, Sink};
use std::collections::BTreeMap;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::time::Instant;
pub use violation::{Kind, Violation};

/// What to do besides verifying and simulating.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Faults to inject.
    pub faults: Vec<FaultSpec>,
    /// Write the timeline as CSV here.
    pub trace: Option<PathBuf>,
    /// Write a picture of stage position and light over time here (PNG, or JPEG for a
    /// `.jpg`/`.jpeg` path).
    pub plot: Option<PathBuf>,
    /// Restrict the trace and the plot to these layers, e.g. "10..20" (inclusive).
    pub layers: Option<String>,
    /// Check the job against this machine instead of the manifest's: its stage, shutter
    /// and DMD are simulated, its projectors' sizes and placement verified (`--machine`:
    /// [`MachineRecord::of`] a profile).
    pub machine: Option<MachineRecord>,
    /// Predict what cures from the masks (`--cure`, `exec::cure`): needs the manifest's `cure`
    /// record and one projector.
    pub cure: bool,
    /// A printer's hardware description (`--machine hardware_config.json`, the SLA
    /// control-file standard's): its build platform is the stage the job runs on, and what
    /// the job's exposures ask of its light engines is checked (`hardware` violations).
    pub hardware: Option<Hardware>,
    /// Changes to keys of the machine record the job runs on (`--set`), applied last.
    pub set: Vec<crate::profile::Override>,
}

/// Parses a layer range for a job of `n` layers: `A..B` or `A..=B` (both inclusive),
/// `A..`, `..B`, or a single `A`.
pub fn parse_layer_range(s: &str, n: usize) -> Result<RangeInclusive<usize>> {
    let bad = |why: &str| Error::Usage(format!("--layers {s:?}: {why}"));
    if n == 0 {
        return Err(bad("the job has no layers"));
    }
    let num = |t: &str, default: usize| -> Result<usize> {
        let t = t.trim();
        if t.is_empty() {
            Ok(default)
        } else {
            t.parse()
                .map_err(|_| bad("expected A..B with layer indices, e.g. 10..20"))
        }
    };
    let (a, b) = match s.split_once("..") {
        Some((a, b)) => (num(a, 0)?, num(b.strip_prefix('=').unwrap_or(b), n - 1)?),
        None => {
            let a = num(s, usize::MAX)?;
            (a, a)
        }
    };
    if a > b {
        return Err(bad("the first layer is after the last"));
    }
    if b >= n {
        return Err(bad(&format!("the job has layers 0..{}", n - 1)));
    }
    Ok(a..=b)
}

/// Verifies and simulates the job at `path` — a bundle directory, a zipped bundle, an
/// SL1/SL1S file or an SLA control-file zip ([`crate::formats::open`]) — on the machine the
/// manifest embeds (for an imported job, the machine the file implies) or on
/// [`RunOptions::machine`].
///
/// Errors (exit code 2) are an unreadable bundle, archive or manifest, an invalid machine
/// profile (the one simulated), bad options, or a trace/plot file that cannot be written.
/// Problems with the job itself are [`Violation`]s in the report.
pub fn run(path: &Path, opts: &RunOptions) -> Result<Report> {
    let t0 = Instant::now();
    let mut job = crate::formats::open(path)?;
    let open_s = t0.elapsed().as_secs_f64();
    let mut report = run_job(&mut job, opts)?;
    report.timings.read_s += open_s;
    Ok(report)
}

/// [`run`] on a job opened already ([`crate::formats::open`]): what `dmdsl export`
/// verifies before it converts a job. An imported job's records are rescaled when the
/// options give another pixel size.
pub fn run_job(job: &mut crate::formats::Job, opts: &RunOptions) -> Result<Report> {
    let t0 = Instant::now();
    let native = matches!(
        job.format,
        crate::formats::Format::Dmdjob | crate::formats::Format::DmdjobZip
    );
    let given = run_machine(job, opts, native)?;
    let hardware = opts
        .hardware
        .as_ref()
        .map_or(Vec::new(), |h| hardware_check(job, h));
    let (format, source, estimate) = (job.format, job.source.as_ref(), &job.estimate);
    let mut notes = job.notes.clone();
    let manifest = job.manifest.clone();
    // A native manifest was checked as it was read; an importer's is checked here.
    manifest.check_numbers().map_err(|msg| Error::Bundle {
        path: job.path.clone(),
        msg,
    })?;
    let (mut manifest, range, machine_check) = check_options(manifest, source, opts, &given)?;
    let cure_model = opts
        .cure
        .then(|| cure::model_of(&manifest, source))
        .transpose()?;
    let read_s = t0.elapsed().as_secs_f64();
    let dir = job.path.as_path();

    let t1 = Instant::now();
    let machine = given.as_ref().map_or(&manifest.machine, |g| &g.0);
    let mut verified = verify::verify_source(source, &manifest, machine, native);
    // The regions resting on nothing below, from the runs the masks' decoding left.
    let printable = printable::check(source, &manifest, machine, &verified.runs);
    verified.runs = Vec::new();
    verified.problems.extend(printable.violations);
    verified
        .problems
        .sort_by_key(|p| p.layer.map_or(0, |l| l + 1));
    verified.problems.extend(hardware);
    let verify_s = t1.elapsed().as_secs_f64();
    let t3 = Instant::now();
    // The cure from the masks, once every mask and gray map read as recorded (a
    // `mask-content` problem does not stop it), under the job's own machine (its
    // exposure, calibration and projector).
    let unreadable = verified.problems.iter().any(|p| {
        !matches!(
            p.kind,
            Kind::MaskContent | Kind::Hardware | Kind::UnsupportedRegion
        )
    });
    let (cure, cure_skipped) = match &cure_model {
        Some(model) if !unreadable => (Some(cure::check(&manifest, source, model)?), None),
        Some(_) => (
            None,
            Some("masks, gray maps or the manifest failed verification".to_string()),
        ),
        None => (None, None),
    };
    let cure_s = t3.elapsed().as_secs_f64();
    // An imported job's timing has no shutter or DMD latency: a machine that adds some is
    // not held against the file's own times.
    let latency =
        |m: &MachineRecord| m.shutter.open_s.get() + m.shutter.close_s.get() + m.dmd.load_s.get();
    let check_estimate = native
        || given
            .as_ref()
            .is_none_or(|g| latency(&g.0) <= latency(&manifest.machine));
    if !check_estimate {
        notes.push("estimate: not checked: the file's own timing has no shutter or DMD latency, the machine's are simulated".into());
    }
    if let Some((m, _)) = given {
        // From here on the job runs on the given machine.
        manifest.machine = m;
    }

    let t2 = Instant::now();
    let mut simulated = simulate_into_sinks(dir, &manifest, opts, (range, check_estimate))?;
    let timeline = std::mem::take(&mut simulated.timeline);
    let violations = all_violations(verified.problems, timeline, &simulated.outcome);
    let simulate_s = t2.elapsed().as_secs_f64();

    let timings = Timings {
        read_s,
        verify_s,
        simulate_s,
        cure_s,
    };
    let estimate_source = match (estimate, native) {
        (Some(e), _) => e.source.clone(),
        (None, true) => "planner".into(),
        (None, false) => "import steps".into(),
    };
    let mut report = report(
        (dir, format.name(), estimate_source),
        &manifest,
        machine_check,
        verified.masks,
        simulated,
        violations,
        timings,
    );
    report.cure = cure;
    report.cure_skipped = cure_skipped;
    report.unsupported_regions = printable.regions;
    report.warnings = printable.warning.into_iter().collect();
    report.notes = notes;
    Ok(report)
}

/// The machine the job runs on when the options change it (`--machine`, a hardware
/// description, `--set`), and which options gave it. An imported job's records are
/// rescaled when it gives another pixel size (the same pixels, now known to be that big).
fn run_machine(
    job: &mut crate::formats::Job,
    opts: &RunOptions,
    native: bool,
) -> Result<Option<(MachineRecord, &'static str)>> {
    let given = match (
        opts.machine.is_some() || opts.hardware.is_some(),
        opts.set.is_empty(),
    ) {
        (false, true) => return Ok(None),
        (true, true) => "--machine",
        (false, false) => "--set",
        (true, false) => "--machine, --set",
    };
    let build = |own: &MachineRecord| -> Result<MachineRecord> {
        let mut m = opts.machine.clone().unwrap_or_else(|| own.clone());
        if let Some(h) = &opts.hardware {
            m = h.machine(&m)?;
        }
        match opts.set.is_empty() {
            true => Ok(m),
            false => m.with_overrides(&opts.set),
        }
    };
    let mut m = build(&job.manifest.machine)?;
    let pixel = |m: &MachineRecord| m.projector.first().map(|p| p.pixel_mm.get());
    if let (false, Some(p)) = (native, pixel(&m)) {
        if pixel(&job.manifest.machine) != Some(p) {
            crate::formats::rescale(&mut job.manifest, p);
            m = build(&job.manifest.machine)?;
        }
    }
    Ok(Some((m, given)))
}

/// What `job` asks of the light engines and vacuum of the printer `h` describes that it
/// lacks (`hardware` violations, at no time yet); a native job's projectors take the
/// engines [`Hardware::engine_of`] gives them.
pub fn hardware_check(job: &crate::formats::Job, h: &Hardware) -> Vec<Violation> {
    let mut requests = job.requests();
    if job.requests.is_empty() {
        let projectors = &job.manifest.machine.projector;
        for r in &mut requests {
            if let Some(k) = projectors.iter().position(|p| p.name == r.engine) {
                if let Some((engine, nm)) = h.engine_of(&r.engine, k) {
                    r.engine = engine.into();
                    r.wavelength_nm = r.wavelength_nm.or(nm);
                }
            }
        }
    }
    h.check(&requests, job.vacuum)
        .into_iter()
        .map(|f| Violation {
            layer: f.layer,
            time_s: None,
            kind: Kind::Hardware,
            message: f.message,
            file: f.file,
        })
        .collect()
}

/// The manifest, the layer range of the trace and the plot, and with `--machine` how the
/// given machine differs from the embedded one.
type ReadBundle = (
    Manifest,
    Option<RangeInclusive<usize>>,
    Option<MachineCheck>,
);

/// Checks the machine record the job will be simulated on (the manifest's, or the
/// `given` one) and the options against it, and parses the layer range of the trace and
/// the plot.
fn check_options(
    manifest: Manifest,
    source: &dyn BundleSource,
    opts: &RunOptions,
    given: &Option<(MachineRecord, &'static str)>,
) -> Result<ReadBundle> {
    let machine_check = match given {
        None => {
            manifest.machine.validate().map_err(|msg| Error::Bundle {
                path: source.shown(MANIFEST),
                msg: format!("machine: {msg}"),
            })?;
            None
        }
        Some((p, by)) => {
            p.validate().map_err(|msg| Error::Profile {
                origin: p.name.clone(),
                msg,
            })?;
            Some(MachineCheck {
                profile: p.name.clone(),
                given: by,
                differences: manifest.machine.differences(p),
            })
        }
    };
    let n = manifest.layers.len();
    for f in &opts.faults {
        if f.layer >= n {
            return Err(Error::Usage(format!(
                "--fault {}@{}: the job has {} (0..{})",
                f.kind,
                f.layer,
                crate::text::count(n as u64, "layer", "layers"),
                n.saturating_sub(1)
            )));
        }
    }
    if opts.layers.is_some() && opts.trace.is_none() && opts.plot.is_none() {
        return Err(Error::Usage(
            "--layers applies to --trace and --plot; give one of them".into(),
        ));
    }
    if let Some(p) = &opts.plot {
        Format::from_path(p).map_err(Error::Usage)?;
    }
    let range = opts
        .layers
        .as_deref()
        .map(|s| parse_layer_range(s, n))
        .transpose()?;
    Ok((manifest, range, machine_check))
}

/// What the simulation and its sinks gave.
struct Simulated {
    outcome: sim::Outcome,
    stats: Stats,
    /// The checker's violations, the invalid steps and the fault, in time order.
    timeline: Vec<Violation>,
}

/// Simulates the job into the checker, the statistics and, when asked, the trace and the
/// plot, which are written.
fn simulate_into_sinks(
    dir: &Path,
    manifest: &Manifest,
    opts: &RunOptions,
    (range, estimate): (Option<RangeInclusive<usize>>, bool),
) -> Result<Simulated> {
    let machine = Machine::of(&manifest.machine);
    let mut trace = opts
        .trace
        .as_deref()
        .map(|p| trace::TraceWriter::create(p, range.clone(), machine))
        .transpose()?;
    let mut plot = opts
        .plot
        .as_ref()
        .map(|_| PlotCollector::new(range.clone()));
    let mut checker = check::Checker::new(manifest);
    checker.estimate = estimate;
    let mut stats = Stats::default();
    let outcome = {
        let mut sinks: Vec<&mut dyn Sink> = vec![&mut checker, &mut stats];
        if let Some(t) = trace.as_mut() {
            sinks.push(t);
        }
        if let Some(p) = plot.as_mut() {
            sinks.push(p);
        }
        sim::simulate(manifest, &opts.faults, &mut sinks)
    };
    let completed = outcome.fault.is_none();
    let mut timeline = checker.finish(outcome.total_s, completed);
    timeline.extend(outcome.invalid_steps.iter().cloned());
    if let Some(f) = &outcome.fault {
        timeline.push(Violation {
            layer: Some(f.layer),
            time_s: Some(f.time_s),
            kind: f.kind.into(),
            message: f.message.clone(),
            file: None,
        });
    }
    timeline.sort_by(|a, b| {
        a.time_s
            .unwrap_or(f64::INFINITY)
            .total_cmp(&b.time_s.unwrap_or(f64::INFINITY))
    });
    if let Some(t) = trace.take() {
        t.finish()?;
    }
    if let (Some(p), Some(path)) = (plot, opts.plot.as_deref()) {
        let name = dir
            .file_name()
            .map_or(String::new(), |s| s.to_string_lossy().into_owned());
        let layers = range.map_or(String::new(), |r| {
            format!(", layers {}–{}", r.start(), r.end())
        });
        let title = format!("{name}: stage position and light over time{layers}");
        let format = Format::from_path(path).map_err(Error::Usage)?;
        write_atomic(path, &p.render(&title).encode(format))?;
    }
    Ok(Simulated {
        outcome,
        stats,
        timeline,
    })
}

/// The verification problems (each given the time its layer starts), then the
/// simulation's `timeline`.
fn all_violations(
    problems: Vec<Violation>,
    timeline: Vec<Violation>,
    outcome: &sim::Outcome,
) -> Vec<Violation> {
    let mut violations = problems;
    for v in &mut violations {
        v.time_s = v
            .layer
            .and_then(|l| outcome.layers.get(l))
            .map(|r| r.start_s);
    }
    violations.extend(timeline);
    violations
}

/// The report of a run.
fn report(
    (dir, format, estimate_source): (&Path, &'static str, String),
    manifest: &Manifest,
    machine: Option<MachineCheck>,
    masks_verified: usize,
    simulated: Simulated,
    violations: Vec<Violation>,
    timings: Timings,
) -> Report {
    let Simulated { outcome, stats, .. } = simulated;
    let mut counts = BTreeMap::new();
    for v in &violations {
        *counts.entry(v.kind.name()).or_insert(0) += 1;
    }
    let per_layer = outcome
        .layers
        .iter()
        .map(|r| {
            let l = &manifest.layers[r.index];
            LayerTiming {
                index: r.index,
                start_s: r.start_s,
                time_s: r.time_s,
                estimate_s: l.time_s,
                light_s: r.light_s,
                exposure_s: l.exposure_s,
            }
        })
        .collect();
    let estimate_s = manifest.totals.print_time_s;
    Report {
        bundle: dir.display().to_string(),
        format,
        estimate_source,
        machine,
        layers: manifest.layers.len(),
        layers_completed: outcome.layers.iter().filter(|r| r.completed).count(),
        masks_verified,
        total_s: outcome.total_s,
        estimate_s,
        estimate_diff_pct: check::pct(outcome.total_s, estimate_s),
        exposure_s: manifest.layers.iter().map(|l| l.exposure_s).sum(),
        light_on_s: stats.light_on_s,
        shutter_open_s: stats.shutter_open_s,
        wait_s: stats.wait_s,
        load_wait_s: stats.load_wait_s,
        stage_travel_mm: stats.travel_mm,
        stage_range_mm: stats.range_mm,
        peak_speed_mm_s: stats.peak_speed_mm_s,
        ok: violations.is_empty() && outcome.fault.is_none(),
        fault: outcome.fault,
        untriggered_faults: outcome
            .untriggered
            .iter()
            .map(|f| format!("{}@{}", f.kind, f.layer))
            .collect(),
        violations,
        violation_counts: counts,
        per_layer,
        timings,
        cure: None,
        cure_skipped: None,
        unsupported_regions: Vec::new(),
        warnings: Vec::new(),
        unchecked: [
            "stage.travel_max_mm",
            "stage.max_speed_mm_s",
            "stage.max_accel_mm_s2",
            "projector[].pixel_mm",
        ]
        .into_iter()
        .filter(|k| !manifest.machine.states(k))
        .map(String::from)
        .collect(),
        notes: Vec::new(),
    }
}

/// Simulates a manifest's steps without reading any mask: the invariants and timing checks
/// of [`run`] (a broken step, a move outside the travel or faster than the stage, light
/// while moving, an estimate off by more than 1 %, …), for a job before it is written.
/// Empty when the job replays clean.
pub fn replay(manifest: &Manifest) -> Vec<Violation> {
    let mut checker = check::Checker::new(manifest);
    let outcome = {
        let mut sinks: Vec<&mut dyn Sink> = vec![&mut checker];
        sim::simulate(manifest, &[], &mut sinks)
    };
    let mut violations = checker.finish(outcome.total_s, outcome.fault.is_none());
    violations.extend(outcome.invalid_steps.iter().cloned());
    violations
}

/// The regions [`run`] finds on nothing in a job with supports ([`unheld_regions`]).
#[derive(Debug, Default)]
pub struct Unheld {
    /// One `unsupported-region` violation per layer that has such regions, in layer order.
    pub violations: Vec<Violation>,
    /// Each such region: its layer and the box of its pixels on the field (first column,
    /// first row, end column, end row).
    pub regions: Vec<(usize, [u32; 4])>,
}

/// What [`run`] finds of a job with supports before it is written (`source`: its files
/// so far; `runs`: each layer's lit runs on the field, as
/// [`crate::bundle::regions::lit_runs`] finds them in its masks): the regions as large as
/// a support head's contact that rest on nothing in the layer below (on a corrected job,
/// by what cures). Empty for a job without supports.
pub fn unheld_regions<R: AsRef<[Run]>>(
    source: &dyn BundleSource,
    manifest: &Manifest,
    runs: &[Option<R>],
) -> Unheld {
    if manifest.supports.is_none() {
        return Unheld::default();
    }
    let p = printable::check(source, manifest, &manifest.machine, runs);
    Unheld {
        violations: p.violations,
        regions: p.held,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layer_ranges() {
        assert_eq!(parse_layer_range("2..5", 10).unwrap(), 2..=5);
        assert_eq!(parse_layer_range("2..=5", 10).unwrap(), 2..=5);
        assert_eq!(parse_layer_range("7..", 10).unwrap(), 7..=9);
        assert_eq!(parse_layer_range("..3", 10).unwrap(), 0..=3);
        assert_eq!(parse_layer_range("4", 10).unwrap(), 4..=4);
        for bad in ["5..2", "0..10", "x..3", "", "10"] {
            let e = parse_layer_range(bad, 10).unwrap_err().to_string();
            assert!(e.starts_with("--layers"), "{bad}: {e}");
        }
    }
}
