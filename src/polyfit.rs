//! Polynomial least squares: the bivariate monomial basis and one least-squares solver,
//! shared by the light calibration fit (`optics::calib`: the field factor P) and the lens
//! distortion fit (`geometry::distortion`: the correction map).
//!
//! The solver factors the design matrix A = Q·R by Householder reflections (nalgebra) and
//! solves R·x = Qᵀ·y: unlike the normal equations AᵀA·x = Aᵀy it does not square A's
//! condition number. The same factors give the leverages (the diagonal of the hat matrix
//! Q·Qᵀ, for closed-form leave-one-out residuals) and the condition number of A (the
//! singular values of R are those of A).

use nalgebra::{DMatrix, DVector};

/// Highest total degree [`basis_into`] evaluates.
pub const MAX_BASIS_DEGREE: usize = 15;

/// Number of monomials u^a·v^b with a + b ≤ `degree`.
pub fn terms(degree: usize) -> usize {
    (degree + 1) * (degree + 2) / 2
}

/// The monomials (a, b) of u^a·v^b, a + b ≤ `degree`, by total degree, then by descending a
/// (1, u, v, u², uv, v², …).
pub fn monomials(degree: usize) -> Vec<(usize, usize)> {
    let mut m = Vec::with_capacity(terms(degree));
    for t in 0..=degree {
        for a in (0..=t).rev() {
            m.push((a, t - a));
        }
    }
    m
}

/// The monomials of [`monomials`] order evaluated at (u, v), written to
/// `out[..terms(degree)]`.
///
/// # Panics
/// If `degree` exceeds [`MAX_BASIS_DEGREE`] or `out` is shorter than `terms(degree)`.
pub fn basis_into(degree: usize, u: f64, v: f64, out: &mut [f64]) {
    assert!(degree <= MAX_BASIS_DEGREE, "degree {degree} too high");
    let mut pu = [1.0; MAX_BASIS_DEGREE + 1];
    let mut pv = [1.0; MAX_BASIS_DEGREE + 1];
    for k in 1..=degree {
        pu[k] = pu[k - 1] * u;
        pv[k] = pv[k - 1] * v;
    }
    let mut i = 0;
    for t in 0..=degree {
        for b in 0..=t {
            out[i] = pu[t - b] * pv[b];
            i += 1;
        }
    }
}

/// A linear least-squares problem min ‖A·x − y‖₂ with its design matrix A (n × m, n ≥ m)
/// factored once, for any number of right-hand sides y.
#[derive(Debug, Clone)]
pub struct LeastSquares {
    /// Qᵀ of the thin factor Q (m × n).
    qt: DMatrix<f64>,
    /// R (m × m, upper triangular).
    r: DMatrix<f64>,
}

impl LeastSquares {
    /// Factors the design matrix `a`; `None` when it has fewer rows than columns.
    pub fn new(a: DMatrix<f64>) -> Option<LeastSquares> {
        if a.nrows() < a.ncols() {
            return None;
        }
        let qr = a.qr();
        Some(LeastSquares {
            qt: qr.q().transpose(),
            r: qr.r(),
        })
    }

    /// Whether every diagonal entry of R exceeds `rel` times the largest in magnitude, i.e.
    /// no column of A is (to that tolerance) a combination of the columns before it.
    pub fn full_rank(&self, rel: f64) -> bool {
        let m = self.r.ncols();
        let rmax = (0..m).map(|k| self.r[(k, k)].abs()).fold(0.0, f64::max);
        (0..m).all(|k| self.r[(k, k)].abs() > rel * rmax.max(1e-300))
    }

    /// The 2-norm condition number of A, σ_max / σ_min (infinite when A is singular).
    pub fn condition(&self) -> f64 {
        let sv = self.r.clone().singular_values();
        let (lo, hi) = (sv.min(), sv.max());
        if lo > 0.0 {
            hi / lo
        } else {
            f64::INFINITY
        }
    }

