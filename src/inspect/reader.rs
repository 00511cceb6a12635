//! Reading a bundle for inspection: its manifest and its masks through [`MaskReader`], so
//! the pictures do not care where the files live (a directory today; an archive form of
//! the bundle can implement the same trait).

use crate::bundle::{Manifest, MANIFEST};
use crate::error::{Error, Result};
use image::GrayImage;
use std::path::{Component, Path, PathBuf};

/// Where a bundle's mask files come from.
pub trait MaskReader: Sync {
    /// The mask file `rel` (a path as the manifest names it, e.g. `masks/00012.png`),
    /// decoded to 8-bit gray. Errors name the file.
    fn read_mask(&self, rel: &str) -> Result<GrayImage>;

    /// How mask file `rel` is named in messages (e.g. `part.dmdjob/masks/00012.png`).
    fn shown(&self, rel: &str) -> PathBuf;
}

/// The masks of a bundle directory.
#[derive(Debug, Clone)]
pub struct DirMasks {
    dir: PathBuf,
}

impl DirMasks {
    /// The masks under bundle directory `dir`.
    pub fn new(dir: &Path) -> DirMasks {
        DirMasks { dir: dir.into() }
    }
}

/// A relative path made only of normal components (nothing outside the bundle).
fn is_inside(rel: &str) -> bool {
    !rel.is_empty()
        && Path::new(rel)
            .components()
            .all(|c| matches!(c, Component::Normal(_)))
}

impl MaskReader for DirMasks {
    fn read_mask(&self, rel: &str) -> Result<GrayImage> {
        let path = self.dir.join(rel);
        if !is_inside(rel) {
            return Err(Error::Bundle {
                path: self.dir.join(MANIFEST),
                msg: format!("mask path {rel:?} leads outside the bundle"),
            });
        }
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        decode_mask(&bytes, &path)
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.dir.join(rel)
    }
}

/// Decodes the PNG `bytes` of the mask at `path` (for errors) to 8-bit gray.
pub fn decode_mask(bytes: &[u8], path: &Path) -> Result<GrayImage> {
    image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
        .map(|img| img.into_luma8())
        .map_err(|e| Error::Bundle {
            path: path.into(),
            msg: format!("mask is not a decodable PNG: {e}"),
        })
}

/// A bundle opened for inspection.
pub struct Bundle {
    /// The bundle's path, as given.
    pub path: PathBuf,
    /// Its manifest, checked.
    pub manifest: Manifest,
    /// Its masks.
    pub masks: Box<dyn MaskReader>,
}

impl Bundle {
    /// Opens the bundle at `path` (a bundle directory, the only form so far): reads and
    /// checks `job.json`, including its machine profile and the projector of every mask.
    pub fn open(path: &Path) -> Result<Bundle> {
        let manifest = Manifest::read(path)?;
        let bad = |msg: String| Error::Bundle {
            path: path.join(MANIFEST),
            msg,
        };
        manifest
            .machine
            .validate()
            .map_err(|m| bad(format!("machine profile: {m}")))?;
        let projectors = manifest.machine.projector.len();
        for l in &manifest.layers {
            for m in &l.masks {
                if m.projector as usize >= projectors {
                    return Err(bad(format!(
                        "layer {}: mask {} is for projector {}, the machine has {projectors}",
                        l.index, m.file, m.projector
                    )));
                }
            }
        }
        Ok(Bundle {
            path: path.into(),
            manifest,
            masks: Box::new(DirMasks::new(path)),
        })
    }

    /// The bundle's name for titles: its file name (`part.dmdjob`).
    pub fn name(&self) -> String {
        self.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.path.display().to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_leading_outside_are_refused() {
        assert!(is_inside("masks/00001.png"));
        assert!(!is_inside("../x.png"));
        assert!(!is_inside("/etc/passwd"));
        assert!(!is_inside(""));
        let r = DirMasks::new(Path::new("/nonexistent-bundle"));
        let e = r.read_mask("../x.png").unwrap_err().to_string();
        assert!(e.contains("leads outside the bundle"), "{e}");
    }
}
