//! Invariants checked on the simulated timeline.
//!
//! The [`Checker`] is a [`Sink`]: it sees every segment the simulator produces and every
//! finished layer, and records a [`Violation`] for every broken invariant, of the kinds
//! `light-during-move` to `estimate` of [`Kind`] (each variant says what is checked).

use super::sim::{LayerRecord, Machine, Motion, SegKind, Segment, Sink};
use super::{Kind, Violation};
use crate::bundle::{Manifest, Mode};
use crate::text::{fixed, number, signed};

/// Relative tolerance between the simulated time and the manifest's estimate.
pub const ESTIMATE_TOLERANCE: f64 = 0.01;
/// Relative tolerance between the light time received and `exposure_s`.
pub const DOSE_TOLERANCE: f64 = 1e-6;
/// Relative slack on speed and acceleration limits (rounding only).
const LIMIT_SLACK: f64 = 1e-9;

/// Checks the timeline's invariants.
#[derive(Debug)]
pub struct Checker<'a> {
    manifest: &'a Manifest,
    machine: Machine,
    /// The previous layer's top, mm (0 before the first layer).
    prev_z: f64,
    /// What position quantization changed in the layers' times so far, s.
    quantization_s: f64,
    violations: Vec<Violation>,
    /// The limits the machine record states (travel, speed, acceleration), and how
    /// messages name them (`Machine::label`).
    limits: [(bool, String); 3],
    /// Compare the simulated times with the manifest's estimates.
    pub estimate: bool,
}

impl<'a> Checker<'a> {
    /// A checker for the manifest's layers and machine.
    pub fn new(manifest: &'a Manifest) -> Self {
        let m = &manifest.machine;
        let limit = |key: &str, short: &str| {
            let label = match m.sources.get(key) {
                Some(s) => format!("{short} ({s})"),
                None => short.to_string(),
            };
            (m.states(key), label)
        };
        Checker {
            manifest,
            machine: Machine::of(m),
            prev_z: 0.0,
            quantization_s: 0.0,
            violations: Vec::new(),
            limits: [
                limit("stage.travel_max_mm", "stage travel"),
                limit("stage.max_speed_mm_s", "max_speed_mm_s"),
                limit("stage.max_accel_mm_s2", "max_accel_mm_s2"),
            ],
            estimate: true,
        }
    }

    fn push(&mut self, layer: Option<usize>, time_s: f64, kind: Kind, message: String) {
        self.violations
            .push(violation(layer, time_s, kind, message));
    }

    /// Ends the check: compares the job's simulated total with `totals.print_time_s`
    /// (skipped when the run was aborted) and returns the violations in time order.
    pub fn finish(mut self, total_s: f64, completed: bool) -> Vec<Violation> {
        let est = self.manifest.totals.print_time_s;
        let tol = ESTIMATE_TOLERANCE * est.abs() + self.quantization_s + 1e-9;
        if self.estimate && completed && (total_s - est).abs() > tol {
            let (total, diff) = (fixed(total_s, 3), signed(pct(total_s, est), 2));
            let msg = format!("simulated job time {total} s differs from the manifest's totals.print_time_s {} s by {diff} % (tolerance 1 %)", fixed(est, 3));
            self.push(None, total_s, Kind::Estimate, msg);
        }
        self.violations
    }
}

/// A violation of `kind` found at `time_s` in `layer`.
fn violation(layer: Option<usize>, time_s: f64, kind: Kind, message: String) -> Violation {
    Violation {
        layer,
        time_s: Some(time_s),
        kind,
        message,
        file: None,
    }
}

/// Relative difference of `a` from `b`, percent.
pub fn pct(a: f64, b: f64) -> f64 {
    if b == 0.0 {
        if a == 0.0 {
            0.0
        } else {
            f64::INFINITY
        }
    } else {
        (a - b) / b * 100.0
    }
}

