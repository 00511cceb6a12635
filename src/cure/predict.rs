//! Where a layer's cured edge lies, compared with its exact section.
//!
//! The light at a point is the sum over pixels of their relative irradiance × the pixel's
//! box convolved with the PSF ([`Psf::axis_weight`] per axis), over the pixels within the
//! PSF's reach ([`light`]); for a layer's cure the pixels hold the light of the layer and
//! of every layer above it, each weighted by its dose and its depth
//! ([`super::Engine::irradiance`]). Along the section's outward normal at sample
//! points spaced at most [`SPACING_PX`] apart on every edge, the cured edge is where that
//! light crosses the mid-plane's threshold (as far as the layer's own light reaches: as
//! for the cured area of [`super::check`], resin cured farther out by the layers above
//! alone is their print-through); its signed distance from the section's edge (positive:
//! the part grows) is the sample's edge error ([`edge_samples`]).

use super::segments::Segments;
pub use crate::bundle::{FeatureBox, LayerCure};
use crate::cure::model::CureModel;
use crate::cure::psf::{AxisTable, Psf};
use crate::slice::Contour;

/// Largest spacing of edge samples, pixels.
pub const SPACING_PX: f64 = 1.0;
/// Bins of the error histogram per pixel.
const BINS_PER_PX: f64 = 100.0;
/// Bins of the error histogram (errors beyond the last bin count in it).
pub const BINS: usize = 1000;
/// A vertex where the contour turns by more than this (degrees) is a corner: samples
/// within 2σ + 1 px of it are not counted in the edge statistics (a blurred corner rounds;
/// the normal there is not defined).
pub const CORNER_DEG: f64 = 30.0;

/// One edge sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeSample {
    /// Point on the section's edge, field pixels.
    pub at: [f64; 2],
    /// Outward unit normal.
    pub normal: [f64; 2],
    /// Signed distance from the section's edge to the cured edge along the normal, px
    /// (`None` when the feature vanishes or merges here).
    pub error_px: Option<f64>,
    /// Width of the material behind the sample and of the gap before it, px (∞ beyond
    /// the search).
    pub widths_px: [f64; 2],
    /// Within 2σ + 1 px of a corner.
    pub near_corner: bool,
    /// Nothing cures from here to the middle of the feature.
    pub vanishes: bool,
    /// Cure reaches across the middle of the gap before it.
    pub merges: bool,
    /// The sample's contour.
    pub contour: u32,
}

impl EdgeSample {
    /// Whether the sample counts in the edge statistics: a defined error on a feature and
    /// a gap at least 4σ wide, away from corners.
    pub fn counted(&self, sigma_px: f64) -> bool {
        self.error_px.is_some()
            && !self.near_corner
            && self.widths_px[0] >= 4.0 * sigma_px
            && self.widths_px[1] >= 4.0 * sigma_px
    }
}

/// Absolute edge errors in bins of 0.01 px (sums of histograms merge layers exactly, in
/// any order).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Histogram(pub Vec<u64>);

impl Default for Histogram {
    fn default() -> Self {
        Histogram(vec![0; BINS])
    }
}

impl Histogram {
    /// Counts an absolute error.
    pub fn add(&mut self, abs_px: f64) {
        let b = ((abs_px * BINS_PER_PX) as usize).min(BINS - 1);
        self.0[b] += 1;
    }
    /// Adds another histogram.
    pub fn merge(&mut self, o: &Histogram) {
        for (a, b) in self.0.iter_mut().zip(&o.0) {
            *a += b;
        }
    }
    /// The `q` quantile (upper edge of its bin), px; 0 when empty.
    pub fn quantile(&self, q: f64) -> f64 {
        let n: u64 = self.0.iter().sum();
        if n == 0 {
            return 0.0;
        }
        let want = (q * n as f64).ceil().max(1.0) as u64;
        let mut acc = 0;
        for (i, &c) in self.0.iter().enumerate() {
            acc += c;
            if acc >= want {
                return (i + 1) as f64 / BINS_PER_PX;
            }
        }
        BINS as f64 / BINS_PER_PX
    }
}

