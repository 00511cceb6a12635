//! Pictures of the prediction: each layer's edge error as a chart, and one layer's cured
//! outline over its section and mask.

use super::predict::EdgeSample;
use super::Irradiance;
use crate::bundle::Layer;
use crate::cure::model::CureModel;
use crate::plot::text::{TextStyle, LABEL, SMALL, TITLE};
use crate::plot::{Canvas, Chart, Panel, Series, Style};
use crate::slice::Contour;

/// The per-layer chart of the predicted edge error (layers with a prediction).
pub fn error_chart(name: &str, layers: &[Layer]) -> Chart {
    let series = |label: &str, color: [u8; 3], f: &dyn Fn(&super::LayerCure) -> f64| Series {
        label: label.into(),
        color,
        style: Style::Line,
        points: layers
            .iter()
            .filter_map(|l| l.cure.as_ref().map(|c| (l.index as f64, f(c))))
            .collect(),
    };
    Chart {
        title: format!("{name}: predicted cured edge against the section, per layer"),
        x_label: "layer number (0 = first layer, on the platform)".into(),
        x_whole: true,
        width: 1200,
        height: 800,
        panels: vec![
            Panel {
                y_label: "absolute edge error (px)".into(),
                series: vec![
                    series("mean", [31, 119, 180], &|c| c.abs_mean_px),
                    series("95th percentile", [255, 127, 14], &|c| c.p95_px),
                    series("largest", [214, 39, 40], &|c| c.max_px),
                ],
                y_from_zero: true,
                ..Default::default()
            },
            Panel {
                y_label: "mean signed error (px, + grows)".into(),
                series: vec![series("", [31, 119, 180], &|c| c.mean_px)],
                ..Default::default()
            },
            Panel {
                y_label: "features (count)".into(),
                series: vec![
                    series("vanish", [44, 160, 44], &|c| c.vanished as f64),
                    series("merge", [148, 103, 189], &|c| c.merged as f64),
                ],
                y_from_zero: true,
                ..Default::default()
            },
        ],
    }
}

/// Pixels shown across the outline picture at most.
const VIEW_PX: f64 = 120.0;
/// Picture pixels per mask pixel.
const ZOOM: f64 = 8.0;

/// Layer `index`'s mask (coverage, gray), its section (blue) and the predicted cured
/// edge (red: solid where counted, hollow where not), around the sample with the largest
/// counted error.
pub fn outline_picture(
    model: &CureModel,
    index: usize,
    (irradiance, (mw, mh)): (&Irradiance, (usize, usize)),
    contours: &[Contour],
    samples: &[EdgeSample],
) -> Canvas {
    let worst = samples
        .iter()
        .filter(|s| s.counted(model.sigma_px))
        .max_by(|a, b| {
            let e = |s: &EdgeSample| s.error_px.unwrap_or(0.0).abs();
            e(a).total_cmp(&e(b))
        })
        .or(samples.first());
    let centre = worst.map_or([mw as f64 / 2.0, mh as f64 / 2.0], |s| s.at);
    let u0 = (centre[0] - VIEW_PX / 2.0).floor().max(0.0);
    let v0 = (centre[1] - VIEW_PX * 0.375).floor().max(0.0);
    let (vw, vh) = (VIEW_PX, VIEW_PX * 0.75);
    let top = 90.0;
    let (w, h) = ((vw * ZOOM) as u32, (vh * ZOOM + top + 30.0) as u32);
    let mut c = Canvas::new(w, h, [255; 3]);
    let to = |u: f64, v: f64| (((u - u0) * ZOOM) as f32, ((v - v0) * ZOOM + top) as f32);
    let [c0, r0, c1, r1] = irradiance.bbox;
    for row in (v0 as usize).max(r0)..((v0 + vh) as usize).min(r1) {
        for col in (u0 as usize).max(c0)..((u0 + vw) as usize).min(c1) {
            let g = irradiance.data[(row - r0) * (c1 - c0) + col - c0].clamp(0.0, 1.0);
            if g > 0.0 {
                let shade = 255 - (g * 150.0) as u8;
                let (x, y) = to(col as f64, row as f64);
                c.fill_rect(x, y, ZOOM as f32, ZOOM as f32, [shade; 3], 255);
            }
        }
    }
    for smp in samples {
        if let Some(e) = smp.error_px {
            let (x, y) = to(smp.at[0] + e * smp.normal[0], smp.at[1] + e * smp.normal[1]);
            if smp.counted(model.sigma_px) {
                c.dot(x, y, 2.5, [214, 39, 40]);
            } else {
                c.dot(x, y, 2.5, [255, 180, 180]);
            }
        }
    }
    let s = 1.0 / model.pixel_mm;
    for ct in contours {
        let mut pts: Vec<(f32, f32)> = ct
            .iter()
            .map(|p| to(p[0] * s, mh as f64 - p[1] * s))
            .collect();
        if let Some(&p) = pts.first() {
            pts.push(p);
        }
        c.polyline(&pts, [31, 119, 180], 1.5);
    }
    c.fill_rect(0.0, 0.0, w as f32, top as f32, [255; 3], 255);
    c.text(
        12.0,
        10.0,
        &format!(
            "layer {index}: mask (gray), section (blue), predicted cured edge at mid-layer (red; pale: corners and narrow features)"
        ),
        TITLE,
    );
    let sub = [
        format!(
            "PSF σ = {} px; the mid-plane cures at {:.3} of a full pixel's light, its layer's and the layers above's;",
            model.sigma_px,
            model.threshold(0.5 * model.layer_mm, Some(0)),
        ),
        format!("view {vw} × {vh} px of {:.4} mm, around the largest counted error", model.pixel_mm),
    ];
    for (k, line) in sub.iter().enumerate() {
        c.text(12.0, 38.0 + 20.0 * k as f32, line, LABEL);
    }
    let scale: TextStyle = SMALL;
    c.fill_rect(0.0, h as f32 - 30.0, w as f32, 30.0, [255; 3], 255);
    c.text(
        12.0,
        h as f32 - 22.0,
        "1 mask pixel = 8 picture pixels",
        scale,
    );
    c
}
