//! The arc and ring covers: a cell between curved walls, or straddling a ring, is dropped
//! when its walls, seen from their centres of curvature as arcs within a thin band,
//! bound its depth.

use super::edges::Segment;
use super::plane::{corners, cross, d2, unit};
use super::walls::MAX_CROSSING_EDGES;
use super::Edges;

/// Most contour points an [`Arc`] is followed each way from its edge to cover the
/// square's projection on that edge's line (and three times as many to reach the rays of
/// the square's corners).
const ARC_MAX_WALK: usize = 64;

/// Radius of the circle a straight wall is seen on, mm (far enough that a wall a few
/// millimetres long stands less than a micrometre off it, near enough that distances to
/// its centre keep about 1e-10 mm of rounding).
const STRAIGHT_WALL_RADIUS_MM: f64 = 1e6;

/// Widening of an [`Arc`]'s band for the rounding of the distances to its centre, mm.
const ARC_BAND_MARGIN_MM: f64 = 1e-9;

/// Arcs kept by a search for the following cells ([`ArcCache`]).
const ARC_CACHE_SIZE: usize = 8;

/// A stretch of a contour, the points `back` to `fwd` (consecutive indexes), seen from a
/// centre `o`: all of it lies at distances in `[lo, hi]` from `o` and in the open
/// half-plane `{y : w·(y − o) > 0}`. The ray from `o` through any point `x` between its
/// ends' rays meets it, which bounds the depth of `x` by `ρ(x) − lo` beyond the band (`ρ`
/// the distance to `o`), `hi − ρ(x)` before it, `hi − lo` in it (docs/PLANNING.md, "Wall
/// covers"). A curved wall is seen from its centre of curvature, so the band is thin
/// however long the stretch; a straight wall from [`STRAIGHT_WALL_RADIUS_MM`] away.
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
pub(super) struct ArcCache {
    arcs: [Option<Arc>; ARC_CACHE_SIZE],
    next: usize,
}

