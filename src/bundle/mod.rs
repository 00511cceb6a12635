//! The job bundle: `part.dmdjob/` = `job.json` (the manifest) + `masks/*.png`.
//!
//! This module is the only thing the slicer and the executor share. The writer is
//! atomic: everything goes into a hidden sibling directory that replaces the destination
//! only when complete, so a reader sees the old bundle or the new one, never a mix, and a
//! failed or interrupted run leaves nothing behind (a killed one leaves its staging
//! directory, which the next run for the same destination removes). It replaces only a
//! bundle holding nothing but its own files ([`BundleWriter`]).
//!
//! ## Step semantics and timing contract
//! The planner estimates and the executor simulates the same machine, so both follow
//! these rules (the planner's `time_s` is its estimate under them):
//! * The job starts with the stage homed at `machine.stage.home_mm`, shutter closed.
//!   Layer 0's steps start there; every later layer's steps start where the previous
//!   layer's steps left the stage.
//! * At the start of each layer the DMD loads that layer's mask(s), taking
//!   `machine.dmd.load_s`, concurrently with the layer's first steps (light is off). An
//!   `expose` or the first `sweep` of a run waits until the load is done.
//! * `move {to_mm, speed_mm_s, accel_mm_s2}`: shutter closed, trapezoidal velocity profile
//!   from rest to rest (`motion::move_time`).
//! * `wait {s}`: nothing happens for `s` seconds.
//! * `expose {s}`: stage still; the shutter opens (`shutter.open_s`, light not yet on),
//!   light is on for exactly `s`, the shutter closes (`shutter.close_s`). Duration
//!   `open_s + s + close_s`; dose time `s`.
//! * `sweep {to_mm, speed_mm_s}`: the stage moves at constant `speed_mm_s` (the
//!   acceleration to that speed is taken as instantaneous; sweeps are slow) while the
//!   layer's mask is shown. Consecutive sweeps (across layers) form one run: the shutter
//!   opens before the run's first sweep (`open_s`, stage still) and closes after its last
//!   (`close_s`); the next layer's mask is preloaded, so switching masks inside a run
//!   takes no time. Duration of a sweep `|to_mm − from| / speed_mm_s`; dose time the same.

/// The hash the manifest records for every file (model, masks, gray maps, tables).
pub use crate::digest::sha256_hex;
use crate::error::{Error, Result};
use crate::warning::Warning;
use serde::{Deserialize, Deserializer, Serialize};
use std::path::Path;

pub mod machine;
mod pixels;
pub mod regions;
mod source;
mod supports;
mod writer;
pub use machine::Machine;
pub use pixels::MaskPixels;
pub use source::{is_inside, BundleSource, DirSource, MemSource};
pub use supports::{Foot, SupportPad, SupportPoint, Supports};
pub(crate) use writer::stale_siblings;
pub use writer::{is_bundle, BundleWriter};

/// Value of the manifest's `format` field.
pub const FORMAT: &str = "dmdsl-job";
/// Manifest version written by this build. Version 4 records every mask's pixels
/// ([`MaskRef::pixels`], required from it on); version 3 records the machine as the job's
/// own record ([`Machine`]); versions 1 and 2 embedded the whole resolved profile, of
/// which a reader takes the record's keys (the same names), ignoring the rest. Version 1
/// stored `warnings` as text, read as code `bundle.uncoded` with the text as the message.
/// Readers accept [`OLDEST_READ`]..=[`VERSION`] and hold what they read as this version.
pub const VERSION: u32 = 4;
/// The first version whose masks all carry their [`MaskPixels`] record.
pub const PIXELS_SINCE: u32 = 4;
/// Oldest manifest version this build reads.
pub const OLDEST_READ: u32 = 1;
/// File name of the manifest inside a bundle.
pub const MANIFEST: &str = "job.json";

