//! The cure model in a job: each layer's correction and prediction (`crate::cure`), the
//! edge errors of all layers, and the manifest's record and warnings.

use crate::bundle::{
    self, CurePrediction, DroppedFeatures, EdgeError, FeatureBox, Layer, LayerCure,
};
use crate::cure::held_back::{Dropped, DroppedScan};
use crate::cure::predict::Histogram;
use crate::cure::{self, widen, Correction, CureModel};
use crate::error::{Error, Result};
use crate::optics::Compensator;
use crate::profile::Profile;
use crate::raster::{Mask, Rasterizer, Scratch};
use crate::slice::Contour;
use crate::text::plural;
use crate::warning::Warning;
use std::sync::Mutex;

/// What a job asks of the cure model.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CureOptions {
    /// Predict each layer's cure (`slice --predict`).
    pub predict: bool,
    /// The masks' correction (`--cure-correction`); `None`: `xy` when the machine has a
    /// PSF, else off.
    pub correction: Option<Correction>,
    /// Directory for the prediction's pictures (`--cure-plots`): the per-layer error chart
    /// and the worst layer's cured outline over its section.
    pub plots: Option<std::path::PathBuf>,
}

/// The cure model of one job.
pub(super) struct CureJob {
    model: CureModel,
    correction: Correction,
    shift_px: f64,
    /// Layers a downward-facing surface is held back by (`xyz`).
    held_back: usize,
    predict: bool,
    /// Absolute edge errors of every layer (sums: the same in any order).
    hist: Mutex<Histogram>,
    /// The flat features the Z correction drops, over the layers drawn so far (sums and
    /// the lowest layer's first feature: the same in any order).
    dropped: Mutex<DroppedFeatures>,
    /// The narrow features drawn wider, over the layers drawn so far (sums and the lowest
    /// layer's first feature: the same in any order).
    widened: Mutex<WidenedFeatures>,
}

/// The narrow features the XY correction drew wider, over a job's layers.
#[derive(Debug, Clone, Default)]
struct WidenedFeatures {
    features: u64,
    layers: u64,
    first_layer: Option<u64>,
    first: Option<FeatureBox>,
}

/// The narrow features of one layer the XY correction drew wider so they cure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LayerWidened {
    /// How many.
    pub features: u32,
    /// The first one's bounding box (in contour order), build-plane mm.
    pub first: FeatureBox,
}

/// What drawing a layer through the cure model gave besides its mask.
pub(super) struct CureDrawn {
    /// Lit area of the section's coverage (before the correction), pixels.
    pub lit_pixels: f64,
    /// Whether the compensation found the layer lit outside its calibrated area.
    pub outside: bool,
    /// The prediction (`--predict`).
    pub cure: Option<LayerCure>,
    /// Its absolute edge errors.
    pub hist: Histogram,
    /// The flat features the Z correction drops whose runs of lit layers end in the layer
    /// below (`(1, …)`) or, for the job's top layer, in this one (`(0, …)`); only those
    /// with pixels.
    pub dropped: Vec<(usize, LayerDropped)>,
    /// The narrow features drawn wider so they cure (`cure::widen`).
    pub widened: Option<LayerWidened>,
}

/// The dropped features of one layer (the last layer of their runs), build-plane mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LayerDropped {
    /// Dropped pixels.
    pub pixels: u64,
    /// Features (4-connected dropped pixels).
    pub features: u32,
    /// The first feature's bounding box.
    pub first: Option<FeatureBox>,
}

impl LayerDropped {
    /// `d` in build-plane mm on a field `height` rows high of `pixel_mm` pixels (`None`
    /// when nothing is dropped).
    fn of(d: Dropped, pixel_mm: f64, height: u32) -> Option<LayerDropped> {
        let r = crate::round::plane_mm;
        (d.pixels > 0).then(|| LayerDropped {
            pixels: d.pixels,
            features: d.features,
            first: d.first.map(|b| FeatureBox {
                x_mm: r(0.5 * (b.c0 + b.c1) as f64 * pixel_mm),
                y_mm: r((height as f64 - 0.5 * (b.r0 + b.r1) as f64) * pixel_mm),
                width_mm: r((b.c1 - b.c0) as f64 * pixel_mm),
                height_mm: r((b.r1 - b.r0) as f64 * pixel_mm),
            }),
        })
    }
}

