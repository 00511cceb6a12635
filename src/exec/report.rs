//! What `dmdsl run` reports: the [`Report`] (serialized for `--json`), the statistics
//! sink, the human summary and the `--plot` chart.

use super::sim::{FaultEvent, Motion, SegKind, Segment, ShutterState, Sink};
use super::Violation;
use crate::plot::{Band, Canvas, Chart, Panel, Series, Style};
use crate::text::{count, hms, signed};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::ops::RangeInclusive;

pub(crate) use crate::round::{six, six_pair};

/// Timing of one layer: simulated and estimated.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LayerTiming {
    /// Layer index.
    pub index: usize,
    /// When the layer's steps start, s.
    #[serde(serialize_with = "six")]
    pub start_s: f64,
    /// Simulated duration, s.
    #[serde(serialize_with = "six")]
    pub time_s: f64,
    /// The manifest's estimate (`layers[].time_s`), s.
    #[serde(serialize_with = "six")]
    pub estimate_s: f64,
    /// Light time received, s.
    #[serde(serialize_with = "six")]
    pub light_s: f64,
    /// The manifest's `exposure_s`.
    #[serde(serialize_with = "six")]
    pub exposure_s: f64,
}

/// One key in which the machine given with `--machine` differs from the job's.
pub use crate::bundle::machine::Difference as MachineDifference;

/// The machine a job was checked against with `--machine`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct MachineCheck {
    /// The given machine's `name` (a profile's, a hardware description's file name; with
    /// only `--set`, the job's own).
    pub profile: String,
    /// What gave it: `--machine`, `--set` or both.
    pub given: &'static str,
    /// Where it differs from the job's machine (empty: nowhere that matters).
    pub differences: Vec<MachineDifference>,
}

/// " (FORMAT)" after a job's name in a summary, except for a bundle directory.
fn shown_format(format: &str) -> String {
    if format == "dmdjob" {
        String::new()
    } else {
        format!(" ({format})")
    }
}

/// Differing keys the human summary names before "and N more".
pub const DIFFERENCES_SHOWN: usize = 4;

/// The result of `dmdsl run`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The bundle, as given.
    pub bundle: String,
    /// The form the job came in: `dmdjob` (bundle directory), `dmdjob-zip`, `sl1`, `sl1s`
    /// or `sla-control`.
    pub format: &'static str,
    /// Where `estimate_s` comes from: `planner` (dmdsl's plan, `totals.print_time_s`),
    /// `PrusaSlicer printTime (config.ini)` for SL1/SL1S files, `import steps` for an
    /// imported job that carries no estimate (the sum of the steps built for it).
    pub estimate_source: String,
    /// The machine given with `--machine` and how it differs from the job's (`None`: the
    /// job ran on the machine its manifest embeds).
    pub machine: Option<MachineCheck>,
    /// Layers in the job.
    pub layers: usize,
    /// Layers simulated to the end (fewer than `layers` after a fault).
    pub layers_completed: usize,
    /// Mask files verified.
    pub masks_verified: usize,
    /// Simulated duration of the job (to the abort after a fault), s.
    #[serde(serialize_with = "six")]
    pub total_s: f64,
    /// The manifest's estimate, `totals.print_time_s`, s.
    #[serde(serialize_with = "six")]
    pub estimate_s: f64,
    /// (total_s − estimate_s) / estimate_s, percent.
    #[serde(serialize_with = "six")]
    pub estimate_diff_pct: f64,
    /// Sum of the layers' `exposure_s`, s.
    #[serde(serialize_with = "six")]
    pub exposure_s: f64,
    /// Time light reached the resin, s.
    #[serde(serialize_with = "six")]
    pub light_on_s: f64,
    /// Time the shutter was not closed (opening, open, closing), s.
    #[serde(serialize_with = "six")]
    pub shutter_open_s: f64,
    /// Time in `wait` steps, s.
    #[serde(serialize_with = "six")]
    pub wait_s: f64,
    /// Time waiting for the DMD to load a mask, s.
    #[serde(serialize_with = "six")]
    pub load_wait_s: f64,
    /// Distance the stage moved, mm.
    #[serde(serialize_with = "six")]
    pub stage_travel_mm: f64,
    /// Stage position range visited, mm: [min, max].
    #[serde(serialize_with = "six_pair")]
    pub stage_range_mm: [f64; 2],
    /// Highest stage speed reached, mm/s.
    #[serde(serialize_with = "six")]
    pub peak_speed_mm_s: f64,
    /// The fault that ended the run, if one was injected and triggered.
    pub fault: Option<FaultEvent>,
    /// Injected faults that never triggered, as `KIND@LAYER`.
    pub untriggered_faults: Vec<String>,
    /// Everything wrong, verification problems first, then in time order.
    pub violations: Vec<Violation>,
    /// Number of violations per kind.
    pub violation_counts: BTreeMap<&'static str, usize>,
    /// Per-layer timing.
    pub per_layer: Vec<LayerTiming>,
    /// Wall-clock seconds spent: read, verify, simulate, cure.
    pub timings: Timings,
    /// What cures, predicted from the masks (`--cure`; docs/EXECUTOR.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cure: Option<super::cure::CureCheck>,
    /// Why `--cure` was not evaluated (the bundle failed verification).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cure_skipped: Option<String>,
    /// The regions of the layers that rest on nothing in the layer below, from the masks
    /// (docs/EXECUTOR.md "Printability").
    pub unsupported_regions: Vec<super::UnsupportedRegion>,
    /// Warnings about the job (`run.unsupported-regions`, docs/WARNINGS.md).
    pub warnings: Vec<crate::warning::Warning>,
    /// The machine record's keys whose checks were not made: its source states no value
    /// for them (`stage.max_speed_mm_s`, …; `projector[].pixel_mm`: areas not measured).
    pub unchecked: Vec<String>,
    /// What the job's reader or the run could not take as stated, one line each: settings
    /// not simulated, figures estimated, checks left out.
    pub notes: Vec<String>,
    /// True when the bundle verified, replayed without violations and no fault triggered.
    pub ok: bool,
}