/// The manifest, `job.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// Manifest version, [`VERSION`].
    pub version: u32,
    /// The program that wrote the bundle.
    pub generator: Generator,
    /// The part the job was compiled from.
    pub source: Source,
    /// Job-level settings (what the command line chose on top of the profile).
    pub settings: Settings,
    /// The machine the job runs on ([`Machine::of`] the profile it was sliced on).
    pub machine: Machine,
    /// Totals over all layers.
    pub totals: Totals,
    /// Warnings raised while compiling the job (mesh defects, repairs, plan notes), each
    /// with its stable code (`docs/WARNINGS.md`).
    #[serde(deserialize_with = "warnings_any_version")]
    pub warnings: Vec<Warning>,
    /// One record per layer, bottom first.
    pub layers: Vec<Layer>,
    /// Light compensation applied to the masks (absent when compensation is off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub optics: Option<Optics>,
    /// Tiled jobs (several projectors): the light compensation of each projector, with one
    /// common target irradiance (absent when off; `optics` is then absent too).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub projector_optics: Vec<Optics>,
    /// The cure model's inputs, the correction applied to the masks and, with
    /// `slice --predict`, the predicted cure (docs/CURE.md); absent when the machine has no
    /// point-spread function.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cure: Option<Cure>,
    /// The supports the job was compiled with (`slice --supports`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supports: Option<Supports>,
}

/// A job's cure model, correction and prediction (docs/CURE.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cure {
    /// Point-spread function's standard deviation, pixels.
    pub psf_sigma_px: f64,
    /// Pixel edge on the build plane, mm.
    pub pixel_mm: f64,
    /// Penetration depth Dp, mm.
    pub dp_mm: f64,
    /// Critical energy Ec, mJ/cm².
    pub ec_mj_cm2: f64,
    /// Where `psf_sigma_px`, `dp_mm` and `ec_mj_cm2` came from: the measurement sheet each
    /// was fitted to (name and SHA-256), or "assumed" (typed into the profile).
    #[serde(default)]
    pub sources: std::collections::BTreeMap<String, String>,
    /// Cure depth beyond the layer, mm.
    pub overcure_mm: f64,
    /// Layer thickness, mm.
    pub layer_mm: f64,
    /// Relative irradiance (of a fully lit interior pixel) at which the cured edge lies at
    /// mid-layer, the following layers lighting it alike.
    pub edge_threshold: f64,
    /// Correction applied to the masks: "off", "xy" or "xyz".
    pub correction: String,
    /// Inward move of the drawn edges, px (0 when the correction is off).
    pub shift_px: f64,
    /// Closed-form print-through under a flat downward-facing surface with many lit layers
    /// above it, mm.
    pub print_through_mm: f64,
    /// Layers of downward-facing surfaces held back (`xyz`).
    #[serde(default)]
    pub held_back_layers: u32,
    /// The layers drawn whole without the correction (XY and Z, as with "off"):
    /// corrected, they left a region of the layer above that a job with supports must hold
    /// on nothing (docs/CURE.md, "Layers drawn uncorrected").
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub uncorrected_layers: Vec<u64>,
    /// The windows of layers drawn without the correction around such regions.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub uncorrected_windows: Vec<UncorrectedWindow>,
    /// The predicted cure (`slice --predict`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predicted: Option<CurePrediction>,
    /// The flat features over nothing the Z correction drops whole (`xyz` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dropped: Option<DroppedFeatures>,
}

/// A window of a layer drawn without the cure correction ([`Cure::uncorrected_windows`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UncorrectedWindow {
    /// Its layer.
    pub layer: u64,
    /// Its pixels on the field: first column, first row, end column, end row (exclusive).
    pub box_px: [u64; 4],
}

/// Flat features over nothing thinner than the held-back layers, which the Z correction
/// (`--cure-correction xyz`) leaves out of every mask (docs/CURE.md).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DroppedFeatures {
    /// Features (4-connected pixels whose runs of lit layers end in one layer), over all
    /// layers.
    pub features: u64,
    /// Their pixels.
    pub pixels: u64,
    /// Layers in which such runs end.
    pub layers: u64,
    /// The first of those layers.
    pub first_layer: Option<u64>,
    /// The first layer's first feature (the one holding its first dropped pixel in
    /// row-major order, i.e. the highest y, then the lowest x).
    pub first: Option<FeatureBox>,
}

/// Where a feature lies on the build plane: the centre and size of its bounding box, mm.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FeatureBox {
    /// Centre, x, mm.
    pub x_mm: f64,
    /// Centre, y, mm.
    pub y_mm: f64,
    /// Width along x, mm.
    pub width_mm: f64,
    /// Height along y, mm.
    pub height_mm: f64,
}

