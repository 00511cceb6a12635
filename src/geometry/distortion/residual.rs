//! The local part of the correction: a natural-neighbour interpolant (spade, Sibson
//! weights) of the polynomial's residuals at the table's seen points. It captures assembly
//! errors no low-order formula describes (Yu et al.); its weight κ is chosen from its
//! leave-one-out predictions so that pure noise is not passed through.

use super::polynomial::PolyMap;
use super::table::Table;
use crate::error::Result;
use spade::handles::FixedVertexHandle;
use spade::{DelaunayTriangulation, HasPosition, NaturalNeighbor, Point2, Triangulation};

/// A seen point and the polynomial's residual (aim − fit) there.
#[derive(Debug, Clone, Copy)]
pub(super) struct Site {
    pos: Point2<f64>,
    r: [f64; 2],
}

impl HasPosition for Site {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.pos
    }
}

/// The triangulated residuals.
pub(super) type Tri = DelaunayTriangulation<Site>;

/// Triangulates the residuals of `poly` at the table's seen points; returns the
/// triangulation and the residuals in table order.
pub(super) fn triangulate(table: &Table, poly: &PolyMap) -> Result<(Tri, Vec<[f64; 2]>)> {
    let mut tri = Tri::new();
    let mut resid = Vec::with_capacity(table.pairs.len());
    for p in &table.pairs {
        let f = poly.eval(p.seen);
        let r = [p.aim[0] - f[0], p.aim[1] - f[1]];
        resid.push(r);
        tri.insert(Site {
            pos: Point2::new(p.seen[0], p.seen[1]),
            r,
        })
        .map_err(|e| table.err(p.line, format!("cannot triangulate this point: {e:?}")))?;
    }
    Ok((tri, resid))
}

/// Leave-one-out residual interpolation: each point removed, the others' residuals
/// interpolated at its position, the point put back. In table order.
pub(super) fn leave_one_out(tri: &Tri, table: &Table) -> Result<Vec<[f64; 2]>> {
    let mut out = Vec::with_capacity(table.pairs.len());
    let mut t = tri.clone();
    let mut buf = Vec::new();
    for p in &table.pairs {
        let pos = Point2::new(p.seen[0], p.seen[1]);
        let h = t.locate_vertex(pos).map(|v| v.fix());
        let Some(h) = h else {
            out.push([0.0; 2]);
            continue;
        };
        let site = t.remove(h);
        let v = if t.num_inner_faces() > 0 {
            let nn = t.natural_neighbor();
            residual_at(&t, &nn, &mut buf, p.seen).0
        } else {
            [0.0; 2]
        };
        out.push(v);
        t.insert(site)
            .map_err(|e| table.err(p.line, format!("cannot triangulate: {e:?}")))?;
    }
    Ok(out)
}

/// The weight κ ∈ [0, 1] of the interpolant that minimizes the leave-one-out error of
/// polynomial + κ·interpolant, from the polynomial's leave-one-out residuals `loo` and the
/// interpolant's leave-one-out predictions `loo_r` of them.
pub(super) fn weight(loo: &[[f64; 2]], loo_r: &[[f64; 2]]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (e, r) in loo.iter().zip(loo_r) {
        num += e[0] * r[0] + e[1] * r[1];
        den += r[0] * r[0] + r[1] * r[1];
    }
    if den > 0.0 {
        (num / den).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// The steepest residual slope along a Delaunay edge (a bound, up to a margin, on the
/// interpolant's slope).
pub(super) fn steepest_edge(tri: &Tri) -> f64 {
    tri.undirected_edges()
        .map(|e| {
            let [a, b] = e.vertices();
            let (a, b) = (a.data(), b.data());
            let d = (a.pos.x - b.pos.x).hypot(a.pos.y - b.pos.y);
            (a.r[0] - b.r[0]).hypot(a.r[1] - b.r[1]) / d.max(1e-9)
        })
        .fold(0.0, f64::max)
}

/// Convex hull of the seen points, in the triangulation's order.
pub(super) fn hull(tri: &Tri) -> Vec<[f64; 2]> {
    tri.convex_hull()
        .map(|e| {
            let p = e.from().position();
            [p.x, p.y]
        })
        .collect()
}

/// Residual at `p` by natural-neighbour interpolation; outside the convex hull, linear
/// interpolation on the nearest hull edge. Returns (value, extrapolated).
pub(super) fn residual_at(
    tri: &Tri,
    nn: &NaturalNeighbor<'_, Tri>,
    buf: &mut Vec<(FixedVertexHandle, f64)>,
    p: [f64; 2],
) -> ([f64; 2], bool) {
    nn.get_weights(Point2::new(p[0], p[1]), buf);
    if !buf.is_empty() {
        let mut o = [0.0; 2];
        for &(h, w) in buf.iter() {
            let r = tri.vertex(h).data().r;
            o[0] += w * r[0];
            o[1] += w * r[1];
        }
        // On a straight stretch of the hull the weights can degenerate; the hull-edge rule
        // below gives the same (linear) value there.
        if o[0].is_finite() && o[1].is_finite() {
            return (o, false);
        }
    }
    let mut best = (f64::INFINITY, [0.0; 2]);
    for e in tri.convex_hull() {
        let a = *e.from().data();
        let b = *e.to().data();
        let (ax, ay) = (a.pos.x, a.pos.y);
        let (dx, dy) = (b.pos.x - ax, b.pos.y - ay);
        let l2 = dx * dx + dy * dy;
        let t = if l2 > 0.0 {
            (((p[0] - ax) * dx + (p[1] - ay) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (qx, qy) = (ax + t * dx - p[0], ay + t * dy - p[1]);
        let d2 = qx * qx + qy * qy;
        if d2 < best.0 {
            best = (
                d2,
                [
                    a.r[0] + t * (b.r[0] - a.r[0]),
                    a.r[1] + t * (b.r[1] - a.r[1]),
                ],
            );
        }
    }
    (best.1, best.0 > 1e-18)
}
