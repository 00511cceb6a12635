//! The best-first search for the largest inscribed circle of a section (its steps are
//! those of [`max_fill_distance_with`](super::max_fill_distance_with)) and the final
//! polish of the best centre. The thresholds below decide only how much work a search
//! does, never what it guarantees.

use super::arcs::ArcCache;
use super::cells::{Cell, Queue};
use super::edges::{seg_d2, Edges};
use super::plane::d2;
use super::points::{exceeds, witness, Witnesses, MAX_COVER_POINTS, MAX_EXTRA_COVER_POINTS};
use super::SearchScratch;

/// Most generations in a row of cells split with the walls followed from their parent's,
/// without a search (the followed walls may miss a nearer third wall).
const MAX_FOLLOWED_GENERATIONS: u8 = 3;

/// How far along its walls a cell's cover points stand (at least) from the walls' points
/// nearest to its centre, in cell half-sizes.
const WALL_POINT_SPACING: f64 = 0.6;

/// Cells whose failed cover test is completed by [`Search::cover_more`]:
/// `(h·√2)² ≤ COVER_MORE_MAX_SIZE · T · precision`; larger ones are split at once.
const COVER_MORE_MAX_SIZE: f64 = 32.0;

/// After its first `SEED_AFTER_CELLS` cells with no centre inside the section (a thin
/// section, whose cells would all be split), a search takes the best of
/// [`Edges::ridge_probe`] on [`SEED_PROBES`] edges spread over the contours as the depth
/// to beat.
const SEED_AFTER_CELLS: usize = 4;

/// Edges whose inward normals seed a search: see [`SEED_AFTER_CELLS`].
const SEED_PROBES: usize = 2;

/// Cells tried by [`Edges::walls_cover`]: half-size above this many times the depth to
/// beat (smaller ones are covered by discs around wall points as cheaply) and at most
/// [`WALLS_MAX_HALF_SIZE_MM`] (walls curve too much over larger cells to be lines).
const WALLS_MIN_HALF_SIZE: f64 = 1.5;

/// See [`WALLS_MIN_HALF_SIZE`], mm.
const WALLS_MAX_HALF_SIZE_MM: f64 = 1.0;

/// Cells tried by [`Edges::arcs_cover`] (below the depth to beat) and
/// [`Edges::ring_cover`] (above it, or centre outside): half-size at least this many times
/// the precision.
const ARCS_MIN_HALF_SIZE: f64 = 8.0;

/// A search tries [`Edges::arcs_cover`] and [`Edges::ring_cover`] on its first
/// `COVER_TRIAL_TRIES` cells, then only while at least one try in [`COVER_TRIES_PER_HIT`]
/// drops its cell (on walls that are not round a failed try costs about a cell's tests).
const COVER_TRIAL_TRIES: usize = 2;

/// See [`COVER_TRIAL_TRIES`].
const COVER_TRIES_PER_HIT: usize = 4;

/// [`Edges::ring_cover`] is also tried on every `RING_PROBE_EVERY`-th cell it could be
/// tried on once its tries have stopped paying (one failed start would stop them for the
/// whole search).
const RING_PROBE_EVERY: usize = 8;

/// The deepest point found so far: its depth (signed distance to the boundary) and its
/// nearest edge.
#[derive(Debug, Clone, Copy)]
struct Best {
    centre: [f64; 2],
    depth: f64,
    near: u32,
}

/// The boundary points a cell is tested against: the first `n` are its walls' points
/// (kept for its children); a cover test completed by [`Search::cover_more`] writes its
/// points after them.
#[derive(Clone, Copy)]
struct CoverPoints {
    p: [[f64; 2]; MAX_COVER_POINTS],
    n: usize,
}

impl CoverPoints {
    fn new() -> CoverPoints {
        CoverPoints {
            p: [[0.0; 2]; MAX_COVER_POINTS],
            n: 0,
        }
    }

    #[inline]
    fn push(&mut self, x: [f64; 2]) {
        self.p[self.n] = x;
        self.n += 1;
    }

    /// The walls' points.
    #[inline]
    fn kept(&self) -> &[[f64; 2]] {
        &self.p[..self.n]
    }
}

