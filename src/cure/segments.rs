//! A layer's section in pixel coordinates with a grid index of its edges: outward
//! normals, ray casts (feature widths) and nearest edges (the correction's band); where
//! shells or supports overlap, the pieces of the edges on the outline of their union
//! (winding numbers counted over the edges of one-pixel rows).

use crate::slice::Contour;

/// Edge of the grid's cells, pixels.
const CELL: f64 = 8.0;

/// One edge of the section, in field pixel coordinates (u = x/p, v = H − y/p: columns
/// right, rows down, as the rasterizer counts them).
#[derive(Debug, Clone, Copy)]
pub struct Segment {
    /// Start point.
    pub a: [f64; 2],
    /// End point.
    pub b: [f64; 2],
    /// Unit normal pointing out of the material.
    pub n: [f64; 2],
}

/// A section's edges and the grid of cells they cross.
pub struct Segments {
    /// Every edge, contour by contour, in order.
    pub segs: Vec<Segment>,
    /// Index of each contour's first edge (and the total at the end).
    pub starts: Vec<usize>,
    origin: [f64; 2],
    cols: usize,
    rows: usize,
    /// The grid's cells, row by row: cell k's edges are `cell_edges[cells[k]..cells[k + 1]]`
    /// (empty without the index).
    cells: Vec<u32>,
    cell_edges: Vec<u32>,
}

impl Segments {
    /// The edges of `contours` (build-plane mm) on a field `height_px` rows high of
    /// `pixel_mm` pixels, with the grid index ([`Segments::ray`]).
    pub fn new(contours: &[Contour], pixel_mm: f64, height_px: f64) -> Segments {
        let mut s = Segments::edges(contours, pixel_mm, height_px);
        s.index();
        s
    }

    /// The edges only, without the grid index.
    pub fn edges(contours: &[Contour], pixel_mm: f64, height_px: f64) -> Segments {
        Segments::simplified(contours, pixel_mm, height_px, 0.0)
    }

