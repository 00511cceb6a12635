//! The manifest: each layer's record and the totals, from the per-layer outputs and the
//! plan, and the records of the source, the settings and the machine.

use super::layer::LayerOutput;
use super::optics_records::OpticsRecords;
use super::{PlacementMode, Transform};
use crate::bundle::FitReport;
use crate::bundle::{self, Generator, Layer, Manifest, Placement, Settings, Source, Totals};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::plan::{self, LayerAnalysis, LayerInfo};
use crate::profile::{Process, Profile};
use crate::round::{self, StageGrid};
use crate::slice;
use crate::warning::Warning;
use std::path::Path;

/// The part as read and placed.
pub(super) struct PlacedPart<'a> {
    /// The model file.
    pub path: &'a Path,
    /// SHA-256 of the file.
    pub sha256: String,
    /// The mesh, placed on the build plane.
    pub mesh: Mesh,
    /// Its bounding box in the file's coordinates, mm.
    pub bbox_in_file: [[f64; 3]; 2],
    /// The scale and rotation applied before placing it.
    pub transform: Transform,
    /// The placement rule.
    pub mode: PlacementMode,
    /// The translation that placed it, mm.
    pub translate_mm: [f64; 3],
    /// Number of layers.
    pub layers: usize,
    /// A plate's copies of its parts, and their mesh warnings naming each file.
    pub plate: Option<(Vec<bundle::PlatePart>, Vec<Warning>)>,
    /// The supports appended to `mesh` (`slice --supports`).
    pub supports: Option<bundle::Supports>,
    /// The first edge of `mesh` that belongs to the supports.
    pub support_edges: Option<u32>,
    /// The support structure alone (pad and supports).
    pub support_mesh: Option<Mesh>,
}

impl PlacedPart<'_> {
    /// The slicer of the part's layers `h` mm high, its supports counted apart and its
    /// sections offset by `offset_mm` (the dimensional correction's).
    pub fn slicer(&self, h: f64, offset_mm: f64) -> crate::slice::Slicer<'_> {
        crate::slice::Slicer::new(&self.mesh, h, self.layers)
            .with_supports_from(self.support_edges)
            .with_offset(offset_mm)
    }

    /// The warnings about the mesh (on a plate, each naming its part's file).
    pub fn mesh_warnings(&self) -> Vec<Warning> {
        match &self.plate {
            Some((_, w)) => w.clone(),
            None => self.mesh.report.warnings(),
        }
    }

    /// What a message about the point `xy` (mm) of the layer at height `z_mm` names
    /// besides its position: the supports' pad, a support (by its point), or on a plate
    /// the part ([`super::plate::part_at`]), as words to follow the position (", in
    /// b.stl"); `None` for a single part without supports there.
    pub fn what_at(&self, xy: [f64; 2], z_mm: f64) -> Option<String> {
        if let Some(s) = &self.supports {
            if z_mm <= s.pad.thickness_mm + 1e-9 {
                return Some(", in the supports' pad".into());
            }
            // A support's column: within its pillar (a head is narrower) from its foot's
            // layer up to its point and the penetration.
            let near = |p: &bundle::SupportPoint| {
                let r = p.pillar_diameter_mm / 2.0 + 0.2;
                let [x, y, z] = p.at_mm;
                (xy[0] - x).hypot(xy[1] - y) <= r
                    && (p.foot_z_mm - 0.1..=z + s.head_penetration_mm + 0.1).contains(&z_mm)
            };
            if let Some(p) = s.points.iter().find(|p| near(p)) {
                let head = z_mm >= p.at_mm[2] - s.head_length_mm - 0.1;
                let [x, y, z] = p.at_mm.map(crate::text::number);
                return Some(match head {
                    true => format!(", in the head of the support of the point at x {x}, y {y}, z {z} mm (supports.head_front_diameter_mm sets its width)"),
                    false => format!(", in the support of the point at x {x}, y {y}, z {z} mm"),
                });
            }
        }
        let parts = &self.plate.as_ref()?.0;
        super::plate::part_at(parts, xy)
            .map(|i| format!(", in {}", super::plate::part_name(&parts[i])))
    }
}

