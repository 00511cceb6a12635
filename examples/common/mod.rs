//! Shared by the examples and the benchmarks (`benches/*.rs` include this file with
//! `#[path]`): a model loaded and placed as `dmdsl slice` places it, the command line's
//! arguments and fixtures, the median of timings. Each program uses some of it.
#![allow(dead_code)]

use dmdsl::job::{place_mesh, PlacementMode};
use dmdsl::mesh::Mesh;
use dmdsl::profile::{Field, Profile};
use dmdsl::slice::Section;
use std::path::{Path, PathBuf};

/// The mesh at `path`, centred on `profile`'s field, and its number of layers of height `h` mm.
pub fn placed(path: &Path, profile: &Profile, h: f64) -> (Mesh, usize) {
    let mut mesh = dmdsl::mesh::load(path).expect("model loads");
    let (_, n) =
        place_mesh(path, &mut mesh, profile, PlacementMode::Center, h).expect("model fits");
    (mesh, n)
}

/// The sections of the model at `path` sliced with the default profile (placed as
/// `dmdsl slice` places it), and the profile's field.
pub fn default_sections(path: &Path) -> (Vec<Section>, Field) {
    let p = Profile::default_profile();
    let h = p.slicing.layer_height_mm.get();
    let field = p.field();
    let (mesh, n) = placed(path, &p, h);
    (dmdsl::slice::slice(&mesh, h, n).0, field)
}

/// The program's arguments but options (`cargo bench` passes `--bench`).
pub fn args() -> Vec<String> {
    std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect()
}

/// Argument `i` of `args` as a path, or fixture `name` when there is none.
pub fn path_arg(args: &[String], i: usize, name: &str) -> PathBuf {
    args.get(i)
        .map(PathBuf::from)
        .unwrap_or_else(|| fixture(name))
}

/// A file under the repository's `fixtures/`.
pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
}

/// The median of `v` (the upper one of an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
