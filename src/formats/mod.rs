//! Every form of a job, each format's reader and writer in one place: [`open`] reads a
//! job in any form `dmdsl run`, `inspect` and `export` accept, found from its content, as a
//! native [`Manifest`] and a [`BundleSource`] for its files; [`write()`] writes one in a
//! [`Format`], atomically, and returns what the format cannot carry as [`Warning`]s (codes
//! `export.*`, `docs/WARNINGS.md`), never dropped silently.
//!
//! * `native.rs`: the bundle directory (`part.dmdjob/`) and the zipped bundle
//!   (`part.dmdjob.zip`: the same files, `job.json` first; read also with all of them in
//!   one folder `NAME/`);
//! * [`sl1`]: PrusaSlicer SL1 / SL1S (`config.ini`, `prusaslicer.ini`, one PNG a layer),
//!   read as layers and steps that reproduce PrusaSlicer 2.5's print-time model on the
//!   machine the file describes;
//! * [`control`]: the SLA control-file standard, schema v5 (the print-settings JSON and
//!   `slices/`), read as layers and steps from its position and image settings;
//! * `imported.rs`: what the importers share (the machine record a file implies, the layer
//!   record of an image, the job around them);
//! * [`archive`]: zips, read whole into memory refusing anything unsafe (nothing is
//!   extracted), and written through a temporary sibling.
//!
//! The form is found from the content, not the extension: a directory is a bundle; a zip
//! holding `job.json` is a zipped bundle, one holding `config.ini` and `prusaslicer.ini`
//! is SL1, one holding a top-level `.json` with `Header` and `Default layer settings` is a
//! control file. A missing setting or a file that cannot be a job of the format is an
//! error naming the file, the entry and the key.

pub mod archive;
pub mod control;
mod format;
mod imported;
mod native;
pub mod sl1;

use crate::bundle::{BundleSource, Machine, Manifest, MANIFEST};
use crate::error::{Error, Result};
use crate::warning::Warning;
use archive::read::{read_zip_bytes, Limits};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

pub use format::Format;
pub(crate) use imported::DEFLATE_MAX_RATIO;

/// Where an imported job's total time estimate comes from, when not from dmdsl's planner.
#[derive(Debug, Clone, PartialEq)]
pub struct ForeignEstimate {
    /// Who made it and where it is, e.g. "PrusaSlicer printTime (config.ini)".
    pub source: String,
    /// The estimate, s (the manifest's `totals.print_time_s`).
    pub print_time_s: f64,
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
    let archive = read_zip_bytes(path, &bytes, &limits)?;
    let sha256 = crate::digest::sha256_hex(&bytes);
    drop(bytes);
    if let Some(dir) = native::bundle_folder(&archive) {
        return native::open_zip(archive, &dir);
    }
    if sl1::holds(&archive) {
        return sl1::import(archive, &sha256);
    }
    if let Some(name) = control::settings_entry(&archive) {
        return control::import(archive, &name, &sha256);
    }
    Err(archive.error(
        None,
        format!(
            "not a job: no `{MANIFEST}` (zipped bundle), no `{}` + `{}` (SL1/SL1S), no print-settings JSON (SLA control file) at the top of the archive",
            sl1::CONFIG,
            sl1::PRUSASLICER
        ),
    ))
}

/// Writes the job (`manifest` and its `files`) at `out` in `format`, atomically; returns
/// what the format could not carry. Nothing is left at `out` (nor beside it) on failure,
/// nor when `cancel` is set while it is written ([`crate::error::Error::Interrupted`]).
pub fn write(
    format: Format,
    manifest: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<Vec<Warning>> {
    check_fits(format, &manifest.machine, out)?;
    let foreign = matches!(format, Format::Sl1 | Format::Sl1s | Format::SlaControl);
    if foreign && manifest.layers.is_empty() {
        return Err(Error::Bundle {
            path: out.into(),
            msg: "the job has no layers".into(),
        });
    }
    let warnings = match format {
        Format::Dmdjob | Format::DmdjobZip => Vec::new(),
        Format::Sl1 | Format::Sl1s => sl1::cannot_carry(format, manifest),
        Format::SlaControl => control::cannot_carry(manifest),
    };
    match format {
        Format::Dmdjob => native::write_dir(manifest, files, out, cancel)?,
        Format::DmdjobZip => native::write_zip(manifest, files, out, cancel)?,
        Format::Sl1 | Format::Sl1s => sl1::write(format, manifest, files, out, cancel)?,
        Format::SlaControl => control::write(manifest, files, out, cancel)?,
    }
    Ok(warnings)
}

/// Checks, before anything is written, that `format` can hold a job for `machine`:
/// SL1/SL1S hold one projector's masks. `out` names the output in the error.
/// A directory in the way of a one-file format is refused here too.
pub fn check_fits(format: Format, machine: &Machine, out: &Path) -> Result<()> {
    if format.is_one_file() {
        archive::write::check_dest(out)?;
    }
    match format {
        Format::Sl1 | Format::Sl1s => sl1::check_projectors(machine.projector.len(), out),
        _ => Ok(()),
    }
}
