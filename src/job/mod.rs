//! The slicing pipeline: load → place → slice → (per layer, in parallel) raster → encode →
//! hash → write; then plan and write the manifest, atomically.
//!
//! One thread slices windows of 32 layers and hands each window to rayon's pool in blocks
//! of 8 consecutive layers as soon as it is cut (no barrier between windows); at most 96
//! layers wait for a worker, and a worker keeps only its current mask, so memory does not
//! grow with the number of layers (but for the lit runs of a block's first and last layers,
//! a few kilobytes each, kept until the end for the islands of the blocks' first layers).
//! Every output byte depends only on the input and the settings, never on the thread count
//! or timing.

use crate::bundle::{
    self, BundleWriter, Generator, Layer, Manifest, MaskRef, Placement, Settings, Source, Totals,
};
use crate::error::{Error, Result};
use crate::geometry::distortion::{self, Correction, DistortionChoice, FitReport};
use crate::geometry::tile::Tiler;
use crate::mesh::{self, Mesh, MeshReport};
use crate::plan::{self, LayerAnalysis, LayerInfo};
use crate::profile::Profile;
use crate::raster::{projector_view, Mask, Rasterizer, Scratch};
use crate::slice::{self, Section};
use crate::units::Positive;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

/// Where the part goes on the build plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlacementMode {
    /// XY bounding box centred on the field, lowest point at z = 0.
    Center,
    /// File coordinates are build-plane coordinates.
    Keep,
}

/// Options of [`slice_to_bundle`].
pub struct SliceOptions<'a> {
    /// The model file.
    pub input: PathBuf,
    /// Bundle path; `None`: `<input stem>.dmdjob` in the current directory.
    pub output: Option<PathBuf>,
    /// Machine profile (already resolved).
    pub profile: Profile,
    /// Overrides the profile's layer height.
    pub layer_height_mm: Option<Positive>,
    /// Overrides the profile's binary setting.
    pub binary: Option<bool>,
    /// Placement rule.
    pub placement: PlacementMode,
    /// Light compensation (mode, dithering).
    pub optics: crate::optics::OpticsOptions,
    /// Called with (layers done, layers total) as layers are written.
    pub progress: Option<&'a (dyn Fn(usize, usize) + Sync)>,
    /// Set to abort (Ctrl-C); the pipeline stops and writes nothing.
    pub cancel: Option<&'a AtomicBool>,
    /// Lens distortion correction (`--distortion`; default: the profile's).
    pub distortion: DistortionChoice,
}

/// Wall time of each stage, s.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Timings {
    /// Reading, welding and validating the mesh.
    pub load_s: f64,
    /// Cutting and chaining contours (time spent by the slicing thread; part of `masks_s`'s
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

/// What [`slice_to_bundle`] produced.
#[derive(Debug, Clone, Serialize)]
pub struct SliceSummary {
    /// The bundle written.
    pub bundle: PathBuf,
    /// Number of layers.
    pub layers: usize,
    /// Warnings (mesh defects, repairs).
    pub warnings: Vec<String>,
    /// Mesh validation report.
    pub mesh: MeshReport,
    /// Totals as in the manifest.
    pub totals: Totals,
    /// Stage timings.
    pub timings: Timings,
    /// Distortion fit report, when a correction was applied.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distortion: Option<FitReport>,
}

/// Default bundle path for an input: `<stem>.dmdjob` in the current directory.
pub fn default_output(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "part".into());
    PathBuf::from(format!("{stem}.dmdjob"))
}

/// Computes the translation that places `bbox` on the field, or an error if it cannot fit.
pub fn placement(
    path: &Path,
    bbox: [[f64; 3]; 2],
    field_w: f64,
    field_h: f64,
    mode: PlacementMode,
) -> Result<[f64; 3]> {
    let [lo, hi] = bbox;
    let size = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    if size[0] > field_w || size[1] > field_h {
        return Err(Error::Job {
            path: path.into(),
            msg: format!(
                "part is {:.3} x {:.3} mm but the build field is {:.3} x {:.3} mm",
                size[0], size[1], field_w, field_h
            ),
        });
    }
    let t = match mode {
        PlacementMode::Center => [
            field_w / 2.0 - (lo[0] + hi[0]) / 2.0,
            field_h / 2.0 - (lo[1] + hi[1]) / 2.0,
            -lo[2],
        ],
        PlacementMode::Keep => {
            let eps = 1e-9;
            if lo[0] < -eps || lo[1] < -eps || hi[0] > field_w + eps || hi[1] > field_h + eps {
                return Err(Error::Job {
                    path: path.into(),
                    msg: format!(
                        "with --keep-position the part spans x {:.3}..{:.3}, y {:.3}..{:.3} mm, outside the build field 0..{:.3} x 0..{:.3} mm",
                        lo[0], hi[0], lo[1], hi[1], field_w, field_h
                    ),
                });
            }
            if lo[2] < -eps {
                return Err(Error::Job {
                    path: path.into(),
                    msg: format!(
                        "with --keep-position the part reaches below the build plane (z min {:.3} mm)",
                        lo[2]
                    ),
                });
            }
            [0.0, 0.0, 0.0]
        }
    };
    Ok(t)
}

