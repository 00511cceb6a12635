//! Masks drawn once and written again: a layer whose section equals the layer below's
//! once collinear points are left out (a prism; `plan::analysis`) is drawn from that
//! simplified section, so equal layers get equal masks, and the bytes drawn for one serve
//! the next. The same section draws the same bytes, so reuse changes only the speed, never
//! the output, whichever worker drew them first. A layer drawn as without the cure
//! correction, in windows or whole (`super::uncorrected`), is drawn unlike the other
//! layers of its section: it neither takes masks nor gives them.
//!
//! Two caches: each worker keeps its previous layer's masks ([`PreviousLayerMasks`], for
//! the layers of its block after the first), and the workers share the masks of the last
//! few simplified sections any of them drew ([`RecentPrismMasks`], for the first layer of
//! a block, whose layer below another worker drew).

use crate::plan::analysis::LitRuns;
use crate::slice::Contour;
use std::sync::{Arc, Mutex};

/// What drawing one section gave: its masks' files and what writing them again must
/// repeat.
pub(super) struct DrawnMasks {
    /// Per projector, whether drawing them reported the layer to its light compensation
    /// as reaching outside the calibrated area, and how far, mm (a copy reports it again:
    /// every such layer counts).
    pub outside: Vec<Option<f64>>,
    /// Lit area, mm².
    pub area_mm2: f64,
    /// The cure correction's moves of the edges they were drawn with (empty without).
    pub shifts: Vec<f64>,
    /// The field's coverage mask as a PNG, for the cure prediction of a job of several
    /// projectors (`--predict`).
    pub field: Option<Vec<u8>>,
    /// The flat features the Z correction drops, found while drawing them (empty unless
    /// `xyz`, where masks are not reused).
    pub dropped: Vec<(usize, super::cure_records::LayerDropped)>,
    /// The narrow features the XY correction drew wider so they cure.
    pub widened: Option<super::cure_records::LayerWidened>,
    /// PNG bytes, SHA-256, projector and pixels (placed in the field) of each mask.
    pub pngs: Vec<(Vec<u8>, String, u32, crate::bundle::MaskPixels)>,
    /// The masks' lit runs on the field (gray at least half), in a job with supports:
    /// what `dmdsl run` finds regions on nothing in (`crate::exec::unheld_regions`).
    pub field_runs: Option<Arc<[crate::bundle::regions::Run]>>,
    /// The lit pixels (for the islands) when drawn from a simplified section, which
    /// [`RecentPrismMasks`] may hand to another worker; empty otherwise.
    pub runs: LitRuns,
}

/// The masks a worker drew or wrote for its previous layer, kept for a following layer
/// with the same section.
pub(super) struct PreviousLayerMasks {
    /// The layer's index.
    pub index: usize,
    /// Whether they were drawn from the section without collinear points (the layer was
    /// equal to the layer below).
    pub simplified: bool,
    /// The masks.
    pub masks: Arc<DrawnMasks>,
}

impl PreviousLayerMasks {
    /// The masks, if they serve layer `index`, equal (`same`) to the layer below and
    /// corrected with the moves `shifts`.
    pub fn serving(self, index: usize, same: bool, shifts: &[f64]) -> Option<Arc<DrawnMasks>> {
        (same
            && self.simplified
            && self.index + 1 == index
            && same_shifts(&self.masks.shifts, shifts))
        .then_some(self.masks)
    }
}

/// Entries of [`RecentPrismMasks`] at most (each holds one layer's PNG files and section).
pub(super) const RECENT_PRISM_MASKS: usize = 4;

/// The masks recently drawn from simplified sections (layers equal to the layer below),
/// shared by the workers: the first layer of a block, whose layer below another worker
/// drew, reuses them when its simplified section is the same, bit for bit (within a block
/// [`PreviousLayerMasks`] does this). Only for one projector without a distortion
/// correction (where drawing a layer counts nothing but what [`DrawnMasks`] replays); at
/// most [`RECENT_PRISM_MASKS`] entries, the oldest dropped.
#[derive(Default)]
pub(super) struct RecentPrismMasks(Mutex<Vec<(Vec<Contour>, Arc<DrawnMasks>)>>);

/// Whether two sections are the same, bit for bit (−0 ≠ +0, NaN = NaN).
fn same_bits(a: &[Contour], b: &[Contour]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            p.len() == q.len()
                && p.iter().zip(q).all(|(u, v)| {
                    u[0].to_bits() == v[0].to_bits() && u[1].to_bits() == v[1].to_bits()
                })
        })
}