impl CureJob {
    /// The cure model of a job on `profile` (already completed for the job); `None` when
    /// the machine has no PSF and nothing is asked. Asking a prediction or a correction of
    /// a machine without a PSF is an error.
    pub fn new(profile: &Profile, opts: &CureOptions) -> Result<Option<CureJob>> {
        let model = CureModel::from_profile(profile);
        let wants =
            opts.predict || matches!(opts.correction, Some(Correction::Xy | Correction::Xyz));
        let Some(model) = model else {
            if wants {
                return Err(Error::Profile {
                    origin: profile.name.clone(),
                    msg: "--predict and --cure-correction need the projector's point-spread function (psf_sigma_px in each [[projector]]; docs/CURE.md)".into(),
                });
            }
            return Ok(None);
        };
        let correction = opts.correction.unwrap_or(Correction::Xy);
        let shift_px = match correction {
            Correction::Off => 0.0,
            _ => cure::edge_shift_px(&model),
        };
        // The print-through under a flat surface with many layers above, in whole layers.
        let held_back = match correction {
            // At most a window of layers below is at hand (job::pipeline), and the
            // detection of dropped features needs one more than are held back.
            Correction::Xyz => {
                ((model.print_through_mm(None) / model.layer_mm).round() as usize).min(31)
            }
            _ => 0,
        };
        Ok(Some(CureJob {
            model,
            correction,
            shift_px,
            held_back,
            predict: opts.predict,
            hist: Mutex::new(Histogram::default()),
            dropped: Mutex::new(DroppedFeatures::default()),
            widened: Mutex::new(WidenedFeatures::default()),
        }))
    }

    /// Whether layers are drawn through [`CureJob::draw`].
    pub fn active(&self) -> bool {
        self.shift_px != 0.0 || self.predict || self.held_back > 0
    }

    /// Layers a downward-facing surface is held back by (0 unless `xyz`).
    pub fn held_back(&self) -> usize {
        self.held_back
    }

    /// Sections below a layer that [`CureJob::draw`] takes: the held-back layers and one
    /// more, for the features the Z correction drops (0 unless `xyz`).
    pub fn lower_layers(&self) -> usize {
        match self.held_back {
            0 => 0,
            m => m + 1,
        }
    }

