//! Narrow features the XY correction would starve: drawn back, then wider, until the
//! predicted light reaches the cure threshold (docs/CURE.md, "Narrow features").
//!
//! The correction ([`super::correct_coverage`]) moves every edge inward by s*. A feature
//! narrower than a few pixels then gets less light than it needs: its blurred light peaks
//! below the mid-layer threshold T ([`CureModel::edge_threshold`]) and nothing of it
//! cures, even where the uncorrected mask would have cured it. Here:
//!
//! 1. **Small features** ([`small_features`]): an outer contour with the holes inside it
//!    is small when 2A/P < 2·(s* + 4σ) px (A its area less its holes', P the length of
//!    its contours and its holes'). 2A/P is the width of a wall and half a disc's
//!    diameter; for a convex feature it is at most twice the radius of the largest disc
//!    inside it, so a convex feature without a flat interior (a point farther than
//!    s* + 4σ from every edge) is small. It misses a thin part of a larger feature (a fin
//!    on a block).
//! 2. **Peak**: the largest predicted light ([`super::predict::light`]) over the pixel
//!    centres within 0.75 px of the feature (inside it or at its edge), refined by a
//!    search in steps of 1/4, 1/8 and 1/16 px. A feature peaking at T·(1 + [`MARGIN`]) or
//!    more keeps its corrected coverage.
//! 3. **Undo, then widen**: each pixel near the feature's edges takes at least its
//!    uncorrected coverage moved outward by d = 0, 0.1, …, [`MAX_OUT_PX`] px (the exact
//!    area of the pixel on the inside of the nearest edge's line, as the correction
//!    computes it), one step at a time until the peak reaches T·(1 + [`MARGIN`]). A
//!    feature that reaches T at the last step cures (at the smallest size the machine
//!    makes, larger than the part's); one that does not gets its corrected coverage back
//!    and is left to the prediction (`cure.features-vanish`). No pixel farther than
//!    [`BOX_SLACK_PX`] outside the section's bounding box is lit (the executor's check of
//!    the masks against the layer's recorded box allows 1 px).
//!
//! With the Z correction, a feature the held-back layers' minimum takes more than half the
//! uncorrected coverage of (a held-back surface) is left as it is; the others are widened
//! after that minimum. Masks of layers without small features, or whose small features
//! cure, are not changed.

use super::correct::{halfplane_coverage, nearest_edges};
use super::segments::Segments;
use crate::bundle::FeatureBox;
use crate::cure::model::CureModel;
use crate::cure::psf::{AxisTable, Psf};
use crate::raster::Mask;
use crate::raster::PixelBox;
use crate::slice::{bounds, signed_area, Contour};

/// The light a narrow feature is drawn to reach: T·(1 + `MARGIN`) (room for the 8-bit
/// grays and the compensation's rounding).
pub const MARGIN: f64 = 0.05;
/// Step of the outward move, px.
pub const STEP_PX: f64 = 0.1;
/// The largest outward move of a narrow feature's edges, px.
pub const MAX_OUT_PX: f64 = 1.0;

/// A small feature of a layer: an outer contour and the holes inside it.
#[derive(Debug, Clone)]
pub struct SmallFeature {
    /// Its contours' indices in the section (the outer one first).
    pub contours: Vec<usize>,
    /// Its outer contour's bounding box (build-plane mm).
    pub at: FeatureBox,
    /// The width of its thin part where its box does not show it, mm: 2A/P (a wall's
    /// width) for a feature with holes (a ring) or one much thinner than its box (a
    /// slanted bar), else 0.
    pub wall_mm: f64,
    /// The pixels its outer contour's bounding box touches.
    pixels: PixelBox,
    /// Whether its contours run backwards (drawn turned round).
    backwards: bool,
}

impl SmallFeature {
    /// The pixels its outer contour's bounding box touches.
    pub fn pixels(&self) -> PixelBox {
        self.pixels
    }
}

