//! The exact nonzero-winding fallback for layers whose shells overlap.

use super::scan::Rows;
use super::{PixelBox, Rasterizer};
use crate::slice::Contour;
use std::ops::Range;

/// Sub-scanlines per pixel row of the nonzero fallback rasterizer.
const SUBLINES: usize = 32;

/// Adds the horizontal span [xa, xb) with weight `wgt` to a pixel row: partial end pixels
/// go to `cover`, whole pixels between them to the difference array `diff`.
fn add_span(cover: &mut [f64], diff: &mut [f64], xa: f64, xb: f64, wgt: f64) {
    if xb <= xa {
        return;
    }
    let ia = xa.floor() as usize;
    let ib = xb.floor() as usize;
    if ia == ib {
        cover[ia] += (xb - xa) * wgt;
        return;
    }
    cover[ia] += ((ia + 1) as f64 - xa) * wgt;
    diff[ia + 1] += wgt;
    diff[ib] -= wgt;
    if ib < cover.len() {
        cover[ib] += (xb - ib as f64) * wgt;
    }
}

impl Rasterizer {
    /// Nonzero-winding coverage by analytic spans on [`SUBLINES`] sub-scanlines per pixel
    /// row: exact horizontally, 1/(2·SUBLINES) px vertically. Used for the rows where shells
    /// overlap, where [`coverage`](Self::coverage)'s signed-area accumulation over-counts.
    ///
    /// Writes the rows `rows` (ascending, disjoint ranges) of `out` (laid out as `layout`
    /// says) inside `lit` (the box of every contour point, outside which the section has no
    /// area).
    pub(super) fn coverage_nonzero(
        &self,
        contours: &[Contour],
        (out, layout): (&mut [u8], Rows),
        lit: PixelBox,
        rows: &[Range<usize>],
    ) {
        let w = self.field.width_px as usize;
        let h = self.field.height_px as usize;
        // Edges in pixel coordinates: (x at y_top, dx/dy, y_top, y_bottom, winding); those
        // that reach the rows drawn.
        let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
            return;
        };
        let (top, bottom) = (first.start as f64, last.end as f64);
        let mut edges: Vec<(f64, f64, f64, f64, i32)> = Vec::new();
        for c in contours {
            for i in 0..c.len() {
                let (x0, y0) = self.px(c[i]);
                let (x1, y1) = self.px(c[(i + 1) % c.len()]);
                if y0 == y1 {
                    continue;
                }
                let (dir, xa, ya, xb, yb) = if y0 < y1 {
                    (1, x0, y0, x1, y1)
                } else {
                    (-1, x1, y1, x0, y0)
                };
                if ya < bottom && yb > top {
                    edges.push((xa, (xb - xa) / (yb - ya), ya, yb, dir));
                }
            }
        }
        edges.sort_by(|a, b| a.2.total_cmp(&b.2));
        for r in rows.iter().flat_map(|rs| rs.clone()) {
            layout.row(out, r)[lit.cols()].fill(0);
        }
        let mut diff = vec![0.0f64; w + 2];
        let mut cover = vec![0.0f64; w + 1];
        let mut active: Vec<usize> = Vec::new();
        let mut next = 0;
        let mut xs: Vec<(f64, i32)> = Vec::new();
        let r_first = edges.first().map_or(h, |e| e.2.floor().max(0.0) as usize);
        let inv = 1.0 / SUBLINES as f64;
        for r in rows
            .iter()
            .flat_map(|rs| rs.clone())
            .filter(|&r| r >= r_first)
        {
            if next >= edges.len() && active.is_empty() {
                break;
            }
            while next < edges.len() && edges[next].2 < (r + 1) as f64 {
                active.push(next);
                next += 1;
            }
            active.retain(|&e| edges[e].3 > r as f64);
            if active.is_empty() {
                continue;
            }
            // Spans lie in the box's columns: cover[c0..=c1] and diff[c0..=c1 + 1] at most.
            cover[lit.c0..(lit.c1 + 1).min(w + 1)].fill(0.0);
            diff[lit.c0..(lit.c1 + 2).min(w + 2)].fill(0.0);
            for s in 0..SUBLINES {
                let y = r as f64 + (s as f64 + 0.5) * inv;
                xs.clear();
                for &e in &active {
                    let (x, k, ya, yb, d) = edges[e];
                    if ya <= y && y < yb {
                        xs.push(((x + k * (y - ya)).clamp(0.0, w as f64), d));
                    }
                }
                xs.sort_by(|a, b| a.0.total_cmp(&b.0));
                let mut wind = 0;
                for j in 0..xs.len() {
                    let before = wind;
                    wind += xs[j].1;
                    if before == 0 && wind != 0 {
                        // span starts at xs[j].0; find where it ends
                        let xa = xs[j].0;
                        let mut wk = wind;
                        let mut xb = xa;
                        for x in &xs[j + 1..] {
                            wk += x.1;
                            if wk == 0 {
                                xb = x.0;
                                break;
                            }
                        }
                        add_span(&mut cover, &mut diff, xa, xb, inv);
                    }
                }
            }
            // Columns left of the box hold no span: `run` is 0 there.
            let dst = &mut layout.row(out, r)[lit.cols()];
            let mut run = 0.0;
            for (col, d) in lit.cols().zip(dst) {
                run += diff[col];
                let v = (cover[col] + run).clamp(0.0, 1.0);
                *d = (v * 255.0 + 0.5) as u8;
            }
        }
    }
}
