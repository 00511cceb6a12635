//! Heatmaps: a grid of values over the build plane, with x and y axes in mm and a colour
//! bar whose range covers every value shown, labelled with the quantity and its unit.

use super::axes::{self, Area, Scale};
use super::canvas::Canvas;
use super::text::{self, Align, TextStyle, INK, LABEL, SMALL, TITLE};

/// A heatmap of a grid of values.
#[derive(Debug, Clone)]
pub struct Heatmap {
    /// Title above the map.
    pub title: String,
    /// Columns.
    pub cols: usize,
    /// Rows.
    pub rows: usize,
    /// Row-major values, row 0 at the top; NaN where there is no value.
    pub values: Vec<f64>,
    /// X of the grid's left and right edges (e.g. mm from the field's left edge).
    pub x_range: [f64; 2],
    /// Y of the grid's bottom and top edges (e.g. mm from the field's bottom edge).
    pub y_range: [f64; 2],
    /// X axis label, with its unit.
    pub x_label: String,
    /// Y axis label, with its unit.
    pub y_label: String,
    /// The colour bar's label: the quantity and its unit, e.g. "correction (mm)".
    pub quantity: String,
    /// Values at the low and high ends of the colour scale; widened to cover every finite
    /// value (see [`Heatmap::scale`]). `None`: the values' own extremes.
    pub range: Option<[f64; 2]>,
    /// Width of one cell, px (its height follows the cells' aspect in x and y).
    pub cell_px: f32,
    /// Write each cell's value in it (where it fits).
    pub annotate: bool,
    /// What a cell without a value means, shown beside a gray swatch under the colour bar
    /// when a cell has no value ("unreachable"); empty: no swatch.
    pub missing: String,
}

/// Colour of cells without a value.
pub const MISSING: [u8; 3] = [200, 200, 200];
/// Width of the colour bar, px.
const BAR_W: f32 = 20.0;
/// Space around the picture's content, px.
const PAD: f32 = 12.0;

/// Maps t in [0, 1] to a perceptually ordered colour (viridis: dark blue → green →
/// yellow); NaN maps to 0.
pub fn colormap(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 122.0],
        [59.0, 81.0, 139.0],
        [44.0, 113.0, 142.0],
        [33.0, 144.0, 141.0],
        [39.0, 173.0, 129.0],
        [92.0, 200.0, 99.0],
        [170.0, 220.0, 50.0],
        [253.0, 231.0, 37.0],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * 8.0;
    let i = (t.floor() as usize).min(7);
    let f = t - i as f64;
    [0, 1, 2].map(|k| (STOPS[i][k] + (STOPS[i + 1][k] - STOPS[i][k]) * f).round() as u8)
}

impl Heatmap {
    /// The colour bar's range: `range` widened to the finite values' extremes, so the bar
    /// always covers every value the map shows (a flat map gets a unit-wide range).
    pub fn scale(&self) -> [f64; 2] {
        let mut r = self.range.unwrap_or([f64::INFINITY, f64::NEG_INFINITY]);
        for &v in self.values.iter().filter(|v| v.is_finite()) {
            r = [r[0].min(v), r[1].max(v)];
        }
        if !r[0].is_finite() || !r[1].is_finite() {
            return [0.0, 1.0];
        }
        if r[1] - r[0] < 1e-12 {
            return [r[0] - 0.5, r[1] + 0.5];
        }
        r
    }

    /// The colour of value `v` on this map's scale.
    pub fn color_of(&self, v: f64) -> [u8; 3] {
        if !v.is_finite() {
            return MISSING;
        }
        let [lo, hi] = self.scale();
        colormap((v - lo) / (hi - lo))
    }

