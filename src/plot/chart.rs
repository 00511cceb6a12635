//! Line charts: one or more panels stacked over a shared x axis, each with its own y axis
//! and unit, series drawn as lines, steps or dots, shaded x ranges, and a legend above the
//! plot area (never over the data).

use super::axes::{self, Area, Scale, Ticks};
use super::canvas::Canvas;
use super::text::{self, Align, LABEL, SMALL, TITLE};

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Straight segments between consecutive points.
    Line,
    /// A dot at each point.
    Points,
}

/// One data series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text (empty: not in the legend).
    pub label: String,
    /// RGB colour.
    pub color: [u8; 3],
    /// Drawing style.
    pub style: Style,
    /// (x, y) points, in x order for `Line`.
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A series labelled `label` (empty: not in the legend).
    pub fn new(label: &str, color: [u8; 3], style: Style, points: Vec<(f64, f64)>) -> Series {
        Series {
            label: label.into(),
            color,
            style,
            points,
        }
    }
}

/// A shaded x range (e.g. "light on", "valid gray range"). Ranges narrower than a pixel
/// column shade it in proportion to the part of it they cover, so thousands of short
/// ranges read as a density.
#[derive(Debug, Clone)]
pub struct Band {
    /// Start of the range.
    pub x0: f64,
    /// End of the range.
    pub x1: f64,
    /// RGB colour (drawn translucent).
    pub color: [u8; 3],
    /// Legend text (empty: no legend entry; one entry per distinct text).
    pub label: String,
}

impl Band {
    /// The range `x0..x1` labelled `label` (empty: no legend entry).
    pub fn new(x0: f64, x1: f64, color: [u8; 3], label: &str) -> Band {
        Band {
            x0,
            x1,
            color,
            label: label.into(),
        }
    }
}

/// One panel: a y axis with its label (quantity and unit) and what is drawn against it.
#[derive(Debug, Clone, Default)]
pub struct Panel {
    /// Y axis label, with its unit: "stage position (mm)".
    pub y_label: String,
    /// Data.
    pub series: Vec<Series>,
    /// Shaded x ranges.
    pub bands: Vec<Band>,
    /// Start the y axis at zero (for quantities such as areas and counts).
    pub y_from_zero: bool,
}

/// A chart: a title, panels stacked top to bottom sharing the x axis, the x axis label.
#[derive(Debug, Clone)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// X axis label, with its unit.
    pub x_label: String,
    /// The x values are whole numbers (layer numbers): ticks fall on whole numbers only.
    pub x_whole: bool,
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// The panels, top to bottom.
    pub panels: Vec<Panel>,
}

/// Opacity of a band covering a whole pixel column (0–255).
const BAND_ALPHA: f32 = 80.0;
/// Gap between stacked panels, px.
const PANEL_GAP: f32 = 18.0;
/// Space around the picture's content, px.
const PAD: f32 = 12.0;

/// A legend entry: its text, colour and what its swatch looks like.
#[derive(Debug, Clone, PartialEq)]
enum Swatch {
    Line,
    Dot,
    Shade,
}

