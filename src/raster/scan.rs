//! The prefix-sum scan of the accumulation buffer: runs of equal coverage written into the
//! mask row, as they are or through a light-compensation map.

use super::accum::{Accum, BLOCK};
use super::{CoverageMap, LitRuns, PixelBox};

/// Where a mask's rows lie in its buffer: the pixel of row `r`, column `c` (field
/// coordinates) at `(r - row0)·stride + skip + c`; a row's slice reaches column `end`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Rows {
    stride: usize,
    row0: usize,
    skip: usize,
    end: usize,
}

impl Rows {
    /// A field-sized mask `w` pixels wide.
    pub(super) fn field(w: usize) -> Rows {
        Rows {
            stride: w,
            row0: 0,
            skip: 0,
            end: w,
        }
    }

    /// The box `lit` with a border of one pixel, preceded by `lit.c0` bytes (so that a
    /// row's slice is indexed by field columns): see [`super::Boxed`].
    pub(super) fn boxed(lit: PixelBox) -> Rows {
        let stride = lit.c1 - lit.c0 + 2;
        Rows {
            stride,
            row0: lit.r0,
            skip: stride + 1,
            end: lit.c1,
        }
    }

    /// Bytes of a buffer holding rows `lit.r0..lit.r1` in the [`Rows::boxed`] layout.
    pub(super) fn boxed_len(lit: PixelBox) -> usize {
        lit.c0 + (lit.r1 - lit.r0 + 2) * (lit.c1 - lit.c0 + 2)
    }

    /// Row `r` of `data`, indexed by field column.
    #[inline(always)]
    pub(super) fn row<'d>(&self, data: &'d mut [u8], r: usize) -> &'d mut [u8] {
        let s = (r - self.row0) * self.stride + self.skip;
        &mut data[s..s + self.end]
    }
}

/// How [`scan_runs`] writes runs of equal (thresholded) coverage into a mask row.
pub(super) trait Emit {
    /// Per-row state.
    type Row<'a>: Copy
    where
        Self: 'a;
    fn row(&self, r: usize) -> Self::Row<'_>;
    /// The area outside which lit pixels are reported.
    fn area(&self) -> PixelBox;
    /// Writes columns a..b of `dst` (zero there) for (thresholded) coverage `v` ≠ 0.
    fn fill(row: Self::Row<'_>, dst: &mut [u8], a: usize, b: usize, v: u8);
}

/// The coverage itself (no map).
pub(super) struct Plain;

impl Emit for Plain {
    type Row<'a> = ();
    #[inline(always)]
    fn row(&self, _: usize) {}
    fn area(&self) -> PixelBox {
        PixelBox::ALL
    }
    #[inline(always)]
    fn fill(_: (), dst: &mut [u8], a: usize, b: usize, v: u8) {
        dst[a..b].fill(v);
    }
}

/// Values through a [`CoverageMap`].
pub(super) struct Mapped<'m, M>(pub(super) &'m M);

impl<M: CoverageMap> Emit for Mapped<'_, M> {
    type Row<'a>
        = M::Row<'a>
    where
        Self: 'a;
    #[inline(always)]
    fn row(&self, r: usize) -> M::Row<'_> {
        self.0.row(r)
    }
    fn area(&self) -> PixelBox {
        self.0.area()
    }
    #[inline(always)]
    fn fill(row: M::Row<'_>, dst: &mut [u8], a: usize, b: usize, v: u8) {
        M::fill(row, dst, a, b, v);
    }
}

/// Maps coverage values `data` in place: 0 stays 0, 255 takes `full` (same index), others
/// `edge(index, value)`. Eight bytes at a time: all-off words are skipped, all-on words
/// copied from `full`, so away from edges eight pixels cost one word test (and a copy).
#[inline(always)]
pub fn map_words(data: &mut [u8], full: &[u8], edge: impl Fn(usize, u8) -> u8) {
    let n = data.len().min(full.len());
    let (data, full) = (&mut data[..n], &full[..n]);
    let rd = |d: &[u8], i: usize| u64::from_ne_bytes(d[i..i + 8].try_into().expect("8 bytes"));
    let px = |d: &mut u8, f: u8, i: usize| {
        *d = match *d {
            0 => 0,
            255 => f,
            v => edge(i, v),
        }
    };
    let mut i = 0;
    while i + 8 <= n {
        let w = rd(data, i);
        if w == 0 {
            i += 8;
            while i + 8 <= n && rd(data, i) == 0 {
                i += 8;
            }
        } else if w == u64::MAX {
            data[i..i + 8].copy_from_slice(&full[i..i + 8]);
            i += 8;
            while i + 8 <= n && rd(data, i) == u64::MAX {
                data[i..i + 8].copy_from_slice(&full[i..i + 8]);
                i += 8;
            }
        } else {
            for k in i..i + 8 {
                px(&mut data[k], full[k], k);
            }
            i += 8;
        }
    }
    for k in i..n {
        px(&mut data[k], full[k], k);
    }
}