/// A job's predicted cure against its sections.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CurePrediction {
    /// Edge samples counted (features and gaps at least 4σ wide, away from corners).
    pub samples: u64,
    /// Absolute edge error, px.
    pub edge_error_px: EdgeError,
    /// Absolute edge error, mm.
    pub edge_error_mm: EdgeError,
    /// Mean signed edge error, px (positive: the cured part is larger).
    pub signed_mean_px: f64,
    /// Outer contours nothing of which cures, over all layers.
    pub vanished: u64,
    /// Contours whose cure reaches across a gap, over all layers.
    pub merged: u64,
    /// The layers with the largest mean absolute edge error, worst first (at most 5).
    pub worst_layers: Vec<u64>,
    /// The per-layer edge offsets from the cured area (`layers[].cure.offset_px`), their
    /// absolute values weighted by the drawn perimeter, px: as `dmdsl run --cure`'s
    /// `edge_offset_px`.
    #[serde(default)]
    pub edge_offset_px: EdgeError,
    /// Their signed mean, px (as `dmdsl run --cure`'s `signed_mean_px`).
    #[serde(default)]
    pub signed_offset_px: f64,
}

/// Statistics of the absolute edge error.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct EdgeError {
    /// Mean.
    pub mean: f64,
    /// 95th percentile (to 0.01 px).
    pub p95: f64,
    /// Largest.
    pub max: f64,
}

/// A layer's predicted cure against its section (`slice --predict`; docs/CURE.md).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LayerCure {
    /// Edge samples counted (features and gaps at least 4σ wide, away from corners).
    pub samples: u64,
    /// Mean signed edge error, px (positive: the cured part is larger).
    pub mean_px: f64,
    /// Mean absolute edge error, px.
    pub abs_mean_px: f64,
    /// 95th percentile of the absolute edge error, px (to 0.01 px).
    pub p95_px: f64,
    /// Largest absolute edge error, px.
    pub max_px: f64,
    /// Outer contours nothing of which cures.
    pub vanished: u32,
    /// Contours whose cure reaches across a gap to the next edge.
    pub merged: u32,
    /// The first vanished feature's bounding box (the layer's section, in build-plane mm
    /// of the drawn section; absent when nothing vanishes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vanished_at: Option<FeatureBox>,
    /// Mean edge offset from the cured area, px: (cured − section area) / drawn perimeter,
    /// as `dmdsl run --cure` computes it (`per_layer[].offset_px`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset_px: Option<f64>,
}

/// Who wrote the job's layers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Generator {
    /// Program name: "dmdsl" for a job it sliced; an imported job's file's writer as the
    /// file names it (e.g. "PrusaSlicer-2.5.0"), its version then empty.
    pub name: String,
    /// Program version.
    pub version: String,
}

impl Generator {
    /// This build of dmdsl.
    pub fn current() -> Self {
        Generator {
            name: "dmdsl".into(),
            version: env!("CARGO_PKG_VERSION").into(),
        }
    }
}

/// The source model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Source {
    /// File name of the model (no directories, so bundles are reproducible across paths).
    pub file: String,
    /// SHA-256 of the model file, hex.
    pub sha256: String,
    /// Number of triangles loaded.
    pub triangles: u64,
    /// Axis-aligned bounding box in the file's coordinates, mm: [min, max].
    pub bbox_mm: [[f64; 3]; 2],
    /// How the part was placed on the build plane.
    pub placement: Placement,
    /// Mesh validation report.
    pub mesh: crate::mesh::MeshReport,
    /// The copies of the parts of a plate (placement mode "plate"), in the order they were
    /// given; then `file` joins their names, `sha256` is the hash of their hashes (one
    /// `<sha256>  <file>` line per copy), `bbox_mm` is the plate's box on the build plane and
    /// `mesh` sums their reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parts: Option<Vec<PlatePart>>,
}

/// One copy of a part on a plate: a point p of its file lands at D·R·(S·p) +
/// `translate_mm`, S and R the plate's `scale` and `rotate_deg`, D the dimensional
/// correction's factors ([`Settings::accuracy`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlatePart {
    /// File name of the part (no directories).
    pub file: String,
    /// SHA-256 of the file, hex.
    pub sha256: String,
    /// Which copy of the part this is, 1 to `copies`.
    pub copy: usize,
    /// How many copies of the part the plate has.
    pub copies: usize,
    /// Number of triangles in the file.
    pub triangles: u64,
    /// Bounding box in the file's coordinates, mm: [min, max].
    pub bbox_mm: [[f64; 3]; 2],
    /// Translation added to the (scaled, rotated) file coordinates, mm.
    pub translate_mm: [f64; 3],
    /// Bounding box on the build plane, mm: [min, max].
    pub placed_bbox_mm: [[f64; 3]; 2],
}

