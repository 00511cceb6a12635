//! The cells of the search and their priority queue, largest upper bound first.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A square cell of the subdivision: centre `c`, half-size `h`, `max` an upper bound of the
/// signed distance inside it (set from the parent when the cell is queued).
#[derive(Debug, Clone, Copy)]
pub(super) struct Cell {
    pub(super) c: [f64; 2],
    pub(super) h: f64,
    pub(super) max: f64,
    /// The parent's nearest edge (a good first guess for this cell's).
    pub(super) hint: u32,
    /// The parent's far-wall edge (`u32::MAX`: none).
    pub(super) hint2: u32,
    /// Index of the parent's boundary points in the search's point arena (`u32::MAX`:
    /// none), tried again when the cell is popped.
    pub(super) pts: u32,
    /// The best depth when the cell was queued: its parent's points did not cover it
    /// then, nor will they while the best has not grown.
    pub(super) best: f64,
    /// For how many generations the walls (`hint`, `hint2`) have been followed along the
    /// contours without a search (0: found by the parent's searches).
    pub(super) followed: u8,
}

/// A queued cell: its key (`Cell::max`) and its index in the search's cell arena. The
/// queue compares keys only, so it moves 16 bytes per step instead of a whole cell. The
/// key is kept as the integer [`f64::total_cmp`] orders by (one comparison per step).
#[derive(Debug, Clone, Copy)]
struct QueuedCell {
    key: i64,
    cell: u32,
}

impl QueuedCell {
    /// `max` as an integer ordered as [`f64::total_cmp`] orders the floats (its own
    /// transform: negative values have their magnitude bits flipped).
    #[inline]
    fn key(max: f64) -> i64 {
        let b = max.to_bits() as i64;
        b ^ (((b >> 63) as u64) >> 1) as i64
    }
}

impl PartialEq for QueuedCell {
    fn eq(&self, o: &Self) -> bool {
        self.key == o.key
    }
}
impl Eq for QueuedCell {}
impl PartialOrd for QueuedCell {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for QueuedCell {
    fn cmp(&self, o: &Self) -> Ordering {
        self.key.cmp(&o.key)
    }
}

/// The search's priority queue of cells (largest bound first).
#[derive(Default)]
pub(super) struct Queue {
    heap: BinaryHeap<QueuedCell>,
    cells: Vec<Cell>,
}

impl Queue {
    /// Empties the queue (its buffers are kept).
    pub(super) fn clear(&mut self) {
        self.heap.clear();
        self.cells.clear();
    }

    #[inline]
    pub(super) fn push(&mut self, c: Cell) {
        self.heap.push(QueuedCell {
            key: QueuedCell::key(c.max),
            cell: self.cells.len() as u32,
        });
        self.cells.push(c);
    }

    #[inline]
    pub(super) fn pop(&mut self) -> Option<Cell> {
        self.heap.pop().map(|q| self.cells[q.cell as usize])
    }
}
