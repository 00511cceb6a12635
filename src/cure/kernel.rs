//! What a layer's cure needs from its mask alone, prepared in parallel ahead of the
//! sequential recurrence: the PSF-blurred light at the samples (`Kernel`), the samples
//! that cure whole whatever the layers above add, the drawn perimeter and the lit runs
//! and islands (`Prepared`).

use super::check::{CHUNK, NEAR, SUB};
use super::islands::{lit_islands, Run};
use super::{CureModel, Psf};

/// A layer's relative irradiance inside its lit box (pixels, ends exclusive): the
/// engine's input.
#[derive(Debug, Clone, Default)]
pub struct Irradiance {
    /// `[c0, r0, c1, r1]`; empty when nothing is lit.
    pub bbox: [usize; 4],
    /// Row-major over the box.
    pub data: Vec<f32>,
}

impl Irradiance {
    /// The irradiance of a whole `w`×`h` image, cut to its nonzero box.
    #[cfg(test)]
    pub(crate) fn from_image(w: usize, h: usize, img: &[f32]) -> Irradiance {
        let lit = |r: usize| img[r * w..(r + 1) * w].iter().any(|&v| v != 0.0);
        let Some(r0) = (0..h).find(|&r| lit(r)) else {
            return Irradiance::default();
        };
        let r1 = (0..h).rfind(|&r| lit(r)).unwrap_or(r0) + 1;
        let col = |c: usize| (r0..r1).any(|r| img[r * w + c] != 0.0);
        let c0 = (0..w).find(|&c| col(c)).unwrap_or(0);
        let c1 = (0..w).rfind(|&c| col(c)).unwrap_or(c0) + 1;
        let data = (r0..r1)
            .flat_map(|r| img[r * w + c0..r * w + c1].iter().copied())
            .collect();
        Irradiance {
            bbox: [c0, r0, c1, r1],
            data,
        }
    }

    /// Whether nothing is lit.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }
}

/// What a layer gives that depends on its mask alone, computed ahead of the sequential
/// recurrence (in parallel, several layers at a time): its own blurred light, perimeter,
/// lit runs and islands.
#[derive(Debug, Clone, Default)]
pub struct Prepared {
    /// The pixel box of the irradiance; empty when nothing is lit.
    pub(super) bbox: [usize; 4],
    /// The sample box the layer's light reaches.
    pub(super) sbox: [usize; 4],
    /// The layer's own light over `sbox` (before the exposure ratio), row-major.
    pub(super) own: Vec<f32>,
    /// Per row of `sbox`: the columns (from its left) outside which `own` is zero (and
    /// not cleared: never read).
    pub(super) spans: Vec<(u32, u32)>,
    /// Samples that cure whole whatever the layers above add: `inner[inner_rows[k]..
    /// inner_rows[k + 1]]` the column ranges (from the box's left) of the box's k-th row.
    pub(super) inner: Vec<(u32, u32)>,
    pub(super) inner_rows: Vec<u32>,
    pub(super) perimeter_px: f64,
    /// Lit runs, row-major.
    pub(super) runs: Vec<Run>,
    /// `rows[r − bbox[1]]..rows[r − bbox[1] + 1]`: the runs of row r.
    pub(super) rows: Vec<u32>,
    /// The island (0-based) of each run.
    pub(super) island: Vec<u32>,
    /// Per island: lit pixels and the sums of their centres' columns and rows.
    pub(super) px: Vec<u64>,
    pub(super) sum: Vec<[f64; 2]>,
}

impl Prepared {
    pub(super) fn is_empty(&self) -> bool {
        self.own.is_empty()
    }

    /// The lit runs of row `r` (none outside the box).
    pub(super) fn row(&self, r: usize) -> &[Run] {
        let [_, r0, _, r1] = self.bbox;
        if r < r0 || r >= r1 {
            return &[];
        }
        let k = r - r0;
        &self.runs[self.rows[k] as usize..self.rows[k + 1] as usize]
    }
}

/// The PSF's weights at the samples, the field's size and the cure threshold: what
/// preparing a layer needs; and the buffers of layers done, for the next ones.
#[derive(Debug)]
pub struct Kernel {
    w: usize,
    h: usize,
    /// Relative light at a layer's top at which its mid-plane cures.
    mid: f32,
    pool: std::sync::Mutex<Vec<Vec<f32>>>,
    /// Pixels either side of a sample's pixel the PSF reaches.
    reach: usize,
    /// `weights[k][d + reach]`: the light at sub-sample `k` of a pixel from the pixel `d`
    /// away.
    weights: Vec<Vec<f32>>,
}