    /// Draws `section`'s coverage, corrects it (XY; with `xyz` each pixel also takes at
    /// most the coverage of the nearest [`CureJob::held_back`] of the `lower` sections,
    /// the layers below, nearest first: a downward-facing surface is drawn only from its
    /// held-back layers on; narrow features the correction starves are then drawn back and
    /// wider, `cure::widen`), predicts its cure (`--predict`), then thresholds (`binary`)
    /// and compensates (`comp`) it in place. With `xyz` it also finds the flat features
    /// the correction drops whose runs of lit layers end in the layer below (from
    /// [`CureJob::lower_layers`] sections below) or, when `top` (the job's last layer), in
    /// this one.
    #[allow(clippy::too_many_arguments)]
    pub fn draw(
        &self,
        raster: &Rasterizer,
        section: &[Contour],
        lower: &[&[Contour]],
        top: bool,
        scratch: &mut Scratch,
        binary: bool,
        comp: Option<&Compensator>,
    ) -> (Mask, CureDrawn) {
        let mut m = raster.render::<Compensator>(section, scratch, false, None);
        let lit = scratch.lit_box();
        // The record's area is the section's, as drawn before the correction.
        let lit_pixels = scratch.lit_pixels(&m);
        let held = self.held_back;
        // The runs of lit layers ending in this layer (the top) or the one below end where
        // this layer's exact coverage is unlit: taken before the correction changes it.
        let mut ends_here = (held > 0 && top).then(|| DroppedScan::new(&m, lit, |_, _| false));
        let here: Vec<bool> = if held > 0 && !lower.is_empty() {
            let w = m.width as usize;
            lit.rows()
                .flat_map(|r| m.data[r * w..][lit.cols()].iter().map(|&v| v >= 128))
                .collect()
        } else {
            Vec::new()
        };
        let lit_here = |c: usize, r: usize| {
            lit.rows().contains(&r)
                && lit.cols().contains(&c)
                && here[(r - lit.r0) * lit.cols().len() + (c - lit.c0)]
        };
        // Small features (geometry only) and their uncorrected coverage, for the narrow
        // ones the correction would starve.
        let small = if self.shift_px != 0.0 {
            widen::small_features(&self.model, section, m.height as f64, self.shift_px)
        } else {
            Vec::new()
        };
        let mut saved =
            (!small.is_empty()).then(|| widen::Uncorrected::take(&m, &small, self.shift_px));
        if self.shift_px != 0.0 {
            cure::correct_coverage(&mut m, lit, section, self.model.pixel_mm, self.shift_px);
        }
        let mut ends_below: Option<DroppedScan> = None;
        if !lower.is_empty() {
            LOWER.with(|s| {
                let s = &mut *s.borrow_mut();
                for (j, below) in lower.iter().enumerate() {
                    let b = raster.coverage(below, s);
                    if j < held {
                        for r in lit.rows() {
                            let row = r * m.width as usize;
                            for c in lit.cols() {
                                let v = &mut m.data[row + c];
                                *v = (*v).min(b.data[row + c]);
                            }
                        }
                        if let Some(t) = ends_here.as_mut() {
                            t.below(&b);
                        }
                        if let Some(u) = saved.as_mut() {
                            u.hold_back(&b);
                        }
                    }
                    if held > 0 {
                        // lower[0] is the layer below; lower[1..=held] the layers below it.
                        match ends_below.as_mut() {
                            None => ends_below = Some(DroppedScan::new(&b, s.lit_box(), lit_here)),
                            Some(e) => e.below(&b),
                        }
                    }
                    s.recycle(b);
                }
            });
        }
        // Narrow features widened until they cure; with xyz not those the held-back layers
        // take more than half of (a held-back surface stays held back).
        let mut drawn_lit = lit;
        let widened = saved.and_then(|saved| {
            let wd = widen::widen(
                &self.model,
                &mut m,
                lit,
                section,
                &small,
                &saved,
                self.shift_px,
            );
            if wd.lit != lit {
                scratch.grow_lit_box(wd.lit);
                drawn_lit = scratch.lit_box();
            }
            Some(LayerWidened {
                features: wd.widened,
                first: wd.first?,
            })
        });
        let (p, h) = (self.model.pixel_mm, m.height);
        let dropped: Vec<(usize, LayerDropped)> = [(1, ends_below), (0, ends_here)]
            .into_iter()
            .filter_map(|(k, d)| Some((k, LayerDropped::of(d?.finish(), p, h)?)))
            .collect();
        if binary {
            crate::raster::threshold(&mut m);
        }
        let (cure, hist) = if self.predict {
            let (c, h) = cure::predict_layer(&self.model, &m, section);
            let r = crate::round::derived;
            let c = LayerCure {
                mean_px: r(c.mean_px),
                abs_mean_px: r(c.abs_mean_px),
                p95_px: r(c.p95_px),
                max_px: r(c.max_px),
                ..c
            };
            (Some(c), h)
        } else {
            (None, Histogram::default())
        };
        let outside = comp.is_some_and(|c| c.apply_in(&mut m, drawn_lit));
        (
            m,
            CureDrawn {
                lit_pixels,
                outside,
                cure,
                hist,
                dropped,
                widened,
            },
        )
    }

    /// Counts the features dropped at layer `index` ([`CureDrawn::dropped`]) into the
    /// job's.
    pub fn count_dropped(&self, index: usize, dropped: &[(usize, LayerDropped)]) {
        let mut t = self.dropped.lock().unwrap_or_else(|p| p.into_inner());
        for (k, d) in dropped {
            let layer = (index - k) as u64;
            t.features += d.features as u64;
            t.pixels += d.pixels;
            t.layers += 1;
            if t.first_layer.is_none_or(|f| layer < f) {
                t.first_layer = Some(layer);
                t.first = d.first;
            }
        }
    }

    /// Counts the narrow features drawn wider at layer `index` into the job's.
    pub fn count_widened(&self, index: usize, widened: Option<LayerWidened>) {
        let Some(w) = widened else { return };
        let mut t = self.widened.lock().unwrap_or_else(|p| p.into_inner());
        let layer = index as u64;
        t.features += w.features as u64;
        t.layers += 1;
        if t.first_layer.is_none_or(|f| layer < f) {
            t.first_layer = Some(layer);
            t.first = Some(w.first);
        }
    }

    /// The warning naming the narrow features drawn wider so they cure, if any.
    pub fn widened_warning(&self) -> Option<Warning> {
        let t = self.widened.lock().unwrap_or_else(|p| p.into_inner());
        let (first, at) = (t.first_layer?, t.first?);
        let (k, n) = (t.features, t.layers);
        Some(
            Warning::new(
                "cure.features-widened",
                format!(
                    "cure: {k} {} too thin to cure {} drawn wider so {} cure, in {n} {} (first: layer {first}, at {}); {} cured size is the smallest the machine makes, larger than the part's",
                    plural(k, "feature", "features"),
                    plural(k, "was", "were"),
                    plural(k, "it", "they"),
                    plural(n, "layer", "layers"),
                    where_is(&at),
                    plural(k, "its", "their"),
                ),
            )
            .with("features", k)
            .with("layers", n)
            .with("first_layer", first)
            .with("x_mm", at.x_mm)
            .with("y_mm", at.y_mm)
            .with("width_mm", at.width_mm)
            .with("height_mm", at.height_mm),
        )
    }

