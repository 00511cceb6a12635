//! What the Z correction drops: a flat feature over nothing thinner than the held-back
//! layers.
//!
//! With `--cure-correction xyz` a pixel of layer j is drawn only where it and the M layers
//! below it are lit (the exact sections' coverage, at least 50 %). A run of lit layers of
//! one pixel that starts over nothing and is at most M layers long is therefore never
//! drawn. At the layer above such a run's last layer j (or past the job's top layer), the
//! run's pixel is lit in layer j, unlit in layer j + 1, and unlit in some layer among
//! j − M..j − 1; layers below the platform count as lit, so a run resting on the platform
//! is never dropped. [`DroppedScan`] finds those pixels from the coverage masks of the
//! layers and groups them into features (4-connected pixels).

use crate::raster::{Mask, PixelBox};

/// A pixel counts as lit from this coverage value on (50 %, as the threshold and the
/// islands count it).
const LIT: u8 = 128;

/// The pixels of one layer (the last layer of their runs) whose runs of lit layers the Z
/// correction drops.
#[derive(Debug, Clone)]
pub struct DroppedScan {
    /// The box of the layer's lit pixels (its coverage is zero outside).
    bx: PixelBox,
    /// Per pixel of `bx`: [`CANDIDATE`] and [`UNLIT_BELOW`] bits.
    state: Vec<u8>,
}

/// Lit in the layer, unlit in the layer above.
const CANDIDATE: u8 = 1;
/// Unlit in one of the M layers below the layer.
const UNLIT_BELOW: u8 = 2;

/// Features whose runs of lit layers end in one layer and are never drawn.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Dropped {
    /// Dropped pixels.
    pub pixels: u64,
    /// Features: 4-connected groups of dropped pixels.
    pub features: u32,
    /// The first feature's (the one holding the first dropped pixel in row-major order)
    /// pixel box.
    pub first: Option<PixelBox>,
}

impl DroppedScan {
    /// Starts the scan of the runs ending in a layer whose coverage is `layer` (zero
    /// outside `lit_box`); `above(col, row)` tells whether the layer above is lit at a
    /// pixel (always `false` past the job's top layer).
    pub fn new(layer: &Mask, lit_box: PixelBox, above: impl Fn(usize, usize) -> bool) -> Self {
        let w = layer.width as usize;
        let mut state = Vec::with_capacity(lit_box.rows().len() * lit_box.cols().len());
        for r in lit_box.rows() {
            for c in lit_box.cols() {
                let lit = layer.data[r * w + c] >= LIT;
                state.push(if lit && !above(c, r) { CANDIDATE } else { 0 });
            }
        }
        DroppedScan { bx: lit_box, state }
    }

    /// Counts in the coverage of one of the M layers below the layer (any order; a layer
    /// below the platform is lit and is not counted in).
    pub fn below(&mut self, m: &Mask) {
        let w = m.width as usize;
        let mut k = 0;
        for r in self.bx.rows() {
            let row = &m.data[r * w..][self.bx.cols()];
            for &v in row {
                if v < LIT {
                    self.state[k] |= UNLIT_BELOW;
                }
                k += 1;
            }
        }
    }

    /// The dropped pixels, grouped into 4-connected features.
    pub fn finish(&self) -> Dropped {
        let (w, h) = (self.bx.cols().len(), self.bx.rows().len());
        let dropped = |s: u8| s == CANDIDATE | UNLIT_BELOW;
        let mut out = Dropped::default();
        let mut seen = vec![false; self.state.len()];
        let mut stack = Vec::new();
        for start in 0..self.state.len() {
            if seen[start] || !dropped(self.state[start]) {
                continue;
            }
            // Flood fill of the feature holding `start`.
            let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
            seen[start] = true;
            stack.push(start);
            while let Some(k) = stack.pop() {
                out.pixels += 1;
                let (r, c) = (k / w, k % w);
                (r0, r1, c0, c1) = (r0.min(r), r1.max(r + 1), c0.min(c), c1.max(c + 1));
                let mut visit = |n: usize| {
                    if !seen[n] && dropped(self.state[n]) {
                        seen[n] = true;
                        stack.push(n);
                    }
                };
                if c > 0 {
                    visit(k - 1);
                }
                if c + 1 < w {
                    visit(k + 1);
                }
                if r > 0 {
                    visit(k - w);
                }
                if r + 1 < h {
                    visit(k + w);
                }
            }
            out.features += 1;
            out.first.get_or_insert(PixelBox {
                r0: self.bx.r0 + r0,
                r1: self.bx.r0 + r1,
                c0: self.bx.c0 + c0,
                c1: self.bx.c0 + c1,
            });
        }
        out
    }
}

/// Holds a layer's coverage `m` back to that of a layer below, `below`, inside `lit`:
/// each pixel takes at most its coverage there.
pub fn hold_back(m: &mut Mask, below: &Mask, lit: PixelBox) {
    let w = m.width as usize;
    for r in lit.rows() {
        let (row, b) = (
            &mut m.data[r * w..][lit.cols()],
            &below.data[r * w..][lit.cols()],
        );
        row.iter_mut().zip(b).for_each(|(v, b)| *v = (*v).min(*b));
    }
}

