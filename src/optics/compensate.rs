//! Applying a calibration: coverage → gray, per zone or per pixel.
//!
//! Everything that depends only on the calibration and the field is computed once per job
//! in [`Compensator::new`]: P at every pixel centre, the target E*, and either one
//! 256-entry lookup table per zone (zone mode) or the full-coverage gray, its level index
//! and E*/P per pixel (pixel mode). [`Compensator::apply`] then rewrites a layer's coverage
//! mask in place, touching only lit pixels:
//!
//! * coverage c = v/255 of a pixel asks for irradiance c·E*; the pixel gets the 8-bit level
//!   whose S·P is nearest to it (so an anti-aliased edge pixel gets S⁻¹(c·E*/P), never
//!   c × the full gray);
//! * zone mode uses P averaged over the zone (one gray per zone for full coverage);
//! * pixel mode uses P at the pixel centre; with dithering, the quantization error (in
//!   irradiance) is diffused to the lit neighbours (Floyd–Steinberg, serpentine), row by
//!   row within the layer, so the output does not depend on the thread count.

use super::field::{FieldModel, Form};
use super::response::Levels;
use super::{Calibration, Dither, Mode};
use crate::bundle::Spreads;
use crate::profile::Field;
use crate::raster::Mask;
use std::sync::atomic::{AtomicU64, Ordering};

/// Per-job compensation tables for one projector's calibration over the field.
#[derive(Debug)]
pub struct Compensator {
    mode: Mode,
    dither: Dither,
    w: usize,
    h: usize,
    levels: Levels,
    // Zone mode.
    zcols: usize,
    zone_of_col: Vec<u16>,
    zone_of_row: Vec<u16>,
    /// Coverage → gray tables: per zone, the lower-gray table then (for zones that mix two
    /// grays, see [`upper_row`]) the upper-gray table, which differs only in entry 255.
    tables: Vec<[u8; 256]>,
    /// Index into `tables` of each zone column for each image row ([r · zcols + zc]).
    row_tables: Vec<u32>,
    /// The full-coverage gray of every pixel (both modes; the gray map).
    full: Vec<u8>,
    // Pixel mode: level index of `full` and E*/P per pixel.
    full_idx: Vec<u16>,
    t: Vec<f32>,
    // Calibrated area in pixels: rows [r0, r1), cols [c0, c1).
    inside_rows: [usize; 2],
    inside_cols: [usize; 2],
    layers_outside: AtomicU64,
    /// What the model predicts; see [`Prediction`].
    pub prediction: Prediction,
}

/// What the calibration model predicts for a full-coverage field.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Target irradiance E* (calibration units).
    pub target: f64,
    /// Mean irradiance of the calibrated area at the brightest valid gray.
    pub mean: f64,
    /// Highest S (at the brightest valid gray).
    pub s_max: f64,
    /// Zone grid size (cols, rows).
    pub zone_grid: (usize, usize),
    /// Mean P of each zone, row 0 = top.
    pub zone_p: Vec<f64>,
    /// Zone centre inside the calibrated area, row 0 = top.
    pub zone_inside: Vec<bool>,
    /// Full-coverage gray of each zone (zone mode) or the zone mean of the pixel grays
    /// rounded (pixel mode), row 0 = top.
    pub zone_gray: Vec<u8>,
    /// Predicted full-coverage irradiance, zone means, row 0 = top.
    pub zone_after: Vec<f64>,
    /// Spreads before/after over the calibrated area.
    pub spreads: Spreads,
    /// Zones with their centre outside the calibrated area.
    pub zones_outside: u64,
    /// Pixels outside the calibrated area.
    pub pixels_outside: u64,
    /// Zones (zone mode) or pixels (pixel mode) that cannot reach E*.
    pub unreachable: u64,
    /// Zones mixing two grays (zone mode).
    pub mixed_zones: u64,
}

/// Zone mode with `Dither::Auto`: a zone whose nearest gray misses the target by more than
/// this fraction mixes the two grays around the target.
pub const MIX_TOLERANCE: f64 = 0.0075;

/// Whether row `r` of a mixing zone shows the upper of its two grays, for a mix of `k`
/// sixty-fourths: the 6-bit bit-reversal of r mod 64 (a 1-D ordered dither) is below
/// `k`. Any 8 consecutive rows hold k/64 of them to within 1/8, any 64 exactly. Whole
/// rows (not a checkerboard) keep the masks run-length friendly.
#[inline]
fn upper_row(r: usize, k: u8) -> bool {
    (((r & 63) as u8).reverse_bits() >> 2) < k
}