impl ArcCache {
    pub(super) fn clear(&mut self) {
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
        self.next = (self.next + 1) % ARC_CACHE_SIZE;
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
/// (`beyond`: the side away from its centre, `ρ − lo`, largest at a corner; else `hi − ρ`,
/// largest at the square's point nearest `o`, `near` away), and of the mean of it and
/// `b`'s (`b` wholly on side `b_beyond`): with `ρ_A − ρ_B ≤ |o_A − o_B|` and `ρ ≥ w·(x − o)`
/// the mean is a constant or a convex function; between a ring's walls, its half-width.
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

/// A stretch of a contour being followed each way from an edge: its first and last
/// points (edge `v` runs from point `v` to the next), the steps taken each way, and where
/// the contour's indexes wrap around when they do.
#[derive(Debug, Clone, Copy)]
struct Walk {
    back: u32,
    fwd: u32,
    steps_back: usize,
    steps_fwd: usize,
    wrap: Option<(u32, u32)>,
}

impl Walk {
    /// Edge `v` alone.
    fn new(e: &Edges, v: u32) -> Walk {
        let fwd = e.next[v as usize];
        Walk {
            back: v,
            fwd,
            steps_back: 0,
            steps_fwd: 0,
            wrap: (fwd < v).then_some((fwd, v)),
        }
    }

    /// One point further back.
    #[inline]
    fn step_back(&mut self, e: &Edges) {
        let p = e.prev[self.back as usize];
        if p > self.back {
            self.wrap = Some((self.back, p));
        }
        self.back = p;
        self.steps_back += 1;
    }

    /// One point further forward.
    #[inline]
    fn step_fwd(&mut self, e: &Edges) {
        let n = e.next[self.fwd as usize];
        if n < self.fwd {
            self.wrap = Some((n, self.fwd));
        }
        self.fwd = n;
        self.steps_fwd += 1;
    }
}

/// The distances from an arc's centre `o` over the edges of its stretch (squared: the
/// smallest to an edge's line, the largest to an edge's start), and its half-plane
/// `{y : w·(y − o) > 0}`.
#[derive(Debug, Clone, Copy)]
struct Band {
    o: [f64; 2],
    w: [f64; 2],
    lo2: f64,
    hi2: f64,
}

impl Band {
    /// `x` relative to the centre.
    #[inline]
    fn rel(&self, x: [f64; 2]) -> [f64; 2] {
        [x[0] - self.o[0], x[1] - self.o[1]]
    }

    /// Whether `y` (relative to the centre) lies in the half-plane.
    #[inline]
    fn faces(&self, y: [f64; 2]) -> bool {
        self.w[0] * y[0] + self.w[1] * y[1] > 0.0
    }

    /// Widens the band over edge `s`; `false` when its start is not in the half-plane.
    #[inline]
    fn add(&mut self, s: &Segment) -> bool {
        let (p, q) = (self.rel([s[0], s[1]]), self.rel([s[2], s[3]]));
        if !self.faces(p) {
            return false;
        }
        self.hi2 = self.hi2.max(p[0] * p[0] + p[1] * p[1]);
        // The distance to the edge's line: at most the distance to the edge.
        let e = [q[0] - p[0], q[1] - p[1]];
        let cr = cross(p, q);
        self.lo2 = self.lo2.min(cr * cr / (e[0] * e[0] + e[1] * e[1]));
        true
    }
}

/// The centre an arc through `p0`, `p1` and `p2` is seen from: the centre of their circle,
/// or, when that circle is larger than [`STRAIGHT_WALL_RADIUS_MM`] (or there is none), a
/// point [`STRAIGHT_WALL_RADIUS_MM`] away from the middle of `p0`–`p2` on the side away
/// from `c`. `None` when `p0` and `p2` coincide.
fn arc_centre([p0, p1, p2]: [[f64; 2]; 3], c: [f64; 2]) -> Option<[f64; 2]> {
    // The circle through the three points, relative to p0.
    let (b, d) = (
        [p1[0] - p0[0], p1[1] - p0[1]],
        [p2[0] - p0[0], p2[1] - p0[1]],
    );
    let den = 2.0 * cross(b, d);
    let (bb, dd) = (b[0] * b[0] + b[1] * b[1], d[0] * d[0] + d[1] * d[1]);
    let oc = [(d[1] * bb - b[1] * dd) / den, (b[0] * dd - d[0] * bb) / den];
    if oc[0].is_finite()
        && oc[1].is_finite()
        && oc[0] * oc[0] + oc[1] * oc[1] <= STRAIGHT_WALL_RADIUS_MM * STRAIGHT_WALL_RADIUS_MM
    {
        return Some([p0[0] + oc[0], p0[1] + oc[1]]);
    }
    // Straight: seen from far away on the side away from the square.
    let m = [0.5 * (p0[0] + p2[0]), 0.5 * (p0[1] + p2[1])];
    let t = unit(d)?;
    let mut n = [-t[1], t[0]];
    if n[0] * (c[0] - m[0]) + n[1] * (c[1] - m[1]) > 0.0 {
        n = [-n[0], -n[1]];
    }
    Some([
        m[0] + STRAIGHT_WALL_RADIUS_MM * n[0],
        m[1] + STRAIGHT_WALL_RADIUS_MM * n[1],
    ])
}

/// The corners `rc` (relative to an arc's centre) first and last in the way `sigma` the
/// arc turns around it.
fn extreme_corners(rc: &[[f64; 2]; 4], sigma: f64) -> ([f64; 2], [f64; 2]) {
    let (mut x0, mut x1) = (rc[0], rc[0]);
    for &y in &rc[1..] {
        if sigma * cross(y, x0) > 0.0 {
            x0 = y;
        }
        if sigma * cross(x1, y) > 0.0 {
            x1 = y;
        }
    }
    (x0, x1)
}

impl Edges {
    /// An [`Arc`] through edge `v` for the square `[c ± h]`: the stretch is first followed
    /// each way until its points' projections on `v`'s line cover the square's corners';
    /// its centre `o` is the circle through its ends and `v`'s start (or a point
    /// [`STRAIGHT_WALL_RADIUS_MM`] away, on the far side from the square, when that circle
    /// is larger); its half-plane faces the square's centre. It is followed further until
    /// its ends' rays hold the square's corners between them. `None` when the stretch
    /// cannot be followed far enough, leaves the half-plane or runs over the end of its
    /// contour's points (its indexes must be consecutive).
    fn arc(&self, v: u32, c: [f64; 2], h: f64) -> Option<Arc> {
        let cs = corners(c, h);
        let mut walk = self.walk_across(v, &cs)?;
        let (p0, p2) = (self.vert(walk.back), self.vert(walk.fwd));
        let o = arc_centre([p0, self.vert(v), p2], c)?;
        let mut band = Band {
            o,
            w: [0.0; 2],
            lo2: f64::INFINITY,
            hi2: 0.0,
        };
        // The half-plane: the corners must be in it too.
        band.w = band.rel(c);
        let rc = cs.map(|x| band.rel(x));
        if !rc.iter().all(|y| band.faces(*y)) {
            return None;
        }
        // The way the stretch turns around `o` from `back` to `fwd`, and the corners
        // first and last that way.
        let sigma = cross(band.rel(p0), band.rel(p2)).signum();
        if sigma == 0.0 || sigma.is_nan() {
            return None;
        }
        let rays = extreme_corners(&rc, sigma);
        // The band over every edge from `back` to `fwd`, following the stretch further
        // while its ends' rays do not hold the corners.
        let mut k = walk.back;
        while k != walk.fwd {
            if !band.add(&self.segs[k as usize]) {
                return None;
            }
            k = self.next[k as usize];
        }
        self.walk_to_rays(&mut walk, &mut band, sigma, rays)?;
        let (rb, rf) = (
            band.rel(self.vert(walk.back)),
            band.rel(self.vert(walk.fwd)),
        );
        if !band.faces(rf) {
            return None;
        }
        band.hi2 = band.hi2.max(rf[0] * rf[0] + rf[1] * rf[1]);
        Some(Arc {
            o,
            lo: band.lo2.sqrt() - ARC_BAND_MARGIN_MM,
            hi: band.hi2.sqrt() + ARC_BAND_MARGIN_MM,
            w: band.w,
            back: walk.back,
            fwd: walk.fwd,
            wrap: walk.wrap,
            rb,
            rf,
            sigma,
        })
    }

    /// The stretch through edge `v` followed each way until its points' projections on
    /// `v`'s line cover those of the corners `cs`; `None` when that takes more than
    /// [`ARC_MAX_WALK`] points either way or the stretch closes on itself.
    fn walk_across(&self, v: u32, cs: &[[f64; 2]; 4]) -> Option<Walk> {
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
        let mut walk = Walk::new(self, v);
        while proj(self.vert(walk.back)) > q_lo {
            walk.step_back(self);
            if walk.steps_back > ARC_MAX_WALK || walk.back == walk.fwd {
                return None;
            }
        }
        while proj(self.vert(walk.fwd)) < q_hi {
            walk.step_fwd(self);
            if walk.steps_fwd > ARC_MAX_WALK || walk.fwd == walk.back {
                return None;
            }
        }
        Some(walk)
    }

    /// Follows `walk` further each way, widening `band` over the edges it adds, until the
    /// rays from the arc's centre through its ends hold the corners between them (`x0`
    /// first and `x1` last in the way `sigma` the arc turns). `None` when that takes more
    /// than three times [`ARC_MAX_WALK`] points either way, the stretch closes on itself or
    /// leaves the half-plane.
    fn walk_to_rays(
        &self,
        walk: &mut Walk,
        band: &mut Band,
        sigma: f64,
        (x0, x1): ([f64; 2], [f64; 2]),
    ) -> Option<()> {
        while sigma * cross(band.rel(self.vert(walk.back)), x0) < 0.0 {
            walk.step_back(self);
            if walk.steps_back > 3 * ARC_MAX_WALK
                || walk.back == walk.fwd
                || !band.add(&self.segs[walk.back as usize])
            {
                return None;
            }
        }
        while sigma * cross(x1, band.rel(self.vert(walk.fwd))) < 0.0 {
            if walk.steps_fwd > 3 * ARC_MAX_WALK || !band.add(&self.segs[walk.fwd as usize]) {
                return None;
            }
            walk.step_fwd(self);
            if walk.fwd == walk.back {
                return None;
            }
        }
        Some(())
    }

    /// Whether no point of the square `[c ± h]` inside the section is deeper than `t`
    /// (its centre must be inside the section), shown from its walls seen as [`Arc`]s:
    /// every edge meeting the square must be in the stretch of one arc `A` (through such
    /// an edge, or through `hints[0]`, the edge nearest to the centre), so the square
    /// falls into `A`'s band (depth at most its width), the part before it and the part
    /// beyond it, which no edge meets: one inside test settles each piece. An inside part
    /// is bounded by `A`, or by the mean of `A` and an arc through the other hint
    /// ([`arc_bound`]; docs/PLANNING.md, "Wall covers"). `false` means not shown.
    pub(super) fn arcs_cover(
        &self,
        c: [f64; 2],
        h: f64,
        t: f64,
        hints: [u32; 2],
        cache: &mut ArcCache,
    ) -> bool {
        let mut es = [0u32; MAX_CROSSING_EDGES];
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

    /// An edge whose bounding box meets the square `[c ± h]` and that is none of `arcs`'
    /// stretches' (`u32::MAX` when the index is too deep to tell), or `None` when every
    /// edge meeting the square is one of theirs.
    fn stray(&self, c: [f64; 2], h: f64, arcs: &[&Arc]) -> Option<u32> {
        let skip = |k: usize| arcs.iter().any(|a| a.has_span(self.spans[k]));
        let stray = |v: u32| (!arcs.iter().any(|a| a.has(v))).then_some(v);
        self.walk_square(c, h, skip, stray)
            .unwrap_or(Some(u32::MAX))
    }

    /// Whether no point of the square `[c ± h]` is deeper than `t`, shown from two walls
    /// crossing it seen as [`Arc`]s, one inside the other (a ring's): `A` through `near`
    /// and `B` through an edge meeting the square that is not `A`'s; every edge meeting
    /// the square must be one of theirs, and the bands nested with room to spare,
    /// `lo_O − hi_I > |o_I − o_O|` (`I` the inner arc, `O` the outer). The square falls into
    /// five parts: before `I`'s band (one inside test), `I`'s band, between the bands
    /// ([`arc_bound`]'s mean holds there inside the section or not: no test), `O`'s band
    /// and beyond it (an inside test at each corner there). Unlike [`Edges::arcs_cover`],
    /// the centre may be outside and the square larger than `t`: a cell straddling a thin
    /// ring (docs/PLANNING.md, "Wall covers"). `false` means not shown.
    pub(super) fn ring_cover(
        &self,
        c: [f64; 2],
        h: f64,
        t: f64,
        near: u32,
        cache: &mut ArcCache,
    ) -> bool {
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
    use crate::slice::Contour;

    /// The hints the search gives: the edge nearest to `c` and the one nearest to the
    /// mirror of that edge's point through `c`.
    fn hints(e: &Edges, c: [f64; 2]) -> [u32; 2] {
        let near = e.nearest(c, u32::MAX).1;
        let q = e.closest_point(near, c);
        let far = e.nearest([2.0 * c[0] - q[0], 2.0 * c[1] - q[1]], u32::MAX);
        [near, far.1]
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
        out.push(vec![closed(500, true, |t| {
            let r = 8.0 + 1.5 * (5.0 * t).sin();
            [r * t.cos(), r * t.sin()]
        })]);
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
                if rnd() < 0.2 {
                    cache.clear();
                }
                tried += 1;
                if !e.arcs_cover(c, h, t, hints(&e, c), &mut cache) {
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
        let section = ring([0.0, 0.0], 10.1, 10.0, 720);
        let e = Edges::new(&section);
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
        let section = ring([0.0, 0.0], 14.0, 10.0, 720);
        let e = Edges::new(&section);
        let hints = |c: [f64; 2]| hints(&e, c);
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
}