    /// The edges without the grid index, runs of points that stay within `tol_px` of the
    /// chord joining their ends replaced by the chord (at most 16 points a run; fine
    /// meshes give many nearly collinear short edges).
    pub fn simplified(
        contours: &[Contour],
        pixel_mm: f64,
        height_px: f64,
        tol_px: f64,
    ) -> Segments {
        let s = 1.0 / pixel_mm;
        let px = |p: [f64; 2]| [p[0] * s, height_px - p[1] * s];
        let mut segs = Vec::new();
        let mut starts = Vec::with_capacity(contours.len() + 1);
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for c in contours {
            starts.push(segs.len());
            let kept = keep_points(c, tol_px * pixel_mm);
            let c: Vec<[f64; 2]> = match &kept {
                Some(k) => k.iter().map(|&i| c[i]).collect(),
                None => c.clone(),
            };
            for i in 0..c.len() {
                let (p, q) = (c[i], c[(i + 1) % c.len()]);
                let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
                let l = dx.hypot(dy);
                if l == 0.0 {
                    continue;
                }
                // Right of the direction of travel, in mm; v runs against y.
                let n = [dy / l, dx / l];
                let (a, b) = (px(p), px(q));
                for k in 0..2 {
                    lo[k] = lo[k].min(a[k]).min(b[k]);
                    hi[k] = hi[k].max(a[k]).max(b[k]);
                }
                segs.push(Segment { a, b, n });
            }
        }
        starts.push(segs.len());
        if segs.is_empty() {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        Segments {
            segs,
            starts,
            origin: lo,
            cols: ((hi[0] - lo[0]) / CELL) as usize + 1,
            rows: ((hi[1] - lo[1]) / CELL) as usize + 1,
            cells: Vec::new(),
            cell_edges: Vec::new(),
        }
    }

    /// Builds the grid index.
    fn index(&mut self) {
        let cols = self.cols;
        let listed: Vec<_> = (self.segs.iter().enumerate())
            .map(|(i, sg)| {
                let (c0, r0) = self.cell(sg.a[0].min(sg.b[0]), sg.a[1].min(sg.b[1]));
                let (c1, r1) = self.cell(sg.a[0].max(sg.b[0]), sg.a[1].max(sg.b[1]));
                let cells = (r0..=r1).flat_map(move |r| (c0..=c1).map(move |c| r * cols + c));
                (cells, i as u32)
            })
            .collect();
        (self.cells, self.cell_edges) = buckets(cols * self.rows, &listed);
    }

    /// The edges listed in cell `k` (row-major) of the grid.
    fn in_cell(&self, k: usize) -> &[u32] {
        &self.cell_edges[self.cells[k] as usize..self.cells[k + 1] as usize]
    }

    fn cell(&self, u: f64, v: f64) -> (usize, usize) {
        let c = ((u - self.origin[0]) / CELL).max(0.0) as usize;
        let r = ((v - self.origin[1]) / CELL).max(0.0) as usize;
        (c.min(self.cols - 1), r.min(self.rows - 1))
    }

    /// Distance from `p` along the unit direction `dir` to the first edge other than
    /// `skip`, if within `max`. Only the cells the ray crosses are visited (an edge
    /// crossing the ray is listed in the cell of the crossing).
    pub fn ray(&self, p: [f64; 2], dir: [f64; 2], max: f64, skip: usize) -> Option<f64> {
        if self.segs.is_empty() {
            return None;
        }
        let mut best = f64::INFINITY;
        // The cells the ray crosses, in order (Amanatides and Woo's traversal), in the
        // grid's coordinates (cells of CELL px from `origin`; outside: clamped to the edge
        // cells, which hold every edge beyond them in that direction).
        let g = [
            (p[0] - self.origin[0]) / CELL,
            (p[1] - self.origin[1]) / CELL,
        ];
        let lim = [self.cols as i64 - 1, self.rows as i64 - 1];
        let mut cell = [g[0].floor() as i64, g[1].floor() as i64];
        let step = [dir[0].signum() as i64, dir[1].signum() as i64];
        let mut t_next = [0.0f64; 2];
        let mut t_delta = [f64::INFINITY; 2];
        for k in 0..2 {
            if dir[k] != 0.0 {
                let boundary = if dir[k] > 0.0 {
                    cell[k] as f64 + 1.0
                } else {
                    cell[k] as f64
                };
                t_next[k] = (boundary - g[k]) * CELL / dir[k];
                t_delta[k] = CELL / dir[k].abs();
            } else {
                t_next[k] = f64::INFINITY;
            }
        }
        let mut t = 0.0;
        let mut last = usize::MAX;
        while t <= max.min(best) {
            let c = [
                cell[0].clamp(0, lim[0]) as usize,
                cell[1].clamp(0, lim[1]) as usize,
            ];
            let idx = c[1] * self.cols + c[0];
            if idx != last {
                last = idx;
                for &i in self.in_cell(idx) {
                    let i = i as usize;
                    if i != skip {
                        if let Some(d) = self.crossing(i, p, dir) {
                            best = best.min(d);
                        }
                    }
                }
            }
            let k = if t_next[0] < t_next[1] { 0 } else { 1 };
            t = t_next[k];
            t_next[k] += t_delta[k];
            cell[k] += step[k];
            let outside =
                |k: usize| (cell[k] < 0 && step[k] < 0) || (cell[k] > lim[k] && step[k] > 0);
            if outside(0) || outside(1) {
                // Beyond the grid in the direction of travel: nothing more to cross.
                break;
            }
        }
        (best <= max).then_some(best)
    }

    /// Where the ray from `p` along `dir` crosses edge `i`, if it does.
    fn crossing(&self, i: usize, p: [f64; 2], dir: [f64; 2]) -> Option<f64> {
        let s = &self.segs[i];
        let e = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
        let den = dir[0] * e[1] - dir[1] * e[0];
        if den.abs() < 1e-15 {
            return None;
        }
        let w = [s.a[0] - p[0], s.a[1] - p[1]];
        let t = (w[0] * e[1] - w[1] * e[0]) / den;
        let u = (w[0] * dir[1] - w[1] * dir[0]) / den;
        (t > 1e-9 && (-1e-12..=1.0 + 1e-12).contains(&u)).then_some(t)
    }
}

impl Segments {
    /// The edges split where edges of other contours cross them, each piece flagged when
    /// it lies inside the section (material on both sides of it: the nonzero winding of
    /// all the contours there is not 0), as the edges of a support within the part, or of
    /// shells that overlap, do. Pieces keep their contour and their edge's normal, turned
    /// round where the material lies only beyond the edge (a shell of a defective mesh that
    /// runs backwards, filled with winding −1); the boundary of the union is the unflagged
    /// pieces, their normals pointing out of it. Last, per contour, whether it runs
    /// backwards: most of its length on the boundary has its normal turned.
    pub fn union_pieces(&self) -> (Segments, Vec<bool>, Vec<bool>) {
        let mut grid = Segments {
            segs: self.segs.clone(),
            starts: self.starts.clone(),
            origin: self.origin,
            cols: self.cols,
            rows: self.rows,
            cells: Vec::new(),
            cell_edges: Vec::new(),
        };
        grid.index();
        let rows = RowIndex::of(&self.segs);
        let mut contour = vec![0u32; self.segs.len()];
        for (k, w) in self.starts.windows(2).enumerate() {
            contour[w[0]..w[1]].fill(k as u32);
        }
        let contour_of = |i: usize| contour[i] as usize;
        let mut out = Vec::with_capacity(self.segs.len());
        let mut interior = Vec::with_capacity(self.segs.len());
        let mut starts = Vec::with_capacity(self.starts.len());
        let (mut ts, mut seen) = (Vec::new(), vec![usize::MAX; self.segs.len()]);
        let mut backwards = Vec::with_capacity(self.starts.len());
        for (own, w) in self.starts.windows(2).enumerate() {
            starts.push(out.len());
            let mut turned = 0.0;
            for i in w[0]..w[1] {
                self.split(&grid, (i, own), (&mut ts, &mut seen), &contour_of);
                let s = &self.segs[i];
                for w in ts.windows(2) {
                    let at = |t: f64| [0, 1].map(|k| s.a[k] + t * (s.b[k] - s.a[k]));
                    let mid = at((w[0] + w[1]) / 2.0);
                    let off = |d: f64| [0, 1].map(|k| mid[k] + d * s.n[k]);
                    let (beyond, behind) = rows.windings(off(1e-3), off(-1e-3));
                    let (beyond, behind) = (beyond != 0, behind != 0);
                    interior.push(beyond && behind);
                    let len = (w[1] - w[0]) * (s.b[0] - s.a[0]).hypot(s.b[1] - s.a[1]);
                    let turn = beyond && !behind;
                    turned += [-len, 0.0, len][usize::from(beyond) + usize::from(turn)];
                    let n = if turn { s.n.map(|v| -v) } else { s.n };
                    out.push(Segment {
                        a: at(w[0]),
                        b: at(w[1]),
                        n,
                    });
                }
            }
            backwards.push(turned > 0.0);
        }
        starts.push(out.len());
        let pieces = Segments {
            segs: out,
            starts,
            origin: self.origin,
            cols: self.cols,
            rows: self.rows,
            cells: Vec::new(),
            cell_edges: Vec::new(),
        };
        (pieces, interior, backwards)
    }

