//! Rasterization of layer sections into 8-bit masks in field pixel coordinates.
//!
//! Orientation (PrusaSlicer's landscape convention): the mask is a top view, +X to the
//! right, +Y up; build-plane point (x, y) measured from the field's bottom-left corner
//! lies in column `floor(x / p)`, row `H − 1 − floor(y / p)`.
//!
//! * Anti-aliased masks (the default) hold the exact fraction of each pixel's area
//!   inside the section, `round(255 · coverage)`, computed analytically with a signed-area
//!   accumulation buffer. The rows where shells overlap (winding above 1), and a row either
//!   side, are redone with an exact-span nonzero-winding scanline fill on 32 sub-scanlines
//!   per row.
//! * Binary masks (`--binary`) threshold that coverage at 50 %.
//!
//! Why not tiny-skia: docs/ARCHITECTURE.md (it is the reference renderer of
//! `benches/raster.rs`).

pub use crate::png::PixelBox;
use crate::profile::Field;
use crate::slice::Contour;

mod accum;
mod nonzero;
mod pool;
mod scan;
mod view;

use accum::{line, Accum};
pub use pool::ScratchPool;
pub use scan::map_words;
use scan::{emit_rows, scan_runs, Mapped, Plain, Rows};
use std::ops::Range;
#[cfg(any(test, feature = "internals"))]
pub use view::projector_view;
pub use view::{projector_view_in, shows_as_is};

/// The winding above which a scanned row counts as overlapping shells (the exact
/// accumulation reaches 1 inside a shell, up to rounding).
const OVERLAP: f32 = 1.001;

/// A grayscale image, row-major, top row first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mask {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// `width × height` values.
    pub data: Vec<u8>,
}

impl Mask {
    /// An all-black mask.
    pub fn zeros(width: u32, height: u32) -> Mask {
        Mask {
            width,
            height,
            data: vec![0; width as usize * height as usize],
        }
    }

    /// Value at (col, row).
    #[cfg(test)]
    pub fn get(&self, col: u32, row: u32) -> u8 {
        self.data[row as usize * self.width as usize + col as usize]
    }

    /// Sum of values / 255: the lit area in pixels.
    #[cfg(any(test, feature = "internals"))]
    pub fn lit_pixels(&self) -> f64 {
        self.lit_pixels_in(PixelBox::whole(self.width as usize, self.height as usize))
    }

    /// Like [`lit_pixels`](Self::lit_pixels) when the mask is known to be zero outside
    /// `lit_box` (e.g. [`Scratch::lit_box`]): visits only that box.
    pub fn lit_pixels_in(&self, lit_box: PixelBox) -> f64 {
        box_sum(self, lit_box) as f64 / 255.0
    }
}

/// A mask kept inside its lit box only ([`Rasterizer::coverage_boxed`]): the box with a
/// border of one zero pixel all round, its rows `lit.c1 − lit.c0 + 2` bytes apart,
/// preceded by `lit.c0` zero bytes. The pixel of row `r`, column `c` (field coordinates)
/// lies at `lit.c0 + (r − lit.r0 + 1)·(lit.c1 − lit.c0 + 2) + (c − lit.c0 + 1)`.
#[derive(Debug, Clone, Default)]
pub struct Boxed {
    /// The bytes.
    pub data: Vec<u8>,
    /// The lit box: zero outside it (empty when nothing was drawn; `data` is then empty).
    pub lit: PixelBox,
}

/// The lit pixels of a mask (coverage at least 50 %, the pixels a binary mask lights) as
/// runs `[row, first column, end column)` in image coordinates (row 0 at the top), sorted
/// by row then column; runs of a row neither overlap nor touch.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LitRuns {
    /// The runs.
    pub runs: Vec<[u32; 3]>,
}

impl LitRuns {
    /// The lit runs of coverage mask `m` inside its box `[r0, r1, c0, c1]` (a
    /// [`PixelBox`]'s rows `r0..r1` and columns `c0..c1`; zero outside).
    #[cfg(test)]
    pub fn of_mask(m: &Mask, [r0, r1, c0, c1]: [usize; 4]) -> LitRuns {
        let mut l = LitRuns::default();
        l.scan_mask(m, PixelBox { r0, r1, c0, c1 });
        l
    }

    /// Replaces the runs by the lit runs of `m` inside `lit_box` (zero outside).
    #[cfg(test)]
    fn scan_mask(&mut self, m: &Mask, lit_box: PixelBox) {
        let PixelBox { r0, r1, c0, c1 } = lit_box;
        self.runs.clear();
        let w = m.width as usize;
        for r in r0..r1 {
            let row = &m.data[r * w..(r + 1) * w];
            let mut c = c0;
            while c < c1 {
                if row[c] >= 128 {
                    let a = c;
                    while c < c1 && row[c] >= 128 {
                        c += 1;
                    }
                    self.runs.push([r as u32, a as u32, c as u32]);
                } else {
                    c += 1;
                }
            }
        }
    }
}

/// What a [`Scratch`] knows of the last mask it drew besides the mask: its lit box, its
/// lit area and its lit runs ([`Scratch::drawn`]), for [`Rasterizer::redraw`].
#[derive(Debug, Clone, Default)]
pub struct Drawn(PixelBox, Option<u64>, Option<LitRuns>);

