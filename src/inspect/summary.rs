//! The numbers of `dmdsl inspect`: the job's totals, its warnings counted by code and the
//! per-layer extremes, from the manifest alone.

use crate::bundle::{Layer, Manifest};
use crate::text::{count, hms, number};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The largest value of one per-layer figure and the first layer that has it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Extreme {
    /// The value, in the figure's unit.
    pub value: f64,
    /// The (first) layer with it.
    pub layer: usize,
}

/// The per-layer extremes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Extremes {
    /// Largest section area, mm².
    pub area_mm2: Extreme,
    /// Longest exposure, s.
    pub exposure_s: Extreme,
    /// Largest fill distance, mm (`None`: the job does not know it, an imported one).
    pub max_fill_distance_mm: Option<Extreme>,
    /// Most islands resting on nothing (`None`: the job does not know them).
    pub islands: Option<Extreme>,
    /// Longest layer time, s.
    pub time_s: Extreme,
}

/// What `dmdsl inspect` reports (and prints with `--json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// True: the bundle was read (failures are errors).
    pub ok: bool,
    /// The bundle, as given.
    pub bundle: String,
    /// The form it came in: `dmdjob`, `dmdjob-zip`, `sl1`, `sl1s` or `sla-control` (the
    /// caller sets it; [`summarize`] says `dmdjob`).
    pub format: String,
    /// The part's file the job was sliced from.
    pub source: String,
    /// The machine profile's name.
    pub profile: String,
    /// Projectors (masks per layer).
    pub projectors: usize,
    /// Layers.
    pub layers: usize,
    /// The job's layer height setting, mm.
    pub layer_height_mm: f64,
    /// Height of the part as printed, mm.
    pub height_mm: f64,
    /// The manifest's estimated print time, s.
    pub print_time_s: f64,
    /// Sum of the exposures, s.
    pub exposure_s: f64,
    /// Cured resin volume, ml.
    pub resin_volume_ml: f64,
    /// Layers printed continuously (hybrid process), if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub continuous_layers: Option<u64>,
    /// The light compensation's mode (`zone` or `pixel`), if the masks are compensated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compensation: Option<String>,
    /// Its zone edge, mm (zone mode).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zone_mm: Option<f64>,
    /// Number of warnings (notes included).
    pub warnings: usize,
    /// Warnings counted by code.
    pub warnings_by_code: BTreeMap<String, usize>,
    /// The per-layer extremes (none for a job without layers).
    pub extremes: Option<Extremes>,
    /// What an imported job's reader could not take as stated (areas estimated from the
    /// masks, settings not simulated), one line each.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// True when the job states no pixel size (an imported file that has none): its areas
    /// and resin volume are counts of a stand-in pixel, not measurements, and the summary
    /// for people says so (the JSON keeps the numbers; `notes` says why).
    #[serde(skip)]
    pub unmeasured: bool,
    /// The pictures written.
    pub pictures: Vec<String>,
}

/// The largest `f` over `layers` and the first layer reaching it.
fn extreme(layers: &[Layer], f: impl Fn(&Layer) -> f64) -> Extreme {
    known_extreme(layers, |l| Some(f(l))).expect("a job with layers")
}

/// The largest `f` over the layers that have it and the first layer reaching it (`None`
/// when no layer has it).
fn known_extreme(layers: &[Layer], f: impl Fn(&Layer) -> Option<f64>) -> Option<Extreme> {
    layers.iter().fold(None, |best, l| match f(l) {
        Some(v) if best.is_none_or(|b: Extreme| v > b.value) => Some(Extreme {
            value: v,
            layer: l.index as usize,
        }),
        _ => best,
    })
}

