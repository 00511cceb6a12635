//! The wall cover: a cell across thin walls is dropped when the walls crossing it, each
//! close to a line over the cell, bound the depth of every part of it inside the section.

use super::plane::{corners, unit};
use super::Edges;

/// Most edges meeting a cell that [`Edges::crossing`] lists: the wall and arc covers give up
/// on cells crossed by more.
pub(super) const MAX_CROSSING_EDGES: usize = 48;

/// Most contour points a wall is followed beyond a cell to cover the cell's projection on
/// its line ([`Edges::wall`]).
const WALL_MAX_WALK: usize = 32;

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
    fn signed_distance(&self, x: [f64; 2]) -> f64 {
        self.n[0] * x[0] + self.n[1] * x[1] - self.off
    }

    /// An upper bound of the depth of `x` (a point of the cell the wall was made for).
    #[inline]
    fn bound(&self, x: [f64; 2]) -> f64 {
        self.signed_distance(x).abs() + self.dev
    }

    /// The point of the line nearest to `x`.
    fn foot(&self, x: [f64; 2]) -> [f64; 2] {
        let l = self.signed_distance(x);
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
struct ConvexPolygon {
    v: [[f64; 2]; 8],
    n: usize,
}

impl ConvexPolygon {
    fn square(c: [f64; 2], h: f64) -> ConvexPolygon {
        let mut v = [[0.0; 2]; 8];
        v[..4].copy_from_slice(&corners(c, h));
        ConvexPolygon { v, n: 4 }
    }

    /// The part where `f(x) ≥ 0`, `f` affine (Sutherland–Hodgman against one line).
    fn clip(&self, f: impl Fn([f64; 2]) -> f64) -> ConvexPolygon {
        let mut out = ConvexPolygon {
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

/// How far a test point must stand from a wall's band to be taken as off it, mm (far
/// above the rounding of the clipping, far below any precision asked).
const WALL_BAND_MARGIN_MM: f64 = 1e-9;

impl Edges {
    /// Walks, depth first, the edges whose bounding boxes meet the square `[c ± h]`,
    /// giving each to `f` until it returns a value; the subtrees of the nodes `skip`
    /// refuses (by index) are left out. `Err(())` when the hierarchy is too deep to walk.
    pub(super) fn walk_square<T>(
        &self,
        c: [f64; 2],
        h: f64,
        skip: impl Fn(usize) -> bool,
        mut f: impl FnMut(u32) -> Option<T>,
    ) -> Result<Option<T>, ()> {
        let (lo, hi) = ([c[0] - h, c[1] - h], [c[0] + h, c[1] + h]);
        let mut stack: [u32; 64] = [0; 64];
        stack[0] = (self.nodes.len() - 1) as u32;
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let k = stack[sp] as usize;
            let n = &self.nodes[k];
            if !(n.lo[0] <= hi[0] && n.hi[0] >= lo[0] && n.lo[1] <= hi[1] && n.hi[1] >= lo[1])
                || skip(k)
            {
                continue;
            }
            if n.count > 0 {
                for v in n.first..n.first + n.count {
                    if self.seg_meets(v, lo, hi) {
                        if let Some(r) = f(v) {
                            return Ok(Some(r));
                        }
                    }
                }
            } else {
                if sp + 2 > stack.len() {
                    return Err(());
                }
                stack[sp] = n.first;
                stack[sp + 1] = n.first + 1;
                sp += 2;
            }
        }
        Ok(None)
    }

    /// Edges whose bounding boxes meet the square `[c ± h]`, into `out`; `None` when there
    /// are more than [`MAX_CROSSING_EDGES`].
    pub(super) fn crossing(
        &self,
        c: [f64; 2],
        h: f64,
        out: &mut [u32; MAX_CROSSING_EDGES],
    ) -> Option<usize> {
        let mut m = 0;
        let walk = self.walk_square(
            c,
            h,
            |_| false,
            |v| {
                if m == MAX_CROSSING_EDGES {
                    return Some(());
                }
                out[m] = v;
                m += 1;
                None
            },
        );
        matches!(walk, Ok(None)).then_some(m)
    }

    /// Whether the bounding box of edge `v` meets the box `[lo, hi]`.
    #[inline]
    pub(super) fn seg_meets(&self, v: u32, lo: [f64; 2], hi: [f64; 2]) -> bool {
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
                if len > MAX_CROSSING_EDGES {
                    return None;
                }
            }
            Some(k)
        };
        let first = run_end(&self.prev)?;
        let last = run_end(&self.next)?;
        let end = self.next[last as usize];
        let corners = ConvexPolygon::square(c, h);
        // Projections on the line from `a` along the unit vector `u`: of the corners, and
        // whether the points from `back` to `fwd` cover them.
        let frame = |a: [f64; 2], b: [f64; 2]| unit([b[0] - a[0], b[1] - a[1]]).map(|u| (a, u));
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
        // The ranges of the points `from` to `to` along the line `f` and across it.
        let extent = |f: ([f64; 2], [f64; 2]), from: u32, to: u32| {
            let n = [-f.1[1], f.1[0]];
            let (mut t, mut l) = (
                [f64::INFINITY, f64::NEG_INFINITY],
                [f64::INFINITY, f64::NEG_INFINITY],
            );
            let mut k = from;
            loop {
                let x = self.vert(k);
                let (a, b) = (proj(f, x), n[0] * (x[0] - f.0[0]) + n[1] * (x[1] - f.0[1]));
                (t, l) = ([t[0].min(a), t[1].max(a)], [l[0].min(b), l[1].max(b)]);
                if k == to {
                    return (t, l);
                }
                k = self.next[k as usize];
            }
        };
        // First pass: along the line through the run's ends (the edge's, for one edge).
        let f = frame(self.vert(first), self.vert(end))?;
        let (q_lo, q_hi) = span(f);
        let ([mut t_lo, mut t_hi], _) = extent(f, first, end);
        let (mut back, mut fwd) = (first, end);
        let mut steps = 0;
        while t_lo > q_lo {
            back = self.prev[back as usize];
            t_lo = t_lo.min(proj(f, self.vert(back)));
            steps += 1;
            if steps > WALL_MAX_WALK || back == end {
                return None;
            }
        }
        steps = 0;
        while t_hi < q_hi {
            fwd = self.next[fwd as usize];
            t_hi = t_hi.max(proj(f, self.vert(fwd)));
            steps += 1;
            if steps > WALL_MAX_WALK || fwd == back {
                return None;
            }
        }
        // Second pass: the line through the stretch's ends (a chord: the points stand
        // less far from it), which must still cover the corners.
        let f = frame(self.vert(back), self.vert(fwd))?;
        let (q_lo, q_hi) = span(f);
        let n = [-f.1[1], f.1[0]];
        let ([t_lo, t_hi], [l_lo, l_hi]) = extent(f, back, fwd);
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
    /// shown from the walls crossing it: the edges meeting the square must form at most
    /// two runs of consecutive edges, each close to a line over the square ([`Wall`]).
    /// The square then falls into the walls' bands (depth at most twice a band's
    /// half-width) and parts no edge meets, each wholly inside or outside the section (one
    /// inside test) and bounded by the walls' convex bounds at its corners
    /// (docs/PLANNING.md, "Wall covers"). This drops cells across a wall thinner than
    /// themselves, which no discs around wall points cover. `false` means not shown.
    pub(super) fn walls_cover(&self, c: [f64; 2], h: f64, t: f64, hints: [u32; 2]) -> bool {
        let mut es = [0u32; MAX_CROSSING_EDGES];
        let Some(m) = self.crossing(c, h, &mut es) else {
            return false;
        };
        let es = &es[..m];
        let sq = ConvexPolygon::square(c, h);
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
                    if nw == 0 || walls[0].signed_distance(f).abs() > walls[0].dev + w.dev {
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
            let (la, lb) = (a.signed_distance(b.foot(c)), b.signed_distance(a.foot(c)));
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
            let part = sq.clip(|x| -w.signed_distance(x) - w.dev);
            if let Some(o) = walls.get(1 - i) {
                // It must not meet the other wall's band.
                let v = part.vertices();
                let above = v.iter().all(|x| o.signed_distance(*x) > o.dev);
                let below = v.iter().all(|x| o.signed_distance(*x) < -o.dev);
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
            .fold(sq, |part, w| part.clip(|x| w.signed_distance(x) - w.dev));
        self.part_covered(&part, walls, t, None)
    }

    /// Whether no point of `part` (a part of a cell crossed by no edge) inside the section
    /// is deeper than `t`: outside (inside test at one point), or bounded by `walls`
    /// (`beyond`: the part beyond that wall, bounded by it; `None`: the part between the
    /// walls, bounded by either or by their mean). The bounds are convex: their largest
    /// value on the part is at a corner.
    fn part_covered(
        &self,
        part: &ConvexPolygon,
        walls: &[Wall],
        t: f64,
        beyond: Option<usize>,
    ) -> bool {
        let Some(p) = part.interior_point() else {
            return true;
        };
        // Rounding could put a point of a thin part on a band: not shown then.
        if walls
            .iter()
            .any(|w| w.signed_distance(p).abs() <= w.dev + WALL_BAND_MARGIN_MM)
        {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::analysis::test_support::*;
    use crate::plan::analysis::{max_fill_distance, PRECISION_MM};
    use crate::slice::Contour;

    /// Thin sections: rings, a ring cut into pieces (walls ending inside cells), a thin
    /// rotated bar and a thin wedge (walls meeting at an angle).
    fn thin_sections(rnd: &mut impl FnMut() -> f64) -> Vec<Vec<Contour>> {
        let mut out = Vec::new();
        for _ in 0..6 {
            let (r, w) = (2.0 + 10.0 * rnd(), 0.01 + 0.3 * rnd());
            let n = 64 + (600.0 * rnd()) as usize;
            out.push(ring([0.0, 0.0], r + w, r, n));
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
        let section = ring([0.0, 0.0], 11.29, 11.25, 1440);
        let e = Edges::new(&section);
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
            let section = ring([0.0, 0.0], 11.25 + w, 11.25, 1440);
            let r = max_fill_distance(&section).0;
            // The regular polygons' ring is a little narrower than w where their edges
            // are (their apothems differ from their radii by the same factor).
            let exact = 0.5 * w * (std::f64::consts::PI / 1440.0).cos();
            assert!(r <= exact + 1e-9 && r >= exact - PRECISION_MM, "{w}: {r}");
        }
    }
}
