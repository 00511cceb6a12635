//! Axes: data-to-pixel scales, "nice" ticks, number labels, and the drawing of grid lines,
//! ticks and their labels around a plot area.

use super::canvas::Canvas;
use super::text::{self, Align, SMALL};

/// Grid lines.
const GRID: [u8; 3] = [228, 228, 228];
/// The plot area's frame and tick marks.
const FRAME: [u8; 3] = [90, 90, 90];
/// Gap between a tick mark's end and its label, px.
const TICK_GAP: f32 = 4.0;
/// Length of a tick mark, px.
const TICK_LEN: f32 = 4.0;

/// A rectangle of the canvas, px.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Area {
    /// Left edge.
    pub x: f32,
    /// Top edge.
    pub y: f32,
    /// Width.
    pub w: f32,
    /// Height.
    pub h: f32,
}

impl Area {
    /// The rectangle of width `w` and height `h` whose top-left corner is (x, y).
    pub fn new(x: f32, y: f32, w: f32, h: f32) -> Area {
        Area { x, y, w, h }
    }
    /// Right edge.
    pub fn right(&self) -> f32 {
        self.x + self.w
    }
    /// Bottom edge.
    pub fn bottom(&self) -> f32 {
        self.y + self.h
    }
}

/// A linear map from data values `lo..hi` to pixels `px0..px1` (px1 < px0 for a y axis,
/// whose values grow upwards).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scale {
    /// Value at `px0`.
    pub lo: f64,
    /// Value at `px1`.
    pub hi: f64,
    /// Pixel of `lo`.
    pub px0: f32,
    /// Pixel of `hi`.
    pub px1: f32,
}

impl Scale {
    /// The map of `lo..hi` to `px0..px1`.
    pub fn new(lo: f64, hi: f64, px0: f32, px1: f32) -> Scale {
        Scale { lo, hi, px0, px1 }
    }

    /// The pixel of value `v`.
    pub fn px(&self, v: f64) -> f32 {
        let span = self.hi - self.lo;
        let t = if span > 0.0 {
            (v - self.lo) / span
        } else {
            0.5
        };
        self.px0 + (self.px1 - self.px0) * t as f32
    }
}

/// Tick values and the step between them.
#[derive(Debug, Clone, PartialEq)]
pub struct Ticks {
    /// Values, ascending.
    pub values: Vec<f64>,
    /// Step between consecutive values.
    pub step: f64,
}

/// About `target` ticks at a "nice" step (1, 2 or 5 × 10^k) inside `[lo, hi]`; with
/// `integer` the step is at least 1 (counts).
pub fn ticks(lo: f64, hi: f64, target: usize, integer: bool) -> Ticks {
    let span = (hi - lo).abs().max(1e-12);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    // The step of 1, 2 or 5 × 10^k giving the count nearest to `target`.
    let count = |s: &f64| (span / s - target as f64).abs();
    let mut step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .min_by(|a, b| count(a).total_cmp(&count(b)))
        .unwrap_or(mag);
    if integer {
        step = step.max(1.0).round();
    }
    let mut values = Vec::new();
    let mut k = (lo / step - 1e-9).ceil();
    while k * step <= hi + step * 1e-9 && values.len() < 1000 {
        let t = k * step;
        values.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        k += 1.0;
    }
    Ticks { values, step }
}

/// `s` with its minus signs as the typographic minus (−).
fn typographic_minus(s: String) -> String {
    if s.starts_with('-') {
        s.replacen('-', "−", 1)
    } else {
        s
    }
}

/// The label of tick `v` on a scale of `step`: as many decimals as the step needs.
pub fn tick_label(v: f64, step: f64) -> String {
    let a = step.abs();
    if a >= 1e6 || (a < 1e-4 && a > 0.0) {
        return value_label(v);
    }
    // 0.5 → 1 decimal, 0.05 → 2, 0.25 → 2 (a mantissa that is not whole needs one more).
    let exp = a.log10().floor();
    let mantissa = a / 10f64.powf(exp);
    let decimals =
        ((-exp).max(0.0) as usize + usize::from(mantissa.fract() > 1e-6 && exp < 0.0)).min(6);
    typographic_minus(format!("{v:.decimals$}"))
}

/// `v` with four significant digits, without trailing zeros (`2.106`, `1500`, `0.0123`,
/// `1.2e-5`).
pub fn value_label(v: f64) -> String {
    if !v.is_finite() {
        return "–".into();
    }
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        return typographic_minus(format!("{v:.2e}"));
    }
    let decimals = if a == 0.0 {
        0
    } else {
        (3 - a.log10().floor() as i32).clamp(0, 6) as usize
    };
    let s = format!("{v:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    typographic_minus(s)
}

