//! Fitting E(x, y, g) = P(x, y)·S(g) to irradiance measurements (docs/CALIBRATION.md):
//! alternating least squares on relative residuals, the valid gray range from the first
//! pass's S, P's form and degree by cross-validation over zones, S normalised to 1 at the
//! brightest valid level (so P is the full-on irradiance). Input: a CSV table
//! `x_mm,y_mm,gray,irradiance_mw_cm2` (read by `table`) of zone centres in build-plane mm,
//! pixel values shown there (255 = fully on) and readings, in any grid and order.

use super::field::{FieldModel, Form, Poly, MAX_DEGREE};
use super::response::{Interpolation, Response};
use super::{Calibration, FitSummary, Units};
use crate::error::{Error, Result};
use crate::polyfit::LeastSquares;
use crate::table::{self, cell_error, Columns};
use crate::text::count;
use crate::units::{NonNegative, Positive};
use crate::warning::Warning;
use nalgebra::{DMatrix, DVector};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// The CSV header columns, in the canonical order.
pub const COLUMNS: [&str; 4] = ["x_mm", "y_mm", "gray", "irradiance_mw_cm2"];

/// Largest accepted condition number of the column-scaled design matrix of P.
pub const MAX_CONDITION: f64 = 1e6;

/// Highest degree of the inverse-square candidates (P = 1/poly²): the quadratic is the
/// cos⁴ law of vignetting. A cubic would be chosen on fields it does not describe (fewer
/// terms than exp(quartic), similar cross-validated error) and then extrapolate worse into
/// the outer half-zone band, so only the quadratic is offered.
const MAX_INVERSE_SQUARE_DEGREE: usize = 2;

/// One measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Line in the file (1-based).
    pub line: u64,
    /// Zone centre x, mm.
    pub x_mm: f64,
    /// Zone centre y, mm.
    pub y_mm: f64,
    /// Pixel value shown.
    pub gray: u8,
    /// Measured irradiance (> 0).
    pub irradiance: f64,
}

/// The measurement table's columns (header required, any order).
const TABLE: Columns = Columns {
    names: &COLUMNS,
    header_optional: false,
};

/// A row of the measurement table, as read.
#[derive(Debug, Deserialize)]
struct TableRow {
    x_mm: f64,
    y_mm: f64,
    gray: f64,
    irradiance_mw_cm2: f64,
}

/// Checks the rows' values: gray an integer pixel value, irradiance positive.
fn readings(path: &Path, rows: Vec<table::Row<TableRow>>) -> Result<Vec<Reading>> {
    if rows.is_empty() {
        return Err(Error::input(path, "no measurements after the header"));
    }
    rows.into_iter()
        .map(|table::Row { line, value: r }| {
            let (g, e) = (r.gray, r.irradiance_mw_cm2);
            let bad = |column, msg: String| Err(cell_error(path, line, column, msg));
            if !(0.0..=255.0).contains(&g) || g.fract() != 0.0 {
                return bad("gray", format!("{g} is not an integer pixel value 0..255"));
            }
            if e <= 0.0 {
                return bad("irradiance_mw_cm2", format!("must be > 0, got {e}"));
            }
            Ok(Reading {
                line,
                x_mm: r.x_mm,
                y_mm: r.y_mm,
                gray: g as u8,
                irradiance: e,
            })
        })
        .collect()
}

/// Parses a measurement table. Errors name `path`, the line and the column.
#[cfg(any(test, feature = "internals"))]
pub fn parse_csv(text: &str, path: &Path) -> Result<Vec<Reading>> {
    readings(path, table::parse(path, text, &TABLE)?)
}

/// Reads and parses a measurement file.
pub fn read_csv(path: &Path) -> Result<Vec<Reading>> {
    let (_, rows) = table::read(path, &TABLE)?;
    readings(path, rows)
}

/// Fit options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Units of the irradiance column as stored in the calibration.
    pub units: Units,
    /// Compensation zone edge, mm.
    pub zone_mm: f64,
    /// How far P is extrapolated beyond the calibrated area, mm.
    pub extrapolate_mm: f64,
    /// Field size (width, height), mm: the calibrated area is clipped to it.
    pub field_mm: (f64, f64),
    /// Degree of P; `None`: chosen by cross-validation from 3 (the paper's cubic) up to
    /// [`MAX_DEGREE`].
    pub degree: Option<usize>,
}

/// One measured zone position.
#[derive(Debug, Clone, PartialEq)]
pub struct ZoneFit {
    /// Zone centre, mm.
    pub x_mm: f64,
    /// Zone centre, mm.
    pub y_mm: f64,
    /// P of this zone alone from its readings (given the fitted S): the "measured" full-on
    /// irradiance.
    pub measured_p: f64,
    /// P of the fitted polynomial at the centre.
    pub fitted_p: f64,
}

