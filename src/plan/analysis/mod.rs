//! Per-layer analysis (docs/PLANNING.md): from the exact section contours, the max fill
//! distance (DisMax-Min of Li et al.: a true inscribed radius within [`PRECISION_MM`] of
//! the largest, [`max_fill_distance_with`]) and the bounding box of the points (mm,
//! `[[x_min, y_min], [x_max, y_max]]`); from the pixels the mask lights
//! ([`crate::raster::LitRuns`]), the islands resting on nothing in the layer below
//! (`islands.rs`; layer 0 rests on the platform).
//!
//! A layer whose section equals the layer below's once collinear points are left out (a
//! prism, `COLLINEAR_MM`) takes the layer below's analysis with no islands
//! ([`Analyser`]). Overlapping shells are not merged: an edge of one inside another counts
//! as boundary, so the max fill distance is then a lower bound.

// A `bench-no-analysis` build skips the search (and the rasterizer keeps no lit runs):
// their state goes unused.
#![cfg_attr(feature = "bench-no-analysis", allow(dead_code))]

pub use crate::raster::LitRuns;
use crate::slice::Contour;

mod collinear;
mod fill_distance;
mod islands;

use collinear::simplify_section;
use fill_distance::{fill_distance, SearchScratch};
#[cfg(any(test, feature = "internals"))]
pub use fill_distance::{max_fill_distance, max_fill_distance_with, Edges, COARSE_MM};
#[cfg(any(test, feature = "internals"))]
pub use islands::islands;
pub use islands::{islands_found, Island, Islands};

/// Guaranteed accuracy of [`max_fill_distance`], mm: the result lies in
/// `[exact − PRECISION_MM, exact]`.
pub const PRECISION_MM: f64 = 0.02;

/// What the planner learns from one layer's section.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LayerAnalysis {
    /// Largest distance from a point of the section to its boundary, mm.
    pub max_fill_distance_mm: f64,
    /// Regions of the section that do not rest on the layer below.
    pub islands: u32,
    /// The largest of them.
    pub island: Option<Island>,
    /// Bounding box of the section, mm; `None` for an empty section.
    pub bbox_mm: Option<[[f64; 2]; 2]>,
}

/// Analyses one layer: `cur` its contours and `lit` its mask's lit pixels, `prev` the
/// contours and lit pixels of the layer below (`None` for layer 0, which rests on the
/// platform).
#[cfg(any(test, feature = "internals"))]
pub fn analyse(
    cur: &[Contour],
    lit: &LitRuns,
    prev: Option<(&[Contour], &LitRuns)>,
) -> LayerAnalysis {
    Analyser::new().analyse(usize::MAX, cur, lit, prev)
}

impl LayerAnalysis {
    /// This analysis with the islands `f`.
    fn with(self, f: Islands) -> LayerAnalysis {
        LayerAnalysis {
            islands: f.count,
            island: f.largest,
            ..self
        }
    }
}

/// What [`Analyser::analyse_or_defer`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Analysed {
    /// The layer's analysis.
    Done(LayerAnalysis),
    /// The layer's section equals the layer below's (collinear points left out, see
    /// `COLLINEAR_MM`), whose analysis this analyser does not have: the layer's analysis
    /// is that one with no islands (every region rests on itself). See
    /// [`Analysed::resolve`].
    SameAsBelow,
    /// The layer's analysis but for its islands (0 here), which need the lit pixels of the
    /// layer below, which this analyser did not see: see [`Analysed::with_islands`].
    NeedsBelow(LayerAnalysis),
}

impl Analysed {
    /// A [`Analysed::NeedsBelow`] result completed: `islands(lit, below)` with `lit` the
    /// layer's lit pixels and `below` those of the layer below
    /// ([`islands`](fn@islands)). Other results are returned as they are, without calling
    /// it.
    pub fn with_islands(self, islands: impl FnOnce() -> Islands) -> Analysed {
        match self {
            Analysed::NeedsBelow(a) => Analysed::Done(a.with(islands())),
            r => r,
        }
    }

