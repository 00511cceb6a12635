//! Pre-warping section contours through a [`Correction`]: every vertex is moved to where
//! the projector must aim, and edges are densified so the warped polyline stays within
//! [`SAG_PX`](super::SAG_PX) of the warped curve.

use super::correction::Correction;
use super::residual::{self, Tri};
use super::SEG_MM;
use crate::slice::Contour;
use spade::handles::FixedVertexHandle;
use spade::NaturalNeighbor;

/// A point the projector cannot reach after correction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unreachable {
    /// The wanted build-plane point, mm.
    pub target: [f64; 2],
    /// Where the projector would have to aim, mm.
    pub aim: [f64; 2],
}

/// Evaluates a [`Correction`] (one per thread: it owns interpolation buffers).
pub struct Warper<'a> {
    c: &'a Correction,
    nn: NaturalNeighbor<'a, Tri>,
    buf: Vec<(FixedVertexHandle, f64)>,
    extrapolated: u64,
}

impl<'a> Warper<'a> {
    /// An evaluator of `c`.
    pub(super) fn new(c: &'a Correction) -> Warper<'a> {
        Warper {
            c,
            nn: c.tri.natural_neighbor(),
            buf: Vec::new(),
            extrapolated: 0,
        }
    }
}

impl Warper<'_> {
    /// Points warped so far that lie outside the convex hull of the table's seen points.
    pub fn extrapolated(&self) -> u64 {
        self.extrapolated
    }

    /// Where the projector must aim so light lands at build-plane point `w`.
    pub fn aim(&mut self, w: [f64; 2]) -> [f64; 2] {
        let mut a = self.c.poly.eval(w);
        if self.c.kappa > 0.0 {
            let (r, ex) = residual::residual_at(&self.c.tri, &self.nn, &mut self.buf, w);
            a[0] += self.c.kappa * r[0];
            a[1] += self.c.kappa * r[1];
            self.extrapolated += ex as u64;
        } else {
            // Count extrapolation for the report even when the interpolant is off.
            self.extrapolated += !inside_convex(&self.c.hull, w) as u64;
        }
        a
    }

    /// True when the warped segment of build-plane length `len` provably stays within half
    /// the sag tolerance of its chord (no midpoint test needed).
    fn flat_enough(&self, len: f64) -> bool {
        self.c.curv * len * len / 8.0 + self.c.kappa * self.c.lip * len / 2.0 <= 0.5 * self.c.tol_mm
    }

    /// Ok when the aim point `a` of build-plane point `target` is inside the projector field.
    pub(super) fn reach(
        &self,
        target: [f64; 2],
        a: [f64; 2],
    ) -> std::result::Result<(), Unreachable> {
        let eps = 1e-9;
        let f = self.c.field_mm;
        if a[0] < -eps || a[1] < -eps || a[0] > f[0] + eps || a[1] > f[1] + eps {
            return Err(Unreachable { target, aim: a });
        }
        Ok(())
    }

    /// Pre-warps contours: every vertex through [`aim`](Self::aim), edges densified so the
    /// warped polyline stays within [`SAG_PX`](super::SAG_PX) of the warped edge.
    pub fn warp(&mut self, contours: &[Contour]) -> std::result::Result<Vec<Contour>, Unreachable> {
        let mut out = Vec::with_capacity(contours.len());
        for c in contours {
            if c.is_empty() {
                continue;
            }
            let mut o: Contour = Vec::with_capacity(c.len() * 2);
            let first = self.aim(c[0]);
            let mut pa = first;
            for i in 0..c.len() {
                let a = c[i];
                let b = c[(i + 1) % c.len()];
                self.reach(a, pa)?;
                o.push(pa);
                let pb = if i + 1 == c.len() { first } else { self.aim(b) };
                self.warp_edge(a, b, pa, pb, &mut o)?;
                pa = pb;
            }
            out.push(o);
        }
        Ok(out)
    }

    /// Pushes the interior points of the warped edge a→b (warped ends pa, pb): cut into
    /// pieces of at most [`SEG_MM`], each refined unless it is provably flat enough.
    fn warp_edge(
        &mut self,
        a: [f64; 2],
        b: [f64; 2],
        pa: [f64; 2],
        pb: [f64; 2],
        o: &mut Contour,
    ) -> std::result::Result<(), Unreachable> {
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let pieces = (len / SEG_MM).ceil().max(1.0) as usize;
        let mut qa = pa;
        for k in 1..=pieces {
            let t1 = k as f64 / pieces as f64;
            let t0 = (k - 1) as f64 / pieces as f64;
            let s0 = lerp(a, b, t0);
            let s1 = lerp(a, b, t1);
            let qb = if k == pieces { pb } else { self.aim(s1) };
            if !self.flat_enough(len / pieces as f64) {
                self.refine(s0, s1, qa, qb, 0, o)?;
            }
            if k < pieces {
                self.reach(s1, qb)?;
                o.push(qb);
            }
            qa = qb;
        }
        Ok(())
    }

    /// Pushes the interior points of the warped segment s0→s1 (warped ends q0, q1).
    fn refine(
        &mut self,
        s0: [f64; 2],
        s1: [f64; 2],
        q0: [f64; 2],
        q1: [f64; 2],
        depth: u32,
        o: &mut Contour,
    ) -> std::result::Result<(), Unreachable> {
        if depth >= 12 {
            return Ok(());
        }
        let sm = lerp(s0, s1, 0.5);
        let qm = self.aim(sm);
        let chord = lerp(q0, q1, 0.5);
        if (qm[0] - chord[0]).hypot(qm[1] - chord[1]) <= self.c.tol_mm {
            return Ok(());
        }
        self.refine(s0, sm, q0, qm, depth + 1, o)?;
        self.reach(sm, qm)?;
        o.push(qm);
        self.refine(sm, s1, qm, q1, depth + 1, o)
    }
}

/// Point in (or on) a CCW convex polygon.
fn inside_convex(hull: &[[f64; 2]], q: [f64; 2]) -> bool {
    let n = hull.len();
    (0..n).all(|i| {
        let (a, b) = (hull[i], hull[(i + 1) % n]);
        (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) >= -1e-9
    })
}

/// The point at `t` of the segment a→b.
pub(super) fn lerp(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
}
