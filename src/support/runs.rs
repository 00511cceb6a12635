//! Sets of lit pixels as runs `[row, first column, end column)` (the layout of
//! [`crate::raster::LitRuns`]: sorted by row then column, a row's runs disjoint and not
//! touching), and the few operations the support search needs on them.

/// A run of one row's pixels: `[row, first column, end column)`.
pub type Run = [u32; 3];

/// Appends `r` to runs in order (by row, then first column), merging it with the last
/// run when they overlap or touch.
fn push_merged(out: &mut Vec<Run>, r: Run) {
    match out.last_mut() {
        Some(l) if l[0] == r[0] && r[1] <= l[2] => l[2] = l[2].max(r[2]),
        _ => out.push(r),
    }
}

/// The pixels of `a` farther than `radius` pixels (centre to centre) from every pixel of
/// `runs`: `a` less the dilation of `runs` ([`dilated_rows`]), made in `a`'s rows only.
pub fn beyond(a: &[Run], runs: &[Run], radius: f64, width: u32) -> Vec<Run> {
    let mut rows: Vec<u32> = a.iter().map(|r| r[0]).collect();
    rows.dedup();
    minus(a, &dilated_rows(runs, radius, width, rows))
}

/// The pixels within `radius` pixels (centre to centre) of a pixel of `runs`, left of
/// column `width`, in the rows `rows` (increasing) only. Row by row: each output row
/// gathers the runs of the rows within `radius`, each widened by its half-chord, and
/// merges them (a sort of a few runs).
fn dilated_rows(
    runs: &[Run],
    radius: f64,
    width: u32,
    rows: impl IntoIterator<Item = u32>,
) -> Vec<Run> {
    let (Some(first), Some(last)) = (runs.first(), runs.last()) else {
        return Vec::new();
    };
    let k = radius.floor() as u32;
    let half: Vec<u32> = (0..=k)
        .map(|dy| (radius * radius - (dy * dy) as f64).sqrt().floor() as u32)
        .collect();
    let (lo, hi) = (first[0], last[0]);
    // `starts[q - lo]..starts[q - lo + 1]`: the runs of row q.
    let mut starts = Vec::with_capacity((hi - lo + 2) as usize);
    let mut i = 0;
    for q in lo..=hi + 1 {
        while i < runs.len() && runs[i][0] < q {
            i += 1;
        }
        starts.push(i);
    }
    let mut out = Vec::with_capacity(runs.len() * 2);
    let mut row: Vec<[u32; 2]> = Vec::new();
    for r in rows {
        row.clear();
        for q in r.saturating_sub(k).max(lo)..=(r + k).min(hi) {
            let w = half[q.abs_diff(r) as usize];
            let of_q = &runs[starts[(q - lo) as usize]..starts[(q - lo + 1) as usize]];
            row.extend(
                of_q.iter()
                    .map(|&[_, a, b]| [a.saturating_sub(w), (b + w).min(width)]),
            );
        }
        row.sort_unstable();
        for &[a, b] in &row {
            push_merged(&mut out, [r, a, b]);
        }
    }
    out
}

/// The pixels of `a` that are not in `b`.
pub fn minus(a: &[Run], b: &[Run]) -> Vec<Run> {
    let mut out = Vec::new();
    let mut j = 0;
    for &[row, s, e] in a {
        while j < b.len() && (b[j][0] < row || (b[j][0] == row && b[j][2] <= s)) {
            j += 1;
        }
        let mut from = s;
        let mut k = j;
        while k < b.len() && b[k][0] == row && b[k][1] < e {
            if b[k][1] > from {
                out.push([row, from, b[k][1]]);
            }
            from = from.max(b[k][2]);
            k += 1;
        }
        if from < e {
            out.push([row, from, e]);
        }
    }
    out
}

