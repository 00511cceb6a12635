//! Test builders shared by the analysis's tests: sections (rectangles, regular polygons,
//! ellipses, pieces of a cut disc), their lit pixels, a random number generator and
//! brute-force references for the max fill distance.

use super::{Edges, LitRuns};
use crate::slice::Contour;

pub(super) use crate::test_support::{closed, ngon, rect, xorshift};

/// The rectangle `[x0, x1] × [y0, y1]` clockwise: a hole.
pub(super) fn hole(x0: f64, y0: f64, x1: f64, y1: f64) -> Contour {
    rect(x0, y0, x1, y1).into_iter().rev().collect()
}

/// A ring of `n`-gons around `c`: the outer counter-clockwise, the hole clockwise.
pub(super) fn ring(c: [f64; 2], outer: f64, inner: f64, n: usize) -> Vec<Contour> {
    vec![
        ngon(c[0], c[1], outer, n, true),
        ngon(c[0], c[1], inner, n, false),
    ]
}

/// An ellipse of half-axes `a` and `b` around the origin, 400 points.
pub(super) fn ellipse(a: f64, b: f64, ccw: bool) -> Contour {
    closed(400, ccw, |t| [a * t.cos(), b * t.sin()])
}

/// A star-shaped polygon of `n` points around `c`, each at a radius drawn from `rnd` in
/// `[r0, r1)`.
pub(super) fn star(
    rnd: &mut dyn FnMut() -> f64,
    c: [f64; 2],
    (r0, r1): (f64, f64),
    n: usize,
    ccw: bool,
) -> Contour {
    closed(n, ccw, |a| {
        let r = r0 + (r1 - r0) * rnd();
        [c[0] + r * a.cos(), c[1] + r * a.sin()]
    })
}

/// Between 1 and `n` rectangles scattered over 20 mm, sides from 0.2 mm to
/// `0.2 + side` mm (some overlapping: several runs per row).
pub(super) fn scattered(rnd: &mut dyn FnMut() -> f64, n: f64, side: f64) -> Vec<Contour> {
    let n = 1 + (rnd() * n) as usize;
    (0..n)
        .map(|_| {
            let (x, y, w) = (rnd() * 20.0, rnd() * 20.0, 0.2 + rnd() * side);
            rect(x, y, x + w, y + 0.2 + rnd() * side)
        })
        .collect()
}

/// The lit pixels of a section on the default profile's field, as the slicer's
/// rasterizer keeps them.
pub(super) fn lit(c: &[Contour]) -> LitRuns {
    let raster = crate::raster::Rasterizer::new(crate::profile::Profile::default_profile().field());
    let mut sc = crate::raster::Scratch::default();
    sc.record_runs = true;
    let m = raster.coverage(c, &mut sc);
    // The runs the scan kept are those of the finished mask.
    assert_eq!(
        sc.lit_runs,
        LitRuns::of_mask(&m, [0, m.height as usize, 0, m.width as usize])
    );
    sc.lit_runs
}

/// Brute-force deepest signed distance: a coarse grid of `(ni + 1) × (nj + 1)` points
/// from `origin` with step `coarse`, then a fine grid of step `fine` and half-width
/// `half` steps around each of the `best` deepest coarse points.
pub(super) fn brute_max(
    e: &Edges,
    origin: [f64; 2],
    coarse: f64,
    (ni, nj): (usize, usize),
    best: usize,
    fine: f64,
    half: i32,
) -> f64 {
    let mut pts: Vec<(f64, [f64; 2])> = Vec::new();
    for i in 0..=ni {
        for j in 0..=nj {
            let p = [origin[0] + coarse * i as f64, origin[1] + coarse * j as f64];
            pts.push((e.signed_distance(p), p));
        }
    }
    pts.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut brute: f64 = 0.0;
    for &(_, p) in pts.iter().take(best) {
        for i in -half..=half {
            for j in -half..=half {
                let q = [p[0] + fine * i as f64, p[1] + fine * j as f64];
                brute = brute.max(e.signed_distance(q));
            }
        }
    }
    brute
}