/// The light at pixel coordinates `p` of an image `w` wide (`px.len() / w` rows) whose
/// pixels hold `T` (relative irradiance × a factor: 255 for a mask), the pixels within
/// the PSF's reach summed through the tabulated axis weights of `table`.
pub fn light<T: Copy + Into<f32>>(
    px: &[T],
    w: usize,
    psf: &Psf,
    table: &AxisTable,
    p: [f64; 2],
) -> f64 {
    let reach = psf.reach_px();
    let (w, h) = (w as i64, (px.len() / w) as i64);
    // ⌊x⌋ without libm's `floor`.
    let floor = |x: f64| {
        let t = x as i64;
        t - ((t as f64) > x) as i64
    };
    let c0 = floor(p[0] - reach - 1.0).max(0);
    let c1 = floor(p[0] + reach).min(w - 1);
    let r0 = floor(p[1] - reach - 1.0).max(0);
    let r1 = floor(p[1] + reach).min(h - 1);
    if c0 > c1 || r0 > r1 {
        return 0.0;
    }
    let mut wx = [0.0f64; 64];
    let nc = ((c1 - c0 + 1) as usize).min(64);
    for (k, x) in wx.iter_mut().take(nc).enumerate() {
        *x = table.weight(p[0] - (c0 + k as i64) as f64);
    }
    let mut sum = 0.0;
    for r in r0..=r1 {
        let row = &px[(r as usize) * w as usize + c0 as usize..][..nc];
        if row.iter().all(|&v| v.into() == 0.0) {
            continue;
        }
        let acc: f64 = row
            .iter()
            .zip(&wx)
            .map(|(&v, &x)| v.into() as f64 * x)
            .sum();
        sum += acc * table.weight(p[1] - r as f64);
    }
    sum
}

/// The edge samples of a layer whose section is `contours` (build-plane mm, on a field
/// `height_px` rows high) where the resin at a point of the layer's mid-plane cures where
/// both of `margin`'s values are at least 0: the light less the threshold, and the layer's
/// own light less the least that makes it the layer's edge. A feature whose inside the
/// layer does not light (held back) does not vanish: it is not drawn. With them, per
/// contour whether it runs backwards ([`Segments::union_pieces`]; empty: none does).
pub fn edge_samples(
    model: &CureModel,
    margin: &dyn Fn([f64; 2]) -> [f64; 2],
    height_px: f64,
    contours: &[Contour],
) -> (Vec<EdgeSample>, Vec<bool>) {
    let psf = Psf {
        sigma_px: model.sigma_px,
    };
    // Where shells cross, touch or nest (supports in the part), the edges inside their
    // union bound nothing that cures: only the union's outline is sampled.
    let (segs, backwards) = match super::segments::contours_may_meet(contours) {
        true => Segments::edges(contours, model.pixel_mm, height_px).union_outline(),
        false => (
            Segments::new(contours, model.pixel_mm, height_px),
            Vec::new(),
        ),
    };
    // Far enough for the cured edge of any sensible model (the light falls from 1 to 0
    // within a pixel and the PSF's reach on either side).
    let search = psf.reach_px() + 2.0;
    let guard = 2.0 * model.sigma_px + 1.0;
    let cos_corner = CORNER_DEG.to_radians().cos();
    let mut out = Vec::new();
    for c in 0..segs.starts.len() - 1 {
        let range = segs.starts[c]..segs.starts[c + 1];
        let n = range.len();
        if n == 0 {
            continue;
        }
        // Arc length at each vertex and the corners' positions along the contour.
        let ss = &segs.segs[range.clone()];
        let mut arc = Vec::with_capacity(n + 1);
        let mut total = 0.0;
        for s in ss {
            arc.push(total);
            total += (s.b[0] - s.a[0]).hypot(s.b[1] - s.a[1]);
        }
        arc.push(total);
        // A corner: the edges turn, or (on a union's outline) the outline leaves the
        // contour for another's between them.
        let corners: Vec<f64> = (0..n)
            .filter(|&i| {
                let (p, q) = (&ss[(i + n - 1) % n], &ss[i]);
                p.n[0] * q.n[0] + p.n[1] * q.n[1] < cos_corner || p.b != q.a
            })
            .map(|i| arc[i])
            .collect();
        let near_corner = |s: f64| {
            corners.iter().any(|&c| {
                let d = (s - c).abs();
                d.min(total - d) < guard
            })
        };
        // Samples at equal steps of at most SPACING_PX along the contour.
        let k = (total / SPACING_PX).ceil().max(1.0) as usize;
        let mut i = 0;
        for j in 0..k {
            let at_arc = (j as f64 + 0.5) / k as f64 * total;
            while i + 1 < n && arc[i + 1] <= at_arc {
                i += 1;
            }
            let sg = &ss[i];
            let len = arc[i + 1] - arc[i];
            let f = if len > 0.0 {
                ((at_arc - arc[i]) / len).clamp(0.0, 1.0)
            } else {
                0.5
            };
            let p = [
                sg.a[0] + f * (sg.b[0] - sg.a[0]),
                sg.a[1] + f * (sg.b[1] - sg.a[1]),
            ];
            let nrm = sg.n;
            let idx = range.start + i;
            let w_in = segs
                .ray(p, [-nrm[0], -nrm[1]], 2.0 * search, idx)
                .unwrap_or(f64::INFINITY);
            let w_out = segs.ray(p, nrm, 2.0 * search, idx).unwrap_or(f64::INFINITY);
            let a = (0.5 * w_in).min(search);
            let b = (0.5 * w_out).min(search);
            let both = |s: f64| margin([p[0] + s * nrm[0], p[1] + s * nrm[1]]);
            let at = |s: f64| {
                let [l, own] = both(s);
                l.min(own)
            };
            let inside = both(-a);
            let (fa, fb) = (inside[0].min(inside[1]), at(b));
            let vanishes = fa < 0.0 && inside[1] >= 0.0;
            let merges = fb >= 0.0;
            let error_px = (fa >= 0.0 && !merges).then(|| root(&at, -a, b, fa, fb));
            out.push(EdgeSample {
                at: p,
                normal: nrm,
                error_px,
                widths_px: [w_in, w_out],
                near_corner: near_corner(at_arc),
                vanishes,
                merges,
                contour: c as u32,
            });
        }
    }
    (out, backwards)
}