    /// The warning naming the flat features the Z correction drops, if any.
    pub fn dropped_warning(&self) -> Option<Warning> {
        let t = self.dropped.lock().unwrap_or_else(|p| p.into_inner());
        let (first, at) = (t.first_layer?, t.first?);
        let (k, n, m) = (t.features, t.layers, self.held_back as u64);
        let thick = crate::round::plane_mm((m + 1) as f64 * self.model.layer_mm);
        Some(
            Warning::new(
                "cure.features-dropped",
                format!(
                    "cure: the xyz correction leaves out {k} flat {} over nothing thinner than {} layers ({} {} in {n} {}; first: layer {first}, at {}); use --cure-correction xy, or make {} at least {} layers ({thick} mm) thick",
                    plural(k, "feature", "features"),
                    m + 1,
                    t.pixels,
                    plural(t.pixels, "pixel", "pixels"),
                    plural(n, "layer", "layers"),
                    where_is(&at),
                    plural(k, "it", "them"),
                    m + 1,
                ),
            )
            .with("features", k)
            .with("pixels", t.pixels)
            .with("layers", n)
            .with("first_layer", first)
            .with("x_mm", at.x_mm)
            .with("y_mm", at.y_mm)
            .with("width_mm", at.width_mm)
            .with("height_mm", at.height_mm)
            .with("held_back_layers", m),
        )
    }

    /// Writes the prediction's pictures into `dir`: `<stem>-cure-errors.png` (per-layer
    /// chart) and `<stem>-cure-layer-<N>.png`, layer N (the worst by mean absolute error)
    /// drawn again (without the distortion pre-warp) with its predicted cured outline.
    /// Returns the files written.
    pub fn write_plots(
        &self,
        dir: &std::path::Path,
        stem: &str,
        manifest: &bundle::Manifest,
        mesh: &crate::mesh::Mesh,
        raster: &Rasterizer,
    ) -> Result<Vec<std::path::PathBuf>> {
        use crate::plot::Format;
        let mut out = Vec::new();
        let chart = cure::plots::error_chart(stem, &manifest.layers).render();
        let p = dir.join(format!("{stem}-cure-errors.png"));
        crate::output::write_atomic(&p, &chart.encode(Format::Png))?;
        out.push(p);
        let worst = manifest
            .cure
            .as_ref()
            .and_then(|c| c.predicted.as_ref())
            .and_then(|p| p.worst_layers.first().copied());
        if let Some(i) = worst.map(|i| i as usize) {
            let n = manifest.layers.len();
            let section = crate::slice::Slicer::new(mesh, self.model.layer_mm, n)
                .window(i..i + 1)
                .pop()
                .unwrap_or_default();
            let mut scratch = Scratch::default();
            let window = crate::slice::Slicer::new(mesh, self.model.layer_mm, n)
                .window(i.saturating_sub(self.lower_layers())..i);
            let lower: Vec<&[Contour]> = window.iter().rev().map(|s| &s.contours[..]).collect();
            let (mask, _) = self.draw(
                raster,
                &section.contours,
                &lower,
                false,
                &mut scratch,
                false,
                None,
            );
            let samples = cure::predict::edge_samples(&self.model, &mask, &section.contours);
            let pic =
                cure::plots::outline_picture(&self.model, i, &mask, &section.contours, &samples);
            let p = dir.join(format!("{stem}-cure-layer-{i:05}.png"));
            crate::output::write_atomic(&p, &pic.encode(Format::Png))?;
            out.push(p);
        }
        Ok(out)
    }

    /// Counts a layer's edge errors into the job's.
    pub fn count(&self, hist: &Histogram) {
        self.hist
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .merge(hist);
    }

