//! How the resin answers the projector's light (docs/CURE.md): the lens's point-spread
//! function (`psf.rs`, a Gaussian), the dose convention, Beer–Lambert in depth and the
//! print-through's closed form (`dose.rs`, Jacobs' working curve).
//!
//! Pure math, below both users: the slicer's prediction and correction (`cure`, which
//! works against the exact sections) and the executor's mask-only check (`exec`, which
//! sees only a bundle).

pub mod dose;
pub mod psf;

pub use dose::CureModel;
pub use psf::Psf;
