//! The max fill distance: the radius of the largest circle inside a section, found by a
//! best-first subdivision of its bounding box (see [`max_fill_distance_with`]). The result
//! is a true inscribed radius, within [`PRECISION_MM`] of the largest.
//!
//! Files: `edges.rs` indexes the edges (nearest edge, inside test), `cells.rs` queues the
//! cells, `points.rs` tests covers of a cell by discs around boundary points, `coarsen.rs`
//! makes the coarse contours searched, `walls.rs` and `arcs.rs` drop cells by their walls
//! (seen as lines, and as arcs of circles and rings), `search.rs` runs the search and
//! `plane.rs` holds small helpers on points and squares.

use super::PRECISION_MM;
use crate::slice::Contour;

mod arcs;
mod cells;
mod coarsen;
mod edges;
mod plane;
mod points;
mod search;
mod walls;

use arcs::ArcCache;
use cells::Queue;
use coarsen::coarsen_section;
#[cfg(any(test, feature = "internals"))]
pub use coarsen::COARSE_MM;
pub use edges::Edges;
use search::search;

/// Largest inscribed circle of the section (nonzero winding): `(radius, centre)`, mm.
/// The radius is a true inscribed radius and within [`PRECISION_MM`] of the largest one.
/// An empty section gives `(0, [0, 0])`.
///
/// The search runs on the contours without the points within [`COARSE_MM`] of the segment
/// that replaces them, which moves the boundary by `δ ≤` [`COARSE_MM`]: at precision
/// [`PRECISION_MM`] − 2δ, its depth lowered by δ (docs/PLANNING.md, "Coarse contours").
#[cfg(any(test, feature = "internals"))]
pub fn max_fill_distance(contours: &[Contour]) -> (f64, [f64; 2]) {
    fill_distance(contours, &mut SearchScratch::default())
}

/// [`max_fill_distance`] with buffers `sc`.
pub(super) fn fill_distance(contours: &[Contour], sc: &mut SearchScratch) -> (f64, [f64; 2]) {
    let mut coarse = std::mem::take(&mut sc.coarse);
    let dev = coarsen_section(contours, &mut coarse);
    let (r, c) = search(&Edges::new(&coarse), PRECISION_MM - 2.0 * dev, sc);
    sc.coarse = coarse;
    ((r - dev).max(0.0), c)
}

/// [`max_fill_distance`] on indexed edges with a chosen precision, mm.
///
/// Best-first search over square cells ordered by an upper bound of the signed distance
/// inside them: with `T` the best centre depth so far plus `precision`, a cell is dropped
/// once shown to hold no point deeper than `T`, and the search ends when the largest bound
/// left is within `precision` of the best depth; a local pattern search then polishes the
/// best centre, moving only to deeper points. A popped cell goes through these steps
/// (`search.rs`; the method, and why each drop is exact: docs/PLANNING.md, "The search"
/// and "Wall covers"):
/// 1. its parent's boundary points, tried again once `T` has grown;
/// 2. its parent's walls followed along their contours (`Edges::descend`);
/// 3. the centre's exact signed distance (edge hierarchy, band-indexed inside test);
/// 4. the cover by discs around boundary points near the centre (completed in small cells
///    by the boundary points nearest to uncovered points), then a ridge probe;
/// 5. to 7. the straight-wall, arc and ring covers (`Edges::walls_cover`,
///    `Edges::arcs_cover`, `Edges::ring_cover`);
/// 8. the split into the children the cell's points do not cover.
///
/// Everything depends only on the section's edges, so the result does not depend on
/// threads or block boundaries.
#[cfg(any(test, feature = "internals"))]
pub fn max_fill_distance_with(e: &Edges, precision: f64) -> (f64, [f64; 2]) {
    search(e, precision, &mut SearchScratch::default())
}

/// Buffers of the max fill distance search, kept from layer to layer by an
/// [`Analyser`](super::Analyser) (results never depend on them).
#[derive(Default)]
pub(super) struct SearchScratch {
    queue: Queue,
    /// The contours searched ([`coarsen_section`]).
    coarse: Vec<Contour>,
    /// Boundary points of split cells, for their children.
    arena: Vec<([[f64; 2]; 6], u8)>,
    /// Arcs of the cells tried between curved walls.
    arcs: ArcCache,
}

impl std::fmt::Debug for SearchScratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SearchScratch")
    }
}

#[cfg(test)]
mod tests {
    use super::plane::d2;
    use super::*;
    use crate::plan::analysis::test_support::*;