/// Wall-clock time of the run's phases, s.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct Timings {
    /// Reading and parsing job.json.
    #[serde(serialize_with = "six")]
    pub read_s: f64,
    /// Hashing and decoding the masks.
    #[serde(serialize_with = "six")]
    pub verify_s: f64,
    /// Simulation, checks, trace.
    #[serde(serialize_with = "six")]
    pub simulate_s: f64,
    /// The cure check (`--cure`; 0 without).
    #[serde(serialize_with = "six")]
    pub cure_s: f64,
}

/// Statistics gathered from the timeline.
#[derive(Debug, Clone, PartialEq)]
pub struct Stats {
    /// See [`Report::light_on_s`].
    pub light_on_s: f64,
    /// See [`Report::shutter_open_s`].
    pub shutter_open_s: f64,
    /// See [`Report::wait_s`].
    pub wait_s: f64,
    /// See [`Report::load_wait_s`].
    pub load_wait_s: f64,
    /// See [`Report::stage_travel_mm`].
    pub travel_mm: f64,
    /// See [`Report::stage_range_mm`].
    pub range_mm: [f64; 2],
    /// See [`Report::peak_speed_mm_s`].
    pub peak_speed_mm_s: f64,
}

impl Default for Stats {
    fn default() -> Self {
        Stats {
            light_on_s: 0.0,
            shutter_open_s: 0.0,
            wait_s: 0.0,
            load_wait_s: 0.0,
            travel_mm: 0.0,
            range_mm: [f64::INFINITY, f64::NEG_INFINITY],
            peak_speed_mm_s: 0.0,
        }
    }
}

impl Sink for Stats {
    fn segment(&mut self, s: &Segment) {
        let d = s.duration();
        if s.light {
            self.light_on_s += d;
        }
        if s.shutter != ShutterState::Closed {
            self.shutter_open_s += d;
        }
        match s.kind {
            SegKind::Wait => self.wait_s += d,
            SegKind::LoadWait => self.load_wait_s += d,
            _ => {}
        }
        self.travel_mm += (s.to_mm - s.from_mm).abs();
        for p in [s.from_mm, s.to_mm] {
            self.range_mm = [self.range_mm[0].min(p), self.range_mm[1].max(p)];
        }
        self.peak_speed_mm_s = self.peak_speed_mm_s.max(s.peak_speed());
    }
}

/// Collects what `--plot` draws: stage position over time and the light-on intervals,
/// for a range of layers.
#[derive(Debug, Clone, Default)]
pub struct PlotCollector {
    layers: Option<RangeInclusive<usize>>,
    points: Vec<(f64, f64)>,
    light: Vec<(f64, f64)>,
    /// Where the stage stood when each light-on interval began: (time, position).
    exposures: Vec<(f64, f64)>,
    times: Vec<f64>,
}

impl PlotCollector {
    /// Collects the segments of `layers` (all if `None`).
    pub fn new(layers: Option<RangeInclusive<usize>>) -> Self {
        PlotCollector {
            layers,
            ..Default::default()
        }
    }

