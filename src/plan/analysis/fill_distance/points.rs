//! Cover tests of a square by discs around boundary points: whether every point of the
//! square lies within a radius of one of the points, and a point that does not.

use super::plane::d2;

/// Most boundary points added to a cell's own cover test when its walls' points do not
/// cover it (`Search::cover_more`): each one the boundary point nearest to a point the test
/// found uncovered (a third wall near a peak, or a wall point between the samples).
pub(super) const MAX_EXTRA_COVER_POINTS: usize = 3;

/// Most points of a cover test: the six wall points and the [`MAX_EXTRA_COVER_POINTS`] ones.
pub(super) const MAX_COVER_POINTS: usize = 6 + MAX_EXTRA_COVER_POINTS;

/// [`uncovered`], but only after [`exceeds`] (cheaper when the square is covered) has
/// found the square not covered. A corner (or centre) [`exceeds`] found far from every
/// point is the point [`uncovered`] gives (the same points left out, the same candidates
/// first, in the same order); otherwise the corners are known not to be far and
/// [`uncovered`] starts after them.
pub(super) fn witness(c: [f64; 2], h: f64, q: &[[f64; 2]], t2: f64) -> Option<[f64; 2]> {
    match cover_test(c, h, q, t2) {
        CoverOutcome::Covered => None,
        CoverOutcome::Corner(x) => Some(x),
        CoverOutcome::Edge(_) | CoverOutcome::Inside => uncovered(c, h, q, t2, false),
    }
}

/// What [`cover_test`] found.
enum CoverOutcome {
    /// The discs cover the square.
    Covered,
    /// The square's centre (no disc meets the square) or the first of its corners (in
    /// [`uncovered`]'s order) that no disc holds.
    Corner([f64; 2]),
    /// A point of an edge that no disc holds (the corners are all held).
    Edge([f64; 2]),
    /// Two circles cross inside the square where no third disc holds (corners and edges
    /// are all held).
    Inside,
}

/// [`cover_test`]: whether some point of the square `[c ± h]` is farther than `sqrt(t2)`
/// from every point of `q` (at most [`MAX_COVER_POINTS`]) and, when that was found on an
/// edge or at a corner, such a point. When none is, the discs of radius `sqrt(t2)` around
/// the points cover the square: around boundary points, no point of it is deeper.
pub(super) fn exceeds(c: [f64; 2], h: f64, q: &[[f64; 2]], t2: f64) -> (bool, Option<[f64; 2]>) {
    match cover_test(c, h, q, t2) {
        CoverOutcome::Covered => (false, None),
        CoverOutcome::Corner(x) | CoverOutcome::Edge(x) => (true, Some(x)),
        CoverOutcome::Inside => (true, None),
    }
}