/// Places a loaded mesh on `field` by `mode` (translating it) and returns the translation
/// and the number of layers of height `h`; a part that does not fit or is thinner than one
/// layer is an error naming `path`. `slice_to_bundle`, the benchmarks and tools that drive
/// the stages themselves share this.
pub fn place_mesh(
    path: &Path,
    mesh: &mut Mesh,
    field: &crate::profile::Field,
    mode: PlacementMode,
    h: f64,
) -> Result<([f64; 3], usize)> {
    let bbox = mesh.bbox();
    let t = placement(path, bbox, field.width_mm(), field.height_mm(), mode)?;
    mesh.translate(t);
    let n = slice::layer_count(bbox[1][2] + t[2], h);
    if n == 0 {
        return Err(Error::Job {
            path: path.into(),
            msg: format!(
                "part is {:.4} mm tall, less than one layer ({h} mm): nothing to print",
                bbox[1][2] - bbox[0][2]
            ),
        });
    }
    Ok((t, n))
}

/// Encodes a mask as an 8-bit grayscale PNG ([`crate::png`]; deterministic).
pub fn encode_png(m: &Mask) -> Vec<u8> {
    crate::png::encode_gray8(m.width, m.height, &m.data)
}

/// Layers sliced at a time: memory depends on this, not on the number of layers.
const WINDOW: usize = 32;
/// Consecutive layers one worker processes in order. Its first layer's analysis scans the
/// layer below again (islands) and cannot copy the analysis of an equal layer below
/// (prisms): larger blocks do that less often (8 rather than 4: −2.8 % analysis
/// instructions on logo_hires), smaller ones balance the workers better at the end.
pub const BLOCK: usize = 8;
/// Layers sliced but not yet made into masks, at most (bounds memory).
const MAX_AHEAD: usize = 3 * WINDOW;

/// Subtracts a block's layer count from the layers in flight when the block ends.
struct Leaving<'a>(&'a AtomicUsize, usize);

impl Drop for Leaving<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(self.1, Ordering::AcqRel);
    }
}

/// A [`Scratch`] borrowed from a pool and returned to it when dropped.
struct Pooled<'p> {
    pool: &'p Mutex<Vec<Scratch>>,
    scratch: Option<Scratch>,
}

impl<'p> Pooled<'p> {
    fn take(pool: &'p Mutex<Vec<Scratch>>) -> Self {
        let scratch = pool
            .lock()
            .ok()
            .and_then(|mut v| v.pop())
            .unwrap_or_default();
        Pooled {
            pool,
            scratch: Some(scratch),
        }
    }
}

impl std::ops::Deref for Pooled<'_> {
    type Target = Scratch;
    fn deref(&self) -> &Scratch {
        self.scratch.as_ref().expect("present until drop")
    }
}

impl std::ops::DerefMut for Pooled<'_> {
    fn deref_mut(&mut self) -> &mut Scratch {
        self.scratch.as_mut().expect("present until drop")
    }
}

impl Drop for Pooled<'_> {
    fn drop(&mut self) {
        if let (Some(s), Ok(mut v)) = (self.scratch.take(), self.pool.lock()) {
            v.push(s);
        }
    }
}

/// One layer handed to a mask worker.
struct LayerIn<'a> {
    index: usize,
    section: &'a Section,
    /// The section of the layer below (None for layer 0), for analyses that compare layers.
    below: Option<&'a Section>,
}