    /// The heatmap drawn on a canvas sized to fit it.
    pub fn render(&self) -> Canvas {
        let [lo, hi] = self.scale();
        let label_h = text::line_height(LABEL.size);
        let cell_w = self.cell_px.max(1.0);
        let (cols, rows) = (self.cols.max(1), self.rows.max(1));
        let mm_w = (self.x_range[1] - self.x_range[0]).abs() / cols as f64;
        let mm_h = (self.y_range[1] - self.y_range[0]).abs() / rows as f64;
        let cell_h = if mm_w > 0.0 && mm_h > 0.0 {
            cell_w * (mm_h / mm_w) as f32
        } else {
            cell_w
        };
        let (map_w, map_h) = (cols as f32 * cell_w, rows as f32 * cell_h);

        // About one tick per 70 px of the map.
        let ticks =
            |[lo, hi]: [f64; 2], px: f32| axes::ticks(lo, hi, (px / 70.0).max(2.0) as usize, false);
        let (x_ticks, y_ticks) = (ticks(self.x_range, map_w), ticks(self.y_range, map_h));
        let bar_ticks = axes::ticks(lo, hi, 6, false);
        let ml = PAD + label_h + 8.0 + axes::y_labels_width(&y_ticks);
        let top = PAD + text::line_height(TITLE.size) + 14.0;
        let area = Area::new(ml, top, map_w, map_h);
        let bar = Area::new(area.right() + 26.0, top, BAR_W, map_h.max(160.0));
        let end_labels = [axes::value_label(lo), axes::value_label(hi)];
        let bar_label_w = bar_ticks
            .values
            .iter()
            .map(|&v| axes::tick_label(v, bar_ticks.step))
            .chain(end_labels.iter().cloned())
            .map(|s| text::text_width(&s, SMALL.size))
            .fold(0.0, f32::max);
        let quantity_x = bar.right() + 8.0 + bar_label_w + 10.0;
        let show_missing = !self.missing.is_empty() && self.values.iter().any(|v| !v.is_finite());
        let missing_w = if !show_missing {
            0.0
        } else {
            18.0 + text::text_width(&self.missing, SMALL.size)
        };
        let width = (quantity_x + label_h + PAD)
            .max(bar.x + missing_w + PAD)
            .max(PAD * 2.0 + text::text_width(&self.title, TITLE.size));
        let bottom_of_bar = bar.bottom() + if missing_w > 0.0 { 30.0 } else { 0.0 };
        let height = (area.bottom() + axes::x_labels_height() + 6.0 + label_h + PAD)
            .max(bottom_of_bar + PAD);
        let mut c = Canvas::new(width.ceil() as u32, height.ceil() as u32, [255; 3]);
        c.text(PAD, PAD, &self.title, TITLE);

        self.draw_cells(&mut c, area, cell_w, cell_h);
        let xs = Scale::new(self.x_range[0], self.x_range[1], area.x, area.right());
        let ys = Scale::new(self.y_range[0], self.y_range[1], area.bottom(), area.y);
        // Grid lines would cross the cells: only tick marks and labels, then the frame.
        let marks = axes::Marks {
            grid: false,
            labels: true,
        };
        axes::x_axis(&mut c, area, &xs, &x_ticks, marks);
        axes::y_axis(&mut c, area, &ys, &y_ticks, marks);
        axes::frame(&mut c, area);
        c.text(
            area.x + area.w / 2.0,
            area.bottom() + axes::x_labels_height() + 6.0,
            &self.x_label,
            LABEL.aligned(Align::Center),
        );
        c.text_up(
            PAD,
            area.y + area.h / 2.0,
            &self.y_label,
            LABEL.aligned(Align::Center),
        );

        self.draw_bar(&mut c, bar, [lo, hi], &bar_ticks, quantity_x, show_missing);
        c
    }

    /// The colour bar: the gradient, its ticks, its exact ends, the quantity, and the
    /// colour of missing cells when `show_missing`.
    fn draw_bar(
        &self,
        c: &mut Canvas,
        bar: Area,
        [lo, hi]: [f64; 2],
        bar_ticks: &axes::Ticks,
        quantity_x: f32,
        show_missing: bool,
    ) {
        let steps = bar.h.round().max(1.0) as usize;
        // Top row: the colour of `hi`, bottom row: that of `lo`.
        for i in 0..steps {
            let t = 1.0 - i as f64 / (steps - 1).max(1) as f64;
            c.fill_rect(bar.x, bar.y + i as f32, bar.w, 1.0, colormap(t), 255);
        }
        let bs = Scale::new(lo, hi, bar.bottom(), bar.y);
        let lx = bar.right() + 8.0;
        let small_h = text::line_height(SMALL.size);
        let end_labels = [axes::value_label(lo), axes::value_label(hi)];
        for (v, label) in [(lo, &end_labels[0]), (hi, &end_labels[1])] {
            let y = bs.px(v);
            c.fill_rect(bar.right(), y.min(bar.bottom() - 1.0), 5.0, 1.0, INK, 255);
            c.text(lx, y - small_h / 2.0, label, SMALL.aligned(Align::Left));
        }
        for &v in &bar_ticks.values {
            let y = bs.px(v);
            if (y - bar.y).abs() < 1.3 * small_h || (y - bar.bottom()).abs() < 1.3 * small_h {
                continue;
            }
            c.fill_rect(bar.right(), y, 4.0, 1.0, INK, 255);
            c.text(
                lx,
                y - small_h / 2.0,
                &axes::tick_label(v, bar_ticks.step),
                SMALL.aligned(Align::Left),
            );
        }
        c.text_up(
            quantity_x,
            bar.y + bar.h / 2.0,
            &self.quantity,
            LABEL.aligned(Align::Center),
        );
        if show_missing {
            let y = bar.bottom() + 12.0;
            c.fill_rect(bar.x, y, 12.0, 12.0, MISSING, 255);
            c.text(
                bar.x + 18.0,
                y + 6.0 - small_h / 2.0,
                &self.missing,
                SMALL.aligned(Align::Left),
            );
        }
    }

