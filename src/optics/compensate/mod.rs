//! Applying a calibration: coverage → gray, per zone or per pixel.
//!
//! Everything that depends only on the calibration and the field is computed once per job
//! in [`Compensator::new`]: P at every pixel centre, the target E*, and either one
//! 256-entry lookup table per zone (zone mode) or the full-coverage gray, its level index
//! and E*/P per pixel (pixel mode). The rasterizer then applies it while it writes each
//! layer's mask (the compensator is its [`crate::raster::CoverageMap`], see
//! [`crate::raster::Rasterizer::render`]), or [`Compensator::apply`] rewrites a finished
//! coverage mask in place, touching only lit pixels; both give the same bytes:
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
use crate::raster::{map_words, Mask};
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
    /// The full-coverage gray of every pixel (both modes; the gray map), as distinct rows
    /// (`w` bytes each) and the index of each image row's: in zone mode a row is one gray
    /// per zone segment, so rows repeat (about 15 distinct rows per zone row, instead of a
    /// w × h map to allocate and fill); in pixel mode every row is its own.
    gray_rows: Vec<u8>,
    gray_row_of: Vec<u32>,
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

/// (max − min) / mean of values added one by one, %.
#[derive(Debug, Clone, Copy)]
struct Spread {
    lo: f64,
    hi: f64,
    sum: f64,
    n: usize,
}

impl Spread {
    fn new() -> Spread {
        Spread {
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
            sum: 0.0,
            n: 0,
        }
    }

    /// Adds `x` (plain comparisons, one instruction each where `f64::min` is several;
    /// like it, they skip NaN).
    #[inline(always)]
    fn add(&mut self, x: f64) {
        self.lo = if x < self.lo { x } else { self.lo };
        self.hi = if x > self.hi { x } else { self.hi };
        self.sum += x;
        self.n += 1;
    }

    /// The extremes part of adding `v as f64 * s` for values `v` whose smallest is `lo`
    /// and largest `hi`: rounding is monotone, so the product of the smallest value is the
    /// smallest product (largest for negative `s`). The sum and count are added by the
    /// caller ([`pixel_spreads`]).
    #[inline]
    fn add_extremes(&mut self, lo: f32, hi: f32, s: f64) {
        let (a, b) = (lo as f64 * s, hi as f64 * s);
        self.lo = self.lo.min(a.min(b));
        self.hi = self.hi.max(a.max(b));
    }

    fn pct(&self) -> f64 {
        if self.n == 0 {
            return 0.0;
        }
        (self.hi - self.lo) / (self.sum / self.n as f64) * 100.0
    }
}

fn spread(v: impl Iterator<Item = f64>) -> f64 {
    let mut s = Spread::new();
    v.for_each(|x| s.add(x));
    s.pct()
}

/// The runs of equal values of a non-decreasing `zone_of_col`: (zone column, first
/// column, end column).
fn zone_segments(zone_of_col: &[u16]) -> Vec<(usize, usize, usize)> {
    let mut out: Vec<(usize, usize, usize)> = Vec::new();
    for (c, &z) in zone_of_col.iter().enumerate() {
        match out.last_mut() {
            Some(l) if l.0 == z as usize => l.2 = c + 1,
            _ => out.push((z as usize, c, c + 1)),
        }
    }
    out
}

/// Whether every f64 sum of `n` f32 values from `lo` to `hi` (all positive, normal, finite)
/// is exact, whatever the order of the additions: each value is then a whole multiple of
/// the unit in the last place of `lo`'s binade, q = 2^(e_lo − 23), and every partial sum a
/// whole multiple of q below n · 2^(e_hi + 1), which f64 holds exactly if that is at most
/// 2^53 · q.
fn sums_are_exact(lo: f32, hi: f32, n: usize) -> bool {
    if !(lo >= f32::MIN_POSITIVE && hi.is_finite() && lo <= hi) {
        return false;
    }
    let e = |v: f32| (v.to_bits() >> 23) as usize;
    let log2n = (usize::BITS - n.saturating_sub(1).leading_zeros()) as usize;
    log2n + e(hi) - e(lo) + 24 <= 53
}

/// The f64 sum of f32 values and their smallest and largest (plain comparisons, which
/// skip NaN), in four lanes. The sum is the same as adding them one by one only when every
/// sum of them is exact ([`sums_are_exact`]); the extremes are the same except, possibly,
/// which of +0 and −0 is the smallest or largest.
#[inline(always)]
fn stats_lanes(vals: &[f32]) -> (f64, f32, f32) {
    let mut acc = [0f64; 4];
    let (mut lo, mut hi) = ([f32::INFINITY; 4], [f32::NEG_INFINITY; 4]);
    let mut chunks = vals.chunks_exact(4);
    for c in &mut chunks {
        for k in 0..4 {
            let v = c[k];
            acc[k] += v as f64;
            lo[k] = if v < lo[k] { v } else { lo[k] };
            hi[k] = if v > hi[k] { v } else { hi[k] };
        }
    }
    finish_stats(&acc, &lo, &hi, chunks.remainder())
}

/// [`stats_lanes`] with AVX2 (eight lanes, the last ones masked): the same sum when it is
/// exact, the same extremes (VMINPS/VMAXPS compare like the plain comparisons).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn stats_avx2(vals: &[f32]) -> (f64, f32, f32) {
    use std::arch::x86_64::*;
    let (mut s0, mut s1) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    let (inf, ninf) = (
        _mm256_set1_ps(f32::INFINITY),
        _mm256_set1_ps(f32::NEG_INFINITY),
    );
    let (mut lo, mut hi) = (inf, ninf);
    let mut chunks = vals.chunks_exact(8);
    for c in &mut chunks {
        // SAFETY: `c` holds eight f32.
        let v = unsafe { _mm256_loadu_ps(c.as_ptr()) };
        s0 = _mm256_add_pd(s0, _mm256_cvtps_pd(_mm256_castps256_ps128(v)));
        s1 = _mm256_add_pd(s1, _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v)));
        // VMINPS a, b = a < b ? a : b.
        lo = _mm256_min_ps(v, lo);
        hi = _mm256_max_ps(v, hi);
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        // The last 1 to 7 values: the other lanes load +0 (adding nothing to the sums)
        // and take ±∞ for the extremes.
        let mask = _mm256_cmpgt_epi32(
            _mm256_set1_epi32(rest.len() as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        );
        // SAFETY: only the lanes of `mask` (the first `rest.len()`) are read.
        let v = unsafe { _mm256_maskload_ps(rest.as_ptr(), mask) };
        s0 = _mm256_add_pd(s0, _mm256_cvtps_pd(_mm256_castps256_ps128(v)));
        s1 = _mm256_add_pd(s1, _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v)));
        let m = _mm256_castsi256_ps(mask);
        lo = _mm256_min_ps(_mm256_blendv_ps(inf, v, m), lo);
        hi = _mm256_max_ps(_mm256_blendv_ps(ninf, v, m), hi);
    }
    // Horizontal: lanes 0–3 with 4–7, then pairs, then the last two.
    let s = _mm256_add_pd(s0, s1);
    let s = _mm_add_pd(_mm256_castpd256_pd128(s), _mm256_extractf128_pd::<1>(s));
    let sum = _mm_cvtsd_f64(_mm_add_sd(s, _mm_unpackhi_pd(s, s)));
    let l = _mm_min_ps(_mm256_castps256_ps128(lo), _mm256_extractf128_ps::<1>(lo));
    let l = _mm_min_ps(l, _mm_movehl_ps(l, l));
    let l = _mm_cvtss_f32(_mm_min_ss(l, _mm_shuffle_ps::<1>(l, l)));
    let h = _mm_max_ps(_mm256_castps256_ps128(hi), _mm256_extractf128_ps::<1>(hi));
    let h = _mm_max_ps(h, _mm_movehl_ps(h, h));
    let h = _mm_cvtss_f32(_mm_max_ss(h, _mm_shuffle_ps::<1>(h, h)));
    (sum, l, h)
}