/// The layers' records and totals, as planned.
pub(super) struct PlannedLayers {
    /// Each layer's record.
    pub layers: Vec<Layer>,
    /// Their totals.
    pub totals: Totals,
    /// The planner's warnings.
    pub warnings: Vec<Warning>,
}

/// Completes the layers' analyses, plans the layers (`plan`) and builds their records; a
/// plan that cannot be made is an error naming `part`'s model.
pub(super) fn plan_layers(
    profile: &Profile,
    outs: Vec<LayerOutput>,
    part: &PlacedPart,
) -> Result<PlannedLayers> {
    let supported = profile.supports.enabled;
    let h = profile.slicing.layer_height_mm.get();
    let n = outs.len();
    let analyses = resolve_analyses(&outs);
    let z_of = layer_tops(profile);
    let field = profile.field();
    let (px, top) = (field.pixel_mm, field.height_mm());
    // The largest island on the build plane: x, y of its centre and its area, mm.
    let island_mm = |i: &plan::analysis::Island| {
        let [c, r] = i.col_row;
        [c * px, top - r * px, i.pixels as f64 * px * px].map(round::plane_mm)
    };
    // What the planner is given is what the manifest records: rounded (crate::round).
    let infos: Vec<LayerInfo> = outs
        .iter()
        .zip(&analyses)
        .enumerate()
        .map(|(i, (o, a))| LayerInfo {
            index: i,
            z_mm: z_of(i + 1),
            thickness_mm: h,
            area_mm2: round::area_mm2(o.area_mm2),
            max_fill_distance_mm: round::plane_mm_down(a.max_fill_distance_mm),
            islands: a.islands,
            island_mm: a.island.as_ref().map(island_mm),
            island_part: a.island.as_ref().and_then(|island| {
                let [x, y, _] = island_mm(island);
                part.what_at([x, y], slice::plane_z(i, h))
            }),
        })
        .collect();
    let plan = plan::plan(profile, &infos).map_err(|msg| Error::Job {
        path: part.path.into(),
        msg,
    })?;
    let hybrid = profile.process == Process::Hybrid;
    let mut layers = Vec::with_capacity(n);
    let (mut exposure_s, mut volume_mm3) = (0.0, 0.0);
    for ((info, o), (a, p)) in infos.iter().zip(outs).zip(analyses.iter().zip(plan.layers)) {
        exposure_s += p.exposure_s;
        volume_mm3 += info.area_mm2 * h;
        layers.push(Layer {
            index: info.index as u64,
            z_mm: info.z_mm,
            slice_z_mm: round::decimals(slice::plane_z(info.index, h), 9),
            thickness_mm: h,
            mode: p.mode,
            exposure_s: p.exposure_s,
            area_mm2: info.area_mm2,
            max_fill_distance_mm: Some(info.max_fill_distance_mm),
            islands: Some(a.islands),
            bbox_mm: a
                .bbox_mm
                .map(|b| b.map(|corner| corner.map(round::plane_mm))),
            masks: o.masks,
            steps: p.steps,
            time_s: p.time_s,
            cure: None,
            support_area_mm2: supported.then(|| round::area_mm2(o.support_area_mm2)),
        });
    }
    let totals = Totals {
        layers: n as u64,
        height_mm: z_of(n),
        print_time_s: plan.print_time_s,
        exposure_s: round::time_s(exposure_s),
        resin_volume_ml: round::derived(volume_mm3 / 1000.0),
        continuous_layers: hybrid.then_some(plan.continuous_layers as u64),
        all_layered_time_s: plan.all_layered_time_s,
    };
    Ok(PlannedLayers {
        layers,
        totals,
        warnings: plan.warnings,
    })
}

