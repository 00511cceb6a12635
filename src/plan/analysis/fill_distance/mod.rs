//! The max fill distance: the radius of the largest circle inside a section, found by a
//! best-first subdivision of its bounding box (see [`max_fill_distance_with`]).

use super::PRECISION_MM;
use crate::slice::Contour;

mod cells;
mod edges;
mod plane;
mod points;

use cells::{Cell, Queue};
use edges::seg_d2;
pub use edges::Edges;
use plane::{corners, cross, d2, unit};
use points::{exceeds, points_exceed, witness, Witnesses, EXTRA, MAX_PTS};

/// Most generations of cells split with walls followed from their parent's without a
/// search (the walls may miss a nearer third wall; measured 1–4, 3 is cheapest).
const FOLLOWED_MAX: u8 = 3;

/// Spacing of the cover points along the walls, in cell half-sizes.
const ALONG: f64 = 0.6;

/// Cells whose cover test is completed by [`cover_more`]: `(h·√2)² ≤ COVER_GATE · T ·
/// precision`. Larger cells are rarely covered (their uncovered points are deeper than
/// `T`) and are split (measured 16, 32, 64: 32 is cheapest on logo_hires and
/// torus_hires).
const COVER_GATE: f64 = 32.0;

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
/// `r' − δ ≥ (largest on the coarse contours − precision) − δ ≥ largest − 2δ −
/// precision = largest − PRECISION_MM`; when `r' ≤ δ`, the largest is at most `r' +
/// precision + δ ≤` [`PRECISION_MM`], so 0 is within the guarantee. Contours with nothing to leave out (`δ = 0`) are searched as
/// they are.
pub fn max_fill_distance(contours: &[Contour]) -> (f64, [f64; 2]) {
    fill_distance(contours, &mut SearchScratch::default())
}

/// Boundary points within this distance of the segment that replaces them are left out of
/// the contours the max fill distance is searched on, mm (a fine mesh gives a contour point
/// every few hundredths of a millimetre; most of them go). See [`max_fill_distance`].
pub const COARSE_MM: f64 = 0.0005;

