//! The smooth part of the correction: a least-squares polynomial map (seen point → aim
//! point) in normalized coordinates, its degree chosen by leave-one-out cross-validation,
//! and a bound on its curvature for the warper.

use super::table::Pair;
use super::MAX_DEGREE;
use crate::polyfit::{self, LeastSquares};
use nalgebra::{DMatrix, DVector};

/// Bivariate polynomial map of total degree `degree` in normalized coordinates: one
/// polynomial per output coordinate.
#[derive(Debug, Clone)]
pub(super) struct PolyMap {
    pub(super) degree: usize,
    center: [f64; 2],
    scale: [f64; 2],
    coef: [Vec<f64>; 2],
}

/// Largest number of terms (degree [`MAX_DEGREE`]).
const MAX_TERMS: usize = (MAX_DEGREE + 1) * (MAX_DEGREE + 2) / 2;

impl PolyMap {
    fn norm(&self, p: [f64; 2]) -> (f64, f64) {
        (
            (p[0] - self.center[0]) / self.scale[0],
            (p[1] - self.center[1]) / self.scale[1],
        )
    }

    /// The map at build-plane point `p`, mm.
    pub(super) fn eval(&self, p: [f64; 2]) -> [f64; 2] {
        let mut b = [0.0; MAX_TERMS];
        let (u, v) = self.norm(p);
        polyfit::basis_into(self.degree, u, v, &mut b);
        let m = polyfit::terms(self.degree);
        self.coef
            .each_ref()
            .map(|c| c.iter().zip(&b[..m]).map(|(c, x)| c * x).sum())
    }

    /// Least-squares fit of degree `d` of aim on seen; returns the map and the leave-one-out
    /// residuals (target − prediction without that point), or None if the design is rank
    /// deficient or a point has leverage 1.
    fn fit(
        d: usize,
        center: [f64; 2],
        scale: [f64; 2],
        pairs: &[Pair],
    ) -> Option<(PolyMap, Vec<[f64; 2]>)> {
        let n = pairs.len();
        let m = polyfit::terms(d);
        if n < m + 1 {
            return None;
        }
        let mut x = DMatrix::<f64>::zeros(n, m);
        let mut b = [0.0; MAX_TERMS];
        for (i, p) in pairs.iter().enumerate() {
            let u = (p.seen[0] - center[0]) / scale[0];
            let v = (p.seen[1] - center[1]) / scale[1];
            polyfit::basis_into(d, u, v, &mut b);
            for k in 0..m {
                x[(i, k)] = b[k];
            }
        }
        let ls = LeastSquares::new(x)?;
        if !ls.full_rank(1e-9) {
            return None;
        }
        let solve = |k: usize| {
            let y = DVector::from_iterator(n, pairs.iter().map(|p| p.aim[k]));
            ls.solve(&y)
                .map(|c| c.iter().copied().collect::<Vec<f64>>())
        };
        let coef = [solve(0)?, solve(1)?];
        let poly = PolyMap {
            degree: d,
            center,
            scale,
            coef,
        };
        let mut loo = Vec::with_capacity(n);
        for (i, p) in pairs.iter().enumerate() {
            let h = ls.leverage(i);
            if h >= 1.0 - 1e-9 {
                return None;
            }
            let f = poly.eval(p.seen);
            loo.push([(p.aim[0] - f[0]) / (1.0 - h), (p.aim[1] - f[1]) / (1.0 - h)]);
        }
        Some((poly, loo))
    }

    /// The degree (1..=[`MAX_DEGREE`]) with the smallest leave-one-out error (PRESS) whose
    /// terms leave at least half the points as redundancy, fitted in seen coordinates
    /// normalized to [-1, 1]: the map and its leave-one-out residuals. None when no degree
    /// can be fitted (the seen points are collinear or nearly).
    pub(super) fn fit_best(pairs: &[Pair]) -> Option<(PolyMap, Vec<[f64; 2]>)> {
        let n = pairs.len();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in pairs {
            for k in 0..2 {
                lo[k] = lo[k].min(p.seen[k]);
                hi[k] = hi[k].max(p.seen[k]);
            }
        }
        let center = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        let scale = [
            ((hi[0] - lo[0]) / 2.0).max(1e-6),
            ((hi[1] - lo[1]) / 2.0).max(1e-6),
        ];
        let mut best: Option<(f64, PolyMap, Vec<[f64; 2]>)> = None;
        for d in 1..=MAX_DEGREE {
            if n < 2 * polyfit::terms(d) {
                break;
            }
            if let Some((poly, loo)) = PolyMap::fit(d, center, scale, pairs) {
                let press: f64 = loo.iter().map(|e| e[0] * e[0] + e[1] * e[1]).sum();
                if best.as_ref().is_none_or(|b| press < b.0) {
                    best = Some((press, poly, loo));
                }
            }
        }
        best.map(|(_, poly, loo)| (poly, loo))
    }

    /// Largest second directional derivative of the map over the field (plus a 5 mm
    /// margin), from its Hessian on a 0.5 mm grid by central differences, with a 1.5×
    /// safety factor: the sag of a warped segment of length L is at most curv · L² / 8.
    pub(super) fn curvature_bound(&self, field_mm: [f64; 2]) -> f64 {
        let h = 0.05;
        let mut worst = 0.0f64;
        let (nx, ny) = (
            ((field_mm[0] + 10.0) / 0.5) as usize,
            ((field_mm[1] + 10.0) / 0.5) as usize,
        );
        for j in 0..=ny {
            for i in 0..=nx {
                let p = [-5.0 + i as f64 * 0.5, -5.0 + j as f64 * 0.5];
                let f = |dx: f64, dy: f64| self.eval([p[0] + dx, p[1] + dy]);
                let c = f(0.0, 0.0);
                let (xp, xm, yp, ym) = (f(h, 0.0), f(-h, 0.0), f(0.0, h), f(0.0, -h));
                let (pp, pm, mp, mm) = (f(h, h), f(h, -h), f(-h, h), f(-h, -h));
                let mut s = 0.0;
                for k in 0..2 {
                    let gxx = (xp[k] - 2.0 * c[k] + xm[k]) / (h * h);
                    let gyy = (yp[k] - 2.0 * c[k] + ym[k]) / (h * h);
                    let gxy = (pp[k] - pm[k] - mp[k] + mm[k]) / (4.0 * h * h);
                    // Frobenius norm bounds the spectral norm.
                    s += gxx * gxx + gyy * gyy + 2.0 * gxy * gxy;
                }
                worst = worst.max(s.sqrt());
            }
        }
        1.5 * worst
    }
}
