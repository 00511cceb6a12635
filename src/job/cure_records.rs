//! The cure model in a job: each layer's correction and prediction (`crate::cure`), the
//! edge errors of all layers, and the manifest's record and warnings.

use super::uncorrected::{covered, Saved, Uncorrected};
use crate::bundle::machine::Projector;
use crate::bundle::{
    self, BundleSource, CurePrediction, DroppedFeatures, EdgeError, FeatureBox, Layer, LayerCure,
    Manifest,
};
use crate::cure::held_back::{self, Dropped, DroppedScan};
use crate::cure::predict::{self, EdgeSample, Histogram};
use crate::cure::psf::{AxisTable, Psf};
use crate::cure::segments::Segments;
use crate::cure::shift::Coverage;
use crate::cure::{self, widen, Correction, CureModel, Irradiance};
use crate::error::{Error, Result};
use crate::geometry::distortion;
use crate::optics::Compensator;
use crate::profile::Profile;
use crate::raster::{Mask, PixelBox, Rasterizer, Scratch};
use crate::slice::{Contour, Section, Slicer};
use crate::text::{number, plural};
use crate::warning::Warning;
use rayon::prelude::*;
use std::path::Path;
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
    /// Where the model's values came from (`bundle::Cure::sources`).
    sources: std::collections::BTreeMap<String, String>,
    /// The pixel-phase averaged light across a drawn edge.
    profile: cure::shift::EdgeProfile,
    /// The exposures of the layers (bottom layers' longer), for their doses.
    exposure: crate::profile::Exposure,
    /// The moves of a straight wall's edges, layer by layer (`cure::shift::wall_shifts`;
    /// made for the job's layer count at the first correction).
    walls: std::sync::OnceLock<Vec<f64>>,
    /// The field's rows.
    model_height_px: f64,
    correction: Correction,
    shift_px: f64,
    /// Layers a downward-facing surface is held back by (`xyz`).
    held_back: usize,
    predict: bool,
    /// The layer with the largest mean absolute edge error the prediction found, for its
    /// picture (`--cure-plots`).
    worst: Mutex<Option<WorstLayer>>,
    /// The flat features the Z correction drops, over the layers drawn so far (sums and
    /// the lowest layer's first feature: the same in any order).
    dropped: Mutex<DroppedFeatures>,
    /// The narrow features drawn wider, over the layers drawn so far (sums and the lowest
    /// layer's first feature: the same in any order).
    widened: Mutex<WidenedFeatures>,
    /// The largest piece of a corrected layer judged for curing loose
    /// ([`cure::loose`]): a support head's contact, pixels; 0 without supports (the
    /// islands warning reports what rests on nothing).
    loose_max_px: usize,
    /// A hybrid job's continuous dose against a normal layer's (the layer height at the
    /// continuous speed): whether a layer prints continuously is planned after it is drawn.
    continuous: Option<f64>,
    /// Where layers are drawn as without the correction: corrected, they left a region
    /// of the layer above on nothing ([`CureJob::drawn_plain`]).
    plain: Uncorrected,
}

/// The layer with the largest mean absolute edge error: what its picture shows, in the
/// frame of its masks' pixels.
struct WorstLayer {
    index: usize,
    abs_mean_px: f64,
    /// The layer's own irradiance and the field's size.
    irradiance: Irradiance,
    size: (usize, usize),
    contours: Vec<Contour>,
    samples: Vec<EdgeSample>,
}

/// The narrow features the XY correction drew wider, over a job's layers, and those it
/// left as they were because they rest on nothing.
#[derive(Debug, Clone, Default)]
struct WidenedFeatures {
    widened: Tally,
    /// The first widened one's wall width, mm.
    wall_mm: f64,
    on_nothing: Tally,
}

/// Features of some kind over a job's layers: how many, in how many layers, and the
/// lowest layer's first (the same in any order of the layers).
#[derive(Debug, Clone, Copy, Default)]
struct Tally {
    features: u64,
    layers: u64,
    first_layer: Option<u64>,
    first: Option<FeatureBox>,
}

impl Tally {
    /// Counts `k` features of `layer`, the first at `first`; whether `layer` is now the
    /// lowest.
    fn add(&mut self, layer: u64, k: u32, first: FeatureBox) -> bool {
        self.features += k as u64;
        self.layers += 1;
        let lowest = self.first_layer.is_none_or(|f| layer < f);
        if lowest {
            (self.first_layer, self.first) = (Some(layer), Some(first));
        }
        lowest
    }
}

/// Points along a drawn contour at which its edges' moves are solved, px apart at most.
const SHIFT_SPACING_PX: f64 = 8.0;

