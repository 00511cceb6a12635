//! The edge index of a section: its edges in contour order with a bounding-volume
//! hierarchy for nearest-edge queries and horizontal bands for the nonzero-winding
//! inside test.

use super::plane::{d2, unit};
use crate::slice::Contour;

/// A directed edge `[ax, ay, bx, by]`.
pub(super) type Segment = [f64; 4];

/// A node of the bounding-volume hierarchy over the edges: the box around its edges.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct BvhNode {
    pub(super) lo: [f64; 2],
    pub(super) hi: [f64; 2],
    /// Leaf: first edge; inner node: index of the left child (the right one follows).
    pub(super) first: u32,
    /// Number of edges of a leaf; 0 for an inner node.
    pub(super) count: u32,
}

/// Most edges of a leaf of the hierarchy (a run of consecutive edges of one contour).
const LEAF_EDGES: usize = 8;

/// The edges of a section with the indexes the distance queries need.
pub struct Edges {
    /// Edge `v` goes from contour point `v` to point `next[v]` (the points of all contours
    /// one contour after the other, repeated consecutive points left out).
    pub(super) segs: Vec<Segment>,
    /// The next and the previous point (and edge) of the same contour.
    pub(super) next: Vec<u32>,
    pub(super) prev: Vec<u32>,
    pub(super) nodes: Vec<BvhNode>,
    /// The edges under each node: a range of consecutive indexes `[first, end)` (leaves
    /// are runs of consecutive edges, and each level pairs neighbours).
    pub(super) spans: Vec<[u32; 2]>,
    band_y0: f64,
    band_inv: f64,
    band_start: Vec<u32>,
    band_items: Vec<u32>,
}

