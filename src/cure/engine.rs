//! The sequential part of the check, from the top layer down: the light accumulated in one
//! field-sized buffer (A_i = r_i·L_i + q·A_{i+1}), each layer's cured samples, the
//! islands that vanish or merge, and the print-through below downward-facing pixels.

use super::check::{NEAR, SUB};
use super::islands::{components, Run};
#[cfg(test)]
use super::kernel::Kernel;
use super::kernel::{Irradiance, Prepared};
use super::CureModel;

/// The accumulation's pending decay factor below which it is applied to the buffer.
const RENORMALIZE: f32 = 1e-20;

/// What one layer gave.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LayerOut {
    /// Cured samples (fractions of a sample at the cured edge).
    pub cured_samples: f64,
    /// Σ|∇| of the irradiance, px.
    pub perimeter_px: f64,
    /// Islands.
    pub islands: usize,
    /// Vanished islands: (pixels, centroid column, row in pixel units).
    pub vanished: Vec<(u64, [f64; 2])>,
    /// Merges: (islands, pixels, centroid).
    pub merged: Vec<(usize, u64, [f64; 2])>,
    /// Deepest cure below the layer's bottom at downward-facing pixels, mm.
    pub print_through_mm: Option<f64>,
}

/// The sequential part of the check: the accumulation buffer and the scratch buffers,
/// for a field of `w`×`h` pixels.
pub struct Engine {
    /// The field's pixels across and down.
    w: usize,
    h: usize,
    /// Samples across.
    sw: usize,
    q: f32,
    /// Relative light at a layer's top at which its mid-plane cures.
    mid: f32,
    /// At which the resin just below its bottom cures.
    bottom: f32,
    dp_mm: f64,
    acc: Vec<f32>,
    /// The sample box where `acc` may be nonzero.
    acc_box: Option<[usize; 4]>,
    /// A = `acc` × `scale` (the decay by q of every layer, applied to the buffer only
    /// when the factor falls below [`RENORMALIZE`]).
    scale: f32,
    /// A row of zeros (the samples beyond the field's top and bottom).
    zero: Vec<f32>,
    /// Runs of cured samples and where each row's begin (merges).
    runs: Vec<Run>,
    rows: Vec<u32>,
    intervals: Vec<(u32, u32)>,
    /// With [`Engine::track_irradiance`]: Σ_k q^k·r_{i+k}·I_{i+k} per pixel (× `scale`),
    /// the unblurred light that reaches the last layer's top; empty otherwise.
    irr: Vec<f32>,
    /// The pixel box where `irr` may be nonzero.
    irr_box: Option<[usize; 4]>,
    /// With [`Engine::count_held_back`]: what a layer's cured area takes in beyond its
    /// own light.
    held: Option<Held>,
}

/// A layer's cured area with `xyz`: a downward-facing surface is drawn M layers late, to
/// cure by the light of the layers above, so a sample counts where the layer's own light
/// or that of one of the M layers above it is at least [`NEAR`].
struct Held {
    /// M.
    layers: u32,
    /// Layers processed, this one included.
    step: u32,
    /// Per sample, the step at which its own light last reached [`NEAR`] (`u32::MAX`:
    /// never).
    lit_at: Vec<u32>,
    /// The sample boxes and perimeters of the last M layers, nearest last.
    recent: std::collections::VecDeque<(Option<[usize; 4]>, f64)>,
}

impl Engine {
    /// An engine for a `w`×`h` field and `model`.
    pub fn new(w: usize, h: usize, model: &CureModel) -> Engine {
        let h_mm = model.layer_mm;
        Engine {
            w,
            h,
            sw: w * SUB,
            q: (-h_mm / model.dp_mm).exp() as f32,
            mid: model.threshold(0.5 * h_mm, Some(0)) as f32,
            bottom: model.threshold(h_mm, Some(0)) as f32,
            dp_mm: model.dp_mm,
            acc: vec![0.0; w * h * SUB * SUB],
            acc_box: None,
            scale: 1.0,
            zero: vec![0.0; w * SUB],
            runs: Vec::new(),
            rows: Vec::new(),
            intervals: Vec::new(),
            irr: Vec::new(),
            irr_box: None,
            held: None,
        }
    }

    /// Counts in a layer's cured area the samples the `layers` layers above it light to
    /// [`NEAR`] as well (`xyz` draws a downward-facing surface that many layers late, to
    /// cure by their light), and takes the largest of their perimeters (0: its own only).
    pub fn count_held_back(&mut self, layers: usize) {
        self.held = (layers > 0).then(|| Held {
            layers: layers as u32,
            step: 0,
            lit_at: vec![u32::MAX; self.acc.len()],
            recent: Default::default(),
        });
    }

