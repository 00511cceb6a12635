//! The per-layer chart: the manifest's figures of every layer against the layer number, in
//! stacked panels sharing the x axis, each with its quantity and unit.

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
    // Each layer's value held over its width on the x axis (layer i spans i ± 0.5).
    let series = |f: &dyn Fn(&Layer) -> f64| {
        let points = layers.iter().flat_map(|l| {
            let (x, v) = (l.index as f64, f(l));
            [(x - 0.5, v), (x + 0.5, v)]
        });
        Series::new("", LINE, Style::Line, points.collect())
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
    let which = match (layers.first(), layers.last()) {
        (Some(a), Some(b)) if layers.len() < n => {
            format!("layers {}–{} of {n}", a.index, b.index)
        }
        _ => format!("{n} layers"),
    };
    Chart {
        title: format!("{name}: figures of each layer ({which})"),
        x_label: "layer number (0 = first layer, on the platform)".into(),
        width: 1200,
        height: 1100,
        panels: vec![
            panel("section area (mm²)", series(&|l| l.area_mm2)),
            panel("exposure (s)", series(&|l| l.exposure_s)),
            panel(
                "largest fill distance (mm)",
                series(&|l| l.max_fill_distance_mm),
            ),
            panel("layer time (s)", series(&|l| l.time_s)),
            panel("islands on nothing (count)", series(&|l| l.islands as f64)),
        ],
    }
}