/// Longest run of consecutive points left out by [`coarsen`] (each one is checked against
/// the final segment).
const COARSE_RUN: usize = 16;

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
        let left_out = run.len() < COARSE_RUN && {
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
fn coarsen_section(contours: &[Contour], out: &mut Vec<Contour>) -> f64 {
    out.resize_with(contours.len(), Vec::new);
    let mut dev2: f64 = 0.0;
    for (c, o) in contours.iter().zip(out.iter_mut()) {
        dev2 = dev2.max(coarsen(c, o));
    }
    dev2.sqrt()
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
/// `SEED_AFTER` cells have found no centre inside the section (a thin one), the best
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
///    the far wall of step 2) and, on the contours of both, the points about `0.6·h` away on
///    either side. If discs of radius `T` around them
///    cover the cell (`points_exceed`) it is dropped. This is what keeps long ridges
///    (walls of constant thickness, rings) from being subdivided down to the precision.
///    When they do not, a cell small enough (`COVER_GATE`) gets up to `EXTRA` more
///    points, each the boundary point nearest to a point the test found uncovered (a
///    third wall at a peak, a wall point between the samples: `cover_more`), and is
///    tested again (the walls-only test of step 2 likewise);
///    otherwise a ridge probe (half-way between the two walls) may raise the best;
/// 5. a cell of half-size between `1.5·T` and 1 mm whose walls are thin (the edges
///    meeting it form at most two runs, each close to a line over the cell) is dropped
///    when the walls bound every part of it inside the section by `T`
///    (`Edges::walls_cover`): cells across a thin ring stick out of it on both sides, and
///    no discs around wall points cover them;
/// 6. a cell of half-size between `8·precision` and `T` (a larger one wholly inside the
///    section is deeper than `T`) is dropped when its walls, seen as arcs of circles
///    around their centres of curvature, show it shallow (`Edges::arcs_cover`): between
///    the two walls of a ring the mean of their bounds is the ring's half-width over the
///    whole cell, however long the ring; tried while it pays (`ARC_TRIAL`);
/// 7. a cell of half-size at least `8·precision` that is larger than `T` or whose centre
///    is outside the section is dropped when it straddles a ring whose two walls, seen as
///    arcs, show it shallow (`Edges::ring_cover`): a thin ring's cells stick out of it on
///    both sides, however large; tried while it pays, and on every `RING_PROBE`-th
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
pub fn max_fill_distance_with(e: &Edges, precision: f64) -> (f64, [f64; 2]) {
    search(e, precision, &mut SearchScratch::default())
}

/// Buffers of the max fill distance search, kept from layer to layer by an [`Analyser`](super::Analyser)
/// (results never depend on them).
#[derive(Default)]
pub(super) struct SearchScratch {
    queue: Queue,
    /// The contours searched ([`coarsen`]).
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

/// Whether discs of radius `T` = best depth + `precision` around `pts[..n]` (boundary
/// points) cover the square `sq` = `(centre, half-size)`; a square small enough
/// (`(h·√2)² ≤ COVER_GATE · T · precision`) that they do not cover is completed with
/// [`cover_more`] (which may raise the best and uses `pts` beyond `n`). The uncovered
/// points found go to `wit`.
#[allow(clippy::too_many_arguments)]
fn covered(
    e: &Edges,
    sq: ([f64; 2], f64),
    pts: &mut [[f64; 2]; MAX_PTS],
    n: usize,
    walls: [u32; 2],
    best: (&mut [f64; 2], &mut f64, &mut u32),
    precision: f64,
    wit: &mut Witnesses,
) -> bool {
    let t = *best.1 + precision;
    let reach = sq.1 * std::f64::consts::SQRT_2;
    if reach * reach > COVER_GATE * t * precision {
        // Too large to be completed: whether the points cover it is all that matters.
        let (exceed, w) = exceeds(sq.0, sq.1, &pts[..n], t * t);
        if let Some(w) = w {
            wit.push(w, t * t);
        }
        return !exceed;
    }
    let Some(x) = witness(sq.0, sq.1, &pts[..n], t * t) else {
        return true;
    };
    wit.push(x, t * t);
    let mut m = n;
    cover_more(e, sq, pts, &mut m, x, walls, best, precision, wit)
}

/// Completes a cover test that failed at the uncovered point `x` of the square `sq` =
/// `(centre, half-size)`: adds the boundary point nearest to `x` to `pts` (first `n`
/// used) and tries again, at most [`EXTRA`] times; returns whether the square is now
/// covered at radius `T` = best depth + `precision`. The nearest point is first looked
/// for by following the cell's `walls` (edges, `u32::MAX`: none) along their contours
/// to `x` ([`Edges::descend`]); only when that point is farther than `T` is the exact
/// nearest edge searched. Every point added is a boundary point, so a cover stays a
/// proof. If `x` is inside the section and deeper than `T`, it becomes the best centre
/// (and the square cannot be covered). The uncovered points found go to `wit`.
#[allow(clippy::too_many_arguments)]
fn cover_more(
    e: &Edges,
    sq: ([f64; 2], f64),
    pts: &mut [[f64; 2]; MAX_PTS],
    n: &mut usize,
    mut x: [f64; 2],
    walls: [u32; 2],
    best: (&mut [f64; 2], &mut f64, &mut u32),
    precision: f64,
    wit: &mut Witnesses,
) -> bool {
    let (best_c, best_d, best_near) = best;
    let stop = (*n + EXTRA).min(MAX_PTS);
    while *n < stop {
        let t = *best_d + precision;
        let mut found = (f64::INFINITY, u32::MAX);
        for w in walls {
            if w != u32::MAX {
                let r = e.descend(w, x);
                if r.0 < found.0 {
                    found = r;
                }
            }
        }
        let (dx, ix) = if found.0 <= t * t {
            (found.0.sqrt(), found.1)
        } else {
            e.nearest_from(x, found)
        };
        if dx > t {
            if e.inside(x) {
                (*best_c, *best_d, *best_near) = (x, dx, ix);
            }
            return false;
        }
        pts[*n] = e.closest_point(ix, x);
        *n += 1;
        match witness(sq.0, sq.1, &pts[..*n], t * t) {
            None => return true,
            Some(w) => {
                x = w;
                wit.push(w, t * t);
            }
        }
    }
    false
}

/// [`max_fill_distance_with`] with buffers `sc`.
fn search(e: &Edges, precision: f64, sc: &mut SearchScratch) -> (f64, [f64; 2]) {
    let Some((lo, hi)) = e.bounds() else {
        return (0.0, [0.0, 0.0]);
    };
    let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
    let size = w.min(h);
    if size.is_nan() || size <= 0.0 {
        return (0.0, [0.0, 0.0]);
    }
    let half = size / 2.0;
    sc.arcs.clear();
    let (mut arc_tries, mut arc_hits) = (0usize, 0usize);
    let (mut ring_tries, mut ring_hits, mut ring_seen) = (0usize, 0usize, 0usize);
    let heap = &mut sc.queue;
    heap.clear();
    let nx = (w / size).ceil() as usize;
    let ny = (h / size).ceil() as usize;
    for i in 0..nx {
        for j in 0..ny {
            let c = [
                lo[0] + (i as f64 + 0.5) * size,
                lo[1] + (j as f64 + 0.5) * size,
            ];
            heap.push(Cell {
                c,
                h: half,
                max: f64::INFINITY,
                hint: u32::MAX,
                hint2: u32::MAX,
                pts: u32::MAX,
                best: f64::NEG_INFINITY,
                followed: 0,
            });
        }
    }
    let mut best_d = f64::NEG_INFINITY;
    let mut best_c = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let mut best_near = u32::MAX;
    let mut pops = 0usize;
    let arena = &mut sc.arena;
    arena.clear();
    let far_corner = |c: [f64; 2], h: f64, q: [f64; 2]| {
        let (dx, dy) = ((c[0] - q[0]).abs() + h, (c[1] - q[1]).abs() + h);
        (dx * dx + dy * dy).sqrt()
    };
    while let Some(c) = heap.pop() {
        // No centre inside the section yet (a thin section: a ring's first layers): a
        // few points on its walls' inward normals give the depth to beat.
        if pops == SEED_AFTER && best_d <= 0.0 {
            for k in 0..SEEDS {
                let v = (k * e.segs.len() / SEEDS) as u32;
                if let Some((p, d, near)) = e.ridge_probe(v, precision, size) {
                    if d > best_d {
                        (best_c, best_d, best_near) = (p, d, near);
                    }
                }
            }
        }
        pops += 1;
        if c.max - best_d <= precision {
            // The heap is ordered by the bound: no remaining cell can do better.
            break;
        }
        let t = best_d + precision;
        if c.pts != u32::MAX && t > 0.0 && best_d > c.best {
            let (p, n) = &arena[c.pts as usize];
            if !points_exceed(c.c, c.h, &p[..*n as usize], t * t) {
                continue;
            }
        }
        // The parent's edges bound the distance from above: many cells are dropped
        // without a search.
        let reach = c.h * std::f64::consts::SQRT_2;
        let mut start = (f64::INFINITY, u32::MAX);
        let mut seed2 = u32::MAX;
        // The inside test of the centre, once made.
        let mut ins = None;
        let mut local = None;
        // Points of the cell that its cover test found uncovered.
        let mut wit = Witnesses::default();
        if c.hint != u32::MAX {
            // The walls of the parent, followed along their contours to the points nearest
            // to this centre.
            let w1 = e.descend(c.hint, c.c);
            start = w1;
            let w2 = (c.hint2 != u32::MAX).then(|| e.descend(c.hint2, c.c));
            seed2 = w2.map_or(u32::MAX, |w| w.1);
            if let Some(w2) = w2 {
                if w2.0 < start.0 {
                    start = w2;
                }
            }
            let u = start.0.sqrt();
            if u + reach - best_d <= precision {
                continue;
            }
            // A centre outside the section has a negative depth, so no point of the cell
            // is deeper than `h·√2`; nor can the walls' points cover such a cell.
            let inside = e.inside(c.c);
            if !inside && reach <= t {
                continue;
            }
            ins = Some(inside);
            // The centre cannot beat the best: try to drop the cell with these walls alone.
            if inside && u <= best_d && t > 0.0 && w2.is_some() {
                let mut pts = [[0.0; 2]; MAX_PTS];
                let mut n = 0;
                for (_, i) in std::iter::once(w1).chain(w2) {
                    let q = e.closest_point(i, c.c);
                    let [a, b] = e.along(i, q, ALONG * c.h);
                    pts[n..n + 3].copy_from_slice(&[q, a, b]);
                    n += 3;
                }
                let walls = [w1.1, w2.map_or(u32::MAX, |w| w.1)];
                let best = (&mut best_c, &mut best_d, &mut best_near);
                if covered(e, (c.c, c.h), &mut pts, n, walls, best, precision, &mut wit) {
                    continue;
                }
                // Not covered: split it with these walls (no search: the centre cannot
                // beat the best), unless they have been followed for too long.
                if c.followed < FOLLOWED_MAX {
                    local = Some((pts, n, u + reach, w1.1, w2.map_or(u32::MAX, |w| w.1)));
                }
            }
        }
        let (pts, n, lip, near, far_edge) = if let Some(l) = local {
            l
        } else {
            let (d, near) = e.nearest_from(c.c, start);
            let d = if ins.unwrap_or_else(|| e.inside(c.c)) {
                d
            } else {
                -d
            };
            if d > best_d {
                (best_c, best_d, best_near) = (c.c, d, near);
            }
            let lip = d + reach;
            if lip - best_d <= precision {
                continue;
            }
            let mut pts = [[0.0; 2]; MAX_PTS];
            let mut n = 0;
            let mut far_edge = u32::MAX;
            if d > 0.0 {
                let q = e.closest_point(near, c.c);
                let mut add = |p: [f64; 2]| {
                    pts[n] = p;
                    n += 1;
                };
                add(q);
                e.along(near, q, ALONG * c.h).into_iter().for_each(&mut add);
                // Wall points farther than this can neither cover the cell at radius `T`
                // nor bound a child's depth below `lip`.
                let limit = best_d + precision + 1.5 * reach;
                let behind = e.nearest_behind(c.c, q, limit, seed2);
                if let Some((q2, i2)) = behind {
                    add(q2);
                    e.along(i2, q2, ALONG * c.h).into_iter().for_each(&mut add);
                    far_edge = i2;
                }
                // The children are tested against the walls' points only (more points
                // make every test dearer than the few children they drop).
                let best = (&mut best_c, &mut best_d, &mut best_near);
                wit.clear();
                if covered(
                    e,
                    (c.c, c.h),
                    &mut pts,
                    n,
                    [near, far_edge],
                    best,
                    precision,
                    &mut wit,
                ) {
                    continue;
                }
                // Ridge probe: half-way between the two walls along the line through q and
                // the centre is (for parallel walls exactly) the deepest point nearby; it keeps
                // the best value close to a ridge's height so ridge cells can be pruned.
                if let Some((q2, i2)) = behind {
                    let t = 0.5 * (d2(q2, c.c).sqrt() - d);
                    if t > 0.25 * precision {
                        let u = [(c.c[0] - q[0]) / d, (c.c[1] - q[1]) / d];
                        let p = [c.c[0] + t * u[0], c.c[1] + t * u[1]];
                        // Both walls bound the probe's depth: search only if it can gain.
                        let mut start = (seg_d2(p, &e.segs[near as usize]), near);
                        let u2 = seg_d2(p, &e.segs[i2 as usize]);
                        if u2 < start.0 {
                            start = (u2, i2);
                        }
                        if best_d < 0.0 || start.0 > best_d * best_d {
                            let (dp, np) = e.nearest_from(p, start);
                            if dp > best_d && e.inside(p) {
                                (best_c, best_d, best_near) = (p, dp, np);
                            }
                        }
                    }
                }
            }
            (pts, n, lip, near, far_edge)
        };
        // A cell across thin walls: dropped when its walls show it shallow.
        let t = best_d + precision;
        if c.h > SLAB_MIN_H * t
            && c.h <= SLAB_MAX_H_MM
            && e.walls_cover(c.c, c.h, t, [near, far_edge])
        {
            continue;
        }
        // A cell between curved walls: dropped when they show it shallow.
        if n > 0
            && c.h >= ARC_MIN_H * precision
            && c.h < t
            && (arc_tries < ARC_TRIAL || arc_hits * ARC_RATE >= arc_tries)
        {
            arc_tries += 1;
            if e.arcs_cover(c.c, c.h, t, [near, far_edge], &mut sc.arcs) {
                arc_hits += 1;
                continue;
            }
        }
        // A cell across a ring (its centre outside the section, or the cell larger than
        // the depth to beat): dropped when the ring's two walls show it shallow.
        if c.h >= ARC_MIN_H * precision && (c.h >= t || n == 0) {
            ring_seen += 1;
            if ring_tries < ARC_TRIAL
                || ring_hits * ARC_RATE >= ring_tries
                || ring_seen % RING_PROBE == 0
            {
                ring_tries += 1;
                if e.ring_cover(c.c, c.h, t, near, &mut sc.arcs) {
                    ring_hits += 1;
                    continue;
                }
            }
        }
        let qh = c.h / 2.0;
        let idx = if n > 0 {
            let mut kept = [[0.0; 2]; 6];
            kept.copy_from_slice(&pts[..6]);
            arena.push((kept, n as u8));
            (arena.len() - 1) as u32
        } else {
            u32::MAX
        };
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let cc = [c.c[0] + sx * qh, c.c[1] + sy * qh];
            let mut cmax = lip;
            if n > 0 {
                // A child holding an uncovered point of the cell's test is not covered
                // by the same points.
                if !wit.uncover(cc, qh, &pts[..n], t * t)
                    && !points_exceed(cc, qh, &pts[..n], t * t)
                {
                    continue;
                }
                cmax = cmax.min(far_corner(cc, qh, pts[0]));
                if n > 3 {
                    cmax = cmax.min(far_corner(cc, qh, pts[3]));
                }
            }
            if cmax - best_d <= precision {
                continue;
            }
            heap.push(Cell {
                c: cc,
                h: qh,
                max: cmax,
                hint: near,
                hint2: far_edge,
                pts: idx,
                best: best_d,
                followed: if local.is_none() { 0 } else { c.followed + 1 },
            });
        }
    }
    if best_d <= 0.0 {
        return (0.0, best_c);
    }
    let (c, d, _) = polish(
        e,
        (best_c, best_d, best_near),
        precision,
        precision / 16.0,
        64,
    );
    (d, c)
}

/// Local pattern search from `c` (depth `d`, nearest edge `near`): tries steps in 8
/// directions, keeps going in a direction while it gains (doubling the step), halves the
/// step when no direction gains, from `precision` down to `precision / 16`; moves only
/// to deeper points, so the result stays a true inscribed radius.
fn polish(
    e: &Edges,
    (mut c, mut d, mut near): ([f64; 2], f64, u32),
    first_step: f64,
    last_step: f64,
    max_evals: usize,
) -> ([f64; 2], f64, u32) {
    const S: f64 = std::f64::consts::FRAC_1_SQRT_2;
    const DIRS: [[f64; 2]; 8] = [
        [1.0, 0.0],
        [S, S],
        [0.0, 1.0],
        [-S, S],
        [-1.0, 0.0],
        [-S, -S],
        [0.0, -1.0],
        [S, -S],
    ];
    let mut step = first_step;
    let mut k0 = 0;
    let mut evals = 0;
    // Edges recently nearest: a point closer to one of them than `d` cannot be deeper,
    // so most trial points are rejected without a search.
    let mut recent = [near; 4];
    let mut slot = 0;
    while step >= last_step && evals < max_evals {
        let mut moved = false;
        for k in (0..8).map(|i| (k0 + i) % 8) {
            let u = DIRS[k];
            let mut s = step;
            loop {
                let p = [c[0] + s * u[0], c[1] + s * u[1]];
                evals += 1;
                let dd = d * d;
                if recent.iter().any(|&i| seg_d2(p, &e.segs[i as usize]) <= dd) {
                    break;
                }
                let (dp, np) = e.nearest(p, near);
                if !recent.contains(&np) {
                    recent[slot] = np;
                    slot = (slot + 1) % 4;
                }
                if dp > d && e.inside(p) {
                    (c, d, near) = (p, dp, np);
                    moved = true;
                    s *= 2.0;
                } else {
                    break;
                }
            }
            if moved {
                k0 = k;
                break;
            }
        }
        if !moved {
            step /= 2.0;
        }
    }
    (c, d, near)
}

/// Most edges crossing a cell that [`Edges::walls_cover`] deals with (more: not tried).
const SLAB_EDGES: usize = 48;

/// Most contour points a wall is followed beyond a cell by [`Edges::walls_cover`].
const SLAB_WALK: usize = 32;

/// A stretch of a contour crossing a cell, seen as a line: all its points lie within
/// `dev` of the line `n·x = off` (`n` a unit normal), and their projections on the line
/// cover those of the cell's corners. So from every point `x` of the cell a point of the
/// stretch lies along the normal through `x`, within `|n·x − off| + dev` of `x`: that
/// bounds `x`'s depth.
#[derive(Debug, Clone, Copy, Default)]
struct Wall {
    n: [f64; 2],
    off: f64,
    dev: f64,
}

impl Wall {
    /// Signed distance of `x` to the line.
    #[inline]
    fn l(&self, x: [f64; 2]) -> f64 {
        self.n[0] * x[0] + self.n[1] * x[1] - self.off
    }

    /// An upper bound of the depth of `x` (a point of the cell the wall was made for).
    #[inline]
    fn bound(&self, x: [f64; 2]) -> f64 {
        self.l(x).abs() + self.dev
    }

    /// The point of the line nearest to `x`.
    fn foot(&self, x: [f64; 2]) -> [f64; 2] {
        let l = self.l(x);
        [x[0] - l * self.n[0], x[1] - l * self.n[1]]
    }

    /// The same line with its normal turned around.
    fn flipped(self) -> Wall {
        Wall {
            n: [-self.n[0], -self.n[1]],
            off: -self.off,
            dev: self.dev,
        }
    }
}

/// A convex polygon of at most 8 vertices (a square clipped by at most 4 half-planes).
#[derive(Debug, Clone, Copy)]
struct Convex {
    v: [[f64; 2]; 8],
    n: usize,
}

impl Convex {
    fn square(c: [f64; 2], h: f64) -> Convex {
        let mut v = [[0.0; 2]; 8];
        v[..4].copy_from_slice(&corners(c, h));
        Convex { v, n: 4 }
    }

    /// The part where `f(x) ≥ 0`, `f` affine (Sutherland–Hodgman against one line).
    fn clip(&self, f: impl Fn([f64; 2]) -> f64) -> Convex {
        let mut out = Convex {
            v: [[0.0; 2]; 8],
            n: 0,
        };
        for i in 0..self.n {
            let (p, q) = (self.v[i], self.v[if i + 1 == self.n { 0 } else { i + 1 }]);
            let (fp, fq) = (f(p), f(q));
            if fp >= 0.0 && out.n < 8 {
                out.v[out.n] = p;
                out.n += 1;
            }
            if (fp >= 0.0) != (fq >= 0.0) && out.n < 8 {
                let s = fp / (fp - fq);
                out.v[out.n] = [p[0] + s * (q[0] - p[0]), p[1] + s * (q[1] - p[1])];
                out.n += 1;
            }
        }
        out
    }

    fn vertices(&self) -> &[[f64; 2]] {
        &self.v[..self.n]
    }

    /// A point inside it, `None` when it has no area.
    fn interior_point(&self) -> Option<[f64; 2]> {
        let v = self.vertices();
        if v.len() < 3 {
            return None;
        }
        let mut a = 0.0;
        let mut s = [0.0; 2];
        for (i, p) in v.iter().enumerate() {
            let q = v[if i + 1 == v.len() { 0 } else { i + 1 }];
            a += p[0] * q[1] - q[0] * p[1];
            s = [s[0] + p[0], s[1] + p[1]];
        }
        let k = v.len() as f64;
        (a.abs() > 0.0).then(|| [s[0] / k, s[1] / k])
    }
}

/// Cells tried by [`Edges::walls_cover`]: half-size above this many times the depth to
/// beat (smaller ones are covered by discs around their walls' points as cheaply) and at
/// most [`SLAB_MAX_H_MM`] (walls curve too much over larger ones). Measured on logo_hires
/// (1, 1.2, 1.5, 2 and 3: 1.5 is cheapest; its thin rings are where the test pays).
const SLAB_MIN_H: f64 = 1.5;

/// See [`SLAB_MIN_H`], mm (no cell above 1 mm was dropped on logo_hires).
const SLAB_MAX_H_MM: f64 = 1.0;

/// How far a test point must stand from a wall's band to be taken as off it, mm (far
/// above the rounding of the clipping, far below any precision asked).
const SLAB_MARGIN: f64 = 1e-9;

impl Edges {
    /// Edges whose bounding boxes meet the square `[c ± h]`, into `out`; `None` when there
    /// are more than [`SLAB_EDGES`].
    fn crossing(&self, c: [f64; 2], h: f64, out: &mut [u32; SLAB_EDGES]) -> Option<usize> {
        let (lo, hi) = ([c[0] - h, c[1] - h], [c[0] + h, c[1] + h]);
        let meets = |a: [f64; 2], b: [f64; 2]| {
            a[0] <= hi[0] && b[0] >= lo[0] && a[1] <= hi[1] && b[1] >= lo[1]
        };
        let mut m = 0;
        let mut stack: [u32; 64] = [0; 64];
        stack[0] = (self.nodes.len() - 1) as u32;
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let n = &self.nodes[stack[sp] as usize];
            if !meets(n.lo, n.hi) {
                continue;
            }
            if n.count > 0 {
                let f = n.first as usize;
                for v in f..f + n.count as usize {
                    if self.seg_meets(v as u32, lo, hi) {
                        if m == SLAB_EDGES {
                            return None;
                        }
                        out[m] = v as u32;
                        m += 1;
                    }
                }
            } else {
                if sp + 2 > stack.len() {
                    return None;
                }
                stack[sp] = n.first;
                stack[sp + 1] = n.first + 1;
                sp += 2;
            }
        }
        Some(m)
    }

    /// Whether the bounding box of edge `v` meets the box `[lo, hi]`.
    #[inline]
    fn seg_meets(&self, v: u32, lo: [f64; 2], hi: [f64; 2]) -> bool {
        let s = &self.segs[v as usize];
        s[0].min(s[2]) <= hi[0]
            && s[0].max(s[2]) >= lo[0]
            && s[1].min(s[3]) <= hi[1]
            && s[1].max(s[3]) >= lo[1]
    }

    /// A [`Wall`] for the square `[c ± h]` through edge `v`: with `grow`, the maximal run
    /// of consecutive edges meeting the square through `v` (with its first edge and number
    /// of edges), otherwise `v` alone (0 edges counted); followed along the contour each
    /// way until the points' projections on the line through the stretch's two ends cover
    /// the square's corners'. `None` when the run closes on itself or is too long, or the
    /// wall cannot be followed far enough.
    fn wall(&self, v: u32, c: [f64; 2], h: f64, grow: bool) -> Option<(Wall, u32, usize)> {
        let (lo, hi) = ([c[0] - h, c[1] - h], [c[0] + h, c[1] + h]);
        let mut len = usize::from(grow);
        // The run's end each way: along `dir` (prev or next) while the edges meet the square.
        let mut run_end = |dir: &[u32]| {
            let mut k = v;
            while grow && self.seg_meets(dir[k as usize], lo, hi) {
                k = dir[k as usize];
                len += 1;
                if len > SLAB_EDGES {
                    return None;
                }
            }
            Some(k)
        };
        let first = run_end(&self.prev)?;
        let last = run_end(&self.next)?;
        let end = self.next[last as usize];
        let corners = Convex::square(c, h);
        // Projections on the line from `a` along the unit vector `u`: of the corners, and
        // whether the points from `back` to `fwd` cover them.
        let frame = |a: [f64; 2], b: [f64; 2]| {
            let d = [b[0] - a[0], b[1] - a[1]];
            let l = (d[0] * d[0] + d[1] * d[1]).sqrt();
            (l > 0.0 && l.is_finite()).then(|| (a, [d[0] / l, d[1] / l]))
        };
        let proj =
            |(a, u): ([f64; 2], [f64; 2]), x: [f64; 2]| u[0] * (x[0] - a[0]) + u[1] * (x[1] - a[1]);
        let span = |f: ([f64; 2], [f64; 2])| {
            corners
                .vertices()
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(m, n), x| {
                    let t = proj(f, *x);
                    (m.min(t), n.max(t))
                })
        };
        // First pass: along the line through the run's ends (the edge's, for one edge).
        let f = frame(self.vert(first), self.vert(end))?;
        let (q_lo, q_hi) = span(f);
        let (mut t_lo, mut t_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut k = first;
        loop {
            let t = proj(f, self.vert(k));
            (t_lo, t_hi) = (t_lo.min(t), t_hi.max(t));
            if k == end {
                break;
            }
            k = self.next[k as usize];
        }
        let (mut back, mut fwd) = (first, end);
        let mut steps = 0;
        while t_lo > q_lo {
            back = self.prev[back as usize];
            t_lo = t_lo.min(proj(f, self.vert(back)));
            steps += 1;
            if steps > SLAB_WALK || back == end {
                return None;
            }
        }
        steps = 0;
        while t_hi < q_hi {
            fwd = self.next[fwd as usize];
            t_hi = t_hi.max(proj(f, self.vert(fwd)));
            steps += 1;
            if steps > SLAB_WALK || fwd == back {
                return None;
            }
        }
        // Second pass: the line through the stretch's ends (a chord: the points stand
        // less far from it), which must still cover the corners.
        let f = frame(self.vert(back), self.vert(fwd))?;
        let (q_lo, q_hi) = span(f);
        let n = [-f.1[1], f.1[0]];
        let (mut t_lo, mut t_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut l_lo, mut l_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut k = back;
        loop {
            let x = self.vert(k);
            let t = proj(f, x);
            let l = n[0] * (x[0] - f.0[0]) + n[1] * (x[1] - f.0[1]);
            (t_lo, t_hi) = (t_lo.min(t), t_hi.max(t));
            (l_lo, l_hi) = (l_lo.min(l), l_hi.max(l));
            if k == fwd {
                break;
            }
            k = self.next[k as usize];
        }
        if t_lo > q_lo || t_hi < q_hi {
            return None;
        }
        let mid = 0.5 * (l_lo + l_hi);
        let wall = Wall {
            n,
            off: n[0] * f.0[0] + n[1] * f.0[1] + mid,
            dev: 0.5 * (l_hi - l_lo),
        };
        Some((wall, first, len))
    }

    /// Whether no point of the square `[c ± h]` inside the section is deeper than `t`,
    /// shown from the walls crossing it: when the edges meeting the square form at most
    /// two runs of consecutive edges, each close to a line over the square ([`Wall`]),
    /// the square falls into the walls' bands (depth at most twice the band's half-width),
    /// the part beyond each wall and the part between them (or on either side of a single
    /// wall). No edge meets those parts, so each is wholly inside or wholly outside the
    /// section (one inside test); an inside part is bounded by the walls' depth bounds,
    /// convex, so by their largest value at the part's corners (between two walls, their
    /// mean: the smaller is at most the mean). `false` means not shown.
    ///
    /// This drops cells that straddle a wall thinner than the cell (a thin ring's cells
    /// stick out of it on both sides, so discs around wall points cannot cover them).
    fn walls_cover(&self, c: [f64; 2], h: f64, t: f64, hints: [u32; 2]) -> bool {
        let mut es = [0u32; SLAB_EDGES];
        let Some(m) = self.crossing(c, h, &mut es) else {
            return false;
        };
        let es = &es[..m];
        let sq = Convex::square(c, h);
        let mut walls = [Wall::default(); 2];
        let mut nw = 0;
        if let Some(&v1) = es.first() {
            let Some((w1, f1, r1)) = self.wall(v1, c, h, true) else {
                return false;
            };
            walls[0] = w1;
            nw = 1;
            if r1 != m {
                // The second run: through an edge not in the first.
                let in_first = |v: u32| {
                    let mut k = f1;
                    for _ in 0..r1 {
                        if k == v {
                            return true;
                        }
                        k = self.next[k as usize];
                    }
                    false
                };
                let Some(&v2) = es.iter().find(|&&v| !in_first(v)) else {
                    return false;
                };
                let Some((w2, _, r2)) = self.wall(v2, c, h, true) else {
                    return false;
                };
                // A third run: not shown.
                if r1 + r2 != m {
                    return false;
                }
                walls[1] = w2;
                nw = 2;
            }
        }
        // Walls near the square but not across it, from the hints.
        for &v in &hints {
            if nw < 2 && v != u32::MAX && !self.seg_meets(v, sq.v[0], sq.v[2]) {
                if let Some((w, _, _)) = self.wall(v, c, h, false) {
                    // Not the wall already found, again.
                    let f = w.foot(c);
                    if nw == 0 || walls[0].l(f).abs() > walls[0].dev + w.dev {
                        walls[nw] = w;
                        nw += 1;
                    }
                }
            }
        }
        if nw == 0 {
            // No boundary in the square: wholly outside, or not shown.
            return m == 0 && !self.inside(c);
        }
        let walls = &mut walls[..nw];
        // Inside each band the depth is at most twice its half-width.
        if walls.iter().any(|w| 2.0 * w.dev > t) {
            return false;
        }
        if let [a, b] = walls {
            // Normals towards each other (whether the bands meet in the square is checked
            // below, through the parts beyond each wall).
            let (la, lb) = (a.l(b.foot(c)), b.l(a.foot(c)));
            if la.abs() <= a.dev || lb.abs() <= b.dev {
                return false;
            }
            if la < 0.0 {
                *a = a.flipped();
            }
            if lb < 0.0 {
                *b = b.flipped();
            }
        }
        let walls = &*walls;
        // The part beyond each wall (away from the other one).
        for (i, w) in walls.iter().enumerate() {
            let part = sq.clip(|x| -w.l(x) - w.dev);
            if let Some(o) = walls.get(1 - i) {
                // It must not meet the other wall's band.
                let v = part.vertices();
                let above = v.iter().all(|x| o.l(*x) > o.dev);
                let below = v.iter().all(|x| o.l(*x) < -o.dev);
                if !above && !below {
                    return false;
                }
            }
            if !self.part_covered(&part, walls, t, Some(i)) {
                return false;
            }
        }
        // The part between them (or on the other side of a single wall).
        let part = walls
            .iter()
            .fold(sq, |part, w| part.clip(|x| w.l(x) - w.dev));
        self.part_covered(&part, walls, t, None)
    }

    /// Whether no point of `part` (a part of a cell crossed by no edge) inside the section
    /// is deeper than `t`: outside (inside test at one point), or bounded by `walls`
    /// (`beyond`: the part beyond that wall, bounded by it; `None`: the part between the
    /// walls, bounded by either or by their mean). The bounds are convex: their largest
    /// value on the part is at a corner.
    fn part_covered(&self, part: &Convex, walls: &[Wall], t: f64, beyond: Option<usize>) -> bool {
        let Some(p) = part.interior_point() else {
            return true;
        };
        // Rounding could put a point of a thin part on a band: not shown then.
        if walls.iter().any(|w| w.l(p).abs() <= w.dev + SLAB_MARGIN) {
            return false;
        }
        if !self.inside(p) {
            return true;
        }
        let v = part.vertices();
        let max =
            |f: &dyn Fn([f64; 2]) -> f64| v.iter().fold(f64::NEG_INFINITY, |m, x| m.max(f(*x)));
        match (beyond, walls) {
            (Some(i), _) => max(&|x| walls[i].bound(x)) <= t,
            (None, [a]) => max(&|x| a.bound(x)) <= t,
            (None, [a, b]) => {
                max(&|x| 0.5 * (a.bound(x) + b.bound(x))) <= t
                    || max(&|x| a.bound(x)) <= t
                    || max(&|x| b.bound(x)) <= t
            }
            _ => false,
        }
    }
}

/// Most contour points an [`Arc`] is followed each way from its edge to cover the
/// square's projection on that edge's line (and three times as many to reach the rays of
/// the square's corners).
const ARC_WALK: usize = 64;

/// Radius of the circle a straight wall is seen on, mm (far enough that a wall a few
/// millimetres long stands less than a micrometre off it, near enough that distances to
/// its centre keep about 1e-10 mm of rounding).
const ARC_LINE_R: f64 = 1e6;

/// Widening of an [`Arc`]'s band for the rounding of the distances to its centre, mm.
const ARC_MARGIN: f64 = 1e-9;

/// Cells tried by [`Edges::arcs_cover`]: half-size at least this many times the
/// precision (smaller ones are covered by discs around their walls' points as cheaply),
/// and below the depth to beat (on logo_hires, 5 % of the tries on larger cells dropped
/// them, against 50 % below).
const ARC_MIN_H: f64 = 8.0;

/// Arcs kept by a search for the following cells ([`ArcCache`]).
const ARC_CACHE: usize = 8;

/// A search tries [`Edges::arcs_cover`] on its first `ARC_TRIAL` cells, then only while
/// at least one try in `ARC_RATE` has dropped its cell: on sections whose walls are not
/// round (a bunny, a gear) the arcs rarely show anything and a failed try costs about a
/// cell's own tests (measured on logo_hires, torus_hires, bunny00 and mcad_gear: trial 2
/// and walks of 64 points cost least over the four).
const ARC_TRIAL: usize = 2;

/// See [`ARC_TRIAL`].
const ARC_RATE: usize = 4;

/// [`Edges::ring_cover`] is tried as [`Edges::arcs_cover`] is ([`ARC_TRIAL`], [`ARC_RATE`]),
/// and also on every `RING_PROBE`-th cell it could be tried on when that has stopped: a
/// search's first cells are large and seldom dropped, and without the probes one failed
/// start would stop the tries for the whole search (logo_hires search instructions: no
/// probes 643 M before the seeds of [`SEED_AFTER`], with them every 16th 557 M, every 8th
/// 511 M; every 2nd or every cell save it a little more but cost mcad_gear 3 % and 7 %).
const RING_PROBE: usize = 8;

/// After its first `SEED_AFTER` cells with no centre inside the section, a search takes
/// the best of [`Edges::ridge_probe`] on `SEEDS` edges spread over the contours as the
/// depth to beat: a thin section (a ring's first layers) has few cells whose centre is
/// inside it, and until one is found every cell is split (logo_hires: search 584 → 511 M
/// instructions; seeding every search costs bunny00 +4 %).
const SEED_AFTER: usize = 4;

/// See [`SEED_AFTER`].
const SEEDS: usize = 2;

/// A stretch of a contour, the points `back` to `fwd` (consecutive indexes), seen from a
/// centre `o`: every point of it (its edges included) lies at a distance in the band
/// `[lo, hi]` from `o`, and all of it lies in the open half-plane `{y : w·(y − o) > 0}`,
/// where the angle around `o` is continuous and compared by cross products. So it goes
/// through every ray from `o` between its ends' rays, and the ray through any point `x`
/// between them meets the stretch at a distance in `[lo, hi]` from `o`: that bounds the
/// depth of `x` by `ρ(x) − lo` beyond the band (`ρ` the distance to `o`), `hi − ρ(x)`
/// before it, `hi − lo` in it. A curved wall (a hole's, a ring's) is seen from its
/// centre of curvature, so the band is thin however long the stretch; a straight wall
/// from a point [`ARC_LINE_R`] away.
#[derive(Debug, Clone, Copy)]
struct Arc {
    o: [f64; 2],
    lo: f64,
    hi: f64,
    w: [f64; 2],
    /// The stretch's first and last points, and their vectors from `o`; when it runs
    /// over the end of its contour's points, their first and last indexes.
    back: u32,
    fwd: u32,
    wrap: Option<(u32, u32)>,
    rb: [f64; 2],
    rf: [f64; 2],
    /// The way the stretch turns around `o` from `rb` to `rf`: the sign of `rb × rf`.
    sigma: f64,
}

impl Arc {
    fn rho(&self, x: [f64; 2]) -> f64 {
        d2(x, self.o).sqrt()
    }

    /// Whether the square's corners lie in the half-plane and between the ends' rays
    /// (then the whole square does: both are convex).
    fn holds(&self, cs: &[[f64; 2]; 4]) -> bool {
        cs.iter().all(|x| {
            let y = [x[0] - self.o[0], x[1] - self.o[1]];
            self.w[0] * y[0] + self.w[1] * y[1] > 0.0
                && self.sigma * cross(self.rb, y) >= 0.0
                && self.sigma * cross(y, self.rf) >= 0.0
        })
    }

    /// Whether the edges `[s0, s1)` (`s0 < s1`) are all the stretch's.
    fn has_span(&self, [s0, s1]: [u32; 2]) -> bool {
        match self.wrap {
            None => self.back <= s0 && s1 <= self.fwd,
            Some((first, last)) => {
                (self.back <= s0 && s1 <= last + 1) || (first <= s0 && s1 <= self.fwd)
            }
        }
    }

    /// Whether edge `v` is one of the stretch's.
    fn has(&self, v: u32) -> bool {
        match self.wrap {
            None => self.back <= v && v < self.fwd,
            Some((first, last)) => (self.back <= v && v <= last) || (first <= v && v < self.fwd),
        }
    }

    /// Distances from `o` to the square's nearest point and farthest corner.
    fn near_far(&self, c: [f64; 2], h: f64, cs: &[[f64; 2]; 4]) -> (f64, f64) {
        let near = d2(clamp_to(c, h, self.o), self.o).sqrt();
        let far = cs.iter().fold(0.0f64, |m, x| m.max(d2(*x, self.o))).sqrt();
        (near, far)
    }
}

/// The arcs a search made last, tried again for the following cells (most cells along a
/// wall are held by the same stretch).
#[derive(Default)]
struct ArcCache {
    arcs: [Option<Arc>; ARC_CACHE],
    next: usize,
}

impl ArcCache {
    fn clear(&mut self) {
        *self = ArcCache::default();
    }

    /// An arc through edge `v` holding the square `[c ± h]` (corners `cs`): a kept one, or
    /// a new one (then kept).
    fn get(&mut self, e: &Edges, v: u32, c: [f64; 2], h: f64, cs: &[[f64; 2]; 4]) -> Option<Arc> {
        if let Some(a) = self.arcs.iter().flatten().find(|a| a.has(v) && a.holds(cs)) {
            return Some(*a);
        }
        let a = e.arc(v, c, h)?;
        self.arcs[self.next] = Some(a);
        self.next = (self.next + 1) % ARC_CACHE;
        Some(a)
    }
}

/// The point of the square `[c ± h]` nearest to `o`.
fn clamp_to(c: [f64; 2], h: f64, o: [f64; 2]) -> [f64; 2] {
    [
        o[0].clamp(c[0] - h, c[0] + h),
        o[1].clamp(c[1] - h, c[1] + h),
    ]
}

/// The largest value over the square `[c ± h]` (corners `cs`) of the depth bound of `a`
/// (`beyond`: the side away from its centre, `ρ − lo`, convex: largest at a corner; else
/// `hi − ρ`, largest at the square's point nearest `o`, `near` away), and of the mean of
/// it and `b`'s (`b` wholly on side `b_beyond`, its `near`): `ρ_A − ρ_B ≤ |o_A − o_B|` and
/// `ρ ≥ w·(x − o)` for a unit `w` (towards the square's centre) leave a constant or a
/// convex function. Between the two walls of a ring (concentric circles) the mean is the
/// ring's half-width over the whole square.
fn arc_bound(
    (c, cs): ([f64; 2], &[[f64; 2]; 4]),
    (a, beyond, a_near): (&Arc, bool, f64),
    b: Option<(&Arc, bool, f64)>,
) -> f64 {
    let max = |f: &dyn Fn([f64; 2]) -> f64| cs.iter().fold(f64::NEG_INFINITY, |m, x| m.max(f(*x)));
    let alone = |a: &Arc, beyond: bool, near: f64| {
        if beyond {
            max(&|x| a.rho(x) - a.lo)
        } else {
            a.hi - near
        }
    };
    let mut best = alone(a, beyond, a_near);
    let Some((b, b_beyond, b_near)) = b else {
        return best;
    };
    best = best.min(alone(b, b_beyond, b_near));
    // `ρ(x) ≥ w·(x − o)`, `w` towards the square's centre (a tangent of the cone).
    let tangent = |a: &Arc| {
        let o = a.o;
        let w = unit([c[0] - o[0], c[1] - o[1]]).unwrap_or([1.0, 0.0]);
        move |x: [f64; 2]| w[0] * (x[0] - o[0]) + w[1] * (x[1] - o[1])
    };
    let oo = d2(a.o, b.o).sqrt();
    let sum = match (beyond, b_beyond) {
        (true, true) => max(&|x| a.rho(x) - a.lo + b.rho(x) - b.lo),
        (true, false) | (false, true) => {
            let (p, q) = if beyond { (a, b) } else { (b, a) };
            // ρ_p − lo_p + hi_q − ρ_q.
            let tq = tangent(q);
            (oo + q.hi - p.lo).min(max(&|x| p.rho(x) - p.lo + q.hi - tq(x)))
        }
        (false, false) => {
            let (ta, tb) = (tangent(a), tangent(b));
            (a.hi + b.hi - oo).min(max(&|x| a.hi + b.hi - ta(x) - tb(x)))
        }
    };
    best.min(0.5 * sum)
}

impl Edges {
    /// An [`Arc`] through edge `v` for the square `[c ± h]`: the stretch is first followed
    /// each way until its points' projections on `v`'s line cover the square's corners';
    /// its centre `o` is the circle through its ends and `v`'s start (or a point
    /// [`ARC_LINE_R`] away, on the far side from the square, when that circle is larger);
    /// its half-plane faces the square's centre. It is followed further until its ends'
    /// rays hold the square's corners between them. `None` when the stretch cannot be
    /// followed far enough, leaves the half-plane or runs over the end of its contour's
    /// points (its indexes must be consecutive).
    fn arc(&self, v: u32, c: [f64; 2], h: f64) -> Option<Arc> {
        let cs = corners(c, h);
        let a = self.vert(v);
        let u = unit([
            self.segs[v as usize][2] - a[0],
            self.segs[v as usize][3] - a[1],
        ])?;
        let proj = |x: [f64; 2]| u[0] * (x[0] - a[0]) + u[1] * (x[1] - a[1]);
        let (q_lo, q_hi) = cs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(m, n), x| {
                (m.min(proj(*x)), n.max(proj(*x)))
            });
        // Points `back` and `fwd` (edge `v` runs from point `v` to the next), the steps
        // taken each way, and where the contour's indexes wrap around when they do.
        let (mut back, mut fwd) = (v, self.next[v as usize]);
        let (mut nb, mut nf) = (0usize, 0usize);
        let mut wrap = (fwd < v).then_some((fwd, v));
        let step_back = |back: &mut u32, wrap: &mut Option<(u32, u32)>| {
            let p = self.prev[*back as usize];
            if p > *back {
                *wrap = Some((*back, p));
            }
            *back = p;
        };
        let step_fwd = |fwd: &mut u32, wrap: &mut Option<(u32, u32)>| {
            let n = self.next[*fwd as usize];
            if n < *fwd {
                *wrap = Some((n, *fwd));
            }
            *fwd = n;
        };
        while proj(self.vert(back)) > q_lo {
            step_back(&mut back, &mut wrap);
            nb += 1;
            if nb > ARC_WALK || back == fwd {
                return None;
            }
        }
        while proj(self.vert(fwd)) < q_hi {
            step_fwd(&mut fwd, &mut wrap);
            nf += 1;
            if nf > ARC_WALK || fwd == back {
                return None;
            }
        }
        let (p0, p1, p2) = (self.vert(back), a, self.vert(fwd));
        // The circle through the three points, relative to p0.
        let (b, d) = (
            [p1[0] - p0[0], p1[1] - p0[1]],
            [p2[0] - p0[0], p2[1] - p0[1]],
        );
        let den = 2.0 * cross(b, d);
        let (bb, dd) = (b[0] * b[0] + b[1] * b[1], d[0] * d[0] + d[1] * d[1]);
        let oc = [(d[1] * bb - b[1] * dd) / den, (b[0] * dd - d[0] * bb) / den];
        let o = if oc[0].is_finite()
            && oc[1].is_finite()
            && oc[0] * oc[0] + oc[1] * oc[1] <= ARC_LINE_R * ARC_LINE_R
        {
            [p0[0] + oc[0], p0[1] + oc[1]]
        } else {
            // Straight: seen from far away on the side away from the square.
            let m = [0.5 * (p0[0] + p2[0]), 0.5 * (p0[1] + p2[1])];
            let t = unit(d)?;
            let mut n = [-t[1], t[0]];
            if n[0] * (c[0] - m[0]) + n[1] * (c[1] - m[1]) > 0.0 {
                n = [-n[0], -n[1]];
            }
            [m[0] + ARC_LINE_R * n[0], m[1] + ARC_LINE_R * n[1]]
        };
        let rel = |x: [f64; 2]| [x[0] - o[0], x[1] - o[1]];
        // The half-plane: the corners must be in it too.
        let w = rel(c);
        let in_h = |y: [f64; 2]| w[0] * y[0] + w[1] * y[1] > 0.0;
        let rc = cs.map(rel);
        if !rc.iter().all(|y| in_h(*y)) {
            return None;
        }
        // The way the stretch turns around `o` from `back` to `fwd`, and the corners
        // first and last that way.
        let sigma = cross(rel(p0), rel(p2)).signum();
        if sigma == 0.0 || sigma.is_nan() {
            return None;
        }
        let (mut x0, mut x1) = (rc[0], rc[0]);
        for &y in &rc[1..] {
            if sigma * cross(y, x0) > 0.0 {
                x0 = y;
            }
            if sigma * cross(x1, y) > 0.0 {
                x1 = y;
            }
        }
        // The band over every edge from `back` to `fwd`, following the stretch further
        // while its ends' rays do not hold the corners.
        let (mut lo2, mut hi2) = (f64::INFINITY, 0.0f64);
        let mut edge = |k: u32| {
            let s = &self.segs[k as usize];
            let (p, q) = (rel([s[0], s[1]]), rel([s[2], s[3]]));
            if !in_h(p) {
                return false;
            }
            hi2 = hi2.max(p[0] * p[0] + p[1] * p[1]);
            // The distance to the edge's line: at most the distance to the edge.
            let e = [q[0] - p[0], q[1] - p[1]];
            let cr = cross(p, q);
            lo2 = lo2.min(cr * cr / (e[0] * e[0] + e[1] * e[1]));
            true
        };
        let mut k = back;
        while k != fwd {
            if !edge(k) {
                return None;
            }
            k = self.next[k as usize];
        }
        while sigma * cross(rel(self.vert(back)), x0) < 0.0 {
            step_back(&mut back, &mut wrap);
            nb += 1;
            if nb > 3 * ARC_WALK || back == fwd || !edge(back) {
                return None;
            }
        }
        while sigma * cross(x1, rel(self.vert(fwd))) < 0.0 {
            if nf > 3 * ARC_WALK || !edge(fwd) {
                return None;
            }
            step_fwd(&mut fwd, &mut wrap);
            nf += 1;
            if fwd == back {
                return None;
            }
        }
        let (rb, rf) = (rel(self.vert(back)), rel(self.vert(fwd)));
        if !in_h(rf) {
            return None;
        }
        hi2 = hi2.max(rf[0] * rf[0] + rf[1] * rf[1]);
        Some(Arc {
            o,
            lo: lo2.sqrt() - ARC_MARGIN,
            hi: hi2.sqrt() + ARC_MARGIN,
            w,
            back,
            fwd,
            wrap,
            rb,
            rf,
            sigma,
        })
    }

    /// Whether no point of the square `[c ± h]` inside the section is deeper than `t`
    /// (its centre must be inside the section), shown from its walls seen as [`Arc`]s:
    /// every edge meeting the square must belong to the stretch of one arc `A` (through
    /// such an edge, or through `hints[0]`, the edge nearest to the centre, when none
    /// does), so the square falls into `A`'s band, the part before it (a disc: convex,
    /// one piece, holding the square's point nearest `A`'s centre) and the part beyond it
    /// (each of its pieces holds a corner: a piece of a square outside a disc reaches the
    /// square's boundary, whose parts outside the disc each hold a corner). No edge meets
    /// those parts, so one inside test settles each piece (none when no edge meets the
    /// square: it is all inside). The band's depth is at most its width; a part inside
    /// the section is bounded by `A`, or by the mean of `A` and a second arc through the
    /// other hint ([`arc_bound`]). Arcs come from `cache` when one holds the square.
    /// `false` means not shown.
    fn arcs_cover(
        &self,
        c: [f64; 2],
        h: f64,
        t: f64,
        hints: [u32; 2],
        cache: &mut ArcCache,
    ) -> bool {
        let mut es = [0u32; SLAB_EDGES];
        let Some(m) = self.crossing(c, h, &mut es) else {
            return false;
        };
        let first = if m > 0 { es[0] } else { hints[0] };
        if first == u32::MAX {
            return false;
        }
        let cs = corners(c, h);
        let Some(a) = cache.get(self, first, c, h, &cs) else {
            return false;
        };
        if !es[..m].iter().all(|&v| a.has(v)) {
            return false;
        }
        let (near, far) = a.near_far(c, h, &cs);
        // The band, where it meets the square.
        if near <= a.hi && far >= a.lo && a.hi - a.lo > t {
            return false;
        }
        // The parts inside the section: before the band, beyond it.
        let before = near < a.lo && (m == 0 || self.inside(clamp_to(c, h, a.o)));
        let beyond =
            far > a.hi && (m == 0 || cs.iter().any(|x| a.rho(*x) > a.hi && self.inside(*x)));
        let mut second = None;
        for side in [false, true] {
            if !(if side { beyond } else { before }) {
                continue;
            }
            if arc_bound((c, &cs), (&a, side, near), None) <= t {
                continue;
            }
            // The other wall, once: wholly on one side of its band's middle (there one of
            // its two bounds is the larger).
            if second.is_none() {
                let other = if m > 0 && hints[0] != u32::MAX && !a.has(hints[0]) {
                    hints[0]
                } else {
                    hints[1]
                };
                second = Some(
                    (other != u32::MAX && !a.has(other))
                        .then(|| cache.get(self, other, c, h, &cs))
                        .flatten()
                        .and_then(|b| {
                            let (near, far) = b.near_far(c, h, &cs);
                            let mid = 0.5 * (b.lo + b.hi);
                            if near >= mid {
                                Some((b, true, near))
                            } else if far <= mid {
                                Some((b, false, near))
                            } else {
                                None
                            }
                        }),
                );
            }
            let Some(Some((b, b_side, b_near))) = second else {
                return false;
            };
            if arc_bound((c, &cs), (&a, side, near), Some((&b, b_side, b_near))) > t {
                return false;
            }
        }
        true
    }
}

impl Edges {
    /// An edge whose bounding box meets the square `[c ± h]` and that is none of `arcs`'
    /// stretches' (`u32::MAX` when the index is too deep to tell), or `None` when every
    /// edge meeting the square is one of theirs.
    fn stray(&self, c: [f64; 2], h: f64, arcs: &[&Arc]) -> Option<u32> {
        let (lo, hi) = ([c[0] - h, c[1] - h], [c[0] + h, c[1] + h]);
        let mut stack: [u32; 64] = [0; 64];
        stack[0] = (self.nodes.len() - 1) as u32;
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let k = stack[sp] as usize;
            let n = &self.nodes[k];
            if !(n.lo[0] <= hi[0] && n.hi[0] >= lo[0] && n.lo[1] <= hi[1] && n.hi[1] >= lo[1])
                || arcs.iter().any(|a| a.has_span(self.spans[k]))
            {
                continue;
            }
            if n.count > 0 {
                let f = n.first;
                for v in f..f + n.count {
                    if self.seg_meets(v, lo, hi) && !arcs.iter().any(|a| a.has(v)) {
                        return Some(v);
                    }
                }
            } else {
                if sp + 2 > stack.len() {
                    return Some(u32::MAX);
                }
                stack[sp] = n.first;
                stack[sp + 1] = n.first + 1;
                sp += 2;
            }
        }
        None
    }

    /// Whether no point of the square `[c ± h]` is deeper than `t`, shown from two walls
    /// crossing it seen as [`Arc`]s, one inside the other (a ring's): `A` through `near`
    /// and `B` through an edge meeting the square that is not `A`'s; every edge meeting
    /// the square must be one of theirs. With `I` the inner arc and `O` the outer one, the
    /// bands must be nested with room to spare, `lo_O − hi_I > |o_I − o_O|`: then `O`'s
    /// stretch lies beyond `I`'s band and `I`'s before `O`'s, and the square falls into
    /// five parts: before `I`'s band (a disc's piece: convex, no edge meets it, one inside
    /// test at its point nearest `o_I`), `I`'s band (depth at most its width), between the
    /// bands, `O`'s band, and beyond `O`'s band (no edge meets it; each piece holds a
    /// corner: one inside test at each such corner). Between the bands no inside test is
    /// needed: a point there is beyond `I` and before `O`, so [`arc_bound`]'s mean bounds
    /// its depth whether it is inside the section or not (outside, the depth is negative).
    /// Unlike [`Edges::arcs_cover`], the centre need not be inside the section, and the
    /// square may be larger than `t`: a cell straddling a thin ring. `false` means not
    /// shown.
    fn ring_cover(&self, c: [f64; 2], h: f64, t: f64, near: u32, cache: &mut ArcCache) -> bool {
        if near == u32::MAX {
            return false;
        }
        let cs = corners(c, h);
        let Some(a) = cache.get(self, near, c, h, &cs) else {
            return false;
        };
        let v = match self.stray(c, h, &[&a]) {
            Some(v) if v != u32::MAX => v,
            _ => return false,
        };
        let Some(b) = cache.get(self, v, c, h, &cs) else {
            return false;
        };
        if self.stray(c, h, &[&a, &b]).is_some() {
            return false;
        }
        let oo = d2(a.o, b.o).sqrt();
        let (i, o) = if b.lo - a.hi > oo {
            (a, b)
        } else if a.lo - b.hi > oo {
            (b, a)
        } else {
            return false;
        };
        let (ni, fi) = i.near_far(c, h, &cs);
        let (no, fo) = o.near_far(c, h, &cs);
        // The bands, where they meet the square.
        if (ni <= i.hi && fi >= i.lo && i.hi - i.lo > t)
            || (no <= o.hi && fo >= o.lo && o.hi - o.lo > t)
        {
            return false;
        }
        let cc = (c, &cs);
        // Between the bands.
        if fi > i.hi && no < o.lo && arc_bound(cc, (&i, true, ni), Some((&o, false, no))) > t {
            return false;
        }
        // Before the inner band, beyond the outer one: bounded, or outside the section.
        if ni < i.lo
            && arc_bound(cc, (&i, false, ni), Some((&o, false, no))) > t
            && self.inside(clamp_to(c, h, i.o))
        {
            return false;
        }
        if fo > o.hi
            && arc_bound(cc, (&i, true, ni), Some((&o, true, no))) > t
            && cs.iter().any(|x| o.rho(*x) > o.hi && self.inside(*x))
        {
            return false;
        }
        true
    }
}