/// Reusable scratch memory for [`Rasterizer::coverage`] (one per worker thread).
#[derive(Debug, Default)]
pub struct Scratch {
    /// When set, [`Rasterizer::render`] keeps the lit runs of each mask it draws in
    /// [`Scratch::lit_runs`].
    pub record_runs: bool,
    /// The lit runs of the last [`Rasterizer::render`] mask (when `record_runs`).
    pub lit_runs: LitRuns,
    acc: Vec<f32>,
    /// Sum of the last [`Rasterizer::coverage`] mask's values, counted by the scan.
    lit_sum: Option<u64>,
    /// Per accumulation row, one bit per [`BLOCK`] cells that `line` wrote to: the scan
    /// visits only those blocks and skips the (zero) cells between them.
    touched: Vec<u64>,
    /// Recycled mask buffers with the box outside which each is known to be zero.
    spare: Vec<(Vec<u8>, PixelBox)>,
    /// The last [`Rasterizer::coverage`] mask's lit box ([`Scratch::lit_box`]).
    lit: PixelBox,
    /// Whether the last [`Rasterizer::render`] reported its layer to the map as lit
    /// outside the map's area, and what the map made of it (how far it reaches).
    reported_outside: Option<f64>,
    /// Per row of the last scan's box: its largest winding and its coverage sum.
    rows: Vec<(f32, u64)>,
}

impl Scratch {
    /// The last [`Rasterizer::coverage`] mask's lit box: the mask is zero outside it (lets
    /// later passes skip the empty part of the field).
    pub fn lit_box(&self) -> PixelBox {
        self.lit
    }

    /// Grows the last mask's lit box to `b` (and its own box): a caller that lit pixels
    /// outside it (the cure correction's widened features) keeps the box covering every
    /// lit pixel, so [`Scratch::recycle`] clears them.
    pub fn grow_lit_box(&mut self, b: PixelBox) {
        let l = &mut self.lit;
        if l.r0 >= l.r1 || l.c0 >= l.c1 {
            *l = b;
        } else if b.r0 < b.r1 && b.c0 < b.c1 {
            l.r0 = l.r0.min(b.r0);
            l.r1 = l.r1.max(b.r1);
            l.c0 = l.c0.min(b.c0);
            l.c1 = l.c1.max(b.c1);
        }
    }

    /// Whether the last [`Rasterizer::render`] with a map reported its layer as lit
    /// outside the map's area ([`CoverageMap::lit_outside`]), with what the map returned:
    /// a caller repeating that layer's mask without drawing it reports it again.
    pub fn reported_outside(&self) -> Option<f64> {
        self.reported_outside
    }

    /// The lit area of the last [`Rasterizer::coverage`] mask in pixels (sum of values /
    /// 255), as [`Mask::lit_pixels`] gives it, without another pass over the mask. For
    /// [`Rasterizer::render`], the lit area of the coverage (before threshold and map).
    pub fn lit_pixels(&self, m: &Mask) -> f64 {
        match self.lit_sum {
            Some(sum) => sum as f64 / 255.0,
            None => m.lit_pixels_in(self.lit),
        }
    }

    /// Hands the mask returned by the latest [`Rasterizer::coverage`] call back for reuse
    /// (saves a fresh, page-faulting allocation per layer). The mask may have been changed,
    /// but only inside [`lit_box`](Self::lit_box): only that box is cleared for reuse.
    pub fn recycle(&mut self, m: Mask) {
        let lit = self.lit;
        debug_assert!(
            m.data.chunks(m.width as usize).enumerate().all(|(r, row)| {
                row.iter()
                    .enumerate()
                    .all(|(c, &v)| v == 0 || (lit.rows().contains(&r) && lit.cols().contains(&c)))
            }),
            "recycled mask is lit outside its lit box"
        );
        if self.spare.len() < 4 {
            self.spare.push((m.data, self.lit));
        }
    }

    /// What the scratch knows of the last [`Rasterizer::coverage`] mask besides the mask.
    pub fn drawn(&self) -> Drawn {
        let runs = self.record_runs.then(|| self.lit_runs.clone());
        Drawn(self.lit, self.lit_sum, runs)
    }

    /// Cells of the accumulation buffer held (its size follows the largest section box
    /// drawn, at most twice its cells, not the field).
    #[cfg(test)]
    pub(crate) fn accum_cells(&self) -> usize {
        self.acc.len()
    }

    fn zeroed(&mut self, w: usize, h: usize) -> Vec<u8> {
        self.zeroed_outside(w, h, PixelBox::EMPTY)
    }

    /// A `w × h` buffer that is zero outside `keep` (inside it, any values: the caller
    /// writes every pixel of `keep`).
    fn zeroed_outside(&mut self, w: usize, h: usize, keep: PixelBox) -> Vec<u8> {
        match self.spare.pop() {
            Some((mut v, old)) if v.len() == w * h => {
                // The recycled buffer's lit box, but for the part of it `keep` covers.
                let clamp = |c: usize| c.clamp(old.c0, old.c1);
                let (kc0, kc1) = (clamp(keep.c0), clamp(keep.c1.max(keep.c0)));
                for r in old.rows() {
                    let row = &mut v[r * w..(r + 1) * w];
                    if keep.rows().contains(&r) {
                        row[old.c0..kc0].fill(0);
                        row[kc1..old.c1].fill(0);
                    } else {
                        row[old.cols()].fill(0);
                    }
                }
                v
            }
            _ => vec![0; w * h],
        }
    }
}

/// Converts sections (in build-plane mm) to masks of a field.
#[derive(Debug, Clone, Copy)]
pub struct Rasterizer {
    field: Field,
}

impl Rasterizer {
    /// A rasterizer for `field`.
    pub fn new(field: Field) -> Self {
        Rasterizer { field }
    }

    #[inline]
    fn px(&self, p: [f64; 2]) -> (f64, f64) {
        let s = 1.0 / self.field.pixel_mm;
        (p[0] * s, self.field.height_px as f64 - p[1] * s)
    }

    /// Anti-aliased coverage mask of the section (exact area fractions).
    pub fn coverage(&self, contours: &[Contour], scratch: &mut Scratch) -> Mask {
        self.render::<NoMap>(contours, scratch, false, None)
    }

