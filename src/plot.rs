//! Minimal PNG charts for people: line/step/point charts (stage position over time,
//! S(g) curves) and heatmaps (irradiance maps). Drawn with tiny-skia; text uses a built-in
//! 5×7 bitmap font (upper case), so plots need no font files.

use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Straight segments between consecutive points.
    Line,
    /// A marker at each point.
    Points,
}

/// One data series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// RGB colour.
    pub color: [u8; 3],
    /// Drawing style.
    pub style: Style,
    /// (x, y) points, in x order for `Line`.
    pub points: Vec<(f64, f64)>,
}

/// A shaded x range (e.g. "shutter open", "valid gray range").
#[derive(Debug, Clone)]
pub struct Band {
    /// Start of the range.
    pub x0: f64,
    /// End of the range.
    pub x1: f64,
    /// RGB colour (drawn translucent).
    pub color: [u8; 3],
    /// Legend text (empty: no legend entry).
    pub label: String,
}

/// An x/y chart.
#[derive(Debug, Clone)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Data.
    pub series: Vec<Series>,
    /// Shaded x ranges.
    pub bands: Vec<Band>,
}

/// A heatmap of a grid of values.
#[derive(Debug, Clone)]
pub struct Heatmap {
    /// Title above the map.
    pub title: String,
    /// Unit shown on the colour bar.
    pub unit: String,
    /// Columns.
    pub cols: usize,
    /// Rows.
    pub rows: usize,
    /// Row-major values, row 0 at the top.
    pub values: Vec<f64>,
    /// Value mapped to the low end of the colour scale.
    pub vmin: f64,
    /// Value mapped to the high end.
    pub vmax: f64,
    /// Edge of one cell, px.
    pub cell_px: u32,
    /// Write each cell's value in it (when cells are large enough).
    pub annotate: bool,
}

/// Scale of the built-in 5×7 font: glyphs are drawn 10×14 px.
const SCALE: f32 = 2.0;
/// Advance of one character, px (the glyph and one column of space).
const GLYPH_W: f32 = 6.0 * SCALE;

fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' | 'µ' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        ' ' => [0; 7],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        '-' | '−' => [0, 0, 0, 0x1F, 0, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '/' => [0, 0x01, 0x02, 0x04, 0x08, 0x10, 0],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '_' => [0, 0, 0, 0, 0, 0, 0x1F],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        '<' => [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        '[' => [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E],
        ']' => [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E],
        '*' | '×' | '·' => [0, 0x04, 0x15, 0x0E, 0x15, 0x04, 0],
        '\'' => [0x04, 0x04, 0x08, 0, 0, 0, 0],
        '#' => [0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A],
        '^' | '²' => [0x04, 0x0A, 0x11, 0, 0, 0, 0],
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0, 0x04],
    }
}

fn color(c: [u8; 3], alpha: u8) -> Color {
    Color::from_rgba8(c[0], c[1], c[2], alpha)
}

fn fill_rect(pm: &mut Pixmap, x: f32, y: f32, w: f32, h: f32, c: Color) {
    // Whole pixels, no anti-aliasing: crisp text and bars.
    let (x0, y0) = (x.round(), y.round());
    let (x1, y1) = ((x + w).round().max(x0 + 1.0), (y + h).round().max(y0 + 1.0));
    if let Some(r) = Rect::from_ltrb(x0, y0, x1, y1) {
        let mut p = Paint::default();
        p.set_color(c);
        p.anti_alias = false;
        pm.fill_rect(r, &p, Transform::identity(), None);
    }
}

/// Width of `s` in pixels when drawn with [`text`].
fn text_width(s: &str) -> f32 {
    s.chars().count() as f32 * GLYPH_W
}

/// Draws `s` with its top-left corner at (x, y).
fn text(pm: &mut Pixmap, x: f32, y: f32, s: &str, c: [u8; 3]) {
    let col = color(c, 255);
    for (i, ch) in s.chars().enumerate() {
        let g = glyph(ch);
        let gx = x + i as f32 * GLYPH_W;
        for (r, bits) in g.iter().enumerate() {
            for b in 0..5 {
                if bits & (0x10 >> b) != 0 {
                    fill_rect(
                        pm,
                        gx + b as f32 * SCALE,
                        y + r as f32 * SCALE,
                        SCALE,
                        SCALE,
                        col,
                    );
                }
            }
        }
    }
}