/// Widest label of `t`, px.
pub fn widest_label(t: &Ticks) -> f32 {
    t.values
        .iter()
        .map(|&v| text::text_width(&tick_label(v, t.step), SMALL.size))
        .fold(0.0, f32::max)
}

/// Space an x axis's tick labels take below the plot area, px.
pub fn x_labels_height() -> f32 {
    TICK_LEN + TICK_GAP + text::line_height(SMALL.size)
}

/// What an axis draws besides its tick marks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Marks {
    /// Grid lines across the plot area at the ticks.
    pub grid: bool,
    /// The ticks' labels.
    pub labels: bool,
}

/// Tick marks at `t` below `area`, with grid lines across it and labels below as `marks`
/// says.
pub fn x_axis(c: &mut Canvas, area: Area, s: &Scale, t: &Ticks, marks: Marks) {
    for &v in &t.values {
        let x = s.px(v);
        if x < area.x - 0.5 || x > area.right() + 0.5 {
            continue;
        }
        if marks.grid {
            c.fill_rect(x, area.y, 1.0, area.h, GRID, 255);
        }
        c.fill_rect(x, area.bottom(), 1.0, TICK_LEN, FRAME, 255);
        if marks.labels {
            c.text(
                x,
                area.bottom() + TICK_LEN + TICK_GAP,
                &tick_label(v, t.step),
                SMALL.aligned(Align::Center),
            );
        }
    }
}

/// Tick marks at `t` left of `area`, with grid lines across it and labels left of it as
/// `marks` says.
pub fn y_axis(c: &mut Canvas, area: Area, s: &Scale, t: &Ticks, marks: Marks) {
    let h = text::line_height(SMALL.size);
    for &v in &t.values {
        let y = s.px(v);
        if y < area.y - 0.5 || y > area.bottom() + 0.5 {
            continue;
        }
        if marks.grid {
            c.fill_rect(area.x, y, area.w, 1.0, GRID, 255);
        }
        c.fill_rect(area.x - TICK_LEN, y, TICK_LEN, 1.0, FRAME, 255);
        if marks.labels {
            c.text(
                area.x - TICK_LEN - TICK_GAP,
                y - h / 2.0,
                &tick_label(v, t.step),
                SMALL.aligned(Align::Right),
            );
        }
    }
}

/// Space a y axis's tick labels take left of the plot area, px.
pub fn y_labels_width(t: &Ticks) -> f32 {
    TICK_LEN + TICK_GAP + widest_label(t)
}

/// The frame around `area`: its left and bottom edges (the axes).
pub fn frame(c: &mut Canvas, area: Area) {
    c.fill_rect(area.x - 1.0, area.y, 1.0, area.h + 1.0, FRAME, 255);
    c.fill_rect(area.x - 1.0, area.bottom(), area.w + 1.0, 1.0, FRAME, 255);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice() {
        assert_eq!(
            ticks(0.0, 10.0, 5, false).values,
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
        assert_eq!(ticks(0.0, 3.0, 10, true).values, vec![0.0, 1.0, 2.0, 3.0]);
        let t = ticks(-0.25, 48.75, 5, false);
        assert_eq!(t.values, vec![0.0, 10.0, 20.0, 30.0, 40.0]);
        assert_eq!(ticks(0.0, 2.106, 5, false).step, 0.5);
        // One layer (its value held over ±0.5): one tick, on the layer's number.
        assert_eq!(ticks(-0.5, 0.5, 9, true).values, vec![0.0]);
        assert_eq!(ticks(2.5, 5.5, 9, true).values, vec![3.0, 4.0, 5.0]);
    }

    #[test]
    fn labels_read_well() {
        assert_eq!(tick_label(0.5, 0.5), "0.5");
        assert_eq!(tick_label(1.0, 0.5), "1.0");
        assert_eq!(tick_label(0.25, 0.05), "0.25");
        assert_eq!(tick_label(40.0, 10.0), "40");
        assert_eq!(tick_label(-2.0, 1.0), "−2");
        assert_eq!(tick_label(0.02, 0.02), "0.02");
        assert_eq!(value_label(2.10634), "2.106");
        assert_eq!(value_label(1500.0), "1500");
        assert_eq!(value_label(0.012345), "0.01235");
        assert_eq!(value_label(0.0), "0");
        assert_eq!(value_label(-3.5), "−3.5");
    }
}
