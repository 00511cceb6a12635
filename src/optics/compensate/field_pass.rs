//! The set-up's one pass over P: the sum of P over every zone and over the calibrated
//! area, and per row and zone segment of that area the sum and extremes of P (for the
//! per-pixel spreads, [`super::spread`]).

use super::field_rows::FieldRows;
#[cfg(target_arch = "x86_64")]
use super::kernels::sum_and_extremes_avx2;
use super::kernels::{min_max, sum_and_extremes};
use super::zones::{ZoneGrid, ZoneSegment};
use crate::png::PixelBox;

/// What the set-up's pass over P gives ([`field_sums`]).
pub(super) struct FieldSums {
    /// Sum of P over each zone.
    pub(super) zone_sums: Vec<f64>,
    /// Pixels of each zone.
    pub(super) zone_pixels: Vec<usize>,
    /// Sum of P over the calibrated area.
    pub(super) inside_sum: f64,
    /// Per row of the calibrated area and zone segment ([`ZoneGrid::segments`]) cut to
    /// it: the sum of P, and its smallest and largest value (row-major; empty cuts
    /// included).
    pub(super) seg_sums: Vec<f64>,
    pub(super) seg_extremes: Vec<(f32, f32)>,
}

/// [`field_sums_with`], with AVX2 when the CPU has it.
pub(super) fn field_sums(
    src: &FieldRows,
    w: usize,
    zones: &ZoneGrid,
    inside: PixelBox,
) -> FieldSums {
    #[cfg(target_arch = "x86_64")]
    let avx2 = std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    let avx2 = false;
    field_sums_with(avx2, src, w, zones, inside)
}

/// The set-up's pass over P (`w` values per row from `src`) over the zones of `zones` and
/// the calibrated area `inside` ([`FieldSums`]): the sums are those of adding the values
/// one by one in row-major order, bit for bit. When every sum is exact ([`sums_are_exact`])
/// the two halves of the field are summed side by side, several values at a time (`avx2`:
/// the same operations on wider vectors); otherwise a second pass adds them one by one.
pub(super) fn field_sums_with(
    avx2: bool,
    src: &FieldRows,
    w: usize,
    zones: &ZoneGrid,
    inside: PixelBox,
) -> FieldSums {
    let (segs, zone_of_row, zcols) = (&zones.segments[..], &zones.of_row[..], zones.cols);
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
    let run = |src: &FieldRows, rows: std::ops::Range<usize>, exact: bool| {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is true only where the CPU has AVX2.
            return unsafe { sum_rows_avx2(src, &geo, rows, exact) };
        }
        sum_rows::<false>(src, &geo, rows, exact)
    };
    let mid = h / 2;
    let (top, bottom) = rayon::join(|| run(src, 0..mid, true), || run(src, mid..h, true));
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
        zone_sums: p.zsum,
        zone_pixels: zcnt,
        inside_sum: p.inside_sum,
        seg_sums: p.seg_sums,
        seg_extremes: p.seg_extremes,
    }
}

/// What a pass over rows of the field works on ([`field_sums_with`]).
struct PassGeometry<'a> {
    w: usize,
    segs: &'a [ZoneSegment],
    zone_of_row: &'a [u16],
    zcols: usize,
    inside: PixelBox,
    nz: usize,
}

/// The sums and extremes of a pass over some rows ([`sum_rows`]).
struct RowSums {
    zsum: Vec<f64>,
    inside_sum: f64,
    seg_sums: Vec<f64>,
    seg_extremes: Vec<(f32, f32)>,
    /// Smallest and largest P of those rows (exact passes only).
    lo: f32,
    hi: f32,
}

/// [`sum_rows`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn sum_rows_avx2(
    src: &FieldRows,
    geo: &PassGeometry,
    rows: std::ops::Range<usize>,
    exact: bool,
) -> RowSums {
    sum_rows::<true>(src, geo, rows, exact)
}

