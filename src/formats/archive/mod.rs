//! Zip archives: the one-file forms of a job (the native bundle as a zip, Prusa SL1/SL1S,
//! the SLA control-file standard) are zips.
//!
//! - [`mod@read`]: reading one from elsewhere into memory, refusing anything unsafe.
//! - [`mod@write`]: writing one, atomically (a temporary sibling renamed into place).

pub mod read;
pub mod write;
