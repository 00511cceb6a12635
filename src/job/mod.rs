//! The slicing pipeline: load → place → slice → (per layer, in parallel) raster → encode →
//! hash → write; then plan and write the manifest, atomically.
//!
//! One task slices windows of 32 layers and hands each window to rayon's pool in blocks
//! of 8 consecutive layers as soon as it is cut (no barrier between windows); when 96
//! layers wait for a worker, the slicing waits without holding a thread (it parks and the
//! block that makes room resumes it), and a worker keeps only its current mask, so memory
//! does not grow with the number of layers (but for the lit runs of a block's first and
//! last layers, a few kilobytes each, kept until the end for the islands of the blocks'
//! first layers). Every output byte depends only on the input and the settings, never on
//! the thread count or timing.
//!
//! Files: `options.rs` (what a job is asked and reports), `placement.rs`, `pipeline.rs`
//! (windows → blocks → layers, and the bound on what waits), `layer.rs` (one layer's masks
//! and analysis), `mask_reuse.rs` (masks of equal layers written again), `clock.rs`
//! (per-thread CPU time), `optics_records.rs` (the light compensation's files and
//! records), `manifest.rs` (layer records, totals and the rest of the manifest),
//! `unheld.rs` (a job with supports checked for regions on nothing before it is written,
//! and made again with what leaves them drawn without the cure correction),
//! `uncorrected.rs` (where: windows around those regions, or whole layers) and `again.rs`
//! (a pass made again takes the blocks it draws alike from the pass before).

mod again;
mod beneath;
mod clock;
mod cure_records;
mod layer;
mod manifest;
mod mask_reuse;
mod optics_records;
mod options;
mod pipeline;
mod placement;
mod plate;
mod sink;
mod supported;
mod uncorrected;
mod unheld;

pub use cure_records::CureOptions;
pub use options::{default_output_as, SliceOptions, SliceSummary, SupportsSummary, Timings};
#[cfg(any(test, feature = "internals"))]
pub use pipeline::BLOCK;
pub use placement::{place_mesh, PlacementMode, Transform};
pub use plate::{Plate, MAX_COPIES, SPACING_MM};

use crate::bundle::regions::Run;
use crate::bundle::FitReport;
use crate::bundle::{self, BundleWriter};
use crate::error::{Error, Result};
use crate::formats::Format;
use crate::geometry::distortion::{self, Correction};
use crate::geometry::tile::Tiler;
use crate::mesh::{self, Mesh};
use crate::optics::JobOptics;
use crate::profile::Profile;
use crate::raster::{Mask, Rasterizer};
use crate::slice::SliceStats;
use crate::text::plural;
use crate::warning::Warning;
use layer::LayerContext;
use manifest::PlacedPart;
use mask_reuse::RecentPrismMasks;
use optics_records::WrittenGrayMap;
use pipeline::Control;
use sink::{MemoryFiles, Sink};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

/// Encodes a mask as an 8-bit grayscale PNG (`png`; deterministic).
pub fn encode_png(m: &Mask) -> Vec<u8> {
    crate::png::encode_gray8(m.width, m.height, &m.data)
}

/// The machine's per-job set-up.
struct SetUp {
    /// Light compensation of the single projector.
    optics: Option<JobOptics>,
    /// Blending and compensation of several projectors.
    tiler: Option<Tiler>,
    /// Lens distortion pre-warp.
    correction: Option<Correction>,
}

impl SetUp {
    /// Forgets what making the layers counted (layers beyond the calibrated area,
    /// extrapolated warps): they are made again.
    fn reset_counts(&self) {
        if let Some(o) = &self.optics {
            o.compensator.reset_counts();
        }
        if let Some(t) = &self.tiler {
            t.reset_counts();
        }
        if let Some(c) = &self.correction {
            c.reset_counts();
        }
    }
}