/// Combines the lanes of [`stats_lanes`] and adds the values left over.
#[inline(always)]
fn finish_stats(acc: &[f64], lo: &[f32], hi: &[f32], rest: &[f32]) -> (f64, f32, f32) {
    let mut sum = acc.iter().fold(0.0, |s, &a| s + a);
    for &v in rest {
        sum += v as f64;
    }
    let (mut l, mut h) = min_max(rest);
    for (&a, &b) in lo.iter().zip(hi) {
        l = if a < l { a } else { l };
        h = if b > h { b } else { h };
    }
    (sum, l, h)
}

/// Smallest and largest of `vals` (plain comparisons, which skip NaN).
#[inline]
fn min_max(vals: &[f32]) -> (f32, f32) {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for &v in vals {
        lo = if v < lo { v } else { lo };
        hi = if v > hi { v } else { hi };
    }
    (lo, hi)
}

/// What the set-up's pass over P gives ([`field_sums`]).
struct FieldSums {
    /// Sum of P over each zone, and the zone's pixel count.
    zsum: Vec<f64>,
    zcnt: Vec<usize>,
    /// Sum of P over the calibrated area.
    inside_sum: f64,
    /// Per row of the calibrated area and zone segment (`segs`) cut to it: the sum of P,
    /// and its smallest and largest value (row-major; empty cuts included).
    seg_sums: Vec<f64>,
    seg_extremes: Vec<(f32, f32)>,
}

/// Where the set-up reads P: row by row from the model (zone mode), or from the whole
/// field's values (pixel mode, which keeps them for its per-pixel tables).
enum PSource<'a> {
    Rows(FieldRows<'a>),
    Field(&'a [f32]),
}

impl PSource<'_> {
    /// Another source of the same values, for a pass over other rows.
    fn split(&self) -> Self {
        match self {
            PSource::Rows(rows) => PSource::Rows(rows.clone()),
            PSource::Field(pp) => PSource::Field(pp),
        }
    }

    /// P at the pixel centres of image row `r` into `row` (`AVX2`: see [`FieldRows::row`]).
    #[inline(always)]
    fn row<const AVX2: bool>(&mut self, r: usize, row: &mut [f32]) {
        match self {
            PSource::Rows(rows) => rows.row::<AVX2>(r, row),
            PSource::Field(pp) => row.copy_from_slice(&pp[r * row.len()..(r + 1) * row.len()]),
        }
    }
}

/// [`field_sums_with`], with AVX2 when the CPU has it.
fn field_sums(
    src: &mut PSource,
    w: usize,
    segs: &[(usize, usize, usize)],
    zone_of_row: &[u16],
    zcols: usize,
    inside: [usize; 4],
) -> FieldSums {
    #[cfg(target_arch = "x86_64")]
    let avx2 = std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    let avx2 = false;
    field_sums_with(avx2, src, w, segs, zone_of_row, zcols, inside)
}

/// The set-up's pass over P (rows from `src`): the sum of P over every zone and over the
/// calibrated area `inside` = [r0, r1, c0, c1) (half-open), and per row and zone segment
/// of that area the sum and extremes of P (for the per-pixel spreads).
///
/// The sums add f32 values in f64. When every such sum is exact ([`sums_are_exact`],
/// checked on the field's extremes: true for any real calibration) the order of the
/// additions does not matter (the zone sums are those of adding the values one by one in
/// row-major order, bit for bit): the top and bottom halves of the field are then summed
/// side by side (rayon) and their sums added, the values four or eight at a time;
/// otherwise a second pass adds them one by one in row-major order. `avx2` (only where
/// the CPU has it): the same operations on wider vectors (no fused multiply-add), so the
/// same bits.
fn field_sums_with(
    avx2: bool,
    src: &mut PSource,
    w: usize,
    segs: &[(usize, usize, usize)],
    zone_of_row: &[u16],
    zcols: usize,
    inside: [usize; 4],
) -> FieldSums {
    let nz = zone_of_row
        .iter()
        .map(|&z| z as usize + 1)
        .max()
        .unwrap_or(1)
        * zcols;
    let mut zcnt = vec![0usize; nz];
    for &zr in zone_of_row {
        for &(zc, a, b) in segs {
            zcnt[zr as usize * zcols + zc] += b - a;
        }
    }
    let h = zone_of_row.len();
    let geo = PassGeometry {
        w,
        segs,
        zone_of_row,
        zcols,
        inside,
        nz,
    };
    let run = |src: &mut PSource, rows: std::ops::Range<usize>, exact: bool| {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is true only where the CPU has AVX2.
            return unsafe { pass_avx2(src, &geo, rows, exact) };
        }
        pass_in::<false>(src, &geo, rows, exact)
    };
    let mid = h / 2;
    let mut other = src.split();
    let (top, bottom) = rayon::join(|| run(src, 0..mid, true), || run(&mut other, mid..h, true));
    let mut p = top;
    for (a, b) in p.zsum.iter_mut().zip(&bottom.zsum) {
        *a += b;
    }
    p.inside_sum += bottom.inside_sum;
    p.seg_sums.extend_from_slice(&bottom.seg_sums);
    p.seg_extremes.extend_from_slice(&bottom.seg_extremes);
    let (lo, hi) = (p.lo.min(bottom.lo), p.hi.max(bottom.hi));
    let exact = sums_are_exact(lo, hi, w * h)
        && p.inside_sum.is_finite()
        && p.zsum.iter().all(|s| s.is_finite());
    if !exact {
        p = run(src, 0..h, false);
    }
    FieldSums {
        zsum: p.zsum,
        zcnt,
        inside_sum: p.inside_sum,
        seg_sums: p.seg_sums,
        seg_extremes: p.seg_extremes,
    }
}

/// What a pass over rows of the field works on ([`field_sums_with`]).
struct PassGeometry<'a> {
    w: usize,
    segs: &'a [(usize, usize, usize)],
    zone_of_row: &'a [u16],
    zcols: usize,
    inside: [usize; 4],
    nz: usize,
}

/// The sums and extremes of a pass over some rows ([`pass_in`]).
struct Pass {
    zsum: Vec<f64>,
    inside_sum: f64,
    seg_sums: Vec<f64>,
    seg_extremes: Vec<(f32, f32)>,
    /// Smallest and largest P of those rows (exact passes only).
    lo: f32,
    hi: f32,
}

/// [`pass_in`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn pass_avx2(
    src: &mut PSource,
    geo: &PassGeometry,
    rows: std::ops::Range<usize>,
    exact: bool,
) -> Pass {
    pass_in::<true>(src, geo, rows, exact)
}

/// One pass over image rows `rows` of P (see [`field_sums_with`]): `exact`: each row
/// segment's values summed four or eight at a time (exact sums only), otherwise one by
/// one in row-major order. `AVX2`: true only when called from [`pass_avx2`].
#[inline(always)]
fn pass_in<const AVX2: bool>(
    src: &mut PSource,
    geo: &PassGeometry,
    rows: std::ops::Range<usize>,
    exact: bool,
) -> Pass {
    let &PassGeometry {
        w,
        segs,
        zone_of_row,
        zcols,
        inside: [r0, r1, c0, c1],
        nz,
    } = geo;
    let mut buf = vec![0f32; w];
    let n_in = (r1.min(rows.end)).saturating_sub(r0.max(rows.start)) * segs.len();
    let mut zsum = vec![0f64; nz];
    let mut inside_sum = 0.0f64;
    let mut seg_sums = Vec::with_capacity(n_in);
    let mut seg_extremes = Vec::with_capacity(n_in);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for r in rows {
        src.row::<AVX2>(r, &mut buf);
        let zr = zone_of_row[r] as usize * zcols;
        let inside_row = (r0..r1).contains(&r);
        for &(zc, a, b) in segs {
            // Columns a..ia and ib..b are outside the calibrated area.
            let (ia, ib) = if inside_row {
                let ia = a.max(c0).min(b);
                (ia, b.min(c1).max(ia))
            } else {
                (b, b)
            };
            let acc = &mut zsum[zr + zc];
            let (ins, ilo, ihi) = if exact {
                let stats = |v: &[f32]| {
                    #[cfg(target_arch = "x86_64")]
                    if AVX2 {
                        // SAFETY: AVX2 is true only in `pass_avx2`, which runs on CPUs
                        // with AVX2.
                        return unsafe { stats_avx2(v) };
                    }
                    stats_lanes(v)
                };
                // (Most rows lie inside the area, or outside it: skip empty parts.)
                let none = (0.0, f32::INFINITY, f32::NEG_INFINITY);
                let (sa, la, ha) = if a < ia { stats(&buf[a..ia]) } else { none };
                let (si, li, hi_) = if ia < ib { stats(&buf[ia..ib]) } else { none };
                let (sb, lb, hb) = if ib < b { stats(&buf[ib..b]) } else { none };
                *acc += sa + si + sb;
                inside_sum += si;
                lo = lo.min(la).min(li).min(lb);
                hi = hi.max(ha).max(hi_).max(hb);
                (si, li, hi_)
            } else {
                let mut ins = 0.0;
                for &v in &buf[a..ia] {
                    *acc += v as f64;
                }
                for &v in &buf[ia..ib] {
                    *acc += v as f64;
                    inside_sum += v as f64;
                    ins += v as f64;
                }
                for &v in &buf[ib..b] {
                    *acc += v as f64;
                }
                let (l, h) = min_max(&buf[ia..ib]);
                (ins, l, h)
            };
            if inside_row {
                seg_sums.push(ins);
                seg_extremes.push((ilo, ihi));
            }
        }
    }
    Pass {
        zsum,
        inside_sum,
        seg_sums,
        seg_extremes,
        lo,
        hi,
    }
}