#[cfg(test)]
mod tests {
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

    /// Thin sections: rings, a ring cut into pieces (walls ending inside cells), a thin
    /// rotated bar and a thin wedge (walls meeting at an angle).
    fn thin_sections(rnd: &mut impl FnMut() -> f64) -> Vec<Vec<Contour>> {
        let mut out = Vec::new();
        for _ in 0..6 {
            let (r, w) = (2.0 + 10.0 * rnd(), 0.01 + 0.3 * rnd());
            let n = 64 + (600.0 * rnd()) as usize;
            out.push(vec![
                ngon(0.0, 0.0, r + w, n, true),
                ngon(0.0, 0.0, r, n, false),
            ]);
        }
        out.push(cross_cut_pieces(6.0, 5.9, 0.05, 200));
        let a = rnd();
        let (u, v) = ([a.cos(), a.sin()], [-a.sin(), a.cos()]);
        let bar = |x: f64, y: f64| [x * u[0] + y * v[0], x * u[1] + y * v[1]];
        out.push(vec![vec![
            bar(-5.0, 0.0),
            bar(5.0, 0.0),
            bar(5.0, 0.07),
            bar(-5.0, 0.07),
        ]]);
        out.push(vec![vec![[0.0, 0.0], [8.0, 0.0], [8.0, 0.4]]]);
        out
    }