/// What [`widen`] did to a layer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Widening {
    /// Small features drawn back or wider so that their peak reaches T.
    pub widened: u32,
    /// The first of them (in contour order).
    pub first: Option<FeatureBox>,
    /// The first one's [`SmallFeature::wall_mm`].
    pub first_wall_mm: f64,
    /// Small features that stay below T even widened (drawn corrected).
    pub failed: u32,
    /// Small features below T that rest on nothing in the layer below (drawn corrected,
    /// not widened: they would cure loose).
    pub on_nothing: u32,
    /// The first of them (in contour order).
    pub first_on_nothing: Option<FeatureBox>,
    /// The mask's lit box grown by the widened pixels.
    pub lit: PixelBox,
}

/// The small features of the section `contours` (build-plane mm) for the correction's
/// move `shift_px` on a field `height_px` rows high: outer contours (with their holes)
/// with 2A/P < 2·(s* + 4σ) px. The contours flagged in `backwards` (if any) run
/// backwards (a defective mesh's shell): their outlines run clockwise, their holes not.
pub fn small_features(
    model: &CureModel,
    (contours, backwards): (&[Contour], &[bool]),
    height_px: f64,
    shift_px: f64,
) -> Vec<SmallFeature> {
    let p = model.pixel_mm;
    let limit_mm = 2.0 * (shift_px.max(0.0) + 4.0 * model.sigma_px) * p;
    let turned = |k: usize| backwards.get(k) == Some(&true);
    let areas: Vec<f64> = (contours.iter().enumerate())
        .map(|(k, c)| [1.0, -1.0][usize::from(turned(k))] * signed_area(c))
        .collect();
    let lengths: Vec<f64> = contours.iter().map(perimeter).collect();
    let boxes: Vec<[f64; 4]> = contours.iter().map(|c| bounds([c])).collect();
    // Each hole's outer contour: the smallest one around its first point.
    let mut area = areas.clone();
    let mut length = lengths.clone();
    let mut holes: Vec<Vec<usize>> = vec![Vec::new(); contours.len()];
    for (h, c) in contours.iter().enumerate() {
        if areas[h] >= 0.0 || c.is_empty() {
            continue;
        }
        let q = c[0];
        let owner = (0..contours.len())
            .filter(|&o| areas[o] > 0.0 && inside_box(&boxes[o], q) && inside(&contours[o], q))
            .min_by(|&a, &b| areas[a].total_cmp(&areas[b]));
        if let Some(o) = owner {
            area[o] += areas[h];
            length[o] += lengths[h];
            holes[o].push(h);
        }
    }
    let mut out = Vec::new();
    for (o, c) in contours.iter().enumerate() {
        if areas[o] <= 0.0 || length[o] <= 0.0 || 2.0 * area[o] / length[o] >= limit_mm {
            continue;
        }
        let b = boxes[o];
        let floor = |x: f64| x.max(0.0) as usize;
        let pixels = PixelBox {
            c0: floor(b[0] / p),
            c1: floor(b[2] / p) + 1,
            r0: floor(height_px - b[3] / p),
            r1: floor(height_px - b[1] / p) + 1,
        };
        let wall_mm = thin_part(2.0 * area[o] / length[o], &b, !holes[o].is_empty());
        let mut list = vec![o];
        list.extend(&holes[o]);
        out.push(SmallFeature {
            contours: list,
            at: super::predict::contour_box(c),
            wall_mm,
            pixels,
            backwards: turned(o),
        });
    }
    out
}

/// [`SmallFeature::wall_mm`] of a feature of width `wall` = 2A/P and box `b`.
fn thin_part(wall: f64, b: &[f64; 4], holes: bool) -> f64 {
    let thinner = wall < 0.5 * (b[2] - b[0]).min(b[3] - b[1]);
    if holes || thinner {
        wall
    } else {
        0.0
    }
}

/// Margin around a feature's pixels that widening may touch, px.
fn margin_px(shift_px: f64) -> usize {
    (std::f64::consts::FRAC_1_SQRT_2 + shift_px.abs() + MAX_OUT_PX).ceil() as usize + 1
}

/// The neighbourhood of a feature's pixels that [`widen`] may change, inside the field.
fn neighbourhood(f: &SmallFeature, shift_px: f64, width: usize, height: usize) -> PixelBox {
    let m = margin_px(shift_px);
    PixelBox {
        r0: f.pixels.r0.saturating_sub(m),
        r1: (f.pixels.r1 + m).min(height),
        c0: f.pixels.c0.saturating_sub(m),
        c1: (f.pixels.c1 + m).min(width),
    }
}