    /// The chart: stage position over time with the light-on intervals shaded, under
    /// `title`. Time is in s, min or h, whichever keeps the numbers short.
    pub fn render(&self, title: &str) -> Canvas {
        let span = match (self.points.first(), self.points.last()) {
            (Some(a), Some(b)) => b.0 - a.0,
            _ => 0.0,
        };
        let (unit, div) = if span > 3.0 * 3600.0 {
            ("h", 3600.0)
        } else if span > 600.0 {
            ("min", 60.0)
        } else {
            ("s", 1.0)
        };
        let points = self.points.iter().map(|&(t, z)| (t / div, z)).collect();
        let bands = self
            .light
            .iter()
            .map(|&(a, b)| Band {
                x0: a / div,
                x1: b / div,
                color: [255, 170, 0],
                label: "light on (exposing)".into(),
            })
            .collect();
        Chart {
            title: title.to_string(),
            x_label: format!("time from the start of the job ({unit})"),
            x_whole: false,
            width: 1400,
            height: 600,
            panels: vec![Panel {
                y_label: "stage position (mm)".into(),
                series: vec![
                    Series {
                        label: "stage position: platform distance from the exposure plane".into(),
                        color: [30, 90, 200],
                        style: Style::Line,
                        points,
                    },
                    Series {
                        label: "where each exposure starts".into(),
                        color: [200, 60, 20],
                        style: Style::Points,
                        points: self.exposures.iter().map(|&(t, z)| (t / div, z)).collect(),
                    },
                ],
                bands,
                y_from_zero: false,
            }],
        }
        .render()
    }
}

impl Sink for PlotCollector {
    fn segment(&mut self, s: &Segment) {
        if let Some(r) = &self.layers {
            if !r.contains(&s.layer) {
                return;
            }
        }
        self.times.clear();
        s.phase_times(&mut self.times);
        if let Motion::Trapezoid { .. } = s.motion {
            // Samples inside the move so its accelerating phases look curved.
            for j in 1..8 {
                self.times.push(s.t0 + s.duration() * j as f64 / 8.0);
            }
            self.times.sort_by(f64::total_cmp);
        }
        for &t in &self.times {
            self.points.push((t, s.position_at(t)));
        }
        self.points.push((s.t1, s.to_mm));
        if s.light && s.t1 > s.t0 {
            match self.light.last_mut() {
                Some(last) if s.t0 - last.1 < 1e-9 => last.1 = s.t1,
                _ => {
                    self.light.push((s.t0, s.t1));
                    self.exposures.push((s.t0, s.from_mm));
                }
            }
        }
    }
}

/// Most violations listed in the human summary.
pub const LIST_MAX: usize = 20;

/// "  ... and N more (--json lists all)" when a list names only `shown` of `total` items.
fn and_more(total: usize, shown: usize) -> Option<String> {
    let more = total.saturating_sub(shown);
    (more > 0).then(|| format!("  ... and {more} more (--json lists all)"))
}

/// The human summary printed by `dmdsl run`.
pub fn render_human(r: &Report) -> String {
    let mut o = String::new();
    let layers = count(r.layers as u64, "layer", "layers");
    let masks = count(r.masks_verified as u64, "mask", "masks");
    let _ = writeln!(
        o,
        "{}{}: {layers}, {masks} checked",
        r.bundle,
        shown_format(r.format)
    );
    if let Some(m) = &r.machine {
        let name = &m.profile;
        if m.differences.is_empty() {
            let by = m.given;
            let _ = writeln!(
                o,
                "machine {name} ({by}): the same stage, shutter, DMD and projectors as the job's"
            );
        } else {
            let shown = m.differences.iter().take(DIFFERENCES_SHOWN);
            let shown: Vec<String> = shown
                .map(|d| format!("{}: job {}, machine {}", d.key, d.job, d.machine))
                .collect();
            let more = match m.differences.len().saturating_sub(DIFFERENCES_SHOWN) {
                0 => String::new(),
                k => format!(" (and {k} more, --json lists all)"),
            };
            let _ = writeln!(
                o,
                "machine {name} ({}) differs from the job's: {}{more}",
                m.given,
                shown.join("; ")
            );
        }
    }
    let estimate = match r.estimate_source.as_str() {
        "planner" => "manifest estimate".to_string(),
        other => format!("estimate, {other},"),
    };
    let (total, est, diff) = (r.total_s, r.estimate_s, r.estimate_diff_pct);
    let _ = writeln!(
        o,
        "simulated {} ({total:.2} s); {estimate} {est:.2} s ({} %)",
        hms(total),
        signed(diff, 2)
    );
    let _ = writeln!(
        o,
        "light on {:.2} s (exposures {:.2} s), shutter open {:.2} s, waits {:.2} s, DMD load waits {:.2} s",
        r.light_on_s, r.exposure_s, r.shutter_open_s, r.wait_s, r.load_wait_s
    );
    let ([lo, hi], travel, peak) = (r.stage_range_mm, r.stage_travel_mm, r.peak_speed_mm_s);
    let _ = writeln!(
        o,
        "stage travel {travel:.1} mm within [{lo:.3}, {hi:.3}] mm, peak speed {peak:.3} mm/s"
    );
    if !r.unchecked.is_empty() {
        let keys = r.unchecked.join(", ");
        let _ = writeln!(
            o,
            "not checked: {keys}: the job's machine states no value (give --machine or --set)"
        );
    }
    for n in &r.notes {
        let _ = writeln!(o, "note: {n}");
    }
    for w in &r.warnings {
        let _ = writeln!(o, "warning: {} [{}]", w.message, w.code);
    }
    if let Some(f) = &r.fault {
        let (t, at) = (f.time_s, hms(f.time_s));
        let _ = writeln!(
            o,
            "FAULT {} in layer {} at {t:.3} s ({at}), stage at {:.4} mm: {}",
            f.kind, f.layer, f.stage_mm, f.message
        );
    }
    for u in &r.untriggered_faults {
        let why = r.fault.as_ref().map_or(String::new(), |f| {
            format!(
                " (the run ended at the {} fault in layer {})",
                f.kind, f.layer
            )
        });
        let _ = writeln!(o, "note: fault {u} never triggered{why}");
    }
    o.push_str(&render_violations(r));
    if let Some(c) = &r.cure {
        render_cure(&mut o, c);
    }
    if let Some(why) = &r.cure_skipped {
        let _ = writeln!(o, "cure: not evaluated: {why}");
    }
    let _ = writeln!(o, "{}", if r.ok { "OK" } else { "FAILED" });
    o
}