    /// Keeps the unblurred light of the layers above as well ([`Engine::irradiance`]).
    pub fn track_irradiance(&mut self, on: bool) {
        self.irr = if on {
            vec![0.0; self.w * self.h]
        } else {
            Vec::new()
        };
    }

    /// The light that reaches the last layer's top before the blur, per pixel (row-major,
    /// the field's width) and the factor its values are to be multiplied by:
    /// Σ_k q^k·r_{i+k}·I_{i+k}, in units of a full pixel of a normal layer (empty without
    /// [`Engine::track_irradiance`]). Its blur is the light the engine cures by.
    pub fn irradiance(&self) -> (&[f32], f32) {
        (&self.irr, self.scale)
    }

    /// The field's size in pixels.
    pub fn size(&self) -> (usize, usize) {
        (self.w, self.h)
    }

    /// The accumulated light at sample (`x`, `y`) after the last layer.
    #[cfg(test)]
    pub fn acc_at(&self, x: usize, y: usize) -> f32 {
        self.acc[y * self.sw + x] * self.scale
    }

    /// Adds layer `cur` (light scaled by `ratio`) on top of the layers processed so far
    /// (the ones above it) and evaluates its cure; `below` is the layer under it (`None`
    /// for the first layer, which rests on the platform).
    /// `irr` is the layer's irradiance, read only with [`Engine::track_irradiance`].
    pub fn layer(
        &mut self,
        cur: &Prepared,
        below: Option<&Prepared>,
        irr: &Irradiance,
        ratio: f32,
    ) -> LayerOut {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { self.layer_avx2(cur, below, irr, ratio) };
        }
        self.layer_with(cur, below, irr, ratio)
    }

    /// [`Engine::layer`] compiled for AVX2 (the same values).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn layer_avx2(
        &mut self,
        cur: &Prepared,
        below: Option<&Prepared>,
        irr: &Irradiance,
        ratio: f32,
    ) -> LayerOut {
        self.layer_with(cur, below, irr, ratio)
    }

    #[inline(always)]
    fn layer_with(
        &mut self,
        cur: &Prepared,
        below: Option<&Prepared>,
        irr: &Irradiance,
        ratio: f32,
    ) -> LayerOut {
        // Everything above reaches this layer's top through one more layer: one factor,
        // folded into the buffer once it gets small.
        self.scale *= self.q;
        if self.scale < RENORMALIZE {
            let f = self.scale;
            for (buf, bx, w) in [
                (&mut self.acc, self.acc_box, self.sw),
                (&mut self.irr, self.irr_box, self.w),
            ] {
                if let (Some([x0, y0, x1, y1]), false) = (bx, buf.is_empty()) {
                    for y in y0..y1 {
                        for a in &mut buf[y * w + x0..y * w + x1] {
                            *a *= f;
                        }
                    }
                }
            }
            self.scale = 1.0;
        }
        if !self.irr.is_empty() && !irr.is_empty() {
            self.add_irradiance(irr, ratio);
        }
        let mut out = LayerOut::default();
        if cur.is_empty() {
            if self.held.is_some() {
                (out.cured_samples, out.perimeter_px) = self.held_cured(cur);
                self.held_lit(cur);
            }
            return out;
        }
        let sbox = cur.sbox;
        self.acc_box = Some(match self.acc_box {
            None => sbox,
            Some(a) => [
                a[0].min(sbox[0]),
                a[1].min(sbox[1]),
                a[2].max(sbox[2]),
                a[3].max(sbox[3]),
            ],
        });
        self.add_own(cur, ratio);
        out.cured_samples = self.cured_samples(cur);
        out.perimeter_px = cur.perimeter_px;
        if self.held.is_some() {
            let (more, perimeter) = self.held_cured(cur);
            out.cured_samples += more;
            out.perimeter_px = out.perimeter_px.max(perimeter);
            self.held_lit(cur);
        }
        self.islands(cur, &mut out);
        if let Some(below) = below {
            out.print_through_mm = self.print_through(cur, below);
        }
        out
    }

    /// irr += ratio · (the layer's irradiance) over its box.
    fn add_irradiance(&mut self, irr: &Irradiance, ratio: f32) {
        let [c0, r0, c1, r1] = irr.bbox;
        let gain = ratio / self.scale;
        for (r, row) in (r0..r1).zip(irr.data.chunks(c1 - c0)) {
            for (a, v) in self.irr[r * self.w + c0..r * self.w + c1]
                .iter_mut()
                .zip(row)
            {
                *a += gain * v;
            }
        }
        self.irr_box = Some(match self.irr_box {
            None => irr.bbox,
            Some(a) => [a[0].min(c0), a[1].min(r0), a[2].max(c1), a[3].max(r1)],
        });
    }

    /// acc += ratio · (the layer's own light) over its sample box (each row's span).
    #[inline(always)]
    fn add_own(&mut self, cur: &Prepared, ratio: f32) {
        let [x0, y0, x1, y1] = cur.sbox;
        let bw = x1 - x0;
        let gain = ratio / self.scale;
        debug_assert!(x1 <= self.sw);
        for y in y0..y1 {
            let (a, b) = cur.spans[y - y0];
            let (a, b) = (a as usize, b as usize);
            let own = &cur.own[(y - y0) * bw + a..(y - y0) * bw + b];
            let acc = &mut self.acc[y * self.sw + x0 + a..y * self.sw + x0 + b];
            for (a, o) in acc.iter_mut().zip(own) {
                *a += gain * o;
            }
        }
    }

    /// The cured samples of the sample box where the layer's own light is at least
    /// [`NEAR`], each counted by the fraction of its cell on the cured side: a sample
    /// whose four neighbours lie on its side of the threshold counts 0 or 1; one next to
    /// the cured edge clamp(½ + (A − T)/|∇A|), its signed distance from the edge in sample
    /// steps (A linear across the cell). Summed over an edge the fractions give the area
    /// behind it without the grid's quantization (exactly for an edge along the grid,
    /// whatever its position). Whole samples are counted 16 at a time, the fractions only
    /// in the groups that hold a sample next to the edge.
    #[inline(always)]
    fn cured_samples(&self, cur: &Prepared) -> f64 {
        let [x0, y0, x1, y1] = cur.sbox;
        let bw = x1 - x0;
        let (sw, sh) = (self.sw, self.acc.len() / self.sw);
        let t = self.mid / self.scale;
        let mut whole = 0u64;
        let mut frac = 0.0f64;
        const GROUP: usize = 16;
        for y in y0..y1 {
            // Only the row's span can have own light; samples with both side neighbours
            // inside the field go by groups.
            let (sa, sb) = cur.spans[y - y0];
            let (x0s, x1s) = (x0 + sa as usize, x0 + sb as usize);
            if x0s == x1s {
                continue;
            }
            let (xa, xb) = (x0s.max(1), x1s.min(sw - 1));
            let row = &self.acc[y * sw..(y + 1) * sw];
            let up = if y > 0 {
                &self.acc[(y - 1) * sw..y * sw]
            } else {
                &self.zero[..]
            };
            let down = if y + 1 < sh {
                &self.acc[(y + 1) * sw..(y + 2) * sw]
            } else {
                &self.zero[..]
            };
            let own = &cur.own[(y - y0) * bw..(y - y0 + 1) * bw];
            let sample = |x: usize| -> f64 {
                if own[x - x0] < NEAR {
                    return 0.0;
                }
                let l = if x > 0 { row[x - 1] } else { 0.0 };
                let r = if x + 1 < sw { row[x + 1] } else { 0.0 };
                cured_fraction(row[x], [l, r, up[x], down[x]], t)
            };
            // The span less the samples that cure whole ([`Kernel::inner`]): by groups,
            // the samples at the field's edge one by one.
            let inner =
                &cur.inner[cur.inner_rows[y - y0] as usize..cur.inner_rows[y - y0 + 1] as usize];
            let mut gaps = Vec::with_capacity(inner.len() + 1);
            let mut pos = x0s;
            for &(a, b) in inner {
                let (a, b) = (x0 + a as usize, x0 + b as usize);
                gaps.push((pos, a));
                whole += (b - a) as u64;
                pos = b;
            }
            gaps.push((pos, x1s));
            for (p, q) in gaps {
                for x in (p..q).filter(|&x| x < xa || x >= xb) {
                    frac += sample(x);
                }
                let (ga, gb) = (p.max(xa), q.min(xb));
                let mut x = ga;
                while x < gb {
                    let e = (x + GROUP).min(gb);
                    let (c, l, r) = (&row[x..e], &row[x - 1..e - 1], &row[x + 1..e + 1]);
                    let (u, d, o) = (&up[x..e], &down[x..e], &own[x - x0..e - x0]);
                    let (mut n, mut edge) = (0u32, false);
                    for j in 0..e - x {
                        let lo = c[j].min(l[j]).min(r[j]).min(u[j]).min(d[j]);
                        let hi = c[j].max(l[j]).max(r[j]).max(u[j]).max(d[j]);
                        let near = o[j] >= NEAR;
                        n += (near & (lo >= t)) as u32;
                        edge |= near & (lo < t) & (hi >= t);
                    }
                    if edge {
                        for xx in x..e {
                            frac += sample(xx);
                        }
                    } else {
                        whole += n as u64;
                    }
                    x = e;
                }
            }
        }
        whole as f64 + frac
    }

    /// The cured samples ([`Engine::cured_samples`]'s fractions) that `cur`'s own light
    /// does not reach to [`NEAR`] but one of the [`Held`] layers above does, and the
    /// largest of those layers' perimeters.
    fn held_cured(&mut self, cur: &Prepared) -> (f64, f64) {
        let (sw, sh) = (self.sw, self.acc.len() / self.sw);
        let held = self.held.as_mut().expect("counting held-back layers");
        held.step += 1;
        let (step, m) = (held.step, held.layers);
        let perimeter = held.recent.iter().map(|r| r.1).fold(0.0, f64::max);
        let boxes = held.recent.iter().filter_map(|r| r.0);
        let Some([x0, y0, x1, y1]) = boxes.reduce(|a, b| {
            [
                a[0].min(b[0]),
                a[1].min(b[1]),
                a[2].max(b[2]),
                a[3].max(b[3]),
            ]
        }) else {
            return (0.0, perimeter);
        };
        // Counted already: the samples of `cur`'s spans where its own light reaches NEAR.
        let own = |x: usize, y: usize| {
            let [a, b, c, d] = cur.sbox;
            if cur.is_empty() || !(a..c).contains(&x) || !(b..d).contains(&y) {
                return false;
            }
            let (sa, sb) = cur.spans[y - b];
            (sa as usize..sb as usize).contains(&(x - a))
                && cur.own[(y - b) * (c - a) + x - a] >= NEAR
        };
        let (t, acc) = (self.mid / self.scale, &self.acc);
        let at = |x: usize, y: usize| {
            if x < sw && y < sh {
                acc[y * sw + x]
            } else {
                0.0
            }
        };
        let mut sum = 0.0;
        for y in y0..y1 {
            for x in x0..x1 {
                let lit = held.lit_at[y * sw + x];
                if lit == u32::MAX || step - lit > m || own(x, y) {
                    continue;
                }
                // Neighbours beyond the field (wrapping) are 0, as `cured_samples` has them.
                let (l, u) = (at(x.wrapping_sub(1), y), at(x, y.wrapping_sub(1)));
                sum += cured_fraction(at(x, y), [l, at(x + 1, y), u, at(x, y + 1)], t);
            }
        }
        (sum, perimeter)
    }

    /// Marks the samples `cur`'s own light reaches to [`NEAR`] as lit at this step, and
    /// keeps its box and perimeter among the [`Held`] layers'.
    fn held_lit(&mut self, cur: &Prepared) {
        let sw = self.sw;
        let held = self.held.as_mut().expect("counting held-back layers");
        let sbox = (!cur.is_empty()).then_some(cur.sbox);
        if let Some([x0, y0, x1, _]) = sbox {
            let bw = x1 - x0;
            for (r, &(a, b)) in cur.spans.iter().enumerate() {
                for x in a as usize..b as usize {
                    if cur.own[r * bw + x] >= NEAR {
                        held.lit_at[(y0 + r) * sw + x0 + x] = held.step;
                    }
                }
            }
        }
        held.recent.push_back((sbox, cur.perimeter_px));
        if held.recent.len() > held.layers as usize {
            held.recent.pop_front();
        }
    }

    /// Islands of `cur` (4-connected lit pixels): which cure nowhere, which one cured
    /// region joins.
    #[inline(never)]
    fn islands(&mut self, cur: &Prepared, out: &mut LayerOut) {
        let n = cur.px.len();
        out.islands = n;
        if n == 0 {
            return;
        }
        let mid = self.mid / self.scale;
        let mut cured = vec![false; n];
        for (run, &i) in cur.runs.iter().zip(&cur.island) {
            let i = i as usize;
            if !cured[i] {
                cured[i] =
                    (run[1]..run[2]).any(|c| self.pixel_max(c as usize, run[0] as usize) >= mid);
            }
        }
        let (px, sum) = (&cur.px, &cur.sum);
        let centroid = |i: usize| [sum[i][0] / px[i] as f64, sum[i][1] / px[i] as f64];
        for i in 0..n {
            if !cured[i] {
                out.vanished.push((px[i], centroid(i)));
            }
        }
        if cured.iter().filter(|&&c| c).count() >= 2 {
            // The cured samples' regions (runs of samples at or above the threshold,
            // connected), and the islands each touches: those with a run whose samples
            // meet one of the region's runs.
            let [x0, y0, x1, y1] = cur.sbox;
            let sw = self.sw;
            let (mut runs, mut rows) = (
                std::mem::take(&mut self.runs),
                std::mem::take(&mut self.rows),
            );
            runs.clear();
            rows.clear();
            rows.push(0);
            for y in y0..y1 {
                let row = &self.acc[y * sw + x0..y * sw + x1];
                let mut x = 0;
                while x < row.len() {
                    let Some(a) = row[x..].iter().position(|&v| v >= mid) else {
                        break;
                    };
                    let b = row[x + a..]
                        .iter()
                        .position(|&v| v < mid)
                        .map_or(row.len(), |b| x + a + b);
                    runs.push([y as u32, (x0 + x + a) as u32, (x0 + b) as u32]);
                    x = b;
                }
                rows.push(runs.len() as u32);
            }
            let (region_of, m) = components(&runs);
            let mut region: Vec<Vec<usize>> = vec![Vec::new(); m];
            for (run, &l) in cur.runs.iter().zip(&cur.island) {
                let (a, b) = (run[1] * SUB as u32, run[2] * SUB as u32);
                for y in run[0] as usize * SUB..(run[0] as usize + 1) * SUB {
                    let k = y - y0;
                    for j in rows[k] as usize..rows[k + 1] as usize {
                        let s = runs[j];
                        if s[1] < b && a < s[2] {
                            let g = region_of[j] as usize;
                            if region[g].last() != Some(&(l as usize)) {
                                region[g].push(l as usize);
                            }
                        }
                    }
                }
            }
            self.runs = runs;
            self.rows = rows;
            for mut isl in region {
                isl.sort_unstable();
                isl.dedup();
                if isl.len() >= 2 {
                    let p: u64 = isl.iter().map(|&i| px[i]).sum();
                    let s = isl
                        .iter()
                        .fold([0.0, 0.0], |a, &i| [a[0] + sum[i][0], a[1] + sum[i][1]]);
                    out.merged
                        .push((isl.len(), p, [s[0] / p as f64, s[1] / p as f64]));
                }
            }
        }
    }

    /// [`Engine::cured_samples`] by its definition: every sample of the box, one by one.
    #[cfg(test)]
    fn cured_samples_reference(&self, cur: &Prepared) -> f64 {
        let [x0, y0, x1, y1] = cur.sbox;
        let (sw, sh) = (self.sw, self.acc.len() / self.sw);
        let t = self.mid / self.scale;
        let at = |x: isize, y: isize| {
            if x < 0 || y < 0 || x as usize >= sw || y as usize >= sh {
                0.0
            } else {
                self.acc[y as usize * sw + x as usize]
            }
        };
        let mut sum = 0.0f64;
        for y in y0..y1 {
            let (sa, sb) = cur.spans[y - y0];
            for x in x0..x1 {
                let k = x - x0;
                let own = if k >= sa as usize && k < sb as usize {
                    cur.own[(y - y0) * (x1 - x0) + k]
                } else {
                    0.0
                };
                if own < NEAR {
                    continue;
                }
                let (xi, yi) = (x as isize, y as isize);
                let (a, l, r, u, d) = (
                    at(xi, yi),
                    at(xi - 1, yi),
                    at(xi + 1, yi),
                    at(xi, yi - 1),
                    at(xi, yi + 1),
                );
                let side = a >= t;
                if side && l >= t && r >= t && u >= t && d >= t {
                    sum += 1.0;
                } else if !side && l < t && r < t && u < t && d < t {
                } else {
                    let (gx, gy) = (0.5 * (r - l), 0.5 * (d - u));
                    let g = (gx * gx + gy * gy).sqrt();
                    sum += if g > 0.0 {
                        (0.5 + (a - t) / g).clamp(0.0, 1.0) as f64
                    } else {
                        side as u8 as f64
                    };
                }
            }
        }
        sum
    }

    /// The largest accumulated light over pixel (c, r)'s samples.
    #[inline]
    fn pixel_max(&self, c: usize, r: usize) -> f32 {
        let mut m = 0.0f32;
        for k in 0..SUB * SUB {
            m = m.max(self.acc[(r * SUB + k / SUB) * self.sw + c * SUB + k % SUB]);
        }
        m
    }

    /// Deepest cure below the layer's bottom at its downward-facing pixels: lit in `cur`,
    /// and neither they nor their 4 neighbours lit in `below` (an anti-aliased wall whose
    /// edge pixel crosses one half from one layer to the next is not an overhang). Per
    /// row, the lit runs of `cur` less the columns `below` rules out (its runs of the rows
    /// above and below, and of the row itself grown by a pixel each side).
    #[inline(never)]
    fn print_through(&mut self, cur: &Prepared, below: &Prepared) -> Option<f64> {
        let [_, r0, _, r1] = cur.bbox;
        let mut best: Option<f32> = None;
        let floor = self.bottom / self.scale;
        let mut iv = std::mem::take(&mut self.intervals);
        for r in r0..r1 {
            let runs = cur.row(r);
            if runs.is_empty() {
                continue;
            }
            iv.clear();
            iv.extend(
                below
                    .row(r)
                    .iter()
                    .map(|b| (b[1].saturating_sub(1), b[2] + 1)),
            );
            if r > 0 {
                iv.extend(below.row(r - 1).iter().map(|b| (b[1], b[2])));
            }
            iv.extend(below.row(r + 1).iter().map(|b| (b[1], b[2])));
            iv.sort_unstable();
            for run in runs {
                let mut pos = run[1];
                let mut free = |a: u32, b: u32| {
                    for c in a..b {
                        let v = self.pixel_max(c as usize, r);
                        if v > floor && best.is_none_or(|m| v > m) {
                            best = Some(v);
                        }
                    }
                };
                for &(s, e) in &iv {
                    if e <= pos {
                        continue;
                    }
                    if s >= run[2] {
                        break;
                    }
                    if s > pos {
                        free(pos, s);
                    }
                    pos = pos.max(e);
                    if pos >= run[2] {
                        break;
                    }
                }
                if pos < run[2] {
                    free(pos, run[2]);
                }
            }
        }
        self.intervals = iv;
        best.map(|a| self.dp_mm * ((a * self.scale) as f64 / self.bottom as f64).ln())
    }
}