/// The uncorrected coverage of the small features' neighbourhoods, taken before the
/// correction changes the mask.
pub struct Uncorrected {
    boxes: Vec<(PixelBox, Vec<u8>)>,
    /// The same boxes, each pixel at most the coverage of the layers below given to
    /// [`Uncorrected::hold_back`] (none given: `None`).
    held: Option<Vec<Vec<u8>>>,
}

impl Uncorrected {
    /// Copies the neighbourhoods of `features` from the exact coverage `mask`.
    pub fn take(mask: &Mask, features: &[SmallFeature], shift_px: f64) -> Uncorrected {
        let (w, h) = (mask.width as usize, mask.height as usize);
        let boxes = features
            .iter()
            .map(|f| {
                let b = neighbourhood(f, shift_px, w, h);
                let mut v = Vec::with_capacity((b.r1 - b.r0) * (b.c1 - b.c0));
                for r in b.rows() {
                    v.extend_from_slice(&mask.data[r * w..][b.cols()]);
                }
                (b, v)
            })
            .collect();
        Uncorrected { boxes, held: None }
    }

    /// Lowers each saved pixel's held-back copy to at most `below`'s coverage (the Z
    /// correction's minimum over the held-back layers below).
    pub fn hold_back(&mut self, below: &Mask) {
        let w = below.width as usize;
        let held = self
            .held
            .get_or_insert_with(|| self.boxes.iter().map(|b| b.1.clone()).collect());
        for ((b, _), h) in self.boxes.iter().zip(held.iter_mut()) {
            let bw = b.c1 - b.c0;
            for r in b.rows() {
                let row = &below.data[r * w..][b.cols()];
                for (v, &l) in h[(r - b.r0) * bw..][..bw].iter_mut().zip(row) {
                    *v = (*v).min(l);
                }
            }
        }
    }

    /// Whether feature `k` is held back: the held-back layers below take more than half
    /// of its uncorrected coverage.
    pub fn held_back(&self, k: usize) -> bool {
        let Some(held) = &self.held else {
            return false;
        };
        let exact: u64 = self.boxes[k].1.iter().map(|&v| v as u64).sum();
        let kept: u64 = held[k].iter().map(|&v| v as u64).sum();
        2 * kept < exact
    }
}