    #[test]
    fn walls_cover_never_hides_a_deep_point() {
        // Whenever the walls drop a cell, no point of it inside the section is deeper than
        // the radius asked (checked on a grid of the cell); and they do drop cells.
        let mut rnd = xorshift(0x005e_ed0f_7ee1);
        let (mut tried, mut dropped) = (0, 0);
        for section in thin_sections(&mut rnd) {
            let e = Edges::new(&section);
            for _ in 0..400 {
                // Cells near the boundary: around a random boundary point.
                let i = (rnd() * e.segs.len() as f64) as usize % e.segs.len();
                let q = e.vert(i as u32);
                let h = 0.01 + 0.6 * rnd();
                let c = [
                    q[0] + h * (2.0 * rnd() - 1.0),
                    q[1] + h * (2.0 * rnd() - 1.0),
                ];
                let t = 0.005 + 0.2 * rnd();
                let hint = if rnd() < 0.5 { i as u32 } else { u32::MAX };
                tried += 1;
                if !e.walls_cover(c, h, t, [hint, u32::MAX]) {
                    continue;
                }
                dropped += 1;
                assert_no_deeper(&e, (c, h), t + 1e-12, 40);
            }
        }
        assert!(dropped * 10 > tried, "{dropped} of {tried} dropped");
    }

