//! Edge blending across projector overlaps, in irradiance.
//!
//! Where projectors overlap, each shows a share of the light so that the shares sum to one
//! **in irradiance** (seeds/003: without blending the overlap gets ~2× dose; halving gray
//! levels does not halve the light because gray → irradiance is nonlinear, BRIEF §5). A
//! share is turned into a gray level through that projector's response curve last
//! ([`Response::inverse_lut`]).
//!
//! A [`BlendCurve`] is an edge ramp `F(t)`, `t` = distance from the projector's edge into
//! the overlap divided by the overlap width (0 at the edge, 1 where the overlap ends), F(0)
//! ≈ 0, F(1) = 1. For every field pixel each projector's raw weight is the product of its
//! ramps towards each overlapped side, and the weights are normalized by their sum, so they
//! sum to one exactly wherever at least one projector shines ([`weight_maps`]). For the
//! symmetric curves (raised cosine, smoothstep, linear) F(t) + F(1 − t) = 1 already and the
//! normalization changes nothing across a simple seam.

use serde::{Deserialize, Serialize};

/// Shape of the edge ramp across an overlap.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "curve", rename_all = "kebab-case", deny_unknown_fields)]
pub enum BlendCurve {
    /// F(t) = sin²(πt/2) = (1 − cos πt)/2: smooth at both ends (the default).
    #[default]
    RaisedCosine,
    /// F(t) = 3t² − 2t³.
    Smoothstep,
    /// F(t) = t.
    Linear,
    /// The seeds/003 "EEHM" curve: a mix of the exponential (power) decay and the improved
    /// trigonometric decay. Its equations are images missing from the paper's text; this is
    /// the reconstruction documented in docs/GEOMETRY.md, with the paper's tuned parameters
    /// as defaults (α = 0.9, p = 0.75, λ = 1.25, β = 0.75, m = 1.1, n = 0.83). The pair is
    /// normalized to sum to one (the paper tuned its parameters by eye on its own projectors;
    /// dmdsl handles the response separately).
    Eehm {
        /// Power-decay value at the overlap's middle, α.
        #[serde(default = "d_alpha")]
        alpha: f64,
        /// Power-decay exponent p.
        #[serde(default = "d_p")]
        p: f64,
        /// Trigonometric exponent λ (replaces the square of sin²).
        #[serde(default = "d_lambda")]
        lambda: f64,
        /// Trigonometric argument exponent β.
        #[serde(default = "d_beta")]
        beta: f64,
        /// Mixing exponent m.
        #[serde(default = "d_m")]
        m: f64,
        /// Mixing share n of the power decay at the inner end.
        #[serde(default = "d_n")]
        n: f64,
    },
    /// No blending: every projector shows full coverage in the overlap (about 2× dose
    /// there). For comparisons only (seeds/003 scheme A).
    None,
}

fn d_alpha() -> f64 {
    0.9
}
fn d_p() -> f64 {
    0.75
}
fn d_lambda() -> f64 {
    1.25
}
fn d_beta() -> f64 {
    0.75
}
fn d_m() -> f64 {
    1.1
}
fn d_n() -> f64 {
    0.83
}

impl BlendCurve {
    /// seeds/003's curve with the paper's parameters.
    pub fn eehm() -> Self {
        BlendCurve::Eehm {
            alpha: d_alpha(),
            p: d_p(),
            lambda: d_lambda(),
            beta: d_beta(),
            m: d_m(),
            n: d_n(),
        }
    }

    /// Checks parameter ranges; the message names the offending key.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if let BlendCurve::Eehm {
            alpha,
            p,
            lambda,
            beta,
            m,
            n,
        } = *self
        {
            let chk = |name: &str, v: f64, lo: f64, hi: f64| {
                if v.is_finite() && v > lo && v <= hi {
                    Ok(())
                } else {
                    Err(format!("[blend].{name} must be in ({lo}, {hi}], got {v}"))
                }
            };
            chk("alpha", alpha, 0.0, 1.0)?;
            chk("p", p, 0.0, 10.0)?;
            chk("lambda", lambda, 0.0, 10.0)?;
            chk("beta", beta, 0.0, 10.0)?;
            chk("m", m, 0.0, 10.0)?;
            if !(n.is_finite() && (0.0..=1.0).contains(&n)) {
                return Err(format!("[blend].n must be in [0, 1], got {n}"));
            }
        }
        Ok(())
    }

    /// The raw edge ramp F(t), t ∈ [0, 1] (clamped): 0 at the projector's edge, 1 where the
    /// overlap ends.
    pub fn ramp(&self, t: f64) -> f64 {
        let t = t.clamp(0.0, 1.0);
        match *self {
            BlendCurve::RaisedCosine => {
                let s = (std::f64::consts::FRAC_PI_2 * t).sin();
                s * s
            }
            BlendCurve::Smoothstep => t * t * (3.0 - 2.0 * t),
            BlendCurve::Linear => t,
            BlendCurve::None => 1.0,
            BlendCurve::Eehm {
                alpha,
                p,
                lambda,
                beta,
                m,
                n,
            } => {
                // Power ("exponential") decay, Bourke's edge-blend form: α at the middle.
                let e = if t < 0.5 {
                    alpha * (2.0 * t).powf(p)
                } else {
                    1.0 - (1.0 - alpha) * (2.0 - 2.0 * t).powf(p)
                };
                // Improved trigonometric decay: sin^λ(π/2 · t^β).
                let tr = (std::f64::consts::FRAC_PI_2 * t.powf(beta))
                    .sin()
                    .powf(lambda);
                // Trig dominates near the projector's edge, the power decay near the inner end.
                let s = n * t.powf(m);
                (1.0 - s) * tr + s * e
            }
        }
    }

    /// Irradiance shares (a, b) at position t across a two-projector seam: `a` for the
    /// projector whose edge is at t = 0 (it fades in), `b` for the other; a + b = 1 (except
    /// for [`BlendCurve::None`], where both are 1).
    pub fn pair(&self, t: f64) -> (f64, f64) {
        let a = self.ramp(t);
        let b = self.ramp(1.0 - t);
        if *self == BlendCurve::None {
            return (1.0, 1.0);
        }
        let s = a + b;
        if s <= 0.0 {
            (0.5, 0.5)
        } else {
            (a / s, b / s)
        }
    }
}

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

