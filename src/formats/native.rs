//! The native bundle, as a directory (through [`BundleWriter`]) or as one zip: the same
//! files with the same bytes, `job.json` first, images stored.

use super::archive::read::Archive;
use super::archive::write::{Method, ZipOut};
use super::{Format, Job};
use crate::bundle::{BundleSource, BundleWriter, DirSource, Manifest, MANIFEST};
use crate::error::Result;
use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

/// The bundle directory `dir`.
pub(super) fn open_dir(dir: &Path) -> Result<Job> {
    if !dir.join(MANIFEST).is_file() {
        return Err(crate::error::Error::Bundle {
            path: dir.into(),
            msg: format!("not a job: a directory without `{MANIFEST}` (a bundle directory holds `{MANIFEST}` and `masks/`)"),
        });
    }
    Ok(Job {
        path: dir.into(),
        format: Format::Dmdjob,
        manifest: Manifest::read(dir)?,
        source: Box::new(DirSource::new(dir)),
        estimate: None,
        requests: Vec::new(),
        vacuum: false,
        notes: Vec::new(),
    })
}

/// The folder of `archive` a zipped bundle's files are in: empty when it holds `job.json`
/// at the top, `NAME/` when every entry is in `NAME/` and it holds `NAME/job.json` (a
/// bundle directory zipped with its folder); `None` for any other archive.
pub(super) fn bundle_folder(archive: &Archive) -> Option<String> {
    if archive.contains(MANIFEST) {
        return Some(String::new());
    }
    let first = archive.names().first()?;
    let dir = &first[..first.find('/')? + 1];
    (archive.contains(&format!("{dir}{MANIFEST}"))
        && archive.names().iter().all(|n| n.starts_with(dir)))
    .then(|| dir.to_string())
}

/// A zipped bundle: its `job.json` read as a bundle directory's; `dir` is the folder the
/// bundle's files are in inside the archive ([`bundle_folder`]).
pub(super) fn open_zip(archive: Archive, dir: &str) -> Result<Job> {
    let path = archive.path().to_path_buf();
    let text = archive
        .get(&format!("{dir}{MANIFEST}"))?
        .unwrap_or_default();
    let manifest = Manifest::from_json(text, &path.join(dir).join(MANIFEST))?;
    Ok(Job {
        source: Box::new(archive.into_source(dir)),
        path,
        format: Format::DmdjobZip,
        manifest,
        estimate: None,
        requests: Vec::new(),
        vacuum: false,
        notes: Vec::new(),
    })
}

/// Where a file of a native bundle comes from: the job's file of that name, or bytes made
/// for it.
enum From {
    File(String),
    Made(std::sync::Arc<Vec<u8>>),
}

/// An 8-bit gray PNG of `w` × `h` pixels, all dark.
fn dark_png(w: u32, h: u32) -> Vec<u8> {
    let mut out = Vec::new();
    image::GrayImage::new(w, h)
        .write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .expect("a PNG encodes into memory");
    out
}

/// The manifest as a native bundle holds it, and where each of its files comes from: a
/// native bundle gives every layer its own file for every projector (`mask-shared`,
/// `manifest`), so a job whose layers share images (an imported control file's
/// duplications) or show one projector at a time (its images exposed in turn) gets
/// `masks/NNNNN.png` (`masks/pK/NNNNN.png` with several projectors, K the projector's
/// index) for each, the same bytes, and a dark image for each projector a layer does not
/// light.
fn own_files(m: &Manifest) -> (std::borrow::Cow<'_, Manifest>, HashMap<String, From>) {
    let mut seen = HashSet::new();
    let n = m.machine.projector.len();
    let own = m.layers.iter().all(|l| l.masks.len() == n)
        && m.layers
            .iter()
            .flat_map(|l| &l.masks)
            .all(|k| seen.insert(k.file.as_str()));
    if own {
        return (std::borrow::Cow::Borrowed(m), HashMap::new());
    }
    let mut out = m.clone();
    let mut from = HashMap::new();
    let name = |k: usize, i: u64| match n > 1 {
        true => format!("masks/p{k}/{i:05}.png"),
        false => format!("masks/{i:05}.png"),
    };
    // Each projector's dark image, its hash and its pixel record (nothing lit).
    let dark: Vec<_> = m
        .machine
        .projector
        .iter()
        .map(|p| {
            let png = dark_png(p.width_px, p.height_px);
            let zeros = vec![0u8; p.width_px as usize * p.height_px as usize];
            let px = crate::bundle::MaskPixels::of_gray8(p.width_px, &zeros).placed(
                [p.width_px, p.height_px],
                p.offset_px,
                [p.mirror_x, p.mirror_y],
            );
            (
                crate::digest::sha256_hex(&png),
                std::sync::Arc::new(png),
                px,
            )
        })
        .collect();
    for l in &mut out.layers {
        let lit: Vec<u32> = l.masks.iter().map(|k| k.projector).collect();
        for k in &mut l.masks {
            let file = name(k.projector as usize, l.index);
            from.insert(
                file.clone(),
                From::File(std::mem::replace(&mut k.file, file)),
            );
        }
        for (k, (sha, png, px)) in dark
            .iter()
            .enumerate()
            .filter(|(k, _)| !lit.contains(&(*k as u32)))
        {
            let file = name(k, l.index);
            from.insert(file.clone(), From::Made(png.clone()));
            l.masks.push(crate::bundle::MaskRef {
                file,
                sha256: sha.clone(),
                projector: k as u32,
                pixels: Some(*px),
            });
        }
        l.masks.sort_by_key(|k| k.projector);
    }
    (std::borrow::Cow::Owned(out), from)
}

/// The bytes of bundle file `rel` (`from` says where it comes from).
fn bytes<'a>(
    files: &'a dyn BundleSource,
    from: &'a HashMap<String, From>,
    rel: &str,
) -> Result<std::borrow::Cow<'a, [u8]>> {
    match from.get(rel) {
        Some(From::Made(b)) => Ok(std::borrow::Cow::Borrowed(b.as_slice())),
        Some(From::File(f)) => files.file(f),
        None => files.file(rel),
    }
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
    let (manifest, from) = own_files(manifest);
    let writer = BundleWriter::create(out)?;
    for rel in bundle_files(&manifest) {
        if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            return Err(crate::error::Error::Interrupted);
        }
        if let Some(dir) = Path::new(rel).parent().filter(|d| d != &Path::new("")) {
            writer.create_dir(&dir.to_string_lossy())?;
        }
        writer.write_file(rel, &bytes(files, &from, rel)?)?;
    }
    writer.finish(&manifest)?;
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
    let (manifest, from) = own_files(manifest);
    let mut zip = ZipOut::create(out, cancel)?;
    zip.add(MANIFEST, &manifest.to_json(), Method::Deflated)?;
    for rel in bundle_files(&manifest) {
        zip.add(rel, &bytes(files, &from, rel)?, Method::Stored)?;
    }
    zip.finish()?;
    Ok(())
}
