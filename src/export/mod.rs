//! Writing a job in another form: the native bundle as a directory or as one zip, Prusa
//! SL1/SL1S, or the open SLA control-file standard (schema v5).
//!
//! A job is a [`Manifest`] and its files, read through [`BundleFiles`] (the files of a
//! bundle directory: [`DirFiles`]; the slicer hands over the files it made in memory).
//! [`write()`] writes one [`Format`] at a path, atomically (a temporary sibling renamed into
//! place, or the bundle writer's staging directory), and returns what the format could not
//! carry as [`Warning`]s (codes `export.*`, `docs/WARNINGS.md`): never silently.
//!
//! - `native.rs`: `dmdjob` (directory) and `dmdjob-zip` (the same files in a zip,
//!   `job.json` first, images stored).
//! - `sl1.rs`: Prusa SL1 / SL1S, the zip PrusaSlicer 2.5 writes.
//! - `control.rs`: the SLA control-file standard, `print_settings.json` + `slices/`.
//! - `thumbnail.rs`: the SL1 preview pictures, rendered from the masks
//!   ([`crate::inspect::preview()`]).

mod control;
mod native;
mod sl1;
mod thumbnail;

pub use control::SCHEMA_VERSION as CONTROL_SCHEMA_VERSION;

use crate::bundle::{Manifest, MANIFEST};
use crate::error::{Error, Result};
use crate::warning::Warning;
use std::borrow::Cow;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// The forms a job can be written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// The native bundle directory `part.dmdjob/` (`job.json` + `masks/*.png`).
    Dmdjob,
    /// The native bundle as one zip, `part.dmdjob.zip`: the same files, `job.json` first.
    DmdjobZip,
    /// Prusa SL1 (`part.sl1`), the zip PrusaSlicer 2.5 writes for the Original Prusa SL1.
    Sl1,
    /// Prusa SL1S (`part.sl1s`): the SL1 layout for the SL1S Speed.
    Sl1s,
    /// The open SLA 3D printer control-file standard, schema v5: a zip of
    /// `print_settings.json` and `slices/*.png`.
    SlaControl,
}

impl Format {
    /// Every format, in the order `--format` lists them.
    pub const ALL: [Format; 5] = [
        Format::Dmdjob,
        Format::DmdjobZip,
        Format::Sl1,
        Format::Sl1s,
        Format::SlaControl,
    ];

    /// The name `--format` takes.
    pub fn name(self) -> &'static str {
        match self {
            Format::Dmdjob => "dmdjob",
            Format::DmdjobZip => "dmdjob-zip",
            Format::Sl1 => "sl1",
            Format::Sl1s => "sl1s",
            Format::SlaControl => "sla-control",
        }
    }

    /// The format named `name` (as [`Format::name`] gives it).
    pub fn parse(name: &str) -> Option<Format> {
        Format::ALL.into_iter().find(|f| f.name() == name)
    }

    /// The file name ending a default output path gets: `.dmdjob`, `.dmdjob.zip`, `.sl1`,
    /// `.sl1s`, `.zip`.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Dmdjob => ".dmdjob",
            Format::DmdjobZip => ".dmdjob.zip",
            Format::Sl1 => ".sl1",
            Format::Sl1s => ".sl1s",
            Format::SlaControl => ".zip",
        }
    }

    /// True for the forms that are one file (every one but the directory bundle).
    pub fn is_one_file(self) -> bool {
        self != Format::Dmdjob
    }

    /// What the name of `path` says: `Some(Ok(format))` for `.dmdjob`, `.dmdjob.zip`,
    /// `.sl1`, `.sl1s` (any case), `Some(Err(()))` for a plain `.zip` (the native zip or
    /// the control-file standard: ambiguous), `None` for any other name.
    fn of_name(path: &Path) -> Option<std::result::Result<Format, ()>> {
        let name = path.file_name()?.to_string_lossy().to_lowercase();
        let f = if name.ends_with(".dmdjob.zip") {
            Ok(Format::DmdjobZip)
        } else if name.ends_with(".zip") {
            Err(())
        } else if name.ends_with(".dmdjob") {
            Ok(Format::Dmdjob)
        } else if name.ends_with(".sl1") {
            Ok(Format::Sl1)
        } else if name.ends_with(".sl1s") {
            Ok(Format::Sl1s)
        } else {
            return None;
        };
        Some(f)
    }

    /// The format of output `path`: `given` (`--format`) if any, else what its name says;
    /// a name without a known ending is a bundle directory. A plain `.zip` without
    /// `--format`, or a `--format` the name contradicts (`-o part.sl1 --format
    /// dmdjob-zip`), is a usage error saying what to do.
    pub fn for_output(given: Option<Format>, path: &Path) -> Result<Format> {
        let shown = path.display();
        match (given, Format::of_name(path)) {
            (None, Some(Ok(f))) => Ok(f),
            (None, None) => Ok(Format::Dmdjob),
            (None, Some(Err(()))) => Err(Error::Usage(format!(
                "{shown}: a .zip can be a dmdjob bundle or an SLA control file; add --format dmdjob-zip or --format sla-control (or name it .dmdjob.zip)"
            ))),
            (Some(f), None) => Ok(f),
            (Some(f), Some(Err(()))) if matches!(f, Format::DmdjobZip | Format::SlaControl) => {
                Ok(f)
            }
            (Some(f), Some(Ok(g))) if f == g => Ok(f),
            (Some(f), _) => Err(Error::Usage(format!(
                "{shown}: --format {} writes a {} file, but the name ends like {}; name it *{} or drop --format",
                f.name(),
                f.name(),
                match Format::of_name(path) {
                    Some(Ok(g)) => format!("a {} file", g.name()),
                    _ => "a zip".into(),
                },
                f.extension()
            ))),
        }
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Where a job's files (masks, gray maps) come from, by the relative path the manifest
/// names.
pub trait BundleFiles: Sync {
    /// The bytes of file `rel` (e.g. `masks/00012.png`). Errors name the file.
    fn read(&self, rel: &str) -> Result<Cow<'_, [u8]>>;

    /// How file `rel` is named in messages.
    fn shown(&self, rel: &str) -> PathBuf;
}

/// The files of a bundle directory.
#[derive(Debug, Clone)]
pub struct DirFiles {
    dir: PathBuf,
}

impl DirFiles {
    /// The files under bundle directory `dir`.
    pub fn new(dir: &Path) -> DirFiles {
        DirFiles { dir: dir.into() }
    }
}

/// A relative path made only of normal components (nothing outside the bundle).
fn is_inside(rel: &str) -> bool {
    !rel.is_empty()
        && Path::new(rel)
            .components()
            .all(|c| matches!(c, Component::Normal(_)))
}

impl BundleFiles for DirFiles {
    fn read(&self, rel: &str) -> Result<Cow<'_, [u8]>> {
        if !is_inside(rel) {
            return Err(Error::Bundle {
                path: self.dir.join(MANIFEST),
                msg: format!("file path {rel:?} leads outside the bundle"),
            });
        }
        let path = self.dir.join(rel);
        let bytes = crate::input::read_file(&path, "bundle file", crate::input::TEXT_MAX_BYTES)?;
        Ok(Cow::Owned(bytes))
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.dir.join(rel)
    }
}

