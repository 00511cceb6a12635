//! Pictures of a job from its manifest and masks alone: a layer's masks back on the build
//! plane ([`field`]) and the shaded part they build ([`preview()`]), for `inspect` and the
//! SL1 thumbnails.

pub mod field;
pub mod preview;

pub use preview::preview;

use crate::error::{Error, Result};
use image::GrayImage;
use std::path::{Path, PathBuf};

/// Where a bundle's mask files come from.
pub trait MaskReader: Sync {
    /// The mask file `rel` (a path as the manifest names it, e.g. `masks/00012.png`),
    /// decoded to 8-bit gray. Errors name the file.
    fn read_mask(&self, rel: &str) -> Result<GrayImage>;

    /// How mask file `rel` is named in messages (e.g. `part.dmdjob/masks/00012.png`).
    fn shown(&self, rel: &str) -> PathBuf;
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