    #[test]
    fn walls_cover_drops_cells_across_a_thin_ring_and_no_deeper() {
        // A ring 0.04 mm wide (depth 0.02): a cell of half-size 0.2 across it holds no
        // point deeper than 0.04, but points deeper than 0.015.
        let ring = vec![
            ngon(0.0, 0.0, 11.29, 1440, true),
            ngon(0.0, 0.0, 11.25, 1440, false),
        ];
        let e = Edges::new(&ring);
        let c = [11.27, 0.05];
        assert!(e.walls_cover(c, 0.2, 0.04, [u32::MAX; 2]));
        assert!(!e.walls_cover(c, 0.2, 0.015, [u32::MAX; 2]));
        // Wholly outside, with no boundary in it: dropped; wholly inside a thick section
        // far from its walls: not shown.
        assert!(e.walls_cover([0.0, 0.0], 0.5, 0.01, [u32::MAX; 2]));
        let disc = vec![ngon(0.0, 0.0, 10.0, 400, true)];
        assert!(!Edges::new(&disc).walls_cover([0.0, 0.0], 0.5, 0.01, [u32::MAX; 2]));
        // The search keeps the guarantee on such rings.
        for w in [0.03, 0.05, 0.2] {
            let ring = vec![
                ngon(0.0, 0.0, 11.25 + w, 1440, true),
                ngon(0.0, 0.0, 11.25, 1440, false),
            ];
            let r = max_fill_distance(&ring).0;
            // The regular polygons' ring is a little narrower than w where their edges
            // are (their apothems differ from their radii by the same factor).
            let exact = 0.5 * w * (std::f64::consts::PI / 1440.0).cos();
            assert!(r <= exact + 1e-9 && r >= exact - PRECISION_MM, "{w}: {r}");
        }
    }

