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
    /// Exclusive end column of each zone column.
    zone_col_end: Vec<usize>,
    zone_of_row: Vec<u16>,
    luts: Vec<[u8; 256]>,
    /// Zone mode: (lower gray, upper gray, count of 64) per zone; rows chosen by
    /// [`upper_row`] show the upper gray at full coverage. k = 0: one gray.
    mix: Vec<(u8, u8, u8)>,
    /// `luts` with entry 255 = the upper gray of the zone's mix.
    luts_upper: Vec<[u8; 256]>,
    // Pixel mode.
    full: Vec<u8>,
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

thread_local! {
    /// Edge pixels of the row being compensated (pixel mode): (index, gray).
    static EDGES: std::cell::RefCell<Vec<(usize, u8)>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// First and last index of a nonzero byte in `row`, testing 32 bytes at a time (an OR
/// reduction the compiler vectorizes).
fn lit_span(row: &[u8]) -> Option<(usize, usize)> {
    const K: usize = 32;
    let any = |c: &[u8]| c.iter().fold(0u8, |acc, &v| acc | v) != 0;
    let n = row.len();
    let nk = n / K;
    let a = match (0..nk).find(|&i| any(&row[i * K..(i + 1) * K])) {
        Some(i) => i * K,
        None => nk * K,
    };
    let a = a + row[a..].iter().position(|&v| v != 0)?;
    let tail = &row[nk * K..];
    let b = match tail.iter().rposition(|&v| v != 0) {
        Some(t) => nk * K + t,
        None => {
            let i = (0..nk)
                .rev()
                .find(|&i| any(&row[i * K..(i + 1) * K]))
                .expect("a lit byte exists");
            i * K
                + row[i * K..(i + 1) * K]
                    .iter()
                    .rposition(|&v| v != 0)
                    .expect("lit")
        }
    };
    Some((a, b))
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
/// extrapolation rule.
fn pixel_p(fm: &FieldModel, field: &Field) -> Vec<f32> {
    let (w, h) = (field.width_px as usize, field.height_px as usize);
    let p = field.pixel_mm;
    let m = fm.extrapolate_mm.get();
    let [x0, y0, x1, y1] = fm.area_mm;
    let [px0, py0, px1, py1] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
    let inv = 1.0 / fm.length_unit_mm.get();
    let sc = fm.scale.get();
    let exp = fm.form == Form::Exponential;
    let mut out = vec![0f32; w * h];
    for (r, row) in out.chunks_exact_mut(w).enumerate() {
        let y = (h as f64 - r as f64 - 0.5) * p;
        let yc = y.clamp(y0 - m, y1 + m);
        // Inside the polynomial's rectangle: Horner in u with this row's coefficients.
        let a =
            (yc >= py0 && yc <= py1).then(|| fm.coefficients.in_u((yc - fm.origin_mm[1]) * inv));
        for (c, o) in row.iter_mut().enumerate() {
            let x = (c as f64 + 0.5) * p;
            let xc = x.clamp(x0 - m, x1 + m);
            *o = match &a {
                Some(a) if xc >= px0 && xc <= px1 => {
                    let u = (xc - fm.origin_mm[0]) * inv;
                    a.iter().rev().fold(0.0, |acc, k| acc * u + k) as f32
                }
                _ => f32::NAN,
            };
        }
        // Separate passes: exp must not be evaluated (speculatively) for polynomials.
        let scf = sc as f32;
        if exp {
            row.iter_mut().for_each(|o| *o = scf * o.exp());
        } else {
            row.iter_mut().for_each(|o| *o *= scf);
        }
        for (c, o) in row.iter_mut().enumerate() {
            if o.is_nan() {
                *o = fm.eval((c as f64 + 0.5) * p, y) as f32;
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
            zone_col_end: (0..zcols)
                .map(|zc| zone_of_col.partition_point(|&z| (z as usize) <= zc))
                .collect(),
            zone_of_col,
            zone_of_row,
            luts: Vec::new(),
            mix: Vec::new(),
            luts_upper: Vec::new(),
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
                comp.luts_upper = luts
                    .iter()
                    .zip(&mix)
                    .map(|(l, &(_, g1, _))| {
                        let mut u = *l;
                        u[255] = g1;
                        u
                    })
                    .collect();
                for (l, &(g0, _, _)) in luts.iter_mut().zip(&mix) {
                    l[255] = g0;
                }
                comp.mix = mix;
                comp.prediction.mixed_zones = mixed;
                let pr = &mut comp.prediction;
                pr.target = target;
                pr.zone_gray = zone_gray;
                pr.zone_after = zone_after;
                pr.spreads.after_zone_pct = after_zone;
                pr.spreads.after_pixel_pct = after_pixel;
                pr.unreachable = unreachable;
                comp.luts = luts;
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
    ///
    /// Only the span from the first to the last lit pixel of each row is touched (found
    /// eight bytes at a time).
    pub fn apply(&self, m: &mut Mask) {
        self.apply_in(m, [0, self.h, 0, self.w]);
    }

    /// [`apply`](Self::apply) for a mask known to be zero outside rows r0..r1 and columns
    /// c0..c1 (`lit_box` = [r0, r1, c0, c1], e.g. [`crate::raster::Scratch::lit_box`]).
    pub fn apply_in(&self, m: &mut Mask, lit_box: [usize; 4]) {
        assert_eq!(
            (m.width as usize, m.height as usize),
            (self.w, self.h),
            "mask size differs from the field"
        );
        let w = self.w;
        let [br0, br1, bc0, bc1] = lit_box;
        let (br1, bc1) = (br1.min(self.h), bc1.min(w));
        let [ir0, ir1] = self.inside_rows;
        let [ic0, ic1] = self.inside_cols;
        let mut outside = false;
        let mut first_lit = None;
        let mut last_lit = 0;
        for r in br0..br1 {
            let row = &m.data[r * w + bc0.min(bc1)..r * w + bc1];
            let Some((a, b)) = lit_span(row) else {
                continue;
            };
            let (a, b) = (a + bc0, b + bc0);
            first_lit.get_or_insert(r);
            last_lit = r;
            outside |= r < ir0 || r >= ir1 || a < ic0 || b >= ic1;
            match (self.mode, self.dither) {
                (Mode::Zone, _) => self.zone_row(m, r, a, b + 1),
                (Mode::Pixel, Dither::On) => {}
                (Mode::Pixel, _) => self.pixel_row(m, r, a, b + 1),
                (Mode::Off, _) => {}
            }
        }
        if outside {
            self.layers_outside.fetch_add(1, Ordering::Relaxed);
        }
        if let (Some(r0), Mode::Pixel, Dither::On) = (first_lit, self.mode, self.dither) {
            self.apply_dither(m, r0, last_lit + 1);
        }
    }

    /// Zone mode, row `r`, columns [a, b): a table lookup per edge pixel (0 stays 0).
    fn zone_row(&self, m: &mut Mask, r: usize, a: usize, b: usize) {
        let w = self.w;
        let zr = self.zone_of_row[r] as usize * self.zcols;
        let row = &mut m.data[r * w..(r + 1) * w];
        let mut c = a;
        while c < b {
            let zc = self.zone_of_col[c];
            let e = self.zone_col_end[zc as usize].min(b);
            let z = zr + zc as usize;
            let lut = if upper_row(r, self.mix[z].2) {
                &self.luts_upper[z]
            } else {
                &self.luts[z]
            };
            // Eight pixels at a time: all-off words stay, all-on words take the full gray,
            // others go through the table pixel by pixel.
            let full = lut[255];
            let mut i = c;
            while i + 8 <= e {
                let chunk = &mut row[i..i + 8];
                let word = u64::from_ne_bytes((&*chunk).try_into().expect("8 bytes"));
                if word == u64::MAX {
                    chunk.copy_from_slice(&[full; 8]);
                } else if word != 0 {
                    chunk.iter_mut().for_each(|v| *v = lut[*v as usize]);
                }
                i += 8;
            }
            row[i..e].iter_mut().for_each(|v| *v = lut[*v as usize]);
            c = e;
        }
    }

    /// Pixel mode without dithering, row `r`, columns [a, b): edge pixels (0 < v < 255)
    /// are looked up first, then full pixels take the precomputed gray in one branch-free
    /// pass, then the edge grays are written.
    fn pixel_row(&self, m: &mut Mask, r: usize, a: usize, b: usize) {
        let lv = &self.levels;
        let span = r * self.w + a..r * self.w + b;
        let data = &mut m.data[span.clone()];
        let full = &self.full[span.clone()];
        let fidx = &self.full_idx[span.clone()];
        let t = &self.t[span];
        EDGES.with(|e| {
            let mut e = e.borrow_mut();
            e.clear();
            let mut edge = |i: usize, v: u8| {
                let target = v as f64 / 255.0 * t[i] as f64;
                e.push((i, lv.gray[lv.nearest_from(fidx[i] as usize, target)]));
            };
            // Eight bytes at a time: all-off and all-on words hold no edge pixel.
            let mut i = 0;
            while i + 8 <= data.len() {
                let word = u64::from_ne_bytes(data[i..i + 8].try_into().expect("8 bytes"));
                if word != 0 && word != u64::MAX {
                    for (k, &v) in data[i..i + 8].iter().enumerate() {
                        if v != 0 && v != 255 {
                            edge(i + k, v);
                        }
                    }
                }
                i += 8;
            }
            for (k, &v) in data[i..].iter().enumerate() {
                if v != 0 && v != 255 {
                    edge(i + k, v);
                }
            }
            for (d, &f) in data.iter_mut().zip(full) {
                *d = if *d == 255 { f } else { *d };
            }
            for &(i, g) in e.iter() {
                data[i] = g;
            }
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
        let mut m = Mask {
            width: self.w as u32,
            height: self.h as u32,
            data: vec![255; self.w * self.h],
        };
        for r in 0..self.h {
            match self.mode {
                Mode::Zone => self.zone_row(&mut m, r, 0, self.w),
                _ => self.pixel_row(&mut m, r, 0, self.w),
            }
        }
        m
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
    fn lit_span_and_row_pattern() {
        for n in [1usize, 7, 8, 9, 23, 64, 1024] {
            assert_eq!(lit_span(&vec![0u8; n]), None);
            for a in 0..n.min(20) {
                for b in a..n.min(a + 19) {
                    let mut row = vec![0u8; n];
                    row[a] = 3;
                    row[b] = 9;
                    assert_eq!(lit_span(&row), Some((a, b)), "n {n} a {a} b {b}");
                }
            }
        }
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
