//! `dmdsl`: a build-job compiler and dry-run executor for DMD mask-projection
//! stereolithography.
//!
//! The library follows the data (`docs/ARCHITECTURE.md`): load the mesh, place and slice
//! it, rasterize every layer into masks (light compensation, cure correction, pre-warp and
//! tiling), plan exposures and stage steps, and write the job; the executor reads only a
//! job (in any form [`open`] reads), verifies and simulates it.
//!
//! # Using the library
//!
//! The two commands are one call each; the items re-exported here are what they take and
//! return, with the job format ([`bundle`]: the manifest and its records) and the machine
//! description ([`profile`]):
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
//! [`open`] reads a job in any form `dmdsl run` reads and [`write()`] writes one in any
//! [`Format`]; [`cli::main`] is the whole `dmdsl` program.
//!
//! The pipeline's stages are private to the crate. The Cargo feature `internals` makes them
//! public for the project's own integration tests, benchmarks and examples, which drive
//! them one by one; they are not a stable interface.
#![warn(missing_docs)]

/// Declares modules that are private to the crate, or public with the `internals` feature.
macro_rules! stages {
    ($($name:ident),* $(,)?) => {$(
        #[cfg(feature = "internals")]
        pub mod $name;
        #[cfg(not(feature = "internals"))]
        pub(crate) mod $name;
    )*};
}

pub mod bundle;
pub mod cli;
pub mod error;
pub mod profile;
#[cfg(test)]
mod test_support;

stages!(
    calib, cure, digest, exec, formats, geometry, input, inspect, job, mesh, motion, optics,
    output, picture, plan, plot, png, polyfit, raster, round, slice, support, table, text, units,
    warning,
);

pub use bundle::Manifest;
pub use error::{Error, Result};
pub use exec::report::Report;
pub use exec::sim::FaultKind;
pub use exec::{run, Kind, RunOptions, Violation};
pub use formats::{open, write, Format, Job};
pub use job::{slice_to_bundle, SliceOptions, SliceSummary};
pub use mesh::Mesh;
pub use profile::Profile;
pub use units::{NonNegative, Positive};
pub use warning::{Severity, Warning, CODES as WARNING_CODES};
