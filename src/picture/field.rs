//! A layer's masks put back on the build plane and shrunk: every projector's mask at its
//! offset with its mirroring undone (overlaps add up), cut to the part's footprint and
//! averaged over cells. The contact sheet's thumbnails and the preview's voxels are made so.

use crate::bundle::BundleSource;
use crate::bundle::Manifest;
use crate::error::{Error, Result};

/// A rectangle of the field in pixels: columns `x0..x1`, rows `y0..y1` counted from the
/// top (as in the masks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Crop {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// Column after the last.
    pub x1: u32,
    /// Row after the last.
    pub y1: u32,
}

impl Crop {
    /// Width, px.
    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }
    /// Height, px.
    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }
}

/// Margin around the part's footprint: this share of its size, and at least
/// [`MARGIN_MIN_MM`] (a distortion pre-warp moves the masks a little off the sections).
const MARGIN_SHARE: f64 = 0.04;
/// The smallest margin around the footprint, mm.
pub const MARGIN_MIN_MM: f64 = 1.0;

/// The part's footprint on the field (the union of the layers' `bbox_mm`) with a margin,
/// in field pixels; the whole field when no layer has a bounding box.
pub fn part_crop(manifest: &Manifest) -> Crop {
    let field = manifest.machine.field();
    let whole = Crop {
        x0: 0,
        y0: 0,
        x1: field.width_px,
        y1: field.height_px,
    };
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for [l, h] in manifest.layers.iter().filter_map(|l| l.bbox_mm) {
        lo = [lo[0].min(l[0]), lo[1].min(l[1])];
        hi = [hi[0].max(h[0]), hi[1].max(h[1])];
    }
    if !(lo[0].is_finite() && hi[0] >= lo[0] && hi[1] >= lo[1]) || field.pixel_mm <= 0.0 {
        return whole;
    }
    let m = ((hi[0] - lo[0]).max(hi[1] - lo[1]) * MARGIN_SHARE).max(MARGIN_MIN_MM);
    let p = field.pixel_mm;
    let (w, h) = (field.width_px as f64, field.height_px as f64);
    let col = |x: f64| (x / p).clamp(0.0, w);
    // Build-plane y up, rows down: row = H − y/p.
    let row = |y: f64| (h - y / p).clamp(0.0, h);
    let c = Crop {
        x0: col(lo[0] - m).floor() as u32,
        x1: col(hi[0] + m).ceil() as u32,
        y0: row(hi[1] + m).floor() as u32,
        y1: row(lo[1] - m).ceil() as u32,
    };
    if c.x1 <= c.x0 || c.y1 <= c.y0 {
        whole
    } else {
        c
    }
}

/// A layer shrunk to `width` × `height` cells (row-major, row 0 at the top).
#[derive(Debug, Clone, PartialEq)]
pub struct Cells {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Mean pixel value of each cell (overlapping projectors add up, at most 255).
    pub mean: Vec<u8>,
    /// Share of each cell's pixels that any projector lights (value above 0).
    pub lit: Vec<f32>,
}

/// Layer `layer`'s masks put on the field, cut to `crop` and averaged over `width` ×
/// `height` cells (at most one cell per pixel each way: fewer when the crop is smaller).
pub fn layer_cells(
    manifest: &Manifest,
    layer: usize,
    masks: &dyn BundleSource,
    crop: Crop,
    width: u32,
    height: u32,
) -> Result<Cells> {
    let (width, height) = (width.clamp(1, crop.width()), height.clamp(1, crop.height()));
    let (w, h) = (width as usize, height as usize);
    let mut sum = vec![0u32; w * h];
    let mut lit = vec![0u32; w * h];
    // Pixels of the crop per cell (a pixel belongs to the cell its index maps to).
    let cell_of = |i: u32, n: u32, cells: usize| ((i as u64 * cells as u64) / n as u64) as usize;
    let mut count = vec![0u32; w * h];
    let col_cell: Vec<usize> = (0..crop.width())
        .map(|i| cell_of(i, crop.width(), w))
        .collect();
    for r in 0..crop.height() {
        let cy = cell_of(r, crop.height(), h);
        for &cx in &col_cell {
            count[cy * w + cx] += 1;
        }
    }
    let Some(l) = manifest.layers.get(layer) else {
        return Ok(finish(width, height, sum, lit, count));
    };
    for m in &l.masks {
        let Some(p) = manifest.machine.projector.get(m.projector as usize) else {
            return Err(Error::Bundle {
                path: masks.shown(&m.file),
                msg: format!(
                    "layer {layer}: mask for projector {}, the machine has {}",
                    m.projector,
                    manifest.machine.projector.len()
                ),
            });
        };
        let img = super::read_mask(masks, &m.file)?;
        if img.dimensions() != (p.width_px, p.height_px) {
            return Err(Error::Bundle {
                path: masks.shown(&m.file),
                msg: format!(
                    "layer {layer}: mask is {}x{}, projector {} is {}x{}",
                    img.width(),
                    img.height(),
                    p.name,
                    p.width_px,
                    p.height_px
                ),
            });
        }
        let (pw, ph) = (p.width_px, p.height_px);
        // The cell of each mask column, or none outside the crop.
        let cols: Vec<Option<usize>> = (0..pw)
            .map(|c| {
                let fx = p.offset_px[0] + if p.mirror_x { pw - 1 - c } else { c };
                (fx >= crop.x0 && fx < crop.x1).then(|| col_cell[(fx - crop.x0) as usize])
            })
            .collect();
        for (r, row) in img.as_raw().chunks_exact(pw as usize).enumerate() {
            let r = r as u32;
            let fy = p.offset_px[1] + if p.mirror_y { ph - 1 - r } else { r };
            if fy < crop.y0 || fy >= crop.y1 {
                continue;
            }
            let base = cell_of(fy - crop.y0, crop.height(), h) * w;
            for (&v, cx) in row.iter().zip(&cols) {
                if let (true, Some(cx)) = (v > 0, cx) {
                    sum[base + cx] += v as u32;
                    lit[base + cx] += 1;
                }
            }
        }
    }
    Ok(finish(width, height, sum, lit, count))
}

/// The cells from their sums, lit counts and pixel counts.
fn finish(width: u32, height: u32, sum: Vec<u32>, lit: Vec<u32>, count: Vec<u32>) -> Cells {
    let mean = sum
        .iter()
        .zip(&count)
        .map(|(&s, &n)| (s / n.max(1)).min(255) as u8)
        .collect();
    let lit = lit
        .iter()
        .zip(&count)
        .map(|(&l, &n)| (l as f32 / n.max(1) as f32).min(1.0))
        .collect();
    Cells {
        width: width.max(1),
        height: height.max(1),
        mean,
        lit,
    }
}