/// One measured gray level.
#[derive(Debug, Clone, PartialEq)]
pub struct LevelFit {
    /// Pixel value.
    pub gray: u8,
    /// Fitted relative response s (1 at the brightest valid level).
    pub s: f64,
    /// Inside the valid range.
    pub valid: bool,
    /// Each reading of this level divided by the fitted P at its zone (for plots).
    pub points: Vec<f64>,
}

/// The result of [`fit`].
#[derive(Debug, Clone)]
pub struct FitResult {
    /// The fitted calibration.
    pub calibration: Calibration,
    /// Per zone position.
    pub zones: Vec<ZoneFit>,
    /// Per gray level, ascending.
    pub levels: Vec<LevelFit>,
    /// Condition number of the scaled design matrix.
    pub condition: f64,
    /// Warnings (poor model fit, …).
    pub warnings: Vec<Warning>,
}

/// A reading prepared for the fit.
struct FitRow {
    /// The monomials of P's basis at the reading's (u, v).
    phi: Vec<f64>,
    /// The measured irradiance E.
    e: f64,
    /// Index of the reading's gray among the fitted levels.
    level: usize,
    /// Index of the reading's zone position (the cross-validation folds split these).
    position: usize,
}

/// A fit of E = P·S: P's coefficients (in the form the caller fitted), S per level.
struct FactorFit {
    /// Coefficients of P's polynomial, in the order of its basis.
    coef: Vec<f64>,
    /// S of each fitted level.
    s: Vec<f64>,
    /// Condition number of the scaled design matrix (0 when not checked).
    condition: f64,
}

/// P of `form` with coefficients `coef` at basis values `phi`.
fn p_of(form: Form, coef: &[f64], phi: &[f64]) -> f64 {
    form.apply(1.0, phi.iter().zip(coef).map(|(a, b)| a * b).sum::<f64>())
}

/// Divides each column of `a` by `norm` of its norm; returns the divisors.
fn scale_columns(a: &mut DMatrix<f64>, norm: impl Fn(f64) -> f64) -> Vec<f64> {
    let norms: Vec<f64> = (0..a.ncols()).map(|t| norm(a.column(t).norm())).collect();
    for (t, &nt) in norms.iter().enumerate() {
        a.column_mut(t).iter_mut().for_each(|v| *v /= nt);
    }
    norms
}

/// Fits `form` to `rows`: alternating least squares for a polynomial or inverse-square P,
/// one linear least-squares solve in log space for an exponential P.
fn fit_form(form: Form, rows: &[&FitRow], nlev: usize) -> std::result::Result<FactorFit, f64> {
    match form {
        Form::Polynomial | Form::InverseSquare => alternating_least_squares(form, rows, nlev),
        Form::Exponential => log_linear_fit(rows, nlev),
    }
}

/// ln E = poly(u, v) + ln s_j with ln s of the brightest level fixed at 0: linear least
/// squares (log residuals ≈ relative residuals).
fn log_linear_fit(rows: &[&FitRow], nlev: usize) -> std::result::Result<FactorFit, f64> {
    let n = rows.len();
    let m = rows.first().map_or(0, |r| r.phi.len());
    let cols = m + nlev - 1;
    let mut a = DMatrix::<f64>::zeros(n, cols);
    let mut b = DVector::<f64>::zeros(n);
    for (k, r) in rows.iter().enumerate() {
        for t in 0..m {
            a[(k, t)] = r.phi[t];
        }
        if r.level + 1 < nlev {
            a[(k, m + r.level)] = 1.0;
        }
        b[k] = r.e.ln();
    }
    let norms = scale_columns(&mut a, |n| n);
    if norms.contains(&0.0) {
        return Err(f64::INFINITY);
    }
    let (x, condition) = solve_scaled(&a, &b, true)?;
    let coef = (0..m).map(|t| x[t] / norms[t]).collect();
    let mut s: Vec<f64> = (m..cols).map(|t| (x[t] / norms[t]).exp()).collect();
    s.push(1.0);
    Ok(FactorFit { coef, s, condition })
}

