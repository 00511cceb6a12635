//! The cure of a whole job from its layers' relative irradiance, from the top layer down
//! (docs/CURE.md, "From the masks"): what `dmdsl run --cure` reports and what
//! `slice --predict` records.
//!
//! In the projector's pixels, for one projector:
//!
//! 1. Each layer's **relative irradiance** (the caller's: a written mask's gray through the
//!    response and the gray map, `exec::cure`), and its dose ratio r = its exposure / the
//!    normal layer's (bottom layers and a continuous layer's sweep time count as they are).
//! 2. The light blurred by the Gaussian PSF (separable pixel-box weights,
//!    [`Psf::axis_weight`](super::Psf::axis_weight)) at [`SUB`]×[`SUB`] samples per
//!    pixel, over the lit box plus the PSF's reach ([`Kernel`]).
//! 3. From the top layer down, A_i = r_i·L_i + q·A_{i+1} (q = exp(−h/Dp)): the light that
//!    reaches layer i's top from its own exposure and every following one. Layer i's
//!    mid-plane cures where A_i·D₀·exp(−h/(2Dp)) ≥ Ec. One accumulation buffer the size of
//!    the field, whatever the layer count ([`Engine`]).
//! 4. Per layer: the cured area (where the layer's own light is at least [`NEAR`]: farther
//!    out it is the print-through of the layers above; with `xyz` also where one of the
//!    held-back layers above lights it, [`Engine::count_held_back`]) against the
//!    section's, the drawn perimeter (Σ|∇| of the relative irradiance by central
//!    differences: exact for a monotone anti-aliased edge at any angle; with `xyz` the
//!    largest of the held-back layers' and its own) and so the mean edge offset; the islands
//!    (4-connected pixels of relative irradiance ≥ [`LIT`]) that do not cure ("vanished")
//!    or that one cured region joins ("merged"); the print-through below downward-facing
//!    pixels (lit, over a pixel that is dark in the layer below, as are its 4 neighbours).

use super::engine::{Engine, LayerOut};
use super::kernel::{Irradiance, Kernel, Prepared};
use super::CureModel;
use crate::error::Result;
use rayon::prelude::*;

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
/// Layers prepared together, ahead of the sequential recurrence.
pub(super) const CHUNK: usize = 8;

/// Runs every layer of a `w`×`h` field through the engine, from the top layer down:
/// `irradiance(i)` gives layer i's relative irradiance (called in parallel, a chunk of
/// layers ahead of the recurrence), `ratio[i]` its dose ratio. `observe(i, engine)` is
/// called right after layer i is evaluated, with its irradiance when `track` (the engine
/// then holds the light that reaches layer i's top, [`Engine::irradiance`]). With
/// `held_back` layers (`xyz`), a layer's cured area also takes what they light
/// ([`Engine::count_held_back`]).
pub fn run_layers(
    model: &CureModel,
    (w, h): (usize, usize),
    ratio: &[f32],
    irradiance: &(dyn Fn(usize) -> Result<Irradiance> + Sync),
    (track, held_back): (bool, usize),
    observe: &mut (dyn FnMut(usize, &Engine, &Irradiance) + Send),
) -> Result<Vec<LayerOut>> {
    let n = ratio.len();
    let kernel = Kernel::new(w, h, model);
    let prepare = |hi: usize| -> Result<Vec<(Irradiance, Prepared)>> {
        // Layers hi−1 down to hi−CHUNK (top first).
        let lo = hi.saturating_sub(CHUNK);
        crate::error::in_order((lo..hi).into_par_iter().rev().map(|i| {
            let irr = irradiance(i)?;
            let p = kernel.prepare(&irr, ratio[i]);
            Ok((if track { irr } else { Irradiance::default() }, p))
        }))
    };
    let mut engine = Engine::new(w, h, model);
    engine.track_irradiance(track);
    engine.count_held_back(held_back);
    let mut outs: Vec<LayerOut> = vec![LayerOut::default(); n];
    let mut hi = n;
    let mut cur = if n > 0 { prepare(n)? } else { Vec::new() };
    while hi > 0 {
        let lo = hi.saturating_sub(CHUNK);
        // Prepare the next chunk while this one runs through the recurrence.
        let (next, ()) = rayon::join(
            || if lo > 0 { prepare(lo) } else { Ok(Vec::new()) },
            || {
                for k in 0..cur.len() - 1 {
                    let i = hi - 1 - k;
                    let (irr, p) = &cur[k];
                    outs[i] = engine.layer(p, Some(&cur[k + 1].1), irr, ratio[i]);
                    observe(i, &engine, irr);
                }
                let last = cur.len() - 1;
                for (_, p) in cur.drain(..last) {
                    kernel.recycle(p);
                }
            },
        );
        let next = next?;
        let (irr, p) = cur.last().expect("a chunk has a layer");
        outs[lo] = engine.layer(p, next.first().map(|n| &n.1), irr, ratio[lo]);
        observe(lo, &engine, irr);
        for (_, p) in cur.drain(..) {
            kernel.recycle(p);
        }
        cur = next;
        hi = lo;
    }
    Ok(outs)
}
