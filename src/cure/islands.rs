//! Islands: runs of lit pixels and their 4-connected components (union-find,
//! [`crate::bundle::regions::components`]). One counter for the planner's islands (regions
//! that print onto nothing, `plan::analysis`), the cure check's (islands that vanish, cured
//! regions that join them) and the executor's unsupported regions.

use super::check::LIT;
use super::kernel::{Irradiance, Prepared};

/// A run of one row's pixels (or samples), and the 4-connected components of runs: the
/// job format's ([`crate::bundle::regions`]), which the executor and `inspect` share.
pub use crate::bundle::regions::{components, Run};

/// The lit runs of `cur` (relative irradiance ≥ [`LIT`]) and its islands, into `p`.
#[inline(never)]
pub(super) fn lit_islands(cur: &Irradiance, p: &mut Prepared) {
    let [c0, r0, c1, r1] = cur.bbox;
    let bw = c1 - c0;
    p.rows.push(0);
    for r in r0..r1 {
        let row = &cur.data[(r - r0) * bw..(r - r0 + 1) * bw];
        let mut c = 0;
        while c < bw {
            if row[c] < LIT {
                c += 1;
                continue;
            }
            let start = c;
            while c < bw && row[c] >= LIT {
                c += 1;
            }
            p.runs
                .push([r as u32, (c0 + start) as u32, (c0 + c) as u32]);
        }
        p.rows.push(p.runs.len() as u32);
    }
    let (ids, count) = components(&p.runs);
    p.px = vec![0; count];
    p.sum = vec![[0.0; 2]; count];
    for (run, &l) in p.runs.iter().zip(&ids) {
        let (l, len) = (l as usize, (run[2] - run[1]) as u64);
        p.px[l] += len;
        // Σ (c + ½) over the run and len·(r + ½): sums of halves, exact in f64.
        p.sum[l][0] += len as f64 * (run[1] + run[2]) as f64 * 0.5;
        p.sum[l][1] += len as f64 * (run[0] as f64 + 0.5);
    }
    p.island = ids;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Components of random pixel grids against a flood fill of their pixels.
    #[test]
    fn components_match_a_flood_fill() {
        let mut rnd = crate::test_support::xorshift(0x51_7e_u64);
        let (w, h) = (23usize, 17usize);
        let mut total = 0;
        for case in 0..300 {
            let p = 0.3 + 0.4 * rnd();
            let g: Vec<bool> = (0..w * h).map(|_| rnd() < p).collect();
            // Some rows left dark, so rows without runs come between lit ones.
            let dark = (rnd() * h as f64) as usize;
            let lit = |k: usize| g[k] && k / w != dark;
            let mut runs = Vec::new();
            for r in 0..h {
                let mut c = 0;
                while c < w {
                    if lit(r * w + c) {
                        let s = c;
                        while c < w && lit(r * w + c) {
                            c += 1;
                        }
                        runs.push([r as u32, s as u32, c as u32]);
                    } else {
                        c += 1;
                    }
                }
            }
            let (ids, count) = components(&runs);
            let flags: Vec<bool> = (0..w * h).map(lit).collect();
            let (label, want) = crate::test_support::flood_labels(&flags, w, h);
            assert_eq!(count, want, "case {case}");
            for (run, &id) in runs.iter().zip(&ids) {
                for c in run[1]..run[2] {
                    let k = run[0] as usize * w + c as usize;
                    assert_eq!(label[k], id as usize, "case {case}");
                }
            }
            total += want;
        }
        assert!(total > 1000, "{total}");
    }
}