/// Draws the small `features` of the section `contours` whose predicted peak light in
/// the corrected coverage `mask` (lit box `lit`) is below T·(1 + [`MARGIN`]) back to
/// their uncorrected coverage (`saved`, from [`Uncorrected::take`]) and then wider, as
/// the module describes; T = `threshold`, the layer's own light at which a feature that
/// the layers above repeat cures. A feature `saved` finds held back
/// ([`Uncorrected::held_back`]) is left as it is, and so is one that `rests` says rests
/// on nothing: given the mask indices of the feature's pixels (those within 0.75 px of
/// it), whether the layer below has material in any of them (a feature widened over
/// nothing would cure loose; no support reaches it, as the sections do not light it).
/// `shift_px`: the correction's largest inward move.
#[allow(clippy::too_many_arguments)]
pub fn widen(
    model: &CureModel,
    mask: &mut Mask,
    lit: PixelBox,
    contours: &[Contour],
    features: &[SmallFeature],
    saved: &Uncorrected,
    shift_px: f64,
    threshold: f64,
    rests: &mut dyn FnMut(&[usize]) -> bool,
) -> Widening {
    let psf = Psf {
        sigma_px: model.sigma_px,
    };
    let table = AxisTable::new(&psf);
    let t = threshold;
    let goal = t * (1.0 + MARGIN);
    let w = mask.width as usize;
    let mut out = Widening {
        lit,
        ..Widening::default()
    };
    let reach = std::f64::consts::FRAC_1_SQRT_2 + shift_px.max(0.0) + MAX_OUT_PX;
    let within = within_section_box(contours, model.pixel_mm, mask.height as f64);
    for (k, f) in features.iter().enumerate() {
        if saved.held_back(k) {
            continue;
        }
        let (nb, orig) = (&saved.boxes[k].0, &saved.boxes[k].1);
        let mut own: Vec<Contour> = f.contours.iter().map(|&c| contours[c].clone()).collect();
        if f.backwards {
            own.iter_mut().for_each(|c| c.reverse());
        }
        let segs = Segments::simplified(&own, model.pixel_mm, mask.height as f64, 0.01);
        // The pixels near the feature's edges: index in the mask, in the box, the edge's
        // normal and the centre's signed distance outside its line.
        let mut band: Vec<(usize, usize, [f64; 2], f64)> = Vec::new();
        nearest_edges(
            &segs,
            (*nb, usize::MAX),
            |_| reach,
            |(r, c, i), _| {
                let s = &segs.segs[i];
                let sd = (c as f64 + 0.5 - s.a[0]) * s.n[0] + (r as f64 + 0.5 - s.a[1]) * s.n[1];
                let j = (r - nb.r0) * (nb.c1 - nb.c0) + (c - nb.c0);
                if within.rows().contains(&r) && within.cols().contains(&c) {
                    band.push((r * w + c, j, s.n, sd));
                }
            },
        );
        let probes: Vec<[f64; 2]> = band
            .iter()
            .filter(|b| b.3 < 0.75)
            .map(|b| [(b.0 % w) as f64 + 0.5, (b.0 / w) as f64 + 0.5])
            .collect();
        let peak = |m: &Mask| peak_light(m, &psf, &table, &probes);
        if probes.is_empty() || peak(mask) >= goal {
            continue;
        }
        let pixels: Vec<usize> = band.iter().filter(|b| b.3 < 0.75).map(|b| b.0).collect();
        if !rests(&pixels) {
            out.on_nothing += 1;
            out.first_on_nothing = out.first_on_nothing.or(Some(f.at));
            continue;
        }
        let corrected: Vec<u8> = band.iter().map(|b| mask.data[b.0]).collect();
        let steps = (MAX_OUT_PX / STEP_PX).round() as usize;
        let mut reached = 0.0;
        for i in 0..=steps {
            let d = i as f64 * STEP_PX;
            for (b, &cv) in band.iter().zip(&corrected) {
                let (n, sd) = (b.2, b.3);
                // Pixels the feature moved out by d does not reach keep their value (a
                // neighbour's corrected coverage).
                if sd - d >= 0.7072 {
                    continue;
                }
                let delta = halfplane_coverage(n, -(sd - d)) - halfplane_coverage(n, -sd);
                let v = super::round_to_u8(orig[b.1] as f64 + 255.0 * delta);
                mask.data[b.0] = v.max(cv);
            }
            reached = peak(mask);
            if reached >= goal {
                break;
            }
        }
        if reached >= t {
            out.widened += 1;
            if out.first.is_none() {
                out.first = Some(f.at);
                out.first_wall_mm = f.wall_mm;
            }
            for b in &band {
                if mask.data[b.0] > 0 {
                    let (r, c) = (b.0 / w, b.0 % w);
                    let l = &mut out.lit;
                    if l.r0 >= l.r1 || l.c0 >= l.c1 {
                        *l = PixelBox {
                            r0: r,
                            r1: r + 1,
                            c0: c,
                            c1: c + 1,
                        };
                    }
                    l.r0 = l.r0.min(r);
                    l.r1 = l.r1.max(r + 1);
                    l.c0 = l.c0.min(c);
                    l.c1 = l.c1.max(c + 1);
                }
            }
        } else {
            out.failed += 1;
            for (b, &cv) in band.iter().zip(&corrected) {
                mask.data[b.0] = cv;
            }
        }
    }
    out
}

/// The pixels within [`BOX_SLACK_PX`] of the bounding box of the section `contours`
/// (build-plane mm) on a field `height_px` rows high: the most a widened feature may
/// light (the executor checks that a mask lights nothing more than 1 px outside the
/// section's box, which the record holds rounded to 1 µm).
pub fn within_section_box(contours: &[Contour], pixel_mm: f64, height_px: f64) -> PixelBox {
    let b = bounds(contours);
    if b[0] > b[2] {
        return PixelBox::EMPTY;
    }
    let s = BOX_SLACK_PX;
    let lo = |x: f64| (x - s).ceil().max(0.0) as usize;
    let hi = |x: f64| (x + s).floor().max(0.0) as usize;
    PixelBox {
        c0: lo(b[0] / pixel_mm),
        c1: hi(b[2] / pixel_mm),
        r0: lo(height_px - b[3] / pixel_mm),
        r1: hi(height_px - b[1] / pixel_mm),
    }
}

