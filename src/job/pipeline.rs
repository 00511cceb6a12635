//! The pipeline driver: windows of sections → blocks of layers → each layer's work.
//!
//! One slicing task cuts windows of [`WINDOW`] layers and spawns each window's layers as
//! blocks of [`BLOCK`] consecutive layers on rayon's pool as soon as they are cut (no
//! barrier between windows), so the slicing overlaps the mask work. Blocks start in the
//! order they were spawned (a FIFO scope): the layers below a section are made soon after
//! it is drawn, and its coverage is dropped (newest first, the blocks of later windows
//! would run while earlier ones wait, and every section whose lower layers wait keeps its
//! coverage). Before it cuts a window, the layers sliced but not yet made into masks must
//! be at most [`MAX_AHEAD`]; otherwise the task parks its state (the slicer, the last
//! window) in the [`Backlog`] and returns, and its worker thread goes on with the queued
//! blocks. The block whose end
//! brings the count back under the limit spawns the slicing task again. So memory is
//! bounded whatever the number of layers, no thread spins or sleeps, and no worker blocks
//! waiting for room: the slicer must run on the pool, since it cuts its windows with the
//! pool's other workers (a slicer blocked on a bounded channel would hold a worker idle
//! and deadlock a pool of one thread).
//!
//! An error at a layer stops the layers above it: each block before its next layer above
//! the failed one, the slicing once no block below that layer waits for its next window.
//! The layers below are still made, and a lower layer's error replaces a higher one's: the
//! error reported is the lowest failing layer's, whichever worker failed first (Ctrl-C,
//! `cancel`, stops everything). Each layer's result goes to its own slot, so the output
//! never depends on which worker made it or when.

use super::layer::{layer_masks, BlockWorker, LayerContext, LayerInput, LayerOutput};
use crate::cure::shift::Coverage;
use crate::error::{Error, Result};
use crate::raster::{Drawn, ScratchPool};
use crate::slice::{Section, SliceStats, Slicer};
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::Instant;

/// Layers sliced at a time: memory depends on this, not on the number of layers.
pub(super) const WINDOW: usize = 32;
/// Consecutive layers one worker processes in order. Its first layer's analysis scans the
/// layer below again (islands) and cannot copy the analysis of an equal layer below
/// (prisms): larger blocks do that less often, smaller ones balance the workers better at
/// the end (docs/PLANNING.md has the measurement behind 8).
pub const BLOCK: usize = 8;
/// Layers sliced but not yet made into masks before the slicer waits (bounds memory: at
/// most this plus one window are held).
const MAX_AHEAD: usize = 3 * WINDOW;

/// A layer's section as the slicer cut it, and its coverage while the cure correction of
/// the layers below it or the layer itself still looks at it: drawn by whichever needs it
/// first (a layer below, or the layer itself when it draws this very section), dropped
/// when the last of them is done. So each section is drawn about once, and only the
/// coverage of the layers in work is kept.
pub(super) struct Cut {
    /// The section.
    pub section: Section,
    /// Its coverage (pre-warped with a distortion correction), and how many layers (those
    /// below and the layer itself) will still look at it.
    coverage: Mutex<(Option<Arc<CutCoverage>>, usize)>,
}

/// A section's coverage as the cure correction reads it, and what the rasterizer's
/// scratch knew of the mask it came from (the layer itself draws its mask from them).
pub(super) type CutCoverage = (Coverage, Drawn);

impl Cut {
    fn new(section: Section, users: usize) -> Cut {
        Cut {
            section,
            coverage: Mutex::new((None, users)),
        }
    }

    /// The coverage, made by `make` unless a layer made it already.
    pub fn coverage(&self, make: impl FnOnce() -> Result<CutCoverage>) -> Result<Arc<CutCoverage>> {
        let mut g = lock(&self.coverage);
        if let Some(c) = &g.0 {
            return Ok(Arc::clone(c));
        }
        let c = Arc::new(make()?);
        if g.1 > 1 {
            g.0 = Some(Arc::clone(&c));
        }
        Ok(c)
    }

    /// The layer itself is done looking for its coverage: the coverage, if a layer below
    /// drew it.
    pub fn take_own(&self) -> Option<Arc<CutCoverage>> {
        let mut g = lock(&self.coverage);
        g.1 = g.1.saturating_sub(1);
        if g.1 == 0 {
            g.0.take()
        } else {
            g.0.clone()
        }
    }

    /// Offers the coverage the layer made of its own section, while a layer below will
    /// still look at it.
    pub fn offer(&self, c: &Arc<CutCoverage>) {
        let mut g = lock(&self.coverage);
        if g.0.is_none() && g.1 > 0 {
            g.0 = Some(Arc::clone(c));
        }
    }