    /// The manifest's record, from the layers' predictions.
    pub fn record(&self, layers: &[Layer]) -> bundle::Cure {
        let m = &self.model;
        let r = crate::round::derived;
        let predicted = self.predict.then(|| {
            let hist = self.hist.lock().unwrap_or_else(|p| p.into_inner());
            let cures: Vec<(u64, &LayerCure)> = layers
                .iter()
                .filter_map(|l| l.cure.as_ref().map(|c| (l.index, c)))
                .collect();
            let n: u64 = cures.iter().map(|(_, c)| c.samples).sum();
            let w = |f: fn(&LayerCure) -> f64| {
                if n == 0 {
                    0.0
                } else {
                    cures
                        .iter()
                        .map(|(_, c)| f(c) * c.samples as f64)
                        .sum::<f64>()
                        / n as f64
                }
            };
            let px = EdgeError {
                mean: r(w(|c| c.abs_mean_px)),
                p95: r(hist.quantile(0.95)),
                max: r(cures.iter().map(|(_, c)| c.max_px).fold(0.0, f64::max)),
            };
            let mm = EdgeError {
                mean: r(px.mean * m.pixel_mm),
                p95: r(px.p95 * m.pixel_mm),
                max: r(px.max * m.pixel_mm),
            };
            let mut worst: Vec<(u64, f64)> = cures
                .iter()
                .filter(|(_, c)| c.samples > 0)
                .map(|(i, c)| (*i, c.abs_mean_px))
                .collect();
            worst.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            CurePrediction {
                samples: n,
                edge_error_px: px,
                edge_error_mm: mm,
                signed_mean_px: r(w(|c| c.mean_px)),
                vanished: cures.iter().map(|(_, c)| c.vanished as u64).sum(),
                merged: cures.iter().map(|(_, c)| c.merged as u64).sum(),
                worst_layers: worst.iter().take(5).map(|w| w.0).collect(),
            }
        });
        bundle::Cure {
            psf_sigma_px: m.sigma_px,
            pixel_mm: m.pixel_mm,
            dp_mm: m.dp_mm,
            ec_mj_cm2: m.ec_mj_cm2,
            overcure_mm: m.overcure_mm,
            layer_mm: m.layer_mm,
            edge_threshold: r(m.edge_threshold()),
            correction: self.correction.as_str().into(),
            shift_px: r(self.shift_px),
            print_through_mm: crate::round::plane_mm(m.print_through_mm(None)),
            held_back_layers: self.held_back as u32,
            predicted,
            dropped: (self.held_back > 0).then(|| {
                self.dropped
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .clone()
            }),
        }
    }
}

/// "x 12.3 mm, y 4.5 mm, 0.1 × 0.2 mm": a feature's centre and size.
fn where_is(b: &FeatureBox) -> String {
    format!(
        "x {} mm, y {} mm, {} × {} mm",
        b.x_mm, b.y_mm, b.width_mm, b.height_mm
    )
}

thread_local! {
    /// Scratch of the layers below's coverage (`xyz`), one per worker thread.
    static LOWER: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// The warnings of the layers' predictions: features that vanish, gaps that close.
pub(super) fn warnings(layers: &[Layer]) -> Vec<Warning> {
    let mut out = Vec::new();
    let count = |f: fn(&LayerCure) -> u32| {
        let hit: Vec<(u64, u32)> = layers
            .iter()
            .filter_map(|l| l.cure.as_ref().map(|c| (l.index, f(c))))
            .filter(|(_, k)| *k > 0)
            .collect();
        let total: u64 = hit.iter().map(|h| h.1 as u64).sum();
        (total, hit.len() as u64, hit.first().map(|h| h.0))
    };
    if let (k, n, Some(first)) = count(|c| c.vanished) {
        let at = layers
            .iter()
            .find(|l| l.index == first)
            .and_then(|l| l.cure.as_ref()?.vanished_at);
        let mut w = Warning::new(
            "cure.features-vanish",
            format!(
                "cure: {k} {} cure nowhere in {n} {} (first: layer {first}{}); widen them or raise the exposure",
                plural(k, "feature", "features"),
                plural(n, "layer", "layers"),
                at.map_or(String::new(), |a| format!(", at {}", where_is(&a))),
            ),
        )
        .with("features", k)
        .with("layers", n)
        .with("first_layer", first);
        if let Some(a) = at {
            w = w
                .with("x_mm", a.x_mm)
                .with("y_mm", a.y_mm)
                .with("width_mm", a.width_mm)
                .with("height_mm", a.height_mm);
        }
        out.push(w);
    }
    if let (k, n, Some(first)) = count(|c| c.merged) {
        out.push(
            Warning::new(
                "cure.features-merge",
                format!(
                    "cure: {k} {} cure across a gap in {n} {} (first: layer {first}): neighbouring features join",
                    plural(k, "contour", "contours"),
                    plural(n, "layer", "layers")
                ),
            )
            .with("contours", k)
            .with("layers", n)
            .with("first_layer", first),
        );
    }
    out
}
