//! Text: DejaVu Sans (a subset of it, `fixtures/fonts/DejaVuSans-plots.ttf`, compiled in),
//! laid out on one line with the font's kerning and rasterized by exact area coverage
//! (ab_glyph). A character the subset lacks is drawn as the font's empty box.

use ab_glyph::{point, Font as _, FontRef, GlyphId, ScaleFont};
use std::sync::OnceLock;

/// The font file: DejaVu Sans 2.37 cut down by `fixtures/fonts/subset.sh` (licence in
/// `fixtures/fonts/LICENSE-DejaVu.txt`).
const FONT_FILE: &[u8] = include_bytes!("../../fixtures/fonts/DejaVuSans-plots.ttf");

/// The parsed font, shared by every drawing.
fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    FONT.get_or_init(|| FontRef::try_from_slice(FONT_FILE).expect("the compiled-in font parses"))
}

/// Where text stands relative to the x it is drawn at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    /// x is the left end.
    Left,
    /// x is the middle.
    Center,
    /// x is the right end.
    Right,
}

/// Size, colour and alignment of a piece of text.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TextStyle {
    /// Font size, px (the height of the font's ascent plus descent).
    pub size: f32,
    /// RGB colour.
    pub color: [u8; 3],
    /// Alignment on x.
    pub align: Align,
}

impl TextStyle {
    /// Left-aligned text of `size` px in `color`.
    pub const fn new(size: f32, color: [u8; 3]) -> TextStyle {
        TextStyle {
            size,
            color,
            align: Align::Left,
        }
    }

    /// The same style aligned by `align`.
    pub const fn aligned(self, align: Align) -> TextStyle {
        TextStyle { align, ..self }
    }
}

/// The ink of dark text.
pub const INK: [u8; 3] = [33, 33, 33];
/// The ink of secondary text (axis labels, notes).
pub const MUTED: [u8; 3] = [85, 85, 85];
/// Titles.
pub const TITLE: TextStyle = TextStyle::new(17.0, INK);
/// Axis labels and legends.
pub const LABEL: TextStyle = TextStyle::new(13.5, INK);
/// Tick labels and small print.
pub const SMALL: TextStyle = TextStyle::new(12.0, MUTED);

/// Glyphs of one line with their pen positions, px from the line's left end.
struct Layout {
    glyphs: Vec<(GlyphId, f32)>,
    width: f32,
}

/// Lays `s` out on one line at `size` px, with kerning.
fn layout(s: &str, size: f32) -> Layout {
    let f = font().as_scaled(size);
    let mut glyphs = Vec::with_capacity(s.len());
    let mut x = 0.0f32;
    let mut prev: Option<GlyphId> = None;
    for c in s.chars() {
        let id = f.glyph_id(c);
        if let Some(p) = prev {
            x += f.kern(p, id);
        }
        glyphs.push((id, x));
        x += f.h_advance(id);
        prev = Some(id);
    }
    Layout { glyphs, width: x }
}

/// Width of `s` drawn at `size` px.
pub fn text_width(s: &str, size: f32) -> f32 {
    layout(s, size).width
}

/// Height of a line of text at `size` px: ascent plus descent.
pub fn line_height(size: f32) -> f32 {
    let f = font().as_scaled(size);
    f.ascent() - f.descent()
}

/// A line of text as coverage: `width` × `height` values in 0..=1, row-major, the top of
/// the line (the font's ascent) at row 0.
pub(super) struct Coverage {
    pub width: usize,
    pub height: usize,
    pub alpha: Vec<f32>,
}

/// Rasterizes `s` at `size` px.
pub(super) fn rasterize(s: &str, size: f32) -> Coverage {
    let l = layout(s, size);
    let f = font().as_scaled(size);
    let ascent = f.ascent();
    let width = l.width.ceil().max(0.0) as usize + 2;
    let height = (ascent - f.descent()).ceil() as usize + 2;
    let mut alpha = vec![0.0f32; width * height];
    for &(id, x) in &l.glyphs {
        let g = id.with_scale_and_position(size, point(x + 1.0, ascent + 1.0));
        let Some(og) = font().outline_glyph(g) else {
            continue;
        };
        let b = og.px_bounds();
        let (bx, by) = (b.min.x as i64, b.min.y as i64);
        og.draw(|gx, gy, c| {
            let (px, py) = (bx + gx as i64, by + gy as i64);
            if px >= 0 && py >= 0 && (px as usize) < width && (py as usize) < height {
                let a = &mut alpha[py as usize * width + px as usize];
                *a = (*a + c).min(1.0);
            }
        });
    }
    Coverage {
        width,
        height,
        alpha,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_have_real_glyphs() {
        // Every character the plots' units use is in the subset (not the empty box).
        for c in "mW/cm² µm × ° − ≤ λ κ Δ …".chars().filter(|c| *c != ' ') {
            assert_ne!(font().glyph_id(c).0, 0, "{c:?} is missing from the font");
        }
    }

    #[test]
    fn text_has_ink_and_width_grows_with_length() {
        let a = rasterize("mm", 14.0);
        let b = rasterize("mW/cm²", 14.0);
        assert!(b.width > a.width);
        let ink: f32 = b.alpha.iter().sum();
        assert!(ink > 20.0, "{ink}");
        assert!((text_width("mW/cm²", 14.0) - (b.width - 2) as f32).abs() < 1.0);
        assert!(line_height(14.0) > 12.0 && line_height(14.0) < 20.0);
    }
}
