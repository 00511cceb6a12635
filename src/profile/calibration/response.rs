//! The gray response S(g): relative irradiance as a function of the pixel value g shown by
//! a mirror (255 = fully on), and its inverse on the 8-bit levels (docs/CALIBRATION.md,
//! "Model" and "Fitting" give its forms and the segment from (0, 0)). A table's first
//! point may be [0, 0]; the cubic below its next point meets the curve with the measured
//! points' three-point end slope, at most 3× the secant. Outside its valid range S is never
//! used, except that pixel value 0 (mirror off) gives S(0) = 0.

use serde::{Deserialize, Serialize};

/// Which variable a response polynomial is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GrayVariable {
    /// The pixel value g (0 = off, 255 = fully on).
    Pixel,
    /// The attenuation z = 255 − g (the "gray" of Xu et al. 2010: z = 0 is the fully-on mirror).
    Attenuation,
}

/// How a response table is interpolated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Interpolation {
    /// Not-a-knot cubic spline through the points (must be increasing on the range).
    Spline,
    /// Monotone piecewise cubic (Fritsch–Carlson PCHIP).
    Pchip,
}

/// The gray response S(g), as stored in a calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Response {
    /// S = Σ `coefficients[k]`·v^k, v the pixel value or the attenuation.
    Polynomial {
        /// The polynomial's variable.
        variable: GrayVariable,
        /// Coefficients, ascending powers (constant first).
        coefficients: Vec<f64>,
        /// Pixel values [lowest, highest] on which the polynomial is valid; S must be
        /// positive and strictly increasing in the pixel value there.
        valid_gray: [u8; 2],
    },
    /// A curve through points (pixel value, S).
    Table {
        /// How the points are joined.
        interpolation: Interpolation,
        /// (pixel value, S) pairs, both strictly increasing; the first may be [0, 0].
        points: Vec<[f64; 2]>,
    },
}

/// A response ready for evaluation (spline coefficients solved once).
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// S from the first measured point up (everywhere without an anchor).
    measured: MeasuredCurve,
    /// Segment from (0, 0) to the first measured point: (g1, s1, slope at 0, slope at g1).
    anchor: Option<(f64, f64, f64, f64)>,
}

/// The part of a [`Curve`] over the measured grays.
#[derive(Debug, Clone, PartialEq)]
enum MeasuredCurve {
    /// A polynomial in the variable, coefficients from the constant up.
    Poly(GrayVariable, Vec<f64>),
    /// The cubic spline through the points, with its second derivatives there
    /// ([`spline_second_derivatives`]).
    Spline(Vec<[f64; 2]>, Vec<f64>),
    /// The PCHIP interpolant through the points.
    Pchip(Vec<[f64; 2]>),
}

impl Curve {
    /// S at pixel value `g` (inside the valid range; unchecked).
    pub fn eval(&self, g: f64) -> f64 {
        if let Some((g1, s1, d0, d1)) = self.anchor {
            if g < g1 {
                return hermite(0.0, 0.0, d0, g1, s1, d1, g.max(0.0));
            }
        }
        match &self.measured {
            MeasuredCurve::Poly(variable, c) => {
                let v = match variable {
                    GrayVariable::Pixel => g,
                    GrayVariable::Attenuation => 255.0 - g,
                };
                c.iter().rev().fold(0.0, |acc, c| acc * v + c)
            }
            MeasuredCurve::Spline(pts, m) => spline_eval(pts, m, g).0,
            MeasuredCurve::Pchip(pts) => pchip_eval(pts, g),
        }
    }
}

/// Cubic Hermite segment from (x0, y0, slope d0) to (x1, y1, slope d1), at x.
fn hermite(x0: f64, y0: f64, d0: f64, x1: f64, y1: f64, d1: f64, x: f64) -> f64 {
    let h = x1 - x0;
    let t = (x - x0) / h;
    let (t2, t3) = (t * t, t * t * t);
    (2.0 * t3 - 3.0 * t2 + 1.0) * y0
        + (t3 - 2.0 * t2 + t) * h * d0
        + (-2.0 * t3 + 3.0 * t2) * y1
        + (t3 - t2) * h * d1
}

