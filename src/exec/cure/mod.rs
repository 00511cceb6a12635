//! `dmdsl run --cure`: what cures, predicted from a bundle's masks alone (docs/CURE.md's
//! model through [`crate::resin`], docs/EXECUTOR.md "Cure check").
//!
//! In the projector's pixels, for one projector:
//!
//! 1. Each mask pixel's **relative irradiance**: with light compensation S(g)/S(G(px)) (g
//!    the mask's gray, G the pixel's full-coverage gray from the bundle's gray map, S the
//!    projector's response), else g/255.
//! 2. Each layer's light scaled by r = `exposure_s` / the profile's normal `layer_s`
//!    (bottom layers and a continuous layer's sweep time count as they are).
//! 3. The light blurred by the Gaussian PSF (separable pixel-box weights,
//!    [`Psf::axis_weight`](crate::resin::Psf::axis_weight)) at [`SUB`]×[`SUB`] samples
//!    per pixel, over the lit box plus the PSF's reach.
//! 4. From the top layer down, A_i = r_i·L_i + q·A_{i+1} (q = exp(−h/Dp)): the light that
//!    reaches layer i's top from its own exposure and every following one. Layer i's
//!    mid-plane cures where A_i·D₀·exp(−h/(2Dp)) ≥ Ec. One accumulation buffer the size of
//!    the field, whatever the layer count.
//! 5. Per layer: the cured area (where the layer's own light is at least [`NEAR`]: farther
//!    out it is the print-through of the layers above) against the section's
//!    (`area_mm2`), the drawn perimeter
//!    (Σ|∇| of the relative irradiance by central differences: exact for a monotone
//!    anti-aliased edge at any angle) and so the mean edge offset; the islands (4-connected
//!    pixels of relative irradiance ≥ 0.5) that do not cure ("vanished") or that one cured
//!    region joins ("merged"); the print-through below downward-facing pixels (lit, over
//!    a pixel that is dark in the layer below, as are its 4 neighbours).
//!
//! Files: `irradiance.rs` a mask's relative irradiance (the gray map and the response)
//! and the PNG decoding; `kernel.rs` what a layer gives from its mask alone (the blurred
//! light, the samples that cure whole, the drawn perimeter), prepared in parallel ahead
//! of the recurrence; `islands.rs` lit runs and their 4-connected components
//! (union-find); `engine.rs` the sequential recurrence from the top layer down, the
//! cured sums, merges and print-through; `report.rs` the report's types and the job's
//! figures from the layers'.

use crate::bundle::{BundleSource, Manifest, MANIFEST};
use crate::error::{Error, Result};
use crate::resin::CureModel;
use rayon::prelude::*;

mod engine;
mod irradiance;
mod islands;
mod kernel;
mod report;

pub use engine::{Engine, LayerOut};
#[cfg(any(test, feature = "internals"))]
pub use irradiance::Irradiance;
pub use kernel::{Kernel, Prepared};
pub use report::CureCheck;
#[cfg(any(test, feature = "internals"))]
pub use report::{Finding, LayerCureCheck, OffsetStats, SlicerAgreement};

use irradiance::{decode_into, Light};
use report::summarize;

/// Samples per pixel along each axis at which the cure is evaluated.
pub const SUB: usize = 2;
/// The worst layers the check names.
pub const WORST_LAYERS: usize = 5;
/// Relative irradiance at which a pixel counts as lit (islands, downward-facing pixels).
pub const LIT: f32 = 0.5;
/// The layer's own light (of a full pixel) below which a sample does not count in its
/// cured area: about 1.3 px outside a straight edge with σ = 0.5 px, well beyond the
/// cured edge; resin cured farther out is the layers above's print-through.
pub const NEAR: f32 = 0.01;
/// Layers decoded together, ahead of the sequential recurrence.
const CHUNK: usize = 8;

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

/// The cure of every layer of the job whose files `source` reads, from its masks (see the
/// module docs). `model` from [`model_of`].
pub fn check(
    manifest: &Manifest,
    source: &dyn BundleSource,
    model: &CureModel,
) -> Result<CureCheck> {
    let proj = &manifest.machine.projector[0];
    let (w, h) = (proj.width_px as usize, proj.height_px as usize);
    let light = Light::of(manifest, source)?;
    let normal_s = manifest.machine.exposure.layer_s.get();
    let n = manifest.layers.len();
    let kernel = Kernel::new(w, h, model);
    let decode_layer = |i: usize| -> Result<Prepared> {
        let Some(m) = manifest.layers[i].masks.first() else {
            return Ok(Prepared::default());
        };
        thread_local! {
            static MASK: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
        }
        let mut px = MASK.with(|b| std::mem::take(&mut *b.borrow_mut()));
        let (mw, mh) = decode_into(source, &m.file, &mut px)?;
        if (mw, mh) != (w, h) {
            return Err(Error::Bundle {
                path: source.shown(&m.file),
                msg: format!("mask is {mw}x{mh}, the projector {w}x{h}"),
            });
        }
        let r = (manifest.layers[i].exposure_s / normal_s) as f32;
        let p = kernel.prepare(&light.irradiance(w, h, &px), r);
        MASK.with(|b| *b.borrow_mut() = px);
        Ok(p)
    };
    let decode_chunk = |hi: usize| -> Result<Vec<Prepared>> {
        // Layers hi−1 down to hi−CHUNK (top first).
        let lo = hi.saturating_sub(CHUNK);
        (lo..hi)
            .rev()
            .collect::<Vec<_>>()
            .par_iter()
            .map(|&i| decode_layer(i))
            .collect()
    };
    let mut engine = Engine::new(w, h, model);
    let mut outs: Vec<LayerOut> = vec![LayerOut::default(); n];
    let mut hi = n;
    let mut cur = if n > 0 { decode_chunk(n)? } else { Vec::new() };
    while hi > 0 {
        let lo = hi.saturating_sub(CHUNK);
        // Decode the next chunk while this one runs through the recurrence.
        let (next, ()) = rayon::join(
            || {
                if lo > 0 {
                    decode_chunk(lo)
                } else {
                    Ok(Vec::new())
                }
            },
            || {
                for k in 0..cur.len() - 1 {
                    let i = hi - 1 - k;
                    let r = (manifest.layers[i].exposure_s / normal_s) as f32;
                    outs[i] = engine.layer(&cur[k], Some(&cur[k + 1]), r);
                }
                for p in cur.drain(..cur.len() - 1) {
                    kernel.recycle(p);
                }
            },
        );
        let next = next?;
        let i = lo;
        let r = (manifest.layers[i].exposure_s / normal_s) as f32;
        let last = cur.last().expect("a chunk has a layer");
        outs[i] = engine.layer(last, next.first(), r);
        for p in cur.drain(..) {
            kernel.recycle(p);
        }
        cur = next;
        hi = lo;
    }
    Ok(summarize(manifest, model, proj, outs))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The model of the unit tests.
    pub(super) fn model() -> CureModel {
        crate::resin::dose::test_model()
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
        man.cure = Some(crate::bundle::Cure {
            psf_sigma_px: m.sigma_px,
            pixel_mm: m.pixel_mm,
            dp_mm: m.dp_mm,
            ec_mj_cm2: m.ec_mj_cm2,
            overcure_mm: m.overcure_mm,
            layer_mm: m.layer_mm,
            edge_threshold: m.edge_threshold(),
            correction: "xy".into(),
            shift_px: 0.49,
            print_through_mm: m.print_through_mm(None),
            held_back_layers: 0,
            predicted: None,
            dropped: None,
        });
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
