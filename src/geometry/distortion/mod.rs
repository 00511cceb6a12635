//! Distortion pre-warp from a measured correction table.
//!
//! A table row `x_mm,y_mm,seen_x_mm,seen_y_mm` says: light the *uncorrected* projector aimed
//! at build-plane point (x, y) (mm from the field's bottom-left corner, +x right, +y up)
//! actually landed at (seen_x, seen_y). Read backwards, every row is a sample of the
//! correction we need, the map G from a wanted build-plane point to the point the projector
//! must aim at: G(seen) = (x, y). So G is fitted directly from the scattered pairs, no
//! inversion needed:
//!
//! 1. A least-squares polynomial in the normalized seen coordinates, total degree 1..=5,
//!    degree chosen by leave-one-out cross-validation (closed form from the hat matrix):
//!    this averages measurement noise (the `polynomial` file).
//! 2. Plus `κ ×` a natural-neighbour interpolant (spade, Sibson weights) of the polynomial's
//!    residuals at the table points: it captures assembly errors no low-order formula
//!    describes (Yu et al.). κ ∈ [0, 1] minimizes the leave-one-out error of the combined
//!    model, so pure noise gets κ ≈ 0 (not passed through) and real structure κ ≈ 1.
//!    Outside the convex hull of the seen points the residual of the nearest hull point is
//!    used (continuous; counted as extrapolated and warned about).
//!
//! Section contours are pre-warped vertex by vertex before rasterizing; each edge is first
//! cut into pieces of at most [`SEG_MM`] and then split at midpoints until the warped
//! midpoint lies within 0.05 px of the chord (the sag bound). A warped point outside the
//! projector's field is a target the projector cannot reach: an error naming the point.
//!
//! Files: `table` (the measured pairs), `polynomial` (the smooth part), `residual` (the
//! interpolant), `correction` (the fit and its report), `warp` (the pre-warp), `plot`.

mod correction;
mod plot;
mod polynomial;
mod residual;
mod table;
#[cfg(test)]
mod tests;
mod warp;

pub use correction::Correction;
pub use table::Table;

use crate::error::{Error, Result};
use crate::profile::{DistortionConfig, Profile};
use crate::slice::Contour;
use std::path::{Path, PathBuf};

/// Longest edge piece before adaptive refinement, mm.
pub const SEG_MM: f64 = 2.0;
/// Largest allowed distance between a warped edge and its chord, px.
pub const SAG_PX: f64 = 0.05;
/// Highest polynomial degree tried.
pub const MAX_DEGREE: usize = 5;
/// Fewest table points accepted.
pub const MIN_POINTS: usize = 6;

/// Which correction a job uses (the command line's `--distortion`).
#[derive(Debug, Clone, Default, PartialEq)]
pub enum DistortionChoice {
    /// The profile's `[distortion]`, if any.
    #[default]
    Profile,
    /// None, even if the profile has one (`--distortion off`).
    Off,
    /// This CSV table (overrides the profile's).
    Table(PathBuf),
}

/// Resolves and fits the correction of a job. On success the profile's `[distortion]` is
/// replaced by the table's points inline (or removed when off), so the manifest's machine is
/// self-contained.
pub fn for_job(choice: &DistortionChoice, profile: &mut Profile) -> Result<Option<Correction>> {
    let table = match choice {
        DistortionChoice::Off => {
            profile.distortion = None;
            return Ok(None);
        }
        DistortionChoice::Table(p) => Table::read(p)?,
        DistortionChoice::Profile => match &profile.distortion {
            None => return Ok(None),
            Some(DistortionConfig { table: Some(t), .. }) => Table::read(Path::new(t))?,
            Some(DistortionConfig {
                points: Some(p), ..
            }) => Table::inline(&profile.name, p),
            Some(_) => {
                return Err(Error::Profile {
                    origin: profile.name.clone(),
                    msg: "[distortion]: needs `table` or `points`".into(),
                })
            }
        },
    };
    if profile.projector.len() > 1 {
        return Err(Error::Profile {
            origin: profile.name.clone(),
            msg: format!(
                "a distortion table ({}) describes one projector's lens; profiles with {} projectors cannot use one",
                table.source,
                profile.projector.len()
            ),
        });
    }
    let field = profile.field();
    let c = Correction::fit(
        &table,
        [field.width_mm(), field.height_mm()],
        field.pixel_mm,
    )?;
    profile.distortion = Some(DistortionConfig {
        table: None,
        points: Some(table.points()),
    });
    Ok(Some(c))
}

/// Ratio of the exact polygon areas of the original and warped contours: scales an area
/// measured on the warped (projector-side) mask back to the build plane.
pub fn area_scale(original: &[Contour], warped: &[Contour]) -> f64 {
    let a: f64 = original.iter().map(crate::slice::signed_area).sum();
    let b: f64 = warped.iter().map(crate::slice::signed_area).sum();
    if b.abs() > 1e-12 {
        a / b
    } else {
        1.0
    }
}
