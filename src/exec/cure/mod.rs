//! `dmdsl run --cure`: what cures, predicted from a bundle's masks alone (docs/CURE.md's
//! model through [`crate::resin`], docs/EXECUTOR.md "Cure check").
//!
//! In the projector's pixels, for one projector:
//!
//! 1. Each mask pixel's **relative irradiance**: with light compensation S(g)/S(G(px)) (g
//!    the mask's gray, G the pixel's full-coverage gray from the bundle's gray map, S the
//!    projector's response), else g/255.
//! 2. Each layer's light scaled by r = `exposure_s` / the profile's normal `layer_s`
//!    (bottom layers and a continuous layer's sweep time count as they are).
//! 3. The light blurred by the Gaussian PSF (separable pixel-box weights,
//!    [`Psf::axis_weight`]) at [`SUB`]×[`SUB`] samples per pixel, over the lit box plus the
//!    PSF's reach.
//! 4. From the top layer down, A_i = r_i·L_i + q·A_{i+1} (q = exp(−h/Dp)): the light that
//!    reaches layer i's top from its own exposure and every following one. Layer i's
//!    mid-plane cures where A_i·D₀·exp(−h/(2Dp)) ≥ Ec. One accumulation buffer the size of
//!    the field, whatever the layer count.
//! 5. Per layer: the cured area (where the layer's own light is at least [`NEAR`]: farther
//!    out it is the print-through of the layers above) against the section's
//!    (`area_mm2`), the drawn perimeter
//!    (Σ|∇| of the relative irradiance by central differences: exact for a monotone
//!    anti-aliased edge at any angle) and so the mean edge offset; the islands (4-connected
//!    pixels of relative irradiance ≥ 0.5) that do not cure ("vanished") or that one cured
//!    region joins ("merged"); the print-through below downward-facing pixels (lit, over
//!    a pixel that is dark in the layer below, as are its 4 neighbours).

use crate::bundle::{BundleSource, Manifest, MANIFEST};
use crate::error::{Error, Result};
use crate::resin::{CureModel, Psf};
use image::codecs::png::PngDecoder;
use image::ImageDecoder;
use rayon::prelude::*;
use serde::Serialize;

use super::report::{six, six_opt};

/// Samples per pixel along each axis at which the cure is evaluated.
pub const SUB: usize = 2;
/// The worst layers the check names.
pub const WORST_LAYERS: usize = 5;
/// Relative irradiance at which a pixel counts as lit (islands, downward-facing pixels).
pub const LIT: f32 = 0.5;
/// The layer's own light (of a full pixel) below which a sample does not count in its
/// cured area: about 1.3 px outside a straight edge with σ = 0.5 px, well beyond the
/// cured edge; resin cured farther out is the layers above's print-through.
pub const NEAR: f32 = 0.01;
/// The accumulation's pending decay factor below which it is applied to the buffer.
const RENORMALIZE: f32 = 1e-20;
/// Layers decoded together, ahead of the sequential recurrence.
const CHUNK: usize = 8;

/// Statistics of the absolute edge offset over layers, px.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct OffsetStats {
    /// Perimeter-weighted mean.
    #[serde(serialize_with = "six")]
    pub mean: f64,
    /// Perimeter-weighted 95th percentile.
    #[serde(serialize_with = "six")]
    pub p95: f64,
    /// Largest.
    #[serde(serialize_with = "six")]
    pub max: f64,
}

/// Something a process engineer must see: an island that does not cure, or cured resin
/// joining islands.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// Layer index.
    pub layer: usize,
    /// `vanished` or `merged`.
    pub kind: &'static str,
    /// Islands concerned (1 for `vanished`).
    pub islands: usize,
    /// Lit pixels of the islands.
    pub pixels: u64,
    /// Their centroid on the build plane, mm from the field's bottom-left corner.
    #[serde(serialize_with = "six_pair")]
    pub at_mm: [f64; 2],
}

fn six_pair<S: serde::Serializer>(v: &[f64; 2], s: S) -> std::result::Result<S::Ok, S::Error> {
    [
        crate::round::decimals(v[0], 6),
        crate::round::decimals(v[1], 6),
    ]
    .serialize(s)
}