/// Least squares A·x ≈ b for a column-scaled A (columns of unit norm; at most 28 columns)
/// by [`LeastSquares`] (QR). With `check`, the condition number of A must not exceed
/// [`MAX_CONDITION`]. Returns (x, condition number or 0 when not checked), or the
/// condition number (infinite when A is singular).
fn solve_scaled(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    check: bool,
) -> std::result::Result<(DVector<f64>, f64), f64> {
    let ls = LeastSquares::new(a.clone()).ok_or(f64::INFINITY)?;
    let mut cond = 0.0;
    if check {
        cond = ls.condition();
        if cond.is_nan() || cond > MAX_CONDITION {
            return Err(cond);
        }
    }
    ls.solve(b).map(|x| (x, cond)).ok_or(f64::INFINITY)
}

/// Alternating least squares on relative residuals over `rows` (levels 0..nlev), for P =
/// poly (`form` polynomial) or P = 1/poly² (inverse square).
/// Err(condition number) if the scaled design matrix of P is ill-conditioned.
fn alternating_least_squares(
    form: Form,
    rows: &[&FitRow],
    nlev: usize,
) -> std::result::Result<FactorFit, f64> {
    let n = rows.len();
    let m = rows.first().map_or(0, |r| r.phi.len());
    // Initial s: geometric mean irradiance per level.
    let mut s = vec![0.0; nlev];
    let mut cnt = vec![0usize; nlev];
    for r in rows {
        s[r.level] += r.e.ln();
        cnt[r.level] += 1;
    }
    for (v, &c) in s.iter_mut().zip(&cnt) {
        *v = if c > 0 { (*v / c as f64).exp() } else { 0.0 };
    }
    let smax = s.iter().cloned().fold(0.0, f64::max);
    s.iter_mut().for_each(|v| *v /= smax);
    let mut coef = vec![0.0; m];
    let mut prev = f64::INFINITY;
    let mut condition = 0.0;
    let mut a = DMatrix::<f64>::zeros(n, m);
    let b = DVector::<f64>::from_element(n, 1.0);
    for iter in 0..200 {
        // P-step: minimise Σ (1 − s_j φ·c / E)² over c. Inverse square: E = s_j / q² with
        // q = φ·c, so q should be q* = √(s_j / E); a relative error ε of q is one of −2ε in
        // E, so minimise Σ (1 − φ·c / q*)² (the linearised relative residual, halved).
        for (k, r) in rows.iter().enumerate() {
            let f = match form {
                Form::InverseSquare => (r.e / s[r.level]).sqrt(),
                _ => s[r.level] / r.e,
            };
            for t in 0..m {
                a[(k, t)] = f * r.phi[t];
            }
        }
        let norms = scale_columns(&mut a, |n| n.max(1e-300));
        let (x, cond) = solve_scaled(&a, &b, iter == 0)?;
        if iter == 0 {
            condition = cond;
        }
        for t in 0..m {
            coef[t] = x[t] / norms[t];
        }
        // s-step: s_j = Σ r / Σ r², r = P / E.
        let mut num = vec![0.0; nlev];
        let mut den = vec![0.0; nlev];
        let ps: Vec<f64> = rows.iter().map(|r| p_of(form, &coef, &r.phi)).collect();
        for (r, &p) in rows.iter().zip(&ps) {
            let q = p / r.e;
            num[r.level] += q;
            den[r.level] += q * q;
        }
        for j in 0..nlev {
            if den[j] > 0.0 {
                s[j] = num[j] / den[j];
            }
        }
        let obj: f64 = rows
            .iter()
            .zip(&ps)
            .map(|(r, &p)| (1.0 - s[r.level] * p / r.e).powi(2))
            .sum();
        if (prev - obj).abs() <= 1e-10 * (1.0 + obj) {
            break;
        }
        prev = obj;
    }
    Ok(FactorFit { coef, s, condition })
}

/// Cross-validated RMS relative error (%) of degree-`d` fits: zone positions are split
/// into `k` interleaved folds; each fold is predicted from a fit to the others.
fn cv_rms(form: Form, rows_d: &[FitRow], nlev: usize, k: usize) -> Option<f64> {
    let (mut ss, mut n) = (0.0, 0usize);
    for fold in 0..k {
        let train: Vec<&FitRow> = rows_d.iter().filter(|r| r.position % k != fold).collect();
        let test: Vec<&FitRow> = rows_d.iter().filter(|r| r.position % k == fold).collect();
        if test.is_empty() {
            continue;
        }
        let mut seen = vec![false; nlev];
        train.iter().for_each(|r| seen[r.level] = true);
        let fit = fit_form(form, &train, nlev).ok()?;
        for r in test.iter().filter(|r| seen[r.level]) {
            let e = p_of(form, &fit.coef, &r.phi) * fit.s[r.level] / r.e - 1.0;
            ss += e * e;
            n += 1;
        }
    }
    (n > 0).then(|| (ss / n as f64).sqrt() * 100.0)
}

