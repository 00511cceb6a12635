//! Edge blending across projector overlaps, in irradiance (docs/GEOMETRY.md, "Blending").
//!
//! Where projectors overlap, each shows a share of the light so that the shares sum to one
//! **in irradiance** (without blending the overlap gets ~2× dose, and halving gray levels
//! does not halve the light: gray → irradiance is nonlinear). A share becomes a gray level
//! through the projector's response last ([`Response::inverse_lut`]). Each projector's raw
//! weight at a pixel is the product of its [`BlendCurve`] ramps towards each overlapped
//! side, divided by the sum over the projectors there ([`shares`]).

use crate::profile::BlendCurve;

/// A projector's footprint in field pixels: columns `x0..x1`, rows `y0..y1` (top row 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl Rect {
    /// Width and height in pixels.
    pub fn size(&self) -> (usize, usize) {
        ((self.x1 - self.x0) as usize, (self.y1 - self.y0) as usize)
    }
    fn overlaps_rows(&self, o: &Rect) -> bool {
        self.y0 < o.y1 && o.y0 < self.y1
    }
    fn overlaps_cols(&self, o: &Rect) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1
    }
    fn contains(&self, c: u32, r: u32) -> bool {
        c >= self.x0 && c < self.x1 && r >= self.y0 && r < self.y1
    }
}

/// Overlap widths (left, right, top, bottom) in pixels of projector `k` with the others;
/// 0 where that side is not overlapped.
pub fn overlap_widths(rects: &[Rect], k: usize) -> [u32; 4] {
    let a = rects[k];
    let mut d = [0u32; 4];
    for (j, b) in rects.iter().enumerate() {
        if j == k {
            continue;
        }
        if a.overlaps_rows(b) {
            if b.x0 < a.x0 && b.x1 > a.x0 {
                d[0] = d[0].max(b.x1.min(a.x1) - a.x0);
            }
            if b.x1 > a.x1 && b.x0 < a.x1 {
                d[1] = d[1].max(a.x1 - b.x0.max(a.x0));
            }
        }
        if a.overlaps_cols(b) {
            if b.y0 < a.y0 && b.y1 > a.y0 {
                d[2] = d[2].max(b.y1.min(a.y1) - a.y0);
            }
            if b.y1 > a.y1 && b.y0 < a.y1 {
                d[3] = d[3].max(a.y1 - b.y0.max(a.y0));
            }
        }
    }
    d
}

/// Raw (unnormalized) weight of projector `k` at field pixel (c, r), which must lie in it.
fn raw_weight(curve: &BlendCurve, rect: &Rect, d: &[u32; 4], c: u32, r: u32) -> f64 {
    let ramp = |dist: u32, width: u32| {
        if width == 0 {
            1.0
        } else {
            curve.ramp((dist as f64 + 0.5) / width as f64)
        }
    };
    ramp(c - rect.x0, d[0])
        * ramp(rect.x1 - 1 - c, d[1])
        * ramp(r - rect.y0, d[2])
        * ramp(rect.y1 - 1 - r, d[3])
}

/// One projector's irradiance shares where they may differ from one: per row of the
/// projector (top first, before mirroring), the columns `a..b` of its overlaps in that
/// row and their shares; every other pixel's share is 1. Memory follows the overlaps, not
/// the projector.
#[derive(Debug, Clone, Default)]
pub struct Shares<T = f32> {
    /// Per row, the columns `a..b` the row's shares cover.
    pub spans: Vec<(u32, u32)>,
    /// Per row, where its shares start in `values`.
    start: Vec<usize>,
    values: Vec<T>,
}

impl<T: Copy + PartialEq + Default> Shares<T> {
    /// The values of row `r`, columns `spans[r]`.
    pub fn row(&self, r: usize) -> &[T] {
        let (a, b) = self.spans[r];
        &self.values[self.start[r]..self.start[r] + (b - a) as usize]
    }