/// Slices a model into a job bundle. See the module docs for the pipeline.
pub fn slice_to_bundle(opts: &SliceOptions) -> Result<SliceSummary> {
    let t0 = Instant::now();
    let mut profile = opts.job_profile();
    // The command line's layer height and flags must fit the machine too.
    profile.validate().map_err(|msg| Error::Profile {
        origin: profile.name.clone(),
        msg,
    })?;
    let cure = cure_records::CureJob::new(&profile, &opts.cure)?;
    let corrected = cure.as_ref().is_some_and(|c| c.corrects());
    let (setup, part) = load_and_place(opts, &mut profile, corrected)?;
    let load_s = t0.elapsed().as_secs_f64();
    let control = Control {
        progress: opts.progress,
        cancel: opts.cancel,
    };
    // Interrupted while loading: stop before anything is created.
    if control.cancelled() {
        return Err(Error::Interrupted);
    }
    let out = opts
        .output
        .clone()
        .unwrap_or_else(|| default_output_as(&opts.input, opts.format.unwrap_or(Format::Dmdjob)));
    let format = Format::for_output(opts.format, &out)?;
    crate::formats::check_fits(format, &crate::bundle::Machine::of(&profile), &out)?;
    let made = MadeDirs::parents_of(&out)?;
    // The cure plots' directory (and its missing parents), made before slicing like the
    // bundle's parents, so that a path that cannot be a directory fails first.
    let made_plots = match opts.cure.plots.as_deref() {
        Some(dir) => Some(MadeDirs::parents_of(&dir.join("plot"))?),
        None => None,
    };
    let inputs = JobInputs {
        opts,
        profile: &profile,
        setup: &setup,
        part: &part,
        control: &control,
        out: &out,
        format,
    };
    let (made_job, cure) = unheld::made_held(&inputs, cure)?;
    let Made {
        writer,
        mut manifest,
        field,
        predicted_at,
        passes,
        ..
    } = made_job;
    // Once, on the pass that is written.
    if let Some(c) = cure.as_ref().filter(|c| c.predicts()) {
        let files = (&writer, field.as_ref());
        predict(c, &mut manifest, files, &part, &setup, predicted_at)?;
    }
    replays_clean(&manifest, part.path)?;
    if control.cancelled() {
        return Err(Error::Interrupted);
    }
    let (bundle, export_warnings) = write_out(writer, format, &manifest, &part, opts)?;
    made.keep();
    cure_plots(cure.as_ref(), opts, &manifest, made_plots)?;
    let mut warnings = manifest.warnings;
    warnings.extend(export_warnings);
    let finish_s = passes.finished.elapsed().as_secs_f64();
    Ok(SliceSummary {
        bundle,
        layers: part.layers,
        warnings,
        format,
        mesh: part.mesh.report,
        totals: manifest.totals,
        timings: Timings {
            load_s,
            slice_s: passes.slice_s,
            masks_s: passes.masks_s,
            analysis_cpu_s: passes.analysis_cpu_s,
            finish_s,
            total_s: t0.elapsed().as_secs_f64(),
        }
        .rounded(),
        distortion: manifest.settings.distortion.clone(),
        cure: manifest.cure,
        supports: manifest.supports.as_ref().map(SupportsSummary::of),
    })
}

/// What a job is made of, for each pass of [`make_job`].
struct JobInputs<'a> {
    opts: &'a SliceOptions<'a>,
    profile: &'a Profile,
    setup: &'a SetUp,
    part: &'a PlacedPart<'a>,
    control: &'a Control<'a>,
    out: &'a Path,
    format: Format,
}

/// The time the passes of [`make_job`] took.
#[derive(Clone, Copy)]
struct Passes {
    slice_s: f64,
    masks_s: f64,
    analysis_cpu_s: f64,
    /// When the last pass's layers were made.
    finished: Instant,
}

/// A job made and planned, before it is written.
struct Made {
    /// Its files.
    writer: Sink,
    manifest: bundle::Manifest,
    /// Each layer's masks' lit runs on the field, with supports.
    field_runs: Vec<Option<Arc<[Run]>>>,
    /// The field's coverage of a job of several projectors, for `--predict`.
    field: Option<Sink>,
    /// Where the prediction's warnings go among the manifest's.
    predicted_at: usize,
    passes: Passes,
    /// Each layer's record as the pipeline made it, and the slicing's repair counts,
    /// where a pass may be made again from this one ([`again::may_make_again`]).
    layers: Option<(Vec<layer::LayerOutput>, SliceStats)>,
}