impl Sink for Checker<'_> {
    fn segment(&mut self, s: &Segment) {
        let Some(layer) = self.manifest.layers.get(s.layer) else {
            return;
        };
        let (i, t, what) = (s.layer, s.t0, s.kind.name());
        let mut push = |kind, msg| self.violations.push(violation(Some(i), t, kind, msg));
        let moving = s.motion != Motion::Still && s.from_mm != s.to_mm;
        // The positions as messages print them (formatted only for a message).
        let (from, to) = (|| fixed(s.from_mm, 4), || fixed(s.to_mm, 4));
        if s.light {
            let exposing = matches!(
                s.kind,
                SegKind::Expose | SegKind::Sweep | SegKind::StuckOpen
            );
            if !exposing {
                push(
                    Kind::LightDuringMove,
                    format!("light on during a {what} of layer {i}"),
                );
            }
            if moving && layer.mode == Mode::Layered {
                let (from, to) = (from(), to());
                let msg = format!("light on while the stage moves from {from} to {to} mm in layer {i}, which is planned as layered");
                push(Kind::LightDuringMove, msg);
            }
            if t < s.mask_ready_s && s.duration() > 0.0 {
                let msg = format!(
                    "light on at {} s before layer {i}'s mask is on the DMD",
                    fixed(t, 3)
                );
                push(Kind::Mask, msg);
            }
        }
        let m = self.machine;
        let [(travel, travel_is), (speed_max, speed_is), (accel_max, accel_is)] = &self.limits;
        let (lo, hi) = (m.travel_min_mm, m.travel_max_mm);
        let out = |p: f64| p < lo - 1e-9 || (*travel && p > hi + 1e-9);
        if (moving || s.kind == SegKind::Home) && (out(s.from_mm) || out(s.to_mm)) {
            let (lo, hi, from, to) = (number(lo), number(hi), from(), to());
            let msg = format!(
                "layer {i}: {what} from {from} to {to} mm leaves the {travel_is} [{lo}, {hi}] mm"
            );
            push(Kind::Travel, msg);
        }
        let (speed, accel) = match s.motion {
            Motion::Still => (0.0, 0.0),
            Motion::Constant { velocity_mm_s } => (velocity_mm_s.abs(), 0.0),
            Motion::Trapezoid {
                speed_mm_s,
                accel_mm_s2,
                ..
            } => (speed_mm_s, accel_mm_s2),
        };
        let (vmax, amax) = (m.max_speed_mm_s, m.max_accel_mm_s2);
        if *speed_max && moving && speed > vmax * (1.0 + LIMIT_SLACK) {
            let (v, max) = (number(speed), number(vmax));
            let msg = format!("layer {i}: {what} at {v} mm/s exceeds the stage's {speed_is} {max}");
            push(Kind::Speed, msg);
        }
        if *accel_max && moving && accel > amax * (1.0 + LIMIT_SLACK) {
            let (a, max) = (number(accel), number(amax));
            let msg =
                format!("layer {i}: {what} at {a} mm/s² exceeds the stage's {accel_is} {max}");
            push(Kind::Accel, msg);
        }
        if s.kind == SegKind::Expose && (s.from_mm - layer.z_mm).abs() > m.half_step_mm() + 1e-9 {
            let (z, from) = (number(layer.z_mm), from());
            let msg = format!("layer {i} exposed with the stage at {from} mm, its z_mm is {z}");
            push(Kind::Position, msg);
        }
    }

    fn layer_end(&mut self, r: &LayerRecord) {
        let Some(layer) = self.manifest.layers.get(r.index) else {
            return;
        };
        let (i, at) = (r.index, Some(r.index));
        let (z, expected) = (|| number(layer.z_mm), self.prev_z + layer.thickness_mm);
        if (layer.z_mm - expected).abs() > 1e-6 {
            let (z, top) = (z(), fixed(expected, 6));
            let msg =
                format!("layer {i}: z_mm {z} but the layers' thicknesses put its top at {top} mm");
            self.push(at, r.start_s, Kind::Position, msg);
        }
        self.prev_z = layer.z_mm;
        if !r.completed {
            return;
        }
        let end = r.start_s + r.time_s;
        if let Some(e) = r.last_sweep_end_mm {
            if (e - layer.z_mm).abs() > self.machine.half_step_mm() + 1e-9 {
                let msg = format!(
                    "layer {i}'s sweep ends at {} mm, its z_mm is {}",
                    fixed(e, 4),
                    z()
                );
                self.push(at, end, Kind::Position, msg);
            }
        }
        let want = layer.exposure_s;
        let tol = DOSE_TOLERANCE * want.abs() + r.dose_quantization_s + 1e-9;
        if (r.light_s - want).abs() > tol {
            let (light, want) = (fixed(r.light_s, 6), number(want));
            let msg = format!("layer {i} received {light} s of light, its exposure_s is {want}");
            self.push(at, end, Kind::Dose, msg);
        }
        self.quantization_s += r.quantization_s;
        let est = layer.time_s;
        let tol = ESTIMATE_TOLERANCE * est.abs() + r.quantization_s + 1e-9;
        if self.estimate && (r.time_s - est).abs() > tol {
            let (took, diff) = (fixed(r.time_s, 3), signed(pct(r.time_s, est), 2));
            let est = fixed(est, 3);
            let msg = format!("layer {i} takes {took} s, the manifest's time_s is {est} s ({diff} %, tolerance 1 %)");
            self.push(at, end, Kind::Estimate, msg);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exec::sim::{simulate, FaultKind, FaultSpec};
    use crate::exec::testutil::*;

    fn check(m: &Manifest) -> Vec<Violation> {
        check_with(m, &[])
    }

    fn check_with(m: &Manifest, faults: &[FaultSpec]) -> Vec<Violation> {
        let mut c = Checker::new(m);
        let o = simulate(m, faults, &mut [&mut c]);
        c.finish(o.total_s, o.fault.is_none())
    }

    fn kinds(v: &[Violation]) -> Vec<(Kind, Option<usize>)> {
        v.iter().map(|v| (v.kind, v.layer)).collect()
    }

    fn clean() -> Manifest {
        two_layer_topdown()
    }

    #[test]
    fn clean_jobs_have_no_violations() {
        assert_eq!(check(&clean()), vec![]);
        assert_eq!(
            check(&sweep_layers(Mode::Continuous, &[2.07, 2.0, 2.05])),
            vec![]
        );
    }

    #[test]
    fn a_move_beyond_travel_is_a_violation() {
        let mut m = clean();
        m.layers[1].steps[0] = move_to(130.0, 2.0, 50.0);
        let v = check(&m);
        let travel: Vec<_> = v.iter().filter(|v| v.kind == Kind::Travel).collect();
        // Out (0.5 → 130) and back (130 → 1.0): both moves touch 130 mm.
        assert_eq!(travel.len(), 2, "{v:?}");
        assert_eq!(travel[0].layer, Some(1));
        let msg = &travel[0].message;
        assert!(msg.contains("move from 0.5000 to 130.0000 mm leaves the stage travel [0, 120]"));
        assert!((travel[0].time_s.unwrap() - 33.91).abs() < 1e-9);
        // The longer moves also break the estimate.
        let estimate = |l| v.iter().any(|v| v.kind == Kind::Estimate && v.layer == l);
        assert!(estimate(Some(1)) && estimate(None));
    }

    #[test]
    fn commanding_more_speed_or_acceleration_than_the_stage_has_is_a_violation() {
        let mut m = clean();
        m.layers[0].steps[0] = move_to(5.5, 20.0, 50.0);
        m.layers[1].steps[1] = move_to(1.0, 1.0, 500.0);
        // Keep the estimates right so only the limits trip: 5.5 mm at 20 mm/s, 50 mm/s²
        // is a triangle, 2·sqrt(5.5/50); 5 mm at 1 mm/s, 500 mm/s²: 0.004 + 4.998.
        m.layers[0].time_s = 2.0 * (5.5f64 / 50.0).sqrt() + 5.02 + 26.1;
        m.layers[1].time_s = 2.79 + 0.004 + 4.998 + 18.1;
        m.totals.print_time_s = m.layers[0].time_s + m.layers[1].time_s;
        let v = check(&m);
        let want = vec![(Kind::Speed, Some(0)), (Kind::Accel, Some(1))];
        assert_eq!(kinds(&v), want, "{v:?}");
        assert!(v[0]
            .message
            .contains("20 mm/s exceeds the stage's max_speed_mm_s 10"));
    }

    #[test]
    fn exposing_at_the_wrong_height_or_dose_is_a_violation() {
        let mut m = clean();
        // Layer 1 returns to 0.9 instead of 1.0 and exposes 7 s instead of 8.
        m.layers[1].steps = recoat_steps(0.9, 10.0, 7.0);
        m.layers[1].time_s = 2.79 + 5.02 + 10.0 + 7.1;
        m.totals.print_time_s = 33.91 + m.layers[1].time_s;
        let v = check(&m);
        let want = vec![(Kind::Position, Some(1)), (Kind::Dose, Some(1))];
        assert_eq!(kinds(&v), want, "{v:?}");
        assert!(v[0].message.contains("stage at 0.9000 mm, its z_mm is 1"));
        assert!(v[1]
            .message
            .contains("received 7.000000 s of light, its exposure_s is 8"));
    }

    #[test]
    fn z_must_follow_from_the_thicknesses() {
        let mut m = clean();
        m.layers[1].thickness_mm = 0.4;
        let v = check(&m);
        assert_eq!(kinds(&v), vec![(Kind::Position, Some(1))]);
        assert!(v[0].message.contains("thicknesses put its top at 0.900000"));
    }

    #[test]
    fn sweeping_in_a_layered_layer_is_light_during_a_move() {
        let v = check(&sweep_layers(Mode::Layered, &[2.07, 2.05]));
        let want = vec![
            (Kind::LightDuringMove, Some(0)),
            (Kind::LightDuringMove, Some(1)),
        ];
        assert_eq!(kinds(&v), want);
    }

    #[test]
    fn a_sweep_must_end_at_the_layer() {
        let l = layer(
            0,
            0.1,
            0.1,
            Mode::Continuous,
            2.0,
            vec![sweep_to(0.2, 0.1)],
            2.12,
        );
        let v = check(&manifest(profile(), vec![l]));
        assert_eq!(kinds(&v), vec![(Kind::Position, Some(0))], "{v:?}");
        assert!(v[0].message.contains("sweep ends at 0.2000 mm"));
    }

    #[test]
    fn estimates_off_by_more_than_one_percent_are_reported() {
        let mut m = clean();
        m.layers[0].time_s = 33.91 * 1.009; // within 1 %
        m.layers[1].time_s = 25.91 * 0.98; // 2 % short
        m.totals.print_time_s = 59.82;
        let v = check(&m);
        assert_eq!(kinds(&v), vec![(Kind::Estimate, Some(1))]);
        assert!(v[0].message.contains("+2.04 %"), "{}", v[0].message);
        m.totals.print_time_s = 59.82 * 1.02;
        let v = check(&m);
        assert_eq!(
            kinds(&v),
            vec![(Kind::Estimate, Some(1)), (Kind::Estimate, None)]
        );
    }

    #[test]
    fn quantization_is_not_an_estimate_error() {
        // 0.0333 mm layers swept at 0.02 mm/s on 800 steps/mm: every sweep is 26 or 27
        // steps instead of 26.64, 0.3 % to 1.4 % away from the unquantized time.
        let layers = (0..6)
            .map(|i| {
                let z = 0.0333 * (i + 1) as f64;
                let light = 0.0333 / 0.02;
                let t = light + [0.07, 0.0, 0.0, 0.0, 0.0, 0.05][i];
                layer(
                    i,
                    z,
                    0.0333,
                    Mode::Continuous,
                    light,
                    vec![sweep_to(z, 0.02)],
                    t,
                )
            })
            .collect();
        assert_eq!(check(&manifest(profile(), layers)), vec![]);
    }

    #[test]
    fn an_aborted_layer_is_not_checked_for_dose_or_estimate() {
        let stall = FaultSpec {
            kind: FaultKind::Stall,
            layer: 1,
        };
        assert_eq!(check_with(&clean(), &[stall]), vec![]);
    }
}
