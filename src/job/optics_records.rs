//! The light-compensation files of a bundle and their manifest records: the single
//! projector's gray map (written beside the masks, as it depends on the set-up only) and,
//! for several projectors, each projector's gray map and record from the tiler.

use super::sink::Sink;
use crate::bundle::{self, Optics};
use crate::error::Result;
use crate::geometry::tile::Tiler;
use crate::optics::{GrayMap, JobOptics};
use crate::profile::Profile;
use crate::warning::Warning;
use std::path::Path;

/// The single projector's gray map as written: its file and SHA-256.
pub(super) type WrittenGrayMap = Result<(String, String)>;

/// Writes the single projector's gray map.
pub(super) fn write_gray_map(
    optics: &JobOptics,
    writer: &Sink,
    profile: &Profile,
) -> WrittenGrayMap {
    write_one(writer, &optics.gray_map(profile))
}

/// Writes a gray map into the bundle; returns its file and SHA-256.
fn write_one(writer: &Sink, map: &GrayMap) -> Result<(String, String)> {
    if let Some(dir) = Path::new(&map.file).parent() {
        writer.create_dir(&dir.to_string_lossy())?;
    }
    writer.write_file(&map.file, &map.png)?;
    Ok((map.file.clone(), bundle::sha256_hex(&map.png)))
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
    pub warnings: Vec<Warning>,
}

/// The records once the masks are made: the single projector's from `gray_map` (what
/// [`write_gray_map`] returned), or each tiled projector's, whose gray maps are written
/// now.
pub(super) fn optics_records(
    optics: Option<&JobOptics>,
    gray_map: Option<WrittenGrayMap>,
    tiler: Option<&Tiler>,
    writer: &Sink,
    profile: &Profile,
) -> Result<OpticsRecords> {
    let mut warnings = Vec::new();
    let optics = match optics {
        Some(o) => {
            let written = gray_map.expect("written beside the masks")?;
            let (record, w) = o.finish_with(written);
            warnings.extend(w);
            Some(record.rounded())
        }
        None => None,
    };
    let projector_optics = match tiler {
        Some(t) => {
            let done = t.finish(profile);
            for map in &done.gray_maps {
                write_one(writer, map)?;
            }
            warnings.extend(done.warnings);
            done.records.into_iter().map(Optics::rounded).collect()
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