/// How far outside the section's bounding box a widened feature may light pixels, px.
pub const BOX_SLACK_PX: f64 = 0.95;

/// The largest light over `probes` (field pixel coordinates), refined around the best one
/// by steps of 1/4, 1/8 and 1/16 px in the 8 directions.
fn peak_light(mask: &Mask, psf: &Psf, table: &AxisTable, probes: &[[f64; 2]]) -> f64 {
    let w = mask.width as usize;
    let light = |p: [f64; 2]| super::predict::light(&mask.data, w, psf, table, p) / 255.0;
    let (mut best, mut at) = (f64::NEG_INFINITY, [0.0; 2]);
    for &p in probes {
        let l = light(p);
        if l > best {
            (best, at) = (l, p);
        }
    }
    for step in [0.25, 0.125, 0.0625] {
        loop {
            let mut moved = false;
            for (dx, dy) in [
                (1.0, 0.0),
                (-1.0, 0.0),
                (0.0, 1.0),
                (0.0, -1.0),
                (1.0, 1.0),
                (1.0, -1.0),
                (-1.0, 1.0),
                (-1.0, -1.0),
            ] {
                let p = [at[0] + dx * step, at[1] + dy * step];
                let l = light(p);
                if l > best {
                    (best, at, moved) = (l, p, true);
                }
            }
            if !moved {
                break;
            }
        }
    }
    best
}