/// For each run of `a`, how many of its pixels `b` also has.
pub fn shared_pixels(a: &[Run], b: &[Run]) -> Vec<u32> {
    let mut j = 0;
    a.iter()
        .map(|&[row, s, e]| {
            while j < b.len() && (b[j][0] < row || (b[j][0] == row && b[j][2] <= s)) {
                j += 1;
            }
            let mut n = 0;
            let mut k = j;
            while k < b.len() && b[k][0] == row && b[k][1] < e {
                n += b[k][2].min(e) - b[k][1].max(s);
                k += 1;
            }
            n
        })
        .collect()
}

/// Whether a pixel of `runs` has its four neighbours in `runs` too (the set survives an
/// erosion by one pixel).
pub fn has_interior(runs: &[Run]) -> bool {
    runs.iter().any(|&[r, a, b]| {
        // The run's columns whose left and right neighbours are in it.
        let (lo, hi) = (a + 1, b.saturating_sub(1));
        r > 0
            && hi > lo
            && row_of(runs, r - 1).iter().any(|u| {
                let (x0, x1) = (u[1].max(lo), u[2].min(hi));
                x0 < x1
                    && row_of(runs, r + 1)
                        .iter()
                        .any(|d| d[1].max(x0) < d[2].min(x1))
            })
    })
}

/// The runs of row `r`.
fn row_of(runs: &[Run], r: u32) -> &[Run] {
    let lo = runs.partition_point(|x| x[0] < r);
    &runs[lo..lo + runs[lo..].partition_point(|x| x[0] == r)]
}

/// The pixels of `runs` whose four neighbours are in `runs` too (an erosion by one pixel).
/// One pass over the rows, each beside the rows above and below it.
pub fn eroded(runs: &[Run]) -> Vec<Run> {
    let mut out = Vec::new();
    let rows: Vec<&[Run]> = runs.chunk_by(|x, y| x[0] == y[0]).collect();
    for k in 1..rows.len().saturating_sub(1) {
        let (up, row, down) = (rows[k - 1], rows[k], rows[k + 1]);
        let r = row[0][0];
        if up[0][0] + 1 != r || down[0][0] != r + 1 {
            continue;
        }
        for &[_, a, b] in row {
            let (lo, hi) = (a + 1, b.saturating_sub(1));
            for u in up.iter().filter(|_| hi > lo) {
                let (x0, x1) = (u[1].max(lo), u[2].min(hi));
                for d in down.iter().filter(|d| d[1].max(x0) < d[2].min(x1)) {
                    out.push([r, d[1].max(x0), d[2].min(x1)]);
                }
            }
        }
    }
    // In order, and no two touch: the pieces of a row lie inside runs that do not.
    out
}

/// The union of two run sets (a merge of the two orders).
pub fn union(a: &[Run], b: &[Run]) -> Vec<Run> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        let r = if j == b.len() || (i < a.len() && a[i] <= b[j]) {
            i += 1;
            a[i - 1]
        } else {
            j += 1;
            b[j - 1]
        };
        push_merged(&mut out, r);
    }
    out
}

/// Whether pixel (`col`, `row`) is in `runs`.
pub fn contains(runs: &[Run], col: u32, row: u32) -> bool {
    let i = runs.partition_point(|r| r[0] < row || (r[0] == row && r[2] <= col));
    i < runs.len() && runs[i][0] == row && runs[i][1] <= col
}

