//! `dmdsl`: a build-job compiler and dry-run executor for DMD mask-projection
//! stereolithography.
//!
//! The library follows the data (see `docs/ARCHITECTURE.md`):
//! [`mesh`] (load, weld, validate) → [`slice`](mod@slice) (contours per layer) → [`raster`]
//! (8-bit masks) → [`plan`] (exposure and stage steps) → [`bundle`] (the job bundle,
//! written atomically), orchestrated by [`job`]. The executor reads only the bundle.
#![warn(missing_docs)]

pub mod bundle;
pub mod digest;
pub mod error;
pub mod exec;
pub mod geometry;
pub mod input;
pub mod job;
pub mod mesh;
pub mod motion;
pub mod optics;
pub mod plan;
pub mod plot;
pub mod png;
pub mod polyfit;
pub mod profile;
pub mod raster;
pub mod round;
pub mod slice;
pub mod table;
pub mod units;
pub mod warning;

pub use error::{Error, Result};