/// One pass over image rows `rows` of P (see [`field_sums_with`]): `exact`: each row
/// segment's values summed four or eight at a time (exact sums only), otherwise one by
/// one in row-major order. `AVX2`: true only when called from [`sum_rows_avx2`].
#[inline(always)]
fn sum_rows<const AVX2: bool>(
    src: &FieldRows,
    geo: &PassGeometry,
    rows: std::ops::Range<usize>,
    exact: bool,
) -> RowSums {
    let &PassGeometry {
        w,
        segs,
        zone_of_row,
        zcols,
        inside: PixelBox { r0, r1, c0, c1 },
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
                        // SAFETY: AVX2 is true only in `sum_rows_avx2`, which runs on CPUs
                        // with AVX2.
                        return unsafe { sum_and_extremes_avx2(v) };
                    }
                    sum_and_extremes(v)
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
    RowSums {
        zsum,
        inside_sum,
        seg_sums,
        seg_extremes,
        lo,
        hi,
    }
}

/// Whether every f64 sum of `n` f32 values from `lo` to `hi` (all positive, normal, finite)
/// is exact, whatever the order of the additions: each value is then a whole multiple of
/// the unit in the last place of `lo`'s binade, q = 2^(e_lo − 23), and every partial sum a
/// whole multiple of q below n · 2^(e_hi + 1), which f64 holds exactly if that is at most
/// 2^53 · q.
pub(super) fn sums_are_exact(lo: f32, hi: f32, n: usize) -> bool {
    if !(lo >= f32::MIN_POSITIVE && hi.is_finite() && lo <= hi) {
        return false;
    }
    let e = |v: f32| (v.to_bits() >> 23) as usize;
    let log2n = (usize::BITS - n.saturating_sub(1).leading_zeros()) as usize;
    log2n + e(hi) - e(lo) + 24 <= 53
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::compensate::field_rows::pixel_p;
    use crate::optics::compensate::test_support::{self, random_field, rng};
    use crate::optics::compensate::Form;
    use crate::optics::field::Poly;

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
            let field = test_support::field(83, 61, 0.53);
            let (w, h) = (83usize, 61usize);
            let pp = pixel_p(&fm, &field);
            let (lo, hi) = min_max(&pp);
            assert_eq!(
                sums_are_exact(lo, hi, w * h),
                case != 24,
                "case {case}: {lo} {hi}"
            );
            let zones = ZoneGrid::new(&field, 5.0);
            let (zone_of_col, zone_of_row, zcols) = (&zones.of_col, &zones.of_row, zones.cols);
            let segs = &zones.segments;
            let inside = PixelBox::new(3, 55, 5, 71);
            let rows = FieldRows::new(&fm, &field);
            let results = [
                field_sums_with(false, &rows, w, &zones, inside),
                field_sums(&rows, w, &zones, inside),
            ];
            let nz = zcols * (*zone_of_row.iter().max().unwrap() as usize + 1);
            let (mut zs, mut zn, mut ins) = (vec![0f64; nz], vec![0usize; nz], 0.0f64);
            for (i, &v) in pp.iter().enumerate() {
                let (r, c) = (i / w, i % w);
                let z = zone_of_row[r] as usize * zcols + zone_of_col[c] as usize;
                zs[z] += v as f64;
                zn[z] += 1;
                if inside.rows().contains(&r) && inside.cols().contains(&c) {
                    ins += v as f64;
                }
            }
            for fs in &results {
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&fs.zone_sums), bits(&zs), "case {case}");
                assert_eq!(fs.zone_pixels, zn, "case {case}");
                assert_eq!(fs.inside_sum.to_bits(), ins.to_bits(), "case {case}");
                let mut k = 0;
                for r in inside.rows() {
                    for &(_, a, b) in segs {
                        let (a, b) = (a.max(inside.c0).min(b), b.min(inside.c1));
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
}