/// [`exceeds`] from the union of the discs itself, in `O(n²)` instead of the
/// `O(n³)` candidates of [`uncovered`], with a witness when one comes cheaply: the discs
/// cover the square if and only if (up to ties) their chords cover its four edges and
/// every crossing of two circles inside it lies strictly inside a third disc
/// (docs/PLANNING.md, "The search", step 4). Returns what decided it, the tests made in
/// this order: a disc holding the square, the centre when no disc meets it, the corners,
/// the edges (a sweep over the chords), the crossings.
fn cover_test(c: [f64; 2], h: f64, q: &[[f64; 2]], t2: f64) -> CoverOutcome {
    let mut p = [[0.0f64; 2]; MAX_COVER_POINTS];
    let mut n = 0;
    for qj in q {
        let v = [qj[0] - c[0], qj[1] - c[1]];
        let (ax, ay) = (v[0].abs(), v[1].abs());
        // As in `uncovered`: one disc holds the square, or a disc misses it.
        if (ax + h).powi(2) + (ay + h).powi(2) <= t2 {
            return CoverOutcome::Covered;
        }
        if (ax - h).max(0.0).powi(2) + (ay - h).max(0.0).powi(2) > t2 {
            continue;
        }
        p[n] = v;
        n += 1;
    }
    let at = |x: [f64; 2]| [c[0] + x[0], c[1] + x[1]];
    if n == 0 {
        return CoverOutcome::Corner(at([0.0, 0.0]));
    }
    let p = &p[..n];
    // The corners, each with the first point whose disc holds it.
    let corners = [[-h, -h], [h, -h], [-h, h], [h, h]];
    let mut by = [0; 4];
    for (k, &x) in corners.iter().enumerate() {
        match p.iter().position(|pj| d2(x, *pj) <= t2) {
            Some(j) => by[k] = j,
            None => return CoverOutcome::Corner(at(x)),
        }
    }
    // The edges: coordinate `b` fixed at `s`, coordinate `a` running over [−h, h], from
    // corner `k0` to corner `k1`.
    let (mut lo, mut hi) = ([0.0f64; MAX_COVER_POINTS], [0.0f64; MAX_COVER_POINTS]);
    for (a, b, s, k0, k1) in [
        (0, 1, -h, 0, 1),
        (0, 1, h, 2, 3),
        (1, 0, -h, 0, 2),
        (1, 0, h, 1, 3),
    ] {
        // A disc holding both ends holds the edge.
        let (c0, c1) = (corners[k0], corners[k1]);
        if by[k0] == by[k1] || d2(c1, p[by[k0]]) <= t2 || d2(c0, p[by[k1]]) <= t2 {
            continue;
        }
        let mut m = 0;
        for pj in p {
            let dy = pj[b] - s;
            let r = t2 - dy * dy;
            if r > 0.0 {
                let w = r.sqrt();
                (lo[m], hi[m]) = (pj[a] - w, pj[a] + w);
                m += 1;
            }
        }
        // The chords that start by `reach` are used up: they end by the next `reach`, so
        // only the others are kept for the following rounds.
        let mut reach = -h;
        while reach < h {
            let mut next = reach;
            let mut kept = 0;
            for k in 0..m {
                if lo[k] <= reach {
                    if hi[k] > next {
                        next = hi[k];
                    }
                } else {
                    (lo[kept], hi[kept]) = (lo[k], hi[k]);
                    kept += 1;
                }
            }
            m = kept;
            if next == reach {
                // Nothing goes beyond `reach`: the edge is uncovered up to the next start.
                let mut end = h;
                for &l in &lo[..m] {
                    if l > reach && l < end {
                        end = l;
                    }
                }
                let mut x = [0.0; 2];
                (x[a], x[b]) = (0.5 * (reach + end), s);
                return CoverOutcome::Edge(at(x));
            }
            reach = next;
        }
    }
    // Inside: the crossings of two circles.
    for i in 0..n {
        for j in i + 1..n {
            let d = [p[j][0] - p[i][0], p[j][1] - p[i][1]];
            let dd = d[0] * d[0] + d[1] * d[1];
            if dd >= 4.0 * t2 || dd == 0.0 {
                continue;
            }
            let f = (t2 / dd - 0.25).sqrt();
            let m = [0.5 * (p[i][0] + p[j][0]), 0.5 * (p[i][1] + p[j][1])];
            for g in [-f, f] {
                let v = [m[0] - g * d[1], m[1] + g * d[0]];
                if v[0].abs() <= h
                    && v[1].abs() <= h
                    && p.iter()
                        .enumerate()
                        .all(|(k, pk)| k == i || k == j || d2(v, *pk) > t2)
                {
                    return CoverOutcome::Inside;
                }
            }
        }
    }
    CoverOutcome::Covered
}