impl Kernel {
    /// The kernel of a `w`×`h` field and `model`.
    pub fn new(w: usize, h: usize, model: &CureModel) -> Kernel {
        let psf = Psf {
            sigma_px: model.sigma_px,
        };
        let reach = psf.reach_px().ceil() as usize + 1;
        let weights = (0..SUB)
            .map(|k| {
                let u = (k as f64 + 0.5) / SUB as f64;
                (0..=2 * reach)
                    .map(|d| psf.axis_weight(u - (d as f64 - reach as f64)) as f32)
                    .collect()
            })
            .collect();
        Kernel {
            w,
            h,
            mid: model.threshold(0.5 * model.layer_mm, Some(0)) as f32,
            pool: std::sync::Mutex::new(Vec::new()),
            reach,
            weights,
        }
    }

    /// Gives a prepared layer's buffer back, for a layer prepared later.
    pub fn recycle(&self, p: Prepared) {
        if let Ok(mut pool) = self.pool.lock() {
            if pool.len() < 4 * CHUNK {
                pool.push(p.own);
            }
        }
    }

    /// The sample box a layer lit in pixel box `b` reaches.
    fn reach_box(&self, b: [usize; 4]) -> [usize; 4] {
        let r = self.reach;
        [
            b[0].saturating_sub(r) * SUB,
            b[1].saturating_sub(r) * SUB,
            (b[2] + r).min(self.w) * SUB,
            (b[3] + r).min(self.h) * SUB,
        ]
    }

