//! The max fill distance: the radius of the largest circle inside a section, found by a
//! best-first subdivision of its bounding box (see [`max_fill_distance_with`]).

use super::PRECISION_MM;
use crate::slice::Contour;

mod arcs;
mod cells;
mod coarsen;
mod edges;
mod plane;
mod points;
mod walls;

use arcs::{ArcCache, ARC_MIN_H, ARC_RATE, ARC_TRIAL, RING_PROBE};
use cells::{Cell, Queue};
use coarsen::coarsen_section;
pub use coarsen::COARSE_MM;
use edges::seg_d2;
pub use edges::Edges;
use plane::d2;
use points::{exceeds, points_exceed, witness, Witnesses, EXTRA, MAX_PTS};
use walls::{SLAB_MAX_H_MM, SLAB_MIN_H};

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

/// After its first `SEED_AFTER` cells with no centre inside the section, a search takes
/// the best of [`Edges::ridge_probe`] on `SEEDS` edges spread over the contours as the
/// depth to beat: a thin section (a ring's first layers) has few cells whose centre is
/// inside it, and until one is found every cell is split (logo_hires: search 584 → 511 M
/// instructions; seeding every search costs bunny00 +4 %).
const SEED_AFTER: usize = 4;

/// See [`SEED_AFTER`].
const SEEDS: usize = 2;

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
