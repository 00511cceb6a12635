//! Projector geometry: where light lands and how projectors share the field
//! (docs/GEOMETRY.md): [`distortion`] pre-warps sections through a measured lens
//! correction, [`blend`] makes overlap ramps whose shares sum to one in irradiance and
//! turns a share into a gray through a projector's response, [`tile`] splits each layer's
//! field coverage into one blended, response-corrected gray mask per projector.
//!
//! Invariants: a warped polyline stays within 0.05 px of the warped curve; every warped point
//! lies inside the projector field or the job fails naming it; `area_mm2` is the build
//! plane's; blend shares sum to one in irradiance for any layout; the output does not depend
//! on the thread count.

pub mod blend;
pub mod distortion;
pub mod tile;