/// Placement of the part in build-plane coordinates: a point p of the file lands at
/// D·R·(S·p) + `translate_mm`, S the `scale`, R the `rotate_deg` rotations and D the
/// dimensional correction's factors ([`Settings::accuracy`]; identity when absent).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// "center" (XY box centred on the field, lowest point at z = 0), "keep" (file
    /// coordinates), "position" (XY box centred on `position_mm`, lowest point at z = 0) or
    /// "plate" (several parts, each placed as its record in [`Source::parts`] says).
    pub mode: String,
    /// Translation added to the (scaled, rotated) file coordinates, mm.
    pub translate_mm: [f64; 3],
    /// Scale factors along the file's X, Y and Z axes, applied first (absent: 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<[f64; 3]>,
    /// Rotations about the X, Y and Z axes, degrees, applied in that order after the
    /// scale (absent: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate_deg: Option<[f64; 3]>,
    /// Where mode "position" put the centre of the part's XY box, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_mm: Option<[f64; 2]>,
}

/// Job-level settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// Layer thickness, mm.
    pub layer_height_mm: f64,
    /// Binary (thresholded) masks instead of 8-bit coverage.
    pub binary: bool,
    /// Light compensation mode: "off", "zone" or "pixel"; "dose": uncompensated masks whose
    /// pixel values are a calibration test job's doses (`dmdsl testjob`).
    pub compensation: String,
    /// Distortion correction applied to the masks: its table and fit report.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<FitReport>,
    /// The dimensional correction applied to the part (the profile's `[accuracy]`; absent
    /// when it corrects nothing).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<Accuracy>,
}

/// The dimensional correction a job applied (docs/CALIBRATION.md, "Dimensions").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Accuracy {
    /// Factors along the machine's X, Y and Z applied to the part after its scale and
    /// rotation ([`Placement`]).
    pub scale: [f64; 3],
    /// Offset of the part's sections along their outward normals, mm.
    pub xy_offset_mm: f64,
    /// The measurement sheet the values were fitted to (name and SHA-256), or "typed in".
    pub source: String,
}

/// Quality of the distortion correction fitted to a measured table (filled by
/// `geometry::distortion`), recorded in the manifest and printed by the CLI.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitReport {
    /// Table file name, or "profile NAME" for inline points.
    pub source: String,
    /// SHA-256 of the table.
    pub sha256: String,
    /// Number of measured points.
    pub points: usize,
    /// Total degree of the least-squares polynomial (chosen by cross-validation).
    pub degree: u32,
    /// Weight κ of the natural-neighbour residual interpolant (0: polynomial only, 1: the
    /// correction passes through every table point).
    pub residual_weight: f64,
    /// RMS distance between the polynomial and the table points, mm.
    pub poly_rms_mm: f64,
    /// Largest such distance, mm.
    pub poly_max_mm: f64,
    /// Where the largest polynomial residual is ("line 37").
    pub poly_max_at: String,
    /// Leave-one-out prediction error of the correction (polynomial + κ·residual), RMS, mm:
    /// an honest estimate of its accuracy between points (it includes measurement noise).
    pub cv_rms_mm: f64,
    /// Largest leave-one-out error, mm.
    pub cv_max_mm: f64,
    /// Where the largest leave-one-out error is.
    pub cv_max_at: String,
    /// Largest correction in the table, |aim − seen|, mm.
    pub max_correction_mm: f64,
    /// Warped points outside the convex hull of the seen points (extrapolated); layers
    /// that repeat the layer below's masks are not warped again and not counted.
    pub extrapolated_points: u64,
}

impl FitReport {
    /// The report with its figures rounded as the manifest records them: errors and
    /// corrections to 6 significant digits (`crate::round::derived`).
    pub fn rounded(mut self) -> FitReport {
        use crate::round::derived;
        for v in [
            &mut self.residual_weight,
            &mut self.poly_rms_mm,
            &mut self.poly_max_mm,
            &mut self.cv_rms_mm,
            &mut self.cv_max_mm,
            &mut self.max_correction_mm,
        ] {
            *v = derived(*v);
        }
        self
    }