/// The summary of the bundle at `bundle` (as given) whose manifest is `m`.
pub fn summarize(bundle: &str, m: &Manifest) -> Summary {
    let mut by_code = BTreeMap::new();
    for w in &m.warnings {
        *by_code.entry(w.code.clone()).or_insert(0) += 1;
    }
    let l = &m.layers;
    let optics = m.optics.as_ref().or(m.projector_optics.first());
    let extremes = (!l.is_empty()).then(|| Extremes {
        area_mm2: extreme(l, |l| l.area_mm2),
        exposure_s: extreme(l, |l| l.exposure_s),
        max_fill_distance_mm: known_extreme(l, |l| l.max_fill_distance_mm),
        islands: known_extreme(l, |l| l.islands.map(f64::from)),
        time_s: extreme(l, |l| l.time_s),
    });
    Summary {
        ok: true,
        bundle: bundle.into(),
        format: "dmdjob".into(),
        source: m.source.file.clone(),
        profile: m.machine.name.clone(),
        projectors: m.machine.projector.len(),
        layers: l.len(),
        layer_height_mm: m.settings.layer_height_mm,
        height_mm: m.totals.height_mm,
        print_time_s: m.totals.print_time_s,
        exposure_s: m.totals.exposure_s,
        resin_volume_ml: m.totals.resin_volume_ml,
        continuous_layers: m.totals.continuous_layers,
        compensation: optics.map(|o| o.mode.clone()),
        zone_mm: optics.filter(|o| o.mode == "zone").map(|o| o.zone_mm),
        warnings: m.warnings.len(),
        warnings_by_code: by_code,
        extremes,
        notes: Vec::new(),
        unmeasured: !m.machine.states("projector[].pixel_mm"),
        pictures: Vec::new(),
    }
}

/// The summary for people.
pub fn render_human(s: &Summary) -> String {
    let mut o = String::new();
    let format = if s.format == "dmdjob" {
        String::new()
    } else {
        format!(" ({})", s.format)
    };
    let projectors = match s.projectors {
        0 | 1 => String::new(),
        k => format!(" ({k} projectors)"),
    };
    let (n, h, tall) = (s.layers, s.layer_height_mm, s.height_mm);
    let (source, profile) = (&s.source, &s.profile);
    // An imported job's profile is a placeholder name: say where its machine comes from.
    // Its layers come from a file's images, not from sections (also in a bundle exported
    // from it): no layer knows its fill distance.
    let imported = (s.extremes.as_ref()).is_some_and(|e| e.max_fill_distance_mm.is_none());
    let origin = match imported {
        true => format!("imported from {source}, for the machine that file states"),
        false => format!("sliced from {source} for {profile}"),
    };
    let _ = writeln!(
        o,
        "{}{format}: {} of {} mm, {tall:.2} mm tall; {origin}{projectors}",
        s.bundle,
        count(n as u64, "layer", "layers"),
        number(h)
    );
    let continuous = s.continuous_layers.map_or(String::new(), |c| {
        format!(", {c} layers printed continuously")
    });
    let (t, exposure, resin) = (s.print_time_s, s.exposure_s, s.resin_volume_ml);
    let resin = match s.unmeasured {
        true => "resin not measured (no pixel size)".to_string(),
        false => format!("resin {resin:.2} ml"),
    };
    let _ = writeln!(
        o,
        "estimated print time {} ({t:.1} s), exposure {exposure:.1} s, {resin}{continuous}",
        hms(t)
    );
    match (s.compensation.as_deref(), s.zone_mm) {
        (Some("zone"), Some(z)) => {
            let _ = writeln!(o, "light compensation: zone: each {} mm zone has its own gray, so a mask shows faint squares inside the part (darker where the projector is brighter)", number(z));
        }
        (Some(mode), _) => {
            let _ = writeln!(o, "light compensation: {mode}: each pixel has its own gray, darker where the projector is brighter");
        }
        (None, _) => {}
    }
    if s.warnings == 0 {
        let _ = writeln!(o, "warnings: none");
    } else {
        let by: Vec<String> = s
            .warnings_by_code
            .iter()
            .map(|(c, n)| format!("{c} {n}"))
            .collect();
        let _ = writeln!(o, "warnings: {} ({})", s.warnings, by.join(", "));
    }
    for n in &s.notes {
        let _ = writeln!(o, "note: {n}");
    }
    if let Some(e) = &s.extremes {
        let rows = [
            ("largest area", Some(e.area_mm2), 2, " mm²"),
            ("longest exposure", Some(e.exposure_s), 2, " s"),
            ("largest fill distance", e.max_fill_distance_mm, 3, " mm"),
            ("most islands on nothing", e.islands, 0, ""),
            ("longest layer time", Some(e.time_s), 2, " s"),
        ];
        for (what, x, decimals, unit) in rows {
            // An imported job's file holds images, not the sections these come from.
            let Some(x) = x else {
                let _ = writeln!(o, "  {what:<23} {:>17}", "not in the file");
                continue;
            };
            let value = match s.unmeasured && what == "largest area" {
                true => "not measured".to_string(),
                false => format!("{:.decimals$}{unit}", x.value),
            };
            let _ = writeln!(o, "  {what:<23} {value:>17}  layer {}", x.layer);
        }
    }
    for p in &s.pictures {
        let _ = writeln!(o, "picture: {p}");
    }
    o
}
