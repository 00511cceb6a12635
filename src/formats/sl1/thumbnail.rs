//! The preview pictures an SL1 carries (`thumbnail/thumbnail400x400.png`,
//! `thumbnail/thumbnail800x480.png`): the shaded picture of the part its masks build
//! ([`crate::picture::preview()`]), as RGBA PNGs like PrusaSlicer's.

use crate::bundle::{BundleSource, Manifest};
use crate::error::Result;
use image::{ImageEncoder, RgbImage};

/// The sizes PrusaSlicer writes for the SL1, px.
pub(super) const SIZES: [(u32, u32); 2] = [(400, 400), (800, 480)];
/// The most layers whose masks a thumbnail is drawn from: slabs of consecutive layers, each
/// drawn from its middle layer's masks (a picture 400 or 800 px wide shows no finer steps,
/// and every mask read costs a PNG decoding).
const SLABS: usize = 48;

/// `m` with its layers merged into at most [`SLABS`] slabs of consecutive layers: each the
/// record of its middle layer, spanning the slab's height, with the slab's bounding box.
fn slabs(m: &Manifest) -> Manifest {
    let k = m.layers.len().div_ceil(SLABS).max(1);
    let layers = m
        .layers
        .chunks(k)
        .map(|group| {
            let (first, last) = (&group[0], &group[group.len() - 1]);
            let mut l = group[group.len() / 2].clone();
            l.z_mm = last.z_mm;
            l.thickness_mm = last.z_mm - (first.z_mm - first.thickness_mm);
            l.bbox_mm = group.iter().filter_map(|x| x.bbox_mm).reduce(|a, b| {
                [
                    [a[0][0].min(b[0][0]), a[0][1].min(b[0][1])],
                    [a[1][0].max(b[1][0]), a[1][1].max(b[1][1])],
                ]
            });
            l
        })
        .collect();
    Manifest {
        layers,
        cure: None,
        warnings: Vec::new(),
        optics: None,
        projector_optics: Vec::new(),
        supports: None,
        format: m.format.clone(),
        version: m.version,
        generator: m.generator.clone(),
        source: m.source.clone(),
        settings: m.settings.clone(),
        machine: m.machine.clone(),
        totals: m.totals.clone(),
    }
}

/// The thumbnails, `(entry name, PNG bytes)`, one per size of [`SIZES`]: the preview is
/// drawn once, at the larger size, and the square one is that picture padded to a square
/// with its background and shrunk (the drawing is most of the cost of an SL1).
pub(super) fn thumbnails(
    manifest: &Manifest,
    files: &dyn BundleSource,
) -> Result<Vec<(String, Vec<u8>)>> {
    let thin = slabs(manifest);
    let (w, h) = SIZES[1];
    let wide = crate::picture::preview(&thin, files, w, h)?;
    let background = *wide.get_pixel(0, 0);
    let side = w.max(h);
    let mut square = RgbImage::from_pixel(side, side, background);
    image::imageops::replace(
        &mut square,
        &wide,
        ((side - w) / 2) as i64,
        ((side - h) / 2) as i64,
    );
    let (sw, sh) = SIZES[0];
    let small = image::imageops::resize(&square, sw, sh, image::imageops::FilterType::Triangle);
    Ok([(sw, sh, &small), (w, h, &wide)]
        .into_iter()
        .map(|(w, h, rgb)| (format!("thumbnail/thumbnail{w}x{h}.png"), rgba_png(rgb)))
        .collect())
}

/// `rgb` as an RGBA PNG, opaque.
fn rgba_png(rgb: &RgbImage) -> Vec<u8> {
    let rgba: Vec<u8> = rgb.pixels().flat_map(|p| [p[0], p[1], p[2], 255]).collect();
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(
            &rgba,
            rgb.width(),
            rgb.height(),
            image::ExtendedColorType::Rgba8,
        )
        .expect("PNG encodes into memory");
    png
}

/// The shaded picture of the part the job's masks build, `size` px, as an RGBA PNG (a
/// NanoDLP plate's `3d.png`).
pub(crate) fn preview_png(
    manifest: &Manifest,
    files: &dyn BundleSource,
    (w, h): (u32, u32),
) -> Result<Vec<u8>> {
    Ok(rgba_png(&crate::picture::preview(
        &slabs(manifest),
        files,
        w,
        h,
    )?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slabs_span_the_part_and_keep_its_footprint() {
        let mut m = crate::exec::testutil::two_layer_topdown();
        let proto = m.layers[1].clone();
        m.layers = (0..200)
            .map(|i| {
                let mut l = proto.clone();
                l.index = i;
                l.thickness_mm = 0.05;
                l.z_mm = 0.05 * (i + 1) as f64;
                l.bbox_mm = Some([
                    [10.0 - i as f64 * 0.01, 10.0],
                    [20.0, 20.0 + i as f64 * 0.01],
                ]);
                l
            })
            .collect();
        let t = slabs(&m);
        assert!(t.layers.len() <= SLABS);
        assert!((t.layers[0].z_mm - t.layers[0].thickness_mm).abs() < 1e-9);
        assert_eq!(t.layers.last().unwrap().z_mm, m.layers[199].z_mm);
        let lo = t
            .layers
            .iter()
            .map(|l| l.bbox_mm.unwrap()[0][0])
            .fold(f64::MAX, f64::min);
        let hi = t
            .layers
            .iter()
            .map(|l| l.bbox_mm.unwrap()[1][1])
            .fold(0.0, f64::max);
        assert!(
            (lo - 8.01).abs() < 1e-9 && (hi - 21.99).abs() < 1e-9,
            "{lo} {hi}"
        );
    }
}