fn perimeter(c: &Contour) -> f64 {
    (0..c.len())
        .map(|i| {
            let (a, b) = (c[i], c[(i + 1) % c.len()]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            // (`sqrt` of the sum rather than libm's slower `hypot`: lengths of mm.)
            (dx * dx + dy * dy).sqrt()
        })
        .sum()
}

fn inside_box(b: &[f64; 4], q: [f64; 2]) -> bool {
    b[0] <= q[0] && q[0] <= b[2] && b[1] <= q[1] && q[1] <= b[3]
}

/// Even-odd point in polygon.
fn inside(c: &Contour, q: [f64; 2]) -> bool {
    let mut inside = false;
    for i in 0..c.len() {
        let (a, b) = (c[i], c[(i + 1) % c.len()]);
        if (a[1] > q[1]) != (b[1] > q[1]) {
            let x = a[0] + (q[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if q[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::Profile;
    use crate::raster::{Rasterizer, Scratch};

    /// [`super::super::edge_shift_px`] of `model`.
    fn prism_shift(model: &CureModel) -> f64 {
        let psf = Psf {
            sigma_px: model.sigma_px,
        };
        super::super::edge_shift_px(model, &crate::cure::shift::EdgeProfile::new(&psf))
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Contour {
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    /// The section drawn with the plain correction and with the widening, the widening's
    /// report, and the peak light of each over the given pixel centres' neighbourhood.
    fn drawn(section: &[Contour]) -> (Mask, Mask, Widening, CureModel) {
        drawn_on(section, None)
    }

    /// As [`drawn`], over the section `below` (`None`: on the platform).
    fn drawn_on(
        section: &[Contour],
        below: Option<&[Contour]>,
    ) -> (Mask, Mask, Widening, CureModel) {
        let profile = Profile::default_profile();
        let model = CureModel::from_profile(&profile).expect("the default profile has a PSF");
        let raster = Rasterizer::new(profile.field());
        let shift = prism_shift(&model);
        let mut scratch = Scratch::default();
        let mut m = raster.coverage(section, &mut scratch);
        let lit = scratch.lit_box();
        let h = m.height as f64;
        let small = small_features(&model, (section, &[]), h, shift);
        let saved = Uncorrected::take(&m, &small, shift);
        let segs = Segments::simplified(section, model.pixel_mm, h, 0.01);
        let shifts = super::super::shift::EdgeShifts::uniform(&segs, shift);
        super::super::correct_coverage(&mut m, lit, &segs, &shifts, lit);
        let plain = m.clone();
        let t = model.edge_threshold();
        let under = below.map(|b| raster.coverage(b, &mut Scratch::default()));
        let mut rests = |px: &[usize]| {
            assert!(!px.is_empty());
            under
                .as_ref()
                .is_none_or(|u| px.iter().any(|&k| u.data[k] > 0))
        };
        let wd = widen(
            &model, &mut m, lit, section, &small, &saved, shift, t, &mut rests,
        );
        (plain, m, wd, model)
    }

    /// The largest light of `m` on a 0.05 px grid over the box [u0, u1] × [v0, v1] (px).
    fn grid_peak(model: &CureModel, m: &Mask, u: [f64; 2], v: [f64; 2]) -> f64 {
        let psf = Psf {
            sigma_px: model.sigma_px,
        };
        let table = AxisTable::new(&psf);
        let mut best = 0.0f64;
        let (nu, nv) = (
            ((u[1] - u[0]) / 0.05) as usize,
            ((v[1] - v[0]) / 0.05) as usize,
        );
        for i in 0..=nu {
            for j in 0..=nv {
                let p = [u[0] + 0.05 * i as f64, v[0] + 0.05 * j as f64];
                best = best.max(
                    super::super::predict::light(&m.data, m.width as usize, &psf, &table, p)
                        / 255.0,
                );
            }
        }
        best
    }

    #[test]
    fn a_thin_wall_the_plain_correction_starves_cures_widened() {
        let p = Profile::default_profile().field().pixel_mm;
        // A wall 0.7 px wide and 40 px long at a fraction of a pixel, beside a block.
        let (x0, y0) = (300.37 * p, 200.2 * p);
        let wall = rect(x0, y0, x0 + 0.7 * p, y0 + 40.0 * p);
        let block = rect(100.0 * p, 100.0 * p, 160.0 * p, 160.0 * p);
        let (plain, wide, wd, model) = drawn(&[block, wall]);
        let t = model.edge_threshold();
        let rows = 768.0;
        let (u, v) = ([299.0, 302.5], [rows - 230.0, rows - 210.0]);
        let before = grid_peak(&model, &plain, u, v);
        let after = grid_peak(&model, &wide, u, v);
        assert!(
            before < t,
            "the plain correction cures it: {before} vs T {t}"
        );
        assert!(after >= t, "widened, it does not cure: {after} vs T {t}");
        assert_eq!(wd.widened, 1, "{wd:?}");
        assert_eq!(wd.failed, 0, "{wd:?}");
        let f = wd.first.expect("the wall is named");
        assert!((f.width_mm - 0.7 * p).abs() < 2e-3, "{f:?}");
        // The block is left as the correction drew it.
        for r in 600..680 {
            for c in 90..170 {
                assert_eq!(plain.get(c, r), wide.get(c, r), "({c}, {r})");
            }
        }
    }

    #[test]
    fn a_pin_over_nothing_is_not_widened_and_one_on_a_block_is() {
        let p = Profile::default_profile().field().pixel_mm;
        let (x0, y0) = (400.6 * p, 300.1 * p);
        let pin = rect(x0, y0, x0 + 0.05, y0 + 0.05);
        let under = rect(x0 - 0.2, y0 - 0.2, x0 + 0.2, y0 + 0.2);
        let aside = rect(x0 + 1.0, y0, x0 + 2.0, y0 + 1.0);
        let (_, wide, wd, _) = drawn_on(std::slice::from_ref(&pin), Some(&[under]));
        assert_eq!((wd.widened, wd.on_nothing), (1, 0), "{wd:?}");
        let (plain, kept, wd, _) = drawn_on(std::slice::from_ref(&pin), Some(&[aside]));
        assert_eq!((wd.widened, wd.failed, wd.on_nothing), (0, 0, 1), "{wd:?}");
        let at = wd.first_on_nothing.expect("named");
        assert!((at.x_mm - (x0 + 0.025)).abs() < 1e-3, "{at:?}");
        assert_eq!(plain, kept);
        assert_ne!(plain, wide);
    }

    #[test]
    fn a_pin_under_a_pixel_cures_widened() {
        let p = Profile::default_profile().field().pixel_mm;
        let (x0, y0) = (400.6 * p, 300.1 * p);
        let pin = rect(x0, y0, x0 + 0.05, y0 + 0.05);
        let (plain, wide, wd, model) = drawn(&[pin]);
        let t = model.edge_threshold();
        let (u, v) = ([399.0, 403.0], [768.0 - 303.0, 768.0 - 299.0]);
        assert!(grid_peak(&model, &plain, u, v) < t);
        let after = grid_peak(&model, &wide, u, v);
        assert!(after >= t, "{after} vs T {t}");
        assert!(
            after < t * (1.0 + MARGIN) + 0.1,
            "widened further than needed: {after}"
        );
        assert_eq!(wd.widened, 1, "{wd:?}");
    }

    #[test]
    fn a_pin_that_would_not_cure_uncorrected_is_drawn_wider_than_its_section() {
        let profile = Profile::default_profile();
        let p = profile.field().pixel_mm;
        // 0.3 px square: uncorrected its light peaks near 0.05, a quarter of T. Two
        // blocks make the layer's box larger than the pin's.
        let (x0, y0) = (400.6 * p, 300.1 * p);
        let pin = rect(x0, y0, x0 + 0.3 * p, y0 + 0.3 * p);
        let low = rect(100.0 * p, 100.0 * p, 120.0 * p, 120.0 * p);
        let high = rect(500.0 * p, 400.0 * p, 520.0 * p, 420.0 * p);
        let exact = Rasterizer::new(profile.field())
            .coverage(std::slice::from_ref(&pin), &mut Scratch::default());
        let (plain, wide, wd, model) = drawn(&[low, pin, high]);
        let t = model.edge_threshold();
        let (u, v) = ([399.0, 403.0], [768.0 - 303.0, 768.0 - 299.0]);
        assert!(grid_peak(&model, &exact, u, v) < 0.5 * t);
        let after = grid_peak(&model, &wide, u, v);
        assert!(after >= t, "{after} vs T {t}");
        assert_eq!(wd.widened, 1, "{wd:?}");
        // Lit beyond the pin's pixel, within the 1 px bound; the blocks as corrected.
        let near =
            |c: u32, r: u32| (398..=402).contains(&c) && (768 - 303..=768 - 299).contains(&r);
        let lit_near = |m: &Mask| {
            (0..768u32)
                .flat_map(|r| (0..1024u32).map(move |c| (c, r)))
                .filter(|&(c, r)| near(c, r) && m.get(c, r) > 0)
                .count()
        };
        assert!(
            lit_near(&wide) > lit_near(&exact),
            "{} vs {}",
            lit_near(&wide),
            lit_near(&exact)
        );
        for r in 0..768u32 {
            for c in 0..1024u32 {
                assert!(
                    near(c, r) || wide.get(c, r) == plain.get(c, r),
                    "({c}, {r})"
                );
            }
        }
    }

    #[test]
    fn wide_features_and_narrow_ones_that_cure_are_not_changed() {
        let p = Profile::default_profile().field().pixel_mm;
        // A 30 px square is not small; a 3 px pin is small but cures corrected.
        let square = rect(100.3 * p, 100.6 * p, 130.3 * p, 130.6 * p);
        let pin = rect(200.3 * p, 100.6 * p, 203.3 * p, 103.6 * p);
        let model = CureModel::from_profile(&Profile::default_profile()).unwrap();
        let shift = prism_shift(&model);
        let small = small_features(&model, (&[square.clone(), pin.clone()], &[]), 768.0, shift);
        assert_eq!(small.len(), 1);
        assert_eq!(small[0].contours, vec![1]);
        let (plain, wide, wd, _) = drawn(&[square, pin]);
        assert_eq!(plain.data, wide.data);
        assert_eq!(wd.widened + wd.failed, 0, "{wd:?}");
    }

    #[test]
    fn a_thin_ring_is_small_with_its_hole() {
        let p = Profile::default_profile().field().pixel_mm;
        let outer = rect(100.0 * p, 100.0 * p, 160.0 * p, 160.0 * p);
        let mut hole = rect(101.0 * p, 101.0 * p, 159.0 * p, 159.0 * p);
        hole.reverse();
        let model = CureModel::from_profile(&Profile::default_profile()).unwrap();
        let shift = prism_shift(&model);
        let small = small_features(&model, (&[outer.clone(), hole], &[]), 768.0, shift);
        assert_eq!(small.len(), 1);
        assert_eq!(small[0].contours, vec![0, 1]);
        assert!(small_features(&model, (&[outer], &[]), 768.0, shift).is_empty());
    }
}
