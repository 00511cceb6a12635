//! Injected faults (`--fault KIND@LAYER`) and the firmware's reaction: a fault is armed
//! when its layer starts, triggers in the segment where it happens, and ends the run with
//! the shutter closed (or the DMD blanked when the shutter is stuck) and the stage stopped.

use super::steps::Simulation;
use super::{SegKind, Segment, ShutterState};
use crate::bundle::Step;
use crate::text::fixed;
use std::fmt;
use std::str::FromStr;

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

    /// Name on the command line and in reports: its violation kind's
    /// ([`crate::exec::Kind`]).
    pub fn name(self) -> &'static str {
        crate::exec::Kind::from(self).name()
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
            .ok_or_else(|| format!("--fault {s}: expected KIND@LAYER (kinds: {names})"))?;
        let kind = FaultKind::ALL
            .into_iter()
            .find(|f| f.name() == k.trim())
            .ok_or_else(|| format!("--fault {s}: unknown kind {k:?} (kinds: {names})"))?;
        let layer = l
            .trim()
            .parse::<usize>()
            .map_err(|_| format!("--fault {s}: layer {l:?} is not a layer index"))?;
        Ok(FaultSpec { kind, layer })
    }
}

impl serde::Serialize for FaultKind {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// A fault that happened during the run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FaultEvent {
    /// What failed.
    pub kind: FaultKind,
    /// Layer during which it happened.
    pub layer: usize,
    /// Time the firmware detected it, s.
    #[serde(serialize_with = "crate::round::six")]
    pub time_s: f64,
    /// Where the stage stopped, mm.
    #[serde(serialize_with = "crate::round::six")]
    pub stage_mm: f64,
    /// What happened and what the firmware did.
    pub message: String,
}

