//! The walk through a job's steps: the simulation's state, and each step turned into
//! timed segments under the bundle's timing contract (moves, waits, exposures, sweep runs
//! that keep the shutter open across layers, DMD loads an exposure waits for).

use super::{FaultEvent, FaultKind, FaultSpec, LayerRecord, Machine, Sink};
use super::{Motion, SegKind, Segment, ShutterState};
use crate::bundle::{Manifest, Step};
use crate::exec::{Kind, Violation};
use crate::motion::move_time;
use crate::text::number;

/// The state of one simulation run: the machine, the clock, the stage, the shutter of a
/// sweep run, the faults and what was measured so far.
pub(super) struct Simulation<'a, 's, 'k> {
    pub(super) machine: Machine,
    pub(super) manifest: &'a Manifest,
    pub(super) sinks: &'s mut [&'k mut dyn Sink],
    /// Current time, s.
    pub(super) t: f64,
    /// Current stage position, mm (quantized).
    pub(super) pos: f64,
    /// Unquantized position the steps asked for, mm (to bound quantization effects).
    pub(super) exact_mm: f64,
    /// The shutter is open in a sweep run.
    pub(super) run_open: bool,
    /// Injected faults not yet armed.
    pub(super) pending_faults: Vec<FaultSpec>,
    /// The current layer's record.
    pub(super) record: LayerRecord,
    /// A mask-load failure armed for the current layer: when the DMD reports it, s.
    pub(super) mask_load_fault_s: Option<f64>,
    /// Stall or limit armed for the current layer's first motion.
    pub(super) motion_fault: Option<FaultKind>,
    /// A stuck-shutter fault is armed.
    pub(super) shutter_stuck: bool,
    /// The fault that ended the run.
    pub(super) fault: Option<FaultEvent>,
    /// Steps that cannot be executed, skipped.
    pub(super) invalid_steps: Vec<Violation>,
    /// One record per finished (or aborted) layer.
    pub(super) records: Vec<LayerRecord>,
}

/// Does the step list start a sweep (so a sweep run continues into it)?
fn starts_with_sweep(steps: &[Step]) -> bool {
    matches!(steps.first(), Some(Step::Sweep { .. }))
}

impl<'a, 's, 'k> Simulation<'a, 's, 'k> {
    /// A simulation of `manifest` on its machine, stage homed, at time 0.
    pub(super) fn new(
        manifest: &'a Manifest,
        faults: &[FaultSpec],
        sinks: &'s mut [&'k mut dyn Sink],
    ) -> Self {
        let machine = Machine::of(&manifest.machine);
        Simulation {
            machine,
            manifest,
            sinks,
            t: 0.0,
            pos: machine.quantize(machine.home_mm),
            exact_mm: machine.home_mm,
            run_open: false,
            pending_faults: faults.to_vec(),
            record: LayerRecord::starting(0, 0.0, 0.0),
            mask_load_fault_s: None,
            motion_fault: None,
            shutter_stuck: false,
            fault: None,
            invalid_steps: Vec::new(),
            records: Vec::with_capacity(manifest.layers.len()),
        }
    }
}

