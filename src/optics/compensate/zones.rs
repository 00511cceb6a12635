//! The zone grid: `zone_mm` squares laid over the field from its bottom-left corner, the
//! unit of zone-mode compensation (one gray per zone, Xu et al. 2010, Chinese J. Lasers
//! 37(7)) and of the per-zone figures both modes report.

use super::{Field, FieldModel};

/// Image columns `first..end` that lie in one zone column: (zone column, first, end).
pub(super) type ZoneSegment = (usize, usize, usize);

/// Which zone each pixel of the field belongs to: a pixel belongs to the zone holding its
/// centre. Zone rows are numbered top first, like the image.
#[derive(Debug)]
pub(super) struct ZoneGrid {
    /// Side of a zone, mm.
    pub(super) zone_mm: f64,
    /// Number of zone columns.
    pub(super) cols: usize,
    /// Number of zone rows.
    pub(super) rows: usize,
    /// Each image column's zone column (non-decreasing).
    pub(super) of_col: Vec<u16>,
    /// Each image row's zone row.
    pub(super) of_row: Vec<u16>,
    /// The runs of image columns in one zone column, left to right.
    pub(super) segments: Vec<ZoneSegment>,
}

impl ZoneGrid {
    /// The zones of `field` for `zone_mm` squares.
    pub(super) fn new(field: &Field, zone_mm: f64) -> ZoneGrid {
        let (w, h) = (field.width_px as usize, field.height_px as usize);
        let (p, zmm) = (field.pixel_mm, zone_mm);
        let cols = ((field.width_mm() / zmm) - 1e-9).ceil().max(1.0) as usize;
        let rows = ((field.height_mm() / zmm) - 1e-9).ceil().max(1.0) as usize;
        let of_col: Vec<u16> = (0..w)
            .map(|c| (((c as f64 + 0.5) * p / zmm) as usize).min(cols - 1) as u16)
            .collect();
        let of_row = (0..h)
            .map(|r| {
                let zb = (((h as f64 - r as f64 - 0.5) * p / zmm) as usize).min(rows - 1);
                (rows - 1 - zb) as u16
            })
            .collect();
        ZoneGrid {
            zone_mm,
            cols,
            rows,
            segments: segments(&of_col),
            of_col,
            of_row,
        }
    }

    /// Number of zones (row-major, row 0 = top).
    pub(super) fn count(&self) -> usize {
        self.cols * self.rows
    }

    /// Whether each zone has pixels (`pixels[z]` > 0) and its centre lies in the
    /// calibrated area of `fm`; a zone cut by the field's top or right edge has the centre
    /// of its part inside the field.
    pub(super) fn centres_inside(
        &self,
        field: &Field,
        fm: &FieldModel,
        pixels: &[usize],
    ) -> Vec<bool> {
        let (zmm, zcols, zrows) = (self.zone_mm, self.cols, self.rows);
        (0..self.count())
            .map(|z| {
                let (zr, zc) = (zrows - 1 - z / zcols, z % zcols);
                let cx = (zc as f64 + 0.5) * zmm;
                let xe = ((zc + 1) as f64 * zmm).min(field.width_mm());
                let cx = cx.min(0.5 * (zc as f64 * zmm + xe));
                let ye = ((zr + 1) as f64 * zmm).min(field.height_mm());
                let cy = 0.5 * (zr as f64 * zmm + ye);
                pixels[z] > 0 && fm.inside(cx, cy)
            })
            .collect()
    }
}

/// The runs of equal values of a non-decreasing `zone_of_col`.
fn segments(zone_of_col: &[u16]) -> Vec<ZoneSegment> {
    let mut out: Vec<ZoneSegment> = Vec::new();
    for (c, &z) in zone_of_col.iter().enumerate() {
        match out.last_mut() {
            Some(l) if l.0 == z as usize => l.2 = c + 1,
            _ => out.push((z as usize, c, c + 1)),
        }
    }
    out
}