    /// The x minimizing ‖A·x − y‖₂ (`y` has one entry per row of A); `None` when R is
    /// singular.
    pub fn solve(&self, y: &DVector<f64>) -> Option<DVector<f64>> {
        self.r.solve_upper_triangular(&(&self.qt * y))
    }

    /// The leverage of observation `i`: entry (i, i) of the hat matrix A·(AᵀA)⁻¹·Aᵀ = Q·Qᵀ.
    /// A fit's leave-one-out residual at i is its residual there divided by 1 − leverage.
    pub fn leverage(&self, i: usize) -> f64 {
        (0..self.qt.nrows())
            .map(|k| self.qt[(k, i)] * self.qt[(k, i)])
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monomials_and_basis_agree() {
        assert_eq!(
            monomials(2),
            vec![(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
        );
        for d in 0..=6 {
            assert_eq!(monomials(d).len(), terms(d));
            let mut b = vec![0.0; terms(d)];
            basis_into(d, 0.7, -1.3, &mut b);
            for (&(a, c), &v) in monomials(d).iter().zip(&b) {
                let want = 0.7f64.powi(a as i32) * (-1.3f64).powi(c as i32);
                assert!(
                    (v - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "{d} {a} {c}"
                );
            }
        }
    }

    /// The normal equations solved by Gaussian elimination, for small well-conditioned
    /// problems: an independent oracle.
    fn normal_equations(a: &DMatrix<f64>, y: &DVector<f64>) -> DVector<f64> {
        (a.transpose() * a)
            .lu()
            .solve(&(a.transpose() * y))
            .unwrap()
    }

    #[test]
    fn solves_fits_and_leverages_like_the_normal_equations() {
        // A quadratic surface plus a fixed wobble, on a 7 × 5 grid.
        let pts: Vec<(f64, f64)> = (0..35)
            .map(|i| ((i % 7) as f64 / 3.0 - 1.0, (i / 7) as f64 / 2.0 - 1.0))
            .collect();
        let m = terms(2);
        let mut a = DMatrix::zeros(pts.len(), m);
        let mut row = vec![0.0; m];
        for (i, &(u, v)) in pts.iter().enumerate() {
            basis_into(2, u, v, &mut row);
            for k in 0..m {
                a[(i, k)] = row[k];
            }
        }
        let y = DVector::from_iterator(
            pts.len(),
            pts.iter().enumerate().map(|(i, &(u, v))| {
                1.0 + 2.0 * u - v + 0.5 * u * v + 0.01 * ((i * 7 % 5) as f64 - 2.0)
            }),
        );
        let ls = LeastSquares::new(a.clone()).unwrap();
        assert!(ls.full_rank(1e-9));
        let x = ls.solve(&y).unwrap();
        let want = normal_equations(&a, &y);
        assert!((&x - &want).amax() < 1e-12, "{x} vs {want}");
        // Leverages: the hat matrix's diagonal, which sums to the number of unknowns.
        let hat = &a * (a.transpose() * &a).try_inverse().unwrap() * a.transpose();
        for i in 0..pts.len() {
            assert!((ls.leverage(i) - hat[(i, i)]).abs() < 1e-12);
        }
        let total: f64 = (0..pts.len()).map(|i| ls.leverage(i)).sum();
        assert!((total - m as f64).abs() < 1e-10);
        // The condition number is that of A: sqrt of the eigenvalue ratio of AᵀA.
        let ev = (a.transpose() * &a).symmetric_eigenvalues();
        let want = (ev.max() / ev.min()).sqrt();
        assert!((ls.condition() / want - 1.0).abs() < 1e-9);
    }

    #[test]
    fn rank_deficient_and_short_designs_are_refused() {
        // Two equal columns.
        let a = DMatrix::from_row_slice(4, 2, &[1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 4.0, 4.0]);
        let ls = LeastSquares::new(a).unwrap();
        assert!(!ls.full_rank(1e-9));
        assert!(ls.condition() > 1e12);
        assert!(LeastSquares::new(DMatrix::zeros(2, 3)).is_none());
    }
}
