//! The per-job set-up ([`Compensator::with_target`]): the calibrated area in pixels, one
//! pass over P ([`super::field_pass`]), the zones' mean P and the spreads before, then
//! the chosen mode's tables ([`super::zone_mode`], [`super::pixel_mode`]).

use super::field_pass::{field_sums, FieldSums};
use super::field_rows::FieldRows;
use super::pixel_mode::{self, PixelTables};
use super::spread::{pixel_spread, zone_spread};
use super::zone_mode::{self, ZoneTables};
use super::zones::ZoneGrid;
use super::{Calibration, Compensator, Dither, Field, FieldModel, Mode, Prediction, Spreads};
use crate::png::PixelBox;
use std::sync::atomic::AtomicU64;

/// The pixels of `field` whose centres lie in the calibrated area of `fm`; fails if there
/// is none.
fn calibrated_pixels(fm: &FieldModel, field: &Field) -> Result<PixelBox, String> {
    let (w, h) = (field.width_px as usize, field.height_px as usize);
    let p = field.pixel_mm;
    let [ax0, ay0, ax1, ay1] = fm.area_mm;
    let cols: Vec<usize> = (0..w)
        .filter(|&c| {
            let x = (c as f64 + 0.5) * p;
            x >= ax0 && x <= ax1
        })
        .collect();
    let rows: Vec<usize> = (0..h)
        .filter(|&r| {
            let y = (h as f64 - r as f64 - 0.5) * p;
            y >= ay0 && y <= ay1
        })
        .collect();
    let (Some(&c0), Some(&c1), Some(&r0), Some(&r1)) =
        (cols.first(), cols.last(), rows.first(), rows.last())
    else {
        return Err(format!(
            "the calibrated area {ax0}..{ax1} x {ay0}..{ay1} mm contains no pixel of the {:.3} x {:.3} mm field",
            field.width_mm(),
            field.height_mm()
        ));
    };
    Ok(PixelBox::new(r0, r1 + 1, c0, c1 + 1))
}

/// What the pass over the field found, which both modes' tables start from.
pub(super) struct FieldSurvey {
    pub(super) zones: ZoneGrid,
    pub(super) sums: FieldSums,
    /// Mean P of each zone (NaN for a zone without pixels), row 0 = top.
    pub(super) zone_p: Vec<f64>,
    /// Whether each zone has its centre in the calibrated area.
    pub(super) zone_inside: Vec<bool>,
    /// The calibrated area in pixels.
    pub(super) inside: PixelBox,
}

impl FieldSurvey {
    /// One pass over P (from `src`) for the zones of `zone_mm` and the calibrated area
    /// `inside` of `fm`.
    fn new(
        src: &FieldRows,
        field: &Field,
        fm: &FieldModel,
        zone_mm: f64,
        inside: PixelBox,
    ) -> FieldSurvey {
        let zones = ZoneGrid::new(field, zone_mm);
        let sums = field_sums(src, field.width_px as usize, &zones, inside);
        let zone_p: Vec<f64> = sums
            .zone_sums
            .iter()
            .zip(&sums.zone_pixels)
            .map(|(s, &n)| if n > 0 { s / n as f64 } else { f64::NAN })
            .collect();
        let zone_inside = zones.centres_inside(field, fm, &sums.zone_pixels);
        FieldSurvey {
            zones,
            sums,
            zone_p,
            zone_inside,
            inside,
        }
    }
}

/// What a mode's tables predict for full coverage (the part of [`Prediction`] each mode
/// fills in).
pub(super) struct ModePrediction {
    pub(super) target: f64,
    pub(super) zone_gray: Vec<u8>,
    pub(super) zone_after: Vec<f64>,
    pub(super) after_zone_pct: f64,
    pub(super) after_pixel_pct: f64,
    pub(super) unreachable: u64,
    pub(super) mixed_zones: u64,
}

impl Compensator {
    /// Precomputes the tables of `mode` (zone or pixel) for calibration `cal` over `field`.
    ///
    /// Fails (with a message for the caller to wrap) if the calibrated area contains no
    /// pixel or zone centre of the field.
    pub fn new(
        cal: &Calibration,
        field: &Field,
        mode: Mode,
        dither: Dither,
    ) -> std::result::Result<Compensator, String> {
        Self::with_target(cal, field, mode, dither, None)
    }