struct LayerOut {
    area_mm2: f64,
    analysis: plan::analysis::Analysed,
    analysis_s: f64,
    masks: Vec<MaskRef>,
    /// The layer's lit pixels, kept where another block needs them: for its own islands
    /// ([`plan::analysis::Analysed::NeedsBelow`]) or those of the next layer (the last
    /// layer of a block).
    runs: Option<plan::analysis::LitRuns>,
}

/// Slices a model into a job bundle. See the module docs for the pipeline.
pub fn slice_to_bundle(opts: &SliceOptions) -> Result<SliceSummary> {
    let t0 = Instant::now();
    let mut profile = opts.profile.clone();
    if let Some(h) = opts.layer_height_mm {
        profile.slicing.layer_height_mm = h;
    }
    if let Some(b) = opts.binary {
        profile.slicing.binary = b;
    }
    let h = profile.slicing.layer_height_mm.get();
    let tiled = profile.projector.len() > 1;
    let path = opts.input.as_path();
    // The machine's per-job set-up (light compensation tables, distortion fit) and reading
    // the model are independent: they run side by side. Set-up errors are reported first.
    let (setup, loaded) = rayon::join(
        || -> Result<_> {
            // Several projectors: tiling (geometry::tile) does their blending and
            // compensation.
            let (optics, tiler) = if tiled {
                (None, Some(Tiler::for_job(&mut profile, &opts.optics, h)?))
            } else {
                (crate::optics::prepare(&mut profile, &opts.optics, h)?, None)
            };
            let correction = distortion::for_job(&opts.distortion, &mut profile)?;
            Ok((optics, tiler, correction))
        },
        || -> Result<(String, Mesh)> {
            let bytes = std::fs::read(path).map_err(|e| {
                if path.is_dir() {
                    Error::input(path, "is a directory, not a mesh file")
                } else {
                    Error::io(path, e)
                }
            })?;
            let (sha, mesh) = rayon::join(
                || bundle::sha256_hex(&bytes),
                || mesh::load_bytes(path, &bytes),
            );
            Ok((sha, mesh?))
        },
    );
    let (optics, tiler, correction) = setup?;
    let (sha, mut mesh) = loaded?;
    let field = profile.field();
    let bbox = mesh.bbox();
    let mode = opts.placement;
    let (t, n) = place_mesh(path, &mut mesh, &field, mode, h)?;
    let mut warnings = mesh.report.warnings();
    let t_load = t0.elapsed().as_secs_f64();

    let out_path = opts.output.clone().unwrap_or_else(|| default_output(path));
    let writer = BundleWriter::create(&out_path)?;
    if tiled {
        for k in 0..profile.projector.len() {
            writer.create_dir(&format!("masks/p{k}"))?;
        }
    }
    let raster = Rasterizer::new(field);
    let done = AtomicUsize::new(0);
    let px_area = field.pixel_mm * field.pixel_mm;
    let binary = profile.slicing.binary;
    let mut slicer = slice::Slicer::new(&mesh, h, n);
    let scratch_pool = Mutex::new(Vec::new());
    let shared_made = SharedMade::default();
    // Reusing masks across blocks (SharedMade): one projector, no distortion correction.
    let shared_made = (!tiled && correction.is_none()).then_some(&shared_made);
    // One slot per layer, filled by whichever worker makes it.
    let slots: Vec<OnceLock<LayerOut>> = (0..n).map(|_| OnceLock::new()).collect();
    let failure: Mutex<Option<Error>> = Mutex::new(None);
    let stop = AtomicBool::new(false);
    let in_flight = AtomicUsize::new(0);
    let gray_map: OnceLock<Result<(String, String)>> = OnceLock::new();
    let cancelled = || opts.cancel.is_some_and(|c| c.load(Ordering::Relaxed));
    let mut t_slice = 0.0;
    let tm = Instant::now();
    // The slicer runs on one worker, window after window, and hands each window's layers
    // to the pool in blocks as soon as they are cut: no barrier between windows, so the
    // slicing and every block overlap. At most MAX_AHEAD layers wait (memory stays
    // bounded); while it waits, the slicing thread makes masks itself.
    rayon::scope(|scope| {
        let (slots, failure, stop, in_flight) = (&slots, &failure, &stop, &in_flight);
        let gray_map = &gray_map;
        let (scratch_pool, done, raster, profile) = (&scratch_pool, &done, &raster, &profile);
        let (writer, optics, tiler, correction) = (
            &writer,
            optics.as_ref(),
            tiler.as_ref(),
            correction.as_ref(),
        );
        // The gray map depends on the set-up only: written while the masks are made (its
        // encoding would otherwise wait for the last layer).
        if let Some(o) = optics {
            scope.spawn(move |_| {
                let r = o.write_gray_map(writer, profile, encode_png);
                let _ = gray_map.set(r);
            });
        }
        let mut prev: Option<Arc<Vec<Section>>> = None;
        for start in (0..n).step_by(WINDOW) {
            while in_flight.load(Ordering::Acquire) > MAX_AHEAD && !stop.load(Ordering::Relaxed) {
                if rayon::yield_now() != Some(rayon::Yield::Executed) {
                    std::thread::sleep(std::time::Duration::from_micros(50));
                }
            }
            if stop.load(Ordering::Relaxed) || cancelled() {
                break;
            }
            let ts = Instant::now();
            let sections = Arc::new(slicer.window(start..start + WINDOW));
            t_slice += ts.elapsed().as_secs_f64();
            let m = sections.len();
            for b in 0..m.div_ceil(BLOCK) {
                let (sections, prev) = (Arc::clone(&sections), prev.clone());
                let ks = b * BLOCK..((b + 1) * BLOCK).min(m);
                in_flight.fetch_add(ks.len(), Ordering::AcqRel);
                scope.spawn(move |_| {
                    // Counts the block's layers off even if it panics (the panic reaches
                    // the caller when the scope ends; the slicing thread must not wait).
                    let _leaving = Leaving(in_flight, ks.len());
                    let run = || -> Result<()> {
                        // Scratch buffers (megabytes) outlive blocks: fresh ones would
                        // page-fault on every block.
                        let mut scratch = Pooled::take(scratch_pool);
                        let scratch = &mut *scratch;
                        let mut analyser = plan::analysis::Analyser::new();
                        let mut made = None;
                        let last = ks.end - 1;
                        for k in ks {
                            if stop.load(Ordering::Relaxed) || cancelled() {
                                return Err(Error::Interrupted);
                            }
                            let layer = LayerIn {
                                index: start + k,
                                section: &sections[k],
                                below: if k == 0 {
                                    prev.as_ref().and_then(|p| p.last())
                                } else {
                                    Some(&sections[k - 1])
                                },
                            };
                            let mut out = layer_masks(
                                writer,
                                profile,
                                raster,
                                scratch,
                                (&mut analyser, &mut made, shared_made),
                                &layer,
                                binary,
                                tiled,
                                px_area,
                                optics,
                                (correction, path),
                                tiler,
                            )?;
                            // The next block's first layer counts its islands over these.
                            if k == last && start + k + 1 < n && out.runs.is_none() {
                                out.runs = analyser.last_runs().cloned();
                            }
                            let _ = slots[start + k].set(out);
                            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
                            if let Some(p) = opts.progress {
                                p(d, n);
                            }
                        }
                        Ok(())
                    };
                    if let Err(e) = run() {
                        stop.store(true, Ordering::Relaxed);
                        let mut f = failure.lock().unwrap_or_else(|p| p.into_inner());
                        // Keep the first real error (others may just be the stop it caused).
                        if f.as_ref()
                            .is_none_or(|old| matches!(old, Error::Interrupted))
                        {
                            *f = Some(e);
                        }
                    }
                });
            }
            prev = Some(sections);
        }
    });
    let t_masks = tm.elapsed().as_secs_f64();
    if let Some(e) = failure.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(e);
    }
    if cancelled() {
        return Err(Error::Interrupted);
    }
    let outs: Vec<LayerOut> = slots
        .into_iter()
        .map(|s| s.into_inner().expect("every layer is made"))
        .collect();
    let stats = slicer.stats;
    if stats.repaired_layers > 0 {
        warnings.push(format!(
            "{} layers had open contours: {} closed, {} dropped (repair rule in README)",
            stats.repaired_layers, stats.joined_chains, stats.dropped_chains
        ));
    }

    let distortion_report = correction.as_ref().map(Correction::report);
    if let Some(r) = distortion_report
        .as_ref()
        .filter(|r| r.extrapolated_points > 0)
    {
        warnings.push(format!(
            "distortion: {} warped points lie outside the area the table ({}) measured; their correction is extrapolated",
            r.extrapolated_points, r.source
        ));
    }

    let t3 = Instant::now();
    let analysis_cpu_s = outs.iter().map(|o| o.analysis_s).sum();
    // A layer equal to the layer below that its worker could not copy takes the layer
    // below's analysis here, and a block's first layer counts its islands over the last
    // layer of the block below.
    let mut analyses: Vec<LayerAnalysis> = Vec::with_capacity(n);
    for (i, o) in outs.iter().enumerate() {
        let a = o.analysis.with_islands(|| {
            let own = o.runs.as_ref().expect("kept with the analysis");
            let below = outs[i - 1].runs.as_ref().expect("kept by the block below");
            plan::analysis::islands(own, below)
        });
        analyses.push(a.resolve(analyses.last()));
    }
    let infos: Vec<LayerInfo> = outs
        .iter()
        .zip(&analyses)
        .enumerate()
        .map(|(i, (o, a))| LayerInfo {
            index: i,
            z_mm: (i + 1) as f64 * h,
            thickness_mm: h,
            area_mm2: o.area_mm2,
            max_fill_distance_mm: a.max_fill_distance_mm,
            islands: a.islands,
        })
        .collect();
    let plan = plan::plan(&profile, &infos).map_err(|msg| Error::Job {
        path: path.into(),
        msg,
    })?;
    warnings.extend(plan.warnings.iter().cloned());
    let hybrid = profile.process == crate::profile::Process::Hybrid;
    let mut layers = Vec::with_capacity(n);
    let mut totals = Totals {
        layers: n as u64,
        height_mm: n as f64 * h,
        print_time_s: 0.0,
        exposure_s: 0.0,
        resin_volume_ml: 0.0,
        continuous_layers: hybrid.then_some(plan.continuous_layers as u64),
        all_layered_time_s: plan.all_layered_time_s,
    };
    for (((info, o), a), p) in infos.iter().zip(outs).zip(&analyses).zip(plan.layers) {
        totals.print_time_s += p.time_s;
        totals.exposure_s += p.exposure_s;
        totals.resin_volume_ml += info.area_mm2 * h / 1000.0;
        layers.push(Layer {
            index: info.index as u64,
            z_mm: info.z_mm,
            slice_z_mm: slice::plane_z(info.index, h),
            thickness_mm: h,
            mode: p.mode,
            exposure_s: p.exposure_s,
            area_mm2: o.area_mm2,
            max_fill_distance_mm: a.max_fill_distance_mm,
            islands: a.islands,
            bbox_mm: a.bbox_mm,
            masks: o.masks,
            steps: p.steps,
            time_s: p.time_s,
        });
    }
    let optics_record = match &optics {
        Some(o) => {
            let written = gray_map
                .into_inner()
                .expect("written in the masks' scope")?;
            let (record, w) = o.finish_with(written)?;
            warnings.extend(w);
            Some(record)
        }
        None => None,
    };
    let projector_optics = match &tiler {
        Some(t) => {
            let (records, w) = t.finish(&writer, &profile, encode_png)?;
            warnings.extend(w);
            records
        }
        None => Vec::new(),
    };
    let manifest = Manifest {
        format: bundle::FORMAT.into(),
        version: bundle::VERSION,
        generator: Generator::current(),
        source: Source {
            file: path
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            sha256: sha,
            triangles: mesh.report.triangles_in_file,
            bbox_mm: bbox,
            placement: Placement {
                mode: match mode {
                    PlacementMode::Center => "center",
                    PlacementMode::Keep => "keep",
                }
                .into(),
                translate_mm: t,
            },
            mesh: mesh.report.clone(),
        },
        settings: Settings {
            layer_height_mm: h,
            binary,
            compensation: match &tiler {
                Some(t) => t.compensation().as_str().into(),
                None => optics_record
                    .as_ref()
                    .map_or("off".into(), |o| o.mode.clone()),
            },
            distortion: distortion_report.clone(),
        },
        machine: profile.clone(),
        totals: totals.clone(),
        warnings: warnings.clone(),
        layers,
        optics: optics_record,
        projector_optics,
    };
    if opts.cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
        return Err(Error::Interrupted);
    }
    let bundle_path = writer.finish(&manifest)?;
    let t_finish = t3.elapsed().as_secs_f64();
    Ok(SliceSummary {
        bundle: bundle_path,
        layers: n,
        warnings,
        mesh: mesh.report,
        totals,
        timings: Timings {
            load_s: t_load,
            slice_s: t_slice,
            masks_s: t_masks,
            analysis_cpu_s,
            finish_s: t_finish,
            total_s: t0.elapsed().as_secs_f64(),
        },
        distortion: distortion_report,
    })
}