/// The per-pixel spread over the calibrated area when the pixels of row r of zone column
/// zc show S = `s_of(r, zc)`: the extremes of P · S from each row segment's extremes
/// (rounding is monotone), the mean from each row segment's sum of P ([`FieldSums`]).
fn pixel_spread(
    fs: &FieldSums,
    segs: &[(usize, usize, usize)],
    [r0, r1, c0, c1]: [usize; 4],
    s_of: impl Fn(usize, usize) -> f64,
) -> f64 {
    // The segments that reach into the area: (index in the row, zone column, pixels).
    let cut: Vec<(usize, usize, usize)> = segs
        .iter()
        .enumerate()
        .filter_map(|(j, &(zc, a, b))| {
            let n = b.min(c1).saturating_sub(a.max(c0));
            (n > 0).then_some((j, zc, n))
        })
        .collect();
    let mut sp = Spread::new();
    for (r, (sums, extremes)) in (r0..r1).zip(
        fs.seg_sums
            .chunks_exact(segs.len())
            .zip(fs.seg_extremes.chunks_exact(segs.len())),
    ) {
        for &(j, zc, n) in &cut {
            let s = s_of(r, zc);
            let (lo, hi) = extremes[j];
            sp.add_extremes(lo, hi, s);
            sp.sum += sums[j] * s;
            sp.n += n;
        }
    }
    sp.pct()
}

/// The zones of `field`: `zone_mm` squares from the bottom-left corner; a pixel belongs to
/// the zone holding its centre. Returns each image column's zone column, each image row's
/// zone row (zone rows top first, like the image), and the numbers of zone columns and rows.
fn zone_geometry(field: &Field, zmm: f64) -> (Vec<u16>, Vec<u16>, usize, usize) {
    let (w, h, p) = (
        field.width_px as usize,
        field.height_px as usize,
        field.pixel_mm,
    );
    let zcols = ((field.width_mm() / zmm) - 1e-9).ceil().max(1.0) as usize;
    let zrows = ((field.height_mm() / zmm) - 1e-9).ceil().max(1.0) as usize;
    let zone_of_col = (0..w)
        .map(|c| (((c as f64 + 0.5) * p / zmm) as usize).min(zcols - 1) as u16)
        .collect();
    let zone_of_row = (0..h)
        .map(|r| {
            let zb = (((h as f64 - r as f64 - 0.5) * p / zmm) as usize).min(zrows - 1);
            (zrows - 1 - zb) as u16
        })
        .collect();
    (zone_of_col, zone_of_row, zcols, zrows)
}

/// P at the pixel centres of the field, one row at a time (no w × h buffer). Inside the
/// polynomial's rectangle: Horner in u with the row's coefficients (in f64, rounded to f32,
/// times the scale in f32); elsewhere [`FieldModel::eval`] rounded to f32 (its linear
/// continuation from the polynomial's value and gradient at the nearest point of the
/// rectangle, computed once per column for the rows above and below it, once per row
/// for the columns left and right of it).
#[derive(Clone)]
struct FieldRows<'a> {
    fm: &'a FieldModel,
    h: usize,
    p: f64,
    /// Per column: the clamped x minus its nearest point of the rectangle, mm, and u
    /// there.
    dx: Vec<f64>,
    u: Vec<f64>,
    /// Whether every u is finite.
    finite_u: bool,
    /// The columns inside the rectangle: one contiguous run [ua, ub).
    ua: usize,
    ub: usize,
    /// Value and gradient of the polynomial along the rectangle's bottom and top edges,
    /// per column (computed when first needed).
    edge: [Vec<[f64; 3]>; 2],
}

