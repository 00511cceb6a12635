//! The cure check's report: its types (`CureCheck`, one `LayerCureCheck` per layer,
//! `Finding`s) and the job's figures from the layers' (`summarize`).

use super::check::{SUB, WORST_LAYERS};
use super::engine::LayerOut;
use super::CureModel;
use crate::bundle::Manifest;
use crate::round::{six, six_opt, six_pair};
use serde::Serialize;

/// Statistics of the absolute edge offset over layers, px.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct OffsetStats {
    /// Perimeter-weighted mean.
    #[serde(serialize_with = "six")]
    pub mean: f64,
    /// Perimeter-weighted 95th percentile.
    #[serde(serialize_with = "six")]
    pub p95: f64,
    /// Largest.
    #[serde(serialize_with = "six")]
    pub max: f64,
}

/// Something a process engineer must see: an island that does not cure, or cured resin
/// joining islands.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// Layer index.
    pub layer: usize,
    /// `vanished` or `merged`.
    pub kind: &'static str,
    /// Islands concerned (1 for `vanished`).
    pub islands: usize,
    /// Lit pixels of the islands.
    pub pixels: u64,
    /// Their centroid on the build plane, mm from the field's bottom-left corner.
    #[serde(serialize_with = "six_pair")]
    pub at_mm: [f64; 2],
}

/// One layer's cure, from its masks.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct LayerCureCheck {
    /// Layer index.
    pub index: usize,
    /// The section's area the bundle records, mm².
    #[serde(serialize_with = "six")]
    pub section_mm2: f64,
    /// Cured area at mid-layer, mm² (samples where the layer's own light is at least
    /// [`NEAR`](super::check::NEAR) of a full pixel's).
    #[serde(serialize_with = "six")]
    pub cured_mm2: f64,
    /// The drawn perimeter, mm (Σ|∇| of the relative irradiance).
    #[serde(serialize_with = "six")]
    pub perimeter_mm: f64,
    /// Mean edge offset (cured − section area) / perimeter, px (positive: grows).
    #[serde(serialize_with = "six")]
    pub offset_px: f64,
    /// The same, mm.
    #[serde(serialize_with = "six")]
    pub offset_mm: f64,
    /// Islands of lit pixels.
    pub islands: usize,
    /// Islands no sample of which cures.
    pub vanished: usize,
    /// Cured regions joining two or more islands.
    pub merged: usize,
    /// Deepest cure below the layer's bottom at its downward-facing pixels, mm.
    #[serde(serialize_with = "six_opt", skip_serializing_if = "Option::is_none")]
    pub print_through_mm: Option<f64>,
    /// The slicer's prediction of the layer's mean edge offset (`layers[].cure.offset_px`;
    /// its signed mean edge error `mean_px` in bundles without it).
    #[serde(serialize_with = "six_opt", skip_serializing_if = "Option::is_none")]
    pub slicer_mean_px: Option<f64>,
    /// `offset_px` − `slicer_mean_px`.
    #[serde(serialize_with = "six_opt", skip_serializing_if = "Option::is_none")]
    pub slicer_diff_px: Option<f64>,
}

/// How the check agrees with the slicer's records (`slice --predict`): information.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct SlicerAgreement {
    /// Layers with both figures.
    pub layers: usize,
    /// Largest |offset − slicer's mean|, px.
    #[serde(serialize_with = "six")]
    pub max_diff_px: f64,
    /// The layer where it is.
    pub max_diff_layer: Option<usize>,
    /// Layers where one finds a vanishing island and the other none.
    pub vanish_disagreements: Vec<usize>,
}

/// The cure predicted from the masks (`dmdsl run --cure`).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CureCheck {
    /// The job's correction: "off", "xy" or "xyz".
    pub correction: String,
    /// Layers of downward-facing surfaces held back (`xyz`).
    pub held_back_layers: u32,
    /// Samples per pixel along each axis.
    pub samples_per_px: usize,
    /// Layers with a drawn perimeter (the offset statistics are over them).
    pub layers_checked: usize,
    /// |edge offset| over layers, weighted by perimeter, px.
    pub edge_offset_px: OffsetStats,
    /// Signed mean edge offset, px (weighted by perimeter).
    #[serde(serialize_with = "six")]
    pub signed_mean_px: f64,
    /// The same, mm.
    #[serde(serialize_with = "six")]
    pub signed_mean_mm: f64,
    /// Islands that do not cure, over all layers.
    pub vanished: usize,
    /// Cured regions joining islands, over all layers.
    pub merged: usize,
    /// Deepest print-through below a downward-facing pixel, mm (`None`: none).
    #[serde(serialize_with = "six_opt")]
    pub print_through_mm: Option<f64>,
    /// With held-back layers: `print_through_mm` − held_back_layers·h, mm.
    #[serde(serialize_with = "six_opt", skip_serializing_if = "Option::is_none")]
    pub z_error_mm: Option<f64>,
    /// Against the slicer's per-layer records, when the bundle has them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub slicer: Option<SlicerAgreement>,
    /// Layers with the largest |offset|, worst first.
    pub worst_layers: Vec<usize>,
    /// Vanished and merged islands, by layer.
    pub findings: Vec<Finding>,
    /// Per layer.
    pub per_layer: Vec<LayerCureCheck>,
}