/// A layer's XY correction: its drawn section's edges and their moves.
pub(super) struct LayerCorrection {
    /// The drawn section's edges (simplified within 0.01 px).
    pub segs: Segments,
    /// Their moves.
    pub shifts: cure::shift::EdgeShifts,
    /// Per contour, whether it runs backwards ([`Segments::union_pieces`]; empty: none).
    pub backwards: Vec<bool>,
    /// The layer's own light at which a feature that the layers above repeat cures (the
    /// narrow features' widening aims at it).
    pub threshold: f64,
    /// The layer's own light at which its resin cures: the model's edge threshold over
    /// the layer's dose against the normal layer's (what `run` judges loose pieces by).
    pub cures_at: f64,
}

/// The narrow features of one layer the XY correction drew wider so they cure, and those
/// it left as they were because they rest on nothing in the layer below.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LayerWidened {
    /// How many were widened.
    pub features: u32,
    /// The first one's bounding box (in contour order), build-plane mm.
    pub first: Option<FeatureBox>,
    /// The first one's wall width, mm.
    pub wall_mm: f64,
    /// How many rest on nothing, and the first one's box.
    pub on_nothing: (u32, Option<FeatureBox>),
}

impl LayerWidened {
    /// The record of what [`widen::widen`] did to a layer, if it found any feature to
    /// widen or over nothing.
    fn of(wd: &widen::Widening) -> Option<LayerWidened> {
        (wd.widened + wd.on_nothing > 0).then_some(LayerWidened {
            features: wd.widened,
            first: wd.first,
            wall_mm: wd.first_wall_mm,
            on_nothing: (wd.on_nothing, wd.first_on_nothing),
        })
    }
}

/// What drawing a layer through the cure model gave besides its mask.
pub(super) struct CureDrawn {
    /// Lit area of the section's coverage (before the correction), pixels.
    pub lit_pixels: f64,
    /// Whether the compensation found the layer lit outside its calibrated area, and how
    /// far it reaches, mm.
    pub outside: Option<f64>,
    /// The flat features the Z correction drops whose runs of lit layers end in the layer
    /// below (`(1, …)`) or, for the job's top layer, in this one (`(0, …)`); only those
    /// with pixels.
    pub dropped: Vec<(usize, LayerDropped)>,
    /// The narrow features drawn wider so they cure (`cure::widen`).
    pub widened: Option<LayerWidened>,
    /// The corrected coverage, for the next layer's loose pieces (`cure::loose`).
    pub drawn: Option<cure::loose::Drawn>,
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
        let edge = cure::shift::EdgeProfile::new(&cure::Psf {
            sigma_px: model.sigma_px,
        });
        let shift_px = match correction {
            Correction::Off => 0.0,
            _ => cure::edge_shift_px(&model, &edge),
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
        let r = &profile.resin;
        let of = |s: &Option<String>| s.clone().unwrap_or_else(|| "assumed".into());
        // σ is the largest of the projectors' (`CureModel::from_profile`): its source.
        let psf = profile
            .projector
            .iter()
            .filter(|p| p.psf_sigma_px.map(|s| s.get()) == Some(model.sigma_px))
            .find_map(|p| p.psf_source.clone());
        let sources = [
            ("psf_sigma_px", of(&psf)),
            ("dp_mm", of(&r.dp_source)),
            ("ec_mj_cm2", of(&r.ec_source)),
        ];
        Ok(Some(CureJob {
            model,
            sources: sources.map(|(k, v)| (k.to_string(), v)).into(),
            profile: edge,
            exposure: profile.exposure.clone(),
            walls: std::sync::OnceLock::new(),
            model_height_px: profile.field().height_px as f64,
            correction,
            shift_px,
            held_back,
            predict: opts.predict,
            worst: Mutex::new(None),
            dropped: Mutex::new(DroppedFeatures::default()),
            widened: Mutex::new(WidenedFeatures::default()),
            loose_max_px: match &profile.supports {
                s if s.enabled => {
                    let r = 0.5 * s.head_front_diameter_mm / model.pixel_mm;
                    (std::f64::consts::PI * r * r).floor() as usize
                }
                _ => 0,
            },
            continuous: profile.hybrid.as_ref().map(|h| {
                let s = model.layer_mm / h.continuous_speed_mm_s.get();
                s / profile.exposure.layer_s.get()
            }),
            plain: Uncorrected::default(),
        }))
    }

    /// The same job with `plain` drawn as without the correction, XY and Z (as
    /// `--cure-correction off` draws them).
    pub fn drawn_plain(mut self, plain: Uncorrected) -> CureJob {
        self.plain = plain;
        self
    }

    /// Where layers are drawn as without the correction.
    pub fn plain(&self) -> &Uncorrected {
        &self.plain
    }

    /// Whether layer `i`'s edges are moved ([`CureJob::corrects`], and it is not drawn
    /// plain whole).
    pub fn corrects_at(&self, i: usize) -> bool {
        self.corrects() && !self.plain.whole(i)
    }