fn stroke_path(pm: &mut Pixmap, pts: &[(f32, f32)], c: [u8; 3], width: f32) {
    if pts.len() < 2 {
        return;
    }
    let mut pb = PathBuilder::new();
    pb.move_to(pts[0].0, pts[0].1);
    for p in &pts[1..] {
        pb.line_to(p.0, p.1);
    }
    if let Some(path) = pb.finish() {
        let mut paint = Paint::default();
        paint.set_color(color(c, 255));
        paint.anti_alias = true;
        let st = Stroke {
            width,
            ..Stroke::default()
        };
        pm.stroke_path(&path, &paint, &st, Transform::identity(), None);
    }
}

/// "Nice" tick positions covering [lo, hi].
fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + step * 1e-9 {
        out.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        t += step;
    }
    out
}

fn fmt_num(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 || v == v.round() {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.2}")
            .trim_end_matches('0')
            .trim_end_matches('.')
            .to_string()
    } else {
        format!("{v:.4}")
            .trim_end_matches('0')
            .trim_end_matches('.')
            .to_string()
    }
}

fn encode(pm: &Pixmap) -> Vec<u8> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    // Pixmaps are opaque here (white background), so premultiplied RGB is plain RGB.
    let rgb: Vec<u8> = pm
        .data()
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Default, FilterType::Adaptive)
        .write_image(
            &rgb,
            pm.width(),
            pm.height(),
            image::ExtendedColorType::Rgb8,
        )
        .expect("encoding to memory cannot fail");
    out
}

