//! Whether a narrow feature that the cure correction would draw wider rests on something
//! below it. The sections do not light such a feature (too thin for a lit pixel), so
//! neither the islands analysis nor the supports see it: widened over nothing, it would
//! cure loose. A feature rests when, walking down through the layers below as long as
//! their sections have material (coverage above 0) under some of its pixels, a layer
//! lights one of them (coverage of at least half a pixel: a lit pixel of its mask), or
//! the walk reaches the platform, or the end of the sections the pipeline holds (a thin
//! wall that tall is taken to stand on something).

use super::layer::{LayerContext, LayerInput};
use crate::bundle::regions::LIT_GRAY;
use crate::raster::{Mask, Scratch};
use crate::slice::Section;

/// The layers below one layer, drawn as a walk needs them.
pub(super) struct Beneath<'a> {
    ctx: &'a LayerContext<'a>,
    index: usize,
    /// The sections below, nearest first.
    sections: &'a [&'a Section],
    /// Their coverages drawn so far (`None`: one the distortion cannot pre-warp).
    drawn: Vec<Option<Mask>>,
    scratch: Scratch,
}

impl<'a> Beneath<'a> {
    /// The layers below `layer`.
    pub fn new(ctx: &'a LayerContext<'a>, layer: &'a LayerInput<'a>) -> Beneath<'a> {
        Beneath {
            ctx,
            index: layer.index,
            sections: &layer.lower,
            drawn: Vec::new(),
            scratch: Scratch::default(),
        }
    }

    /// Whether a feature whose pixels are the mask indices `px` rests on something (see
    /// the module docs).
    pub fn rests(&mut self, px: &[usize]) -> bool {
        let mut left = px.to_vec();
        for d in 0..self.sections.len() {
            let Some(m) = self.coverage(d) else {
                return true;
            };
            if left.iter().any(|&k| m.data[k] >= LIT_GRAY) {
                return true;
            }
            left.retain(|&k| m.data[k] > 0);
            if left.is_empty() {
                return false;
            }
        }
        true
    }

    /// The coverage of the `d`-th layer below (0: the one right below), where this
    /// layer's masks are drawn (pre-warped with a distortion correction).
    fn coverage(&mut self, d: usize) -> Option<&Mask> {
        while self.drawn.len() <= d {
            let k = self.drawn.len();
            let c = &self.sections[k].contours;
            let warped = match self.ctx.correction {
                Some(w) => w.warp_section(c, self.ctx.model, self.index - 1 - k).ok(),
                None => Some(c.clone()),
            };
            let m = warped.map(|w| self.ctx.raster.coverage(&w, &mut self.scratch));
            self.drawn.push(m);
        }
        self.drawn[d].as_ref()
    }
}
