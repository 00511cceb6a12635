//! Zip archives: the one-file forms of a job (a zipped bundle, an SL1 file, an SLA
//! control-file zip).
//!
//! [`read`] reads an archive from elsewhere into memory, refusing anything unsafe.

pub mod read;
