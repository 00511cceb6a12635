//! Step lists per process (docs/PLANNING.md, "Stage coordinate and steps" and
//! "Processes"). `to_mm` is the platform's distance from the exposure plane; a layer's
//! steps start where the previous layer's left the stage and end with its `expose` or its
//! `sweep` to its `z_mm`; a lift or dip belongs to the layer it prepares. Every number is
//! rounded as it is made (`crate::round`: targets to whole stage steps, waits and
//! exposures to 1 ms, speeds derived from an area to 6 significant digits), so the
//! estimate is that of the steps the manifest records.

use super::{LayerInfo, LayerPlan, Notes};
use crate::bundle::{Mode, Step};
use crate::profile::{Profile, WaitModel};
use crate::round::{self, StageGrid};

/// Stage limits the steps must respect, and the stage's grid.
pub(super) struct Limits {
    pub travel_max: f64,
    pub vmax: f64,
    pub accel: f64,
    pub grid: StageGrid,
}

impl Limits {
    pub fn of(p: &Profile) -> Limits {
        Limits {
            travel_max: p.stage.travel_max_mm,
            vmax: p.stage.max_speed_mm_s.get(),
            accel: p.stage.max_accel_mm_s2.get(),
            grid: StageGrid::new(p.stage.steps_per_mm.get()),
        }
    }

    /// A move to the whole step nearest `to_mm`, no faster than the stage allows.
    fn mv(&self, to_mm: f64, speed: f64) -> Step {
        Step::Move {
            to_mm: self.grid.position(to_mm),
            speed_mm_s: speed.min(self.vmax),
            accel_mm_s2: self.accel,
        }
    }

    /// `to` clamped to the travel (to the highest whole step within it); counts a clamp in
    /// `notes`.
    fn clamp_top(&self, to: f64, notes: &mut Notes) -> f64 {
        if to > self.travel_max {
            notes.travel_clamped += 1;
            self.grid.position_at_most(self.travel_max)
        } else {
            to
        }
    }
}

/// Appends a wait of `s` seconds (to 1 ms), unless it is none.
fn push_wait(steps: &mut Vec<Step>, s: f64) {
    let s = round::time_s(s);
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
    lim: &Limits,
    layers: &[LayerInfo],
    notes: &mut Notes,
) -> Vec<LayerPlan> {
    let r = p.recoat.as_ref().expect("validated: top-down has [recoat]");
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
                    notes.wait_model_max_film_mm = l.thickness_mm;
                }
            }
            push_wait(&mut steps, w);
            let e = round::time_s(p.exposure.layer_exposure_s(l.index));
            steps.push(Step::Expose { s: e });
            layered(e, steps)
        })
        .collect()
}

/// Generic bottom-up peel: (wait after cure), two-stage lift, wait, retract, wait, expose.
pub(super) fn bottom_up(
    p: &Profile,
    lim: &Limits,
    layers: &[LayerInfo],
    notes: &mut Notes,
) -> Vec<LayerPlan> {
    let k = p.peel.as_ref().expect("validated: bottom-up has [peel]");
    let bottom = p.exposure.bottom_layers as usize;
    let mut out = Vec::with_capacity(layers.len());
    for (i, l) in layers.iter().enumerate() {
        let mut steps = Vec::with_capacity(7);
        if i > 0 {
            let prev = &layers[i - 1];
            push_wait(&mut steps, k.wait_after_cure_s.get());
            let (lift, v_slow) = k.lift_for(prev.area_mm2, prev.index < bottom);
            let v_slow = round::derived(v_slow);
            let top = lim.grid.position(lim.clamp_top(l.z_mm + lift, notes));
            let slow_to = lim
                .grid
                .position((prev.z_mm + k.slow_lift_mm.get()).min(top));
            if slow_to > lim.grid.position(prev.z_mm) {
                steps.push(lim.mv(slow_to, v_slow));
            }
            if top > slow_to {
                steps.push(lim.mv(top, k.fast_speed_mm_s.get()));
            }
            push_wait(&mut steps, k.wait_after_lift_s.get());
        }
        steps.push(lim.mv(l.z_mm, k.retract_speed_mm_s.get()));
        push_wait(&mut steps, k.wait_before_cure_s.get());
        let e = round::time_s(p.exposure.layer_exposure_s(l.index));
        steps.push(Step::Expose { s: e });
        out.push(layered(e, steps));
    }
    out
}

/// Hybrid continuous/layered. `force_layered`: plan every slice layered (the comparison plan).
pub(super) fn hybrid(
    p: &Profile,
    lim: &Limits,
    layers: &[LayerInfo],
    force_layered: bool,
    notes: &mut Notes,
) -> Vec<LayerPlan> {
    let h = p.hybrid.as_ref().expect("validated: hybrid has [hybrid]");
    let first_free = (p.exposure.bottom_layers + p.exposure.transition_layers) as usize;
    let v = h.continuous_speed_mm_s.get();
    let mut out: Vec<LayerPlan> = Vec::with_capacity(layers.len());
    // Where the previous layer was exposed: as planned, and on the stage's grid.
    let (mut prev_z, mut pos) = (p.stage.home_mm, lim.grid.position(p.stage.home_mm));
    for (i, l) in layers.iter().enumerate() {
        let cont = !force_layered && l.index >= first_free && h.continuous(l.max_fill_distance_mm);
        let prev_layered = i == 0 || out[i - 1].mode == Mode::Layered;
        let mut steps = Vec::with_capacity(6);
        let below = l.z_mm - l.thickness_mm;
        let top = lim.grid.position(l.z_mm);
        if cont {
            // Continuous: the stage sweeps from the previous exposure position to this one
            // while the mask is shown. Explicit switch from layered: the stage is still at
            // the last exposure; wait, then start the run. (Compared as planned, not on the
            // grid: a layer height of a whole number of steps and a half puts consecutive
            // tops on either side of a half step.)
            let mut start = pos;
            if (prev_z - below).abs() > 1e-9 {
                start = lim.grid.position(below);
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
                to_mm: top,
                speed_mm_s: v,
            });
            // The light time of the sweep between whole steps: rarely a whole number of
            // ms, so 7 significant digits (the executor checks the dose to 1e-6).
            out.push(LayerPlan {
                mode: Mode::Continuous,
                exposure_s: round::significant((top - start).abs() / v, 7),
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
                let lifted = lim.clamp_top(l.z_mm + lift, notes);
                steps.push(lim.mv(lifted, h.lift_speed_mm_s.get()));
                push_wait(&mut steps, h.wait_after_lift_s.get());
            }
            steps.push(lim.mv(l.z_mm, h.retract_speed_mm_s.get()));
            push_wait(&mut steps, h.wait_before_cure_s.get());
            let e = round::time_s(p.exposure.layer_exposure_s(l.index));
            steps.push(Step::Expose { s: e });
            out.push(layered(e, steps));
        }
        (prev_z, pos) = (l.z_mm, top);
    }
    out
}