impl Chart {
    /// The chart drawn on a canvas of `width` × `height` (at least 240 × 160).
    pub fn render(&self) -> Canvas {
        let (w, h) = (self.width.max(240) as f32, self.height.max(160) as f32);
        let mut c = Canvas::new(w as u32, h as u32, [255; 3]);
        let title_h = text::line_height(TITLE.size);
        c.text(PAD, PAD, &self.title, TITLE);

        let x_range = self.x_range();
        let y_ranges: Vec<(f64, f64, bool)> = self.panels.iter().map(y_range).collect();
        // About one tick per 45 px of panel height (estimated before the legend is laid
        // out: the tick labels' width sets the left margin).
        let n = self.panels.len().max(1) as f32;
        let per_panel = ((h - 140.0) / n / 45.0).clamp(2.0, 8.0) as usize;
        let y_ticks: Vec<Ticks> = y_ranges
            .iter()
            .map(|&(lo, hi, int)| axes::ticks(lo, hi, per_panel, int))
            .collect();
        let label_h = text::line_height(LABEL.size);
        let tick_w = y_ticks.iter().map(axes::y_labels_width).fold(0.0, f32::max);
        let ml = PAD + label_h + 8.0 + tick_w;
        let mr = 28.0;
        let plot_w = w - ml - mr;

        let legend_top = PAD + title_h + 8.0;
        let legend_bottom = self.legend(&mut c, ml, legend_top, plot_w, true);
        let top = legend_bottom + 8.0;
        let bottom = h - (axes::x_labels_height() + 6.0 + label_h + PAD);
        let panel_h = ((bottom - top - PANEL_GAP * (n - 1.0)) / n).max(20.0);

        let xs = Scale::new(x_range.0, x_range.1, ml, ml + plot_w);
        let x_ticks = axes::ticks(
            x_range.0,
            x_range.1,
            (plot_w / 110.0) as usize,
            self.x_whole,
        );
        for (k, p) in self.panels.iter().enumerate() {
            let area = Area::new(ml, top + k as f32 * (panel_h + PANEL_GAP), plot_w, panel_h);
            let ys = Scale::new(y_ranges[k].0, y_ranges[k].1, area.bottom(), area.y);
            draw_bands(&mut c, area, &xs, &p.bands);
            let last = k + 1 == self.panels.len();
            let marks = |labels| axes::Marks { grid: true, labels };
            axes::x_axis(&mut c, area, &xs, &x_ticks, marks(last));
            axes::y_axis(&mut c, area, &ys, &y_ticks[k], marks(true));
            for s in &p.series {
                draw_series(&mut c, area, &xs, &ys, s);
            }
            axes::frame(&mut c, area);
            // The y label reads upwards along the panel; a long one in smaller type.
            let style = if text::text_width(&p.y_label, LABEL.size) > area.h {
                SMALL
            } else {
                LABEL
            };
            c.text_up(
                PAD,
                area.y + area.h / 2.0,
                &p.y_label,
                style.aligned(Align::Center),
            );
        }
        c.text(
            ml + plot_w / 2.0,
            h - PAD - label_h,
            &self.x_label,
            LABEL.aligned(Align::Center),
        );
        c
    }

    /// The x range every panel shares: the data and the bands.
    fn x_range(&self) -> (f64, f64) {
        let mut r = (f64::INFINITY, f64::NEG_INFINITY);
        for p in &self.panels {
            for s in &p.series {
                for &(x, y) in &s.points {
                    if x.is_finite() && y.is_finite() {
                        r = (r.0.min(x), r.1.max(x));
                    }
                }
            }
            for b in &p.bands {
                r = (r.0.min(b.x0), r.1.max(b.x1));
            }
        }
        if !r.0.is_finite() {
            return (0.0, 1.0);
        }
        if r.1 - r.0 < 1e-12 {
            return (r.0 - 0.5, r.1 + 0.5);
        }
        r
    }

    /// The legend entries: one per distinct label of the series and bands.
    fn legend_entries(&self) -> Vec<(String, [u8; 3], Swatch)> {
        let mut out: Vec<(String, [u8; 3], Swatch)> = Vec::new();
        for p in &self.panels {
            let series = p.series.iter().map(|s| {
                let sw = if s.style == Style::Points {
                    Swatch::Dot
                } else {
                    Swatch::Line
                };
                (s.label.clone(), s.color, sw)
            });
            let bands = p
                .bands
                .iter()
                .map(|b| (b.label.clone(), b.color, Swatch::Shade));
            for e in series.chain(bands) {
                if !e.0.is_empty() && !out.iter().any(|o| o.0 == e.0) {
                    out.push(e);
                }
            }
        }
        out
    }

    /// Lays the legend out in rows from (x, y) within `width` (drawing it when `draw`);
    /// returns the y below it (`y` itself when there is no legend).
    fn legend(&self, c: &mut Canvas, x: f32, y: f32, width: f32, draw: bool) -> f32 {
        let entries = self.legend_entries();
        if entries.is_empty() {
            return y;
        }
        let row_h = text::line_height(LABEL.size) + 6.0;
        let (mut cx, mut cy) = (x, y);
        for (label, color, swatch) in entries {
            let ew = 26.0 + text::text_width(&label, LABEL.size) + 22.0;
            if cx > x && cx + ew > x + width {
                cx = x;
                cy += row_h;
            }
            if draw {
                let mid = cy + row_h / 2.0 - 3.0;
                match swatch {
                    Swatch::Line => c.fill_rect(cx, mid - 1.0, 20.0, 2.5, color, 255),
                    Swatch::Dot => c.dot(cx + 10.0, mid, 3.5, color),
                    Swatch::Shade => {
                        c.fill_rect(cx, mid - 6.0, 20.0, 12.0, color, BAND_ALPHA as u8)
                    }
                }
                c.text(cx + 26.0, cy, &label, LABEL);
            }
            cx += ew;
        }
        cy + row_h
    }
}