    /// A layer below is done looking at it.
    pub fn release(&self) {
        let mut g = lock(&self.coverage);
        g.1 = g.1.saturating_sub(1);
        if g.1 == 0 {
            g.0 = None;
        }
    }
}

/// How the caller follows and stops a job.
pub(super) struct Control<'a> {
    /// Called with (layers done, layers total) as layers are written.
    pub progress: Option<&'a (dyn Fn(usize, usize) + Sync)>,
    /// Set to abort (Ctrl-C).
    pub cancel: Option<&'a AtomicBool>,
}

impl Control<'_> {
    /// Whether the caller asked to stop.
    pub fn cancelled(&self) -> bool {
        self.cancel.is_some_and(|c| c.load(Ordering::Relaxed))
    }
}

/// What the pipeline made of every layer.
pub(super) struct PipelineOutput {
    /// Each layer's output, in layer order.
    pub layers: Vec<LayerOutput>,
    /// The slicer's repair counts.
    pub stats: SliceStats,
    /// Time the slicing task spent cutting, s.
    pub slice_s: f64,
    /// Wall time of the whole pipeline, s.
    pub masks_s: f64,
}

/// Slices every layer with `slicer` and makes its masks with `ctx`, running `beside` on
/// the pool at the same time (work that depends on the set-up only).
pub(super) fn run<'a>(
    ctx: &'a LayerContext<'a>,
    slicer: Slicer<'a>,
    layers: usize,
    control: &'a Control<'a>,
    beside: impl FnOnce() + Send,
) -> Result<PipelineOutput> {
    let start = Instant::now();
    let p = Pipeline {
        ctx,
        control,
        layers,
        slots: (0..layers).map(|_| OnceLock::new()).collect(),
        scratch: ScratchPool::default(),
        backlog: Backlog::default(),
        stop_at: AtomicUsize::new(usize::MAX),
        failure: Mutex::new(None),
        done: AtomicUsize::new(0),
    };
    let cursor = Cursor {
        slicer,
        next: 0,
        prev: None,
        waiting: Vec::new(),
        slice_s: 0.0,
    };
    rayon::scope_fifo(|scope| {
        scope.spawn_fifo(|_| beside());
        feed(scope, &p, cursor);
    });
    let masks_s = start.elapsed().as_secs_f64();
    p.finish(masks_s)
}

/// What the slicing task and the blocks share.
struct Pipeline<'a> {
    ctx: &'a LayerContext<'a>,
    control: &'a Control<'a>,
    layers: usize,
    /// One slot per layer, filled by whichever worker makes it.
    slots: Vec<OnceLock<LayerOutput>>,
    scratch: ScratchPool,
    backlog: Backlog<'a>,
    /// The lowest layer that failed (`usize::MAX` while none did): the layers from there
    /// up are not made.
    stop_at: AtomicUsize,
    /// The lowest failed layer and its error.
    failure: Mutex<Option<(usize, Error)>>,
    /// Layers done, for the progress report.
    done: AtomicUsize,
}

impl Pipeline<'_> {
    /// Whether layer `index` is not to be made: a layer at or below it failed, or the
    /// caller asked to stop.
    fn stopped_at(&self, index: usize) -> bool {
        index >= self.stop_at.load(Ordering::Relaxed) || self.control.cancelled()
    }

    /// Layer `index` failed with `e`: stops the layers above it, keeping the lowest
    /// layer's error.
    fn fail(&self, index: usize, e: Error) {
        self.stop_at.fetch_min(index, Ordering::Relaxed);
        let mut f = lock(&self.failure);
        if f.as_ref().is_none_or(|(old, _)| index < *old) {
            *f = Some((index, e));
        }
    }

    /// Every layer's output once the pool is done, or the lowest failing layer's error.
    fn finish(self, masks_s: f64) -> Result<PipelineOutput> {
        if let Some((_, e)) = self.failure.into_inner().unwrap_or_else(|p| p.into_inner()) {
            return Err(e);
        }
        if self.control.cancelled() {
            return Err(Error::Interrupted);
        }
        let cursor = self.backlog.into_finished();
        Ok(PipelineOutput {
            layers: self
                .slots
                .into_iter()
                .map(|s| s.into_inner().expect("every layer is made"))
                .collect(),
            stats: cursor.slicer.stats,
            slice_s: cursor.slice_s,
            masks_s,
        })
    }
}

