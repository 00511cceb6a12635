//! One layer's work in a block: its masks (drawn, or written again from an equal layer's,
//! see [`mask_reuse`](super::mask_reuse)), their files, and the layer's analysis.

use super::again::LayerCounts;
use super::clock::ThreadClock;
use super::cure_records::LayerCorrection;
use super::mask_reuse::{DrawnMasks, PreviousLayerMasks, RecentPrismMasks};
use super::pipeline::Cut;
use super::sink::Sink;
use crate::bundle::regions::{field_runs, lit_runs, Placement, Run};
use crate::bundle::{self, MaskPixels, MaskRef};
use crate::cure::shift::Coverage;
use crate::error::Result;
use crate::geometry::distortion::{self, Correction};
use crate::geometry::tile::Tiler;
use crate::optics::JobOptics;
use crate::plan::analysis::{Analysed, Analyser, LitRuns};
use crate::profile::{Profile, Projector};
use crate::raster::{projector_view_in, Mask, PixelBox, Rasterizer, Scratch};
use crate::slice::{Contour, Section};
use std::borrow::Cow;
use std::path::Path;
use std::sync::Arc;

/// What every layer of a job is made with.
pub(super) struct LayerContext<'a> {
    /// Where the mask files go.
    pub writer: &'a Sink,
    /// The machine (its projectors).
    pub profile: &'a Profile,
    /// The field's rasterizer.
    pub raster: &'a Rasterizer,
    /// Light compensation of the single projector, if any.
    pub optics: Option<&'a JobOptics>,
    /// Blending and compensation of several projectors, if tiled.
    pub tiler: Option<&'a Tiler>,
    /// Lens distortion pre-warp, if any.
    pub correction: Option<&'a Correction>,
    /// The model file (named by pre-warp errors).
    pub model: &'a Path,
    /// Masks of recent prism layers, shared by the workers (`None` where they cannot be
    /// reused: see [`RecentPrismMasks`]).
    pub recent: Option<&'a RecentPrismMasks>,
    /// Binary masks (coverage thresholded).
    pub binary: bool,
    /// Area of one field pixel, mm².
    pub px_area_mm2: f64,
    /// The cure model's correction and prediction, if the machine has a PSF.
    pub cure: Option<&'a super::cure_records::CureJob>,
    /// Where the field's coverage masks go for the cure prediction of a job of several
    /// projectors (`--predict`; their masks do not show the field's light).
    pub field: Option<&'a Sink>,
    /// Pixel values the drawn masks are scaled to (255 = as drawn): the doses of a test job.
    pub dose: Option<&'a Mask>,
    /// The pass before, whose blocks drawn alike are taken as it made them.
    pub again: Option<&'a super::again::Again>,
}

impl LayerContext<'_> {
    /// The bundle path of projector `k`'s mask of layer `i`.
    fn mask_file(&self, k: usize, i: usize) -> String {
        if self.tiler.is_some() {
            format!("masks/p{k}/{i:05}.png")
        } else {
            format!("masks/{i:05}.png")
        }
    }
}

/// One layer handed to a block's worker.
pub(super) struct LayerInput<'a> {
    /// The layer's index.
    pub index: usize,
    /// Its section.
    pub section: &'a Section,
    /// Its section and coverage as the layers below look at them.
    pub cut: &'a Cut,
    /// The section of the layer below (None for layer 0), for analyses that compare layers.
    pub below: Option<&'a Section>,
    /// The sections of the layers below, nearest first, as many as the pipeline holds
    /// when the cure correction is on (the narrow features' rest, `super::beneath`, and
    /// with `--cure-correction xyz` the held-back layers and one more,
    /// `CureJob::lower_layers`); else empty.
    pub lower: Vec<&'a Section>,
    /// The sections of the layers above, nearest first, that the cure correction looks at
    /// (`CureJob::upper_layers`; else empty).
    pub upper: Vec<&'a Cut>,
    /// Layers above it up to the job's top.
    pub above: usize,
}

