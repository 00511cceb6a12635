//! The signed-area accumulation buffer: every contour edge adds its winding-weighted area
//! to the cells of the rows it crosses; a prefix sum along a row ([`super::scan`]) gives each
//! pixel its exact coverage.

/// A zeroed buffer whose pages are first touched by writes (a first read would map the
/// shared zero page, and the write after it would cost a TLB-flush interrupt to the other
/// CPUs).
pub(super) fn zeroed_by_writes<T: Copy + Default>(n: usize) -> Vec<T> {
    let mut v = vec![T::default(); n];
    let step = (4096 / std::mem::size_of::<T>().max(1)).max(1);
    for i in (0..n).step_by(step) {
        // SAFETY: i < n = v.len(); volatile, so the store of a value the allocation
        // already holds is not left out.
        unsafe { std::ptr::write_volatile(v.as_mut_ptr().add(i), T::default()) };
    }
    v
}

/// Accumulation cells per bit of [`super::Scratch`]'s `touched`.
pub(super) const BLOCK: usize = 32;

/// The signed-area accumulation buffer of one section's box of field pixels (rows
/// `row0..`, columns `col0..col0 + stride`) and its touched-block bitmap. Edges are
/// computed in field pixel coordinates; only their cells' indices are relative to the box.
pub(super) struct Accum<'a> {
    pub(super) cells: &'a mut [f32],
    pub(super) touched: &'a mut [u64],
    /// Cells per row: the box's columns.
    pub(super) stride: usize,
    /// Bitmap words per row.
    pub(super) words: usize,
    /// The field row of the box's first row.
    pub(super) row0: usize,
    /// The field column of the box's first column (a multiple of [`BLOCK`]).
    pub(super) col0: usize,
}

impl<'a> Accum<'a> {
    /// The accumulation buffer for field rows `r0..r1` and columns `c0..=c1` in `cells` and
    /// `touched` (all zero; the scan leaves them so), grown when the box needs more than
    /// they hold, to at least twice their size (a part whose sections grow layer after
    /// layer grows them a few times, not at every layer): their size follows the largest
    /// box drawn, not the field.
    pub(super) fn of_box(
        cells: &'a mut Vec<f32>,
        touched: &'a mut Vec<u64>,
        [r0, r1, c0, c1]: [usize; 4],
    ) -> Self {
        // One column more on the left: a line's column, interpolated in `f32` between its
        // ends, may round to just left of its leftmost end.
        let col0 = c0.saturating_sub(1) / BLOCK * BLOCK;
        let stride = (c1 + 1).saturating_sub(col0);
        let words = stride.div_ceil(BLOCK).div_ceil(64);
        let rows = r1.saturating_sub(r0);
        if cells.len() < stride * rows {
            *cells = zeroed_by_writes((stride * rows).max(2 * cells.len()));
        }
        if touched.len() < words * rows {
            *touched = zeroed_by_writes((words * rows).max(2 * touched.len()));
        }
        Accum {
            cells,
            touched,
            stride,
            words,
            row0: r0,
            col0,
        }
    }

    /// Marks cells `lo..=hi` (box columns) of box row `r` as written.
    #[inline]
    fn mark(&mut self, r: usize, lo: usize, hi: usize) {
        let row = &mut self.touched[r * self.words..(r + 1) * self.words];
        for b in lo / BLOCK..=hi / BLOCK {
            row[b / 64] |= 1 << (b % 64);
        }
    }
}

/// `v.floor()` for `0 ≤ v < 2²⁴` (or −0.0, giving +0.0): truncation is the floor there, and
/// it is one instruction where `f32::floor` is a libm call (the baseline x86-64 target has
/// no rounding instruction).
#[inline(always)]
fn floor_nn(v: f32) -> f32 {
    (v as u32) as f32
}

/// `v.ceil()` for `0 ≤ v < 2²⁴` (or −0.0, giving +0.0), see [`floor_nn`].
#[inline(always)]
fn ceil_nn(v: f32) -> f32 {
    let t = (v as u32) as f32;
    if t < v {
        t + 1.0
    } else {
        t
    }
}

