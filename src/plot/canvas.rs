//! The canvas every picture is drawn on: an opaque RGB tiny-skia pixmap with rectangles,
//! lines, dots, text (horizontal or reading upwards) and images pasted in.

use super::format::Format;
use super::text::{self, Align, TextStyle};
use image::{GrayImage, RgbImage};
use tiny_skia::{Color, FillRule, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};

/// An opaque RGB picture being drawn.
pub struct Canvas {
    pm: Pixmap,
}

/// Paint of one colour with `alpha` (0–255).
fn paint(c: [u8; 3], alpha: u8, anti_alias: bool) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color(Color::from_rgba8(c[0], c[1], c[2], alpha));
    p.anti_alias = anti_alias;
    p
}

/// The path through `pts` (at least one), closed when `close`.
fn path(pts: &[(f32, f32)], close: bool) -> Option<tiny_skia::Path> {
    let mut pb = PathBuilder::new();
    pb.move_to(pts[0].0, pts[0].1);
    pts[1..].iter().for_each(|p| pb.line_to(p.0, p.1));
    if close {
        pb.close();
    }
    pb.finish()
}

impl Canvas {
    /// A `width` × `height` canvas (at least 1 × 1) filled with background colour `bg`.
    pub fn new(width: u32, height: u32, bg: [u8; 3]) -> Canvas {
        let mut pm = Pixmap::new(width.max(1), height.max(1)).expect("canvas size is valid");
        pm.fill(Color::from_rgba8(bg[0], bg[1], bg[2], 255));
        Canvas { pm }
    }

    /// Width, px.
    #[cfg(test)]
    pub fn width(&self) -> u32 {
        self.pm.width()
    }

    /// Height, px.
    #[cfg(test)]
    pub fn height(&self) -> u32 {
        self.pm.height()
    }

    /// Fills the rectangle (x, y, w, h) with `color` at `alpha` (0–255), snapped to whole
    /// pixels (crisp edges), at least one pixel each way.
    pub fn fill_rect(&mut self, x: f32, y: f32, w: f32, h: f32, color: [u8; 3], alpha: u8) {
        let (x0, y0) = (x.round(), y.round());
        let (x1, y1) = ((x + w).round().max(x0 + 1.0), (y + h).round().max(y0 + 1.0));
        if let Some(r) = Rect::from_ltrb(x0, y0, x1, y1) {
            self.pm
                .fill_rect(r, &paint(color, alpha, false), Transform::identity(), None);
        }
    }

    /// Strokes the polyline through `pts` (anti-aliased, `width` px wide).
    pub fn polyline(&mut self, pts: &[(f32, f32)], color: [u8; 3], width: f32) {
        if pts.len() < 2 {
            return;
        }
        if let Some(path) = path(pts, false) {
            let (paint, id) = (paint(color, 255, true), Transform::identity());
            let st = Stroke {
                width,
                ..Stroke::default()
            };
            self.pm.stroke_path(&path, &paint, &st, id, None);
        }
    }

    /// A filled dot of radius `r` centred on (x, y).
    pub fn dot(&mut self, x: f32, y: f32, r: f32, color: [u8; 3]) {
        self.fill(PathBuilder::from_circle(x, y, r), color, 255);
    }

    /// Fills the polygon through `pts` with `color` at `alpha` (anti-aliased).
    pub fn polygon(&mut self, pts: &[(f32, f32)], color: [u8; 3], alpha: u8) {
        if pts.len() >= 3 {
            self.fill(path(pts, true), color, alpha);
        }
    }

    /// Fills `path` (if any) with `color` at `alpha`, anti-aliased.
    fn fill(&mut self, path: Option<tiny_skia::Path>, color: [u8; 3], alpha: u8) {
        if let Some(path) = path {
            let paint = paint(color, alpha, true);
            let id = Transform::identity();
            self.pm
                .fill_path(&path, &paint, FillRule::Winding, id, None);
        }
    }

    /// Blends `color` into pixel (x, y) with opacity `a` in 0..=1 (outside: ignored).
    fn blend(&mut self, x: i64, y: i64, color: [u8; 3], a: f32) {
        let (w, h) = (self.pm.width() as i64, self.pm.height() as i64);
        if a <= 0.0 || x < 0 || y < 0 || x >= w || y >= h {
            return;
        }
        let i = ((y * w + x) * 4) as usize;
        let px = &mut self.pm.data_mut()[i..i + 3];
        for k in 0..3 {
            px[k] = (px[k] as f32 + (color[k] as f32 - px[k] as f32) * a).round() as u8;
        }
    }