/// One layer's cure, from its masks.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct LayerCureCheck {
    /// Layer index.
    pub index: usize,
    /// The section's area the bundle records, mm².
    #[serde(serialize_with = "six")]
    pub section_mm2: f64,
    /// Cured area at mid-layer, mm² (samples where the layer's own light is at least
    /// [`NEAR`] of a full pixel's).
    #[serde(serialize_with = "six")]
    pub cured_mm2: f64,
    /// The drawn perimeter, mm (Σ|∇| of the relative irradiance).
    #[serde(serialize_with = "six")]
    pub perimeter_mm: f64,
    /// Mean edge offset (cured − section area) / perimeter, px (positive: grows).
    #[serde(serialize_with = "six")]
    pub offset_px: f64,
    /// The same, mm.
    #[serde(serialize_with = "six")]
    pub offset_mm: f64,
    /// Islands of lit pixels.
    pub islands: usize,
    /// Islands no sample of which cures.
    pub vanished: usize,
    /// Cured regions joining two or more islands.
    pub merged: usize,
    /// Deepest cure below the layer's bottom at its downward-facing pixels, mm.
    #[serde(serialize_with = "six_opt", skip_serializing_if = "Option::is_none")]
    pub print_through_mm: Option<f64>,
    /// The slicer's signed mean edge error of the layer (`layers[].cure.mean_px`).
    #[serde(serialize_with = "six_opt", skip_serializing_if = "Option::is_none")]
    pub slicer_mean_px: Option<f64>,
    /// `offset_px` − `slicer_mean_px`.
    #[serde(serialize_with = "six_opt", skip_serializing_if = "Option::is_none")]
    pub slicer_diff_px: Option<f64>,
}

/// How the check agrees with the slicer's records (`slice --predict`): information.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct SlicerAgreement {
    /// Layers with both figures.
    pub layers: usize,
    /// Largest |offset − slicer's mean|, px.
    #[serde(serialize_with = "six")]
    pub max_diff_px: f64,
    /// The layer where it is.
    pub max_diff_layer: Option<usize>,
    /// Layers where one finds a vanishing island and the other none.
    pub vanish_disagreements: Vec<usize>,
}

/// The cure predicted from the masks (`dmdsl run --cure`).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CureCheck {
    /// The job's correction: "off", "xy" or "xyz".
    pub correction: String,
    /// Layers of downward-facing surfaces held back (`xyz`).
    pub held_back_layers: u32,
    /// Samples per pixel along each axis.
    pub samples_per_px: usize,
    /// Layers with a drawn perimeter (the offset statistics are over them).
    pub layers_checked: usize,
    /// |edge offset| over layers, weighted by perimeter, px.
    pub edge_offset_px: OffsetStats,
    /// Signed mean edge offset, px (weighted by perimeter).
    #[serde(serialize_with = "six")]
    pub signed_mean_px: f64,
    /// The same, mm.
    #[serde(serialize_with = "six")]
    pub signed_mean_mm: f64,
    /// Islands that do not cure, over all layers.
    pub vanished: usize,
    /// Cured regions joining islands, over all layers.
    pub merged: usize,
    /// Deepest print-through below a downward-facing pixel, mm (`None`: none).
    #[serde(serialize_with = "six_opt")]
    pub print_through_mm: Option<f64>,
    /// With held-back layers: `print_through_mm` − held_back_layers·h, mm.
    #[serde(serialize_with = "six_opt", skip_serializing_if = "Option::is_none")]
    pub z_error_mm: Option<f64>,
    /// Against the slicer's per-layer records, when the bundle has them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub slicer: Option<SlicerAgreement>,
    /// Layers with the largest |offset|, worst first.
    pub worst_layers: Vec<usize>,
    /// Vanished and merged islands, by layer.
    pub findings: Vec<Finding>,
    /// Per layer.
    pub per_layer: Vec<LayerCureCheck>,
}