    /// The layer's analysis, given the (resolved) analysis of the layer below.
    ///
    /// # Panics
    /// If the result is [`Analysed::SameAsBelow`] and `below` is `None` (layer 0 is never
    /// the same as a layer below), or if it is [`Analysed::NeedsBelow`] (complete it with
    /// [`Analysed::with_islands`] first).
    pub fn resolve(self, below: Option<&LayerAnalysis>) -> LayerAnalysis {
        match self {
            Analysed::Done(a) => a,
            Analysed::NeedsBelow(_) => panic!("islands over the layer below not counted"),
            Analysed::SameAsBelow => below
                .expect("a layer equal to the layer below has one")
                .with(Islands::default()),
        }
    }
}

/// The last layer an [`Analyser`] saw.
#[derive(Debug, Clone, Copy)]
struct LastLayer {
    index: usize,
    /// Its analysis; `None` when it was deferred as [`Analysed::SameAsBelow`].
    analysis: Option<LayerAnalysis>,
    /// Its bounding box.
    bbox: Option<[[f64; 2]; 2]>,
    /// Whether `Analyser::last_runs` holds its lit pixels.
    runs: bool,
    /// Whether `Analyser::last_section` holds its section without collinear points.
    section: bool,
}

/// What [`Analyser::equals_below`] found for a layer.
#[derive(Debug, Clone, Copy)]
struct BelowComparison {
    index: usize,
    bbox: Option<[[f64; 2]; 2]>,
    /// Whether `Analyser::section` holds its section without collinear points.
    simplified: bool,
    same: bool,
}

/// Analyses consecutive layers; a worker keeps one for its block of layers. A layer's
/// analysis is the layer below's, with no islands, when the two sections are equal
/// without their collinear points; otherwise that of its own contours (the fill distance
/// and bounding box of `cur`, the islands of its lit pixels over those below). It never
/// depends on the order of the calls or on where blocks start.
#[derive(Debug, Default)]
pub struct Analyser {
    last: Option<LastLayer>,
    /// The comparison of the layer being analysed with the layer below, once made.
    compared: Option<BelowComparison>,
    /// The last layer's section without collinear points (when `LastLayer::section`).
    last_section: Vec<Contour>,
    last_runs: LitRuns,
    /// Buffers reused from layer to layer (results never depend on them).
    section: Vec<Contour>,
    search: SearchScratch,
}

impl Analyser {
    /// A new analyser.
    #[cfg(any(test, feature = "internals"))]
    pub fn new() -> Analyser {
        Analyser::default()
    }

    /// Analyses layer `index` (contours `cur`, its mask's lit pixels `lit`) over the layer
    /// below (`prev`: the contours and lit pixels of layer `index − 1`, `None` for layer
    /// 0). A layer equal to the layer below whose analysis this analyser does not have is
    /// analysed from its own contours, with no islands.
    #[cfg(any(test, feature = "internals"))]
    pub fn analyse(
        &mut self,
        index: usize,
        cur: &[Contour],
        lit: &LitRuns,
        prev: Option<(&[Contour], &LitRuns)>,
    ) -> LayerAnalysis {
        match self.analyse_or_defer(index, cur, Some(lit), prev.map(|p| p.0)) {
            Analysed::Done(a) => a,
            Analysed::NeedsBelow(a) => {
                a.with(prev.map_or(Islands::default(), |p| islands_found(lit, p.1)))
            }
            Analysed::SameAsBelow => {
                let a = LayerAnalysis {
                    max_fill_distance_mm: fill_distance(cur, &mut self.search).0,
                    bbox_mm: bbox(cur),
                    ..Default::default()
                };
                if let Some(l) = self.last.as_mut() {
                    l.analysis = Some(a);
                }
                a
            }
        }
    }

