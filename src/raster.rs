//! Rasterization of layer sections into 8-bit masks in field pixel coordinates.
//!
//! Orientation (PrusaSlicer's landscape convention): the mask is a top view, +X to the
//! right, +Y up; build-plane point (x, y) measured from the field's bottom-left corner
//! lies in column `floor(x / p)`, row `H − 1 − floor(y / p)`.
//!
//! * Anti-aliased masks (the default) hold the exact fraction of each pixel's area
//!   inside the section, `round(255 · coverage)`, computed analytically with a signed-area
//!   accumulation buffer. Layers whose shells overlap (winding above 1 somewhere) are
//!   redone with an exact-span nonzero-winding scanline fill on 32 sub-scanlines per row.
//! * Binary masks (`--binary`) threshold that coverage at 50 %.
//!
//! Why not tiny-skia for masks: its anti-aliasing supersamples 4× (coverage quantized to
//! 1/4 px), and its non-anti-aliased fill snaps edges to fixed point; measured against
//! PrusaSlicer (docs/BENCHMARKS.md, "Mask agreement") both disagree on ~10× more pixels
//! than the exact coverage does. tiny-skia draws the plots (`plot`) and serves as
//! the reference renderer in `benches/raster.rs`.

pub use crate::png::PixelBox;
use crate::profile::{Field, Projector};
use crate::slice::Contour;

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
    #[inline]
    pub fn get(&self, col: u32, row: u32) -> u8 {
        self.data[row as usize * self.width as usize + col as usize]
    }

    /// Sum of values / 255: the lit area in pixels.
    pub fn lit_pixels(&self) -> f64 {
        self.lit_pixels_in(PixelBox::whole(self.width as usize, self.height as usize))
    }

    /// Like [`lit_pixels`](Self::lit_pixels) when the mask is known to be zero outside
    /// `lit_box` (e.g. [`Scratch::lit_box`]): visits only that box.
    pub fn lit_pixels_in(&self, lit_box: PixelBox) -> f64 {
        let PixelBox { r0, r1, c0, c1 } = lit_box;
        let w = self.width as usize;
        let mut sum = 0u64;
        for r in r0..r1 {
            // u32 partial sums per row vectorize well; a row cannot overflow them.
            sum += self.data[r * w + c0..r * w + c1]
                .iter()
                .map(|&v| v as u32)
                .sum::<u32>() as u64;
        }
        sum as f64 / 255.0
    }
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
    pub fn of_mask(m: &Mask, [r0, r1, c0, c1]: [usize; 4]) -> LitRuns {
        let mut l = LitRuns::default();
        l.scan_mask(m, PixelBox { r0, r1, c0, c1 });
        l
    }

    /// Replaces the runs by the lit runs of `m` inside `lit_box` (zero outside).
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