    /// One-line human summary.
    pub fn summary(&self) -> String {
        format!(
            "distortion {}: {} points, degree-{} polynomial + {:.2} x residual interpolant; fit residual RMS {:.4} mm (max {:.4} mm, {}), cross-validated error RMS {:.4} mm (max {:.4} mm, {}); largest correction {:.3} mm",
            self.source,
            self.points,
            self.degree,
            self.residual_weight,
            self.poly_rms_mm,
            self.poly_max_mm,
            self.poly_max_at,
            self.cv_rms_mm,
            self.cv_max_mm,
            self.cv_max_at,
            self.max_correction_mm
        )
    }
}

/// Light compensation of a job (see docs/CALIBRATION.md). Irradiances are in `units`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Optics {
    /// "zone" or "pixel".
    pub mode: String,
    /// Dithering: "auto", "on" or "off" (docs/CALIBRATION.md).
    pub dither: String,
    /// Zones that mix two grays to hit the target (zone mode).
    pub mixed_zones: u64,
    /// Index of the projector whose calibration was applied.
    pub projector: u32,
    /// The calibration's `source` text.
    pub calibration: String,
    /// Unit of the irradiances below: "relative" or "mW/cm2".
    pub units: String,
    /// Target irradiance E*: the highest irradiance every zone (zone mode) or pixel (pixel
    /// mode) of the calibrated area can reach; full-coverage pixels aim at it.
    pub target_irradiance: f64,
    /// Mean irradiance of the calibrated area with every mirror at the brightest valid gray.
    pub mean_irradiance: f64,
    /// target / mean: the fraction of the projector's light a compensated job uses.
    pub throughput: f64,
    /// Calibrated area [x0, y0, x1, y1] in build-plane mm.
    pub calibrated_area_mm: [f64; 4],
    /// Pixel values the response is valid for [lo, hi]; 0 (mirror off) is always allowed.
    pub valid_gray: [u8; 2],
    /// Zone edge, mm (zones start at the field's bottom-left corner).
    pub zone_mm: f64,
    /// Full-coverage gray of each zone, row 0 = top of the image (zone mode; empty in pixel
    /// mode). A mixing zone lists the gray it shows on most of its pixels.
    pub zone_grays: Vec<Vec<u8>>,
    /// Bundle file with the full-coverage gray of every pixel (8-bit PNG, mask orientation).
    pub gray_map: String,
    /// SHA-256 of `gray_map`.
    pub gray_map_sha256: String,
    /// Predicted spreads under the calibration model.
    pub predicted: Spreads,
    /// Zones whose centre lies outside the calibrated area (P extrapolated there).
    pub zones_outside: u64,
    /// Pixels of the field outside the calibrated area.
    pub pixels_outside: u64,
    /// Zones (zone mode) or pixels (pixel mode) that cannot reach the target even fully on.
    pub unreachable: u64,
    /// Layers whose section reaches outside the calibrated area.
    pub layers_outside: u64,
    /// How exposure times were derived.
    pub exposure_rule: String,
    /// Dose of a normal layer at the target irradiance, mJ/cm² (absolute calibrations only).
    pub dose_mj_cm2: Option<f64>,
}

impl Optics {
    /// The record with its figures rounded as the manifest records them: irradiances,
    /// throughput, spreads and dose to 6 significant digits, the calibrated area to 1 µm
    /// (`crate::round`).
    pub fn rounded(mut self) -> Optics {
        use crate::round::{derived, plane_mm};
        let p = &mut self.predicted;
        for v in [
            &mut self.target_irradiance,
            &mut self.mean_irradiance,
            &mut self.throughput,
            &mut p.before_zone_pct,
            &mut p.before_pixel_pct,
            &mut p.after_zone_pct,
            &mut p.after_pixel_pct,
        ] {
            *v = derived(*v);
        }
        self.dose_mj_cm2 = self.dose_mj_cm2.map(derived);
        self.calibrated_area_mm = self.calibrated_area_mm.map(plane_mm);
        self
    }
}

/// Spreads (max − min) / mean of irradiance over the calibrated area, %.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Spreads {
    /// Zone means, uncompensated (every mirror at the brightest valid gray).
    pub before_zone_pct: f64,
    /// Pixels, uncompensated.
    pub before_pixel_pct: f64,
    /// Zone means, compensated.
    pub after_zone_pct: f64,
    /// Pixels, compensated.
    pub after_pixel_pct: f64,
}