    /// Whether layer `index`'s section (`cur`) equals the layer below's (`prev`) once
    /// collinear points are left out (see `COLLINEAR_MM`); then
    /// [`Analyser::simplified_section`] is that section. The answer is kept for the
    /// following [`Analyser::analyse_or_defer`] of the same layer.
    pub fn equals_below(
        &mut self,
        index: usize,
        cur: &[Contour],
        prev: Option<&[Contour]>,
    ) -> bool {
        if let Some(c) = self
            .compared
            .filter(|c| c.index == index && index != usize::MAX)
        {
            return c.same;
        }
        let bb = bbox(cur);
        // This analyser's last layer is the layer below: what it kept of it serves.
        let below = self
            .last
            .filter(|l| index != usize::MAX && l.index.wrapping_add(1) == index);
        let mut c = BelowComparison {
            index,
            bbox: bb,
            simplified: false,
            same: false,
        };
        // Equal sections have equal bounding boxes: only then are they compared (a box
        // is cheap, leaving out collinear points is not).
        if let (Some(p), Some(_)) = (prev, bb) {
            let below_bb = match below {
                Some(l) => l.bbox,
                None => bbox(p),
            };
            if below_bb == bb {
                simplify_section(cur, &mut self.section);
                if !below.is_some_and(|l| l.section) {
                    simplify_section(p, &mut self.last_section);
                    // `last_section` now holds the layer below's section: the last
                    // layer's only if that is the layer below.
                    let follows = below.is_some();
                    if let Some(l) = self.last.as_mut() {
                        l.section = follows;
                    }
                }
                c.simplified = true;
                c.same = self.section == self.last_section;
            }
        }
        self.compared = Some(c);
        c.same
    }

    /// The section of the layer [`Analyser::equals_below`] last found equal to the layer
    /// below, collinear points left out.
    pub fn simplified_section(&self) -> &[Contour] {
        &self.section
    }

    /// [`Analyser::analyse`], except that a layer whose section equals the layer below's
    /// is not analysed again: its result is copied when this analyser has the layer
    /// below's, otherwise it is [`Analysed::SameAsBelow`] (the caller resolves it from the
    /// layer below); and that islands over a layer below this analyser did not see are
    /// left to the caller ([`Analysed::NeedsBelow`]). `lit`: the layer's lit pixels, or
    /// `None` when its mask is the layer below's (then the section must be equal to it).
    pub fn analyse_or_defer(
        &mut self,
        index: usize,
        cur: &[Contour],
        lit: Option<&LitRuns>,
        prev: Option<&[Contour]>,
    ) -> Analysed {
        self.equals_below(index, cur, prev);
        let c = self.compared.take().expect("just compared");
        let bb = c.bbox;
        let last = self.last.take();
        let below = last.filter(|l| index != usize::MAX && l.index.wrapping_add(1) == index);
        let keep = index != usize::MAX;
        let simplified = c.simplified;
        if c.same {
            let copied = below
                .and_then(|l| l.analysis)
                .map(|a| a.with(Islands::default()));
            // The lit pixels kept: this layer's, or the layer below's when its mask is
            // that one.
            let runs = match lit {
                Some(l) => {
                    self.last_runs.clone_from(l);
                    true
                }
                None => below.is_some_and(|l| l.runs),
            };
            self.last = keep.then_some(LastLayer {
                index,
                analysis: copied,
                bbox: bb,
                runs,
                section: true,
            });
            return copied.map_or(Analysed::SameAsBelow, Analysed::Done);
        }
        let lit = lit.expect("a layer unlike the layer below has its own mask");
        let islands = match prev {
            None => Some(Islands::default()),
            Some(_) => below
                .filter(|l| l.runs)
                .map(|_| islands_found(lit, &self.last_runs)),
        };
        let fill = self.fill(cur);
        let a = LayerAnalysis {
            max_fill_distance_mm: fill,
            bbox_mm: bb,
            ..Default::default()
        }
        .with(islands.unwrap_or_default());
        self.last_runs.clone_from(lit);
        if simplified {
            std::mem::swap(&mut self.section, &mut self.last_section);
        }
        self.last = keep.then_some(LastLayer {
            index,
            analysis: Some(a),
            bbox: bb,
            runs: true,
            section: simplified,
        });
        match islands {
            Some(_) => Analysed::Done(a),
            None => Analysed::NeedsBelow(a),
        }
    }

    /// The lit pixels of the last layer analysed, when this analyser has them.
    pub fn last_runs(&self) -> Option<&LitRuns> {
        self.last.filter(|l| l.runs).map(|_| &self.last_runs)
    }

    /// The max fill distance of `cur`.
    #[cfg(not(feature = "bench-no-analysis"))]
    fn fill(&mut self, cur: &[Contour]) -> f64 {
        fill_distance(cur, &mut self.search).0
    }