/// The y range of a panel (padded) and whether its values are all whole numbers.
fn y_range(p: &Panel) -> (f64, f64, bool) {
    let mut r = (f64::INFINITY, f64::NEG_INFINITY);
    let mut integer = true;
    for s in &p.series {
        for &(x, y) in &s.points {
            if x.is_finite() && y.is_finite() {
                r = (r.0.min(y), r.1.max(y));
                integer &= y.fract() == 0.0 && y.abs() < 1e9;
            }
        }
    }
    if !r.0.is_finite() {
        return (0.0, 1.0, false);
    }
    if p.y_from_zero {
        r = (r.0.min(0.0), r.1.max(0.0));
    }
    if r.1 - r.0 < 1e-12 {
        let d = if integer {
            1.0
        } else {
            (r.0.abs() * 0.1).max(1e-9)
        };
        return if p.y_from_zero && r.0 == 0.0 {
            (0.0, d, integer)
        } else {
            (r.0 - d, r.1 + d, integer)
        };
    }
    let pad = (r.1 - r.0) * 0.06;
    let lo = if p.y_from_zero && r.0 == 0.0 {
        0.0
    } else {
        r.0 - pad
    };
    (lo, r.1 + pad, integer)
}

/// Shades the bands in `area`: each pixel column by the share of it each colour covers.
fn draw_bands(c: &mut Canvas, area: Area, xs: &Scale, bands: &[Band]) {
    let cols = area.w.ceil().max(1.0) as usize;
    let mut colours: Vec<([u8; 3], Vec<f32>)> = Vec::new();
    for b in bands {
        let (a, z) = (xs.px(b.x0) - area.x, xs.px(b.x1) - area.x);
        let (a, z) = (a.min(z).max(0.0), a.max(z).min(cols as f32));
        if z <= a {
            continue;
        }
        let k = match colours.iter().position(|(col, _)| *col == b.color) {
            Some(k) => k,
            None => {
                colours.push((b.color, vec![0.0; cols]));
                colours.len() - 1
            }
        };
        let cov = &mut colours[k].1;
        let (first, last) = (a.floor() as usize, (z.ceil() as usize).min(cols));
        for (col, v) in cov.iter_mut().enumerate().take(last).skip(first) {
            let (l, r) = (col as f32, col as f32 + 1.0);
            *v += (z.min(r) - a.max(l)).max(0.0);
        }
    }
    // Ranges closer than a few columns apart would shade alternate columns (stripes that
    // mean nothing): average the shading over a window holding about two of them.
    let per_column = bands.len() as f32 / cols as f32;
    let window = if per_column > 0.25 {
        (2.0 / per_column).ceil() as usize
    } else {
        1
    };
    for (color, cov) in colours {
        let cov = if window > 1 {
            moving_average(&cov, window)
        } else {
            cov
        };
        for (col, v) in cov.into_iter().enumerate() {
            if v > 0.0 {
                let alpha = (BAND_ALPHA * v.min(1.0)).round().max(1.0) as u8;
                c.fill_rect(area.x + col as f32, area.y, 1.0, area.h, color, alpha);
            }
        }
    }
}

/// The mean of `v` over a window of `w` values centred on each one.
fn moving_average(v: &[f32], w: usize) -> Vec<f32> {
    let half = w / 2;
    let mut prefix = vec![0.0f64; v.len() + 1];
    for (i, x) in v.iter().enumerate() {
        prefix[i + 1] = prefix[i] + *x as f64;
    }
    (0..v.len())
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + half + 1).min(v.len()));
            ((prefix[b] - prefix[a]) / (b - a) as f64) as f32
        })
        .collect()
}

/// Draws one series in `area`.
fn draw_series(c: &mut Canvas, area: Area, xs: &Scale, ys: &Scale, s: &Series) {
    let pts = decimate(&s.points, xs.lo, xs.hi, area.w.max(1.0) as usize);
    let px = |&(x, y): &(f64, f64)| (xs.px(x), ys.px(y));
    match s.style {
        Style::Line => {
            let v: Vec<(f32, f32)> = pts.iter().map(px).collect();
            c.polyline(&v, s.color, 1.6);
        }
        Style::Points => {
            for p in &pts {
                let (x, y) = px(p);
                c.dot(x, y, 2.8, s.color);
            }
        }
    }
}