/// [`exceeds`] with a witness: a point of the square `[c ± h]` farther than
/// `sqrt(t2)` from every point of `q` (at most [`MAX_COVER_POINTS`] points), or `None` when the
/// discs of radius `sqrt(t2)` around the points cover the square.
///
/// `x ↦ min_j |x − q_j|²` is convex on each Voronoi cell of the points, so its maximum over
/// the square is at a corner, where a bisector of two points crosses an edge of the square,
/// or at a circumcentre of three points inside it: the test checks those candidates (in a
/// fixed order) and stops at the first one that is far from every point.
///
/// The corners are tried only when `corners` (else they must be known to be held by
/// some disc: the result is the same).
fn uncovered(c: [f64; 2], h: f64, q: &[[f64; 2]], t2: f64, corners: bool) -> Option<[f64; 2]> {
    let mut p = [[0.0f64; 2]; MAX_COVER_POINTS];
    let mut r2 = [0.0f64; MAX_COVER_POINTS];
    let mut n = 0;
    for qj in q {
        let v = [qj[0] - c[0], qj[1] - c[1]];
        let (ax, ay) = (v[0].abs(), v[1].abs());
        // A point whose disc holds the whole square covers it alone; one whose disc
        // misses the square covers none of it and can be left out.
        if (ax + h).powi(2) + (ay + h).powi(2) <= t2 {
            return None;
        }
        if (ax - h).max(0.0).powi(2) + (ay - h).max(0.0).powi(2) > t2 {
            continue;
        }
        p[n] = v;
        r2[n] = v[0] * v[0] + v[1] * v[1];
        n += 1;
    }
    // The witness, back in the section's coordinates.
    let at = |x: [f64; 2]| Some([c[0] + x[0], c[1] + x[1]]);
    if n == 0 {
        return at([0.0, 0.0]);
    }
    let p = &p[..n];
    // True when x is farther than t from all points.
    let far = |x: [f64; 2]| p.iter().all(|pj| d2(x, *pj) > t2);
    if corners {
        for x in [[-h, -h], [h, -h], [-h, h], [h, h]] {
            if far(x) {
                return at(x);
            }
        }
    }
    for i in 0..n {
        for j in i + 1..n {
            let nv = [p[j][0] - p[i][0], p[j][1] - p[i][1]];
            let k = 0.5 * (r2[j] - r2[i]);
            if nv[1] != 0.0 {
                for x in [-h, h] {
                    let y = (k - nv[0] * x) / nv[1];
                    if y.abs() <= h && far([x, y]) {
                        return at([x, y]);
                    }
                }
            }
            if nv[0] != 0.0 {
                for y in [-h, h] {
                    let x = (k - nv[1] * y) / nv[0];
                    if x.abs() <= h && far([x, y]) {
                        return at([x, y]);
                    }
                }
            }
            for m in j + 1..n {
                let (a, b, cc) = (p[i], p[j], p[m]);
                let den =
                    2.0 * (a[0] * (b[1] - cc[1]) + b[0] * (cc[1] - a[1]) + cc[0] * (a[1] - b[1]));
                if den != 0.0 {
                    let u = [
                        (r2[i] * (b[1] - cc[1]) + r2[j] * (cc[1] - a[1]) + r2[m] * (a[1] - b[1]))
                            / den,
                        (r2[i] * (cc[0] - b[0]) + r2[j] * (a[0] - cc[0]) + r2[m] * (b[0] - a[0]))
                            / den,
                    ];
                    if u[0].abs() <= h && u[1].abs() <= h && far(u) {
                        return at(u);
                    }
                }
            }
        }
    }
    None
}

/// Points of a square that its cover test found uncovered, each with the squared radius
/// it was found at: farther than that from every point tested (the first `n` points and
/// any `Search::cover_more` added), so from the first `n` too. A child square holding one is
/// not covered by those points either: its own test is skipped.
#[derive(Clone, Copy, Default)]
pub(super) struct Witnesses {
    x: [([f64; 2], f64); 1 + MAX_EXTRA_COVER_POINTS],
    n: usize,
}

impl Witnesses {
    /// Forgets them all.
    #[inline]
    pub(super) fn clear(&mut self) {
        self.n = 0;
    }

    #[inline]
    pub(super) fn push(&mut self, x: [f64; 2], t2: f64) {
        if self.n < self.x.len() {
            self.x[self.n] = (x, t2);
            self.n += 1;
        }
    }

