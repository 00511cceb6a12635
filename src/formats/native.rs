//! The native bundle, as a directory (through [`BundleWriter`]) or as one zip: the same
//! files with the same bytes, `job.json` first, images stored.

use super::archive::write::{Method, ZipOut};
use super::bundle_files;
use crate::bundle::BundleSource;
use crate::bundle::{BundleWriter, Manifest, MANIFEST};
use crate::error::Result;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

/// Writes the bundle directory `out`.
pub(super) fn write_dir(
    manifest: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<()> {
    let writer = BundleWriter::create(out)?;
    for rel in bundle_files(manifest) {
        if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            return Err(crate::error::Error::Interrupted);
        }
        if let Some(dir) = Path::new(rel).parent().filter(|d| d != &Path::new("")) {
            writer.create_dir(&dir.to_string_lossy())?;
        }
        writer.write_file(rel, &files.file(rel)?)?;
    }
    writer.finish(manifest)?;
    Ok(())
}

/// Writes the bundle as the zip `out`: `job.json` (deflated) first, then every file the
/// manifest names (stored), in layer order.
pub(super) fn write_zip(
    manifest: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<()> {
    let mut zip = ZipOut::create(out, cancel)?;
    zip.add(MANIFEST, &manifest.to_json(), Method::Deflated)?;
    for rel in bundle_files(manifest) {
        zip.add(rel, &files.file(rel)?, Method::Stored)?;
    }
    zip.finish()?;
    Ok(())
}
