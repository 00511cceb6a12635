//! Process planning (docs/PLANNING.md): the per-layer [`analysis`] (run inside the slicing
//! workers: max fill distance, unsupported islands, bounding box), then [`plan`]: per
//! process (the profile's [`crate::profile::Recoat`], [`crate::profile::Peel`] or
//! [`crate::profile::Hybrid`] section) each layer's mode, exposure and steps (`steps`) and
//! the time estimate ([`timing`]); for the hybrid process also the job planned all
//! layered, for the time comparison the hybrid method reports.
//!
//! The planner is pure: the same layers and profile give the same plan, bit for bit.
//! Invariants: each layer's steps start where the previous layer left the stage and end with
//! its `expose` or `sweep`; every position stays inside the stage travel and every speed at
//! most the stage maximum; a continuous slice inside a run is one `sweep`; positions are
//! rounded to whole stage steps before the estimate, so the estimate is that of the steps as
//! written.

pub mod analysis;
mod steps;
pub mod timing;

pub use analysis::LayerAnalysis;

use crate::bundle::{Mode, Step};
use crate::profile::{Process, Profile};
use crate::round;
use crate::text::{first_of, fixed, hms, number, plural};
use crate::warning::Warning;

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
    /// Largest distance from a point of the section to its boundary, mm.
    pub max_fill_distance_mm: f64,
    /// Regions not resting on the layer below.
    pub islands: u32,
    /// The largest of them on the build plane: x and y of its centre and its area, mm.
    pub island_mm: Option<[f64; 3]>,
    /// What the largest island is part of, as words to follow its position in messages
    /// (", in b.stl" on a plate).
    pub island_part: Option<String>,
}

/// The plan of one layer.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerPlan {
    /// Printing mode.
    pub mode: Mode,
    /// Exposure (dose time), s: the `expose` time, or thickness/speed for a sweep.
    pub exposure_s: f64,
    /// Steps in order.
    pub steps: Vec<Step>,
    /// Estimated duration of the steps under the timing contract, s (to 1 ms).
    pub time_s: f64,
}

/// The plan of a job.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// One plan per layer.
    pub layers: Vec<LayerPlan>,
    /// The job's time estimate: the sum of the layer times before they were rounded, to
    /// 1 ms, s.
    pub print_time_s: f64,
    /// Hybrid process: the time the same job would take with every slice layered, s.
    pub all_layered_time_s: Option<f64>,
    /// Layers printed continuously.
    pub continuous_layers: usize,
    /// The plan's warnings for the manifest.
    pub warnings: Vec<Warning>,
}

/// Counters the step builders fill; turned into warnings.
#[derive(Debug, Default)]
pub(crate) struct Notes {
    travel_clamped: usize,
    wait_capped: usize,
    wait_model_max_s: f64,
    wait_model_max_layer: usize,
    wait_model_max_patch_mm: f64,
    wait_model_max_film_mm: f64,
    beyond_table: usize,
    beyond_table_max_mm: f64,
}

/// The layers' plans, each with its time estimate (to 1 ms), and the job's estimate (the
/// sum of the unrounded layer times, to 1 ms).
fn build(
    profile: &Profile,
    layers: &[LayerInfo],
    force_layered: bool,
    notes: &mut Notes,
) -> (Vec<LayerPlan>, f64) {
    let lim = steps::Limits::of(profile);
    let mut plans = match profile.process {
        Process::TopDown => steps::top_down(profile, &lim, layers, notes),
        Process::BottomUp => steps::bottom_up(profile, &lim, layers, notes),
        Process::Hybrid => steps::hybrid(profile, &lim, layers, force_layered, notes),
    };
    let lists: Vec<&[Step]> = plans.iter().map(|p| p.steps.as_slice()).collect();
    let times = timing::Timing::of(profile).layer_times(&lists);
    let total = round::time_s(times.iter().sum());
    for (p, t) in plans.iter_mut().zip(times) {
        p.time_s = round::time_s(t);
    }
    (plans, total)
}

/// Plans every layer for the profile's process. Fails (with a one-line reason) when a
/// layer's exposure position lies outside the stage travel.
pub fn plan(profile: &Profile, layers: &[LayerInfo]) -> Result<Plan, String> {
    let st = &profile.stage;
    if let Some(l) = layers
        .iter()
        .find(|l| l.z_mm > st.travel_max_mm || l.z_mm < st.travel_min_mm)
    {
        return Err(format!(
            "layer {} is exposed at stage position {:.3} mm, outside the stage travel {}..{} mm (part too tall for this machine)",
            l.index, l.z_mm, number(st.travel_min_mm), number(st.travel_max_mm)
        ));
    }
    let mut notes = Notes::default();
    let (layers_plan, print_time_s) = build(profile, layers, false, &mut notes);
    let all_layered_time_s = (profile.process == Process::Hybrid).then(|| {
        let mut scratch = Notes::default();
        build(profile, layers, true, &mut scratch).1
    });
    let warnings = warnings(profile, layers, &notes);
    Ok(Plan {
        print_time_s,
        continuous_layers: layers_plan
            .iter()
            .filter(|p| p.mode == Mode::Continuous)
            .count(),
        layers: layers_plan,
        all_layered_time_s,
        warnings,
    })
}