/// The top of the first `k` layers, mm: k × the layer height, the stage position at which
/// layer k − 1 is exposed. When the layer height is a whole number of stage steps so is
/// every top (written as [`StageGrid::position`] writes it); otherwise the tops are
/// rounded to 1e-9 mm, and the moves to them go to the nearest whole step.
fn layer_tops(profile: &Profile) -> impl Fn(usize) -> f64 {
    let h = profile.slicing.layer_height_mm.get();
    let grid = StageGrid::new(profile.stage.steps_per_mm.get());
    let whole = grid.is_whole(h);
    move |k| {
        let z = k as f64 * h;
        if whole {
            grid.position(z)
        } else {
            round::decimals(z, 9)
        }
    }
}

/// The layers' analyses in order. A layer equal to the layer below that its worker could
/// not copy takes the layer below's analysis here, and a block's first layer counts its
/// islands over the last layer of the block below.
fn resolve_analyses(outs: &[LayerOutput]) -> Vec<LayerAnalysis> {
    let mut analyses: Vec<LayerAnalysis> = Vec::with_capacity(outs.len());
    for (i, o) in outs.iter().enumerate() {
        let a = o.analysis.with_islands(|| {
            let own = o.runs.as_ref().expect("kept with the analysis");
            let below = outs[i - 1].runs.as_ref().expect("kept by the block below");
            plan::analysis::islands_found(own, below)
        });
        analyses.push(a.resolve(analyses.last()));
    }
    analyses
}

/// The manifest of a job: `part` sliced on `profile` into the `planned` layers, with
/// the light compensation's records, the distortion fit report and every warning.
pub(super) fn manifest(
    part: &PlacedPart,
    profile: &Profile,
    planned: PlannedLayers,
    optics: OpticsRecords,
    distortion: Option<FitReport>,
    warnings: Vec<Warning>,
) -> Manifest {
    Manifest {
        format: bundle::FORMAT.into(),
        version: bundle::VERSION,
        generator: Generator::current(),
        source: source(part),
        settings: Settings {
            layer_height_mm: profile.slicing.layer_height_mm.get(),
            binary: profile.slicing.binary,
            compensation: optics.compensation,
            distortion,
            accuracy: (!profile.accuracy.is_identity()).then(|| bundle::Accuracy {
                scale: profile.accuracy.scale,
                xy_offset_mm: profile.accuracy.xy_offset_mm,
                source: profile
                    .accuracy
                    .source
                    .clone()
                    .unwrap_or_else(|| "typed in".into()),
            }),
        },
        machine: bundle::Machine::of(profile),
        totals: planned.totals,
        warnings,
        layers: planned.layers,
        optics: optics.optics,
        projector_optics: optics.projector_optics,
        cure: None,
        supports: part.supports.clone(),
    }
}

/// A file's name without its directories, as the manifest records it (so bundles are
/// reproducible across paths).
pub(super) fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The manifest's record of the model file and its placement.
fn source(part: &PlacedPart) -> Source {
    let parts = part.plate.as_ref().map(|p| p.0.clone());
    Source {
        file: match &parts {
            Some(p) => {
                let mut names: Vec<&str> = p.iter().map(|r| r.file.as_str()).collect();
                names.dedup();
                names.join(" + ")
            }
            None => file_name(part.path),
        },
        sha256: part.sha256.clone(),
        triangles: part.mesh.report.triangles_in_file,
        bbox_mm: part.bbox_in_file.map(|c| c.map(round::plane_mm)),
        placement: Placement {
            mode: if parts.is_some() {
                "plate"
            } else {
                part.mode.as_str()
            }
            .into(),
            // Like the bounding box, to 1 µm.
            translate_mm: part.translate_mm.map(round::plane_mm),
            scale: (part.transform.scale != [1.0; 3]).then_some(part.transform.scale),
            rotate_deg: part
                .transform
                .rotate_deg
                .iter()
                .any(|&a| a != 0.0)
                .then_some(part.transform.rotate_deg),
            position_mm: match part.mode {
                PlacementMode::At(p) => Some(p),
                _ => None,
            },
        },
        mesh: part.mesh.report.clone(),
        parts,
    }
}
