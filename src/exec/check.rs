//! Invariants checked on the simulated timeline.
//!
//! The [`Checker`] is a [`Sink`]: it sees every segment the simulator produces and every
//! finished layer, and records a [`Violation`] whenever
//! * light reaches the resin outside an `expose` or `sweep` (`light-during-move`), or
//!   while the stage moves in a layer planned as `layered`;
//! * the stage leaves its travel (`travel`);
//! * a move or sweep commands more speed or acceleration than the stage has (`speed`,
//!   `accel`);
//! * a layer is exposed somewhere else than its `z_mm` (`position`; sweeps: the layer's
//!   last sweep must end at `z_mm`), or `z_mm` does not follow from the thicknesses;
//! * the light time a layer receives differs from its `exposure_s` (`dose`);
//! * light is on before the layer's own mask is on the DMD (`mask`);
//! * the simulated duration of a layer (or of the job) differs from the manifest's
//!   estimate by more than 1 % (`estimate`).

use super::sim::{LayerRecord, Machine, Motion, SegKind, Segment, Sink};
use super::Violation;
use crate::bundle::{Manifest, Mode};

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
}

impl<'a> Checker<'a> {
    /// A checker for the manifest's layers and machine.
    pub fn new(manifest: &'a Manifest) -> Self {
        Checker {
            manifest,
            machine: Machine::of(&manifest.machine),
            prev_z: 0.0,
            quantization_s: 0.0,
            violations: Vec::new(),
        }
    }

    fn push(&mut self, layer: usize, time_s: f64, kind: &'static str, message: String) {
        self.violations.push(Violation {
            layer: Some(layer),
            time_s: Some(time_s),
            kind,
            message,
            file: None,
        });
    }

    /// Ends the check: compares the job's simulated total with `totals.print_time_s`
    /// (skipped when the run was aborted) and returns the violations in time order.
    pub fn finish(mut self, total_s: f64, completed: bool) -> Vec<Violation> {
        let est = self.manifest.totals.print_time_s;
        if completed {
            let tol = ESTIMATE_TOLERANCE * est.abs() + self.quantization_s + 1e-9;
            if (total_s - est).abs() > tol {
                self.violations.push(Violation {
                    layer: None,
                    time_s: Some(total_s),
                    kind: "estimate",
                    message: format!(
                        "simulated job time {} s differs from the manifest's totals.print_time_s {} s by {:+.2} % (tolerance 1 %)",
                        fixed(total_s, 3),
                        fixed(est, 3),
                        pct(total_s, est)
                    ),
                    file: None,
                });
            }
        }
        self.violations
    }
}

/// A value from the manifest for a message, as written (`25`, `0.9`), in scientific
/// notation when that would be a long run of digits (a tampered bundle's `1e300`).
fn num(v: f64) -> String {
    if v == 0.0 || (v.is_finite() && (1e-4..1e9).contains(&v.abs())) {
        format!("{v}")
    } else {
        format!("{v:.4e}")
    }
}

