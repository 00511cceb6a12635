//! A cure-corrected job's regions on nothing, judged by what cures. The correction draws
//! edges in by the cure's growth and leaves partial grays that only the blur joins, so
//! a lit pixel (gray ≥ 128) is not what cures: a lone pixel beside a region may be lit
//! and the gray pixels between them dark, though the light cures them together. Such a
//! job's candidate regions (by gray, [`crate::bundle::regions`]) are judged again by
//! the cure its correction aims at: the PSF-blurred relative light at each pixel's
//! centre, times the layer's exposure against the normal layer's, at least the model's
//! edge threshold T ([`crate::cure::CureModel::edge_threshold`], the contour the
//! correction puts on the part's edge). A candidate rests when what cures of it, grown
//! through cured pixels of its layer, meets what cures of the layer below or a lit
//! region of its layer that rests; it is dropped when none of its pixels cures; else it
//! is kept. The judgment is local: a window of the region's box and a margin of twice
//! the PSF's reach, so a growth that meets a resting region only beyond it is kept.

use crate::bundle::machine::Machine;
use crate::bundle::regions::Run;
use crate::bundle::{BundleSource, Manifest};
use crate::cure::loose::{judged, labels, Cured, Window};
use crate::cure::Psf;
use crate::exec::cure::{decode, model_of, ratios, Light};
use std::cell::RefCell;
use std::rc::Rc;

/// The judge of one job's candidates: its light, its model's threshold and blur.
pub(super) struct CureJudge<'a> {
    source: &'a dyn BundleSource,
    manifest: &'a Manifest,
    light: Light,
    /// The projector's mask size, offset in the field and mirroring.
    size: [usize; 2],
    offset: [usize; 2],
    mirror: [bool; 2],
    /// The field's size, pixels.
    field: [usize; 2],
    threshold: f32,
    ratios: Vec<f32>,
    psf: Psf,
    /// The masks read last, by layer.
    recent: RefCell<Vec<(usize, Rc<Vec<u8>>)>>,
}

impl<'a> CureJudge<'a> {
    /// The judge of `manifest`'s job, or `None` when its masks are judged by gray alone:
    /// no cure correction, or no model to judge by (no `cure` record, several
    /// projectors, an unreadable gray map). `machine`: where the masks lie in the field.
    pub(super) fn of(
        source: &'a dyn BundleSource,
        manifest: &'a Manifest,
        machine: &Machine,
    ) -> Option<Self> {
        manifest.cure.as_ref().filter(|c| c.correction != "off")?;
        let model = model_of(manifest, source).ok()?;
        let light = Light::of(manifest, source).ok()?;
        let [p] = machine.projector.as_slice() else {
            return None;
        };
        let f = machine.field();
        let psf = Psf {
            sigma_px: model.sigma_px,
        };
        Some(CureJudge {
            source,
            manifest,
            light,
            size: [p.width_px as usize, p.height_px as usize],
            offset: p.offset_px.map(|v| v as usize),
            mirror: [p.mirror_x, p.mirror_y],
            field: [f.width_px as usize, f.height_px as usize],
            threshold: model.edge_threshold() as f32,
            ratios: ratios(manifest),
            psf,
            recent: RefCell::new(Vec::new()),
        })
    }

    /// Judges the candidates of layer `i` (≥ 1), whose lit runs on the field are `cur`
    /// and each run's region `region`: clears `free[g]` of each region g that rests or
    /// does not cure (see the module docs). `free` holds the regions resting on nothing
    /// by gray; all stay when a mask cannot be read.
    pub(super) fn judge(&self, i: usize, cur: &[Run], region: &[u32], free: &mut [bool]) {
        let (Some(this), Some(below)) = (self.mask(i), self.mask(i - 1)) else {
            return;
        };
        let mut rests: Vec<bool> = free.iter().map(|f| !f).collect();
        for g in 0..free.len() {
            if !free[g] {
                continue;
            }
            match self.region(i, cur, region, g as u32, &rests, [&this, &below]) {
                Cured::Rests => {
                    free[g] = false;
                    rests[g] = true;
                }
                Cured::Nothing => free[g] = false,
                Cured::Free => {}
            }
        }
    }

    /// Layer `i`'s (first) mask's grays, `None` when it has none or it cannot be read. The
    /// last two read are kept: consecutive layers with regions share one.
    fn mask(&self, i: usize) -> Option<Rc<Vec<u8>>> {
        let mut recent = self.recent.borrow_mut();
        if let Some((_, m)) = recent.iter().find(|(k, _)| *k == i) {
            return Some(Rc::clone(m));
        }
        let m = self.manifest.layers.get(i)?.masks.first()?;
        let (w, h, px) = decode(self.source, &m.file).ok()?;
        let px = Rc::new(([w, h] == self.size).then_some(px)?);
        if recent.len() == 2 {
            recent.remove(0);
        }
        recent.push((i, Rc::clone(&px)));
        Some(px)
    }