/// What the tests of a cell that was not dropped leave for its covers and its split.
struct Tested {
    /// The walls' points (none when the centre is not inside the section).
    pts: CoverPoints,
    /// The children's Lipschitz bound: the centre's depth (or the walls' distance) plus
    /// `h·√2`.
    lip: f64,
    /// The nearest edge and the far wall's edge (`u32::MAX`: none).
    near: u32,
    far_edge: u32,
    /// Whether the cell is split with its parent's walls followed, without a search.
    followed: bool,
}

/// Where the search of a centre's exact depth starts (step 3).
struct CentreStart {
    /// The nearer of the parent's walls followed to the centre: `(squared distance,
    /// edge)`, or `(∞, u32::MAX)`.
    start: (f64, u32),
    /// The far wall's edge followed to the centre (`u32::MAX`: none), where the search of
    /// the boundary point behind the centre starts.
    far_seed: u32,
    /// The centre's inside test, when made.
    inside: Option<bool>,
}

/// What the parent's walls showed about a cell (step 2).
enum FromWalls {
    /// The cell holds no point deeper than `T`.
    Dropped,
    /// The cell is split with the walls' points, without a search.
    Split(Tested),
    /// The centre's depth must be searched.
    Search(CentreStart),
}

/// How often a cover that only sometimes drops a cell (the arc and the ring cover) has
/// been tried in a search, and how often it dropped the cell.
#[derive(Debug, Default, Clone, Copy)]
struct CoverTries {
    tries: usize,
    hits: usize,
}

impl CoverTries {
    /// Whether it still pays: on the first [`COVER_TRIAL_TRIES`] tries, then while at least one try
    /// in [`COVER_TRIES_PER_HIT`] has dropped its cell.
    #[inline]
    fn pay(&self) -> bool {
        self.tries < COVER_TRIAL_TRIES || self.hits * COVER_TRIES_PER_HIT >= self.tries
    }
}

/// The state of one search: the best centre, the queue of cells and the buffers.
struct Search<'a> {
    e: &'a Edges,
    precision: f64,
    best: Best,
    queue: &'a mut Queue,
    /// Boundary points of split cells, for their children (`Cell::pts` indexes it).
    arena: &'a mut Vec<([[f64; 2]; 6], u8)>,
    arcs: &'a mut ArcCache,
    arc_tries: CoverTries,
    ring_tries: CoverTries,
    /// Cells the ring cover could have been tried on.
    ring_seen: usize,
    /// Cells popped.
    pops: usize,
}