    /// As [`new`](Self::new), but with the target irradiance E* given (`Some`) instead of
    /// chosen from this calibration: projectors tiling one field share one E*
    /// ([`crate::geometry::tile`]).
    pub fn with_target(
        cal: &Calibration,
        field: &Field,
        mode: Mode,
        dither: Dither,
        forced_target: Option<f64>,
    ) -> std::result::Result<Compensator, String> {
        assert!(mode != Mode::Off, "no compensator for mode off");
        let (w, h) = (field.width_px as usize, field.height_px as usize);
        let fm = &cal.field;
        let levels = cal.response.levels();
        let s_max = levels.s_max();
        let area = calibrated_pixels(fm, field)?;
        // P, evaluated row by row (no w × h buffer).
        let src = FieldRows::new(fm, field);
        debug_assert!(source_matches_model(&src, fm, field));
        let survey = FieldSurvey::new(&src, field, fm, cal.zone_mm.get(), area);
        let (zone_tables, pixel_tables, gray_map, after) = match mode {
            Mode::Zone => {
                let Some((t, g, p)) = zone_mode::set_up(&survey, &levels, dither, forced_target)
                else {
                    let [ax0, ay0, ax1, ay1] = fm.area_mm;
                    return Err(format!(
                        "no {} mm zone of the field has its centre in the calibrated area {ax0}..{ax1} x {ay0}..{ay1} mm",
                        cal.zone_mm.get()
                    ));
                };
                (t, PixelTables::default(), g, p)
            }
            Mode::Pixel => {
                let (t, g, p) = pixel_mode::set_up(&survey, &levels, src, forced_target);
                (ZoneTables::default(), t, g, p)
            }
            Mode::Off => unreachable!(),
        };
        let prediction = predict(&survey, area, s_max, after);
        Ok(Compensator {
            mode,
            dither,
            w,
            h,
            levels,
            zones: survey.zones,
            zone_tables,
            pixel_tables,
            gray_map,
            calibrated: area,
            area_mm: fm.area_mm,
            pixel_mm: field.pixel_mm,
            layers_outside: AtomicU64::new(0),
            beyond_bits: AtomicU64::new(0),
            prediction,
        })
    }
}

/// Whether `src` gives P at a pixel centre as [`FieldModel::eval`] does (to 1e-5).
fn source_matches_model(src: &FieldRows, fm: &FieldModel, field: &Field) -> bool {
    let (w, h) = (field.width_px as usize, field.height_px as usize);
    let p = field.pixel_mm;
    let (c, r) = (w / 3, h / 3);
    let direct = fm.eval((c as f64 + 0.5) * p, (h as f64 - r as f64 - 0.5) * p);
    let mut row = vec![0f32; w];
    src.row::<false>(r, &mut row);
    ((row[c] as f64) - direct).abs() <= 1e-5 * direct.abs().max(1e-30)
}

/// The whole prediction: the field before compensation (from `survey` over `area`; the
/// brightest valid gray gives `s_max`) and what the mode's tables give (`after`).
fn predict(survey: &FieldSurvey, area: PixelBox, s_max: f64, after: ModePrediction) -> Prediction {
    let area_pixels = (area.r1 - area.r0) * (area.c1 - area.c0);
    let zones = &survey.zones;
    let (zone_p, zone_inside) = (&survey.zone_p, &survey.zone_inside);
    let before_zone = zone_spread(zone_inside, |z| zone_p[z] * s_max);
    let before_pixel = pixel_spread(&survey.sums, &zones.segments, survey.inside, |_, _| s_max);
    Prediction {
        target: after.target,
        mean: survey.sums.inside_sum / area_pixels as f64 * s_max,
        s_max,
        zone_grid: (zones.cols, zones.rows),
        zone_p: zone_p.clone(),
        zone_inside: zone_inside.clone(),
        zone_gray: after.zone_gray,
        zone_after: after.zone_after,
        spreads: Spreads {
            before_zone_pct: before_zone,
            before_pixel_pct: before_pixel,
            after_zone_pct: after.after_zone_pct,
            after_pixel_pct: after.after_pixel_pct,
        },
        zones_outside: zone_inside.iter().filter(|&&b| !b).count() as u64,
        pixels_outside: (zones.of_col.len() * zones.of_row.len() - area_pixels) as u64,
        unreachable: after.unreachable,
        mixed_zones: after.mixed_zones,
    }
}

#[cfg(test)]
mod tests {
    use super::super::field_rows::pixel_p;
    use super::super::spread::Spread;
    use super::super::test_support::{self, setup, MODES};
    use super::*;