impl Simulation<'_, '_, '_> {
    /// Hands `seg` to every sink.
    pub(super) fn send(&mut self, seg: &Segment) {
        for s in self.sinks.iter_mut() {
            s.segment(seg);
        }
    }

    /// A segment of the current layer from now, `dur` long, taking the stage to `to.0`
    /// with motion `to.1`; light on while the shutter is open.
    fn segment(
        &self,
        (kind, step): (SegKind, Option<usize>),
        dur: f64,
        to: (f64, Motion),
        shutter: ShutterState,
    ) -> Segment {
        Segment {
            kind,
            layer: self.record.index,
            step,
            t0: self.t,
            t1: self.t + dur,
            from_mm: self.pos,
            to_mm: to.0,
            motion: to.1,
            shutter,
            light: shutter == ShutterState::Open,
            mask_ready_s: self.record.mask_ready_s,
        }
    }

    /// A segment of the current layer from now, `dur` long, with the stage still.
    pub(super) fn still_segment(
        &self,
        kind: SegKind,
        step: Option<usize>,
        dur: f64,
        shutter: ShutterState,
    ) -> Segment {
        self.segment((kind, step), dur, (self.pos, Motion::Still), shutter)
    }

    /// Homes the stage and simulates every layer, until the end or a fault.
    pub(super) fn run(&mut self) {
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
                self.machine.load_s
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
            if !self.simulate_layer(i, &layer.steps, next_sweeps[i]) {
                return;
            }
        }
    }

    /// Simulates one layer; false if a fault ended the run.
    fn simulate_layer(&mut self, i: usize, steps: &[Step], next_sweeps: bool) -> bool {
        let preloaded = self.run_open && starts_with_sweep(steps);
        let start = self.t;
        let ready = if preloaded {
            start
        } else {
            start + self.machine.load_s
        };
        self.record = LayerRecord::starting(i, start, ready);
        if !self.arm_faults(steps) {
            return false;
        }
        for (k, step) in steps.iter().enumerate() {
            let ends_run = self.run_open && !matches!(step, Step::Sweep { .. });
            if (ends_run && !self.end_sweep_run(Some(k))) || !self.step(k, step) {
                return false;
            }
        }
        if self.run_open && !next_sweeps && !self.end_sweep_run(None) {
            return false;
        }
        if let Some(tf) = self.mask_load_fault_s {
            // The steps ended before the DMD reported the failed load.
            if tf > self.t {
                let w =
                    self.still_segment(SegKind::LoadWait, None, tf - self.t, ShutterState::Closed);
                self.send(&w);
                self.t = tf;
            }
            let msg = self.mask_load_msg();
            self.abort(FaultKind::MaskLoad, self.t, msg, false);
            return false;
        }
        self.record.time_s = self.t - start;
        self.record.completed = true;
        self.finish_layer();
        true
    }

    /// Closes the shutter a sweep run kept open (before step `step`, or at the layer's
    /// end); false if a fault ended the run.
    fn end_sweep_run(&mut self, step: Option<usize>) -> bool {
        let m = self.machine;
        let c = self.still_segment(SegKind::Close, step, m.close_s, ShutterState::Closing);
        self.run_open = false;
        self.emit(c)
    }

    /// Hands the current layer's record to every sink and keeps it.
    pub(super) fn finish_layer(&mut self) {
        let rec = self.record.clone();
        for s in self.sinks.iter_mut() {
            s.layer_end(&rec);
        }
        self.records.push(rec);
    }

    /// Reports step `k` of the current layer as impossible to execute (it is skipped).
    fn report_invalid_step(&mut self, k: usize, msg: String) {
        self.invalid_steps.push(Violation {
            layer: Some(self.record.index),
            time_s: Some(self.t),
            kind: Kind::InvalidStep,
            message: format!("layer {} step {k}: {msg}; step skipped", self.record.index),
            file: None,
        });
    }

    /// Reports step `k` (`what`) as impossible and true when it would take `dur` from now
    /// to a time no clock holds (not finite): it is skipped, so every simulated figure
    /// stays finite.
    fn endless(&mut self, k: usize, dur: f64, what: impl FnOnce() -> String) -> bool {
        let endless = !(self.t + dur).is_finite();
        if endless {
            let msg = format!("{} never ends ({} s)", what(), number(dur));
            self.report_invalid_step(k, msg);
        }
        endless
    }

    /// Waits (stage still) until the layer's mask is loaded.
    fn wait_for_mask(&mut self, k: usize) -> bool {
        let ready = self.mask_load_fault_s.unwrap_or(self.record.mask_ready_s);
        if ready > self.t {
            let w = self.still_segment(
                SegKind::LoadWait,
                Some(k),
                ready - self.t,
                ShutterState::Closed,
            );
            return self.emit(w);
        }
        true
    }

    /// Simulates step `k` of the current layer; false if a fault ended the run.
    fn step(&mut self, k: usize, step: &Step) -> bool {
        match *step {
            Step::Move {
                to_mm,
                speed_mm_s,
                accel_mm_s2,
            } => self.move_stage(k, to_mm, speed_mm_s, accel_mm_s2),
            Step::Wait { s } => self.wait(k, s),
            Step::Expose { s } => self.expose(k, s),
            Step::Sweep { to_mm, speed_mm_s } => self.sweep(k, to_mm, speed_mm_s),
        }
    }

    /// A `move` step: a trapezoidal move to the quantized target, shutter closed.
    fn move_stage(&mut self, k: usize, to_mm: f64, speed_mm_s: f64, accel_mm_s2: f64) -> bool {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !(ok(speed_mm_s) && ok(accel_mm_s2) && to_mm.is_finite()) {
            self.report_invalid_step(
                k,
                format!(
                    "move to {} mm at {} mm/s, {} mm/s² cannot be executed (speed and acceleration must be > 0)",
                    number(to_mm),
                    number(speed_mm_s),
                    number(accel_mm_s2)
                ),
            );
            return true;
        }
        let target = self.machine.quantize(to_mm);
        let dur = move_time(target - self.pos, speed_mm_s, accel_mm_s2);
        let exact_dur = move_time(to_mm - self.exact_mm, speed_mm_s, accel_mm_s2);
        if self.endless(k, dur + exact_dur, || {
            format!("move to {} mm", number(to_mm))
        }) {
            return true;
        }
        self.record.quantization_s += (dur - exact_dur).abs();
        self.exact_mm = to_mm;
        let motion = Motion::Trapezoid {
            target_mm: target,
            speed_mm_s,
            accel_mm_s2,
        };
        let seg = self.segment(
            (SegKind::Move, Some(k)),
            dur,
            (target, motion),
            ShutterState::Closed,
        );
        self.emit(seg)
    }

    /// A `wait` step of `s` seconds.
    fn wait(&mut self, k: usize, s: f64) -> bool {
        if !(s.is_finite() && s >= 0.0) {
            self.report_invalid_step(k, format!("wait of {} s (must be >= 0)", number(s)));
            return true;
        }
        if self.endless(k, s, || "wait".into()) {
            return true;
        }
        let w = self.still_segment(SegKind::Wait, Some(k), s, ShutterState::Closed);
        self.emit(w)
    }

    /// An `expose` step of `s` seconds: wait for the mask, open, light, close.
    fn expose(&mut self, k: usize, s: f64) -> bool {
        if !(s.is_finite() && s >= 0.0) {
            self.report_invalid_step(k, format!("expose of {} s (must be >= 0)", number(s)));
            return true;
        }
        let m = self.machine;
        if self.endless(k, m.open_s + s + m.close_s + m.load_s, || "expose".into()) {
            return true;
        }
        if !self.wait_for_mask(k) {
            return false;
        }
        let o = self.still_segment(SegKind::Open, Some(k), m.open_s, ShutterState::Opening);
        if !self.emit(o) {
            return false;
        }
        let e = self.still_segment(SegKind::Expose, Some(k), s, ShutterState::Open);
        if !self.emit(e) {
            return false;
        }
        let c = self.still_segment(SegKind::Close, Some(k), m.close_s, ShutterState::Closing);
        self.emit(c)
    }

    /// A `sweep` step: the stage moves at constant speed with the light on; the first
    /// sweep of a run waits for the mask and opens the shutter.
    fn sweep(&mut self, k: usize, to_mm: f64, speed_mm_s: f64) -> bool {
        if !(speed_mm_s.is_finite() && speed_mm_s > 0.0 && to_mm.is_finite()) {
            self.report_invalid_step(
                k,
                format!(
                    "sweep to {} mm at {} mm/s (speed must be > 0)",
                    number(to_mm),
                    number(speed_mm_s)
                ),
            );
            return true;
        }
        let target = self.machine.quantize(to_mm);
        let dist = target - self.pos;
        let dur = dist.abs() / speed_mm_s;
        let (m, what) = (self.machine, || format!("sweep to {} mm", number(to_mm)));
        if self.endless(k, dur + m.open_s + m.load_s, what) {
            return true;
        }
        if !self.run_open {
            if !self.wait_for_mask(k) {
                return false;
            }
            let o = self.still_segment(
                SegKind::Open,
                Some(k),
                self.machine.open_s,
                ShutterState::Opening,
            );
            self.run_open = true;
            if !self.emit(o) {
                return false;
            }
        }
        let q = ((to_mm - self.exact_mm).abs() - dist.abs()).abs() / speed_mm_s;
        self.record.quantization_s += q;
        self.record.dose_quantization_s += q;
        self.exact_mm = to_mm;
        let motion = Motion::Constant {
            velocity_mm_s: speed_mm_s.copysign(dist),
        };
        let seg = self.segment(
            (SegKind::Sweep, Some(k)),
            dur,
            (target, motion),
            ShutterState::Open,
        );
        let ok = self.emit(seg);
        if ok {
            self.record.last_sweep_end_mm = Some(target);
        }
        ok
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{close, layered, run_collecting, sweeps};
    use super::super::SegKind;
    use crate::bundle::{Mode, Step};
    use crate::exec::testutil::*;
    use crate::motion::move_time;
    use crate::units::NonNegative;

    #[test]
    fn layered_times_follow_the_contract() {
        let (o, c) = run_collecting(&layered(), &[]);
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
        let expose = Step::Expose { s: 1.0 };
        let steps = [
            // At home already: waits the whole load.
            vec![expose],
            // 0.1 mm at 1 mm/s, 50 mm/s²: 0.04 + 0.08 = 0.12 s, then waits to 0.5 s.
            vec![move_to(0.2, 1.0, 50.0), expose],
            // A 1 s wait hides the load.
            vec![Step::Wait { s: 1.0 }, move_to(0.3, 1.0, 50.0), expose],
        ];
        let (z, times) = ([0.1, 0.2, 0.3], [1.6, 1.6, 2.22]);
        let layers = steps.into_iter().enumerate();
        let layers = layers.map(|(i, st)| layer(i, z[i], 0.1, Mode::Layered, 1.0, st, times[i]));
        let m = manifest(p, layers.collect());
        let (o, c) = run_collecting(&m, &[]);
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

    #[test]
    fn a_sweep_run_keeps_the_shutter_open_across_layers() {
        let (o, c) = run_collecting(&sweeps(Mode::Continuous), &[]);
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
        m.layers[2].steps = vec![sweep_to(0.3, 0.05)];
        let (o, c) = run_collecting(&m, &[]);
        assert!(close(o.layers[0].time_s, 2.07));
        assert_eq!(o.layers[1].time_s, 0.0);
        assert!(close(o.layers[2].time_s, 4.0 + 0.05));
        let opens = c.segs.iter().filter(|s| s.kind == SegKind::Open).count();
        assert_eq!(opens, 1);
    }

    #[test]
    fn positions_are_quantized_to_steps() {
        let steps = vec![move_to(0.1234, 1.0, 50.0), Step::Expose { s: 1.0 }];
        let l = layer(0, 0.1234, 0.1234, Mode::Layered, 1.0, steps, 1.2);
        let m = manifest(profile(), vec![l]);
        let (o, c) = run_collecting(&m, &[]);
        // 0.1234 mm × 800 = 98.72 steps → 99 steps = 0.12375 mm.
        let mv = c.segs.iter().find(|s| s.kind == SegKind::Move).unwrap();
        assert_eq!(mv.to_mm, 0.12375);
        assert!(close(mv.duration(), 0.04 + (0.12375 - 0.02)));
        let q = (move_time(0.12375, 1.0, 50.0) - move_time(0.1234, 1.0, 50.0)).abs();
        assert!(close(o.layers[0].quantization_s, q));
    }

    #[test]
    fn a_step_that_would_end_past_any_clock_is_skipped() {
        // Two waits of 1e308 s: the second would end at infinity.
        let steps = vec![Step::Wait { s: 1e308 }, Step::Wait { s: 1e308 }];
        let l = layer(0, 0.5, 0.5, Mode::Layered, 0.0, steps, 1.0);
        let mut m = manifest(profile(), vec![l]);
        m.layers[0].steps.push(move_to(0.5, 1e-310, 50.0));
        let (o, _) = run_collecting(&m, &[]);
        assert_eq!(o.total_s, 1e308);
        let msgs: Vec<&str> = o.invalid_steps.iter().map(|v| v.message.as_str()).collect();
        assert_eq!(
            msgs,
            [
                "layer 0 step 1: wait never ends (1e308 s); step skipped",
                "layer 0 step 2: move to 0.5 mm never ends (inf s); step skipped"
            ]
        );
    }

    #[test]
    fn invalid_steps_are_reported_and_skipped() {
        let mut steps = recoat_steps(0.5, 1.0, 2.0);
        steps.insert(0, move_to(3.0, 0.0, 50.0));
        steps.push(Step::Wait { s: -1.0 });
        let l = layer(0, 0.5, 0.5, Mode::Layered, 2.0, steps, 10.91);
        let m = manifest(profile(), vec![l]);
        let (o, _) = run_collecting(&m, &[]);
        assert_eq!(o.invalid_steps.len(), 2);
        assert!(o.invalid_steps[0].message.contains("layer 0 step 0"));
        assert!(o.invalid_steps[1].message.contains("step 5"));
        assert!(close(o.total_s, 2.79 + 5.02 + 1.0 + 2.1));
    }
}