/// Adds the signed-area contribution of the line (x0,y0)→(x1,y1) (pixel units, y down)
/// to the accumulation buffer: after a prefix sum along each row, every cell holds the
/// winding-weighted area of its pixel inside the polygon.
#[inline(always)]
pub(super) fn line(accum: &mut Accum, h: usize, x0: f32, y0: f32, x1: f32, y1: f32) {
    let stride = accum.stride;
    if y0 == y1 {
        return;
    }
    let (dir, xa, ya, xb, yb) = if y0 < y1 {
        (1.0f32, x0, y0, x1, y1)
    } else {
        (-1.0f32, x1, y1, x0, y0)
    };
    let dxdy = (xb - xa) / (yb - ya);
    let mut x = xa;
    // (Through u32: the values are whole and below 2²⁴, and converting to u32 takes fewer
    // instructions than to usize.)
    let r_start = floor_nn(ya) as u32 as usize;
    let r_end = (ceil_nn(yb) as u32 as usize).min(h);
    for r in r_start..r_end {
        // (Through i64: one instruction, where from usize it takes several.)
        let top = (r as i64 as f32).max(ya);
        let bot = ((r + 1) as i64 as f32).min(yb);
        let dy = bot - top;
        if dy <= 0.0 {
            continue;
        }
        let xn = if bot == yb { xb } else { x + dxdy * dy };
        let d = dy * dir;
        let base = (r - accum.row0) * stride;
        let (lx, rx) = if x < xn { (x, xn) } else { (xn, x) };
        let lf = floor_nn(lx);
        let rc = ceil_nn(rx);
        // Box columns: the arithmetic above stays in field coordinates.
        let li = lf as u32 as usize - accum.col0;
        let ri = rc as u32 as usize - accum.col0;
        accum.mark(r - accum.row0, li, ri.max(li + 1));
        let acc = &mut *accum.cells;
        if ri <= li + 1 {
            // The line stays inside one pixel column on this row.
            let mid = 0.5 * (x + xn) - lf;
            acc[base + li] += d * (1.0 - mid);
            acc[base + li + 1] += d * mid;
        } else {
            // Spans several columns: area left of the line in each column, trapezoid rule.
            let inv = 1.0 / (rx - lx);
            let f0 = lx - lf;
            let a0 = 0.5 * inv * (1.0 - f0) * (1.0 - f0);
            let f1 = rx - rc + 1.0;
            let am = 0.5 * inv * f1 * f1;
            acc[base + li] += d * a0;
            if ri == li + 2 {
                acc[base + li + 1] += d * (1.0 - a0 - am);
            } else {
                let a1 = inv * (1.5 - f0);
                acc[base + li + 1] += d * (a1 - a0);
                for c in li + 2..ri - 1 {
                    acc[base + c] += d * inv;
                }
                let a2 = a1 + (ri - li - 3) as f32 * inv;
                acc[base + ri - 1] += d * (1.0 - a2 - am);
            }
            acc[base + ri] += d * am;
        }
        x = xn;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zeroed_by_writes_is_zeroed() {
        for n in [0, 1, 1023, 1024, 1025, 5000] {
            let a: Vec<f32> = zeroed_by_writes(n);
            assert_eq!(a.len(), n);
            assert!(a.iter().all(|&v| v.to_bits() == 0));
            let b: Vec<u64> = zeroed_by_writes(n);
            assert!(b.len() == n && b.iter().all(|&v| v == 0));
        }
    }

    #[test]
    fn floor_and_ceil_of_non_negative_floats() {
        let mut vals = vec![
            0.0f32,
            -0.0,
            0.5,
            1.0,
            1.5,
            767.99994,
            768.0,
            1023.5,
            16_777_215.0,
        ];
        let mut s = 0x9E37_79B9u32;
        for _ in 0..10_000 {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            vals.push(f32::from_bits(s).abs().min(16_000_000.0));
            vals.push((s % 2_000_000) as f32 / 1024.0);
        }
        for v in vals.into_iter().filter(|v| v.is_finite()) {
            assert_eq!(floor_nn(v), v.floor() + 0.0, "{v}");
            assert_eq!(ceil_nn(v), v.ceil() + 0.0, "{v}");
        }
    }
}