    #[test]
    fn zone_and_pixel_modes_flatten_the_model() {
        let (cal, field) = setup();
        for (mode, dither, zone_max, pixel_max) in [
            (Mode::Zone, Dither::Off, 1.5, 20.0),
            (Mode::Zone, Dither::On, 0.2, 20.0),
            (Mode::Pixel, Dither::Off, 0.5, 1.5),
        ] {
            let c = Compensator::new(&cal, &field, mode, dither).unwrap();
            let sp = c.prediction.spreads;
            assert!(sp.before_zone_pct > 50.0, "{sp:?}");
            assert!(sp.after_zone_pct <= zone_max, "{mode:?} {dither:?} {sp:?}");
            assert!(
                sp.after_pixel_pct <= pixel_max,
                "{mode:?} {dither:?} {sp:?}"
            );
            // Target: the dimmest zone (or pixel) fully on, give or take the window.
            let t = c.prediction.target;
            assert!((0.95..=(1.0 + 2.5 / 40.0) * 1.02).contains(&t), "{t}");
        }
    }

    #[test]
    fn prediction_and_zone_tables_match_a_direct_computation() {
        // The set-up's pass (zone sums, mean, spreads) and its table walk must give what
        // the plain definitions give (adding P pixel by pixel in row-major order), also
        // when the calibrated area cuts through zones and rows (0.7 mm pixels: zone edges
        // fall inside pixel columns): exactly, except the per-pixel spreads' means, which
        // the set-up takes from exact sums (one rounding instead of one per pixel).
        let (mut cal, _) = setup();
        let field = test_support::field(57, 43, 0.7);
        for area in [[0.0, 0.0, 40.0, 30.0], [3.5, 2.2, 33.0, 27.5]] {
            cal.field.area_mm = area;
            let pp = pixel_p(&cal.field, &field);
            let (w, h, p) = (57usize, 43usize, 0.7);
            let inside = |i: usize| {
                let (x, y) = ((i % w) as f64 + 0.5, h as f64 - (i / w) as f64 - 0.5);
                let (x, y) = (x * p, y * p);
                x >= area[0] && x <= area[2] && y >= area[1] && y <= area[3]
            };
            for (mode, dither) in MODES.into_iter().take(4) {
                let c = Compensator::new(&cal, &field, mode, dither).unwrap();
                let pr = &c.prediction;
                let what = format!("{area:?} {mode:?} {dither:?}");
                let (mut before, mut after) = (Spread::new(), Spread::new());
                let (mut sum, mut n) = (0.0f64, 0usize);
                for i in (0..w * h).filter(|&i| inside(i)) {
                    sum += pp[i] as f64;
                    n += 1;
                    before.add(pp[i] as f64 * pr.s_max);
                    after.add(pp[i] as f64 * c.s_of_gray(c.gray_row(i / w)[i % w]));
                }
                assert_eq!(pr.mean, sum / n as f64 * pr.s_max, "{what}");
                let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
                assert!(close(pr.spreads.before_pixel_pct, before.pct()), "{what}");
                // Zone means before and (pixel mode) after: P and P · S(gray) added pixel by
                // pixel in row-major order.
                let nz = pr.zone_p.len();
                let (mut zs, mut zn, mut za) = (vec![0f64; nz], vec![0usize; nz], vec![0f64; nz]);
                for (i, &v) in pp.iter().enumerate() {
                    let z = c.zones.of_row[i / w] as usize * c.zones.cols
                        + c.zones.of_col[i % w] as usize;
                    zs[z] += v as f64;
                    zn[z] += 1;
                    if mode == Mode::Pixel {
                        let g = c.gray_row(i / w)[i % w];
                        za[z] += v as f64 * c.levels.s[c.pixel_tables.level(g)];
                    }
                }
                for (z, &pz) in pr.zone_p.iter().enumerate() {
                    let want = if zn[z] > 0 {
                        zs[z] / zn[z] as f64
                    } else {
                        f64::NAN
                    };
                    assert_eq!(pz.to_bits(), want.to_bits(), "{what} zone {z}");
                }
                if mode == Mode::Pixel {
                    for (z, &a) in pr.zone_after.iter().enumerate() {
                        let want = za[z] / zn[z].max(1) as f64;
                        assert_eq!(a.to_bits(), want.to_bits(), "{what} zone {z}");
                    }
                    continue;
                }
                assert!(close(pr.spreads.after_pixel_pct, after.pct()), "{what}");
                // Each zone's lower table: the nearest level to coverage × E*/P̄ (entry
                // 255 is the zone's full gray, which may mix two levels).
                let lv = &c.levels;
                for (z, &pz) in pr.zone_p.iter().enumerate() {
                    // A zone without pixels (NaN mean) cannot be reached.
                    let tz = if pz > 0.0 {
                        pr.target / pz
                    } else {
                        f64::INFINITY
                    };
                    for v in 1..255 {
                        let want = lv.gray[lv.nearest(v as f64 / 255.0 * tz)];
                        assert_eq!(c.zone_tables.tables[z][v], want, "{what} zone {z} v {v}");
                    }
                }
            }
        }
    }
}