    /// Each value through `f`, each row's span trimmed at both ends to the first and last
    /// value that is not `full` (the value of every pixel outside the spans).
    pub fn map_trimmed<U: Copy + PartialEq + Default>(
        &self,
        f: impl Fn(T) -> U,
        full: U,
    ) -> Shares<U> {
        let mut out = Shares::default();
        for (r, &(a, _)) in self.spans.iter().enumerate() {
            let v: Vec<U> = self.row(r).iter().map(|&x| f(x)).collect();
            let i = v.iter().position(|&x| x != full).unwrap_or(v.len());
            let j = v.iter().rposition(|&x| x != full).map_or(i, |j| j + 1);
            out.start.push(out.values.len());
            out.spans.push((a + i as u32, a + j as u32));
            out.values.extend_from_slice(&v[i..j]);
        }
        out
    }
}

/// Irradiance share of every projector at its pixels ([`Shares`]). Wherever projectors
/// overlap, the shares of all projectors covering a field pixel sum to one (for
/// [`BlendCurve::None`] every share is 1).
pub fn shares(rects: &[Rect], curve: &BlendCurve) -> Vec<Shares> {
    let widths: Vec<[u32; 4]> = (0..rects.len()).map(|k| overlap_widths(rects, k)).collect();
    rects
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let mut out = Shares::default();
            let near: Vec<usize> = (0..rects.len())
                .filter(|&j| j != k && a.overlaps_rows(&rects[j]) && a.overlaps_cols(&rects[j]))
                .filter(|_| *curve != BlendCurve::None)
                .collect();
            for r in a.y0..a.y1 {
                // Only pixels inside some intersection can have a share below one.
                let cuts = near
                    .iter()
                    .map(|&j| rects[j])
                    .filter(|b| b.y0 <= r && r < b.y1);
                let cols = cuts.map(|b| (a.x0.max(b.x0), a.x1.min(b.x1)));
                let (c0, c1) =
                    cols.fold((a.x1, a.x0), |(lo, hi), (x0, x1)| (lo.min(x0), hi.max(x1)));
                out.start.push(out.values.len());
                out.spans.push(if c0 < c1 {
                    (c0 - a.x0, c1 - a.x0)
                } else {
                    (0, 0)
                });
                for c in c0..c1 {
                    let mut over = near.iter().filter(|&&i| rects[i].contains(c, r)).peekable();
                    if over.peek().is_none() {
                        out.values.push(1.0);
                        continue;
                    }
                    let mine = raw_weight(curve, a, &widths[k], c, r);
                    let (mut total, mut count) = (mine, 1usize);
                    for &i in over {
                        total += raw_weight(curve, &rects[i], &widths[i], c, r);
                        count += 1;
                    }
                    let v = if total > 0.0 {
                        mine / total
                    } else {
                        1.0 / count as f64
                    };
                    out.values.push(v as f32);
                }
            }
            out
        })
        .collect()
}

/// The shares as one row-major map per projector.
#[cfg(test)]
fn weight_maps(rects: &[Rect], curve: &BlendCurve) -> Vec<Vec<f32>> {
    (shares(rects, curve).iter().zip(rects))
        .map(|(s, a)| {
            let (w, h) = a.size();
            let mut out = vec![1.0f32; w * h];
            for r in 0..h {
                let (c0, c1) = s.spans[r];
                out[r * w + c0 as usize..r * w + c1 as usize].copy_from_slice(s.row(r));
            }
            out
        })
        .collect()
}

/// A projector's gray → relative irradiance curve over its usable gray levels, normalized so
/// the brightest level is 1. Levels are ascending in gray and strictly ascending in
/// irradiance; gray levels outside a calibration's valid range are simply not usable.
#[derive(Debug, Clone, PartialEq)]
pub struct Response {
    gray: Vec<u8>,
    r: Vec<f64>,
}

/// Resolution of [`Response::inverse_lut`]: irradiance fractions in steps of 1/`LUT_STEPS`.
pub const LUT_STEPS: usize = 255 * 16;

impl Response {
    /// Irradiance proportional to gray (DMD pattern mode / PWM with linear output).
    pub fn linear() -> Self {
        Self::from_fn(|g| g / 255.0).expect("linear response is valid")
    }