/// What a worker made of one layer.
#[derive(Clone)]
pub(super) struct LayerOutput {
    /// Lit area, mm².
    pub area_mm2: f64,
    /// The lit area its supports add to the part's, mm².
    pub support_area_mm2: f64,
    /// The layer's analysis, possibly left for the layer below to complete.
    pub analysis: Analysed,
    /// CPU time of the analysis, s.
    pub analysis_s: f64,
    /// The mask files written.
    pub masks: Vec<MaskRef>,
    /// Its masks' lit runs on the field ([`DrawnMasks::field_runs`]; with supports).
    pub field_runs: Option<Arc<[Run]>>,
    /// The layer's lit pixels, kept where another block needs them: for its own islands
    /// ([`Analysed::NeedsBelow`]) or those of the next layer (the last layer of a block).
    pub runs: Option<LitRuns>,
    /// What drawing it counted into the job's totals.
    pub counts: LayerCounts,
}

/// What a block's worker carries from one layer to the next.
#[derive(Default)]
pub(super) struct BlockWorker {
    /// The analysis of consecutive layers.
    pub analyser: Analyser,
    /// The masks of the previous layer.
    previous: Option<PreviousLayerMasks>,
    /// The previous layer's corrected coverage (`crate::cure::loose`), with its index.
    corrected: Option<(usize, crate::cure::loose::Drawn)>,
}

/// A layer's section as it is drawn: without collinear points when it equals the layer
/// below's, pre-warped, and its cure correction.
struct Drawing {
    /// The section (before the pre-warp).
    section: Vec<Contour>,
    /// The pre-warped section and its area's scale, with a distortion correction.
    warped: Option<(Vec<Contour>, f64)>,
    /// The pre-warp's points outside the area its table measured (counted as it warped).
    extrapolated: u64,
    /// The section's coverage (drawn ahead of the masks for the XY correction) and its
    /// lit box.
    coverage: Option<(Mask, PixelBox)>,
    /// The XY correction.
    corr: Option<LayerCorrection>,
}

impl Drawing {
    /// The section the masks are drawn from.
    fn drawn(&self) -> &[Contour] {
        self.warped.as_ref().map_or(&self.section, |w| &w.0)
    }

    /// What equal masks must also share: the correction's moves.
    fn shifts(&self) -> &[f64] {
        self.corr.as_ref().map_or(&[], |c| &c.shifts.values)
    }
}

/// Where a layer's masks came from.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Origin {
    /// Drawn for this layer: its lit pixels are the scratch's.
    Drawn,
    /// This worker's previous layer's: the analyser keeps their lit pixels.
    PreviousLayer,
    /// Another worker's, from [`RecentPrismMasks`]: their lit pixels are kept with them.
    Recent,
}

/// Makes layer `layer`'s masks, writes their files and analyses the layer.
pub(super) fn layer_masks(
    ctx: &LayerContext,
    worker: &mut BlockWorker,
    scratch: &mut Scratch,
    layer: &LayerInput,
) -> Result<LayerOutput> {
    let i = layer.index;
    let below = layer.below.map(|b| b.contours.as_slice());
    let clock = ThreadClock::start();
    // The rasterizer keeps each mask's lit pixels for the islands.
    scratch.record_runs = !cfg!(feature = "bench-no-analysis");
    let same = worker
        .analyser
        .equals_below(i, &layer.section.contours, below);
    let mut analysis_s = clock.elapsed_s();
    // Held back surfaces depend on the layers below, and a layer drawn plain in part or
    // whole is drawn unlike its section's other layers: equal sections may not share masks.
    let reuse = shares_masks(ctx, i);
    let mut drawing = drawing(ctx, worker, scratch, layer, same)?;
    let (drawn, origin) = match reusable(ctx, worker, i, same && reuse, &drawing) {
        Some(reused) => {
            if let Some((m, _)) = drawing.coverage.take() {
                scratch.recycle(m);
            }
            // The masks of the layer below shown again: so is its coverage.
            match (&mut worker.corrected, reused.1) {
                (Some((k, _)), Origin::PreviousLayer) if *k + 1 == i => *k = i,
                (c, _) => *c = None,
            }
            reused
        }
        None => {
            let below = worker.corrected.take().filter(|(k, _)| k + 1 == i);
            let below = below.as_ref().map(|b| &b.1);
            let (m, corrected) = draw(ctx, scratch, layer, &mut drawing, same, below)?;
            worker.corrected = corrected.map(|c| (i, c));
            (m, Origin::Drawn)
        }
    };
    let counts = LayerCounts::of(&drawn, drawing.extrapolated);
    counts.count(ctx, i, origin == Origin::Drawn);
    let masks = write_masks(ctx, &drawn, i)?;
    let area_mm2 = drawn.area_mm2;
    let field_runs = drawn.field_runs.clone();
    worker.previous = Some(PreviousLayerMasks {
        index: i,
        simplified: same && reuse,
        masks: drawn,
    });
    let clock = ThreadClock::start();
    let lit = match origin {
        Origin::Drawn => Some(&scratch.lit_runs),
        Origin::PreviousLayer => None,
        Origin::Recent => worker.previous.as_ref().map(|m| &m.masks.runs),
    };
    let analysis = worker
        .analyser
        .analyse_or_defer(i, &layer.section.contours, lit, below);
    let runs = matches!(analysis, Analysed::NeedsBelow(_)).then(|| scratch.lit_runs.clone());
    analysis_s += clock.elapsed_s();
    Ok(LayerOutput {
        area_mm2,
        support_area_mm2: layer
            .section
            .part_area_mm2
            .map_or(0.0, |part| (area_mm2 - part).max(0.0)),
        analysis,
        analysis_s,
        masks,
        runs,
        field_runs,
        counts,
    })
}