    /// A [`Rasterizer::coverage`] mask again without drawing it: `paint` writes every pixel
    /// of its lit box (the mask it is given is zero outside that box, anything inside), the
    /// scratch is left as that call left it (`drawn`, [`Scratch::drawn`] after it). `None`
    /// when only one of `drawn` and the scratch records lit runs.
    pub fn redraw(
        &self,
        scratch: &mut Scratch,
        drawn: &Drawn,
        paint: impl FnOnce(&mut Mask),
    ) -> Option<Mask> {
        if scratch.record_runs != drawn.2.is_some() {
            return None;
        }
        let (w, h) = (self.field.width_px, self.field.height_px);
        let data = scratch.zeroed_outside(w as usize, h as usize, drawn.0);
        let mut m = Mask {
            width: w,
            height: h,
            data,
        };
        paint(&mut m);
        (scratch.lit, scratch.lit_sum, scratch.reported_outside) = (drawn.0, drawn.1, None);
        let runs = drawn.2.as_ref().map_or(&[][..], |r| &r.runs);
        scratch.lit_runs.runs.clear();
        scratch.lit_runs.runs.extend_from_slice(runs);
        Some(m)
    }

    /// The mask of a layer as it is written: coverage, thresholded at 50 % when `binary`
    /// (as [`threshold`] does), then mapped through `map` (light compensation) when given.
    ///
    /// The scan applies the map as it writes each value (the rows where shells overlap, drawn
    /// again by the nonzero rule, are written the same way), unless the map is not
    /// [`CoverageMap::fusable`]: then the finished (thresholded) coverage goes through
    /// [`CoverageMap::apply`], with the same bytes. The lit area ([`Scratch::lit_pixels`]) is
    /// that of the coverage, before threshold and map.
    #[inline(never)]
    pub fn render<M: CoverageMap>(
        &self,
        contours: &[Contour],
        scratch: &mut Scratch,
        binary: bool,
        map: Option<&M>,
    ) -> Mask {
        let w = self.field.width_px as usize;
        let h = self.field.height_px as usize;
        let mut out = Mask {
            width: w as u32,
            height: h as u32,
            data: scratch.zeroed(w, h),
        };
        let Some(bounds) = self.begin(contours, scratch) else {
            return out;
        };
        let (outside, mapped) = self.scan_into(
            contours,
            scratch,
            (binary, map),
            bounds,
            (&mut out.data, Rows::field(w)),
        );
        let lit = scratch.lit;
        scratch.reported_outside = match (map, mapped) {
            (Some(m), false) => m.apply(&mut out, lit),
            (Some(m), true) if outside => Some(m.lit_outside(&out, lit)),
            _ => None,
        };
        out
    }

    /// The [`coverage`](Self::coverage) mask of the section inside its lit box only, written
    /// into `buf` (its allocation reused) as a [`Boxed`] mask; the scratch is left as
    /// `coverage` leaves it ([`Scratch::lit_box`], [`Scratch::drawn`]). The same values,
    /// without a field-sized buffer to clear and copy out of.
    pub fn coverage_boxed(
        &self,
        contours: &[Contour],
        scratch: &mut Scratch,
        mut buf: Vec<u8>,
    ) -> Boxed {
        buf.clear();
        let Some(bounds) = self.begin(contours, scratch) else {
            return Boxed {
                data: buf,
                lit: PixelBox::EMPTY,
            };
        };
        let lit = self.lit_of(bounds);
        buf.resize(Rows::boxed_len(lit), 0);
        self.scan_into::<NoMap>(
            contours,
            scratch,
            (false, None),
            bounds,
            (&mut buf, Rows::boxed(lit)),
        );
        Boxed { data: buf, lit }
    }

    /// Resets the scratch's record of the last mask drawn; the box [`bounds`](Self::bounds)
    /// of `contours` (`None` when there are none).
    fn begin(&self, contours: &[Contour], scratch: &mut Scratch) -> Option<[usize; 4]> {
        scratch.lit = PixelBox::EMPTY;
        scratch.lit_sum = Some(0);
        scratch.lit_runs.runs.clear();
        scratch.reported_outside = None;
        (!contours.is_empty()).then(|| self.bounds(contours))
    }

    /// The lit box of a section whose [`bounds`](Self::bounds) are `[r0, r1, c0, c1]`.
    fn lit_of(&self, [r0, r1, c0, c1]: [usize; 4]) -> PixelBox {
        PixelBox::new(r0, r1, c0, c1.min(self.field.width_px as usize))
    }