/// The model's inputs of `manifest`, or an error naming the bundle and what is missing:
/// the `cure` record, or a single projector.
pub fn model_of(manifest: &Manifest, source: &dyn BundleSource) -> Result<CureModel> {
    let err = |msg: String| Error::Bundle {
        path: source.shown(MANIFEST),
        msg,
    };
    let Some(c) = &manifest.cure else {
        return Err(err(
            "--cure: the job has no `cure` record (it was sliced with a profile without \
             psf_sigma_px, or imported): nothing to predict with"
                .into(),
        ));
    };
    let n = manifest.machine.projector.len();
    if n != 1 {
        return Err(err(format!(
            "--cure: the job has {n} projectors; the cure check handles one (overlap \
             blending would need the projectors' light summed in the field)"
        )));
    }
    Ok(CureModel {
        sigma_px: c.psf_sigma_px,
        pixel_mm: c.pixel_mm,
        dp_mm: c.dp_mm,
        ec_mj_cm2: c.ec_mj_cm2,
        overcure_mm: c.overcure_mm,
        layer_mm: c.layer_mm,
    })
}

/// A layer's relative irradiance inside its lit box (pixels, ends exclusive).
#[derive(Debug, Clone, Default)]
pub struct Irradiance {
    /// `[c0, r0, c1, r1]`; empty when nothing is lit.
    pub bbox: [usize; 4],
    /// Row-major over the box.
    pub data: Vec<f32>,
}

impl Irradiance {
    /// The irradiance of a whole `w`×`h` image, cut to its nonzero box.
    pub fn from_image(w: usize, h: usize, img: &[f32]) -> Irradiance {
        let (mut c0, mut r0, mut c1, mut r1) = (w, h, 0, 0);
        for r in 0..h {
            let row = &img[r * w..(r + 1) * w];
            if let Some(a) = row.iter().position(|&v| v > 0.0) {
                let b = row.iter().rposition(|&v| v > 0.0).unwrap_or(a);
                c0 = c0.min(a);
                c1 = c1.max(b + 1);
                r0 = r0.min(r);
                r1 = r + 1;
            }
        }
        Irradiance::cut(w, img, [c0, r0, c1, r1])
    }

    fn cut(w: usize, img: &[f32], bbox: [usize; 4]) -> Irradiance {
        let [c0, r0, c1, r1] = bbox;
        if c0 >= c1 || r0 >= r1 {
            return Irradiance::default();
        }
        let mut data = Vec::with_capacity((c1 - c0) * (r1 - r0));
        for r in r0..r1 {
            data.extend_from_slice(&img[r * w + c0..r * w + c1]);
        }
        Irradiance { bbox, data }
    }

    fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The value at pixel (c, r), 0 outside the box.
    #[inline]
    pub fn at(&self, c: usize, r: usize) -> f32 {
        let [c0, r0, c1, r1] = self.bbox;
        if c < c0 || c >= c1 || r < r0 || r >= r1 {
            0.0
        } else {
            self.data[(r - r0) * (c1 - c0) + c - c0]
        }
    }
}

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

/// A run of lit pixels (relative irradiance ≥ [`LIT`]) of one row: columns `[c0, c1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Run {
    r: u32,
    c0: u32,
    c1: u32,
}

/// What a layer gives that depends on its mask alone, computed ahead of the sequential
/// recurrence (in parallel, several layers at a time): its own blurred light, perimeter,
/// lit runs and islands.
#[derive(Debug, Clone, Default)]
pub struct Prepared {
    /// The pixel box of the irradiance; empty when nothing is lit.
    bbox: [usize; 4],
    /// The sample box the layer's light reaches.
    sbox: [usize; 4],
    /// The layer's own light over `sbox` (before the exposure ratio), row-major.
    own: Vec<f32>,
    /// Per row of `sbox`: the columns (from its left) outside which `own` is zero (and
    /// not cleared: never read).
    spans: Vec<(u32, u32)>,
    /// Samples that cure whole whatever the layers above add: `inner[inner_rows[k]..
    /// inner_rows[k + 1]]` the column ranges (from the box's left) of the box's k-th row.
    inner: Vec<(u32, u32)>,
    inner_rows: Vec<u32>,
    perimeter_px: f64,
    /// Lit runs, row-major.
    runs: Vec<Run>,
    /// `rows[r − bbox[1]]..rows[r − bbox[1] + 1]`: the runs of row r.
    rows: Vec<u32>,
    /// The island (0-based) of each run.
    island: Vec<u32>,
    /// Per island: lit pixels and the sums of their centres' columns and rows.
    px: Vec<u64>,
    sum: Vec<[f64; 2]>,
}