/// The zone-mode target: among targets within 3 % of `emax` (the highest every inside
/// zone can reach; about one gray step), the centre of the narrowest irradiance window that holds one
/// achievable full-coverage value P̄·S(level) of every inside zone. One gray per zone
/// cannot do better than that window's width; nearest rounding to `emax` alone can be
/// up to one gray step worse. Falls back to `emax`.
fn best_window(lv: &Levels, zone_p: &[f64], inside: &[bool], emax: f64) -> f64 {
    let zones: Vec<usize> = (0..zone_p.len()).filter(|&z| inside[z]).collect();
    let (lo_b, hi_b) = (emax * 0.97, emax * 1.03);
    let mut pairs: Vec<(f64, usize)> = Vec::new();
    for (k, &z) in zones.iter().enumerate() {
        for &s in &lv.s {
            let a = zone_p[z] * s;
            if a >= lo_b && a <= hi_b {
                pairs.push((a, k));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let n = zones.len();
    let mut cnt = vec![0usize; n];
    let (mut have, mut j) = (0usize, 0usize);
    let mut best: Option<(f64, f64)> = None;
    for i in 0..pairs.len() {
        if cnt[pairs[i].1] == 0 {
            have += 1;
        }
        cnt[pairs[i].1] += 1;
        while have == n {
            let (lo, hi) = (pairs[j].0, pairs[i].0);
            let width = (hi - lo) / (hi + lo);
            if best.is_none_or(|b| width < b.0 - 1e-15) {
                best = Some((width, 0.5 * (lo + hi)));
            }
            let k = pairs[j].1;
            cnt[k] -= 1;
            if cnt[k] == 0 {
                have -= 1;
            }
            j += 1;
        }
    }
    best.map_or(emax, |b| b.1)
}

/// Maps coverage values `data` to grays in place: 0 stays 0, 255 takes `full` (the
/// full-coverage gray of the same pixel), others `edge(index, value)`. Eight bytes at a
/// time: runs of all-off words are skipped and runs of all-on words copied from `full` in
/// tight loops, so the work is a few instructions per eight pixels away from part edges.
#[inline]
fn map_row(data: &mut [u8], full: &[u8], edge: impl Fn(usize, u8) -> u8) {
    let n = data.len().min(full.len());
    let (data, full) = (&mut data[..n], &full[..n]);
    let rd = |d: &[u8], i: usize| u64::from_ne_bytes(d[i..i + 8].try_into().expect("8 bytes"));
    let px = |d: &mut u8, f: u8, i: usize| {
        *d = match *d {
            0 => 0,
            255 => f,
            v => edge(i, v),
        }
    };
    let mut i = 0;
    while i + 8 <= n {
        let w = rd(data, i);
        if w == 0 {
            i += 8;
            while i + 8 <= n && rd(data, i) == 0 {
                i += 8;
            }
        } else if w == u64::MAX {
            data[i..i + 8].copy_from_slice(&full[i..i + 8]);
            i += 8;
            while i + 8 <= n && rd(data, i) == u64::MAX {
                data[i..i + 8].copy_from_slice(&full[i..i + 8]);
                i += 8;
            }
        } else {
            for k in i..i + 8 {
                px(&mut data[k], full[k], k);
            }
            i += 8;
        }
    }
    for k in i..n {
        px(&mut data[k], full[k], k);
    }
}

fn spread(v: impl Iterator<Item = f64>) -> f64 {
    let (mut lo, mut hi, mut sum, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
    for x in v {
        lo = lo.min(x);
        hi = hi.max(x);
        sum += x;
        n += 1;
    }
    if n == 0 {
        return 0.0;
    }
    (hi - lo) / (sum / n as f64) * 100.0
}

/// P at every pixel centre of the field (row-major, top row first), following the
/// extrapolation rule: inside the polynomial's rectangle Horner in u with the row's
/// coefficients, elsewhere [`FieldModel::eval_row`] (the same values as `eval`).
fn pixel_p(fm: &FieldModel, field: &Field) -> Vec<f32> {
    let (w, h) = (field.width_px as usize, field.height_px as usize);
    let p = field.pixel_mm;
    let m = fm.extrapolate_mm.get();
    let [x0, y0, x1, y1] = fm.area_mm;
    let [px0, py0, px1, py1] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
    let inv = 1.0 / fm.length_unit_mm.get();
    let scf = fm.scale.get() as f32;
    let form = fm.form;
    let xs: Vec<f64> = (0..w).map(|c| (c as f64 + 0.5) * p).collect();
    // Columns whose clamped x lies in the polynomial's rectangle: one contiguous run.
    let us: Vec<Option<f64>> = xs
        .iter()
        .map(|&x| {
            let xc = x.clamp(x0 - m, x1 + m);
            (xc >= px0 && xc <= px1).then(|| (xc - fm.origin_mm[0]) * inv)
        })
        .collect();
    let mut out = vec![0f32; w * h];
    let mut cache = super::field::RowCache::default();
    let mut exact = vec![0f64; w];
    for (r, row) in out.chunks_exact_mut(w).enumerate() {
        let y = (h as f64 - r as f64 - 0.5) * p;
        let yc = y.clamp(y0 - m, y1 + m);
        let mut rest = false;
        if yc >= py0 && yc <= py1 {
            let a = fm.coefficients.in_u((yc - fm.origin_mm[1]) * inv);
            for (o, u) in row.iter_mut().zip(&us) {
                match u {
                    Some(u) => *o = a.iter().rev().fold(0.0, |acc, k| acc * u + k) as f32,
                    None => rest = true,
                }
            }
            // Separate passes: exp must not be evaluated (speculatively) for polynomials.
            match form {
                Form::Exponential => row.iter_mut().for_each(|o| *o = scf * o.exp()),
                Form::InverseSquare => row.iter_mut().for_each(|o| *o = scf / (*o * *o)),
                Form::Polynomial => row.iter_mut().for_each(|o| *o *= scf),
            }
        } else {
            rest = true;
        }
        if rest {
            fm.eval_row(y, &xs, &mut cache, &mut exact);
            let inside_row = yc >= py0 && yc <= py1;
            for ((o, u), &e) in row.iter_mut().zip(&us).zip(&exact) {
                if !inside_row || u.is_none() {
                    *o = e as f32;
                }
            }
        }
    }
    out
}

impl Compensator {
    /// Precomputes the tables of `mode` (zone or pixel) for calibration `cal` over `field`.
    ///
    /// Fails (with a message for the caller to wrap) if the calibrated area contains no
    /// pixel or zone centre of the field.
    pub fn new(
        cal: &Calibration,
        field: &Field,
        mode: Mode,
        dither: Dither,
    ) -> std::result::Result<Compensator, String> {
        Self::with_target(cal, field, mode, dither, None)
    }

    /// As [`new`](Self::new), but with the target irradiance E* given (`Some`) instead of
    /// chosen from this calibration: projectors tiling one field share one E*
    /// ([`crate::geometry::tile`]).
    pub fn with_target(
        cal: &Calibration,
        field: &Field,
        mode: Mode,
        dither: Dither,
        forced_target: Option<f64>,
    ) -> std::result::Result<Compensator, String> {
        assert!(mode != Mode::Off, "no compensator for mode off");
        let (w, h) = (field.width_px as usize, field.height_px as usize);
        let p = field.pixel_mm;
        let fm = &cal.field;
        let [ax0, ay0, ax1, ay1] = fm.area_mm;
        let levels = cal.response.levels();
        let s_max = levels.s_max();

        // Calibrated area in pixel index ranges (pixel centres inside the area).
        let cols: Vec<usize> = (0..w)
            .filter(|&c| {
                let x = (c as f64 + 0.5) * p;
                x >= ax0 && x <= ax1
            })
            .collect();
        let rows: Vec<usize> = (0..h)
            .filter(|&r| {
                let y = (h as f64 - r as f64 - 0.5) * p;
                y >= ay0 && y <= ay1
            })
            .collect();
        let (Some(&c0), Some(&c1), Some(&r0), Some(&r1)) =
            (cols.first(), cols.last(), rows.first(), rows.last())
        else {
            return Err(format!(
                "the calibrated area {ax0}..{ax1} x {ay0}..{ay1} mm contains no pixel of the {:.3} x {:.3} mm field",
                field.width_mm(),
                field.height_mm()
            ));
        };
        let (inside_cols, inside_rows) = ([c0, c1 + 1], [r0, r1 + 1]);
        let pixels_inside = (c1 + 1 - c0) * (r1 + 1 - r0);
        let pixels_outside = (w * h - pixels_inside) as u64;

        let pp = pixel_p(fm, field);
        debug_assert!({
            let (c, r) = (w / 3, h / 3);
            let direct = fm.eval((c as f64 + 0.5) * p, (h as f64 - r as f64 - 0.5) * p);
            ((pp[r * w + c] as f64) - direct).abs() <= 1e-5 * direct.abs().max(1e-30)
        });
        // Pixels of the calibrated area, row by row (a plain nested loop: this runs over
        // most of the field several times per job).
        let inside_rows_iter = || (r0..=r1).map(move |r| r * w + c0..r * w + c1 + 1);
        let inside_iter = || inside_rows_iter().flatten();
        let mean = inside_iter().map(|i| pp[i] as f64).sum::<f64>() / pixels_inside as f64 * s_max;

        // Zones: `zone_mm` squares from the bottom-left corner; a pixel belongs to the zone
        // holding its centre. Zone rows are stored top first, like the image.
        let zmm = cal.zone_mm.get();
        let zcols = ((field.width_mm() / zmm) - 1e-9).ceil().max(1.0) as usize;
        let zrows = ((field.height_mm() / zmm) - 1e-9).ceil().max(1.0) as usize;
        let zone_of_col: Vec<u16> = (0..w)
            .map(|c| (((c as f64 + 0.5) * p / zmm) as usize).min(zcols - 1) as u16)
            .collect();
        let zone_of_row: Vec<u16> = (0..h)
            .map(|r| {
                let zb = (((h as f64 - r as f64 - 0.5) * p / zmm) as usize).min(zrows - 1);
                (zrows - 1 - zb) as u16
            })
            .collect();
        let nz = zcols * zrows;
        let mut zsum = vec![0f64; nz];
        let mut zcnt = vec![0usize; nz];
        for r in 0..h {
            let zr = zone_of_row[r] as usize * zcols;
            for c in 0..w {
                let z = zr + zone_of_col[c] as usize;
                zsum[z] += pp[r * w + c] as f64;
                zcnt[z] += 1;
            }
        }
        let zone_p: Vec<f64> = zsum
            .iter()
            .zip(&zcnt)
            .map(|(s, &n)| if n > 0 { s / n as f64 } else { f64::NAN })
            .collect();
        let zone_inside: Vec<bool> = (0..nz)
            .map(|z| {
                let (zr, zc) = (zrows - 1 - z / zcols, z % zcols);
                let cx = (zc as f64 + 0.5) * zmm;
                let xe = ((zc + 1) as f64 * zmm).min(field.width_mm());
                let cx = cx.min(0.5 * (zc as f64 * zmm + xe));
                let ye = ((zr + 1) as f64 * zmm).min(field.height_mm());
                let cy = 0.5 * (zr as f64 * zmm + ye);
                zcnt[z] > 0 && fm.inside(cx, cy)
            })
            .collect();
        let zones_outside = zone_inside.iter().filter(|&&b| !b).count() as u64;
        let before_zone = spread(
            (0..nz)
                .filter(|&z| zone_inside[z])
                .map(|z| zone_p[z] * s_max),
        );
        let before_pixel = spread(inside_iter().map(|i| pp[i] as f64 * s_max));

        let mut comp = Compensator {
            mode,
            dither,
            w,
            h,
            levels,
            zcols,
            zone_of_col,
            zone_of_row,
            tables: Vec::new(),
            row_tables: Vec::new(),
            full: Vec::new(),
            full_idx: Vec::new(),
            t: Vec::new(),
            inside_rows,
            inside_cols,
            layers_outside: AtomicU64::new(0),
            prediction: Prediction {
                target: 0.0,
                mean,
                s_max,
                zone_grid: (zcols, zrows),
                zone_p: zone_p.clone(),
                zone_inside: zone_inside.clone(),
                zone_gray: vec![0; nz],
                zone_after: vec![0.0; nz],
                spreads: Spreads {
                    before_zone_pct: before_zone,
                    before_pixel_pct: before_pixel,
                    after_zone_pct: 0.0,
                    after_pixel_pct: 0.0,
                },
                zones_outside,
                pixels_outside,
                unreachable: 0,
                mixed_zones: 0,
            },
        };
        let lv = &comp.levels;
        let mut s_table = [0.0f64; 256];
        for (&g, &sv) in lv.gray.iter().zip(&lv.s) {
            s_table[g as usize] = sv;
        }
        let s_of = |g: u8| -> f64 { s_table[g as usize] };
        match mode {
            Mode::Zone => {
                let pmin = (0..nz)
                    .filter(|&z| zone_inside[z])
                    .map(|z| zone_p[z])
                    .fold(f64::INFINITY, f64::min);
                if !pmin.is_finite() {
                    return Err(format!(
                        "no {zmm} mm zone of the field has its centre in the calibrated area {ax0}..{ax1} x {ay0}..{ay1} mm"
                    ));
                }
                let emax = pmin * s_max;
                let target = match forced_target {
                    Some(t) => t,
                    None if dither == Dither::On => emax,
                    None => best_window(lv, &zone_p, &zone_inside, emax),
                };
                let mut mixed = 0u64;
                let mut unreachable = 0;
                let mut luts = vec![[0u8; 256]; nz];
                let mut mix = vec![(0u8, 0u8, 0u8); nz];
                let mut zone_after = vec![0.0; nz];
                for z in 0..nz {
                    let pz = zone_p[z];
                    let tz = if pz > 0.0 { target / pz } else { f64::INFINITY };
                    if tz > s_max * (1.0 + 1e-9) {
                        unreachable += 1;
                    }
                    for (v, out) in luts[z].iter_mut().enumerate().skip(1) {
                        *out = lv.gray[lv.nearest(v as f64 / 255.0 * tz)];
                    }
                    let g = luts[z][255];
                    zone_after[z] = pz * s_of(g);
                    mix[z] = (g, g, 0);
                    let miss = (zone_after[z] / target - 1.0).abs();
                    let mixing = match dither {
                        Dither::On => true,
                        Dither::Auto => miss > MIX_TOLERANCE && tz <= s_max,
                        Dither::Off => false,
                    };
                    if mixing {
                        mixed += 1;
                        // Full coverage: mix the two levels around the target in the
                        // fraction that puts the zone mean on it (whole rows, see
                        // `upper_row`).
                        let i = lv.s.partition_point(|&x| x <= tz).clamp(1, lv.s.len() - 1);
                        let (s0, s1) = (lv.s[i - 1], lv.s[i]);
                        let f = ((tz - s0) / (s1 - s0)).clamp(0.0, 1.0);
                        let k = (f * 64.0).round() as u8;
                        mix[z] = (lv.gray[i - 1], lv.gray[i], k);
                        zone_after[z] = pz * (s0 + (s1 - s0) * k as f64 / 64.0);
                    }
                }
                let zone_gray: Vec<u8> = mix
                    .iter()
                    .map(|&(g0, g1, k)| if k >= 32 { g1 } else { g0 })
                    .collect();
                let after_zone = spread((0..nz).filter(|&z| zone_inside[z]).map(|z| zone_after[z]));
                // Per-pixel prediction: each row of a zone shows one gray.
                let zone_of_col = &comp.zone_of_col;
                let zone_of_row = &comp.zone_of_row;
                let pp = &pp;
                let after_pixel = spread((r0..=r1).flat_map(|r| {
                    let zr = zone_of_row[r] as usize * zcols;
                    let row_s: Vec<f64> = (0..zcols)
                        .map(|zc| {
                            let (g0, g1, k) = mix[zr + zc];
                            s_of(if upper_row(r, k) { g1 } else { g0 })
                        })
                        .collect();
                    (c0..=c1).map(move |c| pp[r * w + c] as f64 * row_s[zone_of_col[c] as usize])
                }));
                // Tables: the lower-gray table of every zone, plus an upper-gray one for
                // mixing zones; each row of a zone uses one of them (`upper_row`).
                let mut tables = Vec::with_capacity(nz + mixed as usize);
                let mut upper_idx = vec![u32::MAX; nz];
                for (l, &(g0, _, _)) in luts.iter_mut().zip(&mix) {
                    l[255] = g0;
                    tables.push(*l);
                }
                for z in 0..nz {
                    let (_, g1, k) = mix[z];
                    if k > 0 {
                        let mut u = luts[z];
                        u[255] = g1;
                        upper_idx[z] = tables.len() as u32;
                        tables.push(u);
                    }
                }
                let zone_of_row = &comp.zone_of_row;
                let row_tables: Vec<u32> = (0..h)
                    .flat_map(|r| {
                        let zr = zone_of_row[r] as usize * zcols;
                        let mix = &mix;
                        let upper_idx = &upper_idx;
                        (0..zcols).map(move |zc| {
                            let z = zr + zc;
                            if upper_row(r, mix[z].2) {
                                upper_idx[z]
                            } else {
                                z as u32
                            }
                        })
                    })
                    .collect();
                // The full-coverage gray of every pixel.
                let mut full = vec![0u8; w * h];
                for (r, row) in full.chunks_exact_mut(w).enumerate() {
                    let tabs = &row_tables[r * zcols..(r + 1) * zcols];
                    for (o, &zc) in row.iter_mut().zip(&comp.zone_of_col) {
                        *o = tables[tabs[zc as usize] as usize][255];
                    }
                }
                comp.full = full;
                comp.tables = tables;
                comp.row_tables = row_tables;
                comp.prediction.mixed_zones = mixed;
                let pr = &mut comp.prediction;
                pr.target = target;
                pr.zone_gray = zone_gray;
                pr.zone_after = zone_after;
                pr.spreads.after_zone_pct = after_zone;
                pr.spreads.after_pixel_pct = after_pixel;
                pr.unreachable = unreachable;
            }
            Mode::Pixel => {
                let pmin = inside_iter()
                    .map(|i| pp[i] as f64)
                    .fold(f64::INFINITY, f64::min);
                let target = forced_target.unwrap_or(pmin * s_max);
                let mut unreachable = 0;
                let mut full = vec![0u8; w * h];
                let mut full_idx = vec![0u16; w * h];
                let mut t = vec![0f32; w * h];
                let mut idx = lv.gray.len() - 1;
                for i in 0..w * h {
                    let ti = if pp[i] > 0.0 {
                        target / pp[i] as f64
                    } else {
                        f64::INFINITY
                    };
                    if ti > s_max * (1.0 + 1e-6) {
                        unreachable += 1;
                    }
                    idx = lv.nearest_from(idx, ti);
                    full[i] = lv.gray[idx];
                    full_idx[i] = idx as u16;
                    t[i] = ti as f32;
                }
                let mut zs = vec![0f64; nz];
                let mut zg = vec![0f64; nz];
                for r in 0..h {
                    for c in 0..w {
                        let i = r * w + c;
                        let z = comp.zone_of_row[r] as usize * zcols + comp.zone_of_col[c] as usize;
                        zs[z] += pp[i] as f64 * lv.s[full_idx[i] as usize];
                        zg[z] += full[i] as f64;
                    }
                }
                let zone_after: Vec<f64> = (0..nz).map(|z| zs[z] / zcnt[z].max(1) as f64).collect();
                let zone_gray = (0..nz)
                    .map(|z| (zg[z] / zcnt[z].max(1) as f64).round() as u8)
                    .collect();
                let after_zone = spread((0..nz).filter(|&z| zone_inside[z]).map(|z| zone_after[z]));
                let after_pixel =
                    spread(inside_iter().map(|i| pp[i] as f64 * lv.s[full_idx[i] as usize]));
                let pr = &mut comp.prediction;
                pr.target = target;
                pr.zone_gray = zone_gray;
                pr.zone_after = zone_after;
                pr.spreads.after_zone_pct = after_zone;
                pr.spreads.after_pixel_pct = after_pixel;
                pr.unreachable = unreachable;
                comp.full = full;
                comp.full_idx = full_idx;
                comp.t = t;
            }
            Mode::Off => unreachable!(),
        }
        Ok(comp)
    }

    /// The compensation mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The dithering setting.
    pub fn dither(&self) -> Dither {
        self.dither
    }

    /// Number of layers passed to [`apply`](Self::apply) whose lit pixels reach outside the
    /// calibrated area.
    pub fn layers_outside(&self) -> u64 {
        self.layers_outside.load(Ordering::Relaxed)
    }

    /// Rewrites a coverage mask of the field (values = coverage × 255) into compensated grays.
    pub fn apply(&self, m: &mut Mask) {
        self.apply_in(m, [0, self.h, 0, self.w]);
    }

    /// [`apply`](Self::apply) for a mask known to be zero outside rows r0..r1 and columns
    /// c0..c1 (`lit_box` = [r0, r1, c0, c1], e.g. [`crate::raster::Scratch::lit_box`]).
    ///
    /// One pass over the box, row by row and zone segment by zone segment, eight pixels
    /// at a time: all-off words are skipped, all-on words take the precomputed full gray
    /// (zone mode: the zone's gray for this row; pixel mode: the per-pixel gray map), other
    /// words go pixel by pixel (zone mode: a 256-entry table per zone and row parity;
    /// pixel mode: a search from the full-coverage level).
    pub fn apply_in(&self, m: &mut Mask, lit_box: [usize; 4]) {
        assert_eq!(
            (m.width as usize, m.height as usize),
            (self.w, self.h),
            "mask size differs from the field"
        );
        let w = self.w;
        let [br0, br1, bc0, bc1] = lit_box;
        let (br1, bc1) = (br1.min(self.h), bc1.min(w));
        if br0 >= br1 || bc0 >= bc1 {
            return;
        }
        if self.lit_outside(m, [br0, br1, bc0, bc1]) {
            self.layers_outside.fetch_add(1, Ordering::Relaxed);
        }
        match (self.mode, self.dither) {
            (Mode::Zone, _) => {
                for r in br0..br1 {
                    self.zone_row(&mut m.data[r * w..(r + 1) * w], r, bc0, bc1);
                }
            }
            (Mode::Pixel, Dither::On) => {
                let lit = |r: &usize| m.data[r * w + bc0..r * w + bc1].iter().any(|&v| v != 0);
                let first = (br0..br1).find(lit);
                let last = (br0..br1).rev().find(lit);
                if let (Some(r0), Some(r1)) = (first, last) {
                    self.apply_dither(m, r0, r1 + 1);
                }
            }
            (Mode::Pixel, _) => {
                for r in br0..br1 {
                    self.pixel_row(&mut m.data[r * w..(r + 1) * w], r, bc0, bc1);
                }
            }
            (Mode::Off, _) => {}
        }
    }

    /// Whether any nonzero pixel of the box lies outside the calibrated area (only the
    /// part of the box outside it is scanned; usually there is none).
    fn lit_outside(&self, m: &Mask, [r0, r1, c0, c1]: [usize; 4]) -> bool {
        let w = self.w;
        let [ir0, ir1] = self.inside_rows;
        let [ic0, ic1] = self.inside_cols;
        let any = |r: usize, a: usize, b: usize| {
            a < b && m.data[r * w + a..r * w + b].iter().any(|&v| v != 0)
        };
        (r0..r1).any(|r| {
            if r < ir0 || r >= ir1 {
                any(r, c0, c1)
            } else {
                any(r, c0, c1.min(ic0)) || any(r, c0.max(ic1), c1)
            }
        })
    }

    /// Zone mode, columns [a, b) of row `r` (`row` is the whole row): full pixels take
    /// the zone's gray for this row, edge pixels go through the zone's table.
    fn zone_row(&self, row: &mut [u8], r: usize, a: usize, b: usize) {
        let tabs = &self.row_tables[r * self.zcols..(r + 1) * self.zcols];
        let cols = &self.zone_of_col[a..b];
        let full = &self.full[r * self.w + a..r * self.w + b];
        map_row(&mut row[a..b], full, |k, v| {
            self.tables[tabs[cols[k] as usize] as usize][v as usize]
        });
    }

    /// Pixel mode without dithering, columns [a, b) of row `r`: full pixels take the
    /// precomputed gray, edge pixels (0 < v < 255) are searched from it.
    fn pixel_row(&self, row: &mut [u8], r: usize, a: usize, b: usize) {
        let lv = &self.levels;
        let base = r * self.w;
        let fidx = &self.full_idx[base + a..base + b];
        let t = &self.t[base + a..base + b];
        map_row(&mut row[a..b], &self.full[base + a..base + b], |k, v| {
            let target = v as f64 / 255.0 * t[k] as f64;
            lv.gray[lv.nearest_from(fidx[k] as usize, target)]
        });
    }

    fn apply_dither(&self, m: &mut Mask, r0: usize, r1: usize) {
        let w = self.w;
        let lv = &self.levels;
        let s_max = lv.s_max();
        let top = lv.s.len() - 1;
        // Error (in units of E*) carried to the current and the next row; index c + 1.
        let mut cur = vec![0f32; w + 2];
        let mut next = vec![0f32; w + 2];
        for r in r0..r1 {
            let ltr = (r - r0) % 2 == 0;
            let base = r * w;
            for k in 0..w {
                let c = if ltr { k } else { w - 1 - k };
                let i = base + c;
                let v = m.data[i];
                if v == 0 {
                    continue;
                }
                let ti = self.t[i] as f64;
                let d = v as f64 / 255.0 + cur[c + 1] as f64;
                let target = d * ti;
                let idx = lv.nearest_from(self.full_idx[i] as usize, target);
                m.data[i] = lv.gray[idx];
                if idx == top && target > s_max {
                    // Cannot reach the target here: do not push the deficit around.
                    continue;
                }
                let e = (d - lv.s[idx] / ti).clamp(-0.5, 0.5) as f32;
                // Forward neighbour on this row, three neighbours below (mirrored on
                // right-to-left rows); only lit pixels (coverage > 0) take a share.
                let (fwd, back): (isize, isize) = if ltr { (1, -1) } else { (-1, 1) };
                let cc = c as isize;
                let in_row = |x: isize| x >= 0 && (x as usize) < w;
                if in_row(cc + fwd) && m.data[(base as isize + cc + fwd) as usize] != 0 {
                    cur[(cc + fwd + 1) as usize] += e * (7.0 / 16.0);
                }
                if r + 1 < r1 {
                    let nb = (base + w) as isize;
                    for (dx, wgt) in [(back, 3.0f32), (0, 5.0), (fwd, 1.0)] {
                        let x = cc + dx;
                        if in_row(x) && m.data[(nb + x) as usize] != 0 {
                            next[(x + 1) as usize] += e * (wgt / 16.0);
                        }
                    }
                }
            }
            std::mem::swap(&mut cur, &mut next);
            next.fill(0.0);
        }
    }

    /// The full-coverage gray of every pixel (what a plate covering the field gets, without
    /// error diffusion), in field orientation.
    pub fn gray_map(&self) -> Mask {
        Mask {
            width: self.w as u32,
            height: self.h as u32,
            data: self.full.clone(),
        }
    }

    /// S of pixel value `g` on the levels used (0 for values outside the valid range other
    /// than off).
    pub fn s_of(&self, g: u8) -> f64 {
        let lv = &self.levels;
        let i = lv.gray.partition_point(|&x| x < g);
        if i < lv.gray.len() && lv.gray[i] == g {
            lv.s[i]
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::field::Poly;
    use crate::optics::{Interpolation, Response, Units};
    use crate::units::{NonNegative, Positive};

    /// A 40 × 30 mm field of 1 mm pixels; P = 1 + x/40 (x in mm), S(g) = (g/255)²
    /// measured 50..255 and anchored at 0.
    fn setup() -> (Calibration, Field) {
        let pts: Vec<[f64; 2]> = std::iter::once([0.0, 0.0])
            .chain(
                (50..=255)
                    .step_by(5)
                    .map(|g| [g as f64, (g as f64 / 255.0).powi(2)]),
            )
            .collect();
        let cal = Calibration {
            source: "test".into(),
            units: Units::Relative,
            zone_mm: Positive::new(5.0).unwrap(),
            field: FieldModel {
                origin_mm: [0.0, 0.0],
                length_unit_mm: Positive::new(40.0).unwrap(),
                scale: Positive::new(1.0).unwrap(),
                form: Form::Polynomial,
                coefficients: Poly::from_terms(1, &[1.0, 1.0, 0.0]),
                area_mm: [0.0, 0.0, 40.0, 30.0],
                polynomial_area_mm: None,
                extrapolate_mm: NonNegative::new(5.0).unwrap(),
            },
            response: Response::Table {
                interpolation: Interpolation::Spline,
                points: pts,
            },
            fit: None,
        };
        cal.validate().unwrap();
        let field = Field {
            width_px: 40,
            height_px: 30,
            pixel_mm: 1.0,
        };
        (cal, field)
    }

    fn s(g: u8) -> f64 {
        (g as f64 / 255.0).powi(2)
    }

    #[test]
    fn edge_pixel_gets_inverse_response_of_its_coverage_not_a_scaled_gray() {
        let (cal, field) = setup();
        let c = Compensator::new(&cal, &field, Mode::Zone, Dither::Off).unwrap();
        let pr = &c.prediction;
        // Zone at columns 20..25 (x 20..25 mm), rows 0..5; its mean P is 1 + 22.5/40.
        let pz = 1.0 + 22.5 / 40.0;
        let mut m = Mask::zeros(40, 30);
        for r in 0..5 {
            for col in 20..25 {
                m.data[r * 40 + col] = if col == 24 { 128 } else { 255 };
            }
        }
        c.apply(&mut m);
        let full = m.data[20];
        let edge = m.data[24];
        // Full coverage: the nearest level to E*/P̄; the edge: nearest to (128/255)·E*/P̄.
        let want = |target: f64| {
            (0..=255u8)
                .filter(|&g| g == 0 || g >= 50)
                .min_by(|&a, &b| (s(a) - target).abs().total_cmp(&(s(b) - target).abs()))
                .unwrap()
        };
        assert_eq!(full, want(pr.target / pz));
        assert_eq!(edge, want(128.0 / 255.0 * pr.target / pz));
        // With S = g², half the irradiance is about 0.71 × the gray, not 0.5 ×.
        let scaled = (full as f64 * 128.0 / 255.0).round() as u8;
        assert!(edge > scaled + 20, "edge {edge}, scaled gray {scaled}");
        assert!((s(edge) / s(full) - 128.0 / 255.0).abs() < 0.02);
        // Uncovered pixels stay off.
        assert_eq!(m.data[19], 0);
    }

    #[test]
    fn zone_and_pixel_modes_flatten_the_model() {
        let (cal, field) = setup();
        for (mode, dither, zone_max, pixel_max) in [
            (Mode::Zone, Dither::Off, 1.5, 20.0),
            (Mode::Zone, Dither::On, 0.2, 20.0),
            (Mode::Pixel, Dither::Off, 0.5, 1.5),
        ] {
            let c = Compensator::new(&cal, &field, mode, dither).unwrap();
            let sp = c.prediction.spreads;
            assert!(sp.before_zone_pct > 50.0, "{sp:?}");
            assert!(sp.after_zone_pct <= zone_max, "{mode:?} {dither:?} {sp:?}");
            assert!(
                sp.after_pixel_pct <= pixel_max,
                "{mode:?} {dither:?} {sp:?}"
            );
            // Target: the dimmest zone (or pixel) fully on, give or take the window.
            let t = c.prediction.target;
            assert!((0.95..=(1.0 + 2.5 / 40.0) * 1.02).contains(&t), "{t}");
        }
    }

    #[test]
    fn row_pattern() {
        // k of every 64 consecutive rows show the upper gray, any 8 rows within 1/8.
        for k in 0..=64u8 {
            assert_eq!(
                (0..64).filter(|&r| upper_row(r + 128, k)).count(),
                k as usize
            );
            for s in 0..64 {
                let c = (s..s + 8).filter(|&r| upper_row(r, k)).count() as f64;
                assert!(
                    (c / 8.0 - k as f64 / 64.0).abs() <= 0.125 + 1e-12,
                    "k {k} s {s}"
                );
            }
        }
    }

    #[test]
    fn pixel_dither_is_deterministic_and_keeps_the_mean() {
        let (cal, field) = setup();
        let c = Compensator::new(&cal, &field, Mode::Pixel, Dither::On).unwrap();
        let mut a = Mask::zeros(40, 30);
        a.data.iter_mut().enumerate().for_each(|(i, v)| {
            *v = if i % 40 < 35 { 255 } else { 0 };
        });
        let mut b = a.clone();
        c.apply(&mut a);
        c.apply(&mut b);
        assert_eq!(a, b);
        // Mean delivered irradiance per lit pixel in units of E* stays close to 1.
        let p = |col: usize| 1.0 + (col as f64 + 0.5) / 40.0;
        let (mut sum, mut n) = (0.0, 0);
        for (i, &g) in a.data.iter().enumerate() {
            if i % 40 < 35 {
                sum += s(g) * p(i % 40) / c.prediction.target;
                n += 1;
            } else {
                assert_eq!(g, 0);
            }
        }
        assert!((sum / n as f64 - 1.0).abs() < 0.003, "{}", sum / n as f64);
    }
}