    /// Draws `s` on one line with the top of the line at `y`, placed on x by the style's
    /// alignment; returns its width.
    pub fn text(&mut self, x: f32, y: f32, s: &str, style: TextStyle) -> f32 {
        let cov = text::rasterize(s, style.size);
        let w = cov.width as f32 - 2.0;
        let left = match style.align {
            Align::Left => x,
            Align::Center => x - w / 2.0,
            Align::Right => x - w,
        };
        let (ox, oy) = ((left - 1.0).round() as i64, (y - 1.0).round() as i64);
        for r in 0..cov.height {
            for c in 0..cov.width {
                let a = cov.alpha[r * cov.width + c];
                self.blend(ox + c as i64, oy + r as i64, style.color, a);
            }
        }
        w
    }

    /// Draws `s` reading upwards (turned a quarter left), the top of the line at `x`,
    /// placed on y by the style's alignment (`Center`: its middle at `y`; `Left`: it starts
    /// at `y` and goes up; `Right`: it ends at `y`).
    pub fn text_up(&mut self, x: f32, y: f32, s: &str, style: TextStyle) {
        let cov = text::rasterize(s, style.size);
        let w = cov.width as f32 - 2.0;
        let bottom = match style.align {
            Align::Left => y,
            Align::Center => y + w / 2.0,
            Align::Right => y + w,
        };
        let (ox, oy) = ((x - 1.0).round() as i64, (bottom + 1.0).round() as i64);
        // Text pixel (c, r) goes to (x + r, bottom − c).
        for r in 0..cov.height {
            for c in 0..cov.width {
                let a = cov.alpha[r * cov.width + c];
                self.blend(ox + r as i64, oy - c as i64, style.color, a);
            }
        }
    }

    /// Pastes a gray image with its top-left corner at (x, y).
    pub fn draw_gray(&mut self, img: &GrayImage, x: i64, y: i64) {
        for (c, r, p) in img.enumerate_pixels() {
            self.set(x + c as i64, y + r as i64, [p[0]; 3]);
        }
    }

    /// Pastes an RGB image with its top-left corner at (x, y).
    pub fn draw_rgb(&mut self, img: &RgbImage, x: i64, y: i64) {
        for (c, r, p) in img.enumerate_pixels() {
            self.set(x + c as i64, y + r as i64, p.0);
        }
    }

    /// Sets pixel (x, y) to `color` (outside: ignored).
    fn set(&mut self, x: i64, y: i64, color: [u8; 3]) {
        let (w, h) = (self.pm.width() as i64, self.pm.height() as i64);
        if x >= 0 && y >= 0 && x < w && y < h {
            let i = ((y * w + x) * 4) as usize;
            self.pm.data_mut()[i..i + 3].copy_from_slice(&color);
        }
    }

    /// The colour of pixel (x, y).
    #[cfg(test)]
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = ((y * self.pm.width() + x) * 4) as usize;
        let d = &self.pm.data()[i..i + 3];
        [d[0], d[1], d[2]]
    }

    /// The picture as an RGB image (the canvas is opaque, so its premultiplied colours are
    /// the plain ones).
    pub fn to_rgb(&self) -> RgbImage {
        let rgb: Vec<u8> = self
            .pm
            .data()
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        RgbImage::from_raw(self.pm.width(), self.pm.height(), rgb).expect("sizes agree")
    }

    /// The picture encoded as `format`.
    pub fn encode(&self, format: Format) -> Vec<u8> {
        format.encode(&self.to_rgb())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot::text::LABEL;

    fn dark(c: &Canvas, x0: u32, y0: u32, x1: u32, y1: u32) -> usize {
        let px = (y0..y1).flat_map(|y| (x0..x1).map(move |x| (x, y)));
        px.filter(|&(x, y)| c.pixel(x, y)[0] < 128).count()
    }

    #[test]
    fn text_lands_where_it_is_placed() {
        let mut c = Canvas::new(200, 200, [255; 3]);
        let w = c.text(100.0, 10.0, "Layer 12", LABEL.aligned(Align::Center));
        assert!(w > 40.0 && w < 80.0, "{w}");
        assert!(dark(&c, 50, 8, 150, 30) > 30);
        assert_eq!(dark(&c, 0, 30, 200, 200), 0);
        c.text_up(20.0, 150.0, "area (mm²)", LABEL.aligned(Align::Left));
        // Upward text stands in a column right of x = 20, above y = 150.
        assert!(dark(&c, 18, 60, 40, 152) > 30);
        assert_eq!(dark(&c, 40, 40, 200, 200), 0);
    }
}