/// The fraction of a sample's cell on the cured side, from its light `a` and its left,
/// right, upper and lower neighbours' against the threshold `t`: 0 or 1 when all five lie
/// on one side, else clamp(½ + (a − t)/|∇|) (central differences).
#[inline(always)]
fn cured_fraction(a: f32, [l, r, u, d]: [f32; 4], t: f32) -> f64 {
    let side = a >= t;
    if side {
        if l >= t && r >= t && u >= t && d >= t {
            return 1.0;
        }
    } else if l < t && r < t && u < t && d < t {
        return 0.0;
    }
    let (gx, gy) = (0.5 * (r - l), 0.5 * (d - u));
    let g = (gx * gx + gy * gy).sqrt();
    if g > 0.0 {
        (0.5 + (a - t) / g).clamp(0.0, 1.0) as f64
    } else {
        side as u8 as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cure::psf::phi_inv;
    use crate::cure::test_model as model;
    use crate::cure::{Irradiance, Psf};

    /// A `w`×`h` image with `v` in the pixel rectangle [c0, c1) × [r0, r1).
    fn rect(w: usize, h: usize, [c0, r0, c1, r1]: [usize; 4], v: f32) -> Vec<f32> {
        let mut img = vec![0.0; w * h];
        for r in r0..r1 {
            for c in c0..c1 {
                img[r * w + c] = v;
            }
        }
        img
    }

    /// Runs a stack (bottom first) through the engine, top down; the layers' outputs
    /// bottom first.
    fn run(
        e: &mut Engine,
        m: &CureModel,
        w: usize,
        h: usize,
        stack: &[(Vec<f32>, f32)],
    ) -> Vec<LayerOut> {
        let k = Kernel::new(w, h, m);
        let irr: Vec<Prepared> = stack
            .iter()
            .map(|(img, r)| k.prepare(&Irradiance::from_image(w, h, img), *r))
            .collect();
        let mut out = vec![LayerOut::default(); stack.len()];
        for i in (0..stack.len()).rev() {
            let none = Irradiance::default();
            out[i] = e.layer(
                &irr[i],
                i.checked_sub(1).map(|b| &irr[b]),
                &none,
                stack[i].1,
            );
        }
        out
    }

    /// A_0 of the recurrence equals Σ_k q^k·r_k·L_k with every pixel's light summed
    /// directly (no separable passes, no boxes), on a small random stack.
    #[test]
    fn the_recurrence_equals_a_direct_sum_over_layers() {
        let m = model();
        let (w, h) = (14, 11);
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as f32 / (1u64 << 31) as f32
        };
        let stack: Vec<(Vec<f32>, f32)> = (0..5)
            .map(|k| {
                let img = (0..w * h)
                    .map(|p| {
                        let (c, r) = (p % w, p / w);
                        if (3..11).contains(&c) && (2..9).contains(&r) && rnd() > 0.3 {
                            rnd()
                        } else {
                            0.0
                        }
                    })
                    .collect();
                (img, [2.0, 1.0, 0.5, 1.0, 1.5][k])
            })
            .collect();
        let mut e = Engine::new(w, h, &m);
        run(&mut e, &m, w, h, &stack);
        let psf = Psf { sigma_px: 0.5 };
        let q = (-m.layer_mm / m.dp_mm).exp();
        let mut worst = 0.0f64;
        for y in 0..h * SUB {
            for x in 0..w * SUB {
                let (u, v) = ((x as f64 + 0.5) / SUB as f64, (y as f64 + 0.5) / SUB as f64);
                let direct: f64 = stack
                    .iter()
                    .enumerate()
                    .map(|(k, (img, r))| {
                        let mut l = 0.0;
                        for (p, &val) in img.iter().enumerate() {
                            let (c, rr) = ((p % w) as f64, (p / w) as f64);
                            l += val as f64 * psf.axis_weight(u - c) * psf.axis_weight(v - rr);
                        }
                        q.powi(k as i32) * *r as f64 * l
                    })
                    .sum();
                worst = worst.max((e.acc_at(x, y) as f64 - direct).abs());
            }
        }
        assert!(worst < 1e-4, "{worst}");
    }

    /// The cured sum by spans (whole samples found ahead, groups of 16) equals the sum over
    /// every sample one by one within 1e-9 relative, on random stacks touching the field's
    /// edges, with exposure ratios from 0.1 to 3 (the threshold crossing interiors).
    #[test]
    fn the_cured_sum_by_spans_equals_the_sum_over_every_sample() {
        let mut seed = 987654321u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as f32 / (1u64 << 31) as f32
        };
        for sigma in [0.5, 1.2] {
            let mut m = model();
            m.sigma_px = sigma;
            let (w, h) = (48, 40);
            let mut e = Engine::new(w, h, &m);
            let k = Kernel::new(w, h, &m);
            let mut checked = 0;
            for layer in 0..12 {
                // Blobs of full and partial light, some reaching the field's edges.
                let mut img = vec![0.0f32; w * h];
                for _ in 0..4 {
                    let (cx, cy) = ((rnd() * w as f32) as usize, (rnd() * h as f32) as usize);
                    let (rx, ry) = (2 + (rnd() * 14.0) as usize, 2 + (rnd() * 12.0) as usize);
                    let v = if rnd() < 0.6 { 1.0 } else { 0.3 + 0.7 * rnd() };
                    for r in cy.saturating_sub(ry)..(cy + ry).min(h) {
                        for c in cx.saturating_sub(rx)..(cx + rx).min(w) {
                            img[r * w + c] = v;
                        }
                    }
                }
                let ratio = [0.1, 0.5, 0.9, 1.0, 3.0][layer % 5];
                let p = k.prepare(&Irradiance::from_image(w, h, &img), ratio);
                let out = e.layer(&p, None, &Irradiance::default(), ratio);
                let want = e.cured_samples_reference(&p);
                assert!(
                    (out.cured_samples - want).abs() <= 1e-9 * want.max(1.0),
                    "σ {sigma} layer {layer}: {} vs {want}",
                    out.cured_samples
                );
                checked += (want > 0.0) as usize;
            }
            assert!(checked >= 6, "{checked}");
        }
    }

    /// The cured edge offset of a fully lit square, its light scaled as under infinitely
    /// many layers like it (one layer, r = 1/(1 − q)).
    fn square_offset(m: &CureModel, n: usize, side: usize, phase: f32) -> f64 {
        let (w, h) = (n, n);
        let a = (n - side) / 2;
        // Whole pixels [a, a + side), and `phase` of a pixel more on every side.
        let mut img = rect(w, h, [a - 1, a - 1, a + side + 1, a + side + 1], phase);
        for r in a..a + side {
            for c in a..a + side {
                img[r * w + c] = 1.0;
            }
        }
        for (c, r) in [
            (a - 1, a - 1),
            (a + side, a - 1),
            (a - 1, a + side),
            (a + side, a + side),
        ] {
            img[r * w + c] = phase * phase;
        }
        let q = (-m.layer_mm / m.dp_mm).exp();
        let mut e = Engine::new(w, h, m);
        let out = run(&mut e, m, w, h, &[(img, (1.0 / (1.0 - q)) as f32)]);
        let o = &out[0];
        let s = side as f64 + 2.0 * phase as f64;
        assert!(
            (o.perimeter_px - 4.0 * s).abs() < 0.01 * 4.0 * s,
            "{}",
            o.perimeter_px
        );
        assert_eq!((o.islands, o.vanished.len(), o.merged.len()), (1, 0, 0));
        (o.cured_samples / (SUB * SUB) as f64 - s * s) / o.perimeter_px
    }

    /// A fully lit square's cured edge against the closed form: s* = −σₑ·Φ⁻¹(T) for
    /// anti-aliased edges (docs/CURE.md), within 0.05 px, with a PSF wide enough for the
    /// Gaussian-and-box approximation to hold at any edge position (σ = 1.5 px); and
    /// −σ·Φ⁻¹(T) exactly for edges on pixel boundaries, where the pixels add up to a sharp
    /// half-plane (σ = 0.5 px: 0.43 px).
    #[test]
    fn a_lit_squares_edge_moves_by_the_closed_form() {
        let mut m = model();
        let t = m.edge_threshold();
        let sharp = -m.sigma_px * phi_inv(t);
        let got = square_offset(&m, 64, 40, 0.0);
        assert!(
            (got - sharp).abs() < 0.02,
            "offset {got}, closed form {sharp}"
        );
        m.sigma_px = 1.5;
        let psf = Psf { sigma_px: 1.5 };
        let want = -psf.sigma_edge_px() * phi_inv(t);
        for phase in [0.25, 0.75] {
            let got = square_offset(&m, 240, 200, phase);
            assert!(
                (got - want).abs() < 0.05,
                "phase {phase}: offset {got}, closed form {want}"
            );
        }
    }

    #[test]
    fn a_one_pixel_island_vanishes_and_squares_a_pixel_apart_merge() {
        let m = model();
        let (w, h) = (40, 30);
        // One layer: a pixel alone gets too little light to cure; a square beside it
        // cures.
        let mut img = rect(w, h, [5, 5, 15, 15], 1.0);
        img[20 * w + 30] = 1.0;
        let mut e = Engine::new(w, h, &m);
        let out = run(&mut e, &m, w, h, &[(img, 1.0)]);
        assert_eq!(out[0].islands, 2);
        assert_eq!(out[0].vanished.len(), 1);
        let (px, at) = out[0].vanished[0];
        assert_eq!((px, at), (1, [30.5, 20.5]));
        assert!(out[0].merged.is_empty());
        // Two squares one pixel apart under many layers like them: the gap cures.
        let mut img = rect(w, h, [5, 5, 15, 15], 1.0);
        for r in 5..15 {
            for c in 16..26 {
                img[r * w + c] = 1.0;
            }
        }
        let stack: Vec<(Vec<f32>, f32)> = (0..30).map(|_| (img.clone(), 1.0)).collect();
        let mut e = Engine::new(w, h, &m);
        let out = run(&mut e, &m, w, h, &stack);
        assert_eq!(out[0].islands, 2);
        assert!(out[0].vanished.is_empty());
        assert_eq!(out[0].merged.len(), 1);
        assert_eq!(out[0].merged[0].0, 2);
        assert_eq!(out[0].merged[0].1, 200);
        // Three pixels apart they stay apart.
        let mut img = rect(w, h, [5, 5, 15, 15], 1.0);
        for r in 5..15 {
            for c in 18..28 {
                img[r * w + c] = 1.0;
            }
        }
        let stack: Vec<(Vec<f32>, f32)> = (0..30).map(|_| (img.clone(), 1.0)).collect();
        let mut e = Engine::new(w, h, &m);
        let out = run(&mut e, &m, w, h, &stack);
        assert!(out[0].merged.is_empty());
    }

    /// Print-through under an overhang: the closed form with the layers above it.
    #[test]
    fn print_through_under_an_overhang_follows_the_closed_form() {
        let m = model();
        let (w, h) = (40, 40);
        let lit = rect(w, h, [5, 5, 35, 35], 1.0);
        // Layer 0 empty, layers 1..=200 lit: layer 1 is downward-facing. (The pending
        // decay q^k is folded into the buffer after about 140 layers.)
        let mut stack: Vec<(Vec<f32>, f32)> = vec![(vec![0.0; w * h], 1.0)];
        stack.extend((0..200).map(|_| (lit.clone(), 1.0)));
        let mut e = Engine::new(w, h, &m);
        let out = run(&mut e, &m, w, h, &stack);
        let got = out[1].print_through_mm.unwrap();
        let want = m.print_through_mm(Some(199));
        assert!((got - want).abs() < 1e-4, "{got} vs {want}");
        assert!(out[2].print_through_mm.is_none());
    }

    /// Counting held-back layers (`xyz`), a layer drawn narrower than its section takes
    /// in what the layers above cure through it, up to M layers above: a 30 px square
    /// drawn from layer 4 on over a 10 px one (M = 4 with the defaults) cures through
    /// layer 0's mid-plane.
    #[test]
    fn held_back_layers_cure_through_the_layer_and_count_in_its_area() {
        let m = model();
        let (w, h) = (50, 50);
        let small = rect(w, h, [20, 20, 30, 30], 1.0);
        let big = rect(w, h, [10, 10, 40, 40], 1.0);
        let mut stack: Vec<(Vec<f32>, f32)> = (0..4).map(|_| (small.clone(), 1.0)).collect();
        stack.extend((0..60).map(|_| (big.clone(), 1.0)));
        let area = |held: usize| {
            let mut e = Engine::new(w, h, &m);
            e.count_held_back(held);
            run(&mut e, &m, w, h, &stack)[0].cured_samples / (SUB * SUB) as f64
        };
        let (own, three, four) = (area(0), area(3), area(4));
        assert!(own > 100.0 && own < 200.0 && three == own, "{own} {three}");
        assert!((800.0..950.0).contains(&four), "{four}");
    }
}
