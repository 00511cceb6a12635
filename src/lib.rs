//! `dmdsl`: a build-job compiler and dry-run executor for DMD mask-projection
//! stereolithography.
//!
//! The library follows the data (see `docs/ARCHITECTURE.md`):
//! [`mesh`] (load, weld, validate) → [`slice`](mod@slice) (contours per layer) → [`raster`]
//! (8-bit masks, light compensation from [`optics`], pre-warp and tiling from [`geometry`])
//! → [`plan`] (exposure and stage steps) → [`bundle`] (the job bundle, written atomically),
//! orchestrated by [`job`]. The executor ([`exec`]) reads only the bundle.
//!
//! # Using the library
//!
//! The two commands are one call each; the items re-exported here are what they take and
//! return:
//!
//! ```no_run
//! use dmdsl::{slice_to_bundle, run, Profile, RunOptions, SliceOptions};
//! # fn main() -> dmdsl::Result<()> {
//! let opts = SliceOptions::new("part.stl", "part.dmdjob", Profile::default_profile());
//! let summary = slice_to_bundle(&opts)?;
//! let report = run(&summary.bundle, &RunOptions::default())?;
//! assert!(report.ok);
//! # Ok(())
//! # }
//! ```
//!
//! The stage modules stay public for programs that drive the stages themselves (the
//! benchmarks and examples do), and so does [`plot`], whose pictures several of them return;
//! the building blocks they share (PNG encoding, hashing, least squares, tables, reading
//! input files) are private.
#![warn(missing_docs)]

pub mod archive;
pub mod bundle;
pub mod cure;
mod digest;
pub mod error;
pub mod exec;
pub mod export;
pub mod geometry;
pub mod import;
mod input;
pub mod inspect;
pub mod job;
pub mod mesh;
pub mod motion;
pub mod optics;
pub mod output;
pub mod plan;
pub mod plot;
mod png;
mod polyfit;
pub mod profile;
pub mod raster;
pub mod round;
pub mod slice;
mod table;
#[cfg(test)]
mod test_support;
pub mod units;
pub mod warning;

pub use bundle::Manifest;
pub use error::{Error, Result};
pub use exec::report::Report;
pub use exec::{run, RunOptions, Violation};
pub use job::{slice_to_bundle, SliceOptions, SliceSummary};
pub use mesh::Mesh;
pub use profile::Profile;
pub use warning::{Severity, Warning};