/// Whether layer `i` may share its masks with a layer of the same section
/// ([`super::cure_records::CureJob::shares_masks_at`]).
fn shares_masks(ctx: &LayerContext, i: usize) -> bool {
    ctx.cure.is_none_or(|c| c.shares_masks_at(i))
}

/// Masks drawn already for layer `i`'s section, when it equals (`same`) the layer below's
/// and is corrected alike: this worker's for the layer below, or any worker's for a
/// recent equal section.
fn reusable(
    ctx: &LayerContext,
    worker: &mut BlockWorker,
    i: usize,
    same: bool,
    drawing: &Drawing,
) -> Option<(Arc<DrawnMasks>, Origin)> {
    let shifts = drawing.shifts();
    if let Some(m) = worker
        .previous
        .take()
        .and_then(|p| p.serving(i, same, shifts))
    {
        return Some((m, Origin::PreviousLayer));
    }
    let recent = ctx.recent.filter(|_| same)?;
    let m = recent.get(&drawing.section, shifts)?;
    Some((m, Origin::Recent))
}

/// Layer `layer`'s section as it is drawn: without collinear points when it equals the
/// layer below's (`same`), else its own; pre-warped; and its cure correction, which looks
/// at the layers above (their edges kept in `worker` for the block's next layers).
fn drawing(
    ctx: &LayerContext,
    worker: &BlockWorker,
    scratch: &mut Scratch,
    layer: &LayerInput,
    same: bool,
) -> Result<Drawing> {
    let i = layer.index;
    let section = if same {
        worker.analyser.simplified_section().to_vec()
    } else {
        layer.section.contours.clone()
    };
    // Distortion pre-warp (geometry::distortion): rasterize where the projector must aim.
    let (warped, extrapolated) = match ctx.correction {
        Some(w) => {
            let (c, n) = w.warp_layer(&section, ctx.model, i)?;
            let s = distortion::area_scale(&section, &c);
            (Some((c, s)), n)
        }
        None => (None, 0),
    };
    let Some(job) = ctx.cure.filter(|c| c.corrects_at(i)) else {
        return Ok(Drawing {
            section,
            warped,
            extrapolated,
            coverage: None,
            corr: None,
        });
    };
    // The layers above's coverage (each drawn once, by whoever needs it first).
    let upper = layer
        .upper
        .iter()
        .enumerate()
        .map(|(d, c)| {
            c.coverage(|| {
                let s = match ctx.correction {
                    Some(w) => Some(w.warp_section(&c.section.contours, ctx.model, i + 1 + d)?),
                    None => None,
                };
                let contours = s.as_deref().unwrap_or(&c.section.contours);
                let coverage = Coverage::draw(ctx.raster, contours, scratch);
                Ok((coverage, scratch.drawn()))
            })
        })
        .collect::<Result<Vec<_>>>()?;
    // The section as cut (not one without its collinear points) is drawn as a layer below
    // drew it for its look-ahead, if one did; else here, and its coverage is offered to
    // them. The layer's mask is painted from it.
    let drawn = warped.as_ref().map_or(&section, |w| &w.0);
    let own = match layer.cut.take_own().filter(|_| !same) {
        Some(mine) => mine,
        None => Arc::new((Coverage::draw(ctx.raster, drawn, scratch), scratch.drawn())),
    };
    let m = match ctx.raster.redraw(scratch, &own.1, |m| own.0.paint(m)) {
        Some(m) => m,
        None => ctx
            .raster
            .render::<crate::optics::Compensator>(drawn, scratch, false, None),
    };
    let lit = scratch.lit_box();
    if !same {
        layer.cut.offer(&own);
    }
    let refs: Vec<&Coverage> = upper.iter().map(|c| &c.0).collect();
    let supported = layer.section.part_area_mm2.is_some();
    let corr = job.correction_of((i, layer.above), (drawn, supported), &own.0, &refs);
    for c in &layer.upper {
        c.release();
    }
    Ok(Drawing {
        section,
        warped,
        extrapolated,
        coverage: Some((m, lit)),
        corr,
    })
}

