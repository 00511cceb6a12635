//! Reading a bundle for inspection: its manifest and its masks through [`MaskReader`], so
//! the pictures do not care where the files live (a directory, a zipped bundle, a job
//! imported from another format: any [`BundleSource`]).

use crate::bundle::{BundleSource, DirSource, Manifest, MANIFEST};
use crate::error::{Error, Result};
use crate::formats::Format;
pub use crate::picture::{decode_mask, MaskReader};
use image::GrayImage;
use std::path::{Path, PathBuf};

/// The masks of a bundle directory.
#[derive(Debug, Clone)]
pub struct DirMasks {
    dir: DirSource,
}

impl DirMasks {
    /// The masks under bundle directory `dir`.
    pub fn new(dir: &Path) -> DirMasks {
        DirMasks {
            dir: DirSource::new(dir),
        }
    }
}

/// Reads mask `rel` from `source` and decodes it; errors name the file.
fn read_from(source: &dyn BundleSource, rel: &str) -> Result<GrayImage> {
    let path = source.shown(rel);
    let bytes = source.read(rel).map_err(|e| {
        if e.kind() == std::io::ErrorKind::InvalidInput {
            Error::Bundle {
                path: source.shown(MANIFEST),
                msg: format!("mask path {rel:?} leads outside the bundle"),
            }
        } else {
            Error::io(&path, e)
        }
    })?;
    decode_mask(&bytes, &path)
}

impl MaskReader for DirMasks {
    fn read_mask(&self, rel: &str) -> Result<GrayImage> {
        read_from(&self.dir, rel)
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.dir.shown(rel)
    }
}

/// The masks of any form of job ([`BundleSource`]: a directory, a zipped bundle, an
/// imported file).
pub struct SourceMasks(pub Box<dyn BundleSource>);

impl MaskReader for SourceMasks {
    fn read_mask(&self, rel: &str) -> Result<GrayImage> {
        read_from(&*self.0, rel)
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.0.shown(rel)
    }
}

/// A bundle opened for inspection.
pub struct Bundle {
    /// The bundle's path, as given.
    pub path: PathBuf,
    /// The form it came in (a bundle directory, a zipped bundle, an imported file).
    pub format: Format,
    /// Its manifest, checked.
    pub manifest: Manifest,
    /// Its masks.
    pub masks: Box<dyn MaskReader>,
}

impl Bundle {
    /// Opens the job at `path` in any form [`crate::formats::open`] reads (a bundle
    /// directory, a zipped bundle, an SL1/SL1S file, an SLA control-file zip): reads and
    /// checks its manifest, including its machine record and the projector of every mask.
    pub fn open(path: &Path) -> Result<Bundle> {
        let job = crate::formats::open(path)?;
        let manifest = job.manifest;
        let bad = |msg: String| Error::Bundle {
            path: job.source.shown(MANIFEST),
            msg,
        };
        manifest
            .machine
            .validate()
            .map_err(|m| bad(format!("machine: {m}")))?;
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
            format: job.format,
            manifest,
            masks: Box::new(SourceMasks(job.source)),
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
        let r = DirMasks::new(Path::new("/nonexistent-bundle"));
        let e = r.read_mask("../x.png").unwrap_err().to_string();
        assert!(e.contains("leads outside the bundle"), "{e}");
    }
}