impl Made {
    /// What the next pass takes from this one: its files and, where it may
    /// ([`again::may_make_again`]), its layers drawn with `plain` drawn plain.
    fn again(self, plain: uncorrected::Uncorrected) -> (Sink, Option<again::Again>) {
        let again = (self.layers).map(|l| again::Again::new(plain, l));
        (self.writer, again)
    }
}

/// One pass of the pipeline: the job's layers made with `cure` into a new bundle (or,
/// made `again`, into the pass before's, taking its blocks drawn alike) and planned (the
/// cure is predicted on the pass that is written, not here).
fn make_job(
    inputs: &JobInputs,
    cure: Option<&cure_records::CureJob>,
    again: Option<(Sink, Option<again::Again>)>,
) -> Result<Made> {
    let JobInputs {
        opts,
        profile,
        setup,
        part,
        control,
        out,
        format,
    } = *inputs;
    let (writer, again) = match again {
        Some(a) => a,
        None => (open_bundle(out, format, profile, setup)?, None),
    };
    // Several projectors' masks do not show the field's light: its coverage is kept for
    // the cure prediction.
    let field =
        (cure.is_some_and(|c| c.predicts()) && setup.tiler.is_some()).then(|| Sink::memory(out));
    let (mut sliced, gray_map) = make_layers(
        profile,
        setup,
        part,
        (&writer, field.as_ref()),
        control,
        (cure, opts.dose.as_ref(), again.as_ref()),
    )?;
    let finished = Instant::now();
    let tiled = setup.tiler.is_some();
    if let Some(a) = &again {
        sliced.stats = a.stats();
    }
    let layers = again::may_make_again(profile.supports.enabled, cure, tiled)
        .then(|| (sliced.layers.clone(), sliced.stats));
    let field_runs = sliced
        .layers
        .iter_mut()
        .map(|o| o.field_runs.take())
        .collect();
    let distortion = setup.correction.as_ref().map(Correction::report);
    let mut warnings = part.mesh_warnings();
    warnings.extend(slicing_warnings(&sliced.stats, distortion.as_ref()));
    let analysis_cpu_s = sliced.layers.iter().map(|o| o.analysis_s).sum();
    let mut planned = manifest::plan_layers(profile, sliced.layers, part)?;
    warnings.append(&mut planned.warnings);
    let mut optics = optics_records::optics_records(
        setup.optics.as_ref(),
        gray_map,
        setup.tiler.as_ref(),
        &writer,
        profile,
    )?;
    warnings.append(&mut optics.warnings);
    if opts.dose.is_some() {
        optics.compensation = "dose".into();
    }
    let predicted_at = warnings.len();
    if let Some(c) = cure {
        let what = what_at(part, profile.slicing.layer_height_mm.get());
        warnings.extend(c.dropped_warning(&what));
        warnings.extend(c.widened_warning(&what));
        warnings.extend(c.on_nothing_warning(&what));
        warnings.extend(unheld::plain_warning(c));
    }
    let mut manifest = manifest::manifest(part, profile, planned, optics, distortion, warnings);
    manifest.cure = cure.map(|c| c.record());
    something_to_print(&manifest, part.path)?;
    Ok(Made {
        writer,
        manifest,
        field_runs,
        field,
        predicted_at,
        passes: Passes {
            slice_s: sliced.slice_s,
            masks_s: sliced.masks_s,
            analysis_cpu_s,
            finished,
        },
        layers,
    })
}

/// Writes the support mesh (`--supports-stl`) and then the job through `writer` (in
/// `format` when it writes one file): the bundle's path and what the format could not carry. The support
/// mesh is removed again when the job cannot be written.
fn write_out(
    writer: Sink,
    format: Format,
    manifest: &bundle::Manifest,
    part: &PlacedPart,
    opts: &SliceOptions,
) -> Result<(PathBuf, Vec<Warning>)> {
    let stl = match (&opts.supports_stl, &part.support_mesh) {
        (Some(path), Some(m)) => {
            crate::output::write_atomic(path, &mesh::binary_stl(&m.soup()))?;
            Some(path)
        }
        _ => None,
    };
    let written = match writer {
        Sink::Dir(w) => w.finish(manifest).map(|b| (b, Vec::new())),
        Sink::Memory { out: o, kept } => {
            let files = MemoryFiles::new(&o, kept);
            crate::formats::write(format, manifest, &files, &o, opts.cancel).map(|w| (o, w))
        }
    };
    written.inspect_err(|_| {
        if let Some(p) = stl {
            let _ = std::fs::remove_file(p);
        }
    })
}

