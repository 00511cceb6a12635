//! Integration tests: one test binary that runs `dmdsl` as a user would and checks the
//! files it writes. Each module covers one command.

mod calibrate;
mod common;
mod geometry;
mod plan;
mod run;
mod slice;
