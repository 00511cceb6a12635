//! Whether every layer rests on the one below, from the masks alone: the regions of each
//! layer's lit pixels on the field that share no lit pixel with the layer below
//! ([`crate::bundle::regions`], from the runs the verification collected as it decoded
//! the masks); on a cure-corrected job, those of them that rest on nothing by what cures
//! (`cured`). A job compiled with supports (`supports` in its manifest) must have none as
//! large as a support head's contact ([`smallest_held_mm2`]): each layer that has some is
//! an `unsupported-region` violation. Any other job (no supports asked, or imported) gets
//! the warning `run.unsupported-regions`.

mod cured;

use super::{Kind, Violation};
use crate::bundle::machine::Machine;
use crate::bundle::regions::{regions_of, resting_regions, Region, Run};
use crate::bundle::{BundleSource, Manifest};
use crate::text::{first_of, fixed, number, plural};
use crate::warning::Warning;
use serde::Serialize;

/// Regions a layer's violation names before "and N more".
const SHOWN_PER_LAYER: usize = 3;
/// Layers the warning names with their largest region before "N more layers".
const SHOWN_LAYERS: usize = 3;

/// A region of a layer that rests on nothing in the layer below.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct UnsupportedRegion {
    /// Its layer.
    pub layer: usize,
    /// Build-plane x of its centre, mm.
    #[serde(serialize_with = "crate::round::six")]
    pub x_mm: f64,
    /// Build-plane y of its centre, mm.
    #[serde(serialize_with = "crate::round::six")]
    pub y_mm: f64,
    /// Its area (lit pixels × pixel area), mm².
    #[serde(serialize_with = "crate::round::six")]
    pub area_mm2: f64,
}

/// What the masks say of the job's printability.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Printability {
    /// Every region resting on nothing below, by layer, then in the order of their first
    /// pixel.
    pub regions: Vec<UnsupportedRegion>,
    /// `run.unsupported-regions`, for a job without supports that has such regions.
    pub warning: Option<Warning>,
    /// One `unsupported-region` per layer that has such regions, for a job with supports.
    pub violations: Vec<Violation>,
    /// The regions of `violations`: layer and the box of the region's pixels on the field
    /// ([`Region::box_px`]).
    pub held: Vec<(usize, [u32; 4])>,
}

/// The printability of `manifest`'s job whose layers' lit runs on `machine`'s field are
/// `runs` (`None`: a layer not judged).
pub fn check<R: AsRef<[Run]>>(
    dir: &dyn BundleSource,
    manifest: &Manifest,
    machine: &Machine,
    runs: &[Option<R>],
) -> Printability {
    let field = machine.field();
    let p = field.pixel_mm;
    let mm = |(layer, g): (usize, Region)| {
        let [x_mm, y_mm] = g.at_mm(field.height_px, p);
        let at = UnsupportedRegion {
            layer,
            x_mm,
            y_mm,
            area_mm2: g.area_mm2(p),
        };
        (at, g.box_px)
    };
    // A corrected job's candidates judged by what cures; by gray alone when there is no
    // model to judge by.
    let mut judge = None;
    let mut regions = Vec::new();
    for (i, pair) in runs.windows(2).enumerate() {
        let [Some(below), Some(cur)] = pair else {
            continue;
        };
        let (below, cur) = (below.as_ref(), cur.as_ref());
        let Some((region, rests)) = resting_regions(cur, below) else {
            continue;
        };
        let mut free: Vec<bool> = rests.iter().map(|r| !r).collect();
        if !free.contains(&true) {
            continue;
        }
        if let Some(j) = judge.get_or_insert_with(|| cured::CureJudge::of(dir, manifest, machine)) {
            j.judge(i + 1, cur, &region, &mut free);
        }
        let found = regions_of(cur, &region, &free);
        regions.extend(found.into_iter().map(|g| mm((i + 1, g))));
    }
    let mut out = Printability::default();
    if regions.is_empty() {
        return out;
    }
    let (regions, boxes): (Vec<UnsupportedRegion>, Vec<[u32; 4]>) = regions.into_iter().unzip();
    // Without a model, a corrected job's masks are not judged for violations: the
    // correction moves edges in by up to a pixel and counts on the blur to close what
    // that opens (what they leave over nothing is the warning, and `run --cure` predicts
    // what cures).
    let gray_only = judge.flatten().is_none()
        && manifest
            .cure
            .as_ref()
            .is_some_and(|c| c.correction != "off");
    match manifest.supports.as_ref().filter(|_| !gray_only) {
        Some(s) => {
            let least = smallest_held_mm2(s);
            let (held, boxes): (Vec<UnsupportedRegion>, Vec<_>) = (regions.iter().zip(boxes))
                .filter(|(g, _)| g.area_mm2 >= least)
                .map(|(g, b)| (*g, (g.layer, b)))
                .unzip();
            out.held = boxes;
            out.violations = by_layer(&held)
                .iter()
                .map(|l| violation(dir, manifest, l, least))
                .collect();
        }
        None => {
            let supported = manifest.supports.is_some();
            out.warning = Some(warning(&by_layer(&regions), supported));
        }
    }
    out.regions = regions;
    out
}