/// Totals over the job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Totals {
    /// Number of layers.
    pub layers: u64,
    /// Part height as printed, mm.
    pub height_mm: f64,
    /// Estimated print time from the planned steps, s.
    pub print_time_s: f64,
    /// Sum of layer exposures, s.
    pub exposure_s: f64,
    /// Cured resin volume, ml (sum of area × thickness).
    pub resin_volume_ml: f64,
    /// Hybrid process: layers printed continuously.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub continuous_layers: Option<u64>,
    /// Hybrid process: estimated print time had every slice been printed layered, s (the
    /// saving of the hybrid plan is `all_layered_time_s − print_time_s`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub all_layered_time_s: Option<f64>,
}

/// How a layer is printed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Stop, recoat/peel, expose while stationary.
    Layered,
    /// Exposed while the stage sweeps at constant speed.
    Continuous,
}

/// One layer record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    /// 0-based layer index.
    pub index: u64,
    /// Height of the layer's top above the build plane, mm: (index + 1) × thickness for a
    /// uniform job. This is also the stage coordinate at which the layer is exposed.
    pub z_mm: f64,
    /// Height of the cutting plane that produced the section, mm.
    pub slice_z_mm: f64,
    /// Layer thickness, mm.
    pub thickness_mm: f64,
    /// Printing mode.
    pub mode: Mode,
    /// Exposure the layer receives, s.
    pub exposure_s: f64,
    /// Area of the section, mm² (from anti-aliased coverage).
    pub area_mm2: f64,
    /// Largest distance from a point of the section to its boundary (DisMax-Min of the
    /// hybrid continuous/layered method: the radius of the largest inscribed circle), mm;
    /// `None` (absent) when the job does not know it: an imported job, whose file carries
    /// images, not sections.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_fill_distance_mm: Option<f64>,
    /// Connected regions of the section that do not rest on the layer below; `None`
    /// (absent) when the job does not know them (an imported job).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub islands: Option<u32>,
    /// Bounding box of the section in build-plane mm, `[[x_min, y_min], [x_max, y_max]]`;
    /// `null` for an empty section.
    #[serde(default)]
    pub bbox_mm: Option<[[f64; 2]; 2]>,
    /// Mask image(s) of the layer, one per projector.
    pub masks: Vec<MaskRef>,
    /// Ordered machine steps that take the stage from where the previous layer left it to
    /// this layer's exposure and expose it. The executor replays them literally.
    pub steps: Vec<Step>,
    /// Estimated duration of `steps`, s.
    pub time_s: f64,
    /// Predicted cure against the section (`slice --predict`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cure: Option<LayerCure>,
    /// The lit area the supports and the pad add to the part's section, mm² (jobs with
    /// supports).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub support_area_mm2: Option<f64>,
}

/// A mask file of a layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MaskRef {
    /// Path relative to the bundle, e.g. "masks/00000.png".
    pub file: String,
    /// SHA-256 of the PNG file, hex.
    pub sha256: String,
    /// Index of the projector that shows it.
    pub projector: u32,
    /// What the mask shows, its box placed in the field by its projector (version 4 on;
    /// absent in older bundles and in imported jobs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixels: Option<MaskPixels>,
}

/// One machine step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Step {
    /// Move the stage (light off) to `to_mm` with a trapezoidal profile.
    Move {
        /// Target stage coordinate, mm.
        to_mm: f64,
        /// Cruise speed, mm/s.
        speed_mm_s: f64,
        /// Acceleration, mm/s².
        accel_mm_s2: f64,
    },
    /// Do nothing for `s` seconds (light off).
    Wait {
        /// Duration, s.
        s: f64,
    },
    /// Show the layer's mask with the stage stationary for `s` seconds.
    Expose {
        /// Light-on duration, s.
        s: f64,
    },
    /// Show the layer's mask while the stage moves at constant speed to `to_mm`.
    Sweep {
        /// Target stage coordinate, mm.
        to_mm: f64,
        /// Constant speed, mm/s.
        speed_mm_s: f64,
    },
}

impl Manifest {
    /// The manifest as `job.json` holds it: pretty-printed JSON and a final newline (the
    /// same bytes in every form of the bundle).
    pub fn to_json(&self) -> Vec<u8> {
        let mut json = serde_json::to_vec_pretty(self).expect("manifest serializes");
        json.push(b'\n');
        json
    }