impl<'a> FieldRows<'a> {
    fn new(fm: &'a FieldModel, field: &Field) -> FieldRows<'a> {
        let w = field.width_px as usize;
        let p = field.pixel_mm;
        let m = fm.extrapolate_mm.get();
        let [x0, _, x1, _] = fm.area_mm;
        let [px0, _, px1, _] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
        let s = 1.0 / fm.length_unit_mm.get();
        let (mut dx, mut u) = (Vec::with_capacity(w), Vec::with_capacity(w));
        for c in 0..w {
            let xc = ((c as f64 + 0.5) * p).clamp(x0 - m, x1 + m);
            let xp = xc.clamp(px0, px1);
            dx.push(xc - xp);
            u.push((xp - fm.origin_mm[0]) * s);
        }
        // Columns with xp == xc (dx == 0 also for xp == xc == −0.0, which cannot differ).
        let inside = |c: usize| {
            let xc = ((c as f64 + 0.5) * p).clamp(x0 - m, x1 + m);
            xc >= px0 && xc <= px1
        };
        let ua = (0..w).position(inside).unwrap_or(w);
        let ub = (0..w).rposition(inside).map_or(ua, |i| i + 1);
        debug_assert!((ua..ub).all(inside));
        FieldRows {
            fm,
            h: field.height_px as usize,
            p,
            dx,
            finite_u: u.iter().all(|x| x.is_finite()),
            u,
            ua,
            ub,
            edge: [Vec::new(), Vec::new()],
        }
    }

    /// P at the pixel centres of image row `r` (row 0 = top) into `row` (`w` values).
    /// `AVX2`: true only where the CPU has AVX2 (inlined into [`pass_avx2`]); the
    /// same values either way.
    #[inline(always)]
    fn row<const AVX2: bool>(&mut self, r: usize, row: &mut [f32]) {
        let fm = self.fm;
        let m = fm.extrapolate_mm.get();
        let [_, y0, _, y1] = fm.area_mm;
        let [_, py0, _, py1] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
        let s = 1.0 / fm.length_unit_mm.get();
        let (ua, ub) = (self.ua, self.ub);
        let y = (self.h as f64 - r as f64 - 0.5) * self.p;
        let yc = y.clamp(y0 - m, y1 + m);
        let yp = yc.clamp(py0, py1);
        let v = (yp - fm.origin_mm[1]) * s;
        let dy = yc - yp;
        let (dx, u) = (&self.dx, &self.u);
        if yp == yc {
            let a = fm.coefficients.in_u(v);
            let from_top = self.finite_u && a.last().is_some_and(|&c| c.is_finite() && c != 0.0);
            let seg = &mut row[ua..ub];
            let scf = fm.scale.get() as f32;
            // Separate passes: exp must not be evaluated (speculatively) for polynomials.
            let horner = |seg: &mut [f32], scale: f32| {
                #[cfg(target_arch = "x86_64")]
                if AVX2 {
                    // SAFETY: AVX2 is true only where the CPU has AVX2.
                    return unsafe { horner_avx2(seg, &u[ua..ub], &a, scale, from_top) };
                }
                horner_f32(seg, &u[ua..ub], &a, scale)
            };
            match fm.form {
                Form::Polynomial => horner(seg, scf),
                Form::Exponential => {
                    horner(seg, 1.0);
                    seg.iter_mut().for_each(|o| *o = scf * o.exp())
                }
                Form::InverseSquare => {
                    horner(seg, 1.0);
                    seg.iter_mut().for_each(|o| *o = scf / (*o * *o))
                }
            }
            // Left and right of the rectangle: one nearest point per side (both sides
            // in one run if the rectangle lies between two pixel centres).
            let mut g = (f64::NAN, [0.0; 3]);
            for c in (0..ua).chain(ub..row.len()) {
                if u[c].to_bits() != g.0.to_bits() {
                    let (f, fu, fv) = fm.coefficients.eval_grad(u[c], v);
                    g = (u[c], [f, fu, fv]);
                }
                row[c] = fm.continued(g.1, dx[c], dy) as f32;
            }
        } else {
            // Above or below the rectangle: the nearest point of each column is on its
            // top or bottom edge.
            let side = (yp == py1) as usize;
            let edge = &mut self.edge[side];
            if edge.is_empty() {
                *edge = u
                    .iter()
                    .map(|&uc| {
                        let (f, fu, fv) = fm.coefficients.eval_grad(uc, v);
                        [f, fu, fv]
                    })
                    .collect();
            }
            if fm.form == Form::Polynomial {
                // `continued` written out (the same operations; a loop the compiler
                // vectorizes): scale · max(f + (fu·dx + fv·dy)·s, f/10).
                let scale = fm.scale.get();
                for ((o, &[f, fu, fv]), &d) in row.iter_mut().zip(edge.iter()).zip(dx) {
                    let lin = f + (fu * d + fv * dy) * s;
                    *o = (scale * lin.max(0.1 * f)) as f32;
                }
            } else {
                for ((o, &g), &d) in row.iter_mut().zip(edge.iter()).zip(dx) {
                    *o = fm.continued(g, d, dy) as f32;
                }
            }
        }
    }
}

/// `out[i]` = the polynomial with coefficients `a` (constant first) at `us[i]` by Horner's
/// rule in f64 (from 0: 0·u + a_n, …), rounded to f32, times `scale` in f32 (1 is exact);
/// four lanes at a time.
#[inline(always)]
fn horner_f32(out: &mut [f32], us: &[f64], a: &[f64], scale: f32) {
    #[inline(always)]
    fn lanes<const N: usize>(o: &mut [f32], u: &[f64], a: &[f64], scale: f32) {
        let mut acc = [0f64; N];
        for &k in a.iter().rev() {
            for l in 0..N {
                acc[l] = acc[l] * u[l] + k;
            }
        }
        for l in 0..N {
            o[l] = acc[l] as f32 * scale;
        }
    }
    let mut oc = out.chunks_exact_mut(4);
    let mut uc = us.chunks_exact(4);
    match <[f64; 4]>::try_from(a) {
        // A cubic (the common case): coefficients known to the unrolled loop.
        Ok(a4) => {
            for (o, u) in (&mut oc).zip(&mut uc) {
                lanes::<4>(o, u, &a4, scale);
            }
        }
        Err(_) => {
            for (o, u) in (&mut oc).zip(&mut uc) {
                lanes::<4>(o, u, a, scale);
            }
        }
    }
    for (o, u) in oc.into_remainder().iter_mut().zip(uc.remainder()) {
        lanes::<1>(std::slice::from_mut(o), std::slice::from_ref(u), a, scale);
    }
}

/// [`horner_f32`] with AVX2 (four f64 lanes; the same multiplications and additions, not
/// fused, and the same roundings to f32, so the same values). `from_top`: every u is
/// finite and the highest coefficient finite and nonzero, so Horner's first step
/// (0·u + a_n) gives a_n exactly and is left out.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn horner_avx2(out: &mut [f32], us: &[f64], a: &[f64], scale: f32, from_top: bool) {
    use std::arch::x86_64::*;
    #[target_feature(enable = "avx2")]
    #[inline]
    fn run<const N: usize, const TOP: bool>(
        out: &mut [f32],
        us: &[f64],
        a: &[f64],
        scale: f32,
    ) -> usize {
        let mut k = [_mm256_setzero_pd(); super::field::MAX_DEGREE + 1];
        for (k, &c) in k.iter_mut().zip(a.iter().rev()) {
            *k = _mm256_set1_pd(c);
        }
        let k = &k[..if N > 0 { N } else { a.len() }];
        let sc = _mm_set1_ps(scale);
        let n = out.len().min(us.len()) / 4 * 4;
        for (o, u) in out[..n].chunks_exact_mut(4).zip(us.chunks_exact(4)) {
            // SAFETY: `u` holds four f64.
            let u = unsafe { _mm256_loadu_pd(u.as_ptr()) };
            let (mut acc, rest) = if TOP {
                (k[0], &k[1..])
            } else {
                (_mm256_setzero_pd(), k)
            };
            for &k in rest {
                acc = _mm256_add_pd(_mm256_mul_pd(acc, u), k);
            }
            let f = _mm_mul_ps(_mm256_cvtpd_ps(acc), sc);
            // SAFETY: `o` holds four f32.
            unsafe { _mm_storeu_ps(o.as_mut_ptr(), f) };
        }
        n
    }
    // A cubic's four coefficients as a fixed count (unrolled).
    let n = match (a.len() == 4, from_top && !a.is_empty()) {
        (true, true) => run::<4, true>(out, us, a, scale),
        (true, false) => run::<4, false>(out, us, a, scale),
        (false, true) => run::<0, true>(out, us, a, scale),
        (false, false) => run::<0, false>(out, us, a, scale),
    };
    horner_f32(&mut out[n..], &us[n..], a, scale);
}