/// The cure prediction's pictures (`--cure-plots`) of the job `manifest`, into the
/// directory `made` made for them.
fn cure_plots(
    cure: Option<&cure_records::CureJob>,
    opts: &SliceOptions,
    manifest: &bundle::Manifest,
    made: Option<MadeDirs>,
) -> Result<()> {
    if let (Some(c), Some(dir)) = (cure, opts.cure.plots.as_deref()) {
        let stem = opts
            .input
            .file_stem()
            .map_or("part".into(), |s| s.to_string_lossy());
        c.write_plots(dir, &stem, manifest)?;
    }
    if let Some(m) = made {
        m.keep();
    }
    Ok(())
}

/// The cure of the job's masks (`files`: the bundle's, and the field's coverage of a job
/// of several projectors) into `manifest`, its warnings at `at` among the manifest's.
fn predict(
    cure: &cure_records::CureJob,
    manifest: &mut bundle::Manifest,
    (writer, field): (&Sink, Option<&Sink>),
    part: &PlacedPart,
    setup: &SetUp,
    at: usize,
) -> Result<()> {
    let warp = setup.correction.as_ref().map(|w| (w, part.path));
    let field = field.map(|f| f as &dyn bundle::BundleSource);
    let h = manifest.settings.layer_height_mm;
    let offset = manifest
        .settings
        .accuracy
        .as_ref()
        .map_or(0.0, |a| a.xy_offset_mm);
    cure.predict(manifest, writer, field, part.slicer(h, offset), warp)?;
    let w = cure_records::warnings(&manifest.layers, &what_at(part, h));
    manifest.warnings.splice(at..at, w);
    Ok(())
}

/// What the cure's messages name besides a position: [`PlacedPart::what_at`] of a layer
/// (layers `h` mm high).
fn what_at<'a>(part: &'a PlacedPart, h: f64) -> impl Fn([f64; 2], u64) -> Option<String> + 'a {
    move |xy, layer| part.what_at(xy, crate::slice::plane_z(layer as usize, h))
}

/// An error naming the model `path` when no layer of `manifest` has a closed section.
fn something_to_print(manifest: &bundle::Manifest, path: &Path) -> Result<()> {
    if manifest.layers.iter().all(|l| l.area_mm2 <= 0.0) {
        return Err(Error::Job {
            path: path.into(),
            msg: match manifest.layers.len() {
                1 => "nothing to print: the only layer has no closed section (an open surface or a part of zero volume)".into(),
                n => format!("nothing to print: none of the {n} layers has a closed section (an open surface or a part of zero volume)"),
            },
        });
    }
    Ok(())
}

/// A job dmdsl writes replays clean in `dmdsl run`: the planned steps are simulated
/// ([`crate::exec::replay`]) before the bundle is moved into place, and any violation
/// (a move outside the travel, a step the stage cannot make, times that overflow, …) is an
/// error naming the model, so nothing is written.
fn replays_clean(manifest: &bundle::Manifest, path: &Path) -> Result<()> {
    let violations = crate::exec::replay(manifest);
    match violations.first() {
        None => Ok(()),
        Some(v) => Err(Error::Job {
            path: path.into(),
            msg: format!(
                "the planned job does not replay clean on its machine: {}{}",
                v.message,
                match violations.len() {
                    1 => String::new(),
                    k => format!(" (and {} more)", k - 1),
                }
            ),
        }),
    }
}