    /// Draws `contours` (their box `bounds`) into `out` (zero there, rows laid out as
    /// `layout` says): the scan, thresholded (`binary`) and through the map when it is
    /// fusable, and the rows where shells overlap drawn again by the nonzero rule. Records
    /// the lit box, sum and runs in the scratch. Returns whether a lit pixel lies outside
    /// the map's area and whether the map was applied.
    fn scan_into<M: CoverageMap>(
        &self,
        contours: &[Contour],
        scratch: &mut Scratch,
        (binary, map): (bool, Option<&M>),
        bounds: [usize; 4],
        (out, layout): (&mut [u8], Rows),
    ) -> (bool, bool) {
        let [r0, r1, c0, c1] = bounds;
        let w = self.field.width_px as usize;
        let acc = &mut Accum::of_box(&mut scratch.acc, &mut scratch.touched, bounds);
        self.accumulate(contours, acc);
        let lit = self.lit_of(bounds);
        scratch.lit = lit;
        let fused = map.filter(|m| m.fusable());
        let mut outside = false;
        let runs = scratch.record_runs.then_some(&mut scratch.lit_runs);
        let rows = &mut scratch.rows;
        rows.clear();
        // Rows where shells overlap: the accumulated winding integral over-counts pixels
        // where two boundaries meet; they are drawn again with the exact nonzero rule (with
        // a row either side, where an overlap may lie in pixels that do not reach 1).
        let mut redo: Vec<Range<usize>> = Vec::new();
        let mut redone = (0, Vec::new());
        // The scan for each emitter, threshold (`BIN`) and outside check (`CHECK`), then the
        // overlapping rows drawn again and written as the scan writes.
        macro_rules! scan {
            ($emit:expr, $bin:literal, $check:literal) => {{
                let e = $emit;
                let (sum, max) = scan_runs::<_, $bin, $check>(
                    acc,
                    (&mut *out, layout),
                    lit,
                    e,
                    &mut outside,
                    runs,
                    rows,
                );
                if max > OVERLAP {
                    redo = overlapping_rows(rows, lit);
                    self.coverage_nonzero(contours, (&mut *out, layout), lit, &redo);
                    for rs in &redo {
                        redone.0 += emit_rows::<_, $bin, $check>(
                            (&mut *out, layout),
                            (lit, rs.clone()),
                            $emit,
                            &mut outside,
                            &mut redone.1,
                        );
                    }
                }
                sum
            }};
        }
        let mut lit_sum = match (fused, binary) {
            (Some(m), binary) => {
                // Whether the scan must look for lit pixels outside the map's area.
                let area = m.area();
                let check = r0 < area.r0 || r1 > area.r1 || c0 < area.c0 || c1.min(w) > area.c1;
                match (binary, check) {
                    (false, false) => scan!(Mapped(m), false, false),
                    (false, true) => scan!(Mapped(m), false, true),
                    (true, false) => scan!(Mapped(m), true, false),
                    (true, true) => scan!(Mapped(m), true, true),
                }
            }
            (None, false) => scan!(Plain, false, false),
            (None, true) => scan!(Plain, true, false),
        };
        if !redo.is_empty() {
            let scanned = |r: usize| scratch.rows[r - lit.r0].1;
            lit_sum -= redo
                .iter()
                .flat_map(|rs| rs.clone())
                .map(scanned)
                .sum::<u64>();
            lit_sum += redone.0;
            if scratch.record_runs {
                splice_rows(&mut scratch.lit_runs.runs, &redo, &redone.1);
            }
        }
        scratch.lit_sum = Some(lit_sum);
        (outside, fused.is_some())
    }

    /// The rows `r0..r1` and columns `c0..c1` that [`accumulate`](Self::accumulate) writes
    /// to for `contours` (`c1` may be one past the field: edges carry area one column
    /// past their rightmost pixel; the cells of column `c1` are written too, and hold 0).
    #[inline]
    fn bounds(&self, contours: &[Contour]) -> [usize; 4] {
        let w = self.field.width_px as usize;
        let h = self.field.height_px as usize;
        let (mut r0, mut r1) = (h, 0usize);
        let (mut c0, mut c1) = (w, 0usize);
        // Clamped, so non-negative: `as usize` truncates = floors.
        let ceil = |v: f64| {
            let t = v as usize;
            t + ((t as f64) < v) as usize
        };
        for p in contours.iter().flatten() {
            let (x, y) = self.clamped_px(*p);
            r0 = r0.min(y as usize);
            r1 = r1.max(ceil(y));
            c0 = c0.min(x as usize);
            c1 = c1.max(ceil(x) + 1);
        }
        [r0, r1.min(h), c0, c1.min(w + 1)]
    }

    /// `p` in pixel coordinates, clamped into the field: the planner guarantees parts fit,
    /// this only guards.
    #[inline]
    fn clamped_px(&self, p: [f64; 2]) -> (f64, f64) {
        let (x, y) = self.px(p);
        let (w, h) = (self.field.width_px as f64, self.field.height_px as f64);
        (x.clamp(0.0, w), y.clamp(0.0, h))
    }

    /// Adds every edge of `contours` to the accumulation buffer (its box from
    /// [`bounds`](Self::bounds)).
    #[inline]
    fn accumulate(&self, contours: &[Contour], acc: &mut Accum) {
        let h = self.field.height_px as usize;
        for c in contours {
            for i in 0..c.len() {
                let (x0, y0) = self.clamped_px(c[i]);
                let (x1, y1) = self.clamped_px(c[(i + 1) % c.len()]);
                line(acc, h, x0 as f32, y0 as f32, x1 as f32, y1 as f32);
            }
        }
    }

    /// Binary mask: 255 where the anti-aliased coverage is at least 50 % (value ≥ 128),
    /// else 0.
    #[cfg(test)]
    pub fn binary(&self, contours: &[Contour], scratch: &mut Scratch) -> Mask {
        self.render::<NoMap>(contours, scratch, true, None)
    }
}

/// The rows of `lit` to draw again with the nonzero rule: those whose winding (`rows`, one
/// per row of `lit` from its first) exceeds [`OVERLAP`], and a row either side; ascending,
/// disjoint ranges.
fn overlapping_rows(rows: &[(f32, u64)], lit: PixelBox) -> Vec<Range<usize>> {
    let mut out: Vec<Range<usize>> = Vec::new();
    for (i, _) in rows.iter().enumerate().filter(|(_, r)| r.0 > OVERLAP) {
        let r = lit.r0 + i;
        let rs = r.saturating_sub(1).max(lit.r0)..(r + 2).min(lit.r1);
        match out.last_mut() {
            Some(l) if l.end >= rs.start => l.end = rs.end,
            _ => out.push(rs),
        }
    }
    out
}