/// A disc of radius `r` with a cross of half-width `a` cut out (or, with `hole` > 0,
/// a ring with that inner radius): four separate pieces, each bounded by finely
/// tessellated arcs (`k` points per arc, on the circles) and two straight cuts.
pub(super) fn cross_cut_pieces(r: f64, hole: f64, a: f64, k: usize) -> Vec<Contour> {
    let arc = |rad: f64, from: f64, to: f64| -> Vec<[f64; 2]> {
        (0..k)
            .map(|i| {
                let t = from + (to - from) * i as f64 / (k - 1) as f64;
                [rad * t.cos(), rad * t.sin()]
            })
            .collect()
    };
    let mut out = Vec::new();
    for quad in 0..4 {
        let (sx, sy) = ([1.0, -1.0, -1.0, 1.0][quad], [1.0, 1.0, -1.0, -1.0][quad]);
        // First quadrant piece, counter-clockwise, then mirrored.
        let mut c: Contour = Vec::new();
        let o = (a / r).asin();
        c.extend(arc(r, o, std::f64::consts::FRAC_PI_2 - o));
        if hole > 0.0 {
            let i = (a / hole).asin();
            c.extend(arc(hole, std::f64::consts::FRAC_PI_2 - i, i));
        } else {
            c.push([a, a]);
        }
        let mut c: Contour = c.into_iter().map(|p| [sx * p[0], sy * p[1]]).collect();
        if sx * sy < 0.0 {
            c.reverse();
        }
        out.push(c);
    }
    out
}

/// Asserts that no point of a `(k + 1)²` grid over the square `(c, h)` (a cell a test
/// dropped) is deeper than `max` in the section of `e`.
pub(super) fn assert_no_deeper(e: &Edges, (c, h): ([f64; 2], f64), max: f64, k: usize) {
    let root = e.bounds().unwrap();
    for a in 0..=k {
        for b in 0..=k {
            let x = [
                c[0] - h + 2.0 * h * a as f64 / k as f64,
                c[1] - h + 2.0 * h * b as f64 / k as f64,
            ];
            let d = e.signed_distance(x);
            assert!(
                d <= max,
                "cell {c:?} ± {h} dropped at radius {max}, but {x:?} is {d} deep \
                 (root {:?})",
                root
            );
        }
    }
}

/// The largest depth found in the square `(c, h)` by a plain branch and bound (exact
/// signed distances at cell centres, 1-Lipschitz bound): a point really that deep,
/// and no point of the square is deeper by more than `tol`.
pub(super) fn cell_max(e: &Edges, (c, h): ([f64; 2], f64), tol: f64) -> f64 {
    let mut best = f64::NEG_INFINITY;
    let mut stack = vec![(c, h)];
    while let Some((c, h)) = stack.pop() {
        let d = e.signed_distance(c);
        best = best.max(d);
        if d + h * std::f64::consts::SQRT_2 <= best + tol {
            continue;
        }
        let q = h / 2.0;
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            stack.push(([c[0] + sx * q, c[1] + sy * q], q));
        }
    }
    best
}

/// `c` with points inserted on its edges at fractions drawn from `rnd` (0–3 per edge),
/// starting at point `start`: the same polygon as the slicer cuts it at another height.
pub(super) fn with_collinear_points(
    c: &Contour,
    start: usize,
    rnd: &mut impl FnMut() -> f64,
) -> Contour {
    let n = c.len();
    let mut out = Vec::new();
    for k in 0..n {
        let (a, b) = (c[(start + k) % n], c[(start + k + 1) % n]);
        out.push(a);
        let mut ts: Vec<f64> = (0..(rnd() * 4.0) as usize).map(|_| rnd()).collect();
        ts.sort_by(f64::total_cmp);
        for t in ts {
            out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
        }
    }
    out
}