/// Reduces a long polyline to at most ~4 points per pixel column (min/max envelope),
/// keeping its look.
fn decimate(points: &[(f64, f64)], x0: f64, x1: f64, cols: usize) -> Vec<(f64, f64)> {
    if points.len() <= cols * 4 {
        return points.to_vec();
    }
    let mut out = Vec::with_capacity(cols * 4);
    let span = (x1 - x0).max(1e-300);
    let mut i = 0;
    while i < points.len() {
        let col = (((points[i].0 - x0) / span) * cols as f64).floor();
        let start = i;
        let (mut lo, mut hi) = (i, i);
        while i < points.len() && (((points[i].0 - x0) / span) * cols as f64).floor() == col {
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

impl Chart {
    /// Renders the chart as an RGB PNG.
    pub fn render_png(&self) -> Vec<u8> {
        let (w, h) = (self.width.max(200), self.height.max(150));
        let mut pm = Pixmap::new(w, h).expect("chart size is valid");
        pm.fill(Color::WHITE);
        let (ml, mr, mt, mb) = (110.0f32, 20.0f32, 60.0f32, 60.0f32);
        let (pw, ph) = (w as f32 - ml - mr, h as f32 - mt - mb);

        let mut xs = (f64::INFINITY, f64::NEG_INFINITY);
        let mut ys = (f64::INFINITY, f64::NEG_INFINITY);
        for s in &self.series {
            for &(x, y) in &s.points {
                if x.is_finite() && y.is_finite() {
                    xs = (xs.0.min(x), xs.1.max(x));
                    ys = (ys.0.min(y), ys.1.max(y));
                }
            }
        }
        for b in &self.bands {
            xs = (xs.0.min(b.x0), xs.1.max(b.x1));
        }
        if !xs.0.is_finite() {
            xs = (0.0, 1.0);
        }
        if !ys.0.is_finite() {
            ys = (0.0, 1.0);
        }
        if xs.1 - xs.0 < 1e-12 {
            xs = (xs.0 - 0.5, xs.1 + 0.5);
        }
        let pad = ((ys.1 - ys.0) * 0.05).max(1e-9);
        ys = (ys.0 - pad, ys.1 + pad);
        let px = |x: f64| ml + ((x - xs.0) / (xs.1 - xs.0)) as f32 * pw;
        let py = |y: f64| mt + ph - ((y - ys.0) / (ys.1 - ys.0)) as f32 * ph;

        for b in &self.bands {
            let (a, z) = (px(b.x0.max(xs.0)), px(b.x1.min(xs.1)));
            fill_rect(&mut pm, a, mt, (z - a).max(1.0), ph, color(b.color, 70));
        }
        let grid = [225, 225, 225];
        let ink = [40, 40, 40];
        for t in ticks(xs.0, xs.1, 8) {
            let x = px(t);
            fill_rect(&mut pm, x, mt, 1.0, ph, color(grid, 255));
            let l = fmt_num(t);
            text(&mut pm, x - text_width(&l) / 2.0, mt + ph + 8.0, &l, ink);
        }
        for t in ticks(ys.0, ys.1, 6) {
            let y = py(t);
            fill_rect(&mut pm, ml, y, pw, 1.0, color(grid, 255));
            let l = fmt_num(t);
            text(&mut pm, ml - 8.0 - text_width(&l), y - 7.0, &l, ink);
        }
        fill_rect(&mut pm, ml, mt, 1.5, ph, color(ink, 255));
        fill_rect(&mut pm, ml, mt + ph, pw, 1.5, color(ink, 255));
        text(&mut pm, ml, 12.0, &self.title, ink);
        text(&mut pm, ml, 36.0, &self.y_label, [90, 90, 90]);
        let xl = &self.x_label;
        text(
            &mut pm,
            ml + pw - text_width(xl),
            h as f32 - 22.0,
            xl,
            [90, 90, 90],
        );

        for s in &self.series {
            let pts = decimate(&s.points, xs.0, xs.1, pw as usize);
            match s.style {
                Style::Line => {
                    let v: Vec<(f32, f32)> = pts.iter().map(|&(x, y)| (px(x), py(y))).collect();
                    stroke_path(&mut pm, &v, s.color, 2.0);
                }
                Style::Points => {
                    for &(x, y) in &pts {
                        fill_rect(
                            &mut pm,
                            px(x) - 3.0,
                            py(y) - 3.0,
                            6.0,
                            6.0,
                            color(s.color, 255),
                        );
                    }
                }
            }
        }
        // Legend, top right inside the plot.
        let entries: Vec<(&str, [u8; 3])> = self
            .series
            .iter()
            .map(|s| (s.label.as_str(), s.color))
            .chain(
                self.bands
                    .iter()
                    .filter(|b| !b.label.is_empty())
                    .map(|b| (b.label.as_str(), b.color)),
            )
            .filter(|(l, _)| !l.is_empty())
            .collect();
        let lw = entries
            .iter()
            .map(|(l, _)| text_width(l))
            .fold(0.0, f32::max)
            + 40.0;
        let mut ly = mt + 8.0;
        for (l, c) in entries {
            let lx = ml + pw - lw - 8.0;
            fill_rect(
                &mut pm,
                lx - 4.0,
                ly - 4.0,
                lw + 8.0,
                22.0,
                color([255, 255, 255], 220),
            );
            fill_rect(&mut pm, lx, ly + 3.0, 22.0, 8.0, color(c, 255));
            text(&mut pm, lx + 30.0, ly, l, ink);
            ly += 22.0;
        }
        encode(&pm)
    }
}

/// Maps t in [0, 1] to a perceptually ordered colour (dark blue → green → yellow).
pub fn colormap(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f64;
    let mut c = [0u8; 3];
    for k in 0..3 {
        c[k] = (STOPS[i][k] + (STOPS[i + 1][k] - STOPS[i][k]) * f).round() as u8;
    }
    c
}

/// Renders a heatmap with a colour bar as an RGB PNG.
pub fn heatmap_png(hm: &Heatmap) -> Vec<u8> {
    let cell = hm.cell_px.max(1) as f32;
    let (ml, mt, mb) = (20.0f32, 50.0f32, 20.0f32);
    let bar_w = 200.0f32;
    let map_w = hm.cols as f32 * cell;
    let map_h = hm.rows as f32 * cell;
    let w = (ml + map_w + 30.0 + bar_w).max(text_width(&hm.title) + 2.0 * ml);
    let h = mt + map_h.max(200.0) + mb;
    let mut pm = Pixmap::new(w.ceil() as u32, h.ceil() as u32).expect("heatmap size is valid");
    pm.fill(Color::WHITE);
    let ink = [40, 40, 40];
    text(&mut pm, ml, 14.0, &hm.title, ink);
    let span = if hm.vmax > hm.vmin {
        hm.vmax - hm.vmin
    } else {
        1.0
    };
    for r in 0..hm.rows {
        for c in 0..hm.cols {
            let v = hm.values[r * hm.cols + c];
            let (x, y) = (ml + c as f32 * cell, mt + r as f32 * cell);
            if !v.is_finite() {
                fill_rect(&mut pm, x, y, cell, cell, color([200, 200, 200], 255));
                continue;
            }
            let col = colormap((v - hm.vmin) / span);
            fill_rect(&mut pm, x, y, cell, cell, color(col, 255));
            if hm.annotate {
                let l = fmt_num(v);
                if text_width(&l) + 4.0 <= cell && cell >= 20.0 {
                    let lum = 0.3 * col[0] as f32 + 0.59 * col[1] as f32 + 0.11 * col[2] as f32;
                    let tc = if lum > 140.0 {
                        [0, 0, 0]
                    } else {
                        [255, 255, 255]
                    };
                    text(
                        &mut pm,
                        x + (cell - text_width(&l)) / 2.0,
                        y + (cell - 14.0) / 2.0,
                        &l,
                        tc,
                    );
                }
            }
        }
    }
    // Colour bar.
    let bx = ml + map_w + 30.0;
    let bh = map_h.max(200.0);
    let steps = bh as usize;
    for i in 0..steps {
        let t = 1.0 - i as f64 / steps as f64;
        fill_rect(
            &mut pm,
            bx,
            mt + i as f32,
            24.0,
            1.0,
            color(colormap(t), 255),
        );
    }
    text(&mut pm, bx + 30.0, mt, &fmt_num(hm.vmax), ink);
    text(
        &mut pm,
        bx + 30.0,
        mt + bh / 2.0 - 7.0,
        &fmt_num((hm.vmin + hm.vmax) / 2.0),
        ink,
    );
    text(&mut pm, bx + 30.0, mt + bh - 14.0, &fmt_num(hm.vmin), ink);
    text(
        &mut pm,
        bx + 30.0,
        mt + bh / 2.0 + 16.0,
        &hm.unit,
        [90, 90, 90],
    );
    encode(&pm)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(png: &[u8]) -> image::RgbImage {
        image::load_from_memory(png).unwrap().to_rgb8()
    }

    #[test]
    fn chart_draws_series_in_its_colour() {
        let c = Chart {
            title: "Stage position".into(),
            x_label: "time (s)".into(),
            y_label: "z (mm)".into(),
            width: 640,
            height: 360,
            series: vec![Series {
                label: "stage".into(),
                color: [200, 0, 0],
                style: Style::Line,
                points: (0..100).map(|i| (i as f64, (i % 10) as f64)).collect(),
            }],
            bands: vec![Band {
                x0: 10.0,
                x1: 20.0,
                color: [0, 0, 255],
                label: "shutter open".into(),
            }],
        };
        let img = decode(&c.render_png());
        assert_eq!(img.dimensions(), (640, 360));
        let red = img
            .pixels()
            .filter(|p| p[0] > 150 && p[1] < 60 && p[2] < 60)
            .count();
        assert!(red > 500, "{red}");
        let bluish = img.pixels().filter(|p| p[2] > 200 && p[0] < 200).count();
        assert!(bluish > 1000, "{bluish}");
    }

    #[test]
    fn heatmap_cells_follow_values() {
        let hm = Heatmap {
            title: "irradiance".into(),
            unit: "mW/cm2".into(),
            cols: 2,
            rows: 1,
            values: vec![0.0, 1.0],
            vmin: 0.0,
            vmax: 1.0,
            cell_px: 40,
            annotate: false,
        };
        let img = decode(&heatmap_png(&hm));
        let lo = img.get_pixel(20 + 20, 50 + 20);
        let hi = img.get_pixel(20 + 60, 50 + 20);
        assert_eq!(lo.0, colormap(0.0));
        assert_eq!(hi.0, colormap(1.0));
    }

    #[test]
    fn ticks_are_nice() {
        assert_eq!(ticks(0.0, 10.0, 5), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(fmt_num(0.25), "0.25");
        assert_eq!(fmt_num(1500.0), "1500");
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
