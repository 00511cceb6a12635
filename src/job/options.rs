//! What a job is asked ([`SliceOptions`]) and what it reports ([`SliceSummary`]).

use super::{PlacementMode, Transform};
use crate::bundle::FitReport;
use crate::bundle::Totals;
use crate::formats::Format;
use crate::geometry::distortion::DistortionChoice;
use crate::mesh::MeshReport;
use crate::profile::Profile;
use crate::units::Positive;
use crate::warning::Warning;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// Options of [`slice_to_bundle`](super::slice_to_bundle).
#[derive(Clone)]
pub struct SliceOptions<'a> {
    /// The model file.
    pub input: PathBuf,
    /// The model's bytes when they do not come from the file `input` (standard input): an
    /// STL, binary or ASCII; `input` then only names the part in messages and the manifest.
    pub input_bytes: Option<&'a [u8]>,
    /// Bundle path; `None`: `<input stem>.dmdjob` in the current directory.
    pub output: Option<PathBuf>,
    /// Machine profile (already resolved).
    pub profile: Profile,
    /// Overrides the profile's layer height.
    pub layer_height_mm: Option<Positive>,
    /// Overrides the profile's binary setting.
    pub binary: Option<bool>,
    /// Scale and rotation of the part, applied before it is placed.
    pub transform: Transform,
    /// Placement rule.
    pub placement: PlacementMode,
    /// Light compensation (mode, dithering).
    pub optics: crate::optics::OpticsOptions,
    /// Called with (layers done, layers total) as layers are written.
    pub progress: Option<&'a (dyn Fn(usize, usize) + Sync)>,
    /// Set to abort (an interrupt: Ctrl-C, SIGTERM, SIGHUP); the pipeline stops and writes
    /// nothing (it is checked once the part is loaded and between windows of layers).
    pub cancel: Option<&'a AtomicBool>,
    /// Lens distortion correction (`--distortion`; default: the profile's).
    pub distortion: DistortionChoice,
    /// The form of the output (`--format`); `None`: what the output's name says
    /// ([`Format::for_output`]).
    pub format: Option<Format>,
    /// Cure prediction and correction (`--predict`, `--cure-correction`; docs/CURE.md).
    pub cure: super::CureOptions,
    /// More parts, or copies, on one plate with `input` (`--plate`, `--copies`).
    pub plate: Option<super::Plate>,
    /// Pixel values (field-sized, 255 = as drawn) the masks are scaled to: the doses of a
    /// calibration test job (`dmdsl testjob working-curve`).
    pub dose: Option<crate::raster::Mask>,
    /// Where to write the support structure as a binary STL (`--supports-stl`).
    pub supports_stl: Option<PathBuf>,
}

impl SliceOptions<'_> {
    /// A job slicing `input` into the bundle `output` on `profile`, with the profile's own
    /// settings, the part centred on the field, default light compensation and distortion,
    /// and no progress reports or interruption.
    pub fn new(
        input: impl Into<PathBuf>,
        output: impl Into<PathBuf>,
        profile: Profile,
    ) -> SliceOptions<'static> {
        SliceOptions {
            input: input.into(),
            input_bytes: None,
            output: Some(output.into()),
            profile,
            layer_height_mm: None,
            binary: None,
            transform: Transform::default(),
            placement: PlacementMode::Center,
            optics: Default::default(),
            progress: None,
            cancel: None,
            distortion: DistortionChoice::default(),
            format: None,
            cure: Default::default(),
            plate: None,
            dose: None,
            supports_stl: None,
        }
    }

    /// The profile with this job's overrides (layer height, binary) applied.
    pub(super) fn job_profile(&self) -> Profile {
        let mut profile = self.profile.clone();
        if let Some(h) = self.layer_height_mm {
            profile.slicing.layer_height_mm = h;
        }
        if let Some(b) = self.binary {
            profile.slicing.binary = b;
        }
        profile
    }
}

/// Wall time of each stage, s.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Timings {
    /// Reading, welding and validating the mesh.
    pub load_s: f64,
    /// Cutting and chaining contours (time spent by the slicing task; part of `masks_s`'s
    /// wall time, overlapping the mask work).
    pub slice_s: f64,
    /// Slicing, rasterizing, encoding, hashing and writing masks, and the layer analysis
    /// (wall time of the parallel stage).
    pub masks_s: f64,
    /// Layer analysis (max fill distance, islands), summed over the worker threads (CPU
    /// time, part of `masks_s`'s wall time).
    pub analysis_cpu_s: f64,
    /// Planning and writing the manifest.
    pub finish_s: f64,
    /// Everything.
    pub total_s: f64,
}

impl Timings {
    /// The timings to 1 µs, as `--json` prints them.
    pub fn rounded(self) -> Timings {
        let r = crate::round::elapsed_s;
        Timings {
            load_s: r(self.load_s),
            slice_s: r(self.slice_s),
            masks_s: r(self.masks_s),
            analysis_cpu_s: r(self.analysis_cpu_s),
            finish_s: r(self.finish_s),
            total_s: r(self.total_s),
        }
    }
}

/// What [`slice_to_bundle`](super::slice_to_bundle) produced.
#[derive(Debug, Clone, Serialize)]
pub struct SliceSummary {
    /// The bundle written (a directory, or one file in another [`format`](Self::format)).
    pub bundle: PathBuf,
    /// The form it was written in.
    #[serde(serialize_with = "format_name")]
    pub format: Format,
    /// Number of layers.
    pub layers: usize,
    /// Warnings (mesh defects, repairs, plan, compensation) as in the manifest, then what
    /// the output format could not carry (`export.*`).
    pub warnings: Vec<Warning>,
    /// Mesh validation report.
    pub mesh: MeshReport,
    /// Totals as in the manifest.
    pub totals: Totals,
    /// Stage timings.
    pub timings: Timings,
    /// Distortion fit report, when a correction was applied.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distortion: Option<FitReport>,
    /// The cure model, correction and prediction, when the machine has a PSF.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cure: Option<crate::bundle::Cure>,
    /// The supports, when generated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub supports: Option<SupportsSummary>,
}

/// What `--json` and the summary say of a job's supports.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SupportsSummary {
    /// Support points.
    pub points: usize,
    /// Of them, those holding an island.
    pub on_islands: usize,
    /// Of them, those standing on the part (the others stand on the pad).
    pub on_part: usize,
    /// Volume of the pad and supports, mm³.
    pub volume_mm3: f64,
    /// Area of the pad's top, mm².
    pub pad_area_mm2: f64,
    /// How far the part was lifted, mm.
    pub lift_mm: f64,
}

impl SupportsSummary {
    /// The summary of a manifest's supports record.
    pub fn of(s: &crate::bundle::Supports) -> SupportsSummary {
        SupportsSummary {
            points: s.points.len(),
            on_islands: s.points.iter().filter(|p| p.island).count(),
            on_part: s
                .points
                .iter()
                .filter(|p| p.foot == crate::bundle::Foot::Part)
                .count(),
            volume_mm3: s.volume_mm3,
            pad_area_mm2: s.pad.area_mm2,
            lift_mm: s.lift_mm,
        }
    }
}

/// Serializes a format by its name.
fn format_name<S: serde::Serializer>(f: &Format, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(f.name())
}

/// Default output path for an input in `format`: `<stem>` and the format's ending
/// (`.dmdjob`, `.sl1`, …) in the current directory.
pub fn default_output_as(input: &Path, format: Format) -> PathBuf {
    PathBuf::from(format!("{}{}", stem(input), format.extension()))
}

/// The file stem of a part, `part` when it has none.
fn stem(input: &Path) -> String {
    input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "part".into())
}