/// The prefix-sum scan of the accumulation buffer over the pixels of `span`: writes the
/// coverage (thresholded when `BIN`) through `emit` into the rows of `data` (zero there)
/// laid out as `layout` says, clears the buffer and its block marks
/// as it reads them, and returns the sum of the coverage values (before threshold) and the
/// largest winding seen. Only the touched blocks are visited (between them every cell is
/// zero and the value repeats), and each run of equal coverage is written once, when it
/// ends (zero runs are left as they are). With `CHECK`, sets `outside` if a lit pixel lies
/// outside `emit`'s area. With `lit`, appends the lit runs (coverage ≥ 50 %) to it. Appends
/// each row's largest winding and coverage sum to `rows`.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
pub(super) fn scan_runs<E: Emit, const BIN: bool, const CHECK: bool>(
    acc: &mut Accum,
    (data, layout): (&mut [u8], Rows),
    span: PixelBox,
    emit: E,
    outside: &mut bool,
    mut lit: Option<&mut LitRuns>,
    rows: &mut Vec<(f32, u64)>,
) -> (u64, f32) {
    let PixelBox {
        r0,
        r1,
        c0,
        c1: end,
    } = span;
    let area = emit.area();
    let (stride, words, col0) = (acc.stride, acc.words, acc.col0);
    let mut max_winding = 0.0f32;
    let mut lit_sum = 0u64;
    for r in r0..r1 {
        let k = r - acc.row0;
        let row = &mut acc.cells[k * stride..(k + 1) * stride];
        let marks = &mut acc.touched[k * words..(k + 1) * words];
        let mut sink = Runs::<E, BIN, CHECK> {
            er: emit.row(r),
            dst: layout.row(data, r),
            lit_sum: 0,
            lo: usize::MAX,
            hi: 0,
        };
        let mut sum = 0.0f32;
        let mut row_max = 0.0f32;
        // The current run: columns start.. of coverage `val`.
        let mut val = 0u8;
        let mut start = c0;
        // Where the lit run (coverage ≥ 50 %) being followed started.
        let mut lit_from = 0u32;
        for (wi, m) in marks.iter_mut().enumerate() {
            let mut bits = std::mem::take(m);
            while bits != 0 {
                let b = wi * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                // The block's box cells and field columns.
                let (ks, ke) = (b * BLOCK, ((b + 1) * BLOCK).min(stride));
                let (bs, be) = (col0 + ks, col0 + ke);
                let from = bs.max(c0).min(end);
                let to = be.min(end).max(from);
                // Most cells of a touched block are zero: one vectorizable pass marks the
                // nonzero ones, then only those are visited (in column order).
                let mut nonzero = nonzero_cells(&row[ks..ke]);
                // Cells left of the section's box (a rounded line end): not part of the
                // mask, just cleared.
                row[ks..from.max(bs) - col0].fill(0.0);
                nonzero &= (1u64 << (to - bs)) - 1;
                nonzero &= !((1u64 << (from - bs)) - 1);
                while nonzero != 0 {
                    let i = nonzero.trailing_zeros() as usize;
                    let c = bs + i;
                    nonzero &= nonzero - 1;
                    let a = row[ks + i];
                    sum += a;
                    // Cleared as it is read: the buffer is all zeros after the scan.
                    row[ks + i] = 0.0;
                    let v = sum.abs();
                    row_max = row_max.max(v);
                    let nv = (v.min(1.0) * 255.0 + 0.5) as u8;
                    if nv != val {
                        sink.end(start, c, val);
                        // Lit (≥ 128) on one side of c only: a lit run starts or ends.
                        if (nv ^ val) & 0x80 != 0 {
                            if let Some(l) = lit.as_deref_mut() {
                                if nv >= 128 {
                                    lit_from = c as u32;
                                } else {
                                    l.runs.push([r as u32, lit_from, c as u32]);
                                }
                            }
                        }
                        (start, val) = (c, nv);
                    }
                }
                // Cells right of the field (edges carry area one column past their
                // rightmost pixel): not part of the mask, just cleared.
                row[to.max(bs) - col0..ke].fill(0.0);
            }
        }
        if start < end {
            sink.end(start, end, val);
        }
        // A lit run reaching the end of the row.
        if val >= 128 {
            if let Some(l) = lit.as_deref_mut() {
                l.runs.push([r as u32, lit_from, end as u32]);
            }
        }
        lit_sum += sink.lit_sum;
        max_winding = max_winding.max(row_max);
        rows.push((row_max, sink.lit_sum));
        if CHECK && sink.lo < sink.hi {
            *outside |= r < area.r0 || r >= area.r1 || sink.lo < area.c0 || sink.hi > area.c1;
        }
    }
    (lit_sum, max_winding)
}

