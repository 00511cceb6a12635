//! Integration tests: one test binary that runs `dmdsl` as a user would and checks the
//! files it writes. Each module covers one command (`batch`: `slice` in scripts and CI); `layers` checks the source tree's module
//! dependencies.

mod batch;
mod calibrate;
mod calibrate_sweep;
mod common;
mod cure;
mod cure_dropped;
mod cure_models;
mod cure_widen;
mod export;
mod fuzz;
mod geometry;
mod help;
mod import;
mod inspect;
mod json;
mod layers;
mod limits;
mod messages;
mod plan;
mod plate;
mod printable;
mod psf;
mod readme;
mod replace;
mod roundtrip;
mod run;
mod run_cure;
mod schema;
mod slice;
mod supports;
mod synthetic;
mod tamper;
mod warnings;
mod working_curve;