/// Second derivatives of the not-a-knot cubic spline through `pts` (natural for 3 points,
/// linear for 2).
pub fn spline_second_derivatives(pts: &[[f64; 2]]) -> Vec<f64> {
    let n = pts.len();
    if n < 3 {
        return vec![0.0; n];
    }
    let h: Vec<f64> = pts.windows(2).map(|w| w[1][0] - w[0][0]).collect();
    let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
    let mut b = nalgebra::DVector::<f64>::zeros(n);
    for i in 1..n - 1 {
        a[(i, i - 1)] = h[i - 1];
        a[(i, i)] = 2.0 * (h[i - 1] + h[i]);
        a[(i, i + 1)] = h[i];
        b[i] = 6.0 * ((pts[i + 1][1] - pts[i][1]) / h[i] - (pts[i][1] - pts[i - 1][1]) / h[i - 1]);
    }
    if n >= 4 {
        a[(0, 0)] = h[1];
        a[(0, 1)] = -(h[0] + h[1]);
        a[(0, 2)] = h[0];
        a[(n - 1, n - 3)] = h[n - 2];
        a[(n - 1, n - 2)] = -(h[n - 3] + h[n - 2]);
        a[(n - 1, n - 1)] = h[n - 3];
    } else {
        a[(0, 0)] = 1.0;
        a[(n - 1, n - 1)] = 1.0;
    }
    match a.lu().solve(&b) {
        Some(m) => m.iter().copied().collect(),
        None => vec![0.0; n],
    }
}

/// Value and slope of the spline at x (clamped to the range).
fn spline_eval(pts: &[[f64; 2]], m: &[f64], x: f64) -> (f64, f64) {
    let n = pts.len();
    if n == 1 {
        return (pts[0][1], 0.0);
    }
    let x = x.clamp(pts[0][0], pts[n - 1][0]);
    let k = pts.partition_point(|p| p[0] <= x).clamp(1, n - 1) - 1;
    let h = pts[k + 1][0] - pts[k][0];
    let t = x - pts[k][0];
    let a = (m[k + 1] - m[k]) / (6.0 * h);
    let b = m[k] / 2.0;
    let c = (pts[k + 1][1] - pts[k][1]) / h - h * (2.0 * m[k] + m[k + 1]) / 6.0;
    (
        pts[k][1] + t * (c + t * (b + t * a)),
        c + t * (2.0 * b + 3.0 * t * a),
    )
}

impl Response {
    /// Pixel values [lo, hi] on which S is defined.
    pub fn valid_gray(&self) -> [u8; 2] {
        match self {
            Response::Polynomial { valid_gray, .. } => *valid_gray,
            Response::Table { points, .. } => [
                points.first().map_or(0, |p| p[0] as u8),
                points.last().map_or(0, |p| p[0] as u8),
            ],
        }
    }

    /// The curve, ready for evaluation.
    pub fn curve(&self) -> Curve {
        match self {
            Response::Polynomial {
                variable,
                coefficients,
                ..
            } => Curve {
                measured: MeasuredCurve::Poly(*variable, coefficients.clone()),
                anchor: None,
            },
            Response::Table {
                interpolation,
                points,
            } => {
                let anchored = points.len() >= 3 && points[0] == [0.0, 0.0];
                let pts = points[usize::from(anchored)..].to_vec();
                let measured = match interpolation {
                    Interpolation::Spline => {
                        MeasuredCurve::Spline(pts.clone(), spline_second_derivatives(&pts))
                    }
                    Interpolation::Pchip => MeasuredCurve::Pchip(pts.clone()),
                };
                // Slope where the anchor segment meets the curve: the three-point
                // (parabola) end slope of the measured points, less noise-sensitive than
                // the spline's own end slope.
                let slope = if pts.len() >= 2 {
                    pchip_slope(&pts, 0)
                } else {
                    0.0
                };
                let anchor = anchored.then(|| {
                    let (g1, s1) = (pts[0][0], pts[0][1]);
                    let sec = s1 / g1;
                    let d1 = slope.clamp(0.0, 3.0 * sec);
                    let d0 = (2.0 * sec - d1).clamp(0.0, 3.0 * sec);
                    (g1, s1, d0, d1)
                });
                Curve { measured, anchor }
            }
        }
    }

