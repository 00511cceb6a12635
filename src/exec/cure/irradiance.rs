//! A mask's relative irradiance (the mask's gray through the projector's response and
//! the bundle's gray map, or g/255), cut to its lit box, and the decoding of the bundle's
//! 8-bit gray PNGs.

use crate::bundle::{BundleSource, Manifest};
use crate::error::{Error, Result};
use image::codecs::png::PngDecoder;
use image::ImageDecoder;

/// A layer's relative irradiance inside its lit box (pixels, ends exclusive).
#[derive(Debug, Clone, Default)]
pub struct Irradiance {
    /// `[c0, r0, c1, r1]`; empty when nothing is lit.
    pub bbox: [usize; 4],
    /// Row-major over the box.
    pub data: Vec<f32>,
}

impl Irradiance {
    /// The irradiance of a whole `w`×`h` image, cut to its nonzero box.
    #[cfg(test)]
    pub fn from_image(w: usize, h: usize, img: &[f32]) -> Irradiance {
        let (mut c0, mut r0, mut c1, mut r1) = (w, h, 0, 0);
        for r in 0..h {
            let row = &img[r * w..(r + 1) * w];
            if let Some(a) = row.iter().position(|&v| v > 0.0) {
                let b = row.iter().rposition(|&v| v > 0.0).unwrap_or(a);
                c0 = c0.min(a);
                c1 = c1.max(b + 1);
                r0 = r0.min(r);
                r1 = r + 1;
            }
        }
        Irradiance::cut(w, img, [c0, r0, c1, r1])
    }

    #[cfg(test)]
    fn cut(w: usize, img: &[f32], bbox: [usize; 4]) -> Irradiance {
        let [c0, r0, c1, r1] = bbox;
        if c0 >= c1 || r0 >= r1 {
            return Irradiance::default();
        }
        let mut data = Vec::with_capacity((c1 - c0) * (r1 - r0));
        for r in r0..r1 {
            data.extend_from_slice(&img[r * w + c0..r * w + c1]);
        }
        Irradiance { bbox, data }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.data.is_empty()
    }
}

/// How a mask's gray turns into relative irradiance.
pub(super) enum Light {
    /// g/255.
    Linear([f32; 256]),
    /// S(g)/S(G(px)): `s[g]` and 1/S(G) per pixel (0 where G = 0: g/255 there).
    Compensated { s: [f32; 256], inv_full: Vec<f32> },
}

impl Light {
    /// How `manifest`'s masks turn into relative irradiance, or an error naming the gray
    /// map and what is wrong.
    pub(super) fn of(manifest: &Manifest, source: &dyn BundleSource) -> Result<Light> {
        let mut linear = [0f32; 256];
        for (g, v) in linear.iter_mut().enumerate() {
            *v = g as f32 / 255.0;
        }
        let Some(o) = &manifest.optics else {
            return Ok(Light::Linear(linear));
        };
        let bad = |msg: String| Error::Bundle {
            path: source.shown(&o.gray_map),
            msg,
        };
        let proj = manifest
            .machine
            .projector
            .get(o.projector as usize)
            .ok_or_else(|| bad("--cure: the gray map's projector is not the machine's".into()))?;
        let cal = proj.calibration.as_ref().ok_or_else(|| {
            bad("--cure: light compensation without the projector's calibration".into())
        })?;
        let [lo, hi] = cal.response.valid_gray();
        let curve = cal.response.curve();
        let mut s = [0f32; 256];
        for (g, v) in s.iter_mut().enumerate().skip(1) {
            *v = curve.eval(g.clamp(lo as usize, hi as usize) as f64) as f32;
        }
        let (w, h, full) = decode(source, &o.gray_map)?;
        if (w, h) != (proj.width_px as usize, proj.height_px as usize) {
            return Err(bad(format!(
                "gray map is {w}x{h}, the projector {}x{}",
                proj.width_px, proj.height_px
            )));
        }
        let inv_full = full
            .iter()
            .map(|&g| if g == 0 { 0.0 } else { 1.0 / s[g as usize] })
            .collect();
        Ok(Light::Compensated { s, inv_full })
    }

    /// The relative irradiance of a `w`-wide mask, cut to its lit box.
    pub(super) fn irradiance(&self, w: usize, h: usize, mask: &[u8]) -> Irradiance {
        let (mut c0, mut r0, mut c1, mut r1) = (w, h, 0, 0);
        for (r, row) in mask.chunks(w).enumerate() {
            // Dark rows (most) told by an OR of the bytes (vectorizes).
            if row.iter().fold(0u8, |a, &v| a | v) == 0 {
                continue;
            }
            if let Some(a) = row.iter().position(|&v| v != 0) {
                let b = row.iter().rposition(|&v| v != 0).unwrap_or(a);
                c0 = c0.min(a);
                c1 = c1.max(b + 1);
                r0 = r0.min(r);
                r1 = r + 1;
            }
        }
        if c0 >= c1 {
            return Irradiance::default();
        }
        let mut data = Vec::with_capacity((c1 - c0) * (r1 - r0));
        for r in r0..r1 {
            let row = &mask[r * w + c0..r * w + c1];
            match self {
                Light::Linear(t) => data.extend(row.iter().map(|&g| t[g as usize])),
                Light::Compensated { s, inv_full } => {
                    let inv = &inv_full[r * w + c0..r * w + c1];
                    data.extend(row.iter().zip(inv).map(|(&g, &i)| {
                        if i > 0.0 {
                            s[g as usize] * i
                        } else {
                            g as f32 / 255.0
                        }
                    }))
                }
            }
        }
        Irradiance {
            bbox: [c0, r0, c1, r1],
            data,
        }
    }
}

/// Decodes an 8-bit gray PNG of the bundle.
fn decode(source: &dyn BundleSource, rel: &str) -> Result<(usize, usize, Vec<u8>)> {
    let mut buf = Vec::new();
    let (w, h) = decode_into(source, rel, &mut buf)?;
    Ok((w, h, buf))
}

/// Decodes an 8-bit gray PNG of the bundle into `buf` (its size, the image's; cleared
/// only where it grows): its width and height.
pub(super) fn decode_into(
    source: &dyn BundleSource,
    rel: &str,
    buf: &mut Vec<u8>,
) -> Result<(usize, usize)> {
    let bad = |msg: String| Error::Bundle {
        path: source.shown(rel),
        msg,
    };
    let bytes = source
        .read(rel)
        .map_err(|e| bad(format!("cannot read: {e}")))?;
    let dec = PngDecoder::new(std::io::Cursor::new(&bytes[..]))
        .map_err(|e| bad(format!("not a decodable PNG: {e}")))?;
    if dec.color_type() != image::ColorType::L8 {
        return Err(bad("not 8-bit gray".into()));
    }
    let (w, h) = dec.dimensions();
    buf.resize(dec.total_bytes() as usize, 0);
    dec.read_image(buf)
        .map_err(|e| bad(format!("PNG does not decode: {e}")))?;
    Ok((w as usize, h as usize))
}