    /// What cures of region `g` of layer `i` (see [`CureJudge::judge`]); `masks`: the
    /// layer's and the layer below's grays.
    fn region(
        &self,
        i: usize,
        cur: &[Run],
        region: &[u32],
        g: u32,
        rests: &[bool],
        masks: [&[u8]; 2],
    ) -> Cured {
        let Window { rows, cols } = Window::of((cur, region), g, &self.psf, self.field);
        let ww = cols.len();
        // The candidate's own pixels and those of resting regions of its layer.
        let label = labels((cur, region), g, rests, &rows, &cols);
        let cured_here = self.cured(masks[0], i, &rows, &cols);
        let cured_below = self.cured(masks[1], i - 1, &rows, &cols);
        judged(&label, &cured_here, &cured_below, ww)
    }

    /// Whether each pixel of the field window `rows` × `cols` cures under layer `i`'s
    /// mask `mask`: its blurred light times the layer's dose ratio reaches the threshold.
    fn cured(
        &self,
        mask: &[u8],
        i: usize,
        rows: &std::ops::Range<usize>,
        cols: &std::ops::Range<usize>,
    ) -> Vec<bool> {
        let t = self.threshold / self.ratios.get(i).copied().unwrap_or(1.0);
        // 0 off the masks.
        let light = |fr: Option<usize>, fc: Option<usize>| {
            let k = fr.zip(fc).and_then(|(r, c)| self.mask_index(r, c));
            k.map_or(0.0, |k| self.light.at(k, mask[k]))
        };
        self.psf.cures_in(rows.clone(), cols.clone(), t, light)
    }

    /// The index into the projector's mask of field pixel (row `fr`, column `fc`), `None`
    /// off the mask.
    fn mask_index(&self, fr: usize, fc: usize) -> Option<usize> {
        let [w, h] = self.size;
        let c = fc.checked_sub(self.offset[0]).filter(|&c| c < w)?;
        let r = fr.checked_sub(self.offset[1]).filter(|&r| r < h)?;
        let c = if self.mirror[0] { w - 1 - c } else { c };
        let r = if self.mirror[1] { h - 1 - r } else { r };
        Some(r * w + c)
    }
}

#[cfg(test)]
mod tests {
    use crate::bundle::regions::{field_runs, Placement};
    use crate::bundle::{MemSource, Mode};
    use crate::exec::printable::check;
    use crate::exec::testutil::{cure_record, layer, manifest, profile};
    use std::collections::HashMap;

    /// Layer 0: a block. Layer 1 (the normal exposure): the block; a lit pixel past a
    /// gray one at its edge; an island. Layer 2 (half the exposure): the block and a lone
    /// pixel over nothing. By gray, the pixels and the island rest on nothing; by the cure
    /// of a corrected job, the first pixel cures with the block, the second does not cure
    /// at all, and only the island is left.
    #[test]
    fn a_corrected_jobs_regions_are_what_cures_over_nothing() {
        let (w, h) = (1024usize, 768usize);
        let mut masks = vec![vec![0u8; w * h]; 3];
        let mut set = |i: usize, r: usize, c: usize, g: u8| masks[i][r * w + c] = g;
        for i in 0..3 {
            for r in 100..120 {
                for c in 100..120 {
                    set(i, r, c, 255);
                }
            }
        }
        set(1, 120, 110, 115);
        set(1, 121, 110, 130);
        for r in 300..310 {
            for c in 300..310 {
                set(1, r, c, 255);
            }
        }
        set(2, 400, 400, 128);
        let normal = profile().exposure.layer_s.get();
        let layers = (0..3)
            .map(|i| {
                let t = if i == 2 { normal / 2.0 } else { normal };
                layer(i, 0.05 * (i + 1) as f64, 0.05, Mode::Layered, t, vec![], t)
            })
            .collect();
        let mut m = manifest(profile(), layers);
        let files: HashMap<String, Vec<u8>> = masks
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let png = crate::png::encode_gray8(w as u32, h as u32, d);
                (format!("masks/{i:05}.png"), png)
            })
            .collect();
        let src = MemSource::new(std::path::Path::new("part.dmdjob"), files);
        let at = Placement::of(&m.machine.projector[0]);
        let runs: Vec<_> = masks.iter().map(|d| Some(field_runs(&[(d, at)]))).collect();
        let machine = m.machine.clone();
        let found = |m: &crate::bundle::Manifest| {
            let p = check(&src, m, &machine, &runs);
            let at: Vec<(usize, u64)> = p
                .regions
                .iter()
                .map(|g| {
                    (
                        g.layer,
                        (g.area_mm2 / (m.machine.field().pixel_mm.powi(2))).round() as u64,
                    )
                })
                .collect();
            at
        };
        assert_eq!(found(&m), [(1, 1), (1, 100), (2, 1)], "no model: by gray");
        m.cure = Some(cure_record("off"));
        assert_eq!(
            found(&m),
            [(1, 1), (1, 100), (2, 1)],
            "uncorrected: by gray"
        );
        m.cure = Some(cure_record("xy"));
        assert_eq!(found(&m), [(1, 100)], "corrected: by what cures");
    }
}