    /// S at pixel value `g` (inside the valid range; unchecked). Solves the curve on every
    /// call: use [`Response::curve`] for many evaluations.
    pub fn eval(&self, g: f64) -> f64 {
        self.curve().eval(g)
    }

    /// Checks the stored curve: a valid range inside 0..=255 with at least 2 levels, S
    /// finite, positive (S(0) = 0 allowed) and strictly increasing on every integer level.
    pub fn validate(&self) -> std::result::Result<(), String> {
        match self {
            Response::Polynomial {
                coefficients,
                valid_gray,
                ..
            } => {
                if coefficients.is_empty() || coefficients.iter().any(|c| !c.is_finite()) {
                    return Err("response.coefficients must be finite numbers".into());
                }
                if valid_gray[0] >= valid_gray[1] {
                    return Err(format!(
                        "response.valid_gray [{}, {}] must be [lowest, highest] with lowest < highest",
                        valid_gray[0], valid_gray[1]
                    ));
                }
            }
            Response::Table { points, .. } => {
                if points.len() < 2 {
                    return Err("response.points needs at least 2 points".into());
                }
                for (i, p) in points.iter().enumerate() {
                    if !(p[0].is_finite() && p[1].is_finite()) {
                        return Err(format!("response.points[{i}] is not finite"));
                    }
                    if p[0] < 0.0 || p[0] > 255.0 || p[0].fract() != 0.0 {
                        return Err(format!(
                            "response.points[{i}]: gray {} must be an integer 0..=255",
                            p[0]
                        ));
                    }
                    if p[1] <= 0.0 && !(i == 0 && p[0] == 0.0 && p[1] == 0.0) {
                        return Err(format!(
                            "response.points[{i}]: S must be > 0 (only a first point [0, 0], mirror off, may be 0)"
                        ));
                    }
                    if i > 0 && (p[0] <= points[i - 1][0] || p[1] <= points[i - 1][1]) {
                        return Err(format!(
                            "response.points[{i}]: gray and S must both increase from point to point"
                        ));
                    }
                }
            }
        }
        let [lo, hi] = self.valid_gray();
        let curve = self.curve();
        let mut prev = 0.0;
        for g in lo..=hi {
            let s = curve.eval(g as f64);
            if !s.is_finite() || (s <= 0.0 && !(g == 0 && s == 0.0)) {
                return Err(format!(
                    "response: S({g}) = {s} is not positive on the valid gray range {lo}..={hi}"
                ));
            }
            if g > lo && s <= prev {
                return Err(format!(
                    "response: S is not strictly increasing on the valid gray range {lo}..={hi} (S({}) = {prev:.6} >= S({g}) = {s:.6})",
                    g - 1
                ));
            }
            prev = s;
        }
        Ok(())
    }

    /// The 8-bit levels a pixel may take, ascending in S: pixel value 0 with S = 0 (mirror
    /// off) unless the valid range starts at 0, then every integer gray of the valid range.
    pub fn levels(&self) -> Levels {
        let [lo, hi] = self.valid_gray();
        let curve = self.curve();
        let mut gray = Vec::with_capacity(257);
        let mut s = Vec::with_capacity(257);
        if lo > 0 {
            gray.push(0u8);
            s.push(0.0);
        }
        for g in lo..=hi {
            let v = curve.eval(g as f64);
            if s.last().is_none_or(|&l| v > l) {
                gray.push(g);
                s.push(v);
            }
        }
        let mid = s.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
        Levels { gray, s, mid }
    }
}

/// The usable 8-bit levels, ascending in S, for nearest-irradiance quantization.
#[derive(Debug, Clone, PartialEq)]
pub struct Levels {
    /// Pixel values, ascending.
    pub gray: Vec<u8>,
    /// S of each pixel value, strictly ascending.
    pub s: Vec<f64>,
    /// Midpoints between consecutive S values (decision thresholds).
    pub mid: Vec<f64>,
}

impl Levels {
    /// Index of the level whose S is nearest to `target` (ties go up); targets above the
    /// highest level give the highest.
    pub fn nearest(&self, target: f64) -> usize {
        self.mid.partition_point(|&m| m <= target)
    }

