//! The forms a job is written and read in ([`Format`]) and how an output's name says
//! which.

use crate::error::{Error, Result};
use std::path::Path;

/// The forms a job can be written in (`slice --format`, `export`) and read in (`run`,
/// `inspect`).
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

    /// One line on what the format is (`--format`'s help).
    pub fn about(self) -> &'static str {
        match self {
            Format::Dmdjob => "The bundle directory: job.json and masks/*.png",
            Format::DmdjobZip => "The bundle's files in one zip (job.json first, images stored)",
            Format::Sl1 => "Prusa SL1 (PrusaSlicer 2.5's zip)",
            Format::Sl1s => "Prusa SL1S",
            Format::SlaControl => {
                "The SLA 3D printer control-file standard, schema v5 (print_settings.json + slices/)"
            }
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
