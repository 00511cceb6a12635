//! Islands: the connected regions of a layer's lit pixels that share no pixel with the
//! layer below's (they would print onto nothing).

use super::LitRuns;

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// The runs of `cur` that share no pixel with a run of `prev` in the same row (indexes
/// into `cur.runs`, increasing), into `out`.
fn unsupported_runs(cur: &LitRuns, prev: &LitRuns, out: &mut Vec<u32>) {
    out.clear();
    let (rc, rp) = (&cur.runs, &prev.runs);
    // Both sorted by row then column, and a row's runs are disjoint: one merge-walk.
    let mut j = 0;
    for (i, r) in rc.iter().enumerate() {
        // Skip the runs below that end before this one starts (in this row or earlier).
        while j < rp.len() && (rp[j][0] < r[0] || (rp[j][0] == r[0] && rp[j][2] <= r[1])) {
            j += 1;
        }
        if j == rp.len() || rp[j][0] != r[0] || rp[j][1] >= r[2] {
            out.push(i as u32);
        }
    }
}

/// Number of connected regions (4-connected) of the lit pixels `cur` that share no pixel
/// with the lit pixels `prev` of the layer below. A region is supported when one of its
/// runs is; so only the runs that rest on nothing (usually none, else a few along the
/// layer's new parts) are joined into regions (union-find over them), each region marked
/// supported when one of its runs touches a supported run in the row above or below.
pub fn islands(cur: &LitRuns, prev: &LitRuns) -> u32 {
    // Empty (no allocation) in the usual case.
    let mut unsup = Vec::new();
    unsupported_runs(cur, prev, &mut unsup);
    if unsup.is_empty() {
        return 0;
    }
    let rc = &cur.runs;
    let u = &unsup[..];
    let mut parent: Vec<u32> = (0..u.len() as u32).collect();
    let mut supported = vec![false; u.len()];
    for (a, &i) in u.iter().enumerate() {
        let [row, s, e] = rc[i as usize];
        for nrow in [row.checked_sub(1), Some(row + 1)].into_iter().flatten() {
            // The runs of row `nrow` that share a column with `[s, e)`: sorted by row,
            // then by start (and end: a row's runs are disjoint).
            let mut k = rc.partition_point(|r| r[0] < nrow || (r[0] == nrow && r[2] <= s));
            while k < rc.len() && rc[k][0] == nrow && rc[k][1] < e {
                match u.binary_search(&(k as u32)) {
                    Ok(b) => {
                        let (x, y) = (find(&mut parent, a as u32), find(&mut parent, b as u32));
                        if x != y {
                            parent[x as usize] = y;
                            supported[y as usize] |= supported[x as usize];
                        }
                    }
                    Err(_) => {
                        let x = find(&mut parent, a as u32);
                        supported[x as usize] = true;
                    }
                }
                k += 1;
            }
        }
    }
    let mut n = 0;
    for a in 0..u.len() as u32 {
        if find(&mut parent, a) == a && !supported[a as usize] {
            n += 1;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::analysis::test_support::{lit, rect, ring, xorshift};
    use crate::slice::Contour;

    /// [`islands`] of two sections.
    fn islands_of(cur: &[Contour], prev: &[Contour]) -> u32 {
        islands(&lit(cur), &lit(prev))
    }

    #[test]
    fn islands_count_unsupported_regions() {
        let base = [rect(0.0, 0.0, 10.0, 10.0)];
        // Same region: supported.
        assert_eq!(islands_of(&base, &base), 0);
        // Two new regions, one overlapping the base and one beside it.
        let two = [rect(5.0, 5.0, 8.0, 8.0), rect(20.0, 0.0, 25.0, 5.0)];
        assert_eq!(islands_of(&two, &base), 1);
        // Nothing below at all.
        assert_eq!(islands_of(&two, &[]), 2);
        // A ring counts once, and rests on a base touching only part of it.
        let section = ring([40.0, 30.0], 10.0, 8.0, 64);
        assert_eq!(islands_of(&section, &[]), 1);
        assert_eq!(islands_of(&section, &[rect(48.0, 28.0, 52.0, 32.0)]), 0);
        // A base inside the ring's hole does not support it.
        assert_eq!(islands_of(&section, &[rect(38.0, 28.0, 42.0, 32.0)]), 1);
        assert_eq!(islands_of(&[], &base), 0);
        // Pixels, not contours: a region lighting no pixel is no island, and regions that
        // touch only at a corner are two (4-connected).
        assert_eq!(islands_of(&[rect(30.0, 30.0, 30.02, 30.02)], &[]), 0);
        let px = 0.0634765625;
        let corner = [
            rect(0.0, 0.0, 10.0 * px, 10.0 * px),
            rect(10.0 * px, 10.0 * px, 20.0 * px, 20.0 * px),
        ];
        assert_eq!(islands_of(&corner, &[]), 2);
        // A base covering less than half of every pixel it touches supports nothing.
        let thin = [rect(0.0, 0.0, 10.0, 0.4 * px)];
        assert_eq!(islands_of(&base, &thin), 1);
    }

    fn rows(r: &[[u32; 3]], out: &mut Vec<(u32, usize, usize)>) {
        out.clear();
        for (i, run) in r.iter().enumerate() {
            match out.last_mut() {
                Some(last) if last.0 == run[0] => last.2 = i + 1,
                _ => out.push((run[0], i, i + 1)),
            }
        }
    }

    /// [`islands`] the direct way (without the shortcut of the unsupported runs): every run
    /// joined into its region (union-find), a region supported when one of its runs
    /// shares a pixel with a run below.
    fn join_and_count(cur: &LitRuns, prev: &LitRuns) -> u32 {
        let (rc, rp) = (&cur.runs, &prev.runs);
        if rc.is_empty() {
            return 0;
        }
        let (mut rows_c, mut rows_p) = (Vec::new(), Vec::new());
        rows(rc, &mut rows_c);
        rows(rp, &mut rows_p);
        let mut parent: Vec<u32> = (0..rc.len() as u32).collect();
        for w in rows_c.windows(2) {
            let (a, b) = (w[0], w[1]);
            if b.0 != a.0 + 1 {
                continue;
            }
            let (mut i, mut j) = (a.1, b.1);
            while i < a.2 && j < b.2 {
                if rc[i][1] < rc[j][2] && rc[j][1] < rc[i][2] {
                    let (x, y) = (find(&mut parent, i as u32), find(&mut parent, j as u32));
                    parent[x as usize] = y;
                }
                if rc[i][2] < rc[j][2] {
                    i += 1;
                } else {
                    j += 1;
                }
            }
        }
        let mut supported = vec![false; rc.len()];
        let mut pi = 0;
        for &(k, s, e) in &rows_c {
            while pi < rows_p.len() && rows_p[pi].0 < k {
                pi += 1;
            }
            if pi == rows_p.len() || rows_p[pi].0 != k {
                continue;
            }
            let (_, ps, pe) = rows_p[pi];
            let (mut i, mut j) = (s, ps);
            while i < e && j < pe {
                if rc[i][1] < rp[j][2] && rp[j][1] < rc[i][2] {
                    let r = find(&mut parent, i as u32);
                    supported[r as usize] = true;
                }
                if rc[i][2] < rp[j][2] {
                    i += 1;
                } else {
                    j += 1;
                }
            }
        }
        let mut n = 0;
        for i in 0..rc.len() as u32 {
            if find(&mut parent, i) == i && !supported[i as usize] {
                n += 1;
            }
        }
        n
    }

    #[test]
    fn supported_runs_shortcut_agrees_with_joining() {
        // Random layers of scattered squares and rings over random layers below: when
        // every run rests on a run below, joining finds no island either, and the count
        // with the shortcut is the count without it.
        let mut rnd = xorshift(0x1d5_0a7e_u64);
        let layer = |rnd: &mut dyn FnMut() -> f64| -> Vec<Contour> {
            let n = 1 + (rnd() * 5.0) as usize;
            let mut v: Vec<Contour> = (0..n)
                .map(|_| {
                    let (x, y, w) = (rnd() * 20.0, rnd() * 20.0, 0.2 + rnd() * 8.0);
                    rect(x, y, x + w, y + 0.2 + rnd() * 8.0)
                })
                .collect();
            if rnd() < 0.5 {
                let (cx, cy, r) = (5.0 + rnd() * 10.0, 5.0 + rnd() * 10.0, 2.0 + rnd() * 4.0);
                v.extend(ring([cx, cy], r, r * 0.6, 48));
            }
            v
        };
        let (mut shortcut, mut found) = (0, 0);
        for _ in 0..200 {
            let (cur, below) = (layer(&mut rnd), layer(&mut rnd));
            // Sometimes the layer below is the same or larger, so all runs rest on it.
            let below = if rnd() < 0.3 { cur.clone() } else { below };
            let (rc, rp) = (lit(&cur), lit(&below));
            let joined = join_and_count(&rc, &rp);
            let mut unsup = Vec::new();
            unsupported_runs(&rc, &rp, &mut unsup);
            if unsup.is_empty() {
                assert_eq!(joined, 0);
                shortcut += 1;
            }
            assert_eq!(islands(&rc, &rp), joined);
            found += joined;
        }
        assert!(shortcut > 40 && found > 40, "{shortcut} {found}");
    }

    #[test]
    fn islands_match_a_pixel_flood_fill() {
        // Random pixel grids (lit with probability 0.3–0.7, so regions of every shape:
        // U-shapes resting by one arm, regions touching the layer below in one pixel)
        // over random grids below: the count from the unsupported runs against a flood
        // fill of the pixels and against joining every run.
        let mut rnd = xorshift(0x15_1a_2d_u64);
        let (w, h) = (23usize, 17usize);
        let runs_of = |g: &[bool]| {
            let mut l = LitRuns::default();
            for r in 0..h {
                let mut c = 0;
                while c < w {
                    if g[r * w + c] {
                        let s = c;
                        while c < w && g[r * w + c] {
                            c += 1;
                        }
                        l.runs.push([r as u32, s as u32, c as u32]);
                    } else {
                        c += 1;
                    }
                }
            }
            l
        };
        let mut total = 0;
        for case in 0..300 {
            let (pc, pb) = (0.3 + 0.4 * rnd(), 0.1 + 0.6 * rnd());
            let cur: Vec<bool> = (0..w * h).map(|_| rnd() < pc).collect();
            let below: Vec<bool> = (0..w * h).map(|_| rnd() < pb).collect();
            // Flood fill of the lit pixels; a region is an island when none of its pixels
            // is lit below.
            let mut seen = vec![false; w * h];
            let mut want = 0;
            for s in 0..w * h {
                if !cur[s] || seen[s] {
                    continue;
                }
                seen[s] = true;
                let (mut stack, mut rests) = (vec![s], false);
                while let Some(k) = stack.pop() {
                    rests |= below[k];
                    let (r, c) = (k / w, k % w);
                    let mut nb = Vec::new();
                    if r > 0 {
                        nb.push(k - w);
                    }
                    if r + 1 < h {
                        nb.push(k + w);
                    }
                    if c > 0 {
                        nb.push(k - 1);
                    }
                    if c + 1 < w {
                        nb.push(k + 1);
                    }
                    for q in nb {
                        if cur[q] && !seen[q] {
                            seen[q] = true;
                            stack.push(q);
                        }
                    }
                }
                want += u32::from(!rests);
            }
            let (rc, rb) = (runs_of(&cur), runs_of(&below));
            assert_eq!(islands(&rc, &rb), want, "case {case}");
            assert_eq!(join_and_count(&rc, &rb), want, "case {case}");
            total += want;
        }
        assert!(total > 300, "{total}");
    }
}
