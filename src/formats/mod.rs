//! Every form of a job, each format's reader and writer in one place (docs/FORMATS.md):
//! [`open`] reads a job in any form `dmdsl run`, `inspect` and `export` accept, found from
//! its content (docs/EXECUTOR.md, "What it reads"), as a native [`Manifest`] and a
//! [`BundleSource`] for its files; [`write()`] writes one in a [`Format`], atomically, and
//! returns what the format cannot carry as [`Warning`]s (codes `export.*`), never dropped
//! silently.
//!
//! `native.rs` is the bundle directory and its zip; [`sl1`], [`control`] and [`nanodlp`]
//! the foreign formats; `imported.rs` what their importers share; [`archive`] the zip
//! reader and writer. A missing setting or a file that cannot be a job of the format is an
//! error naming the file, the entry and the key.

pub mod archive;
pub mod control;
mod format;
mod imported;
pub mod nanodlp;
mod native;
pub mod sl1;
mod written;

use crate::bundle::{BundleSource, Machine, Manifest, MANIFEST};
use crate::error::{Error, Result};
use crate::warning::Warning;
use archive::read::{read_zip, Limits};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

pub use format::Format;
pub(crate) use imported::rescale;
pub(crate) use imported::DEFLATE_MAX_RATIO;

/// Where an imported job's total time estimate comes from, when not from dmdsl's planner.
#[derive(Debug, Clone, PartialEq)]
pub struct ForeignEstimate {
    /// Who made it and where it is, e.g. "PrusaSlicer printTime (config.ini)".
    pub source: String,
    /// The estimate, s (the manifest's `totals.print_time_s`).
    pub print_time_s: f64,
}

/// What one exposure of a job asks of the printer's light engine, as the SLA control
/// file's image settings say it (for a native job: its projectors'), for the checks of a
/// machine description (`run --machine hardware_config.json`).
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    /// The layer record.
    pub layer: usize,
    /// Where the file says it, e.g. `Layers[3].Image settings list[1]` (empty for a
    /// native job).
    pub at: String,
    /// The image, as the job names it.
    pub file: String,
    /// The light engine.
    pub engine: String,
    /// Its wavelength, nm, when stated.
    pub wavelength_nm: Option<u32>,
    /// Where the image goes: the control file's `Image x/y offset (um)`.
    pub offset_um: [f64; 2],
    /// `Do grayscale correction`.
    pub gray_correction: bool,
    /// The image's size, px (when it decodes).
    pub size_px: Option<(u32, u32)>,
}

/// A job opened for the executor, `inspect` or `export`.
pub struct Job {
    /// The path as given.
    pub path: PathBuf,
    /// The form it came in.
    pub format: Format,
    /// The manifest (native, or built by the importer).
    pub manifest: Manifest,
    /// Its files.
    pub source: Box<dyn BundleSource>,
    /// The estimate the file carried, for imported jobs that carry one.
    pub estimate: Option<ForeignEstimate>,
    /// What each exposure asks of the light engines, as an imported file states it
    /// (empty: the projectors' own, [`Job::requests`]).
    pub requests: Vec<Request>,
    /// The job asks to print under vacuum (the control file's `Special print
    /// techniques`).
    pub vacuum: bool,
    /// What the reader could not take as stated, one line each: settings it does not
    /// simulate, figures it estimated.
    pub notes: Vec<String>,
}

impl Job {
    /// What each exposure asks of the light engines: the file's requests, or one per mask
    /// from its projector (name, wavelength, offset).
    pub fn requests(&self) -> Vec<Request> {
        if !self.requests.is_empty() {
            return self.requests.clone();
        }
        let m = &self.manifest;
        let mut out = Vec::new();
        for (i, l) in m.layers.iter().enumerate() {
            for mask in &l.masks {
                let Some(p) = m.machine.projector.get(mask.projector as usize) else {
                    continue;
                };
                let um = p.pixel_mm.get() * 1000.0;
                out.push(Request {
                    layer: i,
                    at: String::new(),
                    file: mask.file.clone(),
                    engine: p.name.clone(),
                    wavelength_nm: p.wavelength_nm,
                    offset_um: p.offset_px.map(|o| o as f64 * um),
                    gray_correction: false,
                    size_px: Some((p.width_px, p.height_px)),
                });
            }
        }
        out
    }
}

impl std::fmt::Debug for Job {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Job")
            .field("path", &self.path)
            .field("format", &self.format)
            .field("layers", &self.manifest.layers.len())
            .finish_non_exhaustive()
    }
}