/// Draws layer `layer`'s masks from `drawing`; when the layer equals the layer below's
/// (`same`) they are offered to the recent prism masks. `below`: the layer below as
/// drawn by this worker (its corrected coverage), against which the job's pieces that
/// would cure loose are found (`crate::cure::loose`); returned with the masks: this layer
/// as drawn, for the next.
fn draw(
    ctx: &LayerContext,
    scratch: &mut Scratch,
    layer: &LayerInput,
    drawing: &mut Drawing,
    same: bool,
    below: Option<&crate::cure::loose::Drawn>,
) -> Result<(Arc<DrawnMasks>, Option<crate::cure::loose::Drawn>)> {
    let area_scale = drawing.warped.as_ref().map_or(1.0, |w| w.1);
    // Coverage (thresholded when binary), compensated while it is drawn: coverage → gray
    // through S⁻¹(coverage·E*/P) (docs/CALIBRATION.md).
    let comp = ctx.optics.map(|o| &o.compensator);
    let coverage = drawing.coverage.take();
    let drawn_section = drawing.drawn();
    let (mut field_mask, lit_pixels, outside, dropped, widened, corrected) =
        match ctx.cure.filter(|c| c.active_at(layer.index)) {
            // The cure correction works on the coverage (the relative irradiance the
            // compensation then delivers): drawn and corrected, then thresholded and
            // compensated.
            Some(job) => {
                let held = job.lower_layers().min(layer.lower.len());
                let lower: Vec<&[Contour]> = layer.lower[..held]
                    .iter()
                    .map(|s| &s.contours[..])
                    .collect();
                let mut rests = super::beneath::Beneath::new(ctx, layer);
                let (m, c) = job.draw(
                    ctx.raster,
                    drawn_section,
                    (coverage, job.plain().windows(layer.index)),
                    drawing.corr.as_ref(),
                    &lower,
                    &mut |px| rests.rests(px),
                    below,
                    layer.above == 0,
                    scratch,
                    ctx.binary,
                    comp,
                );
                (m, c.lit_pixels, c.outside, c.dropped, c.widened, c.drawn)
            }
            None => {
                let m = ctx.raster.render(drawn_section, scratch, ctx.binary, comp);
                let lit = scratch.lit_pixels(&m);
                let outside = comp.and(scratch.reported_outside());
                (m, lit, outside, Vec::new(), None, None)
            }
        };
    if let Some(d) = ctx.dose {
        // Zero outside the lit box stays zero.
        let (w, lit) = (field_mask.width as usize, scratch.lit_box());
        for r in lit.rows() {
            let (row, dose) = (&mut field_mask.data[r * w..], &d.data[r * w..]);
            for (v, d) in row[lit.cols()].iter_mut().zip(&dose[lit.cols()]) {
                *v = ((*v as u32 * *d as u32 + 127) / 255) as u8;
            }
        }
    }
    let area_mm2 = lit_pixels * ctx.px_area_mm2 * area_scale;
    // Per projector (the tiler compensates each projector's view as it renders it).
    let mut outside: Vec<_> = ctx.tiler.is_none().then_some(outside).into_iter().collect();
    let supported = ctx.profile.supports.enabled;
    let mut views = Vec::new();
    let mut pngs = Vec::with_capacity(ctx.profile.projector.len());
    for (k, p) in ctx.profile.projector.iter().enumerate() {
        // The view and the box outside which it is zero.
        let (view, b) = match ctx.tiler {
            Some(t) => {
                let (m, b, beyond) = t.render(k, &field_mask, scratch.lit_box());
                outside.push(beyond);
                (Cow::Owned(m), b)
            }
            // The field mask is zero outside the rasterizer's lit box.
            None => projector_view_in(&field_mask, p, scratch.lit_box()),
        };
        let (png, lit) = crate::png::encode_gray8_in(view.width, view.height, &view.data, b);
        let pixels = MaskPixels::of_encoded(&png, lit);
        // A projector's own view is counted in its pixels: its box placed in the field.
        let pixels = match &view {
            Cow::Borrowed(_) => pixels,
            Cow::Owned(_) => pixels.placed(
                [p.width_px, p.height_px],
                p.offset_px,
                [p.mirror_x, p.mirror_y],
            ),
        };
        let sha = bundle::sha256_hex(&png);
        pngs.push((png, sha, k as u32, pixels));
        if supported && ctx.tiler.is_some() {
            views.push((view.into_owned().data, p));
        }
    }
    let field_runs = supported.then(|| lit_on_field(&field_mask, scratch.lit_box(), &views));
    // Several projectors: the field's coverage for the cure prediction.
    let field = ctx.field.map(|_| super::encode_png(&field_mask));
    scratch.recycle(field_mask);
    let recent = ctx
        .recent
        .filter(|_| same && shares_masks(ctx, layer.index));
    let masks = Arc::new(DrawnMasks {
        outside,
        area_mm2,
        field,
        shifts: drawing.shifts().to_vec(),
        dropped,
        widened,
        pngs,
        field_runs,
        runs: if recent.is_some() {
            scratch.lit_runs.clone()
        } else {
            LitRuns::default()
        },
    });
    if let Some(recent) = recent {
        recent.put(&drawing.section, &masks);
    }
    Ok((masks, corrected))
}

