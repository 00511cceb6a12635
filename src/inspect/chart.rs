//! The per-layer chart: the manifest's figures of every layer against the layer number, in
//! stacked panels sharing the x axis, each with its quantity and unit. The figures of the
//! sections (fill distance, islands) have no panel for a job that does not know them (an
//! imported one).

use crate::bundle::{Layer, Manifest, Mode};
use crate::plot::{Band, Chart, Panel, Series, Style};
use std::ops::RangeInclusive;

/// Colour of the panels' lines.
const LINE: [u8; 3] = [31, 100, 180];
/// Colour and legend of the shading of continuously printed layers.
const CONTINUOUS: [u8; 3] = [44, 160, 44];
const CONTINUOUS_LABEL: &str = "printed continuously (stage sweeping)";

/// The chart of the layers in `range` (all if `None`) of the bundle named `name`.
pub fn layer_chart(name: &str, manifest: &Manifest, range: Option<RangeInclusive<usize>>) -> Chart {
    let n = manifest.layers.len();
    let layers: &[Layer] = match &range {
        Some(r) if n > 0 => &manifest.layers[*r.start()..=(*r.end()).min(n - 1)],
        _ => &manifest.layers,
    };
    // Each layer's value held over its width on the x axis (layer i spans i ± 0.5); none
    // for a layer without it.
    let series = |f: &dyn Fn(&Layer) -> Option<f64>| {
        let points = layers.iter().flat_map(|l| {
            let x = l.index as f64;
            f(l).map(|v| [(x - 0.5, v), (x + 0.5, v)])
        });
        Series::new("", LINE, Style::Line, points.flatten().collect())
    };
    // Continuous (swept) layers of a hybrid job, shaded in every panel.
    let mut bands = Vec::new();
    for l in layers.iter().filter(|l| l.mode == Mode::Continuous) {
        let x = l.index as f64;
        match bands.last_mut() {
            Some(Band { x1, .. }) if (*x1 - (x - 0.5)).abs() < 1e-9 => *x1 = x + 0.5,
            _ => bands.push(Band::new(x - 0.5, x + 0.5, CONTINUOUS, CONTINUOUS_LABEL)),
        }
    }
    let panel = |y_label: &str, s: Series| Panel {
        y_label: y_label.into(),
        series: vec![s],
        bands: bands.clone(),
        y_from_zero: true,
    };
    // A section's figure has a panel unless every layer lacks it.
    let known = |y_label: &str, s: Series| {
        (layers.is_empty() || !s.points.is_empty()).then(|| panel(y_label, s))
    };
    let which = match (layers.first(), layers.last()) {
        (Some(a), Some(b)) if layers.len() < n => {
            format!("{} of {n}", crate::text::layer_range(a.index, b.index))
        }
        _ => crate::text::count(n as u64, "layer", "layers"),
    };
    Chart {
        title: format!("{name}: figures of each layer ({which})"),
        x_label: "layer number (0 = first layer, on the platform)".into(),
        x_whole: true,
        width: 1200,
        height: 1100,
        panels: [
            Some(panel("section area (mm²)", series(&|l| Some(l.area_mm2)))),
            Some(panel("exposure (s)", series(&|l| Some(l.exposure_s)))),
            known(
                "largest fill distance (mm)",
                series(&|l| l.max_fill_distance_mm),
            ),
            Some(panel("layer time (s)", series(&|l| Some(l.time_s)))),
            known(
                "islands on nothing (count)",
                series(&|l| l.islands.map(f64::from)),
            ),
        ]
        .into_iter()
        .flatten()
        .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(m: &Manifest) -> Vec<String> {
        let chart = layer_chart("t", m, None);
        chart.panels.into_iter().map(|p| p.y_label).collect()
    }

    #[test]
    fn a_range_of_layers_is_titled_by_it_on_whole_layer_numbers() {
        let m = crate::exec::testutil::two_layer_topdown();
        let title = |r| layer_chart("t", &m, Some(r)).title;
        assert_eq!(title(1..=1), "t: figures of each layer (layer 1 of 2)");
        assert_eq!(title(0..=1), "t: figures of each layer (2 layers)");
        assert!(layer_chart("t", &m, None).x_whole);
    }

    #[test]
    fn a_job_without_sections_has_no_panels_for_their_figures() {
        let mut m = crate::exec::testutil::two_layer_topdown();
        assert_eq!(labels(&m).len(), 5);
        for l in &mut m.layers {
            (l.max_fill_distance_mm, l.islands) = (None, None);
        }
        let got = labels(&m);
        assert_eq!(got.len(), 3, "{got:?}");
        assert!(got
            .iter()
            .all(|l| !l.contains("fill") && !l.contains("islands")));
    }
}