/// [`max_fill_distance_with`](super::max_fill_distance_with) with buffers `sc`.
pub(super) fn search(e: &Edges, precision: f64, sc: &mut SearchScratch) -> (f64, [f64; 2]) {
    let Some((lo, hi)) = e.bounds() else {
        return (0.0, [0.0, 0.0]);
    };
    let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
    let size = w.min(h);
    if size.is_nan() || size <= 0.0 {
        return (0.0, [0.0, 0.0]);
    }
    sc.arcs.clear();
    sc.queue.clear();
    sc.arena.clear();
    let mut s = Search {
        e,
        precision,
        best: Best {
            centre: [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
            depth: f64::NEG_INFINITY,
            near: u32::MAX,
        },
        queue: &mut sc.queue,
        arena: &mut sc.arena,
        arcs: &mut sc.arcs,
        arc_tries: CoverTries::default(),
        ring_tries: CoverTries::default(),
        ring_seen: 0,
        pops: 0,
    };
    s.queue_grid(lo, (w, h), size);
    s.run(size);
    let best = s.best;
    if best.depth <= 0.0 {
        return (0.0, best.centre);
    }
    let (c, d) = polish(e, (best.centre, best.depth, best.near), precision);
    (d, c)
}

/// Distance from `q` to the corner of the square `[c ± h]` farthest from it: with `q` a
/// boundary point, a bound of the depth of every point of the square.
#[inline]
fn far_corner(c: [f64; 2], h: f64, q: [f64; 2]) -> f64 {
    let (dx, dy) = ((c[0] - q[0]).abs() + h, (c[1] - q[1]).abs() + h);
    (dx * dx + dy * dy).sqrt()
}

impl Search<'_> {
    /// Keeps `centre` (at `depth`, nearest edge `near`) as the best when it is deeper.
    #[inline]
    fn raise(&mut self, centre: [f64; 2], depth: f64, near: u32) {
        if depth > self.best.depth {
            self.best = Best {
                centre,
                depth,
                near,
            };
        }
    }

    /// Queues the square cells of side `size` (the box's smaller side) that cover the box
    /// from `lo` of width `w` and height `h`.
    fn queue_grid(&mut self, lo: [f64; 2], (w, h): (f64, f64), size: f64) {
        let half = size / 2.0;
        let nx = (w / size).ceil() as usize;
        let ny = (h / size).ceil() as usize;
        for i in 0..nx {
            for j in 0..ny {
                let c = [
                    lo[0] + (i as f64 + 0.5) * size,
                    lo[1] + (j as f64 + 0.5) * size,
                ];
                self.queue.push(Cell {
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
    }

    /// Pops cells, largest bound first, until no cell left can beat the best depth by more
    /// than the precision (the steps of
    /// [`max_fill_distance_with`](super::max_fill_distance_with)).
    fn run(&mut self, size: f64) {
        while let Some(c) = self.queue.pop() {
            if self.pops == SEED_AFTER_CELLS && self.best.depth <= 0.0 {
                self.seed(size);
            }
            self.pops += 1;
            if c.max - self.best.depth <= self.precision {
                // The queue is ordered by the bound: no remaining cell can do better.
                break;
            }
            if self.parent_points_cover(&c) {
                continue;
            }
            // Points of the cell that its cover test found uncovered.
            let mut wit = Witnesses::default();
            let Some(tested) = self.test(&c, &mut wit) else {
                continue;
            };
            if self.walls_cover(&c, &tested)
                || self.arcs_cover(&c, &tested)
                || self.ring_cover(&c, &tested)
            {
                continue;
            }
            self.split(&c, &tested, &wit);
        }
    }

    /// No centre inside the section yet (a thin section: a ring's first layers): a few
    /// points on its walls' inward normals give the depth to beat (`size`: the largest
    /// step along a normal).
    fn seed(&mut self, size: f64) {
        let e = self.e;
        for k in 0..SEED_PROBES {
            let v = (k * e.segs.len() / SEED_PROBES) as u32;
            if let Some((p, d, near)) = e.ridge_probe(v, self.precision, size) {
                self.raise(p, d, near);
            }
        }
    }

    /// Step 1: whether the parent's boundary points still cover the cell at radius `T`
    /// (tried only when the best depth has grown since the cell was queued: they did not
    /// cover it then).
    #[inline]
    fn parent_points_cover(&self, c: &Cell) -> bool {
        let t = self.best.depth + self.precision;
        if c.pts != u32::MAX && t > 0.0 && self.best.depth > c.best {
            let (p, n) = &self.arena[c.pts as usize];
            return !exceeds(c.c, c.h, &p[..*n as usize], t * t).0;
        }
        false
    }

    /// Steps 2 to 4: the parent's walls, then the centre's exact depth and the cell's
    /// wall points; `None` when the cell is dropped. The uncovered points found go to
    /// `wit`.
    #[inline]
    fn test(&mut self, c: &Cell, wit: &mut Witnesses) -> Option<Tested> {
        let reach = c.h * std::f64::consts::SQRT_2;
        let mut from = CentreStart {
            start: (f64::INFINITY, u32::MAX),
            far_seed: u32::MAX,
            inside: None,
        };
        if c.hint != u32::MAX {
            match self.follow_parent_walls(c, reach, wit) {
                FromWalls::Dropped => return None,
                FromWalls::Split(tested) => return Some(tested),
                FromWalls::Search(f) => from = f,
            }
        }
        self.test_centre(c, reach, from, wit)
    }

    /// Step 2: the parent's nearest and far-wall edges, each followed along its contour to
    /// the points nearest this centre, bound the centre's depth from above; when the
    /// centre cannot beat the best, the walls' points may drop the cell, or split it
    /// without a search. `reach`: the cell's half-diagonal.
    #[inline]
    fn follow_parent_walls(&mut self, c: &Cell, reach: f64, wit: &mut Witnesses) -> FromWalls {
        let e = self.e;
        let t = self.best.depth + self.precision;
        let w1 = e.descend(c.hint, c.c);
        let mut start = w1;
        let w2 = (c.hint2 != u32::MAX).then(|| e.descend(c.hint2, c.c));
        let far_seed = w2.map_or(u32::MAX, |w| w.1);
        if let Some(w2) = w2 {
            if w2.0 < start.0 {
                start = w2;
            }
        }
        let u = start.0.sqrt();
        if u + reach - self.best.depth <= self.precision {
            return FromWalls::Dropped;
        }
        // A centre outside the section has a negative depth, so no point of the cell is
        // deeper than `h·√2`; nor can the walls' points cover such a cell.
        let inside = e.inside(c.c);
        if !inside && reach <= t {
            return FromWalls::Dropped;
        }
        // The centre cannot beat the best: try to drop the cell with these walls alone.
        if inside && u <= self.best.depth && t > 0.0 && w2.is_some() {
            let mut pts = CoverPoints::new();
            for (_, i) in std::iter::once(w1).chain(w2) {
                let q = e.closest_point(i, c.c);
                let [a, b] = e.along(i, q, WALL_POINT_SPACING * c.h);
                pts.push(q);
                pts.push(a);
                pts.push(b);
            }
            if self.covered((c.c, c.h), &mut pts, [w1.1, far_seed], wit) {
                return FromWalls::Dropped;
            }
            // Not covered: split it with these walls (no search: the centre cannot beat
            // the best), unless they have been followed for too long.
            if c.followed < MAX_FOLLOWED_GENERATIONS {
                return FromWalls::Split(Tested {
                    pts,
                    lip: u + reach,
                    near: w1.1,
                    far_edge: far_seed,
                    followed: true,
                });
            }
        }
        FromWalls::Search(CentreStart {
            start,
            far_seed,
            inside: Some(inside),
        })
    }

    /// Steps 3 and 4: the centre's exact signed distance (it may become the best) and,
    /// inside the section, the cover test of the cell by its walls' points, then a ridge
    /// probe. `None` when the cell is dropped.
    #[inline]
    fn test_centre(
        &mut self,
        c: &Cell,
        reach: f64,
        from: CentreStart,
        wit: &mut Witnesses,
    ) -> Option<Tested> {
        let e = self.e;
        let (d, near) = e.nearest_from(c.c, from.start);
        let d = if from.inside.unwrap_or_else(|| e.inside(c.c)) {
            d
        } else {
            -d
        };
        self.raise(c.c, d, near);
        let lip = d + reach;
        if lip - self.best.depth <= self.precision {
            return None;
        }
        let mut pts = CoverPoints::new();
        let mut far_edge = u32::MAX;
        if d > 0.0 {
            let q = e.closest_point(near, c.c);
            let behind = self.wall_points(c, (q, near), from.far_seed, reach, &mut pts);
            if let Some((_, i2)) = behind {
                far_edge = i2;
            }
            // The children are tested against the walls' points only (more points make
            // every test dearer than the few children they drop).
            wit.clear();
            if self.covered((c.c, c.h), &mut pts, [near, far_edge], wit) {
                return None;
            }
            if let Some(behind) = behind {
                self.probe_ridge(c, d, q, near, behind);
            }
        }
        Some(Tested {
            pts,
            lip,
            near,
            far_edge,
            followed: false,
        })
    }

    /// Step 4's boundary points, into `pts`: the nearest one `q` (on edge `near`), the
    /// nearest one behind the centre (the other wall of a ridge; its search starts from
    /// edge `far_seed`) and, on the contours of both, the points about
    /// `WALL_POINT_SPACING·h` away on either side. Returns the point behind the centre and
    /// its edge.
    #[inline]
    fn wall_points(
        &self,
        c: &Cell,
        (q, near): ([f64; 2], u32),
        far_seed: u32,
        reach: f64,
        pts: &mut CoverPoints,
    ) -> Option<([f64; 2], u32)> {
        let e = self.e;
        pts.push(q);
        for p in e.along(near, q, WALL_POINT_SPACING * c.h) {
            pts.push(p);
        }
        // Wall points farther than this can neither cover the cell at radius `T` nor bound
        // a child's depth below `lip`.
        let limit = self.best.depth + self.precision + 1.5 * reach;
        let behind = e.nearest_behind(c.c, q, limit, far_seed);
        if let Some((q2, i2)) = behind {
            pts.push(q2);
            for p in e.along(i2, q2, WALL_POINT_SPACING * c.h) {
                pts.push(p);
            }
        }
        behind
    }

    /// Ridge probe: the point half-way between the two walls on the line through the
    /// centre and `q` (its nearest boundary point, on edge `near`, `d` away), the deepest
    /// point nearby for parallel walls, raises the best so ridge cells can be pruned.
    /// `(q2, i2)`: the boundary point behind the centre and its edge.
    #[inline]
    fn probe_ridge(&mut self, c: &Cell, d: f64, q: [f64; 2], near: u32, (q2, i2): ([f64; 2], u32)) {
        let e = self.e;
        let t = 0.5 * (d2(q2, c.c).sqrt() - d);
        if t > 0.25 * self.precision {
            let u = [(c.c[0] - q[0]) / d, (c.c[1] - q[1]) / d];
            let p = [c.c[0] + t * u[0], c.c[1] + t * u[1]];
            // Both walls bound the probe's depth: search only if it can gain.
            let mut start = (seg_d2(p, &e.segs[near as usize]), near);
            let u2 = seg_d2(p, &e.segs[i2 as usize]);
            if u2 < start.0 {
                start = (u2, i2);
            }
            if self.best.depth < 0.0 || start.0 > self.best.depth * self.best.depth {
                let (dp, np) = e.nearest_from(p, start);
                if dp > self.best.depth && e.inside(p) {
                    self.raise(p, dp, np);
                }
            }
        }
    }

    /// Whether discs of radius `T` = best depth + precision around the boundary points
    /// `pts` cover the square `sq` = `(centre, half-size)`; a square small enough (`(h·√2)²
    /// ≤ COVER_MORE_MAX_SIZE · T · precision`) that they do not cover is completed with
    /// [`Search::cover_more`] (which may raise the best and writes points after `pts`'
    /// own). The uncovered points found go to `wit`.
    fn covered(
        &mut self,
        sq: ([f64; 2], f64),
        pts: &mut CoverPoints,
        walls: [u32; 2],
        wit: &mut Witnesses,
    ) -> bool {
        let precision = self.precision;
        let t = self.best.depth + precision;
        let reach = sq.1 * std::f64::consts::SQRT_2;
        if reach * reach > COVER_MORE_MAX_SIZE * t * precision {
            // Too large to be completed: whether the points cover it is all that matters.
            let (exceed, w) = exceeds(sq.0, sq.1, pts.kept(), t * t);
            if let Some(w) = w {
                wit.push(w, t * t);
            }
            return !exceed;
        }
        let Some(x) = witness(sq.0, sq.1, pts.kept(), t * t) else {
            return true;
        };
        wit.push(x, t * t);
        self.cover_more(sq, pts, x, walls, wit)
    }

    /// Completes a cover test that failed at the uncovered point `x` of the square `sq` =
    /// `(centre, half-size)`: adds the boundary point nearest to `x` (found by following
    /// the cell's `walls` to `x`, searched only when that one is farther than `T`) after
    /// `pts`' own and tries again, at most [`MAX_EXTRA_COVER_POINTS`] times; returns whether
    /// the square is now covered at `T`. An `x` inside the section and deeper than `T`
    /// becomes the best centre. The uncovered points found go to `wit`.
    fn cover_more(
        &mut self,
        sq: ([f64; 2], f64),
        pts: &mut CoverPoints,
        mut x: [f64; 2],
        walls: [u32; 2],
        wit: &mut Witnesses,
    ) -> bool {
        let e = self.e;
        let mut n = pts.n;
        let stop = (n + MAX_EXTRA_COVER_POINTS).min(MAX_COVER_POINTS);
        while n < stop {
            let t = self.best.depth + self.precision;
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
                    self.raise(x, dx, ix);
                }
                return false;
            }
            pts.p[n] = e.closest_point(ix, x);
            n += 1;
            match witness(sq.0, sq.1, &pts.p[..n], t * t) {
                None => return true,
                Some(w) => {
                    x = w;
                    wit.push(w, t * t);
                }
            }
        }
        false
    }

    /// Step 5: whether the cell lies across thin walls that show it shallow.
    #[inline]
    fn walls_cover(&self, c: &Cell, tested: &Tested) -> bool {
        let t = self.best.depth + self.precision;
        c.h > WALLS_MIN_HALF_SIZE * t
            && c.h <= WALLS_MAX_HALF_SIZE_MM
            && self
                .e
                .walls_cover(c.c, c.h, t, [tested.near, tested.far_edge])
    }

    /// Step 6: whether the cell lies between curved walls that show it shallow (tried
    /// while it pays).
    #[inline]
    fn arcs_cover(&mut self, c: &Cell, tested: &Tested) -> bool {
        let t = self.best.depth + self.precision;
        if tested.pts.n > 0
            && c.h >= ARCS_MIN_HALF_SIZE * self.precision
            && c.h < t
            && self.arc_tries.pay()
        {
            self.arc_tries.tries += 1;
            let walls = [tested.near, tested.far_edge];
            if self.e.arcs_cover(c.c, c.h, t, walls, self.arcs) {
                self.arc_tries.hits += 1;
                return true;
            }
        }
        false
    }

    /// Step 7: whether the cell (its centre outside the section, or the cell larger than
    /// the depth to beat) straddles a ring whose two walls show it shallow (tried while it
    /// pays, and on every [`RING_PROBE_EVERY`]-th cell).
    #[inline]
    fn ring_cover(&mut self, c: &Cell, tested: &Tested) -> bool {
        let t = self.best.depth + self.precision;
        if c.h >= ARCS_MIN_HALF_SIZE * self.precision && (c.h >= t || tested.pts.n == 0) {
            self.ring_seen += 1;
            if self.ring_tries.pay() || self.ring_seen.is_multiple_of(RING_PROBE_EVERY) {
                self.ring_tries.tries += 1;
                if self.e.ring_cover(c.c, c.h, t, tested.near, self.arcs) {
                    self.ring_tries.hits += 1;
                    return true;
                }
            }
        }
        false
    }

    /// Step 8: the four children not covered by the cell's wall points are queued, with
    /// the cell's Lipschitz bound (or the far-corner distance to the nearest point or the
    /// far-wall point, if smaller) as their key; a child holding a point the cell's own
    /// test found uncovered (`wit`) is queued without a test.
    #[inline]
    fn split(&mut self, c: &Cell, tested: &Tested, wit: &Witnesses) {
        let t = self.best.depth + self.precision;
        let (pts, n) = (&tested.pts.p, tested.pts.n);
        let qh = c.h / 2.0;
        let idx = if n > 0 {
            let mut kept = [[0.0; 2]; 6];
            kept.copy_from_slice(&pts[..6]);
            self.arena.push((kept, n as u8));
            (self.arena.len() - 1) as u32
        } else {
            u32::MAX
        };
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let cc = [c.c[0] + sx * qh, c.c[1] + sy * qh];
            let mut cmax = tested.lip;
            if n > 0 {
                // A child holding an uncovered point of the cell's test is not covered
                // by the same points.
                if !wit.uncover(cc, qh, &pts[..n], t * t) && !exceeds(cc, qh, &pts[..n], t * t).0 {
                    continue;
                }
                cmax = cmax.min(far_corner(cc, qh, pts[0]));
                if n > 3 {
                    cmax = cmax.min(far_corner(cc, qh, pts[3]));
                }
            }
            if cmax - self.best.depth <= self.precision {
                continue;
            }
            self.queue.push(Cell {
                c: cc,
                h: qh,
                max: cmax,
                hint: tested.near,
                hint2: tested.far_edge,
                pts: idx,
                best: self.best.depth,
                followed: if tested.followed { c.followed + 1 } else { 0 },
            });
        }
    }
}

/// Local pattern search from `c` (depth `d`, nearest edge `near`): tries steps in 8
/// directions, keeps going in a direction while it gains (doubling the step), halves the
/// step when no direction gains, from `precision` down to `precision / 16`, for at most 64
/// trial points; moves only to deeper points, so the result stays a true inscribed radius.
fn polish(
    e: &Edges,
    (mut c, mut d, mut near): ([f64; 2], f64, u32),
    precision: f64,
) -> ([f64; 2], f64) {
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
    let (mut step, last_step, max_evals) = (precision, precision / 16.0, 64);
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
    (c, d)
}
