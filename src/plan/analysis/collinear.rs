//! Sections without their collinear points: a prism's layers, cut through the same
//! straight walls at different heights, then compare equal (see [`COLLINEAR_MM`]).

use crate::slice::Contour;

/// Points closer than this to the segment joining their neighbours are left out of the
/// analysed section, mm: the slicer's points on a straight wall slide along it from layer
/// to layer, and without them consecutive sections of a prism are equal (analysed once).
/// Moving the boundary by at most this much moves a fill distance by at most as much.
pub const COLLINEAR_MM: f64 = 1e-9;

/// At most this many consecutive points are left out (each left-out point is checked
/// against the final segment, so the cost stays linear).
const COLLINEAR_MAX_RUN: usize = 16;

/// Whether `b` lies within [`COLLINEAR_MM`] of the segment `a`–`d` (and between its ends).
#[inline]
fn near_segment(a: [f64; 2], b: [f64; 2], d: [f64; 2]) -> bool {
    let eps2 = COLLINEAR_MM * COLLINEAR_MM;
    let (ux, uy) = (d[0] - a[0], d[1] - a[1]);
    let (vx, vy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = ux * ux + uy * uy;
    let cross = ux * vy - uy * vx;
    // Most points are corners: off the line.
    if cross * cross > eps2 * l2 {
        return false;
    }
    if l2 == 0.0 {
        return vx * vx + vy * vy <= eps2;
    }
    (0.0..=l2).contains(&(ux * vx + uy * vy))
}

/// `c` without its collinear points (within [`COLLINEAR_MM`] of the segment that replaces
/// them), starting at its smallest point (x, then y), into `out`. For contours whose
/// corners stand clear of the tolerance the result depends only on the geometry and
/// direction, not on where the contour started, so two layers with the same walls give
/// equal contours (a near-degenerate corner can make them differ: the layers are then
/// analysed separately, never wrongly). Every point of either boundary is within
/// [`COLLINEAR_MM`] of the other.
fn simplify_contour(c: &[[f64; 2]], out: &mut Vec<[f64; 2]>) {
    out.clear();
    let n = c.len();
    // Start at a corner: a point off the segment of its two neighbours.
    let corner = (0..n).find(|&i| {
        let a = c[if i == 0 { n - 1 } else { i - 1 }];
        !near_segment(a, c[i], c[if i + 1 == n { 0 } else { i + 1 }])
    });
    let first = match corner.filter(|_| n > 3) {
        Some(s) => leave_out_collinear(c, s, out),
        None => {
            out.extend_from_slice(c);
            (0..n).fold(0, |m, i| if less(c[i], c[m]) { i } else { m })
        }
    };
    out.rotate_left(first);
}

/// `p < q` by x, then y.
#[inline]
fn less(p: [f64; 2], q: [f64; 2]) -> bool {
    p[0] < q[0] || (p[0] == q[0] && p[1] < q[1])
}

/// The points of `c` from its corner `s` on, without those within [`COLLINEAR_MM`] of
/// the segment that replaces them, into `out`; returns the index in `out` of the
/// smallest point.
fn leave_out_collinear(c: &[[f64; 2]], s: usize, out: &mut Vec<[f64; 2]>) -> usize {
    let n = c.len();
    // The k-th point from the corner on (k = n is the corner again).
    let at = |k: usize| c[if s + k >= n { s + k - n } else { s + k }];
    let mut anchor = c[s];
    out.push(anchor);
    let mut min = 0;
    // Points left out since the anchor, as steps from the corner.
    let mut left = [0usize; COLLINEAR_MAX_RUN];
    let mut nl = 0;
    let mut d = at(1);
    for k in 1..n {
        let b = d;
        d = at(k + 1);
        if nl < COLLINEAR_MAX_RUN
            && near_segment(anchor, b, d)
            && left[..nl].iter().all(|&i| near_segment(anchor, at(i), d))
        {
            left[nl] = k;
            nl += 1;
        } else {
            if less(b, out[min]) {
                min = out.len();
            }
            out.push(b);
            anchor = b;
            nl = 0;
        }
    }
    min
}

/// [`simplify_contour`] of every contour into `out` (its vectors are reused).
pub(super) fn simplify_section(contours: &[Contour], out: &mut Vec<Contour>) {
    out.resize_with(contours.len(), Vec::new);
    for (c, o) in contours.iter().zip(out.iter_mut()) {
        simplify_contour(c, o);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::analysis::test_support::{with_collinear_points, xorshift};
    use crate::plan::analysis::Edges;

    /// Largest distance from a vertex of `a` to the polygon (closed polyline) `b`.
    fn vertex_gap(a: &Contour, b: &Contour) -> f64 {
        let e = Edges::new(std::slice::from_ref(b));
        a.iter().map(|&p| e.distance(p)).fold(0.0, f64::max)
    }

    #[test]
    fn collinear_points_are_left_out_wherever_the_contour_starts() {
        let mut rnd = xorshift(0xc011_1ea7);
        for case in 0..200 {
            // Random star-shaped polygons, some with collinear corners of their own.
            let n = 3 + case % 9;
            let base: Contour = (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * (i as f64 + 0.3 * rnd()) / n as f64;
                    let r = 2.0 + 8.0 * rnd();
                    [20.0 + r * a.cos(), 15.0 + r * a.sin()]
                })
                .collect();
            let mut want = Vec::new();
            simplify_contour(&base, &mut want);
            for start in [0, n / 2, n - 1] {
                let cut = with_collinear_points(&base, start, &mut rnd);
                let mut got = Vec::new();
                simplify_contour(&cut, &mut got);
                assert_eq!(got, want, "case {case}, start {start}");
                // Every point of either boundary lies within the tolerance of the other.
                assert!(vertex_gap(&cut, &got) <= COLLINEAR_MM, "case {case}");
                assert!(vertex_gap(&got, &cut) <= COLLINEAR_MM, "case {case}");
            }
        }
    }

    #[test]
    fn simplified_contours_stay_within_the_tolerance_on_fine_arcs() {
        // Arc points so dense that each lies within the tolerance of its neighbours'
        // chord: leaving out a long run of them would cut the arc, the run limit and the
        // check against the final segment must not.
        let r = 10.0;
        let step = (2.0 * COLLINEAR_MM / r).sqrt() * 0.9;
        let mut c: Contour = (0..2000)
            .map(|i| {
                let a = i as f64 * step;
                [r * a.cos(), r * a.sin()]
            })
            .collect();
        c.push([0.0, 0.0]);
        let mut got = Vec::new();
        simplify_contour(&c, &mut got);
        assert!(got.len() < c.len(), "some points are left out");
        assert!(vertex_gap(&c, &got) <= COLLINEAR_MM);
        assert!(vertex_gap(&got, &c) <= COLLINEAR_MM);
        // Too few points: kept as they are. A flat contour (there and back along a line)
        // stays one.
        let c = vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]];
        simplify_contour(&c, &mut got);
        assert_eq!(got, c);
        let c = vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [1.0, 0.0]];
        simplify_contour(&c, &mut got);
        assert_eq!(got, vec![[0.0, 0.0], [2.0, 0.0]]);
    }
}