/// Reusable scratch memory for [`Rasterizer::coverage`] (one per worker thread).
#[derive(Debug, Default)]
pub struct Scratch {
    /// When set, [`Rasterizer::render`] keeps the lit runs of each mask it draws in
    /// [`Scratch::lit_runs`].
    pub record_runs: bool,
    /// The lit runs of the last [`Rasterizer::render`] mask (when `record_runs`).
    pub lit_runs: LitRuns,
    acc: Vec<f32>,
    /// Sum of the last [`Rasterizer::coverage`] mask's values, counted by the scan (`None`
    /// when the nonzero fallback drew the mask).
    lit_sum: Option<u64>,
    /// Per accumulation row, one bit per [`BLOCK`] cells that `line` wrote to: the scan
    /// visits only those blocks and skips the (zero) cells between them.
    touched: Vec<u64>,
    /// Recycled mask buffers with the box outside which each is known to be zero.
    spare: Vec<(Vec<u8>, PixelBox)>,
    /// The last [`Rasterizer::coverage`] mask's lit box ([`Scratch::lit_box`]).
    lit: PixelBox,
    /// Whether the last [`Rasterizer::render`] reported its layer to the map as lit
    /// outside the map's area.
    reported_outside: bool,
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
    /// outside the map's area ([`CoverageMap::lit_outside`]): a caller repeating that
    /// layer's mask without drawing it reports it again.
    pub fn reported_outside(&self) -> bool {
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

    fn zeroed(&mut self, w: usize, h: usize) -> Vec<u8> {
        match self.spare.pop() {
            Some((mut v, PixelBox { r0, r1, c0, c1 })) if v.len() == w * h => {
                for r in r0..r1 {
                    v[r * w + c0..r * w + c1].fill(0);
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

    /// The mask of a layer as it is written: coverage, thresholded at 50 % when `binary`
    /// (as [`threshold`] does), then mapped through `map` (light compensation) when given.
    ///
    /// The map is applied by the scan itself, where it writes each value (one pass over the
    /// lit box instead of two), unless [`CoverageMap::fusable`] declines the layer or its
    /// shells overlap (nonzero fallback): then the finished (thresholded) coverage mask goes
    /// through [`CoverageMap::apply`]. Either way the bytes are the same. The lit area
    /// ([`Scratch::lit_pixels`]) is always that of the coverage, before threshold and map.
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
        let stride = w + 2;
        let mut out = Mask {
            width: w as u32,
            height: h as u32,
            data: scratch.zeroed(w, h),
        };
        scratch.lit = PixelBox::EMPTY;
        scratch.lit_sum = Some(0);
        scratch.lit_runs.runs.clear();
        if contours.is_empty() {
            return out;
        }
        let words = stride.div_ceil(BLOCK).div_ceil(64);
        if scratch.acc.len() != stride * h {
            scratch.acc = zeroed_by_writes(stride * h);
            scratch.touched = zeroed_by_writes(words * h);
        }
        let acc = &mut Accum {
            cells: &mut scratch.acc,
            touched: &mut scratch.touched,
            stride,
            words,
        };
        let (mut r0, mut r1) = (h, 0usize);
        let (mut c0, mut c1) = (w, 0usize);
        for c in contours {
            for i in 0..c.len() {
                let (x0, y0) = self.px(c[i]);
                let (x1, y1) = self.px(c[(i + 1) % c.len()]);
                // Clamp into the field: the planner guarantees parts fit, this only guards.
                let cl = |v: f64, m: usize| v.clamp(0.0, m as f64);
                let (x0, y0, x1, y1) = (cl(x0, w), cl(y0, h), cl(x1, w), cl(y1, h));
                line(acc, h, x0 as f32, y0 as f32, x1 as f32, y1 as f32);
                // Clamped, so non-negative: `as usize` truncates = floors.
                let ceil = |v: f64| {
                    let t = v as usize;
                    t + ((t as f64) < v) as usize
                };
                r0 = r0.min(y0.min(y1) as usize);
                r1 = r1.max(ceil(y0.max(y1)));
                c0 = c0.min(x0.min(x1) as usize);
                c1 = c1.max(ceil(x0.max(x1)) + 1);
            }
        }
        let r1 = r1.min(h);
        let c1 = c1.min(w + 1);
        debug_assert!(c1 < stride);
        let lit = PixelBox {
            r0,
            r1,
            c0,
            c1: c1.min(w),
        };
        scratch.lit = lit;
        let fused = map.filter(|m| m.fusable(lit));
        let span = ScanSpan {
            r0,
            r1,
            c0,
            end: c1.min(w),
        };
        let mut outside = false;
        let runs = scratch.record_runs.then_some(&mut scratch.lit_runs);
        let (lit_sum, max_winding) = match (fused, binary) {
            (Some(m), binary) => {
                // Whether the scan must look for lit pixels outside the map's area.
                let area = m.area();
                let check = r0 < area.r0 || r1 > area.r1 || c0 < area.c0 || c1.min(w) > area.c1;
                let data = &mut out.data;
                let o = &mut outside;
                match (binary, check) {
                    (false, false) => {
                        scan_runs::<_, false, false>(acc, data, w, span, Mapped(m), o, runs)
                    }
                    (false, true) => {
                        scan_runs::<_, false, true>(acc, data, w, span, Mapped(m), o, runs)
                    }
                    (true, false) => {
                        scan_runs::<_, true, false>(acc, data, w, span, Mapped(m), o, runs)
                    }
                    (true, true) => {
                        scan_runs::<_, true, true>(acc, data, w, span, Mapped(m), o, runs)
                    }
                }
            }
            (None, false) => {
                scan_runs::<_, false, false>(acc, &mut out.data, w, span, Plain, &mut outside, runs)
            }
            (None, true) => {
                scan_runs::<_, true, false>(acc, &mut out.data, w, span, Plain, &mut outside, runs)
            }
        };
        scratch.lit_sum = Some(lit_sum);
        let mut mapped = fused.is_some();
        if max_winding > 1.001 {
            // Overlapping shells: the accumulated winding integral over-counts pixels where
            // two boundaries meet; redo the layer with the exact nonzero rule.
            self.coverage_nonzero(contours, &mut out);
            scratch.lit_sum = Some(box_sum(&out, lit));
            if scratch.record_runs {
                scratch.lit_runs.scan_mask(&out, lit);
            }
            if binary {
                threshold_in(&mut out, lit);
            }
            mapped = false;
        }
        scratch.reported_outside = match (map, mapped) {
            (Some(m), false) => m.apply(&mut out, lit),
            (Some(m), true) if outside => {
                m.lit_outside();
                true
            }
            _ => false,
        };
        out
    }

    /// Nonzero-winding coverage by analytic spans on [`SUBLINES`] sub-scanlines per pixel
    /// row: exact horizontally, 1/(2·SUBLINES) px vertically. Used for layers whose shells
    /// overlap, where [`coverage`](Self::coverage)'s signed-area accumulation over-counts.
    fn coverage_nonzero(&self, contours: &[Contour], out: &mut Mask) {
        let w = self.field.width_px as usize;
        let h = self.field.height_px as usize;
        // Edges in pixel coordinates: (x at y_top, dx/dy, y_top, y_bottom, winding).
        let mut edges: Vec<(f64, f64, f64, f64, i32)> = Vec::new();
        for c in contours {
            for i in 0..c.len() {
                let (x0, y0) = self.px(c[i]);
                let (x1, y1) = self.px(c[(i + 1) % c.len()]);
                if y0 == y1 {
                    continue;
                }
                let (dir, xa, ya, xb, yb) = if y0 < y1 {
                    (1, x0, y0, x1, y1)
                } else {
                    (-1, x1, y1, x0, y0)
                };
                edges.push((xa, (xb - xa) / (yb - ya), ya, yb, dir));
            }
        }
        edges.sort_by(|a, b| a.2.total_cmp(&b.2));
        out.data.fill(0);
        let mut diff = vec![0.0f64; w + 2];
        let mut cover = vec![0.0f64; w + 1];
        let mut active: Vec<usize> = Vec::new();
        let mut next = 0;
        let mut xs: Vec<(f64, i32)> = Vec::new();
        let r_first = edges.first().map_or(h, |e| e.2.floor().max(0.0) as usize);
        let inv = 1.0 / SUBLINES as f64;
        for r in r_first..h {
            if next >= edges.len() && active.is_empty() {
                break;
            }
            while next < edges.len() && edges[next].2 < (r + 1) as f64 {
                active.push(next);
                next += 1;
            }
            active.retain(|&e| edges[e].3 > r as f64);
            if active.is_empty() {
                continue;
            }
            cover.fill(0.0);
            diff.fill(0.0);
            for s in 0..SUBLINES {
                let y = r as f64 + (s as f64 + 0.5) * inv;
                xs.clear();
                for &e in &active {
                    let (x, k, ya, yb, d) = edges[e];
                    if ya <= y && y < yb {
                        xs.push(((x + k * (y - ya)).clamp(0.0, w as f64), d));
                    }
                }
                xs.sort_by(|a, b| a.0.total_cmp(&b.0));
                let mut wind = 0;
                for j in 0..xs.len() {
                    let before = wind;
                    wind += xs[j].1;
                    if before == 0 && wind != 0 {
                        // span starts at xs[j].0; find where it ends
                        let xa = xs[j].0;
                        let mut wk = wind;
                        let mut xb = xa;
                        for x in &xs[j + 1..] {
                            wk += x.1;
                            if wk == 0 {
                                xb = x.0;
                                break;
                            }
                        }
                        add_span(&mut cover, &mut diff, xa, xb, inv);
                    }
                }
            }
            let dst = &mut out.data[r * w..(r + 1) * w];
            let mut run = 0.0;
            for (col, d) in dst.iter_mut().enumerate() {
                run += diff[col];
                let v = (cover[col] + run).clamp(0.0, 1.0);
                *d = (v * 255.0 + 0.5) as u8;
            }
        }
    }

    /// Binary mask: 255 where the anti-aliased coverage is at least 50 % (value ≥ 128),
    /// else 0.
    pub fn binary(&self, contours: &[Contour], scratch: &mut Scratch) -> Mask {
        self.render::<NoMap>(contours, scratch, true, None)
    }
}

/// Thresholds a coverage mask at 50 % in place: values ≥ 128 become 255, others 0.
pub fn threshold(m: &mut Mask) {
    for v in &mut m.data {
        *v = if *v >= 128 { 255 } else { 0 };
    }
}

/// Thresholds the box `lit_box` of a mask at 50 % in place (the mask is zero outside it).
fn threshold_in(m: &mut Mask, lit_box: PixelBox) {
    let PixelBox { r0, r1, c0, c1 } = lit_box;
    let w = m.width as usize;
    for r in r0..r1 {
        for v in &mut m.data[r * w + c0..r * w + c1] {
            *v = if *v >= 128 { 255 } else { 0 };
        }
    }
}

/// Sum of a mask's values inside `b`.
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
    /// Whether the scan may apply the map to a layer whose lit pixels all lie in
    /// `lit_box`; if not, [`apply`](Self::apply) maps the finished mask (e.g. when the map
    /// must look at the coverage of other pixels first).
    fn fusable(&self, lit_box: PixelBox) -> bool;
    /// The map's area: the scan reports through [`lit_outside`](Self::lit_outside) a layer
    /// it mapped that has a lit pixel (coverage, thresholded when binary, above zero)
    /// outside it.
    fn area(&self) -> PixelBox;
    /// Called once for each layer the scan mapped that is lit outside [`area`](Self::area).
    fn lit_outside(&self);
    /// What the map needs for one row (looked up once per row, not per pixel).
    type Row<'a>: Copy
    where
        Self: 'a;
    /// The per-row state of row `r`.
    fn row(&self, r: usize) -> Self::Row<'_>;
    /// Writes columns a..b of a mask row `dst` (zero there) for coverage `v` (1..=255):
    /// what coverage `v` becomes in each of those columns.
    fn fill(row: Self::Row<'_>, dst: &mut [u8], a: usize, b: usize, v: u8);
    /// Maps a finished coverage mask in place; it is zero outside `lit_box`. Returns
    /// whether the layer is lit outside [`area`](Self::area) (and reported as such).
    fn apply(&self, m: &mut Mask, lit_box: PixelBox) -> bool;
}

/// No map (the [`Rasterizer::coverage`] and [`Rasterizer::binary`] masks).
enum NoMap {}

impl CoverageMap for NoMap {
    fn fusable(&self, _: PixelBox) -> bool {
        match *self {}
    }
    fn area(&self) -> PixelBox {
        match *self {}
    }
    fn lit_outside(&self) {
        match *self {}
    }
    type Row<'a> = ();
    fn row(&self, _: usize) {
        match *self {}
    }
    fn fill(_: (), _: &mut [u8], _: usize, _: usize, _: u8) {}
    fn apply(&self, _: &mut Mask, _: PixelBox) -> bool {
        match *self {}
    }
}

/// How [`scan_runs`] writes runs of equal (thresholded) coverage into a mask row.
trait Emit {
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
struct Plain;

impl Emit for Plain {
    type Row<'a> = ();
    #[inline(always)]
    fn row(&self, _: usize) {}
    fn area(&self) -> PixelBox {
        PixelBox {
            r0: 0,
            r1: usize::MAX,
            c0: 0,
            c1: usize::MAX,
        }
    }
    #[inline(always)]
    fn fill(_: (), dst: &mut [u8], a: usize, b: usize, v: u8) {
        dst[a..b].fill(v);
    }
}

/// Values through a [`CoverageMap`].
struct Mapped<'m, M>(&'m M);

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

/// The rows and columns the scans visit: rows r0..r1, columns c0..end.
#[derive(Clone, Copy)]
struct ScanSpan {
    r0: usize,
    r1: usize,
    c0: usize,
    end: usize,
}

/// The prefix-sum scan of the accumulation buffer: writes the coverage (thresholded when
/// `BIN`) through `emit` (as is, or through a light-compensation map), clears the buffer
/// and its block marks as it reads them, and returns the sum of the coverage values (before
/// threshold) and the largest winding seen. Only the touched blocks are visited: between
/// them every cell is zero and the value repeats. The value changes only at nonzero cells:
/// the scan follows runs of equal coverage and writes each run once, when it ends (zero
/// runs are left as they are), so a run of full coverage is one fill, or one copy from the
/// map's full-coverage row. With `CHECK`, sets `outside` if a lit pixel lies outside
/// `emit`'s area. With `lit`, appends the lit runs (coverage ≥ 50 %) to it.
#[inline(never)]
fn scan_runs<E: Emit, const BIN: bool, const CHECK: bool>(
    acc: &mut Accum,
    data: &mut [u8],
    w: usize,
    ScanSpan { r0, r1, c0, end }: ScanSpan,
    emit: E,
    outside: &mut bool,
    mut lit: Option<&mut LitRuns>,
) -> (u64, f32) {
    let PixelBox {
        r0: ar0,
        r1: ar1,
        c0: ac0,
        c1: ac1,
    } = emit.area();
    let (stride, words) = (acc.stride, acc.words);
    let mut max_winding = 0.0f32;
    let mut lit_sum = 0u64;
    for r in r0..r1 {
        let row = &mut acc.cells[r * stride..(r + 1) * stride];
        let marks = &mut acc.touched[r * words..(r + 1) * words];
        let mut sink = Runs::<E, BIN, CHECK> {
            er: emit.row(r),
            dst: &mut data[r * w..(r + 1) * w],
            lit_sum: 0,
            lo: usize::MAX,
            hi: 0,
        };
        let mut sum = 0.0f32;
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
                let (bs, be) = (b * BLOCK, ((b + 1) * BLOCK).min(stride));
                let from = bs.max(c0).min(end);
                let to = be.min(end).max(from);
                // Most cells of a touched block are zero: one vectorizable pass marks the
                // nonzero ones, then only those are visited (in column order).
                let mut nonzero = nonzero_cells(&row[bs..be]);
                nonzero &= (1u64 << (to - bs)) - 1;
                nonzero &= !((1u64 << (from - bs)) - 1);
                while nonzero != 0 {
                    let c = bs + nonzero.trailing_zeros() as usize;
                    nonzero &= nonzero - 1;
                    let a = row[c];
                    sum += a;
                    // Cleared as it is read: the buffer is all zeros after the scan.
                    row[c] = 0.0;
                    let v = sum.abs();
                    max_winding = max_winding.max(v);
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
                row[to.max(bs)..be].fill(0.0);
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
        if CHECK && sink.lo < sink.hi {
            *outside |= r < ar0 || r >= ar1 || sink.lo < ac0 || sink.hi > ac1;
        }
    }
    (lit_sum, max_winding)
}

/// A zeroed buffer whose pages are first touched by writes. A fresh zeroed allocation is
/// mapped lazily: reading a page first maps the shared zero page, and the write that
/// follows must copy it and flush the other CPUs' TLBs (an inter-processor interrupt per
/// page, costly in a VM) — what the accumulation's `+=` and the block marks' `|=` would
/// do on their first pass. Written first, each page costs one plain fault.
fn zeroed_by_writes<T: Copy + Default>(n: usize) -> Vec<T> {
    let mut v = vec![T::default(); n];
    let step = (4096 / std::mem::size_of::<T>().max(1)).max(1);
    for i in (0..n).step_by(step) {
        // SAFETY: i < n = v.len(); volatile, so the store of a value the allocation
        // already holds is not left out.
        unsafe { std::ptr::write_volatile(v.as_mut_ptr().add(i), T::default()) };
    }
    v
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

/// Accumulation cells per bit of [`Scratch::touched`].
const BLOCK: usize = 32;

/// The signed-area accumulation buffer of one field and its touched-block bitmap.
struct Accum<'a> {
    cells: &'a mut [f32],
    touched: &'a mut [u64],
    stride: usize,
    /// Bitmap words per row.
    words: usize,
}

impl Accum<'_> {
    /// Marks cells `lo..=hi` of row `r` as written.
    #[inline]
    fn mark(&mut self, r: usize, lo: usize, hi: usize) {
        let row = &mut self.touched[r * self.words..(r + 1) * self.words];
        for b in lo / BLOCK..=hi / BLOCK {
            row[b / 64] |= 1 << (b % 64);
        }
    }
}

/// Sub-scanlines per pixel row of the nonzero fallback rasterizer.
const SUBLINES: usize = 32;

/// Adds the horizontal span [xa, xb) with weight `wgt` to a pixel row: partial end pixels
/// go to `cover`, whole pixels between them to the difference array `diff`.
fn add_span(cover: &mut [f64], diff: &mut [f64], xa: f64, xb: f64, wgt: f64) {
    if xb <= xa {
        return;
    }
    let ia = xa.floor() as usize;
    let ib = xb.floor() as usize;
    if ia == ib {
        cover[ia] += (xb - xa) * wgt;
        return;
    }
    cover[ia] += ((ia + 1) as f64 - xa) * wgt;
    diff[ia + 1] += wgt;
    diff[ib] -= wgt;
    if ib < cover.len() {
        cover[ib] += (xb - ib as f64) * wgt;
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
fn line(accum: &mut Accum, h: usize, x0: f32, y0: f32, x1: f32, y1: f32) {
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
    let r_start = floor_nn(ya) as usize;
    let r_end = (ceil_nn(yb) as usize).min(h);
    for r in r_start..r_end {
        let top = (r as f32).max(ya);
        let bot = ((r + 1) as f32).min(yb);
        let dy = bot - top;
        if dy <= 0.0 {
            continue;
        }
        let xn = if bot == yb { xb } else { x + dxdy * dy };
        let d = dy * dir;
        let base = r * stride;
        let (lx, rx) = if x < xn { (x, xn) } else { (xn, x) };
        let lf = floor_nn(lx);
        let li = lf as usize;
        let rc = ceil_nn(rx);
        let ri = rc as usize;
        accum.mark(r, li, ri.max(li + 1));
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

/// Cuts projector `p`'s part out of a field mask and applies its mirror flags (borrows the
/// field mask when the projector covers it exactly, unmirrored).
pub fn projector_view<'a>(field_mask: &'a Mask, p: &Projector) -> std::borrow::Cow<'a, Mask> {
    let (ox, oy) = (p.offset_px[0] as usize, p.offset_px[1] as usize);
    let (w, h) = (p.width_px as usize, p.height_px as usize);
    if ox == 0
        && oy == 0
        && w == field_mask.width as usize
        && h == field_mask.height as usize
        && !p.mirror_x
        && !p.mirror_y
    {
        return std::borrow::Cow::Borrowed(field_mask);
    }
    let fw = field_mask.width as usize;
    let mut out = Mask::zeros(w as u32, h as u32);
    for r in 0..h {
        let sr = if p.mirror_y { h - 1 - r } else { r };
        let src = &field_mask.data[(oy + sr) * fw + ox..(oy + sr) * fw + ox + w];
        let dst = &mut out.data[r * w..(r + 1) * w];
        dst.copy_from_slice(src);
        if p.mirror_x {
            dst.reverse();
        }
    }
    std::borrow::Cow::Owned(out)
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

    fn field() -> Field {
        Field {
            width_px: 1024,
            height_px: 768,
            pixel_mm: 0.0634765625,
        }
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Contour {
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    fn circle(cx: f64, cy: f64, r: f64, n: usize, ccw: bool) -> Contour {
        let mut c: Contour = (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                [cx + r * a.cos(), cy + r * a.sin()]
            })
            .collect();
        if !ccw {
            c.reverse();
        }
        c
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
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut reused = Scratch::default();
        for case in 0..40 {
            let (cx, cy) = (rnd() * fw, rnd() * fh);
            let n = 3 + (rnd() * 60.0) as usize;
            let rmax = 0.2 + rnd() * if case % 4 == 0 { 40.0 } else { 8.0 };
            let star: Contour = (0..n)
                .map(|i| {
                    let a = i as f64 / n as f64 * std::f64::consts::TAU;
                    let rad = rmax * (0.3 + 0.7 * rnd());
                    [cx + rad * a.cos(), cy + rad * a.sin()]
                })
                .collect();
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
    fn mirror_flags() {
        let mut m = Mask::zeros(4, 2);
        m.data = vec![1, 2, 3, 4, 5, 6, 7, 8];
        let mut p = crate::profile::Profile::default_profile().projector[0].clone();
        p.width_px = 4;
        p.height_px = 2;
        p.mirror_x = true;
        assert_eq!(projector_view(&m, &p).data, vec![4, 3, 2, 1, 8, 7, 6, 5]);
        p.mirror_x = false;
        p.mirror_y = true;
        assert_eq!(projector_view(&m, &p).data, vec![5, 6, 7, 8, 1, 2, 3, 4]);
    }
}
