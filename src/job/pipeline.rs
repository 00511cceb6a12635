//! The pipeline driver: windows of sections → blocks of layers → each layer's work.
//!
//! One slicing thread cuts windows of [`WINDOW`] layers and spawns each window's layers
//! as blocks of [`BLOCK`] consecutive layers on rayon's pool as soon as they are cut (no
//! barrier between windows), so the slicing overlaps the mask work. At most [`MAX_AHEAD`]
//! layers wait (memory stays bounded); while it waits, the slicing thread makes masks
//! itself.
//!
//! The first error (or Ctrl-C, `cancel`) stops the slicing before its next window and
//! every block before its next layer. Each layer's result goes to its own slot, so the
//! output never depends on which worker made it or when.

use super::layer::{layer_masks, BlockWorker, LayerContext, LayerIn, LayerOut};
use crate::error::{Error, Result};
use crate::raster::Scratch;
use crate::slice::{Section, SliceStats, Slicer};
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::Instant;

/// Layers sliced at a time: memory depends on this, not on the number of layers.
const WINDOW: usize = 32;
/// Consecutive layers one worker processes in order. Its first layer's analysis scans the
/// layer below again (islands) and cannot copy the analysis of an equal layer below
/// (prisms): larger blocks do that less often (8 rather than 4: −2.8 % analysis
/// instructions on logo_hires), smaller ones balance the workers better at the end.
pub const BLOCK: usize = 8;
/// Layers sliced but not yet made into masks, at most (bounds memory).
const MAX_AHEAD: usize = 3 * WINDOW;

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
pub(super) struct Sliced {
    /// Each layer's output, in layer order.
    pub layers: Vec<LayerOut>,
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
) -> Result<Sliced> {
    let start = Instant::now();
    let p = Pipeline {
        ctx,
        control,
        layers,
        slots: (0..layers).map(|_| OnceLock::new()).collect(),
        scratch: ScratchPool::default(),
        in_flight: AtomicUsize::new(0),
        finished: Mutex::new(None),
        stop: AtomicBool::new(false),
        failure: Mutex::new(None),
        done: AtomicUsize::new(0),
    };
    let cursor = Cursor {
        slicer,
        next: 0,
        prev: None,
        slice_s: 0.0,
    };
    rayon::scope(|scope| {
        scope.spawn(|_| beside());
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
    slots: Vec<OnceLock<LayerOut>>,
    scratch: ScratchPool,
    /// Layers sliced and not yet made into masks.
    in_flight: AtomicUsize,
    /// The slicing state once it has cut its last window.
    finished: Mutex<Option<Cursor<'a>>>,
    /// Set by the first error: the rest stops.
    stop: AtomicBool,
    /// The first real error (others may just be the stop it caused).
    failure: Mutex<Option<Error>>,
    /// Layers done, for the progress report.
    done: AtomicUsize,
}

impl Pipeline<'_> {
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed) || self.control.cancelled()
    }

    /// Stops the rest, keeping the first real error.
    fn fail(&self, e: Error) {
        self.stop.store(true, Ordering::Relaxed);
        let mut f = lock(&self.failure);
        if f.as_ref()
            .is_none_or(|old| matches!(old, Error::Interrupted))
        {
            *f = Some(e);
        }
    }

    /// Every layer's output once the pool is done, or the first error.
    fn finish(self, masks_s: f64) -> Result<Sliced> {
        if let Some(e) = self.failure.into_inner().unwrap_or_else(|p| p.into_inner()) {
            return Err(e);
        }
        if self.control.cancelled() {
            return Err(Error::Interrupted);
        }
        let cursor = (self.finished.into_inner())
            .unwrap_or_else(|p| p.into_inner())
            .expect("the slicing loop ends before the pool does");
        Ok(Sliced {
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
    prev: Option<Arc<Vec<Section>>>,
    /// Time spent cutting, s.
    slice_s: f64,
}

impl Cursor<'_> {
    /// Cuts the next window.
    fn cut(&mut self) -> Arc<Vec<Section>> {
        let t = Instant::now();
        let sections = self.slicer.window(self.next..self.next + WINDOW);
        self.slice_s += t.elapsed().as_secs_f64();
        self.next += WINDOW;
        Arc::new(sections)
    }
}

/// The slicing loop: cuts windows and spawns their blocks, waiting (and making masks)
/// while more than [`MAX_AHEAD`] layers wait.
fn feed<'s, 'a: 's>(scope: &rayon::Scope<'s>, p: &'s Pipeline<'a>, mut cursor: Cursor<'a>) {
    while cursor.next < p.layers {
        while p.in_flight.load(Ordering::Acquire) > MAX_AHEAD && !p.stop.load(Ordering::Relaxed) {
            if rayon::yield_now() != Some(rayon::Yield::Executed) {
                std::thread::sleep(std::time::Duration::from_micros(50));
            }
        }
        if p.stopped() {
            break;
        }
        let start = cursor.next;
        let sections = cursor.cut();
        let m = sections.len();
        for b in 0..m.div_ceil(BLOCK) {
            let block = Block {
                start,
                sections: Arc::clone(&sections),
                prev: cursor.prev.clone(),
                ks: b * BLOCK..((b + 1) * BLOCK).min(m),
            };
            p.in_flight.fetch_add(block.ks.len(), Ordering::AcqRel);
            scope.spawn(move |_| run_block(p, block));
        }
        cursor.prev = Some(sections);
    }
    *lock(&p.finished) = Some(cursor);
}