    /// Same as [`nearest`](Self::nearest), searching from `start` (fast when the answer is
    /// close to `start`).
    #[inline]
    pub fn nearest_from(&self, mut i: usize, target: f64) -> usize {
        while i > 0 && self.mid[i - 1] > target {
            i -= 1;
        }
        while i < self.mid.len() && self.mid[i] <= target {
            i += 1;
        }
        i
    }

    /// Highest S.
    pub fn s_max(&self) -> f64 {
        *self.s.last().expect("levels are never empty")
    }
}

/// Monotone piecewise-cubic Hermite interpolation (Fritsch–Carlson slopes with the
/// shape-preserving three-point end conditions). `pts` strictly increasing in x;
/// x outside the range is clamped.
pub fn pchip_eval(pts: &[[f64; 2]], x: f64) -> f64 {
    let n = pts.len();
    if n == 0 {
        return f64::NAN;
    }
    if n == 1 {
        return pts[0][1];
    }
    let x = x.clamp(pts[0][0], pts[n - 1][0]);
    let k = (pts.partition_point(|p| p[0] <= x)).clamp(1, n - 1) - 1;
    let (d0, d1) = (pchip_slope(pts, k), pchip_slope(pts, k + 1));
    hermite(
        pts[k][0],
        pts[k][1],
        d0,
        pts[k + 1][0],
        pts[k + 1][1],
        d1,
        x,
    )
}