    /// Whether one of them lies in the square `[c ± h]` and is farther than `sqrt(t2)`
    /// from every point of `q` (checked again only when `t2` is larger than the radius it
    /// was found at).
    #[inline]
    pub(super) fn uncover(&self, c: [f64; 2], h: f64, q: &[[f64; 2]], t2: f64) -> bool {
        self.x[..self.n].iter().any(|&(w, w2)| {
            (w[0] - c[0]).abs() <= h
                && (w[1] - c[1]).abs() <= h
                && (t2 <= w2 || q.iter().all(|p| d2(w, *p) > t2))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::analysis::test_support::xorshift;

    /// The largest squared distance from a point of a `(steps + 1)²` grid over the square
    /// `[c ± h]` to its nearest point of `q`.
    fn grid_max2(q: &[[f64; 2]], c: [f64; 2], h: f64, steps: usize) -> f64 {
        let step = 2.0 * h / steps as f64;
        let mut max: f64 = 0.0;
        for i in 0..=steps {
            for j in 0..=steps {
                let x = [c[0] - h + step * i as f64, c[1] - h + step * j as f64];
                max = max.max(q.iter().map(|&p| d2(x, p)).fold(f64::INFINITY, f64::min));
            }
        }
        max
    }

    /// `n` random points in `[-2, 2]²`.
    fn random_points(rnd: &mut impl FnMut() -> f64, n: usize) -> Vec<[f64; 2]> {
        (0..n)
            .map(|_| [4.0 * rnd() - 2.0, 4.0 * rnd() - 2.0])
            .collect()
    }

    #[test]
    fn exceeds_matches_a_grid() {
        // Random point sets and squares: the decision must agree with the largest
        // min-distance found on a fine grid of the square, away from the threshold.
        let mut rnd = xorshift(0x2545f4914f6cdd1d);
        let mut decided = [0, 0];
        for _ in 0..300 {
            let n = 1 + (rnd() * 6.0) as usize;
            let q = random_points(&mut rnd, n);
            let c = [rnd() - 0.5, rnd() - 0.5];
            let h = 0.1 + rnd();
            let step = 2.0 * h / 60.0;
            let grid_max = grid_max2(&q, c, h, 60).sqrt();
            // The true maximum is in [grid_max, grid_max + step].
            let t = grid_max * (0.5 + rnd());
            if (t - grid_max).abs() < 2.0 * step {
                continue;
            }
            let exceed = exceeds(c, h, &q, t * t).0;
            assert_eq!(exceed, grid_max > t, "{q:?} {c:?} {h} {t} {grid_max}");
            decided[exceed as usize] += 1;
        }
        assert!(decided[0] > 50 && decided[1] > 50, "{decided:?}");
    }

    #[test]
    fn exceeds_agrees_with_the_candidates() {
        // The cover decided from the edges' chords and the circles' crossings against
        // the candidates of `uncovered` (corners, bisector crossings, circumcentres), on
        // random squares and points with radii around the covering one; and its witness
        // lies in the square, farther than the radius from every point.
        let mut rnd = xorshift(0x0e8c_ee45_1234_5678);
        let mut seen = [0, 0, 0];
        for case in 0..20000 {
            let n = 1 + (rnd() * MAX_COVER_POINTS as f64) as usize;
            let c = [rnd() - 0.5, rnd() - 0.5];
            let h = 0.1 + rnd();
            let (q, t): (Vec<[f64; 2]>, f64) = if case % 2 == 0 {
                (random_points(&mut rnd, n), 0.3 + 2.0 * rnd())
            } else {
                // Points around the square's centre: the discs often cover its edges
                // and leave a hole inside.
                let r = h * (1.0 + rnd());
                let q = (0..n)
                    .map(|k| {
                        let a = std::f64::consts::TAU * (k as f64 + 0.3 * rnd()) / n as f64;
                        [c[0] + r * a.cos(), c[1] + r * a.sin()]
                    })
                    .collect();
                (q, r * (0.8 + 0.4 * rnd()))
            };
            let (exceed, w) = exceeds(c, h, &q, t * t);
            assert_eq!(
                exceed,
                uncovered(c, h, &q, t * t, true).is_some(),
                "{q:?} {c:?} {h} {t}"
            );
            assert_eq!(witness(c, h, &q, t * t), uncovered(c, h, &q, t * t, true));
            if let Some(w) = w {
                assert!(exceed);
                let inside = |x: f64| x.abs() <= h * (1.0 + 1e-12);
                assert!(
                    inside(w[0] - c[0]) && inside(w[1] - c[1]),
                    "{w:?} {c:?} {h}"
                );
                assert!(q.iter().all(|&p| d2(w, p) > t * t), "{w:?} {q:?} {t}");
            }
            seen[usize::from(exceed) + usize::from(w.is_some())] += 1;
        }
        assert!(seen.iter().all(|&k| k > 500), "{seen:?}");
    }

    #[test]
    fn uncovered_gives_a_point_of_the_square_far_from_every_point() {
        // The witness of a failed cover test must lie in the square and be farther than
        // the radius from every point (cover_more adds the boundary point nearest to it);
        // when there is none the square is covered (checked on a grid).
        let mut rnd = xorshift(0x51a2c3d4e5f60718);
        let mut seen = [0, 0];
        for _ in 0..400 {
            let n = 1 + (rnd() * MAX_COVER_POINTS as f64) as usize;
            let q = random_points(&mut rnd, n);
            let c = [rnd() - 0.5, rnd() - 0.5];
            let h = 0.1 + rnd();
            let t = 0.3 + 2.0 * rnd();
            match uncovered(c, h, &q, t * t, true) {
                Some(w) => {
                    assert!(
                        (w[0] - c[0]).abs() <= h * (1.0 + 1e-12)
                            && (w[1] - c[1]).abs() <= h * (1.0 + 1e-12),
                        "{w:?} outside {c:?} ± {h}"
                    );
                    assert!(q.iter().all(|&p| d2(w, p) > t * t), "{w:?} {q:?} {t}");
                    seen[1] += 1;
                }
                None => {
                    let m = grid_max2(&q, c, h, 40);
                    assert!(m <= t * t * (1.0 + 1e-9), "uncovered: {q:?} {c:?} {h} {t}");
                    seen[0] += 1;
                }
            }
        }
        assert!(seen[0] > 50 && seen[1] > 50, "{seen:?}");
    }
}