/// The root of `f` in `[a, b]` with `f(a) = fa ≥ 0 > f(b) = fb` (Illinois regula falsi,
/// to 10⁻⁴ px).
fn root(f: &impl Fn(f64) -> f64, mut a: f64, mut b: f64, mut fa: f64, mut fb: f64) -> f64 {
    let mut side = 0;
    for _ in 0..60 {
        let c = (a * fb - b * fa) / (fb - fa);
        let fc = f(c);
        if (b - a).abs() < 1e-4 || fc == 0.0 {
            return c;
        }
        if fc >= 0.0 {
            a = c;
            fa = fc;
            if side == 1 {
                fb *= 0.5;
            }
            side = 1;
        } else {
            b = c;
            fb = fc;
            if side == -1 {
                fa *= 0.5;
            }
            side = -1;
        }
    }
    0.5 * (a + b)
}

/// The layer's figures from its samples of the section `contours` (flagged when they run
/// backwards, as [`edge_samples`] gives them), with the first vanished feature's bounding
/// box.
pub fn summarize(
    model: &CureModel,
    samples: &[EdgeSample],
    (contours, backwards): (&[Contour], &[bool]),
) -> (LayerCure, Histogram) {
    // Outlines run counter-clockwise, but those of a shell that runs backwards.
    let outer: Vec<bool> = (contours.iter().enumerate())
        .map(|(k, c)| (crate::slice::signed_area(c) > 0.0) != (backwards.get(k) == Some(&true)))
        .collect();
    let mut hist = Histogram::default();
    let (mut n, mut sum, mut abs, mut max) = (0u64, 0.0, 0.0, 0.0f64);
    for s in samples.iter().filter(|s| s.counted(model.sigma_px)) {
        let e = s.error_px.unwrap_or(0.0);
        n += 1;
        sum += e;
        abs += e.abs();
        max = max.max(e.abs());
        hist.add(e.abs());
    }
    let vanished = vanished_contours(samples, &outer);
    let mut merged = vec![false; outer.len()];
    for s in samples {
        merged[s.contour as usize] |= s.merges;
    }
    let cure = LayerCure {
        samples: n,
        mean_px: if n > 0 { sum / n as f64 } else { 0.0 },
        abs_mean_px: if n > 0 { abs / n as f64 } else { 0.0 },
        p95_px: hist.quantile(0.95),
        max_px: max,
        vanished: vanished.len() as u32,
        merged: merged.iter().filter(|&&m| m).count() as u32,
        vanished_at: vanished.first().map(|&c| contour_box(&contours[c])),
        offset_px: None,
    };
    (cure, hist)
}

/// The vanished features among the contours (`outer[c]`: contour c is an outer
/// boundary): outer contours with samples, every one of which vanishes; in contour order.
pub fn vanished_contours(samples: &[EdgeSample], outer: &[bool]) -> Vec<usize> {
    let mut all_vanish = vec![true; outer.len()];
    let mut any = vec![false; outer.len()];
    for s in samples {
        let c = s.contour as usize;
        any[c] = true;
        all_vanish[c] &= s.vanishes;
    }
    (0..outer.len())
        .filter(|&c| outer[c] && any[c] && all_vanish[c])
        .collect()
}

/// The bounding box of a contour (build-plane mm), its centre and size rounded to 1 µm.
pub fn contour_box(contour: &Contour) -> FeatureBox {
    let [x0, y0, x1, y1] = crate::slice::bounds([contour]);
    let (lo, hi) = ([x0, y0], [x1, y1]);
    let r = crate::round::plane_mm;
    FeatureBox {
        x_mm: r(0.5 * (lo[0] + hi[0])),
        y_mm: r(0.5 * (lo[1] + hi[1])),
        width_mm: r(hi[0] - lo[0]),
        height_mm: r(hi[1] - lo[1]),
    }
}
