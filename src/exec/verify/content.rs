//! What a layer's masks must show against its record.
//!
//! A mask is a top view of the build plane: build-plane point (x, y), measured in mm from
//! the field's bottom-left corner, lands in field column ⌊x/p⌋ and row H − 1 − ⌊y/p⌋ (p
//! the pixel edge, H the field's height in pixels); projector k shows field columns
//! `offset_px[0]..+width_px` and rows `offset_px[1]..+height_px`, mirrored last by its
//! `mirror_x`/`mirror_y`. A mask pixel is nonzero only where the section covers part of
//! it: anti-aliased coverage, binary masks (≥ 50 % coverage), compensated grays and tiled
//! shares all keep zero at zero. So per layer, with the lit boxes of its masks mapped into
//! the field and united (tiled projectors each light their share), `mask-content` is
//! reported when
//! * the layer has no section (`bbox_mm` null, `area_mm2` 0) and its masks light any
//!   pixel;
//! * lit pixels lie outside `bbox_mm` (converted to field pixels) by more than the
//!   tolerance: 1 px, plus `settings.distortion.max_correction_mm`/p + 1 px when the
//!   masks were pre-warped (a record with an area but no `bbox_mm`, from a bundle written
//!   before the box was recorded, is checked for its area only);
//! * the masks light too few pixels for the section. For masks whose values are coverage
//!   (anti-aliased, light compensation off, linear tiled responses) every pixel the
//!   section covers by 1/510 or more is lit, so at least 0.5 × `area_mm2`/p² − 4 pixels,
//!   and one for an area of a pixel or more. In every mode the pixels wholly inside the
//!   section's largest inscribed circle (radius `max_fill_distance_mm`, less the
//!   pre-warp's tolerance) are fully covered and lit: at least max(1, π(r/p − √2)²) of
//!   them once r ≥ √2·p, spanning 2(r/p − √2) px across. With the cure correction both
//!   rules shrink by the farthest it may move an edge in ([`inward_px`]).
//!
//! With the Z correction (`cure.held_back_layers` > 0) a layer's masks light only what the
//! layers below it also hold, so the last rule is not applied to such jobs.
//!
//! The lit box may fall short of `bbox_mm` by any amount: a sliver of the section thinner
//! than 1/510 of a pixel shows as 0, binary masks leave pixels below 50 % coverage dark
//! and compensated ones those below the lowest usable gray (thin walls, tips, a shorter
//! feature's top).

use super::{box_text, problem};
use crate::bundle::machine::Machine;
use crate::bundle::{BundleSource, Layer, Manifest, MaskPixels, MaskRef};
use crate::cure::shift::EdgeProfile;
use crate::exec::{Kind, Violation};
use crate::text::{count as count_of, number};

/// Lit pixels a section's masks may miss below half its area (coverage masks), px².
const AREA_SLACK_PX: f64 = 4.0;
/// How far the grays of coverage masks may add up from the recorded area (written to 9
/// significant digits), relative.
const AREA_REL_TOL: f64 = 1e-8;

/// How a job's masks must agree with its layer records (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ContentRule {
    /// Pixel edge, mm.
    pixel_mm: f64,
    /// Field height, px.
    field_h_px: f64,
    /// How far the lit box may pass the section's box, px.
    tol_px: f64,
    /// How far the pre-warp may move the section, mm (0 without).
    warp_mm: f64,
    /// Mask values are coverage: every pixel the section covers noticeably is lit.
    coverage: bool,
    /// The Z correction held back downward-facing surfaces (`cure.held_back_layers` > 0):
    /// a layer's masks may light less than its section, down to nothing.
    held_back: bool,
    /// The grays add up to the section's area exactly: coverage masks of one projector,
    /// neither pre-warped nor moved by the cure correction, in a job dmdsl sliced from a
    /// mesh (an imported job's areas are its importer's estimates, also once exported to a
    /// bundle).
    exact_area: bool,
    /// Binary masks of one projector without compensation: every lit pixel is 255.
    binary: bool,
    /// How far the cure correction may move the edges in, px (0 without it).
    shift_px: f64,
}