/// The forms of P, in the order candidates of as many terms are preferred.
const FORMS: [Form; 3] = [Form::Polynomial, Form::Exponential, Form::InverseSquare];

fn form_name(f: Form) -> &'static str {
    match f {
        Form::Polynomial => "polynomial",
        Form::Exponential => "exponential",
        Form::InverseSquare => "inverse-square",
    }
}

/// A zone position's key: its centre in nm.
fn position_key(r: &Reading) -> (i64, i64) {
    ((r.x_mm * 1e6).round() as i64, (r.y_mm * 1e6).round() as i64)
}

/// The measured set-up of a fit: the readings, their distinct zone positions (numbered in
/// sorted order: that order makes the CV folds) and gray levels, and the calibrated area
/// with the normalized coordinates (u, v) of P.
struct Setup<'a> {
    readings: &'a [Reading],
    path: &'a Path,
    /// Number of each distinct zone position.
    pos: BTreeMap<(i64, i64), usize>,
    /// The distinct gray levels, ascending.
    grays: Vec<u8>,
    /// Span of the zone centres [x0, y0, x1, y1], mm.
    span: [f64; 4],
    /// Calibrated area [x0, y0, x1, y1], mm.
    area: [f64; 4],
    /// Where u = v = 0, mm.
    origin: [f64; 2],
    /// Length of one unit of u and v, mm.
    unit: f64,
}

