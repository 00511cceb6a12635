//! Segments: the stretches of the simulated timeline (what the machine does, the shutter
//! state, the stage motion) and the stage kinematics inside one.

use crate::motion::{move_time, position_at};

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

    /// A trapezoidal move's peak speed (reached or not), acceleration, time to the peak
    /// and total time; `None` for other motions.
    fn trapezoid(&self) -> Option<(f64, f64, f64, f64)> {
        let Motion::Trapezoid {
            target_mm,
            speed_mm_s: v,
            accel_mm_s2: a,
        } = self.motion
        else {
            return None;
        };
        let d = (target_mm - self.from_mm).abs();
        let vp = if d >= v * v / a { v } else { (a * d).sqrt() };
        Some((vp, a, vp / a, move_time(d, v, a)))
    }

    /// Signed stage velocity at time `t` (the value from `t` on), mm/s.
    pub fn velocity_at(&self, t: f64) -> f64 {
        if t < self.t0 || t >= self.t1 {
            return 0.0;
        }
        match (self.motion, self.trapezoid()) {
            (Motion::Constant { velocity_mm_s }, _) => velocity_mm_s,
            (Motion::Trapezoid { target_mm, .. }, Some((vp, a, ta, total))) => {
                let sign = if target_mm >= self.from_mm { 1.0 } else { -1.0 };
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
            _ => 0.0,
        }
    }

    /// Peak speed reached in the segment, mm/s.
    pub fn peak_speed(&self) -> f64 {
        match (self.motion, self.trapezoid()) {
            (Motion::Constant { velocity_mm_s }, _) => velocity_mm_s.abs(),
            // A move cut short by a fault may stop before reaching its peak.
            (_, Some((vp, a, ..))) => vp.min(a * (self.t1 - self.t0)),
            _ => 0.0,
        }
    }

    /// Appends the times inside `[t0, t1)` at which the motion changes phase (start,
    /// end of acceleration, start of deceleration), in order.
    pub fn phase_times(&self, out: &mut Vec<f64>) {
        out.push(self.t0);
        if let Some((_, _, ta, total)) = self.trapezoid() {
            for tau in [ta, total - ta] {
                let t = self.t0 + tau;
                if t > *out.last().unwrap() && t < self.t1 {
                    out.push(t);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{close, layered, run_collecting};
    use super::*;

    #[test]
    fn velocity_profile_is_consistent_with_positions() {
        let m = layered();
        let (_, c) = run_collecting(&m, &[]);
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