    fn mfd(c: &[Contour]) -> f64 {
        max_fill_distance(c).0
    }

    #[test]
    fn square_and_rectangle() {
        assert!((mfd(&[rect(10.0, 10.0, 20.0, 20.0)]) - 5.0).abs() <= 0.001);
        assert!((mfd(&[rect(3.0, 4.0, 8.0, 9.0)]) - 2.5).abs() <= 0.001);
        assert!((mfd(&[rect(0.0, 0.0, 20.0, 10.0)]) - 5.0).abs() <= 0.001);
        assert!((mfd(&[rect(0.0, 0.0, 60.0, 0.5)]) - 0.25).abs() <= 0.001);
        // Never more than the exact value: it is a real inscribed circle.
        assert!(mfd(&[rect(0.0, 0.0, 20.0, 10.0)]) <= 5.0 + 1e-12);
    }

    #[test]
    fn circle_ring_and_l_shape() {
        // A regular n-gon of circumradius r has inradius r·cos(π/n).
        let n = 96;
        let exact = 7.5 * (std::f64::consts::PI / n as f64).cos();
        let v = mfd(&[ngon(30.0, 20.0, 7.5, n, true)]);
        assert!((v - exact).abs() <= 0.001, "{v} vs {exact}");
        // Ring: outer r 10, inner r 8 (hole clockwise). The wall is 2 mm: radius 1 mm up to
        // the polygon's chord error.
        let section = ring([0.0, 0.0], 10.0, 8.0, 256);
        let v = mfd(&section);
        assert!((v - 1.0).abs() <= 0.001, "{v}");
        // L-shape: the circle touches x = 0, y = 0 and the reflex corner (10, 10):
        // r = 10·(2 − √2).
        let l = vec![
            [0.0, 0.0],
            [20.0, 0.0],
            [20.0, 10.0],
            [10.0, 10.0],
            [10.0, 20.0],
            [0.0, 20.0],
        ];
        let exact = 10.0 * (2.0 - std::f64::consts::SQRT_2);
        let (v, c) = max_fill_distance(&[l]);
        assert!((v - exact).abs() <= 0.001, "{v} vs {exact}");
        assert!(
            (c[0] - exact).abs() < 0.05 && (c[1] - exact).abs() < 0.05,
            "{c:?}"
        );
    }

    #[test]
    fn two_parts_and_empty() {
        let two = [rect(0.0, 0.0, 4.0, 4.0), rect(10.0, 0.0, 22.0, 30.0)];
        assert!((mfd(&two) - 6.0).abs() <= 0.005);
        assert_eq!(mfd(&[]), 0.0);
        // A hole in the middle of a square: the best circle sits between hole and rim.
        let holed = [rect(0.0, 0.0, 20.0, 20.0), {
            let mut h = rect(8.0, 8.0, 12.0, 12.0);
            h.reverse();
            h
        }];
        // Corner circle touching two sides and the hole corner (8, 8): centre (t, t) with
        // √2·(8 − t) = t → t = 8√2/(1+√2).
        let t = 8.0 * std::f64::consts::SQRT_2 / (1.0 + std::f64::consts::SQRT_2);
        assert!((mfd(&holed) - t).abs() <= 0.005, "{} vs {t}", mfd(&holed));
    }

    #[test]
    fn matches_brute_force_on_random_polygons() {
        // Star-shaped random polygons; reference: a fine grid plus the exact distance.
        let mut rnd = xorshift(0x9e3779b97f4a7c15);
        for _ in 0..6 {
            let n = 5 + (rnd() * 20.0) as usize;
            let c = star(&mut rnd, [0.0, 0.0], (3.0, 10.0), n, true);
            let e = Edges::new(std::slice::from_ref(&c));
            let (v, _) = max_fill_distance_with(&e, PRECISION_MM);
            let brute = brute_max(&e, [-10.0, -10.0], 0.05, (400, 400), 5, 0.002, 30);
            // The fine grid is within 0.0015 mm of the optimum and cannot exceed it; the
            // search is a true inscribed radius, guaranteed within PRECISION_MM and, after
            // the polish, much closer.
            assert!(v <= brute + 0.0015, "{v} vs {brute}");
            assert!(v >= brute - 0.005, "{v} vs {brute}");
        }
    }

