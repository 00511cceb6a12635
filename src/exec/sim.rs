//! Event-based simulation of the machine a bundle was compiled for: the lift stage,
//! the exposure shutter and the DMD.
//!
//! The simulator follows the "Step semantics and timing contract" of [`crate::bundle`]
//! literally. It turns every step into one or more [`Segment`]s (a stretch of time with a
//! known stage motion, shutter state and light state), computed analytically from the
//! event times (no time stepping), and hands them in time order to [`Sink`]s: the
//! invariant checker, the CSV trace writer, the plot collector, the statistics. Nothing
//! is stored per segment, so a 10,000-layer job simulates in constant memory (one small
//! [`LayerRecord`] per layer is kept).
//!
//! Stage positions are quantized to the stage's `steps_per_mm`: every target is rounded
//! to the nearest step and the stage moves by whole steps, so a move's duration is that
//! of the quantized distance.
//!
//! Faults ([`FaultSpec`]) are injected here and handled as firmware must: the shutter is
//! closed (or, if it is stuck, the DMD is blanked), the stage stops where it is, and the
//! run ends with a [`FaultEvent`] naming the layer and the time.

use super::Violation;
use crate::bundle::{Manifest, Step};
use crate::motion::{move_time, position_at};
use crate::profile::Profile;
use std::fmt;
use std::str::FromStr;

/// The simulated machine, taken from the manifest's resolved profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Machine {
    /// Lowest allowed stage coordinate, mm.
    pub travel_min_mm: f64,
    /// Highest allowed stage coordinate, mm.
    pub travel_max_mm: f64,
    /// Where homing leaves the stage, mm.
    pub home_mm: f64,
    /// Stage speed limit, mm/s.
    pub max_speed_mm_s: f64,
    /// Stage acceleration limit, mm/s².
    pub max_accel_mm_s2: f64,
    /// Stage resolution, steps per mm.
    pub steps_per_mm: f64,
    /// Shutter opening latency, s.
    pub open_s: f64,
    /// Shutter closing latency, s.
    pub close_s: f64,
    /// DMD mask load time, s.
    pub load_s: f64,
}

impl Machine {
    /// The machine described by a (validated) profile.
    pub fn from_profile(p: &Profile) -> Machine {
        Machine {
            travel_min_mm: p.stage.travel_min_mm,
            travel_max_mm: p.stage.travel_max_mm,
            home_mm: p.stage.home_mm,
            max_speed_mm_s: p.stage.max_speed_mm_s.get(),
            max_accel_mm_s2: p.stage.max_accel_mm_s2.get(),
            steps_per_mm: p.stage.steps_per_mm.get(),
            open_s: p.shutter.open_s.get(),
            close_s: p.shutter.close_s.get(),
            load_s: p.dmd.load_s.get(),
        }
    }

    /// `mm` rounded to the nearest whole stage step.
    pub fn quantize(&self, mm: f64) -> f64 {
        (mm * self.steps_per_mm).round() / self.steps_per_mm
    }

    /// Half a stage step, mm: the largest distance between a target and where the stage
    /// can actually stop.
    pub fn half_step_mm(&self) -> f64 {
        0.5 / self.steps_per_mm
    }
}

/// What the machine does during a [`Segment`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SegKind {
    /// The stage is homed (zero duration, at the start of the job).
    Home,
    /// A `move` step: shutter closed, trapezoidal profile.
    Move,
    /// A `wait` step.
    Wait,
    /// An `expose` or the first `sweep` of a run waits for the DMD to finish loading.
    LoadWait,
    /// The shutter opens (latency; light not yet on).
    Open,
    /// Light on, stage still (`expose`).
    Expose,
    /// Light on, stage moving at constant speed (`sweep`).
    Sweep,
    /// The shutter closes (latency; light off).
    Close,
    /// Fault: the shutter was commanded closed but stayed open (light on).
    StuckOpen,
}

impl SegKind {
    /// Lowercase name used in the trace and in messages.
    pub fn name(self) -> &'static str {
        match self {
            SegKind::Home => "home",
            SegKind::Move => "move",
            SegKind::Wait => "wait",
            SegKind::LoadWait => "load-wait",
            SegKind::Open => "shutter-open",
            SegKind::Expose => "expose",
            SegKind::Sweep => "sweep",
            SegKind::Close => "shutter-close",
            SegKind::StuckOpen => "shutter-stuck",
        }
    }
}

/// State of the exposure shutter during a segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShutterState {
    /// Closed: no light.
    Closed,
    /// Opening (latency), no light yet.
    Opening,
    /// Open: light reaches the resin (where the mask is lit).
    Open,
    /// Closing (latency), light off.
    Closing,
}

impl ShutterState {
    /// Lowercase name used in the trace.
    pub fn name(self) -> &'static str {
        match self {
            ShutterState::Closed => "closed",
            ShutterState::Opening => "opening",
            ShutterState::Open => "open",
            ShutterState::Closing => "closing",
        }
    }
}

/// Stage motion during a segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// The stage does not move.
    Still,
    /// Trapezoidal move from the segment's `from_mm` toward `target_mm`, started at the
    /// segment's `t0` (a fault may cut it short: then `to_mm` ≠ `target_mm`).
    Trapezoid {
        /// Commanded (quantized) target, mm.
        target_mm: f64,
        /// Commanded cruise speed, mm/s.
        speed_mm_s: f64,
        /// Commanded acceleration, mm/s².
        accel_mm_s2: f64,
    },
    /// Constant velocity (a sweep), mm/s, signed.
    Constant {
        /// Signed velocity, mm/s.
        velocity_mm_s: f64,
    },
}