impl<'a> Setup<'a> {
    /// Checks that the readings can determine a model and finds the calibrated area.
    fn new(readings: &'a [Reading], path: &'a Path, opts: &FitOptions) -> Result<Setup<'a>> {
        let input_error = |m: String| Error::input(path, m);
        let keys: std::collections::BTreeSet<_> = readings.iter().map(position_key).collect();
        let pos: BTreeMap<(i64, i64), usize> = keys.into_iter().zip(0..).collect();
        let npos = pos.len();
        let positions = count(
            npos as u64,
            "distinct zone position",
            "distinct zone positions",
        );
        let grays: std::collections::BTreeSet<u8> = readings.iter().map(|r| r.gray).collect();
        // Without several grays nothing else can be fitted: say so first.
        if grays.len() < 3 {
            return Err(input_error(too_few_grays(&grays)));
        }
        let min_terms = Poly::terms(3);
        if npos < min_terms {
            return Err(input_error(format!(
                "only {positions}; the cubic P(x, y) has {min_terms} terms and needs at least {min_terms} zones"
            )));
        }
        if let Some(d) = opts.degree {
            if !(3..=MAX_DEGREE).contains(&d) {
                return Err(Error::Usage(format!(
                    "degree {d}: P's degree must be 3..={MAX_DEGREE}"
                )));
            }
            if npos < Poly::terms(d) {
                return Err(input_error(format!(
                    "only {positions}; a degree-{d} P(x, y) has {} terms",
                    Poly::terms(d)
                )));
            }
        }
        // A cubic needs at least 4 distinct coordinates along each axis.
        for (i, axis) in ["x", "y"].into_iter().enumerate() {
            let vals: std::collections::BTreeSet<i64> = readings
                .iter()
                .map(|r| <[i64; 2]>::from(position_key(r))[i])
                .collect();
            if vals.len() < 4 {
                return Err(input_error(format!(
                    "ill-conditioned fit: the zone centres take only {} distinct {axis} {}; a cubic P(x, y) needs zones spread over the field in both x and y (at least 4 distinct values each)",
                    vals.len(),
                    crate::text::plural(vals.len() as u64, "value", "values")
                )));
            }
        }
        let (span, area) = calibrated_area(readings, opts.field_mm, path)?;
        Ok(Setup {
            readings,
            path,
            pos,
            grays: grays.into_iter().collect(),
            span,
            area,
            origin: [(area[0] + area[2]) / 2.0, (area[1] + area[3]) / 2.0],
            unit: ((area[2] - area[0]).max(area[3] - area[1]) / 2.0).max(1e-3),
        })
    }

    /// An input error naming the measurement file.
    fn input_error(&self, m: String) -> Error {
        Error::input(self.path, m)
    }

    /// The error of an ill-conditioned design of condition number `cond`.
    fn ill_conditioned(&self, cond: f64) -> Error {
        self.input_error(format!(
            "ill-conditioned fit (condition number {cond:.2e}): the {} zone positions do not determine a cubic P(x, y); measure zones spread over the field in both x and y",
            self.pos.len()
        ))
    }

    /// The normalized coordinates of a point, mm.
    fn uv_of(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x - self.origin[0]) / self.unit,
            (y - self.origin[1]) / self.unit,
        )
    }

    /// The index of a measured gray level.
    fn level_index(&self, g: u8) -> usize {
        self.grays.binary_search(&g).expect("known gray")
    }

    /// The fit rows of degree `d` of the readings at gray levels `lo..` (level indices
    /// counted from `lo`).
    fn rows(&self, d: usize, lo: usize) -> Vec<FitRow> {
        self.readings
            .iter()
            .filter(|r| self.level_index(r.gray) >= lo)
            .map(|r| {
                let (u, v) = self.uv_of(r.x_mm, r.y_mm);
                FitRow {
                    phi: Poly::basis(d, u, v),
                    e: r.irradiance,
                    level: self.level_index(r.gray) - lo,
                    position: self.pos[&position_key(r)],
                }
            })
            .collect()
    }

    /// The lowest valid level: the run of levels from the brightest down over which the
    /// first pass's s keeps falling, at least 3 levels long.
    fn valid_range(&self, first: &FactorFit) -> Result<usize> {
        let top = self.grays.len() - 1;
        let mut lo = top;
        while lo > 0 && first.s[lo - 1] < first.s[lo] {
            lo -= 1;
        }
        if first.s[top] <= 0.0 || top + 1 - lo < 3 {
            let shown: Vec<String> = self
                .grays
                .iter()
                .zip(&first.s)
                .rev()
                .take(4)
                .map(|(g, s)| format!("S({g}) = {:.4}", s / first.s[top].max(1e-300)))
                .collect();
            return Err(self.input_error(format!(
                "no monotone S fits the data: the response must fall from the brightest gray ({}) over at least 3 measured levels, but {} (255 = mirror fully on; is the gray column inverted?)",
                self.grays[top],
                shown.join(", ")
            )));
        }
        Ok(lo)
    }

    /// The model of P on the valid levels `lo..`: the forced degree (polynomial form), or
    /// among the polynomial (degrees 3..), exponential (degrees 2..) and inverse-square
    /// candidates the one with the fewest terms whose cross-validated error is within one
    /// standard error of the best (the polynomial first on ties).
    fn choose_model(&self, lo: usize, forced: Option<usize>) -> Result<Model> {
        let top = self.grays.len() - 1;
        let valid_n = top + 1 - lo;
        let min_terms = Poly::terms(3);
        let used_pos: std::collections::BTreeSet<usize> =
            self.rows(0, lo).iter().map(|r| r.position).collect();
        if used_pos.len() < min_terms {
            return Err(self.input_error(format!(
                "only {} distinct zone positions were measured at the valid gray levels {}..{}; the cubic P(x, y) needs at least {min_terms}",
                used_pos.len(),
                self.grays[lo],
                self.grays[top]
            )));
        }
        let k = used_pos.len().min(10);
        let mut m = Model {
            form: Form::Polynomial,
            degree: 3,
            cv: Vec::new(),
            cv_exp: Vec::new(),
            cv_inv: Vec::new(),
        };
        if let Some(d) = forced {
            m.degree = d;
            return Ok(m);
        }
        let mut cands: Vec<(usize, u8, Form, usize, f64)> = Vec::new();
        for d in 2..=MAX_DEGREE {
            if 2 * Poly::terms(d) > used_pos.len() {
                break;
            }
            let rows_d = self.rows(d, lo);
            let offered = [d >= 3, true, d <= MAX_INVERSE_SQUARE_DEGREE];
            let cvs = [&mut m.cv, &mut m.cv_exp, &mut m.cv_inv];
            for (rank, ((form, cv), ok)) in FORMS.into_iter().zip(cvs).zip(offered).enumerate() {
                if let Some(e) = ok.then(|| cv_rms(form, &rows_d, valid_n, k)).flatten() {
                    cv.push((d as u64, e));
                    cands.push((Poly::terms(d), rank as u8, form, d, e));
                }
            }
        }
        cands.sort_by_key(|c| (c.0, c.1));
        // One-standard-error rule: an RMS over n held-out readings is uncertain by about
        // 1/sqrt(2n) of itself; prefer the simplest model within that of the best.
        let best = cands.iter().map(|c| c.4).fold(f64::INFINITY, f64::min);
        let tol = (0.5 / self.rows(0, lo).len() as f64).sqrt().max(0.02);
        (m.form, m.degree) = cands
            .iter()
            .find(|c| c.4 <= best * (1.0 + tol))
            .map_or((Form::Polynomial, 3), |c| (c.2, c.3));
        Ok(m)
    }
}