/// Whether a pixel of `runs` has its centre within `radius` pixels of the point
/// (`cx`, `cy`) (in pixels: column, row; pixel centres at +0.5).
pub fn any_within(runs: &[Run], cx: f64, cy: f64, radius: f64) -> bool {
    let lo = (cy - radius - 0.5).floor().max(0.0) as u32;
    let hi = (cy + radius - 0.5).ceil().max(0.0) as u32;
    let mut i = runs.partition_point(|r| r[0] < lo);
    while i < runs.len() && runs[i][0] <= hi {
        let [row, a, b] = runs[i];
        let dy = row as f64 + 0.5 - cy;
        if dy.abs() <= radius {
            let w = (radius * radius - dy * dy).sqrt();
            if a as f64 + 0.5 <= cx + w && b as f64 - 0.5 >= cx - w {
                return true;
            }
        }
        i += 1;
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The runs of a boolean grid (row-major, `w` wide).
    fn runs_of(g: &[bool], w: usize) -> Vec<Run> {
        let mut out = Vec::new();
        for (r, row) in g.chunks(w).enumerate() {
            let mut c = 0;
            while c < w {
                if row[c] {
                    let a = c;
                    while c < w && row[c] {
                        c += 1;
                    }
                    out.push([r as u32, a as u32, c as u32]);
                } else {
                    c += 1;
                }
            }
        }
        out
    }

    /// A pseudo-random grid (fixed seed).
    fn grid(seed: u64, w: usize, h: usize, fill: u64) -> Vec<bool> {
        let mut s = seed;
        (0..w * h)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 33) % 100 < fill
            })
            .collect()
    }

    #[test]
    fn operations_match_brute_force_on_random_grids() {
        let (w, h) = (37usize, 23usize);
        for seed in 0..40 {
            let ga = grid(seed, w, h, 30);
            let gb = grid(seed + 1000, w, h, 20);
            let (a, b) = (runs_of(&ga, w), runs_of(&gb, w));
            let at = |g: &[bool], c: i64, r: i64| {
                c >= 0
                    && r >= 0
                    && (c as usize) < w
                    && (r as usize) < h
                    && g[r as usize * w + c as usize]
            };
            let radius = 1.0 + (seed % 5) as f64 * 0.7;
            let dil = dilated_rows(&a, radius, w as u32, 0..h as u32);
            let k = radius.floor() as i64;
            let brute_dil: Vec<bool> = (0..w * h)
                .map(|i| {
                    let (c, r) = ((i % w) as i64, (i / w) as i64);
                    (-k..=k).any(|dy| {
                        (-k..=k).any(|dx| {
                            (dx * dx + dy * dy) as f64 <= radius * radius && at(&ga, c + dx, r + dy)
                        })
                    })
                })
                .collect();
            assert_eq!(dil, runs_of(&brute_dil, w), "seed {seed}");
            let far: Vec<bool> = gb.iter().zip(&brute_dil).map(|(&x, &d)| x && !d).collect();
            assert_eq!(beyond(&b, &a, radius, w as u32), runs_of(&far, w));
            let diff: Vec<bool> = ga.iter().zip(&gb).map(|(&x, &y)| x && !y).collect();
            assert_eq!(minus(&a, &b), runs_of(&diff, w));
            let uni: Vec<bool> = ga.iter().zip(&gb).map(|(&x, &y)| x || y).collect();
            assert_eq!(union(&a, &b), runs_of(&uni, w));
            for (run, n) in a.iter().zip(shared_pixels(&a, &b)) {
                let brute = (run[1]..run[2])
                    .filter(|&c| gb[run[0] as usize * w + c as usize])
                    .count();
                assert_eq!(n as usize, brute);
            }
            for r in 0..h {
                for c in 0..w {
                    assert_eq!(contains(&a, c as u32, r as u32), ga[r * w + c]);
                }
            }
            let (cx, cy, rad) = (10.3 + seed as f64 * 0.4, 7.9, 2.6);
            let brute_near = (0..w * h).any(|i| {
                let (c, r) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
                ga[i] && (c - cx).powi(2) + (r - cy).powi(2) <= rad * rad
            });
            assert_eq!(any_within(&a, cx, cy, rad), brute_near, "seed {seed}");
            // Dense grids, so that some pixels keep their four neighbours.
            let gd = grid(seed + 2000, w, h, 85);
            let inner: Vec<bool> = (0..w * h)
                .map(|i| {
                    let (c, r) = ((i % w) as i64, (i / w) as i64);
                    [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]
                        .iter()
                        .all(|(dx, dy)| at(&gd, c + dx, r + dy))
                })
                .collect();
            let d = runs_of(&gd, w);
            assert_eq!(eroded(&d), runs_of(&inner, w), "seed {seed}");
            assert_eq!(has_interior(&d), inner.contains(&true));
        }
    }
}
