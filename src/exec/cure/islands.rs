//! Lit runs of a layer's pixels and their islands: 4-connected components of runs by
//! union-find (also the cured regions' components, `Engine`'s merges).

use super::irradiance::Irradiance;
use super::kernel::Prepared;
use super::LIT;

/// A run of lit pixels (relative irradiance ≥ [`LIT`]) of one row: columns `[c0, c1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Run {
    pub(super) r: u32,
    pub(super) c0: u32,
    pub(super) c1: u32,
}

/// The lit runs of `cur` and its islands (4-connected runs, union-find with the smallest
/// run as root; islands numbered in the order of their first run, row-major).
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
            p.runs.push(Run {
                r: r as u32,
                c0: (c0 + start) as u32,
                c1: (c0 + c) as u32,
            });
        }
        p.rows.push(p.runs.len() as u32);
    }
    let n = p.runs.len();
    let (ids, count) = connect(&p.runs, &p.rows);
    p.px = vec![0; count];
    p.sum = vec![[0.0; 2]; count];
    p.island = ids;
    for i in 0..n {
        let l = p.island[i] as usize;
        let run = p.runs[i];
        let len = (run.c1 - run.c0) as u64;
        p.px[l] += len;
        // Σ (c + ½) over the run and len·(r + ½): sums of halves, exact in f64.
        p.sum[l][0] += len as f64 * (run.c0 + run.c1) as f64 * 0.5;
        p.sum[l][1] += len as f64 * (run.r as f64 + 0.5);
    }
}

/// The 4-connected components of `runs` (row-major, `rows[k]..rows[k + 1]` the runs of
/// the k-th row): each run's component, numbered from 0 in the order of their first run,
/// and the count (union-find, a component's smallest run its root).
pub(super) fn connect(runs: &[Run], rows: &[u32]) -> (Vec<u32>, usize) {
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let n = runs.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for k in 1..rows.len().saturating_sub(1) {
        let (above, here) = (
            rows[k - 1] as usize..rows[k] as usize,
            rows[k] as usize..rows[k + 1] as usize,
        );
        let mut j = above.start;
        for i in here {
            let a = runs[i];
            while j < above.end && runs[j].c1 <= a.c0 {
                j += 1;
            }
            let mut t = j;
            while t < above.end && runs[t].c0 < a.c1 {
                let (x, y) = (find(&mut parent, t as u32), find(&mut parent, i as u32));
                if x != y {
                    parent[x.max(y) as usize] = x.min(y);
                }
                t += 1;
            }
        }
    }
    let mut map = vec![u32::MAX; n];
    let mut ids = Vec::with_capacity(n);
    let mut count = 0u32;
    for i in 0..n {
        let root = find(&mut parent, i as u32) as usize;
        if map[root] == u32::MAX {
            map[root] = count;
            count += 1;
        }
        ids.push(map[root]);
    }
    (ids, count as usize)
}