/// The span of the zone centres and the calibrated area: their bounding box grown by half
/// the zone pitch, clipped to the field.
fn calibrated_area(
    readings: &[Reading],
    (fw, fh): (f64, f64),
    path: &Path,
) -> Result<([f64; 4], [f64; 4])> {
    let pitch = |mut v: Vec<f64>| -> f64 {
        v.sort_by(|a, b| a.partial_cmp(b).unwrap());
        v.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        let mut gaps: Vec<f64> = v.windows(2).map(|w| w[1] - w[0]).collect();
        if gaps.is_empty() {
            return 0.0;
        }
        gaps.sort_by(|a, b| a.partial_cmp(b).unwrap());
        gaps[gaps.len() / 2]
    };
    let xs: Vec<f64> = readings.iter().map(|r| r.x_mm).collect();
    let ys: Vec<f64> = readings.iter().map(|r| r.y_mm).collect();
    let (px, py) = (pitch(xs.clone()), pitch(ys.clone()));
    let min = |v: &[f64]| v.iter().cloned().fold(f64::INFINITY, f64::min);
    let max = |v: &[f64]| v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let span = [min(&xs), min(&ys), max(&xs), max(&ys)];
    let area = [
        (span[0] - px / 2.0).max(0.0),
        (span[1] - py / 2.0).max(0.0),
        (span[2] + px / 2.0).min(fw),
        (span[3] + py / 2.0).min(fh),
    ];
    if area[0] >= area[2] || area[1] >= area[3] {
        return Err(Error::input(
            path,
            format!(
                "the zone centres span x {:.3}..{:.3}, y {:.3}..{:.3} mm: no area inside the {fw} x {fh} mm field",
                span[0], span[2], span[1], span[3]
            ),
        ));
    }
    Ok((span, area))
}

/// The chosen model of P and the cross-validated errors of the candidates.
struct Model {
    form: Form,
    degree: usize,
    cv: Vec<(u64, f64)>,
    cv_exp: Vec<(u64, f64)>,
    cv_inv: Vec<(u64, f64)>,
}

/// RMS and largest relative residual (with its line) of the model P·S over `used`.
fn residuals(used: &[&Reading], p_s: impl Fn(&Reading) -> f64) -> (f64, f64, u64) {
    let (mut ss, mut worst, mut worst_line) = (0.0, 0.0f64, 0u64);
    for r in used {
        let rel = p_s(r) / r.irradiance - 1.0;
        ss += rel * rel;
        if rel.abs() > worst.abs() {
            worst = rel;
            worst_line = r.line;
        }
    }
    ((ss / used.len() as f64).sqrt() * 100.0, worst, worst_line)
}

/// Per zone: the measured P from its own readings (`s_at`: S at a reading's gray) and the
/// fitted P (`p_xy`) at its centre.
fn zone_fits(
    used: &[&Reading],
    s_at: impl Fn(&Reading) -> f64,
    p_xy: impl Fn(f64, f64) -> f64,
) -> Vec<ZoneFit> {
    let mut zacc: BTreeMap<(i64, i64), (f64, f64, f64, f64)> = BTreeMap::new();
    for r in used {
        let q = s_at(r) / r.irradiance;
        let e = zacc
            .entry(position_key(r))
            .or_insert((r.x_mm, r.y_mm, 0.0, 0.0));
        e.2 += q;
        e.3 += q * q;
    }
    zacc.values()
        .map(|&(x, y, a, b)| ZoneFit {
            x_mm: x,
            y_mm: y,
            measured_p: a / b,
            fitted_p: p_xy(x, y),
        })
        .collect()
}

/// S through the valid levels (`grays` with values `s`), also interpolated to pixel value
/// 0 (mirror off, no light) when `to_zero`: the not-a-knot spline when it is increasing on
/// every gray, else PCHIP.
fn response_through(grays: &[u8], s: &[f64], to_zero: bool) -> Response {
    let mut points: Vec<[f64; 2]> = Vec::with_capacity(grays.len() + 1);
    if to_zero {
        points.push([0.0, 0.0]);
    }
    points.extend(grays.iter().zip(s).map(|(&g, &v)| [g as f64, v]));
    let table = |interpolation| Response::Table {
        interpolation,
        points: points.clone(),
    };
    let spline = table(Interpolation::Spline);
    match spline.validate() {
        Ok(()) => spline,
        Err(_) => table(Interpolation::Pchip),
    }
}

/// The coefficients of P for a form whose S was divided by `s_top` (P times `s_top`).
fn scaled_by(form: Form, mut coef: Vec<f64>, s_top: f64) -> Vec<f64> {
    match form {
        Form::Polynomial => coef.iter_mut().for_each(|c| *c *= s_top),
        Form::Exponential => coef[0] += s_top.ln(),
        Form::InverseSquare => coef.iter_mut().for_each(|c| *c /= s_top.sqrt()),
    }
    coef
}