/// `v` with `decimals` decimals, or in scientific notation beyond 10⁹ (never hundreds of
/// digits).
fn fixed(v: f64, decimals: usize) -> String {
    if v.is_finite() && v.abs() >= 1e9 {
        format!("{v:.4e}")
    } else {
        format!("{v:.decimals$}")
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
        let i = s.layer;
        let moving = s.motion != Motion::Still && s.from_mm != s.to_mm;
        if s.light {
            match s.kind {
                SegKind::Expose | SegKind::Sweep | SegKind::StuckOpen => {}
                k => self.push(
                    i,
                    s.t0,
                    "light-during-move",
                    format!("light on during a {} of layer {i}", k.name()),
                ),
            }
            if moving && layer.mode == Mode::Layered {
                self.push(
                    i,
                    s.t0,
                    "light-during-move",
                    format!(
                        "light on while the stage moves from {} to {} mm in layer {i}, which is planned as layered",
                        fixed(s.from_mm, 4),
                        fixed(s.to_mm, 4)
                    ),
                );
            }
            if s.t0 < s.mask_ready_s && s.duration() > 0.0 {
                self.push(
                    i,
                    s.t0,
                    "mask",
                    format!(
                        "light on at {} s before layer {i}'s mask is on the DMD",
                        fixed(s.t0, 3)
                    ),
                );
            }
        }
        if moving || s.kind == SegKind::Home {
            let (lo, hi) = (self.machine.travel_min_mm, self.machine.travel_max_mm);
            let eps = 1e-9;
            let out = |p: f64| p < lo - eps || p > hi + eps;
            if out(s.from_mm) || out(s.to_mm) {
                self.push(
                    i,
                    s.t0,
                    "travel",
                    format!(
                        "layer {i}: {} from {} to {} mm leaves the stage travel [{}, {}] mm",
                        s.kind.name(),
                        fixed(s.from_mm, 4),
                        fixed(s.to_mm, 4),
                        num(lo),
                        num(hi)
                    ),
                );
            }
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
        if moving {
            let vmax = self.machine.max_speed_mm_s;
            if speed > vmax * (1.0 + LIMIT_SLACK) {
                self.push(
                    i,
                    s.t0,
                    "speed",
                    format!(
                        "layer {i}: {} at {} mm/s exceeds the stage's max_speed_mm_s {}",
                        s.kind.name(),
                        num(speed),
                        num(vmax)
                    ),
                );
            }
            let amax = self.machine.max_accel_mm_s2;
            if accel > amax * (1.0 + LIMIT_SLACK) {
                self.push(
                    i,
                    s.t0,
                    "accel",
                    format!(
                        "layer {i}: {} at {} mm/s² exceeds the stage's max_accel_mm_s2 {}",
                        s.kind.name(),
                        num(accel),
                        num(amax)
                    ),
                );
            }
        }
        if s.kind == SegKind::Expose {
            let z = layer.z_mm;
            if (s.from_mm - z).abs() > self.machine.half_step_mm() + 1e-9 {
                self.push(
                    i,
                    s.t0,
                    "position",
                    format!(
                        "layer {i} exposed with the stage at {} mm, its z_mm is {}",
                        fixed(s.from_mm, 4),
                        num(z)
                    ),
                );
            }
        }
    }

    fn layer_end(&mut self, r: &LayerRecord) {
        let Some(layer) = self.manifest.layers.get(r.index) else {
            return;
        };
        let i = r.index;
        let expected = self.prev_z + layer.thickness_mm;
        if (layer.z_mm - expected).abs() > 1e-6 {
            self.push(
                i,
                r.start_s,
                "position",
                format!(
                    "layer {i}: z_mm {} but the layers' thicknesses put its top at {} mm",
                    num(layer.z_mm),
                    fixed(expected, 6)
                ),
            );
        }
        self.prev_z = layer.z_mm;
        if !r.completed {
            return;
        }
        let end = r.start_s + r.time_s;
        if let Some(e) = r.last_sweep_end_mm {
            if (e - layer.z_mm).abs() > self.machine.half_step_mm() + 1e-9 {
                self.push(
                    i,
                    end,
                    "position",
                    format!(
                        "layer {i}'s sweep ends at {} mm, its z_mm is {}",
                        fixed(e, 4),
                        num(layer.z_mm)
                    ),
                );
            }
        }
        let want = layer.exposure_s;
        let tol = DOSE_TOLERANCE * want.abs() + r.dose_quantization_s + 1e-9;
        if (r.light_s - want).abs() > tol {
            self.push(
                i,
                end,
                "dose",
                format!(
                    "layer {i} received {} s of light, its exposure_s is {}",
                    fixed(r.light_s, 6),
                    num(want)
                ),
            );
        }
        self.quantization_s += r.quantization_s;
        let est = layer.time_s;
        let tol = ESTIMATE_TOLERANCE * est.abs() + r.quantization_s + 1e-9;
        if (r.time_s - est).abs() > tol {
            self.push(
                i,
                end,
                "estimate",
                format!(
                    "layer {i} takes {} s, the manifest's time_s is {} s ({:+.2} %, tolerance 1 %)",
                    fixed(r.time_s, 3),
                    fixed(est, 3),
                    pct(r.time_s, est)
                ),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::Step;
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

    fn kinds(v: &[Violation]) -> Vec<(&'static str, Option<usize>)> {
        v.iter().map(|v| (v.kind, v.layer)).collect()
    }

    fn clean() -> Manifest {
        two_layer_topdown()
    }

    #[test]
    fn clean_jobs_have_no_violations() {
        assert_eq!(check(&clean()), vec![]);
        let sweep = |i: usize, t: f64| {
            let z = 0.1 * (i + 1) as f64;
            layer(
                i,
                z,
                0.1,
                Mode::Continuous,
                2.0,
                vec![Step::Sweep {
                    to_mm: z,
                    speed_mm_s: 0.05,
                }],
                t,
            )
        };
        let m = manifest(
            profile(),
            vec![sweep(0, 2.07), sweep(1, 2.0), sweep(2, 2.05)],
        );
        assert_eq!(check(&m), vec![]);
    }

    #[test]
    fn a_move_beyond_travel_is_a_violation() {
        let mut m = clean();
        m.layers[1].steps[0] = Step::Move {
            to_mm: 130.0,
            speed_mm_s: 2.0,
            accel_mm_s2: 50.0,
        };
        let v = check(&m);
        let travel: Vec<_> = v.iter().filter(|v| v.kind == "travel").collect();
        // Out (0.5 → 130) and back (130 → 1.0): both moves touch 130 mm.
        assert_eq!(travel.len(), 2, "{v:?}");
        assert_eq!(travel[0].layer, Some(1));
        assert!(travel[0]
            .message
            .contains("move from 0.5000 to 130.0000 mm leaves the stage travel [0, 120]"));
        assert!((travel[0].time_s.unwrap() - 33.91).abs() < 1e-9);
        // The longer moves also break the estimate.
        assert!(v.iter().any(|v| v.kind == "estimate" && v.layer == Some(1)));
        assert!(v.iter().any(|v| v.kind == "estimate" && v.layer.is_none()));
    }

    #[test]
    fn commanding_more_speed_or_acceleration_than_the_stage_has_is_a_violation() {
        let mut m = clean();
        m.layers[0].steps[0] = Step::Move {
            to_mm: 5.5,
            speed_mm_s: 20.0,
            accel_mm_s2: 50.0,
        };
        m.layers[1].steps[1] = Step::Move {
            to_mm: 1.0,
            speed_mm_s: 1.0,
            accel_mm_s2: 500.0,
        };
        // Keep the estimates right so only the limits trip: 5.5 mm at 20 mm/s, 50 mm/s²
        // is a triangle, 2·sqrt(5.5/50); 5 mm at 1 mm/s, 500 mm/s²: 0.004 + 4.998.
        m.layers[0].time_s = 2.0 * (5.5f64 / 50.0).sqrt() + 5.02 + 26.1;
        m.layers[1].time_s = 2.79 + 0.004 + 4.998 + 18.1;
        m.totals.print_time_s = m.layers[0].time_s + m.layers[1].time_s;
        let v = check(&m);
        assert_eq!(
            kinds(&v),
            vec![("speed", Some(0)), ("accel", Some(1))],
            "{v:?}"
        );
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
        assert_eq!(
            kinds(&v),
            vec![("position", Some(1)), ("dose", Some(1))],
            "{v:?}"
        );
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
        assert_eq!(kinds(&v), vec![("position", Some(1))]);
        assert!(v[0].message.contains("thicknesses put its top at 0.900000"));
    }

    #[test]
    fn sweeping_in_a_layered_layer_is_light_during_a_move() {
        let sweep = |i: usize, t: f64| {
            let z = 0.1 * (i + 1) as f64;
            layer(
                i,
                z,
                0.1,
                Mode::Layered,
                2.0,
                vec![Step::Sweep {
                    to_mm: z,
                    speed_mm_s: 0.05,
                }],
                t,
            )
        };
        let m = manifest(profile(), vec![sweep(0, 2.07), sweep(1, 2.05)]);
        let v = check(&m);
        assert_eq!(
            kinds(&v),
            vec![
                ("light-during-move", Some(0)),
                ("light-during-move", Some(1))
            ]
        );
    }

    #[test]
    fn a_sweep_must_end_at_the_layer() {
        let m = manifest(
            profile(),
            vec![layer(
                0,
                0.1,
                0.1,
                Mode::Continuous,
                2.0,
                vec![Step::Sweep {
                    to_mm: 0.2,
                    speed_mm_s: 0.1,
                }],
                2.12,
            )],
        );
        let v = check(&m);
        assert_eq!(kinds(&v), vec![("position", Some(0))], "{v:?}");
        assert!(v[0].message.contains("sweep ends at 0.2000 mm"));
    }

    #[test]
    fn estimates_off_by_more_than_one_percent_are_reported() {
        let mut m = clean();
        m.layers[0].time_s = 33.91 * 1.009; // within 1 %
        m.layers[1].time_s = 25.91 * 0.98; // 2 % short
        m.totals.print_time_s = 59.82;
        let v = check(&m);
        assert_eq!(kinds(&v), vec![("estimate", Some(1))]);
        assert!(v[0].message.contains("+2.04 %"), "{}", v[0].message);
        m.totals.print_time_s = 59.82 * 1.02;
        let v = check(&m);
        assert_eq!(kinds(&v), vec![("estimate", Some(1)), ("estimate", None)]);
    }

    #[test]
    fn quantization_is_not_an_estimate_error() {
        // 0.0333 mm layers swept at 0.02 mm/s on 800 steps/mm: every sweep is 26 or 27
        // steps instead of 26.64, 0.3 % to 1.4 % away from the unquantized time.
        let layers = (0..6)
            .map(|i| {
                let z = 0.0333 * (i + 1) as f64;
                let t = 0.0333 / 0.02
                    + if i == 0 { 0.07 } else { 0.0 }
                    + if i == 5 { 0.05 } else { 0.0 };
                layer(
                    i,
                    z,
                    0.0333,
                    Mode::Continuous,
                    0.0333 / 0.02,
                    vec![Step::Sweep {
                        to_mm: z,
                        speed_mm_s: 0.02,
                    }],
                    t,
                )
            })
            .collect();
        let m = manifest(profile(), layers);
        assert_eq!(check(&m), vec![]);
    }

    #[test]
    fn an_aborted_layer_is_not_checked_for_dose_or_estimate() {
        let v = check_with(
            &clean(),
            &[FaultSpec {
                kind: FaultKind::Stall,
                layer: 1,
            }],
        );
        assert_eq!(v, vec![]);
    }

    #[test]
    fn huge_values_never_print_hundreds_of_digits() {
        assert_eq!(num(25.0), "25");
        assert_eq!(num(0.9), "0.9");
        assert_eq!(num(1e300), "1.0000e300");
        assert_eq!(num(f64::INFINITY), "inf");
        assert_eq!(fixed(500.0, 4), "500.0000");
        assert_eq!(fixed(1e300, 4), "1.0000e300");
        assert_eq!(fixed(-1e12, 3), "-1.0000e12");
    }
}
