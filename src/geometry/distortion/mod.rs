//! Distortion pre-warp from a measured correction table (docs/GEOMETRY.md, "Distortion
//! correction", gives the table, the fit and the densification).
//!
//! Every row of the table samples the correction G (wanted point → point to aim at),
//! fitted as a least-squares polynomial (`polynomial`) plus `κ ×` a natural-neighbour
//! interpolant of its residuals (`residual`), in `correction`. Section contours are
//! pre-warped vertex by vertex, edges cut into pieces of at most [`SEG_MM`] and split until
//! the warped polyline is within [`SAG_PX`] of the warped curve (`warp`); a warped point
//! outside the projector's field is an error naming it. `table` reads the measured pairs,
//! `plot` draws the map.

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
