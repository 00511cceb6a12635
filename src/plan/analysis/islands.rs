//! Islands: the connected regions of a layer's lit pixels that share no pixel with the
//! layer below's (they would print onto nothing). The regions are
//! [`crate::cure::islands::components`], the counter the cure check shares.

use super::LitRuns;
use crate::cure::islands::components;

/// Number of connected regions (4-connected) of the lit pixels `cur` that share no pixel
/// with the lit pixels `prev` of the layer below.
#[cfg(any(test, feature = "internals"))]
pub fn islands(cur: &LitRuns, prev: &LitRuns) -> u32 {
    islands_found(cur, prev).count
}

/// An island of a layer: where it is and how large, in the field's pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Island {
    /// Centre of its pixels: column and row (pixel centres at +0.5; row 0 at the top).
    pub col_row: [f64; 2],
    /// Its lit pixels.
    pub pixels: u64,
}

/// The islands of a layer: how many, and the largest.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Islands {
    /// Number of regions resting on nothing below.
    pub count: u32,
    /// The largest of them.
    pub largest: Option<Island>,
}

/// [`islands`], with the largest island.
pub fn islands_found(cur: &LitRuns, prev: &LitRuns) -> Islands {
    count_islands(cur, prev)
}

/// Whether each run of `cur` shares a pixel with a run of `prev` in the same row, and
/// whether any does not.
fn supported_runs(cur: &LitRuns, prev: &LitRuns) -> (Vec<bool>, bool) {
    let (rc, rp) = (&cur.runs, &prev.runs);
    // Both sorted by row then column, and a row's runs are disjoint: one merge-walk.
    let mut j = 0;
    let mut all = true;
    let on = rc
        .iter()
        .map(|r| {
            // Skip the runs below that end before this one starts (in this row or earlier).
            while j < rp.len() && (rp[j][0] < r[0] || (rp[j][0] == r[0] && rp[j][2] <= r[1])) {
                j += 1;
            }
            let rests = j < rp.len() && rp[j][0] == r[0] && rp[j][1] < r[2];
            all &= rests;
            rests
        })
        .collect();
    (on, !all)
}

