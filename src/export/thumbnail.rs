//! The preview pictures an SL1 carries (`thumbnail/thumbnail400x400.png`,
//! `thumbnail/thumbnail800x480.png`): the shaded picture of the part its masks build
//! ([`crate::inspect::preview()`]), as RGBA PNGs like PrusaSlicer's.

use super::BundleFiles;
use crate::bundle::Manifest;
use crate::error::Result;
use crate::inspect::reader::{decode_mask, MaskReader};
use image::{GrayImage, ImageEncoder};
use std::path::PathBuf;

/// The sizes PrusaSlicer writes for the SL1, px.
pub(super) const SIZES: [(u32, u32); 2] = [(400, 400), (800, 480)];

/// The masks of a job, decoded from its files.
struct Masks<'a>(&'a dyn BundleFiles);

impl MaskReader for Masks<'_> {
    fn read_mask(&self, rel: &str) -> Result<GrayImage> {
        decode_mask(&self.0.read(rel)?, &self.0.shown(rel))
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.0.shown(rel)
    }
}

/// The thumbnails, `(entry name, PNG bytes)`, one per size of [`SIZES`].
pub(super) fn thumbnails(
    manifest: &Manifest,
    files: &dyn BundleFiles,
) -> Result<Vec<(String, Vec<u8>)>> {
    let masks = Masks(files);
    SIZES
        .iter()
        .map(|&(w, h)| {
            let rgb = crate::inspect::preview(manifest, &masks, w, h)?;
            let rgba: Vec<u8> = rgb.pixels().flat_map(|p| [p[0], p[1], p[2], 255]).collect();
            let mut png = Vec::new();
            image::codecs::png::PngEncoder::new(&mut png)
                .write_image(&rgba, w, h, image::ExtendedColorType::Rgba8)
                .expect("PNG encodes into memory");
            Ok((format!("thumbnail/thumbnail{w}x{h}.png"), png))
        })
        .collect()
}
