//! A pool of [`Scratch`] buffers shared by the tasks of a parallel loop.

use super::Scratch;
use std::sync::Mutex;

/// Scratch buffers kept from task to task (the pipeline's blocks, the support search's
/// splits of a window), so that each is allocated once per thread rather than per task.
#[derive(Default)]
pub struct ScratchPool(Mutex<Vec<Scratch>>);

impl ScratchPool {
    /// A scratch from the pool (or a new one), returned to it when dropped.
    pub fn take(&self) -> PooledScratch<'_> {
        let scratch = self
            .0
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .pop()
            .unwrap_or_default();
        PooledScratch {
            pool: self,
            scratch: Some(scratch),
        }
    }
}

/// A [`Scratch`] borrowed from a [`ScratchPool`].
pub struct PooledScratch<'p> {
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
            self.pool
                .0
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .push(s);
        }
    }
}
