//! Writing a job in another form: the native bundle as a directory or as one zip, Prusa
//! SL1/SL1S, or the open SLA control-file standard (schema v5).
//!
//! A job is a [`Manifest`] and its files, read through a [`BundleSource`] (any form
//! [`crate::import::open`] opens, or the files the slicer made in memory).
//! [`write()`] writes one [`Format`] at a path, atomically (a temporary sibling renamed into
//! place, or the bundle writer's staging directory), and returns what the format could not
//! carry as [`Warning`]s (codes `export.*`, `docs/WARNINGS.md`): never silently.
//!
//! - `native.rs`: `dmdjob` (directory) and `dmdjob-zip` (the same files in a zip,
//!   `job.json` first, images stored).
//! - `sl1.rs`: Prusa SL1 / SL1S, the zip PrusaSlicer 2.5 writes.
//! - `control.rs`: the SLA control-file standard, `print_settings.json` + `slices/`.
//! - `thumbnail.rs`: the SL1 preview pictures, rendered from the masks
//!   ([`crate::inspect::preview()`]).

mod control;
mod native;
mod sl1;
mod thumbnail;

pub use control::SCHEMA_VERSION as CONTROL_SCHEMA_VERSION;

pub use crate::bundle::Format;
use crate::bundle::{BundleSource, Manifest};
use crate::error::Result;
use crate::warning::Warning;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// Opens the job at `path` for export, in any form `dmdsl run` reads
/// ([`crate::import::open`]: a bundle directory, a zipped bundle, an SL1/SL1S file, an SLA
/// control-file zip): its manifest and its files. The one place `dmdsl export` opens its
/// input.
pub fn open_bundle(path: &Path) -> Result<(Manifest, Box<dyn BundleSource>)> {
    let job = crate::import::open(path)?;
    Ok((job.manifest, job.source))
}

/// The files of a bundle its manifest names, in the order the native forms store them:
/// every layer's masks, then the gray maps.
pub fn bundle_files(m: &Manifest) -> Vec<&str> {
    let mut files: Vec<&str> = m
        .layers
        .iter()
        .flat_map(|l| l.masks.iter().map(|k| k.file.as_str()))
        .collect();
    files.extend(m.optics.iter().map(|o| o.gray_map.as_str()));
    files.extend(m.projector_optics.iter().map(|o| o.gray_map.as_str()));
    files
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
    match format {
        Format::Dmdjob => native::write_dir(manifest, files, out, cancel).map(|()| Vec::new()),
        Format::DmdjobZip => native::write_zip(manifest, files, out, cancel).map(|()| Vec::new()),
        Format::Sl1 | Format::Sl1s => sl1::write(format, manifest, files, out, cancel),
        Format::SlaControl => control::write(manifest, files, out, cancel),
    }
}

/// Checks, before anything is written, that `format` can hold a job for `machine`:
/// SL1/SL1S hold one projector's masks. `out` names the output in the error.
/// A directory in the way of a one-file format is refused here too.
pub fn check_fits(format: Format, machine: &crate::bundle::Machine, out: &Path) -> Result<()> {
    if format.is_one_file() {
        crate::archive::write::check_dest(out)?;
    }
    match format {
        Format::Sl1 | Format::Sl1s => sl1::check_projectors(machine.projector.len(), out),
        _ => Ok(()),
    }
}