/// The slicing task's state from one window to the next.
struct Cursor<'a> {
    slicer: Slicer<'a>,
    /// First layer of the next window.
    next: usize,
    /// The last window cut (its last section is the layer below the next window's first).
    prev: Option<Arc<Vec<Cut>>>,
    /// The last window's blocks whose layers look at sections of the next window (the cure
    /// correction's layers above), spawned once it is cut.
    waiting: Vec<Block>,
    /// Time spent cutting, s.
    slice_s: f64,
}

impl Cursor<'_> {
    /// Cuts the next window.
    fn cut(&mut self, ahead: usize) -> Arc<Vec<Cut>> {
        let t = Instant::now();
        let sections = self.slicer.window(self.next..self.next + WINDOW);
        self.slice_s += t.elapsed().as_secs_f64();
        let start = self.next;
        self.next += WINDOW;
        Arc::new(
            sections
                .into_iter()
                .enumerate()
                .map(|(k, section)| Cut::new(section, ahead.min(start + k) + (ahead > 0) as usize))
                .collect(),
        )
    }
}

/// The layers sliced and not yet made into masks, and the slicing task while it waits
/// for them to be fewer than [`MAX_AHEAD`].
#[derive(Default)]
struct Backlog<'a>(Mutex<BacklogState<'a>>);

#[derive(Default)]
struct BacklogState<'a> {
    /// Layers sliced and not yet made into masks.
    waiting: usize,
    /// The slicing task, waiting for room.
    parked: Option<Cursor<'a>>,
    /// The slicing task, done.
    finished: Option<Cursor<'a>>,
}

impl<'a> Backlog<'a> {
    /// `cursor` back when there is room for another window; otherwise it is kept until a
    /// block's end makes room ([`Backlog::leave`]).
    fn room_or_park(&self, cursor: Cursor<'a>) -> Option<Cursor<'a>> {
        let mut s = lock(&self.0);
        if s.waiting > MAX_AHEAD {
            s.parked = Some(cursor);
            return None;
        }
        Some(cursor)
    }

    /// Counts `layers` sliced layers in.
    fn enter(&self, layers: usize) {
        lock(&self.0).waiting += layers;
    }

    /// Counts a block's `layers` off; returns the parked slicing task when that made room.
    fn leave(&self, layers: usize) -> Option<Cursor<'a>> {
        let mut s = lock(&self.0);
        s.waiting -= layers;
        if s.waiting > MAX_AHEAD {
            return None;
        }
        s.parked.take()
    }

    /// Keeps the slicing task once it has cut its last window.
    fn finish(&self, cursor: Cursor<'a>) {
        lock(&self.0).finished = Some(cursor);
    }

    fn into_finished(self) -> Cursor<'a> {
        let s = self.0.into_inner().unwrap_or_else(|p| p.into_inner());
        s.finished
            .expect("the slicing task ends before the pool does")
    }
}

/// The slicing task: cuts windows and spawns their blocks while there is room, then parks
/// (see the module docs).
fn feed<'s, 'a: 's>(scope: &rayon::ScopeFifo<'s>, p: &'s Pipeline<'a>, mut cursor: Cursor<'a>) {
    loop {
        // Past a failed layer, only blocks below it that wait for this window need it.
        let stop_at = p.stop_at.load(Ordering::Relaxed);
        let needed = cursor.next < stop_at || cursor.waiting.iter().any(|b| b.first() < stop_at);
        if cursor.next >= p.layers || !needed || p.control.cancelled() {
            p.backlog.finish(cursor);
            return;
        }
        cursor = match p.backlog.room_or_park(cursor) {
            Some(c) => c,
            None => return,
        };
        let start = cursor.next;
        let ahead = p.ctx.cure.map_or(0, |c| c.upper_layers());
        let sections = cursor.cut(ahead);
        let m = sections.len();
        p.backlog.enter(m);
        // The last window's blocks that waited for this one's sections.
        for mut block in cursor.waiting.drain(..) {
            block.next = Some(Arc::clone(&sections));
            scope.spawn_fifo(move |scope| run_block(scope, p, block));
        }
        for b in 0..m.div_ceil(BLOCK) {
            let block = Block {
                start,
                sections: Arc::clone(&sections),
                prev: cursor.prev.clone(),
                next: None,
                ks: b * BLOCK..((b + 1) * BLOCK).min(m),
            };
            // Waits while its last layer's look-ahead reaches the next window.
            if block.ks.end - 1 + ahead >= m && start + m < p.layers {
                cursor.waiting.push(block);
            } else {
                scope.spawn_fifo(move |scope| run_block(scope, p, block));
            }
        }
        cursor.prev = Some(sections);
    }
}