/// The job's figures from the layers' (`outs`, in layer order), mask pixels mapped to
/// the build plane by `to_mm`.
pub fn summarize(
    manifest: &Manifest,
    model: &CureModel,
    to_mm: &dyn Fn([f64; 2]) -> [f64; 2],
    outs: Vec<LayerOut>,
) -> CureCheck {
    let p = model.pixel_mm;
    let sample_mm2 = p * p / (SUB * SUB) as f64;
    let c = manifest.cure.as_ref();
    let held = c.map_or(0, |c| c.held_back_layers);
    let mut per_layer = Vec::with_capacity(outs.len());
    let mut findings = Vec::new();
    let mut agree = SlicerAgreement::default();
    let mut any_slicer = false;
    for (i, o) in outs.into_iter().enumerate() {
        let l = &manifest.layers[i];
        let cured_mm2 = o.cured_samples * sample_mm2;
        let offset_px = if o.perimeter_px > 0.0 {
            (cured_mm2 - l.area_mm2) / (p * p) / o.perimeter_px
        } else {
            0.0
        };
        for &(px, at) in &o.vanished {
            findings.push(Finding {
                layer: i,
                kind: "vanished",
                islands: 1,
                pixels: px,
                at_mm: to_mm(at),
            });
        }
        for &(k, px, at) in &o.merged {
            findings.push(Finding {
                layer: i,
                kind: "merged",
                islands: k,
                pixels: px,
                at_mm: to_mm(at),
            });
        }
        let slicer = l.cure.as_ref();
        let diff = slicer
            .filter(|_| o.perimeter_px > 0.0)
            .map(|s| offset_px - s.offset_px.unwrap_or(s.mean_px));
        if let Some(s) = slicer {
            any_slicer = true;
            if (s.vanished == 0) != o.vanished.is_empty() {
                agree.vanish_disagreements.push(i);
            }
        }
        if let Some(d) = diff {
            agree.layers += 1;
            if agree.max_diff_layer.is_none() || d.abs() > agree.max_diff_px {
                agree.max_diff_px = d.abs();
                agree.max_diff_layer = Some(i);
            }
        }
        per_layer.push(LayerCureCheck {
            index: i,
            section_mm2: l.area_mm2,
            cured_mm2,
            perimeter_mm: o.perimeter_px * p,
            offset_px,
            offset_mm: offset_px * p,
            islands: o.islands,
            vanished: o.vanished.len(),
            merged: o.merged.len(),
            print_through_mm: o.print_through_mm,
            slicer_mean_px: slicer.map(|s| s.offset_px.unwrap_or(s.mean_px)),
            slicer_diff_px: diff,
        });
    }
    let checked: Vec<&LayerCureCheck> = per_layer.iter().filter(|l| l.perimeter_mm > 0.0).collect();
    let (edge, signed) = offset_stats(&checked);
    let mut worst: Vec<&LayerCureCheck> = checked.clone();
    worst.sort_by(|a, b| {
        b.offset_px
            .abs()
            .total_cmp(&a.offset_px.abs())
            .then(a.index.cmp(&b.index))
    });
    let print_through = per_layer
        .iter()
        .filter_map(|l| l.print_through_mm)
        .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))));
    CureCheck {
        correction: c.map_or_else(String::new, |c| c.correction.clone()),
        held_back_layers: held,
        samples_per_px: SUB,
        layers_checked: checked.len(),
        edge_offset_px: edge,
        signed_mean_px: signed,
        signed_mean_mm: signed * p,
        vanished: per_layer.iter().map(|l| l.vanished).sum(),
        merged: per_layer.iter().map(|l| l.merged).sum(),
        print_through_mm: print_through,
        z_error_mm: (held > 0)
            .then(|| print_through.map(|t| t - held as f64 * model.layer_mm))
            .flatten(),
        slicer: any_slicer.then_some(agree),
        worst_layers: worst.iter().take(WORST_LAYERS).map(|l| l.index).collect(),
        findings,
        per_layer,
    }
}

/// The absolute per-layer offsets of `checked` weighted by their perimeters (mean, p95,
/// largest) and their signed mean.
fn offset_stats(checked: &[&LayerCureCheck]) -> (OffsetStats, f64) {
    let total: f64 = checked.iter().map(|l| l.perimeter_mm).sum();
    let mut edge = OffsetStats::default();
    let mut signed = 0.0;
    if total > 0.0 {
        edge.mean = checked
            .iter()
            .map(|l| l.perimeter_mm * l.offset_px.abs())
            .sum::<f64>()
            / total;
        signed = checked
            .iter()
            .map(|l| l.perimeter_mm * l.offset_px)
            .sum::<f64>()
            / total;
        let mut by: Vec<(f64, f64)> = checked
            .iter()
            .map(|l| (l.offset_px.abs(), l.perimeter_mm))
            .collect();
        by.sort_by(|a, b| a.0.total_cmp(&b.0));
        edge.max = by.last().map_or(0.0, |b| b.0);
        let mut cum = 0.0;
        edge.p95 = edge.max;
        for (a, wgt) in by {
            cum += wgt;
            if cum >= 0.95 * total {
                edge.p95 = a;
                break;
            }
        }
    }
    (edge, signed)
}
