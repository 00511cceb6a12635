//! Spreads, (max − min) / mean in %: how uneven the irradiance over the calibrated area is
//! before and after compensation, per zone and per pixel.

use super::field_pass::FieldSums;
use super::zones::ZoneSegment;
use crate::png::PixelBox;

/// (max − min) / mean of values added one by one, %.
#[derive(Debug, Clone, Copy)]
pub(super) struct Spread {
    lo: f64,
    hi: f64,
    sum: f64,
    n: usize,
}

impl Spread {
    /// No values yet.
    pub(super) fn new() -> Spread {
        Spread {
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
            sum: 0.0,
            n: 0,
        }
    }

    /// Adds `x` (plain comparisons, cheaper than `f64::min`; like it, they skip NaN).
    #[inline(always)]
    pub(super) fn add(&mut self, x: f64) {
        self.lo = if x < self.lo { x } else { self.lo };
        self.hi = if x > self.hi { x } else { self.hi };
        self.sum += x;
        self.n += 1;
    }

    /// The extremes part of adding `v as f64 * s` for values `v` whose smallest is `lo`
    /// and largest `hi`: rounding is monotone, so the product of the smallest value is the
    /// smallest product (largest for negative `s`). The sum and count are added by the
    /// caller ([`pixel_spread`]).
    #[inline]
    fn add_extremes(&mut self, lo: f32, hi: f32, s: f64) {
        let (a, b) = (lo as f64 * s, hi as f64 * s);
        self.lo = self.lo.min(a.min(b));
        self.hi = self.hi.max(a.max(b));
    }

    /// The spread, %; 0 for no values.
    pub(super) fn pct(&self) -> f64 {
        if self.n == 0 {
            return 0.0;
        }
        (self.hi - self.lo) / (self.sum / self.n as f64) * 100.0
    }
}

/// The spread of `v(z)` over the zones `z` with `inside[z]`, %.
pub(super) fn zone_spread(inside: &[bool], v: impl Fn(usize) -> f64) -> f64 {
    let mut s = Spread::new();
    (0..inside.len())
        .filter(|&z| inside[z])
        .for_each(|z| s.add(v(z)));
    s.pct()
}

/// The per-pixel spread over the calibrated area `inside` when the pixels of image row r
/// in zone column zc show the relative response S = `shown_s(r, zc)` (the S of their
/// gray): the extremes of P · S from each row segment's extremes (rounding is monotone),
/// the mean from each row segment's sum of P ([`FieldSums`]).
pub(super) fn pixel_spread(
    fs: &FieldSums,
    segs: &[ZoneSegment],
    inside: PixelBox,
    shown_s: impl Fn(usize, usize) -> f64,
) -> f64 {
    let PixelBox { r0, r1, c0, c1 } = inside;
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
            let s = shown_s(r, zc);
            let (lo, hi) = extremes[j];
            sp.add_extremes(lo, hi, s);
            sp.sum += sums[j] * s;
            sp.n += n;
        }
    }
    sp.pct()
}