/// A stretch of the timeline with one kind of activity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// What happens.
    pub kind: SegKind,
    /// Layer (0-based) whose steps produced the segment.
    pub layer: usize,
    /// Index of the step in the layer's `steps`, if the segment comes from one.
    pub step: Option<usize>,
    /// Start time, s since the job started.
    pub t0: f64,
    /// End time, s.
    pub t1: f64,
    /// Stage position at `t0`, mm (quantized).
    pub from_mm: f64,
    /// Stage position at `t1`, mm (quantized).
    pub to_mm: f64,
    /// Stage motion.
    pub motion: Motion,
    /// Shutter state.
    pub shutter: ShutterState,
    /// True while light reaches the resin.
    pub light: bool,
    /// Time from which the layer's mask is on the DMD (before it: loading, nothing shown);
    /// infinite if it never loads.
    pub mask_ready_s: f64,
}

impl Segment {
    /// Duration, s.
    pub fn duration(&self) -> f64 {
        self.t1 - self.t0
    }

    /// Stage position at time `t` (clamped to the segment), mm, not quantized.
    pub fn position_at(&self, t: f64) -> f64 {
        let t = t.clamp(self.t0, self.t1);
        match self.motion {
            Motion::Still => self.from_mm,
            Motion::Trapezoid {
                target_mm,
                speed_mm_s,
                accel_mm_s2,
            } => {
                if t >= self.t1 {
                    self.to_mm
                } else {
                    position_at(
                        self.from_mm,
                        target_mm,
                        speed_mm_s,
                        accel_mm_s2,
                        t - self.t0,
                    )
                }
            }
            Motion::Constant { velocity_mm_s } => {
                if t >= self.t1 {
                    self.to_mm
                } else {
                    self.from_mm + velocity_mm_s * (t - self.t0)
                }
            }
        }
    }

    /// Signed stage velocity at time `t` (the value from `t` on), mm/s.
    pub fn velocity_at(&self, t: f64) -> f64 {
        if t < self.t0 || t >= self.t1 {
            return 0.0;
        }
        match self.motion {
            Motion::Still => 0.0,
            Motion::Constant { velocity_mm_s } => velocity_mm_s,
            Motion::Trapezoid {
                target_mm,
                speed_mm_s: v,
                accel_mm_s2: a,
            } => {
                let d = (target_mm - self.from_mm).abs();
                let sign = if target_mm >= self.from_mm { 1.0 } else { -1.0 };
                let total = move_time(d, v, a);
                let vp = if d >= v * v / a { v } else { (a * d).sqrt() };
                let ta = vp / a;
                let tau = t - self.t0;
                let speed = if tau < ta {
                    a * tau
                } else if tau <= total - ta {
                    vp
                } else {
                    (a * (total - tau)).max(0.0)
                };
                sign * speed + 0.0 // no negative zero
            }
        }
    }

    /// Peak speed reached in the segment, mm/s.
    pub fn peak_speed(&self) -> f64 {
        match self.motion {
            Motion::Still => 0.0,
            Motion::Constant { velocity_mm_s } => velocity_mm_s.abs(),
            Motion::Trapezoid {
                target_mm,
                speed_mm_s: v,
                accel_mm_s2: a,
            } => {
                let d = (target_mm - self.from_mm).abs();
                let vp = if d >= v * v / a { v } else { (a * d).sqrt() };
                // A move cut short by a fault may stop before reaching its peak.
                let tau = self.t1 - self.t0;
                vp.min(a * tau)
            }
        }
    }

    /// Appends the times inside `[t0, t1)` at which the motion changes phase (start,
    /// end of acceleration, start of deceleration), in order.
    pub fn phase_times(&self, out: &mut Vec<f64>) {
        out.push(self.t0);
        if let Motion::Trapezoid {
            target_mm,
            speed_mm_s: v,
            accel_mm_s2: a,
        } = self.motion
        {
            let d = (target_mm - self.from_mm).abs();
            let total = move_time(d, v, a);
            let vp = if d >= v * v / a { v } else { (a * d).sqrt() };
            let ta = vp / a;
            for tau in [ta, total - ta] {
                let t = self.t0 + tau;
                if t > *out.last().unwrap() && t < self.t1 {
                    out.push(t);
                }
            }
        }
    }
}

/// Consumer of the simulated timeline.
pub trait Sink {
    /// Called for every segment, in time order.
    fn segment(&mut self, seg: &Segment);
    /// Called when a layer's steps are done (or the run was aborted during the layer).
    fn layer_end(&mut self, _rec: &LayerRecord) {}
}

/// What the simulation measured for one layer.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerRecord {
    /// Layer index.
    pub index: usize,
    /// Time the layer's steps start, s.
    pub start_s: f64,
    /// Simulated duration of the layer, s (to the start of the next layer).
    pub time_s: f64,
    /// Light-on time the layer's mask received, s.
    pub light_s: f64,
    /// Time the layer's mask was on the DMD.
    pub mask_ready_s: f64,
    /// Where the layer's last sweep ended, mm, if it has sweeps.
    pub last_sweep_end_mm: Option<f64>,
    /// How much position quantization changed the layer's duration, s (bound for comparing
    /// with the unquantized estimate).
    pub quantization_s: f64,
    /// How much position quantization changed the layer's light time, s.
    pub dose_quantization_s: f64,
    /// False if a fault ended the run during this layer.
    pub completed: bool,
}

