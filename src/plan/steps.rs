//! Step lists per process. Stage coordinate `to_mm` = platform distance from the exposure
//! plane; layer i is exposed at its `z_mm` ((i + 1)·thickness for a uniform job). Each
//! layer's steps start where the previous layer's steps left the stage and end with its
//! exposure (layered: `expose`; continuous: a `sweep` to its `z_mm`). Lifts and dips that
//! prepare a layer belong to that layer; their height is the highest `to_mm` of the layer
//! minus the layer's exposure position.

use super::{LayerInfo, LayerPlan, Notes};
use crate::bundle::{Mode, Step};
use crate::profile::{Hybrid, Peel, Profile, Recoat, WaitModel};

/// Stage limits the steps must respect.
pub(super) struct Limits {
    pub travel_max: f64,
    pub vmax: f64,
    pub accel: f64,
}

impl Limits {
    pub fn of(p: &Profile) -> Limits {
        Limits {
            travel_max: p.stage.travel_max_mm,
            vmax: p.stage.max_speed_mm_s.get(),
            accel: p.stage.max_accel_mm_s2.get(),
        }
    }

    fn mv(&self, to_mm: f64, speed: f64) -> Step {
        Step::Move {
            to_mm,
            speed_mm_s: speed.min(self.vmax),
            accel_mm_s2: self.accel,
        }
    }

    /// `to` clamped to the travel; counts a clamp in `notes`.
    fn clamp_top(&self, to: f64, notes: &mut Notes) -> f64 {
        if to > self.travel_max {
            notes.travel_clamped += 1;
            self.travel_max
        } else {
            to
        }
    }
}

fn push_wait(steps: &mut Vec<Step>, s: f64) {
    if s > 0.0 {
        steps.push(Step::Wait { s });
    }
}

fn layered(exposure_s: f64, steps: Vec<Step>) -> LayerPlan {
    LayerPlan {
        mode: Mode::Layered,
        exposure_s,
        steps,
        time_s: 0.0,
    }
}

/// Top-down natural-leveling recoat: dip, return, wait for leveling, expose.
pub(super) fn top_down(
    p: &Profile,
    r: &Recoat,
    lim: &Limits,
    layers: &[LayerInfo],
    notes: &mut Notes,
) -> Vec<LayerPlan> {
    let mu = p.resin.viscosity_pa_s.get();
    layers
        .iter()
        .map(|l| {
            let mut steps = Vec::with_capacity(4);
            let dip = r.dip_mm.get();
            if dip > 0.0 {
                let to = lim.clamp_top(l.z_mm + dip, notes);
                steps.push(lim.mv(to, r.dip_speed_mm_s.get()));
            }
            steps.push(lim.mv(l.z_mm, r.return_speed_mm_s.get()));
            let (w, raw) = r.wait_for(l.max_fill_distance_mm, l.thickness_mm, mu);
            if raw > w && r.wait_model == WaitModel::Leveling {
                notes.wait_capped += 1;
                if raw > notes.wait_model_max_s {
                    notes.wait_model_max_s = raw;
                    notes.wait_model_max_layer = l.index;
                    notes.wait_model_max_patch_mm = 2.0 * l.max_fill_distance_mm;
                }
            }
            push_wait(&mut steps, w);
            let e = p.exposure.layer_exposure_s(l.index);
            steps.push(Step::Expose { s: e });
            layered(e, steps)
        })
        .collect()
}