/// The lit runs on the field of a layer's masks: with several projectors, their `views`'
/// grays added up; else those of the field mask `m` (zero outside `lit`), which one
/// projector's view only mirrors and offsets.
fn lit_on_field(m: &Mask, lit: PixelBox, views: &[(Vec<u8>, &Projector)]) -> Arc<[Run]> {
    if views.is_empty() {
        return Arc::from(lit_runs(m.width, &m.data, lit.rows(), lit.cols()));
    }
    let masks: Vec<(&[u8], Placement)> = (views.iter())
        .map(|(d, p)| {
            let at = Placement {
                size: [p.width_px, p.height_px],
                offset: p.offset_px,
                mirror: [p.mirror_x, p.mirror_y],
            };
            (&d[..], at)
        })
        .collect();
    Arc::from(field_runs(&masks))
}

/// Writes layer `i`'s mask files and returns their records.
fn write_masks(ctx: &LayerContext, drawn: &DrawnMasks, i: usize) -> Result<Vec<MaskRef>> {
    let mut masks = Vec::with_capacity(drawn.pngs.len());
    for (k, (png, sha, projector, pixels)) in drawn.pngs.iter().enumerate() {
        let file = ctx.mask_file(k, i);
        ctx.writer.write_file(&file, png)?;
        masks.push(MaskRef {
            file,
            sha256: sha.clone(),
            projector: *projector,
            pixels: Some(*pixels),
        });
    }
    if let (Some(store), Some(png)) = (ctx.field, &drawn.field) {
        store.write_file(&super::cure_records::field_file(i), png)?;
    }
    Ok(masks)
}
