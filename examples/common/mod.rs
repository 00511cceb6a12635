//! Shared by the examples: a model loaded and placed as `dmdsl slice` places it.

use dmdsl::job::{place_mesh, PlacementMode};
use dmdsl::mesh::Mesh;
use dmdsl::profile::Field;
use std::path::Path;

/// The mesh at `path`, centred on `field`, and its number of layers of height `h` mm.
pub fn placed(path: &Path, field: &Field, h: f64) -> (Mesh, usize) {
    let mut mesh = dmdsl::mesh::load(path).expect("model loads");
    let (_, n) = place_mesh(path, &mut mesh, field, PlacementMode::Center, h).expect("model fits");
    (mesh, n)
}
