//! A job made again with more of it drawn as without the cure correction
//! ([`super::unheld`]) takes the blocks whose layers draw alike from the pass before: a
//! layer's masks depend on its section, the sections around it, and where the layers of
//! its own block up to it are drawn plain ([`super::uncorrected::Uncorrected`]: the
//! loose-piece step carries the layer below as drawn only within a block, whose first
//! layer starts without it). So a block none of whose layers changed how it is drawn
//! gets the same bytes: its files stay as the pass before wrote them, its layers'
//! records are that pass's, and what drawing them counted into the job's totals is
//! counted again. The slicer cuts only the sections the blocks drawn again look at, and
//! the slicing's repair counts are the pass before's (the Z correction looks at the
//! sections below, not at how they were drawn; a distortion correction's extrapolated
//! points are each layer's own warp's). Not for a job of several projectors: the field's
//! coverage it keeps for `--predict` is not carried from one pass to the next.

use super::cure_records::{CureJob, LayerDropped, LayerWidened};
use super::layer::{LayerContext, LayerInput, LayerOutput};
use super::mask_reuse::DrawnMasks;
use super::pipeline::{BLOCK, WINDOW};
use super::uncorrected::Uncorrected;
use crate::slice::SliceStats;
use std::ops::Range;

/// What drawing a layer counted into the job's totals, counted again when the layer is
/// taken from the pass before.
#[derive(Debug, Clone, Default)]
pub(super) struct LayerCounts {
    /// Per projector, the light compensation's reach outside the calibrated area
    /// ([`DrawnMasks::outside`]).
    outside: Vec<Option<f64>>,
    /// The flat features the Z correction dropped ([`DrawnMasks::dropped`]).
    dropped: Vec<(usize, LayerDropped)>,
    /// The narrow features drawn wider ([`DrawnMasks::widened`]).
    widened: Option<LayerWidened>,
    /// The distortion pre-warp's extrapolated points (each layer's own warp counts them).
    extrapolated: u64,
}

impl LayerCounts {
    /// What `drawn` counts, and the `extrapolated` points of the layer's pre-warp.
    pub fn of(drawn: &DrawnMasks, extrapolated: u64) -> LayerCounts {
        LayerCounts {
            outside: drawn.outside.clone(),
            dropped: drawn.dropped.clone(),
            widened: drawn.widened,
            extrapolated,
        }
    }

    /// Counts layer `i` into the job's totals; the compensation's only unless `drawn` (it
    /// counted the layer as it drew it).
    pub fn count(&self, ctx: &LayerContext, i: usize, drawn: bool) {
        for (k, beyond) in self.outside.iter().enumerate().filter(|_| !drawn) {
            match (beyond, ctx.tiler, ctx.optics) {
                (Some(b), Some(t), _) => t.count_outside(k, *b),
                (Some(b), None, Some(o)) => o.compensator.count_outside(*b),
                _ => {}
            }
        }
        if let Some(job) = ctx.cure {
            job.count_dropped(i, &self.dropped);
            job.count_widened(i, self.widened);
        }
    }
}

// The pipeline's blocks start at multiples of BLOCK (windows of WINDOW layers split into
// blocks), as `Again::wanted` walks them.
const _: () = assert!(WINDOW.is_multiple_of(BLOCK));

/// The pass before: where it drew layers plain, each layer's record as its pipeline made
/// it (before the planning), and the slicing's repair counts.
pub(super) struct Again {
    plain: Uncorrected,
    layers: Vec<LayerOutput>,
    stats: SliceStats,
}

impl Again {
    /// The pass that drew `plain` plain and made `layers`, slicing with `stats`.
    pub fn new(plain: Uncorrected, (layers, stats): (Vec<LayerOutput>, SliceStats)) -> Again {
        Again {
            plain,
            layers,
            stats,
        }
    }

    /// The slicing's repair counts over every layer (the pass before's: the sections do
    /// not change).
    pub fn stats(&self) -> SliceStats {
        self.stats
    }

    /// The layers whose sections the blocks that `cure` draws otherwise look at: their
    /// own, the [`WINDOW`] below (the layer below, the rests of narrow features, the Z
    /// correction's) and the correction's layers above.
    pub fn wanted(&self, cure: Option<&CureJob>) -> Vec<bool> {
        let n = self.layers.len();
        let above = cure.map_or(0, CureJob::upper_layers);
        let mut wanted = vec![false; n];
        for b in (0..n).step_by(BLOCK) {
            let end = (b + BLOCK).min(n);
            if !self.serves(cure, b..end) {
                let from = b.saturating_sub(WINDOW);
                wanted[from..(end + above).min(n)].fill(true);
            }
        }
        wanted
    }

    /// Whether the block of `layers` is drawn by `cure` as the pass before drew it.
    pub fn serves(&self, cure: Option<&CureJob>, layers: Range<usize>) -> bool {
        let now = cure.map(CureJob::plain);
        layers
            .into_iter()
            .all(|i| i < self.layers.len() && now.is_some_and(|p| p.same_at(&self.plain, i)))
    }

