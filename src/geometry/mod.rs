//! Projector geometry: where light lands and how projectors share the field.
//!
//! * [`distortion`]: a measured correction table (`x_mm,y_mm,seen_x_mm,seen_y_mm`) is fitted
//!   by a least-squares polynomial plus a cross-validated natural-neighbour residual
//!   interpolant; section contours are pre-warped (long edges densified) before they are
//!   rasterized, so the part prints where the file says despite lens distortion and keystone.
//! * [`blend`]: edge-blend ramps across projector overlaps whose weights sum to one in
//!   irradiance, and the conversion of an irradiance fraction to a gray level through a
//!   projector's (nonlinear) response curve.
//! * [`tile`]: per job, LUT tables that split each layer's field coverage mask into one
//!   blended, response-corrected gray mask per projector.
//!
//! Method and limits: `docs/GEOMETRY.md`.
//!
//! Invariants: a warped polyline stays within 0.05 px of the warped curve; every warped point
//! lies inside the projector field or the job fails naming it; `area_mm2` is the build
//! plane's; blend shares sum to one in irradiance for any layout; the output does not depend
//! on the thread count.

pub mod blend;
pub mod distortion;
pub mod tile;
