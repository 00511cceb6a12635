//! Applying a calibration: coverage → gray, per zone or per pixel.
//!
//! Everything that depends only on the calibration and the field is computed once per job
//! in [`Compensator::new`]: P at every pixel centre, the target E*, and either one
//! 256-entry lookup table per zone (zone mode, the per-zone compensation of Xu et al.
//! 2010, Chinese J. Lasers 37(7)) or the full-coverage gray, its level index and E*/P per
//! pixel (pixel mode). The rasterizer then applies it while it writes each layer's mask
//! (the compensator is its [`crate::raster::CoverageMap`], see
//! [`crate::raster::Rasterizer::render`]), or [`Compensator::apply`] rewrites a finished
//! coverage mask in place, touching only lit pixels; both give the same bytes:
//!
//! * coverage c = v/255 of a pixel asks for irradiance c·E*; the pixel gets the 8-bit level
//!   whose S·P is nearest to it (so an anti-aliased edge pixel gets S⁻¹(c·E*/P), never
//!   c × the full gray);
//! * zone mode uses P averaged over the zone (one gray per zone for full coverage);
//! * pixel mode uses P at the pixel centre; with dithering, the quantization error (in
//!   irradiance) is diffused to the lit neighbours (Floyd–Steinberg, serpentine), row by
//!   row within the layer, so the output does not depend on the thread count.
//!
//! The parts (private modules): `setup` reads P (`field_rows`) in one pass over the field
//! (`field_pass`, with the vector kernels of `kernels`) over the zone grid (`zones`),
//! measures the spreads (`spread`) and builds the tables of `zone_mode` or `pixel_mode`
//! and the gray map (`gray_map`); `apply` and `dither` turn each layer's coverage into
//! grays.

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
    /// Pixel mode's per-pixel tables (empty in zone mode).
    pixel_tables: PixelTables,
    /// The full-coverage gray of every pixel (both modes).
    gray_map: GrayMap,
    /// The calibrated area in pixels.
    calibrated: PixelBox,
    layers_outside: AtomicU64,
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
}