    /// R(g) = (g/255)^γ.
    #[cfg(test)]
    pub fn gamma(gamma: f64) -> Option<Self> {
        Self::from_fn(|g| (g / 255.0).powf(gamma))
    }

    /// Builds a response from any function of gray (all 256 levels usable), normalized so
    /// R(255) = 1. None if it is not finite, not non-decreasing, or R(255) ≤ 0.
    pub fn from_fn(f: impl Fn(f64) -> f64) -> Option<Self> {
        let levels: Vec<(u8, f64)> = (0..=255u8).map(|g| (g, f(g as f64))).collect();
        if levels.iter().any(|l| !l.1.is_finite()) || levels.windows(2).any(|w| w[1].1 < w[0].1) {
            return None;
        }
        // Keep the first of equal levels (a flat stretch gives no extra light).
        let mut kept: Vec<(u8, f64)> = Vec::with_capacity(256);
        for l in levels {
            if kept.last().is_none_or(|k| l.1 > k.1) {
                kept.push(l);
            }
        }
        Self::from_levels(&kept)
    }

    /// Builds a response from usable levels `(gray, irradiance)`, ascending in both (strictly
    /// in irradiance), normalized so the last is 1. None if empty, not ascending, not finite,
    /// or the brightest irradiance is ≤ 0.
    pub fn from_levels(levels: &[(u8, f64)]) -> Option<Self> {
        let top = levels.last()?.1;
        if !(top.is_finite() && top > 0.0)
            || levels
                .windows(2)
                .any(|w| w[1].0 <= w[0].0 || w[1].1 <= w[0].1)
            || levels.iter().any(|l| !l.1.is_finite())
        {
            return None;
        }
        Some(Response {
            gray: levels.iter().map(|l| l.0).collect(),
            r: levels.iter().map(|l| l.1 / top).collect(),
        })
    }

    /// Relative irradiance at `gray` (None if that level is not usable).
    #[cfg(test)]
    pub fn irradiance(&self, gray: u8) -> Option<f64> {
        self.gray.binary_search(&gray).ok().map(|i| self.r[i])
    }

    /// The usable gray whose irradiance is nearest to `fraction` (0..=1); ties go down.
    pub fn gray_for(&self, fraction: f64) -> u8 {
        let f = fraction.clamp(0.0, 1.0);
        let n = self.r.len();
        let hi = self.r.partition_point(|&v| v < f).min(n - 1);
        if hi > 0 && (f - self.r[hi - 1]) <= (self.r[hi] - f) {
            self.gray[hi - 1]
        } else {
            self.gray[hi]
        }
    }

