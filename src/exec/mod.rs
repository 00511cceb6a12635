//! The dry-run executor behind `dmdsl run`: replays a job bundle against a simulated
//! lift stage, shutter and DMD.
//!
//! The executor reads only the bundle (`job.json` through [`crate::bundle::Manifest`] and
//! the mask files); the machine comes from the resolved profile embedded in the manifest.
//! It shares nothing with the slicer and the planner except the bundle format and the
//! pure trapezoid math of [`crate::motion`]. Stages:
//!
//! 1. [`verify`]: manifest structure and every mask (present, SHA-256, decodable PNG of
//!    the projector's size and bit depth), all problems collected, in parallel.
//! 2. [`sim`]: event-based simulation of the steps under the bundle's timing contract,
//!    with optional fault injection, streaming [`sim::Segment`]s to sinks.
//! 3. Sinks: [`check::Checker`] (invariants → violations), [`report::Stats`],
//!    [`trace::TraceWriter`] (`--trace`), [`report::PlotCollector`] (`--plot`).
//! 4. [`report::Report`]: the summary, `--json`, exit status.
//!
//! [`testutil`] builds manifests by hand for the executor's tests and benchmarks.
//!
//! See `docs/EXECUTOR.md` for the model and every check.

pub mod check;
pub mod report;
pub mod sim;
pub mod trace;
pub mod verify;

pub mod testutil;

use crate::bundle::{Manifest, MANIFEST};
use crate::error::{Error, Result};
use report::{LayerTiming, PlotCollector, Report, Stats, Timings};
use serde::Serialize;
use sim::{FaultSpec, Machine, Sink};
use std::collections::BTreeMap;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One thing wrong with a job: a verification problem, a broken invariant or a fault.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Violation {
    /// Layer concerned (`None`: the whole job).
    pub layer: Option<usize>,
    /// Simulated time, s (for verification problems: when the layer starts).
    #[serde(serialize_with = "report::six_opt")]
    pub time_s: Option<f64>,
    /// Machine-readable kind, e.g. `travel`, `mask-checksum`, `stall` (see docs/EXECUTOR.md).
    pub kind: &'static str,
    /// One line for people; names the file for mask problems.
    pub message: String,
    /// File concerned, relative to the bundle.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
}

/// What to do besides verifying and simulating.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Faults to inject.
    pub faults: Vec<FaultSpec>,
    /// Write the timeline as CSV here.
    pub trace: Option<PathBuf>,
    /// Write a PNG of stage position and light over time here.
    pub plot: Option<PathBuf>,
    /// Restrict the trace and the plot to these layers, e.g. "10..20" (inclusive).
    pub layers: Option<String>,
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

/// Verifies and simulates the bundle at `dir`.
///
/// Errors (exit code 2) are an unreadable bundle or manifest, an invalid machine profile
/// in it, bad options, or a trace/plot file that cannot be written. Problems with the job
/// itself are [`Violation`]s in the report.
pub fn run(dir: &Path, opts: &RunOptions) -> Result<Report> {
    let t0 = Instant::now();
    let (manifest, range) = read_bundle(dir, opts)?;
    let read_s = t0.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let verified = verify::verify(dir, &manifest);
    let verify_s = t1.elapsed().as_secs_f64();

    let t2 = Instant::now();
    let simulated = simulate_into_sinks(dir, &manifest, opts, range)?;
    let violations = all_violations(verified.problems, simulated.timeline, &simulated.outcome);
    let simulate_s = t2.elapsed().as_secs_f64();

    let timings = Timings {
        read_s,
        verify_s,
        simulate_s,
    };
    Ok(report(
        dir,
        &manifest,
        verified.masks,
        simulated.outcome,
        simulated.stats,
        violations,
        timings,
    ))
}

/// Reads the manifest, checks its machine profile and the options against it, and
/// parses the layer range of the trace and the plot.
fn read_bundle(dir: &Path, opts: &RunOptions) -> Result<(Manifest, Option<RangeInclusive<usize>>)> {
    let manifest = Manifest::read(dir)?;
    manifest.machine.validate().map_err(|msg| Error::Bundle {
        path: dir.join(MANIFEST),
        msg: format!("machine profile: {msg}"),
    })?;
    let n = manifest.layers.len();
    for f in &opts.faults {
        if f.layer >= n {
            return Err(Error::Usage(format!(
                "--fault {}@{}: the job has {n} {} (0..{})",
                f.kind,
                f.layer,
                report::plural(n, "layer", "layers"),
                n.saturating_sub(1)
            )));
        }
    }
    let range = opts
        .layers
        .as_deref()
        .map(|s| parse_layer_range(s, n))
        .transpose()?;
    Ok((manifest, range))
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
    range: Option<RangeInclusive<usize>>,
) -> Result<Simulated> {
    let machine = Machine::from_profile(&manifest.machine);
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
            kind: f.kind,
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
        let title = format!(
            "{}: stage position and light{}",
            dir.file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            match &range {
                Some(r) => format!(", layers {}..{}", r.start(), r.end()),
                None => String::new(),
            }
        );
        write_atomic(path, &p.render(&title))?;
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
    dir: &Path,
    manifest: &Manifest,
    masks_verified: usize,
    outcome: sim::Outcome,
    stats: Stats,
    violations: Vec<Violation>,
    timings: Timings,
) -> Report {
    let mut counts = BTreeMap::new();
    for v in &violations {
        *counts.entry(v.kind).or_insert(0) += 1;
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

/// The temporary sibling (`.NAME.tmp-PID`) a file is written to before it is renamed into
/// place, or `None` when `path` has no file name.
fn temp_sibling(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?;
    Some(path.with_file_name(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    )))
}

/// Writes `bytes` to `path` through a temporary sibling renamed into place.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_sibling(path)
        .ok_or_else(|| Error::Usage(format!("{}: not a file name", path.display())))?;
    std::fs::write(&tmp, bytes).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
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