/// Kinds of injected faults.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FaultKind {
    /// The stage stalls halfway through the layer's first move or sweep.
    Stall,
    /// A limit switch trips halfway through the layer's first move or sweep.
    Limit,
    /// The shutter sticks open at its first close from the layer on.
    ShutterStuck,
    /// The DMD fails to load the layer's mask.
    MaskLoad,
}

impl FaultKind {
    /// All kinds, in the order of `--help`.
    pub const ALL: [FaultKind; 4] = [
        FaultKind::Stall,
        FaultKind::Limit,
        FaultKind::ShutterStuck,
        FaultKind::MaskLoad,
    ];

    /// Name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::Stall => "stall",
            FaultKind::Limit => "limit",
            FaultKind::ShutterStuck => "shutter-stuck",
            FaultKind::MaskLoad => "mask-load",
        }
    }
}

impl fmt::Display for FaultKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A fault to inject: `KIND@LAYER`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaultSpec {
    /// What fails.
    pub kind: FaultKind,
    /// Layer index (0-based, as in the manifest).
    pub layer: usize,
}

impl FromStr for FaultSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let names = FaultKind::ALL.map(|k| k.name()).join(", ");
        let (k, l) = s
            .split_once('@')
            .ok_or_else(|| format!("fault {s:?}: expected KIND@LAYER (kinds: {names})"))?;
        let kind = FaultKind::ALL
            .into_iter()
            .find(|f| f.name() == k.trim())
            .ok_or_else(|| format!("fault {s:?}: unknown kind {k:?} (kinds: {names})"))?;
        let layer = l
            .trim()
            .parse::<usize>()
            .map_err(|_| format!("fault {s:?}: layer {l:?} is not a layer index"))?;
        Ok(FaultSpec { kind, layer })
    }
}

/// A fault that happened during the run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FaultEvent {
    /// What failed.
    pub kind: &'static str,
    /// Layer during which it happened.
    pub layer: usize,
    /// Time the firmware detected it, s.
    pub time_s: f64,
    /// Where the stage stopped, mm.
    pub stage_mm: f64,
    /// What happened and what the firmware did.
    pub message: String,
}

/// Result of a simulation.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// One record per simulated layer (fewer than the job's layers after a fault).
    pub layers: Vec<LayerRecord>,
    /// Simulated end of the job (or of the abort), s.
    pub total_s: f64,
    /// The fault that ended the run, if any.
    pub fault: Option<FaultEvent>,
    /// Injected faults that never triggered (e.g. a stuck shutter with no close after it).
    pub untriggered: Vec<FaultSpec>,
    /// Steps that cannot be executed at all (non-positive speed, negative time); skipped.
    pub invalid_steps: Vec<Violation>,
}

/// Simulates the manifest's steps on its machine, feeding every segment to `sinks`.
pub fn simulate(manifest: &Manifest, faults: &[FaultSpec], sinks: &mut [&mut dyn Sink]) -> Outcome {
    let m = Machine::from_profile(&manifest.machine);
    let mut sim = Sim {
        m,
        manifest,
        sinks,
        t: 0.0,
        pos: m.quantize(m.home_mm),
        exact: m.home_mm,
        run_open: false,
        faults: faults.to_vec(),
        rec: LayerRecord {
            index: 0,
            start_s: 0.0,
            time_s: 0.0,
            light_s: 0.0,
            mask_ready_s: 0.0,
            last_sweep_end_mm: None,
            quantization_s: 0.0,
            dose_quantization_s: 0.0,
            completed: false,
        },
        load_fail: None,
        motion_fault: None,
        stuck: false,
        fault: None,
        invalid: Vec::new(),
        records: Vec::with_capacity(manifest.layers.len()),
    };
    sim.run();
    // Faults are only armed when their layer is reached; without a fault every layer was.
    let untriggered = if sim.fault.is_none() {
        faults.to_vec()
    } else {
        Vec::new()
    };
    Outcome {
        layers: sim.records,
        total_s: sim.t,
        fault: sim.fault,
        untriggered,
        invalid_steps: sim.invalid,
    }
}

struct Sim<'a, 's, 'k> {
    m: Machine,
    manifest: &'a Manifest,
    sinks: &'s mut [&'k mut dyn Sink],
    /// Current time, s.
    t: f64,
    /// Current stage position, mm (quantized).
    pos: f64,
    /// Unquantized position the steps asked for (to bound quantization effects).
    exact: f64,
    /// The shutter is open in a sweep run.
    run_open: bool,
    /// Faults not yet triggered.
    faults: Vec<FaultSpec>,
    rec: LayerRecord,
    /// Mask-load failure pending for the current layer: detection time.
    load_fail: Option<f64>,
    /// Stall or limit armed for the current layer's first motion.
    motion_fault: Option<FaultKind>,
    /// A stuck-shutter fault is armed.
    stuck: bool,
    fault: Option<FaultEvent>,
    invalid: Vec<Violation>,
    records: Vec<LayerRecord>,
}

/// Does the step list start a sweep (so a sweep run continues into it)?
fn starts_with_sweep(steps: &[Step]) -> bool {
    matches!(steps.first(), Some(Step::Sweep { .. }))
}