impl Prepared {
    fn is_empty(&self) -> bool {
        self.own.is_empty()
    }

    /// The lit runs of row `r` (none outside the box).
    fn row(&self, r: usize) -> &[Run] {
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
    /// light's scale, see [`Engine::layer`]).
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

/// The lit runs of `cur` and its islands (4-connected runs, union-find with the smallest
/// run as root; islands numbered in the order of their first run, row-major).
#[inline(never)]
fn lit_islands(cur: &Irradiance, p: &mut Prepared) {
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
fn connect(runs: &[Run], rows: &[u32]) -> (Vec<u32>, usize) {
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

/// The sequential part of the check: the accumulation buffer and the scratch buffers,
/// for a field of `w`×`h` pixels.
pub struct Engine {
    w: usize,
    h: usize,
    model: CureModel,
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
}

impl Engine {
    /// An engine for a `w`×`h` field and `model`.
    pub fn new(w: usize, h: usize, model: &CureModel) -> Engine {
        let h_mm = model.layer_mm;
        Engine {
            w,
            h,
            model: *model,
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
        }
    }

    /// The kernel that prepares the layers of this engine's field and model.
    pub fn kernel(&self) -> Kernel {
        Kernel::new(self.w, self.h, &self.model)
    }

    /// The accumulated light at sample (`x`, `y`) after the last layer.
    pub fn acc_at(&self, x: usize, y: usize) -> f32 {
        self.acc[y * self.sw + x] * self.scale
    }

    /// Adds layer `cur` (light scaled by `ratio`) on top of the layers processed so far
    /// (the ones above it) and evaluates its cure; `below` is the layer under it (`None`
    /// for the first layer, which rests on the platform).
    pub fn layer(&mut self, cur: &Prepared, below: Option<&Prepared>, ratio: f32) -> LayerOut {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { self.layer_avx2(cur, below, ratio) };
        }
        self.layer_with(cur, below, ratio)
    }

    /// [`Engine::layer`] compiled for AVX2 (the same values).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn layer_avx2(&mut self, cur: &Prepared, below: Option<&Prepared>, ratio: f32) -> LayerOut {
        self.layer_with(cur, below, ratio)
    }

    #[inline(always)]
    fn layer_with(&mut self, cur: &Prepared, below: Option<&Prepared>, ratio: f32) -> LayerOut {
        // Everything above reaches this layer's top through one more layer: one factor,
        // folded into the buffer once it gets small.
        self.scale *= self.q;
        if self.scale < RENORMALIZE {
            if let Some([x0, y0, x1, y1]) = self.acc_box {
                let f = self.scale;
                for y in y0..y1 {
                    for a in &mut self.acc[y * self.sw + x0..y * self.sw + x1] {
                        *a *= f;
                    }
                }
            }
            self.scale = 1.0;
        }
        let mut out = LayerOut::default();
        if cur.is_empty() {
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
        self.islands(cur, &mut out);
        if let Some(below) = below {
            out.print_through_mm = self.print_through(cur, below);
        }
        out
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
                let a = row[x];
                let l = if x > 0 { row[x - 1] } else { 0.0 };
                let r = if x + 1 < sw { row[x + 1] } else { 0.0 };
                let (u, d) = (up[x], down[x]);
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
                    (run.c0..run.c1).any(|c| self.pixel_max(c as usize, run.r as usize) >= mid);
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
                    runs.push(Run {
                        r: y as u32,
                        c0: (x0 + x + a) as u32,
                        c1: (x0 + b) as u32,
                    });
                    x = b;
                }
                rows.push(runs.len() as u32);
            }
            let (region_of, m) = connect(&runs, &rows);
            let mut region: Vec<Vec<usize>> = vec![Vec::new(); m];
            for (run, &l) in cur.runs.iter().zip(&cur.island) {
                let (a, b) = (run.c0 * SUB as u32, run.c1 * SUB as u32);
                for y in run.r as usize * SUB..(run.r as usize + 1) * SUB {
                    let k = y - y0;
                    for j in rows[k] as usize..rows[k + 1] as usize {
                        let s = runs[j];
                        if s.c0 < b && a < s.c1 {
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
                    .map(|b| (b.c0.saturating_sub(1), b.c1 + 1)),
            );
            if r > 0 {
                iv.extend(below.row(r - 1).iter().map(|b| (b.c0, b.c1)));
            }
            iv.extend(below.row(r + 1).iter().map(|b| (b.c0, b.c1)));
            iv.sort_unstable();
            for run in runs {
                let mut pos = run.c0;
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
                    if s >= run.c1 {
                        break;
                    }
                    if s > pos {
                        free(pos, s);
                    }
                    pos = pos.max(e);
                    if pos >= run.c1 {
                        break;
                    }
                }
                if pos < run.c1 {
                    free(pos, run.c1);
                }
            }
        }
        self.intervals = iv;
        best.map(|a| self.dp_mm * ((a * self.scale) as f64 / self.bottom as f64).ln())
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

/// How a mask's gray turns into relative irradiance.
enum Light {
    /// g/255.
    Linear([f32; 256]),
    /// S(g)/S(G(px)): `s[g]` and 1/S(G) per pixel (0 where G = 0: g/255 there).
    Compensated { s: [f32; 256], inv_full: Vec<f32> },
}

impl Light {
    fn of(manifest: &Manifest, source: &dyn BundleSource) -> Result<Light> {
        let mut linear = [0f32; 256];
        for (g, v) in linear.iter_mut().enumerate() {
            *v = g as f32 / 255.0;
        }
        let Some(o) = &manifest.optics else {
            return Ok(Light::Linear(linear));
        };
        let bad = |msg: String| Error::Bundle {
            path: source.shown(&o.gray_map),
            msg,
        };
        let proj = manifest
            .machine
            .projector
            .get(o.projector as usize)
            .ok_or_else(|| bad("--cure: the gray map's projector is not the machine's".into()))?;
        let cal = proj.calibration.as_ref().ok_or_else(|| {
            bad("--cure: light compensation without the projector's calibration".into())
        })?;
        let [lo, hi] = cal.response.valid_gray();
        let curve = cal.response.curve();
        let mut s = [0f32; 256];
        for (g, v) in s.iter_mut().enumerate().skip(1) {
            *v = curve.eval(g.clamp(lo as usize, hi as usize) as f64) as f32;
        }
        let (w, h, full) = decode(source, &o.gray_map)?;
        if (w, h) != (proj.width_px as usize, proj.height_px as usize) {
            return Err(bad(format!(
                "gray map is {w}x{h}, the projector {}x{}",
                proj.width_px, proj.height_px
            )));
        }
        let inv_full = full
            .iter()
            .map(|&g| if g == 0 { 0.0 } else { 1.0 / s[g as usize] })
            .collect();
        Ok(Light::Compensated { s, inv_full })
    }

    /// The relative irradiance of a `w`-wide mask, cut to its lit box.
    fn irradiance(&self, w: usize, h: usize, mask: &[u8]) -> Irradiance {
        let (mut c0, mut r0, mut c1, mut r1) = (w, h, 0, 0);
        for (r, row) in mask.chunks(w).enumerate() {
            // Dark rows (most) told by an OR of the bytes (vectorizes).
            if row.iter().fold(0u8, |a, &v| a | v) == 0 {
                continue;
            }
            if let Some(a) = row.iter().position(|&v| v != 0) {
                let b = row.iter().rposition(|&v| v != 0).unwrap_or(a);
                c0 = c0.min(a);
                c1 = c1.max(b + 1);
                r0 = r0.min(r);
                r1 = r + 1;
            }
        }
        if c0 >= c1 {
            return Irradiance::default();
        }
        let mut data = Vec::with_capacity((c1 - c0) * (r1 - r0));
        for r in r0..r1 {
            let row = &mask[r * w + c0..r * w + c1];
            match self {
                Light::Linear(t) => data.extend(row.iter().map(|&g| t[g as usize])),
                Light::Compensated { s, inv_full } => {
                    let inv = &inv_full[r * w + c0..r * w + c1];
                    data.extend(row.iter().zip(inv).map(|(&g, &i)| {
                        if i > 0.0 {
                            s[g as usize] * i
                        } else {
                            g as f32 / 255.0
                        }
                    }))
                }
            }
        }
        Irradiance {
            bbox: [c0, r0, c1, r1],
            data,
        }
    }
}

/// Decodes an 8-bit gray PNG of the bundle.
fn decode(source: &dyn BundleSource, rel: &str) -> Result<(usize, usize, Vec<u8>)> {
    let mut buf = Vec::new();
    let (w, h) = decode_into(source, rel, &mut buf)?;
    Ok((w, h, buf))
}

/// Decodes an 8-bit gray PNG of the bundle into `buf` (its size, the image's; cleared
/// only where it grows): its width and height.
fn decode_into(source: &dyn BundleSource, rel: &str, buf: &mut Vec<u8>) -> Result<(usize, usize)> {
    let bad = |msg: String| Error::Bundle {
        path: source.shown(rel),
        msg,
    };
    let bytes = source
        .read(rel)
        .map_err(|e| bad(format!("cannot read: {e}")))?;
    let dec = PngDecoder::new(std::io::Cursor::new(&bytes[..]))
        .map_err(|e| bad(format!("not a decodable PNG: {e}")))?;
    if dec.color_type() != image::ColorType::L8 {
        return Err(bad("not 8-bit gray".into()));
    }
    let (w, h) = dec.dimensions();
    buf.resize(dec.total_bytes() as usize, 0);
    dec.read_image(buf)
        .map_err(|e| bad(format!("PNG does not decode: {e}")))?;
    Ok((w as usize, h as usize))
}

/// The cure of every layer of the job whose files `source` reads, from its masks (see the
/// module docs). `model` from [`model_of`].
pub fn check(
    manifest: &Manifest,
    source: &dyn BundleSource,
    model: &CureModel,
) -> Result<CureCheck> {
    let proj = &manifest.machine.projector[0];
    let (w, h) = (proj.width_px as usize, proj.height_px as usize);
    let light = Light::of(manifest, source)?;
    let normal_s = manifest.machine.exposure.layer_s.get();
    let n = manifest.layers.len();
    let kernel = Kernel::new(w, h, model);
    let decode_layer = |i: usize| -> Result<Prepared> {
        let Some(m) = manifest.layers[i].masks.first() else {
            return Ok(Prepared::default());
        };
        thread_local! {
            static MASK: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
        }
        let mut px = MASK.with(|b| std::mem::take(&mut *b.borrow_mut()));
        let (mw, mh) = decode_into(source, &m.file, &mut px)?;
        if (mw, mh) != (w, h) {
            return Err(Error::Bundle {
                path: source.shown(&m.file),
                msg: format!("mask is {mw}x{mh}, the projector {w}x{h}"),
            });
        }
        let r = (manifest.layers[i].exposure_s / normal_s) as f32;
        let p = kernel.prepare(&light.irradiance(w, h, &px), r);
        MASK.with(|b| *b.borrow_mut() = px);
        Ok(p)
    };
    let decode_chunk = |hi: usize| -> Result<Vec<Prepared>> {
        // Layers hi−1 down to hi−CHUNK (top first).
        let lo = hi.saturating_sub(CHUNK);
        (lo..hi)
            .rev()
            .collect::<Vec<_>>()
            .par_iter()
            .map(|&i| decode_layer(i))
            .collect()
    };
    let mut engine = Engine::new(w, h, model);
    let mut outs: Vec<LayerOut> = vec![LayerOut::default(); n];
    let mut hi = n;
    let mut cur = if n > 0 { decode_chunk(n)? } else { Vec::new() };
    while hi > 0 {
        let lo = hi.saturating_sub(CHUNK);
        // Decode the next chunk while this one runs through the recurrence.
        let (next, ()) = rayon::join(
            || {
                if lo > 0 {
                    decode_chunk(lo)
                } else {
                    Ok(Vec::new())
                }
            },
            || {
                for k in 0..cur.len() - 1 {
                    let i = hi - 1 - k;
                    let r = (manifest.layers[i].exposure_s / normal_s) as f32;
                    outs[i] = engine.layer(&cur[k], Some(&cur[k + 1]), r);
                }
                for p in cur.drain(..cur.len() - 1) {
                    kernel.recycle(p);
                }
            },
        );
        let next = next?;
        let i = lo;
        let r = (manifest.layers[i].exposure_s / normal_s) as f32;
        let last = cur.last().expect("a chunk has a layer");
        outs[i] = engine.layer(last, next.first(), r);
        for p in cur.drain(..) {
            kernel.recycle(p);
        }
        cur = next;
        hi = lo;
    }
    Ok(summarize(manifest, model, proj, outs))
}

/// The job's figures from the layers'.
fn summarize(
    manifest: &Manifest,
    model: &CureModel,
    proj: &crate::profile::Projector,
    outs: Vec<LayerOut>,
) -> CureCheck {
    let p = model.pixel_mm;
    let sample_mm2 = p * p / (SUB * SUB) as f64;
    let c = manifest.cure.as_ref();
    let held = c.map_or(0, |c| c.held_back_layers);
    // Mask pixel (column, row) in pixel units → build-plane mm.
    let field_h = manifest.machine.field().height_px as f64;
    let to_mm = |[u, v]: [f64; 2]| {
        let u = if proj.mirror_x {
            proj.width_px as f64 - u
        } else {
            u
        };
        let v = if proj.mirror_y {
            proj.height_px as f64 - v
        } else {
            v
        };
        [
            (proj.offset_px[0] as f64 + u) * p,
            (field_h - proj.offset_px[1] as f64 - v) * p,
        ]
    };
    let mut per_layer = Vec::with_capacity(outs.len());
    let mut findings = Vec::new();
    let mut agree = SlicerAgreement::default();
    let mut any_slicer = false;
    for (i, o) in outs.into_iter().enumerate() {
        let l = &manifest.layers[i];
        let cured_mm2 = o.cured_samples * sample_mm2;
        let offset_px = if o.perimeter_px > 0.0 {
            (cured_mm2 - l.area_mm2) / (p * p) / o.perimeter_px
        } else {
            0.0
        };
        for &(px, at) in &o.vanished {
            findings.push(Finding {
                layer: i,
                kind: "vanished",
                islands: 1,
                pixels: px,
                at_mm: to_mm(at),
            });
        }
        for &(k, px, at) in &o.merged {
            findings.push(Finding {
                layer: i,
                kind: "merged",
                islands: k,
                pixels: px,
                at_mm: to_mm(at),
            });
        }
        let slicer = l.cure.as_ref();
        let diff = slicer
            .filter(|_| o.perimeter_px > 0.0)
            .map(|s| offset_px - s.mean_px);
        if let Some(s) = slicer {
            any_slicer = true;
            if (s.vanished == 0) != o.vanished.is_empty() {
                agree.vanish_disagreements.push(i);
            }
        }
        if let Some(d) = diff {
            agree.layers += 1;
            if agree.max_diff_layer.is_none() || d.abs() > agree.max_diff_px {
                agree.max_diff_px = d.abs();
                agree.max_diff_layer = Some(i);
            }
        }
        per_layer.push(LayerCureCheck {
            index: i,
            section_mm2: l.area_mm2,
            cured_mm2,
            perimeter_mm: o.perimeter_px * p,
            offset_px,
            offset_mm: offset_px * p,
            islands: o.islands,
            vanished: o.vanished.len(),
            merged: o.merged.len(),
            print_through_mm: o.print_through_mm,
            slicer_mean_px: slicer.map(|s| s.mean_px),
            slicer_diff_px: diff,
        });
    }
    let checked: Vec<&LayerCureCheck> = per_layer.iter().filter(|l| l.perimeter_mm > 0.0).collect();
    let total: f64 = checked.iter().map(|l| l.perimeter_mm).sum();
    let mut edge = OffsetStats::default();
    let mut signed = 0.0;
    if total > 0.0 {
        edge.mean = checked
            .iter()
            .map(|l| l.perimeter_mm * l.offset_px.abs())
            .sum::<f64>()
            / total;
        signed = checked
            .iter()
            .map(|l| l.perimeter_mm * l.offset_px)
            .sum::<f64>()
            / total;
        let mut by: Vec<(f64, f64)> = checked
            .iter()
            .map(|l| (l.offset_px.abs(), l.perimeter_mm))
            .collect();
        by.sort_by(|a, b| a.0.total_cmp(&b.0));
        edge.max = by.last().map_or(0.0, |b| b.0);
        let mut cum = 0.0;
        edge.p95 = edge.max;
        for (a, wgt) in by {
            cum += wgt;
            if cum >= 0.95 * total {
                edge.p95 = a;
                break;
            }
        }
    }
    let mut worst: Vec<&LayerCureCheck> = checked.clone();
    worst.sort_by(|a, b| {
        b.offset_px
            .abs()
            .total_cmp(&a.offset_px.abs())
            .then(a.index.cmp(&b.index))
    });
    let print_through = per_layer
        .iter()
        .filter_map(|l| l.print_through_mm)
        .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))));
    CureCheck {
        correction: c.map_or_else(String::new, |c| c.correction.clone()),
        held_back_layers: held,
        samples_per_px: SUB,
        layers_checked: checked.len(),
        edge_offset_px: edge,
        signed_mean_px: signed,
        signed_mean_mm: signed * p,
        vanished: per_layer.iter().map(|l| l.vanished).sum(),
        merged: per_layer.iter().map(|l| l.merged).sum(),
        print_through_mm: print_through,
        z_error_mm: (held > 0)
            .then(|| print_through.map(|t| t - held as f64 * model.layer_mm))
            .flatten(),
        slicer: any_slicer.then_some(agree),
        worst_layers: worst.iter().take(WORST_LAYERS).map(|l| l.index).collect(),
        findings,
        per_layer,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::resin::psf::phi_inv;

    fn model() -> CureModel {
        CureModel {
            sigma_px: 0.5,
            pixel_mm: 0.0634765625,
            dp_mm: 0.15,
            ec_mj_cm2: 10.0,
            overcure_mm: 0.03,
            layer_mm: 0.05,
        }
    }

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
    fn run(e: &mut Engine, w: usize, h: usize, stack: &[(Vec<f32>, f32)]) -> Vec<LayerOut> {
        let k = e.kernel();
        let irr: Vec<Prepared> = stack
            .iter()
            .map(|(img, r)| k.prepare(&Irradiance::from_image(w, h, img), *r))
            .collect();
        let mut out = vec![LayerOut::default(); stack.len()];
        for i in (0..stack.len()).rev() {
            out[i] = e.layer(&irr[i], i.checked_sub(1).map(|b| &irr[b]), stack[i].1);
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
        run(&mut e, w, h, &stack);
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
            let k = e.kernel();
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
                let out = e.layer(&p, None, ratio);
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
        let out = run(&mut e, w, h, &[(img, (1.0 / (1.0 - q)) as f32)]);
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
        let out = run(&mut e, w, h, &[(img, 1.0)]);
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
        let out = run(&mut e, w, h, &stack);
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
        let out = run(&mut e, w, h, &stack);
        assert!(out[0].merged.is_empty());
    }

    /// `--cure` needs the `cure` record and one projector; each refusal names the bundle.
    #[test]
    fn jobs_without_the_record_or_with_several_projectors_are_refused() {
        use crate::bundle::DirSource;
        let src = DirSource::new(std::path::Path::new("some.dmdjob"));
        let mut man = crate::exec::testutil::two_layer_topdown();
        man.cure = None;
        let e = model_of(&man, &src).unwrap_err().to_string();
        assert!(
            e.contains("some.dmdjob") && e.contains("`cure` record"),
            "{e}"
        );
        let m = model();
        man.cure = Some(crate::bundle::Cure {
            psf_sigma_px: m.sigma_px,
            pixel_mm: m.pixel_mm,
            dp_mm: m.dp_mm,
            ec_mj_cm2: m.ec_mj_cm2,
            overcure_mm: m.overcure_mm,
            layer_mm: m.layer_mm,
            edge_threshold: m.edge_threshold(),
            correction: "xy".into(),
            shift_px: 0.49,
            print_through_mm: m.print_through_mm(None),
            held_back_layers: 0,
            predicted: None,
            dropped: None,
        });
        assert_eq!(model_of(&man, &src).unwrap(), m);
        man.machine = crate::profile::Profile::resolve("tiled-2x1").unwrap();
        let e = model_of(&man, &src).unwrap_err().to_string();
        assert!(
            e.contains("some.dmdjob") && e.contains("2 projectors"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1);
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
        let out = run(&mut e, w, h, &stack);
        let got = out[1].print_through_mm.unwrap();
        let want = m.print_through_mm(Some(199));
        assert!((got - want).abs() < 1e-4, "{got} vs {want}");
        assert!(out[2].print_through_mm.is_none());
    }
}
