//! `dmdsl run --cure`: what cures, predicted from a bundle's masks alone. The engine is
//! [`crate::cure`]'s (docs/CURE.md, docs/EXECUTOR.md "Cure check"); this is the adapter
//! from a bundle to it: the model from the manifest's `cure` record, each mask's relative
//! irradiance (its gray through the projector's response and the bundle's gray map, or
//! g/255) and each layer's dose ratio (its exposure against the normal layer's).

use crate::bundle::machine::Projector;
use crate::bundle::{BundleSource, Manifest, MANIFEST};
pub use crate::cure::CureCheck;
use crate::cure::{CureModel, Irradiance};
use crate::error::{Error, Result};
use image::codecs::png::PngDecoder;
use image::ImageDecoder;

/// The model's inputs of `manifest`, or an error naming the bundle and what is missing:
/// the `cure` record, or a single projector.
pub fn model_of(manifest: &Manifest, source: &dyn BundleSource) -> Result<CureModel> {
    let err = |msg: String| Error::Bundle {
        path: source.shown(MANIFEST),
        msg,
    };
    let Some(c) = &manifest.cure else {
        return Err(err(
            "--cure: the job has no `cure` record (it was sliced with a profile without \
             psf_sigma_px, or imported): nothing to predict with"
                .into(),
        ));
    };
    let n = manifest.machine.projector.len();
    if n != 1 {
        return Err(err(format!(
            "--cure: the job has {n} projectors; the cure check handles one (overlap \
             blending would need the projectors' light summed in the field)"
        )));
    }
    Ok(CureModel {
        sigma_px: c.psf_sigma_px,
        pixel_mm: c.pixel_mm,
        dp_mm: c.dp_mm,
        ec_mj_cm2: c.ec_mj_cm2,
        overcure_mm: c.overcure_mm,
        layer_mm: c.layer_mm,
    })
}

/// Each layer's dose ratio: its exposure against the machine's normal layer's.
pub fn ratios(manifest: &Manifest) -> Vec<f32> {
    let normal_s = manifest.machine.exposure.layer_s.get();
    manifest
        .layers
        .iter()
        .map(|l| (l.exposure_s / normal_s) as f32)
        .collect()
}

