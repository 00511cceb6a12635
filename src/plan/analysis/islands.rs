//! Islands: the connected regions of a layer's lit pixels that share no pixel with the
//! layer below's (they would print onto nothing), found by
//! [`crate::bundle::regions::unsupported`], which `dmdsl run` judges masks with too.

use super::LitRuns;
use crate::bundle::regions::unsupported;

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

/// [`islands_found`]: the regions [`unsupported`] finds, counted, and the largest (the
/// first of equals).
pub(super) fn count_islands(cur: &LitRuns, prev: &LitRuns) -> Islands {
    let free = unsupported(&cur.runs, &prev.runs);
    Islands {
        count: free.len() as u32,
        largest: free.iter().rev().max_by_key(|g| g.pixels).map(|g| Island {
            col_row: g.col_row,
            pixels: g.pixels,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::regions::resting_runs;
    use crate::plan::analysis::test_support::{lit, rect, ring, scattered, xorshift};
    use crate::slice::Contour;
    use crate::test_support::flood_regions as flood;

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

    /// The lit pixels of `l` on a `w × h` grid.
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
            let want = flood(&grid_of(&rc, w, h), &grid_of(&rp, w, h), w, h).len() as u32;
            if !resting_runs(&rc.runs, &rp.runs).1 {
                assert_eq!(want, 0);
                shortcut += 1;
            }
            assert_eq!(islands(&rc, &rp), want);
            found += want;
        }
        assert!(shortcut > 40 && found > 40, "{shortcut} {found}");
    }
}