impl Simulation<'_, '_, '_> {
    /// Takes the injected fault `kind@layer` out of the pending ones; false if it is not there.
    fn take_fault(&mut self, kind: FaultKind, layer: usize) -> bool {
        if let Some(i) = self
            .pending_faults
            .iter()
            .position(|f| f.kind == kind && f.layer == layer)
        {
            self.pending_faults.remove(i);
            true
        } else {
            false
        }
    }

    /// Arms the faults injected at the layer that just started (`self.record`); false if
    /// one ends the run at once (a stall or limit in a layer that does not move).
    pub(super) fn arm_faults(&mut self, steps: &[Step]) -> bool {
        let i = self.record.index;
        self.mask_load_fault_s = None;
        self.motion_fault = None;
        if self.take_fault(FaultKind::MaskLoad, i) {
            self.mask_load_fault_s = Some(self.record.mask_ready_s);
            self.record.mask_ready_s = f64::INFINITY;
        }
        for k in [FaultKind::Stall, FaultKind::Limit] {
            if self.motion_fault.is_none() && self.take_fault(k, i) {
                self.motion_fault = Some(k);
            }
        }
        if self.take_fault(FaultKind::ShutterStuck, i) {
            self.shutter_stuck = true;
        }
        if let Some(kind) = self.motion_fault {
            let has_motion = steps
                .iter()
                .any(|s| matches!(s, Step::Move { .. } | Step::Sweep { .. }));
            if !has_motion {
                let msg = format!(
                    "{kind} at the start of layer {i} (the layer has no move): stage stopped at {} mm",
                    fixed(self.pos, 4)
                );
                self.abort(kind, self.t, msg, false);
                return false;
            }
        }
        true
    }

    /// Sends a segment through fault injection; false if a fault ended the run.
    pub(super) fn emit(&mut self, mut seg: Segment) -> bool {
        // Earliest fault that triggers in this segment, if any.
        let mut hit: Option<(f64, FaultKind)> = None;
        if let Some(tf) = self.mask_load_fault_s {
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
        if self.shutter_stuck && seg.kind == SegKind::Close && hit.is_none() {
            // The firmware finds the shutter still open when it should have closed
            // (`close_s`), then blanks the DMD: a dark frame loads like a mask (`load_s`).
            // The light stays on until then.
            let (close_s, load_s) = (self.machine.close_s, self.machine.load_s);
            seg.kind = SegKind::StuckOpen;
            seg.shutter = ShutterState::Open;
            seg.light = true;
            seg.t1 = seg.t0 + close_s + load_s;
            self.send_counted(&seg);
            self.t = seg.t1;
            let (at, i, extra) = (fixed(self.pos, 4), self.record.index, seg.duration());
            let msg = format!("shutter stuck open: still open {close_s:.3} s after the close command; DMD blanked {load_s:.3} s later, stage stopped at {at} mm; layer {i} got {extra:.3} s of extra light");
            self.abort(FaultKind::ShutterStuck, seg.t1, msg, false);
            return false;
        }
        match hit {
            None => {
                self.send_counted(&seg);
                self.t = seg.t1;
                self.pos = seg.to_mm;
                true
            }
            Some((tf, kind)) => {
                let started = tf > seg.t0;
                let target = seg.to_mm;
                let was_open = started && seg.shutter != ShutterState::Closed;
                if started {
                    seg.to_mm = self.machine.quantize(seg.position_at(tf));
                    seg.t1 = tf;
                    self.send_counted(&seg);
                    self.pos = seg.to_mm;
                }
                self.t = tf;
                let msg = match kind {
                    FaultKind::MaskLoad => self.mask_load_msg(),
                    FaultKind::Stall | FaultKind::Limit => {
                        let what = match kind {
                            FaultKind::Stall => "stage stalled",
                            _ => "limit switch hit",
                        };
                        let (at, to) = (fixed(self.pos, 4), fixed(target, 4));
                        let (during, step) = (seg.kind.name(), seg.step.unwrap_or(0));
                        format!("{what} at {at} mm during the {during} to {to} mm (step {step}); shutter closed, stage stopped")
                    }
                    FaultKind::ShutterStuck => unreachable!("handled above"),
                };
                self.abort(kind, tf, msg, was_open);
                false
            }
        }
    }

    /// Hands `seg` to the sinks and adds its light to the layer's.
    fn send_counted(&mut self, seg: &Segment) {
        self.send(seg);
        if seg.light {
            self.record.light_s += seg.duration();
        }
    }

    /// What the firmware reports when the DMD fails to load the current layer's mask.
    pub(super) fn mask_load_msg(&self) -> String {
        let files: Vec<&str> = self.manifest.layers[self.record.index]
            .masks
            .iter()
            .map(|m| m.file.as_str())
            .collect();
        let masks = match files.len() {
            0 => "the layer's mask".to_string(),
            _ => files.join(", "),
        };
        let at = fixed(self.pos, 4);
        format!("DMD failed to load {masks}; shutter kept closed, stage stopped at {at} mm")
    }

    /// Firmware reaction to a fault at time `tf`: close the shutter if it is (partly)
    /// open, stop the stage, end the run.
    pub(super) fn abort(&mut self, kind: FaultKind, tf: f64, message: String, shutter_open: bool) {
        self.t = tf;
        if kind != FaultKind::ShutterStuck && (self.run_open || shutter_open) {
            let m = self.machine;
            let c = self.still_segment(SegKind::Close, None, m.close_s, ShutterState::Closing);
            self.send(&c);
            self.t = c.t1;
        }
        self.run_open = false;
        self.record.time_s = self.t - self.record.start_s;
        self.record.completed = false;
        self.finish_layer();
        self.fault = Some(FaultEvent {
            kind,
            layer: self.record.index,
            time_s: tf,
            stage_mm: self.pos,
            message,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{close, fault, layered, run_collecting, sweeps};
    use super::super::{Machine, SegKind};
    use super::*;
    use crate::bundle::Mode;
    use crate::exec::testutil::*;
    use crate::motion::position_at;

    fn last_light_off(c: &Collect) -> bool {
        let last = c.segs.last().unwrap();
        !last.light && last.velocity_at(last.t1) == 0.0
    }

    #[test]
    fn stall_and_limit_stop_the_stage_halfway_through_the_first_move() {
        for kind in [FaultKind::Stall, FaultKind::Limit] {
            let (o, c) = run_collecting(&layered(), &[FaultSpec { kind, layer: 1 }]);
            let f = o.fault.unwrap();
            assert_eq!((f.kind, f.layer), (kind, 1));
            // Layer 1 starts at 33.91 s; its first move (0.5 → 6.0 mm) takes 2.79 s.
            assert!(close(f.time_s, 33.91 + 2.79 / 2.0));
            let halfway = position_at(0.5, 6.0, 2.0, 50.0, 2.79 / 2.0);
            let want = Machine::of(&crate::bundle::Machine::of(&profile())).quantize(halfway);
            assert!(close(f.stage_mm, want), "{} {want}", f.stage_mm);
            assert!(close(o.total_s, f.time_s));
            assert_eq!(o.layers.len(), 2);
            assert!(!o.layers[1].completed && o.layers[0].completed);
            assert!(last_light_off(&c));
        }
    }

    #[test]
    fn a_stall_during_a_sweep_closes_the_shutter() {
        let (o, c) = run_collecting(&sweeps(Mode::Continuous), &[fault(FaultKind::Stall, 1)]);
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
        let (o, c) = run_collecting(&layered(), &[fault(FaultKind::MaskLoad, 1)]);
        let f = o.fault.unwrap();
        assert_eq!((f.kind, f.layer), (FaultKind::MaskLoad, 1));
        assert!(close(f.time_s, 33.91 + 0.02));
        // 0.02 s into a move accelerating at 50 mm/s²: 0.01 mm.
        assert!(close(f.stage_mm, 0.51));
        assert!(f.message.contains("masks/00001.png"));
        assert!(c.segs.iter().filter(|s| s.layer == 1).all(|s| !s.light));
        assert!(last_light_off(&c));
    }

    #[test]
    fn a_stuck_shutter_blanks_the_dmd_after_the_close_latency() {
        let (o, c) = run_collecting(&layered(), &[fault(FaultKind::ShutterStuck, 0)]);
        let f = o.fault.unwrap();
        assert_eq!((f.kind, f.layer), (FaultKind::ShutterStuck, 0));
        // Close commanded at 2.79 + 5.02 + 10 + 0.05 + 16 = 33.86 s, found stuck 0.05 s
        // later, DMD dark after its 0.02 s load.
        assert!(close(f.time_s, 33.93));
        assert!(close(o.layers[0].light_s, 16.07));
        let msg = &f.message;
        assert!(msg.contains("got 0.070 s of extra light"), "{msg}");
        let last = c.segs.last().unwrap();
        assert_eq!(last.kind, SegKind::StuckOpen);
        assert!(close(o.total_s, 33.93));
    }

    #[test]
    fn a_stuck_shutter_without_close_latency_still_lights_until_the_dmd_is_dark() {
        // A machine whose shutter closes at once (like the built-in bottom-up profile).
        let mut m = layered();
        m.machine.shutter.close_s = crate::units::NonNegative::new(0.0).unwrap();
        let (o, _) = run_collecting(&m, &[fault(FaultKind::ShutterStuck, 0)]);
        let f = o.fault.unwrap();
        assert!(close(o.layers[0].light_s, 16.02));
        let msg = &f.message;
        assert!(msg.contains("got 0.020 s of extra light"), "{msg}");
    }

    #[test]
    fn untriggered_faults_are_listed() {
        // No shutter close at or after layer 0 of a job without light.
        let wait = vec![Step::Wait { s: 1.0 }];
        let m = manifest(
            profile(),
            vec![layer(0, 0.5, 0.5, Mode::Layered, 0.0, wait, 1.0)],
        );
        let spec = fault(FaultKind::ShutterStuck, 0);
        let (o, _) = run_collecting(&m, &[spec]);
        assert!(o.fault.is_none());
        assert_eq!(o.untriggered, vec![spec]);
        // A fault whose layer the run never reaches, after the one that ends it.
        let stall = fault(FaultKind::Stall, 1);
        let limit = fault(FaultKind::Limit, 0);
        let (o, _) = run_collecting(&layered(), &[stall, limit]);
        assert_eq!(o.fault.unwrap().kind, FaultKind::Limit);
        assert_eq!(o.untriggered, vec![stall]);
    }

    #[test]
    fn fault_specs_parse() {
        let f: FaultSpec = "shutter-stuck@12".parse().unwrap();
        assert_eq!(f, fault(FaultKind::ShutterStuck, 12));
        let err = |s: &str| s.parse::<FaultSpec>().unwrap_err();
        assert!(err("stall").contains("KIND@LAYER"));
        assert!(err("jam@1").starts_with("--fault jam@1: unknown kind"));
        assert!(err("limit@-1").starts_with("--fault limit@-1: layer"));
    }
}
