//! Applying a calibration: coverage → gray, per zone or per pixel (docs/CALIBRATION.md,
//! "Compensation"). A pixel of coverage c = v/255 gets the 8-bit level whose S·P is nearest
//! to c·E*, with P the zone's mean (zone mode) or the pixel's own (pixel mode).
//!
//! [`Compensator::new`] computes once per job what depends only on the calibration and the
//! field (`setup`: P from `field_rows` in one pass over the field, `field_pass` with the
//! vector `kernels`, over the `zones`; the `spread`s; the tables of `zone_mode` or
//! `pixel_mode` and the `gray_map`). The rasterizer applies it while it writes a mask (the
//! compensator is its [`crate::raster::CoverageMap`]) or [`Compensator::apply`] rewrites a
//! finished coverage mask (`apply`, `dither`); both give the same bytes.

mod apply;
mod dither;
mod field_pass;
mod field_rows;
mod gray_map;
mod kernels;
mod pixel_mode;
mod setup;
mod spread;
#[cfg(test)]
mod test_support;
mod zone_mode;
mod zones;

// What the module takes from the rest of the crate; the submodules import it from here.
use super::field::{FieldModel, Form};
use super::response::Levels;
use super::{Calibration, Dither, Mode};
use crate::bundle::Spreads;
use crate::png::PixelBox;
use crate::profile::Field;
use crate::raster::{map_words, Mask};
use gray_map::GrayMap;
use pixel_mode::PixelTables;
use std::sync::atomic::{AtomicU64, Ordering};
use zone_mode::ZoneTables;
use zones::ZoneGrid;

/// Per-job compensation tables for one projector's calibration over the field.
#[derive(Debug)]
pub struct Compensator {
    mode: Mode,
    dither: Dither,
    w: usize,
    h: usize,
    levels: Levels,
    zones: ZoneGrid,
    /// Zone mode's coverage → gray tables (empty in pixel mode).
    zone_tables: ZoneTables,
    /// What pixel mode keeps besides the gray map (empty in zone mode).
    pixel_tables: PixelTables,
    /// The full-coverage gray of every pixel (both modes).
    gray_map: GrayMap,
    /// The calibrated area in pixels.
    calibrated: PixelBox,
    /// The calibrated area, mm, and the pixel size, mm (for [`beyond_mm`](Self::beyond_mm)).
    area_mm: [f64; 4],
    pixel_mm: f64,
    layers_outside: AtomicU64,
    /// The bits of the largest distance, mm, a lit pixel centre lies beyond the calibrated
    /// area (a non-negative `f64`: its bits order as the values do).
    beyond_bits: AtomicU64,
    /// What the model predicts; see [`Prediction`].
    pub prediction: Prediction,
}

/// What the calibration model predicts for a full-coverage field.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Target irradiance E* (calibration units).
    pub target: f64,
    /// Mean irradiance of the calibrated area at the brightest valid gray.
    pub mean: f64,
    /// Highest S (at the brightest valid gray).
    pub s_max: f64,
    /// Zone grid size (cols, rows).
    pub zone_grid: (usize, usize),
    /// Mean P of each zone, row 0 = top.
    pub zone_p: Vec<f64>,
    /// Zone centre inside the calibrated area, row 0 = top.
    pub zone_inside: Vec<bool>,
    /// Full-coverage gray of each zone (zone mode) or the zone mean of the pixel grays
    /// rounded (pixel mode), row 0 = top.
    pub zone_gray: Vec<u8>,
    /// Predicted full-coverage irradiance, zone means, row 0 = top.
    pub zone_after: Vec<f64>,
    /// Spreads before/after over the calibrated area.
    pub spreads: Spreads,
    /// Zones with their centre outside the calibrated area.
    pub zones_outside: u64,
    /// Pixels outside the calibrated area.
    pub pixels_outside: u64,
    /// Zones (zone mode) or pixels (pixel mode) that cannot reach E*.
    pub unreachable: u64,
    /// Zones mixing two grays (zone mode).
    pub mixed_zones: u64,
}

impl Compensator {
    /// The compensation mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The dithering setting.
    pub fn dither(&self) -> Dither {
        self.dither
    }

    /// S of pixel value `g` on the levels used (0 for values outside the valid range other
    /// than off).
    #[cfg(test)]
    pub fn s_of_gray(&self, g: u8) -> f64 {
        let lv = &self.levels;
        let i = lv.gray.partition_point(|&x| x < g);
        if i < lv.gray.len() && lv.gray[i] == g {
            lv.s[i]
        } else {
            0.0
        }
    }

    /// Number of layers passed to [`apply`](Self::apply) whose lit pixels reach outside the
    /// calibrated area.
    pub fn layers_outside(&self) -> u64 {
        self.layers_outside.load(Ordering::Relaxed)
    }

    /// How far, mm, the farthest lit pixel centre of those layers lies beyond the
    /// calibrated area (along x or y, whichever is farther: the calibration's
    /// `extrapolate_mm` margin is per axis).
    pub fn beyond_mm(&self) -> f64 {
        f64::from_bits(self.beyond_bits.load(Ordering::Relaxed))
    }

    /// Forgets the layers counted (and their reach): the job's layers are made again.
    pub fn reset_counts(&self) {
        self.layers_outside.store(0, Ordering::Relaxed);
        self.beyond_bits.store(0, Ordering::Relaxed);
    }

    /// Counts a layer lit outside the calibrated area whose mask repeats one counted
    /// before, in this pass or the last: `beyond_mm`, that one's reach
    /// ([`Compensator::beyond_mm`]; what recording it returned).
    pub fn count_outside(&self, beyond_mm: f64) {
        self.layers_outside.fetch_add(1, Ordering::Relaxed);
        self.beyond_bits
            .fetch_max(beyond_mm.to_bits(), Ordering::Relaxed);
    }

    /// Counts the layer of mask `m` (zero outside `lit_box`) as lit outside the calibrated
    /// area and records how far its lit pixel centres reach (rows outside the area whole,
    /// the others left and right of it); returns that reach, mm.
    fn record_outside(&self, m: &Mask, lit_box: PixelBox) -> f64 {
        let (PixelBox { r0, r1, c0, c1 }, cal, w) = (lit_box, self.calibrated, self.w);
        let ([ax0, ay0, ax1, ay1], p, c1) = (self.area_mm, self.pixel_mm, c1.min(w));
        let mut beyond = 0.0f64;
        for r in r0..r1.min(self.h) {
            let row = &m.data[r * w..(r + 1) * w];
            let inside = r >= cal.r0 && r < cal.r1;
            let (left, right) = if inside {
                (c1.min(cal.c0), c0.max(cal.c1))
            } else {
                (c1, c0)
            };
            let x = |c: Option<usize>| c.map(|c| (c as f64 + 0.5) * p);
            let xl = x((c0..left).find(|&c| row[c] != 0));
            let xr = x((right..c1).rev().find(|&c| row[c] != 0));
            if xl.or(xr).is_some() {
                let y = (self.h - r) as f64 * p - 0.5 * p;
                let dx = xl.map_or(0.0, |x| ax0 - x).max(xr.map_or(0.0, |x| x - ax1));
                beyond = beyond.max(dx).max(ay0 - y).max(y - ay1);
            }
        }
        self.count_outside(beyond);
        beyond
    }
}