    /// The parts of layer `cur`'s cure that depend on its mask alone (`ratio`: its
    /// light's scale, see [`Engine::layer`](super::Engine::layer)).
    pub fn prepare(&self, cur: &Irradiance, ratio: f32) -> Prepared {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { self.prepare_avx2(cur, ratio) };
        }
        self.prepare_with(cur, ratio)
    }

    /// [`Kernel::prepare`] compiled for AVX2 (the same operations in the same order, 8
    /// lanes wide: the same values).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn prepare_avx2(&self, cur: &Irradiance, ratio: f32) -> Prepared {
        self.prepare_with(cur, ratio)
    }

    #[inline(always)]
    fn prepare_with(&self, cur: &Irradiance, ratio: f32) -> Prepared {
        if cur.is_empty() {
            return Prepared::default();
        }
        let sbox = self.reach_box(cur.bbox);
        let (own, spans, inner, inner_rows) = self.blur(cur, sbox, self.inner(ratio));
        let mut p = Prepared {
            bbox: cur.bbox,
            sbox,
            own,
            spans,
            inner,
            inner_rows,
            perimeter_px: perimeter(cur),
            ..Prepared::default()
        };
        lit_islands(cur, &mut p);
        p
    }

    /// The bound on the layer's own light above which a sample counts whole in the cured
    /// sum whatever the layers above add, when it holds at the sample and its four
    /// neighbours: at least [`NEAR`] and, scaled by `ratio`, 10⁻⁴ above the threshold (the
    /// accumulated light is at least the layer's own, and the margin covers the rounding
    /// of the scaled values).
    fn inner(&self, ratio: f32) -> f32 {
        if ratio > 0.0 {
            NEAR.max(self.mid * (1.0 + 1e-4) / ratio)
        } else {
            f32::INFINITY
        }
    }

    /// Appends to `inner` the column ranges of row `k` of the sample box (left edge `x0`,
    /// `bw` wide) where [`Kernel::inner`]'s bound `theta` holds at the sample and its four
    /// neighbours: `own`'s rows k − 1 to k + 1 final.
    #[inline(always)]
    fn inner_row(
        &self,
        own: &[f32],
        spans: &[(u32, u32)],
        (x0, bw): (usize, usize),
        k: usize,
        theta: f32,
        inner: &mut Vec<(u32, u32)>,
    ) {
        let (a, b) = spans[k];
        let (mut a, mut b) = (a as usize + 1, (b as usize).saturating_sub(1));
        if k == 0 || k + 1 == spans.len() {
            b = 0;
        } else {
            for (c, d) in [spans[k - 1], spans[k + 1]] {
                a = a.max(c as usize);
                b = b.min(d as usize);
            }
        }
        // Not at the field's edge (its neighbours there are dark).
        a = a.max(1usize.saturating_sub(x0));
        b = b.min((self.w * SUB - 1).saturating_sub(x0));
        if a < b {
            let row = |j: usize| &own[j * bw..(j + 1) * bw];
            let (up, here, down) = (row(k - 1), row(k), row(k + 1));
            // Groups of 16 all in or all out decided at once (vectorizes).
            const GROUP: usize = 16;
            let ok = |x: usize| {
                here[x]
                    .min(here[x - 1])
                    .min(here[x + 1])
                    .min(up[x])
                    .min(down[x])
                    >= theta
            };
            let mut start: Option<usize> = None;
            let mut x = a;
            while x < b {
                let e = (x + GROUP).min(b);
                let (c, l, r) = (&here[x..e], &here[x - 1..e - 1], &here[x + 1..e + 1]);
                let (u, d) = (&up[x..e], &down[x..e]);
                let mut n = 0u32;
                for j in 0..e - x {
                    n += (c[j].min(l[j]).min(r[j]).min(u[j]).min(d[j]) >= theta) as u32;
                }
                if n as usize == e - x {
                    start.get_or_insert(x);
                } else if n == 0 {
                    if let Some(s0) = start.take() {
                        inner.push((s0 as u32, x as u32));
                    }
                } else {
                    for xx in x..e {
                        if ok(xx) {
                            start.get_or_insert(xx);
                        } else if let Some(s0) = start.take() {
                            inner.push((s0 as u32, xx as u32));
                        }
                    }
                }
                x = e;
            }
            if let Some(s0) = start {
                inner.push((s0 as u32, b as u32));
            }
        }
    }

    /// The blurred light of `cur` over the sample box `sbox`, row-major, each row's span
    /// of possibly nonzero samples, and the samples that cure whole (`theta`,
    /// [`Kernel::inner_row`]) with where each row's begin: each row's found as soon as the
    /// row below it is blurred.
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    fn blur(
        &self,
        cur: &Irradiance,
        sbox: [usize; 4],
        theta: f32,
    ) -> (Vec<f32>, Vec<(u32, u32)>, Vec<(u32, u32)>, Vec<u32>) {
        let [c0, r0, c1, r1] = cur.bbox;
        let [x0, y0, x1, y1] = sbox;
        let bw = x1 - x0;
        let reach = self.reach;
        let cw = c1 - c0;
        // Only the rows' extents are written and read: no clearing.
        thread_local! {
            static HBUF: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
        }
        let mut hbuf = HBUF.with(|b| std::mem::take(&mut *b.borrow_mut()));
        if hbuf.len() < bw * (r1 - r0) {
            hbuf.resize(bw * (r1 - r0), 0.0);
        }
        // Along rows: the light of each lit row at the sample columns its lit pixels
        // reach (`extent`, relative to x0; empty for a dark row). Per sub-sample k, a 1-D
        // convolution of the row (padded with `reach` zeros each side) over the pixels'
        // bases, tap by tap (vectorizes), then interleaved into the samples.
        let mut extent = vec![(0usize, 0usize); r1 - r0];
        let taps = 2 * reach + 1;
        let mut pad = Vec::new();
        let mut conv = Vec::new();
        for r in r0..r1 {
            let row = &cur.data[(r - r0) * cw..(r - r0 + 1) * cw];
            let Some(first) = row.iter().position(|&v| v != 0.0) else {
                continue;
            };
            let last = row.iter().rposition(|&v| v != 0.0).unwrap_or(first);
            // Pixel bases whose samples the lit pixels reach, inside the sample box.
            let (pa, pb) = (
                (c0 + first).saturating_sub(reach).max(x0 / SUB),
                (c0 + last + 1 + reach).min(self.w).min(x1 / SUB),
            );
            // pad[j] = pixel pa − reach + j.
            let n = pb - pa;
            pad.clear();
            pad.resize(n + 2 * reach, 0.0);
            let j0 = c0 + first + reach - pa;
            pad[j0..j0 + last + 1 - first].copy_from_slice(&row[first..=last]);
            let out = &mut hbuf[(r - r0) * bw..(r - r0 + 1) * bw];
            for k in 0..SUB {
                // Sample k of base b: Σ_d weights[k][d]·pixel(b + d − reach).
                conv.clear();
                conv.resize(n, 0.0);
                let wk = &self.weights[k];
                for d in 0..taps {
                    let wgt = wk[d];
                    for (o, v) in conv.iter_mut().zip(&pad[d..d + n]) {
                        *o += wgt * v;
                    }
                }
                for (j, v) in conv.iter().enumerate() {
                    out[(pa + j) * SUB + k - x0] = *v;
                }
            }
            extent[r - r0] = (pa * SUB - x0, pb * SUB - x0);
        }
        // Down columns: the layer's own light at every sample of a row's span (the
        // extents of the rows it sums; cleared there only).
        let mut own = self
            .pool
            .lock()
            .ok()
            .and_then(|mut p| p.pop())
            .unwrap_or_default();
        if own.len() < bw * (y1 - y0) {
            own.resize(bw * (y1 - y0), 0.0);
        }
        own.truncate(bw * (y1 - y0));
        let mut spans = vec![(0u32, 0u32); y1 - y0];
        let (mut inner, mut inner_rows) = (Vec::new(), vec![0u32]);
        for y in y0..y1 {
            if y > y0 + 1 {
                self.inner_row(&own, &spans, (x0, bw), y - y0 - 2, theta, &mut inner);
                inner_rows.push(inner.len() as u32);
            }
            let (base, k) = (y / SUB, y % SUB);
            let wk = &self.weights[k];
            let lo = (base + reach).saturating_sub(reach * 2).max(r0);
            let hi = (base + reach).min(r1 - 1);
            if lo > hi {
                continue;
            }
            let own = &mut own[(y - y0) * bw..(y - y0 + 1) * bw];
            let span = &mut spans[y - y0];
            for r in lo..=hi {
                let (a, b) = extent[r - r0];
                if a != b {
                    *span = if span.0 == span.1 {
                        (a as u32, b as u32)
                    } else {
                        (span.0.min(a as u32), span.1.max(b as u32))
                    };
                }
            }
            own[span.0 as usize..span.1 as usize].fill(0.0);
            for r in lo..=hi {
                let (a, b) = extent[r - r0];
                if a == b {
                    continue;
                }
                let wgt = wk[r + reach - base];
                let src = &hbuf[(r - r0) * bw + a..(r - r0) * bw + b];
                for (o, s) in own[a..b].iter_mut().zip(src) {
                    *o += wgt * s;
                }
            }
        }
        HBUF.with(|b| *b.borrow_mut() = hbuf);
        for k in (y1 - y0).saturating_sub(2)..y1 - y0 {
            self.inner_row(&own, &spans, (x0, bw), k, theta, &mut inner);
            inner_rows.push(inner.len() as u32);
        }
        (own, spans, inner, inner_rows)
    }
}