#[inline]
pub(super) fn seg_d2(p: [f64; 2], s: &Segment) -> f64 {
    let (ax, ay, bx, by) = (s[0], s[1], s[2], s[3]);
    let (dx, dy) = (bx - ax, by - ay);
    let (px, py) = (p[0] - ax, p[1] - ay);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        ((px * dx + py * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (px - t * dx, py - t * dy);
    ex * ex + ey * ey
}

/// [`seg_d2`] when it is below `best`, else `None`: the distance to the edge's line is
/// compared before it is divided out.
#[inline]
fn seg_d2_below(p: [f64; 2], s: &Segment, best: f64) -> Option<f64> {
    let (ax, ay, bx, by) = (s[0], s[1], s[2], s[3]);
    let (dx, dy) = (bx - ax, by - ay);
    let (px, py) = (p[0] - ax, p[1] - ay);
    let l2 = dx * dx + dy * dy;
    let dot = px * dx + py * dy;
    let d = if dot <= 0.0 || l2 == 0.0 {
        px * px + py * py
    } else if dot >= l2 {
        let (qx, qy) = (p[0] - bx, p[1] - by);
        qx * qx + qy * qy
    } else {
        let cr = px * dy - py * dx;
        let c2 = cr * cr;
        if c2 >= best * l2 {
            return None;
        }
        c2 / l2
    };
    (d < best).then_some(d)
}

fn box_d2(p: [f64; 2], n: &BvhNode) -> f64 {
    let dx = (n.lo[0] - p[0]).max(0.0).max(p[0] - n.hi[0]);
    let dy = (n.lo[1] - p[1]).max(0.0).max(p[1] - n.hi[1]);
    dx * dx + dy * dy
}

fn union(a: &BvhNode, b: &BvhNode) -> ([f64; 2], [f64; 2]) {
    (
        [a.lo[0].min(b.lo[0]), a.lo[1].min(b.lo[1])],
        [a.hi[0].max(b.hi[0]), a.hi[1].max(b.hi[1])],
    )
}

/// Builds the hierarchy bottom-up in contour order: leaves are runs of up to [`LEAF_EDGES`]
/// consecutive edges of one contour (a short piece of curve, so a tight box), and each
/// level pairs neighbours of the level below. Linear time; the root is the last node.
fn build(segs: &[Segment], contour_ends: &[usize]) -> (Vec<BvhNode>, Vec<[u32; 2]>) {
    let mut nodes: Vec<BvhNode> = Vec::with_capacity(2 * segs.len() / LEAF_EDGES + 4);
    let mut spans: Vec<[u32; 2]> = Vec::with_capacity(2 * segs.len() / LEAF_EDGES + 4);
    let mut start = 0;
    for &end in contour_ends {
        let mut i = start;
        while i < end {
            let j = (i + LEAF_EDGES).min(end);
            let mut n = BvhNode {
                lo: [f64::INFINITY; 2],
                hi: [f64::NEG_INFINITY; 2],
                first: i as u32,
                count: (j - i) as u32,
            };
            // Each edge starts where the previous one ended (the same values): the start
            // points and the last end point are all the points, each visited once (plain
            // comparisons: no NaN handling needed).
            let run = &segs[i..j];
            let tail = run.last().map(|s| (s[2], s[3]));
            for (x, y) in run.iter().map(|s| (s[0], s[1])).chain(tail) {
                if x < n.lo[0] {
                    n.lo[0] = x;
                }
                if x > n.hi[0] {
                    n.hi[0] = x;
                }
                if y < n.lo[1] {
                    n.lo[1] = y;
                }
                if y > n.hi[1] {
                    n.hi[1] = y;
                }
            }
            nodes.push(n);
            spans.push([i as u32, j as u32]);
            i = j;
        }
        start = end;
    }
    let (mut lo, mut hi) = (0, nodes.len());
    while hi - lo > 1 {
        let mut k = lo;
        while k < hi {
            if k + 1 < hi {
                let (a, b) = (nodes[k], nodes[k + 1]);
                let (l, h) = union(&a, &b);
                nodes.push(BvhNode {
                    lo: l,
                    hi: h,
                    first: k as u32,
                    count: 0,
                });
                spans.push([spans[k][0], spans[k + 1][1]]);
            } else {
                // An odd node out moves up unchanged.
                let a = nodes[k];
                nodes.push(a);
                spans.push(spans[k]);
            }
            k += 2;
        }
        (lo, hi) = (hi, nodes.len());
    }
    (nodes, spans)
}

impl Edges {
    /// Indexes the edges of closed `contours` (zero-length edges are skipped).
    pub fn new(contours: &[Contour]) -> Edges {
        let total: usize = contours.iter().map(|c| c.len()).sum();
        let mut segs: Vec<Segment> = Vec::with_capacity(total);
        let mut ends = Vec::with_capacity(contours.len());
        let mut next: Vec<u32> = Vec::with_capacity(total);
        let mut prev: Vec<u32> = Vec::with_capacity(total);
        for c in contours {
            // The start points (repeated ones left out), each one also the end point of the
            // edge before it; the last edge's end point is set once the contour is done.
            let first = segs.len();
            let Some((&p0, rest)) = c.split_first() else {
                ends.push(segs.len());
                continue;
            };
            segs.push([p0[0], p0[1], 0.0, 0.0]);
            let mut last = p0;
            for &p in rest {
                if p != last {
                    if let Some(s) = segs.last_mut() {
                        s[2] = p[0];
                        s[3] = p[1];
                    }
                    segs.push([p[0], p[1], 0.0, 0.0]);
                    last = p;
                }
            }
            while segs.len() > first + 1 && segs[segs.len() - 1][..2] == segs[first][..2] {
                segs.pop();
            }
            let n = segs.len() - first;
            if n < 2 {
                segs.truncate(first);
                ends.push(segs.len());
                continue;
            }
            let end = first + n;
            next.extend((first as u32 + 1)..end as u32);
            next.push(first as u32);
            prev.push(end as u32 - 1);
            prev.extend(first as u32..end as u32 - 1);
            let (x, y) = (segs[first][0], segs[first][1]);
            segs[end - 1][2] = x;
            segs[end - 1][3] = y;
            ends.push(segs.len());
        }
        let (nodes, spans) = if segs.is_empty() {
            (Vec::new(), Vec::new())
        } else {
            build(&segs, &ends)
        };
        // Horizontal bands for the inside test, about 4 edges deep each.
        let (y0, y1) = match nodes.last() {
            Some(n) => (n.lo[1], n.hi[1]),
            None => (0.0, 1.0),
        };
        let nb = (segs.len() / 4).clamp(1, 4096);
        let band_inv = if y1 > y0 { nb as f64 / (y1 - y0) } else { 0.0 };
        // `y ≥ y0` (the lowest point), so the product is not negative and far below 2^63:
        // truncating through `i64` (cheaper than through `usize`) gives what `as usize` gives.
        let top = nb as i64 - 1;
        let band_of = |y: f64| (((y - y0) * band_inv) as i64).min(top) as u32;
        // The band of each contour point (the start of each edge), once; edge `v` spans
        // the bands of its two points.
        let vband: Vec<u32> = segs.iter().map(|s| band_of(s[1])).collect();
        // Edges per band: a difference array (+1 at an edge's first band, −1 after its
        // last), then each band's first slot (exclusive prefix sums).
        let mut start = vec![0u32; nb + 1];
        for (&a, &w) in vband.iter().zip(&next) {
            let b = vband[w as usize];
            let (a, b) = if a <= b { (a, b) } else { (b, a) };
            start[a as usize] = start[a as usize].wrapping_add(1);
            start[b as usize + 1] = start[b as usize + 1].wrapping_sub(1);
        }
        let (mut active, mut total) = (0u32, 0u32);
        for s in start[..nb].iter_mut() {
            active = active.wrapping_add(*s);
            *s = total;
            total += active;
        }
        start[nb] = total;
        // Each edge into the bands it spans, in edge order; `start[k]` moves to the end of
        // band k (the start of band k + 1), so a shift by one gives the bands' starts.
        let mut items = vec![0u32; total as usize];
        for (v, (&a, &w)) in vband.iter().zip(&next).enumerate() {
            let b = vband[w as usize];
            let (a, b) = if a <= b { (a, b) } else { (b, a) };
            for s in &mut start[a as usize..=b as usize] {
                items[*s as usize] = v as u32;
                *s += 1;
            }
        }
        start.copy_within(0..nb, 1);
        start[0] = 0;
        Edges {
            segs,
            next,
            prev,
            nodes,
            spans,
            band_y0: y0,
            band_inv,
            band_start: start,
            band_items: items,
        }
    }

    /// The box around all edges, `(lower corner, upper corner)`; `None` when there are
    /// none.
    pub(in crate::plan::analysis) fn bounds(&self) -> Option<([f64; 2], [f64; 2])> {
        self.nodes.last().map(|n| (n.lo, n.hi))
    }

    /// Distance from `p` to the nearest edge.
    #[cfg(test)]
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        self.nearest(p, u32::MAX).0
    }

    /// Distance from `p` to the nearest edge and that edge's index; `hint`, an edge likely
    /// to be near (or `u32::MAX`), bounds the search from the start.
    pub(super) fn nearest(&self, p: [f64; 2], hint: u32) -> (f64, u32) {
        let start = match self.segs.get(hint as usize) {
            Some(s) => (seg_d2(p, s), hint),
            None => (f64::INFINITY, u32::MAX),
        };
        self.nearest_from(p, start)
    }

    /// [`Edges::nearest`] started from a known edge `(squared distance to p, index)`.
    pub(super) fn nearest_from(&self, p: [f64; 2], (mut best, mut arg): (f64, u32)) -> (f64, u32) {
        if self.nodes.is_empty() {
            return (f64::INFINITY, u32::MAX);
        }
        // Depth first, nearer child first: the node visited and its box distance, and the
        // farther children left for later with theirs (each box distance computed once).
        // A node is skipped when its box is no nearer than the best (which only shrinks).
        // At most one node per level waits: 32 hold any tree over u32-indexed edges.
        let mut wait_i = [0u32; 32];
        let mut wait_d = [0.0f64; 32];
        let mut sp = 0usize;
        let root = self.nodes.len() - 1;
        let (mut i, mut dn) = (root as u32, box_d2(p, &self.nodes[root]));
        loop {
            if dn < best {
                let n = &self.nodes[i as usize];
                if n.count > 0 {
                    let f = n.first as usize;
                    for (k, s) in self.segs[f..f + n.count as usize].iter().enumerate() {
                        if let Some(d) = seg_d2_below(p, s, best) {
                            best = d;
                            arg = (f + k) as u32;
                        }
                    }
                } else {
                    let (l, r) = (n.first, n.first + 1);
                    let dl = box_d2(p, &self.nodes[l as usize]);
                    let dr = box_d2(p, &self.nodes[r as usize]);
                    let (far, near) = if dl <= dr {
                        ((r, dr), (l, dl))
                    } else {
                        ((l, dl), (r, dr))
                    };
                    if far.1 < best {
                        if sp == wait_i.len() {
                            // Deeper than any tree over u32-indexed edges; correct anyway.
                            return self.nearest_brute(p);
                        }
                        (wait_i[sp], wait_d[sp]) = far;
                        sp += 1;
                    }
                    (i, dn) = near;
                    continue;
                }
            }
            if sp == 0 {
                break;
            }
            sp -= 1;
            (i, dn) = (wait_i[sp], wait_d[sp]);
        }
        (best.sqrt(), arg)
    }

    /// A point inside the section on the inward normal through the middle of edge `v`
    /// (the interior is on the edges' left), about half-way to the wall across: steps
    /// along the normal from `s0`, doubling while the edge is still the nearest wall (up
    /// to `cap`), then half-way between the step and the wall across. With its depth and
    /// nearest edge; `None` when it is not inside the section.
    pub(super) fn ridge_probe(&self, v: u32, s0: f64, cap: f64) -> Option<([f64; 2], f64, u32)> {
        let g = self.segs[v as usize];
        let u = unit([g[2] - g[0], g[3] - g[1]])?;
        let (m, n) = ([0.5 * (g[0] + g[2]), 0.5 * (g[1] + g[3])], [-u[1], u[0]]);
        let at = |s: f64| [m[0] + n[0] * s, m[1] + n[1] * s];
        let depth = |s: f64| {
            let p = at(s);
            self.nearest_from(p, (seg_d2(p, &g), v))
        };
        let mut s = s0;
        let (mut d, mut near) = depth(s);
        while d >= 0.999 * s && s < cap {
            s *= 2.0;
            (d, near) = depth(s);
        }
        if d < 0.999 * s {
            let s2 = 0.5 * (s + d);
            let (d2, n2) = depth(s2);
            if d2 > d {
                (s, d, near) = (s2, d2, n2);
            }
        }
        let p = at(s);
        self.inside(p).then_some((p, d, near))
    }

    /// The boundary point nearest to `p` among those on the far side of `p` from `q`
    /// (in the half-plane `(x − p)·(q − p) ≤ 0`) and closer than `limit`, if any.
    /// `seed`, an edge likely to hold such a point (or `u32::MAX`), bounds the search
    /// from the start.
    pub(super) fn nearest_behind(
        &self,
        p: [f64; 2],
        q: [f64; 2],
        limit: f64,
        seed: u32,
    ) -> Option<([f64; 2], u32)> {
        if self.nodes.is_empty() {
            return None;
        }
        let u = [q[0] - p[0], q[1] - p[1]];
        let side = |x: f64, y: f64| (x - p[0]) * u[0] + (y - p[1]) * u[1];
        let mut best = limit * limit;
        let mut arg = None;
        if seed != u32::MAX {
            // Its point nearest to p, if that is behind p (else the seed does not count).
            let x = self.closest_point(seed, p);
            let dd = d2(x, p);
            if side(x[0], x[1]) <= 0.0 && dd < best {
                (best, arg) = (dd, Some((x, seed)));
            }
        }
        // Nodes to visit with their box distance, computed once (when pushed).
        let mut stack: [(u32, f64); 64] = [(0, 0.0); 64];
        let root = self.nodes.len() - 1;
        stack[0] = (root as u32, box_d2(p, &self.nodes[root]));
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let (i, dn) = stack[sp];
            if dn >= best {
                continue;
            }
            let n = &self.nodes[i as usize];
            // Boxes wholly on q's side hold nothing behind p.
            // (Its lowest corner: centre minus half-extents; rounding can only drop a
            // point exactly on the line, which is a choice of cover point, not a bound.)
            let lo_side = side(0.5 * (n.lo[0] + n.hi[0]), 0.5 * (n.lo[1] + n.hi[1]))
                - 0.5 * ((n.hi[0] - n.lo[0]) * u[0].abs() + (n.hi[1] - n.lo[1]) * u[1].abs());
            if lo_side > 0.0 {
                continue;
            }
            if n.count > 0 {
                let f = n.first as usize;
                for (k, sg) in self.segs[f..f + n.count as usize].iter().enumerate() {
                    let (ga, gb) = (side(sg[0], sg[1]), side(sg[2], sg[3]));
                    if ga > 0.0 && gb > 0.0 {
                        continue;
                    }
                    // Part of the segment behind p: t in [t0, t1].
                    let (mut t0, mut t1) = (0.0f64, 1.0f64);
                    if ga > 0.0 {
                        t0 = ga / (ga - gb);
                    } else if gb > 0.0 {
                        t1 = ga / (ga - gb);
                    }
                    let (dx, dy) = (sg[2] - sg[0], sg[3] - sg[1]);
                    let l2 = dx * dx + dy * dy;
                    let t = if l2 > 0.0 {
                        (((p[0] - sg[0]) * dx + (p[1] - sg[1]) * dy) / l2).clamp(t0, t1)
                    } else {
                        0.0
                    };
                    let x = [sg[0] + t * dx, sg[1] + t * dy];
                    let dd = d2(x, p);
                    if dd < best {
                        best = dd;
                        arg = Some((x, (f + k) as u32));
                    }
                }
            } else {
                let (l, r) = (n.first, n.first + 1);
                let dl = box_d2(p, &self.nodes[l as usize]);
                let dr = box_d2(p, &self.nodes[r as usize]);
                let (far, near) = if dl <= dr {
                    ((r, dr), (l, dl))
                } else {
                    ((l, dl), (r, dr))
                };
                if sp + 2 > stack.len() {
                    return None;
                }
                stack[sp] = far;
                stack[sp + 1] = near;
                sp += 2;
            }
        }
        arg
    }

    /// Boundary points about `h` away from `q` (a point of edge `i`) along its contour,
    /// one each way: the first contour points at least `h` from `q` (at most 64 points
    /// walked).
    pub(super) fn along(&self, i: u32, q: [f64; 2], h: f64) -> [[f64; 2]; 2] {
        let h2 = h * h;
        let mut k = self.next[i as usize];
        let mut fwd = self.vert(k);
        for _ in 1..63 {
            if d2(fwd, q) >= h2 {
                break;
            }
            k = self.next[k as usize];
            fwd = self.vert(k);
        }
        let mut k = i;
        let mut back = self.vert(k);
        for _ in 1..64 {
            if d2(back, q) >= h2 {
                break;
            }
            k = self.prev[k as usize];
            back = self.vert(k);
        }
        [fwd, back]
    }

    /// From edge `v`, along its contour while the points get nearer to `p` (a local
    /// minimum of the distance to the contour points, at most 64 steps), then the nearer
    /// of the two edges at that point: `(squared distance, edge)`. A cheap guess of the
    /// nearest edge of this wall; any edge gives a valid bound.
    pub(super) fn descend(&self, mut v: u32, p: [f64; 2]) -> (f64, u32) {
        let mut d = d2(self.vert(v), p);
        for dir in [&self.next, &self.prev] {
            let mut moved = false;
            for _ in 0..64 {
                let w = dir[v as usize];
                let dw = d2(self.vert(w), p);
                if dw < d {
                    (d, v) = (dw, w);
                    moved = true;
                } else {
                    break;
                }
            }
            if moved {
                break;
            }
        }
        let w = self.prev[v as usize];
        let (a, b) = (
            seg_d2(p, &self.segs[v as usize]),
            seg_d2(p, &self.segs[w as usize]),
        );
        if b < a {
            (b, w)
        } else {
            (a, v)
        }
    }

    /// Start point of edge `v`.
    #[inline]
    pub(super) fn vert(&self, v: u32) -> [f64; 2] {
        let s = &self.segs[v as usize];
        [s[0], s[1]]
    }

    /// The point of edge `i` nearest to `p`.
    #[inline]
    pub(super) fn closest_point(&self, i: u32, p: [f64; 2]) -> [f64; 2] {
        let s = &self.segs[i as usize];
        let (dx, dy) = (s[2] - s[0], s[3] - s[1]);
        let l2 = dx * dx + dy * dy;
        let t = if l2 > 0.0 {
            (((p[0] - s[0]) * dx + (p[1] - s[1]) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        [s[0] + t * dx, s[1] + t * dy]
    }

    fn nearest_brute(&self, p: [f64; 2]) -> (f64, u32) {
        let mut best = (f64::INFINITY, u32::MAX);
        for (i, s) in self.segs.iter().enumerate() {
            let d = seg_d2(p, s);
            if d < best.0 {
                best = (d, i as u32);
            }
        }
        (best.0.sqrt(), best.1)
    }

    /// Nonzero-winding inside test.
    pub fn inside(&self, p: [f64; 2]) -> bool {
        let Some(root) = self.nodes.last() else {
            return false;
        };
        if p[1] < root.lo[1] || p[1] > root.hi[1] || p[0] < root.lo[0] || p[0] > root.hi[0] {
            return false;
        }
        let nb = self.band_start.len() - 1;
        let k = (((p[1] - self.band_y0) * self.band_inv) as usize).min(nb - 1);
        let mut w = 0i32;
        for &i in &self.band_items[self.band_start[k] as usize..self.band_start[k + 1] as usize] {
            let s = &self.segs[i as usize];
            let (ay, by) = (s[1], s[3]);
            // Upward (`ay ≤ y < by`) or downward (`by ≤ y < ay`) across the line.
            let up = ay <= p[1];
            if up != (by <= p[1]) {
                let x = s[0] + (p[1] - ay) * (s[2] - s[0]) / (by - ay);
                if x > p[0] {
                    w += if up { 1 } else { -1 };
                }
            }
        }
        w != 0
    }

    /// Signed distance: positive inside, negative outside.
    #[cfg(test)]
    pub fn signed_distance(&self, p: [f64; 2]) -> f64 {
        let d = self.distance(p);
        if self.inside(p) {
            d
        } else {
            -d
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::analysis::test_support::{rect, star, xorshift};
    use crate::plan::analysis::{max_fill_distance_with, PRECISION_MM};

    #[test]
    fn repeated_points_are_left_out() {
        // Repeated consecutive points (and a closing point equal to the first) add no
        // edges: same edges, same result; a contour of one distinct point has none.
        let clean = rect(0.0, 0.0, 20.0, 10.0);
        let mut rep = vec![clean[0], clean[0], clean[1], clean[2], clean[2], clean[3]];
        rep.push(clean[0]);
        let (a, b) = (
            Edges::new(std::slice::from_ref(&clean)),
            Edges::new(&[rep, vec![[5.0, 5.0]; 3]]),
        );
        assert_eq!(a.segs, b.segs);
        assert_eq!((&a.next, &a.prev), (&b.next, &b.prev));
        assert_eq!(a.next, vec![1, 2, 3, 0]);
        assert_eq!(
            max_fill_distance_with(&a, PRECISION_MM),
            max_fill_distance_with(&b, PRECISION_MM)
        );
    }

    #[test]
    fn inside_and_distance() {
        let sq = [rect(0.0, 0.0, 10.0, 10.0), {
            let mut h = rect(4.0, 4.0, 6.0, 6.0);
            h.reverse();
            h
        }];
        let e = Edges::new(&sq);
        assert!(e.inside([1.0, 1.0]));
        assert!(!e.inside([5.0, 5.0]));
        assert!(!e.inside([11.0, 5.0]));
        assert!((e.signed_distance([1.0, 2.0]) - 1.0).abs() < 1e-12);
        assert!((e.signed_distance([5.0, 5.0]) + 1.0).abs() < 1e-12);
        assert!((e.signed_distance([13.0, 14.0]) + 5.0).abs() < 1e-12);
    }

    #[test]
    fn band_index_matches_the_reference_construction() {
        // The band index (difference array, prefix sums, one fill pass) against the direct
        // construction it replaced: every band's edges, in edge order.
        let mut rnd = xorshift(0xba5d_0001_u64);
        for case in 0..60 {
            let mut contours: Vec<Contour> = Vec::new();
            for _ in 0..1 + case % 4 {
                let (cx, cy) = (rnd() * 20.0, rnd() * 20.0);
                let n = 3 + (rnd() * 60.0) as usize;
                contours.push(star(&mut rnd, [cx, cy], (0.1, 6.1), n, true));
            }
            if case % 5 == 0 {
                contours.push(rect(0.0, 0.0, 30.0, 0.5));
            }
            let e = Edges::new(&contours);
            let root = e.nodes.last().unwrap();
            let nb = e.band_start.len() - 1;
            let band_of = |y: f64| ((((y - root.lo[1]) * e.band_inv) as usize).min(nb - 1)) as u32;
            let mut want: Vec<Vec<u32>> = vec![Vec::new(); nb];
            for (v, s) in e.segs.iter().enumerate() {
                let (a, b) = (band_of(s[1]), band_of(s[3]));
                for k in a.min(b)..=a.max(b) {
                    want[k as usize].push(v as u32);
                }
            }
            for (k, w) in want.iter().enumerate() {
                let got = &e.band_items[e.band_start[k] as usize..e.band_start[k + 1] as usize];
                assert_eq!(got, w.as_slice(), "case {case} band {k}");
            }
            assert_eq!(e.band_start[nb] as usize, e.band_items.len());
        }
    }
}