/// Irradiance share of every projector at every one of its pixels (row-major over the
/// projector's own pixels, before mirroring). Wherever projectors overlap, the shares of all
/// projectors covering a field pixel sum to one (for [`BlendCurve::None`] every share is 1).
pub fn weight_maps(rects: &[Rect], curve: &BlendCurve) -> Vec<Vec<f32>> {
    let widths: Vec<[u32; 4]> = (0..rects.len()).map(|k| overlap_widths(rects, k)).collect();
    rects
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let w = (a.x1 - a.x0) as usize;
            let h = (a.y1 - a.y0) as usize;
            let mut out = vec![1.0f32; w * h];
            if *curve == BlendCurve::None {
                return out;
            }
            let near: Vec<usize> = (0..rects.len())
                .filter(|&j| j != k && a.overlaps_rows(&rects[j]) && a.overlaps_cols(&rects[j]))
                .collect();
            // Only pixels inside some intersection can have a share below one.
            for &j in &near {
                let b = rects[j];
                for r in a.y0.max(b.y0)..a.y1.min(b.y1) {
                    for c in a.x0.max(b.x0)..a.x1.min(b.x1) {
                        let mine = raw_weight(curve, a, &widths[k], c, r);
                        let (mut total, mut count) = (mine, 1usize);
                        for &i in &near {
                            if rects[i].contains(c, r) {
                                total += raw_weight(curve, &rects[i], &widths[i], c, r);
                                count += 1;
                            }
                        }
                        let v = if total > 0.0 {
                            mine / total
                        } else {
                            1.0 / count as f64
                        };
                        out[(r - a.y0) as usize * w + (c - a.x0) as usize] = v as f32;
                    }
                }
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

    const CURVES: [BlendCurve; 3] = [
        BlendCurve::RaisedCosine,
        BlendCurve::Smoothstep,
        BlendCurve::Linear,
    ];

    #[test]
    fn ramps_go_from_zero_to_one_and_pairs_sum_to_one() {
        for c in CURVES.into_iter().chain([BlendCurve::eehm()]) {
            assert!(c.ramp(0.0).abs() < 1e-12, "{c:?}");
            assert!((c.ramp(1.0) - 1.0).abs() < 1e-12, "{c:?}");
            let mut prev = -1.0;
            for i in 0..=1000 {
                let t = i as f64 / 1000.0;
                let v = c.ramp(t);
                assert!(v >= prev - 1e-12, "{c:?} not monotone at {t}");
                prev = v;
                let (a, b) = c.pair(t);
                assert!((a + b - 1.0).abs() < 1e-12, "{c:?} at {t}");
            }
        }
        // The symmetric curves need no normalization.
        for c in CURVES {
            for i in 0..=100 {
                let t = i as f64 / 100.0;
                assert!((c.ramp(t) + c.ramp(1.0 - t) - 1.0).abs() < 1e-12, "{c:?}");
            }
        }
        // The seeds/003 curve does not sum to one raw (it was tuned by eye), so it is
        // normalized: the raw mid-overlap sum is well above 1.
        let e = BlendCurve::eehm();
        assert!(e.ramp(0.5) * 2.0 > 1.2, "{}", e.ramp(0.5));
        assert_eq!(BlendCurve::None.pair(0.3), (1.0, 1.0));
    }

    #[test]
    fn two_by_one_seam_weights() {
        // tiled-2x1: 1024-wide projectors, the second at column 992 (32 px overlap).
        let rects = [
            Rect {
                x0: 0,
                y0: 0,
                x1: 1024,
                y1: 768,
            },
            Rect {
                x0: 992,
                y0: 0,
                x1: 2016,
                y1: 768,
            },
        ];
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
            Rect {
                x0: 0,
                y0: 0,
                x1: 100,
                y1: 80,
            },
            Rect {
                x0: 80,
                y0: 0,
                x1: 180,
                y1: 80,
            },
            Rect {
                x0: 0,
                y0: 60,
                x1: 100,
                y1: 140,
            },
            Rect {
                x0: 80,
                y0: 60,
                x1: 180,
                y1: 140,
            },
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
