//! What cures, not only what is drawn: the cure model (docs/CURE.md), the prediction of
//! each layer's cured edge against its exact section, and the correction of the masks
//! for the projector's blur and the light that reaches through later layers.
//!
//! The model itself (the Gaussian point-spread function, the dose convention, Beer–Lambert
//! in depth) is [`crate::resin`], which the executor shares. Files: `segments.rs` (a section's
//! edges in pixels, with a grid index), `predict.rs` (cured edges and their errors),
//! `correct.rs` (the XY correction of the coverage), `widen.rs` (narrow features the
//! correction would starve, drawn back and wider until they cure), `held_back.rs` (the flat
//! features the Z correction drops). Like every algorithm stage it takes
//! inputs and returns values; `job` records them.

pub mod correct;
pub mod held_back;
pub mod plots;
pub mod predict;
pub mod segments;
pub mod widen;

pub use crate::resin::CureModel;
pub use correct::{correct_coverage, edge_shift_px};
pub use predict::{predict_layer, LayerCure};

use serde::{Deserialize, Serialize};

/// The correction a job applies to its masks (`slice --cure-correction`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Correction {
    /// Masks are the exact sections.
    Off,
    /// Edges moved so the cured edge at mid-layer lands on the section's.
    Xy,
    /// XY, and the first layers of downward-facing surfaces held back by the
    /// print-through.
    Xyz,
}

impl Correction {
    /// The mode as the command line and the manifest write it.
    pub fn as_str(self) -> &'static str {
        match self {
            Correction::Off => "off",
            Correction::Xy => "xy",
            Correction::Xyz => "xyz",
        }
    }
}