    /// The outline of the union of the contours' shells, with the grid index: the pieces
    /// of [`Segments::union_pieces`] with no material beyond them, by contour; and per
    /// contour whether it runs backwards.
    pub fn union_outline(&self) -> (Segments, Vec<bool>) {
        let (pieces, interior, backwards) = self.union_pieces();
        let mut out = Segments {
            segs: Vec::with_capacity(pieces.segs.len()),
            starts: vec![0],
            origin: pieces.origin,
            cols: pieces.cols,
            rows: pieces.rows,
            cells: Vec::new(),
            cell_edges: Vec::new(),
        };
        for w in pieces.starts.windows(2) {
            out.segs.extend(
                (w[0]..w[1])
                    .filter(|&i| !interior[i])
                    .map(|i| pieces.segs[i]),
            );
            out.starts.push(out.segs.len());
        }
        out.index();
        (out, backwards)
    }

    /// The fractions of edge `i` (of contour `own`) where edges of other contours cross
    /// it, with its ends, sorted, into `ts` (`seen`: the edge each other edge was last
    /// tested against). The edges are found by the cells `i` spans in `grid`.
    fn split(
        &self,
        grid: &Segments,
        (i, own): (usize, usize),
        (ts, seen): (&mut Vec<f64>, &mut [usize]),
        contour_of: &impl Fn(usize) -> usize,
    ) {
        let s = &self.segs[i];
        // Where other contours' edges cross this one (by the cells it spans).
        ts.clear();
        ts.extend([0.0, 1.0]);
        let (c0, r0) = grid.cell(s.a[0].min(s.b[0]), s.a[1].min(s.b[1]));
        let (c1, r1) = grid.cell(s.a[0].max(s.b[0]), s.a[1].max(s.b[1]));
        for r in r0..=r1 {
            for c in c0..=c1 {
                for &j in grid.in_cell(r * grid.cols + c) {
                    let j = j as usize;
                    if seen[j] != i && contour_of(j) != own {
                        seen[j] = i;
                        ts.extend(cross(s, &self.segs[j]));
                    }
                }
            }
        }
        ts.sort_by(f64::total_cmp);
        ts.dedup_by(|b, a| *b - *a < 1e-9);
    }
}

/// A section's edges by rows one pixel high, for winding numbers: each edge is listed in
/// every row its span of v meets, so a row holds every edge that a ray along it can cross
/// and few others; within a row, by their largest u, right to left, so that a ray stops
/// at the first edge that ends left of it.
struct RowIndex {
    /// v of the top of row 0.
    v0: f64,
    /// Per row, where its entries begin in `ends` (and the total at the end).
    start: Vec<u32>,
    /// The rows' edges: [a.u, a.v, b.u, b.v].
    ends: Vec<[f64; 4]>,
}

impl RowIndex {
    fn of(segs: &[Segment]) -> RowIndex {
        let v0 = segs
            .iter()
            .fold(f64::INFINITY, |m, s| m.min(s.a[1]).min(s.b[1]));
        let v1 = segs.iter().fold(v0, |m, s| m.max(s.a[1]).max(s.b[1]));
        let rows = if segs.is_empty() {
            1
        } else {
            (v1 - v0) as usize + 1
        };
        let row = |v: f64| row_at(v0, rows, v);
        let listed: Vec<_> = (segs.iter())
            .map(|s| {
                let span = row(s.a[1].min(s.b[1]))..=row(s.a[1].max(s.b[1]));
                (span, [s.a[0], s.a[1], s.b[0], s.b[1]])
            })
            .collect();
        let (start, ends) = buckets(rows, &listed);
        let mut index = RowIndex { v0, start, ends };
        let right = |e: &[f64; 4]| e[0].max(e[2]);
        for r in index.start.windows(2) {
            index.ends[r[0] as usize..r[1] as usize]
                .sort_unstable_by(|a, b| right(b).total_cmp(&right(a)));
        }
        index
    }