/// The smallest region a job with supports `s` must not leave over nothing, mm²: the
/// contact of a support head ([`crate::bundle::Supports::head_contact_mm2`]). Smaller
/// ones are listed but are no violation: the light compensation's grays and the cure
/// correction's moved and widened edges leave lone pixels and pixels that touch their
/// neighbours only at a corner at the masks' edges, which the slicer's analysis of the
/// sections does not see, and a head could not hold a region that small.
pub fn smallest_held_mm2(s: &crate::bundle::Supports) -> f64 {
    s.head_contact_mm2()
}

/// The regions of each layer that has some, largest first (the first found among equals).
fn by_layer(regions: &[UnsupportedRegion]) -> Vec<Vec<UnsupportedRegion>> {
    let mut out: Vec<Vec<UnsupportedRegion>> = Vec::new();
    for g in regions {
        match out.last_mut() {
            Some(l) if l[0].layer == g.layer => l.push(*g),
            _ => out.push(vec![*g]),
        }
    }
    for l in &mut out {
        l.sort_by(|a, b| b.area_mm2.total_cmp(&a.area_mm2));
    }
    out
}

/// "layer 5 at x 37.99, y 23.90 mm (15.992 mm²)", without the layer when `layer` is false.
fn at_text(g: &UnsupportedRegion, layer: bool) -> String {
    let (x, y) = (fixed(g.x_mm, 2), fixed(g.y_mm, 2));
    let area = number(crate::round::plane_mm(g.area_mm2));
    let on = if layer {
        format!("layer {} ", g.layer)
    } else {
        String::new()
    };
    format!("{on}at x {x}, y {y} mm ({area} mm²)")
}

/// The `unsupported-region` violation of one layer's regions (largest first).
fn violation(
    dir: &dyn BundleSource,
    manifest: &Manifest,
    regions: &[UnsupportedRegion],
    least_mm2: f64,
) -> Violation {
    let i = regions[0].layer;
    let file = manifest
        .layers
        .get(i)
        .and_then(|l| l.masks.first())
        .map(|m| m.file.clone());
    let shown = file
        .as_deref()
        .map_or(String::new(), |f| format!("{}: ", dir.shown(f).display()));
    let k = regions.len() as u64;
    let mut at: Vec<String> = regions
        .iter()
        .take(SHOWN_PER_LAYER)
        .map(|g| at_text(g, false))
        .collect();
    if regions.len() > SHOWN_PER_LAYER {
        at.push(format!("{} more", regions.len() - SHOWN_PER_LAYER));
    }
    let message = format!(
        "{shown}layer {i}: {k} {} of its masks ({} mm² or more, a support head's contact) {} on nothing in the layer below, though the job was compiled with supports: {}",
        plural(k, "region", "regions"),
        number(crate::round::plane_mm(least_mm2)),
        plural(k, "rests", "rest"),
        at.join("; ")
    );
    Violation {
        layer: Some(i),
        time_s: None,
        kind: Kind::UnsupportedRegion,
        message,
        file,
    }
}