/// `calibrate.poor-fit` when the residual RMS is above 3 %.
fn poor_fit(rms: f64, degree: usize, form: Form) -> Option<Warning> {
    (rms > 3.0).then(|| {
        Warning::new(
            "calibrate.poor-fit",
            format!(
                "residual RMS {rms:.2} %: the model P(x, y)·S(g) with a degree-{degree} {} P does not describe these measurements well",
                form_name(form)
            ),
        )
        .with("residual_rms_pct", rms)
        .with("degree", degree as u64)
        .with("form", form_name(form))
    })
}

/// Each measured gray level's S (the first fit's below the valid range `lo`) and its
/// readings divided by P.
fn level_fits(
    readings: &[Reading],
    glist: &[u8],
    lo: usize,
    s: &[f64],
    first: &FactorFit,
    p_at: &dyn Fn(&Reading) -> f64,
) -> Vec<LevelFit> {
    let top = glist.len() - 1;
    glist
        .iter()
        .enumerate()
        .map(|(j, &g)| LevelFit {
            gray: g,
            s: if j >= lo {
                s[j - lo]
            } else {
                first.s[j] / first.s[top]
            },
            valid: j >= lo,
            points: readings
                .iter()
                .filter(|r| r.gray == g)
                .map(|r| r.irradiance / p_at(r))
                .collect(),
        })
        .collect()
}

/// Fits a calibration to `readings` (from `path`, named in errors).
pub fn fit(readings: &[Reading], path: &Path, opts: &FitOptions) -> Result<FitResult> {
    let setup = Setup::new(readings, path, opts)?;
    let glist = &setup.grays;
    let top = glist.len() - 1;
    // First pass (cubic, all levels): the valid range of gray levels.
    let rows3 = setup.rows(3, 0);
    let first = alternating_least_squares(
        Form::Polynomial,
        &rows3.iter().collect::<Vec<_>>(),
        glist.len(),
    )
    .map_err(|c| setup.ill_conditioned(c))?;
    let lo = setup.valid_range(&first)?;
    let valid_n = top + 1 - lo;
    let model = setup.choose_model(lo, opts.degree)?;
    let (form, degree) = (model.form, model.degree);

    // Final fit on the valid levels, normalized so that S = 1 at the brightest level.
    let rows = setup.rows(degree, lo);
    let second = fit_form(form, &rows.iter().collect::<Vec<_>>(), valid_n)
        .map_err(|c| setup.ill_conditioned(c))?;
    let s_top = second.s[valid_n - 1];
    let coef = scaled_by(form, second.coef.clone(), s_top);
    let s: Vec<f64> = second.s.iter().map(|v| v / s_top).collect();
    if s.windows(2).any(|w| w[1] <= w[0]) {
        return Err(setup.input_error(
            "no monotone S fits the data: the refitted response is not increasing over the valid gray levels"
                .to_string(),
        ));
    }
    let poly = Poly::from_terms(degree, &coef);
    let p_xy = |x: f64, y: f64| {
        let (u, v) = setup.uv_of(x, y);
        form.apply(1.0, poly.eval(u, v))
    };
    let p_at = |r: &Reading| p_xy(r.x_mm, r.y_mm);
    let s_at = |r: &Reading| s[setup.level_index(r.gray) - lo];

    let used: Vec<&Reading> = readings.iter().filter(|r| r.gray >= glist[lo]).collect();
    let (rms, worst, worst_line) = residuals(&used, |r| p_at(r) * s_at(r));
    let warnings: Vec<Warning> = poor_fit(rms, degree, form).into_iter().collect();

    let zones = zone_fits(&used, s_at, p_xy);
    let levels = level_fits(readings, glist, lo, &s, &first, &p_at);
    // S: the measured levels; when S falls all the way down the measured levels, it is
    // also interpolated to pixel value 0 (mirror off, no light).
    let response = response_through(&glist[lo..], &s, lo == 0 && glist[0] > 0);

    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let calibration = Calibration {
        source: format!(
            "dmdsl calibrate {name} ({} readings, {} zones, {} gray levels, degree-{degree} {} P)",
            readings.len(),
            setup.pos.len(),
            glist.len(),
            form_name(form)
        ),
        units: opts.units,
        zone_mm: Positive::new(opts.zone_mm)
            .ok_or_else(|| Error::Usage(format!("zone size must be > 0, got {}", opts.zone_mm)))?,
        field: FieldModel {
            origin_mm: setup.origin,
            length_unit_mm: Positive::new(setup.unit).expect("unit > 0"),
            scale: Positive::new(1.0).expect("1 > 0"),
            form,
            coefficients: poly,
            area_mm: setup.area,
            // Degree ≤ 3 extrapolates reliably (Xu et al. 2010 use their cubic on the whole
            // grid); higher degrees continue linearly beyond the measured zone centres.
            polynomial_area_mm: (degree > 3).then_some(setup.span),
            extrapolate_mm: NonNegative::new(opts.extrapolate_mm).ok_or_else(|| {
                Error::Usage(format!(
                    "extrapolation distance must be >= 0, got {}",
                    opts.extrapolate_mm
                ))
            })?,
        },
        response,
        fit: Some(FitSummary {
            measurements: name,
            form,
            degree: degree as u64,
            cv_rms_pct: model.cv,
            cv_exp_rms_pct: model.cv_exp,
            cv_inv_rms_pct: model.cv_inv,
            measured_gray: [glist[lo], glist[top]],
            readings: used.len() as u64,
            zones: setup.pos.len() as u64,
            gray_levels: glist.len() as u64,
            excluded_grays: glist[..lo].to_vec(),
            residual_rms_pct: rms,
            residual_max_pct: worst * 100.0,
            residual_max_line: worst_line,
        }),
    };
    calibration.validate().map_err(|m| {
        setup.input_error(format!(
            "the fitted model is unusable ({m}); the measurements do not describe a smooth field"
        ))
    })?;
    Ok(FitResult {
        calibration,
        zones,
        levels,
        condition: second.condition,
        warnings,
    })
}