/// How far the cure correction `c` may move an edge in, px: its closed-form shift, or, where
/// the layers above's print-through cures the section's edge (a thin first layer under
/// thicker ones), as far as the layer's own light at the edge falls to nothing
/// ([`EdgeProfile::inward_limit_px`]).
fn inward_px(c: &crate::bundle::Cure) -> f64 {
    let psf = crate::cure::Psf {
        sigma_px: c.psf_sigma_px,
    };
    let limit = (c.psf_sigma_px > 0.0).then(|| EdgeProfile::new(&psf).inward_limit_px());
    c.shift_px.max(limit.unwrap_or(0.0)).max(0.0)
}

/// The layer's largest inscribed circle's radius, mm (0 when the job does not know it:
/// no pixel is then required lit by it).
fn fill_mm(layer: &Layer) -> f64 {
    layer.max_fill_distance_mm.unwrap_or(0.0)
}

impl ContentRule {
    /// The rule for `manifest`'s masks shown by `machine`; `native`: a job dmdsl sliced.
    pub(super) fn of(manifest: &Manifest, machine: &Machine, native: bool) -> ContentRule {
        let field = machine.field();
        let p = field.pixel_mm;
        let warp_mm = manifest
            .settings
            .distortion
            .as_ref()
            .map_or(0.0, |d| d.max_correction_mm.max(0.0) + p);
        let (made, s) = (&manifest.machine, &manifest.settings);
        let linear =
            made.projector.len() <= 1 || made.projector.iter().all(|p| p.calibration.is_none());
        let coverage = !s.binary && s.compensation == "off" && linear;
        let one = made.projector.len() == 1;
        let corrected = manifest
            .cure
            .as_ref()
            .is_some_and(|c| c.correction != "off");
        ContentRule {
            pixel_mm: p,
            field_h_px: field.height_px as f64,
            // The cure correction moves edges by up to a pixel either way (in, and out
            // where it widens what would not cure), so a corrected mask may light a pixel
            // beyond the section's box.
            tol_px: 1.0 + warp_mm / p + if corrected { 1.0 } else { 0.0 },
            warp_mm,
            coverage,
            held_back: manifest
                .cure
                .as_ref()
                .is_some_and(|c| c.held_back_layers > 0),
            exact_area: native
                && manifest.source.triangles > 0
                && coverage
                && one
                && !corrected
                && s.distortion.is_none(),
            binary: s.binary && s.compensation == "off" && one,
            shift_px: manifest
                .cure
                .as_ref()
                .filter(|_| corrected)
                .map_or(0.0, inward_px),
        }
    }

    /// The fewest lit pixels the masks of `layer` may have.
    fn min_lit(&self, layer: &Layer) -> f64 {
        let p = self.pixel_mm;
        let area_px = layer.area_mm2 / (p * p);
        let mut min: f64 = 0.0;
        if layer.area_mm2 <= 0.0 || self.held_back {
            // No section: nothing must be lit. Held back (`xyz`): a layer over nothing
            // lights only what its layers below also hold, possibly nothing.
            return min;
        }
        if self.coverage {
            if area_px >= 1.0 {
                min = 1.0;
            }
            // Edges moved in by the cure correction shrink a section whose largest
            // inscribed circle has radius r by up to ((r − shift) / r)² (a layer of small
            // round features, such as support heads, the most).
            let r = fill_mm(layer) / p;
            let shrink = if self.shift_px > 0.0 && r > 0.0 {
                ((r - self.shift_px).max(0.0) / r).powi(2)
            } else {
                1.0
            };
            min = min.max(0.5 * area_px * shrink - AREA_SLACK_PX);
        }
        // Pixels wholly inside the largest inscribed circle (less the correction's move)
        // are fully covered.
        let r = (fill_mm(layer) - self.warp_mm) / p - self.shift_px;
        if r >= std::f64::consts::SQRT_2 {
            let inner = self.inner_radius_px(layer);
            min = min.max((std::f64::consts::PI * inner * inner).max(1.0));
        }
        min
    }