/// Consecutive layers of one window, made in order by one worker.
struct Block {
    /// The window's first layer.
    start: usize,
    /// The window's sections.
    sections: Arc<Vec<Section>>,
    /// The window below's sections.
    prev: Option<Arc<Vec<Section>>>,
    /// The block's layers, as indices into `sections`.
    ks: Range<usize>,
}

fn run_block(p: &Pipeline, block: Block) {
    // Counts the block's layers off even if it panics (the panic reaches the caller when
    // the scope ends; the slicing thread must not wait).
    let _leaving = Leaving(&p.in_flight, block.ks.len());
    if let Err(e) = make_block(p, &block) {
        p.fail(e);
    }
}

/// Makes a block's layers in order.
fn make_block(p: &Pipeline, block: &Block) -> Result<()> {
    // Scratch buffers (megabytes) outlive blocks: fresh ones would page-fault on every
    // block.
    let mut scratch = p.scratch.take();
    let mut worker = BlockWorker::default();
    let sections = &block.sections;
    let last = block.ks.end - 1;
    for k in block.ks.clone() {
        if p.stopped() {
            return Err(Error::Interrupted);
        }
        let index = block.start + k;
        let layer = LayerIn {
            index,
            section: &sections[k],
            below: match k {
                0 => block.prev.as_ref().and_then(|w| w.last()),
                _ => Some(&sections[k - 1]),
            },
        };
        let mut out = layer_masks(p.ctx, &mut worker, &mut scratch, &layer)?;
        // The next block's first layer counts its islands over these.
        if k == last && index + 1 < p.layers && out.runs.is_none() {
            out.runs = worker.analyser.last_runs().cloned();
        }
        let _ = p.slots[index].set(out);
        let d = p.done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(progress) = p.control.progress {
            progress(d, p.layers);
        }
    }
    Ok(())
}

/// Subtracts a block's layer count from the layers in flight when the block ends.
struct Leaving<'a>(&'a AtomicUsize, usize);

impl Drop for Leaving<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(self.1, Ordering::AcqRel);
    }
}

/// Scratch buffers kept from block to block.
#[derive(Default)]
struct ScratchPool(Mutex<Vec<Scratch>>);

impl ScratchPool {
    /// A scratch from the pool (or a new one), returned to it when dropped.
    fn take(&self) -> PooledScratch<'_> {
        let scratch = lock(&self.0).pop().unwrap_or_default();
        PooledScratch {
            pool: self,
            scratch: Some(scratch),
        }
    }
}

/// A [`Scratch`] borrowed from a [`ScratchPool`].
struct PooledScratch<'p> {
    pool: &'p ScratchPool,
    scratch: Option<Scratch>,
}

impl std::ops::Deref for PooledScratch<'_> {
    type Target = Scratch;
    fn deref(&self) -> &Scratch {
        self.scratch.as_ref().expect("present until drop")
    }
}

impl std::ops::DerefMut for PooledScratch<'_> {
    fn deref_mut(&mut self) -> &mut Scratch {
        self.scratch.as_mut().expect("present until drop")
    }
}

impl Drop for PooledScratch<'_> {
    fn drop(&mut self) {
        if let Some(s) = self.scratch.take() {
            lock(&self.pool.0).push(s);
        }
    }
}

/// Locks `m`, also after a panic elsewhere (every state these mutexes guard stays
/// consistent between statements).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}
