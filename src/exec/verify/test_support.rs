//! Masks, layers and a field of 64 × 48 pixels for the verification's tests.

use super::Verification;
use crate::bundle::{sha256_hex, Layer, Mode};
use crate::exec::testutil::*;
use crate::exec::Kind;
use crate::profile::Profile;
use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder};
use std::path::{Path, PathBuf};

/// The default projector's pixel, mm.
pub(super) const PX: f64 = 0.0634765625;

/// The section most tests use: columns 10..30, rows 5..15 (200 px).
pub(super) const BOX: Option<[f64; 4]> = Some([10.0, 5.0, 30.0, 15.0]);

/// A `w`×`h` PNG of colour type `ct` (8-bit gray or RGB) with varied pixel values.
pub(super) fn png(w: u32, h: u32, ct: ExtendedColorType) -> Vec<u8> {
    let ch = if ct == ExtendedColorType::Rgb8 { 3 } else { 1 };
    let px: Vec<u8> = (0..w * h * ch).map(|i| (i % 251) as u8).collect();
    let mut out = Vec::new();
    PngEncoder::new(&mut out)
        .write_image(&px, w, h, ct)
        .unwrap();
    out
}

/// A `w`×`h` gray PNG with `f(column, row)` as pixel values.
pub(super) fn gray_png(w: u32, h: u32, f: impl Fn(u32, u32) -> u8) -> Vec<u8> {
    let px: Vec<u8> = (0..h)
        .flat_map(|r| (0..w).map(move |c| (c, r)))
        .map(|(c, r)| f(c, r))
        .collect();
    let mut out = Vec::new();
    PngEncoder::new(&mut out)
        .write_image(&px, w, h, ExtendedColorType::L8)
        .unwrap();
    out
}

/// Value `v` inside columns c0..c1, rows r0..r1 (ends exclusive), else 0.
pub(super) fn rect(c0: u32, r0: u32, c1: u32, r1: u32, v: u8) -> impl Fn(u32, u32) -> u8 {
    move |c, r| {
        if (c0..c1).contains(&c) && (r0..r1).contains(&r) {
            v
        } else {
            0
        }
    }
}

/// A 64 × 48 mask lighting columns c0..c1, rows r0..r1 fully.
pub(super) fn lit_png(c0: u32, r0: u32, c1: u32, r1: u32) -> Vec<u8> {
    gray_png(64, 48, rect(c0, r0, c1, r1, 255))
}

/// A scratch bundle directory with `masks/`, removed when dropped.
pub(super) struct Scratch(PathBuf);

impl Scratch {
    /// A fresh directory for the test `name`.
    pub(super) fn new(name: &str) -> Scratch {
        let dir = crate::test_support::scratch("verify", name);
        std::fs::create_dir_all(dir.join("masks")).unwrap();
        Scratch(dir)
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Layer `i`: 0.1 mm, exposed 1 s, no steps, its mask `masks/0000i.png` not written.
pub(super) fn blank_layer(i: usize) -> Layer {
    layer(
        i,
        0.1 * (i + 1) as f64,
        0.1,
        Mode::Layered,
        1.0,
        vec![],
        0.0,
    )
}

/// Layer `i` (as [`blank_layer`]) whose mask file holds `png`, with section box `bbox_px`
/// = [c0, r0, c1, r1] in pixels of a 64×48 field (None: no section) and area `area_px`
/// pixels.
pub(super) fn layer_with(
    dir: &Path,
    i: usize,
    png: &[u8],
    bbox_px: Option<[f64; 4]>,
    area_px: f64,
) -> Layer {
    let mut l = blank_layer(i);
    std::fs::write(dir.join(&l.masks[0].file), png).unwrap();
    l.masks[0].sha256 = sha256_hex(png);
    // Rows count from the top: y = (48 − row)·p.
    l.bbox_mm =
        bbox_px.map(|[c0, r0, c1, r1]| [[c0 * PX, (48.0 - r1) * PX], [c1 * PX, (48.0 - r0) * PX]]);
    l.area_mm2 = area_px * PX * PX;
    l
}

/// The default profile with a 64 × 48 projector.
pub(super) fn small_profile() -> Profile {
    let mut p = profile();
    p.projector[0].width_px = 64;
    p.projector[0].height_px = 48;
    p
}

/// Each problem's layer and kind.
pub(super) fn found(v: &Verification) -> Vec<(Option<usize>, Kind)> {
    v.problems.iter().map(|p| (p.layer, p.kind)).collect()
}

/// A `mask-content` problem for each of `layers`, as [`found`] lists them.
pub(super) fn content(layers: &[usize]) -> Vec<(Option<usize>, Kind)> {
    layers
        .iter()
        .map(|&i| (Some(i), Kind::MaskContent))
        .collect()
}

/// Asserts that problem `i`'s message contains `text`.
pub(super) fn says(v: &Verification, i: usize, text: &str) {
    let m = &v.problems[i].message;
    assert!(m.contains(text), "problem {i}: {m:?} does not say {text:?}");
}

/// Asserts that problem `i`'s message ends with `text`.
pub(super) fn ends(v: &Verification, i: usize, text: &str) {
    let m = &v.problems[i].message;
    assert!(
        m.ends_with(text),
        "problem {i}: {m:?} does not end with {text:?}"
    );
}