    /// Reads and checks `job.json` of the bundle at `dir`.
    pub fn read(dir: &Path) -> Result<Manifest> {
        if !dir.exists() {
            let e = std::io::Error::new(std::io::ErrorKind::NotFound, "does not exist");
            return Err(Error::io(dir, e));
        }
        if !dir.is_dir() {
            return Err(Error::Bundle {
                path: dir.into(),
                msg: "not a job bundle directory".into(),
            });
        }
        let path = dir.join(MANIFEST);
        let text = crate::input::read_file(&path, "manifest", crate::input::TEXT_MAX_BYTES)?;
        Manifest::from_json(&text, &path)
    }

    /// Parses and checks manifest JSON (format, supported version, structure); `path` names
    /// the file in errors.
    pub fn from_json(text: &[u8], path: &Path) -> Result<Manifest> {
        let path = path.to_path_buf();
        let v: serde_json::Value = serde_json::from_slice(text).map_err(|e| Error::Bundle {
            path: path.clone(),
            msg: format!("invalid JSON: {e}"),
        })?;
        match v.get("format").and_then(|f| f.as_str()) {
            Some(FORMAT) => {}
            other => {
                return Err(Error::Bundle {
                    path,
                    msg: format!("format is {other:?}, expected \"{FORMAT}\""),
                })
            }
        }
        let version = match v.get("version").and_then(|f| f.as_u64()) {
            Some(n) if (OLDEST_READ as u64..=VERSION as u64).contains(&n) => n as u32,
            other => {
                return Err(Error::Bundle {
                    path,
                    msg: format!(
                        "unsupported version {other:?}; this dmdsl reads versions {OLDEST_READ} to {VERSION}"
                    ),
                })
            }
        };
        let bad = |msg: String| Error::Bundle {
            path: path.clone(),
            msg,
        };
        let mut m: Manifest =
            serde_json::from_value(v).map_err(|e| bad(format!("invalid manifest: {e}")))?;
        for (i, l) in m.layers.iter().enumerate() {
            let bare = l.masks.iter().position(|x| x.pixels.is_none());
            if let (Some(k), true) = (bare, version >= PIXELS_SINCE) {
                return Err(bad(format!("layers[{i}].masks[{k}] has no `pixels` record (every mask has one from version {PIXELS_SINCE} on)")));
            }
        }
        m.check_numbers().map_err(bad)?;
        m.version = VERSION;
        Ok(m)
    }
}

impl Manifest {
    /// Checks that every number of the layers and the totals is one a job can hold: the
    /// lengths, durations, speeds and accelerations in the ranges a machine has (the
    /// profile's, by the unit the key names), a layer's thickness, exposure, fill
    /// distance, time and area not negative, the area at most the field's, the box's
    /// corners in order. The error names the key (`layers[3].area_mm2 = -1.0 is …`). A
    /// step's speed, acceleration or time of 0 or less is the executor's to report
    /// (`invalid-step`).
    pub fn check_numbers(&self) -> std::result::Result<(), String> {
        let unit = crate::profile::check_unit;
        let field = self.machine.field();
        let field_mm2 = field.width_mm() * field.height_mm();
        for (i, l) in self.layers.iter().enumerate() {
            let at = |k: &str| format!("layers[{i}].{k}");
            unit(&at("z_mm"), "z_mm", l.z_mm)?;
            unit(&at("slice_z_mm"), "_mm", l.slice_z_mm)?;
            let figures = [
                ("thickness_mm", l.thickness_mm),
                ("exposure_s", l.exposure_s),
                (
                    "max_fill_distance_mm",
                    l.max_fill_distance_mm.unwrap_or(0.0),
                ),
                ("time_s", l.time_s),
            ];
            for (k, v) in figures {
                unit(&at(k), k, v)?;
                if v < 0.0 {
                    return Err(format!("{} = {v:?} is negative", at(k)));
                }
            }
            let a = l.area_mm2;
            if a < 0.0 || (field_mm2 > 0.0 && a > field_mm2 * (1.0 + 1e-9)) {
                return Err(format!(
                    "{} = {a:?} is not an area of the {} mm² field",
                    at("area_mm2"),
                    crate::text::number(field_mm2)
                ));
            }
            if let Some([lo, hi]) = l.bbox_mm {
                for v in [lo, hi].into_iter().flatten() {
                    unit(&at("bbox_mm"), "_mm", v)?;
                }
                if lo[0] > hi[0] || lo[1] > hi[1] {
                    return Err(format!("{}: the corners are not in order", at("bbox_mm")));
                }
            }
            for (j, step) in l.steps.iter().enumerate() {
                let at = |k: &str| format!("layers[{i}].steps[{j}].{k}");
                let named: &[(&str, f64)] = match *step {
                    Step::Move {
                        to_mm,
                        speed_mm_s,
                        accel_mm_s2,
                    } => &[
                        ("to_mm", to_mm),
                        ("speed_mm_s", speed_mm_s),
                        ("accel_mm_s2", accel_mm_s2),
                    ],
                    Step::Wait { s } | Step::Expose { s } => &[("s", s)],
                    Step::Sweep { to_mm, speed_mm_s } => {
                        &[("to_mm", to_mm), ("speed_mm_s", speed_mm_s)]
                    }
                };
                for &(k, v) in named {
                    // `s` is a duration: the unit its key names is `_s`.
                    unit(&at(k), if k == "s" { "_s" } else { k }, v)?;
                }
            }
        }
        let t = &self.totals;
        unit("totals.height_mm", "height_mm", t.height_mm)?;
        let totals = [
            ("print_time_s", t.print_time_s),
            ("exposure_s", t.exposure_s),
            ("resin_volume_ml", t.resin_volume_ml),
        ];
        match totals.iter().find(|(_, v)| *v < 0.0) {
            Some((k, v)) => Err(format!("totals.{k} = {v:?} is negative")),
            None => Ok(()),
        }
    }
}