/// Why readings at the pixel values `grays` (fewer than 3) cannot give S(g), and how to
/// measure it.
fn too_few_grays(grays: &std::collections::BTreeSet<u8>) -> String {
    const HOW: &str = "S(g), the response to the pixel value, needs readings at 3 or more pixel values, including pixel values below 255: show a uniform mask of each gray (e.g. 255, 223, 191, 159, 127), read the meter at the zone centres (all of them, or a few) and add those rows with their gray";
    let list: Vec<String> = grays.iter().map(|g| g.to_string()).collect();
    if grays.iter().all(|&g| g == 255) {
        format!(
            "every reading is at gray 255 (mirrors fully on): that measures P(x, y) but not {HOW}"
        )
    } else {
        format!(
            "readings at only {} ({}): {HOW}",
            count(grays.len() as u64, "pixel value", "pixel values"),
            list.join(", ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("m.csv")
    }

    #[test]
    fn csv_errors_name_file_line_and_column() {
        let e = |t: &str| parse_csv(t, p()).unwrap_err().to_string();
        let h = "x_mm,y_mm,gray,irradiance_mw_cm2\n";
        assert_eq!(
            e("x_mm,y_mm,gray\n1,2,3\n"),
            "m.csv: line 1: missing column \"irradiance_mw_cm2\" (expected the header x_mm,y_mm,gray,irradiance_mw_cm2)"
        );
        assert!(e("x_mm,y_mm,gray,irradiance_mw_cm2,z\n").contains("line 1: unknown column \"z\""));
        assert_eq!(
            e(&format!("{h}1,2,255,3\n# c\n1,2,255\n")),
            "m.csv: line 4: expected 4 columns (x_mm,y_mm,gray,irradiance_mw_cm2), found 3"
        );
        assert_eq!(
            e(&format!("{h}1,abc,255,3\n")),
            "m.csv: line 2, column y_mm: \"abc\" is not a number"
        );
        assert_eq!(
            e(&format!("{h}1,2,255,0\n")),
            "m.csv: line 2, column irradiance_mw_cm2: must be > 0, got 0"
        );
        assert!(e(&format!("{h}1,2,255,-1\n")).contains("must be > 0"));
        assert_eq!(
            e(&format!("{h}1,2,255.5,1\n")),
            "m.csv: line 2, column gray: 255.5 is not an integer pixel value 0..255"
        );
        assert!(
            e(&format!("{h}1,2,NaN,1\n")).contains("column gray: \"NaN\" is not a finite number")
        );
        assert!(e("").contains("empty file"));
        assert!(e(h).contains("no measurements"));
        // Column order is free; CRLF, comments and a gray written as a decimal are fine.
        let r = parse_csv(
            "# m\r\ngray,irradiance_mw_cm2,x_mm,y_mm\r\n200.0,1.5,3,4 # zone 7\r\n",
            p(),
        )
        .unwrap();
        assert_eq!(
            r,
            vec![Reading {
                line: 3,
                x_mm: 3.0,
                y_mm: 4.0,
                gray: 200,
                irradiance: 1.5
            }]
        );
    }
}