/// Consecutive layers of one window, made in order by one worker.
struct Block {
    /// The window's first layer.
    start: usize,
    /// The window's sections.
    sections: Arc<Vec<Cut>>,
    /// The window below's sections.
    prev: Option<Arc<Vec<Cut>>>,
    /// The window above's sections, where the block's layers look at them.
    next: Option<Arc<Vec<Cut>>>,
    /// The block's layers, as indices into `sections`.
    ks: Range<usize>,
}

impl Block {
    /// The block's first layer.
    fn first(&self) -> usize {
        self.start + self.ks.start
    }
}

fn run_block<'s, 'a: 's>(scope: &rayon::ScopeFifo<'s>, p: &'s Pipeline<'a>, block: Block) {
    // Counts the block's layers off even if it panics (the panic reaches the caller when
    // the scope ends; the slicing task must not stay parked).
    let _leaving = Leaving {
        scope,
        p,
        layers: block.ks.len(),
    };
    make_block(p, &block);
}

/// Makes a block's layers in order, up to the first that fails or is stopped.
fn make_block(p: &Pipeline, block: &Block) {
    // Scratch buffers (megabytes) outlive blocks: fresh ones would page-fault on every
    // block.
    let mut scratch = p.scratch.take();
    let mut worker = BlockWorker::default();
    let sections = &block.sections;
    let last = block.ks.end - 1;
    // Drawn as the pass before drew it: taken from that pass.
    let first = block.first();
    let again = (p.ctx.again).filter(|a| a.serves(p.ctx.cure, first..first + block.ks.len()));
    for k in block.ks.clone() {
        let index = block.start + k;
        if p.stopped_at(index) {
            return;
        }
        let layer = LayerInput {
            index,
            section: &sections[k].section,
            cut: &sections[k],
            below: match k {
                0 => block.prev.as_ref().and_then(|w| w.last()),
                _ => Some(&sections[k - 1]),
            }
            .map(|c| &c.section),
            lower: lower_sections(
                block,
                k,
                p.ctx.cure.filter(|c| c.corrects()).map_or(0, |_| WINDOW),
            ),
            upper: upper_sections(block, k, p.ctx.cure.map_or(0, |c| c.upper_layers())),
            above: p.layers - 1 - index,
        };
        let mut out = match again {
            Some(a) => a.layer(p.ctx, &layer),
            None => match layer_masks(p.ctx, &mut worker, &mut scratch, &layer) {
                Ok(out) => out,
                Err(e) => return p.fail(index, e),
            },
        };
        // The next block's first layer counts its islands over these (a block taken from
        // the pass before has them from there).
        if k == last && index + 1 < p.layers && out.runs.is_none() && again.is_none() {
            out.runs = worker.analyser.last_runs().cloned();
        }
        let _ = p.slots[index].set(out);
        let d = p.done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(progress) = p.control.progress {
            progress(d, p.layers);
        }
    }
}

/// The sections of the `m` layers below layer `k` of `block`'s window (nearest first;
/// fewer near the platform), from the window and the window below (so `m` ≤ [`WINDOW`]).
fn lower_sections(block: &Block, k: usize, m: usize) -> Vec<&Section> {
    (1..=m)
        .map_while(|d| match k.checked_sub(d) {
            Some(j) => Some(&block.sections[j].section),
            None => block
                .prev
                .as_ref()
                .and_then(|w| w.len().checked_sub(d - k).map(|j| &w[j].section)),
        })
        .collect()
}

/// The sections of the `m` layers above layer `k` of `block`'s window (nearest first;
/// fewer near the job's top), from the window and the window above (so `m` ≤ [`WINDOW`]).
fn upper_sections(block: &Block, k: usize, m: usize) -> Vec<&Cut> {
    (1..=m)
        .map_while(|d| match block.sections.get(k + d) {
            Some(s) => Some(s),
            None => block
                .next
                .as_ref()
                .and_then(|w| w.get(k + d - block.sections.len())),
        })
        .collect()
}

/// Counts a block's layers off when it ends, resuming the slicing task when that makes
/// room; a block that panics stops the rest.
struct Leaving<'x, 's, 'a: 's> {
    scope: &'x rayon::ScopeFifo<'s>,
    p: &'s Pipeline<'a>,
    layers: usize,
}

impl Drop for Leaving<'_, '_, '_> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.p.stop_at.store(0, Ordering::Relaxed);
        }
        if let Some(cursor) = self.p.backlog.leave(self.layers) {
            let p = self.p;
            self.scope.spawn_fifo(move |scope| feed(scope, p, cursor));
        }
    }
}

/// Locks `m`, also after a panic elsewhere (every state these mutexes guard stays
/// consistent between statements).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}