    /// `LUT_STEPS + 1` entries: entry i is [`gray_for`](Self::gray_for)(i / LUT_STEPS).
    pub fn inverse_lut(&self) -> Vec<u8> {
        (0..=LUT_STEPS)
            .map(|i| self.gray_for(i as f64 / LUT_STEPS as f64))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(x0: u32, y0: u32, x1: u32, y1: u32) -> Rect {
        Rect { x0, y0, x1, y1 }
    }

    const CURVES: [BlendCurve; 3] = BlendCurve::SYMMETRIC;

    #[test]
    fn two_by_one_seam_weights() {
        // tiled-2x1: 1024-wide projectors, the second at column 992 (32 px overlap).
        let rects = [rect(0, 0, 1024, 768), rect(992, 0, 2016, 768)];
        assert_eq!(overlap_widths(&rects, 0), [0, 32, 0, 0]);
        assert_eq!(overlap_widths(&rects, 1), [32, 0, 0, 0]);
        for curve in CURVES.into_iter().chain([BlendCurve::eehm()]) {
            let w = weight_maps(&rects, &curve);
            for r in [0usize, 400, 767] {
                for c in 0..2016usize {
                    let a = if c < 1024 { w[0][r * 1024 + c] } else { 0.0 };
                    let b = if c >= 992 {
                        w[1][r * 1024 + c - 992]
                    } else {
                        0.0
                    };
                    assert!(
                        ((a + b) as f64 - 1.0).abs() < 1e-6,
                        "{curve:?} col {c}: {a} + {b}"
                    );
                    if c < 992 {
                        assert_eq!(a, 1.0);
                    }
                    if c >= 1024 {
                        assert_eq!(b, 1.0);
                    }
                }
                // Projector 0 fades out towards its right edge.
                assert!(w[0][r * 1024 + 1023] < 0.05 && w[0][r * 1024 + 992] > 0.95);
            }
        }
    }

    #[test]
    fn four_projector_corner_sums_to_one() {
        // 2x2 with a 20 px overlap both ways: the corner is covered four times.
        let rects = [
            rect(0, 0, 100, 80),
            rect(80, 0, 180, 80),
            rect(0, 60, 100, 140),
            rect(80, 60, 180, 140),
        ];
        for curve in [BlendCurve::RaisedCosine, BlendCurve::eehm()] {
            let w = weight_maps(&rects, &curve);
            for r in 0..140u32 {
                for c in 0..180u32 {
                    let s: f64 = rects
                        .iter()
                        .enumerate()
                        .filter(|(_, q)| q.contains(c, r))
                        .map(|(k, q)| w[k][((r - q.y0) * (q.x1 - q.x0) + c - q.x0) as usize] as f64)
                        .sum();
                    assert!((s - 1.0).abs() < 1e-6, "{curve:?} ({c},{r}): {s}");
                }
            }
        }
    }

    #[test]
    fn response_inverse() {
        let lin = Response::linear();
        assert_eq!(lin.gray_for(0.502), 128);
        assert_eq!(lin.gray_for(0.4975), 127);
        assert_eq!(lin.gray_for(1.0), 255);
        assert_eq!(lin.gray_for(0.0), 0);
        let lut = lin.inverse_lut();
        assert_eq!(lut.len(), LUT_STEPS + 1);
        for (i, &g) in lut.iter().enumerate() {
            assert!((g as f64 - i as f64 / 16.0).abs() <= 0.5, "{i}: {g}");
        }
        let g22 = Response::gamma(2.2).unwrap();
        // Half the light needs far more than half the gray under gamma 2.2.
        let g = g22.gray_for(0.5);
        assert!((184..=187).contains(&g), "{g}");
        assert!((g22.irradiance(g).unwrap() - 0.5).abs() < 0.005);
        // Only usable levels are chosen: a response valid on 121..=255 plus 0 (off).
        let mut lv = vec![(0u8, 0.0)];
        lv.extend((121..=255u8).map(|g| (g, 0.2 + (g as f64 - 121.0) / 134.0)));
        let z = Response::from_levels(&lv).unwrap();
        assert_eq!(z.gray_for(0.05), 0);
        assert_eq!(z.gray_for(0.15), 121);
        assert_eq!(z.gray_for(1.0), 255);
        assert_eq!(z.irradiance(60), None);
        assert!(Response::from_levels(&[(3, 1.0), (2, 2.0)]).is_none());
        assert!(Response::from_fn(|g| 255.0 - g).is_none());
        assert!(Response::from_fn(|_| 0.0).is_none());
    }

    #[test]
    fn failure_modes_the_blend_fixes() {
        // No blending: two full projectors deliver twice the irradiance in the overlap.
        let lin = Response::linear();
        let e = |r: &Response, g: u8| r.irradiance(g).unwrap();
        let dose = e(&lin, 255) + e(&lin, 255);
        assert!((dose - 2.0).abs() < 1e-12);
        // Halving the gray under a nonlinear response does not give half the light each.
        let g22 = Response::gamma(2.2).unwrap();
        let halves = 2.0 * e(&g22, 128);
        assert!(
            halves < 0.5,
            "two half-gray projectors give {halves} of the dose"
        );
        // Blending in irradiance then converting through the response does.
        for i in 0..=32 {
            let t = (i as f64 + 0.5) / 33.0;
            let (a, b) = BlendCurve::RaisedCosine.pair(t);
            let s = e(&g22, g22.gray_for(a)) + e(&g22, g22.gray_for(b));
            assert!((s - 1.0).abs() < 0.02, "{t}: {s}");
        }
    }
}
