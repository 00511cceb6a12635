//! The native bundle, as a directory (through [`BundleWriter`]) or as one zip: the same
//! files with the same bytes, `job.json` first, images stored.

use super::archive::read::Archive;
use super::archive::write::{Method, ZipOut};
use super::{Format, Job};
use crate::bundle::{BundleSource, BundleWriter, DirSource, Manifest, MemSource, MANIFEST};
use crate::error::Result;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

/// The bundle directory `dir`.
pub(super) fn open_dir(dir: &Path) -> Result<Job> {
    Ok(Job {
        path: dir.into(),
        format: Format::Dmdjob,
        manifest: Manifest::read(dir)?,
        source: Box::new(DirSource::new(dir)),
        estimate: None,
    })
}

/// The folder of `archive` a zipped bundle's files are in: empty when it holds `job.json`
/// at the top, `NAME/` when every entry is in `NAME/` and it holds `NAME/job.json` (a
/// bundle directory zipped with its folder); `None` for any other archive.
pub(super) fn bundle_folder(archive: &Archive) -> Option<String> {
    if archive.get(MANIFEST).is_some() {
        return Some(String::new());
    }
    let first = archive.names().first()?;
    let dir = &first[..first.find('/')? + 1];
    (archive.get(&format!("{dir}{MANIFEST}")).is_some()
        && archive.names().iter().all(|n| n.starts_with(dir)))
    .then(|| dir.to_string())
}

/// A zipped bundle: its `job.json` read as a bundle directory's; `dir` is the folder the
/// bundle's files are in inside the archive ([`bundle_folder`]).
pub(super) fn open_zip(archive: Archive, dir: &str) -> Result<Job> {
    let path = archive.path().to_path_buf();
    let text = archive.get(&format!("{dir}{MANIFEST}")).unwrap_or_default();
    let manifest = Manifest::from_json(text, &path.join(dir).join(MANIFEST))?;
    let files = archive
        .into_files()
        .into_iter()
        .map(|(k, v)| (k[dir.len()..].to_string(), v))
        .collect();
    Ok(Job {
        source: Box::new(MemSource::new(&path.join(dir), files)),
        path,
        format: Format::DmdjobZip,
        manifest,
        estimate: None,
    })
}

/// The files of a bundle its manifest names, in the order the native forms store them:
/// every layer's masks, then the gray maps.
fn bundle_files(m: &Manifest) -> impl Iterator<Item = &str> {
    let masks = m.layers.iter().flat_map(|l| &l.masks).map(|k| &k.file);
    let maps = m
        .optics
        .iter()
        .chain(&m.projector_optics)
        .map(|o| &o.gray_map);
    masks.chain(maps).map(String::as_str)
}

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