/// Reads the bundle directory `dir` for export: its manifest, checked, and its files. The
/// one place `dmdsl export` opens its input.
pub fn open_bundle(dir: &Path) -> Result<(Manifest, Box<dyn BundleFiles>)> {
    let manifest = Manifest::read(dir)?;
    Ok((manifest, Box::new(DirFiles::new(dir))))
}

/// The files of a bundle its manifest names, in the order the native forms store them:
/// every layer's masks, then the gray maps.
pub fn bundle_files(m: &Manifest) -> Vec<&str> {
    let mut files: Vec<&str> = m
        .layers
        .iter()
        .flat_map(|l| l.masks.iter().map(|k| k.file.as_str()))
        .collect();
    files.extend(m.optics.iter().map(|o| o.gray_map.as_str()));
    files.extend(m.projector_optics.iter().map(|o| o.gray_map.as_str()));
    files
}

/// Writes the job (`manifest` and its `files`) at `out` in `format`, atomically; returns
/// what the format could not carry. Nothing is left at `out` (nor beside it) on failure,
/// nor when `cancel` is set while it is written ([`Error::Interrupted`]).
pub fn write(
    format: Format,
    manifest: &Manifest,
    files: &dyn BundleFiles,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<Vec<Warning>> {
    match format {
        Format::Dmdjob => native::write_dir(manifest, files, out, cancel).map(|()| Vec::new()),
        Format::DmdjobZip => native::write_zip(manifest, files, out, cancel).map(|()| Vec::new()),
        Format::Sl1 | Format::Sl1s => sl1::write(format, manifest, files, out, cancel),
        Format::SlaControl => control::write(manifest, files, out, cancel),
    }
}

/// Checks, before anything is written, that `format` can hold the job of `profile`:
/// SL1/SL1S hold one projector's masks. `out` names the output in the error.
/// A directory in the way of a one-file format is refused here too.
pub fn check_fits(format: Format, profile: &crate::profile::Profile, out: &Path) -> Result<()> {
    if format.is_one_file() {
        crate::archive::write::check_dest(out)?;
    }
    match format {
        Format::Sl1 | Format::Sl1s => sl1::check_projectors(profile.projector.len(), out),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_follow_the_name_or_the_flag() {
        let f = |given: Option<&str>, p: &str| {
            Format::for_output(given.map(|g| Format::parse(g).unwrap()), Path::new(p))
        };
        assert_eq!(f(None, "a.dmdjob").unwrap(), Format::Dmdjob);
        assert_eq!(f(None, "out/a").unwrap(), Format::Dmdjob);
        assert_eq!(f(None, "a.DMDJOB.zip").unwrap(), Format::DmdjobZip);
        assert_eq!(f(None, "a.sl1").unwrap(), Format::Sl1);
        assert_eq!(f(None, "a.sl1s").unwrap(), Format::Sl1s);
        assert_eq!(f(Some("sla-control"), "a.zip").unwrap(), Format::SlaControl);
        assert_eq!(f(Some("dmdjob-zip"), "a.zip").unwrap(), Format::DmdjobZip);
        assert_eq!(f(Some("sl1"), "a").unwrap(), Format::Sl1);
        for (given, p) in [
            (None, "a.zip"),
            (Some("sl1"), "a.zip"),
            (Some("sl1"), "a.sl1s"),
            (Some("dmdjob"), "a.dmdjob.zip"),
            (Some("sla-control"), "a.dmdjob.zip"),
        ] {
            let e = f(given, p).unwrap_err();
            assert!(matches!(e, Error::Usage(_)), "{e}");
            assert!(!e.to_string().contains('\n'));
        }
        for g in Format::ALL {
            assert_eq!(Format::parse(g.name()), Some(g));
        }
    }
}