    /// The radius of the circle, concentric with the section's largest inscribed circle
    /// (moved by the pre-warp, shrunk by the cure correction), whose every pixel lies wholly
    /// inside the section, px (0 when there is none).
    fn inner_radius_px(&self, layer: &Layer) -> f64 {
        let r = (fill_mm(layer) - self.warp_mm) / self.pixel_mm - self.shift_px;
        (r - std::f64::consts::SQRT_2).max(0.0)
    }

    /// Checks layer `i`'s masks, whose lit pixels in field coordinates are `px`.
    pub(super) fn check(
        &self,
        dir: &dyn BundleSource,
        i: usize,
        layer: &Layer,
        px: MaskPixels,
        masks: &[&MaskRef],
    ) -> Option<Violation> {
        let file = masks.first()?.file.as_str();
        let files: Vec<&str> = masks.iter().map(|m| m.file.as_str()).collect();
        let shown = format!("{}", dir.shown(&files.join(", ")).display());
        let at = |msg: String| {
            let message = format!("{shown}: layer {i}: {msg}");
            Some(problem(Some(i), Kind::MaskContent, Some(file), message))
        };
        let lit_text = |b| box_text(Some(b));
        let (count, area) = (px.lit_px, layer.area_mm2);
        if let (None, true, Some(b)) = (layer.bbox_mm, area <= 0.0, px.lit_box_px) {
            let lit = lit_text(b);
            return at(format!("the layer has no section (bbox_mm null) but its masks light {} ({lit} of the field)", count_of(count, "pixel", "pixels")));
        }
        let min = self.min_lit(layer);
        let Some(b) = px.lit_box_px else {
            if min < 1.0 && !(self.exact_area && area > 0.0) {
                return None;
            }
            return at(format!(
                "the section's area is {area:.3} mm² but its masks light no pixel"
            ));
        };
        let p = self.pixel_mm;
        let got = b.map(f64::from);
        // A section's box (bundles written before it was recorded have an area but none).
        if let Some(bb) = layer.bbox_mm {
            // The section's box in field pixel coordinates: columns x/p, rows H − y/p.
            let want = [
                bb[0][0] / p,
                self.field_h_px - bb[1][1] / p,
                bb[1][0] / p,
                self.field_h_px - bb[0][1] / p,
            ];
            let tol = self.tol_px + 1e-3;
            let outside = got[0] < want[0] - tol
                || got[1] < want[1] - tol
                || got[2] > want[2] + tol
                || got[3] > want[3] + tol;
            if outside {
                // The pixels the section's box touches.
                let touched = [
                    want[0].floor().max(0.0) as u32,
                    want[1].floor().max(0.0) as u32,
                    (want[2].ceil() as u32).max(1),
                    (want[3].ceil() as u32).max(1),
                ];
                let [[x0, y0], [x1, y1]] = bb.map(|c| c.map(number));
                let (lit, covers, tol) = (lit_text(b), lit_text(touched), self.tol_px);
                return at(format!("its masks light {lit} of the field, outside the section (bbox_mm [[{x0}, {y0}], [{x1}, {y1}]] covers {covers}; tolerance {tol:.1} px)"));
            }
        }
        // The pixels wholly inside the largest inscribed circle are lit: the lit box is at
        // least as wide and as high as the circle less a pixel diagonal on each side (not
        // when held back: the layers below may hold less of the section).
        let inner = 2.0 * (self.inner_radius_px(layer) - 1e-3);
        let (w, h) = (got[2] - got[0], got[3] - got[1]);
        if (w < inner || h < inner) && !self.held_back {
            let (lit, r) = (lit_text(b), number(fill_mm(layer)));
            return at(format!("its masks light {lit} of the field ({w}x{h} px), less than the section's largest inscribed circle (max_fill_distance_mm {r}) leaves lit ({inner:.1} px across)"));
        }
        if (count as f64) < min {
            let (lit_mm2, least) = (count as f64 * p * p, min.ceil());
            return at(format!("its masks light {} ({lit_mm2:.3} mm²), too few for the section's area {area:.3} mm² (at least {least:.0} expected)", count_of(count, "pixel", "pixels")));
        }
        let g = px.gray_sum;
        if self.binary && g != 255 * count {
            return at(format!("settings.binary is true, but its masks hold grays other than 0 and 255 ({}, gray sum {g})", count_of(count, "lit pixel", "lit pixels")));
        }
        let shown = g as f64 / 255.0 * p * p;
        if self.exact_area && (shown - area).abs() > AREA_REL_TOL * area {
            let (shown, area) = (crate::round::area_mm2(shown), crate::round::area_mm2(area));
            return at(format!("its grays add up to {shown} mm² (gray sum {g} / 255 × pixel area), but the section's area is {area} mm² (the values of coverage masks are the section's area)"));
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::super::{verify, Verification};
    use crate::bundle::{sha256_hex, Manifest, MaskRef};
    use crate::exec::testutil::manifest;

    /// Layers 0 to 10, each a case of what a mask may show of its section.
    fn content_cases(dir: &Scratch) -> Manifest {
        let white = gray_png(64, 48, |_, _| 255);
        let black = gray_png(64, 48, |_, _| 0);
        // A 20×10 px rectangle with anti-aliased (half-covered) edge pixels around it.
        let soft = gray_png(64, 48, |c, r| {
            let inside = |a: u32, lo: u32, hi: u32| (lo..hi).contains(&a);
            if inside(c, 10, 30) && inside(r, 5, 15) {
                255
            } else if inside(c, 9, 31) && inside(r, 4, 16) {
                128
            } else {
                0
            }
        });
        let section = Some([9.5, 4.5, 30.5, 15.5]);
        // What `soft` shows: 200 pixels full, 64 half.
        let area = 200.0 + 64.0 * 128.0 / 255.0;
        let cases = [
            (&soft, section, area),                   // 0: as sliced.
            (&white, section, area),                  // 1: all white.
            (&black, section, area),                  // 2: all black.
            (&soft, None, 0.0),                       // 3: no section, lit.
            (&black, None, 0.0),                      // 4: no section, dark: fine.
            (&lit_png(12, 6, 16, 10), section, area), // 5: a 4×4 px patch inside the box.
            // 6: another layer's mask, moved: lit 3 px right of the section.
            (&lit_png(13, 5, 34, 15), section, area),
            // 7: a sliver too small to show: dark is fine, but not with a lit area.
            (&black, Some([40.0, 40.0, 40.002, 41.0]), 0.002),
            // 8: lit within a pixel of the section's box: fine, but more than its area.
            (&lit_png(9, 4, 31, 16), section, area),
            // 9 and 10: an area but no box (bundles from before it was recorded): the
            // area is checked, the box cannot be.
            (&soft, None, area),
            (&black, None, area),
        ];
        let layers = cases.iter().enumerate();
        let layers = layers.map(|(i, &(png, bbox, area))| layer_with(dir, i, png, bbox, area));
        manifest(small_profile(), layers.collect())
    }

    #[test]
    fn masks_that_do_not_show_their_layer_are_found() {
        let dir = Scratch::new("content");
        let mut m = content_cases(&dir);
        let v = verify(&dir, &m);
        assert_eq!(
            found(&v),
            content(&[1, 2, 3, 5, 6, 7, 8, 10]),
            "{:#?}",
            v.problems
        );
        says(&v, 0, "masks/00001.png: layer 1: its masks light columns 0..63, rows 0..47 of the field, outside the section");
        says(&v, 0, "covers columns 9..30, rows 4..15");
        says(
            &v,
            1,
            "layer 2: the section's area is 0.935 mm² but its masks light no pixel",
        );
        says(
            &v,
            2,
            "layer 3: the layer has no section (bbox_mm null) but its masks light 264 pixels",
        );
        says(&v, 3, "layer 5: its masks light 16 pixels (0.064 mm²), too few for the section's area 0.935 mm² (at least 113 expected)");
        says(&v, 4, "layer 6: its masks light columns 13..33, rows 5..14");
        says(&v, 6, "layer 8: its grays add up to 1.06372833 mm² (gray sum 67320 / 255 × pixel area), but the section's area is 0.935297199 mm²");
        assert_eq!(v.problems[0].file.as_deref(), Some("masks/00001.png"));

        // Binary and compensated masks may leave thin parts dark: only the largest
        // inscribed circle's pixels must be lit.
        // Binary masks light 255 only.
        m.settings.binary = true;
        let v = verify(&dir, &m);
        assert_eq!(found(&v), content(&[0, 1, 3, 6, 9]), "{:#?}", v.problems);
        says(&v, 0, "layer 0: settings.binary is true, but its masks hold grays other than 0 and 255 (264 lit pixels, gray sum 59192)");
        // A section 11 px high holds a circle of 5.5 px: 4.1 px wholly lit around its centre.
        for l in &mut m.layers {
            l.max_fill_distance_mm = Some(5.5 * PX);
        }
        m.settings.binary = false;
        m.settings.compensation = "zone".into();
        let v = verify(&dir, &m);
        // Compensation without its record is a `settings` problem of the job.
        let mut want = vec![(None, crate::exec::Kind::Settings)];
        want.extend(content(&[1, 2, 3, 5, 6, 7, 10]));
        assert_eq!(found(&v), want, "{:#?}", v.problems);
        says(
            &v,
            4,
            "(4x4 px), less than the section's largest inscribed circle",
        );
    }

    /// The problems of one layer of section [`BOX`] whose mask is `png`, in a job changed
    /// by `f`.
    fn verify_one(dir: &Scratch, png: &[u8], f: impl FnOnce(&mut Manifest)) -> Verification {
        let mut m = manifest(small_profile(), vec![layer_with(dir, 0, png, BOX, 200.0)]);
        f(&mut m);
        verify(dir, &m)
    }

    /// A cure record of a job corrected with `correction`, `held` layers held back.
    fn cure_record(correction: &str, held: u32) -> crate::bundle::Cure {
        serde_json::from_value(serde_json::json!({
            "psf_sigma_px": 0.5, "pixel_mm": PX, "dp_mm": 0.15, "ec_mj_cm2": 10.0,
            "overcure_mm": 0.03, "layer_mm": 0.1, "edge_threshold": 0.2,
            "correction": correction, "shift_px": 0.49,
            "print_through_mm": 0.2, "held_back_layers": held
        }))
        .unwrap()
    }

    #[test]
    fn a_corrected_thin_strip_may_be_left_to_the_print_through_of_the_layers_above() {
        let dir = Scratch::new("strip");
        // A strip about 2.9 px wide (its inscribed circle 1.45 px in radius) lit at 4 px:
        // too few uncorrected, or moved in by the closed-form shift (0.49 px) alone, but
        // the correction may move its edges in until the layer's own light there falls to
        // nothing (1.46 px at σ = 0.5 px), where the layers above cure it.
        let few = lit_png(18, 8, 20, 10);
        let strip = |m: &mut Manifest, correction: &str| {
            m.layers[0].max_fill_distance_mm = Some(1.45 * PX);
            m.cure = Some(cure_record(correction, 0));
        };
        assert_eq!(
            found(&verify_one(&dir, &few, |m| strip(m, "off"))),
            content(&[0])
        );
        assert_eq!(found(&verify_one(&dir, &few, |m| strip(m, "xy"))), vec![]);
        let mut c = cure_record("xy", 0);
        c.psf_sigma_px = 0.0;
        let v = verify_one(&dir, &few, |m| {
            m.layers[0].max_fill_distance_mm = Some(1.45 * PX);
            m.cure = Some(c.clone());
        });
        assert_eq!(found(&v), content(&[0]), "without a PSF: the shift alone");
    }

    #[test]
    fn held_back_layers_may_light_less_than_their_section() {
        let dir = Scratch::new("held");
        // A section of 200 px whose mask lights nothing: the first layer of an overhang
        // the Z correction holds back.
        let dark = gray_png(64, 48, |_, _| 0);
        let cure = |held: u32| Some(cure_record(if held > 0 { "xyz" } else { "xy" }, held));
        assert_eq!(found(&verify_one(&dir, &dark, |_| {})), content(&[0]));
        assert_eq!(
            found(&verify_one(&dir, &dark, |m| m.cure = cure(0))),
            content(&[0])
        );
        assert_eq!(
            found(&verify_one(&dir, &dark, |m| m.cure = cure(4))),
            vec![]
        );
        // Lit over less than the section's largest inscribed circle (a section 10 px high
        // holds a circle of 5 px; 4 × 4 px lit): what the layers below hold.
        let small = lit_png(18, 8, 22, 12);
        let inscribed = |m: &mut Manifest, held: u32| {
            m.layers[0].max_fill_distance_mm = Some(5.0 * PX);
            m.cure = cure(held);
        };
        assert_eq!(
            found(&verify_one(&dir, &small, |m| inscribed(m, 0))),
            content(&[0])
        );
        assert_eq!(
            found(&verify_one(&dir, &small, |m| inscribed(m, 4))),
            vec![]
        );
        // Light outside the section's box is still found.
        let outside = lit_png(40, 5, 50, 15);
        assert_eq!(
            found(&verify_one(&dir, &outside, |m| m.cure = cure(4))),
            content(&[0])
        );
    }

    #[test]
    fn pre_warped_masks_may_move_by_the_largest_correction() {
        let dir = Scratch::new("warp");
        // Lit 3 px right of the section: beyond 1 px, within 1 + 0.1 mm / p + 1 = 3.6 px.
        let moved = lit_png(13, 5, 33, 15);
        assert_eq!(found(&verify_one(&dir, &moved, |_| {})), content(&[0]));
        let fit: crate::bundle::FitReport = serde_json::from_value(serde_json::json!({
            "source": "lens.csv", "sha256": "", "points": 9, "degree": 2,
            "residual_weight": 0.0, "poly_rms_mm": 0.0, "poly_max_mm": 0.0,
            "poly_max_at": "", "cv_rms_mm": 0.0, "cv_max_mm": 0.0, "cv_max_at": "",
            "max_correction_mm": 0.1, "extrapolated_points": 0
        }))
        .unwrap();
        let v = verify_one(&dir, &moved, |m| m.settings.distortion = Some(fit));
        assert_eq!(found(&v), vec![]);
    }

    #[test]
    fn tiled_masks_show_their_share_of_the_layer() {
        let dir = Scratch::new("tiled");
        std::fs::create_dir_all(dir.join("masks/p1")).unwrap();
        // Two 32×48 projectors side by side, the second mirrored in x; the section spans
        // columns 20..44 of the 64 px field.
        let mut p = small_profile();
        p.projector[0].width_px = 32;
        let mut p1 = p.projector[0].clone();
        p1.name = "p1".into();
        p1.offset_px = [32, 0];
        p1.mirror_x = true;
        p.projector.push(p1);
        // Field columns 32..44 are projector columns 20..32 once mirrored.
        let share = gray_png(32, 48, rect(20, 10, 32, 20, 255));
        let mut l = layer_with(&dir, 0, &share, Some([20.0, 10.0, 44.0, 20.0]), 240.0);
        let (file, sha256) = ("masks/p1/00000.png".to_string(), sha256_hex(&share));
        std::fs::write(dir.join(&file), &share).unwrap();
        l.masks.push(MaskRef {
            file,
            sha256,
            projector: 1,
            pixels: None,
        });
        let mut m = manifest(p, vec![l]);
        assert_eq!(found(&verify(&dir, &m)), vec![]);
        // Unmirrored, the second projector's share lands at field columns 52..64.
        m.machine.projector[1].mirror_x = false;
        let v = verify(&dir, &m);
        assert_eq!(found(&v), content(&[0]));
        says(
            &v,
            0,
            "masks/00000.png, masks/p1/00000.png: layer 0: its masks light columns 20..63",
        );
    }
}
