//! Coarse contours: without the points within [`COARSE_MM`] of the segment that replaces
//! them, the contours the max fill distance is searched on.

use crate::slice::Contour;

/// Boundary points within this distance of the segment that replaces them are left out of
/// the contours the max fill distance is searched on, mm (a fine mesh gives a contour point
/// every few hundredths of a millimetre; most of them go). See
/// [`max_fill_distance`](super::max_fill_distance).
pub const COARSE_MM: f64 = 0.0005;

/// Longest run of consecutive points left out by [`coarsen`] (each one is checked against
/// the final segment).
const COARSE_MAX_RUN: usize = 16;

/// `c` without the points within [`COARSE_MM`] of the segment that replaces them (and
/// between its ends), into `out`; returns the largest squared distance of a left-out point
/// to its segment (0 when none is left out). With `δ` its root, every point of either
/// boundary is within `δ` of the other: the left-out points lie in the segment's `δ`-tube,
/// a convex set, so the path through them does too, and that path crosses every
/// perpendicular of the segment. Distances to the two boundaries differ by at most `δ`.
fn coarsen(c: &[[f64; 2]], out: &mut Vec<[f64; 2]>) -> f64 {
    out.clear();
    let n = c.len();
    if n < 4 {
        out.extend_from_slice(c);
        return 0.0;
    }
    out.reserve(n);
    const EPS2: f64 = COARSE_MM * COARSE_MM;
    let mut dev2: f64 = 0.0;
    let mut anchor = c[0];
    out.push(anchor);
    // The points left out since the anchor: `c[s..k]` (`s` is where the run starts).
    let mut s = 1;
    for k in 1..n {
        let b = c[k];
        let d = if k + 1 < n { c[k + 1] } else { c[0] };
        let run = &c[s..k];
        // Whether b and the run's points all lie within the tolerance of the segment from
        // the anchor to d (and between its ends).
        let left_out = run.len() < COARSE_MAX_RUN && {
            let (ux, uy) = (d[0] - anchor[0], d[1] - anchor[1]);
            let l2 = ux * ux + uy * uy;
            if l2 == 0.0 {
                // d repeats the anchor: only points within the tolerance of it.
                let near = |p: &[f64; 2]| {
                    let (vx, vy) = (p[0] - anchor[0], p[1] - anchor[1]);
                    vx * vx + vy * vy <= EPS2
                };
                near(&b) && run.iter().all(near)
            } else {
                let tol = EPS2 * l2;
                let near = |p: &[f64; 2]| {
                    let (vx, vy) = (p[0] - anchor[0], p[1] - anchor[1]);
                    let cross = ux * vy - uy * vx;
                    let dot = ux * vx + uy * vy;
                    cross * cross <= tol && dot >= 0.0 && dot <= l2
                };
                near(&b) && run.iter().all(near)
            }
        };
        if !left_out {
            // The run ends: its points' distances to their final segment (anchor to b).
            // (Plain comparisons: the squares are neither NaN nor −0.)
            let r = run_d2(anchor, run, b);
            if r > dev2 {
                dev2 = r;
            }
            out.push(b);
            anchor = b;
            s = k + 1;
        }
    }
    dev2.max(run_d2(anchor, &c[s..], c[0]))
}

/// Largest squared distance of the points `run` to the line through `a` and `d` (to `a`
/// when they coincide; 0 when `run` is empty). The division by the squared length is done
/// once, on the largest squared cross product: division rounds monotonically, so this is
/// the largest of the per-point quotients, the same value.
#[inline]
fn run_d2(a: [f64; 2], run: &[[f64; 2]], d: [f64; 2]) -> f64 {
    let (ux, uy) = (d[0] - a[0], d[1] - a[1]);
    let l2 = ux * ux + uy * uy;
    let mut m: f64 = 0.0;
    if l2 == 0.0 {
        for p in run {
            let (vx, vy) = (p[0] - a[0], p[1] - a[1]);
            m = m.max(vx * vx + vy * vy);
        }
        return m;
    }
    if run.is_empty() {
        return 0.0;
    }
    for p in run {
        let (vx, vy) = (p[0] - a[0], p[1] - a[1]);
        let cross = ux * vy - uy * vx;
        let q = cross * cross;
        if q > m {
            m = q;
        }
    }
    m / l2
}

/// [`coarsen`] of every contour into `out` (its vectors are reused); returns the largest
/// distance of a left-out point to its segment, `δ`.
pub(super) fn coarsen_section(contours: &[Contour], out: &mut Vec<Contour>) -> f64 {
    out.resize_with(contours.len(), Vec::new);
    let mut dev2: f64 = 0.0;
    for (c, o) in contours.iter().zip(out.iter_mut()) {
        dev2 = dev2.max(coarsen(c, o));
    }
    dev2.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::analysis::fill_distance::edges::seg_d2;
    use crate::plan::analysis::test_support::{closed, xorshift};

    /// Distance from `p` to the closed polyline `c`.
    fn polyline_distance(c: &[[f64; 2]], p: [f64; 2]) -> f64 {
        let mut a = *c.last().unwrap();
        let mut best = f64::INFINITY;
        for &b in c {
            best = best.min(seg_d2(p, &[a[0], a[1], b[0], b[1]]));
            a = b;
        }
        best.sqrt()
    }

    #[test]
    fn coarse_contours_stay_within_their_deviation() {
        // Wiggly closed curves (fine noise on a circle, runs of collinear points, repeated
        // points, a contour coming back to its start): every point of either boundary lies
        // within the reported deviation of the other, and that is at most COARSE_MM.
        let mut rnd = xorshift(0x51ab_cdef_0123_4567);
        for case in 0..40 {
            let n = 50 + (rnd() * 2000.0) as usize;
            let noise = [0.0, 0.0002, 0.0008, 0.003][case % 4];
            let mut c = closed(n, true, |a| {
                let r = 5.0 + noise * (rnd() - 0.5);
                [r * a.cos(), r * a.sin()]
            });
            if case % 5 == 0 {
                let k = (rnd() * n as f64) as usize;
                let p = c[k];
                c.insert(k, p);
                c.insert(k, p);
            }
            if case % 7 == 0 {
                // Straight runs: points on the chords between every eighth point.
                c = c
                    .chunks(8)
                    .flat_map(|w| {
                        let (a, b) = (w[0], *w.last().unwrap());
                        (0..w.len()).map(move |i| {
                            let t = i as f64 / w.len() as f64;
                            [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
                        })
                    })
                    .collect();
            }
            let mut out = Vec::new();
            let dev = coarsen(&c, &mut out).sqrt();
            assert!(dev <= COARSE_MM, "case {case}: {dev}");
            assert!(out.len() <= c.len() && out.len() >= 3, "case {case}");
            // Points of either boundary, and the middles of its edges.
            let probe = |from: &Contour, to: &Contour| {
                let mut a = *from.last().unwrap();
                for &b in from {
                    for p in [b, [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]] {
                        let d = polyline_distance(to, p);
                        assert!(d <= dev + 1e-12, "case {case}: {d} > {dev}");
                    }
                    a = b;
                }
            };
            probe(&c, &out);
            probe(&out, &c);
        }
        // A contour whose next point repeats the anchor leaves nothing far out.
        let back = vec![[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.0, 1.0], [0.0, 0.0]];
        let mut out = Vec::new();
        assert!(coarsen(&back, &mut out) <= COARSE_MM * COARSE_MM);
    }
}
