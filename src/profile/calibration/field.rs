//! The field factor P(x, y): irradiance across the build plane at the brightest valid gray
//! (up to the factor S), a bivariate polynomial. Xu et al. 2010 use a cubic (10 terms);
//! `dmdsl calibrate` fits degree 3 unless cross-validation shows that a higher degree
//! (up to [`MAX_DEGREE`]) predicts held-out zones better.

use crate::units::{NonNegative, Positive};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Highest polynomial degree of P.
pub const MAX_DEGREE: usize = 6;

/// A bivariate polynomial in u, v of total degree ≤ [`MAX_DEGREE`].
///
/// Stored as a table of monomial names to coefficients: `c` is the constant, and a
/// monomial u^a·v^b is written as `a` letters `x` followed by `b` letters `y` (`x` = u,
/// `xy` = u·v, `xxy` = u²·v, `yyy` = v³). Missing monomials are zero.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "BTreeMap<String, f64>")]
pub struct Poly {
    /// Total degree (highest a + b with a nonzero entry slot).
    degree: usize,
    /// coef[a][b] for u^a v^b, a + b ≤ degree.
    coef: Vec<Vec<f64>>,
}

/// The monomials (a, b) of total degree ≤ `degree`, by degree then descending a (the
/// order of [`Poly::basis`] and [`Poly::from_terms`]).
pub use crate::polyfit::monomials;

/// Name of monomial u^a v^b in the file format.
pub fn monomial_name(a: usize, b: usize) -> String {
    if a + b == 0 {
        "c".into()
    } else {
        "x".repeat(a) + &"y".repeat(b)
    }
}

impl Poly {
    /// The zero polynomial of `degree`.
    pub fn zeros(degree: usize) -> Poly {
        Poly {
            degree,
            coef: (0..=degree).map(|a| vec![0.0; degree + 1 - a]).collect(),
        }
    }

    /// From coefficients in [`monomials`] order.
    pub fn from_terms(degree: usize, values: &[f64]) -> Poly {
        let mut p = Poly::zeros(degree);
        for (&(a, b), &v) in monomials(degree).iter().zip(values) {
            p.coef[a][b] = v;
        }
        p
    }

    /// Total degree.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Number of terms of a polynomial of `degree`.
    pub fn terms(degree: usize) -> usize {
        crate::polyfit::terms(degree)
    }

    /// The basis functions at (u, v), in [`monomials`] order.
    pub fn basis(degree: usize, u: f64, v: f64) -> Vec<f64> {
        let mut out = vec![0.0; Poly::terms(degree)];
        crate::polyfit::basis_into(degree, u, v, &mut out);
        out
    }

    /// Coefficients of the polynomial in u for fixed v: `out[a] = Σ_b coef[a][b]·v^b`.
    #[inline]
    pub fn in_u(&self, v: f64) -> Vec<f64> {
        self.coef
            .iter()
            .map(|cb| cb.iter().rev().fold(0.0, |acc, c| acc * v + c))
            .collect()
    }

    /// Value at (u, v): Horner in u over [`in_u`](Self::in_u)'s coefficients (the same
    /// operations, without allocating them).
    pub fn eval(&self, u: f64, v: f64) -> f64 {
        self.coef.iter().rev().fold(0.0, |acc, cb| {
            acc * u + cb.iter().rev().fold(0.0, |a, c| a * v + c)
        })
    }

    /// Value and gradient (∂/∂u, ∂/∂v) at (u, v).
    pub fn eval_grad(&self, u: f64, v: f64) -> (f64, f64, f64) {
        let (mut f, mut fu, mut fv) = (0.0, 0.0, 0.0);
        let (mut ua, mut ua1) = (1.0, 0.0); // u^a and a·u^(a−1)
        for (a, cb) in self.coef.iter().enumerate() {
            // q(v) = Σ_b c_b v^b and q'(v).
            let (mut q, mut qv, mut vb, mut vb1) = (0.0, 0.0, 1.0, 0.0);
            for (b, &c) in cb.iter().enumerate() {
                q += c * vb;
                qv += c * vb1;
                vb1 = (b + 1) as f64 * vb;
                vb *= v;
            }
            f += q * ua;
            fu += q * ua1;
            fv += qv * ua;
            ua1 = (a + 1) as f64 * ua;
            ua *= u;
        }
        (f, fu, fv)
    }