    /// Benchmark builds that measure what the analysis adds to slicing (Cargo feature
    /// `bench-no-analysis`, never for real jobs): no search (the islands count is
    /// skipped too: the slicer does not record lit pixels); the comparison with the layer
    /// below (which the masks of prisms use too) stays.
    #[cfg(feature = "bench-no-analysis")]
    fn fill(&mut self, _: &[Contour]) -> f64 {
        0.0
    }
}

/// Bounding box of all contour points, or `None` if there are none.
pub fn bbox(contours: &[Contour]) -> Option<[[f64; 2]; 2]> {
    let mut it = contours.iter().flatten();
    let first = *it.next()?;
    let mut b = [first, first];
    // Plain comparisons (`f64::min` also orders NaNs, which contours do not have).
    for p in it {
        for k in 0..2 {
            if p[k] < b[0][k] {
                b[0][k] = p[k];
            }
            if p[k] > b[1][k] {
                b[1][k] = p[k];
            }
        }
    }
    Some(b)
}

#[cfg(test)]
mod test_support;

#[cfg(test)]
mod tests {
    use super::test_support::*;
    use super::*;

    #[test]
    fn analyser_reuses_the_layer_below_without_changing_results() {
        let layers = [
            vec![rect(0.0, 0.0, 10.0, 10.0)],
            vec![rect(5.0, 5.0, 8.0, 8.0), rect(20.0, 0.0, 25.0, 5.0)],
            vec![rect(20.0, 0.0, 25.0, 5.0), rect(30.0, 0.0, 31.0, 1.0)],
        ];
        let lits: Vec<LitRuns> = layers.iter().map(|l| lit(l)).collect();
        let below = |i: usize| i.checked_sub(1).map(|j| (layers[j].as_slice(), &lits[j]));
        let mut a = Analyser::new();
        let seq: Vec<u32> = (0..3)
            .map(|i| a.analyse(i, &layers[i], &lits[i], below(i)).islands)
            .collect();
        assert_eq!(seq, vec![0, 1, 1]);
        // Out of order (the layer below's lit pixels given) gives the same.
        assert_eq!(analyse(&layers[2], &lits[2], below(2)).islands, 1);
        assert_eq!(a.analyse(1, &layers[1], &lits[1], below(1)).islands, 1);
        // Without the layer below's: the islands are left to the caller.
        let mut b = Analyser::new();
        let r = b.analyse_or_defer(2, &layers[2], Some(&lits[2]), Some(&layers[1]));
        assert!(matches!(r, Analysed::NeedsBelow(_)));
        assert_eq!(
            r.with_islands(|| islands_found(&lits[2], &lits[1]))
                .resolve(None)
                .islands,
            1
        );
    }

    #[test]
    fn analyse_fills_all_fields() {
        let sq = [rect(1.0, 2.0, 11.0, 12.0)];
        let a = analyse(&sq, &lit(&sq), None);
        assert!((a.max_fill_distance_mm - 5.0).abs() <= 0.005);
        assert_eq!(a.islands, 0);
        assert_eq!(a.bbox_mm, Some([[1.0, 2.0], [11.0, 12.0]]));
        assert_eq!(analyse(&[], &LitRuns::default(), None).bbox_mm, None);
    }

    #[test]
    fn analyser_buffers_never_change_results() {
        // Random layers of scattered rectangles, analysed in and out of order by one analyser (every reuse and recycling path),
        // must give what a fresh analysis gives.
        let mut rnd = xorshift(0x5eed_1a7e_u64);
        let layers: Vec<Vec<Contour>> = (0..12).map(|_| scattered(&mut rnd, 6.0, 6.0)).collect();
        let lits: Vec<LitRuns> = layers.iter().map(|l| lit(l)).collect();
        let below = |i: usize| i.checked_sub(1).map(|j| (layers[j].as_slice(), &lits[j]));
        let fresh = |i: usize| analyse(&layers[i], &lits[i], below(i));
        let mut a = Analyser::new();
        let order: [usize; 16] = [0, 1, 2, 3, 5, 6, 4, 5, 11, 10, 11, 7, 8, 9, 1, 2];
        let mut islands = 0;
        for &i in &order {
            let got = a.analyse(i, &layers[i], &lits[i], below(i));
            assert_eq!(got, fresh(i), "layer {i}");
            islands += got.islands;
        }
        // The layers do have islands (the test exercises the supported/unsupported logic).
        assert!(islands > 0);
    }

