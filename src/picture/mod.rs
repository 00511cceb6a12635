//! Pictures of a job from its manifest and mask files alone (any [`BundleSource`]): a
//! layer's masks back on the build plane ([`field`]) and the shaded part they build
//! ([`preview()`]), for `inspect` and the SL1 thumbnails.

pub mod field;
pub mod preview;

pub use preview::{preview, preview_projected, Projection};

use crate::bundle::{BundleSource, MANIFEST};
use crate::error::{Error, Result};
use image::GrayImage;

/// The mask file `rel` of `files` (a path as the manifest names it, e.g.
/// `masks/00012.png`), decoded to 8-bit gray. Errors name the file, or the manifest for a
/// path leading outside the bundle.
pub fn read_mask(files: &dyn BundleSource, rel: &str) -> Result<GrayImage> {
    let path = files.shown(rel);
    let bytes = files.read(rel).map_err(|e| {
        if e.kind() == std::io::ErrorKind::InvalidInput {
            Error::Bundle {
                path: files.shown(MANIFEST),
                msg: format!("mask path {rel:?} leads outside the bundle"),
            }
        } else {
            Error::io(&path, e)
        }
    })?;
    image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .map(|img| img.into_luma8())
        .map_err(|e| Error::Bundle {
            path,
            msg: format!("mask is not a decodable PNG: {e}"),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_leading_outside_are_refused() {
        let dir = crate::bundle::DirSource::new(std::path::Path::new("/nonexistent-bundle"));
        let e = read_mask(&dir, "../x.png").unwrap_err().to_string();
        assert!(e.contains("leads outside the bundle"), "{e}");
    }
}