    #[test]
    fn three_wall_peaks_are_resolved() {
        // Triangles: the largest circle is the incircle (touching all three walls),
        // r = 2·area / perimeter.
        let mut rnd = xorshift(0x7f4a7c159e3779b9);
        for _ in 0..12 {
            let p: Vec<[f64; 2]> = (0..3)
                .map(|_| [30.0 * rnd() - 15.0, 30.0 * rnd() - 15.0])
                .collect();
            let area2 = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
            if area2.abs() < 20.0 {
                continue;
            }
            let per = d2(p[0], p[1]).sqrt() + d2(p[1], p[2]).sqrt() + d2(p[2], p[0]).sqrt();
            let exact = area2.abs() / per;
            let v = mfd(&[p]);
            assert!(v <= exact + 1e-9 && v >= exact - 0.005, "{v} vs {exact}");
        }
        // Quarter discs (logo_hires's layers): the circle touches both cuts and the arc,
        // √2·(a + r) = R − r; the chords of the arc move it by < 1e-4 mm.
        let (big, a) = (19.5, 2.0);
        let exact = (big - std::f64::consts::SQRT_2 * a) / (1.0 + std::f64::consts::SQRT_2);
        let pieces = cross_cut_pieces(big, 0.0, a, 340);
        let (v, c) = max_fill_distance(&pieces);
        assert!(
            v <= exact + 1e-9 && v >= exact - 0.005,
            "{v} vs {exact} at {c:?}"
        );
        let e = Edges::new(&pieces);
        let brute = brute_max(&e, [-20.0, -20.0], 0.1, (400, 400), 8, 0.002, 30);
        assert!(v <= brute + 0.0015 && v >= brute - 0.005, "{v} vs {brute}");
        // Ring pieces: a whole arc of centres at half the ring's width.
        let pieces = cross_cut_pieces(19.9, 11.25, 4.0, 340);
        let half = (19.9 - 11.25) / 2.0;
        let v = mfd(&pieces);
        assert!((v - half).abs() <= 0.005, "{v} vs {half}");
    }

    #[test]
    fn matches_brute_force_on_random_polygons_with_holes() {
        // A random star with a random star-shaped hole (and a second part), the kind of
        // section where the far wall and the contour neighbours come from other contours.
        let mut rnd = xorshift(0x853c49e6748fea9b);
        let mut part = |c: [f64; 2], r: (f64, f64), ccw: bool| {
            let n = 8 + (rnd() * 40.0) as usize;
            star(&mut rnd, c, r, n, ccw)
        };
        for _ in 0..4 {
            let contours = vec![
                part([0.0, 0.0], (7.0, 10.0), true),
                part([0.5, -0.5], (2.0, 5.0), false),
                part([14.0, 0.0], (1.0, 3.0), true),
            ];
            let e = Edges::new(&contours);
            let (v, centre) = max_fill_distance_with(&e, PRECISION_MM);
            // A true inscribed circle.
            assert!(e.inside(centre) && e.distance(centre) >= v - 1e-12);
            let brute = brute_max(&e, [-11.0, -11.0], 0.15, (180, 140), 8, 0.003, 40);
            // The fine grid is within 0.003 mm of the optimum near the coarse maxima.
            assert!(v <= brute + 0.003, "{v} vs {brute}");
            assert!(v >= brute - PRECISION_MM, "{v} vs {brute}");
        }
    }

    #[test]
    fn fine_curves_keep_the_guarantee() {
        // Fine tessellations (as from a hi-res mesh) lose most points to the coarse search,
        // yet the result stays a true inscribed radius within PRECISION_MM of the exact
        // one (here: the search on the original points at a precision of 0.001 mm).
        let mut rnd = xorshift(0x0dd_ba11);
        for case in 0..6 {
            let n = 1500 + (rnd() * 1500.0) as usize;
            let outer = 6.0 + 8.0 * rnd();
            let inner = outer - 0.05 - 3.0 * rnd();
            let section = [
                ngon(1.0, 2.0, outer, n, true),
                ngon(1.0 + 0.3 * rnd(), 2.0, inner, n / 2, false),
            ];
            let mut coarse = Vec::new();
            let dev = coarsen_section(&section, &mut coarse);
            let kept: usize = coarse.iter().map(Vec::len).sum();
            assert!(
                dev > 0.0 && kept < n,
                "case {case}: {kept} of {}",
                n + n / 2
            );
            let (v, c) = max_fill_distance(&section);
            let e = Edges::new(&section);
            let reference = max_fill_distance_with(&e, 0.001).0;
            assert!(
                e.signed_distance(c) >= v - 1e-12,
                "case {case}: not inscribed"
            );
            assert!(v <= reference + 0.001, "case {case}: {v} vs {reference}");
            assert!(
                v >= reference - PRECISION_MM,
                "case {case}: {v} vs {reference}"
            );
        }
    }
}
