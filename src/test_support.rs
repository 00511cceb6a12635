//! Scaffolding the unit tests share: scratch directories and listings, a fixed-seed random
//! number generator, simple contours.

use crate::slice::Contour;
use std::path::{Path, PathBuf};

/// A fresh, empty scratch directory `dmdsl-PREFIX-PID-TAG` in the temporary directory.
pub(crate) fn scratch(prefix: &str, tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("dmdsl-{prefix}-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The names in `dir`, sorted.
pub(crate) fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The xorshift (13, 7, 17) generator from `seed`: its raw 64-bit states.
pub(crate) fn xorshift_bits(mut s: u64) -> impl FnMut() -> u64 {
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    }
}

/// [`xorshift_bits`] as numbers uniform in [0, 1).
pub(crate) fn xorshift(seed: u64) -> impl FnMut() -> f64 {
    let mut bits = xorshift_bits(seed);
    move || (bits() >> 11) as f64 / (1u64 << 53) as f64
}

/// The rectangle `[x0, x1] × [y0, y1]`, counter-clockwise.
pub(crate) fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Contour {
    vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
}

/// The closed contour through `f(a)` for `n` angles `a` evenly spaced over a turn
/// (counter-clockwise, or reversed).
pub(crate) fn closed(n: usize, ccw: bool, f: impl FnMut(f64) -> [f64; 2]) -> Contour {
    let mut c: Contour = (0..n)
        .map(|i| std::f64::consts::TAU * i as f64 / n as f64)
        .map(f)
        .collect();
    if !ccw {
        c.reverse();
    }
    c
}

/// The regular `n`-gon of circumradius `r` around (`cx`, `cy`).
pub(crate) fn ngon(cx: f64, cy: f64, r: f64, n: usize, ccw: bool) -> Contour {
    closed(n, ccw, |a| [cx + r * a.cos(), cy + r * a.sin()])
}

/// The 4-connected regions of the lit flags `lit` (`w × h`, row-major) by a flood fill, the
/// independent oracle of the run-based region counters: each pixel's region, numbered in
/// the order of its first pixel (`usize::MAX` where dark), and how many.
pub(crate) fn flood_labels(lit: &[bool], w: usize, h: usize) -> (Vec<usize>, usize) {
    let mut label = vec![usize::MAX; w * h];
    let mut n = 0;
    for s in 0..w * h {
        if !lit[s] || label[s] != usize::MAX {
            continue;
        }
        label[s] = n;
        let mut stack = vec![s];
        while let Some(k) = stack.pop() {
            let (r, c) = (k / w, k % w);
            let near = [
                (r > 0).then(|| k - w),
                (r + 1 < h).then(|| k + w),
                (c > 0).then(|| k - 1),
                (c + 1 < w).then(|| k + 1),
            ];
            for q in near.into_iter().flatten() {
                if lit[q] && label[q] == usize::MAX {
                    label[q] = n;
                    stack.push(q);
                }
            }
        }
        n += 1;
    }
    (label, n)
}

/// The regions of `cur` over `below` (`w × h` lit flags, row-major) that rest on nothing,
/// by [`flood_labels`]: (pixels, Σ columns, Σ rows) of each region none of whose pixels is
/// lit below (pixel centres at +0.5).
pub(crate) fn flood_regions(
    cur: &[bool],
    below: &[bool],
    w: usize,
    h: usize,
) -> Vec<(u64, f64, f64)> {
    let (label, n) = flood_labels(cur, w, h);
    let mut rests = vec![false; n];
    let mut sums = vec![(0u64, 0.0, 0.0); n];
    for (k, &g) in label.iter().enumerate().filter(|(_, &g)| g != usize::MAX) {
        rests[g] |= below[k];
        let t = &mut sums[g];
        *t = (
            t.0 + 1,
            t.1 + (k % w) as f64 + 0.5,
            t.2 + (k / w) as f64 + 0.5,
        );
    }
    (0..n).filter(|&g| !rests[g]).map(|g| sums[g]).collect()
}