/// Whether two corrections' moves are the same, bit for bit.
fn same_shifts(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

impl RecentPrismMasks {
    /// The masks drawn from `section` corrected with the moves `shifts`, if kept.
    pub fn get(&self, section: &[Contour], shifts: &[f64]) -> Option<Arc<DrawnMasks>> {
        let v = self.0.lock().ok()?;
        v.iter()
            .rev()
            .find(|(s, m)| same_bits(s, section) && same_shifts(&m.shifts, shifts))
            .map(|(_, m)| Arc::clone(m))
    }

    /// Keeps the masks drawn from `section` (unless that section, corrected alike, is
    /// kept already).
    pub fn put(&self, section: &[Contour], masks: &Arc<DrawnMasks>) {
        if let Ok(mut v) = self.0.lock() {
            if v.iter()
                .any(|(s, m)| same_bits(s, section) && same_shifts(&m.shifts, &masks.shifts))
            {
                return;
            }
            if v.len() >= RECENT_PRISM_MASKS {
                v.remove(0);
            }
            v.push((section.to_vec(), Arc::clone(masks)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn masks(tag: u8) -> Arc<DrawnMasks> {
        Arc::new(DrawnMasks {
            outside: vec![(tag % 2 == 1).then_some(tag as f64)],
            area_mm2: tag as f64,
            shifts: Vec::new(),
            field: None,
            dropped: Vec::new(),
            widened: None,
            field_runs: None,
            pngs: vec![(vec![tag; 3], format!("sha{tag}"), 0, Default::default())],
            runs: Default::default(),
        })
    }

    fn square(x: f64) -> Vec<Vec<[f64; 2]>> {
        vec![vec![[x, 0.0], [x + 1.0, 0.0], [x + 1.0, 1.0], [x, 1.0]]]
    }

    #[test]
    fn sections_compare_bit_for_bit() {
        assert!(same_bits(&square(1.0), &square(1.0)));
        assert!(!same_bits(&square(1.0), &square(1.0 + 1e-15)));
        // −0 and +0 are equal numbers but not the same section (their masks could differ
        // in principle; a hit must never change a byte).
        assert!(!same_bits(&square(0.0), &square(-0.0)));
        let nan = vec![vec![[f64::NAN, 0.0]]];
        assert!(same_bits(&nan, &nan));
        // Contour count and lengths.
        let mut two = square(1.0);
        two.push(vec![[5.0, 5.0]]);
        assert!(!same_bits(&square(1.0), &two));
        let mut short = square(1.0);
        short[0].pop();
        assert!(!same_bits(&square(1.0), &short));
        assert!(same_bits(&[], &[]));
    }

    #[test]
    fn finds_the_same_section_keeps_a_few_and_drops_the_oldest() {
        let cache = RecentPrismMasks::default();
        assert!(cache.get(&square(0.0), &[]).is_none());
        cache.put(&square(0.0), &masks(0));
        let got = cache.get(&square(0.0), &[]).expect("hit");
        assert_eq!((got.area_mm2, &got.outside[..]), (0.0, &[None][..]));
        assert!(cache.get(&square(0.5), &[]).is_none());
        // A second put of the same section keeps the first entry (same bytes anyway).
        cache.put(&square(0.0), &masks(9));
        assert_eq!(cache.get(&square(0.0), &[]).unwrap().area_mm2, 0.0);
        for k in 1..=RECENT_PRISM_MASKS as u8 {
            cache.put(&square(k as f64), &masks(k));
        }
        assert_eq!(cache.0.lock().unwrap().len(), RECENT_PRISM_MASKS);
        assert!(
            cache.get(&square(0.0), &[]).is_none(),
            "the oldest is dropped"
        );
        for k in 1..=RECENT_PRISM_MASKS as u8 {
            let m = cache.get(&square(k as f64), &[]).expect("kept");
            assert_eq!(m.pngs[0].0, vec![k; 3]);
            assert_eq!(m.outside[0].is_some(), k % 2 == 1);
        }
    }

    #[test]
    fn previous_layer_masks_serve_only_the_next_equal_layer() {
        let prev = |simplified| PreviousLayerMasks {
            index: 4,
            simplified,
            masks: masks(1),
        };
        assert!(prev(true).serving(5, true, &[]).is_some());
        assert!(
            prev(true).serving(5, false, &[]).is_none(),
            "unlike the layer below"
        );
        assert!(
            prev(true).serving(6, true, &[]).is_none(),
            "not the layer below"
        );
        assert!(
            prev(false).serving(5, true, &[]).is_none(),
            "drawn unsimplified"
        );
    }
}