/// P at every pixel centre of the field (row-major, top row first); see [`FieldRows`].
fn pixel_p(fm: &FieldModel, field: &Field) -> Vec<f32> {
    let w = field.width_px as usize;
    let mut rows = FieldRows::new(fm, field);
    let mut out = vec![0f32; w * field.height_px as usize];
    for (r, row) in out.chunks_exact_mut(w).enumerate() {
        rows.row::<false>(r, row);
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

        // P: pixel mode keeps it for the whole field (its per-pixel tables need it); zone
        // mode evaluates it row by row in its one pass over the field (no w × h buffer to
        // allocate and fill).
        let pp = if mode == Mode::Pixel {
            pixel_p(fm, field)
        } else {
            Vec::new()
        };
        let mut src = if pp.is_empty() {
            PSource::Rows(FieldRows::new(fm, field))
        } else {
            PSource::Field(&pp)
        };
        debug_assert!({
            let (c, r) = (w / 3, h / 3);
            let direct = fm.eval((c as f64 + 0.5) * p, (h as f64 - r as f64 - 0.5) * p);
            let mut row = vec![0f32; w];
            src.row::<false>(r, &mut row);
            ((row[c] as f64) - direct).abs() <= 1e-5 * direct.abs().max(1e-30)
        });

        let zmm = cal.zone_mm.get();
        let (zone_of_col, zone_of_row, zcols, zrows) = zone_geometry(field, zmm);
        let nz = zcols * zrows;
        let segs = zone_segments(&zone_of_col);
        let inside = [r0, r1 + 1, c0, c1 + 1];
        let fs = field_sums(&mut src, w, &segs, &zone_of_row, zcols, inside);
        let (zsum, zcnt, inside_sum) = (&fs.zsum, fs.zcnt.as_slice(), fs.inside_sum);
        let mean = inside_sum / pixels_inside as f64 * s_max;
        let zone_p: Vec<f64> = zsum
            .iter()
            .zip(zcnt)
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
            gray_rows: Vec::new(),
            gray_row_of: Vec::new(),
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
                    before_pixel_pct: pixel_spread(&fs, &segs, inside, |_, _| s_max),
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
                // v / 255 for each coverage value v.
                let coverage: [f64; 256] = std::array::from_fn(|v| v as f64 / 255.0);
                let mut mix = vec![(0u8, 0u8, 0u8); nz];
                let mut zone_after = vec![0.0; nz];
                for z in 0..nz {
                    let pz = zone_p[z];
                    let tz = if pz > 0.0 { target / pz } else { f64::INFINITY };
                    if tz > s_max * (1.0 + 1e-9) {
                        unreachable += 1;
                    }
                    if tz >= 0.0 {
                        // Targets grow with v: walk the level thresholds upwards (the
                        // same levels as `nearest`'s search, in one pass per zone).
                        let (mid, lut) = (&lv.mid[..], &mut luts[z]);
                        let mut i = 0;
                        for v in 1..256 {
                            let t = coverage[v] * tz;
                            while i < mid.len() && mid[i] <= t {
                                i += 1;
                            }
                            lut[v] = lv.gray[i];
                        }
                    } else {
                        for (v, out) in luts[z].iter_mut().enumerate().skip(1) {
                            *out = lv.gray[lv.nearest(v as f64 / 255.0 * tz)];
                        }
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
                let zone_of_row = &comp.zone_of_row;
                let after_pixel = pixel_spread(&fs, &segs, inside, |r, zc| {
                    let (g0, g1, k) = mix[zone_of_row[r] as usize * zcols + zc];
                    s_of(if upper_row(r, k) { g1 } else { g0 })
                });
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
                let mut row_tables: Vec<u32> = Vec::with_capacity(h * zcols);
                for (r, &zr) in zone_of_row.iter().enumerate() {
                    let zr = zr as usize * zcols;
                    for (z, (&(_, _, k), &u)) in
                        (zr..).zip(mix[zr..zr + zcols].iter().zip(&upper_idx[zr..zr + zcols]))
                    {
                        row_tables.push(if upper_row(r, k) { u } else { z as u32 });
                    }
                }
                // The full-coverage gray of every pixel: rows with the same tables have the
                // same grays. Tables belong to one zone, so only rows of the same zone row
                // can be the same, and there rows with the same r mod 64 are (`upper_row`):
                // a row new in its phase is looked for among the distinct rows of its zone
                // row; distinct rows are numbered in order of appearance.
                let mut gray_rows = Vec::new();
                let mut gray_row_of: Vec<u32> = Vec::with_capacity(h);
                // Distinct rows so far (index, first image row) of the current zone row,
                // and the index of each phase seen there.
                let mut in_zone_row: Vec<(u32, usize)> = Vec::new();
                let mut by_phase = [u32::MAX; 64];
                let mut next = 0u32;
                for r in 0..h {
                    if r > 0 && zone_of_row[r] != zone_of_row[r - 1] {
                        in_zone_row.clear();
                        by_phase = [u32::MAX; 64];
                    }
                    if by_phase[r & 63] != u32::MAX {
                        gray_row_of.push(by_phase[r & 63]);
                        continue;
                    }
                    let tabs = &row_tables[r * zcols..(r + 1) * zcols];
                    let found = in_zone_row
                        .iter()
                        .find(|&&(_, r0)| &row_tables[r0 * zcols..(r0 + 1) * zcols] == tabs);
                    let k = match found {
                        Some(&(k, _)) => k,
                        None => {
                            for &(zc, a, b) in &segs {
                                gray_rows.resize(
                                    gray_rows.len() + b - a,
                                    tables[tabs[zc] as usize][255],
                                );
                            }
                            in_zone_row.push((next, r));
                            next += 1;
                            next - 1
                        }
                    };
                    by_phase[r & 63] = k;
                    gray_row_of.push(k);
                }
                comp.gray_rows = gray_rows;
                comp.gray_row_of = gray_row_of;
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
                // The smallest P of the calibrated area: of its row segments' smallest.
                let pmin = fs.seg_extremes.iter().fold(f64::INFINITY, |m, &(lo, _)| {
                    if (lo as f64) < m {
                        lo as f64
                    } else {
                        m
                    }
                });
                let target = forced_target.unwrap_or(pmin * s_max);
                let mut unreachable = 0;
                let mut full = vec![0u8; w * h];
                let mut full_idx = vec![0u16; w * h];
                let mut t = vec![0f32; w * h];
                let mut idx = lv.gray.len() - 1;
                // Row by row: E*/P (divisions, vectorized), the nearest level searched from
                // the previous pixel's, then per zone P · S(level) added pixel by pixel in
                // row-major order (a zone's pixels in a row are one segment) and, over the
                // calibrated area, the spread after, also in row-major order. The gray sums
                // are exact in any order.
                let mut zs = vec![0f64; nz];
                let mut zg = vec![0u64; nz];
                let mut after_px = Spread::new();
                let mut ti_row = vec![0f64; w];
                let [ir0, ir1, ic0, ic1] = inside;
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
                    let zr = comp.zone_of_row[r] as usize * zcols;
                    let inside_row = (ir0..ir1).contains(&r);
                    for &(zc, a, b) in &segs {
                        let (ia, ib) = if inside_row {
                            let ia = a.max(ic0).min(b);
                            (ia, b.min(ic1).max(ia))
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
                let zone_after: Vec<f64> = (0..nz).map(|z| zs[z] / zcnt[z].max(1) as f64).collect();
                let zone_gray = (0..nz)
                    .map(|z| (zg[z] as f64 / zcnt[z].max(1) as f64).round() as u8)
                    .collect();
                let after_zone = spread((0..nz).filter(|&z| zone_inside[z]).map(|z| zone_after[z]));
                let after_pixel = after_px.pct();
                let pr = &mut comp.prediction;
                pr.target = target;
                pr.zone_gray = zone_gray;
                pr.zone_after = zone_after;
                pr.spreads.after_zone_pct = after_zone;
                pr.spreads.after_pixel_pct = after_pixel;
                pr.unreachable = unreachable;
                comp.gray_rows = full;
                comp.gray_row_of = (0..h as u32).collect();
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
    ///
    /// Returns whether the layer reaches outside the calibrated area (it is then counted
    /// in [`layers_outside`](Self::layers_outside)).
    pub fn apply_in(&self, m: &mut Mask, lit_box: [usize; 4]) -> bool {
        assert_eq!(
            (m.width as usize, m.height as usize),
            (self.w, self.h),
            "mask size differs from the field"
        );
        let w = self.w;
        let [br0, br1, bc0, bc1] = lit_box;
        let (br1, bc1) = (br1.min(self.h), bc1.min(w));
        if br0 >= br1 || bc0 >= bc1 {
            return false;
        }
        let outside = self.lit_outside(m, [br0, br1, bc0, bc1]);
        if outside {
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
        outside
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
        let full = &self.gray_row(r)[a..b];
        map_words(&mut row[a..b], full, |k, v| {
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
        map_words(&mut row[a..b], &self.gray_row(r)[a..b], |k, v| {
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

    /// Row `r` of the gray map (the full-coverage gray of each pixel).
    #[inline(always)]
    fn gray_row(&self, r: usize) -> &[u8] {
        let k = self.gray_row_of[r] as usize * self.w;
        &self.gray_rows[k..k + self.w]
    }

    /// The full-coverage gray of every pixel (what a plate covering the field gets, without
    /// error diffusion), in field orientation.
    pub fn gray_map(&self) -> Mask {
        let mut data = Vec::with_capacity(self.w * self.h);
        for r in 0..self.h {
            data.extend_from_slice(self.gray_row(r));
        }
        Mask {
            width: self.w as u32,
            height: self.h as u32,
            data,
        }
    }

    /// The gray map as projector `p` shows it ([`crate::raster::projector_view`]),
    /// encoded by `png`, which must give [`crate::png::encode_gray8`]'s bytes (the
    /// bundle's mask encoder): when `p` shows the field as it is, the map is encoded row by
    /// row with [`crate::png::encode_gray8_rows`] (the same bytes) without making it.
    pub fn gray_map_png(
        &self,
        p: &crate::profile::Projector,
        png: impl Fn(&Mask) -> Vec<u8>,
    ) -> Vec<u8> {
        let identity = p.offset_px == [0, 0]
            && p.width_px as usize == self.w
            && p.height_px as usize == self.h
            && !p.mirror_x
            && !p.mirror_y;
        if identity {
            let (w, h) = (self.w as u32, self.h as u32);
            crate::png::encode_gray8_rows(w, h, |r| self.gray_row(r))
        } else {
            let m = self.gray_map();
            png(&crate::raster::projector_view(&m, p))
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

/// One row of a [`Compensator`] as the rasterizer's scan uses it
/// ([`crate::raster::CoverageMap::row`]).
#[derive(Clone, Copy)]
pub struct CompRow<'a> {
    comp: &'a Compensator,
    r: usize,
    /// The row of the gray map (full coverage).
    full: &'a [u8],
    /// Zone mode: the row's table index of each zone column.
    tabs: &'a [u32],
    zone: bool,
}

/// The rasterizer applies the compensation while it writes a layer's mask
/// ([`crate::raster::Rasterizer::render`]), with the same values as
/// [`Compensator::apply_in`]: full coverage takes the gray map, other coverage the zone's
/// table (zone mode) or a search from the pixel's full-coverage level (pixel mode); the
/// scan reports layers lit outside the calibrated area (on the coverage, as
/// [`apply_in`](Compensator::apply_in) counts them). Not fused (the rasterizer calls
/// [`apply_in`](Compensator::apply_in) on the finished coverage): error diffusion (pixel
/// mode, `--dither on`), which reads the neighbours' coverage.
impl crate::raster::CoverageMap for Compensator {
    fn fusable(&self, _: [usize; 4]) -> bool {
        !(self.mode == Mode::Pixel && self.dither == Dither::On)
    }

    fn area(&self) -> [usize; 4] {
        let ([r0, r1], [c0, c1]) = (self.inside_rows, self.inside_cols);
        [r0, r1, c0, c1]
    }

    fn lit_outside(&self) {
        self.layers_outside.fetch_add(1, Ordering::Relaxed);
    }

    type Row<'a> = CompRow<'a>;

    #[inline(always)]
    fn row(&self, r: usize) -> CompRow<'_> {
        let zone = self.mode == Mode::Zone;
        CompRow {
            comp: self,
            r,
            full: self.gray_row(r),
            tabs: if zone {
                &self.row_tables[r * self.zcols..(r + 1) * self.zcols]
            } else {
                &[]
            },
            zone,
        }
    }

    #[inline(always)]
    fn fill(row: CompRow<'_>, dst: &mut [u8], a: usize, b: usize, v: u8) {
        let d = &mut dst[a..b];
        if v == 255 {
            let f = &row.full[a..b];
            if d.len() <= 8 {
                d.iter_mut().zip(f).for_each(|(x, &g)| *x = g);
            } else {
                d.copy_from_slice(f);
            }
        } else if row.zone {
            // One table per zone (and row): a run inside one zone is one value. The zone
            // of a column never decreases along the row.
            let (comp, tabs) = (row.comp, row.tabs);
            let zones = &comp.zone_of_col[a..b];
            let table = |z: u16| &comp.tables[tabs[z as usize] as usize];
            let (first, last) = (zones[0], zones[zones.len() - 1]);
            if first == last {
                let g = table(first)[v as usize];
                if d.len() == 1 {
                    d[0] = g;
                } else {
                    d.fill(g);
                }
            } else {
                for (x, &z) in d.iter_mut().zip(zones) {
                    *x = table(z)[v as usize];
                }
            }
        } else {
            let (comp, r) = (row.comp, row.r);
            let lv = &comp.levels;
            let f = v as f64 / 255.0;
            for (k, x) in d.iter_mut().enumerate() {
                let i = r * comp.w + a + k;
                let target = f * comp.t[i] as f64;
                *x = lv.gray[lv.nearest_from(comp.full_idx[i] as usize, target)];
            }
        }
    }

    fn apply(&self, m: &mut Mask, lit_box: [usize; 4]) -> bool {
        self.apply_in(m, lit_box)
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
    /// [`setup`]'s calibration measured on 40 × 26 mm only, over a 40 × 30 mm field of
    /// 0.2 mm pixels (so the top of the field lies outside the calibrated area).
    fn small_setup() -> (Calibration, Field) {
        let (mut cal, _) = setup();
        cal.field.area_mm = [0.0, 0.0, 40.0, 26.0];
        let field = Field {
            width_px: 200,
            height_px: 150,
            pixel_mm: 0.2,
        };
        (cal, field)
    }

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
    fn prediction_and_zone_tables_match_a_direct_computation() {
        // The set-up's pass (zone sums, mean, spreads) and its table walk must give what
        // the plain definitions give (adding P pixel by pixel in row-major order), also
        // when the calibrated area cuts through zones and rows (0.7 mm pixels: zone edges
        // fall inside pixel columns): exactly, except the per-pixel spreads' means, which
        // the set-up takes from exact sums (one rounding instead of one per pixel).
        let (mut cal, _) = setup();
        let field = Field {
            width_px: 57,
            height_px: 43,
            pixel_mm: 0.7,
        };
        for area in [[0.0, 0.0, 40.0, 30.0], [3.5, 2.2, 33.0, 27.5]] {
            cal.field.area_mm = area;
            let pp = pixel_p(&cal.field, &field);
            let (w, h, p) = (57usize, 43usize, 0.7);
            let inside = |i: usize| {
                let (x, y) = ((i % w) as f64 + 0.5, h as f64 - (i / w) as f64 - 0.5);
                let (x, y) = (x * p, y * p);
                x >= area[0] && x <= area[2] && y >= area[1] && y <= area[3]
            };
            for (mode, dither) in [
                (Mode::Zone, Dither::Auto),
                (Mode::Zone, Dither::On),
                (Mode::Zone, Dither::Off),
                (Mode::Pixel, Dither::Off),
            ] {
                let c = Compensator::new(&cal, &field, mode, dither).unwrap();
                let pr = &c.prediction;
                let what = format!("{area:?} {mode:?} {dither:?}");
                let (mut before, mut after) = (Spread::new(), Spread::new());
                let (mut sum, mut n) = (0.0f64, 0usize);
                for i in (0..w * h).filter(|&i| inside(i)) {
                    sum += pp[i] as f64;
                    n += 1;
                    before.add(pp[i] as f64 * pr.s_max);
                    after.add(pp[i] as f64 * c.s_of(c.gray_row(i / w)[i % w]));
                }
                assert_eq!(pr.mean, sum / n as f64 * pr.s_max, "{what}");
                let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
                assert!(close(pr.spreads.before_pixel_pct, before.pct()), "{what}");
                // Zone means: the sums of P added one by one in row-major order.
                let (mut zs, mut zn) = (vec![0f64; pr.zone_p.len()], vec![0usize; pr.zone_p.len()]);
                for (i, &v) in pp.iter().enumerate() {
                    let z = c.zone_of_row[i / w] as usize * c.zcols + c.zone_of_col[i % w] as usize;
                    zs[z] += v as f64;
                    zn[z] += 1;
                }
                for (z, &pz) in pr.zone_p.iter().enumerate() {
                    let want = if zn[z] > 0 {
                        zs[z] / zn[z] as f64
                    } else {
                        f64::NAN
                    };
                    assert_eq!(pz.to_bits(), want.to_bits(), "{what} zone {z}");
                }
                if mode == Mode::Pixel {
                    // Zone means after: P · S(gray) added pixel by pixel in row-major order.
                    let mut za = vec![0f64; pr.zone_p.len()];
                    for (i, &v) in pp.iter().enumerate() {
                        let z =
                            c.zone_of_row[i / w] as usize * c.zcols + c.zone_of_col[i % w] as usize;
                        za[z] += v as f64 * c.levels.s[c.full_idx[i] as usize];
                    }
                    for (z, &a) in pr.zone_after.iter().enumerate() {
                        let want = za[z] / zn[z].max(1) as f64;
                        assert_eq!(a.to_bits(), want.to_bits(), "{what} zone {z}");
                    }
                    continue;
                }
                assert!(close(pr.spreads.after_pixel_pct, after.pct()), "{what}");
                // Each zone's lower table: the nearest level to coverage × E*/P̄ (entry
                // 255 is the zone's full gray, which may mix two levels).
                let lv = &c.levels;
                for (z, &pz) in pr.zone_p.iter().enumerate() {
                    // A zone without pixels (NaN mean) cannot be reached.
                    let tz = if pz > 0.0 {
                        pr.target / pz
                    } else {
                        f64::INFINITY
                    };
                    for v in 1..255 {
                        let want = lv.gray[lv.nearest(v as f64 / 255.0 * tz)];
                        assert_eq!(c.tables[z][v], want, "{what} zone {z} v {v}");
                    }
                }
            }
        }
    }

    #[test]
    fn compensation_in_the_scan_equals_rasterize_then_apply() {
        // Fixed-seed random star polygons (some overlapping: the nonzero fallback; some
        // reaching above the calibrated area: the unfused path) on a 40 × 30 mm field of
        // 0.2 mm pixels, every mode, dithering and binary/anti-aliased: the mask drawn with
        // the compensation in the scan equals coverage → threshold → `apply_in`, the lit
        // area is that of the coverage, and the layers outside are counted alike.
        use crate::raster::{threshold, CoverageMap, Rasterizer, Scratch};
        let (cal, field) = small_setup();
        let raster = Rasterizer::new(field);
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let star = |rnd: &mut dyn FnMut() -> f64| {
            let (cx, cy) = (2.0 + rnd() * 36.0, 2.0 + rnd() * 27.0);
            let n = 3 + (rnd() * 40.0) as usize;
            let rmax = 0.3 + rnd() * 12.0;
            (0..n)
                .map(|i| {
                    let a = i as f64 / n as f64 * std::f64::consts::TAU;
                    let rad = rmax * (0.3 + 0.7 * rnd());
                    [
                        (cx + rad * a.cos()).clamp(0.0, 40.0),
                        (cy + rad * a.sin()).clamp(0.0, 30.0),
                    ]
                })
                .collect::<Vec<[f64; 2]>>()
        };
        let layers: Vec<Vec<Vec<[f64; 2]>>> = (0..48)
            .map(|case| {
                let first = star(&mut rnd);
                let mut shapes = vec![first.clone()];
                if case % 5 == 0 {
                    // The same shell shifted by 0.3 mm: overlapping shells.
                    shapes.push(first.iter().map(|p| [p[0] + 0.3, p[1]]).collect());
                }
                shapes
            })
            .collect();
        for (mode, dither) in [
            (Mode::Zone, Dither::Auto),
            (Mode::Zone, Dither::On),
            (Mode::Zone, Dither::Off),
            (Mode::Pixel, Dither::Off),
            (Mode::Pixel, Dither::On),
        ] {
            for binary in [false, true] {
                let fused = Compensator::new(&cal, &field, mode, dither).unwrap();
                let reference = Compensator::new(&cal, &field, mode, dither).unwrap();
                let (mut s_fused, mut s_ref) = (Scratch::default(), Scratch::default());
                let mut in_scan = 0;
                for (case, shapes) in layers.iter().enumerate() {
                    let mut want = raster.coverage(shapes, &mut s_ref);
                    let area = s_ref.lit_pixels(&want);
                    let lit = s_ref.lit_box();
                    if binary {
                        threshold(&mut want);
                    }
                    reference.apply_in(&mut want, lit);
                    let got = raster.render(shapes, &mut s_fused, binary, Some(&fused));
                    let what = format!("{mode:?} {dither:?} binary {binary} case {case}");
                    assert!(got == want, "{what}: masks differ");
                    assert_eq!(s_fused.lit_pixels(&got), area, "{what}: lit area");
                    in_scan += fused.fusable(lit) as usize;
                    s_fused.recycle(got);
                    s_ref.recycle(want);
                }
                assert_eq!(
                    fused.layers_outside(),
                    reference.layers_outside(),
                    "{mode:?} {dither:?} binary {binary}"
                );
                assert!(fused.layers_outside() > 0);
                let pixel_dither = mode == Mode::Pixel && dither == Dither::On;
                assert!(
                    pixel_dither || in_scan > 20,
                    "{mode:?} {dither:?}: {in_scan}"
                );
            }
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

    /// A tiny fixed-seed PRNG (xorshift), uniform in [0, 1).
    fn rng(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A random calibration field over a 40 × 30 mm area: every form, degrees 1 to
    /// [`MAX_DEGREE`](crate::optics::field::MAX_DEGREE), sometimes a smaller polynomial
    /// rectangle (linear continuation), sometimes one narrower than a pixel.
    fn random_field(rnd: &mut impl FnMut() -> f64, case: usize) -> FieldModel {
        let degree = 1 + case % crate::optics::field::MAX_DEGREE;
        let form = [Form::Polynomial, Form::Exponential, Form::InverseSquare][case % 3];
        let n = Poly::terms(degree);
        let mut coef: Vec<f64> = (0..n).map(|_| (rnd() - 0.5) * 0.2).collect();
        coef[0] = 1.0 + rnd();
        let area = [
            rnd() * 4.0,
            rnd() * 3.0,
            36.0 + rnd() * 4.0,
            26.0 + rnd() * 4.0,
        ];
        let poly_area = match case % 4 {
            0 => None,
            1 => Some([area[0] + 2.5, area[1] + 2.5, area[2] - 2.5, area[3] - 2.5]),
            2 => Some([20.01, area[1] + 1.0, 20.02, area[3] - 1.0]),
            _ => Some([area[0] + 1.0, 15.01, area[2] - 1.0, 15.02]),
        };
        FieldModel {
            origin_mm: [20.0 + rnd(), 15.0 + rnd()],
            length_unit_mm: Positive::new(10.0 + 20.0 * rnd()).unwrap(),
            scale: Positive::new(0.5 + rnd() * 1e-3).unwrap(),
            form,
            coefficients: Poly::from_terms(degree, &coef),
            area_mm: area,
            polynomial_area_mm: poly_area,
            extrapolate_mm: NonNegative::new(rnd() * 6.0).unwrap(),
        }
    }

    /// P at a pixel centre as the set-up defines it: inside the polynomial's rectangle
    /// Horner in u (f64) rounded to f32 and scaled in f32, elsewhere `eval` rounded to f32.
    fn p_reference(fm: &FieldModel, field: &Field, r: usize, c: usize) -> f32 {
        let p = field.pixel_mm;
        let (x, y) = (
            (c as f64 + 0.5) * p,
            (field.height_px as f64 - r as f64 - 0.5) * p,
        );
        let m = fm.extrapolate_mm.get();
        let [x0, y0, x1, y1] = fm.area_mm;
        let [px0, py0, px1, py1] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
        let (xc, yc) = (x.clamp(x0 - m, x1 + m), y.clamp(y0 - m, y1 + m));
        if !(xc >= px0 && xc <= px1 && yc >= py0 && yc <= py1) {
            return fm.eval(x, y) as f32;
        }
        let inv = 1.0 / fm.length_unit_mm.get();
        let a = fm.coefficients.in_u((yc - fm.origin_mm[1]) * inv);
        let u = (xc - fm.origin_mm[0]) * inv;
        let q = a.iter().rev().fold(0.0, |acc, k| acc * u + k) as f32;
        let scf = fm.scale.get() as f32;
        match fm.form {
            Form::Polynomial => q * scf,
            Form::Exponential => scf * q.exp(),
            Form::InverseSquare => scf / (q * q),
        }
    }

    #[test]
    fn field_rows_equal_the_definition_with_and_without_avx2() {
        let mut rnd = rng(0x9e37_79b9_7f4a_7c15);
        for case in 0..36 {
            let fm = random_field(&mut rnd, case);
            let field = Field {
                width_px: 61 + (case as u32 % 5) * 7,
                height_px: 47,
                pixel_mm: 0.73,
            };
            let (w, h) = (field.width_px as usize, field.height_px as usize);
            let mut rows = FieldRows::new(&fm, &field);
            let (mut a, mut b) = (vec![0f32; w], vec![0f32; w]);
            for r in 0..h {
                rows.row::<false>(r, &mut a);
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2.
                    unsafe { avx2_row(&mut rows, r, &mut b) };
                    assert_eq!(a, b, "case {case} row {r}: AVX2");
                }
                for (c, &v) in a.iter().enumerate() {
                    let want = p_reference(&fm, &field, r, c);
                    assert_eq!(v.to_bits(), want.to_bits(), "case {case} row {r} col {c}");
                }
            }
        }
    }

    #[test]
    fn horner_avx2_from_the_top_equals_horner_from_zero() {
        // Leaving out Horner's first step (0·u + a_n = a_n for finite u and a finite
        // nonzero a_n) changes no bit; with a zero top coefficient the full rule runs.
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut rnd = rng(0x5851_f42d_4c95_7f2d);
            for case in 0..40 {
                let n = 1 + case % 7;
                let mut a: Vec<f64> = (0..n).map(|_| (rnd() - 0.5) * 3.0).collect();
                if case % 5 == 4 {
                    *a.last_mut().unwrap() = if case % 2 == 0 { 0.0 } else { -0.0 };
                }
                let us: Vec<f64> = (0..37).map(|_| (rnd() - 0.5) * 8.0).collect();
                let top = a.last().is_some_and(|&c| c.is_finite() && c != 0.0);
                let mut want = vec![0f32; us.len()];
                horner_f32(&mut want, &us, &a, 0.7);
                for from_top in [top, false] {
                    let mut got = vec![0f32; us.len()];
                    // SAFETY: the CPU has AVX2.
                    unsafe { horner_avx2(&mut got, &us, &a, 0.7, from_top) };
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&got), bits(&want), "case {case} from_top {from_top}");
                }
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn avx2_row(rows: &mut FieldRows, r: usize, out: &mut [f32]) {
        rows.row::<true>(r, out)
    }

    #[test]
    fn field_sums_equal_adding_pixel_by_pixel() {
        // Random fields (and one whose values span too many binades for exact sums: the
        // one-by-one fallback): the zone and inside sums are those of adding P pixel by
        // pixel in row-major order, bit for bit, with and without AVX2; the per-segment
        // sums and extremes are those of the segment's pixels.
        let mut rnd = rng(0x2545_f491_4f6c_dd1d);
        for case in 0..25 {
            let mut fm = random_field(&mut rnd, case);
            if case == 24 {
                fm.form = Form::Exponential;
                fm.coefficients = Poly::from_terms(1, &[0.0, 40.0, 0.0]);
            }
            let field = Field {
                width_px: 83,
                height_px: 61,
                pixel_mm: 0.53,
            };
            let (w, h) = (83usize, 61usize);
            let pp = pixel_p(&fm, &field);
            let (lo, hi) = min_max(&pp);
            assert_eq!(
                sums_are_exact(lo, hi, w * h),
                case != 24,
                "case {case}: {lo} {hi}"
            );
            let (zone_of_col, zone_of_row, zcols, _) = zone_geometry(&field, 5.0);
            let segs = zone_segments(&zone_of_col);
            let inside = [3, 55, 5, 71];
            let mut results = vec![field_sums_with(
                false,
                &mut PSource::Rows(FieldRows::new(&fm, &field)),
                w,
                &segs,
                &zone_of_row,
                zcols,
                inside,
            )];
            results.push(field_sums(
                &mut PSource::Field(&pp),
                w,
                &segs,
                &zone_of_row,
                zcols,
                inside,
            ));
            results.push(field_sums(
                &mut PSource::Rows(FieldRows::new(&fm, &field)),
                w,
                &segs,
                &zone_of_row,
                zcols,
                inside,
            ));
            let nz = zcols * (*zone_of_row.iter().max().unwrap() as usize + 1);
            let (mut zs, mut zn, mut ins) = (vec![0f64; nz], vec![0usize; nz], 0.0f64);
            for (i, &v) in pp.iter().enumerate() {
                let (r, c) = (i / w, i % w);
                let z = zone_of_row[r] as usize * zcols + zone_of_col[c] as usize;
                zs[z] += v as f64;
                zn[z] += 1;
                if (inside[0]..inside[1]).contains(&r) && (inside[2]..inside[3]).contains(&c) {
                    ins += v as f64;
                }
            }
            for fs in &results {
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&fs.zsum), bits(&zs), "case {case}");
                assert_eq!(fs.zcnt, zn, "case {case}");
                assert_eq!(fs.inside_sum.to_bits(), ins.to_bits(), "case {case}");
                let mut k = 0;
                for r in inside[0]..inside[1] {
                    for &(_, a, b) in &segs {
                        let (a, b) = (a.max(inside[2]).min(b), b.min(inside[3]));
                        let vals = &pp[r * w + a..r * w + b.max(a)];
                        let s = vals.iter().fold(0.0, |s, &v| s + v as f64);
                        assert_eq!(fs.seg_sums[k].to_bits(), s.to_bits(), "case {case}");
                        assert_eq!(fs.seg_extremes[k], min_max(vals), "case {case}");
                        k += 1;
                    }
                }
                assert_eq!(k, fs.seg_sums.len());
            }
        }
    }

    #[test]
    fn exact_sums_bound() {
        // 2^20 values within one binade: 20 + 0 + 24 = 44 bits, exact; spanning 9 binades
        // 53 bits, exact; 10 binades, not.
        assert!(sums_are_exact(1.0, 1.5, 1 << 20));
        assert!(sums_are_exact(1.0, 1023.0, 1 << 20));
        assert!(!sums_are_exact(1.0, 1024.0, 1 << 20));
        assert!(sums_are_exact(1.0, 1024.0, 1 << 19));
        // Zero, negative, subnormal, infinite or NaN bounds: never.
        for (lo, hi) in [
            (0.0, 1.0),
            (-1.0, 1.0),
            (1e-40, 1e-39),
            (1.0, f32::INFINITY),
            (f32::NAN, 1.0),
        ] {
            assert!(!sums_are_exact(lo, hi, 4), "{lo} {hi}");
        }
        // Exact means exact: a worst case of the bound adds without rounding.
        let (lo, hi) = (1.0f32 + f32::EPSILON, 511.999_97f32);
        let n = 1usize << 20;
        assert!(sums_are_exact(lo, hi, n));
        let mut s = 0.0f64;
        for k in 0..n {
            s += if k % 2 == 0 { lo } else { hi } as f64;
        }
        let want = (n / 2) as f64 * (lo as f64 + hi as f64);
        assert_eq!(s, want);
    }

    #[test]
    fn stats_lanes_and_avx2_agree_with_one_by_one() {
        let mut rnd = rng(7);
        for len in (0..40).chain([257, 1024]) {
            let vals: Vec<f32> = (0..len).map(|_| (1.0 + rnd() * 3.0) as f32).collect();
            let s = vals.iter().fold(0.0, |s, &v| s + v as f64);
            let (lo, hi) = min_max(&vals);
            assert_eq!(stats_lanes(&vals), (s, lo, hi), "len {len}");
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2.
                assert_eq!(unsafe { stats_avx2(&vals) }, (s, lo, hi), "len {len}");
            }
        }
    }

    #[test]
    fn gray_map_rows_and_png_equal_the_per_zone_grays() {
        // The gray map kept as distinct rows is, pixel for pixel, the full-coverage gray
        // of the pixel's zone table for its row (zone mode) and the per-pixel gray (pixel
        // mode: checked against `apply` on a plate); its PNG, encoded row by row, is
        // `encode_gray8` of the map, also as mirrored projectors see it.
        let (cal, field) = small_setup();
        let (w, h) = (200usize, 150usize);
        for (mode, dither) in [
            (Mode::Zone, Dither::Auto),
            (Mode::Zone, Dither::On),
            (Mode::Zone, Dither::Off),
            (Mode::Pixel, Dither::Off),
        ] {
            let c = Compensator::new(&cal, &field, mode, dither).unwrap();
            let map = c.gray_map();
            if mode == Mode::Zone {
                assert!(c.gray_rows.len() / w < h / 2, "{}", c.gray_rows.len() / w);
                for r in 0..h {
                    for col in 0..w {
                        let t = c.row_tables[r * c.zcols + c.zone_of_col[col] as usize];
                        assert_eq!(map.data[r * w + col], c.tables[t as usize][255]);
                    }
                }
            }
            let mut plate = Mask {
                width: w as u32,
                height: h as u32,
                data: vec![255; w * h],
            };
            c.apply(&mut plate);
            assert!(plate == map, "{mode:?} {dither:?}");
            let mut p = crate::profile::Profile::default_profile().projector[0].clone();
            (p.width_px, p.height_px) = (w as u32, h as u32);
            let png = |m: &Mask| crate::png::encode_gray8(m.width, m.height, &m.data);
            assert_eq!(c.gray_map_png(&p, png), png(&map));
            p.mirror_x = true;
            let view = crate::raster::projector_view(&map, &p);
            assert_eq!(c.gray_map_png(&p, png), png(&view));
        }
    }
}