/// The plan's warnings from the step builders' `notes` and the layers' islands.
fn warnings(profile: &Profile, layers: &[LayerInfo], notes: &Notes) -> Vec<Warning> {
    let n = layers.len() as u64;
    let st = &profile.stage;
    let mut warnings = Vec::new();
    if notes.wait_capped > 0 {
        let cap = profile.recoat.as_ref().map_or(0.0, |r| r.wait_max_s.get());
        let capped = notes.wait_capped as u64;
        warnings.push(
            Warning::new(
                "plan.wait-capped",
                format!(
                    "natural leveling takes longer than recoat.wait_max_s = {} s on {capped} of {n} {} (the thin-film model: up to {} for the {} mm film over the {} mm wide flat patch of layer {}): they are exposed on a surface that may not be level yet, and large flat areas may come out uneven in thickness",
                    number(cap),
                    plural(n, "layer", "layers"),
                    hms(notes.wait_model_max_s),
                    number(notes.wait_model_max_film_mm),
                    fixed(notes.wait_model_max_patch_mm, 1),
                    notes.wait_model_max_layer,
                ),
            )
            .with("layers", capped)
            .with("layers_total", n)
            .with("wait_max_s", cap)
            .with("model_max_s", notes.wait_model_max_s)
            .with("model_max_layer", notes.wait_model_max_layer as u64)
            .with("flat_patch_mm", notes.wait_model_max_patch_mm),
        );
    }
    if notes.travel_clamped > 0 {
        let k = notes.travel_clamped as u64;
        warnings.push(
            Warning::new(
                "plan.travel-clamped",
                format!(
                    "{k} {} shortened to end at stage.travel_max_mm = {} mm",
                    plural(k, "lift or dip was", "lifts or dips were"),
                    number(st.travel_max_mm)
                ),
            )
            .with("moves", k)
            .with("travel_max_mm", st.travel_max_mm),
        );
    }
    if notes.beyond_table > 0 {
        let h = profile.hybrid.as_ref().expect("hybrid");
        let k = notes.beyond_table as u64;
        let table_max = h.olh.last().map_or(0.0, |r| r.up_to_mm.get());
        let lift = h.olh.last().map_or(0.0, |r| r.lift_mm.get());
        warnings.push(
            Warning::new(
                "plan.beyond-lift-table",
                format!(
                    "{k} {} a max fill distance beyond the lift table (up to {} mm > {} mm): {} the last row's lift, {} mm",
                    plural(k, "slice has", "slices have"),
                    fixed(notes.beyond_table_max_mm, 2),
                    number(table_max),
                    plural(k, "it uses", "they use"),
                    number(lift),
                ),
            )
            .with("slices", k)
            .with("max_fill_distance_mm", notes.beyond_table_max_mm)
            .with("table_max_mm", table_max)
            .with("lift_mm", lift),
        );
    }
    warnings.extend(bottom_layers_cover_job(profile, layers));
    let with_islands: Vec<&LayerInfo> = layers.iter().filter(|l| l.islands > 0).collect();
    if let Some(first) = with_islands.first() {
        let islands = with_islands.iter().map(|l| l.islands as u64).sum::<u64>();
        let k = with_islands.len() as u64;
        // Where: the largest island of each of the first layers, and how many more.
        let shown = 3;
        let at = with_islands.iter().take(shown).filter_map(|l| {
            let [x, y, a] = l.island_mm?;
            let part = l.island_part.as_deref().unwrap_or_default();
            Some(format!(
                "layer {} at x {}, y {} mm ({} mm²){part}",
                l.index,
                fixed(x, 2),
                fixed(y, 2),
                number(a)
            ))
        });
        let at = first_of(at, (shown, with_islands.len()), ("layer", "layers"));
        let largest = if at.is_empty() {
            String::new()
        } else {
            format!("; largest per layer: {at}")
        };
        warnings.push(
            Warning::new(
                "plan.unsupported-islands",
                format!(
                    "{islands} unsupported {} on {k} {} (first at layer {}){largest}: regions that do not rest on the layer below need supports",
                    plural(islands, "island", "islands"),
                    plural(k, "layer", "layers"),
                    first.index
                ),
            )
            .with("islands", islands)
            .with("layers", k)
            .with("first_layer", first.index as u64)
            .with("largest_mm", largest_mm(&with_islands)),
        );
    }
    warnings
}

/// The warning for a job none of whose layers gets the normal exposure: the profile's
/// bottom and transition layers reach past its last layer (and the bottom exposure differs
/// from the normal one).
fn bottom_layers_cover_job(profile: &Profile, layers: &[LayerInfo]) -> Option<Warning> {
    let e = &profile.exposure;
    let (b, t) = (e.bottom_layers as usize, e.transition_layers as usize);
    let last = layers.iter().map(|l| l.index).max()?;
    if last >= b + t || e.bottom_s == e.layer_s {
        return None;
    }
    let n = layers.len() as u64;
    let what = if last < b {
        format!(
            "{} exposed bottom_s = {} s",
            plural(n, "it is", "every layer is"),
            number(e.bottom_s.get())
        )
    } else {
        format!(
            "{}, on the ramp, is exposed {} s",
            plural(n, "it", "the last"),
            number(round::time_s(e.layer_exposure_s(last)))
        )
    };
    Some(
        Warning::new(
            "plan.bottom-layers-cover-job",
            format!(
                "exposure.bottom_layers = {b} and transition_layers = {t} reach past the job's {n} {}: {} exposed the normal layer_s = {} s ({what})",
                plural(n, "layer", "layers"),
                plural(n, "it is not", "none is"),
                number(e.layer_s.get()),
            ),
        )
        .with("bottom_layers", b as u64)
        .with("transition_layers", t as u64)
        .with("layers_total", n),
    )
}

/// The largest island of each layer that has any: `[layer, x_mm, y_mm, area_mm2]`.
fn largest_mm(layers: &[&LayerInfo]) -> serde_json::Value {
    let rows = layers.iter().filter_map(|l| {
        let [x, y, a] = l.island_mm?;
        Some(serde_json::json!([l.index, x, y, a]))
    });
    serde_json::Value::Array(rows.collect())
}

#[cfg(test)]
mod tests;