/// Reads `warnings` as objects (version 2) or as text (version 1, code `bundle.uncoded`).
fn warnings_any_version<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Warning>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Any {
        Coded(Warning),
        Text(String),
    }
    Ok(Vec::<Any>::deserialize(d)?
        .into_iter()
        .map(|w| match w {
            Any::Coded(w) => w,
            Any::Text(t) => Warning::new("bundle.uncoded", t),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_json_shape() {
        let s = Step::Move {
            to_mm: 1.5,
            speed_mm_s: 2.0,
            accel_mm_s2: 50.0,
        };
        assert_eq!(
            serde_json::to_string(&s).unwrap(),
            r#"{"kind":"move","to_mm":1.5,"speed_mm_s":2.0,"accel_mm_s2":50.0}"#
        );
        let e: Step = serde_json::from_str(r#"{"kind":"expose","s":8.0}"#).unwrap();
        assert_eq!(e, Step::Expose { s: 8.0 });
    }

    #[test]
    fn a_version_2_manifest_reads_its_embedded_profile_as_the_record() {
        let profile = crate::profile::Profile::resolve("tiled-2x1").unwrap();
        let mut v = serde_json::to_value(crate::exec::testutil::two_layer_topdown()).unwrap();
        v["version"] = 2.into();
        v["machine"] = serde_json::to_value(&profile).unwrap();
        let text = serde_json::to_vec(&v).unwrap();
        let m = Manifest::from_json(&text, Path::new("job.json")).unwrap();
        assert_eq!(m.machine, Machine::of(&profile));
        assert_eq!(m.version, VERSION);
        v["version"] = (VERSION + 1).into();
        let text = serde_json::to_vec(&v).unwrap();
        let e = Manifest::from_json(&text, Path::new("job.json")).unwrap_err();
        assert!(
            e.to_string().contains("this dmdsl reads versions 1 to 4"),
            "{e}"
        );
    }

    #[test]
    fn warnings_read_as_objects_or_version_1_text() {
        #[derive(Deserialize)]
        struct W {
            #[serde(deserialize_with = "warnings_any_version")]
            warnings: Vec<Warning>,
        }
        let w: W = serde_json::from_str(
            r#"{"warnings": ["old text", {"code": "plan.travel-clamped", "severity": "warning", "message": "m", "fields": {"moves": 2}}]}"#,
        )
        .unwrap();
        assert_eq!(w.warnings[0].code, "bundle.uncoded");
        assert!(w.warnings[0].message.starts_with("old text; "));
        assert_eq!(w.warnings[1].code, "plan.travel-clamped");
        assert_eq!(w.warnings[1].fields["moves"], 2);
    }
}