/// The masks a worker made for its previous layer, kept for a following layer with the
/// same section.
struct Made {
    index: usize,
    /// Whether they were drawn from the section without collinear points (the layer was
    /// equal to the layer below).
    simplified: bool,
    masks: Arc<MadeMasks>,
}

/// What drawing one section gave.
struct MadeMasks {
    /// Whether drawing them reported the layer to the light compensation as reaching
    /// outside the calibrated area (a copy reports it again: every such layer counts).
    outside: bool,
    area_mm2: f64,
    /// PNG bytes, SHA-256 and projector of each mask.
    pngs: Vec<(Vec<u8>, String, u32)>,
    /// The lit pixels (for the islands) when drawn from a simplified section, which
    /// [`SharedMade`] may hand to another worker; empty otherwise.
    runs: plan::analysis::LitRuns,
}

/// Entries of [`SharedMade`] at most (each holds one layer's PNG files and section).
const SHARED_MADE: usize = 4;

/// The masks recently drawn from simplified sections (layers equal to the layer below),
/// shared by the workers: the first layer of a block, whose layer below another worker
/// drew, reuses them when its simplified section is the same, bit for bit (prisms; within
/// a block [`Made`] does this). The same section draws the same bytes, so a hit changes
/// only the speed, never the output, whichever worker drew it first. Only for one
/// projector without a distortion correction (where drawing a layer counts nothing but
/// what [`MadeMasks`] replays); at most [`SHARED_MADE`] entries, the oldest dropped.
#[derive(Default)]
struct SharedMade(Mutex<Vec<(Vec<crate::slice::Contour>, Arc<MadeMasks>)>>);