/// The relative irradiance of the mask `rel` of `source` as `light` turns its grays, or
/// an error naming the file (unreadable, or not `size` pixels).
pub fn irradiance_of(
    source: &dyn BundleSource,
    rel: &str,
    (w, h): (usize, usize),
    light: &Light,
) -> Result<Irradiance> {
    thread_local! {
        static MASK: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    let mut px = MASK.with(|b| std::mem::take(&mut *b.borrow_mut()));
    let (mw, mh) = decode_into(source, rel, &mut px)?;
    if (mw, mh) != (w, h) {
        return Err(Error::Bundle {
            path: source.shown(rel),
            msg: format!("mask is {mw}x{mh}, the projector {w}x{h}"),
        });
    }
    let irr = light.irradiance(w, h, &px);
    MASK.with(|b| *b.borrow_mut() = px);
    Ok(irr)
}

/// Mask pixel coordinates (column, row, in pixel units) of projector `p` → build-plane
/// mm, on a field `field_h` rows high of `pixel_mm` pixels (mirroring undone, offset
/// added, rows from the top).
pub fn to_build_plane(p: &Projector, pixel_mm: f64, field_h: f64) -> impl Fn([f64; 2]) -> [f64; 2] {
    let (w, h) = (p.width_px as f64, p.height_px as f64);
    let (ox, oy, mx, my) = (
        p.offset_px[0] as f64,
        p.offset_px[1] as f64,
        p.mirror_x,
        p.mirror_y,
    );
    move |[u, v]| {
        let u = if mx { w - u } else { u };
        let v = if my { h - v } else { v };
        [(ox + u) * pixel_mm, (field_h - oy - v) * pixel_mm]
    }
}

/// The cure of every layer of the job whose files `source` reads, from its masks (see the
/// module docs). `model` from [`model_of`].
pub fn check(
    manifest: &Manifest,
    source: &dyn BundleSource,
    model: &CureModel,
) -> Result<CureCheck> {
    let proj = &manifest.machine.projector[0];
    let size = (proj.width_px as usize, proj.height_px as usize);
    let light = Light::of(manifest, source)?;
    let outs = crate::cure::run_layers(
        model,
        size,
        &ratios(manifest),
        &|i| match manifest.layers[i].masks.first() {
            Some(m) => irradiance_of(source, &m.file, size, &light),
            None => Ok(Irradiance::default()),
        },
        (false, held_back(manifest)),
        &mut |_, _, _| {},
    )?;
    let field_h = manifest.machine.field().height_px as f64;
    let to_mm = to_build_plane(proj, model.pixel_mm, field_h);
    Ok(crate::cure::summarize(manifest, model, &to_mm, outs))
}

/// The layers `manifest`'s `xyz` correction holds downward-facing surfaces back by.
fn held_back(manifest: &Manifest) -> usize {
    manifest
        .cure
        .as_ref()
        .map_or(0, |c| c.held_back_layers as usize)
}

/// How a mask's gray turns into relative irradiance.
pub enum Light {
    /// g/255.
    Linear([f32; 256]),
    /// S(g)/S(G(px)), 0 where G = 0 (g/255 there).
    Compensated {
        /// S(g), the response, per gray.
        s: [f32; 256],
        /// 1/S(G) per pixel, G its full-coverage gray.
        inv_full: Vec<f32>,
    },
}

impl Light {
    /// g/255: masks of relative irradiance (uncompensated coverage).
    pub fn linear() -> Light {
        let mut linear = [0f32; 256];
        for (g, v) in linear.iter_mut().enumerate() {
            *v = g as f32 / 255.0;
        }
        Light::Linear(linear)
    }

    /// How `manifest`'s masks turn into relative irradiance, or an error naming the gray
    /// map and what is wrong.
    pub fn of(manifest: &Manifest, source: &dyn BundleSource) -> Result<Light> {
        let Some(o) = &manifest.optics else {
            return Ok(Light::linear());
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
    pub fn irradiance(&self, w: usize, h: usize, mask: &[u8]) -> Irradiance {
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
                    data.extend(row.iter().zip(inv).map(|(&g, &i)| compensated(s, g, i)))
                }
            }
        }
        Irradiance {
            bbox: [c0, r0, c1, r1],
            data,
        }
    }

    /// The relative irradiance of gray `g` at pixel `k` (row-major) of a mask.
    pub fn at(&self, k: usize, g: u8) -> f32 {
        match self {
            Light::Linear(t) => t[g as usize],
            Light::Compensated { s, inv_full } => compensated(s, g, inv_full[k]),
        }
    }
}

/// S(g)/S(G) from the response `s` and `inv` = 1/S(G) of a pixel, g/255 where G = 0.
#[inline]
fn compensated(s: &[f32; 256], g: u8, inv: f32) -> f32 {
    if inv > 0.0 {
        s[g as usize] * inv
    } else {
        g as f32 / 255.0
    }
}

/// Decodes an 8-bit gray PNG of the bundle.
pub(super) fn decode(source: &dyn BundleSource, rel: &str) -> Result<(usize, usize, Vec<u8>)> {
    let mut buf = Vec::new();
    let (w, h) = decode_into(source, rel, &mut buf)?;
    Ok((w, h, buf))
}

/// Decodes an 8-bit gray PNG of the bundle into `buf` (its size, the image's; cleared
/// only where it grows): its width and height.
fn decode_into(source: &dyn BundleSource, rel: &str, buf: &mut Vec<u8>) -> Result<(usize, usize)> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The model of the unit tests.
    pub(super) fn model() -> CureModel {
        crate::cure::test_model()
    }

    /// `--cure` needs the `cure` record and one projector; each refusal names the bundle.
    #[test]
    fn jobs_without_the_record_or_with_several_projectors_are_refused() {
        use crate::bundle::DirSource;
        let src = DirSource::new(std::path::Path::new("some.dmdjob"));
        let mut man = crate::exec::testutil::two_layer_topdown();
        man.cure = None;
        let e = model_of(&man, &src).unwrap_err().to_string();
        assert!(
            e.contains("some.dmdjob") && e.contains("`cure` record"),
            "{e}"
        );
        let m = model();
        man.cure = Some(crate::exec::testutil::cure_record("xy"));
        assert_eq!(model_of(&man, &src).unwrap(), m);
        man.machine =
            crate::bundle::Machine::of(&crate::profile::Profile::resolve("tiled-2x1").unwrap());
        let e = model_of(&man, &src).unwrap_err().to_string();
        assert!(
            e.contains("some.dmdjob") && e.contains("2 projectors"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1);
    }
}