/// Generic bottom-up peel: (wait after cure), two-stage lift, wait, retract, wait, expose.
pub(super) fn bottom_up(
    p: &Profile,
    k: &Peel,
    lim: &Limits,
    layers: &[LayerInfo],
    notes: &mut Notes,
) -> Vec<LayerPlan> {
    let bottom = p.exposure.bottom_layers as usize;
    let mut out = Vec::with_capacity(layers.len());
    for (i, l) in layers.iter().enumerate() {
        let mut steps = Vec::with_capacity(7);
        if i > 0 {
            let prev = &layers[i - 1];
            push_wait(&mut steps, k.wait_after_cure_s.get());
            let (lift, v_slow) = k.lift_for(prev.area_mm2, prev.index < bottom);
            let top = lim.clamp_top(l.z_mm + lift, notes);
            let slow_to = (prev.z_mm + k.slow_lift_mm.get()).min(top);
            if slow_to > prev.z_mm {
                steps.push(lim.mv(slow_to, v_slow));
            }
            if top > slow_to {
                steps.push(lim.mv(top, k.fast_speed_mm_s.get()));
            }
            push_wait(&mut steps, k.wait_after_lift_s.get());
        }
        steps.push(lim.mv(l.z_mm, k.retract_speed_mm_s.get()));
        push_wait(&mut steps, k.wait_before_cure_s.get());
        let e = p.exposure.layer_exposure_s(l.index);
        steps.push(Step::Expose { s: e });
        out.push(layered(e, steps));
    }
    out
}

/// Hybrid continuous/layered. `force_layered`: plan every slice layered (the comparison plan).
pub(super) fn hybrid(
    p: &Profile,
    h: &Hybrid,
    lim: &Limits,
    layers: &[LayerInfo],
    force_layered: bool,
    notes: &mut Notes,
) -> Vec<LayerPlan> {
    let first_free = (p.exposure.bottom_layers + p.exposure.transition_layers) as usize;
    let v = h.continuous_speed_mm_s.get();
    let mut out: Vec<LayerPlan> = Vec::with_capacity(layers.len());
    let mut pos = p.stage.home_mm;
    for (i, l) in layers.iter().enumerate() {
        let cont = !force_layered && l.index >= first_free && h.continuous(l.max_fill_distance_mm);
        let prev_layered = i == 0 || out[i - 1].mode == Mode::Layered;
        let mut steps = Vec::with_capacity(6);
        let below = l.z_mm - l.thickness_mm;
        if cont {
            // Continuous: the stage sweeps from the previous exposure position to this one
            // while the mask is shown. Explicit switch from layered: the stage is still at
            // the last exposure; wait, then start the run.
            if (pos - below).abs() > 1e-9 {
                steps.push(lim.mv(below, h.retract_speed_mm_s.get()));
            }
            if prev_layered {
                let w = if i > 0 {
                    h.wait_after_cure_s.get() + h.switch_wait_s.get()
                } else {
                    h.switch_wait_s.get()
                };
                push_wait(&mut steps, w);
            }
            steps.push(Step::Sweep {
                to_mm: l.z_mm,
                speed_mm_s: v,
            });
            out.push(LayerPlan {
                mode: Mode::Continuous,
                exposure_s: l.thickness_mm / v,
                steps,
                time_s: 0.0,
            });
        } else {
            if i > 0 {
                // Lift by the slice's optimal lift height and come back down to it. After a
                // continuous run the stage is already at the previous slice's top.
                if prev_layered {
                    push_wait(&mut steps, h.wait_after_cure_s.get());
                }
                let (mut lift, beyond) = h.olh_for(l.max_fill_distance_mm);
                if beyond && !force_layered {
                    notes.beyond_table += 1;
                    notes.beyond_table_max_mm =
                        notes.beyond_table_max_mm.max(l.max_fill_distance_mm);
                }
                if layers[i - 1].index < p.exposure.bottom_layers as usize {
                    lift = lift.max(h.bottom_lift_mm.get());
                }
                let top = lim.clamp_top(l.z_mm + lift, notes);
                steps.push(lim.mv(top, h.lift_speed_mm_s.get()));
                push_wait(&mut steps, h.wait_after_lift_s.get());
            }
            steps.push(lim.mv(l.z_mm, h.retract_speed_mm_s.get()));
            push_wait(&mut steps, h.wait_before_cure_s.get());
            let e = p.exposure.layer_exposure_s(l.index);
            steps.push(Step::Expose { s: e });
            out.push(layered(e, steps));
        }
        pos = l.z_mm;
    }
    out
}