    /// The row of v.
    fn row(&self, v: f64) -> usize {
        row_at(self.v0, self.start.len() - 1, v)
    }

    /// The nonzero winding numbers of the edges at `p` and at `q`: signed crossings of the
    /// rays from them along +u.
    fn windings(&self, p: [f64; 2], q: [f64; 2]) -> (i32, i32) {
        let (rp, rq) = (self.row(p[1]), self.row(q[1]));
        if rp != rq {
            return (self.winding(p), self.winding(q));
        }
        let ends = &self.ends[self.start[rp] as usize..self.start[rp + 1] as usize];
        let left = p[0].min(q[0]) - LEFT_OF;
        ends.iter()
            .take_while(|e| e[0].max(e[2]) >= left)
            .fold((0, 0), |(a, b), e| (a + crossing(e, p), b + crossing(e, q)))
    }

    /// The winding number at `p`, as [`RowIndex::windings`].
    fn winding(&self, p: [f64; 2]) -> i32 {
        let r = self.row(p[1]);
        let ends = &self.ends[self.start[r] as usize..self.start[r + 1] as usize];
        ends.iter()
            .take_while(|e| e[0].max(e[2]) >= p[0] - LEFT_OF)
            .map(|e| crossing(e, p))
            .sum()
    }
}

/// The row of v among `rows` rows one pixel high from `v0` (beyond the ends: the end rows).
fn row_at(v0: f64, rows: usize, v: f64) -> usize {
    ((v - v0).max(0.0) as usize).min(rows - 1)
}

/// Lists each item's value in the buckets (of `n`) its iterator names, in item order:
/// where each bucket's entries begin in the list (and the total at the end), and the list.
fn buckets<I, T>(n: usize, items: &[(I, T)]) -> (Vec<u32>, Vec<T>)
where
    I: Iterator<Item = usize> + Clone,
    T: Copy + Default,
{
    let mut start = vec![0u32; n + 1];
    for (at, _) in items {
        at.clone().for_each(|k| start[k + 1] += 1);
    }
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    let mut fill = start.clone();
    let mut list = vec![T::default(); start[n] as usize];
    for (at, v) in items {
        for k in at.clone() {
            list[fill[k] as usize] = *v;
            fill[k] += 1;
        }
    }
    (start, list)
}

/// An edge that ends this far (px) left of a point cannot cross the ray from it along +u,
/// rounding included (where [`crossing`] puts the crossing is within a few ulps of the
/// edge's span).
const LEFT_OF: f64 = 1e-6;

/// What the edge `e` ([a.u, a.v, b.u, b.v]) adds to the winding number at `p`: ±1 when it
/// crosses the ray from `p` along +u (upward +1), else 0.
#[inline(always)]
fn crossing(e: &[f64; 4], p: [f64; 2]) -> i32 {
    let [au, av, bu, bv] = *e;
    if (av <= p[1]) != (bv <= p[1]) {
        let t = (p[1] - av) / (bv - av);
        if au + t * (bu - au) > p[0] {
            return if bv > av { 1 } else { -1 };
        }
    }
    0
}

/// Whether two contours of `contours` (a section, filled by the nonzero rule) may cross,
/// touch or nest with the same orientation: two shells that overlap or meet, whose edges
/// inside the union [`Segments::union_pieces`] must hold. Decided on their boxes (touching
/// boxes count), per orientation: an outline and the holes inside it never ask for it.
/// Also when a clockwise contour lies in no counter-clockwise one's box: a hole outside
/// every outline is a shell that runs backwards (a defective mesh), whose edges'
/// normals point into its material until [`Segments::union_pieces`] turns them.
pub fn contours_may_meet(contours: &[Contour]) -> bool {
    let mut boxes: [Vec<[f64; 4]>; 2] = [Vec::new(), Vec::new()];
    for c in contours {
        let b = crate::slice::bounds([c]);
        boxes[usize::from(crate::slice::signed_area(c) < 0.0)].push(b);
    }
    let within =
        |b: &[f64; 4], a: &[f64; 4]| a[0] <= b[0] && a[1] <= b[1] && b[2] <= a[2] && b[3] <= a[3];
    let [outlines, holes] = &boxes;
    if holes.iter().any(|h| !outlines.iter().any(|o| within(h, o))) {
        return true;
    }
    boxes.iter_mut().any(|group| {
        group.sort_unstable_by(|a, b| a[0].total_cmp(&b[0]));
        (0..group.len()).any(|i| {
            let a = group[i];
            group[i + 1..]
                .iter()
                .take_while(|b| b[0] <= a[2])
                .any(|b| b[1] <= a[3] && a[1] <= b[3])
        })
    })
}

/// Where segment `e` crosses segment `s`, as a fraction of `s` strictly inside it.
fn cross(s: &Segment, e: &Segment) -> Option<f64> {
    let d = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
    let f = [e.b[0] - e.a[0], e.b[1] - e.a[1]];
    let den = d[0] * f[1] - d[1] * f[0];
    if den.abs() < 1e-15 {
        return None;
    }
    let w = [e.a[0] - s.a[0], e.a[1] - s.a[1]];
    let t = (w[0] * f[1] - w[1] * f[0]) / den;
    let u = (w[0] * d[1] - w[1] * d[0]) / den;
    ((1e-9..1.0 - 1e-9).contains(&t) && (0.0..=1.0).contains(&u)).then_some(t)
}

/// The indices of the points of closed contour `c` kept when runs within `tol` (mm) of
/// their chord are replaced by it (`None`: all, when `tol` is 0).
fn keep_points(c: &Contour, tol: f64) -> Option<Vec<usize>> {
    if tol <= 0.0 || c.len() < 4 {
        return None;
    }
    let n = c.len();
    let mut keep = vec![0usize];
    let mut start = 0;
    while start < n {
        // Extend the run from `start` while every point between stays near the chord.
        let mut end = start + 1;
        while end < n && end - start < 16 {
            let next = end + 1;
            let (a, b) = (c[start], c[next % n]);
            // Distance to the chord's line, squared and scaled by the chord's length.
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let lim = tol * tol * (dx * dx + dy * dy);
            let near = |k: usize| {
                let cross = (c[k][0] - a[0]) * dy - (c[k][1] - a[1]) * dx;
                let along = (c[k][0] - a[0]) * dx + (c[k][1] - a[1]) * dy;
                cross * cross <= lim && along >= 0.0 && along <= dx * dx + dy * dy
            };
            if (start + 1..next).all(near) {
                end = next;
            } else {
                break;
            }
        }
        if end >= n {
            break;
        }
        keep.push(end);
        start = end;
    }
    Some(keep)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contours_meet_when_shells_cross_touch_or_nest_but_not_for_holes() {
        let sq = |x: f64, y: f64, s: f64| vec![[x, y], [x + s, y], [x + s, y + s], [x, y + s]];
        let hole = |x: f64, y: f64, s: f64| {
            let mut c = sq(x, y, s);
            c.reverse();
            c
        };
        assert!(!contours_may_meet(&[
            sq(0.0, 0.0, 10.0),
            hole(2.0, 2.0, 3.0)
        ]));
        assert!(!contours_may_meet(&[sq(0.0, 0.0, 4.0), sq(5.0, 0.0, 4.0)]));
        assert!(contours_may_meet(&[sq(0.0, 0.0, 4.0), sq(4.0, 0.0, 4.0)]));
        assert!(contours_may_meet(&[sq(0.0, 0.0, 4.0), sq(3.0, 3.0, 4.0)]));
        assert!(contours_may_meet(&[sq(0.0, 0.0, 10.0), sq(2.0, 2.0, 3.0)]));
        assert!(!contours_may_meet(&[sq(0.0, 0.0, 4.0)]));
        // A shell that runs backwards: a hole outside every outline.
        assert!(contours_may_meet(&[hole(0.0, 0.0, 4.0)]));
        assert!(contours_may_meet(&[sq(0.0, 0.0, 4.0), hole(5.0, 0.0, 4.0)]));
    }

    /// A shell that runs backwards (clockwise outline, counter-clockwise hole: winding −1,
    /// lit by the nonzero rule) bounds the union: its pieces' normals turn round to point
    /// out of the material, where the same shell running forwards has them.
    #[test]
    fn union_pieces_turn_the_normals_of_a_shell_that_runs_backwards() {
        let outline: Contour = vec![[0.0, 0.0], [0.0, 10.0], [10.0, 10.0], [10.0, 0.0]];
        let hole: Contour = vec![[4.0, 4.0], [6.0, 4.0], [6.0, 6.0], [4.0, 6.0]];
        let back = Segments::edges(&[outline.clone(), hole.clone()], 1.0, 100.0);
        let fwd: Vec<Contour> = [outline, hole]
            .map(|c| c.into_iter().rev().collect())
            .into();
        for (segs, turn) in [(back, -1.0), (Segments::edges(&fwd, 1.0, 100.0), 1.0)] {
            let (pieces, interior, backwards) = segs.union_pieces();
            assert!(interior.iter().all(|&i| !i) && pieces.segs.len() == segs.segs.len());
            assert_eq!(backwards, [turn < 0.0; 2]);
            for (p, s) in pieces.segs.iter().zip(&segs.segs) {
                assert_eq!(p.n, s.n.map(|v| turn * v));
            }
        }
    }

    /// A support overlapping a part's edge: the pieces inside the other shape are flagged,
    /// and the unflagged pieces are the union's outline.
    #[test]
    fn union_pieces_flag_the_edges_inside_the_other_shape() {
        let part: Contour = vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let support: Contour = vec![[8.0, 4.0], [12.0, 4.0], [12.0, 6.0], [8.0, 6.0]];
        let segs = Segments::edges(&[part, support], 1.0, 100.0);
        let (pieces, interior, _) = segs.union_pieces();
        assert_eq!(pieces.starts, vec![0, 6, 12]);
        let len = |s: &Segment| (s.b[0] - s.a[0]).hypot(s.b[1] - s.a[1]);
        let (mut inside, mut outline) = (0.0, 0.0);
        for (s, &i) in pieces.segs.iter().zip(&interior) {
            if i {
                inside += len(s);
                // Inside: the part's edge across the support, the support's within the part.
                let mid = [(s.a[0] + s.b[0]) / 2.0, 100.0 - (s.a[1] + s.b[1]) / 2.0];
                assert!((8.0..=10.0).contains(&mid[0]) && (4.0..=6.0).contains(&mid[1]));
            } else {
                outline += len(s);
            }
        }
        // 2 (part's edge) + 2 (support's left) + 2·2 (its top and bottom within the part).
        assert!((inside - 8.0).abs() < 1e-9, "{inside}");
        assert!(
            (outline - (40.0 - 2.0 + 2.0 + 2.0 * 2.0)).abs() < 1e-9,
            "{outline}"
        );
        // Shapes apart: nothing split, nothing flagged.
        let apart: Contour = vec![[20.0, 4.0], [22.0, 4.0], [22.0, 6.0], [20.0, 6.0]];
        let square: Contour = vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let (pieces, interior, _) = Segments::edges(&[square, apart], 1.0, 100.0).union_pieces();
        assert_eq!(pieces.segs.len(), 8);
        assert!(interior.iter().all(|&i| !i));
    }

    /// The row index's winding numbers are those of every edge's crossing: at random
    /// points, at the edges' end points (rows' and spans' ends) and just off their ends.
    #[test]
    fn windings_match_every_edge() {
        let mut rnd = crate::test_support::xorshift(7);
        // Random star-shaped contours, both orientations, overlapping.
        let contours: Vec<Contour> = (0..12)
            .map(|k| {
                let (cx, cy, r) = (20.0 * rnd(), 20.0 * rnd(), 1.0 + 6.0 * rnd());
                let n = 3 + (rnd() * 30.0) as usize;
                let mut c: Contour = (0..n)
                    .map(|i| {
                        let a = std::f64::consts::TAU * i as f64 / n as f64;
                        let f = r * (0.4 + 0.6 * rnd());
                        [cx + f * a.cos(), cy + f * a.sin()]
                    })
                    .collect();
                if k % 3 == 0 {
                    c.reverse();
                }
                c
            })
            .collect();
        let segs = Segments::edges(&contours, 0.05, 600.0);
        let index = RowIndex::of(&segs.segs);
        let every = |p: [f64; 2]| -> i32 {
            let e = segs.segs.iter().map(|s| [s.a[0], s.a[1], s.b[0], s.b[1]]);
            e.map(|e| crossing(&e, p)).sum()
        };
        let mut points: Vec<[f64; 2]> = (0..3000)
            .map(|_| [600.0 * rnd() - 100.0, 600.0 * rnd() + 100.0])
            .collect();
        for s in &segs.segs {
            for p in [s.a, s.b] {
                for d in [
                    [0.0, 0.0],
                    [-1e-3, 0.0],
                    [1e-3, 0.0],
                    [0.0, 1e-9],
                    [0.0, -1e-9],
                ] {
                    points.push([p[0] + d[0], p[1] + d[1]]);
                }
            }
        }
        let mut nonzero = 0;
        for (k, &p) in points.iter().enumerate() {
            let q = points[(k * 7 + 1) % points.len()];
            let near = [p[0] + 1e-3, p[1] - 1e-3];
            assert_eq!(index.winding(p), every(p), "{p:?}");
            assert_eq!(index.windings(p, q), (every(p), every(q)), "{p:?} {q:?}");
            assert_eq!(index.windings(p, near), (every(p), every(near)), "{p:?}");
            nonzero += usize::from(every(p) != 0);
        }
        assert!(nonzero > 1000, "{nonzero}");
        assert_eq!(RowIndex::of(&[]).windings([1.0, 2.0], [3.0, 4.0]), (0, 0));
    }

    /// The grid's ray casts find what testing every edge finds.
    #[test]
    fn ray_casts_match_testing_every_edge() {
        // A 7-pointed star with a square hole, in mm (pixel 0.1 mm, 500 rows).
        let star: Contour = (0..14)
            .map(|k| {
                let a = std::f64::consts::PI * k as f64 / 7.0;
                let r = if k % 2 == 0 { 4.0 } else { 1.7 };
                [10.0 + r * a.cos(), 20.0 + r * a.sin()]
            })
            .collect();
        let hole: Contour = vec![[9.5, 19.5], [9.5, 20.5], [10.5, 20.5], [10.5, 19.5]];
        let segs = Segments::new(&[star, hole], 0.1, 500.0);
        let mut checked = 0;
        for (i, s) in segs.segs.iter().enumerate() {
            for f in [0.1, 0.5, 0.77] {
                let p = [
                    s.a[0] + f * (s.b[0] - s.a[0]),
                    s.a[1] + f * (s.b[1] - s.a[1]),
                ];
                for k in 0..16 {
                    let a = 0.3 + std::f64::consts::PI * k as f64 / 8.0;
                    let dir = [a.cos(), a.sin()];
                    for max in [3.0, 25.0, 200.0] {
                        let want = (0..segs.segs.len())
                            .filter(|&j| j != i)
                            .filter_map(|j| segs.crossing(j, p, dir))
                            .fold(f64::INFINITY, f64::min);
                        let want = (want <= max).then_some(want);
                        assert_eq!(segs.ray(p, dir, max, i), want, "edge {i} f {f} dir {k}");
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 1000);
    }
}