    /// Whether layer `i` is drawn through [`CureJob::draw`] ([`CureJob::active`], and it
    /// is not drawn plain whole).
    pub fn active_at(&self, i: usize) -> bool {
        self.active() && !self.plain.whole(i)
    }

    /// Whether layer `i`'s masks may be those of another layer with the same section, or
    /// serve one: not with the Z correction (what it holds back depends on the layers
    /// below), nor where the layer is drawn plain in part or whole.
    pub fn shares_masks_at(&self, i: usize) -> bool {
        self.held_back == 0 && !self.plain.has(i)
    }

    /// Whether layers are drawn through [`CureJob::draw`].
    pub fn active(&self) -> bool {
        self.corrects() || self.held_back > 0
    }

    /// Whether the masks' edges are moved (`xy`, `xyz`).
    pub fn corrects(&self) -> bool {
        self.correction != Correction::Off
    }

    /// The dose of layer `k` against a normal layer's (the profile's exposure schedule:
    /// bottom and transition layers; a continuous layer's sweep is not known before it is
    /// planned).
    fn ratio(&self, k: usize) -> f64 {
        self.exposure.layer_exposure_s(k) / self.exposure.layer_s.get()
    }

    /// The dose of layer `index` against a normal layer's that its loose pieces are judged
    /// by: [`CureJob::ratio`], or in a hybrid job the continuous dose where it is smaller
    /// and the layer may print continuously (past the bottom and transition layers).
    fn loose_ratio(&self, index: usize) -> f64 {
        let e = &self.exposure;
        let free = (e.bottom_layers + e.transition_layers) as usize;
        match self.continuous {
            Some(c) if index >= free => self.ratio(index).min(c),
            _ => self.ratio(index),
        }
    }

    /// Layer `index`'s correction (`None` with `off`): the edges of its drawn `section`
    /// (`own`: its coverage), their moves from its dose and from the layers above, `upper`
    /// (their sections' coverage, nearest first, at most [`cure::shift::LOOK_AHEAD`]),
    /// `above` layers in all up to the job's top. With `overlapping` contours (supports in
    /// the section), or shells that may cross, touch or nest
    /// ([`cure::segments::contours_may_meet`]), only the edges of their union move.
    pub fn correction_of(
        &self,
        (index, above): (usize, usize),
        (section, overlapping): (&[Contour], bool),
        own: &Coverage,
        upper: &[&Coverage],
    ) -> Option<LayerCorrection> {
        if !self.corrects() {
            return None;
        }
        let h = self.model_height_px;
        let segs = Segments::simplified(section, self.model.pixel_mm, h, 0.01);
        let overlapping = overlapping || cure::segments::contours_may_meet(section);
        let (segs, interior, backwards) = match overlapping {
            true => {
                let (pieces, interior, backwards) = segs.union_pieces();
                (pieces, Some(interior), backwards)
            }
            false => (segs, None, Vec::new()),
        };
        let mut pairs = Vec::new();
        let layers = index + above + 1;
        let walls = self.walls.get_or_init(|| {
            cure::shift::wall_shifts(&self.model, &self.profile, layers, |k| self.ratio(k))
        });
        let look = cure::shift::LookAhead::new(
            &self.model,
            (index, layers),
            (|k| self.ratio(k), walls),
            upper,
            &mut pairs,
        );
        let mut shifts = cure::shift::EdgeShifts::solve(
            &self.model,
            &self.profile,
            (&segs, own),
            &look,
            SHIFT_SPACING_PX,
        );
        if let Some(interior) = &interior {
            shifts.hold(interior);
        }
        let all = look.total();
        Some(LayerCorrection {
            segs,
            shifts,
            backwards,
            threshold: self.model.threshold(0.5 * self.model.layer_mm, Some(0)) / all,
            cures_at: self.model.edge_threshold() / self.loose_ratio(index),
        })
    }

    /// Whether the job's cure is predicted (`--predict`).
    pub fn predicts(&self) -> bool {
        self.predict
    }

    /// Layers a downward-facing surface is held back by (0 unless `xyz`).
    pub fn held_back(&self) -> usize {
        self.held_back
    }