/// Whether each pixel of `m` inside `lit` (row-major) is lit (coverage ≥ 50 %); empty
/// unless `wanted`.
pub fn lit_pixels_of(m: &Mask, lit: PixelBox, wanted: bool) -> Vec<bool> {
    if !wanted {
        return Vec::new();
    }
    let w = m.width as usize;
    lit.rows()
        .flat_map(|r| m.data[r * w..][lit.cols()].iter().map(|&v| v >= 128))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mask `w × h` lit (255) where `lit(col, row)`.
    fn mask(w: usize, h: usize, lit: impl Fn(usize, usize) -> bool) -> Mask {
        let mut m = Mask::zeros(w as u32, h as u32);
        for r in 0..h {
            for c in 0..w {
                if lit(c, r) {
                    m.data[r * w + c] = 255;
                }
            }
        }
        m
    }

    /// Dropped pixels of every layer of a stack of one-row masks (layer j lit at column c
    /// where `stack[j][c]`), scanned as the pipeline does: at layer i the runs ending in
    /// layer i − 1, and past the top the runs ending in the top layer.
    fn scan(stack: &[Vec<bool>], m: usize) -> Vec<u64> {
        let w = stack[0].len();
        let layer = |j: usize| mask(w, 1, |c, _| stack[j][c]);
        let whole = PixelBox::whole(w, 1);
        (0..stack.len())
            .map(|end| {
                let above = |c: usize, _| stack.get(end + 1).is_some_and(|l| l[c]);
                let mut s = DroppedScan::new(&layer(end), whole, above);
                for d in 1..=m {
                    if let Some(j) = end.checked_sub(d) {
                        s.below(&layer(j));
                    }
                }
                s.finish().pixels
            })
            .collect()
    }

    /// The same from the definition: runs of lit layers not resting on the platform, at
    /// most `m` layers long, counted at their last layer.
    fn runs(stack: &[Vec<bool>], m: usize) -> Vec<u64> {
        let mut out = vec![0; stack.len()];
        for c in 0..stack[0].len() {
            let mut j = 0;
            while j < stack.len() {
                if !stack[j][c] {
                    j += 1;
                    continue;
                }
                let a = j;
                while j < stack.len() && stack[j][c] {
                    j += 1;
                }
                if a > 0 && j - a <= m {
                    out[j - 1] += 1;
                }
            }
        }
        out
    }

    #[test]
    fn dropped_runs_are_the_runs_over_nothing_at_most_m_layers_long() {
        // Fixed pseudo-random columns of 40 layers: runs of every length, on the platform,
        // reaching the top.
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let cols = 64;
        let stack: Vec<Vec<bool>> = (0..40)
            .map(|_| (0..cols).map(|_| next() % 3 != 0).collect())
            .collect();
        for m in [1, 2, 4, 6] {
            let want = runs(&stack, m);
            assert!(want.iter().sum::<u64>() > 10, "the stack has dropped runs");
            assert_eq!(scan(&stack, m), want, "M = {m}");
        }
        // A run on the platform is kept, one just above it is dropped.
        let col = |v: &[u8]| v.iter().map(|&b| vec![b == 1]).collect::<Vec<_>>();
        assert_eq!(scan(&col(&[1, 1, 0, 0]), 4), vec![0, 0, 0, 0]);
        assert_eq!(scan(&col(&[0, 1, 1, 0]), 4), vec![0, 0, 1, 0]);
        // A run of M + 1 layers is drawn once; one of M layers reaching the top is dropped.
        assert_eq!(scan(&col(&[0, 1, 1, 1, 1, 1, 0]), 4), vec![0; 7]);
        assert_eq!(scan(&col(&[0, 0, 1, 1, 1, 1]), 4), vec![0, 0, 0, 0, 0, 1]);
    }

    #[test]
    fn dropped_pixels_group_into_4_connected_features() {
        // Layer lit in two blocks and a diagonal pair, the layer above unlit, a layer below
        // unlit: every lit pixel is dropped.
        let lit = |c: usize, r: usize| {
            (2..5).contains(&c) && (1..3).contains(&r)
                || (8..10).contains(&c) && (4..7).contains(&r)
                || (c, r) == (12, 0)
                || (c, r) == (13, 1)
        };
        let layer = mask(16, 8, lit);
        let bx = PixelBox {
            r0: 0,
            r1: 8,
            c0: 1,
            c1: 15,
        };
        let mut s = DroppedScan::new(&layer, bx, |_, _| false);
        s.below(&mask(16, 8, |_, _| false));
        let d = s.finish();
        assert_eq!(d.pixels, 6 + 6 + 2);
        assert_eq!(d.features, 4);
        // The first in row-major order: the pixel (12, 0).
        let first = d.first.unwrap();
        assert_eq!((first.c0, first.c1, first.r0, first.r1), (12, 13, 0, 1));
        // Lit below everywhere: nothing is dropped.
        let mut s = DroppedScan::new(&layer, bx, |_, _| false);
        s.below(&mask(16, 8, |_, _| true));
        assert_eq!(s.finish(), Dropped::default());
        // Lit above the left block: it is not the end of its run.
        let mut s = DroppedScan::new(&layer, bx, |c, _| c < 6);
        s.below(&mask(16, 8, |_, _| false));
        assert_eq!(s.finish().features, 3);
    }
}
