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
/// The search ([`max_fill_distance_with`]) runs on the contours without the points within
/// [`COARSE_MM`] of the segment that replaces them (most of the points a fine mesh puts on
/// gently curved walls), which moves the boundary by at most `δ ≤` [`COARSE_MM`], the
/// largest distance of a left-out point. It runs at precision [`PRECISION_MM`] − 2δ and
/// finds a centre `c` at depth `r'` on the coarse contours; the result is `max(r' − δ, 0)`.
/// When `r' > δ` the circle of radius `r' − δ` around `c` lies inside the section (`c` is
/// farther than `δ` from the coarse boundary, so on the same side of both boundaries), and
/// `r' − δ ≥ (largest on the coarse contours − precision) − δ ≥ largest − 2δ − precision
/// = largest − PRECISION_MM`; when `r' ≤ δ`, the largest is at most
/// `r' + precision + δ ≤` [`PRECISION_MM`], so 0 is within the guarantee. Contours with
/// nothing to leave out (`δ = 0`) are searched as they are.
#[cfg(any(test, feature = "internals"))]
pub fn max_fill_distance(contours: &[Contour]) -> (f64, [f64; 2]) {
    fill_distance(contours, &mut SearchScratch::default())
}

/// [`max_fill_distance`] of a section from its coarsened contours `coarse` (moved by at
/// most `dev` from the section's), with buffers `sc`.
fn search_coarse(coarse: &[Contour], dev: f64, sc: &mut SearchScratch) -> (f64, [f64; 2]) {
    let (r, c) = search(&Edges::new(coarse), PRECISION_MM - 2.0 * dev, sc);
    ((r - dev).max(0.0), c)
}

/// [`max_fill_distance`] with buffers `sc`.
pub(super) fn fill_distance(contours: &[Contour], sc: &mut SearchScratch) -> (f64, [f64; 2]) {
    let mut coarse = std::mem::take(&mut sc.coarse);
    let dev = coarsen_section(contours, &mut coarse);
    let r = search_coarse(&coarse, dev, sc);
    sc.coarse = coarse;
    r
}

/// [`max_fill_distance`] on indexed edges with a chosen precision, mm.
///
/// Best-first search over square cells ordered by an upper bound of the signed distance
/// inside them; `T` below is the best centre depth so far plus `precision`, and a cell is
/// dropped as soon as it is shown to hold no point deeper than `T`. When the first
/// `SEED_AFTER_CELLS` cells have found no centre inside the section (a thin one), the best
/// depth starts from points on a few walls' inward normals (`Edges::ridge_probe`).
/// Popping a cell of half-size `h`:
/// 1. its parent's boundary points (below) still cover it at radius `T` (only tried when
///    `T` has grown since it was queued: they did not cover it then): dropped without a
///    search;
/// 2. the parent's nearest and far-wall edges, each followed along its contour to the
///    points nearest this centre (`Edges::descend`, a local minimum): their distance `u`
///    bounds the centre's depth from above (they are boundary), so `u + h·√2 ≤ T` drops
///    the cell without a search. If `u ≤` the best depth the centre cannot improve the
///    best, so its exact distance is not needed: the cover test of step 4 with these two
///    walls' points drops it without a search when it can, and otherwise it is split as in
///    step 5 with these walls (key `u + h·√2`), also without a search, for at most
///    3 generations in a row (followed walls can miss a nearer third wall).
///    A centre outside the section (inside test) has a negative depth, so the cell is
///    dropped when `h·√2 ≤ T`;
/// 3. the centre's exact signed distance `d` and nearest edge (bounding-volume hierarchy,
///    seeded with the nearer of the walls of step 2; band-indexed nonzero-winding inside
///    test);
///    `d + h·√2 ≤ T` (1-Lipschitz): dropped;
/// 4. inside the section: a few boundary points — the nearest point `q`, the nearest
///    boundary point behind the centre (the other wall of a ridge; its search starts from
///    the far wall of step 2) and, on the contours of both, the points about `0.6·h` away
///    on either side. If discs of radius `T` around them cover the cell (`points_exceed`)
///    it is dropped. This is what keeps long ridges (walls of constant thickness, rings)
///    from being subdivided down to the precision. When they do not, a cell small enough
///    (`COVER_MORE_MAX_SIZE`) gets up to `MAX_EXTRA_COVER_POINTS` more points, each the
///    boundary point nearest to a point the test found uncovered (a third wall at a peak, a
///    wall point between the samples: `cover_more`), and is tested again (the walls-only
///    test of step 2 likewise); otherwise a ridge probe (half-way between the two walls)
///    may raise the best;
/// 5. a cell of half-size between `1.5·T` and 1 mm whose walls are thin (the edges
///    meeting it form at most two runs, each close to a line over the cell) is dropped
///    when the walls bound every part of it inside the section by `T`
///    (`Edges::walls_cover`): cells across a thin ring stick out of it on both sides, and
///    no discs around wall points cover them;
/// 6. a cell of half-size between `8·precision` and `T` (a larger one wholly inside the
///    section is deeper than `T`) is dropped when its walls, seen as arcs of circles
///    around their centres of curvature, show it shallow (`Edges::arcs_cover`): between
///    the two walls of a ring the mean of their bounds is the ring's half-width over the
///    whole cell, however long the ring; tried while it pays (`COVER_TRIAL_TRIES`);
/// 7. a cell of half-size at least `8·precision` that is larger than `T` or whose centre
///    is outside the section is dropped when it straddles a ring whose two walls, seen as
///    arcs, show it shallow (`Edges::ring_cover`): a thin ring's cells stick out of it on
///    both sides, however large; tried while it pays, and on every `RING_PROBE_EVERY`-th
///    cell;
/// 8. the four children are tested against the same points at once, and only those not
///    covered are queued, with the parent's Lipschitz bound (or the far-corner distance to
///    `q` or the far-wall point, if smaller) as their key; a child holding an uncovered
///    point the cell's own test found (`Witnesses`) is queued without a test.
///
/// The search ends when the largest key left is within `precision` of the best depth.
/// The best centre found is finally polished by a local pattern search on the exact
/// distance (it only ever moves to a deeper point; trial points closer than the current
/// depth to a recently nearest edge are rejected without a search), so typical results
/// are much closer than the guaranteed precision.
///
/// Everything depends only on the section's edges (no state carried between layers), so
/// the result does not depend on threads or block boundaries.
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
        let ring = [
            ngon(0.0, 0.0, 10.0, 256, true),
            ngon(0.0, 0.0, 8.0, 256, false),
        ];
        let v = mfd(&ring);
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
            let c: Contour = (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    let r = 3.0 + 7.0 * rnd();
                    [r * a.cos(), r * a.sin()]
                })
                .collect();
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
        let star = |rnd: &mut dyn FnMut() -> f64, c: [f64; 2], r0: f64, r1: f64, ccw: bool| {
            let n = 8 + (rnd() * 40.0) as usize;
            let mut v: Contour = (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    let r = r0 + (r1 - r0) * rnd();
                    [c[0] + r * a.cos(), c[1] + r * a.sin()]
                })
                .collect();
            if !ccw {
                v.reverse();
            }
            v
        };
        for _ in 0..4 {
            let contours = vec![
                star(&mut rnd, [0.0, 0.0], 7.0, 10.0, true),
                star(&mut rnd, [0.5, -0.5], 2.0, 5.0, false),
                star(&mut rnd, [14.0, 0.0], 1.0, 3.0, true),
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