/// Reduces a long polyline to at most about 4 points per pixel column (each column's
/// first, lowest, highest and last point), keeping its look.
fn decimate(points: &[(f64, f64)], x0: f64, x1: f64, cols: usize) -> Vec<(f64, f64)> {
    if points.len() <= cols * 4 {
        return points.to_vec();
    }
    let mut out = Vec::with_capacity(cols * 4);
    let span = (x1 - x0).max(1e-300);
    let column = |x: f64| (((x - x0) / span) * cols as f64).floor();
    let mut i = 0;
    while i < points.len() {
        let col = column(points[i].0);
        let start = i;
        let (mut lo, mut hi) = (i, i);
        while i < points.len() && column(points[i].0) == col {
            if points[i].1 < points[lo].1 {
                lo = i;
            }
            if points[i].1 > points[hi].1 {
                hi = i;
            }
            i += 1;
        }
        let mut keep = [start, lo, hi, i - 1];
        keep.sort_unstable();
        let mut last = usize::MAX;
        for k in keep {
            if k != last {
                out.push(points[k]);
                last = k;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_panel(series: Vec<Series>, bands: Vec<Band>) -> Chart {
        Chart {
            title: "Stage position".into(),
            x_label: "time (s)".into(),
            x_whole: false,
            width: 640,
            height: 360,
            panels: vec![Panel {
                y_label: "z (mm)".into(),
                series,
                bands,
                y_from_zero: false,
            }],
        }
    }

    #[test]
    fn chart_draws_series_in_its_colour() {
        let points = (0..100).map(|i| (i as f64, (i % 10) as f64)).collect();
        let c = one_panel(
            vec![Series::new("stage", [200, 0, 0], Style::Line, points)],
            vec![Band::new(10.0, 20.0, [0, 0, 255], "shutter open")],
        )
        .render()
        .to_rgb();
        assert_eq!(c.dimensions(), (640, 360));
        let red = c
            .pixels()
            .filter(|p| p[0] > 150 && p[1] < 60 && p[2] < 60)
            .count();
        assert!(red > 500, "{red}");
        let bluish = c.pixels().filter(|p| p[2] > 200 && p[0] < 200).count();
        assert!(bluish > 1000, "{bluish}");
    }

    #[test]
    fn the_legend_stays_out_of_the_plot_area() {
        // Data filling the whole plot area: the legend's text must not be drawn over it.
        let pts: Vec<(f64, f64)> = (0..=200).map(|i| (i as f64, 10.0)).collect();
        let label = "a long legend entry for the series";
        let ch = one_panel(
            vec![Series::new(label, [200, 0, 0], Style::Line, pts)],
            vec![],
        );
        let mut probe = Canvas::new(640, 360, [255; 3]);
        let below = ch.legend(&mut probe, 0.0, 100.0, 600.0, false);
        assert!(below > 100.0);
        let img = ch.render().to_rgb();
        // The topmost red pixel (the line at y = 10 is the top of the data) lies below
        // the legend's text.
        let top_red = img
            .enumerate_pixels()
            .filter(|(x, _, p)| *x > 150 && p[0] > 150 && p[1] < 80)
            .map(|(_, y, _)| y)
            .min()
            .unwrap();
        let legend_text_bottom = img
            .enumerate_pixels()
            .filter(|(x, y, p)| *x > 150 && *y < top_red && p[0] < 100 && p[1] < 100)
            .map(|(_, y, _)| y)
            .max()
            .unwrap();
        assert!(
            legend_text_bottom < top_red,
            "{legend_text_bottom} {top_red}"
        );
    }

    #[test]
    fn thin_bands_shade_by_coverage() {
        // 1000 bands each a tenth of a column: light shading, not a solid block.
        let bands = (0..1000)
            .map(|i| Band::new(i as f64, i as f64 + 0.1, [0, 0, 255], ""))
            .collect();
        let line = vec![(0.0, 0.0), (1000.0, 0.0)];
        let ch = one_panel(vec![Series::new("", [0, 0, 0], Style::Line, line)], bands);
        let img = ch.render().to_rgb();
        let p = img.get_pixel(320, 100);
        assert!(p[0] > 200 && p[0] < 255, "{p:?}");
    }

    #[test]
    fn decimation_keeps_extremes() {
        let pts: Vec<(f64, f64)> = (0..100_000)
            .map(|i| (i as f64, if i == 5000 { 9.0 } else { 0.0 }))
            .collect();
        let d = decimate(&pts, 0.0, 100_000.0, 100);
        assert!(d.len() <= 400);
        assert!(d.iter().any(|p| p.1 == 9.0));
    }
}