/// The human summary's lines on the violations: their count by kind, then each (at most
/// [`LIST_MAX`]) as `layer N at T s: kind: message`.
pub fn render_violations(r: &Report) -> String {
    let mut o = String::new();
    if r.violations.is_empty() {
        let _ = writeln!(o, "violations: none");
        return o;
    }
    let counts: Vec<String> = r
        .violation_counts
        .iter()
        .map(|(k, n)| format!("{k} {n}"))
        .collect();
    let (n, counts) = (r.violations.len(), counts.join(", "));
    let _ = writeln!(o, "violations: {n} ({counts})");
    for v in r.violations.iter().take(LIST_MAX) {
        let layer = v.layer.map_or("job".to_string(), |l| format!("layer {l}"));
        let time = v.time_s.map_or(String::new(), |t| format!(" at {t:.3} s"));
        let _ = writeln!(o, "  {layer}{time}: {}: {}", v.kind, v.message);
    }
    if let Some(more) = and_more(r.violations.len(), LIST_MAX) {
        let _ = writeln!(o, "{more}");
    }
    o
}

/// Findings (vanished, merged) the human summary lists before "and N more".
pub const FINDINGS_SHOWN: usize = 5;

/// The cure check's lines of the human summary.
fn render_cure(o: &mut String, c: &super::cure::CureCheck) {
    let pt = c
        .print_through_mm
        .map_or("none".to_string(), |t| format!("{t:.3} mm"));
    let held = c.held_back_layers;
    let z = c.z_error_mm.map_or(String::new(), |z| {
        format!(
            " (Z error {} mm, {} held back)",
            signed(z, 3),
            count(held as u64, "layer", "layers")
        )
    });
    let _ = writeln!(
        o,
        "cure: edge offset {} px mean ({} mm), {:.2} px p95; {} vanished, {} merged; print-through {pt}{z}",
        signed(c.signed_mean_px, 2), signed(c.signed_mean_mm, 3), c.edge_offset_px.p95, c.vanished, c.merged
    );
    if let Some((s, l)) = c.slicer.as_ref().and_then(|s| Some((s, s.max_diff_layer?))) {
        let islands = match s.vanish_disagreements.len() {
            0 => String::new(),
            k => format!("; vanishing islands differ in {k} layers"),
        };
        let (diff, layers) = (s.max_diff_px, s.layers);
        let _ = writeln!(o, "cure: against the slicer's prediction: largest difference {diff:.2} px (layer {l}) over {layers} layers{islands}");
    }
    for f in c.findings.iter().take(FINDINGS_SHOWN) {
        let what = if f.kind == "vanished" {
            format!("an island of {} px does not cure", f.pixels)
        } else {
            format!("cured resin joins {} islands", f.islands)
        };
        let [x, y] = f.at_mm;
        let _ = writeln!(o, "  layer {}: {what} at ({x:.2}, {y:.2}) mm", f.layer);
    }
    if let Some(more) = and_more(c.findings.len(), FINDINGS_SHOWN) {
        let _ = writeln!(o, "{more}");
    }
}