/// Opens the job at `path`: a bundle directory, or a file whose content says what it is
/// (see the module docs).
pub fn open(path: &Path) -> Result<Job> {
    let meta = std::fs::metadata(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            Error::io(
                path,
                std::io::Error::new(std::io::ErrorKind::NotFound, "does not exist"),
            )
        } else {
            Error::io(path, e)
        }
    })?;
    if meta.is_dir() {
        return native::open_dir(path);
    }
    let limits = Limits::default();
    let bytes = crate::input::read_file(path, "job", limits.max_archive_bytes)?;
    if !archive::read::looks_like_zip(&bytes) {
        return Err(Error::Bundle {
            path: path.into(),
            msg: "not a job: neither a bundle directory nor a zip archive (a zipped bundle, an SL1/SL1S file or an SLA control-file zip)".into(),
        });
    }
    let sha256 = crate::digest::sha256_hex(&bytes);
    let archive = read_zip(path, bytes, &limits)?;
    if let Some(dir) = native::bundle_folder(&archive) {
        return native::open_zip(archive, &dir);
    }
    if sl1::holds(&archive) {
        return sl1::import(archive, &sha256);
    }
    if nanodlp::holds(&archive) {
        return nanodlp::import(archive, &sha256);
    }
    if let Some(name) = control::settings_entry(&archive) {
        return control::import(archive, &name, &sha256);
    }
    Err(archive.error(
        None,
        format!(
            "not a job: no `{MANIFEST}` (zipped bundle), no `{}` + `{}` (SL1/SL1S), no `{}` + `{}` (NanoDLP), no print-settings JSON (SLA control file) at the top of the archive",
            sl1::CONFIG,
            sl1::PRUSASLICER,
            nanodlp::PLATE,
            nanodlp::PROFILE
        ),
    ))
}

/// Writes the job (`manifest` and its `files`) at `out` in `format`, atomically; returns
/// what the format could not carry. Nothing is left at `out` (nor beside it) on failure,
/// nor when `cancel` is set while it is written ([`crate::error::Error::Interrupted`]).
///
/// Every PNG is written as its bytes up to the end of its `IEND` chunk: what follows it
/// (which PNG readers ignore) is dropped. A native form records the masks' hashes of
/// the bytes written and every mask's pixels (counted from the file when the manifest has
/// no record: an older bundle, an imported job).
pub fn write(
    format: Format,
    manifest: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<Vec<Warning>> {
    write_at_most(format, manifest, files, out, cancel, None)
}

/// [`write()`], refused before anything is written when the images would add up to more
/// than `max_bytes` (each image as many times as the format writes it).
pub fn write_at_most(
    format: Format,
    manifest: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
    max_bytes: Option<u64>,
) -> Result<Vec<Warning>> {
    check_fits(format, &manifest.machine, out)?;
    let foreign = !matches!(format, Format::Dmdjob | Format::DmdjobZip);
    if foreign && manifest.layers.is_empty() {
        return Err(Error::Bundle {
            path: out.into(),
            msg: "the job has no layers".into(),
        });
    }
    let files = written::Trimmed(files);
    let (bytes, manifest) = written::survey(manifest, &files, !foreign)?;
    if let Some(max) = max_bytes.filter(|&m| bytes > m) {
        let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
        let (now, most) = (mib(bytes), mib(max));
        return Err(Error::Bundle {
            path: out.into(),
            msg: format!("its images would add up to {bytes} bytes ({now:.3} MiB), more than the {max} ({most:.3} MiB) allowed (--max-size; --force writes it anyway)"),
        });
    }
    let (manifest, files) = (manifest.as_ref(), &files as &dyn BundleSource);
    let warnings = match format {
        Format::Dmdjob | Format::DmdjobZip => Vec::new(),
        Format::Sl1 | Format::Sl1s => sl1::cannot_carry(format, manifest),
        Format::SlaControl => control::cannot_carry(manifest),
        Format::Nanodlp => nanodlp::cannot_carry(manifest),
    };
    match format {
        Format::Dmdjob => native::write_dir(manifest, files, out, cancel)?,
        Format::DmdjobZip => native::write_zip(manifest, files, out, cancel)?,
        Format::Sl1 | Format::Sl1s => sl1::write(format, manifest, files, out, cancel)?,
        Format::SlaControl => control::write(manifest, files, out, cancel)?,
        Format::Nanodlp => nanodlp::write(manifest, files, out, cancel)?,
    }
    Ok(warnings)
}

/// Checks, before anything is written, that `format` can hold a job for `machine`:
/// SL1/SL1S and NanoDLP plates hold one projector's masks. `out` names the output in the
/// error.
/// A directory in the way of a one-file format is refused here too.
pub fn check_fits(format: Format, machine: &Machine, out: &Path) -> Result<()> {
    if format.is_one_file() {
        archive::write::check_dest(out)?;
    }
    match format {
        Format::Sl1 | Format::Sl1s | Format::Nanodlp => {
            sl1::check_projectors(format, machine.projector.len(), out)
        }
        _ => Ok(()),
    }
}

/// Now, s since 1970 (or `SOURCE_DATE_EPOCH`, for reproducible files): the time stamps
/// the foreign formats record.
pub(crate) fn now_secs() -> i64 {
    std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|s| s.trim().parse::<i64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs() as i64)
        })
}