/// [`islands_found`]. Usually every run rests on a run below and there is no island;
/// otherwise the runs' regions, each supported when one of its runs rests on the layer
/// below.
pub(super) fn count_islands(cur: &LitRuns, prev: &LitRuns) -> Islands {
    let (on, any_free) = supported_runs(cur, prev);
    if !any_free {
        return Islands::default();
    }
    let (region, n) = components(&cur.runs);
    let mut supported = vec![false; n];
    // Per region: pixels, Σ column centres, Σ row centres.
    let mut sums = vec![(0u64, 0.0, 0.0); n];
    for ((&g, &s), r) in region.iter().zip(&on).zip(&cur.runs) {
        supported[g as usize] |= s;
        let (len, [row, c0, c1]) = (u64::from(r[2] - r[1]), r.map(f64::from));
        let t = &mut sums[g as usize];
        *t = (
            t.0 + len,
            t.1 + (c0 + c1) / 2.0 * (c1 - c0),
            t.2 + (row + 0.5) * (c1 - c0),
        );
    }
    let free = || (0..n).filter(|&g| !supported[g]);
    let largest = free()
        .max_by_key(|&g| (sums[g].0, std::cmp::Reverse(g)))
        .map(|g| {
            let (k, sc, sr) = sums[g];
            Island {
                col_row: [sc / k as f64, sr / k as f64],
                pixels: k,
            }
        });
    Islands {
        count: free().count() as u32,
        largest,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::analysis::test_support::{lit, rect, ring, scattered, xorshift};
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

    #[test]
    fn the_largest_island_is_found_with_its_centre_and_size() {
        let runs = |r: &[[u32; 3]]| LitRuns { runs: r.to_vec() };
        // Below: row 0, columns 0..4. Above: a 2-pixel region resting on it, a 6-pixel
        // island (rows 2-3, columns 10..13) and a 1-pixel island.
        let below = runs(&[[0, 0, 4]]);
        let cur = runs(&[[0, 1, 3], [2, 10, 13], [2, 20, 21], [3, 10, 13]]);
        let f = islands_found(&cur, &below);
        assert_eq!(f.count, 2);
        let big = f.largest.unwrap();
        assert_eq!(big.pixels, 6);
        assert_eq!(big.col_row, [11.5, 3.0]);
        assert_eq!(islands_found(&below, &below), Islands::default());
    }

    /// The islands of the `w × h` pixel grid `cur` (row-major) over `below` by a flood
    /// fill: a 4-connected region of lit pixels counts when none of them is lit below.
    fn flood_islands(cur: &[bool], below: &[bool], w: usize, h: usize) -> u32 {
        let mut seen = vec![false; w * h];
        let mut n = 0;
        for s in 0..w * h {
            if !cur[s] || seen[s] {
                continue;
            }
            seen[s] = true;
            let (mut stack, mut rests) = (vec![s], false);
            while let Some(k) = stack.pop() {
                rests |= below[k];
                let (r, c) = (k / w, k % w);
                let nb = [
                    (r > 0).then(|| k - w),
                    (r + 1 < h).then(|| k + w),
                    (c > 0).then(|| k - 1),
                    (c + 1 < w).then(|| k + 1),
                ];
                for q in nb.into_iter().flatten() {
                    if cur[q] && !seen[q] {
                        seen[q] = true;
                        stack.push(q);
                    }
                }
            }
            n += u32::from(!rests);
        }
        n
    }

    /// The lit runs of the `w × h` grid `g`, and back.
    fn runs_of(g: &[bool], w: usize) -> LitRuns {
        let mut l = LitRuns::default();
        for (r, row) in g.chunks(w).enumerate() {
            let mut c = 0;
            while c < w {
                let s = c;
                while c < w && row[c] {
                    c += 1;
                }
                if c > s {
                    l.runs.push([r as u32, s as u32, c as u32]);
                }
                c += 1;
            }
        }
        l
    }
    fn grid_of(l: &LitRuns, w: usize, h: usize) -> Vec<bool> {
        let mut g = vec![false; w * h];
        for &[r, s, e] in &l.runs {
            g[r as usize * w + s as usize..r as usize * w + e as usize].fill(true);
        }
        g
    }

    #[test]
    fn supported_runs_shortcut_agrees_with_a_flood_fill() {
        // Random layers of scattered squares and rings over random layers below: when
        // every run rests on a run below there is no island, and the count with the
        // shortcut is that of a flood fill of the pixels.
        let mut rnd = xorshift(0x1d5_0a7e_u64);
        let layer = |rnd: &mut dyn FnMut() -> f64| -> Vec<Contour> {
            let mut v = scattered(rnd, 5.0, 8.0);
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
            // The field's rows and columns the layers reach.
            let (w, h) = rc.runs.iter().chain(&rp.runs).fold((0, 0), |(w, h), r| {
                (w.max(r[2] as usize), h.max(r[0] as usize + 1))
            });
            let want = flood_islands(&grid_of(&rc, w, h), &grid_of(&rp, w, h), w, h);
            if !supported_runs(&rc, &rp).1 {
                assert_eq!(want, 0);
                shortcut += 1;
            }
            assert_eq!(islands(&rc, &rp), want);
            found += want;
        }
        assert!(shortcut > 40 && found > 40, "{shortcut} {found}");
    }

    #[test]
    fn islands_match_a_pixel_flood_fill() {
        // Random pixel grids (lit with probability 0.3–0.7, so regions of every shape:
        // U-shapes resting by one arm, regions touching the layer below in one pixel)
        // over random grids below: the count from the unsupported runs against a flood
        // fill of the pixels.
        let mut rnd = xorshift(0x15_1a_2d_u64);
        let (w, h) = (23usize, 17usize);
        let mut total = 0;
        for case in 0..300 {
            let (pc, pb) = (0.3 + 0.4 * rnd(), 0.1 + 0.6 * rnd());
            let cur: Vec<bool> = (0..w * h).map(|_| rnd() < pc).collect();
            let below: Vec<bool> = (0..w * h).map(|_| rnd() < pb).collect();
            let want = flood_islands(&cur, &below, w, h);
            let (rc, rb) = (runs_of(&cur, w), runs_of(&below, w));
            assert_eq!(grid_of(&rc, w, h), cur);
            assert_eq!(islands(&rc, &rb), want, "case {case}");
            total += want;
        }
        assert!(total > 300, "{total}");
    }
}