/// Σ|∇I| by central differences over the box grown by one pixel: the drawn perimeter, px.
#[inline(always)]
fn perimeter(cur: &Irradiance) -> f64 {
    let [c0, r0, c1, r1] = cur.bbox;
    let (w, h) = (c1 - c0, r1 - r0);
    // The box with two pixels of zeros around it (a buffer of the thread's, only its
    // frame cleared).
    thread_local! {
        static PAD: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    let pw = w + 4;
    let mut pad = PAD.with(|b| std::mem::take(&mut *b.borrow_mut()));
    if pad.len() < pw * (h + 4) {
        pad.resize(pw * (h + 4), 0.0);
    }
    pad[..2 * pw].fill(0.0);
    pad[(h + 2) * pw..(h + 4) * pw].fill(0.0);
    for r in 0..h {
        let row = &mut pad[(r + 2) * pw..(r + 3) * pw];
        row[..2].fill(0.0);
        row[2..2 + w].copy_from_slice(&cur.data[r * w..(r + 1) * w]);
        row[2 + w..].fill(0.0);
    }
    let mut s = 0.0f64;
    for r in 1..h + 3 {
        let (up, row, down) = (
            &pad[(r - 1) * pw..r * pw],
            &pad[r * pw..(r + 1) * pw],
            &pad[(r + 1) * pw..(r + 2) * pw],
        );
        for c in 1..w + 3 {
            let gx = 0.5 * (row[c + 1] - row[c - 1]);
            let gy = 0.5 * (down[c] - up[c]);
            if gx != 0.0 || gy != 0.0 {
                s += ((gx * gx + gy * gy) as f64).sqrt();
            }
        }
    }
    PAD.with(|b| *b.borrow_mut() = pad);
    s
}