    /// True if every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        self.coef.iter().flatten().all(|c| c.is_finite())
    }
}

impl TryFrom<BTreeMap<String, f64>> for Poly {
    type Error = String;
    fn try_from(m: BTreeMap<String, f64>) -> Result<Self, String> {
        let mut terms = Vec::new();
        for (k, &v) in &m {
            let (a, b) = if k == "c" {
                (0, 0)
            } else {
                let a = k.chars().take_while(|&c| c == 'x').count();
                let b = k.len() - a;
                if k.is_empty() || !k[a..].chars().all(|c| c == 'y') {
                    return Err(format!(
                        "coefficient name {k:?}: use c, or x's then y's (x = u, xxy = u^2 v)"
                    ));
                }
                (a, b)
            };
            if a + b > MAX_DEGREE {
                return Err(format!(
                    "coefficient {k:?}: degree {} above {MAX_DEGREE}",
                    a + b
                ));
            }
            terms.push((a, b, v));
        }
        let degree = terms.iter().map(|t| t.0 + t.1).max().unwrap_or(0);
        let mut p = Poly::zeros(degree);
        for (a, b, v) in terms {
            p.coef[a][b] = v;
        }
        Ok(p)
    }
}

impl Serialize for Poly {
    /// A table of monomial names in degree order (c, x, y, xx, xy, yy, …).
    fn serialize<S: serde::Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let m = monomials(self.degree);
        let mut map = ser.serialize_map(Some(m.len()))?;
        for (a, b) in m {
            map.serialize_entry(&monomial_name(a, b), &self.coef[a][b])?;
        }
        map.end()
    }
}

/// How the polynomial gives P.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Form {
    /// P = scale · poly(u, v) (Xu et al. 2010).
    #[default]
    Polynomial,
    /// P = scale · exp(poly(u, v)): for fields that fall off multiplicatively (vignetting,
    /// Gaussian beams), fitted in log space.
    Exponential,
    /// P = scale / poly(u, v)²: the cos⁴ law of natural vignetting, cos⁴θ =
    /// (1 + r²/f²)⁻², is this form with a quadratic poly (about any centre).
    #[serde(rename = "inverse-square")]
    InverseSquare,
}

impl Form {
    /// P from the scale and the polynomial's value `q`.
    #[inline]
    pub fn apply(self, scale: f64, q: f64) -> f64 {
        match self {
            Form::Polynomial => scale * q,
            Form::Exponential => scale * q.exp(),
            Form::InverseSquare => scale / (q * q),
        }
    }
}

/// The field factor P(x, y) of a calibration.
///
/// P(x_mm, y_mm) = scale · poly(u, v) (or scale · exp(poly(u, v)), scale / poly(u, v)²,
/// see [`Form`]) with u = (x_mm − `origin_mm[0]`) / length_unit_mm and
/// v = (y_mm − `origin_mm[1]`) / length_unit_mm; (x_mm, y_mm) are build-plane coordinates from
/// the field's bottom-left corner (+x right, +y up).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldModel {
    /// Build-plane point where u = v = 0, mm.
    pub origin_mm: [f64; 2],
    /// Length that is one unit of u and v, mm (10 = centimetres, the reading of Xu et al. 2010).
    pub length_unit_mm: Positive,
    /// Factor applied to the polynomial (1e-8 in Xu et al. 2010).
    pub scale: Positive,
    /// Polynomial (default), exponential of a polynomial, or inverse square of one.
    #[serde(default)]
    pub form: Form,
    /// The polynomial's coefficients (see [`Poly`] for the names).
    pub coefficients: Poly,
    /// The calibrated area [x0, y0, x1, y1], mm: the union of the measured zones.
    pub area_mm: [f64; 4],
    /// Rectangle [x0, y0, x1, y1] (mm) where P is the polynomial itself: the span of the
    /// measured zone centres. Outside it P continues linearly (first-order Taylor
    /// expansion at the nearest point of the rectangle), because a polynomial fitted to
    /// points is unreliable beyond them. Default: `area_mm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub polynomial_area_mm: Option<[f64; 4]>,
    /// Beyond the calibrated area P is extrapolated this far (mm) and held constant
    /// further out (P at the nearest point of the enlarged area).
    pub extrapolate_mm: NonNegative,
}

