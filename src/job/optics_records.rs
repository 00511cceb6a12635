//! The light-compensation files of a bundle and their manifest records: the single
//! projector's gray map (written beside the masks, as it depends on the set-up only) and,
//! for several projectors, each projector's gray map and record from the tiler.

use super::encode_png;
use crate::bundle::{BundleWriter, Optics};
use crate::error::Result;
use crate::geometry::tile::Tiler;
use crate::optics::JobOptics;
use crate::profile::Profile;

/// The single projector's gray map as written: its file and SHA-256.
pub(super) type WrittenGrayMap = Result<(String, String)>;

/// Writes the single projector's gray map.
pub(super) fn write_gray_map(
    optics: &JobOptics,
    writer: &BundleWriter,
    profile: &Profile,
) -> WrittenGrayMap {
    optics.write_gray_map(writer, profile, encode_png)
}

/// The manifest's light-compensation records.
pub(super) struct OpticsRecords {
    /// The single projector's compensation.
    pub optics: Option<Optics>,
    /// Each projector's compensation, when tiled.
    pub projector_optics: Vec<Optics>,
    /// The compensation mode (`settings.compensation`).
    pub compensation: String,
    /// Warnings about the compensation.
    pub warnings: Vec<String>,
}

/// The records once the masks are made: the single projector's from `gray_map` (what
/// [`write_gray_map`] returned), or each tiled projector's, whose gray maps are written
/// now.
pub(super) fn optics_records(
    optics: Option<&JobOptics>,
    gray_map: Option<WrittenGrayMap>,
    tiler: Option<&Tiler>,
    writer: &BundleWriter,
    profile: &Profile,
) -> Result<OpticsRecords> {
    let mut warnings = Vec::new();
    let optics = match optics {
        Some(o) => {
            let written = gray_map.expect("written beside the masks")?;
            let (record, w) = o.finish_with(written)?;
            warnings.extend(w);
            Some(record)
        }
        None => None,
    };
    let projector_optics = match tiler {
        Some(t) => {
            let (records, w) = t.finish(writer, profile, encode_png)?;
            warnings.extend(w);
            records
        }
        None => Vec::new(),
    };
    let compensation = match tiler {
        Some(t) => t.compensation().as_str().into(),
        None => optics.as_ref().map_or("off".into(), |o| o.mode.clone()),
    };
    Ok(OpticsRecords {
        optics,
        projector_optics,
        compensation,
        warnings,
    })
}