/// Replaces the lit runs of the rows `redo` (ascending ranges) in `runs` (sorted by row) by
/// `fresh` (the runs of those rows, sorted).
fn splice_rows(runs: &mut Vec<[u32; 3]>, redo: &[Range<usize>], fresh: &[[u32; 3]]) {
    let redone = |r: u32| redo.iter().any(|rs| rs.contains(&(r as usize)));
    let mut out = Vec::with_capacity(runs.len() + fresh.len());
    let mut f = fresh.iter().peekable();
    for &run in runs.iter().filter(|run| !redone(run[0])) {
        while let Some(&&n) = f.peek() {
            if n[0] >= run[0] {
                break;
            }
            out.push(n);
            f.next();
        }
        out.push(run);
    }
    out.extend(f);
    *runs = out;
}

/// Thresholds a coverage mask at 50 % in place: values ≥ 128 become 255, others 0.
#[cfg(any(test, feature = "internals"))]
pub fn threshold(m: &mut Mask) {
    threshold_in(m, PixelBox::whole(m.width as usize, m.height as usize));
}

/// Thresholds the box `lit_box` of a mask at 50 % in place (the mask is zero outside it).
pub fn threshold_in(m: &mut Mask, lit_box: PixelBox) {
    let PixelBox { r0, r1, c0, c1 } = lit_box;
    let w = m.width as usize;
    for r in r0..r1 {
        for v in &mut m.data[r * w + c0..r * w + c1] {
            *v = if *v >= 128 { 255 } else { 0 };
        }
    }
}

/// Sum of a mask's values inside `b` (u32 partial sums per row vectorize well; a row
/// cannot overflow them).
fn box_sum(m: &Mask, b: PixelBox) -> u64 {
    let PixelBox { r0, r1, c0, c1 } = b;
    let w = m.width as usize;
    (r0..r1)
        .map(|r| {
            m.data[r * w + c0..r * w + c1]
                .iter()
                .map(|&v| v as u32)
                .sum::<u32>() as u64
        })
        .sum()
}

/// A per-pixel map from coverage to mask values that the rasterizer's scan can apply as it
/// writes the mask ([`Rasterizer::render`]): light compensation
/// ([`crate::optics::Compensator`]). Coverage 0 always stays 0.
pub trait CoverageMap {
    /// Whether the scan may apply the map as it writes; if not, [`apply`](Self::apply) maps
    /// the finished mask (e.g. when the map must look at the coverage of other pixels first).
    fn fusable(&self) -> bool;
    /// The map's area: the scan reports through [`lit_outside`](Self::lit_outside) a layer
    /// it mapped that has a lit pixel (coverage, thresholded when binary, above zero)
    /// outside it.
    fn area(&self) -> PixelBox;
    /// Called once for each layer the scan mapped that is lit outside [`area`](Self::area),
    /// with its mapped mask `m` (zero outside `lit_box`); returns how far it reaches (for
    /// [`Scratch::reported_outside`]).
    fn lit_outside(&self, m: &Mask, lit_box: PixelBox) -> f64;
    /// What the map needs for one row (looked up once per row, not per pixel).
    type Row<'a>: Copy
    where
        Self: 'a;
    /// The per-row state of row `r`.
    fn row(&self, r: usize) -> Self::Row<'_>;
    /// Writes columns a..b of a mask row `dst` (zero there) for coverage `v` (1..=255):
    /// what coverage `v` becomes in each of those columns.
    fn fill(row: Self::Row<'_>, dst: &mut [u8], a: usize, b: usize, v: u8);
    /// Maps a finished coverage mask in place; it is zero outside `lit_box`. Returns,
    /// for a layer lit outside [`area`](Self::area) (and reported as such), what
    /// [`lit_outside`](Self::lit_outside) returns.
    fn apply(&self, m: &mut Mask, lit_box: PixelBox) -> Option<f64>;
}

/// No map (the [`Rasterizer::coverage`] and [`Rasterizer::binary`] masks).
enum NoMap {}

impl CoverageMap for NoMap {
    fn fusable(&self) -> bool {
        match *self {}
    }
    fn area(&self) -> PixelBox {
        match *self {}
    }
    fn lit_outside(&self, _: &Mask, _: PixelBox) -> f64 {
        match *self {}
    }
    type Row<'a> = ();
    fn row(&self, _: usize) {
        match *self {}
    }
    fn fill(_: (), _: &mut [u8], _: usize, _: usize, _: u8) {}
    fn apply(&self, _: &mut Mask, _: PixelBox) -> Option<f64> {
        match *self {}
    }
}

#[cfg(test)]
mod tests {
    use super::accum::BLOCK;
    use super::*;
    use crate::test_support::{closed, ngon as circle, rect, xorshift};

    fn field() -> Field {
        Field {
            width_px: 1024,
            height_px: 768,
            pixel_mm: 0.0634765625,
        }
    }

    #[test]
    fn pixel_aligned_square_is_exact_and_oriented() {
        let p = 0.0634765625;
        let r = Rasterizer::new(field());
        // columns 100..110, rows from the bottom 20..30 → image rows 738..748
        let c = rect(100.0 * p, 20.0 * p, 110.0 * p, 30.0 * p);
        let mut s = Scratch::default();
        let m = r.coverage(std::slice::from_ref(&c), &mut s);
        let b = r.binary(std::slice::from_ref(&c), &mut Scratch::default());
        for row in 0..768 {
            for col in 0..1024 {
                let inside = (100..110).contains(&col) && (738..748).contains(&row);
                let want = if inside { 255 } else { 0 };
                assert_eq!(m.get(col, row), want, "aa {col},{row}");
                assert_eq!(b.get(col, row), want, "bin {col},{row}");
            }
        }
        // Scratch is left clean: a second, different call is unaffected.
        let m2 = r.coverage(&[rect(0.0, 0.0, p, p)], &mut s);
        assert_eq!(m2.lit_pixels(), 1.0);
        assert_eq!(m2.get(0, 767), 255);
    }