/// Sets the machine up for the job (completing `profile`) and reads and places the model.
/// The two are independent: they run side by side. Set-up errors are reported first.
fn load_and_place<'a>(
    opts: &'a SliceOptions<'a>,
    profile: &mut Profile,
    corrected: bool,
) -> Result<(SetUp, PlacedPart<'a>)> {
    let path = opts.input.as_path();
    let (setup, loaded) = rayon::join(
        || set_up(opts, profile),
        || read_model(path, opts.input_bytes),
    );
    let setup = setup?;
    let (sha256, mut mesh) = loaded?;
    let h = profile.slicing.layer_height_mm.get();
    let bbox_in_file = mesh.bbox();
    opts.transform.validate().map_err(|msg| Error::Job {
        path: path.into(),
        msg,
    })?;
    if let Some(plate) = &opts.plate {
        let mut part = plate::place_plate(opts, plate, profile, (sha256, mesh))?;
        if profile.supports.enabled {
            supported::add_supports(&mut part, profile, corrected)?;
        }
        return Ok((setup, part));
    }
    opts.transform.apply(&mut mesh);
    mesh.scale_axes(profile.accuracy.scale);
    let (translate_mm, layers) = place_mesh(path, &mut mesh, profile, opts.placement, h)?;
    let mut part = PlacedPart {
        path,
        sha256,
        mesh,
        bbox_in_file,
        transform: opts.transform,
        mode: opts.placement,
        translate_mm,
        layers,
        plate: None,
        supports: None,
        support_edges: None,
        support_mesh: None,
    };
    if profile.supports.enabled {
        supported::add_supports(&mut part, profile, corrected)?;
    }
    Ok((setup, part))
}

/// The directories made for a bundle's path: its missing parents, created before the
/// bundle is opened and removed again (those still empty, deepest first) when the job
/// fails, unless [`kept`](MadeDirs::keep).
struct MadeDirs {
    /// Created, outermost first.
    dirs: Vec<PathBuf>,
    keep: bool,
}

impl MadeDirs {
    /// Creates the missing parent directories of `out`.
    fn parents_of(out: &Path) -> Result<MadeDirs> {
        let mut missing = Vec::new();
        let mut parent = out.parent();
        while let Some(d) = parent.filter(|d| !d.as_os_str().is_empty()) {
            if d.exists() {
                break;
            }
            missing.push(d.to_path_buf());
            parent = d.parent();
        }
        let mut made = MadeDirs {
            dirs: Vec::new(),
            keep: false,
        };
        for d in missing.into_iter().rev() {
            match std::fs::create_dir(&d) {
                Ok(()) => made.dirs.push(d),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(Error::io(d, e)),
            }
        }
        Ok(made)
    }

    /// Keeps the directories: the bundle is in place.
    fn keep(mut self) {
        self.keep = true;
    }
}

impl Drop for MadeDirs {
    fn drop(&mut self) {
        if !self.keep {
            for d in self.dirs.iter().rev() {
                let _ = std::fs::remove_dir(d);
            }
        }
    }
}

/// Creates the bundle's staging directory for `out`, with a mask folder per projector
/// when tiled; or, for a one-file `format`, the place in memory its files go until it is
/// written.
fn open_bundle(out: &Path, format: Format, profile: &Profile, setup: &SetUp) -> Result<Sink> {
    let writer = if format.is_one_file() {
        Sink::memory(out)
    } else {
        Sink::Dir(BundleWriter::create(out)?)
    };
    if setup.tiler.is_some() {
        for k in 0..profile.projector.len() {
            writer.create_dir(&format!("masks/p{k}"))?;
        }
    }
    Ok(writer)
}

/// Slices the placed part and makes every layer's masks (the pipeline), writing the
/// single projector's gray map beside them; returns the layers and the gray map's file
/// and SHA-256.
fn make_layers(
    profile: &Profile,
    setup: &SetUp,
    part: &PlacedPart,
    (writer, field_store): (&Sink, Option<&Sink>),
    control: &Control,
    (cure, dose, again): (
        Option<&cure_records::CureJob>,
        Option<&Mask>,
        Option<&again::Again>,
    ),
) -> Result<(pipeline::PipelineOutput, Option<WrittenGrayMap>)> {
    let h = profile.slicing.layer_height_mm.get();
    let field = profile.field();
    let n = part.layers;
    let raster = Rasterizer::new(field);
    let recent = RecentPrismMasks::default();
    let ctx = LayerContext {
        writer,
        profile,
        raster: &raster,
        optics: setup.optics.as_ref(),
        tiler: setup.tiler.as_ref(),
        correction: setup.correction.as_ref(),
        model: part.path,
        // Reusing masks across blocks: one projector, no distortion correction.
        recent: (setup.tiler.is_none() && setup.correction.is_none()).then_some(&recent),
        binary: profile.slicing.binary,
        px_area_mm2: field.pixel_mm * field.pixel_mm,
        cure,
        field: field_store,
        dose,
        again,
    };
    let gray_map = OnceLock::new();
    let slicer = part.slicer(h, profile.accuracy.xy_offset_mm);
    let slicer = match again {
        Some(a) => slicer.only(a.wanted(cure)),
        None => slicer,
    };
    let sliced = pipeline::run(&ctx, slicer, n, control, || {
        // The gray map depends on the set-up only: written while the masks are made (its
        // encoding would otherwise wait for the last layer).
        if let Some(o) = ctx.optics {
            let _ = gray_map.set(optics_records::write_gray_map(o, writer, profile));
        }
    })?;
    Ok((sliced, gray_map.into_inner()))
}

