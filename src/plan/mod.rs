//! Process planning: per-layer analysis, exposure and the machine steps of each layer.

use crate::bundle::{Mode, Step};
use crate::motion::move_time;
use crate::profile::{Process, Profile};

/// What the planner needs to know about one layer.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerInfo {
    /// Layer index.
    pub index: usize,
    /// Stage coordinate at which the layer is exposed (top of the layer), mm.
    pub z_mm: f64,
    /// Layer thickness, mm.
    pub thickness_mm: f64,
    /// Section area, mm².
    pub area_mm2: f64,
}

/// The plan of one layer.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerPlan {
    /// Printing mode.
    pub mode: Mode,
    /// Exposure, s.
    pub exposure_s: f64,
    /// Steps in order.
    pub steps: Vec<Step>,
    /// Estimated duration of the steps, s.
    pub time_s: f64,
}

/// Estimated duration of a step list starting at stage position `from_mm`.
pub fn steps_time(steps: &[Step], from_mm: f64) -> f64 {
    let mut pos = from_mm;
    let mut t = 0.0;
    for s in steps {
        match *s {
            Step::Move {
                to_mm,
                speed_mm_s,
                accel_mm_s2,
            } => {
                t += move_time(to_mm - pos, speed_mm_s, accel_mm_s2);
                pos = to_mm;
            }
            Step::Wait { s } | Step::Expose { s } => t += s,
            Step::Sweep { to_mm, speed_mm_s } => {
                t += (to_mm - pos).abs() / speed_mm_s;
                pos = to_mm;
            }
        }
    }
    t
}

/// Plans every layer: fixed exposure from the profile and, for top-down machines, a plain
/// natural-leveling recoat (dip deeper, return, wait, expose).
pub fn plan(profile: &Profile, layers: &[LayerInfo]) -> Vec<LayerPlan> {
    let st = &profile.stage;
    let accel = st.max_accel_mm_s2.get();
    let vmax = st.max_speed_mm_s.get();
    let mut pos = st.home_mm;
    let mut out = Vec::with_capacity(layers.len());
    for l in layers {
        let exposure_s = profile.exposure.layer_exposure_s(l.index);
        let mut steps = Vec::new();
        match profile.process {
            Process::TopDown => {
                let r = profile
                    .recoat
                    .as_ref()
                    .expect("validated: top-down has [recoat]");
                let dip = r.dip_mm.get();
                if dip > 0.0 {
                    steps.push(Step::Move {
                        to_mm: (l.z_mm + dip).min(st.travel_max_mm),
                        speed_mm_s: r.dip_speed_mm_s.get().min(vmax),
                        accel_mm_s2: accel,
                    });
                }
                steps.push(Step::Move {
                    to_mm: l.z_mm,
                    speed_mm_s: r.return_speed_mm_s.get().min(vmax),
                    accel_mm_s2: accel,
                });
                if r.wait_s.get() > 0.0 {
                    steps.push(Step::Wait { s: r.wait_s.get() });
                }
            }
            Process::BottomUp | Process::Hybrid => {
                steps.push(Step::Move {
                    to_mm: l.z_mm,
                    speed_mm_s: vmax,
                    accel_mm_s2: accel,
                });
            }
        }
        steps.push(Step::Expose { s: exposure_s });
        let time_s = steps_time(&steps, pos);
        pos = l.z_mm;
        out.push(LayerPlan {
            mode: Mode::Layered,
            exposure_s,
            steps,
            time_s,
        });
    }
    out
}