    /// Fills the cells (and writes their values when `annotate`).
    fn draw_cells(&self, c: &mut Canvas, area: Area, cell_w: f32, cell_h: f32) {
        // The cells' edges, whole pixels.
        let xs: Vec<f32> = (0..=self.cols)
            .map(|k| (area.x + k as f32 * cell_w).round())
            .collect();
        let ys: Vec<f32> = (0..=self.rows)
            .map(|k| (area.y + k as f32 * cell_h).round())
            .collect();
        for r in 0..self.rows {
            let (y0, y1) = (ys[r], ys[r + 1]);
            for col in 0..self.cols {
                let (x0, x1) = (xs[col], xs[col + 1]);
                let v = self
                    .values
                    .get(r * self.cols + col)
                    .copied()
                    .unwrap_or(f64::NAN);
                let color = self.color_of(v);
                c.fill_rect(x0, y0, x1 - x0, y1 - y0, color, 255);
                if self.annotate && v.is_finite() {
                    let l = axes::value_label(v);
                    let tw = text::text_width(&l, SMALL.size);
                    if tw + 6.0 <= x1 - x0 && y1 - y0 >= 18.0 {
                        let lum =
                            0.3 * color[0] as f32 + 0.59 * color[1] as f32 + 0.11 * color[2] as f32;
                        let ink = if lum > 140.0 { [0, 0, 0] } else { [255; 3] };
                        let style = TextStyle::new(SMALL.size, ink);
                        c.text(
                            (x0 + x1) / 2.0,
                            (y0 + y1) / 2.0 - text::line_height(SMALL.size) / 2.0,
                            &l,
                            style.aligned(Align::Center),
                        );
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(values: Vec<f64>, range: Option<[f64; 2]>) -> Heatmap {
        Heatmap {
            title: "Irradiance".into(),
            cols: 2,
            rows: 1,
            values,
            x_range: [0.0, 10.0],
            y_range: [0.0, 5.0],
            x_label: "x (mm)".into(),
            y_label: "y (mm)".into(),
            quantity: "irradiance (mW/cm²)".into(),
            range,
            cell_px: 80.0,
            annotate: false,
            missing: String::new(),
        }
    }

    #[test]
    fn cells_follow_values() {
        let hm = map(vec![0.0, 1.0], None);
        let img = hm.render();
        let top = (PAD + text::line_height(TITLE.size) + 14.0) as u32;
        let row = top + 20;
        let xs: Vec<u32> = (0..img.width())
            .filter(|&x| img.pixel(x, row) == colormap(0.0))
            .collect();
        assert!(xs.len() >= 70, "{}", xs.len());
        let right = xs[xs.len() - 1] + 40;
        assert_eq!(img.pixel(right, row), colormap(1.0));
    }

    #[test]
    fn the_scale_covers_every_value() {
        assert_eq!(map(vec![0.5, 2.1], Some([0.0, 1.8])).scale(), [0.0, 2.1]);
        assert_eq!(map(vec![0.5, 1.0], Some([0.0, 1.8])).scale(), [0.0, 1.8]);
        assert_eq!(map(vec![f64::NAN, 3.0], None).scale(), [2.5, 3.5]);
        assert_eq!(map(vec![f64::NAN, f64::NAN], None).scale(), [0.0, 1.0]);
    }
}