    /// Sections with curved walls: rings (concentric, off-centre, coarse and fine), a
    /// ring cut into quarters (straight and curved walls), an elliptic ring (walls that
    /// are no circles), a disc and a wavy blob.
    fn curved_sections(rnd: &mut impl FnMut() -> f64) -> Vec<Vec<Contour>> {
        let mut out = Vec::new();
        for _ in 0..4 {
            let (r, w) = (3.0 + 10.0 * rnd(), 0.5 + 4.0 * rnd());
            let n = 48 + (600.0 * rnd()) as usize;
            let off = if rnd() < 0.5 { 0.0 } else { 0.3 * w * rnd() };
            out.push(vec![
                ngon(0.0, 0.0, r + w, n, true),
                ngon(off, 0.0, r, n, false),
            ]);
        }
        out.push(cross_cut_pieces(12.0, 7.0, 1.5, 240));
        out.push(vec![ellipse(12.0, 8.0, true), ellipse(9.0, 5.0, false)]);
        out.push(vec![ngon(1.0, -2.0, 6.0, 300, true)]);
        out.push(vec![(0..500)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 500.0;
                let r = 8.0 + 1.5 * (5.0 * t).sin();
                [r * t.cos(), r * t.sin()]
            })
            .collect()]);
        out
    }

    #[test]
    fn arcs_cover_never_hides_a_deep_point() {
        // Whenever the arcs drop a cell (centre inside the section, as the search asks),
        // no point of it inside the section is deeper than the radius asked (checked on a
        // grid of the cell); and they do drop cells.
        let mut rnd = xorshift(0x00a7_c5c0_7e75);
        let (mut tried, mut dropped) = (0, 0);
        for section in curved_sections(&mut rnd) {
            let e = Edges::new(&section);
            let root = e.nodes.last().unwrap();
            let mut cache = ArcCache::default();
            let mut k = 0;
            while k < 200 {
                let c = [
                    root.lo[0] + (root.hi[0] - root.lo[0]) * rnd(),
                    root.lo[1] + (root.hi[1] - root.lo[1]) * rnd(),
                ];
                let d = e.signed_distance(c);
                if d <= 0.0 {
                    continue;
                }
                k += 1;
                let h = (0.05 + 3.0 * rnd()).min(2.0 * d + 1.0);
                // About the cell's largest depth (on a coarse grid), a little below or above.
                let mut m = d;
                for a in 0..=8 {
                    for b in 0..=8 {
                        let x = [c[0] - h + h * a as f64 / 4.0, c[1] - h + h * b as f64 / 4.0];
                        m = m.max(e.signed_distance(x));
                    }
                }
                let t = m - 0.02 + 0.1 * rnd();
                // The hints: the nearest edge and the one nearest the mirror of its point.
                let near = e.nearest(c, u32::MAX).1;
                let q = e.closest_point(near, c);
                let far = e
                    .nearest([2.0 * c[0] - q[0], 2.0 * c[1] - q[1]], u32::MAX)
                    .1;
                if rnd() < 0.2 {
                    cache.clear();
                }
                tried += 1;
                if !e.arcs_cover(c, h, t, [near, far], &mut cache) {
                    continue;
                }
                dropped += 1;
                assert_no_deeper(&e, (c, h), t + 1e-9, 32);
            }
        }
        assert!(dropped * 4 > tried, "{dropped} of {tried} dropped");
    }

    /// Rings of all widths (thin ones as a fine mesh's first layers have, off-centre,
    /// coarse and fine), an elliptic ring, the thin rings' complement (a gap between two
    /// parts of the section) and a disc.
    fn ring_sections(rnd: &mut impl FnMut() -> f64) -> Vec<Vec<Contour>> {
        let mut out = Vec::new();
        for k in 0..6 {
            let r = 3.0 + 10.0 * rnd();
            let w = if k % 2 == 0 {
                0.01 + 0.3 * rnd()
            } else {
                0.5 + 3.0 * rnd()
            };
            let n = 48 + (600.0 * rnd()) as usize;
            let off = if k < 3 { 0.0 } else { 0.3 * w * rnd() };
            out.push(vec![
                ngon(0.0, 0.0, r + w, n, true),
                ngon(off, 0.0, r, n, false),
            ]);
        }
        out.push(vec![ellipse(12.0, 8.0, true), ellipse(11.8, 7.9, false)]);
        out.push(vec![
            ngon(0.0, 0.0, 20.0, 400, true),
            ngon(0.0, 0.0, 8.2, 300, false),
            ngon(0.0, 0.0, 8.0, 300, true),
        ]);
        // A thin ring with discs beside it, in its hole and out of it: third walls.
        // (The discs' edges come first: a stray edge is looked for from the last ones.)
        let mut islands: Vec<Contour> = (0..6)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 6.0;
                let r = if k % 2 == 0 { 11.0 } else { 9.1 };
                ngon(r * a.cos(), r * a.sin(), 0.4, 120, true)
            })
            .collect();
        islands.push(ngon(0.0, 0.0, 10.1, 720, true));
        islands.push(ngon(0.0, 0.0, 10.0, 720, false));
        out.push(islands);
        out.push(vec![ngon(1.0, -2.0, 6.0, 300, true)]);
        out
    }

    #[test]
    fn ring_cover_never_hides_a_deep_point() {
        // Whenever the two walls drop a cell (its centre inside the section or not, the
        // cell larger than the radius asked or not), no point of it is deeper than the
        // radius asked by more than the check's tolerance; and they do drop cells.
        let mut rnd = xorshift(0x0052_1ac0_fe55);
        let (mut tried, mut dropped) = (0, 0);
        for section in ring_sections(&mut rnd) {
            let e = Edges::new(&section);
            let mut cache = ArcCache::default();
            for _ in 0..150 {
                // Cells around a random boundary point, up to 3 mm from it.
                let i = (rnd() * e.segs.len() as f64) as usize % e.segs.len();
                let q = e.vert(i as u32);
                let c = [q[0] + 4.0 * rnd() - 2.0, q[1] + 4.0 * rnd() - 2.0];
                let h = 0.05 + 3.0 * rnd();
                // About the cell's largest depth, a little below or above.
                let m = cell_max(&e, (c, h), 0.004);
                let t = m - 0.02 + 0.06 * rnd();
                if t <= 0.0 {
                    continue;
                }
                if rnd() < 0.2 {
                    cache.clear();
                }
                tried += 1;
                let near = e.nearest(c, u32::MAX).1;
                if !e.ring_cover(c, h, t, near, &mut cache) {
                    continue;
                }
                dropped += 1;
                let found = cell_max(&e, (c, h), 0.004);
                assert!(
                    found <= t + 1e-9,
                    "cell {c:?} ± {h} dropped at radius {t}, but a point is {found} deep"
                );
            }
        }
        assert!(dropped * 6 > tried, "{dropped} of {tried} dropped");
    }

    #[test]
    fn ring_cover_drops_cells_across_a_thin_ring_and_no_deeper() {
        // A ring between circles of radius 10 and 10.1 (depth 0.05 at most): cells larger
        // than the ring, straddling it, centres inside and outside the section.
        let ring = vec![
            ngon(0.0, 0.0, 10.1, 720, true),
            ngon(0.0, 0.0, 10.0, 720, false),
        ];
        let e = Edges::new(&ring);
        let mut cache = ArcCache::default();
        for (c, h) in [([10.05, 0.0], 1.0), ([0.3, -9.5], 1.5), ([7.0, 7.3], 0.5)] {
            let near = e.nearest(c, u32::MAX).1;
            assert!(e.ring_cover(c, h, 0.051, near, &mut cache), "{c:?}");
            assert!(!e.ring_cover(c, h, 0.045, near, &mut cache), "{c:?}");
        }
        // The same walls around a gap (the section is the disc inside and the part
        // outside): the parts beside the gap are deep.
        let gap = vec![
            ngon(0.0, 0.0, 30.0, 720, true),
            ngon(0.0, 0.0, 10.1, 720, false),
            ngon(0.0, 0.0, 10.0, 720, true),
        ];
        let g = Edges::new(&gap);
        let c = [10.05, 0.0];
        let near = g.nearest(c, u32::MAX).1;
        assert!(!g.ring_cover(c, 1.0, 0.5, near, &mut ArcCache::default()));
    }

    #[test]
    fn arcs_cover_drops_cells_of_a_ring_and_no_deeper() {
        // A ring between circles of radius 10 and 14 (depth 2 at most; the polygons'
        // edges make it a little less): a cell on its middle circle, larger than the
        // discs around wall points cover, and a cell across its inner wall.
        let ring = vec![
            ngon(0.0, 0.0, 14.0, 720, true),
            ngon(0.0, 0.0, 10.0, 720, false),
        ];
        let e = Edges::new(&ring);
        let hints = |c: [f64; 2]| {
            let near = e.nearest(c, u32::MAX).1;
            let q = e.closest_point(near, c);
            [
                near,
                e.nearest([2.0 * c[0] - q[0], 2.0 * c[1] - q[1]], u32::MAX)
                    .1,
            ]
        };
        let mut cache = ArcCache::default();
        for c in [[12.0, 0.3], [0.5, -12.0], [8.4, 8.6]] {
            assert!(e.arcs_cover(c, 0.9, 2.001, hints(c), &mut cache), "{c:?}");
            assert!(!e.arcs_cover(c, 0.9, 1.99, hints(c), &mut cache), "{c:?}");
        }
        // Across the inner wall (part of it in the hole).
        let c = [10.2, 0.1];
        assert!(e.arcs_cover(c, 0.6, 2.001, hints(c), &mut cache));
        // Wholly inside a disc, nearer its middle than its radius: deeper than asked.
        let disc = vec![ngon(0.0, 0.0, 10.0, 400, true)];
        let d = Edges::new(&disc);
        let c = [3.0, 0.0];
        let near = d.nearest(c, u32::MAX).1;
        assert!(!d.arcs_cover(c, 1.0, 7.5, [near, u32::MAX], &mut ArcCache::default()));
        assert!(d.arcs_cover(c, 1.0, 8.01, [near, u32::MAX], &mut ArcCache::default()));
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
            let mut c: Contour = (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    let r = 5.0 + noise * (rnd() - 0.5);
                    [r * a.cos(), r * a.sin()]
                })
                .collect();
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
