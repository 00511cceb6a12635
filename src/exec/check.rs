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
    m: Machine,
    prev_z: f64,
    quantization_s: f64,
    violations: Vec<Violation>,
}

impl<'a> Checker<'a> {
    /// A checker for the manifest's layers and machine.
    pub fn new(manifest: &'a Manifest) -> Self {
        Checker {
            manifest,
            m: Machine::from_profile(&manifest.machine),
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
                        "simulated job time {total_s:.3} s differs from the manifest's totals.print_time_s {est:.3} s by {:+.2} % (tolerance 1 %)",
                        pct(total_s, est)
                    ),
                    file: None,
                });
            }
        }
        self.violations
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
                        "light on while the stage moves from {:.4} to {:.4} mm in layer {i}, which is planned as layered",
                        s.from_mm, s.to_mm
                    ),
                );
            }
            if s.t0 < s.mask_ready_s && s.duration() > 0.0 {
                self.push(
                    i,
                    s.t0,
                    "mask",
                    format!("light on at {:.3} s before layer {i}'s mask is on the DMD", s.t0),
                );
            }
        }
        if moving || s.kind == SegKind::Home {
            let (lo, hi) = (self.m.travel_min_mm, self.m.travel_max_mm);
            let eps = 1e-9;
            let out = [s.from_mm, s.to_mm]
                .into_iter()
                .find(|&p| p < lo - eps || p > hi + eps);
            if let Some(p) = out {
                self.push(
                    i,
                    s.t0,
                    "travel",
                    format!(
                        "layer {i}: {} to {p:.4} mm leaves the stage travel [{lo}, {hi}] mm",
                        s.kind.name()
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
            let vmax = self.m.max_speed_mm_s;
            if speed > vmax * (1.0 + LIMIT_SLACK) {
                self.push(
                    i,
                    s.t0,
                    "speed",
                    format!(
                        "layer {i}: {} at {speed} mm/s exceeds the stage's max_speed_mm_s {vmax}",
                        s.kind.name()
                    ),
                );
            }
            let amax = self.m.max_accel_mm_s2;
            if accel > amax * (1.0 + LIMIT_SLACK) {
                self.push(
                    i,
                    s.t0,
                    "accel",
                    format!(
                        "layer {i}: {} at {accel} mm/s² exceeds the stage's max_accel_mm_s2 {amax}",
                        s.kind.name()
                    ),
                );
            }
        }
        if s.kind == SegKind::Expose {
            let z = layer.z_mm;
            if (s.from_mm - z).abs() > self.m.half_step_mm() + 1e-9 {
                self.push(
                    i,
                    s.t0,
                    "position",
                    format!(
                        "layer {i} exposed with the stage at {:.4} mm, its z_mm is {z}",
                        s.from_mm
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
                    "layer {i}: z_mm {} but the layers' thicknesses put its top at {expected:.6} mm",
                    layer.z_mm
                ),
            );
        }
        self.prev_z = layer.z_mm;
        if !r.completed {
            return;
        }
        let end = r.start_s + r.time_s;
        if let Some(e) = r.last_sweep_end_mm {
            if (e - layer.z_mm).abs() > self.m.half_step_mm() + 1e-9 {
                self.push(
                    i,
                    end,
                    "position",
                    format!(
                        "layer {i}'s sweep ends at {e:.4} mm, its z_mm is {}",
                        layer.z_mm
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
                    "layer {i} received {:.6} s of light, its exposure_s is {want}",
                    r.light_s
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
                    "layer {i} takes {:.3} s, the manifest's time_s is {est:.3} s ({:+.2} %, tolerance 1 %)",
                    r.time_s,
                    pct(r.time_s, est)
                ),
            );
        }
    }
}
