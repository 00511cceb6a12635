//! The SLA 3D printer control-file standard, schema v5: [`mod@read`] imports one (with
//! `expr.rs`'s `${...}` evaluator), `write.rs` writes a job as one.

mod expr;
pub mod read;
pub(crate) mod write;

pub(crate) use read::{import, settings_entry};
pub use read::{MAX_LAYERS, PIXEL_MM};
pub use write::{IMAGES, SCHEMA_VERSION, SETTINGS};