    #[test]
    fn prism_layers_are_analysed_once_with_the_same_results() {
        // A prism cut at random heights: the same polygons with different collinear
        // points; some layers differ (a hole comes and goes). Analysed in blocks (deferred
        // at block starts, resolved afterwards) and out of order, the results must be what
        // a fresh analysis gives for every layer.
        let mut rnd = xorshift(0x9e15_3a11);
        let outer = ngon(25.0, 20.0, 12.0, 24, true);
        let inner = hole(20.0, 15.0, 24.0, 19.0);
        let layers: Vec<Vec<Contour>> = (0..23)
            .map(|i| {
                let mut l = vec![with_collinear_points(&outer, i % 5, &mut rnd)];
                if (8..15).contains(&i) {
                    l.push(with_collinear_points(&inner, i % 3, &mut rnd));
                }
                l
            })
            .collect();
        let lits: Vec<LitRuns> = layers.iter().map(|l| lit(l)).collect();
        let below2 = |i: usize| i.checked_sub(1).map(|j| (layers[j].as_slice(), &lits[j]));
        // Reference: one analyser over all layers in order.
        let mut seq = Analyser::new();
        let fresh: Vec<LayerAnalysis> = (0..layers.len())
            .map(|i| seq.analyse(i, &layers[i], &lits[i], below2(i)))
            .collect();
        for block in [1, 2, 4, 7] {
            let mut out: Vec<Analysed> = Vec::new();
            let mut deferred = 0;
            for b in 0..layers.len().div_ceil(block) {
                let mut a = Analyser::new();
                for i in b * block..((b + 1) * block).min(layers.len()) {
                    let below = i.checked_sub(1).map(|j| layers[j].as_slice());
                    // Asking first (as the slicer does, for the masks) changes nothing.
                    if block != 4 {
                        let hole = |i: usize| (8..15).contains(&i);
                        let want = i > 0 && hole(i) == hole(i - 1);
                        assert_eq!(a.equals_below(i, &layers[i], below), want, "layer {i}");
                        if want {
                            let mut s = Vec::new();
                            simplify_section(&layers[i - 1], &mut s);
                            assert_eq!(a.simplified_section(), s.as_slice());
                        }
                    }
                    let r = a.analyse_or_defer(i, &layers[i], Some(&lits[i]), below);
                    deferred += usize::from(r == Analysed::SameAsBelow);
                    out.push(r.with_islands(|| islands_found(&lits[i], &lits[i - 1])));
                }
            }
            let mut got: Vec<LayerAnalysis> = Vec::new();
            for r in out {
                let v = r.resolve(got.last());
                got.push(v);
            }
            assert_eq!(got, fresh, "blocks of {block}");
            // 20 layers equal the one below: deferred when their worker has no result to
            // copy (a block's first layer, and those after it while they stay equal).
            assert!(deferred <= 20, "blocks of {block}");
            if block == 1 {
                assert_eq!(deferred, 20);
            }
        }
        // The hole is an island-free change: fill distances differ with and without it.
        assert!(fresh[10].max_fill_distance_mm < fresh[5].max_fill_distance_mm - 1.0);
        // Out of order: the plain `analyse` never defers. A layer equal to the layer below
        // that it has not analysed is analysed from its own contours (the same polygon
        // with other collinear points: the search may take another path and stop at
        // another circle, both within the guarantee), so its fill distance agrees within
        // PRECISION_MM, not bit for bit (measured: up to 1.4e-4 mm here).
        let mut a = Analyser::new();
        for &i in &[3usize, 4, 4, 10, 9, 20, 21, 0, 1] {
            let got = a.analyse(i, &layers[i], &lits[i], below2(i));
            assert_eq!(
                (got.islands, got.bbox_mm),
                (fresh[i].islands, fresh[i].bbox_mm),
                "layer {i}"
            );
            let d = (got.max_fill_distance_mm - fresh[i].max_fill_distance_mm).abs();
            assert!(d <= PRECISION_MM, "layer {i}: {got:?} vs {:?}", fresh[i]);
        }
    }
}
