//! Prusa SL1 / SL1S, the zip PrusaSlicer 2.5 writes: [`mod@read`] imports one,
//! `write.rs` writes a job as one, with `thumbnail.rs`'s preview pictures.

pub mod read;
mod thumbnail;
pub(crate) mod write;

pub(crate) use read::import;
pub use read::{CONFIG, PRUSASLICER};