    /// Sections above a layer that its correction looks at (0 with `off`).
    pub fn upper_layers(&self) -> usize {
        if self.corrects() {
            cure::shift::LOOK_AHEAD
        } else {
            0
        }
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
    /// wider, `cure::widen`, unless `rests` says they rest on nothing; in a job with
    /// supports, pieces that would cure loose on `below`, the layer below as drawn, are
    /// drawn dark, `cure::loose`, and the layer is kept as drawn for the next), then
    /// thresholds (`binary`) and compensates (`comp`) it in place. With `xyz` it also finds
    /// the flat features the correction drops whose runs of lit layers end in the layer
    /// below (from [`CureJob::lower_layers`] sections below) or, when `top` (the job's last
    /// layer), in this one. In the layer's `plain` windows ([`Uncorrected::windows`]) the
    /// coverage is drawn as without the correction.
    #[allow(clippy::too_many_arguments)]
    pub fn draw(
        &self,
        raster: &Rasterizer,
        section: &[Contour],
        (coverage, plain): (Option<(Mask, PixelBox)>, &[PixelBox]),
        corr: Option<&LayerCorrection>,
        lower: &[&[Contour]],
        rests: &mut dyn FnMut(&[usize]) -> bool,
        below: Option<&cure::loose::Drawn>,
        top: bool,
        scratch: &mut Scratch,
        binary: bool,
        comp: Option<&Compensator>,
    ) -> (Mask, CureDrawn) {
        // The coverage (drawn already for the correction, else here).
        let (mut m, lit) = match coverage {
            Some(c) => c,
            None => {
                let m = raster.render::<Compensator>(section, scratch, false, None);
                (m, scratch.lit_box())
            }
        };
        // The record's area is the section's, as drawn before the correction.
        let lit_pixels = scratch.lit_pixels(&m);
        let held = self.held_back;
        // The runs of lit layers ending in this layer (the top) or the one below end where
        // this layer's exact coverage is unlit: taken before the correction changes it.
        let mut ends_here = (held > 0 && top).then(|| DroppedScan::new(&m, lit, |_, _| false));
        let here = held_back::lit_pixels_of(&m, lit, held > 0 && !lower.is_empty());
        let lit_here = |c: usize, r: usize| {
            lit.rows().contains(&r)
                && lit.cols().contains(&c)
                && here[(r - lit.r0) * lit.cols().len() + (c - lit.c0)]
        };
        // Small features (geometry only; not those plain windows draw, as `off` would) and
        // their uncorrected coverage, for the narrow ones the correction would starve.
        let inward = corr.map_or(0.0, |c| c.shifts.range().1);
        let rows = m.height as f64;
        let mut small = corr.map_or(Vec::new(), |c| {
            widen::small_features(&self.model, (section, &c.backwards), rows, inward)
        });
        small.retain(|f| !covered(plain, f.pixels()));
        let mut saved = (!small.is_empty()).then(|| widen::Uncorrected::take(&m, &small, inward));
        let plain = (!plain.is_empty()).then(|| Saved::take(&m, plain));
        if let Some(c) = corr {
            let within = widen::within_section_box(section, self.model.pixel_mm, m.height as f64);
            cure::correct_coverage(&mut m, lit, &c.segs, &c.shifts, within);
        }
        let mut ends_below: Option<DroppedScan> = None;
        if !lower.is_empty() {
            LOWER.with(|s| {
                let s = &mut *s.borrow_mut();
                for (j, below) in lower.iter().enumerate() {
                    let b = raster.coverage(below, s);
                    if j < held {
                        held_back::hold_back(&mut m, &b, lit);
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
        let widened = saved.zip(corr).and_then(|(saved, c)| {
            let wd = widen::widen(
                &self.model,
                &mut m,
                lit,
                section,
                &small,
                &saved,
                inward,
                c.threshold,
                rests,
            );
            if wd.lit != lit {
                scratch.grow_lit_box(wd.lit);
                drawn_lit = scratch.lit_box();
            }
            LayerWidened::of(&wd)
        });
        let drawn = corr.and_then(|c| self.loose(raster, section, (&mut m, drawn_lit), c, below));
        let drawn = match plain {
            Some(p) => p.put_back(&mut m, drawn),
            None => drawn,
        };
        let (p, h) = (self.model.pixel_mm, m.height);
        let dropped: Vec<(usize, LayerDropped)> = [(1, ends_below), (0, ends_here)]
            .into_iter()
            .filter_map(|(k, d)| Some((k, LayerDropped::of(d?.finish(), p, h)?)))
            .collect();
        if binary {
            crate::raster::threshold_in(&mut m, drawn_lit);
        }
        let outside = comp.and_then(|c| c.apply_in(&mut m, drawn_lit));
        (
            m,
            CureDrawn {
                lit_pixels,
                outside,
                dropped,
                widened,
                drawn,
            },
        )
    }

    /// In a job with supports, draws dark the pieces of the corrected coverage `m` (lit
    /// box `lit`) of `section` that would cure loose on `below` (`cure::loose`), and
    /// returns the layer as drawn, for the next; `None` without supports.
    fn loose(
        &self,
        raster: &Rasterizer,
        section: &[Contour],
        (m, lit): (&mut Mask, PixelBox),
        c: &LayerCorrection,
        below: Option<&cure::loose::Drawn>,
    ) -> Option<cure::loose::Drawn> {
        if self.loose_max_px == 0 {
            return None;
        }
        let psf = cure::Psf {
            sigma_px: self.model.sigma_px,
        };
        let mut exact = || LOWER.with(|s| raster.coverage(section, &mut s.borrow_mut()));
        let judge = (&psf, c.cures_at as f32);
        let max = (self.loose_max_px, self.held_back == 0);
        let found = cure::loose::loose_pieces(m, lit, judge, max, below, &mut exact);
        for k in found.dark {
            m.data[k] = 0;
        }
        for k in found.bridges {
            m.data[k] = 255;
        }
        Some(cure::loose::Drawn::of(m, lit, c.cures_at as f32))
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
        if let Some(first) = w.first {
            if t.widened.add(layer, w.features, first) {
                t.wall_mm = w.wall_mm;
            }
        }
        if let (k, Some(first)) = w.on_nothing {
            t.on_nothing.add(layer, k, first);
        }
    }

    /// The warning naming the narrow features over nothing that were left as the
    /// correction drew them (not widened), if any; `what_at` as for
    /// [`CureJob::widened_warning`].
    pub fn on_nothing_warning(&self, what_at: &WhatAt) -> Option<Warning> {
        let t = self.widened.lock().unwrap_or_else(|p| p.into_inner());
        let o = t.on_nothing;
        let (first, at, k, n) = (o.first_layer?, o.first?, o.features, o.layers);
        Some(with_features(
            Warning::new(
                "cure.features-on-nothing",
                format!(
                    "cure: {k} {} too thin to cure {} on nothing in the layer below, so {} not drawn wider, in {n} {} (first: layer {first}, at {}); widened, {} would cure loose",
                    plural(k, "feature", "features"),
                    plural(k, "rests", "rest"),
                    plural(k, "it was", "they were"),
                    plural(n, "layer", "layers"),
                    where_is(&at, first, what_at),
                    plural(k, "it", "they"),
                ),
            ),
            (k, n, first),
            &at,
        ))
    }

    /// The warning naming the narrow features drawn wider so they cure, if any; `what_at`
    /// names what the first one is part of (words to follow its position).
    pub fn widened_warning(&self, what_at: &WhatAt) -> Option<Warning> {
        let t = self.widened.lock().unwrap_or_else(|p| p.into_inner());
        let w = t.widened;
        let (first, at) = (w.first_layer?, w.first?);
        let (k, n, wall_mm) = (w.features, w.layers, t.wall_mm);
        Some(
            with_features(
                Warning::new(
                "cure.features-widened",
                format!(
                    "cure: {k} {} too thin to cure {} drawn wider so that {}, in {n} {} (first: layer {first}, at {}{}); {} cured size is the smallest the machine makes, larger than the part's",
                    plural(k, "feature", "features"),
                    plural(k, "was", "were"),
                    plural(k, "it cures", "they cure"),
                    plural(n, "layer", "layers"),
                    where_is(&at, first, what_at),
                    match wall_mm > 0.0 {
                        true => format!(", its thin part {} mm wide", number((wall_mm * 1e3).round() / 1e3)),
                        false => String::new(),
                    },
                    plural(k, "its", "their"),
                ),
            ),
                (k, n, first),
                &at,
            )
            .with("wall_mm", wall_mm),
        )
    }

    /// The warning naming the flat features the Z correction drops, if any; `what_at` as
    /// for [`CureJob::widened_warning`].
    pub fn dropped_warning(&self, what_at: &WhatAt) -> Option<Warning> {
        let t = self.dropped.lock().unwrap_or_else(|p| p.into_inner());
        let (first, at) = (t.first_layer?, t.first?);
        let (k, n, m) = (t.features, t.layers, self.held_back as u64);
        let thick = crate::round::plane_mm((m + 1) as f64 * self.model.layer_mm);
        Some(
            with_features(
                Warning::new(
                "cure.features-dropped",
                format!(
                    "cure: the xyz correction leaves out {k} flat {} over nothing thinner than {} layers ({} {} in {n} {}; first: layer {first}, at {}): {} at least {} layers ({} mm) thick",
                    plural(k, "feature", "features"),
                    m + 1,
                    t.pixels,
                    plural(t.pixels, "pixel", "pixels"),
                    plural(n, "layer", "layers"),
                    where_is(&at, first, what_at),
                    plural(k, "it is kept when", "they are kept when"),
                    m + 1,
                    number(thick),
                ),
            ),
                (k, n, first),
                &at,
            )
            .with("pixels", t.pixels)
            .with("held_back_layers", m),
        )
    }

    /// Writes the prediction's pictures into `dir`: `<stem>-cure-errors.png` (per-layer
    /// chart) and `<stem>-cure-layer-<N>.png`, layer N (the worst by mean absolute error)
    /// in its masks' pixels with its predicted cured outline. Returns the files written.
    pub fn write_plots(
        &self,
        dir: &Path,
        stem: &str,
        manifest: &bundle::Manifest,
    ) -> Result<Vec<std::path::PathBuf>> {
        use crate::plot::Format;
        let mut out = Vec::new();
        let chart = cure::plots::error_chart(stem, &manifest.layers).render();
        let p = dir.join(format!("{stem}-cure-errors.png"));
        crate::output::write_atomic(&p, &chart.encode(Format::Png))?;
        out.push(p);
        let worst = self.worst.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(w) = worst.as_ref().filter(|w| w.abs_mean_px > 0.0) {
            let pic = cure::plots::outline_picture(
                &self.model,
                w.index,
                (&w.irradiance, w.size),
                &w.contours,
                &w.samples,
            );
            let p = dir.join(format!("{stem}-cure-layer-{:05}.png", w.index));
            crate::output::write_atomic(&p, &pic.encode(Format::Png))?;
            out.push(p);
        }
        Ok(out)
    }

    /// The cure prediction (`--predict`) of the planned job `manifest` from the masks it
    /// wrote (`files`; for several projectors `field`, the field's coverage masks): the
    /// engine of `dmdsl run --cure` from the top layer down, each layer's cured edge also
    /// compared along its exact section's normals (re-cut by `slicer`, as the job cut it;
    /// pre-warped by `warp`). Fills `layers[].cure` and `cure.predicted`.
    pub fn predict(
        &self,
        manifest: &mut Manifest,
        files: &dyn BundleSource,
        field: Option<&dyn BundleSource>,
        mut slicer: Slicer<'_>,
        warp: Option<(&distortion::Correction, &Path)>,
    ) -> Result<()> {
        let m = self.model;
        let n = manifest.layers.len();
        let (frame, light, source): (Projector, _, &dyn BundleSource) = match field {
            Some(f) => (
                field_frame(&manifest.machine),
                crate::exec::cure::Light::linear(),
                f,
            ),
            None => (
                manifest.machine.projector[0].clone(),
                crate::exec::cure::Light::of(manifest, files)?,
                files,
            ),
        };
        let (w, h) = (frame.width_px as usize, frame.height_px as usize);
        let field_h = manifest.machine.field().height_px as f64;
        let mut window: (usize, Vec<Section>) = (n, Vec::new());
        let mut layers: Vec<Option<(LayerCure, Histogram)>> = vec![None; n];
        let mut failed: Option<Error> = None;
        let mut worst: Option<WorstLayer> = None;
        let mut batch: Vec<LayerLight> = Vec::new();
        let mut observe = |i: usize, e: &cure::Engine, irr: &Irradiance| {
            if failed.is_some() {
                return;
            }
            if i < window.0 {
                let lo = (i + 1).saturating_sub(PREDICT_WINDOW);
                window = (lo, slicer.window(lo..i + 1));
            }
            let section = &window.1[i - window.0].contours;
            let drawn = match warp {
                Some((c, model)) => match c.warp_section(section, model, i) {
                    Ok(d) => d,
                    Err(err) => {
                        failed = Some(err);
                        return;
                    }
                },
                None => section.clone(),
            };
            let framed = in_frame(&drawn, &frame, m.pixel_mm, field_h);
            batch.push(LayerLight::take(i, e, irr, (drawn, framed), &m));
            // The layers' samples in parallel, a batch at a time.
            if batch.len() == PREDICT_BATCH || i == 0 {
                let done: Vec<_> = batch.par_iter().map(|l| l.samples(&m)).collect();
                for (l, (c, hist, samples)) in batch.drain(..).zip(done) {
                    let abs = crate::round::derived(c.abs_mean_px);
                    if c.samples > 0 && worst.as_ref().is_none_or(|w| abs >= w.abs_mean_px) {
                        worst = Some(WorstLayer {
                            index: l.index,
                            abs_mean_px: abs,
                            irradiance: l.own,
                            size: (w, h),
                            contours: l.framed,
                            samples,
                        });
                    }
                    layers[l.index] = Some((c, hist));
                }
            }
        };
        let ratios = crate::exec::cure::ratios(manifest);
        let outs = cure::run_layers(
            &m,
            (w, h),
            &ratios,
            &|i| {
                let file = match field {
                    Some(_) => field_file(i),
                    None => match manifest.layers[i].masks.first() {
                        Some(m) => m.file.clone(),
                        None => return Ok(Irradiance::default()),
                    },
                };
                crate::exec::cure::irradiance_of(source, &file, (w, h), &light)
            },
            (true, self.held_back),
            &mut observe,
        )?;
        if let Some(err) = failed {
            return Err(err);
        }
        let to_mm = crate::exec::cure::to_build_plane(&frame, m.pixel_mm, field_h);
        let check = cure::summarize(manifest, &m, &to_mm, outs);
        let r = crate::round::derived;
        let mut hist = Histogram::default();
        for ((l, c), o) in manifest.layers.iter_mut().zip(layers).zip(&check.per_layer) {
            let (c, h) = c.unwrap_or_default();
            hist.merge(&h);
            l.cure = Some(LayerCure {
                mean_px: r(c.mean_px),
                abs_mean_px: r(c.abs_mean_px),
                p95_px: r(c.p95_px),
                max_px: r(c.max_px),
                offset_px: (o.perimeter_mm > 0.0).then(|| r(o.offset_px)),
                ..c
            });
        }
        let mut p = prediction(&manifest.layers, &hist, m.pixel_mm);
        p.edge_offset_px = EdgeError {
            mean: r(check.edge_offset_px.mean),
            p95: r(check.edge_offset_px.p95),
            max: r(check.edge_offset_px.max),
        };
        p.signed_offset_px = r(check.signed_mean_px);
        if let Some(c) = manifest.cure.as_mut() {
            c.predicted = Some(p);
        }
        *self.worst.lock().unwrap_or_else(|p| p.into_inner()) = worst;
        Ok(())
    }

    /// The manifest's record (without the prediction, [`CureJob::predict`]'s).
    pub fn record(&self) -> bundle::Cure {
        let m = &self.model;
        let r = crate::round::derived;
        bundle::Cure {
            psf_sigma_px: m.sigma_px,
            pixel_mm: m.pixel_mm,
            dp_mm: m.dp_mm,
            ec_mj_cm2: m.ec_mj_cm2,
            sources: self.sources.clone(),
            overcure_mm: m.overcure_mm,
            layer_mm: m.layer_mm,
            edge_threshold: r(m.edge_threshold()),
            correction: self.correction.as_str().into(),
            shift_px: r(self.shift_px),
            print_through_mm: crate::round::plane_mm(m.print_through_mm(None)),
            held_back_layers: self.held_back as u32,
            uncorrected_layers: (self.plain.whole_layers().into_iter())
                .map(|i| i as u64)
                .collect(),
            uncorrected_windows: (self.plain.all_windows())
                .map(|(i, b)| bundle::UncorrectedWindow {
                    layer: i as u64,
                    box_px: [b.c0, b.r0, b.c1, b.r1].map(|v| v as u64),
                })
                .collect(),
            predicted: None,
            dropped: (self.held_back > 0).then(|| {
                self.dropped
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .clone()
            }),
        }
    }
}

/// The file of layer `i`'s field coverage in the store of a job of several projectors.
pub(super) fn field_file(i: usize) -> String {
    format!("field/{i:05}.png")
}

/// Sections cut at a time for the prediction (from the top layer down).
const PREDICT_WINDOW: usize = 32;
/// Layers whose edges the prediction samples together.
const PREDICT_BATCH: usize = 8;

/// A layer's light as the prediction samples it, around its section: the light that
/// reaches its top (its own and the layers above's, the engine's) and its own.
struct LayerLight {
    index: usize,
    /// The section (build-plane mm) and the same in the frame of the masks.
    drawn: Vec<Contour>,
    framed: Vec<Contour>,
    /// The pixel box `[c0, r0, c1, r1]` of `light` in the masks' frame.
    bbox: [usize; 4],
    light: Vec<f32>,
    own: Irradiance,
    height: usize,
}

impl LayerLight {
    /// The light of layer `index` from the engine `e` (which has just evaluated it) and
    /// its own irradiance `own`, around its section.
    fn take(
        index: usize,
        e: &cure::Engine,
        own: &Irradiance,
        (drawn, framed): (Vec<Contour>, Vec<Contour>),
        m: &CureModel,
    ) -> LayerLight {
        let (w, h) = e.size();
        // The samples search 4σ + 2 px from the edge and the light there sums 4σ + 1 px.
        let pad = 2.0 * (4.0 * m.sigma_px + 2.0) + 2.0;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for q in framed.iter().flatten() {
            let p = [q[0] / m.pixel_mm, h as f64 - q[1] / m.pixel_mm];
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let cut = |x: f64, n: usize| (x.max(0.0) as usize).min(n);
        let bbox = if lo[0] <= hi[0] {
            [
                cut(lo[0] - pad, w),
                cut(lo[1] - pad, h),
                cut(hi[0] + pad + 1.0, w),
                cut(hi[1] + pad + 1.0, h),
            ]
        } else {
            [0; 4]
        };
        let (px, scale) = e.irradiance();
        let mut light = Vec::with_capacity((bbox[2] - bbox[0]) * (bbox[3] - bbox[1]));
        for r in bbox[1]..bbox[3] {
            light.extend(
                px[r * w + bbox[0]..r * w + bbox[2]]
                    .iter()
                    .map(|v| v * scale),
            );
        }
        LayerLight {
            index,
            drawn,
            framed,
            bbox,
            light,
            own: own.clone(),
            height: h,
        }
    }

    /// The layer's edge samples and figures.
    fn samples(&self, m: &CureModel) -> (LayerCure, Histogram, Vec<EdgeSample>) {
        let psf = Psf {
            sigma_px: m.sigma_px,
        };
        let table = AxisTable::new(&psf);
        let mid = m.threshold(0.5 * m.layer_mm, Some(0));
        let [c0, r0, c1, _] = self.bbox;
        let [o0, o1, o2, _] = self.own.bbox;
        let near = cure::check::NEAR as f64;
        let margin = |p: [f64; 2]| {
            let at = [p[0] - c0 as f64, p[1] - r0 as f64];
            let a = predict::light(&self.light, (c1 - c0).max(1), &psf, &table, at) - mid;
            if self.own.is_empty() {
                return [a, -near];
            }
            let at = [p[0] - o0 as f64, p[1] - o1 as f64];
            [
                a,
                predict::light(&self.own.data, o2 - o0, &psf, &table, at) - near,
            ]
        };
        let (samples, backwards) =
            predict::edge_samples(m, &margin, self.height as f64, &self.framed);
        let (c, h) = predict::summarize(m, &samples, (&self.drawn, &backwards));
        (c, h, samples)
    }
}

/// The field of a machine as one projector (its pixels, unmirrored): the frame of the
/// field's coverage masks.
fn field_frame(machine: &bundle::Machine) -> Projector {
    let f = machine.field();
    let mut p = machine.projector[0].clone();
    p.width_px = f.width_px;
    p.height_px = f.height_px;
    p.offset_px = [0, 0];
    p.mirror_x = false;
    p.mirror_y = false;
    p
}

/// `contours` (build-plane mm, on a field `field_h` rows high of `pixel_mm` pixels) in
/// the frame of projector `p`'s pixels, as mm of a field of its size: its offset taken
/// off and its mirroring applied (the contours reversed where that turns them over).
fn in_frame(contours: &[Contour], p: &Projector, pixel_mm: f64, field_h: f64) -> Vec<Contour> {
    let (w, h) = (p.width_px as f64, p.height_px as f64);
    let (ox, oy) = (p.offset_px[0] as f64, p.offset_px[1] as f64);
    let map = |q: &[f64; 2]| {
        let (u, v) = (q[0] / pixel_mm - ox, field_h - q[1] / pixel_mm - oy);
        let u = if p.mirror_x { w - u } else { u };
        let v = if p.mirror_y { h - v } else { v };
        [u * pixel_mm, (h - v) * pixel_mm]
    };
    contours
        .iter()
        .map(|c| {
            let mut c: Contour = c.iter().map(map).collect();
            if p.mirror_x != p.mirror_y {
                c.reverse();
            }
            c
        })
        .collect()
}

/// The job's prediction from its layers' (`layers[].cure`) and their absolute edge
/// errors `hist`.
fn prediction(layers: &[Layer], hist: &Histogram, pixel_mm: f64) -> CurePrediction {
    let r = crate::round::derived;
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
        mean: r(px.mean * pixel_mm),
        p95: r(px.p95 * pixel_mm),
        max: r(px.max * pixel_mm),
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
        ..CurePrediction::default()
    }
}

/// What a message about a point (mm) of a layer (index) names besides the position, as
/// words to follow it (", in b.stl"), or nothing ([`super::manifest::PlacedPart::what_at`]).
pub(super) type WhatAt<'a> = dyn Fn([f64; 2], u64) -> Option<String> + 'a;

/// `w` with the fields of a count of features: `features` (k), `layers` (n),
/// `first_layer` and the first one's box `x_mm`, `y_mm`, `width_mm`, `height_mm`.
fn with_features(w: Warning, (k, n, first): (u64, u64, u64), at: &FeatureBox) -> Warning {
    w.with("features", k)
        .with("layers", n)
        .with("first_layer", first)
        .with("x_mm", at.x_mm)
        .with("y_mm", at.y_mm)
        .with("width_mm", at.width_mm)
        .with("height_mm", at.height_mm)
}

/// "x 12.3 mm, y 4.5 mm, 0.1 × 0.2 mm": a feature's centre and size, and what it is part
/// of (`what_at` of layer `layer`).
fn where_is(b: &FeatureBox, layer: u64, what_at: &WhatAt) -> String {
    format!(
        "x {} mm, y {} mm, {} × {} mm{}",
        number(b.x_mm),
        number(b.y_mm),
        number(b.width_mm),
        number(b.height_mm),
        what_at([b.x_mm, b.y_mm], layer).unwrap_or_default()
    )
}

thread_local! {
    /// Scratch of the layers below's coverage (`xyz`), one per worker thread.
    static LOWER: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// The warnings of the layers' predictions: features that vanish, gaps that close
/// (`what_at` as for [`CureJob::widened_warning`]).
pub(super) fn warnings(layers: &[Layer], what_at: &WhatAt) -> Vec<Warning> {
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
                "cure: {k} {} cure nowhere in {n} {} (first: layer {first}{})",
                plural(k, "feature", "features"),
                plural(n, "layer", "layers"),
                at.map_or(String::new(), |a| format!(
                    ", at {}",
                    where_is(&a, first, what_at)
                )),
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
