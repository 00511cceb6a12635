//! The plan's time estimate, under the "step semantics and timing contract" of
//! [`crate::bundle`] (the executor simulates the same rules independently): the job starts
//! at `stage.home_mm`; an `expose`, or the first `sweep` of a run, waits for the layer's
//! DMD load; consecutive sweeps form one run, the shutter opening before its first and
//! closing after its last (counted in that layer).

use crate::bundle::Step;
use crate::motion::move_time;
use crate::profile::Profile;
use crate::round::StageGrid;

/// The machine constants the estimate needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Where the job starts, mm.
    pub home_mm: f64,
    /// Shutter opening latency, s.
    pub open_s: f64,
    /// Shutter closing latency, s.
    pub close_s: f64,
    /// DMD mask load time, s.
    pub load_s: f64,
}

impl Timing {
    /// The constants of `p`; the job starts at the whole stage step nearest `home_mm`, where
    /// the executor homes the stage.
    pub fn of(p: &Profile) -> Timing {
        Timing {
            home_mm: StageGrid::new(p.stage.steps_per_mm.get()).position(p.stage.home_mm),
            open_s: p.shutter.open_s.get(),
            close_s: p.shutter.close_s.get(),
            load_s: p.dmd.load_s.get(),
        }
    }

    /// Duration of each layer's steps, s (layers in job order).
    pub fn layer_times(&self, layers: &[&[Step]]) -> Vec<f64> {
        let mut pos = self.home_mm;
        let mut in_run = false;
        let mut out = Vec::with_capacity(layers.len());
        for (li, steps) in layers.iter().enumerate() {
            let mut t = 0.0;
            for (k, s) in steps.iter().enumerate() {
                match *s {
                    Step::Move {
                        to_mm,
                        speed_mm_s,
                        accel_mm_s2,
                    } => {
                        t += move_time(to_mm - pos, speed_mm_s, accel_mm_s2);
                        pos = to_mm;
                    }
                    Step::Wait { s } => t += s,
                    Step::Expose { s } => {
                        t = t.max(self.load_s) + self.open_s + s + self.close_s;
                    }
                    Step::Sweep { to_mm, speed_mm_s } => {
                        if !in_run {
                            t = t.max(self.load_s) + self.open_s;
                            in_run = true;
                        }
                        t += (to_mm - pos).abs() / speed_mm_s;
                        pos = to_mm;
                        if !next_is_sweep(layers, li, k) {
                            t += self.close_s;
                            in_run = false;
                        }
                    }
                }
            }
            out.push(t);
        }
        out
    }
}

/// Whether the step after `layers[li][k]` (possibly in a later layer) is a sweep.
fn next_is_sweep(layers: &[&[Step]], li: usize, k: usize) -> bool {
    let mut next = layers[li][k + 1..]
        .iter()
        .chain(layers[li + 1..].iter().flat_map(|l| l.iter()));
    matches!(next.next(), Some(Step::Sweep { .. }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t() -> Timing {
        Timing {
            home_mm: 0.0,
            open_s: 0.1,
            close_s: 0.2,
            load_s: 0.5,
        }
    }

    fn mv(to_mm: f64, speed_mm_s: f64, accel_mm_s2: f64) -> Step {
        Step::Move {
            to_mm,
            speed_mm_s,
            accel_mm_s2,
        }
    }

    fn sweep(to_mm: f64) -> [Step; 1] {
        [Step::Sweep {
            to_mm,
            speed_mm_s: 0.05,
        }]
    }

    #[test]
    fn expose_waits_for_load_and_adds_latencies() {
        let a = [Step::Expose { s: 2.0 }];
        assert!((t().layer_times(&[&a])[0] - (0.5 + 0.1 + 2.0 + 0.2)).abs() < 1e-12);
        // A move longer than the load hides it.
        let b = [
            mv(10.0, 10.0, 100.0),
            Step::Wait { s: 0.25 },
            Step::Expose { s: 2.0 },
        ];
        let mv = move_time(10.0, 10.0, 100.0);
        assert!((t().layer_times(&[&b])[0] - (mv + 0.25 + 2.3)).abs() < 1e-12);
    }

    #[test]
    fn sweep_run_opens_once_and_closes_in_last_layer() {
        let (s1, s2) = (sweep(0.1), sweep(0.2));
        let m = [
            mv(2.3, 5.0, 50.0),
            mv(0.3, 5.0, 50.0),
            Step::Expose { s: 1.0 },
        ];
        let v = t().layer_times(&[&s1, &s2, &m]);
        assert!((v[0] - (0.5 + 0.1 + 2.0)).abs() < 1e-12, "{v:?}");
        assert!((v[1] - (2.0 + 0.2)).abs() < 1e-12, "{v:?}");
        let mv = move_time(2.1, 5.0, 50.0) + move_time(2.0, 5.0, 50.0);
        assert!((v[2] - (mv + 1.3)).abs() < 1e-12, "{v:?}");
    }
}
