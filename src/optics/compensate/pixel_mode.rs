//! Pixel mode's tables: P at each pixel centre, so each pixel gets its own full-coverage
//! gray (the level nearest to E*/P), and edge pixels are searched from that level.

use super::gray_map::GrayMap;
use super::setup::{FieldSurvey, ModePrediction};
use super::spread::{zone_spread, Spread};
use super::Levels;

/// Pixel mode's per-pixel tables (row-major, top row first).
#[derive(Debug, Default)]
pub(super) struct PixelTables {
    /// Level index of each pixel's full-coverage gray.
    pub(super) full_idx: Vec<u16>,
    /// E*/P of each pixel: the S that full coverage asks for.
    pub(super) target_over_p: Vec<f32>,
}

/// Pixel mode's tables, gray map and prediction for `survey` on the levels `lv`, with P at every
/// pixel centre `pp` (row-major) and the target `forced_target` or, by default, the
/// highest irradiance every pixel of the calibrated area can reach.
///
/// Row by row: E*/P (divisions, vectorized), the nearest level searched from the
/// previous pixel's, then per zone P · S(level) added pixel by pixel in row-major
/// order (a zone's pixels in a row are one segment) and, over the calibrated area, the
/// spread after, also in row-major order. The gray sums are exact in any order.
pub(super) fn set_up(
    survey: &FieldSurvey,
    lv: &Levels,
    pp: &[f32],
    forced_target: Option<f64>,
) -> (PixelTables, GrayMap, ModePrediction) {
    let zones = &survey.zones;
    let (w, h) = (zones.of_col.len(), zones.of_row.len());
    let (nz, zcols) = (zones.count(), zones.cols);
    let s_max = lv.s_max();
    let target = forced_target.unwrap_or(smallest_inside_p(survey) * s_max);
    let mut unreachable = 0;
    let mut full = vec![0u8; w * h];
    let mut full_idx = vec![0u16; w * h];
    let mut t = vec![0f32; w * h];
    let mut idx = lv.gray.len() - 1;
    let mut zs = vec![0f64; nz];
    let mut zg = vec![0u64; nz];
    let mut after_px = Spread::new();
    let mut ti_row = vec![0f64; w];
    let inside = survey.inside;
    for r in 0..h {
        let base = r * w;
        let prow = &pp[base..base + w];
        for (o, &v) in ti_row.iter_mut().zip(prow) {
            *o = if v > 0.0 {
                target / v as f64
            } else {
                f64::INFINITY
            };
        }
        unreachable += ti_row
            .iter()
            .filter(|&&ti| ti > s_max * (1.0 + 1e-6))
            .count() as u64;
        let frow = &mut full[base..base + w];
        let irow = &mut full_idx[base..base + w];
        let trow = &mut t[base..base + w];
        for c in 0..w {
            let ti = ti_row[c];
            idx = lv.nearest_from(idx, ti);
            frow[c] = lv.gray[idx];
            irow[c] = idx as u16;
            trow[c] = ti as f32;
        }
        let zr = zones.of_row[r] as usize * zcols;
        let inside_row = inside.rows().contains(&r);
        for &(zc, a, b) in &zones.segments {
            let (ia, ib) = if inside_row {
                let ia = a.max(inside.c0).min(b);
                (ia, b.min(inside.c1).max(ia))
            } else {
                (b, b)
            };
            let mut acc = zs[zr + zc];
            for c in a..b {
                let x = prow[c] as f64 * lv.s[irow[c] as usize];
                acc += x;
                if c >= ia && c < ib {
                    after_px.add(x);
                }
            }
            zs[zr + zc] = acc;
            zg[zr + zc] += frow[a..b].iter().map(|&g| g as u64).sum::<u64>();
        }
    }
    let zcnt = &survey.sums.zone_pixels;
    let zone_after: Vec<f64> = (0..nz).map(|z| zs[z] / zcnt[z].max(1) as f64).collect();
    let zone_gray = (0..nz)
        .map(|z| (zg[z] as f64 / zcnt[z].max(1) as f64).round() as u8)
        .collect();
    let after_zone = zone_spread(&survey.zone_inside, |z| zone_after[z]);
    let tables = PixelTables {
        full_idx,
        target_over_p: t,
    };
    let prediction = ModePrediction {
        target,
        zone_gray,
        zone_after,
        after_zone_pct: after_zone,
        after_pixel_pct: after_px.pct(),
        unreachable,
        mixed_zones: 0,
    };
    (tables, GrayMap::per_pixel(full, h), prediction)
}

/// The smallest P of the calibrated area: of its row segments' smallest.
fn smallest_inside_p(survey: &FieldSurvey) -> f64 {
    survey.sums.seg_extremes.iter().fold(
        f64::INFINITY,
        |m, &(lo, _)| if (lo as f64) < m { lo as f64 } else { m },
    )
}
