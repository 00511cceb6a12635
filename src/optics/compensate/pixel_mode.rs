//! Pixel mode: each pixel gets its own full-coverage gray (the level nearest to E*/P, with
//! P at its centre), kept in the gray map; an edge pixel's gray is searched from that
//! level with P evaluated for it alone. Nothing else per pixel is kept.

use super::field_rows::FieldRows;
use super::gray_map::GrayMap;
use super::setup::{FieldSurvey, ModePrediction};
use super::spread::{zone_spread, Spread};
use super::Levels;

/// What pixel mode keeps besides the gray map.
#[derive(Debug, Default)]
pub(super) struct PixelTables {
    /// P at the pixel centres (None in zone mode).
    p: Option<FieldRows>,
    /// The target irradiance E*.
    target: f64,
    /// The level index of each gray that is a level.
    level_of: Vec<u16>,
}

impl PixelTables {
    /// E*/P at the centre of pixel (`r`, `c`) as the set-up computes it for the full gray
    /// (infinite where P ≤ 0), rounded to f32.
    #[inline]
    pub(super) fn target_over_p(&self, r: usize, c: usize) -> f32 {
        let mut p = [0f32];
        self.p
            .as_ref()
            .expect("pixel mode")
            .row_in::<false>(r, c, &mut p);
        target_over(self.target, p[0]) as f32
    }

    /// E*/P at the centres of columns `c0..c0 + out.len()` of row `r`, rounded to f32.
    pub(super) fn target_over_p_in(&self, r: usize, c0: usize, out: &mut [f32]) {
        self.p
            .as_ref()
            .expect("pixel mode")
            .row_in::<false>(r, c0, out);
        out.iter_mut()
            .for_each(|x| *x = target_over(self.target, *x) as f32);
    }

    /// The level index of full-coverage gray `g`.
    #[inline]
    pub(super) fn level(&self, g: u8) -> usize {
        self.level_of[g as usize] as usize
    }
}

/// E*/`p` (infinite where `p` ≤ 0).
#[inline]
fn target_over(target: f64, p: f32) -> f64 {
    if p > 0.0 {
        target / p as f64
    } else {
        f64::INFINITY
    }
}

/// Pixel mode's tables, gray map and prediction for `survey` on the levels `lv`, with P
/// from `rows` and the target `forced_target` or, by default, the highest irradiance
/// every pixel of the calibrated area can reach.
///
/// Row by row: P, E*/P, the nearest level searched from the previous pixel's, then per
/// zone P · S(level) added pixel by pixel in row-major order (a zone's pixels in a row are
/// one segment) and, over the calibrated area, the spread after, also in row-major order.
/// The gray sums are exact in any order. Only the grays are kept.
pub(super) fn set_up(
    survey: &FieldSurvey,
    lv: &Levels,
    rows: FieldRows,
    forced_target: Option<f64>,
) -> (PixelTables, GrayMap, ModePrediction) {
    let zones = &survey.zones;
    let (w, h) = (zones.of_col.len(), zones.of_row.len());
    let (nz, zcols) = (zones.count(), zones.cols);
    let s_max = lv.s_max();
    let target = forced_target.unwrap_or(smallest_inside_p(survey) * s_max);
    let mut unreachable = 0;
    let mut full = vec![0u8; w * h];
    let (mut prow, mut irow) = (vec![0f32; w], vec![0u16; w]);
    let mut idx = lv.gray.len() - 1;
    let mut zs = vec![0f64; nz];
    let mut zg = vec![0u64; nz];
    let mut after_px = Spread::new();
    let mut ti_row = vec![0f64; w];
    let inside = survey.inside;
    for r in 0..h {
        let base = r * w;
        rows.row::<false>(r, &mut prow);
        for (o, &v) in ti_row.iter_mut().zip(&prow) {
            *o = target_over(target, v);
        }
        unreachable += ti_row
            .iter()
            .filter(|&&ti| ti > s_max * (1.0 + 1e-6))
            .count() as u64;
        let frow = &mut full[base..base + w];
        for c in 0..w {
            idx = lv.nearest_from(idx, ti_row[c]);
            frow[c] = lv.gray[idx];
            irow[c] = idx as u16;
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
    let mut level_of = vec![0u16; 256];
    for (i, &g) in lv.gray.iter().enumerate() {
        level_of[g as usize] = i as u16;
    }
    let tables = PixelTables {
        p: Some(rows),
        target,
        level_of,
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

#[cfg(test)]
mod tests {
    use super::super::field_rows::pixel_p;
    use super::super::test_support::small_setup;
    use super::super::{Compensator, Dither, Mask, Mode};

    #[test]
    fn every_pixel_gets_the_level_nearest_to_its_share_of_the_target() {
        // Pixel mode keeps only the gray map; each pixel of a mask of every coverage (the
        // calibrated area's edge rows and columns beyond it included) still becomes the
        // level nearest to v/255 · E*/P with P at its centre, as from whole-field tables.
        let (cal, field) = small_setup();
        let c = Compensator::new(&cal, &field, Mode::Pixel, Dither::Off).unwrap();
        let (w, h) = (field.width_px as usize, field.height_px as usize);
        let pp = pixel_p(&cal.field, &field);
        let mut m = Mask::zeros(w as u32, h as u32);
        for (i, v) in m.data.iter_mut().enumerate() {
            *v = ((i * 37 + i / w * 11) % 256) as u8;
        }
        let coverage = m.data.clone();
        c.apply(&mut m);
        let (lv, target) = (&c.levels, c.prediction.target);
        for (i, (&v, &g)) in coverage.iter().zip(&m.data).enumerate() {
            let t = (target / pp[i] as f64) as f32 as f64;
            let want = match v {
                0 => 0,
                255 => lv.gray[lv.nearest(target / pp[i] as f64)],
                _ => lv.gray[lv.nearest(v as f64 / 255.0 * t)],
            };
            assert_eq!(g, want, "pixel {i}, coverage {v}");
        }
    }
}