impl Sim<'_, '_, '_> {
    fn send(&mut self, seg: &Segment) {
        for s in self.sinks.iter_mut() {
            s.segment(seg);
        }
    }

    fn take_fault(&mut self, kind: FaultKind, layer: usize) -> bool {
        if let Some(i) = self
            .faults
            .iter()
            .position(|f| f.kind == kind && f.layer == layer)
        {
            self.faults.remove(i);
            true
        } else {
            false
        }
    }

    fn still(
        &self,
        kind: SegKind,
        step: Option<usize>,
        dur: f64,
        shutter: ShutterState,
    ) -> Segment {
        Segment {
            kind,
            layer: self.rec.index,
            step,
            t0: self.t,
            t1: self.t + dur,
            from_mm: self.pos,
            to_mm: self.pos,
            motion: Motion::Still,
            shutter,
            light: shutter == ShutterState::Open,
            mask_ready_s: self.rec.mask_ready_s,
        }
    }

    fn run(&mut self) {
        let home = Segment {
            kind: SegKind::Home,
            layer: 0,
            step: None,
            t0: 0.0,
            t1: 0.0,
            from_mm: self.pos,
            to_mm: self.pos,
            motion: Motion::Still,
            shutter: ShutterState::Closed,
            light: false,
            mask_ready_s: if self.manifest.layers.is_empty() {
                f64::INFINITY
            } else {
                self.m.load_s
            },
        };
        self.send(&home);
        let layers = &self.manifest.layers;
        // next_sweeps[i]: the first step after layer i (skipping layers without steps) is
        // a sweep, so a sweep run still going at the end of layer i continues.
        let mut next_sweeps = vec![false; layers.len()];
        let mut after = false;
        for (i, l) in layers.iter().enumerate().rev() {
            next_sweeps[i] = after;
            if !l.steps.is_empty() {
                after = starts_with_sweep(&l.steps);
            }
        }
        for (i, layer) in layers.iter().enumerate() {
            if !self.layer(i, &layer.steps, next_sweeps[i]) {
                return;
            }
        }
    }

    /// Simulates one layer; false if a fault ended the run.
    fn layer(&mut self, i: usize, steps: &[Step], next_sweeps: bool) -> bool {
        let preloaded = self.run_open && starts_with_sweep(steps);
        let start = self.t;
        let ready = if preloaded {
            start
        } else {
            start + self.m.load_s
        };
        self.rec = LayerRecord {
            index: i,
            start_s: start,
            time_s: 0.0,
            light_s: 0.0,
            mask_ready_s: ready,
            last_sweep_end_mm: None,
            quantization_s: 0.0,
            dose_quantization_s: 0.0,
            completed: false,
        };
        self.load_fail = None;
        self.motion_fault = None;
        if self.take_fault(FaultKind::MaskLoad, i) {
            self.load_fail = Some(ready);
            self.rec.mask_ready_s = f64::INFINITY;
        }
        for k in [FaultKind::Stall, FaultKind::Limit] {
            if self.motion_fault.is_none() && self.take_fault(k, i) {
                self.motion_fault = Some(k);
            }
        }
        if self.take_fault(FaultKind::ShutterStuck, i) {
            self.stuck = true;
        }
        if let Some(kind) = self.motion_fault {
            let has_motion = steps
                .iter()
                .any(|s| matches!(s, Step::Move { .. } | Step::Sweep { .. }));
            if !has_motion {
                let msg = format!(
                    "{kind} at the start of layer {i} (the layer has no move): stage stopped at {:.4} mm",
                    self.pos
                );
                self.abort(kind, self.t, msg, false);
                return false;
            }
        }
        for (k, step) in steps.iter().enumerate() {
            if self.run_open && !matches!(step, Step::Sweep { .. }) {
                let c = self.still(
                    SegKind::Close,
                    Some(k),
                    self.m.close_s,
                    ShutterState::Closing,
                );
                self.run_open = false;
                if !self.emit(c) {
                    return false;
                }
            }
            if !self.step(k, step) {
                return false;
            }
        }
        if self.run_open && !next_sweeps {
            let c = self.still(SegKind::Close, None, self.m.close_s, ShutterState::Closing);
            self.run_open = false;
            if !self.emit(c) {
                return false;
            }
        }
        if let Some(tf) = self.load_fail {
            // The steps ended before the DMD reported the failed load.
            if tf > self.t {
                let w = self.still(SegKind::LoadWait, None, tf - self.t, ShutterState::Closed);
                self.send(&w);
                self.t = tf;
            }
            let msg = self.mask_load_msg();
            self.abort(FaultKind::MaskLoad, self.t, msg, false);
            return false;
        }
        self.rec.time_s = self.t - start;
        self.rec.completed = true;
        self.finish_layer();
        true
    }

    fn finish_layer(&mut self) {
        let rec = self.rec.clone();
        for s in self.sinks.iter_mut() {
            s.layer_end(&rec);
        }
        self.records.push(rec);
    }

    fn invalid(&mut self, k: usize, msg: String) {
        self.invalid.push(Violation {
            layer: Some(self.rec.index),
            time_s: Some(self.t),
            kind: "invalid-step",
            message: format!("layer {} step {k}: {msg}; step skipped", self.rec.index),
            file: None,
        });
    }

    /// Waits (stage still) until the layer's mask is loaded.
    fn wait_for_mask(&mut self, k: usize) -> bool {
        let ready = self.load_fail.unwrap_or(self.rec.mask_ready_s);
        if ready > self.t {
            let w = self.still(
                SegKind::LoadWait,
                Some(k),
                ready - self.t,
                ShutterState::Closed,
            );
            return self.emit(w);
        }
        true
    }

    fn step(&mut self, k: usize, step: &Step) -> bool {
        let m = self.m;
        match *step {
            Step::Move {
                to_mm,
                speed_mm_s,
                accel_mm_s2,
            } => {
                let ok = |v: f64| v.is_finite() && v > 0.0;
                if !(ok(speed_mm_s) && ok(accel_mm_s2) && to_mm.is_finite()) {
                    self.invalid(
                        k,
                        format!(
                            "move to {to_mm} mm at {speed_mm_s} mm/s, {accel_mm_s2} mm/s² cannot be executed (speed and acceleration must be > 0)"
                        ),
                    );
                    return true;
                }
                let target = m.quantize(to_mm);
                let dur = move_time(target - self.pos, speed_mm_s, accel_mm_s2);
                let exact_dur = move_time(to_mm - self.exact, speed_mm_s, accel_mm_s2);
                self.rec.quantization_s += (dur - exact_dur).abs();
                self.exact = to_mm;
                let seg = Segment {
                    kind: SegKind::Move,
                    layer: self.rec.index,
                    step: Some(k),
                    t0: self.t,
                    t1: self.t + dur,
                    from_mm: self.pos,
                    to_mm: target,
                    motion: Motion::Trapezoid {
                        target_mm: target,
                        speed_mm_s,
                        accel_mm_s2,
                    },
                    shutter: ShutterState::Closed,
                    light: false,
                    mask_ready_s: self.rec.mask_ready_s,
                };
                self.emit(seg)
            }
            Step::Wait { s } => {
                if !(s.is_finite() && s >= 0.0) {
                    self.invalid(k, format!("wait of {s} s (must be >= 0)"));
                    return true;
                }
                let w = self.still(SegKind::Wait, Some(k), s, ShutterState::Closed);
                self.emit(w)
            }
            Step::Expose { s } => {
                if !(s.is_finite() && s >= 0.0) {
                    self.invalid(k, format!("expose of {s} s (must be >= 0)"));
                    return true;
                }
                if !self.wait_for_mask(k) {
                    return false;
                }
                let o = self.still(SegKind::Open, Some(k), m.open_s, ShutterState::Opening);
                if !self.emit(o) {
                    return false;
                }
                let e = self.still(SegKind::Expose, Some(k), s, ShutterState::Open);
                if !self.emit(e) {
                    return false;
                }
                let c = self.still(SegKind::Close, Some(k), m.close_s, ShutterState::Closing);
                self.emit(c)
            }
            Step::Sweep { to_mm, speed_mm_s } => {
                if !(speed_mm_s.is_finite() && speed_mm_s > 0.0 && to_mm.is_finite()) {
                    self.invalid(
                        k,
                        format!("sweep to {to_mm} mm at {speed_mm_s} mm/s (speed must be > 0)"),
                    );
                    return true;
                }
                if !self.run_open {
                    if !self.wait_for_mask(k) {
                        return false;
                    }
                    let o = self.still(SegKind::Open, Some(k), m.open_s, ShutterState::Opening);
                    self.run_open = true;
                    if !self.emit(o) {
                        return false;
                    }
                }
                let target = m.quantize(to_mm);
                let dist = target - self.pos;
                let dur = dist.abs() / speed_mm_s;
                let q = ((to_mm - self.exact).abs() - dist.abs()).abs() / speed_mm_s;
                self.rec.quantization_s += q;
                self.rec.dose_quantization_s += q;
                self.exact = to_mm;
                let seg = Segment {
                    kind: SegKind::Sweep,
                    layer: self.rec.index,
                    step: Some(k),
                    t0: self.t,
                    t1: self.t + dur,
                    from_mm: self.pos,
                    to_mm: target,
                    motion: Motion::Constant {
                        velocity_mm_s: speed_mm_s.copysign(dist),
                    },
                    shutter: ShutterState::Open,
                    light: true,
                    mask_ready_s: self.rec.mask_ready_s,
                };
                let ok = self.emit(seg);
                if ok {
                    self.rec.last_sweep_end_mm = Some(target);
                }
                ok
            }
        }
    }

    /// Sends a segment through fault injection; false if a fault ended the run.
    fn emit(&mut self, mut seg: Segment) -> bool {
        // Earliest fault that triggers in this segment, if any.
        let mut hit: Option<(f64, FaultKind)> = None;
        if let Some(tf) = self.load_fail {
            if seg.t0 >= tf || seg.t1 > tf {
                hit = Some((tf.max(seg.t0), FaultKind::MaskLoad));
            }
        }
        if let Some(kind) = self.motion_fault {
            if matches!(seg.kind, SegKind::Move | SegKind::Sweep) {
                let tm = 0.5 * (seg.t0 + seg.t1);
                match hit {
                    Some((t, _)) if t <= tm => {}
                    _ => hit = Some((tm, kind)),
                }
            }
        }
        if self.stuck && seg.kind == SegKind::Close && hit.is_none() {
            seg.kind = SegKind::StuckOpen;
            seg.shutter = ShutterState::Open;
            seg.light = true;
            self.send(&seg);
            self.rec.light_s += seg.duration();
            self.t = seg.t1;
            let msg = format!(
                "shutter stuck open: still open {:.3} s after the close command; DMD blanked, stage stopped at {:.4} mm; layer {} got {:.3} s of extra light",
                self.m.close_s, self.pos, self.rec.index, self.m.close_s
            );
            self.abort(FaultKind::ShutterStuck, seg.t1, msg, false);
            return false;
        }
        match hit {
            None => {
                self.send(&seg);
                if seg.light {
                    self.rec.light_s += seg.duration();
                }
                self.t = seg.t1;
                self.pos = seg.to_mm;
                true
            }
            Some((tf, kind)) => {
                let started = tf > seg.t0;
                let target = seg.to_mm;
                let was_open = started && seg.shutter != ShutterState::Closed;
                if started {
                    seg.to_mm = self.m.quantize(seg.position_at(tf));
                    seg.t1 = tf;
                    self.send(&seg);
                    if seg.light {
                        self.rec.light_s += seg.duration();
                    }
                    self.pos = seg.to_mm;
                }
                self.t = tf;
                let msg = match kind {
                    FaultKind::MaskLoad => self.mask_load_msg(),
                    FaultKind::Stall | FaultKind::Limit => {
                        let what = if kind == FaultKind::Stall {
                            "stage stalled"
                        } else {
                            "limit switch hit"
                        };
                        format!(
                            "{what} at {:.4} mm during the {} to {target:.4} mm (step {}); shutter closed, stage stopped",
                            self.pos,
                            seg.kind.name(),
                            seg.step.unwrap_or(0)
                        )
                    }
                    FaultKind::ShutterStuck => unreachable!("handled above"),
                };
                self.abort(kind, tf, msg, was_open);
                false
            }
        }
    }

    fn mask_load_msg(&self) -> String {
        let files: Vec<&str> = self.manifest.layers[self.rec.index]
            .masks
            .iter()
            .map(|m| m.file.as_str())
            .collect();
        format!(
            "DMD failed to load {}; shutter kept closed, stage stopped at {:.4} mm",
            if files.is_empty() {
                "the layer's mask".to_string()
            } else {
                files.join(", ")
            },
            self.pos
        )
    }

    /// Firmware reaction to a fault at time `tf`: close the shutter if it is (partly)
    /// open, stop the stage, end the run.
    fn abort(&mut self, kind: FaultKind, tf: f64, message: String, shutter_open: bool) {
        self.t = tf;
        if kind != FaultKind::ShutterStuck && (self.run_open || shutter_open) {
            let c = self.still(SegKind::Close, None, self.m.close_s, ShutterState::Closing);
            self.send(&c);
            self.t = c.t1;
        }
        self.run_open = false;
        self.rec.time_s = self.t - self.rec.start_s;
        self.rec.completed = false;
        self.finish_layer();
        self.fault = Some(FaultEvent {
            kind: kind.name(),
            layer: self.rec.index,
            time_s: tf,
            stage_mm: self.pos,
            message,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::Mode;
    use crate::exec::testutil::*;
    use crate::units::NonNegative;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    /// Two top-down layers, 0.5 mm: (dip, return, wait 10, expose 16 / 8).
    fn layered() -> crate::bundle::Manifest {
        two_layer_topdown()
    }

    fn sim(m: &crate::bundle::Manifest, faults: &[FaultSpec]) -> (Outcome, Collect) {
        let mut c = Collect::default();
        let o = simulate(m, faults, &mut [&mut c]);
        (o, c)
    }

    #[test]
    fn layered_times_follow_the_contract() {
        let (o, c) = sim(&layered(), &[]);
        // Layer 0: 5.5 mm at 2 mm/s, 50 mm/s²: 2·2/50 + (5.5 − 0.08)/2 = 2.79 s; back 5 mm at
        // 1 mm/s: 0.04 + 4.98 = 5.02 s; wait 10; open 0.05 + 16 + close 0.05.
        assert!(close(o.layers[0].time_s, 2.79 + 5.02 + 10.0 + 16.1));
        assert!(close(o.layers[1].time_s, 2.79 + 5.02 + 10.0 + 8.1));
        assert!(close(o.total_s, 59.82));
        assert!(close(o.layers[0].light_s, 16.0) && close(o.layers[1].light_s, 8.0));
        assert!(o.fault.is_none() && o.invalid_steps.is_empty());
        // Segments tile time without gaps, light only in expose, never while moving.
        for w in c.segs.windows(2) {
            assert!(close(w[0].t1, w[1].t0), "{w:?}");
        }
        for s in &c.segs {
            assert_eq!(s.light, s.kind == SegKind::Expose, "{s:?}");
            if s.kind == SegKind::Expose {
                assert_eq!(s.from_mm, [0.5, 1.0][s.layer]);
            }
        }
        // The DMD load (0.02 s) runs during the first move: no load wait.
        assert!(c.segs.iter().all(|s| s.kind != SegKind::LoadWait));
        assert!(close(c.layers[1].mask_ready_s, 33.91 + 0.02));
    }

    #[test]
    fn expose_waits_for_the_dmd_load() {
        let mut p = profile();
        p.dmd.load_s = NonNegative::new(0.5).unwrap();
        p.stage.home_mm = 0.1;
        let m = manifest(
            p,
            vec![
                // At home already: waits the whole load.
                layer(
                    0,
                    0.1,
                    0.1,
                    Mode::Layered,
                    1.0,
                    vec![Step::Expose { s: 1.0 }],
                    1.6,
                ),
                // 0.1 mm at 1 mm/s, 50 mm/s²: 0.04 + 0.08 = 0.12 s, then waits to 0.5 s.
                layer(
                    1,
                    0.2,
                    0.1,
                    Mode::Layered,
                    1.0,
                    vec![
                        Step::Move {
                            to_mm: 0.2,
                            speed_mm_s: 1.0,
                            accel_mm_s2: 50.0,
                        },
                        Step::Expose { s: 1.0 },
                    ],
                    1.6,
                ),
                // A 1 s wait hides the load.
                layer(
                    2,
                    0.3,
                    0.1,
                    Mode::Layered,
                    1.0,
                    vec![
                        Step::Wait { s: 1.0 },
                        Step::Move {
                            to_mm: 0.3,
                            speed_mm_s: 1.0,
                            accel_mm_s2: 50.0,
                        },
                        Step::Expose { s: 1.0 },
                    ],
                    2.22,
                ),
            ],
        );
        let (o, c) = sim(&m, &[]);
        assert!(close(o.layers[0].time_s, 0.5 + 0.05 + 1.0 + 0.05));
        assert!(close(o.layers[1].time_s, 0.5 + 0.05 + 1.0 + 0.05));
        assert!(close(o.layers[2].time_s, 1.0 + 0.12 + 1.1));
        let waits: Vec<f64> = c
            .segs
            .iter()
            .filter(|s| s.kind == SegKind::LoadWait)
            .map(|s| s.duration())
            .collect();
        assert_eq!(waits.len(), 2);
        assert!(close(waits[0], 0.5) && close(waits[1], 0.5 - 0.12));
    }

    fn sweeps(mode: Mode) -> crate::bundle::Manifest {
        let l = |i: usize, t: f64| {
            let z = 0.1 * (i + 1) as f64;
            layer(
                i,
                z,
                0.1,
                mode,
                2.0,
                vec![Step::Sweep {
                    to_mm: z,
                    speed_mm_s: 0.05,
                }],
                t,
            )
        };
        manifest(profile(), vec![l(0, 2.07), l(1, 2.0), l(2, 2.05)])
    }

    #[test]
    fn a_sweep_run_keeps_the_shutter_open_across_layers() {
        let (o, c) = sim(&sweeps(Mode::Continuous), &[]);
        // Layer 0 waits for its mask (0.02 s), opens (0.05 s), sweeps 0.1 mm at 0.05 mm/s.
        assert!(close(o.layers[0].time_s, 0.02 + 0.05 + 2.0));
        // Later masks are preloaded: no load time inside the run.
        assert!(close(o.layers[1].time_s, 2.0));
        assert!(close(c.layers[1].mask_ready_s, c.layers[1].start_s));
        // The last layer closes the shutter.
        assert!(close(o.layers[2].time_s, 2.0 + 0.05));
        let opens = c.segs.iter().filter(|s| s.kind == SegKind::Open).count();
        let closes = c.segs.iter().filter(|s| s.kind == SegKind::Close).count();
        assert_eq!((opens, closes), (1, 1));
        for r in &o.layers {
            assert!(close(r.light_s, 2.0));
            assert!(close(
                r.last_sweep_end_mm.unwrap(),
                0.1 * (r.index + 1) as f64
            ));
        }
        let sw: Vec<_> = c.segs.iter().filter(|s| s.kind == SegKind::Sweep).collect();
        assert!(sw.iter().all(|s| s.light && s.velocity_at(s.t0) == 0.05));
    }

    #[test]
    fn a_layer_without_steps_does_not_end_a_sweep_run() {
        let mut m = sweeps(Mode::Continuous);
        m.layers[1].steps.clear();
        m.layers[2].steps = vec![Step::Sweep {
            to_mm: 0.3,
            speed_mm_s: 0.05,
        }];
        let (o, c) = sim(&m, &[]);
        assert!(close(o.layers[0].time_s, 2.07));
        assert_eq!(o.layers[1].time_s, 0.0);
        assert!(close(o.layers[2].time_s, 4.0 + 0.05));
        let opens = c.segs.iter().filter(|s| s.kind == SegKind::Open).count();
        assert_eq!(opens, 1);
    }

    #[test]
    fn positions_are_quantized_to_steps() {
        let m = manifest(
            profile(),
            vec![layer(
                0,
                0.1234,
                0.1234,
                Mode::Layered,
                1.0,
                vec![
                    Step::Move {
                        to_mm: 0.1234,
                        speed_mm_s: 1.0,
                        accel_mm_s2: 50.0,
                    },
                    Step::Expose { s: 1.0 },
                ],
                1.2,
            )],
        );
        let (o, c) = sim(&m, &[]);
        // 0.1234 mm × 800 = 98.72 steps → 99 steps = 0.12375 mm.
        let mv = c.segs.iter().find(|s| s.kind == SegKind::Move).unwrap();
        assert_eq!(mv.to_mm, 0.12375);
        assert!(close(mv.duration(), 0.04 + (0.12375 - 0.02)));
        let q = (move_time(0.12375, 1.0, 50.0) - move_time(0.1234, 1.0, 50.0)).abs();
        assert!(close(o.layers[0].quantization_s, q));
    }

    #[test]
    fn invalid_steps_are_reported_and_skipped() {
        let mut steps = recoat_steps(0.5, 1.0, 2.0);
        steps.insert(
            0,
            Step::Move {
                to_mm: 3.0,
                speed_mm_s: 0.0,
                accel_mm_s2: 50.0,
            },
        );
        steps.push(Step::Wait { s: -1.0 });
        let m = manifest(
            profile(),
            vec![layer(0, 0.5, 0.5, Mode::Layered, 2.0, steps, 10.91)],
        );
        let (o, _) = sim(&m, &[]);
        assert_eq!(o.invalid_steps.len(), 2);
        assert!(o.invalid_steps[0].message.contains("layer 0 step 0"));
        assert!(o.invalid_steps[1].message.contains("step 5"));
        assert!(close(o.total_s, 2.79 + 5.02 + 1.0 + 2.1));
    }

    fn last_light_off(c: &Collect) -> bool {
        let last = c.segs.last().unwrap();
        !last.light && last.velocity_at(last.t1) == 0.0
    }

    #[test]
    fn stall_and_limit_stop_the_stage_halfway_through_the_first_move() {
        for kind in [FaultKind::Stall, FaultKind::Limit] {
            let (o, c) = sim(&layered(), &[FaultSpec { kind, layer: 1 }]);
            let f = o.fault.unwrap();
            assert_eq!((f.kind, f.layer), (kind.name(), 1));
            // Layer 1 starts at 33.91 s; its first move (0.5 → 6.0 mm) takes 2.79 s.
            assert!(close(f.time_s, 33.91 + 2.79 / 2.0));
            let want = Machine::from_profile(&profile()).quantize(position_at(
                0.5,
                6.0,
                2.0,
                50.0,
                2.79 / 2.0,
            ));
            assert!(close(f.stage_mm, want), "{} {want}", f.stage_mm);
            assert!(close(o.total_s, f.time_s));
            assert_eq!(o.layers.len(), 2);
            assert!(!o.layers[1].completed && o.layers[0].completed);
            assert!(last_light_off(&c));
        }
    }

    #[test]
    fn a_stall_during_a_sweep_closes_the_shutter() {
        let (o, c) = sim(
            &sweeps(Mode::Continuous),
            &[FaultSpec {
                kind: FaultKind::Stall,
                layer: 1,
            }],
        );
        let f = o.fault.unwrap();
        assert!(close(f.time_s, 2.07 + 1.0));
        assert!(close(f.stage_mm, 0.15));
        let last = c.segs.last().unwrap();
        assert_eq!(last.kind, SegKind::Close);
        assert!(close(last.t0, f.time_s) && close(o.total_s, f.time_s + 0.05));
        assert!(close(o.layers[1].light_s, 1.0));
    }

    #[test]
    fn a_failed_mask_load_stops_the_stage_with_the_shutter_closed() {
        let (o, c) = sim(
            &layered(),
            &[FaultSpec {
                kind: FaultKind::MaskLoad,
                layer: 1,
            }],
        );
        let f = o.fault.unwrap();
        assert_eq!((f.kind, f.layer), ("mask-load", 1));
        assert!(close(f.time_s, 33.91 + 0.02));
        // 0.02 s into a move accelerating at 50 mm/s²: 0.01 mm.
        assert!(close(f.stage_mm, 0.51));
        assert!(f.message.contains("masks/00001.png"));
        assert!(c.segs.iter().filter(|s| s.layer == 1).all(|s| !s.light));
        assert!(last_light_off(&c));
    }

    #[test]
    fn a_stuck_shutter_blanks_the_dmd_after_the_close_latency() {
        let (o, c) = sim(
            &layered(),
            &[FaultSpec {
                kind: FaultKind::ShutterStuck,
                layer: 0,
            }],
        );
        let f = o.fault.unwrap();
        assert_eq!((f.kind, f.layer), ("shutter-stuck", 0));
        // Close commanded at 2.79 + 5.02 + 10 + 0.05 + 16 = 33.86 s, detected 0.05 s later.
        assert!(close(f.time_s, 33.91));
        assert!(close(o.layers[0].light_s, 16.05));
        let last = c.segs.last().unwrap();
        assert_eq!(last.kind, SegKind::StuckOpen);
        assert!(close(o.total_s, 33.91));
    }

    #[test]
    fn untriggered_faults_are_listed() {
        // No shutter close at or after layer 0 of a job without light.
        let m = manifest(
            profile(),
            vec![layer(
                0,
                0.5,
                0.5,
                Mode::Layered,
                0.0,
                vec![Step::Wait { s: 1.0 }],
                1.0,
            )],
        );
        let spec = FaultSpec {
            kind: FaultKind::ShutterStuck,
            layer: 0,
        };
        let (o, _) = sim(&m, &[spec]);
        assert!(o.fault.is_none());
        assert_eq!(o.untriggered, vec![spec]);
    }

    #[test]
    fn fault_specs_parse() {
        let f: FaultSpec = "shutter-stuck@12".parse().unwrap();
        assert_eq!(
            f,
            FaultSpec {
                kind: FaultKind::ShutterStuck,
                layer: 12
            }
        );
        assert!("stall"
            .parse::<FaultSpec>()
            .unwrap_err()
            .contains("KIND@LAYER"));
        assert!("jam@1"
            .parse::<FaultSpec>()
            .unwrap_err()
            .contains("unknown kind"));
        assert!("limit@-1".parse::<FaultSpec>().is_err());
    }

    #[test]
    fn velocity_profile_is_consistent_with_positions() {
        let m = layered();
        let (_, c) = sim(&m, &[]);
        let mv = c.segs.iter().find(|s| s.kind == SegKind::Move).unwrap();
        // Numerical derivative of the position matches the reported velocity.
        let mut t = mv.t0 + 1e-3;
        while t < mv.t1 - 1e-3 {
            let d = (mv.position_at(t + 1e-6) - mv.position_at(t - 1e-6)) / 2e-6;
            assert!((d - mv.velocity_at(t)).abs() < 1e-3, "{t} {d}");
            t += 0.01;
        }
        let mut times = vec![];
        mv.phase_times(&mut times);
        assert_eq!(times.len(), 3);
        assert!(close(times[1] - times[0], 0.04));
        assert_eq!(mv.peak_speed(), 2.0);
    }
}