/// PCHIP derivative at node `k`.
fn pchip_slope(pts: &[[f64; 2]], k: usize) -> f64 {
    let n = pts.len();
    let h = |i: usize| pts[i + 1][0] - pts[i][0];
    let del = |i: usize| (pts[i + 1][1] - pts[i][1]) / h(i);
    if n == 2 {
        return del(0);
    }
    let end = |h0: f64, h1: f64, d0: f64, d1: f64| {
        let d = ((2.0 * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
        if d.signum() != d0.signum() {
            0.0
        } else if d0.signum() != d1.signum() && d.abs() > 3.0 * d0.abs() {
            3.0 * d0
        } else {
            d
        }
    };
    if k == 0 {
        return end(h(0), h(1), del(0), del(1));
    }
    if k == n - 1 {
        return end(h(n - 2), h(n - 3), del(n - 2), del(n - 3));
    }
    let (d0, d1) = (del(k - 1), del(k));
    if d0 * d1 <= 0.0 {
        return 0.0;
    }
    let (h0, h1) = (h(k - 1), h(k));
    let w1 = 2.0 * h1 + h0;
    let w2 = h1 + 2.0 * h0;
    (w1 + w2) / (w1 / d0 + w2 / d1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The published S of Xu et al. 2010 (in z = 255 − pixel value) on `valid_gray`.
    fn published(valid_gray: [u8; 2]) -> Response {
        Response::Polynomial {
            variable: GrayVariable::Attenuation,
            coefficients: vec![5.72, -0.101, 5.78e-4, -1e-6],
            valid_gray,
        }
    }

    #[test]
    fn published_cubic_valid_range_is_where_s_falls_in_z() {
        let r = published([121, 255]);
        r.validate().unwrap();
        assert!((r.eval(255.0) - 5.72).abs() < 1e-12);
        // S is lowest at z = 133.9; one level further (z = 135) it rises again in z: the
        // range cannot be extended.
        let wider = published([120, 255]);
        let e = wider.validate().unwrap_err();
        assert!(e.contains("not strictly increasing"), "{e}");
    }

    #[test]
    fn pchip_interpolates_monotonically_and_reproduces_lines() {
        let pts = vec![[100.0, 0.1], [150.0, 0.2], [200.0, 0.8], [255.0, 1.0]];
        let mut prev = 0.0;
        for g in 100..=255 {
            let v = pchip_eval(&pts, g as f64);
            assert!(v > prev, "g {g}");
            prev = v;
        }
        for p in &pts {
            assert!((pchip_eval(&pts, p[0]) - p[1]).abs() < 1e-12);
        }
        let line: Vec<[f64; 2]> = (0..6).map(|i| [i as f64 * 50.0, 1.0 + i as f64]).collect();
        for g in 0..250 {
            let want = 1.0 + g as f64 / 50.0;
            assert!((pchip_eval(&line, g as f64) - want).abs() < 1e-12);
        }
    }

    #[test]
    fn levels_nearest_in_irradiance() {
        let r = published([121, 255]);
        let lv = r.levels();
        assert_eq!(lv.gray[0], 0);
        assert_eq!(lv.s[0], 0.0);
        assert_eq!(lv.gray[1], 121);
        assert_eq!(*lv.gray.last().unwrap(), 255);
        for (i, &s) in lv.s.iter().enumerate() {
            assert_eq!(lv.nearest(s), i);
            assert_eq!(lv.nearest_from(0, s), i);
            assert_eq!(lv.nearest_from(lv.s.len() - 1, s), i);
        }
        assert_eq!(lv.nearest(1e9), lv.s.len() - 1);
        assert_eq!(lv.nearest(-1.0), 0);
        // Brute force agrees.
        for k in 0..2000 {
            let t = k as f64 * 0.003;
            let best = (0..lv.s.len())
                .min_by(|&a, &b| {
                    (lv.s[a] - t)
                        .abs()
                        .partial_cmp(&(lv.s[b] - t).abs())
                        .unwrap()
                })
                .unwrap();
            let got = lv.nearest(t);
            assert!((lv.s[got] - t).abs() <= (lv.s[best] - t).abs() + 1e-15);
        }
    }

    fn table(interpolation: Interpolation, points: Vec<[f64; 2]>) -> Response {
        Response::Table {
            interpolation,
            points,
        }
    }

    #[test]
    fn table_validation() {
        let bad = table(Interpolation::Pchip, vec![[100.0, 0.5], [200.0, 0.4]]);
        assert!(bad.validate().is_err());
        let good = table(
            Interpolation::Pchip,
            vec![[100.0, 0.2], [180.0, 0.5], [255.0, 1.0]],
        );
        good.validate().unwrap();
        assert_eq!(good.valid_gray(), [100, 255]);
        let zero_inside = vec![[100.0, 0.2], [180.0, 0.0], [255.0, 1.0]];
        assert!(table(Interpolation::Pchip, zero_inside).validate().is_err());
    }

    #[test]
    fn spline_is_exact_for_cubic_responses_and_anchor_is_monotone() {
        // The S of Xu et al. 2010 in pixel values, sampled at 7 levels: the not-a-knot spline
        // reproduces it (PCHIP would be off by ~1 %).
        let s = crate::optics::synthetic::s_published;
        let pts: Vec<[f64; 2]> = [135.0, 155.0, 175.0, 195.0, 215.0, 235.0, 255.0]
            .iter()
            .map(|&g| [g, s(g)])
            .collect();
        let mut with0 = vec![[0.0, 0.0]];
        with0.extend(pts.iter().copied());
        let r = table(Interpolation::Spline, with0);
        r.validate().unwrap();
        let c = r.curve();
        for g in 135..=255 {
            assert!((c.eval(g as f64) / s(g as f64) - 1.0).abs() < 1e-9, "g {g}");
        }
        // The (0, 0) anchor segment rises monotonically to the first point.
        assert_eq!(c.eval(0.0), 0.0);
        let mut prev = 0.0;
        for g in 1..=135 {
            let v = c.eval(g as f64);
            assert!(v > prev, "g {g}");
            prev = v;
        }
        // A power law (gamma 2.2) measured from 135 up is continued well below it.
        let gam = |g: f64| (g / 255.0).powf(2.2);
        let mut p = vec![[0.0, 0.0]];
        p.extend([135.0, 155.0, 175.0, 195.0, 215.0, 235.0, 255.0].map(|g| [g, gam(g)]));
        let c = table(Interpolation::Spline, p).curve();
        assert!((c.eval(100.0) / gam(100.0) - 1.0).abs() < 0.01);
        for g in 135..=255 {
            assert!(
                (c.eval(g as f64) / gam(g as f64) - 1.0).abs() < 1e-4,
                "g {g}"
            );
        }
    }
}