impl FieldModel {
    /// P at build-plane point (x, y) mm: the polynomial inside `polynomial_area_mm`, its
    /// linear continuation outside it up to `extrapolate_mm` beyond `area_mm`, constant
    /// further out (for the exponential form the exponent is continued, for the inverse
    /// square the polynomial). A polynomial continuation is kept at or above 10 % of P at
    /// the rectangle's edge, an inverse-square one at or below 4 × P there.
    pub fn eval(&self, x: f64, y: f64) -> f64 {
        let m = self.extrapolate_mm.get();
        let [x0, y0, x1, y1] = self.area_mm;
        let xc = x.clamp(x0 - m, x1 + m);
        let yc = y.clamp(y0 - m, y1 + m);
        let [px0, py0, px1, py1] = self.polynomial_area_mm.unwrap_or(self.area_mm);
        let xp = xc.clamp(px0, px1);
        let yp = yc.clamp(py0, py1);
        let s = 1.0 / self.length_unit_mm.get();
        let (u, v) = ((xp - self.origin_mm[0]) * s, (yp - self.origin_mm[1]) * s);
        if xp == xc && yp == yc {
            self.form
                .apply(self.scale.get(), self.coefficients.eval(u, v))
        } else {
            let (f, fu, fv) = self.coefficients.eval_grad(u, v);
            self.continued([f, fu, fv], xc - xp, yc - yp)
        }
    }

    /// P at a point (dx, dy) mm from the nearest point of the polynomial's rectangle
    /// (within the extrapolation margin), from the polynomial's value and gradient `g` =
    /// [f, ∂f/∂u, ∂f/∂v] there: the linear continuation of [`eval`](Self::eval).
    #[inline(always)]
    pub fn continued(&self, g: [f64; 3], dx: f64, dy: f64) -> f64 {
        let [f, fu, fv] = g;
        let s = 1.0 / self.length_unit_mm.get();
        let lin = f + (fu * dx + fv * dy) * s;
        let q = match self.form {
            Form::Polynomial => lin.max(0.1 * f),
            Form::Exponential => lin,
            Form::InverseSquare => lin.max(0.5 * f),
        };
        self.form.apply(self.scale.get(), q)
    }

    /// True if (x, y) lies in the calibrated area.
    #[inline]
    pub fn inside(&self, x: f64, y: f64) -> bool {
        let [x0, y0, x1, y1] = self.area_mm;
        x >= x0 && x <= x1 && y >= y0 && y <= y1
    }