/// Writes rows `rows` of `span` again, which hold coverage (the nonzero fallback's), as
/// [`scan_runs`] writes them: thresholded when `BIN`, through `emit`, `outside` set as there.
/// Returns the sum of their coverage values and their lit runs (coverage ≥ 50 %), in order.
pub(super) fn emit_rows<E: Emit, const BIN: bool, const CHECK: bool>(
    (data, layout): (&mut [u8], Rows),
    (span, rows): (PixelBox, std::ops::Range<usize>),
    emit: E,
    outside: &mut bool,
    lit: &mut Vec<[u32; 3]>,
) -> u64 {
    let area = emit.area();
    let cols = span.c0..span.c1;
    let mut coverage = vec![0u8; cols.len()];
    let mut sum = 0;
    for r in rows {
        let dst = layout.row(data, r);
        coverage.copy_from_slice(&dst[cols.clone()]);
        dst[cols.clone()].fill(0);
        let mut sink = Runs::<E, BIN, CHECK> {
            er: emit.row(r),
            dst,
            lit_sum: 0,
            lo: usize::MAX,
            hi: 0,
        };
        let mut start = 0;
        for i in 1..=coverage.len() {
            if i == coverage.len() || coverage[i] != coverage[start] {
                let v = coverage[start];
                sink.end(span.c0 + start, span.c0 + i, v);
                if v >= 128 {
                    match lit.last_mut() {
                        Some(l) if l[0] == r as u32 && l[2] == (span.c0 + start) as u32 => {
                            l[2] = (span.c0 + i) as u32
                        }
                        _ => lit.push([r as u32, (span.c0 + start) as u32, (span.c0 + i) as u32]),
                    }
                }
                start = i;
            }
        }
        sum += sink.lit_sum;
        if CHECK && sink.lo < sink.hi {
            *outside |= r < area.r0 || r >= area.r1 || sink.lo < area.c0 || sink.hi > area.c1;
        }
    }
    sum
}

/// Bit i set where `cells[i]` (at most [`BLOCK`] cells) is nonzero. A whole block is one
/// branch-free pass the compiler vectorizes.
#[inline(always)]
fn nonzero_cells(cells: &[f32]) -> u64 {
    let mark = |m: u64, (i, &a): (usize, &f32)| m | (((a != 0.0) as u64) << i);
    match <&[f32; BLOCK]>::try_from(cells) {
        Ok(block) => block.iter().enumerate().fold(0, mark),
        Err(_) => cells.iter().enumerate().fold(0, mark),
    }
}

/// Where [`scan_runs`] puts the runs of one row.
struct Runs<'a, E: Emit + 'a, const BIN: bool, const CHECK: bool> {
    er: E::Row<'a>,
    dst: &'a mut [u8],
    /// Sum of the coverage values of the row.
    lit_sum: u64,
    /// Columns lo..hi hold the row's lit pixels (thresholded coverage above zero); kept
    /// when `CHECK` (the lit box is not inside the map's area).
    lo: usize,
    hi: usize,
}

impl<E: Emit, const BIN: bool, const CHECK: bool> Runs<'_, E, BIN, CHECK> {
    /// Columns a..b have coverage `v`.
    #[inline(always)]
    fn end(&mut self, a: usize, b: usize, v: u8) {
        if v != 0 {
            self.lit_sum += v as u64 * (b - a) as u64;
            let t = match (BIN, v >= 128) {
                (false, _) => v,
                (true, true) => 255,
                (true, false) => 0,
            };
            if t != 0 {
                E::fill(self.er, self.dst, a, b, t);
                if CHECK {
                    self.lo = self.lo.min(a);
                    self.hi = self.hi.max(b);
                }
            }
        }
    }
}