/// Whether two sections are the same, bit for bit (−0 ≠ +0, NaN = NaN).
fn same_bits(a: &[crate::slice::Contour], b: &[crate::slice::Contour]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            p.len() == q.len()
                && p.iter().zip(q).all(|(u, v)| {
                    u[0].to_bits() == v[0].to_bits() && u[1].to_bits() == v[1].to_bits()
                })
        })
}

impl SharedMade {
    fn get(&self, section: &[crate::slice::Contour]) -> Option<Arc<MadeMasks>> {
        let v = self.0.lock().ok()?;
        v.iter()
            .rev()
            .find(|(s, _)| same_bits(s, section))
            .map(|(_, m)| Arc::clone(m))
    }

    fn put(&self, section: &[crate::slice::Contour], masks: &Arc<MadeMasks>) {
        if let Ok(mut v) = self.0.lock() {
            if v.iter().any(|(s, _)| same_bits(s, section)) {
                return;
            }
            if v.len() >= SHARED_MADE {
                v.remove(0);
            }
            v.push((section.to_vec(), Arc::clone(masks)));
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn layer_masks(
    writer: &BundleWriter,
    profile: &Profile,
    raster: &Rasterizer,
    scratch: &mut Scratch,
    (analyser, made, shared): (
        &mut plan::analysis::Analyser,
        &mut Option<Made>,
        Option<&SharedMade>,
    ),
    layer: &LayerIn,
    binary: bool,
    tiled: bool,
    px_area: f64,
    optics: Option<&crate::optics::JobOptics>,
    (correction, model): (Option<&Correction>, &Path),
    tiler: Option<&Tiler>,
) -> Result<LayerOut> {
    let i = layer.index;
    let below = layer.below.map(|b| b.contours.as_slice());
    // A layer whose section equals the layer below's once collinear points are left out
    // (prisms; plan::analysis) is drawn from that simplified section, so equal layers get
    // equal masks: when this worker drew the layer below that way, its bytes serve again.
    let ta = ThreadClock::start();
    // The rasterizer keeps each mask's lit pixels for the islands.
    scratch.record_runs = !cfg!(feature = "bench-no-analysis");
    let same = analyser.equals_below(i, &layer.section.contours, below);
    let mut analysis_s = ta.elapsed_s();
    let file_name = |k: usize| {
        if tiled {
            format!("masks/p{k}/{i:05}.png")
        } else {
            format!("masks/{i:05}.png")
        }
    };
    let mut masks = Vec::with_capacity(profile.projector.len());
    let reusable = made
        .take()
        .filter(|m| same && m.simplified && m.index + 1 == i)
        .map(|m| m.masks);
    // Drawn by this worker for the layer below: the analyser keeps that layer's lit pixels.
    let from_below = reusable.is_some();
    let reusable = reusable.or_else(|| {
        let shared = shared.filter(|_| same)?;
        shared.get(analyser.simplified_section())
    });
    // The mask's lit pixels are the scratch's when it is drawn, the layer below's (which
    // the analyser keeps) when this worker's bytes serve again, and those kept with the
    // shared masks when another worker drew them.
    let drawn = reusable.is_none();
    let area_mm2 = if let Some(m) = reusable {
        if m.outside {
            if let Some(o) = optics {
                use crate::raster::CoverageMap;
                o.compensator.lit_outside();
            }
        }
        for (k, (png, sha, projector)) in m.pngs.iter().enumerate() {
            let file = file_name(k);
            writer.write_file(&file, png)?;
            masks.push(MaskRef {
                file,
                sha256: sha.clone(),
                projector: *projector,
            });
        }
        let area_mm2 = m.area_mm2;
        *made = Some(Made {
            index: i,
            simplified: true,
            masks: m,
        });
        area_mm2
    } else {
        let section: &[crate::slice::Contour] = if same {
            analyser.simplified_section()
        } else {
            &layer.section.contours
        };
        // Distortion pre-warp (geometry::distortion): rasterize where the projector must
        // aim.
        let (warped, area_scale) = match correction {
            Some(c) => {
                let w = c.warp_section(section, model, i)?;
                let s = distortion::area_scale(section, &w);
                (Some(w), s)
            }
            None => (None, 1.0),
        };
        // Coverage (thresholded when binary), compensated while it is drawn: coverage →
        // gray through S⁻¹(coverage·E*/P) (docs/CALIBRATION.md).
        let comp = optics.map(|o| &o.compensator);
        let field_mask = raster.render(warped.as_deref().unwrap_or(section), scratch, binary, comp);
        let area_mm2 = scratch.lit_pixels(&field_mask) * px_area * area_scale;
        let outside = comp.is_some() && scratch.reported_outside();
        let mut pngs = Vec::with_capacity(profile.projector.len());
        for (k, p) in profile.projector.iter().enumerate() {
            let view = match tiler {
                Some(t) => std::borrow::Cow::Owned(t.render(k, &field_mask)),
                None => projector_view(&field_mask, p),
            };
            let png = match &view {
                // The field mask itself: zero outside the rasterizer's lit box.
                std::borrow::Cow::Borrowed(m) => {
                    crate::png::encode_gray8_in(m.width, m.height, &m.data, scratch.lit_box())
                }
                std::borrow::Cow::Owned(m) => encode_png(m),
            };
            let file = file_name(k);
            writer.write_file(&file, &png)?;
            let sha = bundle::sha256_hex(&png);
            masks.push(MaskRef {
                file,
                sha256: sha.clone(),
                projector: k as u32,
            });
            pngs.push((png, sha, k as u32));
        }
        scratch.recycle(field_mask);
        let masks = Arc::new(MadeMasks {
            outside,
            area_mm2,
            pngs,
            runs: if same && shared.is_some() {
                scratch.lit_runs.clone()
            } else {
                plan::analysis::LitRuns::default()
            },
        });
        if let Some(shared) = shared.filter(|_| same) {
            shared.put(section, &masks);
        }
        *made = Some(Made {
            index: i,
            simplified: same,
            masks,
        });
        area_mm2
    };
    let ta = ThreadClock::start();
    let lit = if drawn {
        Some(&scratch.lit_runs)
    } else if from_below {
        None
    } else {
        made.as_ref().map(|m| &m.masks.runs)
    };
    let analysis = analyser.analyse_or_defer(i, &layer.section.contours, lit, below);
    let runs = matches!(analysis, plan::analysis::Analysed::NeedsBelow(_))
        .then(|| scratch.lit_runs.clone());
    analysis_s += ta.elapsed_s();
    Ok(LayerOut {
        area_mm2,
        analysis,
        analysis_s,
        masks,
        runs,
    })
}

/// Measures the CPU time of the calling thread (so a busy machine preempting the worker
/// does not count), or wall time where the platform has no per-thread clock.
struct ThreadClock {
    cpu: Option<f64>,
    wall: Instant,
}

impl ThreadClock {
    fn start() -> ThreadClock {
        ThreadClock {
            cpu: thread_cpu_s(),
            wall: Instant::now(),
        }
    }

    /// Seconds since [`start`](Self::start), on the same thread.
    fn elapsed_s(&self) -> f64 {
        match (self.cpu, thread_cpu_s()) {
            (Some(a), Some(b)) => (b - a).max(0.0),
            _ => self.wall.elapsed().as_secs_f64(),
        }
    }
}

/// CPU time consumed by the calling thread, s.
#[cfg(unix)]
fn thread_cpu_s() -> Option<f64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec through a valid, exclusive pointer.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
}

/// CPU time consumed by the calling thread: not available here.
#[cfg(not(unix))]
fn thread_cpu_s() -> Option<f64> {
    None
}

#[cfg(test)]
mod clock_tests {
    use super::ThreadClock;

    #[test]
    fn thread_clock_counts_work_not_sleep() {
        let c = ThreadClock::start();
        std::thread::sleep(std::time::Duration::from_millis(60));
        let slept = c.elapsed_s();
        let c = ThreadClock::start();
        let mut x = 1u64;
        let t = std::time::Instant::now();
        while t.elapsed().as_millis() < 60 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
        }
        std::hint::black_box(x);
        let busy = c.elapsed_s();
        assert!(busy > 0.0 && busy >= slept, "busy {busy} slept {slept}");
        if cfg!(unix) {
            // A sleeping thread uses (almost) no CPU.
            assert!(slept < 0.03, "{slept}");
        }
    }
}

#[cfg(test)]
mod shared_made_tests {
    use super::{same_bits, MadeMasks, SharedMade, SHARED_MADE};
    use std::sync::Arc;