/// Warnings about the slicing: contours repaired, distortion corrections extrapolated.
fn slicing_warnings(stats: &SliceStats, distortion: Option<&FitReport>) -> Vec<Warning> {
    let mut warnings = Vec::new();
    if stats.repaired_layers > 0 {
        let n = stats.repaired_layers as u64;
        warnings.push(
            Warning::new(
                "slice.contours-repaired",
                format!(
                    "{n} {} open contours: {} closed, {} dropped",
                    plural(n, "layer had", "layers had"),
                    stats.joined_chains,
                    stats.dropped_chains
                ),
            )
            .with("layers", n)
            .with("closed", stats.joined_chains as u64)
            .with("dropped", stats.dropped_chains as u64),
        );
    }
    if let Some(r) = distortion.filter(|r| r.extrapolated_points > 0) {
        warnings.push(
            Warning::new(
                "distortion.extrapolated",
                format!(
                    "distortion: {} warped {} outside the area the table ({}) measured; {} extrapolated",
                    r.extrapolated_points,
                    plural(r.extrapolated_points, "point lies", "points lie"),
                    r.source,
                    plural(r.extrapolated_points, "its correction is", "their correction is")
                ),
            )
            .with("points", r.extrapolated_points)
            .with("table", r.source.clone()),
        );
    }
    warnings
}

/// The machine's per-job set-up for `profile` (which it completes): light compensation
/// tables, or for several projectors the tiling, and the distortion fit.
fn set_up(opts: &SliceOptions, profile: &mut Profile) -> Result<SetUp> {
    let h = profile.slicing.layer_height_mm.get();
    // Several projectors: tiling (geometry::tile) does their blending and compensation.
    let (optics, tiler) = if profile.projector.len() > 1 {
        (None, Some(Tiler::for_job(profile, &opts.optics, h)?))
    } else {
        (crate::optics::prepare(profile, &opts.optics, h)?, None)
    };
    let correction = distortion::for_job(&opts.distortion, profile)?;
    Ok(SetUp {
        optics,
        tiler,
        correction,
    })
}

/// Reads the model file (or takes its `bytes`, already read): its SHA-256 and its mesh
/// (loaded and validated).
fn read_model(path: &Path, bytes: Option<&[u8]>) -> Result<(String, Mesh)> {
    let read;
    let bytes = match bytes {
        Some(b) => b,
        None => {
            read = crate::input::read_file(path, "mesh file", crate::input::MESH_MAX_BYTES)?;
            &read[..]
        }
    };
    let (sha, mesh) = rayon::join(
        || bundle::sha256_hex(bytes),
        || mesh::load_bytes(path, bytes),
    );
    Ok((sha, mesh?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::Step;
    use crate::exec::testutil;

    #[test]
    fn a_job_that_would_not_replay_clean_is_refused() {
        let good = testutil::two_layer_topdown();
        assert!(replays_clean(&good, Path::new("part.stl")).is_ok());
        // Dip beyond the travel (0..120 mm) and expose longer than planned.
        let mut bad = good.clone();
        bad.layers[1].steps[0] = Step::Move {
            to_mm: 500.0,
            speed_mm_s: 2.0,
            accel_mm_s2: 50.0,
        };
        let e = replays_clean(&bad, Path::new("part.stl"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("part.stl: the planned job does not replay clean"),
            "{e}"
        );
        assert!(e.contains("leaves the stage travel"), "{e}");
        assert!(!e.contains('\n'), "{e}");
    }
}