    /// Layer `layer` as the pass before made it: its files are in place; the coverage it
    /// would have looked at is let go, and its counts are counted again.
    pub fn layer(&self, ctx: &LayerContext, layer: &LayerInput) -> LayerOutput {
        let i = layer.index;
        if ctx.cure.is_some_and(|c| c.corrects_at(i)) {
            let _ = layer.cut.take_own();
            layer.upper.iter().for_each(|c| c.release());
        }
        let kept = &self.layers[i];
        kept.counts.count(ctx, i, false);
        if let Some(w) = ctx.correction {
            w.count_extrapolated(kept.counts.extrapolated);
        }
        LayerOutput {
            analysis_s: 0.0,
            ..kept.clone()
        }
    }
}

/// Whether a pass of the job may be made again from the one before ([`Again`]): with
/// supports (only their jobs are made again), the cure correction and one projector.
pub(super) fn may_make_again(supports: bool, cure: Option<&CureJob>, tiled: bool) -> bool {
    let possible = cure.is_some_and(|c| c.corrects());
    supports && possible && !tiled && !from_scratch()
}

/// Whether every pass is made whole (the tests' reference for what taking blocks from the
/// pass before must not change).
#[cfg(test)]
fn from_scratch() -> bool {
    tests::FROM_SCRATCH.load(std::sync::atomic::Ordering::Relaxed)
}

#[cfg(not(test))]
fn from_scratch() -> bool {
    false
}

#[cfg(test)]
mod tests {
    use crate::job::{slice_to_bundle, SliceOptions, Transform};
    use crate::profile::Profile;
    use std::sync::atomic::{AtomicBool, Ordering};

    pub(super) static FROM_SCRATCH: AtomicBool = AtomicBool::new(false);
    /// One test at a time sets [`FROM_SCRATCH`] (test threads share it).
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

    /// Slices bunny00 with supports, turned by `rotate_deg`, with `args` set on the
    /// options, once taking blocks from the pass before and once making every pass whole;
    /// both jobs must be made again (`cure.layers-uncorrected`), warn `codes` too, and
    /// their files be the same.
    fn made_again_and_whole(
        tag: &str,
        rotate_deg: [f64; 3],
        codes: &[&str],
        args: impl Fn(&mut SliceOptions),
    ) {
        let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
        let dir = crate::test_support::scratch("again", tag);
        let bunny = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/bunny00.stl");
        let mut profile = Profile::default_profile();
        profile.supports.enabled = true;
        let job = |name: &str| {
            let mut o = SliceOptions::new(bunny, dir.join(name), profile.clone());
            o.transform = Transform {
                rotate_deg,
                ..Transform::default()
            };
            args(&mut o);
            let s = slice_to_bundle(&o).unwrap();
            let warned: Vec<_> = s.warnings.iter().map(|w| w.code.as_str()).collect();
            for code in codes.iter().chain(&["cure.layers-uncorrected"]) {
                assert!(warned.contains(code), "{tag}: {warned:?}");
            }
            std::fs::read(dir.join(name)).unwrap()
        };
        let again = job("again.dmdjob.zip");
        FROM_SCRATCH.store(true, Ordering::Relaxed);
        let whole = job("whole.dmdjob.zip");
        FROM_SCRATCH.store(false, Ordering::Relaxed);
        assert!(again == whole, "{tag}: the two jobs differ");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_job_made_again_from_the_pass_before_is_the_job_made_whole() {
        // The first pass leaves a region on nothing; the second draws a window of one
        // layer plain (tests/it/supports.rs).
        made_again_and_whole("xy", [60.0, 0.0, 20.0], &[], |o| o.binary = Some(true));
    }

    #[test]
    fn with_the_z_correction_too() {
        // At half size: five layers drawn whole in each of two places.
        made_again_and_whole("xyz", [0.0, 45.0, 0.0], &[], |o| {
            o.transform.scale = [0.5; 3];
            o.cure.correction = Some(crate::cure::Correction::Xyz)
        });
    }

    #[test]
    fn with_a_distortion_correction_too() {
        // A table measured over the field's right half only: the points of the part's
        // left half are warped by extrapolation, and the blocks taken from the pass
        // before count theirs again.
        let dir = crate::test_support::scratch("again", "table");
        let table = dir.join("half.csv");
        let mut t = String::from("x_mm,y_mm,seen_x_mm,seen_y_mm\n");
        for j in 0..9 {
            for i in 0..7 {
                let (x, y) = (30.0 + 5.0 * i as f64, 5.0 + 5.0 * j as f64);
                let seen = [x + 0.002 * i as f64, y + 0.001 * j as f64];
                t.push_str(&format!("{x},{y},{},{}\n", seen[0], seen[1]));
            }
        }
        std::fs::write(&table, t).unwrap();
        made_again_and_whole(
            "warped",
            [0.0, 45.0, 0.0],
            &["distortion.extrapolated"],
            |o| {
                o.transform.scale = [0.5; 3];
                o.cure.correction = Some(crate::cure::Correction::Xyz);
                o.distortion = crate::geometry::distortion::DistortionChoice::Table(table.clone());
            },
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