    fn masks(tag: u8) -> Arc<MadeMasks> {
        Arc::new(MadeMasks {
            outside: tag % 2 == 1,
            area_mm2: tag as f64,
            pngs: vec![(vec![tag; 3], format!("sha{tag}"), 0)],
            runs: Default::default(),
        })
    }

    fn square(x: f64) -> Vec<Vec<[f64; 2]>> {
        vec![vec![[x, 0.0], [x + 1.0, 0.0], [x + 1.0, 1.0], [x, 1.0]]]
    }

    #[test]
    fn sections_compare_bit_for_bit() {
        assert!(same_bits(&square(1.0), &square(1.0)));
        assert!(!same_bits(&square(1.0), &square(1.0 + 1e-15)));
        // −0 and +0 are equal numbers but not the same section (their masks could differ
        // in principle; a hit must never change a byte).
        assert!(!same_bits(&square(0.0), &square(-0.0)));
        let nan = vec![vec![[f64::NAN, 0.0]]];
        assert!(same_bits(&nan, &nan));
        // Contour count and lengths.
        let mut two = square(1.0);
        two.push(vec![[5.0, 5.0]]);
        assert!(!same_bits(&square(1.0), &two));
        let mut short = square(1.0);
        short[0].pop();
        assert!(!same_bits(&square(1.0), &short));
        assert!(same_bits(&[], &[]));
    }

    #[test]
    fn finds_the_same_section_keeps_a_few_and_drops_the_oldest() {
        let cache = SharedMade::default();
        assert!(cache.get(&square(0.0)).is_none());
        cache.put(&square(0.0), &masks(0));
        let got = cache.get(&square(0.0)).expect("hit");
        assert_eq!((got.area_mm2, got.outside), (0.0, false));
        assert!(cache.get(&square(0.5)).is_none());
        // A second put of the same section keeps the first entry (same bytes anyway).
        cache.put(&square(0.0), &masks(9));
        assert_eq!(cache.get(&square(0.0)).unwrap().area_mm2, 0.0);
        for k in 1..=SHARED_MADE as u8 {
            cache.put(&square(k as f64), &masks(k));
        }
        assert_eq!(cache.0.lock().unwrap().len(), SHARED_MADE);
        assert!(cache.get(&square(0.0)).is_none(), "the oldest is dropped");
        for k in 1..=SHARED_MADE as u8 {
            let m = cache.get(&square(k as f64)).expect("kept");
            assert_eq!(m.pngs[0].0, vec![k; 3]);
            assert_eq!(m.outside, k % 2 == 1);
        }
    }
}