    /// Checks finiteness, the area, and that P is positive over the calibrated area
    /// (sampled on a 0.5 mm grid).
    pub fn validate(&self) -> std::result::Result<(), String> {
        let [x0, y0, x1, y1] = self.area_mm;
        if !self.area_mm.iter().all(|v| v.is_finite()) || x0 >= x1 || y0 >= y1 {
            return Err("field.area_mm must be [x0, y0, x1, y1] with x0 < x1, y0 < y1".into());
        }
        if let Some([a0, b0, a1, b1]) = self.polynomial_area_mm {
            if ![a0, b0, a1, b1].iter().all(|v| v.is_finite()) || a0 > a1 || b0 > b1 {
                return Err(
                    "field.polynomial_area_mm must be [x0, y0, x1, y1] with x0 <= x1, y0 <= y1"
                        .into(),
                );
            }
        }
        if !self.origin_mm.iter().all(|v| v.is_finite()) || !self.coefficients.is_finite() {
            return Err("field: origin_mm and coefficients must be finite numbers".into());
        }
        let (fx, fy) = (((x1 - x0) / 0.5).ceil(), ((y1 - y0) / 0.5).ceil());
        // Compared as f64: the counts of an absurd area do not fit a usize product.
        if fx * fy > 4e6 {
            return Err("field.area_mm is implausibly large".into());
        }
        let (nx, ny) = (fx as usize, fy as usize);
        let unit = self.length_unit_mm.get();
        let mut sign = 0.0;
        // P at the samples as `eval` computes it, without its per-point set-up: inside the
        // polynomial's rectangle the inner polynomials in v of each sample row once, then
        // Horner in u over them (the same operations as `Poly::eval`, so the same values).
        let s = 1.0 / unit;
        let [px0, py0, px1, py1] = self.polynomial_area_mm.unwrap_or(self.area_mm);
        let ys: Vec<f64> = (0..=ny).map(|j| (y0 + j as f64 * 0.5).min(y1)).collect();
        let inner: Vec<Option<Vec<f64>>> = ys
            .iter()
            .map(|&y| {
                (py0 <= y && y <= py1).then(|| self.coefficients.in_u((y - self.origin_mm[1]) * s))
            })
            .collect();
        let scale = self.scale.get();
        for i in 0..=nx {
            let x = (x0 + i as f64 * 0.5).min(x1);
            let u = (px0 <= x && x <= px1).then(|| (x - self.origin_mm[0]) * s);
            for (&y, q) in ys.iter().zip(&inner) {
                let p = match (u, q) {
                    (Some(u), Some(q)) => self
                        .form
                        .apply(scale, q.iter().rev().fold(0.0, |acc, &c| acc * u + c)),
                    _ => self.eval(x, y),
                };
                if !(p.is_finite() && p > 0.0) {
                    return Err(format!(
                        "field: P({x:.1} mm, {y:.1} mm) = {p:.4e} is not positive inside the calibrated area"
                    ));
                }
                if self.form == Form::InverseSquare {
                    // P = scale / q²: q crossing zero would make P infinite between samples.
                    let q = self.coefficients.eval(
                        (x - self.origin_mm[0]) / unit,
                        (y - self.origin_mm[1]) / unit,
                    );
                    if sign == 0.0 {
                        sign = q.signum();
                    } else if q.signum() != sign {
                        return Err(format!(
                            "field: the inverse-square polynomial changes sign near ({x:.1} mm, {y:.1} mm) inside the calibrated area (P would be infinite there)"
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// P on the area [0, 0, 60, 40] mm, extrapolated 5 mm, from its origin, length unit,
    /// scale, form and polynomial.
    fn model(origin_mm: [f64; 2], unit: f64, scale: f64, form: Form, q: Poly) -> FieldModel {
        FieldModel {
            origin_mm,
            length_unit_mm: Positive::new(unit).unwrap(),
            scale: Positive::new(scale).unwrap(),
            form,
            coefficients: q,
            area_mm: [0.0, 0.0, 60.0, 40.0],
            polynomial_area_mm: None,
            extrapolate_mm: NonNegative::new(5.0).unwrap(),
        }
    }

    #[test]
    fn names_round_trip_and_a_cubic_evaluates() {
        // Every name of a cubic, each with its own coefficient (the published cubic of
        // Xu et al. 2010 is checked against the built-in profile in `optics`).
        let src = "c = 2.5\nx = -0.5\ny = 1.25\nxx = 0.75\nxy = -1.5\nyy = 0.25\nxxx = 0.125\nxxy = -0.375\nxyy = 0.5\nyyy = -0.0625\n";
        let p: Poly = toml::from_str(src).unwrap();
        assert_eq!(p.degree(), 3);
        let (x, y) = (2.0, 3.0);
        let want = 0.125 * x * x * x - 0.0625 * y * y * y + 0.5 * x * y * y - 0.375 * x * x * y
            + 0.75 * x * x
            + 0.25 * y * y
            - 1.5 * x * y
            - 0.5 * x
            + 1.25 * y
            + 2.5;
        assert!((p.eval(x, y) - want).abs() < 1e-12);
        let back: Poly = toml::from_str(&toml::to_string(&p).unwrap()).unwrap();
        assert_eq!(back, p);
        // Basis order matches from_terms.
        let vals: Vec<f64> = (0..Poly::terms(4)).map(|i| i as f64 * 0.1 - 0.3).collect();
        let q = Poly::from_terms(4, &vals);
        let b = Poly::basis(4, 0.7, -0.4);
        let dot: f64 = b.iter().zip(&vals).map(|(a, c)| a * c).sum();
        assert!((q.eval(0.7, -0.4) - dot).abs() < 1e-12);
        let (f, fu, fv) = q.eval_grad(0.7, -0.4);
        let h = 1e-6;
        assert!((f - q.eval(0.7, -0.4)).abs() < 1e-12);
        assert!((fu - (q.eval(0.7 + h, -0.4) - q.eval(0.7 - h, -0.4)) / (2.0 * h)).abs() < 1e-6);
        assert!((fv - (q.eval(0.7, -0.4 + h) - q.eval(0.7, -0.4 - h)) / (2.0 * h)).abs() < 1e-6);
        assert!(toml::from_str::<Poly>("yx = 1.0").is_err());
        // eval is Horner in u over in_u's coefficients, bit for bit.
        for (k, (u, v)) in [(0.7, -0.4), (-3.1, 2.9), (0.0, 0.0), (12.5, -7.25)]
            .into_iter()
            .enumerate()
        {
            let want = q.in_u(v).iter().rev().fold(0.0, |acc, c| acc * u + c);
            assert_eq!(q.eval(u, v).to_bits(), want.to_bits(), "{k}");
        }
        assert!(toml::from_str::<Poly>("xxxxxxx = 1.0").is_err());
    }

    #[test]
    fn inverse_square_form_is_the_cos4_law_and_must_not_cross_zero() {
        // cos⁴θ = (1 + r²/f²)⁻² = 1 / (1 + u² + v²)² with u, v in units of f.
        let q = Poly::from_terms(2, &[1.0, 0.0, 0.0, 1.0, 0.0, 1.0]);
        let mut fm = model([30.0, 20.0], 50.0, 2.0, Form::InverseSquare, q);
        for (x, y) in [(30.0, 20.0), (0.0, 0.0), (55.0, 12.0)] {
            let r2: f64 = (x - 30.0f64).powi(2) + (y - 20.0f64).powi(2);
            let want = 2.0 * (1.0 + r2 / 2500.0).powi(-2);
            assert!((fm.eval(x, y) / want - 1.0).abs() < 1e-12, "{x} {y}");
        }
        assert!(fm.validate().is_ok());
        let toml_text = toml::to_string(&fm).unwrap();
        assert!(
            toml_text.contains("form = \"inverse-square\""),
            "{toml_text}"
        );
        // q = 0.205 − u changes sign at x = 40.25 mm, between samples: refused.
        fm.coefficients = Poly::from_terms(2, &[0.205, -1.0, 0.0, 0.0, 0.0, 0.0]);
        let e = fm.validate().unwrap_err();
        assert!(e.contains("changes sign"), "{e}");
    }

    #[test]
    fn validation_names_the_first_sample_where_p_is_not_positive() {
        // P = 1 − 0.2·u with u = x/10 mm: zero at x = 50 mm.
        let q = Poly::from_terms(1, &[1.0, -0.2, 0.0]);
        let mut fm = model([0.0, 0.0], 10.0, 1.0, Form::Polynomial, q);
        // The first sample (x outer, y inner, 0.5 mm apart) where eval is not positive.
        let first_bad = |fm: &FieldModel| {
            (0..=120).find_map(|i| {
                (0..=80).find_map(|j| {
                    let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
                    (fm.eval(x, y) <= 0.0).then_some((x, y))
                })
            })
        };
        assert_eq!(first_bad(&fm), Some((50.0, 0.0)));
        let e = fm.validate().unwrap_err();
        assert!(e.contains("P(50.0 mm, 0.0 mm) = 0.0000e0"), "{e}");
        // Beyond a polynomial rectangle ending at x = 45 mm P is continued linearly and
        // kept above a tenth of its edge value: positive everywhere.
        fm.polynomial_area_mm = Some([0.0, 0.0, 45.0, 40.0]);
        assert_eq!(first_bad(&fm), None);
        assert!(fm.validate().is_ok());
        // A rectangle ending below the area's top: rows above it take eval's own path.
        fm.polynomial_area_mm = Some([0.0, 0.0, 60.0, 30.0]);
        assert_eq!(first_bad(&fm), Some((50.0, 0.0)));
        assert!(fm.validate().unwrap_err().contains("P(50.0 mm, 0.0 mm)"));
        fm.coefficients = Poly::from_terms(1, &[1.0, 0.0, -0.3]);
        // P = 1 − 0.3·v: zero at y = 33.3 mm, above the rectangle (continued there).
        assert_eq!(first_bad(&fm), None);
        assert!(fm.validate().is_ok());
        fm.polynomial_area_mm = None;
        assert_eq!(first_bad(&fm), Some((0.0, 33.5)));
        assert!(fm.validate().unwrap_err().contains("P(0.0 mm, 33.5 mm)"));
    }
}