/// The `run.unsupported-regions` warning of the layers' regions (each largest first).
fn warning(layers: &[Vec<UnsupportedRegion>], supported: bool) -> Warning {
    let n: u64 = layers.iter().map(|l| l.len() as u64).sum();
    let k = layers.len() as u64;
    let first = layers[0][0].layer;
    let at = first_of(
        layers.iter().map(|l| at_text(&l[0], true)),
        (SHOWN_LAYERS, layers.len()),
        ("layer", "layers"),
    );
    let largest: Vec<serde_json::Value> = layers
        .iter()
        .map(|l| {
            let g = l[0];
            let [x, y, a] = [g.x_mm, g.y_mm, g.area_mm2].map(crate::round::plane_mm);
            serde_json::json!([g.layer, x, y, a])
        })
        .collect();
    Warning::new(
        "run.unsupported-regions",
        format!(
            "{n} unsupported {} on {k} {} (first at layer {first}); largest per layer: {}: regions of the masks that do not rest on the layer below need supports{}",
            plural(n, "region", "regions"),
            plural(k, "layer", "layers"),
            at,
            if supported {
                " (the job has supports, and its cure correction moved these edges in: `dmdsl run --cure` predicts whether they cure together)"
            } else {
                ""
            }
        ),
    )
    .with("regions", n)
    .with("layers", k)
    .with("first_layer", first as u64)
    .with("largest_mm", serde_json::Value::Array(largest))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exec::testutil::manifest;

    #[test]
    fn regions_warn_without_supports_and_are_violations_with_them() {
        let mut m = manifest(crate::exec::testutil::profile(), vec![]);
        let machine = m.machine.clone();
        let field = machine.field();
        let h = field.height_px;
        // Layer 0 on the platform; layer 1: one region on it, two beside it; layer 2:
        // one region over nothing.
        let runs = vec![
            Some(vec![[0, 0, 4]]),
            Some(vec![[0, 1, 3], [2, 10, 13], [3, 10, 13], [5, 20, 21]]),
            Some(vec![[9, 30, 32]]),
        ];
        let dir = crate::bundle::DirSource::new(std::path::Path::new("part.dmdjob"));
        let p = check(&dir, &m, &machine, &runs);
        assert_eq!(p.regions.len(), 3);
        assert!(p.violations.is_empty());
        let px = field.pixel_mm;
        assert_eq!(p.regions[0].layer, 1);
        assert_eq!(p.regions[0].x_mm, 11.5 * px);
        assert_eq!(p.regions[0].y_mm, (h as f64 - 3.0) * px);
        assert_eq!(p.regions[0].area_mm2, 6.0 * px * px);
        let w = p.warning.expect("warned");
        assert_eq!(w.code, "run.unsupported-regions");
        assert!(
            w.message
                .starts_with("3 unsupported regions on 2 layers (first at layer 1); largest per layer: layer 1 at x "),
            "{}",
            w.message
        );
        assert_eq!(w.fields["regions"], 3);
        assert_eq!(w.fields["largest_mm"].as_array().unwrap().len(), 2);
        // Supports whose heads hold 3 pixels: the 6-pixel region is a violation, the
        // 1- and 2-pixel ones are only listed.
        let d = 2.0 * (3.0 * px * px / std::f64::consts::PI).sqrt();
        m.supports = Some(
            serde_json::from_value(serde_json::json!({
                "head_front_diameter_mm": d, "head_penetration_mm": 0.2, "head_length_mm": 1.0,
                "lift_mm": 5.0, "points": [], "volume_mm3": 0.0,
                "pad": {"thickness_mm": 1.0, "area_mm2": 0.0, "outline_mm": []}
            }))
            .unwrap(),
        );
        let p = check(&dir, &m, &machine, &runs);
        assert!(p.warning.is_none());
        assert_eq!(p.regions.len(), 3);
        assert_eq!(p.violations.len(), 1);
        let v = &p.violations[0];
        assert_eq!((v.layer, v.kind), (Some(1), Kind::UnsupportedRegion));
        let want = format!(
            "layer 1: 1 region of its masks ({} mm² or more, a support head's contact) rests on nothing in the layer below, though the job was compiled with supports: at x ",
            number(crate::round::plane_mm(3.0 * px * px))
        );
        assert!(v.message.contains(&want), "{}", v.message);
        // Nothing over nothing: no finding.
        let p = check(&dir, &m, &machine, &runs[..1]);
        assert_eq!(p, Printability::default());
    }
}