    /// Shoelace area of a polygon, mm².
    fn area(c: &Contour) -> f64 {
        (0..c.len())
            .map(|i| {
                let (a, b) = (c[i], c[(i + 1) % c.len()]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum::<f64>()
            / 2.0
    }

    #[test]
    fn random_polygons_reused_scratch_matches_fresh_and_area() {
        // Fixed-seed random star polygons, some crossing the field's edges (clamped), drawn
        // one after another with one scratch: every mask must equal the one drawn with a
        // fresh scratch (the accumulation buffer and its block marks are left clean), and
        // polygons inside the field must cover their exact area.
        let f = field();
        let (fw, fh) = (1024.0 * f.pixel_mm, 768.0 * f.pixel_mm);
        let r = Rasterizer::new(f);
        let mut rnd = xorshift(0x9e37_79b9_7f4a_7c15);
        let mut reused = Scratch::default();
        for case in 0..40 {
            let (cx, cy) = (rnd() * fw, rnd() * fh);
            let n = 3 + (rnd() * 60.0) as usize;
            let rmax = 0.2 + rnd() * if case % 4 == 0 { 40.0 } else { 8.0 };
            let star = closed(n, true, |a| {
                let rad = rmax * (0.3 + 0.7 * rnd());
                [cx + rad * a.cos(), cy + rad * a.sin()]
            });
            let shapes = [star.clone()];
            let a = r.coverage(&shapes, &mut reused);
            let b = r.coverage(&shapes, &mut Scratch::default());
            assert!(
                a.data == b.data,
                "case {case}: reused scratch changed the mask"
            );
            assert_eq!(
                reused.lit_pixels(&a),
                a.lit_pixels(),
                "case {case}: lit sum"
            );
            let inside = star
                .iter()
                .all(|p| (0.0..fw).contains(&p[0]) && (0.0..fh).contains(&p[1]));
            if inside {
                let got = a.lit_pixels() * f.pixel_mm * f.pixel_mm;
                let want = area(&star);
                // 8-bit rounding: at most half a step per edge pixel.
                let tol = 1e-3 * want + 0.5 / 255.0 * f.pixel_mm * rmax * 30.0;
                assert!((got - want).abs() <= tol, "case {case}: {got} vs {want}");
            }
            reused.recycle(a);
        }
    }

    #[test]
    fn half_pixel_edges_give_half_coverage() {
        let p = 0.0634765625;
        let r = Rasterizer::new(field());
        let c = rect(10.5 * p, 10.0 * p, 20.0 * p, 20.5 * p);
        let m = r.coverage(&[c], &mut Scratch::default());
        // Bottom rows 10..20 are full (image rows 757..748), bottom row 20 half (row 747).
        assert_eq!(m.get(10, 750), 128); // left column half
        assert_eq!(m.get(15, 747), 128); // top row half
        assert_eq!(m.get(10, 747), 64); // corner quarter
        assert_eq!(m.get(15, 750), 255);
        assert_eq!(m.get(15, 746), 0);
        assert_eq!(m.get(9, 750), 0);
    }

    #[test]
    fn ring_area_and_hole() {
        let r = Rasterizer::new(field());
        let outer = circle(30.0, 20.0, 10.0, 720, true);
        let hole = circle(30.0, 20.0, 4.0, 720, false);
        let exact = crate::slice::signed_area(&outer) + crate::slice::signed_area(&hole);
        let m = r.coverage(&[outer.clone(), hole.clone()], &mut Scratch::default());
        let px2 = 0.0634765625f64.powi(2);
        let area = m.lit_pixels() * px2;
        assert!((area - exact).abs() / exact < 1e-3, "{area} vs {exact}");
        // Centre of the hole is dark, ring is lit.
        let col = (30.0 / 0.0634765625) as u32;
        let row = 767 - (20.0 / 0.0634765625) as u32;
        assert_eq!(m.get(col, row), 0);
        assert_eq!(m.get(col + (7.0 / 0.0634765625) as u32, row), 255);
        let b = r.binary(&[outer, hole], &mut Scratch::default());
        let barea = b.lit_pixels() * px2;
        assert!((barea - exact).abs() / exact < 2e-3, "{barea} vs {exact}");
    }

    #[test]
    fn a_small_section_in_a_huge_field_uses_a_buffer_of_its_box() {
        // A 16384 × 16384 px field (268 M pixels): the accumulation buffer holds the
        // section's box (plus a block of columns), never the field; the mask's values are
        // exact there, and one scratch drawing boxes of other shapes and places in turn
        // gives the masks a fresh scratch gives (the buffer is left clean at any stride).
        let p = 0.0625;
        let f = Field {
            width_px: 16384,
            height_px: 16384,
            pixel_mm: p,
        };
        let r = Rasterizer::new(f);
        let mut s = Scratch::default();
        // Columns 9000..9100, rows from the bottom 12000..12040 → image rows 4344..4384,
        // the left column half covered.
        let c = rect(8999.5 * p, 12000.0 * p, 9100.0 * p, 12040.0 * p);
        let m = r.coverage(std::slice::from_ref(&c), &mut s);
        let b = s.lit_box();
        assert_eq!((b.r0, b.r1, b.c0, b.c1), (4344, 4384, 8999, 9101));
        assert!(
            s.accum_cells() <= 40 * (102 + 2 * BLOCK),
            "accumulation buffer of {} cells for a 40 × 102 px box",
            s.accum_cells()
        );
        assert_eq!(m.get(8999, 4350), 128);
        assert_eq!(m.get(9000, 4344), 255);
        assert_eq!(m.get(9099, 4383), 255);
        assert_eq!(m.get(9100, 4383), 0);
        assert_eq!(m.lit_pixels_in(b), (100 * 255 + 128) as f64 * 40.0 / 255.0);
        // (Masks are dropped, not recycled: the recycling check would visit the field.)
        drop(m);
        let mut largest = 40 * (102 + 2 * BLOCK);
        let mut rnd = xorshift(0x5eed_1234_abcd_ef01);
        for case in 0..12 {
            let (cx, cy) = (rnd() * 1000.0, rnd() * 1000.0);
            let rmax = 0.3 + rnd() * 6.0;
            let star = closed(5 + case * 3, true, |a| {
                let rad = rmax * (0.3 + 0.7 * rnd());
                [cx + rad * a.cos(), cy + rad * a.sin()]
            });
            let shapes = [star];
            let a = r.coverage(&shapes, &mut s);
            let box_a = s.lit_box();
            // The buffer grows to the largest box drawn (at most twice its cells).
            largest = largest.max((box_a.r1 - box_a.r0) * (box_a.c1 - box_a.c0 + 2 + 2 * BLOCK));
            assert!(s.accum_cells() <= 2 * largest, "case {case}");
            let mut fresh = Scratch::default();
            let want = r.coverage(&shapes, &mut fresh);
            assert_eq!(box_a, fresh.lit_box(), "case {case}");
            for row in box_a.rows() {
                let cols = row * 16384 + box_a.c0..row * 16384 + box_a.c1;
                assert!(
                    a.data[cols.clone()] == want.data[cols],
                    "case {case} row {row}"
                );
            }
        }
    }

    /// Fixed-seed random sections (stars, some crossing the field's edges; pairs of
    /// overlapping stars, drawn by the nonzero fallback; none) drawn straight into their
    /// box with one scratch and one reused buffer: each equals the field-sized coverage
    /// mask inside the box, every other byte is zero, and the scratch records the same lit
    /// box, sum and runs.
    #[test]
    fn boxed_coverage_is_the_coverage_inside_its_box() {
        let f = field();
        let (fw, fh) = (1024.0 * f.pixel_mm, 768.0 * f.pixel_mm);
        let r = Rasterizer::new(f);
        let mut rnd = xorshift(0x5851_f42d_4c95_7f2d);
        let mut boxed = Scratch {
            record_runs: true,
            ..Scratch::default()
        };
        let mut buf = Vec::new();
        let mut overlapped = 0;
        for case in 0..60 {
            let (cx, cy) = (rnd() * fw, rnd() * fh);
            let rmax = 0.2 + rnd() * if case % 4 == 0 { 40.0 } else { 8.0 };
            let mut star = |dx: f64| {
                let n = 3 + (rnd() * 60.0) as usize;
                closed(n, true, |a| {
                    let rad = rmax * (0.3 + 0.7 * rnd());
                    [cx + dx + rad * a.cos(), cy + rad * a.sin()]
                })
            };
            let shapes = match case % 5 {
                0 => vec![star(0.0), star(0.5 * rmax)],
                4 if case == 9 => Vec::new(),
                _ => vec![star(0.0)],
            };
            let mut plain = Scratch {
                record_runs: true,
                ..Scratch::default()
            };
            let m = r.coverage(&shapes, &mut plain);
            let b = r.coverage_boxed(&shapes, &mut boxed, std::mem::take(&mut buf));
            let lit = plain.lit_box();
            assert_eq!((b.lit, boxed.lit_box()), (lit, lit), "case {case}");
            assert_eq!(boxed.lit_pixels(&m), plain.lit_pixels(&m), "case {case}");
            assert_eq!(boxed.lit_runs, plain.lit_runs, "case {case}");
            overlapped += plain.rows.iter().any(|r| r.0 > OVERLAP) as usize;
            let w = m.width as usize;
            let stride = lit.c1 - lit.c0 + 2;
            let mut want = vec![
                0u8;
                if lit == PixelBox::EMPTY {
                    0
                } else {
                    Rows::boxed_len(lit)
                }
            ];
            for row in lit.rows() {
                for c in lit.cols() {
                    want[lit.c0 + (row - lit.r0 + 1) * stride + c - lit.c0 + 1] =
                        m.data[row * w + c];
                }
            }
            assert!(b.data == want, "case {case}: boxed coverage differs");
            let outside = m.data.iter().enumerate().filter(|&(k, &v)| {
                v != 0 && !(lit.rows().contains(&(k / w)) && lit.cols().contains(&(k % w)))
            });
            assert_eq!(outside.count(), 0, "case {case}: lit outside the box");
            buf = b.data;
        }
        assert!(
            overlapped >= 5,
            "{overlapped} cases drawn by the nonzero rule"
        );
    }

    /// A mask drawn again into a recycled buffer whose lit box overlaps its own in part
    /// (left of it, right, inside, around, apart): `paint` writes only its box, the rest is
    /// zero as in a mask drawn afresh.
    #[test]
    fn redraw_clears_what_the_paint_does_not_write() {
        let r = Rasterizer::new(field());
        let shapes = [
            rect(10.0, 10.0, 20.0, 20.0),
            rect(15.0, 12.0, 30.0, 18.0),
            rect(5.0, 5.0, 12.0, 25.0),
            rect(12.0, 14.0, 14.0, 16.0),
            rect(1.0, 1.0, 40.0, 40.0),
            rect(50.0, 30.0, 60.0, 40.0),
            rect(12.0, 14.0, 14.0, 16.0),
        ];
        let mut s = Scratch::default();
        for pair in shapes.windows(2) {
            let fresh = r.coverage(&[pair[1].clone()], &mut Scratch::default());
            let drawn = {
                let mut t = Scratch::default();
                let _ = r.coverage(&[pair[1].clone()], &mut t);
                t.drawn()
            };
            let lit = drawn.0;
            let first = r.coverage(&[pair[0].clone()], &mut s);
            s.recycle(first);
            let w = fresh.width as usize;
            let again = r
                .redraw(&mut s, &drawn, |m| {
                    for row in lit.rows() {
                        let k = row * w;
                        m.data[k..][lit.cols()].copy_from_slice(&fresh.data[k..][lit.cols()]);
                    }
                })
                .expect("no runs either way");
            assert!(
                again.data == fresh.data,
                "{:?} after {:?}",
                pair[1],
                pair[0]
            );
            s.recycle(again);
        }
    }

    /// Largest per-pixel difference between two masks.
    fn max_diff(a: &Mask, b: &Mask) -> u8 {
        a.data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap()
    }

    #[test]
    fn overlapping_shells_union() {
        let r = Rasterizer::new(field());
        let a = rect(10.0, 10.0, 20.0, 20.0);
        let b = rect(15.0, 10.0, 25.0, 20.0);
        let mut s = Scratch::default();
        let m = r.coverage(&[a, b], &mut s);
        let area = m.lit_pixels() * 0.0634765625f64.powi(2);
        assert!((area - 150.0).abs() < 0.05, "{area}");
        // Same picture as the union drawn as one rectangle, to 1/32 of a level step.
        let u = r.coverage(&[rect(10.0, 10.0, 25.0, 20.0)], &mut s);
        let worst = max_diff(&m, &u);
        assert!(worst <= 8, "{worst}");
        // Touching shells (shared edge at x = 15) need no fallback and are exact too.
        let t = r.coverage(
            &[rect(10.0, 10.0, 15.0, 20.0), rect(15.0, 10.0, 25.0, 20.0)],
            &mut s,
        );
        let worst = max_diff(&t, &u);
        assert!(worst <= 1, "{worst}");
    }

    #[test]
    fn only_rows_where_shells_overlap_are_drawn_by_the_nonzero_rule() {
        // Fixed-seed random stars, each layer with a pair of overlapping shells (one shifted
        // by a fraction of a pixel) and a lone shell in other rows: the lone shell's rows are
        // the exact coverage of it alone; the pair's pixels are within 4 levels of a
        // brute-force nonzero count of 32 × 32 samples per pixel; lit runs and lit area are
        // those of the mask.
        let f = Field {
            width_px: 96,
            height_px: 96,
            pixel_mm: 0.1,
        };
        let r = Rasterizer::new(f);
        let mut rnd = xorshift(0x51ed_270b_2f3c_9a11);
        let mut s = Scratch {
            record_runs: true,
            ..Scratch::default()
        };
        for case in 0..6 {
            let mut star = |cy: f64| {
                let (cx, rmax, n) = (
                    2.0 + rnd() * 5.6,
                    0.4 + rnd() * 1.6,
                    3 + (rnd() * 20.0) as usize,
                );
                closed(n, true, |a| {
                    let rad = rmax * (0.3 + 0.7 * rnd());
                    [cx + rad * a.cos(), cy + rad * a.sin()]
                })
            };
            let (a, lone) = (star(2.2), star(7.4));
            let b: Vec<[f64; 2]> = a.iter().map(|p| [p[0] + 0.037, p[1] + 0.21]).collect();
            let shells = [a.clone(), b.clone(), lone];
            let m = r.coverage(&shells, &mut s);
            assert_eq!(
                s.lit_runs,
                LitRuns::of_mask(&m, [0, 96, 0, 96]),
                "case {case}: runs"
            );
            assert_eq!(s.lit_pixels(&m), m.lit_pixels(), "case {case}: lit area");
            let alone = r.coverage(&shells[2..], &mut Scratch::default());
            // The pair's pixel rows and columns.
            let span = |v: &dyn Fn(&[f64; 2]) -> f64| {
                let (lo, hi) = a
                    .iter()
                    .chain(&b)
                    .map(v)
                    .fold((f64::INFINITY, 0.0f64), |(l, h), x| (l.min(x), h.max(x)));
                ((lo / f.pixel_mm).floor() as usize).saturating_sub(1)
                    ..((hi / f.pixel_mm).ceil() as usize + 1).min(96)
            };
            let pair_rows = span(&|p| f.height_mm() - p[1]);
            let pair_cols = span(&|p| p[0]);
            for row in (0..96).filter(|row| !pair_rows.contains(row)) {
                let at = row * 96..(row + 1) * 96;
                assert_eq!(m.data[at.clone()], alone.data[at], "case {case}: row {row}");
            }
            let winding = |x: f64, y: f64| {
                let mut w = 0;
                for c in &shells {
                    for (i, p) in c.iter().enumerate() {
                        let q = c[(i + 1) % c.len()];
                        if (p[1] <= y) != (q[1] <= y) {
                            let t = (y - p[1]) / (q[1] - p[1]);
                            if p[0] + t * (q[0] - p[0]) > x {
                                w += if q[1] > p[1] { 1 } else { -1 };
                            }
                        }
                    }
                }
                w
            };
            for i in pair_rows
                .clone()
                .flat_map(|row| pair_cols.clone().map(move |c| row * 96 + c))
            {
                let (v, col, row) = (m.data[i], (i % 96) as f64, (i / 96) as f64);
                let inside = (0..32 * 32)
                    .filter(|k| {
                        let x = (col + ((k % 32) as f64 + 0.5) / 32.0) * f.pixel_mm;
                        let y = f.height_mm() - (row + ((k / 32) as f64 + 0.5) / 32.0) * f.pixel_mm;
                        winding(x, y) != 0
                    })
                    .count();
                let want = (inside as f64 / 1024.0 * 255.0).round() as u8;
                assert!(
                    v.abs_diff(want) <= 4,
                    "case {case}: pixel {i}: {v} vs {want}"
                );
            }
            s.recycle(m);
        }
    }
}
